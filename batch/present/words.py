"""The words of a verdict: the sentence every presenter shows (the command line, report.html, JUnit, the
dashboard, the Blender panel), written from the outcome's JSON (`welch_core.Outcome.to_json`, report.json's
``outcome``) and nothing else, so that every place that shows a verdict says the same with the same numbers.

Nothing here decides: the verdict and each number come from the outcome; these functions only choose words.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .._siblings import welch_core as wc
from . import fmt

Why = wc.VerdictReason  # why a verdict is what it is: each has its words below

#: Each tile test's words (`welch_core.tile_tests`): its name in the method's sentence, and how it sees
#: tile-channels whose difference no noise explains.
TEST_WORDS = {
    wc.TileTestKind.WELCH: ("Welch's t-test", "{count} tile-channels are constant on both sides but differ"),
    wc.TileTestKind.PAIRED: (
        "paired t-test on per-pass differences",
        "{count} tile-channels differ by the same amount in every pass",
    ),
}


def where(d: dict[str, Any], outcome: dict[str, Any] | None = None) -> str:
    """'R of the 16x16 tile at x 32, y 48' (its true size at a partial edge), or 'R of the whole image' where
    `outcome` says that one tile of that size covers it."""
    scale = scale_of(outcome, d["tile"]) if outcome is not None else None
    if scale is not None and scale["tiles"] == 1:
        return f"{d['channel']} of the whole image"
    size = (
        f"{d['tile']}x{d['tile']}"
        if (d["width"], d["height"]) == (d["tile"], d["tile"])
        else (f"{d['width']}x{d['height']} (edge)")
    )
    return f"{d['channel']} of the {size} tile at x {d['x']}, y {d['y']}"


def whole_image(outcome: dict[str, Any]) -> str | None:
    """'whole image +0.91 % [+0.45 %, +1.37 %]' or None where it has no estimate."""
    d = outcome.get("whole_image")
    if d is None or d["estimate"] is None:
        return None
    return f"whole image {fmt.difference(d)}"


def box(b: dict[str, int] | None) -> str:
    return "" if b is None else f"x {b['x']}..{b['x'] + b['width']}, y {b['y']}..{b['y'] + b['height']}"


def claim_scale(outcome: dict[str, Any]) -> dict[str, Any] | None:
    return next((s for s in outcome["scales"] if s["tile"] == outcome["claim_tile"]), None)


def ruled_out_list(outcome: dict[str, Any]) -> str:
    """'16: not bounded, 32: 2.10 %, 64: 1.20 %' : the bias ruled out at each tile size."""
    return ", ".join(
        f"{s['tile']}: {'not bounded' if s['ruled_out'] is None else fmt.bound(s['ruled_out'])}"
        for s in outcome["scales"]
    )


def scale_of(outcome: dict[str, Any], tile: int | None) -> dict[str, Any] | None:
    return next((s for s in outcome.get("scales", ()) if s["tile"] == tile), None)


def every_tile(scale: dict[str, Any]) -> str:
    """'every 64x64 tile', or 'the whole image' where one tile of that size covers it."""
    return "the whole image" if scale["tiles"] == 1 else f"every {scale['tile']}x{scale['tile']} tile"


def _ruled_out_there(scale: dict[str, Any]) -> str:
    """'a bias beyond 0.82 % is ruled out there', or that every tile is identical on both sides."""
    if scale["ruled_out"] == 0:
        return "identical on both sides there"
    return f"a bias beyond {fmt.bound(scale['ruled_out'])} is ruled out there"


def finer_needs(outcome: dict[str, Any], tile: int) -> str | None:
    """What the sizes finer than `tile` would need if the sides agree, projected from the variances: '16x16 tiles
    would need about 4500 passes a side, 32x32 about 1100' (None: no finer size)."""
    finer = [s for s in outcome["scales"] if s["tile"] < tile]
    reachable = [s for s in finer if s["projected"] is not None]
    parts = [f"{s['tile']}x{s['tile']} about {s['projected']}" for s in reachable]
    if parts:
        parts[0] = parts[0].replace(" about", " tiles would need about", 1) + " passes a side"
    stuck = [f"{s['tile']}x{s['tile']}" for s in finer if s["projected"] is None]
    if stuck:
        parts.append(f"{', '.join(stuck)} tiles can't be bounded by more passes alone")
    return ", ".join(parts) or None


def _tolerance(outcome: dict[str, Any]) -> str:
    """'1.00 %', or with the digits a small tolerance needs ('0.001 %', never '0.00 %')."""
    tolerance = outcome["tolerance"]
    return fmt.magnitude(tolerance, max(2, -math.floor(math.log10(100 * tolerance))))


def _identical_share(outcome: dict[str, Any]) -> str:
    return f"a change that alters one pass in ten would have shown ({1 - outcome['alpha']:.0%})"


def deterministic(count: int, test: str) -> str:
    """Tile-channels whose difference no noise explains, as the test saw them."""
    return TEST_WORDS[test][1].format(count=count)


def _biased_claim(outcome: dict[str, Any], text: str, whole: str | None) -> list[str]:
    """A `biased` verdict's parts: the whole image first where its interval agrees (excludes 0), else the tile that
    decided first and the whole image said to be not significant on its own where its interval holds 0; an
    interval too wide to state said so."""
    top, image = outcome["most_significant"], outcome.get("whole_image") or {}
    agrees = image.get("low") is not None and (image["low"] > 0 or image["high"] < 0)
    decided = None
    if top is not None:
        interval = (
            fmt.difference(top)
            if top["low"] is not None
            else f"{fmt.percent(top['estimate'])} (its interval over every tile needs more passes)"
        )
        decided = f"{interval} in {where(top, outcome)} (p {fmt.p_value(top['p_value'])})"
    if agrees or decided is None:
        return [f"{text}: {whole}" if whole else text] + ([f"most significant {decided}"] if decided else [])
    if whole and image.get("low") is not None:  # its interval is known and holds 0: it alone shows nothing
        whole += ", not significant on its own"
    return [f"{text}: {decided}"] + ([whole] if whole else [])


def sentence(outcome: dict[str, Any]) -> str:
    """The verdict in one sentence, its own word first: what it claims, at which scale, with its numbers; at a
    look of a check that goes on, "so far" first (no verdict yet). Each reason's words: `REASON_WORDS`."""
    said = _Said.of(outcome)
    words = REASON_WORDS[outcome["reason"]]
    parts = words.claim(said)
    if words.whole and said.whole:
        parts.append(said.whole)
    return "; ".join(parts)


def resampling_notes(outcome: dict[str, Any]) -> list[str]:
    """What the permutation test that `biased` needs between sides of different pass counts said, when it ran."""
    test = outcome.get("resampling")
    if test is None:
        return []
    sides = f"the sides differ in passes ({outcome['n_ref']} v {outcome['n_test']})"
    if test["limited"]:
        return [
            f"{sides}: `biased` also needs a permutation test of the whole family, whose smallest p-value with "
            f"these passes is {fmt.p_value(test['smallest'])}, above the {fmt.p_value(test['level'])} it must reach: "
            "these passes cannot show a bias (render more passes on the smaller side)"
        ]
    return [
        f"{sides}: `biased` also needs a permutation test of the whole family (Welch's t alone is not calibrated "
        f"there when tile sums are skewed): p {fmt.p_value(test['p_value'])} against "
        f"{fmt.p_value(test['level'])}, {test['resamples']} resamples"
    ]


def _loss(outcome: dict[str, Any]) -> str:
    """The power a futility stop gives up at most, as a percentage ('5 %')."""
    return f"{100 * outcome['futility_loss']:g} %"


def _passes_to_bound(scale: dict[str, Any]) -> str:
    """'; about 900 passes a side would bound them if the sides agree', or that the estimates put it out of reach
    (one projection, the variances', wherever a pass count is quoted)."""
    if scale["projected"] is None:
        return "; more passes alone can't bound them (tiles whose samples are not normal, or a reference too noisy)"
    if scale["passes_needed"] is None:
        return (
            f"; about {scale['projected']} passes a side would bound them if the sides agreed, but an estimate is at "
            "or beyond the tolerance"
        )
    return f"; about {scale['projected']} passes a side would bound them if the sides agree"


def _early(check: dict[str, Any] | None) -> str:
    """The early design's part of the spending, when the check had one."""
    if not (check or {}).get("early_share"):
        return ""
    return f"; {check['early_share']:.0%} of it by {check['early_passes']} passes a side, the rest over the budget"


def method(
    outcome: dict[str, Any], pvalue_method: str = "exact", check: dict[str, Any] | None = None,
    pixels: dict[str, Any] | None = None,
) -> str:  # fmt: skip
    """How the verdict was reached, in a sentence (`check`: the design of a check, see `summary.check_record`;
    `pixels`: whether tiles were tested by their pixel variances, `welch_core.PixelUse.to_json`)."""
    name = TEST_WORDS[outcome["test"]][0]
    sizes = ", ".join(str(s["tile"]) for s in outcome["scales"])
    if outcome["design"] == "sequential":
        text = (
            f"{name} per tile and channel at tile sizes {sizes}, looked at after every chunk of passes: each "
            f"tile-channel of each size its Bonferroni share of alpha {outcome['alpha']:g}, spent over the looks "
            f"(Pocock{_early(check)}); Welch's t with n - 1 degrees of freedom"
            + (" where a tile's variance is from its tile sums" if pixels and pixels["used"] else "")
        )
    else:
        text = (
            f"{name} per tile and channel (p: {pvalue_method}) at tile sizes {sizes}; channels combined by "
            "Bonferroni; the tiles of a size by Holm and a one-sided Kolmogorov-Smirnov test of uniformity, "
            "Bonferroni-combined; the sizes by Bonferroni"
        )
    if pixels and pixels["used"]:
        text += (
            f"; {pixels['share']:.0%} of the tile-channels (every size) take their variance from their pixels' "
            f"variances (independent pixels: {pixels['reason']}; Satterthwaite's df, the tile sums' test where it "
            f"is below {pixels['min_df']:g})"
        )
    if outcome.get("resampling") is not None:
        text += (
            "; the sides' pass counts differ, so `biased` also needs a permutation max-T test of every tile-channel "
            "of every size (passes reassigned between the sides)"
        )
    if outcome["tolerance"] is not None:
        tile = outcome["claim_tile"]
        level = 1 - 2 * outcome["alpha"]
        text += (
            f"; equivalent: every tile-channel of the {tile}x{tile} tiles has its {level:.0%} interval inside "
            f"±{_tolerance(outcome)} (an intersection-union test at {outcome['alpha']:g}"
            + (", the intervals repeated over the looks)" if outcome["design"] == "sequential" else ")")
        )
        if outcome.get("target_tile"):
            target = outcome["target_tile"]
            text += (
                f"; the claim's size, {target}x{target}, chosen for the budget from the variances alone (the finest "
                "that the budget bounds if the sides agree), and every coarser size bounded too, so that a size chosen "
                "this way, or a coarser one at the end, keeps the error rate of `equivalent` at alpha"
            )
    return text


def pixel_line(pixels: dict[str, Any] | None) -> str | None:
    """Which variance the tiles were tested with, and why, in a line (None: the test was off)."""
    if pixels is None or pixels["mode"] == "off":
        return None
    if pixels["used"]:
        return (f"pixel variances: {pixels['share']:.0%} of the tile-channels of every size tested by them "
                f"({pixels['reason']})")  # fmt: skip
    return f"pixel variances: not used, {pixels['reason']}; tile sums' variances everywhere"


def attribution(where: str | None, components: tuple[str, ...] = ()) -> str | None:
    """Where the layers put the image's difference (`welch_core.LayerFamily.attribution`), in a line."""
    if where == "components":
        return f"the difference is in {', '.join(components)}"
    if where == "spread":
        return "no single component is biased on its own: the difference is spread over several"
    return None


#: What marks a `hidden` difference of a setting that acts only above some samples per render (`sample_hidden`).
_ACTING = ", acting from "


def sample_hidden(name: str, values: tuple[str, str], fewest: int, spp: int) -> str:
    """A difference the passes cannot show: a setting that acts only from `fewest` samples per render, with passes
    of `spp` (`next_step`'s `hidden`; `batch.present.summary.sample_notes`)."""
    return f"{name}: {values[0]} → {values[1]}{_ACTING}{fewest} samples per render, {spp} in the passes"


def next_step(outcome: dict[str, Any], check: dict[str, Any] | None = None, hidden: list[str] = ()) -> str:
    """What to do with this verdict, in a sentence or two; `check`: a check's record (`check_record`), None for a
    compare; `hidden`: the settings in which the two sides differ but the passes do not: a setting the passes
    replace on both sides (`batch.present.summary.fixed_notes`), or one that acts only from more samples per render
    than the passes have (`sample_hidden`). Each reason's words: `REASON_WORDS`."""
    words = REASON_WORDS[outcome["reason"]]
    if hidden and words.agree:
        names = ", ".join(dict.fromkeys(h.split(":")[0] for h in hidden))
        if any(_ACTING in h for h in hidden):
            return (
                f"The passes agree, but they have too few samples to show {names} (settings that act only above "
                "some samples per render; see the notes): run the same command with --spp at the scene files' "
                "samples, or at least those the notes give, and another --out."
            )
        return (
            f"The passes agree, but the scene files differ in what the passes replace ({names}), a difference not "
            "tested: compare samples, sampling patterns or devices directly (--test-spp, --test-sampling-pattern, "
            "--test-device); a denoiser, adaptive sampling or a time limit is outside what this test can judge."
        )
    return words.step(_Said.of(outcome, check))


# -- each reason's words ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Said:
    """What a reason's words are made of: the outcome, its verdict's word (or "so far" at a look that goes on),
    the passes a side, the whole image's difference, and a check's record (None for a compare)."""

    outcome: dict[str, Any]
    text: str
    n: int
    whole: str | None
    check: dict[str, Any] | None = None

    @classmethod
    def of(cls, outcome: dict[str, Any], check: dict[str, Any] | None = None) -> _Said:
        text = outcome["verdict_text"] if outcome.get("decided", True) else "so far"
        n = min(outcome["n_ref"], outcome["n_test"])
        return cls(outcome, text, n, whole_image(outcome), check)

    @property
    def timed(self) -> bool:
        """A check with a time budget: it can't grow on resume, a new check is the way on."""
        return bool(self.check and self.check.get("max_seconds"))

    @property
    def more(self) -> str:
        """How to get more passes."""
        if self.timed:
            return (
                "run the check again with a larger --max-seconds (or --max-passes alone) and another --out: a time "
                "budget does not grow on resume"
            )
        if self.check:
            return (
                "run the same check again with a larger --max-passes and --resume: the looks already made keep "
                "their boundaries, and the looks past the budget spend the share of alpha kept for them"
            )
        return (
            "render more passes into both runs (the same render commands with --resume and more seeds), then "
            "compare again, or let `python -m batch check` render until it decides"
        )


@dataclass(frozen=True)
class ReasonWords:
    """A reason's words: its sentence's parts (`claim`), whether the whole image's difference follows them
    (`whole`), its next step (`step`), and whether the passes agree (`agree`: a difference the passes do not
    show, `next_step`'s `hidden`, is said first)."""

    claim: Callable[[_Said], list[str]]
    step: Callable[[_Said], str]
    whole: bool = True
    agree: bool = False


def _deterministic_claim(said: _Said) -> list[str]:
    return [f"{said.text}: {deterministic(said.outcome['deterministic'], said.outcome['test'])}"]


def _identical_claim(said: _Said) -> list[str]:
    return [f"{said.text}: all {said.n} passes are identical on both sides", _identical_share(said.outcome)]


def _identical_too_few_claim(said: _Said) -> list[str]:
    return [
        f"{said.text}: all {said.n} passes are identical on both sides so far",
        f"{said.outcome['identical_needed']} identical passes would rule out a change that alters one pass in ten",
    ]


def _bounded_claim(said: _Said) -> list[str]:
    outcome = said.outcome
    claim = claim_scale(outcome)
    parts = [f"{said.text} within ±{_tolerance(outcome)} in {every_tile(claim)} ({_ruled_out_there(claim)})"]
    target = scale_of(outcome, outcome.get("target_tile"))
    if target is not None and target["tile"] != claim["tile"]:
        parts.append(f"not in {every_tile(target)}, the size the budget was planned for")
    finer = finer_needs(outcome, claim["tile"])
    return parts + ([finer] if finer else [])


def _significant_claim(said: _Said) -> list[str]:
    return _biased_claim(said.outcome, said.text, said.whole)


def _spread_claim(said: _Said) -> list[str]:
    return [f"{said.text}: a difference spread over many tiles (too many small p-values)"]


def _futile_claim(said: _Said) -> list[str]:
    outcome = said.outcome
    claim = claim_scale(outcome)
    need = claim["passes_needed"]
    reach = (
        f"about {need} passes a side at the current estimates" if need is not None
        else "more passes than any budget at the current estimates (an estimate near or beyond the tolerance)"
    )  # fmt: skip
    return [
        f"{said.text}: stopped early after {said.n} of {outcome['budget']} passes a side, neither claim within the "
        f"budget's reach: {every_tile(claim)} within ±{_tolerance(outcome)} would take {reach}, and no "
        f"tile-channel would reach `biased` by the budget with more than a {_loss(outcome)} chance even if it held "
        "the bias the budget detects there",
        f"bias ruled out per tile size: {ruled_out_list(outcome)}",
    ]


def _unbounded_claim(said: _Said) -> list[str]:
    outcome, text, n = said.outcome, said.text, said.n
    claim = claim_scale(outcome)
    tile = claim["tile"]
    coarser = next((s for s in outcome["scales"] if s["tile"] > tile and s["ruled_out"] is not None
                    and s["ruled_out"] <= outcome["tolerance"]), None)  # fmt: skip
    first = f"{text}: not shown within ±{_tolerance(outcome)} in {every_tile(claim)}"
    if coarser is not None:
        first = f"{text}: within ±{_tolerance(outcome)} in {every_tile(coarser)}; {tile}x{tile} not bounded"
    if outcome["reason"] == Why.BEYOND:
        first += " (a finer tile found biased differs by more than that)"
    parts = [first]
    if n < outcome["identical_needed"]:
        parts.append(f"equivalence needs {outcome['identical_needed']} passes a side, {n} so far")
    elif claim["tiles"] - claim["bounded"]:
        open_ = f"{claim['tiles'] - claim['bounded']} of {claim['tiles']} tiles not bounded"
        if claim["unbounded_box"] is not None and claim["bounded"]:
            open_ += f" ({box(claim['unbounded_box'])})"
        parts.append(open_ + _passes_to_bound(claim))
    return parts + [f"bias ruled out per tile size: {ruled_out_list(outcome)}"]


def _undecided_claim(said: _Said) -> list[str]:
    return [f"{said.text}: undecided after {said.n} passes a side"]


def _unreachable_claim(said: _Said) -> list[str]:
    outcome = said.outcome
    return [
        f"{said.text}: with {outcome['n_ref']} v {outcome['n_test']} passes no bias can be shown (the permutation "
        "test that sides of different pass counts need can't give a p-value below "
        f"{fmt.p_value(outcome['resampling']['smallest'])})"
    ]


def _untestable_claim(said: _Said) -> list[str]:
    return [f"{said.text}: no tile can be tested (too few passes, constant images or non-finite values)"]


def _too_untested_claim(said: _Said) -> list[str]:
    outcome = said.outcome
    return [
        f"{said.text}: the Welch samples of {outcome['untestable']} tiles ({box(outcome['untestable_box'])}) are "
        "clearly not normal at every tile size (fireflies or caustics): too much of the image can't be tested"
    ]


def _nothing_found_claim(said: _Said) -> list[str]:
    detectable = said.outcome["min_detectable"]
    finest = said.outcome["scales"][0]["tile"]
    found = (
        f": a bias of {fmt.magnitude(detectable)} in a {finest}x{finest} tile would have been found with 80 % power"
        if detectable is not None
        else ""
    )
    return [f"{said.text}{found}"]


def _differ_step(said: _Said) -> str:
    top = said.outcome["most_significant"]
    located = f" The most significant difference is in {where(top, said.outcome)}." if top else ""
    return (
        "The two do not converge to the same image." + located + " Look at the recorded differences and the "
        "tiles outlined in the map; a difference you expected (a setting changed on purpose) confirms the test "
        "works."
    )


def _bounded_step(said: _Said) -> str:
    outcome = said.outcome
    claim = claim_scale(outcome)
    done = f"Nothing to do at this size: {every_tile(claim)} is within ±{_tolerance(outcome)} of the reference."
    finer = [x for x in outcome["scales"] if x["tile"] < claim["tile"] and x["projected"] is not None]
    if finer:
        size = finer[-1]
        done += (
            f" To speak for {size['tile']}x{size['tile']} tiles too: the same check with --equivalence-tile "
            f"{size['tile']} and --max-passes {size['projected']} (about that many passes a side), another --out."
        )
    return done


def _identical_step(said: _Said) -> str:
    return "Nothing to do: the change leaves every pass as it was."


def _identical_too_few_step(said: _Said) -> str:
    needed = said.outcome["identical_needed"]
    return f"Render at least {needed} passes a side to rule out a rarely visible change: {said.more}."


def _unbounded_step(said: _Said) -> str:
    """Not bounded at the claim's size (at the budget, or stopped early for futility): the passes that would."""
    outcome, check, timed = said.outcome, said.check, said.timed
    claim = claim_scale(outcome)
    coarser = [x for x in outcome["scales"] if x["tile"] > claim["tile"] and x["projected"] is not None]
    if claim["projected"] is not None:
        need = claim["projected"]
        grow = (
            f"{every_tile(claim)} within ±{_tolerance(outcome)} would need about {need} passes a side if the sides "
            "agree: "
            + (f"the check again with --max-passes {need} (no --max-seconds) and another --out" if timed
               else f"the same check with --max-passes {need} and --resume" if check
               else f"render about {need} passes a side into both runs (--resume, more seeds), then compare again")
        )  # fmt: skip
        if claim["passes_needed"] is None and said.n >= outcome["identical_needed"]:
            grow += " (an estimate is at or beyond the tolerance now: look at the tiles not bounded in the map)"
    else:
        grow = (
            f"more passes alone can't bound {every_tile(claim)} (tiles whose samples are not normal, or a "
            "reference too noisy): more samples per pass (--spp) make each pass's tile sums more normal"
        )
    if coarser and not outcome.get("target_tile"):
        size = coarser[0]
        grow += (
            f"; or claim a coarser size: --equivalence-tile {size['tile']} (about {size['projected']} passes a side)"
        )
    if outcome["reason"] == Why.FUTILE:
        return (
            f"The check stopped early: {grow}. The stop gave up at most {_loss(outcome)} of the power to find a "
            "bias the budget detects; --no-futility renders the whole budget."
        )
    return f"Not decided at this size: {grow}."


def _unreachable_step(said: _Said) -> str:
    return (
        "Too few passes on the smaller side for a test that holds with skewed tile sums: render more passes there "
        "(the same render command with --resume and more seeds), then compare again."
    )


def _untestable_step(said: _Said) -> str:
    return f"No tile could be tested (too few passes, or constant images): {said.more}."


def _too_untested_step(said: _Said) -> str:
    return (
        f"The Welch samples of {box(said.outcome['untestable_box'])} are clearly not normal (fireflies or caustics) "
        "at every tile size, so that part can't be tested yet: more samples per pass (--spp) make each pass's tile "
        f"sums more normal; or {said.more}."
    )


def _undecided_step(said: _Said) -> str:
    return f"Not decided yet: {said.more}."


def _nothing_found_step(said: _Said) -> str:
    detectable = said.outcome["min_detectable"]
    smaller = f"a bias below {fmt.magnitude(detectable)} per tile" if detectable is not None else "a small bias"
    return (
        f"No bias was found, but {smaller} could still hide: to rule it out, {said.more}; with --tolerance the "
        "verdict says whether the two are equivalent within it."
    )


#: Every reason of a verdict (`welch_core.VerdictReason`, one per branch of `decide`) and its words.
REASON_WORDS: dict[Why, ReasonWords] = {
    Why.DETERMINISTIC: ReasonWords(_deterministic_claim, _differ_step, whole=False),
    Why.SIGNIFICANT: ReasonWords(_significant_claim, _differ_step, whole=False),  # the claim places the whole
    Why.SPREAD: ReasonWords(_spread_claim, _differ_step),
    Why.IDENTICAL: ReasonWords(_identical_claim, _identical_step, whole=False, agree=True),
    Why.BOUNDED: ReasonWords(_bounded_claim, _bounded_step, agree=True),
    Why.IDENTICAL_TOO_FEW: ReasonWords(_identical_too_few_claim, _identical_too_few_step, whole=False, agree=True),
    Why.FUTILE: ReasonWords(_futile_claim, _unbounded_step),
    Why.UNDECIDED: ReasonWords(_undecided_claim, _undecided_step),
    Why.UNTESTABLE: ReasonWords(_untestable_claim, _untestable_step),
    Why.UNREACHABLE: ReasonWords(_unreachable_claim, _unreachable_step),
    Why.TOO_UNTESTED: ReasonWords(_too_untested_claim, _too_untested_step),
    Why.BEYOND: ReasonWords(_unbounded_claim, _unbounded_step),
    Why.UNBOUNDED: ReasonWords(_unbounded_claim, _unbounded_step),
    Why.NOTHING_FOUND: ReasonWords(_nothing_found_claim, _nothing_found_step),
}
