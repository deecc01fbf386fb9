"""The report (batch.present.report): one self-contained page with the per-tile data, report.json, pvalues.exr;
no plotting library on the way."""

from __future__ import annotations

import base64
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import welch_core as wc
from batch.present import report, summary
from tests.helpers.synthetic import scene_means, tile_sum_samples

ROOT = Path(__file__).resolve().parents[2]


def runs_with_pictures(bias=1.1, n=16):
    rng = np.random.default_rng(5)
    m = scene_means(3, 4)
    ref_sums, test_sums = tile_sum_samples(rng, n, m), tile_sum_samples(rng, n, m)
    test_sums[:, 1, 2] *= bias
    pictures = [rng.uniform(0.1, 1.0, (96, 128, 3)).astype(np.float32) * n for _ in range(2)]
    ref = wc.TileStats.from_sums(ref_sums, range(n), 96, 128, 32, pixel_sum=pictures[0])
    test = wc.TileStats.from_sums(test_sums, range(n, 2 * n), 96, 128, 32, pixel_sum=pictures[1])
    return ref, test


def page_data(path: Path) -> dict:
    text = path.read_text()
    found = re.search(r'<script type="application/json" id="report-data">(.*?)</script>', text, re.S)
    return json.loads(found.group(1))


def test_the_page_carries_every_tile_and_both_pictures(tmp_path):
    ref, test = runs_with_pictures()
    c = wc.compare(ref, test)
    written = report.write_report(tmp_path, summary.summarize(c, ref, test), c, ref, test)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pvalues.exr", "report.html", "report.json"]
    assert written["files"] == {"pvalues_exr": "pvalues.exr", "html": "report.html"}
    data = page_data(tmp_path / "report.html")
    assert data["grid"] == {"width": 128, "height": 96, "tile": 32, "tiles_x": 4, "tiles_y": 3, "channels": 3,
                            "reasons": [r.label for r in wc.Reason]}  # fmt: skip
    tiles = data["tiles"]

    def f32(key):
        return np.frombuffer(base64.b64decode(tiles[key]), "<f4")

    def f64(key):
        return np.frombuffer(base64.b64decode(tiles[key]), "<f8")

    np.testing.assert_array_equal(f64("p"), c.pvalues.ravel())
    np.testing.assert_array_equal(f64("tile_p"), c.tile_pvalues.ravel())
    np.testing.assert_array_equal(f32("rel"), c.effect.rel_diff.astype(np.float32).ravel())
    assert np.frombuffer(base64.b64decode(tiles["significant"]), "u1").tolist() == c.significant.ravel().tolist()
    assert c.significant[1, 2] and f32("scale")[6] == 32
    assert set(data["pictures"]) == {"reference", "test", "difference"}
    _rgb, limit = wc.difference_picture(ref.pixel_sum / ref.n, test.pixel_sum / test.n)
    assert data["display"] == {"width": 128, "height": 96, "factor": 1, "difference_scale": pytest.approx(limit)}
    for url in data["pictures"].values():
        assert base64.b64decode(url.removeprefix("data:image/png;base64,"))[:8] == b"\x89PNG\r\n\x1a\n"
    assert data["summary"]["verdict"] == "biased" == json.loads((tmp_path / "report.json").read_text())["verdict"]
    html = (tmp_path / "report.html").read_text()
    assert '<h1 id="verdict">Biased</h1>' in html and "http" not in html.replace("http://www.w3.org/2000/svg", "")
    assert html.count("<rect") == report.HISTOGRAM_BINS


def test_large_images_are_shown_shrunk_and_full_maps_on_request(tmp_path):
    rng = np.random.default_rng(6)
    sums = rng.normal(100, 1, (4, 3, 4, 3))  # 2100x3100 in 1024-px tiles: partial tiles at the edges
    pixels = np.ones((2100, 3100, 3), np.float32) * 4
    ref = wc.TileStats.from_sums(sums, range(4), 2100, 3100, 1024, pixel_sum=pixels)
    test = wc.TileStats.from_sums(sums + 1, range(4, 8), 2100, 3100, 1024, pixel_sum=pixels)
    c = wc.compare(ref, test)
    report.write_report(tmp_path, summary.summarize(c, ref, test), c, ref, test, full_maps=True)
    display = page_data(tmp_path / "report.html")["display"]
    assert display == {"width": 775, "height": 525, "factor": 4, "difference_scale": 0.0}  # the same pixels
    png = (tmp_path / "pvalue_map.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and int.from_bytes(png[16:20], "big") == 3100  # full resolution
    assert (tmp_path / "overlay.png").is_file()


def test_a_check_report_lists_its_looks(tmp_path):
    ref, test = runs_with_pictures()
    c = wc.compare(ref, test)
    plan = wc.SequentialPlan(max_passes=32)
    look = wc.sequential_look(ref, test, plan, [ref.n / 32])
    looks = [{"passes": 2, "fraction": 0.01, "verdict": None, "p_value": 0.1, "threshold": 1e-6, "crossed": 0,
              "ruled_out": None, "ruled_out_tile": 32, "whole_image": None, "uncovered": 0,
              "seconds": 0.1}]  # fmt: skip

    class Job:
        max_seconds, min_passes, tolerance, paired, seed_offset, auto_samples = None, None, 0.01, False, 0, None

    durations = {"wall": 76.0, "sides": {"reference": 52.0, "test": 52.4}}  # the sides render at once
    check = summary.check_record(Job, looks, 32, look, durations=durations)
    s = summary.summarize(c, ref, test, outcome=look.outcome, check=check)
    report.write_report(tmp_path, s, c, ref, test, significant=look.outcome.significant)
    data = page_data(tmp_path / "report.html")
    assert data["summary"]["check"]["looks"] == looks and data["summary"]["p_value"] is None
    assert data["summary"]["outcome"]["design"] == "sequential"
    # Each duration says what it is: not '1 min 44 s of rendering' (both sides added) in a run of 76 s.
    text = (tmp_path / "report.html").read_text()
    assert f"1 look, {look.passes} passes a side, 1 min 16 s wall clock, rendering: reference 52 s, test 52 s" in text
    fixed = summary.check_record(
        Job, looks, 32, look, durations={"wall": 6.1, "sides": {"reference": 0.0, "test": 5.9}}
    )
    assert summary.durations_text(fixed) == "6.1 s wall clock, rendering: test 5.9 s"  # a suite: a stored reference
    older = summary.check_record(Job, looks, 32, look)  # a check whose state predates the durations
    assert summary.durations_text(older) == "rendering: 0.1 s, sides summed"


def test_compare_imports_no_plotting_library_and_no_scipy_stats(tmp_path):
    ref, test = runs_with_pictures()
    wc.save_stats(tmp_path / "a.npz", ref)
    wc.save_stats(tmp_path / "b.npz", test)
    code = (
        "import sys\n"
        "from batch import cli\n"
        f"code = cli.main(['compare', {str(tmp_path / 'a.npz')!r}, {str(tmp_path / 'b.npz')!r}, '--out', "
        f"{str(tmp_path / 'r')!r}])\n"
        "print(code, sorted(m for m in ('matplotlib', 'scipy.stats', 'OpenEXR', 'PIL') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.stdout.strip().splitlines()[-1] == "1 []", done.stderr


@pytest.mark.parametrize("shape", [(1, 1, 3), (0, 4, 3), (4, 4, 2)])
def test_png_refuses_what_it_cannot_write(shape):
    with pytest.raises(wc.WelchInputError, match="`image` must be a non-empty H×W×3 or H×W×4 uint8 array"):
        wc.png.png_bytes(np.zeros(shape, np.float32 if shape[0] == 1 else np.uint8))


def test_the_pages_json_carries_the_pictures_as_they_are():
    """`script_json` adds the pictures' data URLs without encoding them again: the JSON reads back as the same data
    with them, escaped as ever elsewhere; a picture that is not base64 is refused."""
    data = {"summary": {"scene": "</script><!--&"}, "tiles": [1.0, 2.5], "display": None}
    pictures = {"reference": "data:image/png;base64,iVBORw0KGgo+/=", "test": "data:image/png;base64,AAAA"}
    text = report.script_json(data, pictures)
    assert json.loads(text) == data | {"pictures": pictures}
    assert "<" not in text and ">" not in text and "&" not in text
    assert json.loads(report.script_json({}, {})) == {"pictures": {}}
    with pytest.raises(ValueError, match="a picture must be a data URL in base64"):
        report.script_json(data, {"test": 'data:image/png;base64,"</script>'})
