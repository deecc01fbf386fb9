"""A command template's words: the shell-like line of ``render --command`` (see `batch.jobs.command`), split and
checked. Its own module so that a job checks its command without importing the code that runs it."""

from __future__ import annotations

import shlex
import string

from ..errors import BatchError

PLACEHOLDERS = ("seed", "out", "spp", "set", "python")
REQUIRED = ("seed", "out")


def words(template: str) -> list[str]:
    """The template's words, checked: it splits like a shell line, names only `PLACEHOLDERS`, has ``{seed}``
    and ``{out}``, and ``{set}`` only as a word of its own. Raises BatchError naming the problem."""
    try:
        split = shlex.split(template)
    except ValueError as exc:
        raise BatchError(f"--command {template!r}: {exc}") from None
    if not split:
        raise BatchError("--command is empty: give the command that renders one pass, e.g. "
                         "'{python} render.py --seed {seed} --out {out}'")  # fmt: skip
    seen = set()
    for word in split:
        try:
            fields = [field for _, field, _, _ in string.Formatter().parse(word) if field is not None]
        except ValueError as exc:
            raise BatchError(f"--command {template!r}: {exc} (write {{{{ and }}}} for a literal brace)") from None
        for field in fields:
            if field not in PLACEHOLDERS:
                raise BatchError(f"--command {template!r}: unknown placeholder {{{field}}} (it takes "
                                 f"{', '.join('{' + p + '}' for p in PLACEHOLDERS)})")  # fmt: skip
            if field == "set" and word != "{set}":
                raise BatchError(f"--command {template!r}: {{set}} must be a word of its own, not in {word!r}")
        seen.update(fields)
    missing = [p for p in REQUIRED if p not in seen]
    if missing:
        raise BatchError(f"--command {template!r} has no {{{missing[0]}}}: each pass needs its own seed and file")
    return split
