"""``check``: render both sides in interleaved chunks and stop as soon as the data decide.

Each side is a render job served by its own process (``render --serve``: the scene stays loaded, the passes come
in chunks asked for on stdin), so the two sides may be two scenes, two settings or two Blender builds. After every
chunk both statistics files are read and `welch_core.looks.sequential_look` decides: `biased` or `equivalent`
stop the run; at the budget it ends `inconclusive`, saying which bias it rules out. The looks are recorded in
``check.json`` next to the statistics, so an interrupted check continues with ``--resume`` exactly where it
stopped (the boundaries are recomputed from the recorded looks).

Nothing here imports bpy.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError
from ..jobs import protocol
from ..jobs.job import RenderJob
from ..jobs.launch import JobProcess, job_command
from ..jobs.protocol import Exit
from ..present.progress import Progress

STATE_FILE = "check.json"
STATE_VERSION = 1

#: Passes a side when neither --max-passes nor --max-seconds is given.
DEFAULT_MAX_PASSES = 512


@dataclass(frozen=True)
class CheckJob:
    """A check: the two sides' render jobs (their seeds are the most either may render), the budget (passes a
    side, or render seconds: then the pass budget is fixed from the speed of the first chunk), the verdicts'
    alpha and tolerance, and the output folder."""

    reference: RenderJob
    test: RenderJob
    out: str
    max_passes: int | None = DEFAULT_MAX_PASSES
    max_seconds: float | None = None
    alpha: float = 0.01
    tolerance: float | None = 0.01
    equivalence_tile: int | None = None  # claim `equivalent` at this tile size (default: the finest)
    resume: bool = False
    #: The reference is a finished statistics file (a suite's blessed reference), not rendered: only the test
    #: side renders, and the looks' information fractions count its passes against the reference's fixed ones.
    fixed_reference: bool = False
    #: Render the passes on a Dask cluster (batch.distributed): local worker processes, or a running cluster.
    workers: int | None = None
    scheduler: str | None = None
    threads: int | None = None  # Cycles threads of each render process on the cluster (None: its default)

    def plan(self, max_passes: int) -> wc.SequentialPlan:
        return wc.SequentialPlan(
            max_passes=max_passes, alpha=self.alpha, tolerance=self.tolerance, equivalence_tile=self.equivalence_tile
        )

    @property
    def paired(self) -> bool:
        return self.reference.seeds == self.test.seeds

    def state_path(self) -> Path:
        return Path(self.out) / STATE_FILE


def sides_identical(reference: RenderJob, test: RenderJob) -> bool:
    """Both sides render the same scene the same way with the same seeds: every difference would be zero."""
    fields = (
        "blend",
        "scene",
        "blend_scene",
        "resolution",
        "device",
        "sampling_pattern",
        "overrides",
        "blender",
        "spp",
    )
    same = all(getattr(reference, f) == getattr(test, f) for f in fields)
    return same and reference.seeds == test.seeds


@dataclass
class _Side:
    name: str
    job: RenderJob
    process: JobProcess | None = None
    passes: int = 0
    progress: Progress | None = None  # its live line, on a terminal
    fixed: bool = False  # a finished statistics file: never rendered
    pool: object = None  # a batch.distributed.PassPool where the passes render on a cluster


class Check:
    """Runs a `CheckJob`; `run()` returns the final `Look` and the final statistics of both sides."""

    def __init__(self, job: CheckJob, progress):
        self.job = job
        self.progress = progress
        self.sides = [_Side("reference", job.reference, fixed=job.fixed_reference), _Side("test", job.test)]
        if progress.live:
            for side in self.sides:
                side.progress = Progress(len(side.job.seeds), label=side.name, live=True)
        self.looks: list[dict] = []
        self.plan = job.plan(job.max_passes) if job.max_passes else None
        self.render_seconds = 0.0
        self._cluster = None  # a LocalCluster both sides' pools share (--workers)

    # -- state on disk ---------------------------------------------------------------------------------------

    def _state(self) -> dict:
        return {
            "format": "welch-bias-check",
            "version": STATE_VERSION,
            "plan": dataclasses.asdict(self.plan),
            "max_seconds": self.job.max_seconds,
            "reference": self.job.reference.replace(resume=False).to_argv(),
            "test": self.job.test.replace(resume=False).to_argv(),
            "render_seconds": self.render_seconds,
            "looks": self.looks,
        }

    def _save_state(self) -> None:
        text = json.dumps(self._state(), indent=2, allow_nan=False, default=_json_default)
        wc.formats.atomic_write(self.job.state_path(), lambda f: f.write(text.encode()))

    def _load_state(self) -> None:
        path = self.job.state_path()
        try:
            state = json.loads(path.read_text())
        except FileNotFoundError:
            raise BatchError(f"nothing to resume: {path} does not exist") from None
        except (OSError, ValueError) as exc:
            raise BatchError(f"{path} is not a readable check state ({exc})") from None
        if not isinstance(state, dict) or state.get("format") != "welch-bias-check":
            raise BatchError(f"{path} is not a check state file")
        for side in self.sides:
            if state.get(side.name) != side.job.replace(resume=False).to_argv():
                raise BatchError(f"can't resume {self.job.out}: the {side.name} side was started with other arguments")
        try:
            stored = wc.SequentialPlan(**state["plan"])
        except (KeyError, TypeError, wc.WelchInputError) as exc:
            raise BatchError(f"{path} is not a readable check state ({exc})") from None
        if self.job.plan(stored.max_passes) != stored or state.get("max_seconds") != self.job.max_seconds:
            raise BatchError(f"can't resume {self.job.out}: it was started with another budget, alpha or tolerance")
        self.plan = stored
        self.looks = list(state.get("looks", []))
        self.render_seconds = float(state.get("render_seconds", 0.0))

    # -- the sides -------------------------------------------------------------------------------------------

    def _start(self) -> None:
        for side in self.sides:
            if Path(side.job.out).exists():  # resumed (or fixed): the passes already in the file count
                side.passes = wc.load_stats(side.job.out, pixels=False).n
            elif side.fixed:
                raise BatchError(f"the reference {side.job.out} does not exist")
            if side.fixed:
                continue
            if self.job.workers or self.job.scheduler:
                side.pool = self._pool(side.job)
                if side.progress is not None:
                    side.progress.start(side.passes, side.job.out)
            else:
                side.process = JobProcess(job_command(side.job, serve=True), requests=True)

    def _pool(self, job: RenderJob):
        """A pass pool for one side; with local workers both sides share one cluster (started with the first)."""
        from ..jobs import distributed

        if self.job.scheduler:
            return distributed.PassPool(job, scheduler=self.job.scheduler, threads=self.job.threads)
        if self._cluster is None:
            self._cluster = distributed.local_cluster(self.job.workers)
        threads = distributed.local_threads(self.job.workers)
        return distributed.PassPool(job, scheduler=self._cluster.scheduler_address, threads=threads)

    def _stop(self) -> None:
        for side in self.sides:
            if side.process is not None:
                side.process.stop()
        self._close_pools()

    def _close_pools(self) -> None:
        for side in self.sides:
            if side.pool is not None:
                side.pool.close()
                side.pool = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def _finish(self) -> None:
        self._close_pools()
        for side in self.sides:
            if side.process is not None:
                side.process.close_requests()
        for side in self.sides:
            if side.process is not None:
                code = side.process.wait(60)
                self._relay(side)
                if code not in (0, None):
                    self._failed(side, code)

    def _render_to(self, passes: int) -> None:
        """Both sides up to `passes` passes (at once: the sides share the machine, the chunk takes the longer)."""
        start = time.perf_counter()
        if self.job.workers or self.job.scheduler:
            self._render_on_pools(passes)
            self.render_seconds += time.perf_counter() - start
            return
        waiting = []
        for side in self._rendered():
            if side.passes < passes:
                side.process.request(passes - side.passes)
                waiting.append(side)
        while waiting:
            for side in list(waiting):
                saved = self._relay(side)
                if saved is not None:
                    side.passes = saved
                    waiting.remove(side)
                    continue
                code = side.process.popen.poll()
                if code is not None:
                    self._relay(side)
                    self._failed(side, code)
            if waiting:
                time.sleep(0.005)
        self.render_seconds += time.perf_counter() - start

    def _render_on_pools(self, passes: int) -> None:
        """Both sides up to `passes` passes on the cluster: every chunk of both submitted first, so they render at
        once; each side's file saved in seed order, as one process saves it."""
        from ..jobs import distributed

        waiting = [side for side in self._rendered() if side.passes < passes]
        for side in waiting:
            seeds = list(side.job.seeds[side.passes : passes])
            size = distributed.default_chunk(len(seeds), side.pool.parallelism() or 1)
            for first in range(0, len(seeds), size):
                side.pool.submit(seeds[first : first + size])
        for side in waiting:
            stats = wc.load_stats(side.job.out) if Path(side.job.out).exists() else None
            for result in side.pool:
                stats = distributed.accumulate(stats, result, side.job)
                for message in result.warnings:
                    self.progress.warning(f"{side.name}: {result.worker}: {message}")
                if side.progress is not None:
                    for seed in result.seeds:
                        side.progress.pass_done(seed, result.wall_seconds / max(len(result.seeds), 1))
            side.passes = distributed.save_in_seed_order(side.job, stats).n

    def _rendered(self) -> list[_Side]:
        return [side for side in self.sides if not side.fixed]

    def _fraction(self, passes: int) -> float:
        fixed = self.sides[0].passes if self.job.fixed_reference else None
        return wc.looks.information_fraction(passes, self.plan.max_passes, fixed)

    def _relay(self, side: _Side) -> int | None:
        """Show the side's events (its passes on its own live line, where there is a terminal); the pass count of
        its last `Saved` event, if any arrived."""
        saved = None
        for event in side.process.drain():
            if isinstance(event, protocol.Saved):
                saved = event.passes
            elif isinstance(event, protocol.Warned):
                self.progress.warning(f"{side.name}: {event.message}")
            elif side.progress is not None and isinstance(event, protocol.Started | protocol.PassDone):
                side.progress.emit(event)
        return saved

    def _failed(self, side: _Side, code: int) -> None:
        reason = side.process.error_message() or "no error message"
        self._stop()
        if code == Exit.USAGE:
            raise BatchError(f"{side.name} side: {reason}")
        if protocol.interrupted(code):
            raise KeyboardInterrupt
        raise RuntimeError(f"the {side.name} side's render failed (exit code {code}): {reason}")

    def _load(self) -> tuple[wc.TileStats, wc.TileStats]:
        return wc.load_stats(self.job.reference.out), wc.load_stats(self.job.test.out)

    # -- the looks -------------------------------------------------------------------------------------------

    def _fix_budget(self) -> None:
        """A time budget becomes a pass budget once the first chunk shows the speed (the looks' information
        fractions need it, and it must not change afterwards)."""
        done = min(s.passes for s in self._rendered())
        seconds_per_pass = self.render_seconds / max(done, 1)
        left = self.job.max_seconds - self.render_seconds
        passes = done + int(left / max(seconds_per_pass, 1e-9))
        self.plan = self.job.plan(min(max(passes, wc.looks.FIRST_LOOK), len(self.job.test.seeds)))

    def run(self) -> tuple[wc.Look, wc.TileStats, wc.TileStats]:
        if self.job.resume:
            self._load_state()
        self._start()
        try:
            result = self._loop()
        except BaseException:
            self._stop()
            if self.plan is not None:
                self._save_state()
            raise
        self._finish()
        self._save_state()
        return result

    def _loop(self):
        done = max([look["passes"] for look in self.looks] + [min(s.passes for s in self._rendered())])
        fractions = [look["fraction"] for look in self.looks]
        if self.looks and self.looks[-1]["verdict"] is not None:
            # Decided already (a resumed check): answer with that decision; another look would be one more peek.
            ref, test = self._load()
            n = self.looks[-1]["passes"]
            ref, test = (ref if self.job.fixed_reference else self._at(ref, n)), self._at(test, n)
            return wc.sequential_look(ref, test, self.plan, fractions, final=True), ref, test
        if self.plan is None:
            self._render_to(wc.looks.FIRST_LOOK)
            self._fix_budget()
        schedule = [n for n in wc.look_schedule(self.plan.max_passes) if n > done]
        deadline = None if self.job.max_seconds is None else self.job.max_seconds
        look = None
        for index, n in enumerate(schedule):
            out_of_time = deadline is not None and self.render_seconds >= deadline
            if out_of_time:
                break
            self._render_to(n)
            ref, test = self._load()
            n = min(ref.n, test.n) if not self.job.fixed_reference else test.n
            fractions.append(self._fraction(n))
            look = wc.sequential_look(ref, test, self.plan, fractions)
            self.looks.append(_look_record(look, self.render_seconds))
            self._save_state()
            bound = look.ruled_out if math.isfinite(look.ruled_out) else None
            verdict = look.verdict.text if look.verdict is not None else None
            self.progress.emit(
                protocol.Looked(
                    passes=n,
                    p_value=look.p_value,
                    threshold=look.threshold,
                    ruled_out=bound,
                    verdict=verdict,
                    left=len(schedule) - index - 1,
                    seconds=self.render_seconds,
                )
            )
            if look.verdict is not None:
                return look, ref, test
        ref, test = self._load()
        if not fractions:  # nothing looked at (resumed after the last look): the first look on what is there
            fractions = [self._fraction(min(ref.n, test.n))]
        # The budget is spent (or the time): the last look, as the final one.
        return wc.sequential_look(ref, test, self.plan, fractions, final=True), ref, test

    @staticmethod
    def _at(run: wc.TileStats, n: int) -> wc.TileStats:
        """The run as it was at a look of `n` passes (a side may hold more: rendered after the look)."""
        return run if run.n <= n else run.subset(range(n))


def _look_record(look: wc.Look, seconds: float) -> dict:
    outcome = look.outcome
    record = {
        "passes": look.passes,
        "fraction": look.fraction,
        "verdict": look.verdict.label if look.verdict is not None else None,
        "p_value": look.p_value,
        "threshold": look.threshold,
        "crossed": look.crossed,
        "ruled_out": look.ruled_out,
        "ruled_out_tile": look.ruled_out_tile,
        "whole_image": outcome.whole_image.to_json() if outcome.whole_image is not None else None,
        "uncovered": look.uncovered,
        "seconds": seconds,
    }
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in record.items()}


def _json_default(value):
    raise TypeError(f"not JSON: {type(value).__name__}")


def run_check(job: CheckJob, progress) -> tuple[wc.Verdict, dict]:
    """Run `job` and write its report into ``job.out``: the verdict and the report's content. The verdict and its
    numbers are the last look's; the map and the tiles are the final passes' statistics (descriptive)."""
    from ..present.pipeline import present
    from ..present.summary import check_record

    Path(job.out).mkdir(parents=True, exist_ok=True)
    check = Check(job, progress)
    look, ref, test = check.run()
    comparison = wc.compare(ref, test, job.alpha, tolerance=job.tolerance)
    layers = (wc.load_layers(job.reference.out, pixels=False), wc.load_layers(job.test.out, pixels=False))
    record = check_record(job, check.looks, check.plan.max_passes, look)
    report = present(job.out, comparison, ref, test, outcome=look.outcome, check=record, layers=layers)
    return look.outcome.verdict, report


#: Seeds a side may use under a time budget (the pass budget is fixed once the speed is known).
MAX_SEEDS_FOR_SECONDS = 100_000


def check_job_from_args(args) -> CheckJob:
    """The check the command line describes, refused in one line where it can't work, before anything renders."""
    if args.max_passes is not None and args.max_seconds is not None:
        raise BatchError("give --max-passes or --max-seconds, not both")
    if args.max_passes is not None and args.max_passes < wc.looks.FIRST_LOOK:
        raise BatchError(f"--max-passes must be at least {wc.looks.FIRST_LOOK}, got {args.max_passes}")
    if args.max_seconds is not None and not args.max_seconds > 0:
        raise BatchError(f"--max-seconds must be a positive number of seconds, got {args.max_seconds:g}")
    if args.blend is not None and args.scene is not None:
        raise BatchError(f"give a .blend file or a built-in scene, not both ({args.blend}, {args.scene!r})")
    if args.blend is None and args.scene is None:
        raise BatchError("no scene to check: give a .blend file or a built-in scene (--scene)")
    for option, path in (("SCENE.blend", args.blend), ("--test-blend", args.test_blend)):
        if path is not None and not Path(path).is_file():
            raise BatchError(f"{option} {path}: no such file")
    max_passes = None if args.max_seconds is not None else (args.max_passes or DEFAULT_MAX_PASSES)
    count = max_passes or MAX_SEEDS_FOR_SECONDS
    same_build = (args.test_blender or args.blender) == args.blender
    paired = same_build and not args.unpaired
    ref_seeds = range(count)
    test_seeds = ref_seeds if paired else range(count, 2 * count)
    out = Path(args.out)
    common = {
        "spp": args.spp,
        "tile": args.tile,
        "resolution": tuple(args.resolution) if args.resolution else None,
        "device": args.device,
        "sampling_pattern": args.sampling_pattern,
        "resume": args.resume,
        "checkpoint_every": count,  # saved after every chunk anyway
        "lobes": args.lobes,
    }
    reference = RenderJob(
        out=str(out / "reference.npz"),
        seeds=tuple(ref_seeds),
        blend=args.blend,
        scene=args.scene,
        blend_scene=args.blend_scene,
        blender=args.blender,
        **common,
    )
    test = RenderJob(
        out=str(out / "test.npz"),
        seeds=tuple(test_seeds),
        blend=args.test_blend or args.blend,
        scene=None if args.test_blend else args.scene,
        blend_scene=args.test_blend_scene or (None if args.test_blend else args.blend_scene),
        blender=args.test_blender or args.blender,
        overrides=tuple(args.overrides),
        **common,
    )
    if sides_identical(reference, test):
        raise BatchError(
            "the two sides are identical by construction (same scene, build, settings and seeds): every difference "
            "would be zero; give --set, --test-blend or --test-blender, or --unpaired for an A/A check"
        )
    if not args.resume:
        for job in (reference, test):
            if Path(job.out).exists():
                raise BatchError(f"{job.out} already exists: pass --resume to continue the check, or another --out")
    return CheckJob(
        reference=reference,
        test=test,
        out=str(out),
        max_passes=max_passes,
        max_seconds=args.max_seconds,
        alpha=args.alpha,
        tolerance=args.tolerance,
        equivalence_tile=args.equivalence_tile,
        resume=args.resume,
    )
