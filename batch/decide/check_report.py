"""The report of a check's final look: its record and the map of its final passes, written into its folder, as
`run_check` and the Blender add-on end a check.

Nothing here imports bpy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._siblings import welch_core as wc

if TYPE_CHECKING:
    from .check import Check
    from .check_job import CheckJob


def report_check(check: Check, look: wc.Look, ref: wc.TileStats, test: wc.TileStats):
    """Write the report of a check's final look into its folder: (report.json's content, its
    `batch.present.pipeline.Assessment`: the comparison of the final passes that the map shows, the layers').
    `run_check` and the Blender add-on both end a check here."""
    from ..present.pipeline import assess, write
    from ..present.summary import check_record

    job = check.job
    layers = (wc.load_layers(job.reference.out, pixels=False), wc.load_layers(job.test.out, pixels=False))
    early = (check.plan.early, wc.looks.EARLY_PASSES)
    durations = {"wall": check.wall_seconds, "sides": check.side_seconds}
    record = check_record(job, check.looks, check.plan.max_passes, look, early, check.ended_pass, durations)
    comparison = look_comparison(job, ref, test, check.pixel_pairs, check.plan.pixel_variance)
    assessment = assess(comparison, ref, test, outcome=look.outcome, check=record, layers=layers)
    return write(job.out, assessment, ref, test), assessment


def look_comparison(job: CheckJob, ref, test, pairs=None, pixel_variance: str | None = None) -> wc.Comparison:
    """The fixed-design comparison of a look's passes (`pairs`: their pixels' paired differences, where kept;
    `pixel_variance`: the plan's, default the job's): what its map draws (descriptive; the look's own outcome is
    the verdict)."""
    pixels = pixel_variance or job.pixel_variance
    return wc.compare(ref, test, job.alpha, tolerance=job.tolerance, pixel_variance=pixels, pairs=pairs)
