"""Light components and light groups (batch.jobs.lobes, ``--lobes``, ``ingest --layers``): the pass arithmetic with
the names of Blender 5.0 and of 3.4, the layers through ingest, merge and compare, and real Cycles renders where a
change of one lobe shows in that lobe only."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

import welch_core as wc
from batch import cli
from batch.errors import BatchError, Exit
from batch.jobs import lobes
from tests.helpers.layers import ingest_layers, write_layered_passes


def test_parse_lobes():
    assert lobes.parse_lobes("all") == lobes.LOBES
    assert lobes.parse_lobes("glossy, diffuse") == ("diffuse", "glossy")
    with pytest.raises(BatchError, match=re.escape("--lobes takes 'all' or some of diffuse,glossy,transmission,")):
        lobes.parse_lobes("diffuse,sss")


def pass_channels(rng, names: dict[str, str], shape=(4, 6), prefix="ViewLayer.") -> dict[str, np.ndarray]:
    """Channels of a multilayer pass: each colour-split lobe's direct, indirect and colour, the additive ones, and
    Combined as their sum, under the names of one Blender version (`names`: component part -> pass name)."""
    channels, combined = {}, np.zeros((*shape, 3), np.float32)
    for lobe in ("Diffuse", "Glossy", "Transmission"):
        d, i, c = (rng.uniform(0.1, 1.0, (*shape, 3)).astype(np.float32) for _ in range(3))
        for part, value in (("Direct", d), ("Indirect", i), ("Color", c)):
            for k, ch in enumerate("RGB"):
                channels[f"{prefix}{names[lobe + ' ' + part]}.{ch}"] = value[..., k]
        combined += (d + i) * c
    for name in ("Volume Direct", "Volume Indirect", "Emission", "Environment"):
        value = rng.uniform(0.0, 0.2, (*shape, 3)).astype(np.float32)
        for k, ch in enumerate("RGB"):
            channels[f"{prefix}{names[name]}.{ch}"] = value[..., k]
        combined += value
    for k, ch in enumerate("RGBA"):
        channels[f"{prefix}Combined.{ch}"] = combined[..., k] if k < 3 else np.ones(shape, np.float32)
    for k, ch in enumerate("RGB"):
        channels[f"{prefix}Combined_key.{ch}"] = combined[..., k] * 0.5
    return channels


NAMES_50 = {n: n for n in ("Diffuse Direct", "Diffuse Indirect", "Diffuse Color", "Glossy Direct", "Glossy Indirect",
            "Glossy Color", "Transmission Direct", "Transmission Indirect", "Transmission Color", "Volume Direct",
            "Volume Indirect", "Emission", "Environment")}  # fmt: skip
OLD_NAMES = ("DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol", "TransDir", "TransInd", "TransCol",
             "VolumeDir", "VolumeInd", "Emit", "Env")  # fmt: skip
NAMES_34 = dict(zip(NAMES_50, OLD_NAMES, strict=True))


@pytest.mark.parametrize("names", [NAMES_50, NAMES_34], ids=["blender-5.0", "blender-3.4"])
def test_components_add_up_to_combined_with_either_blenders_names(names):
    channels = pass_channels(np.random.default_rng(1), names)
    layers = lobes.layers_from_channels(channels, lobes.LOBES)
    assert list(layers) == ["combined", *lobes.COMPONENTS, "lightgroup:key"]
    total = sum(layers[name] for name in lobes.COMPONENTS)
    np.testing.assert_allclose(total, layers["combined"], rtol=1e-6)
    np.testing.assert_allclose(layers["lightgroup:key"], layers["combined"] * 0.5, rtol=1e-6)
    assert wc.component_sum_error(layers["combined"], [layers[n] for n in lobes.COMPONENTS]) < 1e-6
    missing = [layers[n] for n in lobes.COMPONENTS if n != "glossy"]
    assert wc.component_sum_error(layers["combined"], missing) > 0.01
    with pytest.raises(BatchError, match="the pass has no 'Glossy Direct' layer"):
        lobes.layers_from_channels({k: v for k, v in channels.items() if "Gloss" not in k}, ("glossy",))


def test_ingest_merge_and_compare_test_every_layer(tmp_path, capsys):
    ref = ingest_layers(tmp_path, "ref", range(0, 24))
    test = ingest_layers(tmp_path, "test", range(100, 124), glossy_scale=1.15)
    layers = wc.load_layers(test)
    assert list(layers) == ["diffuse", "glossy"] and layers["glossy"].n == 24
    assert cli.main(["compare", ref, test, "--out", str(tmp_path / "r")]) == Exit.BIASED
    out = capsys.readouterr().out
    assert "layer glossy: biased" in out and "layer diffuse: no evidence of bias" in out
    assert "the difference is in glossy" in out
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    rows = {row["name"]: row for row in report["layers"]["layers"]}
    assert rows["glossy"]["verdict"] == "biased" and rows["diffuse"]["verdict"] == "no_evidence"
    assert 0.1 < rows["glossy"]["largest"]["estimate"] < 0.6 and 0.55 < rows["diffuse"]["share"] < 0.8
    assert report["layers"]["alpha"] == pytest.approx(0.01 / 2)  # Bonferroni over the two layers
    assert report["layers"]["explained_by"] == ["glossy"]
    assert report["layers"]["component_sum"] == {"reference": None, "test": None}  # not every component
    html = (tmp_path / "r" / "report.html").read_text()
    assert html.count('<tr class="layer"') == 2 and 'alt="p-value map of glossy"' in html
    # Merge keeps the layers; runs with other layers do not merge.
    more = ingest_layers(tmp_path, "more", range(200, 208))
    assert cli.main(["merge", ref, more, "--out", str(tmp_path / "merged.npz")]) == 0
    assert wc.load_layers(tmp_path / "merged.npz")["glossy"].n == 32
    plain = tmp_path / "plain.npz"
    wc.save_stats(plain, wc.load_stats(more))
    assert cli.main(["merge", ref, str(plain), "--out", str(tmp_path / "m2.npz")]) == Exit.USAGE
    assert "its layers (none) differ from" in capsys.readouterr().err


def test_layers_only_one_run_has_are_named_as_not_tested(tmp_path, capsys):
    ref = ingest_layers(tmp_path, "ref", range(0, 16))
    test = ingest_layers(tmp_path, "test", range(100, 116), layers="diffuse")
    cli.main(["compare", ref, test, "--out", str(tmp_path / "r")])
    assert "not tested: glossy (only the reference has it)" in capsys.readouterr().out
    report = json.loads((tmp_path / "r" / "report.json").read_text())
    assert [row["name"] for row in report["layers"]["layers"]] == ["diffuse"]
    assert report["layers"]["untested"] == {"reference": ["glossy"], "test": []}
    assert "not tested: glossy (only the reference has it)" in (tmp_path / "r" / "report.html").read_text()
    plain = tmp_path / "plain.npz"  # no layers at all on the test side
    wc.save_stats(plain, wc.load_stats(test))
    cli.main(["compare", ref, str(plain), "--out", str(tmp_path / "p")])
    assert "not tested: diffuse, glossy (only the reference has them)" in capsys.readouterr().out


def test_ingest_names_a_missing_layer(tmp_path, capsys):
    folder = tmp_path / "p"
    folder.mkdir()
    paths = write_layered_passes(folder, range(2), drop="glossy")
    args = ["ingest", *paths, "--spp", "1", "--tile", "8", "--layers", "glossy", "--out", str(tmp_path / "x.npz")]
    assert cli.main(args) == Exit.USAGE
    assert "has no layer 'glossy' with R, G, B (its layers: diffuse)" in capsys.readouterr().err


# -- real renders ------------------------------------------------------------------------------------------------


FLOOR = 'materials["CheckerFloor"].node_tree.nodes["Principled BSDF"].inputs'
#: The `glossy` scene with a rough metal floor under its sharp metal sphere, and no reflective caustics: Filter
#: Glossy then acts on the floor's reflection of the sphere (a sharp glossy bounce after a blurry one), which is
#: glossy light. With caustics on, its larger effect is on the caustic the sphere casts onto the walls, which is
#: light on diffuse surfaces: measured, Filter Glossy is then biased in diffuse and not in glossy.
GLOSSY_FLOOR = [f'{FLOOR}["Metallic"].default_value=1', f'{FLOOR}["Roughness"].default_value=0.5',
                "cycles.caustics_reflective=False"]  # fmt: skip
WALLS = 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value'


def render(tmp_path, name, seeds, *extra, floor=True):
    out = tmp_path / f"{name}.npz"
    overrides = [a for o in GLOSSY_FLOOR for a in ("--set", o)] if floor else []
    done = subprocess.run(
        [sys.executable, "-m", "batch", "render", "--scene", "glossy", "--seeds", seeds, "--spp", "1",
         "--resolution", "64", "64", "--tile", "8", "--sampling-pattern", "TABULATED_SOBOL", "--out", str(out),
         *overrides, *extra],
        capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    return str(out)


def compare_layers(tmp_path, ref, test, name):
    out = tmp_path / name
    code = cli.main(["compare", ref, test, "--out", str(out)])
    report = json.loads((out / "report.json").read_text())
    return code, report, {row["name"]: row["verdict"] for row in report["layers"]["layers"]}


@pytest.mark.slow
def test_a_change_of_one_lobe_shows_in_that_lobe(tmp_path):
    """Cycles with every component: Filter Glossy on is biased in glossy, not in diffuse; a wall colour change is
    biased in diffuse, not in glossy (at 32 passes: the sphere and the floor reflect the walls, so their glossy
    light changes too, by a fraction too small to show that soon); the components add up to the image."""
    # 4 spp a pass: at 1 spp Filter Glossy's -0.4 % over the image is at the edge of 512 passes (p 0.018 or 1e-3,
    # by the seeds); at 4 spp p 4e-9, glossy 8e-9, diffuse 1 (22 s of rendering for both runs).
    ref = render(tmp_path, "ref", "0:512", "--lobes", "all", "--spp", "4")
    blur = render(tmp_path, "blur", "1000:1512", "--lobes", "all", "--set", "cycles.blur_glossy=1.0", "--spp", "4")
    plain = render(tmp_path, "plain", "3000:3032", "--lobes", "all", floor=False)
    walls = render(tmp_path, "walls", "2000:2032", "--lobes", "all", "--set", f"{WALLS}=0.21,0.21,0.21,1", floor=False)
    layers = wc.load_layers(ref)
    assert list(layers) == list(lobes.COMPONENTS)  # no light group in this scene: none asked for by 'all'
    code, report, verdicts = compare_layers(tmp_path, ref, blur, "blur")
    assert code == Exit.BIASED and verdicts["glossy"] == "biased" and verdicts["diffuse"] == "no_evidence"
    assert report["layers"]["component_sum"]["reference"]["ok"] and report["layers"]["component_sum"]["test"]["ok"]
    code, report, verdicts = compare_layers(tmp_path, plain, walls, "walls")
    assert code == Exit.BIASED and verdicts["diffuse"] == "biased" and verdicts["glossy"] != "biased"
    assert "diffuse" in report["layers"]["explained_by"] and "glossy" not in report["layers"]["explained_by"]


@pytest.mark.slow
def test_a_light_strength_change_is_found_in_its_light_group(tmp_path):
    """Two light groups in the many-lights scene (set up with overrides): a stronger light shows in its group."""
    groups = [f'objects["Small{i:02d}"].lightgroup={"warm" if i < 8 else "cool"}' for i in range(16)]
    setup = ["--scene", "many_lights"]
    extra = ["--lobes", "lightgroups", *[a for g in groups for a in ("--set", g)]]
    ref = render_scene(tmp_path, "ref", "0:48", setup, extra)
    test = render_scene(tmp_path, "test", "100:148", setup, [*extra, "--set", 'lights["Small03"].energy=25'])
    code, report, verdicts = compare_layers(tmp_path, ref, test, "light")
    assert verdicts == {"lightgroup:cool": "no_evidence", "lightgroup:warm": "biased"}


def render_scene(tmp_path, name, seeds, setup, extra):
    out = tmp_path / f"{name}.npz"
    done = subprocess.run(
        [sys.executable, "-m", "batch", "render", *setup, "--seeds", seeds, "--spp", "1", "--resolution", "64", "64",
         "--tile", "16", "--sampling-pattern", "TABULATED_SOBOL", "--out", str(out), *extra],
        capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    return str(out)


@pytest.mark.slow
def test_the_components_add_up_to_the_image_in_every_builtin_scene():
    """Each built-in scene, two passes at 32x32 with every component: their tile sums add up to Combined's (the
    check that flags a missing or double-counted component; volumes, SSS, hair and the environment included)."""
    from batch.blender import render
    from batch.blender.scenes import SCENES

    worst = {}
    for name in SCENES:
        scene = render.open_scene(None, name)
        render.configure_unbiased(scene, "CPU", 1, (32, 32), "TABULATED_SOBOL", lobes=lobes.COMPONENTS)
        with render.PassRenderer(scene, lobes=lobes.COMPONENTS) as renderer:
            for seed in (0, 1):
                layers = renderer.render_layers(seed)
                sums = {key: wc.tile_sums(image, 8) for key, image in layers.items()}
                error = wc.component_sum_error(sums["combined"], [sums[c] for c in lobes.COMPONENTS])
                worst[name] = max(worst.get(name, 0.0), error)
    assert max(worst.values()) <= wc.layers.SUM_TOLERANCE, worst


@pytest.mark.slow
def test_check_with_lobes_tests_each_layer_of_the_final_passes(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "batch", "check", "--scene", "corner", "--set", f"{WALLS}=0.21,0.21,0.21,1",
         "--lobes", "diffuse,glossy", "--resolution", "32", "32", "--tile", "8", "--max-passes", "16",
         "--sampling-pattern", "TABULATED_SOBOL", "--out", str(tmp_path)],
        capture_output=True, text=True,
    )  # fmt: skip
    assert done.returncode == Exit.BIASED, done.stderr[-2000:]
    assert "layer diffuse: biased" in done.stdout and "layer glossy: no light in either run" in done.stdout
    layers = json.loads((tmp_path / "report.json").read_text())["layers"]
    assert layers["after_looks"] and layers["explained_by"] == ["diffuse"]
    assert "tested once on the final passes" in (tmp_path / "report.html").read_text()
