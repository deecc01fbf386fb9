"""The one render loop: passes arrive from a source (rendered here one by one, `batch.blender.run`; or in chunks
from a Dask pool, `batch.jobs.distributed`) and go into one run (the statistics and their layers), with the
progress of each pass, a checkpoint every so many passes, the file in the order of the job's seeds, and nothing
that arrived lost on a failure, Ctrl-C or SIGTERM. Resuming a statistics file is checked here too, once.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from .._siblings import welch_core as wc
from ..errors import BatchError
from .checkpoint import Checkpoints
from .job import RenderJob


@dataclass
class Arrival:
    """Passes that arrived: their seeds; their statistics and the layers of the same passes by name (a chunk's),
    or None where the source added them to the run itself (a pass rendered here goes straight into the run's
    statistics: no second copy of its pixels); each pass's seconds (None: the time since the last arrival, shared
    by its passes); the warnings that came with them and who rendered them."""

    seeds: tuple[int, ...]
    stats: wc.TileStats | None = None
    layers: dict[str, wc.TileStats] = field(default_factory=dict)
    seconds: tuple[float, ...] | None = None
    warnings: tuple[str, ...] = ()
    source: str = ""


class Run:
    """The statistics file a loop writes, `out` (None: kept in memory only): `stats` and `layers` as they grow,
    saved with their passes in the order of `seeds` (the job's: what one process renders, whatever order the
    passes arrive in). A `scratch` file (a worker's chunk, read at once and removed by the process that asked
    for it, which checks it as it reads) is written without a preview and not read back: at 1920x1080 the two
    took 50 ms of a chunk's 130 ms save."""

    def __init__(self, out: str | None, seeds=(), stats: wc.TileStats | None = None, layers: dict | None = None,
                 scratch: bool = False):  # fmt: skip
        self.out = out
        self.position = {seed: i for i, seed in enumerate(seeds)}
        self.stats = stats
        self.layers = dict(layers or {})
        self.scratch = scratch

    @classmethod
    def of(cls, job: RenderJob, stats: wc.TileStats | None = None, layers: dict | None = None) -> Run:
        return cls(job.out, job.seeds, stats, layers)

    def add(self, arrival: Arrival) -> None:
        """Add the passes of `arrival`; refused in one line where they are of another configuration or carry
        other layers than the run."""
        chunk = arrival.stats
        if chunk is None:  # added by its source
            return
        if self.stats is None:
            self.stats, self.layers = chunk, dict(arrival.layers)
            return
        try:
            self.stats.same_run(chunk, "merge")
        except wc.WelchInputError as exc:
            # A worker with another Blender build, or a resumed file of another configuration.
            raise BatchError(f"{arrival.source or 'a renderer'} rendered another configuration than {self.out} "
                             f"holds: {exc}") from None  # fmt: skip
        if list(arrival.layers) != list(self.layers):
            raise BatchError(f"can't resume {self.out}: it has layers {list(self.layers) or 'none'}, this run "
                             f"{list(arrival.layers) or 'none'}")  # fmt: skip
        self.stats.add_sums(chunk.sums, chunk.seeds, chunk.pixel_sum, chunk.pixels)
        for name, layer in arrival.layers.items():
            self.layers[name].add_sums(layer.sums, layer.seeds, layer.pixel_sum)

    def save(self, checkpoints: Checkpoints | None = None) -> None:
        """Write the file, its passes (and its layers') in the order of the job's seeds: now, or by `checkpoints`'
        thread while the loop goes on."""
        if self.out is None or self.stats is None:
            return
        order = sorted(range(self.stats.n), key=lambda i: self.position[self.stats.seeds[i]]) if self.position else []
        if order and order != list(range(self.stats.n)):
            self.stats = _reordered(self.stats, order)
            self.layers = {name: _reordered(layer, order) for name, layer in self.layers.items()}
        if self.scratch:
            wc.formats.write_arrays(self.out, wc.formats.stats_arrays(self.stats, self.layers), verify=False)
        elif checkpoints is None:
            wc.save_stats(self.out, self.stats, self.layers)
        else:
            checkpoints.write(self.out, self.stats, self.layers)


def _reordered(stats: wc.TileStats, order: list[int]) -> wc.TileStats:
    pixel_sum = stats.pixel_sum if stats.pixels is None else None  # (with moments, their mean is the mean image)
    return wc.TileStats.from_sums(stats.sums[order], [stats.seeds[i] for i in order], stats.height, stats.width,
                                  stats.tile, stats.info, pixel_sum=pixel_sum, pixels=stats.pixels,
                                  mean_from_pixels=True)  # fmt: skip


def render_loop(arrivals: Iterable[Arrival], run: Run, progress, checkpoint_every: int,
                checkpoints: Checkpoints | None = None) -> None:  # fmt: skip
    """Add each arrival to `run`, report its passes to `progress` (a `batch.present.progress.Progress`) and save
    every `checkpoint_every` passes, or further apart where writing them would take the passes' cores (by a thread
    of its own, `batch.jobs.checkpoint`: the passes go on meanwhile), and at the end, also when the loop ends on a
    failure or an interrupt (the source raises KeyboardInterrupt on Ctrl-C or SIGTERM): nothing that arrived is
    lost. The last save waits for the checkpoint being written, so the file ends with every pass."""
    unsaved, last = 0, time.perf_counter()
    checkpoints = checkpoints or Checkpoints()
    try:
        for arrival in arrivals:
            run.add(arrival)
            unsaved += len(arrival.seeds)  # in the run now: saved however the loop ends
            for message in arrival.warnings:
                progress.warning(f"{arrival.source}: {message}" if arrival.source else message)
            now = time.perf_counter()
            seeds = arrival.seeds
            shared = (now - last) / max(len(seeds), 1)  # a chunk's wall time per pass: the ETA holds for a pool
            for seed, seconds in zip(seeds, arrival.seconds or [shared] * len(seeds), strict=True):
                progress.pass_done(seed, seconds)
            last = now
            if unsaved >= checkpoint_every and checkpoints.due():
                run.save(checkpoints)
                unsaved = 0
    finally:
        try:
            checkpoints.wait()
        finally:
            if unsaved:
                run.save()


def resumed(job: RenderJob, fresh: wc.TileStats | None = None) -> tuple[wc.TileStats | None, dict]:
    """What a run of `job` starts from: its statistics file when resuming (with its layers), checked against the
    job's seeds and, where the run's configuration is known before anything renders (`fresh`: the grid and
    `RunInfo` of this run), against that; else `fresh` and no layers. Refused in one line where the file exists
    and `job.resume` is off."""
    if not os.path.exists(job.out):
        return fresh, {}
    if not job.resume:
        raise BatchError(f"{job.out} already exists: pass --resume to continue it, or choose another --out")
    stats = wc.load_stats(job.out)
    if fresh is not None:
        try:
            stats.same_run(fresh, "resume")
        except wc.WelchInputError as exc:
            raise BatchError(f"{job.out}: {exc}") from None
    extra = sorted(set(stats.seeds) - set(job.seeds))
    if extra:
        raise BatchError(f"can't resume {job.out}: it holds seed {extra[0]}, which is not in --seeds")
    return stats, wc.load_layers(job.out)
