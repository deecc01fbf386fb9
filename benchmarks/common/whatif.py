"""The tool with one piece switched off: a what-if, or the tool as it was before a change, measured beside the
tool as it is. Each replaces one function of welch_core, or registers a variant of a tile test, inside a ``with``
block and puts it back after.

A replacement has to be made in the module that looks the function up, so this is the one module of the benchmarks
that uses welch_core's modules (``welch_core.looks``, ``welch_core.welch_test``, ``welch_core.paired_test``, which
the package serves as attributes) instead of its top-level names; it uses their public names only. Everything else
of the charts and the studies goes through welch_core's top-level names.
"""

from __future__ import annotations

import contextlib

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

    class WelchAlone(wc.welch_test.WelchTest):
        def needs_resampling(self, n_ref, n_test):
            return False

    with _registered(WelchAlone(wc.TileTestKind.WELCH)):
        yield


@contextlib.contextmanager
def paired_alone():
    """Within: `compare` without the Welch rule: a paired tile-channel whose differences are not normal stays
    untrusted (the "paired alone" of `benchmarks.studies.sparse`)."""

    class PairedAlone(wc.paired_test.PairedTest):
        welch_rule = False

    with _registered(PairedAlone(wc.TileTestKind.PAIRED)):
        yield


@contextlib.contextmanager
def _registered(method):
    """`method` is the registered tile test of its kind within (`welch_core.tile_tests.TILE_TESTS`)."""
    saved = wc.TILE_TESTS[method.kind]
    wc.TILE_TESTS[method.kind] = method
    try:
        yield
    finally:
        wc.TILE_TESTS[method.kind] = saved


@contextlib.contextmanager
def _replaced(module, name: str, value):
    """`module.name` is `value` within."""
    saved = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, saved)
