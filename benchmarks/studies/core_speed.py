"""Speed and precision of welch_core, measured in one process as ratios (the machine may be noisy).

Run from the repository root::

    python -m benchmarks.studies.core_speed

(a) One 4K pass (3840x2160 RGBA float32) into 32x32 tile sums: `tile_sums` against a plain `img.sum()` over the
    same array (the memory-bandwidth floor) and against the naive float64 reshape-sum; `TileStats.add_pass`, which
    also keeps the per-pixel mean image.
(b) The full `compare` on a 4K tile grid (120x67 tiles x 3 channels = 24 120 tile-channels, N = 32 a side) against
    `scipy.stats.ttest_ind_from_stats` on the same arrays.
(c) Exact, Gaussian and Abramowitz-Stegun p-values: time per million and the largest relative error against
    mpmath at 40 digits on a grid of nu in [1, 1e4] and |t| up to 40.

Every time is the minimum over several repeats. Nothing is asserted.
"""

from __future__ import annotations

import argparse

import mpmath
import numpy as np
from scipy import special, stats

from welch_core import (
    TileStats,
    compare,
    pvalue_as_erf,
    pvalue_exact,
    pvalue_gauss,
    tile_sums,
    two_sided_pvalue,
    welch_from_stats,
)

from ..common.measure import best_time, mp_student

WIDTH, HEIGHT, TILE = 3840, 2160, 32


def table(title: str, header: tuple[str, ...], rows: list[tuple]) -> None:
    widths = [max(len(str(x)) for x in column) for column in zip(header, *rows, strict=True)]
    print(f"\n{title}")
    for i, row in enumerate([header, *rows]):
        print(
            "  "
            + "  ".join(
                str(x).rjust(w) if j else str(x).ljust(w) for j, (x, w) in enumerate(zip(row, widths, strict=True))
            )
        )
        if i == 0:
            print("  " + "  ".join("-" * w for w in widths))


# -- (a) accumulation ----------------------------------------------------------------------------------------


def bench_accumulation() -> None:
    rng = np.random.default_rng(1)
    img = rng.exponential(size=(HEIGHT, WIDTH, 4)).astype(np.float32)
    ty, tx = HEIGHT // TILE, WIDTH // TILE

    def naive():
        return img[: ty * TILE, : tx * TILE, :3].reshape(ty, TILE, tx, TILE, 3).sum(axis=(1, 3), dtype=np.float64)

    run = TileStats(HEIGHT, WIDTH, TILE)
    seeds = iter(range(10**6))

    tile_sums(img, TILE)  # touch the pages once before timing
    measured = [
        (name, best_time(func, 9))
        for name, func in (
            ("img.sum() (memory floor)", img.sum),
            ("tile_sums", lambda: tile_sums(img, TILE)),
            ("naive reshape-sum float64", naive),
            ("TileStats.add_pass (+ mean image)", lambda: run.add_pass(img, next(seeds))),
        )
    ]
    floor = measured[0][1]
    rows = [(name, f"{t * 1e3:.1f}", f"{t / floor:.2f}") for name, t in measured]
    table(f"(a) one 4K pass {WIDTH}x{HEIGHT} RGBA float32 into {TILE}x{TILE} tiles", ("", "ms", "x floor"), rows)


# -- (b) the full test on a 4K tile grid ----------------------------------------------------------------------


def bench_compare() -> None:
    rng = np.random.default_rng(2)
    ty, tx, n = HEIGHT // TILE, WIDTH // TILE, 32
    mean = rng.uniform(100.0, 1000.0, size=(ty, tx, 3))
    ref = TileStats.from_sums(mean + rng.normal(0, 10, size=(n, ty, tx, 3)), range(n), HEIGHT, WIDTH, TILE)
    test = TileStats.from_sums(mean + rng.normal(0, 20, size=(n, ty, tx, 3)), range(n, 2 * n), HEIGHT, WIDTH, TILE)
    m1, s1, m2, s2 = ref.mean, np.sqrt(ref.variance), test.mean, np.sqrt(test.variance)

    base = best_time(lambda: stats.ttest_ind_from_stats(m1, s1, n, m2, s2, n, equal_var=False))
    rows = [("scipy ttest_ind_from_stats", f"{base * 1e3:.2f}", "1.00")]
    for name, func in (
        ("welch_from_stats", lambda: welch_from_stats(m1, ref.variance, n, m2, test.variance, n)),
        ("compare (test, diagnostics, verdict, effects)", lambda: compare(ref, test)),
    ):
        t = best_time(func)
        rows.append((name, f"{t * 1e3:.2f}", f"{t / base:.2f}"))
    table(
        f"(b) full test on a 4K tile grid: {ty}x{tx}x3 = {ty * tx * 3} tile-channels, N = {n} a side",
        ("", "ms", "x scipy"),
        rows,
    )


# -- (c) p-values ---------------------------------------------------------------------------------------------


def mp_gauss(t: float) -> mpmath.mpf:
    return mpmath.erfc(mpmath.mpf(t) / mpmath.sqrt(2))


def max_rel_err(values, refs) -> float:
    worst = 0.0
    for v, r in zip(values, refs, strict=True):
        if r < mpmath.mpf("1e-300"):  # below double precision's normal range: not representable anyway
            continue
        worst = max(worst, float(abs((mpmath.mpf(float(v)) - r) / r)))
    return worst


def bench_pvalues() -> None:
    rng = np.random.default_rng(3)
    size = 10**6
    t = rng.uniform(-40.0, 40.0, size)
    df = 10.0 ** rng.uniform(0.0, 4.0, size)
    per_million = {
        "exact (Student t, real nu)": best_time(lambda: pvalue_exact(t, df), 5),
        "gauss (erfc, eq. 5)": best_time(lambda: pvalue_gauss(t), 5),
        "as_erf (A&S, eq. 6)": best_time(lambda: pvalue_as_erf(t), 5),
        "two_sided 'gauss' (exact below nu 20)": best_time(lambda: two_sided_pvalue(t, df, "gauss"), 5),
    }

    grid_df = [1.0, 2.0, 3.5, 7.0, 19.5, 20.0, 50.0, 200.0, 1e3, 1e4]
    grid_t = [0.05, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 20.0, 30.0, 40.0]
    pts_t = np.array([x for _ in grid_df for x in grid_t])
    pts_df = np.array([d for d in grid_df for _ in grid_t])
    with mpmath.workdps(40):
        ref_student = [mp_student(a, b) for a, b in zip(pts_t, pts_df, strict=True)]
        ref_gauss = [mp_gauss(a) for a in pts_t]
    # Where the Gaussian forms are used (nu >= 20), in the range that decisions see (p >= 1e-4) and everywhere.
    used = pts_df >= 20.0
    large_p = np.array([r >= mpmath.mpf("1e-4") for r in ref_student])
    decisive = used & large_p

    def errors(values):
        own = max_rel_err(values, ref_gauss)
        return (
            own,
            max_rel_err(values[decisive], [r for r, k in zip(ref_student, decisive, strict=True) if k]),
            max_rel_err(values[used], [r for r, k in zip(ref_student, used, strict=True) if k]),
        )

    exact = pvalue_exact(pts_t, pts_df)
    both = two_sided_pvalue(pts_t, pts_df, "gauss")
    results = {
        "exact (Student t, real nu)": (
            max_rel_err(exact, ref_student),
            max_rel_err(exact[large_p], [r for r, k in zip(ref_student, large_p, strict=True) if k]),
            max_rel_err(exact, ref_student),
        ),
        "gauss (erfc, eq. 5)": errors(pvalue_gauss(pts_t)),
        "as_erf (A&S, eq. 6)": errors(pvalue_as_erf(pts_t)),
        "two_sided 'gauss' (exact below nu 20)": (
            "-",
            max_rel_err(both[decisive | ~used], [r for r, k in zip(ref_student, decisive | ~used, strict=True) if k]),
            max_rel_err(both, ref_student),
        ),
    }
    ramp = np.linspace(0.0, 40.0, 400001)
    as_abs = float(np.abs(pvalue_as_erf(ramp) - special.erfc(ramp / np.sqrt(2.0))).max())

    def fmt(x):
        return x if isinstance(x, str) else f"{x:.1e}"

    rows = [(name, f"{per_million[name] * 1e3:.1f}", *(fmt(x) for x in results[name])) for name in per_million]
    table(
        "(c) p-values: ms per million (t, nu) pairs; largest relative error against mpmath at 40 digits\n"
        f"    (references below 1e-300 skipped); grid: nu in {grid_df},\n    |t| in {grid_t}",
        ("", "ms / 1e6", "vs own formula", "vs Student t, p >= 1e-4", "vs Student t, all p"),
        rows,
    )
    print("  'vs own formula': exact against the Student-t p, gauss/as_erf against erfc(|t|/sqrt 2).")
    print(
        "  'vs Student t': gauss/as_erf where they are used (nu >= 20); exact and two_sided 'gauss' on the whole grid."
    )
    print(f"  A&S eq. 6: largest absolute error against erfc over |t| in [0, 40]: {as_abs:.2e} (bound 2.5e-5)")


def main(argv: list[str] | None = None) -> int:
    argparse.ArgumentParser(
        prog="python -m benchmarks.studies.core_speed", description=__doc__.splitlines()[0]
    ).parse_args(argv)
    bench_accumulation()
    bench_compare()
    bench_pvalues()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
