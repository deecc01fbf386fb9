"""Simulated runs of ``python -m batch check`` on pools: the passes a side come in a random order of the pool's seeds,
and `welch_core.sequential_look` decides at every look of `welch_core.look_schedule`, as `batch.decide.check.Check` does
after each chunk (the fraction of a look is its passes over the budget; `biased` or `equivalent` stop the run; at the
budget it ends `inconclusive`, or `no_evidence` without a tolerance). Nothing renders: a run costs a few milliseconds a
look.

Paired runs take the same seeds on both sides (what `check` does on one build), unpaired runs take the reference's
passes from one half of the seeds and the test's from the other (two builds, or ``--unpaired``). The budget is the
pool: all its passes a side when paired, half of them when unpaired.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import welch_core as wc

from .cache import digest, memo_json, welch_digest
from .trials import ALPHA, BASE_TILE

#: Part of the cache key of simulated runs, with welch_core's source.
CHECKS_VERSION = 2

#: `check`'s defaults (batch.cli / batch.decide.check): alpha 1 %, tolerance 1 %, finest tile 16 px.
TOLERANCE = 0.01


def budget(pool, paired: bool) -> int:
    """The most passes a side a run can have from `pool`."""
    return pool.n if paired else pool.n // 2


def one_run(ref, test, ref_order, test_order, plan: wc.SequentialPlan, tile: int = BASE_TILE) -> dict:
    """One simulated `check`: the passes a side and the verdict where it stopped, and what the last look saw.
    With the plan's pixel-variance test, each look's statistics keep their pixel moments and paired runs get each
    pixel's differences over the look's seeds, as `check` folds them (`batch.jobs.pairs`)."""
    fractions, look, n = [], None, 0
    pixels = plan.pixel_variance != "off"
    for n in wc.look_schedule(plan.max_passes):
        fractions.append(min(n / plan.max_passes, 1.0))
        a, b = ref.stats(ref_order[:n], tile, pixels), test.stats(test_order[:n], tile, pixels)
        pairs = None
        if pixels and a.seeds == b.seeds:
            order = np.sort(ref_order[:n])  # the statistics' pixel moments are of the sorted positions as well
            pairs = wc.PixelMoments.of_passes(np.asarray(test.images[order], float) - ref.images[order])
        claim = look.outcome.target_tile if look is not None else None  # sized at an earlier look: kept
        look = wc.sequential_look(a, b, plan, fractions, pairs=pairs, claim_tile=claim)
        if look.verdict is not None:
            break
    verdict = look.outcome.verdict.label  # the last look is the final one: decided
    ruled_out = look.ruled_out if np.isfinite(look.ruled_out) else None
    return {"passes": n, "verdict": verdict, "ruled_out": ruled_out, "ruled_out_tile": look.ruled_out_tile,
            "uncovered": look.uncovered, "looks": len(fractions), "pixels": look.pixel_use.used}  # fmt: skip


def run_many(ref, test, paired: bool, runs: int, plan: wc.SequentialPlan, rng, tile: int = BASE_TILE) -> list[dict]:
    """`runs` simulated checks of `plan`, each in its own random order of the pool's seeds (see `one_run`)."""
    out = []
    for _ in range(runs):
        perm = rng.permutation(ref.n)
        ref_order, test_order = (perm, perm) if paired else (perm[: ref.n // 2], perm[ref.n // 2 :])
        out.append(one_run(ref, test, ref_order, test_order, plan, tile))
    return out


def simulate(
    ref,
    test,
    paired: bool,
    runs: int,
    cache_dir: Path,
    max_passes: int | None = None,
    tolerance: float | None = TOLERANCE,
    tile: int = BASE_TILE,
    df: str = "n-1",
) -> list[dict]:
    """`runs` simulated checks of `test` against `ref` (cached): one dict per run (see `one_run`). `df` only names
    the degrees of freedom in the cache key: the caller patches `welch_core.looks` for a what-if."""
    max_passes = max_passes or budget(ref, paired)
    if max_passes > budget(ref, paired):
        raise ValueError(f"a budget of {max_passes} passes a side needs a larger pool than {ref.n}")

    def compute():
        rng = np.random.default_rng(int(key[:8], 16))
        plan = wc.SequentialPlan(max_passes=max_passes, alpha=ALPHA, tolerance=tolerance)
        return run_many(ref, test, paired, runs, plan, rng, tile)

    key = digest("check", ref.spec.key, test.spec.key, paired, runs, max_passes, tolerance, tile, df,
                 welch_digest(), CHECKS_VERSION)  # fmt: skip
    return memo_json(cache_dir, "check", key, compute)


def percentile(values, q: float) -> float | None:
    """The q-quantile of `values` (inf for runs that never got there); None when it is inf."""
    if not len(values):
        return None
    v = float(np.quantile(np.asarray(values, dtype=float), q, method="higher"))
    return v if np.isfinite(v) else None


def tally(runs: list[dict], seconds_per_pass: float) -> dict:
    """Outcome counts and the seconds to a decision (any verdict) and to `biased` (runs that did not end
    `biased` count as never): median, 80th and 90th percentile. Seconds are passes a side times
    `seconds_per_pass` (both sides' median pass seconds added)."""
    total = len(runs)
    counts = {v: sum(r["verdict"] == v for r in runs) for v in ("biased", "equivalent", "inconclusive", "no_evidence")}
    decided = [r["passes"] * seconds_per_pass for r in runs]
    to_biased = [r["passes"] * seconds_per_pass if r["verdict"] == "biased" else np.inf for r in runs]
    out = {"runs": total, **counts}
    for name, values in (("decision", decided), ("biased", to_biased)):
        for q, tag in ((0.5, "median"), (0.8, "p80"), (0.9, "p90")):
            s = percentile(values, q)
            out[f"{name}_{tag}_s"] = s
            out[f"{name}_{tag}_passes"] = None if s is None else round(s / seconds_per_pass)
    return out
