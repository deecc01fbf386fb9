"""Borrowing strength across tiles for the variance at small n: moderated variances (limma's empirical Bayes)
against the t-tests `check` uses, on the rendered pools — power on the bias cases, false positives on the A/A pairs.

    python -m benchmarks.studies.moderated           # pools in benchmarks/cache/, writes docs/benchmarks/moderated.csv
    python -m benchmarks.studies.moderated --quick --out /tmp/moderated  # the quick pools of the sparse study

At n passes a side a tile-channel's variance has n - 1 degrees of freedom, and at n = 2 to 4 the critical |t| of a
Bonferroni level is in the hundreds to millions. limma (Smyth 2004) treats every tile-channel's variance as drawn
from one scaled inverse chi-square prior with d0 degrees of freedom, fitted to all of them (here with a trend in
the log tile mean, limma-trend: bright tiles are noisier), and tests each with the posterior variance
``(d0 s0^2 + d s^2) / (d0 + d)`` and ``d0 + d`` degrees of freedom: exact when the prior holds. Both are run as a
fixed design at alpha 0.01, one tile size (16²), Bonferroni over the tile-channels, on the same draws:

* "t": the tests of `check` — Welch's t with the conservative n - 1 degrees of freedom (unpaired), the paired
  t-test (paired, n - 1);
* "moderated": the same statistics with each side's (or the differences') variances moderated, d0 + n - 1 degrees
  of freedom.

Rows: per pair (the bias cases of chart 5 and the A/A pairs of chart 6), test and n, the share of trials that say
`biased` (power, or the false-positive rate on an A/A pair, which must stay at most alpha) and the median d0.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import optimize, special, stats

from ..common import plan
from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import load_or_render, say
from ..common.trials import ALPHA, BASE_TILE, draw_paired, draw_unpaired

FULL = {"n": (2, 3, 4, 6, 8), "trials": 300, "plan": plan.FULL, "sparse_pool": plan.SPARSE_POOL}
QUICK = {"n": (2, 4), "trials": 5, "plan": None, "sparse_pool": plan.SPARSE_QUICK_POOL}


def _trigamma_inverse(value: float) -> float:
    """The y with trigamma(y) = value (trigamma falls from inf at 0 to 0 at inf)."""
    return optimize.brentq(lambda y: special.polygamma(1, y) - value, 1e-8, 1e8, xtol=1e-12)


def prior(variance: np.ndarray, mean: np.ndarray, d: int) -> tuple[float, np.ndarray]:
    """limma-trend's prior for sample variances with `d` degrees of freedom (flat arrays): d0 and s0^2 per entry,
    from the moments of log s^2 with a linear trend in log |mean| (limma's fitFDist with a covariate)."""
    usable = (variance > 0) & (np.abs(mean) > 0)
    if usable.sum() < 3:
        return 0.0, np.zeros_like(variance)
    x = np.log(np.abs(mean))
    e = np.log(variance[usable]) - special.digamma(d / 2) + np.log(d / 2)
    design = np.column_stack([np.ones(usable.sum()), x[usable]])
    coef, *_ = np.linalg.lstsq(design, e, rcond=None)
    residual = e - design @ coef
    excess = residual.var(ddof=2) - special.polygamma(1, d / 2)
    d0 = 2 * _trigamma_inverse(excess) if excess > 0 else np.inf
    fitted = coef[0] + coef[1] * np.where(np.abs(mean) > 0, x, np.median(x[usable]))
    shift = special.digamma(d0 / 2) - np.log(d0 / 2) if np.isfinite(d0) else 0.0
    return float(d0), np.exp(fitted + shift)


def moderate(variance: np.ndarray, mean: np.ndarray, d: int) -> tuple[np.ndarray, float]:
    """Posterior variances and d0 (inf: every variance is the prior's)."""
    d0, s0 = prior(variance, mean, d)
    if not np.isfinite(d0):
        return s0, d0
    return (d0 * s0 + d * variance) / (d0 + d), d0


def verdicts(ref_sums: np.ndarray, test_sums: np.ndarray, paired: bool) -> tuple[bool, bool, float]:
    """`biased` by the t-tests of `check` and by the moderated ones (fixed design, Bonferroni), and d0."""
    n = len(ref_sums)
    r, t = ref_sums.reshape(n, -1), test_sums.reshape(n, -1)
    level = ALPHA / r.shape[1]
    diff = t.mean(axis=0) - r.mean(axis=0)
    if paired:
        d = t - r
        var = d.var(axis=0, ddof=1)
        mod, d0 = moderate(var, r.mean(axis=0), n - 1)
        se, se_mod = np.sqrt(var / n), np.sqrt(mod / n)
    else:
        var_r, var_t = r.var(axis=0, ddof=1), t.var(axis=0, ddof=1)
        mod_r, d0_r = moderate(var_r, r.mean(axis=0), n - 1)
        mod_t, d0_t = moderate(var_t, t.mean(axis=0), n - 1)
        d0 = min(d0_r, d0_t)
        se, se_mod = np.sqrt((var_r + var_t) / n), np.sqrt((mod_r + mod_t) / n)
    with np.errstate(divide="ignore", invalid="ignore"):
        p = 2 * stats.t.sf(np.abs(diff / se), n - 1)
        z = np.abs(diff / se_mod)
        p_mod = 2 * (stats.t.sf(z, n - 1 + d0) if np.isfinite(d0) else stats.norm.sf(z))
    tested = (se > 0) & (se_mod > 0)
    return bool(np.any(p[tested] <= level)), bool(np.any(p_mod[tested] <= level)), d0


def pairs(budget: dict, cache: Path) -> list[dict]:
    """The bias cases and the A/A pairs: name, kind ('bias' or 'A/A'), the pools, the tests to run."""
    out = []
    if budget["plan"] is not None:
        for case in [*plan.cases(budget["plan"]), plan.local_case(budget["plan"])]:
            out.append({"name": case.name, "kind": "bias", "ref": case.ref, "test": case.test, "tests": (True, False)})
        for pair in plan.aa_pairs(budget["plan"]):
            out.append({"name": pair["name"], "kind": "A/A", "ref": pair["ref"], "test": pair["test"],
                        "tests": (pair["paired"],)})  # fmt: skip
    for scene, change, _label in plan.SPARSE_CASES[:2]:
        specs = plan.sparse_pools(scene, change, budget["sparse_pool"])
        out.append({"name": scene, "kind": "bias", "ref": specs[0], "test": specs[1], "tests": (True, False)})
        out.append({"name": f"{scene} A/A", "kind": "A/A", "ref": specs[0], "test": specs[0], "tests": (False,)})
    return out


def measure(budget: dict, cache: Path) -> list[dict]:
    rows = []
    for pair in pairs(budget, cache):
        ref, test = load_or_render(pair["ref"], cache), load_or_render(pair["test"], cache)
        ref_sums, test_sums = ref.sums(BASE_TILE), test.sums(BASE_TILE)
        for paired in pair["tests"]:
            for n in budget["n"]:
                rng = np.random.default_rng([n, paired, sum(map(ord, pair["name"]))])
                found = []
                for _ in range(budget["trials"]):
                    draw = (draw_paired if paired else draw_unpaired)(rng, ref.n, n)
                    found.append(verdicts(ref_sums[draw.ref], test_sums[draw.test], paired))
                plain, mod, d0 = (np.array(v, dtype=float) for v in zip(*found, strict=True))
                rows.append({"pair": pair["name"], "kind": pair["kind"], "test": "paired" if paired else "unpaired",
                             "n": n, "trials": len(found), "t_biased": plain.mean(), "moderated_biased": mod.mean(),
                             "median_d0": float(np.median(d0))})  # fmt: skip
                say(f"  {pair['name']} {rows[-1]['test']} n={n}: biased t {plain.mean():.1%}, moderated "
                    f"{mod.mean():.1%} (median d0 {np.median(d0):.3g})")  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("moderated", __doc__, "the quick pools of benchmarks.studies.sparse, few trials", argv)
    rows = measure(QUICK if args.quick else FULL, args.cache)
    write_csv(args.out / "moderated.csv", rows)
    say(f"wrote {args.out / 'moderated.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
