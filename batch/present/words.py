"""The words of a verdict: the sentence every presenter shows (the command line, report.html, JUnit, the
dashboard, the Blender panel), written from the outcome's JSON (`welch_core.Outcome.to_json`, report.json's
``outcome``) and nothing else, so that every place that shows a verdict says the same with the same numbers.

Nothing here decides: the verdict and each number come from the outcome; these functions only choose words.
"""

from __future__ import annotations

from typing import Any

from . import fmt


def where(d: dict[str, Any]) -> str:
    """'R of the 16x16 tile at x 32, y 48' (its true size at a partial edge)."""
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
    """'16: 2.10 %, 32: 1.20 %, 64: —' : the bias ruled out at each tile size."""
    return ", ".join(f"{s['tile']}: {fmt.magnitude(s['ruled_out'])}" for s in outcome["scales"])


def _tolerance(outcome: dict[str, Any]) -> str:
    return fmt.magnitude(outcome["tolerance"])


def _identical_share(outcome: dict[str, Any]) -> str:
    return f"a change that alters one pass in ten would have shown ({1 - outcome['alpha']:.0%})"


def deterministic(count: int, test: str) -> str:
    """Tile-channels whose difference no noise explains, as the test saw them."""
    if test == "paired":
        return f"{count} tile-channels differ by the same amount in every pass"
    return f"{count} tile-channels are constant on both sides but differ"


def _biased_claim(outcome: dict[str, Any], text: str, whole: str | None) -> list[str]:
    """A `biased` verdict's parts: the whole image first where its interval agrees (excludes 0), else the tile that
    decided first and the whole image said to be not significant on its own; an interval too wide to state said
    so."""
    top, image = outcome["most_significant"], outcome.get("whole_image") or {}
    agrees = image.get("low") is not None and (image["low"] > 0 or image["high"] < 0)
    decided = None
    if top is not None:
        interval = (
            fmt.difference(top)
            if top["low"] is not None
            else f"{fmt.percent(top['estimate'])} (its interval over every tile needs more passes)"
        )
        decided = f"{interval} in {where(top)} (p {fmt.p_value(top['p_value'])})"
    if agrees or decided is None:
        return [f"{text}: {whole}" if whole else text] + ([f"most significant {decided}"] if decided else [])
    return [f"{text}: {decided}"] + ([f"{whole}, not significant on its own"] if whole else [])


def sentence(outcome: dict[str, Any]) -> str:
    """The verdict in one sentence, its own word first: what it claims, at which scale, with its numbers; at a
    look of a check that goes on, "so far" first (no verdict yet)."""
    text, reason = outcome["verdict_text"] if outcome.get("decided", True) else "so far", outcome["reason"]
    whole = whole_image(outcome)
    n = min(outcome["n_ref"], outcome["n_test"])
    if reason == "deterministic":
        return f"{text}: {deterministic(outcome['deterministic'], outcome['test'])}"
    if reason == "identical":
        return f"{text}: all {n} passes are identical on both sides; {_identical_share(outcome)}"
    if reason == "identical_too_few":
        return (
            f"{text}: all {n} passes are identical on both sides so far; {outcome['identical_needed']} identical "
            "passes would rule out a change that alters one pass in ten"
        )
    parts = []
    if reason == "bounded":
        claim = claim_scale(outcome)
        tile = claim["tile"]
        parts.append(
            f"{text} within ±{_tolerance(outcome)} in every {tile}x{tile} tile (a bias beyond "
            f"{fmt.magnitude(claim['ruled_out'])} is ruled out there)"
        )
        finest = outcome["scales"][0]
        if finest["tile"] != tile:
            parts.append(
                f"in {finest['tile']}x{finest['tile']} tiles a bias up to {fmt.magnitude(finest['ruled_out'])} is "
                "not ruled out"
            )
    elif reason == "significant":
        parts += _biased_claim(outcome, text, whole)
        whole = None
    elif reason == "spread":
        parts.append(f"{text}: a difference spread over many tiles (too many small p-values)")
    elif reason == "futile":
        claim = claim_scale(outcome)
        tile, need = claim["tile"], claim["projected"]
        first = (
            f"{text}: stopped early, every {tile}x{tile} tile within ±{_tolerance(outcome)} would take "
            + (f"about {need} passes a side" if need is not None else "more passes than the reference has")
            + f" (projected from the variances), beyond the budget of {outcome['budget']}; no tile pointed to a bias "
            "by then"
        )
        parts.append(first)
        reachable = reachable_scales(outcome)
        if reachable:
            parts.append("within the budget: " + ", ".join(f"{t}x{t} (about {p} passes)" for t, p in reachable))
    elif reason in ("unbounded", "beyond"):
        claim = claim_scale(outcome)
        tile = claim["tile"]
        coarser = next((s for s in outcome["scales"] if s["tile"] > tile and s["ruled_out"] is not None
                        and s["ruled_out"] <= outcome["tolerance"]), None)  # fmt: skip
        first = f"{text}: not shown within ±{_tolerance(outcome)} in every {tile}x{tile} tile"
        if coarser is not None:
            first = (
                f"{text}: within ±{_tolerance(outcome)} in every {coarser['tile']}x{coarser['tile']} tile; "
                f"{tile}x{tile} not bounded"
            )
        if reason == "beyond":
            first += " (a finer tile found biased differs by more than that)"
        parts.append(first)
        if n < outcome["identical_needed"]:
            parts.append(f"equivalence needs {outcome['identical_needed']} passes a side, {n} so far")
        elif claim["tiles"] - claim["bounded"]:
            open_ = f"{claim['tiles'] - claim['bounded']} of {claim['tiles']} tiles not bounded"
            if claim["unbounded_box"] is not None and claim["bounded"]:
                open_ += f" ({box(claim['unbounded_box'])})"
            if _reachable(claim["passes_needed"], n):
                open_ += f"; about {claim['passes_needed']} passes a side would bound them"
            elif claim["passes_needed"] is not None:
                open_ += "; not reachable at this size by more passes"
            parts.append(open_)
        parts.append(f"bias ruled out per tile size: {ruled_out_list(outcome)}")
    elif reason == "undecided":
        parts.append(f"{text}: undecided after {n} passes a side")
    elif reason == "unreachable":
        test = outcome["resampling"]
        parts.append(
            f"{text}: with {outcome['n_ref']} v {outcome['n_test']} passes no bias can be shown (the permutation test "
            f"that sides of different pass counts need can't give a p-value below {fmt.p_value(test['smallest'])})"
        )
    elif reason == "untestable":
        parts.append(f"{text}: no tile can be tested (too few passes, constant images or non-finite values)")
    elif reason == "too_untested":
        region = box(outcome["untestable_box"])
        parts.append(
            f"{text}: the Welch samples of {outcome['untestable']} tiles ({region}) are clearly not normal at every "
            "tile size (fireflies or caustics): too much of the image can't be tested"
        )
    else:  # nothing found
        detectable = outcome["min_detectable"]
        finest = outcome["scales"][0]["tile"]
        found = (
            f": a bias of {fmt.magnitude(detectable)} in a {finest}x{finest} tile would have been found with 80 % power"
            if detectable is not None
            else ""
        )
        parts.append(f"{text}{found}")
    if whole:
        parts.append(whole)
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


#: A pass count more than this many times the passes so far is advice nobody follows: "not reachable".
_REACHABLE_FACTOR = 64


def _reachable(need: int | None, n: int) -> bool:
    return need is not None and need <= _REACHABLE_FACTOR * max(n, 1)


def reachable_scales(outcome: dict[str, Any]) -> list[tuple[int, int]]:
    """(tile, projected passes) of the scales the budget can bound if the sides agree, finest first."""
    budget = outcome.get("budget")
    return [
        (s["tile"], s["projected"])
        for s in outcome["scales"]
        if budget is not None and s.get("projected") is not None and s["projected"] <= budget
    ]


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
    name = "paired t-test on per-pass differences" if outcome["test"] == "paired" else "Welch's t-test"
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


def next_step(outcome: dict[str, Any], check: bool = False, hidden: list[str] = ()) -> str:
    """What to do with this verdict, in a sentence or two; `hidden`: the settings in which the two sides differ
    but the passes do not: a setting the passes replace on both sides (`batch.present.summary.fixed_notes`), or one
    that acts only from more samples per render than the passes have (`sample_hidden`)."""
    reason = outcome["reason"]
    if hidden and reason in ("bounded", "identical", "identical_too_few"):
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
    more = (
        "run the same check again with a larger --max-passes and --resume: the looks already made keep their "
        "boundaries, and the looks past the budget spend the share of alpha kept for them"
        if check
        else "render more passes into both runs (the same render commands with --resume and more seeds), then "
        "compare again, or let `python -m batch check` render until it decides"
    )
    if reason in ("significant", "spread", "deterministic"):
        top = outcome["most_significant"]
        located = f" The most significant difference is in {where(top)}." if top else ""
        return (
            "The two do not converge to the same image." + located + " Look at the recorded differences and the "
            "tiles outlined in the map; a difference you expected (a setting changed on purpose) confirms the test "
            "works."
        )
    if reason == "bounded":
        claim = claim_scale(outcome)
        return (
            f"Nothing to do: every {claim['tile']}x{claim['tile']} tile is within ±{_tolerance(outcome)} of the "
            "reference."
        )
    if reason == "identical":
        return "Nothing to do: the change leaves every pass as it was."
    if reason == "identical_too_few":
        return (
            f"Render at least {outcome['identical_needed']} passes a side to rule out a rarely visible change: {more}."
        )
    if reason == "futile":
        reachable = reachable_scales(outcome)
        claim = claim_scale(outcome)
        need = claim["projected"]
        if _reachable(need, min(outcome["n_ref"], outcome["n_test"])):
            grow = f"give it about {need} passes a side (the same command with --max-passes {need} and --resume)"
        elif need is not None:
            grow = f"no budget within reach bounds every {claim['tile']}x{claim['tile']} tile (about {need} passes)"
        else:
            grow = "only a longer reference can bound every tile (bless it with more passes)"
        search = (
            " The stop also ended the search for `biased`: a bias that shows only later in the budget is found with "
            "--no-futility, which renders the whole budget."
        )
        if reachable:
            return (
                f"The check stopped early: claim `equivalent` at a size the budget can bound, the same command with "
                f"--equivalence-tile {reachable[0][0]} and another --out; or {grow}.{search}"
            )
        return f"The check stopped early: {grow}.{search}"
    if reason in ("unbounded", "beyond"):
        claim = claim_scale(outcome)
        need = claim["passes_needed"]
        n = min(outcome["n_ref"], outcome["n_test"])
        if need is not None and not _reachable(need, n):
            sizes = [s["tile"] for s in outcome["scales"] if _reachable(s.get("projected"), n)
                     and s["tile"] > claim["tile"]]  # fmt: skip
            other = f": try --equivalence-tile {sizes[0]}" if sizes else ""
            return (
                f"Every {claim['tile']}x{claim['tile']} tile within the tolerance is not reachable at this size "
                f"(about {need} passes a side){other}; or {more}."
            )
        if need is not None:
            return f"To bound every tile within the tolerance, about {need} passes a side are needed: {more}."
        return (
            "More passes alone may not bound every tile (an estimate beyond the tolerance, or tiles whose samples "
            f"are not normal): look at the tiles not bounded, or give a coarser --equivalence-tile; or {more}."
        )
    if reason == "unreachable":
        return (
            "Too few passes on the smaller side for a test that holds with skewed tile sums: render more passes there "
            "(the same render command with --resume and more seeds), then compare again."
        )
    if reason == "untestable":
        return f"No tile could be tested (too few passes, or constant images): {more}."
    if reason == "too_untested":
        return (
            f"The Welch samples of {box(outcome['untestable_box'])} are clearly not normal (fireflies or caustics) at "
            "every tile size, so that part can't be tested yet: more samples per pass (--spp) make each pass's tile "
            f"sums more normal; or {more}."
        )
    if reason == "undecided":
        return f"Not decided yet: {more}."
    detectable = outcome["min_detectable"]
    smaller = f"a bias below {fmt.magnitude(detectable)} per tile" if detectable is not None else "a small bias"
    return (
        f"No bias was found, but {smaller} could still hide: to rule it out, {more}; with --tolerance the verdict "
        "says whether the two are equivalent within it."
    )
