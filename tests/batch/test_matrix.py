"""The release matrix and the bisect (batch/decide/matrix.py) on stored statistics: which pairs are compared, the
cells' verdicts and their JUnit, the page, and the bisect's search, its levels and its answers at the edges."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import welch_core as wc
from batch.decide import matrix
from batch.present.junit import junit_xml
from batch.present.matrix_page import write_bisect_page, write_matrix_page


def test_adjacent_pairs_then_the_baseline_against_the_rest():
    assert matrix.matrix_pairs(["a", "b", "c", "d"], "a") == [("a", "b"), ("b", "c"), ("c", "d"), ("a", "c"),
                                                              ("a", "d")]  # fmt: skip
    assert matrix.matrix_pairs(["a", "b", "c"], "b") == [("a", "b"), ("b", "c")]  # adjacent to both already


def test_builds_are_named_once():
    with pytest.raises(matrix.BatchError, match="build current is given twice"):
        matrix.unique([matrix.Build("current"), matrix.Build("current")])
    with pytest.raises(matrix.BatchError, match="at least two builds"):
        matrix.unique([matrix.Build("current")])
    with pytest.raises(matrix.BatchError, match="not `current`, a release such as 4.5.4, or an existing program"):
        matrix.build_of("4.5")


def stored(folder, name, shift, seeds, rng):
    """A 64x64 run in 16-px tiles whose whole image is `shift` brighter (relative)."""
    mean = np.full((4, 4, 3), 100.0 * 256) * (1 + shift)
    sums = mean + rng.normal(0.0, 0.02 * 100 * 256, size=(len(seeds), 4, 4, 3))
    path = folder / f"{name}.npz"
    wc.save_stats(path, wc.TileStats.from_sums(sums, list(seeds), 64, 64, 16))
    return path


@pytest.fixture
def builds(tmp_path):
    """Four builds of 32 passes each; the difference (+3 %) appears in the third."""
    rng = np.random.default_rng(4)
    shifts = {"4.2.9": 0.0, "4.5.4": 0.0, "5.0.0": 0.03, "5.0.1": 0.03}
    return {name: stored(tmp_path, name, shift, range(32 * k, 32 * (k + 1)), rng)
            for k, (name, shift) in enumerate(shifts.items())}  # fmt: skip


def test_the_matrix_of_stored_runs_its_junit_and_its_page(builds, tmp_path):
    labels = list(builds)
    pairs = matrix.run_matrix(builds, labels, labels[0], tmp_path / "m", 0.01, None)
    verdicts = {(p.reference, p.test): p.verdict for p in pairs}
    assert verdicts == {("4.2.9", "4.5.4"): "no_evidence", ("4.5.4", "5.0.0"): "biased",
                        ("5.0.0", "5.0.1"): "no_evidence", ("4.2.9", "5.0.0"): "biased",
                        ("4.2.9", "5.0.1"): "biased"}  # fmt: skip
    changed = next(p for p in pairs if (p.reference, p.test) == ("4.5.4", "5.0.0"))
    assert changed.whole_image["estimate"] == pytest.approx(0.03, abs=0.005) and changed.sentence.startswith("biased")
    root = ET.fromstring(junit_xml("matrix", [p.result("corner") for p in pairs]))
    failed = [c.get("name") for c in root.iter("testcase") if c.find("failure") is not None]
    assert failed == ["4.5.4 vs 5.0.0", "4.2.9 vs 5.0.0", "4.2.9 vs 5.0.1"]
    page = tmp_path / "m" / "index.html"
    write_matrix_page(page, "Release matrix: corner", labels, pairs)
    text = page.read_text()
    assert text.count('<td class="pair" data-verdict="biased">') == 3 and text.count("data:image/png") == 5
    assert 'href="pairs/4.5.4__5.0.0/report.html"' in text
    matrix.write_json(tmp_path / "m.json", {"pairs": pairs})
    assert len(json.loads((tmp_path / "m.json").read_text())["pairs"]) == 5


def test_the_bisect_finds_the_first_build_that_differs_from_the_first(builds, tmp_path):
    labels = list(builds)

    def shows(label, level):
        if label == labels[0]:
            return matrix.Pair(label, label, "no_evidence", "the reference", None, None, "")
        return matrix.compare_pair(builds[labels[0]], builds[label], tmp_path / label, level, None,
                                   (labels[0], label))  # fmt: skip

    found = matrix.bisect(labels, shows, 0.01)
    assert (
        found.first == "5.0.0"
        and found.message == "the difference appears in 5.0.0 (not in 4.5.4, the build before it)"
    )
    # the last, the first, then halving: 4.5.4 does not differ, 5.0.0 does
    assert [s.build for s in found.steps] == ["5.0.1", "4.2.9", "4.5.4", "5.0.0"]
    assert all(s.alpha == pytest.approx(0.01 / 4) for s in found.steps)  # ceil(log2 3) + 2 = 4 steps planned
    write_bisect_page(tmp_path / "b.html", "Bisect", found)
    assert "the difference appears in 5.0.0" in (tmp_path / "b.html").read_text()


@pytest.mark.parametrize(
    ("verdicts", "first", "message"),
    [
        ({"a": "no_evidence", "b": "no_evidence", "c": "no_evidence"}, None, "c does not show the difference"),
        ({"a": "biased", "b": "biased", "c": "biased"}, None, "a already shows the difference"),
        ({"a": "no_evidence", "b": "biased", "c": "biased"}, "b", "the difference appears in b"),
        ({"a": "no_evidence", "b": "inconclusive", "c": "biased"}, "c", "the difference appears in c"),
    ],
)
def test_the_bisect_at_its_edges(verdicts, first, message):
    def shows(label, level):
        return matrix.Pair(label, label, verdicts[label], verdicts[label], None, None, "")

    found = matrix.bisect(list(verdicts), shows, 0.05)
    assert found.first == first and found.message.startswith(message)
    assert len(found.steps) <= 4  # ceil(log2(2)) + 2 steps planned for 3 builds: at most that many taken


def test_the_bisect_takes_a_logarithmic_number_of_steps():
    labels = [f"r{k:02d}" for k in range(33)]  # the difference from r20 on
    found = matrix.bisect(labels, lambda x, _: matrix.Pair(x, x, "biased" if x >= "r20" else "no_evidence", "", None,
                                                           None, ""), 0.01)  # fmt: skip
    assert found.first == "r20" and len(found.steps) <= 5 + 2
    assert found.steps[0].alpha == pytest.approx(0.01 / 7)
