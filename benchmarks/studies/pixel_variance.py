"""A tile's variance from its pixels: calibration, dependence and power of a t-test on summed pixel variances.

    python -m benchmarks.studies.pixel_variance     # benchmarks/cache/ -> docs/benchmarks/pixel_variance.{csv,png}
    python -m benchmarks.studies.pixel_variance --quick --out /tmp/pv    # small pools, few trials: the pipeline

Issue 32, the measurement (no product change). The tool's unpaired test estimates a tile's variance from the n
tile sums of a side: n - 1 degrees of freedom, nearly useless at 2-4 passes a side. Where the pixels of a pass are
independent (Cycles: filter importance sampling, no splatting, a scrambled sequence per pixel),
Var(tile sum) = sum over the tile's pixels of Var(pixel), estimable from the per-pixel sample variances over the
passes with up to tile² (n - 1) degrees of freedom.

* The statistic (`pixel_test`): per 16² tile and channel, t = (mean_B - mean_A) / sqrt(V_A / n_A + V_B / n_B) on
  the side means of the tile sums, with V = sum_p s_p² (the per-pixel sample variances over a side's passes, ddof
  1) and Satterthwaite's degrees of freedom from the per-pixel pieces; two-sided p from Student's t. With the
  fallback, a tile-channel whose pixel df is below `DF_FLOOR` is tested by Welch's t on its tile sums instead;
  a third variant leaves such a tile-channel untested (the tile test's own miscalibration at 2 v 8 made it worth
  measuring).
  The family (`family_pvalue`): channels by Bonferroni, then Holm over the tiles of the one scale; `biased` when it
  rejects at alpha 0.01 (for the family's decision Holm and Bonferroni agree: both reject when the number of
  tiles times the smallest tile p is at most alpha).
* Calibration: A/A trials (disjoint random passes of one pool on the two sides) at 2, 3, 4 and 8 passes a side and
  2 v 8, 4 v 16; the rate of `biased` with its 95 % Wilson interval, for the pixel test without, with the
  fallback and with the tile-channels below the floor left untested, and for the tile test (Welch's t on the
  tile sums, as the tool tests one scale, without its normality screen and permutation test). The criterion of
  the issue: rate <= 1.5 alpha and the interval's lower end below alpha.
* Dependence: D = Var(tile sum) / sum_p Var(pixel) per tile-channel over all of a pool's passes (1 where the
  pixels are independent), its median and maximum against a permutation null (every pixel's values shuffled
  across the passes on their own, which makes the pixels independent and keeps their distributions).
* Broken settings rendered here (64², 1 spp, 400 passes, seconds each): the diffuse corner with
  ``cycles.scrambling_distance=0.1`` (the scenes keep ``auto_scrambling_distance`` off, so it takes effect) and
  with the developer pattern SOBOL_BURLEY (offered only with the developer preferences on, set before the scene
  is built; checked to render other images than BLUE_NOISE), and BLUE_NOISE for that check.
* Power: unpaired detection rate on two biased pairs at 2, 3, 4, 8, 16, 32 and 64 passes a side.
"""

from __future__ import annotations

import contextlib
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import special

import welch_core as wc

from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import PoolSpec, load_or_render, say
from ..common.trials import wilson

ALPHA, TILE, RESOLUTION = 0.01, 16, 64
#: Below this pixel Satterthwaite df a tile-channel falls back to Welch's t on its tile sums.
DF_FLOOR = 100.0
CONFIGS = ((2, 2), (3, 3), (4, 4), (8, 8), (2, 8), (4, 16))
METHODS = {
    "pixel": "pixel variances",
    "pixel_fallback": f"pixel variances, tile fallback below df {DF_FLOOR:.0f}",
    "pixel_drop": f"pixel variances, untested below df {DF_FLOOR:.0f}",
    "tile": "tile sums (Welch)",
}
DEVELOPER_PATTERNS = ("SOBOL_BURLEY",)

#: (name, label, scene, overrides, pattern, passes in the full run, passes in the quick run, rendered by this study)
POOLS = (
    ("corner", "diffuse corner", "corner", (), "TABULATED_SOBOL", 1000, 80, False),
    ("corner_glass", "glass caustic", "corner_glass", (), "TABULATED_SOBOL", 1000, 80, False),
    ("corner_glass_blue", "glass caustic, blue noise", "corner_glass", (), "BLUE_NOISE", 1000, 80, False),
    ("glossy", "glossy room", "glossy", (), "TABULATED_SOBOL", 1000, 80, False),
    ("textured", "textured", "textured", (), "TABULATED_SOBOL", 400, 40, False),
    ("textured_blur", "textured, Filter Glossy 1.0", "textured", ("cycles.blur_glossy=1.0",), "TABULATED_SOBOL",
     400, 40, False),
    ("corner_glass_clamp", "glass caustic, indirect clamp 20", "corner_glass", ("cycles.sample_clamp_indirect=20",),
     "TABULATED_SOBOL", 400, 40, False),
    ("corner_blue", "diffuse corner, blue noise", "corner", (), "BLUE_NOISE", 400, 40, True),
    ("corner_burley", "diffuse corner, SOBOL_BURLEY", "corner", (), "SOBOL_BURLEY", 400, 40, True),
    ("corner_glass_burley", "glass caustic, SOBOL_BURLEY", "corner_glass", (), "SOBOL_BURLEY", 400, 40, True),
    ("corner_scrambling", "diffuse corner, scrambling distance 0.1", "corner", ("cycles.scrambling_distance=0.1",),
     "TABULATED_SOBOL", 400, 40, True),
)  # fmt: skip
#: Biased pairs (reference pool, test pool, label) for the power hint: both 400 passes with seeds 0-399 (40 quick).
POWER_PAIRS = (
    ("textured", "textured_blur", "textured v Filter Glossy 1.0"),
    ("corner_glass_400", "corner_glass_clamp", "glass caustic v indirect clamp 20"),
)
FULL = {"trials": 1000, "power_trials": 400, "power_n": (2, 3, 4, 8, 16, 32, 64), "permutations": 20, "quick": False}
QUICK = {"trials": 10, "power_trials": 10, "power_n": (2, 3, 4, 8), "permutations": 2, "quick": True}
#: Passes held in memory at once by a batch of trials (float64, 64² x 3: 100 kB a pass).
BATCH_PASSES = 400


# ---------------------------------------------------------------------------------------------------------------
# The statistic


def tile_total(per_pixel: np.ndarray, tile: int = TILE) -> np.ndarray:
    """Sum of a per-pixel array (..., H, W, C) over each tile: (..., H / tile, W / tile, C)."""
    *lead, h, w, c = per_pixel.shape
    return per_pixel.reshape(*lead, h // tile, tile, w // tile, tile, c).sum(axis=(-4, -2))


@dataclass(frozen=True)
class Side:
    """One side's passes (..., n, H, W, C) reduced per tile-channel: the mean of the tile sums, the sample variance
    of the tile sums, and the sums over the tile's pixels of s_p² and of s_p⁴ (s_p² the pixel's sample variance
    over the n passes, ddof 1). Variances are NaN where n < 2."""

    n: int
    mean: np.ndarray
    tile_var: np.ndarray
    pixel_var: np.ndarray
    pixel_var2: np.ndarray


def side(passes: np.ndarray, tile: int = TILE) -> Side:
    x = np.asarray(passes, dtype=np.float64)
    n = x.shape[-4]
    sums = tile_total(x, tile)
    mean = sums.mean(axis=-4)
    if n < 2:
        nan = np.full(mean.shape, np.nan)
        return Side(n, mean, nan, nan, nan)
    s2 = x.var(axis=-4, ddof=1)
    return Side(n, mean, sums.var(axis=-4, ddof=1), tile_total(s2, tile), tile_total(s2 * s2, tile))


def two_sided_p(diff: np.ndarray, se2: np.ndarray, df: np.ndarray) -> np.ndarray:
    """Two-sided p of t = diff / sqrt(se2) under Student's t with `df`; where se2 is 0: 0 if diff differs from 0
    (a deterministic difference), NaN if not (nothing to test)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        t = diff / np.sqrt(se2)
        p = 2.0 * special.stdtr(df, -np.abs(t))
    return np.where(se2 > 0, p, np.where(diff != 0, 0.0, np.nan))


def tile_welch(a: Side, b: Side) -> tuple[np.ndarray, np.ndarray]:
    """Welch's t-test on the tile sums: (p, Welch-Satterthwaite df); NaN where either side has n < 2."""
    va, vb = a.tile_var / a.n, b.tile_var / b.n
    se2 = va + vb
    with np.errstate(invalid="ignore", divide="ignore"):
        df = se2 * se2 / (va * va / (a.n - 1) + vb * vb / (b.n - 1)) if min(a.n, b.n) >= 2 else np.nan * se2
    return two_sided_p(b.mean - a.mean, se2, df), df


@dataclass(frozen=True)
class PixelTest:
    """Per tile-channel: the pixel test's p and df, and where the tile test replaced it (the fallback)."""

    pvalue: np.ndarray
    df: np.ndarray
    fallback: np.ndarray


def pixel_test(a: Side, b: Side, df_floor: float | None = DF_FLOOR, below: str = "tile") -> PixelTest:
    """t on the side means of the tile sums with V = sum_p s_p² a side; Satterthwaite's df from the per-pixel pieces,
    df = (sum s_Ap² / n_A + sum s_Bp² / n_B)² / (sum (s_Ap² / n_A)² / (n_A - 1) + sum (s_Bp² / n_B)² / (n_B - 1)).
    With `df_floor`, a tile-channel whose df is below it (or undefined) gets Welch's t on its tile sums instead
    (`below` "tile") or is left untested (`below` "drop": p NaN, out of the family)."""
    se2 = a.pixel_var / a.n + b.pixel_var / b.n
    with np.errstate(invalid="ignore", divide="ignore"):
        pieces = a.pixel_var2 / (a.n * a.n * (a.n - 1)) + b.pixel_var2 / (b.n * b.n * (b.n - 1))
        df = se2 * se2 / pieces
    p = two_sided_p(b.mean - a.mean, se2, df)
    fallback = np.zeros(p.shape, bool)
    if df_floor is not None:
        fallback = ~(df >= df_floor)
        p = np.where(fallback, tile_welch(a, b)[0] if below == "tile" else np.nan, p)
    return PixelTest(p, df, fallback)


def family_pvalue(pvalues: np.ndarray) -> np.ndarray:
    """The family's p of one scale from tile-channel p-values (..., tiles_y, tiles_x, C): channels by Bonferroni
    (`welch_core.combine_channels`), then Holm over the tiles, whose smallest adjusted p is the number of testable
    tiles times the smallest tile p (capped at 1; NaN where no tile is testable). `biased` where it is <= alpha."""
    tile_p = wc.combine_channels(pvalues)
    flat = tile_p.reshape(*tile_p.shape[:-2], -1)
    m = np.isfinite(flat).sum(axis=-1)
    smallest = np.min(np.where(np.isfinite(flat), flat, np.inf), axis=-1)
    with np.errstate(invalid="ignore"):  # 0 x inf where no tile is testable
        return np.where(m > 0, np.minimum(1.0, m * smallest), np.nan)


def dependence(passes: np.ndarray, tile: int = TILE) -> np.ndarray:
    """D = Var(tile sum) / sum_p Var(pixel) per tile-channel over all `passes` (N, H, W, C), both ddof 1; NaN where
    the tile's pixels do not vary."""
    x = np.asarray(passes, dtype=np.float64)
    pixels = tile_total(x.var(axis=0, ddof=1), tile)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(pixels > 0, tile_total(x, tile).var(axis=0, ddof=1) / pixels, np.nan)


# ---------------------------------------------------------------------------------------------------------------
# Trials


def decisions(a: np.ndarray, b: np.ndarray) -> dict[str, np.ndarray]:
    """Per trial of a batch (a: (B, n_A, H, W, C), b likewise): each method's family p, and the pixel test's
    share of tile-channels that fell back and median df."""
    sa, sb = side(a), side(b)
    plain, fallback = pixel_test(sa, sb, None), pixel_test(sa, sb, DF_FLOOR)
    axes = (-3, -2, -1)
    return {
        "pixel": family_pvalue(plain.pvalue),
        "pixel_fallback": family_pvalue(fallback.pvalue),
        "pixel_drop": family_pvalue(pixel_test(sa, sb, DF_FLOOR, "drop").pvalue),
        "tile": family_pvalue(tile_welch(sa, sb)[0]),
        "fallback_share": fallback.fallback.mean(axis=axes),
        "median_df": np.nanmedian(plain.df.reshape(plain.df.shape[0], -1), axis=-1),
    }


def run_trials(ref: np.ndarray, test: np.ndarray, n_a: int, n_b: int, trials: int, seed) -> dict[str, np.ndarray]:
    """`trials` draws of disjoint passes, n_a from `ref` and n_b from `test` (positions drawn from the shorter
    pool's range, so a pair of pools with the same seeds never shares a seed); every method on the same draws."""
    rng = np.random.default_rng(seed)
    passes = min(len(ref), len(test))
    picks = np.stack([rng.choice(passes, n_a + n_b, replace=False) for _ in range(trials)])
    batch = max(1, BATCH_PASSES // (n_a + n_b))
    parts = [decisions(ref[picks[i : i + batch, :n_a]], test[picks[i : i + batch, n_a:]])
             for i in range(0, trials, batch)]  # fmt: skip
    return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}


def rate_row(kind: str, pool: str, label: str, n_a: int, n_b: int, method: str, family_p: np.ndarray,
             extra: dict[str, np.ndarray]) -> dict:  # fmt: skip
    k, n = int(np.sum(family_p <= ALPHA)), len(family_p)
    low, high = wilson(k, n)
    meets = (k / n <= 1.5 * ALPHA and low < ALPHA) if kind == "aa" else None
    uses_pixels = method != "tile"
    return {"kind": kind, "pool": pool, "label": label, "config": f"{n_a} v {n_b}", "n_a": n_a, "n_b": n_b,
            "method": method, "trials": n, "biased": k, "rate": k / n, "low": low, "high": high, "meets": meets,
            "fallback_share": float(extra["fallback_share"].mean()) if method.startswith("pixel_") else None,
            "median_df": float(np.median(extra["median_df"])) if uses_pixels else None}  # fmt: skip


# ---------------------------------------------------------------------------------------------------------------
# Pools


@contextlib.contextmanager
def developer_patterns():
    """Offer Cycles' developer patterns (SOBOL_BURLEY) while pools are rendered: the add-on lists them only with
    the developer UI and the Cycles debug option on, which the scene's factory reset turns off, and renders them
    as blue noise unless they were on before the scene's first render; so they are set between the reset and the
    build (see docs/findings/blue_noise_volume.md)."""
    import bpy

    from batch.blender import render

    build = render.build_scene

    def building(name):
        prefs = bpy.context.preferences
        prefs.view.show_developer_ui = True
        prefs.experimental.use_cycles_debug = True
        return build(name)

    render.build_scene = building
    try:
        yield
    finally:
        render.build_scene = build


def pool_spec(entry, quick: bool) -> PoolSpec:
    _name, _label, scene, overrides, pattern, full, small, _rendered = entry
    return PoolSpec(scene, overrides, RESOLUTION, passes=small if quick else full, pattern=pattern)


def load(spec: PoolSpec, cache: Path, label: str):
    if spec.pattern in DEVELOPER_PATTERNS and not (Path(cache) / f"pool-{spec.key}" / "meta.json").exists():
        with developer_patterns():
            return load_or_render(spec, cache, label)
    return load_or_render(spec, cache, label)


def load_pools(budget: dict, cache: Path) -> dict[str, tuple[str, np.ndarray, float]]:
    """name -> (label, images as float32 in memory, render seconds of the pool)."""
    out = {}
    for entry in POOLS:
        name, label = entry[0], entry[1]
        start = time.perf_counter()
        pool = load(pool_spec(entry, budget["quick"]), cache, label)
        if entry[7]:
            say(f"  {label}: {pool.n} passes, {pool.total_seconds:.1f} s of rendering "
                f"({time.perf_counter() - start:.1f} s to load or render)")  # fmt: skip
        out[name] = (label, np.asarray(pool.images, dtype=np.float32), pool.total_seconds)
    burley, blue = out["corner_burley"][1], out["corner_blue"][1]
    if np.array_equal(burley[0], blue[0]):
        raise RuntimeError("SOBOL_BURLEY rendered the same pass as BLUE_NOISE: the developer pattern was not used")
    glass = PoolSpec("corner_glass", (), RESOLUTION, passes=40 if budget["quick"] else 400)
    out["corner_glass_400"] = ("glass caustic", np.asarray(load(glass, cache, "glass").images, np.float32), 0.0)
    return out


# ---------------------------------------------------------------------------------------------------------------
# The measurement


def dependence_row(name: str, label: str, images: np.ndarray, seconds: float, permutations: int) -> dict:
    d = dependence(images)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    null_median, null_max, null_all = [], [], []
    for _ in range(permutations):
        shuffled = dependence(rng.permuted(images, axis=0))
        null_median.append(np.nanmedian(shuffled))
        null_max.append(np.nanmax(shuffled))
        null_all.append(shuffled[np.isfinite(shuffled)])
    pooled = np.concatenate(null_all)
    row = {"kind": "dependence", "pool": name, "label": label, "passes": len(images),
           "tile_channels": int(np.isfinite(d).sum()), "d_median": float(np.nanmedian(d)),
           "d_min": float(np.nanmin(d)), "d_max": float(np.nanmax(d)),
           "null_tile_low": float(np.quantile(pooled, 0.005)), "null_tile_high": float(np.quantile(pooled, 0.995)),
           "null_median_low": float(np.min(null_median)), "null_median_high": float(np.max(null_median)),
           "null_max_high": float(np.max(null_max)), "permutations": permutations,
           "render_seconds": round(seconds, 2)}  # fmt: skip
    say(f"  D {label}: median {row['d_median']:.2f}, range [{row['d_min']:.2f}, {row['d_max']:.2f}]; null "
        f"median [{row['null_median_low']:.2f}, {row['null_median_high']:.2f}], tile 99 % "
        f"[{row['null_tile_low']:.2f}, {row['null_tile_high']:.2f}], max up to {row['null_max_high']:.2f}")  # fmt: skip
    return row


def measure(budget: dict, cache: Path) -> list[dict]:
    pools = load_pools(budget, cache)
    rows = []
    for name, label, *_ in POOLS:
        rows.append(dependence_row(name, label, pools[name][1], pools[name][2], budget["permutations"]))
    for name, label, *_ in POOLS:
        images = pools[name][1]
        for n_a, n_b in CONFIGS:
            found = run_trials(images, images, n_a, n_b, budget["trials"], [zlib.crc32(name.encode()), n_a, n_b])
            line = []
            for method in METHODS:
                rows.append(rate_row("aa", name, label, n_a, n_b, method, found[method], found))
                line.append(f"{method} {rows[-1]['biased']}/{rows[-1]['trials']}{'' if rows[-1]['meets'] else ' !'}")
            say(f"  A/A {label}, {n_a} v {n_b}: " + ", ".join(line))
    for ref, test, label in POWER_PAIRS:
        for n in budget["power_n"]:
            found = run_trials(
                pools[ref][1], pools[test][1], n, n, budget["power_trials"], [zlib.crc32(ref.encode()), n]
            )
            line = []
            for method in METHODS:
                rows.append(rate_row("power", f"{ref} v {test}", label, n, n, method, found[method], found))
                line.append(f"{method} {rows[-1]['biased']}/{rows[-1]['trials']}")
            say(f"  power {label}, {n} v {n}: " + ", ".join(line))
    return rows


def uniform_rows(rows: list[dict]) -> list[dict]:
    """Every row with every column (the CSV's header is the union, in order of first appearance)."""
    keys = list(dict.fromkeys(k for row in rows for k in row))
    return [{k: row.get(k) for k in keys} for row in rows]


def chart(rows: list[dict], path: Path) -> None:
    from ..common.plotting import plt, save

    colours = {"pixel": "#1f77b4", "pixel_fallback": "#2ca02c", "pixel_drop": "#ff7f0e", "tile": "#7f7f7f"}
    aa = [r for r in rows if r["kind"] == "aa"]
    pools = list(dict.fromkeys(r["pool"] for r in aa))
    configs = [f"{a} v {b}" for a, b in CONFIGS]
    fig = plt.figure(figsize=(18, 11))
    grid = fig.add_gridspec(2, 3, height_ratios=(3, 2))
    ax = fig.add_subplot(grid[0, :])
    labels = [f"{p}\n{c}" for p in pools for c in configs]
    for offset, method in zip((-0.3, -0.1, 0.1, 0.3), METHODS, strict=True):
        mine = [r for r in aa if r["method"] == method]
        x = np.array([labels.index(f"{r['pool']}\n{r['config']}") for r in mine]) + offset
        y = 100 * np.array([r["rate"] for r in mine])
        err = 100 * np.array([[r["rate"] - r["low"] for r in mine], [r["high"] - r["rate"] for r in mine]])
        ax.errorbar(x, y, yerr=err, fmt="o", ms=3, capsize=2, color=colours[method], label=METHODS[method])
    ax.axhline(100 * ALPHA, color="k", lw=0.8, ls="--", label="alpha")
    ax.axhline(150 * ALPHA, color="r", lw=0.8, ls=":", label="1.5 alpha")
    for i in range(1, len(pools)):
        ax.axvline(i * len(configs) - 0.5, color="0.8", lw=0.8)
    ax.set_xticks(range(len(labels)), [c if i % len(configs) else f"{c}\n{p}" for i, (p, c) in
                                       enumerate((p, c) for p in pools for c in configs)], fontsize=6)  # fmt: skip
    ax.set_yscale("symlog", linthresh=1)
    ax.set_ylim(0, 100)
    ax.set(ylabel="% of A/A trials called biased", title="A/A: false `biased` rate (95 % Wilson intervals)")
    ax.legend(fontsize=8, ncol=5)
    ax.grid(alpha=0.3)

    dep = [r for r in rows if r["kind"] == "dependence"]
    ax = fig.add_subplot(grid[1, 0])
    y = np.arange(len(dep))
    ax.hlines(y, [r["d_min"] for r in dep], [r["d_max"] for r in dep], color="#1f77b4", lw=2, label="range of D")
    ax.plot([r["d_median"] for r in dep], y, "o", color="#1f77b4", label="median D")
    ax.hlines(y + 0.25, [r["null_tile_low"] for r in dep], [r["null_tile_high"] for r in dep], color="#ff7f0e",
              label="permutation null, 99 % of tile-channels")  # fmt: skip
    ax.axvline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_yticks(y, [r["label"] for r in dep], fontsize=7)
    ax.invert_yaxis()
    ax.set(xlabel="D = Var(tile sum) / sum Var(pixel)", title="dependence of the pixels of a tile")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)

    power = [r for r in rows if r["kind"] == "power"]
    for ax, pair in zip((fig.add_subplot(grid[1, 1]), fig.add_subplot(grid[1, 2])), POWER_PAIRS, strict=True):
        for method in METHODS:
            mine = [r for r in power if r["label"] == pair[2] and r["method"] == method]
            ax.plot([r["n_a"] for r in mine], [100 * r["rate"] for r in mine], "o-", color=colours[method],
                    label=METHODS[method])  # fmt: skip
        ax.set(xlabel="passes a side", ylabel="% called biased", title=f"power: {pair[2]}", ylim=(-3, 103))
        ax.set_xscale("log", base=2)
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, path)


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("pixel_variance", __doc__, "small pools and few trials (checks the pipeline)", argv)
    start = time.perf_counter()
    rows = uniform_rows(measure(QUICK if args.quick else FULL, args.cache))
    write_csv(args.out / "pixel_variance.csv", rows)
    chart(rows, args.out / "pixel_variance.png")
    say(f"wrote {args.out / 'pixel_variance.csv'} and {args.out / 'pixel_variance.png'} "
        f"in {time.perf_counter() - start:.0f} s")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
