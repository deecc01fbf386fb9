"""What crosses from a Dask worker to the client: a chunk's passes (`ChunkResult`, with their layers) or the job
error that stopped it (`ChunkError`)."""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..._siblings import welch_core as wc
from ..loop import Arrival


@dataclass(frozen=True, eq=False)
class ChunkResult:
    """The passes of one chunk as a worker sends them back (by Dask's pickling): per-pass tile sums, shape
    (n, tiles_y, tiles_x, channels) in the order of `seeds`; the per-pixel sum over these passes (None when not
    kept, or when the moments are sent: their mean makes it) and their pixel moments (each pixel's mean and M2,
    `welch_core.PixelMoments`; None when not kept); the
    grid and the `RunInfo` (as JSON) of the run; each pass's render seconds; the chunk's seconds in
    the worker, request to result; its warnings; which worker rendered it; and the same for each layer of the
    passes (light components, light groups: name -> (sums, pixel sum)). One way out (`from_stats`), one way in
    (`stats`, `arrival`).

    `path`: the chunk's statistics file, where the client shares the worker's machine (a cluster started here).
    The result then carries the tile sums alone, and the client reads the pixel moments and sums from the file
    and removes it (`discard` where it drops the chunk): at 1920x1080 a chunk's 100 MB of moments are neither
    read by the worker nor sent through Dask."""

    seeds: tuple[int, ...]
    sums: np.ndarray
    pixel_sum: np.ndarray | None
    height: int
    width: int
    tile: int
    info: dict
    seconds: tuple[float, ...] = ()
    wall_seconds: float = 0.0
    warnings: tuple[str, ...] = ()
    worker: str = ""
    layers: dict[str, tuple[np.ndarray, np.ndarray | None]] = field(default_factory=dict)
    moments: tuple[np.ndarray, np.ndarray] | None = None
    path: str | None = None

    @classmethod
    def from_stats(
        cls, stats: wc.TileStats, seconds=(), wall_seconds=0.0, warnings=(), worker="", layers=None, path=None
    ) -> ChunkResult:
        def arrays(run: wc.TileStats):
            pixels = None if run.pixel_sum is None else np.ascontiguousarray(run.pixel_sum)
            return np.ascontiguousarray(run.sums), pixels

        sums, pixel_sum = arrays(stats) if stats.pixels is None else (np.ascontiguousarray(stats.sums), None)
        return cls(
            seeds=tuple(int(s) for s in stats.seeds),
            sums=sums,
            pixel_sum=pixel_sum,
            height=stats.height,
            width=stats.width,
            tile=stats.tile,
            info=stats.info.to_json(),
            seconds=tuple(float(s) for s in seconds),
            wall_seconds=float(wall_seconds),
            warnings=tuple(warnings),
            worker=worker,
            layers={name: arrays(layer) for name, layer in (layers or {}).items()},
            moments=None if stats.pixels is None else (stats.pixels.mean, stats.pixels.m2),
            path=None if path is None else os.fspath(path),
        )

    def stats(self) -> wc.TileStats:
        return self._read()[0]

    def arrival(self) -> Arrival:
        """The chunk's passes and layers for the render loop (`batch.jobs.loop`)."""
        stats, layers = self._read()
        return Arrival(self.seeds, stats, layers, None, self.warnings, self.worker)

    def discard(self) -> None:
        """Remove the chunk's file (`path`), for a chunk the client drops."""
        if self.path is not None:
            remove_file(self.path)

    def _read(self) -> tuple[wc.TileStats, dict[str, wc.TileStats]]:
        """The chunk's passes and layers: from its file (then removed), or as sent."""
        if self.path is None:
            pixels = None if self.moments is None else wc.PixelMoments.of(*self.moments, len(self.seeds))
            layers = {name: self._run(sums, pixels) for name, (sums, pixels) in self.layers.items()}
            return self._run(self.sums, self.pixel_sum, pixels), layers
        try:
            stats, layers = wc.load_stats(self.path), wc.load_layers(self.path)
        finally:
            self.discard()
        if tuple(stats.seeds) != self.seeds or list(layers) != list(self.layers):
            raise wc.StatsFileError(f"{self.path}: the chunk file of {self.worker} holds other passes than it sent")
        return stats, layers

    def _run(self, sums, pixel_sum, pixels=None) -> wc.TileStats:
        info = wc.RunInfo.from_json(self.info)
        return wc.TileStats.from_sums(sums, self.seeds, self.height, self.width, self.tile, info, pixel_sum=pixel_sum,
                                      pixels=pixels, mean_from_pixels=True)  # fmt: skip


def remove_file(path: str) -> None:
    """Remove `path` if it is there."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


@dataclass(frozen=True)
class ChunkError:
    """A chunk a worker could not render because of the job itself (a .blend it can't open, a NaN pass with
    ``--on-nan stop``): sent back as a result, not raised, so that Dask does not run it again."""

    seeds: tuple[int, ...]
    message: str
    worker: str
