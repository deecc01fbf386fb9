"""One comparison through every presenter: the command line, report.json, report.html, a suite's JUnit and
dashboard, the Blender panel, and a check's looks table say the same verdict with the same numbers, to their
printed precision, because each of them shows the outcome welch_core decided and none decides anything."""

import html
import json
import re
import textwrap
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import numpy as np
import pytest

import welch_core as wc
from batch.decide import suite as suites
from batch.present import fmt, words
from batch.present.dashboard import write_dashboard
from batch.present.junit import junit_xml
from batch.present.pipeline import assess, lines, present
from batch.present.summary import check_record


def runs(kind: str, n: int = 48):
    rng = np.random.default_rng({"biased": 1, "equivalent": 5, "unbounded": 3, "identical": 4}[kind])
    mean = np.full((4, 4, 3), 100.0)
    shifted = mean * (1.02 if kind == "biased" else 1.0)
    sd = {"biased": 1.0, "equivalent": 0.5, "unbounded": 8.0, "identical": 1.0}[kind]
    ref_sums = rng.normal(mean, min(sd, 1.0), (n, 4, 4, 3))
    test_sums = ref_sums.copy() if kind == "identical" else rng.normal(shifted, sd, (n, 4, 4, 3))
    info = wc.RunInfo(scene="corner", overrides=("cycles.film_exposure=1.0",) if kind == "identical" else ())
    ref = wc.TileStats.from_sums(ref_sums, range(n), 64, 64, 16, wc.RunInfo(scene="corner"))
    seeds = range(n) if kind == "identical" else range(1000, 1000 + n)
    test = wc.TileStats.from_sums(test_sums, seeds, 64, 64, 16, info)
    return ref, test


def page_data(path) -> dict:
    text = path.read_text()
    start = text.index('<script type="application/json" id="report-data">') + len(
        '<script type="application/json" id="report-data">'
    )
    return json.loads(text[start : text.index("</script>", start)])


def numbers(sentence: str) -> list[str]:
    """Every number as the sentence prints it (percentages, p-values, counts)."""
    return re.findall(r"[+-]?\d+(?:\.\d+)?(?:e[+-]?\d+)? ?%?", sentence)


class Layout:
    """What a panel draws, as text (the add-on's draw functions take any object with these methods)."""

    def __init__(self, texts=None):
        self.texts = [] if texts is None else texts
        self.alert = False

    def box(self):
        return Layout(self.texts)

    row = column = box

    def label(self, text="", icon="NONE"):
        self.texts.append(text)


def through_every_presenter(tmp_path, comparison, ref, test, report):
    """The verdict sentence each presenter shows, and the whole text it shows it in."""
    shown = {}
    cli = "\n".join(lines(report, tmp_path))
    shown["command line"] = (cli.splitlines()[0].removeprefix("verdict: "), cli)
    stored = json.loads((tmp_path / "report.json").read_text())
    shown["report.json"] = (stored["sentence"], json.dumps(stored))
    page = (tmp_path / "report.html").read_text()
    sentence = re.search(r'<p class="sentence" id="sentence">(.*?)</p>', page).group(1)
    shown["report.html"] = (html.unescape(sentence), html.unescape(page))
    assert page_data(tmp_path / "report.html")["summary"]["sentence"] == stored["sentence"]
    case = suites.Case(name="c", scene="corner")
    result = suites.CaseResult(case, "CPU", "passed", report["verdict"], report["sentence"], 1.0, report["n_test"],
                               str(tmp_path), report)  # fmt: skip
    record = suites._outcome_record(result, tmp_path)
    junit = ET.fromstring(junit_xml("s", [result])).find("testsuite/testcase/system-out").text
    shown["JUnit"] = (junit.splitlines()[0], junit)
    summary = {"suite": "s", "file": "s.toml", "refs": "refs", "alpha": 0.01, "exit_code": 0,
               "counts": {"passed": 1}, "cases": [record]}  # fmt: skip
    write_dashboard(tmp_path / "index.html", summary, [result], [tmp_path / "none.npz"])
    board = html.unescape((tmp_path / "index.html").read_text())
    shown["dashboard"] = (re.search(r'<div class="muted">([^<]*)</div></td><td>', board).group(1), board)
    bpy = pytest.importorskip("bpy", reason="the panel's text needs the bpy module")  # noqa: F841
    from blender_addon import results, ui

    names = ("ref.npz", "test.npz")
    sources = {"reference": names[0], "test": names[1]}
    panel = results.summarize(assess(comparison, ref, test, names=names), sources)
    layout = Layout()
    ui.draw_verdict(layout, panel)
    wrapped = len(textwrap.wrap(panel["sentence"], ui.SENTENCE_WIDTH))
    shown["panel"] = (" ".join(layout.texts[1 : 1 + wrapped]), "\n".join(layout.texts))
    return shown


@pytest.mark.parametrize("kind", ["biased", "equivalent", "unbounded", "identical"])
def test_one_comparison_says_the_same_everywhere(tmp_path, kind):
    ref, test = runs(kind)
    comparison = wc.compare(ref, test, tolerance=0.01 if kind != "biased" else None)
    report = present(tmp_path, comparison, ref, test)
    outcome = report["outcome"]
    assert report["sentence"] == words.sentence(outcome) and outcome["verdict"] == comparison.verdict
    expected = {"biased": "biased", "equivalent": "equivalent", "unbounded": "inconclusive", "identical": "equivalent"}
    assert comparison.verdict == expected[kind]
    for name, (sentence, text) in through_every_presenter(tmp_path, comparison, ref, test, report).items():
        assert sentence == report["sentence"], name
        assert numbers(sentence) == numbers(report["sentence"]), name
        if outcome["reason"] != "identical" and name != "panel":
            assert fmt.difference(outcome["whole_image"]) in text, name  # the whole image, as the outcome has it


def test_a_check_says_its_last_looks_verdict_everywhere(tmp_path):
    """A check's report: the verdict and numbers of its last look (not a fixed-sample test of the final passes),
    the same in the sentence, the looks table and the outlines of the map."""
    ref, test = runs("biased", 16)
    plan = wc.SequentialPlan(max_passes=16, tolerance=0.01)
    schedule = wc.look_schedule(16)
    fractions, looks, looks_made = [], [], []
    for n in schedule:
        fractions.append(n / 16)
        claim = looks_made[-1].outcome.target_tile if looks_made else None
        look = wc.sequential_look(ref.subset(range(n)), test.subset(range(n)), plan, fractions, claim_tile=claim)
        looks_made.append(look)
        looks.append({"passes": n, "fraction": n / 16, "verdict": look.verdict, "p_value": look.p_value,
                      "threshold": look.threshold, "crossed": look.crossed,
                      "ruled_out": look.outcome.claim.ruled_out, "ruled_out_tile": look.ruled_out_tile,
                      "whole_image": look.outcome.whole_image.to_json(), "uncovered": 0, "seconds": 0.0})  # fmt: skip
        if look.verdict is not None:
            break
    job = SimpleNamespace(
        max_seconds=None, min_passes=None, tolerance=0.01, paired=False, seed_offset=0, auto_samples=None
    )
    comparison = wc.compare(ref.subset(range(n)), test.subset(range(n)), tolerance=0.01)
    report = present(tmp_path, comparison, ref.subset(range(n)), test.subset(range(n)), outcome=look.outcome,
                     check=check_record(job, looks, 16, look))  # fmt: skip
    assert report["outcome"]["design"] == "sequential" and report["verdict"] == look.outcome.verdict
    assert report["sentence"] == words.sentence(look.outcome.to_json())
    data = page_data(tmp_path / "report.html")
    assert data["summary"]["check"]["looks"][-1]["whole_image"] == report["outcome"]["whole_image"]
    outlined = np.frombuffer(__import__("base64").b64decode(data["tiles"]["significant"]), np.uint8)
    assert (outlined.reshape(look.outcome.significant.shape) == look.outcome.significant).all()
    shown = through_every_presenter(tmp_path, comparison, ref, test, report)
    for name, (sentence, _text) in shown.items():
        if name != "panel":  # the panel shows its own comparison's outcome (it runs no check yet)
            assert sentence == report["sentence"], name


def test_a_biased_headline_leads_with_the_claim_that_decided():
    """A local bias: the tile that decided leads, the whole image's interval (which includes 0) is said to be no
    evidence on its own, and an interval too wide to state says why instead of '[—]'."""
    tile = {"estimate": -0.0604, "low": None, "high": None, "confidence": 0.99, "simultaneous": "every tile",
            "tile": 128, "x": 0, "y": 0, "width": 128, "height": 128, "channel": "R", "p_value": 2.42e-6,
            "trusted": True}  # fmt: skip
    outcome = {"verdict_text": "biased", "reason": "significant", "n_ref": 3, "n_test": 3, "most_significant": tile,
               "whole_image": {"estimate": -0.0786, "low": -1.0271, "high": 0.081, "confidence": 0.99}}  # fmt: skip
    assert words.sentence(outcome) == (
        "biased: -6.04 % (its interval over every tile needs more passes) in R of the 128x128 tile at x 0, y 0 "
        "(p 2.42e-06); whole image -7.86 % [-102.71 %, +8.10 %], not significant on its own"
    )
    # Where one 128x128 tile is the whole image, it is called so; a whole image without an interval is not said
    # to be not significant.
    whole = dict(
        outcome,
        scales=[{"tile": 128, "tiles": 1}],
        whole_image={"estimate": -0.1035, "low": None, "high": None, "confidence": 0.99},
    )
    assert words.sentence(whole) == (
        "biased: -6.04 % (its interval over every tile needs more passes) in R of the whole image (p 2.42e-06); "
        "whole image -10.35 % (no interval yet)"
    )
    outcome["whole_image"] |= {"low": -0.09, "high": -0.06}  # the whole image agrees: it leads, as before
    assert words.sentence(outcome).startswith(
        "biased: whole image -7.86 % [-9.00 %, -6.00 %]; most significant -6.04 %"
    )


def test_every_reason_of_a_verdict_has_its_words():
    """A verdict's reason (`welch_core.VerdictReason`, one per branch of `decide`) has its words in one table
    (`words.REASON_WORDS`): its sentence and its next step; a reason without words is a KeyError, not another
    reason's words."""
    import inspect

    from welch_core import decision

    decided = inspect.getsource(decision.decide)
    assert set(words.REASON_WORDS) == set(wc.VerdictReason)
    for reason in wc.VerdictReason:
        assert f"VerdictReason.{reason.name}" in decided, reason
    assert "Why." not in inspect.getsource(words.sentence) + inspect.getsource(words.next_step)


def test_every_tile_test_has_its_words():
    """Each registered tile test (`welch_core.tile_tests.TILE_TESTS`) has a name in the method's sentence and its own
    words for a difference no noise explains."""
    assert set(words.TEST_WORDS) == set(wc.TILE_TESTS) == set(wc.TileTestKind)
    assert len({name for name, _ in words.TEST_WORDS.values()}) == len(wc.TileTestKind)
    for kind in wc.TileTestKind:
        assert words.deterministic(3, kind).startswith("3 tile-channels "), kind
        assert words.deterministic(3, kind.value) == words.deterministic(3, kind)  # report files hold the value


def test_every_status_is_shown_from_one_table():
    """A status's colour, JUnit element and meaning are written once (`statuses.STATUSES`); a verdict takes its
    status's colour, as report.html's did before the table (biased red, inconclusive amber, the others green); the
    statuses that count against a suite are JUnit's failures."""
    from batch.jobs.protocol import FAILING, CaseStatus
    from batch.present import statuses

    assert set(statuses.STATUSES) == set(statuses.STATUS_COLOURS) == set(statuses.FIRST) == set(CaseStatus)
    assert {s for s, words in statuses.STATUSES.items() if words.junit == "failure"} == set(FAILING)
    assert statuses.FIRST[0] == CaseStatus.FAILED and statuses.FIRST[-1] == CaseStatus.SKIPPED
    expected = {"biased": "#b00020", "inconclusive": "#a06000", "equivalent": "#1b7f3b", "no_evidence": "#1b7f3b"}
    assert {verdict: statuses.verdict_colour(verdict) for verdict in expected} == expected
    assert {v.label: statuses.verdict_colour(v) for v in wc.Verdict} == expected
