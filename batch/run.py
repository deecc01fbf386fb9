"""Render runs: many passes with different seeds into one statistics file, with checkpoints and resume.

Imports bpy (through `batch.render`); argument parsing and reports live elsewhere so they import without it.
"""

from __future__ import annotations

import os
import signal
import time
from dataclasses import dataclass, field

from . import render
from ._siblings import welch_core as wc
from .overrides import apply_overrides, parse_override
from .passes import ON_NAN, add_pass
from .progress import Progress


class RunError(Exception):
    """A run can't start or go on; the message is one line for the user."""


@dataclass
class RenderJob:
    """Everything a render run needs; mirrors the `render` command's arguments."""

    out: str
    seeds: list[int]
    spp: int = 1
    blend: str | None = None
    scene: str | None = None
    blend_scene: str | None = None
    tile: int = 32
    resolution: tuple[int, int] | None = None
    device: str = "CPU"
    sampling_pattern: str = "TABULATED_SOBOL"
    overrides: list[str] = field(default_factory=list)
    resume: bool = False
    on_nan: str = "stop"
    checkpoint_every: int = 8


#: Changes of the pass settings worth telling the user: they make the passes differ from the scene's own renders.
NOTABLE_CHANGES = ("render.engine", "use_denoising", "use_adaptive_sampling", "time_limit")


def prepare_scene(job: RenderJob, warn=None):
    """Open or build the scene, apply the unbiased render settings and the overrides; return (scene, info).

    `warn`, if given, is called with a message for each notable setting changed for the passes.
    """
    overrides = [parse_override(text) for text in job.overrides]  # syntax errors before the slow part
    scene = render.open_scene(job.blend, job.scene, job.blend_scene)
    changes = render.configure_unbiased(scene, job.device, job.spp, job.resolution, job.sampling_pattern)
    for change in changes:
        if warn is not None and change["path"].endswith(NOTABLE_CHANGES):
            warn(f"{change['path']} was {change['old']!r} in the scene; passes render with {change['new']!r}")
    apply_overrides(scene, overrides)
    settings = render.scene_settings(scene)
    renderer = render.renderer_info(scene, job.device)
    info = wc.RunInfo(
        spp=job.spp,
        renderer=renderer["renderer"],
        renderer_version=renderer["version"],
        device=renderer["device"],
        sampling_pattern=renderer["sampling_pattern"],
        scene=job.scene or os.path.basename(job.blend or scene.name),
        settings=settings,
        settings_hash=render.settings_hash({**settings, "overrides": list(job.overrides)}),
        overrides=tuple(job.overrides),
    )
    return scene, info


def _start_stats(job: RenderJob, scene, info: wc.RunInfo) -> wc.TileStats:
    """A new TileStats, or the checkpoint in `job.out` when resuming (checked to be the same run)."""
    width, height = render.resolution(scene)
    exists = os.path.exists(job.out)
    if exists and not job.resume:
        raise RunError(f"{job.out} already exists: pass --resume to continue it, or choose another --out")
    if not (exists and job.resume):
        return wc.TileStats(height, width, job.tile, 3, info)
    stats = wc.load_stats(job.out)
    if (stats.width, stats.height, stats.tile) != (width, height, job.tile):
        raise RunError(f"can't resume {job.out}: it is {stats.width}x{stats.height} at tile {stats.tile}")
    if stats.info.settings_hash != info.settings_hash or stats.info.spp != info.spp:
        raise RunError(f"can't resume {job.out}: it was rendered with other settings, spp or overrides")
    extra = sorted(set(stats.seeds) - set(job.seeds))
    if extra:
        raise RunError(f"can't resume {job.out}: it holds seed {extra[0]}, which is not in --seeds")
    return stats


def render_run(job: RenderJob, progress: Progress) -> wc.TileStats:
    """Render every seed of `job` not yet in its statistics file, checkpointing as it goes."""
    if job.on_nan not in ON_NAN:
        raise RunError(f"--on-nan must be one of {ON_NAN}, got {job.on_nan!r}")
    out_dir = os.path.dirname(os.path.abspath(job.out))
    if not os.access(out_dir, os.W_OK):
        raise RunError(f"can't write into {out_dir}: the folder is missing or not writable")
    scene, info = prepare_scene(job, progress.warning)
    stats = _start_stats(job, scene, info)
    todo = [seed for seed in job.seeds if seed not in set(stats.seeds)]
    progress.start(len(job.seeds) - len(todo), job.out)
    with render.PassRenderer(scene) as renderer, _StopOnTerminate() as stop:
        render_passes(renderer, todo, stats, progress, job.on_nan, job.out, job.checkpoint_every, stop)
    progress.finished(job.out, stats.n)
    return stats


def render_passes(
    renderer,
    seeds,
    stats: wc.TileStats,
    progress: Progress,
    on_nan: str = "stop",
    out: str | None = None,
    checkpoint_every: int = 8,
    stop=None,
) -> None:
    """Render `seeds` into `stats`; save `out` every `checkpoint_every` passes, at the end and on interruption.

    `stop`, if given, is asked between passes whether to stop (raising KeyboardInterrupt, as Ctrl-C does).
    """
    pending = 0
    try:
        for seed in seeds:
            if stop is not None and stop.requested:
                raise KeyboardInterrupt
            start = time.perf_counter()
            image = renderer.render(seed)
            try:
                if not add_pass(stats, image, seed, on_nan, progress.warning):
                    continue
            except wc.WelchInputError as exc:
                raise RunError(f"{exc} (use --on-nan skip or keep to go on)") from None
            pending += 1
            progress.pass_done(seed, time.perf_counter() - start)
            if out and pending >= checkpoint_every:
                wc.save_stats(out, stats)
                pending = 0
    finally:
        if out and pending:
            wc.save_stats(out, stats)  # also on Ctrl-C or a failed pass: nothing rendered is lost


class _StopOnTerminate:
    """Note SIGTERM (a cancel from the add-on, a job scheduler) and stop between passes, so the checkpoint is
    written. Raising from the handler itself could land inside Blender's operator call, which swallows it."""

    def __init__(self):
        self.requested = False
        self._old = None

    def __enter__(self):
        try:
            self._old = signal.signal(signal.SIGTERM, self._note)
        except ValueError:  # not the main thread: leave signals alone
            self._old = None
        return self

    def _note(self, _signum, _frame):
        self.requested = True

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGTERM, self._old)
        return False
