"""The verdict of a comparison, named once: its label in files and its words for people. (Its exit code is the
batch tool's protocol, its icon the Blender add-on's.)"""

from __future__ import annotations

import enum

__all__ = ["Verdict", "VerdictReason"]


class Verdict(enum.StrEnum):
    """What a comparison concludes. The value is the label written to report files (``Verdict("biased")``); a
    member equals its label as a string, so JSON and comparisons with plain labels just work.
    """

    BIASED = ("biased", "biased", "Biased")
    EQUIVALENT = ("equivalent", "equivalent", "Equivalent")
    NO_EVIDENCE = ("no_evidence", "no evidence of bias", "No Evidence of Bias")
    INCONCLUSIVE = ("inconclusive", "inconclusive", "Inconclusive")

    def __new__(cls, label: str, text: str, title: str):
        member = str.__new__(cls, label)
        member._value_ = label
        member.text = text  # lower case, for a sentence
        member.title = title  # Title Case, for a panel (Blender's convention)
        return member

    @property
    def label(self) -> str:
        return self.value


class VerdictReason(enum.StrEnum):
    """Why a comparison's verdict is what it is (`welch_core.decision.decide`), one per branch of the decision: the
    key report files carry (``reason``; a member equals it as a string). Its words are the presenters'
    (`batch.present.words.sentence` and `next_step`)."""

    DETERMINISTIC = "deterministic"  # biased: tiles differ by the same amount in every pass (no noise to test)
    SIGNIFICANT = "significant"  # biased: a tile-channel's difference crossed its boundary
    SPREAD = "spread"  # biased: no tile crossed, but the p-values as a whole are too small (KS)
    IDENTICAL = "identical"  # equivalent: every pass identical on both sides, enough passes to say so
    BOUNDED = "bounded"  # equivalent: every tile of the claimed size (and coarser) within the tolerance
    IDENTICAL_TOO_FEW = "identical_too_few"  # inconclusive: identical passes, too few yet
    FUTILE = "futile"  # inconclusive: stopped early, neither claim within the budget's reach
    UNDECIDED = "undecided"  # a look of a check that goes on
    UNTESTABLE = "untestable"  # inconclusive: no tile-channel can be tested
    UNREACHABLE = "unreachable"  # inconclusive: the permutation test can't reach alpha with these pass counts
    TOO_UNTESTED = "too_untested"  # inconclusive: too much of the image is not normal at any tile size
    BEYOND = "beyond"  # inconclusive: bounded, but a finer tile found biased differs by more than the tolerance
    UNBOUNDED = "unbounded"  # inconclusive: the claimed size not bounded within the tolerance
    NOTHING_FOUND = "nothing_found"  # no evidence of bias (no tolerance: no equivalence claim asked for)
