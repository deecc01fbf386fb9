"""A comparison's way to people, written once: its summary (`batch.summary`), the layers tested beside it, the
report (`batch.report`) and the lines the command line prints. `compare`, `selftest`, `check`, `demo`, the suites
and the Blender add-on all go through `assess` (and `present`, which also writes the report); none of them
summarises, reports or decides a comparison itself.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from typing import Any

from .._siblings import welch_core as wc
from ..jobs.lobes import COMPONENTS
from ..jobs.options import default
from . import summary as summaries


@dataclass(frozen=True)
class Assessment:
    """A comparison ready for people, nothing left to decide: report.json's content without its file list (the
    verdict is `outcome`'s), the comparison whose maps are drawn, and each layer's comparison at the layers'
    alpha (the rows of ``summary["layers"]``)."""

    summary: dict[str, Any]
    comparison: wc.Comparison
    outcome: wc.Outcome
    layers: dict[str, wc.Comparison]


def assess(
    comparison: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    *,
    names: tuple[str | None, str | None] = (None, None),
    outcome: wc.Outcome | None = None,
    check: dict[str, Any] | None = None,
    layers: tuple[dict, dict] | None = None,
    selftest: bool = True,
) -> Assessment:
    """Summarise `comparison` (its own outcome, or the given `outcome` of a check's last look with the check's
    record), with the reference tested against itself (`selftest`), and test the `layers` both runs have (light
    components and light groups: the reference's and the test's by name). Every number is welch_core's."""
    outcome = outcome or comparison.outcome
    own = wc.selftest(ref, outcome.alpha) if selftest else None
    summary = summaries.summarize(comparison, ref, test, *names, selftest=own, outcome=outcome, check=check)
    family = wc.compare_layers(comparison, ref, test, *layers, COMPONENTS, check is not None) if layers else None
    if family is not None:
        summary["layers"] = summaries.layers_summary(family)
    return Assessment(summary, comparison, outcome, family.comparisons if family else {})


def write(out_dir: str | os.PathLike, assessment: Assessment, ref, test, previews=None, full_maps: bool = False):
    """Write the report of `assessment` into `out_dir`; returns report.json's content."""
    from .report import write_report

    a = assessment
    return write_report(out_dir, a.summary, a.comparison, ref, test, full_maps, previews, a.layers,
                        a.outcome.significant)  # fmt: skip


def present(
    out_dir: str | os.PathLike,
    comparison: wc.Comparison,
    ref: wc.TileStats,
    test: wc.TileStats,
    *,
    previews=None,
    full_maps: bool = False,
    **assessing,
) -> dict[str, Any]:
    """`assess` (with its keyword options `assessing`: names, outcome, check, layers, selftest) and `write` in one:
    the report of `comparison` in `out_dir`. Returns report.json's content."""
    return write(out_dir, assess(comparison, ref, test, **assessing), ref, test, previews, full_maps)


def _load(ref_path: str, test_path: str, pixels: bool, moments: bool = True, previews: bool = False):
    """Both statistics files (their pixel sums and pixel moments where asked for), both files' layers and, where
    asked for, their previews; the two files read at once (reading and checking arrays releases the GIL)."""

    def read(path: str):
        stats = wc.load_stats(path, pixels=pixels, moments=moments)
        return stats, wc.load_layers(path, pixels=False), wc.load_preview(path) if previews else None

    (ref, ref_layers, ref_preview), (test, test_layers, test_preview) = wc.parallel.at_once(
        functools.partial(read, ref_path), functools.partial(read, test_path)
    )
    return ref, test, (ref_layers, test_layers), (ref_preview, test_preview) if previews else None


def compare_files(ref_path: str, test_path: str, out_dir: str, *, alpha: float = default("alpha", "compare"),
                  kind: str = "auto", pvalue_method: str = "exact", tile: int | None = None,
                  tolerance: float | None = None, equivalence_tile: int | None = None,
                  pixel_variance: str = default("pixel_variance", "compare"),
                  full_maps: bool = False) -> dict[str, Any]:  # fmt: skip
    """Load two statistics files, compare them and their layers, and report into `out_dir` (the `compare`
    command). The pixel sums are read only where full-resolution maps are asked for; the page needs the stored
    previews alone."""
    ref, test, layers, previews = _load(ref_path, test_path, full_maps, pixel_variance != "off", not full_maps)
    comparison = wc.compare(ref, test, alpha, kind, pvalue_method, tile, tolerance, equivalence_tile, pixel_variance)
    return present(out_dir, comparison, ref, test, layers=layers, previews=previews, full_maps=full_maps)


def assess_files(ref_path: str, test_path: str, alpha: float) -> tuple[Assessment, wc.TileStats, wc.TileStats]:
    """Load two statistics files with their pixel sums (a map over the mean render) and assess them and their
    layers as `compare` does, the sides named by their paths, writing nothing (the Blender add-on's statistics
    files)."""
    ref, test, layers, _ = _load(ref_path, test_path, True)
    comparison = wc.compare(ref, test, alpha, pixel_variance=default("pixel_variance", "check"))
    return assess(comparison, ref, test, names=(ref_path, test_path), layers=layers), ref, test


def lines(report: dict[str, Any], out_dir: str | os.PathLike) -> list[str]:
    """What the command line prints about a report: the verdict sentence, the design, notes, layers, the next
    step and where the report is."""
    out = [summaries.verdict_line(report)]
    out += [f"  {line}" for line in summaries.console_lines(report)]
    out.append(f"report: {os.path.join(os.fspath(out_dir), 'report.html')}")
    return out
