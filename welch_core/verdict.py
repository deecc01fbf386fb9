"""The verdict of a comparison, named once: its label in files and its words for people. (Its exit code is the
batch tool's protocol, its icon the Blender add-on's.)"""

from __future__ import annotations

import enum

__all__ = ["Verdict"]


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
