"""Does each case of the built-in suite do its job at its size and budget? For every case: the current build
against the shipped reference (an A/A run on the same build: it must not say `biased`), and the case's `planted`
change applied to the test side (it must say `biased` within the budget).

Run from the repository root::

    python -m benchmarks.studies.suite_cases [--cases glossy_rough volume ...] [--repeats 1] [--out /tmp/suite-cases]

Prints one row per case and repeat (verdicts, passes, render seconds) and writes ``suite_cases.csv`` into
``--out``; the figures go into docs/suite.md.
"""

from __future__ import annotations

import argparse
import csv
import shutil
import sys
import tempfile
from pathlib import Path

from batch.decide import suite as suites
from batch.present.progress import Progress


def run_case(suite, case, refs: Path, out: Path, planted: bool, repeat: int) -> suites.Outcome:
    overrides = (case.planted,) if planted else ()
    folder = out / f"{'planted' if planted else 'same'}-{repeat}"
    shutil.rmtree(folder / case.name, ignore_errors=True)
    [outcome] = suites.run_suite(
        suite, [case], refs, folder, lambda n: Progress(n, live=False, brief=True),
        overrides=overrides, say=lambda line: None, seed_offset=repeat * 10_000,
    )  # fmt: skip
    return outcome


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.studies.suite_cases", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--cases", nargs="+", metavar="NAME", help="some cases (default: all)")
    parser.add_argument("--suite", default="builtin", help="another suite file (its cases need `planted`)")
    parser.add_argument("--refs", type=Path, help="its references (default: the built-in suite's)")
    parser.add_argument("--repeats", type=int, default=1, help="A/A and planted runs per case (new seeds each)")
    parser.add_argument("--out", type=Path, default=None, help="folder for the runs and the CSV (default: temporary)")
    args = parser.parse_args(argv)
    suite = suites.load_suite(args.suite)
    refs = args.refs or suites.BUILTIN_REFS
    cases = suite.select(args.cases)
    out = args.out or Path(tempfile.mkdtemp(prefix="suite-cases-"))
    rows = []
    print(f"{'case':<16} {'repeat':>6}  {'A/A verdict':<14} {'passes':>6} {'s':>5}  {'planted verdict':<15} "
          f"{'passes':>6} {'s':>5}")  # fmt: skip
    for case in cases:
        for repeat in range(args.repeats):
            same = run_case(suite, case, refs, out, planted=False, repeat=repeat)
            if case.planted is None:  # a known difference (expect = "biased"): its A/A run is the test itself
                changed = same
            else:
                changed = run_case(suite, case, refs, out, planted=True, repeat=repeat)
            rows.append({
                "case": case.name, "repeat": repeat, "aa_verdict": same.verdict or same.status,
                "aa_passes": same.passes, "aa_seconds": round(same.seconds, 2),
                "planted_verdict": changed.verdict or changed.status, "planted_passes": changed.passes,
                "planted_seconds": round(changed.seconds, 2), "planted": case.planted,
            })  # fmt: skip
            r = rows[-1]
            line = f"{case.name:<16} {repeat:>6}  {r['aa_verdict']:<14} {r['aa_passes']:>6} {r['aa_seconds']:>5}  "
            print(line + f"{r['planted_verdict']:<15} {r['planted_passes']:>6} {r['planted_seconds']:>5}", flush=True)
    with open(out / "suite_cases.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"csv: {out / 'suite_cases.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
