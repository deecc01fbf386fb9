"""The verdict of a comparison, named once: its label in files, exit code, words for people and panel icon."""

from __future__ import annotations

import enum

__all__ = ["Verdict"]


class Verdict(enum.StrEnum):
    """What a comparison concludes. The value is the label written to report files (``Verdict("biased")``); a
    member equals its label as a string, so JSON and comparisons with plain labels just work.

    Exit codes are those of the command line: 1 is reserved for ``biased``; ``equivalent`` and ``no_evidence``
    both mean that nothing was found (0); ``inconclusive`` is 3.
    """

    BIASED = ("biased", 1, "biased", "Biased", "ERROR")
    EQUIVALENT = ("equivalent", 0, "equivalent", "Equivalent", "CHECKMARK")
    NO_EVIDENCE = ("no_evidence", 0, "no evidence of bias", "No Evidence of Bias", "CHECKMARK")
    INCONCLUSIVE = ("inconclusive", 3, "inconclusive", "Inconclusive", "QUESTION")

    def __new__(cls, label: str, exit_code: int, text: str, title: str, icon: str):
        member = str.__new__(cls, label)
        member._value_ = label
        member.exit_code = exit_code
        member.text = text  # lower case, for a sentence
        member.title = title  # Title Case, for a panel (Blender's convention)
        member.icon = icon  # a Blender icon name
        return member

    @property
    def label(self) -> str:
        return self.value
