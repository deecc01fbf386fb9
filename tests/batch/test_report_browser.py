"""The HTML report in a real browser (Debian's Chromium, headless, driven by Playwright): the canvas is drawn, the
layers switch, hovering a tile shows its numbers, and a screenshot is saved (docs/screenshots/report.png)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
playwright = pytest.importorskip("playwright.sync_api", reason="playwright is not installed (pip install playwright)")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None, reason="no chromium on PATH (apt-get install chromium; ./dev test does it)"),
]

SCREENSHOT = ROOT / "docs" / "screenshots" / "report.png"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run"]  # fmt: skip


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The demo's comparison, smaller: the corner scene against walls of grey 0.21, rendered for real."""
    out = tmp_path_factory.mktemp("demo")
    done = subprocess.run(
        [sys.executable, "-m", "batch", "demo", "--out", str(out), "--passes", "24", "--resolution", "128"],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return out / "report.html"


@pytest.fixture(scope="module")
def page(report):
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        errors = []
        page.on("pageerror", lambda error: errors.append(str(error)))
        page.goto(report.as_uri())
        page.wait_for_function("document.body.dataset.drawn === 'yes'", timeout=20000)
        yield page, errors
        browser.close()


def canvas_colours(page) -> int:
    """Distinct colours on the canvas (a drawn picture has many, an empty canvas one)."""
    return page.evaluate(
        """() => { const c = document.getElementById('canvas'), d = c.getContext('2d').getImageData(0, 0, c.width,
        c.height).data, seen = new Set(); for (let i = 0; i < d.length; i += 4) seen.add(d[i] << 16 | d[i + 1] << 8 |
        d[i + 2]); return seen.size; }"""
    )


def canvas_mean(page) -> list[float]:
    """The canvas's mean red, green and blue."""
    return page.evaluate(
        """() => { const c = document.getElementById('canvas'), d = c.getContext('2d').getImageData(0, 0, c.width,
        c.height).data, sum = [0, 0, 0]; for (let i = 0; i < d.length; i += 4) for (let k = 0; k < 3; k++)
        sum[k] += d[i + k]; return sum.map(s => s / (d.length / 4)); }"""
    )


def test_the_canvas_is_drawn_and_layers_switch(page):
    page, errors = page
    assert errors == []
    assert page.locator("#verdict").inner_text() == "Biased"
    assert canvas_colours(page) > 20  # an undrawn canvas has one colour
    before = page.evaluate("document.getElementById('canvas').toDataURL()")
    legends = set()
    for layer in ("effect", "scale", "log10", "q", "none"):
        page.select_option("#layer", layer)
        legends.add(page.locator("#legend-text").inner_text())
        if layer in ("effect", "none"):  # every tile has p ~ 0 here: the p-value layers all show it yellow
            assert page.evaluate("document.getElementById('canvas').toDataURL()") != before
    assert len(legends) == 5
    page.select_option("#layer", "none")
    on_test = page.evaluate("document.getElementById('canvas').toDataURL()")
    assert page.locator("#difference-bar").is_hidden()
    page.select_option("#base", "difference")  # test - reference per pixel, with its scale bar
    assert page.evaluate("document.getElementById('canvas').toDataURL()") != on_test
    red, _green, blue = canvas_mean(page)  # the palette picture drawn: the test side brighter, so more red than blue
    assert red > blue + 10, (red, blue)
    assert page.locator("#difference-bar").is_visible()
    assert "brighter (of the reference's mean brightness" in page.locator("#difference-text").inner_text()
    page.click("#flip")  # A/B: from anything to the test side, then between the sides
    assert page.evaluate("baseSelect.value") == "test"
    page.click("#flip")
    assert page.evaluate("baseSelect.value") == "reference" and page.locator("#difference-bar").is_hidden()
    assert page.evaluate("document.getElementById('canvas').toDataURL()") != on_test  # the other side drawn
    page.select_option("#base", "test")
    page.select_option("#layer", "min")


def test_hovering_a_tile_shows_its_numbers(page):
    page, errors = page
    box = page.locator("#canvas").bounding_box()
    data = page.evaluate("[G.tiles_x, G.tile, disp.factor, zoom]")
    tiles_x, tile, factor, zoom = data
    size = tile / factor * zoom
    page.mouse.move(box["x"] + 1.5 * size, box["y"] + 0.5 * size)  # row 0, column 1
    info = page.locator("#tile-info").inner_text()
    assert f"x {tile}, y 0" in info and "p (channels combined)" in info and "test vs reference" in info
    shown = page.evaluate("fmtP(T.tile_p[1])")
    assert shown in info
    page.mouse.click(box["x"] + 1.5 * size, box["y"] + 0.5 * size)
    page.mouse.move(box["x"] + 2, box["y"] + box["height"] - 2)  # elsewhere: the clicked tile stays shown
    assert f"x {tile}, y 0" in page.locator("#tile-info").inner_text()
    page.locator("#top tr.row").first.click()
    assert page.evaluate("pinned") == page.evaluate("+document.querySelector('#top tr.row').dataset.tile")
    assert errors == []


def test_zoom_and_screenshot(page, tmp_path):
    page, errors = page
    width = page.evaluate("document.getElementById('canvas').width")
    page.click("#zoom-in")
    assert page.evaluate("document.getElementById('canvas').width") > width
    page.click("#zoom-fit")
    page.mouse.move(*_centre(page))
    shot = tmp_path / "report.png"
    page.screenshot(path=str(shot), full_page=True)
    assert shot.stat().st_size > 50_000
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(shot, SCREENSHOT)
    assert errors == []


def _centre(page):
    box = page.locator("#canvas").bounding_box()
    return box["x"] + box["width"] * 0.55, box["y"] + box["height"] * 0.45


def test_a_report_with_layers_and_untestable_scales_is_drawn(page, tmp_path):
    """Layers (ingest --layers) and a run whose coarsest scales have no p-value (null in the page's data): the page
    draws, shows a row per layer, and no script error occurs."""
    from batch import cli
    from tests.helpers.layers import ingest_layers

    ref = ingest_layers(tmp_path, "ref", range(0, 12))
    test = ingest_layers(tmp_path, "test", range(100, 112), glossy_scale=1.2)
    cli.main(["compare", ref, test, "--out", str(tmp_path / "r")])
    layers = page[0].context.browser.new_page()  # the browser of the demo's page: one browser per module
    errors = []
    layers.on("pageerror", lambda error: errors.append(str(error)))
    layers.goto((tmp_path / "r" / "report.html").as_uri())
    layers.wait_for_function("document.body.dataset.drawn === 'yes'", timeout=20000)
    assert errors == []
    assert layers.locator("#layers tr.layer").count() == 2
    assert layers.evaluate("[...document.querySelectorAll('#layers img')].every(i => i.naturalWidth > 0)")
    assert layers.evaluate("fmtP(null)") == "n/a"
    layers.close()
