"""Render runs: many passes with different seeds into one statistics file, with checkpoints and resume.

Imports bpy (through `batch.blender.render`) where a job renders with Cycles, not for another renderer's command;
the job, argument parsing and reports live elsewhere so they import without it.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator

from .._siblings import welch_core as wc
from ..errors import BatchError
from ..jobs import command, protocol
from ..jobs.job import RenderJob
from ..jobs.launch import THREADS_ENV
from ..jobs.lock import OutputLock, output_folder
from ..jobs.loop import Arrival, Run, render_loop, resumed
from ..jobs.overrides import apply_overrides, parse_override
from ..jobs.pairs import save_pass_image
from ..jobs.passes import add_layered_pass, add_pass
from ..jobs.protocol import ChunkRequest, parse_request
from ..jobs.rna import render_size
from ..present.progress import Progress


class RunError(BatchError):
    """A run can't start or go on; the message is one line for the user."""


#: Changes of the pass settings worth telling the user: they make the passes differ from the scene's own renders.
NOTABLE_CHANGES = ("render.engine", "use_denoising", "use_adaptive_sampling", "time_limit")


def prepare_scene(job: RenderJob, warn=None):
    """Open or build the scene, apply the unbiased render settings and the overrides; return (scene, info).

    `warn`, if given, is called with a message for each notable setting changed for the passes. An override that
    changes a setting the job fixes (samples, resolution, ...) is refused: what is rendered is what is recorded.
    """
    from . import render  # imports bpy: only a Cycles job comes here

    overrides = [parse_override(text) for text in job.overrides]  # syntax errors before the slow part
    scene = render.open_scene(job.blend, job.scene, job.blend_scene)
    changes = render.configure_unbiased(scene, job.device, job.spp, job.resolution, job.sampling_pattern, job.lobes)
    for change in changes:
        if warn is not None and change["path"].endswith(NOTABLE_CHANGES):
            warn(f"{change['path']} was {change['old']!r} in the scene; passes render with {change['new']!r}")
    applied = apply_overrides(scene, overrides)
    render.check_fixed_settings(scene, job.spp, job.resolution, applied, job.sampling_pattern)
    render.check_sample_subset(scene, job.spp)
    if "lightgroups" in job.lobes:
        render.add_named_lightgroups(scene)
        if not render.layer_names(scene, ("lightgroups",)) and warn is not None:
            warn('--lobes lightgroups: the scene has no light groups (make one with --set objects["Light"].lightgroup'
                 "=NAME)")  # fmt: skip
    settings = render.scene_settings(scene)
    renderer = render.renderer_info(scene, job.device)
    if job.scene is not None:
        name = job.scene
    else:
        name = f"{os.path.basename(job.blend or render.bpy.data.filepath)}/{scene.name}"
    info = wc.RunInfo(
        spp=job.spp,
        renderer=renderer["renderer"],
        renderer_version=renderer["version"],
        build_hash=renderer["build_hash"],
        device=renderer["device"],
        sampling_pattern=renderer["sampling_pattern"],
        scene=name,
        scene_id=render.scene_id(job.scene),
        settings=settings,
        settings_hash=render.settings_hash({**settings, "overrides": list(job.overrides)}),
        overrides=job.overrides,
        fixed=render.fixed_record(scene, job.spp, job.resolution, job.sampling_pattern, changes),
    )
    return scene, info


def limit_threads(scene, value: str | None = None) -> None:
    """Give Cycles `value` CPU threads (default: the `batch.launch.THREADS_ENV` variable); nothing when it is
    unset or empty. Not recorded with the run: the thread count does not change the image (Cycles draws each
    pixel's samples from the seed whichever thread renders it; the distributed tests compare one thread against
    the default)."""
    text = os.environ.get(THREADS_ENV, "") if value is None else value
    if not text.strip():
        return
    try:
        threads = int(text)
    except ValueError:
        threads = 0
    if not 1 <= threads <= 1024:  # 1024: the most Blender's render.threads takes
        raise RunError(f"{THREADS_ENV} must be an integer in 1..1024, got {text!r}")
    scene.render.threads_mode = "FIXED"
    scene.render.threads = threads


def _start(job: RenderJob, size, info: wc.RunInfo, scene) -> tuple[wc.TileStats, dict[str, wc.TileStats]]:
    """The statistics and layers (`job.lobes`: light components, light groups) a run starts from: new ones, or
    the checkpoint in `job.out` when resuming (checked to be the same run); `size()` is the image's (width,
    height)."""
    if os.path.exists(job.out) and not job.resume:  # before size(), which may render a command's first pass
        raise RunError(f"{job.out} already exists: pass --resume to continue it, or choose another --out")
    width, height = size()
    if job.tile > min(width, height):
        raise RunError(f"--tile {job.tile} is larger than the image {width}x{height}")
    names = []
    if job.lobes:
        from . import render  # imports bpy: layers are Cycles'

        names = render.layer_names(scene, job.lobes)
    fresh = wc.TileStats(height, width, job.tile, 3, info, keep_pixel_moments=True)  # the pixel-variance test
    stats, layers = resumed(job, fresh)
    if stats is fresh:
        return stats, {name: _like(stats) for name in names}
    if list(layers) != names:
        raise RunError(f"can't resume {job.out}: it has layers {list(layers) or 'none'}, this run {names or 'none'}")
    return stats, layers


def _like(stats: wc.TileStats, moments: bool = False) -> wc.TileStats:
    """New, empty statistics of the same run as `stats` (keeping pixel moments where `moments` and it does)."""
    keep = moments and stats.pixels is not None
    return wc.TileStats(stats.height, stats.width, stats.tile, stats.channels, stats.info, keep_pixel_moments=keep)


def render_run(job: RenderJob, progress: Progress, requests=None) -> wc.TileStats:
    """Render every seed of `job` not yet in its statistics file, checkpointing as it goes.

    With `requests` (e.g. lines of stdin for ``render --serve``, read by `chunk_requests`), the scene stays
    loaded and passes are rendered as asked, until the requests end or the seeds run out: a pass count N renders
    the next N seeds into `job.out`, saved after each chunk; a `batch.jobs.protocol.ChunkRequest` renders exactly its
    seeds into its own new file (a worker's chunk, `batch.distributed`) and leaves `job.out` alone. Each chunk
    ends with a `Saved` event naming the file it saved.
    """
    output_folder(job.out)
    with OutputLock(job.out):
        if job.command is not None:  # another renderer: no scene, the size is its images'
            scene, info, renderer = None, command.run_info(job), command.CommandRenderer(job)
        else:
            from . import render  # imports bpy: a command job renders without it

            scene, info = prepare_scene(job, progress.warning)
            own = [parse_override(o).path.removeprefix("scene.") for o in job.overrides]
            if not any(path.startswith("render.threads") for path in own):
                limit_threads(scene)  # a worker's share of the cores, unless the job sets the threads itself
            if job.pass_images is not None:  # each pass's EXR is renamed there: written on its file system
                os.makedirs(job.pass_images, exist_ok=True)
            renderer = render.PassRenderer(scene, job.pass_images, lobes=job.lobes)
        with renderer, StopRequest() as stop:
            renderer.stop = stop  # a command's pass ends at once on a stop; a Cycles pass is short
            # A new command run learns its image size from its first pass: rendering starts with it (a time
            # budget counts it, `batch.jobs.side.Side.running_seconds`), so the run says it starts before it.
            probing = job.command is not None and not os.path.exists(job.out)
            if probing:
                progress.start(0, job.out)
            stats, layers = _start(job, lambda: _image_size(job, scene, renderer), info, scene)
            done = set(stats.seeds)
            todo = [seed for seed in job.seeds if seed not in done]
            if not probing:
                progress.start(len(job.seeds) - len(todo), job.out)
            if requests is None:
                render_passes(renderer, todo, stats, progress, job.on_nan, job.out, job.checkpoint_every, stop, layers,
                              job.pass_images)  # fmt: skip
            else:
                for request in requests:
                    if isinstance(request, ChunkRequest):
                        _render_chunk(job, renderer, request, stats, progress, stop, layers)
                        continue
                    count = request
                    chunk, todo = todo[: max(count, 0)], todo[max(count, 0) :]
                    before = stats.n
                    render_passes(renderer, chunk, stats, progress, job.on_nan, job.out, len(chunk) + 1, stop, layers,
                                  job.pass_images)  # fmt: skip
                    if stats.n == before:  # the loop saves the passes it added: without any, the file still answers
                        wc.save_stats(job.out, stats, layers)
                    progress.emit(protocol.Saved(out=job.out, passes=stats.n))
                    if not todo:
                        break
    progress.finished(job.out, stats.n)
    return stats


def _image_size(job: RenderJob, scene, renderer) -> tuple[int, int]:
    """(width, height) of the job's passes: the scene's, or a command's (its checkpoint's, else its first pass's)."""
    if scene is not None:
        return render_size(scene)
    if os.path.exists(job.out):
        stats = wc.load_stats(job.out, pixels=False)
        return stats.width, stats.height
    return renderer.size(job.seeds[0])


def _render_chunk(
    job: RenderJob, renderer, request: ChunkRequest, like: wc.TileStats, progress: Progress, stop, layers=None
) -> None:
    """Render exactly the seeds of `request` into a new statistics file of the same run as `like` (with the
    layers of `layers`), saved once at the end (with the passes done so far when the chunk stops early), then
    tell the caller with a `Saved` event."""
    allowed = set(job.seeds)
    unknown = [seed for seed in request.seeds if seed not in allowed]
    if unknown:
        raise RunError(f"a chunk asks for seed {unknown[0]}, which is not in --seeds of this job")
    chunk, chunk_layers = _like(like, moments=True), {name: _like(like) for name in layers or {}}
    # Saved by render_passes once it ends, however it ends (with the passes done so far on a failure or a stop).
    render_passes(renderer, request.seeds, chunk, progress, job.on_nan, request.out, len(request.seeds) + 1, stop,
                  chunk_layers, scratch=True)  # fmt: skip
    if chunk.n == 0:
        wc.save_stats(request.out, chunk, chunk_layers)  # every pass was skipped (--on-nan skip): it still answers
    progress.emit(protocol.Saved(out=request.out, passes=chunk.n))


def chunk_requests(stream):
    """What each line of `stream` asks for (``render --serve``): a pass count or a `ChunkRequest`; anything else
    ends the run."""
    for line in stream:
        request = parse_request(line)
        if request is None:
            return
        yield request


def render_passes(
    renderer,
    seeds,
    stats: wc.TileStats,
    progress: Progress,
    on_nan: str = "stop",
    out: str | None = None,
    checkpoint_every: int = 8,
    stop=None,
    layers: dict[str, wc.TileStats] | None = None,
    pass_images: str | None = None,
    scratch: bool = False,
) -> None:
    """Render `seeds` into `stats` (and `layers`, each pass's light components and light groups) through the one
    render loop (`batch.jobs.loop.render_loop`): `out` saved every `checkpoint_every` passes, at the end and on
    interruption (a `scratch` file: a worker's chunk, see `batch.jobs.loop.Run`); each pass's image also into the
    folder `pass_images` where given (`batch.jobs.pairs`).

    `stop`, if given, is asked between passes whether to stop (raising KeyboardInterrupt, as Ctrl-C does).
    """
    run = Run(out, (), stats, layers, scratch)
    rendered = _rendered(renderer, seeds, run, progress, on_nan, stop, pass_images)
    render_loop(rendered, run, progress, checkpoint_every)


def _rendered(renderer, seeds, run: Run, progress: Progress, on_nan: str, stop, pass_images=None) -> Iterator[Arrival]:
    """Each pass of `seeds` as it is rendered here, added to `run` at once (a skipped one, `on_nan`, arrives not
    at all). A renderer that can (`start_next`: a command's) renders the next pass while this one is added."""
    seeds = list(seeds)
    start_next = getattr(renderer, "start_next", None)
    for index, seed in enumerate(seeds):
        if stop is not None and stop.requested:
            raise KeyboardInterrupt
        start = time.perf_counter()
        try:
            if run.layers:
                images = renderer.render_layers(seed)
                image = images["combined"]
                added = add_layered_pass(run.stats, run.layers, images, seed, on_nan, progress.warning)
            else:
                image = renderer.render(seed)
                if start_next is not None and index + 1 < len(seeds):
                    start_next(seeds[index + 1])
                added = add_pass(run.stats, image, seed, on_nan, progress.warning)
        except wc.WelchInputError as exc:
            # --on-nan answers non-finite pixels only: another size or layer set is no pass of this run
            hint = " (use --on-nan skip or keep to go on)" if "non-finite" in str(exc) else ""
            raise RunError(f"{exc}{hint}") from None
        if added and pass_images is not None:
            save_pass_image(pass_images, seed, image, renderer.pass_file)
        if added:
            # A command's first pass may have been rendered earlier, to learn the image size: its time counts.
            seconds = time.perf_counter() - start + getattr(renderer, "replayed_seconds", 0.0)
            yield Arrival((seed,), seconds=(seconds,))


class StopRequest:
    """Note Ctrl-C (SIGINT) and SIGTERM (a cancel from the add-on, a job scheduler) and stop between passes, so
    the checkpoint is written. Raising from the handler itself could land inside Blender's render operator,
    which swallows the exception and goes on rendering."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self._requested = False
        self._old: dict = {}

    @property
    def requested(self) -> bool:
        """Whether a stop was asked for: a signal while active, or one before that a library swallowed (the
        command line's `batch.jobs.protocol.Interrupts` noted it)."""
        return self._requested or protocol.Interrupts.pending()

    def __enter__(self) -> StopRequest:
        # A signal the process was told to ignore (a Dask worker's render) it goes on ignoring.
        self._old = protocol.take_signals(self.SIGNALS, self._note)
        return self

    def _note(self, _signum, _frame) -> None:
        self._requested = True

    def __exit__(self, *exc) -> bool:
        protocol.give_back_signals(self._old)
        return False
