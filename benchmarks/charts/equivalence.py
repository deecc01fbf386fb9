"""Chart 8: the passes `check` needs to reach `equivalent` at each scale, against a fixed-sample oracle that knows
the true variances.

Synthetic passes, so that the truth is known exactly: a 128×128 image in 16-px tiles, 3 channels, each tile-channel's
Welch sample (its per-pass sum) a gamma variable with its own mean and its own coefficient of variation (1-3 %:
unequal variances, skewed), two tiles with fireflies (a spike of 30 % of the tile's mean in 1 % of the passes:
skewness near 10 per pass). A coarser tile's sample is the sum of its 16-px tiles'. Two independent sides (two
builds, or ``check --unpaired``), `check`'s defaults (alpha 1 %, tolerance 1 %, every scale, the budget a ceiling)
with ``--equivalence-tile`` set to each scale in turn.

The oracle is the best a fixed design could do knowing every variance: one look after n passes a side, each
tile-channel's two one-sided z-tests at alpha (intersection-union: no correction over tiles), so a tile-channel of
mean mu and per-pass variance v passes with probability 2 Phi(delta mu / sqrt(2 v / n) - z_(1-alpha)) - 1 when the
sides agree, and the image when all of them pass. Its median (and 90th percentile) passes are where that product
reaches 0.5 (0.9). What separates `check` from it is what `check` cannot know: the variances (estimated, and with
n - 1 degrees of freedom at every look), when to stop (the boundaries of its looks) and the normality of small
samples (its early looks' rule).

The same runs with the test side +3 % in one 16-px tile (a local bias three times the tolerance) show what
`equivalent` at a coarser scale means: true there, where the tile's difference is averaged down, and never at 16².
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import stats

import welch_core as wc

from ..common.cache import digest, memo_json, welch_digest
from ..common.plotting import plt, save, write_csv
from ..common.pools import say
from ..common.trials import ALPHA, BASE_TILE
from ..common.words import n as _n
from ..common.words import pct as _pct

#: `check`'s defaults: tolerance 1 %.
TOLERANCE = 0.01
SIZE = 128
TILES = SIZE // BASE_TILE
CHANNELS = 3
SCALES = (16, 32, 64, 128)
#: The local bias of the second case: +3 % in the 16-px tile at (row 2, column 5), every channel.
LOCAL_BIAS, LOCAL_TILE = 0.03, (2, 5)
#: Part of the cache key, with welch_core's source.
VERSION = 1


class Model:
    """The synthetic scene: each 16-px tile-channel's per-pass sum is Gamma(k, theta) plus, in the firefly tiles, a
    spike `spike` with probability `P_SPIKE`."""

    P_SPIKE = 0.01

    def __init__(self, seed: int = 8):
        rng = np.random.default_rng(seed)
        shape = (TILES, TILES, CHANNELS)
        self.mean = rng.uniform(50.0, 200.0, shape) * BASE_TILE**2
        cv = rng.uniform(0.01, 0.03, shape)
        fireflies = np.zeros(shape, bool)
        fireflies[1, 6] = fireflies[5, 2] = True
        self.spike = np.where(fireflies, 0.3 * self.mean, 0.0)
        gamma_mean = self.mean - self.P_SPIKE * self.spike
        self.k = 1.0 / cv**2
        self.theta = gamma_mean / self.k
        self.variance = self.k * self.theta**2 + self.P_SPIKE * (1 - self.P_SPIKE) * self.spike**2

    def draw(self, rng: np.random.Generator, n: int, scale: np.ndarray | float = 1.0) -> np.ndarray:
        """`n` passes' 16-px tile sums, shape (n, tiles, tiles, channels), times `scale` (a bias)."""
        shape = (n, *self.mean.shape)
        spikes = (rng.random(shape) < self.P_SPIKE) * self.spike
        return (rng.gamma(self.k, self.theta, shape) + spikes) * scale

    def at(self, values: np.ndarray, tile: int) -> np.ndarray:
        """Per-tile sums of `values` (16-px tiles' means or variances) at `tile`."""
        f = tile // BASE_TILE
        return values.reshape(TILES // f, f, TILES // f, f, CHANNELS).sum(axis=(1, 3))

    def bias(self) -> np.ndarray:
        """The test side's factor per 16-px tile-channel in the local-bias case."""
        factor = np.ones(self.mean.shape)
        factor[LOCAL_TILE] += LOCAL_BIAS
        return factor

    def true_difference(self, tile: int) -> float:
        """The largest relative difference of a tile at `tile` in the local-bias case."""
        return float(np.max(self.at(self.mean * self.bias(), tile) / self.at(self.mean, tile) - 1.0))

    def oracle(self, tile: int, quantile: float, alpha: float = ALPHA, tolerance: float = TOLERANCE) -> int:
        """The passes a side at which the fixed-sample known-variance design ends `equivalent` with probability
        `quantile` when the sides agree."""
        mean, variance = self.at(self.mean, tile), self.at(self.variance, tile)
        z = stats.norm.ppf(1 - alpha)

        def p_all(n: int) -> float:
            margin = tolerance * mean / np.sqrt(2 * variance / n) - z
            return float(np.prod(np.clip(2 * stats.norm.cdf(margin) - 1, 0.0, 1.0)))

        lo, hi = 2, 2
        while p_all(hi) < quantile:
            lo, hi = hi, hi * 2
        while lo < hi:  # the smallest n with p_all(n) >= quantile (p_all grows with n)
            mid = (lo + hi) // 2
            lo, hi = (mid + 1, hi) if p_all(mid) < quantile else (lo, mid)
        return lo


def one_run(model: Model, rng, plan: wc.SequentialPlan, biased: bool) -> dict:
    """One simulated `check --unpaired --equivalence-tile N`: where it stopped and how."""
    n_max = plan.max_passes
    ref = model.draw(rng, n_max)
    test = model.draw(rng, n_max, model.bias() if biased else 1.0)
    schedule = wc.look_schedule(n_max)
    look, n = None, 0
    for k, n in enumerate(schedule):
        fractions = [min(m / n_max, 1.0) for m in schedule[: k + 1]]
        a = wc.TileStats.from_sums(ref[:n], list(range(n)), SIZE, SIZE, BASE_TILE)
        b = wc.TileStats.from_sums(test[:n], list(range(n_max, n_max + n)), SIZE, SIZE, BASE_TILE)
        claim = look.outcome.target_tile if look is not None else None  # sized at an earlier look: kept
        look = wc.sequential_look(a, b, plan, fractions, claim_tile=claim)
        if look.verdict is not None:
            break
    return {"passes": n, "verdict": look.outcome.verdict.label}


def simulate(model: Model, tile: int, biased: bool, runs: int, max_passes: int, cache_dir: Path) -> list[dict]:
    key = digest("equivalence", tile, biased, runs, max_passes, welch_digest(), VERSION)

    def compute():
        rng = np.random.default_rng(int(key[:8], 16))
        plan = wc.SequentialPlan(max_passes=max_passes, alpha=ALPHA, tolerance=TOLERANCE, equivalence_tile=tile)
        return [one_run(model, rng, plan, biased) for _ in range(runs)]

    return memo_json(cache_dir, "equivalence", key, compute)


def quantile(runs: list[dict], q: float) -> float | None:
    """The q-quantile of the passes to `equivalent`, runs that did not get there counting as never."""
    passes = [r["passes"] if r["verdict"] == "equivalent" else np.inf for r in runs]
    v = float(np.quantile(passes, q, method="higher"))
    return v if np.isfinite(v) else None


def run(b, cache_dir: Path, out_dir: Path) -> dict:
    model, rows = Model(), []
    for tile in SCALES:
        row = {"tile": tile, "oracle_median_passes": model.oracle(tile, 0.5),
               "oracle_p90_passes": model.oracle(tile, 0.9), "max_passes": b.equivalence_passes,
               "runs": b.equivalence_runs}  # fmt: skip
        for case, biased in (("aa", False), ("local", True)):
            say(f"chart 8: {b.equivalence_runs} runs of check --equivalence-tile {tile}" + (", local bias" * biased))
            runs = simulate(model, tile, biased, b.equivalence_runs, b.equivalence_passes, cache_dir)
            counts = {v: sum(r["verdict"] == v for r in runs) for v in ("equivalent", "biased", "inconclusive")}
            row |= {f"{case}_{v}": k for v, k in counts.items()}
            if not biased:
                row |= {"check_median_passes": quantile(runs, 0.5), "check_p90_passes": quantile(runs, 0.9)}
        row["local_true_difference"] = model.true_difference(tile)
        m, o = row["check_median_passes"], row["oracle_median_passes"]
        row["check_over_oracle"] = None if m is None else m / o
        rows.append(row)
    files = [write_csv(out_dir / "chart8_equivalence.csv", rows), _plot(out_dir / "chart8_equivalence.png", rows)]
    return {"files": files, "rows": rows}


def _plot(path: Path, rows: list[dict]) -> str:
    fig, (left, right) = plt.subplots(1, 2, figsize=(14, 5.2))
    x = np.arange(len(rows))
    labels = [f"{r['tile']}²" for r in rows]
    budget = rows[0]["max_passes"]
    for key, label, style in (("check_median_passes", "check, median", "o-"),
                              ("check_p90_passes", "check, 90 % of runs", "o--"),
                              ("oracle_median_passes", "oracle (known variances, one look), median", "s-"),
                              ("oracle_p90_passes", "oracle, 90 %", "s--")):  # fmt: skip
        y = [r[key] if r[key] is not None else np.nan for r in rows]
        left.plot(x, y, style, label=label, color="#1f77b4" if key.startswith("check") else "#7f7f7f")
    left.axhline(budget, color="#d62728", lw=0.8, ls=":", label=f"budget ({budget} passes a side)")
    floor = wc.identical_passes(ALPHA)
    left.axhline(floor, color="black", lw=0.8, ls=":", label=f"no `equivalent` before {floor} passes (rare changes)")
    left.set_yscale("log")
    left.set_xticks(x, labels)
    left.set_xlabel("--equivalence-tile (the scale `equivalent` is claimed at; 16² is the default, the finest)")
    left.set_ylabel("passes a side to `equivalent` (log)")
    left.set_title("A/A: passes to `equivalent` by scale (missing: not reached within the budget)", fontsize=10)
    left.grid(alpha=0.3, which="both", lw=0.4)
    left.legend(fontsize=8)
    width = 0.38
    for offset, case, label, color in ((-width / 2, "aa", "A/A", "#2ca02c"),
                                       (width / 2, "local", "+3 % in one 16² tile", "#d62728")):  # fmt: skip
        share = [r[f"{case}_equivalent"] / r["runs"] for r in rows]
        right.bar(x + offset, share, width, color=color, label=label)
    for xi, r in zip(x, rows, strict=True):
        right.text(xi + width / 2, 0.02, f"true\n{_pct(r['local_true_difference'], 2)}", ha="center", fontsize=7,
                   color="white")  # fmt: skip
    right.axhline(ALPHA, color="black", lw=0.8, ls=":", label=f"α = {ALPHA}")
    right.set_xticks(x, labels)
    right.set_ylim(0, 1.05)
    right.set_xlabel("--equivalence-tile")
    right.set_ylabel("share of runs ending `equivalent`")
    right.set_title("`equivalent` holds at its scale: the local bias is within 1 % only once averaged", fontsize=10)
    right.legend(fontsize=8, loc="upper left")
    fig.suptitle(f"Chart 8: the passes to `equivalent` at each scale, against a known-variance oracle (α = {ALPHA})")
    fig.tight_layout()
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


CHART8 = """
## Chart 8: passes to `equivalent` at each scale, against a known-variance oracle

![chart 8](chart8_equivalence.png)

Synthetic passes with a known truth (`benchmarks/equivalence.py`): a 128×128 image in 16-px tiles, each
tile-channel's per-pass sum gamma-distributed with its own mean and a coefficient of variation of 1-3 %, two tiles
with fireflies (30 % of the tile's mean in 1 % of the passes); two independent sides, `check`'s defaults with
`--equivalence-tile` at each scale. The oracle knows every variance and looks once: each tile-channel's two
one-sided z-tests at α, all tiles at once (no correction over tiles, as `check`'s intersection-union test);
its median is the pass count at which the sides, when they agree, pass with probability 0.5.
"""


def section(f: dict) -> list[str]:
    """Chart 8's section of docs/benchmarks/README.md from the figures `f`."""
    rows = f["chart8"]["rows"]
    lines = [
        CHART8,
        "| `--equivalence-tile` | oracle: median, p90 passes | `check`: median, p90 passes (× oracle) "
        "| A/A runs: `equivalent` / `biased` / `inconclusive` | +3 % in one 16² tile: its true largest difference "
        "at this scale, runs `equivalent` |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = "" if r["check_over_oracle"] is None else f" ({r['check_over_oracle']:.2f}×)"
        lines.append(
            f"| {r['tile']}² | {_n(r['oracle_median_passes'])}, {_n(r['oracle_p90_passes'])} | "
            f"{_n(r['check_median_passes'])}, {_n(r['check_p90_passes'])}{ratio} | "
            f"{r['aa_equivalent']} / {r['aa_biased']} / {r['aa_inconclusive']} of {r['runs']} | "
            f"{_pct(r['local_true_difference'], 2)}: {r['local_equivalent']} of {r['runs']} |"
        )
    lines.append("")
    fine = rows[0]
    budget = fine["max_passes"]
    lines.append(
        f"- **The default, 16²**: the oracle needs {_n(fine['oracle_median_passes'])} passes a side (median); "
        + (f"`check` {_n(fine['check_median_passes'])}, {fine['check_over_oracle']:.2f}× as many."
           if fine["check_median_passes"] is not None else
           f"`check` reached `equivalent` in {fine['aa_equivalent']} of {fine['runs']} runs within {budget} passes "
           "(its median is beyond the budget).")
        + " The price of estimating every variance (n − 1 degrees of freedom at each look), of looking often "
        "(each look's boundary is above the fixed design's z), and of the firefly tiles, whose skewed early samples "
        "are not trusted to decide."
    )  # fmt: skip
    lines.append(
        f"- **Coarse scales** stop at the floor: `check` claims nothing before {wc.identical_passes(ALPHA)} passes "
        "a side, however tight the intervals (`welch_core.identical_passes`: enough passes that a change altering "
        "one pass in ten would have shown at 1 − α). The oracle has no such rule, so the ratio there is the floor's, "
        "not the test's."
    )
    wrong = [r for r in rows if r["local_true_difference"] > TOLERANCE and r["local_equivalent"] > ALPHA * r["runs"]]
    lines.append(
        "- **A local bias above the tolerance is not called `equivalent` at a scale where it is above it**: "
        + ("at most α of the runs at every such scale." if not wrong else
           "exceeded α at " + ", ".join(f"{r['tile']}²" for r in wrong) + ".")
        + " Where it is averaged below 1 % (a coarser `--equivalence-tile`), `equivalent` at that scale is the true "
        "answer, and the sentence names the scale."
    )  # fmt: skip
    return lines
