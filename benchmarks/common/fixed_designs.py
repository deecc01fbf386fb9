"""Every fixed design on the bias cases: `compare` at one tile size (or every scale) and a fixed number of passes
a side, Welch's and the paired test, and the two calibrated baselines (RMSE against a converged reference, the
largest tile difference), in trials drawn from the pools (`trials`). Chart 1 draws these trials; chart 5 measures
`check` against the best fixed design in hindsight (`best_fixed`) and chart 7 compares every scale at once with
each tile size, on chart 1's cases and a local bias (`local_results`). The trials are cached: once chart 1 has run,
the others read them back.

Seconds count as on chart 1: the median seconds of a pass of each side times the passes a side (for the RMSE
baseline the converged reference's whole render time plus the test's passes).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from . import plan, trials
from .cache import digest, memo_json, welch_digest
from .pools import load_or_render, say
from .trials import BASE_TILE, CALIBRATED_METHODS, METHODS, PAIRED, UNPAIRED

#: Detection share the "seconds to detect" figures refer to.
TARGET = 0.8


def _code() -> str:
    return f"{welch_digest()}-{trials.TRIALS_VERSION}"


# -- unbiased pairs ------------------------------------------------------------------------------------------


def null_results(b: plan.Budget, ref, converged, cache_dir: Path, label: str = "") -> dict:
    """A/A trials on one reference pool: verdict counts of the tool's unpaired tests per n, and the baselines'
    statistics per n (first half of the trials calibrates the threshold, the second half measures the rate)."""

    def compute():
        rng = np.random.default_rng(int(digest("null", ref.spec.key)[:8], 16))
        out = {"compare": {}, "rmse": {}, "tilediff16": {}}
        for n in b.n_grid:
            if 2 * n > ref.n:
                continue
            counts = {}  # method -> [biased, inconclusive]
            for _ in range(b.null_trials):
                verdicts = trials.compare_verdicts(ref, ref, trials.draw_unpaired(rng, ref.n, n), UNPAIRED)
                for m, v in verdicts.items():
                    counts.setdefault(m, [0, 0])
                    counts[m][0] += v == "biased"
                    counts[m][1] += v == "inconclusive"
            out["compare"][str(n)] = {"trials": b.null_trials, "counts": counts}
        ns = [n for n in b.n_grid if 2 * n <= ref.n]
        rmse, tdiff = [], []
        for _ in range(b.calibration_trials):
            rmse.append(trials.rmse_curve(ref, rng.permutation(ref.n), ns, converged.mean_image).tolist())
            perm = rng.permutation(ref.n)
            half = ref.n // 2
            tdiff.append(trials.tilediff_curve(ref, ref, perm[:half], perm[half:], ns).tolist())
        out["rmse"] = {str(n): [row[i] for row in rmse] for i, n in enumerate(ns)}
        out["tilediff16"] = {str(n): [row[i] for row in tdiff] for i, n in enumerate(ns)}
        return out

    key = digest(ref.spec.key, converged.spec.key, b.n_grid, b.null_trials, b.calibration_trials, _code())
    say(f"chart 1: unbiased pairs on {label or ref.spec.scene}")
    return memo_json(cache_dir, "null", key, compute)


def paired_null_results(b: plan.Budget, ref, other, cache_dir: Path) -> dict:
    """The paired tests on an unbiased pair with identical seeds (two sampling patterns of one scene)."""

    def compute():
        rng = np.random.default_rng(int(digest("paired-null", ref.spec.key)[:8], 16))
        out = {}
        for n in b.n_grid:
            if n > ref.n:
                continue
            counts = {}
            for _ in range(b.null_trials):
                verdicts = trials.compare_verdicts(ref, other, trials.draw_paired(rng, ref.n, n), PAIRED)
                for m, v in verdicts.items():
                    counts.setdefault(m, [0, 0])
                    counts[m][0] += v == "biased"
                    counts[m][1] += v == "inconclusive"
            out[str(n)] = {"trials": b.null_trials, "counts": counts}
        return out

    key = digest(ref.spec.key, other.spec.key, b.n_grid, b.null_trials, _code())
    return memo_json(cache_dir, "paired-null", key, compute)


def thresholds(null: dict) -> dict[str, dict[int, float]]:
    """Per baseline and n: the threshold from the calibration half of the unbiased trials."""
    return {
        m: {int(n): trials.calibrate(np.array(v[: len(v) // 2])) for n, v in null[m].items()}
        for m in CALIBRATED_METHODS
    }


def false_positive_rows(group: str, null: dict, paired: dict | None) -> list[dict]:
    rows = []
    for n, entry in null["compare"].items():
        for m, (k, inc) in entry["counts"].items():
            rows.append(_rate_row(group, m, int(n), k, entry["trials"], inc))
    limits = thresholds(null)
    for m in CALIBRATED_METHODS:
        for n, values in null[m].items():
            held_out = np.array(values[len(values) // 2 :])  # not used to set the threshold
            rows.append(_rate_row(group, m, int(n), int((held_out > limits[m][int(n)]).sum()), len(held_out), 0))
    for n, entry in (paired or {}).items():
        for m, (k, inc) in entry["counts"].items():
            rows.append(_rate_row(group, m, int(n), k, entry["trials"], inc))
    return rows


def _rate_row(group, method, n, k, total, inconclusive) -> dict:
    lo, hi = trials.wilson(k, total)
    return {
        "group": group, "method": method, "n": n, "trials": total, "biased": k, "rate": k / total,
        "lo": lo, "hi": hi, "inconclusive": inconclusive,
    }  # fmt: skip


# -- biased pairs --------------------------------------------------------------------------------------------


def case_results(b: plan.Budget, case: plan.Case, pools: dict, null: dict, cache_dir: Path) -> list[dict]:
    """Detection counts per method and n; a method stops once two consecutive n found every trial biased."""
    ref, test, conv = pools[case.ref.key], pools[case.test.key], pools[case.converged.key]
    limits = thresholds(null)

    def compute():
        rng = np.random.default_rng(int(digest("case", case.test.key)[:8], 16))
        rows, saturated = [], {m: 0 for m in METHODS}
        for n in b.n_grid:
            unpaired = [m for m in UNPAIRED if saturated[m] < 2 and 2 * n <= ref.n]
            paired = [m for m in PAIRED if saturated[m] < 2 and n <= ref.n]
            counts = {}
            for _ in range(b.trials):
                for methods, draw in ((unpaired, trials.draw_unpaired), (paired, trials.draw_paired)):
                    if not methods:
                        continue
                    for m, v in trials.compare_verdicts(ref, test, draw(rng, ref.n, n), methods).items():
                        counts.setdefault(m, [0, 0])
                        counts[m][0] += v == "biased"
                        counts[m][1] += v == "inconclusive"
            if str(n) in null["rmse"]:
                for m in CALIBRATED_METHODS:
                    counts[m] = [0, 0]
                for _ in range(b.trials):
                    r = trials.rmse_curve(test, rng.permutation(test.n)[:n], [n], conv.mean_image)[0]
                    perm = rng.permutation(ref.n)
                    half = ref.n // 2
                    d = trials.tilediff_curve(ref, test, perm[:half], perm[half:], [n])[0]
                    counts["rmse"][0] += r > limits["rmse"][n]
                    counts["tilediff16"][0] += d > limits["tilediff16"][n]
            for m, (k, inc) in counts.items():
                rows.append({"method": m, "n": n, "trials": b.trials, "biased": int(k), "inconclusive": int(inc)})
                saturated[m] = saturated[m] + 1 if k == b.trials else 0
            say(f"  {case.name}: n = {n}: " + ", ".join(f"{m} {k / b.trials:.2f}" for m, (k, _) in counts.items()))
        return rows

    key = digest(case.ref.key, case.test.key, case.converged.key, b.n_grid, b.trials, b.calibration_trials, _code())
    say(f"chart 1: case {case.name}")
    return memo_json(cache_dir, "case", key, compute)


def seconds(method: str, n: int, ref, test, conv) -> float:
    """Render seconds behind one trial of `method` with n passes a side."""
    if method == "rmse":
        return conv.total_seconds + n * test.seconds_per_pass
    return n * (ref.seconds_per_pass + test.seconds_per_pass)


def seconds_to_target(rows: list[dict]) -> tuple[float | None, float | None]:
    """Seconds and passes at which the detection rate first reaches TARGET (log-linear between grid points)."""
    prev = None
    for row in sorted(rows, key=lambda r: r["n"]):
        if row["rate"] >= TARGET:
            if prev is None or prev["rate"] >= TARGET:
                return row["seconds"], row["n"]
            f = (TARGET - prev["rate"]) / (row["rate"] - prev["rate"])
            s = np.exp(np.log(prev["seconds"]) + f * (np.log(row["seconds"]) - np.log(prev["seconds"])))
            n = np.exp(np.log(prev["n"]) + f * (np.log(row["n"]) - np.log(prev["n"])))
            return float(s), float(n)
        prev = row
    return None, None


def mean_change(ref, test) -> tuple[float, float, float]:
    """Relative change of the image mean (test / ref - 1), its standard error from the pass-to-pass spread, and
    the ratio of the per-pixel variances (test / ref, averaged over pixels): a bias can also change the noise."""
    r = np.asarray(ref.images, dtype=np.float64).mean(axis=(1, 2, 3))
    t = np.asarray(test.images, dtype=np.float64).mean(axis=(1, 2, 3))
    change = t.mean() / r.mean() - 1
    se = np.sqrt(r.var(ddof=1) / len(r) + t.var(ddof=1) / len(t)) / r.mean()
    ratio = np.var(test.images, axis=0).mean() / np.var(ref.images, axis=0).mean()
    return float(change), float(se), float(ratio)


# -- every case ----------------------------------------------------------------------------------------------


def compute(b: plan.Budget, cache_dir: Path) -> dict:
    """Render (or read) the pools and run (or read back) every trial: the cases, the pools, the detection rows,
    the false-positive rows and the seconds to 80 % per case and method. Charts 1, 5 and 7 call it (the trials
    come from the cache once one of them has run)."""
    cases = plan.cases(b)
    paired_ref, paired_other = plan.paired_null(b)
    specs = {}
    for c in cases:
        specs |= {c.ref.key: c.ref, c.test.key: c.test, c.converged.key: c.converged}
    specs[paired_other.key] = paired_other
    say(f"chart 1: {len(specs)} pools")
    pools = {key: load_or_render(spec, cache_dir) for key, spec in specs.items()}

    groups = {}  # reference pool key -> (group name, null results)
    fp_rows = []
    for c in cases:
        if c.ref.key in groups:
            continue
        name = c.group
        null = null_results(b, pools[c.ref.key], pools[c.converged.key], cache_dir, name)
        paired = None
        if c.ref.key == paired_ref.key:
            paired = paired_null_results(b, pools[paired_ref.key], pools[paired_other.key], cache_dir)
        groups[c.ref.key] = (name, null)
        fp_rows += false_positive_rows(name, null, paired)

    det_rows, summary = [], []
    for c in cases:
        ref, test, conv = pools[c.ref.key], pools[c.test.key], pools[c.converged.key]
        change, se, var_ratio = mean_change(ref, test)
        for row in case_results(b, c, pools, groups[c.ref.key][1], cache_dir):
            lo, hi = trials.wilson(row["biased"], row["trials"])
            det_rows.append(
                {"case": c.name, **row, "rate": row["biased"] / row["trials"], "lo": lo, "hi": hi,
                 "seconds": seconds(row["method"], row["n"], ref, test, conv)}
            )  # fmt: skip
        for m in METHODS:
            rows = [r for r in det_rows if r["case"] == c.name and r["method"] == m]
            if not rows:  # a tile larger than the image (quick run)
                continue
            s, n = seconds_to_target(rows)
            summary.append(
                {"case": c.name, "label": c.label, "mean_change": change, "mean_change_se": se,
                 "variance_ratio": var_ratio, "method": m, "seconds_to_80": s, "passes_to_80": n,
                 "converged_seconds": conv.total_seconds,
                 "seconds_per_pass_ref": ref.seconds_per_pass, "seconds_per_pass_test": test.seconds_per_pass}
            )  # fmt: skip
    return {"cases": cases, "pools": pools, "detection": det_rows, "false_positives": fp_rows, "summary": summary}


def best_fixed(summary: list[dict], case: str, methods) -> dict | None:
    """The fixed design chosen in hindsight: of `methods` (one tile size each), the one with the fewest seconds to
    80 % detection on `case`; None when none gets there."""
    found = [r for r in summary if r["case"] == case and r["method"] in methods and r["seconds_to_80"] is not None]
    return min(found, key=lambda r: r["seconds_to_80"]) if found else None


# -- the local bias of chart 7 -------------------------------------------------------------------------------


def local_results(b: plan.Budget, cache_dir: Path) -> dict:
    """Chart 1's trials (every `compare` method, no baselines) on the local bias, its detection rows, seconds to
    80 % per method and the relative change per tile."""
    case = plan.local_case(b)
    specs = {case.ref.key: case.ref, case.test.key: case.test, case.converged.key: case.converged}
    pools = {key: load_or_render(spec, cache_dir) for key, spec in specs.items()}
    ref, test, conv = pools[case.ref.key], pools[case.test.key], pools[case.converged.key]
    no_baselines = {"rmse": {}, "tilediff16": {}}
    rows = []
    for row in case_results(b, case, pools, no_baselines, cache_dir):
        lo, hi = trials.wilson(row["biased"], row["trials"])
        rows.append({"case": case.name, **row, "rate": row["biased"] / row["trials"], "lo": lo, "hi": hi,
                     "seconds": seconds(row["method"], row["n"], ref, test, conv)})  # fmt: skip
    change, se, var_ratio = mean_change(ref, test)
    summary = []
    for m in trials.COMPARE_METHODS:
        found = [r for r in rows if r["method"] == m]
        if not found:
            continue
        s, n = seconds_to_target(found)
        summary.append(
            {"case": case.name, "label": case.label, "mean_change": change, "mean_change_se": se,
             "variance_ratio": var_ratio, "method": m, "seconds_to_80": s, "passes_to_80": n,
             "converged_seconds": conv.total_seconds,
             "seconds_per_pass_ref": ref.seconds_per_pass, "seconds_per_pass_test": test.seconds_per_pass}
        )  # fmt: skip
    return {"case": case, "rows": rows, "summary": summary, "tiles": tile_changes(ref, test)}


def tile_changes(ref, test) -> dict:
    """The relative change of the tile means (test / ref - 1) at each tile size: the largest in magnitude over
    tile-channels, and how many 16² tiles change by more than 1 %."""
    out = {}
    size = ref.spec.resolution
    tile = BASE_TILE
    while tile <= size:
        r, t = ref.sums(tile).mean(axis=0), test.sums(tile).mean(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.where(r > 0, t / r - 1, np.nan)
        out[str(tile)] = {"largest": float(rel.flat[np.nanargmax(np.abs(rel))]),
                          "tiles_over_1pct": int((np.nanmax(np.abs(rel), axis=-1) > 0.01).sum()),
                          "tiles": int(rel.shape[0] * rel.shape[1])}  # fmt: skip
        tile *= 2
    return out
