"""Progress of a render run: a human line per pass on stderr, or one JSON object per line on stdout for programs.

JSON events (the add-on reads them; other lines on stdout, such as Blender's own, are to be skipped):
``{"event": "start", "total": n, "todo": k, "out": path}``,
``{"event": "pass", "done": k, "total": n, "seed": s, "seconds": t, "eta": e}``,
``{"event": "warning", "message": "..."}``, ``{"event": "done", "out": path, "passes": n}``,
``{"event": "error", "message": "..."}``.
"""

from __future__ import annotations

import json
import sys


class Progress:
    """Reports passes done, seconds per pass and the estimated time left."""

    def __init__(self, total: int, json_lines: bool = False, label: str = "render"):
        self.total = total
        self.json_lines = json_lines
        self.label = label
        self.done = 0
        self._times: list[float] = []

    def _emit(self, event: dict, text: str) -> None:
        if self.json_lines:
            print(json.dumps(event), flush=True)
        else:
            print(text, file=sys.stderr, flush=True)

    def start(self, done: int, out: str) -> None:
        self.done = done
        self._emit(
            {"event": "start", "total": self.total, "todo": self.total - done, "out": out},
            f"{self.label}: {self.total - done} of {self.total} passes to render into {out}",
        )

    def pass_done(self, seed: int, seconds: float) -> None:
        self.done += 1
        self._times.append(seconds)
        recent = self._times[-16:]  # the first passes include start-up costs; recent ones predict better
        eta = sum(recent) / len(recent) * (self.total - self.done)
        self._emit(
            {"event": "pass", "done": self.done, "total": self.total, "seed": seed, "seconds": seconds, "eta": eta},
            f"{self.label}: pass {self.done}/{self.total} (seed {seed}) {seconds:.2f} s, ETA {_duration(eta)}",
        )

    def warning(self, message: str) -> None:
        self._emit({"event": "warning", "message": message}, f"warning: {message}")

    def finished(self, out: str, passes: int) -> None:
        self._emit({"event": "done", "out": out, "passes": passes}, f"{self.label}: {passes} passes in {out}")

    def error(self, message: str) -> None:
        self._emit({"event": "error", "message": message}, f"error: {message}")


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"
