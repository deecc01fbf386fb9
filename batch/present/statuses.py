"""How each status of a suite case or a matrix cell (`batch.jobs.protocol.CaseStatus`) is shown, in one table:
its colour on every page (report.html's verdict, the dashboard's rows, the matrix's cells, the audit's page), the
element a JUnit test case gets, what it means, and the dashboard's order of rows (what needs a look first). A
verdict takes its status's colour (`batch.jobs.protocol.verdict_status`)."""

from __future__ import annotations

from dataclasses import dataclass

from ..jobs.protocol import CaseStatus, verdict_status

__all__ = ["FIRST", "STATUS_COLOURS", "STATUSES", "StatusWords", "verdict_colour"]


@dataclass(frozen=True)
class StatusWords:
    colour: str
    junit: str | None  # the JUnit element of a test case with this status (None: it passed)
    meaning: str


#: Each status, in the order of the dashboard's rows: what needs a look first.
STATUSES = {
    CaseStatus.FAILED: StatusWords("#b00020", "failure", "another verdict than the case expects"),
    CaseStatus.ERROR: StatusWords("#b00020", "error", "the case could not run"),
    CaseStatus.INCONCLUSIVE: StatusWords("#a06000", "failure", "no verdict within the budget"),
    CaseStatus.UNDERPOWERED: StatusWords("#a06000", "failure", "nothing found, but a bias of the tolerance could hide"),
    CaseStatus.PASSED: StatusWords("#1b7f3b", None, "the verdict the case expects, where it could have failed"),
    CaseStatus.SKIPPED: StatusWords("#777", "skipped", "not run here (no GPU)"),
}

#: The statuses in the dashboard's order, and each one's colour.
FIRST = tuple(STATUSES)
STATUS_COLOURS = {status: words.colour for status, words in STATUSES.items()}


def verdict_colour(verdict) -> str:
    """The colour of a `welch_core.Verdict` (or its label): its status's where no difference is expected."""
    return STATUS_COLOURS[verdict_status(verdict)]
