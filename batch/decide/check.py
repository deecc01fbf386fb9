"""``check``: render both sides in interleaved chunks and stop as soon as the data decide.

Each side is a render job served by its own process (``render --serve``: the scene stays loaded, the passes come
in chunks asked for on stdin), so the two sides may be two scenes, two settings or two Blender builds. After every
chunk both statistics files are read and `welch_core.looks.sequential_look` decides: `biased` or `equivalent`
stop the run; at the budget it ends `inconclusive`, saying which bias it rules out. A time budget bounds the
render seconds: a pass still rendering `BUDGET_MARGIN` seconds after it is spent is stopped (its render
process's group ended), and the check ends with the verdict on the passes before it. The looks are recorded in
``check.json`` next to the statistics, so an interrupted check continues with ``--resume`` exactly where it
stopped (the boundaries are recomputed from the recorded looks).

Nothing here imports bpy.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError, Undecided
from ..jobs import protocol
from ..jobs.distributed import Cluster, ClusterSide, cluster
from ..jobs.job import RenderJob
from ..jobs.options import TEST_SIDE, default
from ..jobs.pairs import PixelPairs
from ..jobs.samples import BUILTIN, AutoSamples, SceneSamples, auto_samples, side_settings
from ..jobs.seeds import MAX_PASSES, parse_seeds
from ..jobs.side import Side, probe_scenes
from ..present import fmt
from ..present.progress import Progress

STATE_FILE = "check.json"
STATE_VERSION = 2  # 2: the budget apart from the plan, and the plan's alpha reserve for a grown budget

#: A check that ended with one of these stopped on its evidence: resuming it answers with that verdict.
DECIDED = ("biased", "equivalent")

#: The seeds of an unpaired check's test side start here, whatever the budget (the reference's start at 0): a
#: grown budget extends both sides' seeds and they never overlap.
UNPAIRED_SEEDS = MAX_PASSES  # --max-passes is at most this

#: Passes a side when neither --max-passes nor --max-seconds is given.
DEFAULT_MAX_PASSES = default("max_passes", "check")

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
    #: The fewest passes a side a time budget renders, whatever their seconds (None: none; a check whose budget
    #: ends its first passes then ends `inconclusive`, too few to look at): a scene whose first pass builds much
    #: (Cycles 5's volume octree) still gets a few passes.
    min_passes: int | None = None
    alpha: float = default("alpha", "check")
    tolerance: float | None = default("tolerance", "check")
    equivalence_tile: int | None = None  # claim `equivalent` at this tile size (default: sized for the budget)
    futility: bool = True  # stop once neither claim is within the budget's reach (welch_core.decision)
    pixel_variance: str = default("pixel_variance", "check")  # the pixel-variance test (welch_core.pixels)
    resume: bool = False
    #: The reference is a finished statistics file (a suite's blessed reference), not rendered: only the test
    #: side renders, and the looks' information fractions count its passes against the reference's fixed ones.
    fixed_reference: bool = False
    #: Render the passes on a Dask cluster (batch.jobs.distributed): local worker processes, or a running cluster.
    workers: int | None = None
    scheduler: str | None = None
    seed_offset: int = 0  # both sides' seeds shifted by it (--seed-offset): another, independent check
    auto_samples: dict | None = None  # why --spp auto renders more than 1 sample a pass (`AutoSamples.to_json`)

    def plan(self, max_passes: int, early_share: float | None = None, started: dict | None = None) -> wc.SequentialPlan:
        """The design for `max_passes`; a resumed check keeps the early share it was started with (None: the
        default), and one `started` (its stored plan) before the pixel-variance test existed goes on without it."""
        early = {} if early_share is None else {"early_share": early_share}
        pixels = "off" if started is not None and "pixel_variance" not in started else self.pixel_variance
        return wc.SequentialPlan(
            max_passes=max_passes,
            alpha=self.alpha,
            tolerance=self.tolerance,
            equivalence_tile=self.equivalence_tile,
            futility=self.futility,
            pixel_variance=pixels,
            **early,
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
        "python",
        "spp",
        "command",
        "command_dir",
    )
    same = all(getattr(reference, f) == getattr(test, f) for f in fields)
    return same and reference.seeds == test.seeds


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
        self._clock: float | None = None  # since when the wall clock runs uncounted (None: not running)
        self.last_look: tuple | None = None  # (the last look, both sides' statistics then): a live view's
        self.pairs: PixelPairs | None = None  # each pixel's difference per seed (paired, `batch.jobs.pairs`)
        self.pixel_pairs: wc.PixelMoments | None = None  # their moments at the last look
        #: the size of the `equivalent` claim, chosen for the budget at its sizing look (`welch_core.sizing`) and
        #: kept from then on (None: not chosen yet, or the user's --equivalence-tile, which the plan holds)
        self.claim_tile: int | None = None
        self.ended_pass: str | None = None  # what the time budget ended, in a sentence (None: it ended nothing)

    # -- state on disk ---------------------------------------------------------------------------------------

    def _state(self) -> dict:
        return {
            "format": "welch-bias-check",
            "version": STATE_VERSION,
            "plan": dataclasses.asdict(self.plan) if self.plan is not None else None,
            "budget": self.budget,
            "max_seconds": self.job.max_seconds,
            "min_passes": self.job.min_passes,
            "reference": _side_record(self.job.reference),
            "test": _side_record(self.job.test),
            "render_seconds": self.render_seconds,
            "side_seconds": self.side_seconds,
            "wall_seconds": self.wall_seconds,
            "claim_tile": self.claim_tile,
            "ended_pass": self.ended_pass,
            "looks": self.looks,
        }

    def _save_state(self) -> None:
        if self._clock is not None:
            now = time.monotonic()
            self.wall_seconds, self._clock = self.wall_seconds + now - self._clock, now
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
        if state.get("version") != STATE_VERSION:
            raise BatchError(
                f"{path} was written by another version of this tool (check state {state.get('version')!r}, this one "
                f"reads {STATE_VERSION}): start the check again with another --out"
            )
        grown = []  # the sides whose seeds were extended (a grown budget)
        for side in (self.reference, self.test):
            stored_record, record = state.get(side.name), _side_record(side.job)
            if stored_record != record:
                if not _reseeded(stored_record, record):
                    raise BatchError(_not_resumable(self.job.out, side.name, stored_record, record))
                grown.append(side.name)
        stored = None
        if state.get("plan") is not None:  # None: stopped before a time budget became a pass budget
            try:
                # a check started before the early design or the pixel-variance test existed goes on without them
                stored = wc.SequentialPlan(**{"early_share": 0.0, "pixel_variance": "off", **state["plan"]})
            except (KeyError, TypeError, wc.WelchInputError) as exc:
                raise BatchError(f"{path} is not a readable check state ({exc})") from None
        budget = state.get("budget") or (stored.max_passes if stored is not None else None)
        if stored is not None and state.get("max_seconds") is None and self.job.max_seconds is None:
            planned = self.job.plan(stored.max_passes, stored.early_share, state["plan"])  # the budget may grow
            if planned != stored:
                raise BatchError(
                    f"can't resume {self.job.out}: it was started with {_plan_difference(stored, planned)}"
                )
            if self.job.max_passes < budget:
                raise BatchError(
                    f"can't resume {self.job.out} with --max-passes {self.job.max_passes}: it has a budget of "
                    f"{budget} passes a side, which can grow but not shrink"
                )
            budget = self._grown_budget(stored, budget)
        else:
            planned = (
                self.job.plan(stored.max_passes, stored.early_share, state["plan"]) if stored is not None else None
            )
            floor = state.get("min_passes") != self.job.min_passes and self.job.max_seconds is not None
            if planned != stored or state.get("max_seconds") != self.job.max_seconds or grown or floor:
                raise BatchError(
                    f"can't resume {self.job.out}: it was started with another budget, alpha or tolerance"
                    + (" (the budget of a --max-seconds check does not grow: start it with --max-passes)"
                       if state.get("max_seconds") is not None and self.job.max_seconds is None else "")
                )  # fmt: skip
        self.budget = budget
        self.plan = stored
        self.looks = list(state.get("looks", []))
        self.render_seconds = float(state.get("render_seconds", 0.0))
        sides = state.get("side_seconds")
        known = isinstance(sides, dict) and all(isinstance(sides.get(k), (int, float)) for k in ("reference", "test"))
        self.side_seconds = {k: float(sides[k]) for k in ("reference", "test")} if known else None
        self.wall_seconds = float(state.get("wall_seconds", 0.0))
        claim = state.get("claim_tile")
        if claim is not None and (isinstance(claim, bool) or not isinstance(claim, int) or claim < 1):
            raise BatchError(f"{path} is not a readable check state (claim_tile {claim!r})")
        self.claim_tile = claim
        self.ended_pass = state.get("ended_pass")

    def _grown_budget(self, plan: wc.SequentialPlan, budget: int) -> int:
        """The budget a resumed check gets from --max-passes: the last look of the schedule it fits (the looks past
        the plan's last follow from the plan alone, not from the budget asked for)."""
        asked = self.job.max_passes
        if asked == budget:
            return budget
        fits = wc.look_schedule(plan.max_passes, budget=asked)[-1]
        if fits <= budget:
            after = wc.look_schedule(plan.max_passes, budget=10 * budget + 10)
            following = next(n for n in after if n > budget)
            raise BatchError(
                f"--max-passes {asked} adds no look to {self.job.out}: its next look is at {following} passes a side"
            )
        return fits

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
        self._save_state()

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
            self._load_state()
        elif self.job.reference.pass_images is not None:
            PixelPairs.clear(self.job.out)  # a new check: nothing of an earlier one in this folder counts
        self._clock = time.monotonic()
        if self.job.reference.pass_images is not None:
            self.pairs = PixelPairs(self.job.out)
        self._save_state()  # before anything renders: a check stopped at once can still be resumed
        try:
            self._start()
            result = yield from self._loop()
        except BaseException:  # an interrupt, an error, or the generator closed
            self._stop()
            self._save_state()
            raise
        self._finish()
        self._save_state()
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
            final = last.get("reason") != "futile"  # a futility stop is made again at the look where it was made
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
        self.looks.append(_look_record(look, self.render_seconds))
        self._save_state()
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


def _plan_difference(stored: wc.SequentialPlan, planned: wc.SequentialPlan) -> str:
    """What differs between the design a check was started with and the one asked for, named by option."""

    def shown(name: str, value) -> str:
        if name == "futility":
            return "the futility stop" if value else "--no-futility"
        if name == "equivalence_tile":
            return "the claim sized for the budget" if value is None else f"--equivalence-tile {value}"
        if name == "tolerance":
            return "--tolerance off" if value is None else f"--tolerance {100 * value:g}%"
        if name == "pixel_variance":
            return f"--pixel-variance {value}"
        return f"--{name} {value:g}"

    names = ("alpha", "tolerance", "equivalence_tile", "futility", "pixel_variance")
    differ = [n for n in names if getattr(stored, n) != getattr(planned, n)]
    return "; ".join(f"{shown(n, getattr(stored, n))}, not {shown(n, getattr(planned, n))}" for n in differ) or (
        "another design"
    )


def _side_record(job: RenderJob) -> list[str]:
    """What must stay the same for a side to be resumed: its job's arguments, its statistics file by its name in
    the check's folder (the folder may be given another way, or moved)."""
    return job.replace(resume=False, out=Path(job.out).name, pass_images=None).to_argv()


def _not_resumable(out: str, name: str, stored: list[str] | None, record: list[str]) -> str:
    """Why side `name` of the check in `out` can't be resumed with `record`: its seeds start elsewhere (another
    --seed-offset), or other arguments."""
    first = [_first_seed(r) for r in (stored, record)]
    if None not in first and first[0] != first[1]:
        why = "another --seed-offset" if name == "reference" else "another --seed-offset, or paired and unpaired"
        return f"can't resume {out}: its {name} side was started on seeds from {first[0]}, not {first[1]} ({why})"
    return f"can't resume {out}: the {name} side was started with other arguments"


def _first_seed(record: list[str] | None) -> int | None:
    """The first seed of a side's record (its arguments), or None."""
    if not isinstance(record, list) or "--seeds" not in record[:-1]:
        return None
    try:
        return parse_seeds(record[record.index("--seeds") + 1])[0]
    except ValueError:
        return None


def _reseeded(stored: list[str] | None, record: list[str]) -> bool:
    """Whether side `record` is side `stored` with its seeds' list made longer or shorter at the end (another
    budget)."""
    if not isinstance(stored, list) or len(stored) != len(record) or "--seeds" not in record:
        return False
    at = record.index("--seeds") + 1
    if stored[:at] != record[:at] or stored[at + 1 :] != record[at + 1 :]:
        return False
    try:
        before, after = parse_seeds(stored[at]), parse_seeds(record[at])
    except ValueError:
        return False
    common = min(len(before), len(after))
    return before[:common] == after[:common]


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
        "budget": outcome.budget,
        "reason": outcome.reason,
        "claim_tile": outcome.claim_tile,
        "promise": outcome.promise,
    }
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in record.items()}


def _json_default(value):
    raise TypeError(f"not JSON: {type(value).__name__}")


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


def report_check(check: Check, look: wc.Look, ref: wc.TileStats, test: wc.TileStats):
    """Write the report of a check's final look into its folder: (report.json's content, its
    `batch.present.pipeline.Assessment`: the comparison of the final passes that the map shows, the layers').
    `run_check` and the Blender add-on both end a check here."""
    from ..present.pipeline import assess, write
    from ..present.summary import check_record

    job = check.job
    layers = (wc.load_layers(job.reference.out, pixels=False), wc.load_layers(job.test.out, pixels=False))
    early = (check.plan.early, wc.looks.EARLY_PASSES)
    durations = {"wall": check.wall_seconds, "sides": check.side_seconds}
    record = check_record(job, check.looks, check.plan.max_passes, look, early, check.ended_pass, durations)
    comparison = look_comparison(job, ref, test, check.pixel_pairs, check.plan.pixel_variance)
    assessment = assess(comparison, ref, test, outcome=look.outcome, check=record, layers=layers)
    return write(job.out, assessment, ref, test), assessment


def look_comparison(job: CheckJob, ref, test, pairs=None, pixel_variance: str | None = None) -> wc.Comparison:
    """The fixed-design comparison of a look's passes (`pairs`: their pixels' paired differences, where kept;
    `pixel_variance`: the plan's, default the job's): what its map draws (descriptive; the look's own outcome is
    the verdict)."""
    pixels = pixel_variance or job.pixel_variance
    return wc.compare(ref, test, job.alpha, tolerance=job.tolerance, pixel_variance=pixels, pairs=pairs)


#: Seeds a side may use under a time budget (the pass budget is fixed once the speed is known).
MAX_SEEDS_FOR_SECONDS = 100_000


def _absolute(path: str | None) -> str | None:
    """A scene file's path as its sides record it: absolute, so a check resumed from another folder is the same."""
    return None if path is None else os.path.abspath(path)


@dataclass(frozen=True)
class CheckRequest:
    """What a check is asked for, as the command line (``check``'s arguments: `from_args`) and the Blender add-on
    give it, values already checked; `check_job` makes the check of it. The defaults are the command line's
    (`batch.jobs.options`)."""

    out: str
    blend: str | None = None
    scene: str | None = None
    blend_scene: str | None = None
    test_blend: str | None = None
    test_blend_scene: str | None = None
    overrides: tuple[str, ...] = ()
    spp: int | None = default("spp", "check")  # None: auto (`batch.jobs.samples.auto_samples`)
    tile: int = default("tile", "check")
    resolution: tuple[int, int] | None = None
    device: str = default("device", "check")
    sampling_pattern: str | None = None
    lobes: tuple[str, ...] = default("lobes", "check")
    test_spp: int | None = None
    test_device: str | None = None
    test_sampling_pattern: str | None = None
    blender: str | None = None
    python: str | None = None
    test_blender: str | None = None
    test_python: str | None = None
    pass_command: str | None = None
    test_command: str | None = None
    command_dir: str | None = None
    max_passes: int | None = None  # None: DEFAULT_MAX_PASSES, unless max_seconds is given
    max_seconds: float | None = None
    min_passes: int | None = None
    alpha: float = default("alpha", "check")
    tolerance: float | None = default("tolerance", "check")
    equivalence_tile: int | None = None
    futility: bool = True
    pixel_variance: str = default("pixel_variance", "check")
    unpaired: bool = False
    seed_offset: int = default("seed_offset", "check")
    resume: bool = False
    workers: int | None = None
    scheduler: str | None = None

    @classmethod
    def from_args(cls, args) -> CheckRequest:
        """The request of ``check``'s parsed command line."""
        return cls(**{f.name: getattr(args, f.name) for f in dataclasses.fields(cls)})


def check_job_from_args(args) -> CheckJob:
    """The check the command line describes (`check_job` of its `CheckRequest`)."""
    return check_job(CheckRequest.from_args(args))


def check_job(request: CheckRequest, probe=None) -> CheckJob:
    """The check `request` describes, refused in one line where it can't work, before anything renders. `probe`
    reads what scene files ask of the passes for ``--spp auto`` (default `batch.jobs.side.probe_scenes`: a process
    of each side's build opens its file; the add-on reads its own scenes)."""
    args = request
    if args.blend is not None and args.scene is not None:
        raise BatchError(f"give a .blend file or a built-in scene, not both ({args.blend}, {args.scene!r})")
    if args.test_command and not args.pass_command:
        raise BatchError("--test-command needs --command: the reference side's passes are rendered the same way")
    if args.blend is None and args.scene is None and not args.pass_command:
        raise BatchError("no scene to check: give a .blend file or a built-in scene (--scene), or --command")
    for option, path in (("SCENE.blend", args.blend), ("--test-blend", args.test_blend)):
        if path is not None and not Path(path).is_file():
            raise BatchError(f"{option} {path}: no such file")
    max_passes = None if args.max_seconds is not None else (args.max_passes or DEFAULT_MAX_PASSES)
    if args.min_passes is not None and args.max_seconds is None:
        raise BatchError("--min-passes is the floor of a time budget: give --max-seconds too (without it every pass "
                         "of --max-passes renders)")  # fmt: skip
    if args.min_passes is not None and args.max_passes is not None and args.min_passes > args.max_passes:
        raise BatchError(f"--min-passes {args.min_passes} is more than --max-passes {args.max_passes}")
    # A time budget renders at most --max-passes where given too (whichever ends first): its pass budget, fixed from
    # the speed of the first chunk, is at most the seeds a side has.
    count = args.max_passes or max_passes or MAX_SEEDS_FOR_SECONDS
    if (args.blender and args.python) or (args.test_blender and args.test_python):
        raise BatchError("give a side's build as a Blender binary or as a Python with bpy, not both (--blender or "
                         "--python; --test-blender or --test-python)")  # fmt: skip
    # The test side's build: its own, else the reference's (a binary given to one side is not the other's Python).
    test_blender = args.test_blender or (None if args.test_python else args.blender)
    test_python = args.test_python or (None if args.test_blender else args.python)
    same_build = test_blender == args.blender and test_python == args.python and (
        args.test_command or args.pass_command
    ) == args.pass_command  # fmt: skip
    paired = same_build and not args.unpaired
    offset = args.seed_offset
    ref_seeds = range(offset, offset + count)
    test_seeds = ref_seeds if paired else range(UNPAIRED_SEEDS + offset, UNPAIRED_SEEDS + offset + count)
    out = Path(args.out)
    common = {
        "spp": args.spp or 1,  # auto: resolved below
        "tile": args.tile,
        "resolution": tuple(args.resolution) if args.resolution else None,
        "device": args.device,
        "sampling_pattern": args.sampling_pattern,
        "resume": args.resume,
        "checkpoint_every": MAX_PASSES,  # saved after every chunk anyway (and the same whatever the budget)
        "lobes": args.lobes,
        "command_dir": str(Path(args.command_dir or ".").resolve()) if args.pass_command else None,
    }
    reference = RenderJob(
        out=str(out / "reference.npz"),
        seeds=tuple(ref_seeds),
        blend=_absolute(args.blend),
        scene=args.scene,
        blend_scene=args.blend_scene,
        blender=args.blender,
        python=args.python,
        command=args.pass_command,
        **common,
    )
    own = {dest: value for dest in TEST_SIDE if (value := getattr(args, f"test_{dest}", None)) is not None}
    test = RenderJob(
        out=str(out / "test.npz"),
        seeds=tuple(test_seeds),
        blend=_absolute(args.test_blend or args.blend),
        scene=None if args.test_blend else args.scene,
        blend_scene=args.test_blend_scene or (None if args.test_blend else args.blend_scene),
        blender=test_blender,
        python=test_python,
        overrides=tuple(args.overrides),
        command=args.test_command or args.pass_command,
        **(common | own),
    )
    if sides_identical(reference, test):
        raise BatchError(
            "the two sides are identical by construction (same scene, build, settings and seeds): every difference "
            "would be zero; give --set, --test-blend, --test-blender, --test-command or a --test- setting such as "
            "--test-sampling-pattern, or --unpaired for an A/A check"
        )
    if not args.resume:
        for job in (reference, test):
            if Path(job.out).exists():
                raise BatchError(f"{job.out} already exists: pass --resume to continue the check, or another --out")
    auto = AutoSamples(args.spp) if args.spp is not None else _auto_samples(reference, test, probe)
    reference = reference.replace(spp=auto.spp)
    test = test.replace(spp=own.get("spp", auto.spp))
    if paired and args.pixel_variance != "off" and args.workers is None and args.scheduler is None:
        # Each side also writes its passes' images: the pixel test of paired runs needs each pixel's difference.
        reference = reference.replace(pass_images=PixelPairs.folder(out, "reference"))
        test = test.replace(pass_images=PixelPairs.folder(out, "test"))
    return CheckJob(
        reference=reference,
        test=test,
        out=str(out),
        max_passes=max_passes,
        max_seconds=args.max_seconds,
        min_passes=args.min_passes,
        alpha=args.alpha,
        tolerance=args.tolerance,
        equivalence_tile=args.equivalence_tile,
        futility=args.futility,
        pixel_variance=args.pixel_variance,
        resume=args.resume,
        workers=args.workers,
        scheduler=args.scheduler,
        seed_offset=offset,
        auto_samples=auto.to_json(),
    )


def _auto_samples(reference: RenderJob, test: RenderJob, probe=None) -> AutoSamples:
    """``--spp auto`` (`batch.jobs.samples.auto_samples`): what each side's scene asks of the passes (a built-in
    scene's is known; each scene file is read once, by `probe`), with the test side's pattern and overrides.
    Another renderer's passes (``--command``) take 1 sample."""
    if reference.command is not None:
        return AutoSamples(1)
    files = {}  # each scene file by what reads it: the file, its scene and the build
    for name, job in (("reference", reference), ("test", test)):
        if job.scene is None:
            read = job.replace(seeds=(0,), spp=1, overrides=(), sampling_pattern=None, lobes=(), pass_images=None)
            files.setdefault((job.blend, job.blend_scene, job.blender, job.python), (name, read))
    found = dict(zip(files, (probe or probe_scenes)(list(files.values())), strict=True))
    scenes: list[SceneSamples] = [
        BUILTIN if job.scene is not None else found[(job.blend, job.blend_scene, job.blender, job.python)]
        for job in (reference, test)
    ]
    settings = [
        side_settings(scene, job.sampling_pattern, job.overrides)
        for scene, job in zip(scenes, (reference, test), strict=True)
    ]
    return auto_samples(*scenes, *settings)
