"""How numbers are written for people, in one place: p-values, percentages, durations, one-line messages."""

from __future__ import annotations

import math

#: Characters kept of a message shown in one line (a status bar, a panel row).
ONE_LINE_LENGTH = 200


def p_value(p: float | None) -> str:
    """'0.0123', '< 1e-300' where p underflowed, 'n/a' where it is undefined."""
    if p is None or not math.isfinite(p):
        return "n/a"
    return "< 1e-300" if p == 0 else f"{p:.3g}"  # p underflows to 0 only far beyond any alpha


def p_is(p: float | None) -> str:
    """'= 0.0123' or '< 1e-300', for text like 'global p = 0.0123'."""
    text = p_value(p)
    return text if text.startswith("<") else f"= {text}"


def percent(x: float | None, digits: int = 2) -> str:
    """A relative difference as a signed percentage: '+1.25 %'; 'n/a' where undefined."""
    if x is None or not math.isfinite(x):
        return "n/a"
    return f"{x * 100:+.{digits}f} %"


def duration(seconds: float | None) -> str:
    """'42 s', '2 min 05 s', '2 h 01 min'; '?' when unknown."""
    if seconds is None or not math.isfinite(seconds) or seconds < 0:
        return "?"
    if seconds < 9.95:
        return f"{seconds:.1f} s"
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"


def count(n: int, word: str, plural: str | None = None) -> str:
    """'1 look', '5 looks', '1 pass', '2 passes' (`plural`: the word's plural where adding s is wrong)."""
    if n == 1:
        return f"{n} {word}"
    return f"{n} {plural or (word + 'es' if word.endswith('s') else word + 's')}"


def one_line(text: str, limit: int = ONE_LINE_LENGTH) -> str:
    """Whitespace collapsed to single spaces and cut to `limit` characters."""
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def magnitude(x: float | None, digits: int = 2) -> str:
    """An unsigned relative size: '0.82 %'; '—' where it is not known (an unbounded bias)."""
    if x is None or not math.isfinite(x):
        return "—"
    return f"{abs(x) * 100:.{digits}f} %"


def bound(x: float | None, digits: int = 2) -> str:
    """A bias ruled out beyond `x`, as `magnitude` says it, but never '0.00 %' for a bound above 0 (a difference of
    float rounding): the smallest size shown, '0.01 %', which it is below."""
    if x is not None and math.isfinite(x) and 0 < abs(x) * 100 < 0.5 * 10**-digits:
        return f"{10**-digits:.{digits}f} %"
    return magnitude(x, digits)


def interval(low: float | None, high: float | None, digits: int = 2) -> str:
    """'[-0.35 %, +1.68 %]'; '[—]' where either end is unknown."""
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return "[—]"
    return f"[{percent(low, digits)}, {percent(high, digits)}]"


def difference(d, digits: int = 2) -> str:
    """A `welch_core.Difference` as '+1.02 % [+0.35 %, +1.68 %]', '+1.02 % (no interval yet)' where its interval is
    unbounded ('—' without an estimate)."""
    if d is None or d.get("estimate") is None:
        return "—"
    low, high = d.get("low"), d.get("high")
    if low is None or high is None or not (math.isfinite(low) and math.isfinite(high)):
        return f"{percent(d['estimate'], digits)} (no interval yet)"
    return f"{percent(d['estimate'], digits)} {interval(low, high, digits)}"
