"""Seed lists on the command line: ``A:B`` is the half-open range A..B-1, ``S1,S2,...`` an explicit list."""

from __future__ import annotations

#: Cycles' seed property is a non-negative 32-bit int.
MAX_SEED = 2**31 - 1

#: Passes a run may have: far beyond any useful test, and small enough that the list and the statistics
#: (n numbers per tile-channel) fit in memory.
MAX_PASSES = 1_000_000


def parse_seeds(text: str) -> list[int]:
    """Parse ``A:B`` or ``S1,S2,...`` into a list of distinct seeds; raise ValueError with a one-line reason.

    Sizes are checked before anything is allocated.
    """
    text = text.strip()
    try:
        if ":" in text:
            start, _, stop = text.partition(":")
            start, stop = int(start), int(stop)
            bounds = (start, stop - 1)
            count = stop - start
        else:
            items = text.split(",")
            if len(items) > MAX_PASSES:
                raise OverflowError
            seeds = [int(s) for s in items if s.strip()]
            bounds = (min(seeds, default=0), max(seeds, default=0))
            count = len(seeds)
    except ValueError:
        raise ValueError(f"--seeds must be A:B or S1,S2,... with integers, got {_short(text)!r}") from None
    except OverflowError:
        count, bounds = MAX_PASSES + 1, (0, 0)
    if count <= 0:
        raise ValueError(f"--seeds gives no seeds: {_short(text)!r}")
    if bounds[0] < 0 or bounds[1] > MAX_SEED:
        raise ValueError(f"--seeds must lie in 0..{MAX_SEED}, got {_short(text)!r}")
    if count > MAX_PASSES:
        raise ValueError(f"--seeds {_short(text)} gives {count} seeds; a run takes at most {MAX_PASSES}")
    if ":" in text:
        return list(range(start, stop))
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds repeats a seed: {_short(text)!r}")
    return seeds


def format_seeds(seeds) -> str:
    """The shortest ``--seeds`` text for `seeds` (a range when they are consecutive)."""
    seeds = list(seeds)
    if seeds and seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]}:{seeds[0] + len(seeds)}"
    return ",".join(map(str, seeds))


def _short(text: str) -> str:
    return text if len(text) <= 60 else text[:57] + "..."
