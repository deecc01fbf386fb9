"""What the speed and precision measurements share: the best of several wall times, and the exact two-sided
p-value of Student's t in mpmath (the reference the p-value methods are measured against)."""

from __future__ import annotations

import time

import mpmath


def best_time(func, repeats: int = 7) -> float:
    """Minimum wall time of `repeats` calls, in seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return min(times)


def mp_student(t: float, df: float) -> mpmath.mpf:
    """The two-sided p of Student's t with `df` degrees of freedom, at mpmath's working precision."""
    t, df = mpmath.mpf(t), mpmath.mpf(df)
    return mpmath.betainc(df / 2, mpmath.mpf(1) / 2, 0, df / (df + t * t), regularized=True)
