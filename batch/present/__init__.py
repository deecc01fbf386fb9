"""Everything people read about a run or a comparison: numbers in words (``fmt``), the verdict's sentence
(``words``), the summary that report.json holds and every presenter reads (``summary``), the one way from a
comparison to its report (``pipeline``), the report page (``report``), a suite's dashboard and JUnit, and
progress lines (``progress``).

Presenting reads welch_core's `Outcome` and decides nothing. May import welch_core and ``batch.jobs``'s
protocol and definitions; nothing of ``blender``, ``decide`` or ``cli``.
"""
