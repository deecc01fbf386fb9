"""Regenerate the benchmark charts, CSVs and README::

    python -m benchmarks                 # everything into docs/benchmarks/ (pools cached in benchmarks/cache/)
    python -m benchmarks --quick --out /tmp/bench    # tiny pools and few trials: checks the pipeline, not the figures
    python -m benchmarks --charts 2 4    # some charts only (the others keep their last figures)

Charts: 1 detection rate against render time, 2 p-value methods, 3 stability on unbiased pairs, 4 cost, 5 render
seconds to a decision (`check` against the best fixed design), 6 A/A runs of `check`, 7 multi-scale tiles against
fixed tile sizes, 8 passes to `equivalent` at each scale against a known-variance oracle. ``--quick`` alone runs
charts 1-4 (tests/benchmarks/test_pipeline.py counts their four PNGs);
``--quick --charts 5 6 7 8`` checks the others (tests/benchmarks/test_decision.py). The charts are the modules of
``benchmarks.charts``; the studies beside them are commands of their own (``python -m benchmarks.studies.<name>``,
listed by ``--help``).
"""

from __future__ import annotations

import argparse
import json
import os
import pkgutil
import platform
import time
from importlib import metadata
from pathlib import Path

from . import studies
from .charts import aa, cost, decision, detection, equivalence, pvalues, scales, stability
from .common import plan, readme
from .common.cache import DEFAULT_DIR, REPO, welch_digest
from .common.pools import RENDERED, say

CHARTS = {"1": detection, "2": pvalues, "3": stability, "4": cost, "5": decision, "6": aa, "7": scales,
          "8": equivalence}  # fmt: skip
#: Each chart's part of the README, in the order of the charts.
SECTIONS = {f"chart{number}": chart.section for number, chart in CHARTS.items()}
#: What ``--quick`` runs without ``--charts``.
QUICK_CHARTS = ("1", "2", "3", "4")


def machine() -> dict:
    """What the figures were measured on."""
    model = ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {name: metadata.version(name) for name in ("bpy", "numpy", "scipy", "matplotlib")}
    return {"cores": os.cpu_count(), "cpu": model, "gpu": "none (Cycles on CPU)", "python": platform.python_version(),
            **versions}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    names = ", ".join(m.name for m in pkgutil.iter_modules(studies.__path__))
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks",
        description=__doc__.splitlines()[0],
        epilog="Charts (the modules of benchmarks/charts/): "
        + ", ".join(f"{number} {chart.__name__.rpartition('.')[2]}" for number, chart in CHARTS.items())
        + f". Studies beside the charts, each its own command: python -m benchmarks.studies.NAME [--help], NAME one "
        f"of {names} (see benchmarks/studies/__init__.py).",
    )
    parser.add_argument("--quick", action="store_true", help="tiny pools and few trials (CI)")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "benchmarks", help="output folder")
    parser.add_argument("--cache", type=Path, default=DEFAULT_DIR, help="pool and trial cache folder")
    parser.add_argument(
        "--charts", nargs="+", choices=sorted(CHARTS), help="charts to run (default: all; with --quick: 1-4)"
    )
    args = parser.parse_args(argv)
    if args.charts is None:
        args.charts = list(QUICK_CHARTS) if args.quick else sorted(CHARTS)
    budget = plan.QUICK if args.quick else plan.FULL
    welch_digest()  # the code of this run, fixed now (see `cache.welch_digest`)
    args.out.mkdir(parents=True, exist_ok=True)
    args.cache.mkdir(parents=True, exist_ok=True)
    figures_path = args.out / "figures.json"
    figures = json.loads(figures_path.read_text()) if figures_path.exists() else {}
    if figures.get("quick") != args.quick:
        figures = {}  # never mix quick and full figures
    figures |= {"quick": args.quick, "machine": machine(), "budget": budget.__dict__}
    start = time.perf_counter()
    for chart in args.charts:
        t0 = time.perf_counter()
        say(f"== chart {chart} ==")
        figures[f"chart{chart}"] = CHARTS[chart].run(budget, args.cache, args.out)
        figures[f"chart{chart}"]["seconds"] = time.perf_counter() - t0
        say(
            f"== chart {chart} done in {time.perf_counter() - t0:.0f} s: {', '.join(figures[f'chart{chart}']['files'])}"
        )
    notes = {k: v for k, v in figures.get("notes", {}).items() if k not in args.charts}  # a re-run chart's note goes
    figures["notes"] = notes  # chart -> a sentence about where its figures come from (set by hand, see readme)
    if set(args.charts) == set(CHARTS) or "command" not in figures:  # a run of some charts keeps the full run's record
        figures["last_run_seconds"] = time.perf_counter() - start
        figures["pools_rendered"] = len(set(RENDERED))
        figures["command"] = "python -m benchmarks" + (" --quick" if args.quick else "")
    figures_path.write_text(json.dumps(figures, indent=1, default=float))
    readme.write(args.out, figures, SECTIONS)
    say(f"done in {time.perf_counter() - start:.0f} s; figures in {args.out}")
    for line in readme.headlines(figures):
        say("  " + line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
