"""What the add-on holds between operator calls, outside the user's file: the running session and the last result.

Panels read these and never compute; operators and timers write them. Module state, because a running subprocess
and a numpy comparison cannot live in Blender properties and must not be saved into the blend file.
"""

from __future__ import annotations

from .runner import RUNNING

session = None  # runner.Session while a run is going on or until the next one starts
run_context: dict = {}  # what the running session needs when it ends: output paths, scene names, settings key
result: dict | None = None  # summary of the last comparison, for drawing (see results.summarize)
comparison = None  # the last welch_core.Comparison, to re-colour the map without recomputing
stats: tuple = ()  # (reference, test) TileStats of the last comparison
highlight: tuple[int, int] | None = None  # (row, col) of the tile outlined in the result image
last_error: str = ""
resumable: dict | None = None  # run_context of a cancelled or failed run whose statistics can be continued


def running() -> bool:
    return session is not None and session.state == RUNNING


def clear_result() -> None:
    global result, comparison, stats, highlight
    result, comparison, stats, highlight = None, None, (), None
