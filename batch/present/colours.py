"""The colour of each status (`batch.jobs.protocol.CaseStatus`) on every page: report.html's verdict, the
dashboard's rows, the matrix's cells and the audit's page. A verdict takes its status's colour
(`batch.jobs.protocol.verdict_status`)."""

from __future__ import annotations

from ..jobs.protocol import CaseStatus, verdict_status

__all__ = ["STATUS_COLOURS", "verdict_colour"]

STATUS_COLOURS = {
    CaseStatus.PASSED: "#1b7f3b",
    CaseStatus.FAILED: "#b00020",
    CaseStatus.INCONCLUSIVE: "#a06000",
    CaseStatus.UNDERPOWERED: "#a06000",
    CaseStatus.ERROR: "#b00020",
    CaseStatus.SKIPPED: "#777",
}


def verdict_colour(verdict) -> str:
    """The colour of a `welch_core.Verdict` (or its label): its status's where no difference is expected."""
    return STATUS_COLOURS[verdict_status(verdict)]
