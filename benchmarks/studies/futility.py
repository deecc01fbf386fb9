"""The futility stop of `equivalent`, on rendered unbiased pairs: passes and seconds it saves, the verdicts it gives
away, and how often the tile size it recommends reaches `equivalent`.

    python -m benchmarks.studies.futility            # pools in benchmarks/cache/, writes docs/benchmarks/futility.csv
    python -m benchmarks.studies.futility --quick --out /tmp/futility    # small pools and few runs: the pipeline

A/A pools of built-in scenes at 64x64, 1 spp a pass; each run is `check` simulated on them
(`welch_core.sequential_look` at every look, unpaired, disjoint halves of a random order of the pool's seeds,
tolerance 1 %, 16-px tiles, budget 256 passes a side, 200 on the textured scene's smaller pool). Each run is made with
the futility stop and without it (``SequentialPlan(futility=False)``, what ``--no-futility`` runs) on the same
passes; a run stopped for futility is made again with `--equivalence-tile` at the finest size its outcome names as
within the budget. Seconds are passes a side times both sides' median pass render seconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

import welch_core as wc

from ..common.cache import study_arguments
from ..common.plotting import write_csv
from ..common.pools import PoolSpec, load_or_render, say

TILE, RESOLUTION, TOLERANCE, ALPHA = 16, 64, 0.01, 0.01
SCENES = (("corner", "diffuse corner", 1000), ("glossy", "glossy room", 1000),
          ("corner_glass", "glass caustic", 1000), ("textured", "textured", 400))  # fmt: skip
#: Real biases that `check` finds late in its budget: what the futility stop gives away (400-pass pools).
DETECTION = (("corner_glass", "cycles.sample_clamp_indirect=20", "caustic, indirect clamp 20"),
             ("textured", "cycles.blur_glossy=1.0", "textured, Filter Glossy 1.0"))  # fmt: skip
FULL = {"runs": 60, "budget": 256, "detection_runs": 30, "detection_pool": 400}
QUICK = {"runs": 2, "budget": 20, "pool": 48, "detection_runs": 2, "detection_pool": 40}


def one_check(
    pool, ref_order, test_order, budget: int, claim: int | None = None, test_pool=None, futility: bool = True
) -> wc.Outcome:
    """`check` simulated on the passes `ref_order` of `pool` and `test_order` of `test_pool` (default `pool`),
    with or without the futility stop."""
    plan = wc.SequentialPlan(
        max_passes=budget, alpha=ALPHA, tolerance=TOLERANCE, equivalence_tile=claim, futility=futility
    )
    fractions, test_pool = [], test_pool or pool
    for n in wc.look_schedule(budget):
        fractions.append(n / budget)
        ref, test = pool.stats(ref_order[:n], TILE), test_pool.stats(test_order[:n], TILE)
        look = wc.sequential_look(ref, test, plan, fractions)
        if look.verdict is not None:
            break
    return look.outcome


def measure(budget: dict, cache: Path) -> list[dict]:
    rows = []
    for number, (scene, label, size) in enumerate(SCENES):
        pool = load_or_render(PoolSpec(scene, (), RESOLUTION, passes=budget.get("pool", size)), cache, label)
        most = min(budget["budget"], pool.n // 2)
        seconds = 2 * pool.seconds_per_pass
        rng = np.random.default_rng([30, number])
        for run in range(budget["runs"]):
            order = rng.permutation(pool.n)
            ref_order, test_order = order[: pool.n // 2], order[pool.n // 2 :]
            stopped = one_check(pool, ref_order, test_order, most)
            full = one_check(pool, ref_order, test_order, most, futility=False)
            recommended = None
            if stopped.reason == "futile":
                within = [x.tile for x in stopped.scales if x.projected is not None and x.projected <= most]
                if within:
                    recommended = one_check(pool, ref_order, test_order, most, within[0])
            row = {
                "scene": label,
                "run": run,
                "budget": most,
                "verdict": stopped.verdict.label,
                "reason": stopped.reason,
                "passes": min(stopped.n_ref, stopped.n_test),
                "seconds": round(min(stopped.n_ref, stopped.n_test) * seconds, 3),
                "without_futility": full.verdict.label,
                "without_futility_passes": min(full.n_ref, full.n_test),
                "without_futility_seconds": round(min(full.n_ref, full.n_test) * seconds, 3),
                "recommended_tile": None if recommended is None else recommended.claim_tile,
                "recommended_verdict": None if recommended is None else recommended.verdict.label,
                "recommended_passes": None if recommended is None else min(recommended.n_ref, recommended.n_test),
            }
            rows.append(row)
        mine = [r for r in rows if r["scene"] == label]
        futile = [r for r in mine if r["reason"] == "futile"]
        lost = [r for r in futile if r["without_futility"] in ("equivalent", "biased")]
        recommended = [r for r in futile if r["recommended_verdict"] is not None]
        say(
            f"  {label}: futile {len(futile)}/{len(mine)}; passes {sum(r['passes'] for r in mine)} against "
            f"{sum(r['without_futility_passes'] for r in mine)} without the stop; verdicts given away {len(lost)}; "
            f"recommended size equivalent {sum(r['recommended_verdict'] == 'equivalent' for r in recommended)}"
            f"/{len(recommended)}"
        )
    return rows + detection(budget, cache)


def detection(budget: dict, cache: Path) -> list[dict]:
    """Real biases, paired (the same seeds, budget the pool) and unpaired (disjoint halves): `check` with and
    without the futility stop on the same passes."""
    rows = []
    for number, (scene, change, label) in enumerate(DETECTION):
        size = budget["detection_pool"]
        reference = load_or_render(PoolSpec(scene, (), RESOLUTION, passes=size), cache, scene)
        changed = load_or_render(PoolSpec(scene, (change,), RESOLUTION, passes=size), cache, label)
        for paired in (True, False):
            rng = np.random.default_rng([40, number, paired])
            most = size if paired else size // 2
            found = {"with": [], "without": []}
            for _ in range(budget["detection_runs"]):
                order = rng.permutation(size)
                ref_order, test_order = (order, order) if paired else (order[: size // 2], order[size // 2 :])
                found["with"].append(one_check(reference, ref_order, test_order, most, test_pool=changed))
                found["without"].append(
                    one_check(reference, ref_order, test_order, most, test_pool=changed, futility=False)
                )
            for method, outcomes in found.items():
                biased = [min(o.n_ref, o.n_test) for o in outcomes if o.verdict == "biased"]
                rows.append({"scene": label, "run": "paired" if paired else "unpaired", "budget": most,
                             "verdict": f"biased {len(biased)}/{len(outcomes)}", "reason": f"{method} the stop",
                             "passes": float(np.median(biased)) if biased else None})  # fmt: skip
                say(f"  {label}, {rows[-1]['run']}, {method} the futility stop: {rows[-1]['verdict']}, median passes "
                    f"{rows[-1]['passes']}")  # fmt: skip
    return rows


def main(argv: list[str] | None = None) -> int:
    args = study_arguments("futility", __doc__, "small pools and few runs (checks the pipeline)", argv)
    rows = measure(QUICK if args.quick else FULL, args.cache)
    write_csv(args.out / "futility.csv", rows)
    say(f"wrote {args.out / 'futility.csv'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
