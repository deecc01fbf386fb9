"""What the add-on holds between operator calls, outside the user's file: one small typed object, `current`.

Panels read it and never compute; operators and timers write it. Module state, because a running subprocess
and a numpy comparison cannot live in Blender properties and must not be saved into the blend file.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .runner import RUNNING, CheckRun


@dataclass(frozen=True)
class RunFolder:
    """A started run: its folder, statistics files, alpha, and the settings it was started with (`key`), which
    must be unchanged for a stopped run to be resumed."""

    dir: str
    reference: str
    test: str
    alpha: float
    key: tuple = ()


@dataclass
class AddonState:
    session: CheckRun | None = None  # while a check is going on, and until the next one starts
    run: RunFolder | None = None  # the run of `session`
    resumable: RunFolder | None = None  # a cancelled or failed run whose statistics can be continued
    result: dict | None = None  # the panel's summary of the last comparison (see results.summarize)
    comparison: object = None  # the last welch_core.Comparison, to re-colour the map without recomputing
    layers: dict = field(default_factory=dict)  # its layers' comparisons (light components, light groups)
    stats: tuple = field(default_factory=tuple)  # (reference, test) TileStats of the last comparison
    highlight: tuple[int, int] | None = None  # (row, col) of the tile outlined in the result image
    significant: object = None  # the finest tiles the verdict found significant (a check's: its look's)
    overlay: object = None  # overlay.Geometry of the comparison with the display settings, or None
    overlay_batches: object = None  # the GPU batches drawn from `overlay`, made by the first draw after a change
    overlay_error: str = ""  # why the overlay could not be drawn, shown in the panel
    last_error: str = ""

    def running(self) -> bool:
        return self.session is not None and self.session.state == RUNNING

    def clear_result(self) -> None:
        self.result, self.comparison, self.stats, self.highlight, self.significant = None, None, (), None, None
        self.layers = {}
        self.overlay, self.overlay_batches, self.overlay_error = None, None, ""

    def reset(self) -> None:
        """Forget everything (a new file was loaded, the add-on is being disabled)."""
        self.__init__()


current = AddonState()
