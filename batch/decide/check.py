"""``check``: render both sides in interleaved chunks and stop as soon as the data decide.

Each side is a render job served by its own process (``render --serve``: the scene stays loaded, the passes come
in chunks asked for on stdin), so the two sides may be two scenes, two settings or two Blender builds. After every
chunk both statistics files are read and `welch_core.looks.sequential_look` decides: `biased` or `equivalent`
stop the run; at the budget it ends `inconclusive`, saying which bias it rules out. A time budget bounds the
render seconds: a pass still rendering `BUDGET_MARGIN` seconds after it is spent is stopped (its render
process's group ended), and the check ends with the verdict on the passes before it. The looks are recorded in
``check.json`` next to the statistics, so an interrupted check continues with ``--resume`` exactly where it
stopped (the boundaries are recomputed from the recorded looks).

This module is the engine; what a check is (the request made into a job) is `batch.decide.check_job`, its state on
disk `batch.decide.check_state`, its report `batch.decide.check_report`.

Nothing here imports bpy.
"""

from __future__ import annotations

import contextlib
import math
import time
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError, Undecided
from ..jobs import protocol
from ..jobs.distributed import Cluster, ClusterSide, cluster
from ..jobs.job import RenderJob
from ..jobs.pairs import PixelPairs
from ..jobs.side import Side
from ..present import fmt
from ..present.progress import Progress
from . import check_state
from .check_job import CheckJob, CheckRequest, check_job, check_job_from_args
from .check_report import look_comparison, report_check

#: What the Blender add-on reaches through this module (`blender_addon._siblings.checking`): the request and the job
#: (`check_job`), the engine, and the report (`check_report`).
__all__ = ["Check", "CheckJob", "CheckRequest", "check_job", "check_job_from_args", "look_comparison", "report_check",
           "run_check"]  # fmt: skip

#: A check that ended with one of these stopped on its evidence: resuming it answers with that verdict.
DECIDED = ("biased", "equivalent")

#: Render seconds past a time budget (--max-seconds, a suite case's `seconds`) after which the passes still
#: rendering are stopped, their process groups ended. The looks are planned to spend the budget (`_fix_budget`),
#: and a chunk that starts before it is spent may end a little after it: a Cycles pass of a check takes well under
#: this, so an ordinary pass is let finish. A pass that runs on (a hung renderer; a pass longer than this, which
#: is stopped too) costs only itself: the passes before it are saved and the check ends with the verdict on them.
#: A few seconds, not a share of the budget: the budget is the promise, whatever its size.
BUDGET_MARGIN = 2.0

#: A check's floor (`CheckJob.min_passes`, ``--min-passes``) renders its passes whatever their seconds, up to this
#: many times the time budget: a renderer that hangs in them still ends (a pass of the floor then ends as one the
#: budget ends, and the check with it).
FLOOR_LIMIT = 10.0


class Check:
    """Runs a `CheckJob` (on `cluster`, a `batch.jobs.side.Cluster`, where given); `run()` returns the final
    `Look` and the final statistics of both sides."""

    def __init__(self, job: CheckJob, progress, cluster: Cluster | None = None, side_progress=None, env=None):
        self.job = job
        self.progress = progress

        def side(name: str, side_job: RenderJob) -> Side:
            # Each side's own events (its passes): to `side_progress(name)` where given (the Blender add-on),
            # else to a live line of its own on a terminal, or to a log's plain lines (its passes at most one
            # line every few seconds, and a line that often while a pass takes long); none for programs.
            if side_progress is not None:
                live = side_progress(name)
            elif getattr(progress, "json_lines", False):
                live = None
            else:
                live = Progress(len(side_job.seeds), label=name, live=progress.live, brief=True)
            if cluster is not None:
                return ClusterSide(name, side_job, cluster, live, warn=progress.warning)
            return Side(name, side_job, live, warn=progress.warning, env=env)

        self.reference, self.test = side("reference", job.reference), side("test", job.test)
        self.rendered = [self.test] if job.fixed_reference else [self.reference, self.test]
        self.looks: list[dict] = []
        self.plan = job.plan(job.max_passes) if job.max_passes else None
        # The passes a side it may render: the plan's, or more when a resumed check's budget grew (its looks past
        # the plan's last spend the alpha kept for them, `wc.looks.EXTENSION_RESERVE`).
        self.budget = job.max_passes
        self.render_seconds = 0.0  # both sides' passes together (what --max-seconds counts)
        # Each side's own render seconds (None: not known, a check started before they were kept) and the wall
        # clock seconds of the check's runs (resumed runs add theirs), for people: the sides render at once.
        self.side_seconds: dict[str, float] | None = {"reference": 0.0, "test": 0.0}
        self.wall_seconds = 0.0
        self.clock_since: float | None = None  # since when the wall clock runs uncounted (None: not running)
        self.last_look: tuple | None = None  # (the last look, both sides' statistics then): a live view's
        self.pairs: PixelPairs | None = None  # each pixel's difference per seed (paired, `batch.jobs.pairs`)
        self.pixel_pairs: wc.PixelMoments | None = None  # their moments at the last look
        #: the size of the `equivalent` claim, chosen for the budget at its sizing look (`welch_core.sizing`) and
        #: kept from then on (None: not chosen yet, or the user's --equivalence-tile, which the plan holds)
        self.claim_tile: int | None = None
        self.ended_pass: str | None = None  # what the time budget ended, in a sentence (None: it ended nothing)

    # -- the sides -------------------------------------------------------------------------------------------

    def _start(self) -> None:
        if self.job.fixed_reference:
            if not Path(self.reference.job.out).exists():
                raise BatchError(f"the reference {self.reference.job.out} does not exist")
            self.reference.passes = wc.load_stats(self.reference.job.out, pixels=False).n
        for side in self.rendered:
            side.start()

    def _stop(self) -> None:
        for side in self.rendered:  # every side told before any is waited for
            side.ask_to_stop()
        for side in self.rendered:
            side.stop()

    def _finish(self) -> None:
        for side in self.rendered:
            side.finish()

    def _render_to(self, passes: int):
        """Both sides up to `passes` passes (at once: the sides share the machine, the chunk takes the longer),
        yielding while they render. The render seconds are the passes' own (what `--max-seconds` counts): a render
        process's start-up, loading the scene once, is not a pass's. Passes within the floor (`min_passes`) are
        not ended by the time budget, only by `FLOOR_LIMIT` times it."""
        before = {side.name: side.render_seconds for side in self.rendered}
        for side in self.rendered:
            side.request(passes)
        waiting = list(self.rendered)
        while waiting:
            waiting = [side for side in waiting if not side.poll()]
            if waiting and self._past_budget(before, waiting, passes <= self._floor()):
                self._end_passes(before, waiting)
                return
            if waiting:
                yield
        for side in self.rendered:
            spent = side.render_seconds - before[side.name]
            self.render_seconds += spent
            if self.side_seconds is not None:
                self.side_seconds[side.name] += spent

    def _spent(self, before: dict[str, float], waiting: list[Side]) -> float:
        """The render seconds spent so far, with those of the passes rendering now (`before`: each side's render
        seconds when the chunk was asked for)."""
        rendered = sum(side.render_seconds - before[side.name] for side in self.rendered)
        return self.render_seconds + rendered + sum(side.running_seconds() for side in waiting)

    def _floor(self) -> int:
        """The passes a side the time budget does not end (0: none)."""
        return self.job.min_passes or 0 if self.job.max_seconds is not None else 0

    def _past_budget(self, before: dict[str, float], waiting: list[Side], floor: bool = False) -> bool:
        """Whether the passes rendering now have run `BUDGET_MARGIN` past the time budget (never without one);
        passes of the floor (`floor`), `FLOOR_LIMIT` times past it."""
        budget = self.job.max_seconds
        if budget is None:
            return False
        return self._spent(before, waiting) > (FLOOR_LIMIT * budget if floor else budget) + BUDGET_MARGIN

    def _end_passes(self, before: dict[str, float], waiting: list[Side]) -> None:
        """The time budget is spent: stop the passes still rendering (their sides end, the passes they saved stay
        theirs) and count the seconds they ran as spent, so that a resumed check knows its budget spent."""
        spent = self._spent(before, waiting)
        running = {side.name: side.running_seconds() for side in waiting}
        at_stop = {side.name: side.render_seconds - before[side.name] + running.get(side.name, 0.0)
                   for side in self.rendered}  # fmt: skip
        budget = fmt.duration(self.job.max_seconds)
        self.progress.warning(f"the time budget ({budget}) is spent: stopping the passes still rendering")
        for side in waiting:
            side.ask_to_stop()
        for side in waiting:
            side.end_pass()
        rendered = sum(side.render_seconds - before[side.name] for side in self.rendered)
        self.render_seconds = max(self.render_seconds + rendered, spent)
        if self.side_seconds is not None:
            for side in self.rendered:
                self.side_seconds[side.name] += max(side.render_seconds - before[side.name], at_stop[side.name])
        whose = f"the {waiting[0].name} side's pass" if len(waiting) == 1 else "the passes of both sides"
        self.ended_pass = (f"the time budget ({budget}) ended {whose} still rendering at {fmt.duration(spent)} of "
                           "render seconds")  # fmt: skip
        check_state.save(self)

    def _fraction(self, passes: int) -> float:
        fixed = self.reference.passes if self.job.fixed_reference else None
        return wc.looks.information_fraction(passes, self.plan.max_passes, fixed)

    def _load(self) -> tuple[wc.TileStats, wc.TileStats]:
        return wc.load_stats(self.job.reference.out), wc.load_stats(self.job.test.out)

    # -- the looks -------------------------------------------------------------------------------------------

    def _fix_budget(self) -> None:
        """A time budget becomes a pass budget once the first chunk shows the speed (the looks' information
        fractions need it, and it must not change afterwards)."""
        done = min(s.passes for s in self.rendered)
        # A pass of each side at its fastest so far: a side's first passes also build the scene's render data (2-3x
        # slower here). Too many passes planned only leaves alpha unspent when the time runs out (conservative);
        # too few would stop the check before its time.
        fastest = [min(s.pass_seconds) for s in self.rendered if s.pass_seconds]
        seconds_per_pass = sum(fastest) if fastest else self.render_seconds / max(done, 1)
        left = self.job.max_seconds - self.render_seconds
        passes = done + int(left / max(seconds_per_pass, 1e-9))
        self.plan = self.job.plan(min(max(passes, wc.looks.FIRST_LOOK, self._floor()), len(self.job.test.seeds)))
        self.budget = self.plan.max_passes

    def run(self) -> tuple[wc.Look, wc.TileStats, wc.TileStats]:
        """The whole check, blocking: (the final look, both sides' statistics)."""
        steps = self.steps()
        while True:
            try:
                next(steps)
            except StopIteration as done:
                return done.value
            time.sleep(0.005)

    def steps(self):
        """The check as a generator that never blocks: each step polls the sides once (or makes a look) and yields;
        it returns what `run` returns. Closing it (a Stop in the Blender add-on) stops the sides and keeps the
        state, as an interrupt does."""
        Path(self.job.out).mkdir(parents=True, exist_ok=True)
        if self.job.resume:
            check_state.resume(self)
        elif self.job.reference.pass_images is not None:
            PixelPairs.clear(self.job.out)  # a new check: nothing of an earlier one in this folder counts
        self.clock_since = time.monotonic()
        if self.job.reference.pass_images is not None:
            self.pairs = PixelPairs(self.job.out)
        check_state.save(self)  # before anything renders: a check stopped at once can still be resumed
        try:
            self._start()
            result = yield from self._loop()
        except BaseException:  # an interrupt, an error, or the generator closed
            self._stop()
            check_state.save(self)
            raise
        self._finish()
        check_state.save(self)
        return result

    def _loop(self):
        done = max([look["passes"] for look in self.looks] + [min(s.passes for s in self.rendered)])
        fractions = [look["fraction"] for look in self.looks]
        last = self.looks[-1] if self.looks else None
        stopped = last is not None and last["verdict"] == "inconclusive" and last.get("budget") == self.budget
        if last is not None and (
            last["verdict"] in DECIDED or stopped or (last["verdict"] is not None and done >= self.budget)
        ):
            # Decided already (a resumed check; a futility stop too, unless the budget grew), or its budget spent and
            # not grown: answer with that outcome; another look would be one more peek.
            ref, test = self._load()
            n = self.looks[-1]["passes"]
            ref, test = (ref if self.job.fixed_reference else self._at(ref, n)), self._at(test, n)
            final = (
                last.get("reason") != wc.VerdictReason.FUTILE
            )  # a futility stop is made again at the look where it was made
            return self._look(ref, test, fractions, final), ref, test
        deadline = None if self.job.max_seconds is None else self.job.max_seconds
        if self.plan is None:
            if self.ended_pass is None:  # (a resumed check whose budget ended its first passes renders no more)
                yield from self._render_to(wc.looks.FIRST_LOOK)
            self._fix_budget()
        schedule = [n for n in wc.look_schedule(self.plan.max_passes, budget=self.budget) if n > done]
        look, floor = None, self._floor()
        for index, n in enumerate(schedule):
            seen = self.looks[-1]["passes"] if self.looks else done
            if self.ended_pass is not None:
                break
            if deadline is not None and self.render_seconds >= deadline:
                if seen >= floor:
                    break
                n = floor  # the time is spent, the floor's passes are not: rendered, and looked at (the last look)
            elif seen < floor < n:
                yield from self._render_to(floor)  # the floor first: the budget does not end its passes
            if self.ended_pass is None:
                yield from self._render_to(n)
            if self.ended_pass is not None:
                break
            ref, test = self._load()
            n = min(ref.n, test.n) if not self.job.fixed_reference else test.n
            fractions.append(self._fraction(n))
            look = self._look(ref, test, fractions, index == len(schedule) - 1)
            if self.claim_tile is None and look.outcome.target_tile is not None:
                self.claim_tile = look.outcome.target_tile  # sized at this look: every later look keeps it
            self.looks.append(check_state.look_record(look, self.render_seconds))
            check_state.save(self)
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
            self.last_look = look, ref, test
            yield
            if look.verdict is not None:
                return look, ref, test
        few = [side for side in self.rendered if side.passes < wc.looks.FIRST_LOOK]
        if few and self.ended_pass is not None:  # the time budget ended the first passes
            counts = ", ".join(f"{side.passes} of the {side.name} side" for side in few)
            raise Undecided(f"{self.ended_pass}: too few passes to look at ({counts}; a look needs "
                            f"{wc.looks.FIRST_LOOK} a side)")  # fmt: skip
        # The budget is spent (or the time): the last look, as the final one, on the passes both sides have (a
        # chunk the time budget ended leaves the sides at other counts).
        ref, test = self._load()
        n = test.n if self.job.fixed_reference else min(ref.n, test.n)
        ref, test = (ref if self.job.fixed_reference else self._at(ref, n)), self._at(test, n)
        if n <= (self.looks[-1]["passes"] if self.looks else 0):
            return self._look(ref, test, fractions, True), ref, test
        # Passes no look saw (the time budget ended a chunk; a check stopped before its look and resumed): a look
        # of their own.
        fractions.append(self._fraction(n))
        look = self._look(ref, test, fractions, True)
        self.looks.append(check_state.look_record(look, self.render_seconds))
        check_state.save(self)
        self.last_look = look, ref, test
        return look, ref, test

    def _look(self, ref: wc.TileStats, test: wc.TileStats, fractions, final: bool) -> wc.Look:
        """The look at the sides' passes, with each pixel's paired differences where the check keeps them."""
        paired = self.pairs is not None and ref.seeds == test.seeds
        self.pixel_pairs = self.pairs.at(ref.seeds) if paired else None
        return wc.sequential_look(ref, test, self.plan, fractions, final=final, budget=self.budget,
                                  pairs=self.pixel_pairs, claim_tile=self.claim_tile)  # fmt: skip

    @staticmethod
    def _at(run: wc.TileStats, n: int) -> wc.TileStats:
        """The run as it was at a look of `n` passes (a side may hold more: rendered after the look)."""
        return run if run.n <= n else run.subset(range(n))


def run_check(job: CheckJob, progress, where: Cluster | None = None) -> tuple[wc.Verdict, dict]:
    """Run `job` and write its report into ``job.out``: the verdict and the report's content. The verdict and its
    numbers are the last look's; the map and the tiles are the final passes' statistics (descriptive). The passes
    render on `where` (a cluster a suite shares between its cases), else where the job's `workers` or
    `scheduler` say."""

    Path(job.out).mkdir(parents=True, exist_ok=True)
    work = 2 * (job.max_passes or wc.looks.FIRST_LOOK)  # the most passes both sides render
    local = cluster(job.workers, job.scheduler, work)
    with contextlib.nullcontext(where) if where is not None else local as place:
        check = Check(job, progress, place)
        look, ref, test = check.run()
    return look.outcome.verdict, report_check(check, look, ref, test)[0]
