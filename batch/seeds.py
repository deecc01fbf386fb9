"""Seed lists on the command line: ``A:B`` is the half-open range A..B-1, ``S1,S2,...`` an explicit list."""

from __future__ import annotations

#: Cycles' seed property is a non-negative 32-bit int.
MAX_SEED = 2**31 - 1


def parse_seeds(text: str) -> list[int]:
    """Parse ``A:B`` or ``S1,S2,...`` into a list of distinct seeds; raise ValueError with a one-line reason."""
    text = text.strip()
    try:
        if ":" in text:
            start, _, stop = text.partition(":")
            seeds = list(range(int(start), int(stop)))
        else:
            seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ValueError(f"--seeds must be A:B or S1,S2,... with integers, got {text!r}") from None
    if not seeds:
        raise ValueError(f"--seeds gives no seeds: {text!r}")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds repeats a seed: {text!r}")
    if min(seeds) < 0 or max(seeds) > MAX_SEED:
        raise ValueError(f"--seeds must lie in 0..{MAX_SEED}, got {text!r}")
    return seeds


def format_seeds(seeds: list[int]) -> str:
    """The shortest ``--seeds`` text for `seeds` (a range when they are consecutive)."""
    if seeds and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}:{seeds[0] + len(seeds)}"
    return ",".join(map(str, seeds))
