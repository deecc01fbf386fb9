"""The tool with one piece switched off: a what-if, or the tool as it was before a change, measured beside the
tool as it is. Each replaces one function of welch_core inside a ``with`` block and puts it back after.

A replacement has to be made in the module that looks the function up, so this is the one module of the benchmarks
that uses welch_core's modules (``welch_core.looks``, ``welch_core.comparison``, which the package serves as
attributes) instead of its top-level names; it uses their public names only. Everything else of the charts and the
studies goes through welch_core's top-level names.
"""

from __future__ import annotations

import contextlib
import dataclasses

import numpy as np

import welch_core as wc


def welch_df_available() -> bool:
    """Whether `welch_df` still applies: welch_core's looks take the conservative n - 1 degrees of freedom."""
    return hasattr(wc.looks, "conservative")


@contextlib.contextmanager
def welch_df():
    """Within: the sequential looks use Welch-Satterthwaite's degrees of freedom, not n - 1 (a what-if of chart 5:
    the design is calibrated with n - 1 only)."""
    with _replaced(wc.looks, "conservative", lambda tested, n: tested):
        yield


@contextlib.contextmanager
def without_permutation():
    """Within: the tool as it was before the permutation test: Welch's t-tests alone decide `biased` whatever the
    pass counts (the "before" of `benchmarks.studies.unequal`)."""

    def never(*args):
        return False

    with _replaced(wc.comparison, "needs_resampling", never), _replaced(wc.looks, "needs_resampling", never):
        yield


@contextlib.contextmanager
def paired_alone():
    """Within: `compare` without the Welch rule: a paired tile-channel whose differences are not normal stays
    untrusted (the "paired alone" of `benchmarks.studies.sparse`)."""
    original = wc.comparison.test_tiles

    def without_welch(ref, test, kind, pvalue_method="exact", pixels=False, pairs=None):
        tested = original(ref, test, kind, pvalue_method, pixels, pairs)
        if tested.unpaired is None or not tested.unpaired.any():
            return tested
        diffs = wc.comparison.paired_differences(ref, test)
        paired = wc.paired_from_stats(diffs.mean, diffs.variance, diffs.n, pvalue_method=pvalue_method)
        where = tested.unpaired
        fields = (f.name for f in dataclasses.fields(wc.TTestResult))
        result = wc.TTestResult(**{f: np.where(where, getattr(paired, f), getattr(tested.result, f)) for f in fields})
        with np.errstate(invalid="ignore", divide="ignore"):
            cross = (test.variance - ref.variance - diffs.variance) / (2.0 * diffs.n)
        cross = np.where(where, cross, tested.cross)
        return dataclasses.replace(
            tested, result=result, suspect=tested.suspect | where, cross=cross, unpaired=np.zeros_like(where)
        )

    with _replaced(wc.comparison, "test_tiles", without_welch):
        yield


@contextlib.contextmanager
def _replaced(module, name: str, value):
    """`module.name` is `value` within."""
    saved = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, saved)
