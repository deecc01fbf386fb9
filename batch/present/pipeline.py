"""A comparison's way to people, written once: its summary (`batch.summary`), the layers tested beside it, the
report (`batch.report`) and the lines the command line prints. `compare`, `selftest`, `check`, `demo`, the suites
and the Blender add-on all go through `present`; none of them summarises or reports a comparison itself.
"""

from __future__ import annotations

import os
from typing import Any

from .._siblings import welch_core as wc
from . import summary as summaries


def present(
    out_dir: str | os.PathLike,
    comparison: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    *,
    names: tuple[str | None, str | None] = (None, None),
    outcome: wc.Outcome | None = None,
    check: dict[str, Any] | None = None,
    layers: tuple[dict, dict] | None = None,
    previews=None,
    full_maps: bool = False,
    selftest: bool = True,
) -> dict[str, Any]:
    """Summarise `comparison` (its own outcome, or the given `outcome` of a check's last look with the check's
    record), test the `layers` both runs have (light components and light groups: the reference's and the test's
    by name), and write the report into `out_dir`. Returns report.json's content."""
    from .report import write_report

    summary = summaries.summarize(comparison, ref, test, *names, selftest=selftest, outcome=outcome, check=check)
    tested = summaries.layers_summary(comparison, ref, test, *layers, after_looks=check is not None) if layers else None
    if tested is not None:
        summary["layers"] = tested[0]
    significant = (outcome or comparison.outcome).significant
    layer_results = tested[1] if tested else None
    return write_report(out_dir, summary, comparison, ref, test, full_maps, previews, layer_results, significant)


def compare_files(ref_path: str, test_path: str, out_dir: str, *, alpha: float = 0.01, kind: str = "auto",
                  pvalue_method: str = "exact", tile: int | None = None, tolerance: float | None = None,
                  equivalence_tile: int | None = None, full_maps: bool = False) -> dict[str, Any]:  # fmt: skip
    """Load two statistics files, compare them and their layers, and report into `out_dir` (the `compare`
    command and the add-on's statistics files). The pixel sums are read only where full-resolution maps are
    asked for; the page needs the stored previews alone."""
    ref, test = (wc.load_stats(path, pixels=full_maps) for path in (ref_path, test_path))
    previews = None if full_maps else (wc.load_preview(ref_path), wc.load_preview(test_path))
    comparison = wc.compare(ref, test, alpha, kind, pvalue_method, tile, tolerance, equivalence_tile)
    layers = (wc.load_layers(ref_path, pixels=False), wc.load_layers(test_path, pixels=False))
    return present(out_dir, comparison, ref, test, layers=layers, previews=previews, full_maps=full_maps)


def lines(report: dict[str, Any], out_dir: str | os.PathLike) -> list[str]:
    """What the command line prints about a report: the verdict sentence, the design, notes, layers, the next
    step and where the report is."""
    out = [summaries.verdict_line(report)]
    out += [f"  {line}" for line in summaries.console_lines(report)]
    out.append(f"report: {os.path.join(os.fspath(out_dir), 'report.html')}")
    return out
