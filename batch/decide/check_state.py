"""A check's state on disk, ``check.json`` in its folder: its plan, budget, seconds and looks, written (atomically)
before anything renders, after every look and on any stop, and read back by ``--resume``, which goes on exactly
where the check stopped (the boundaries are recomputed from the recorded looks) or refuses in one line where the
arguments would make it another check. The functions read and set the attributes of a running
`batch.decide.check.Check`.

Nothing here imports bpy.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path

from .._siblings import welch_core as wc
from ..errors import BatchError
from ..jobs.job import RenderJob
from ..jobs.options import OPTIONS
from ..jobs.seeds import parse_seeds

STATE_FILE = "check.json"
STATE_VERSION = 2  # 2: the budget apart from the plan, and the plan's alpha reserve for a grown budget


def state_path(out: str) -> Path:
    """The state file of the check whose folder is `out`."""
    return Path(out) / STATE_FILE


def record(check) -> dict:
    """What ``check.json`` holds of `check` now."""
    return {
        "format": "welch-bias-check",
        "version": STATE_VERSION,
        "plan": dataclasses.asdict(check.plan) if check.plan is not None else None,
        "budget": check.budget,
        "max_seconds": check.job.max_seconds,
        "min_passes": check.job.min_passes,
        "reference": _side_record(check.job.reference),
        "test": _side_record(check.job.test),
        "render_seconds": check.render_seconds,
        "side_seconds": check.side_seconds,
        "wall_seconds": check.wall_seconds,
        "claim_tile": check.claim_tile,
        "ended_pass": check.ended_pass,
        "looks": check.looks,
    }


def save(check) -> None:
    """Write `check`'s state (atomically), its wall clock counted up to now."""
    if check.clock_since is not None:
        now = time.monotonic()
        check.wall_seconds, check.clock_since = check.wall_seconds + now - check.clock_since, now
    text = json.dumps(record(check), indent=2, allow_nan=False, default=_json_default)
    wc.formats.atomic_write(state_path(check.job.out), lambda f: f.write(text.encode()))


def resume(check) -> None:
    """Set `check` to the state its folder holds, refused in one line where it can't be resumed with its job."""
    path = state_path(check.job.out)
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
    for side in (check.reference, check.test):
        started, asked = state.get(side.name), _side_record(side.job)
        if started != asked:
            if not _reseeded(started, asked):
                raise BatchError(_not_resumable(check.job.out, side.name, started, asked))
            grown.append(side.name)
    stored = None
    if state.get("plan") is not None:  # None: stopped before a time budget became a pass budget
        try:
            # a check started before the early design or the pixel-variance test existed goes on without them
            stored = wc.SequentialPlan(**{"early_share": 0.0, "pixel_variance": "off", **state["plan"]})
        except (KeyError, TypeError, wc.WelchInputError) as exc:
            raise BatchError(f"{path} is not a readable check state ({exc})") from None
    budget = state.get("budget") or (stored.max_passes if stored is not None else None)
    if stored is not None and state.get("max_seconds") is None and check.job.max_seconds is None:
        planned = check.job.plan(stored.max_passes, stored.early_share, state["plan"])  # the budget may grow
        if planned != stored:
            raise BatchError(f"can't resume {check.job.out}: it was started with {_plan_difference(stored, planned)}")
        if check.job.max_passes < budget:
            raise BatchError(
                f"can't resume {check.job.out} with --max-passes {check.job.max_passes}: it has a budget of "
                f"{budget} passes a side, which can grow but not shrink"
            )
        budget = _grown_budget(check, stored, budget)
    else:
        planned = check.job.plan(stored.max_passes, stored.early_share, state["plan"]) if stored is not None else None
        floor = state.get("min_passes") != check.job.min_passes and check.job.max_seconds is not None
        if planned != stored or state.get("max_seconds") != check.job.max_seconds or grown or floor:
            raise BatchError(
                f"can't resume {check.job.out}: it was started with another budget, alpha or tolerance"
                + (" (the budget of a --max-seconds check does not grow: start it with --max-passes)"
                   if state.get("max_seconds") is not None and check.job.max_seconds is None else "")
            )  # fmt: skip
    check.budget = budget
    check.plan = stored
    check.looks = list(state.get("looks", []))
    check.render_seconds = float(state.get("render_seconds", 0.0))
    sides = state.get("side_seconds")
    known = isinstance(sides, dict) and all(isinstance(sides.get(k), (int, float)) for k in ("reference", "test"))
    check.side_seconds = {k: float(sides[k]) for k in ("reference", "test")} if known else None
    check.wall_seconds = float(state.get("wall_seconds", 0.0))
    claim = state.get("claim_tile")
    if claim is not None and (isinstance(claim, bool) or not isinstance(claim, int) or claim < 1):
        raise BatchError(f"{path} is not a readable check state (claim_tile {claim!r})")
    check.claim_tile = claim
    check.ended_pass = state.get("ended_pass")


def _grown_budget(check, plan: wc.SequentialPlan, budget: int) -> int:
    """The budget a resumed check gets from --max-passes: the last look of the schedule it fits (the looks past
    the plan's last follow from the plan alone, not from the budget asked for)."""
    asked = check.job.max_passes
    if asked == budget:
        return budget
    fits = wc.look_schedule(plan.max_passes, budget=asked)[-1]
    if fits <= budget:
        after = wc.look_schedule(plan.max_passes, budget=10 * budget + 10)
        following = next(n for n in after if n > budget)
        raise BatchError(
            f"--max-passes {asked} adds no look to {check.job.out}: its next look is at {following} passes a side"
        )
    return fits


def _plan_difference(stored: wc.SequentialPlan, planned: wc.SequentialPlan) -> str:
    """What differs between the design a check was started with and the one asked for, named by option: the
    plan's fields that are check's declared options."""

    def shown(name: str, value) -> str:
        if name == "futility":
            return "the futility stop" if value else "--no-futility"
        if name == "equivalence_tile":
            return "the claim sized for the budget" if value is None else f"--equivalence-tile {value}"
        option = OPTIONS[name]
        return f"{option.flag} {option.show(value) if value is not None else 'off'}"

    names = [f.name for f in dataclasses.fields(stored) if f.name in OPTIONS and "check" in OPTIONS[f.name].uses]
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


def look_record(look: wc.Look, seconds: float) -> dict:
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
