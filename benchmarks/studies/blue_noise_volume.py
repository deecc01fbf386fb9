"""Cycles' blue-noise pattern against Tabulated Sobol on a cube of fog: the measurement behind
``docs/findings/blue_noise_volume.md``::

    python -m benchmarks.studies.blue_noise_volume          # about 15 min on 2 cores; writes docs/findings/
    python -m benchmarks.studies.blue_noise_volume --quick  # tiny budget into a temporary folder: the pipeline
    python -m benchmarks.studies.blue_noise_volume --parts split ablation   # re-run some parts, their rows replaced
    python -m benchmarks.studies.blue_noise_volume --plot-only              # redraw the chart from the CSV
    python -m benchmarks.studies.blue_noise_volume --save-blend docs/findings/fog.blend  # only the scene, for the CLI

The parts, all on the minimal scene of `fog_scene` (a cube of homogeneous Volume Scatter fog, anisotropy 0.6, lit
by one point light, black world, Cycles' default of 0 volume bounces) unless said otherwise:

- sweep: BLUE_NOISE and TABULATED_SOBOL at 1, 2, 4, ... 64 spp per pass (about 2048 samples per pixel a point),
  each against the reference and against each other. The reference is TABULATED_SOBOL at 1 spp per pass, many
  passes, with a 0.01 px box pixel filter: no sample of such a render is steered by an earlier one, and the filter
  makes Cycles' centred sample 0 harmless. It is cross-checked against SOBOL_BURLEY at 1 spp (a third generator,
  developer-only, enabled through the preferences) and Tabulated Sobol at 256 spp.
- filter: Tabulated Sobol at 1 spp against 256 spp with Cycles' default pixel filter.
- controls, at 2 spp per pass against Tabulated Sobol: blue noise against itself (A/A), AUTOMATIC (identical to
  BLUE_NOISE in a final render), BLUE_NOISE_FIRST and SOBOL_BURLEY, and each sample of a 2-sample render alone.
- split: 2 and 4 spp per pass as one render and with each sample rendered alone (the same random numbers): the
  pattern or the coupling of the samples of a render?
- coupling: does a sample's value depend on the other samples of its render (fog against a surface scene)?
- ablation, at 2 spp per pass, blue noise against Tabulated Sobol: one ingredient changed at a time.

Every difference is the relative difference of the fog region's mean with its 99 % interval (Welch's test on the
per-pass region means) and the project's tile test (`welch_core.compare`, every scale). Every run takes its own
block of seeds, so any two runs are disjoint (unpaired).
"""

from __future__ import annotations

import argparse
import csv
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

import welch_core as wc
from batch.blender import render, scenes

from ..common.cache import REPO
from ..common.plotting import plt, save, write_csv
from ..common.pools import quiet_stdout, say

ALPHA = 0.01  # 99 % intervals, and the tile test's level

# The minimal scene. Cube, density, light and camera are the first values tried; the anisotropy was picked from
# 0, 0.3, 0.6, 0.9 and -0.6 because it makes the effect larger (it is not needed: the ablation).
CUBE_HALF = 1.5  # metres: a 3 m cube of fog at the origin
DENSITY = 0.5
ANISOTROPY = 0.6  # Henyey-Greenstein g; isotropic fog (0) shows the effect too, about 4.5x weaker
LIGHT_ENERGY = 500.0  # watts
LIGHT_LOCATION = (0.0, 0.0, 2.5)  # 1 m above the cube
CAMERA_LOCATION = (0.0, -7.0, 0.0)  # looking along +Y at the cube, 50 mm lens
SCATTER_COLOR = (0.8, 0.3, 0.1)  # the ablation's "scattering colour"
RESOLUTION = 128

FOG_NODE = "Volume Scatter"
ANISOTROPY_PATH = f'materials["Fog"].node_tree.nodes["{FOG_NODE}"].inputs["Anisotropy"].default_value'


@dataclass(frozen=True)
class Budget:
    resolution: int
    tile: int
    sweep_spp: tuple[int, ...]
    samples_per_point: int  # spp x passes of a sweep point, at least `min_passes` passes
    min_passes: int
    ref_passes: int  # of the reference: 1 spp per pass
    high_spp: int  # a high-spp cross-check of the reference
    high_passes: int
    control_passes: int
    split_samples: int  # samples per pixel of each split run (and 1-spp passes of its reference)
    ablation_passes: int
    ablation: tuple[str, ...]


FULL = Budget(128, 32, (1, 2, 4, 8, 16, 32, 64), 2048, 48, 8192, 256, 16, 256, 1024, 128,
              ("minimal", "isotropic", "dof", "color", "principled", "reported", "area", "sun", "world", "noise",
               "bounces", "bounces_isotropic"))  # fmt: skip
QUICK = Budget(64, 16, (1, 2, 8), 64, 8, 128, 32, 4, 16, 32, 16, ("minimal", "isotropic", "sun"))

#: The sweep's pixel filter: a 0.01 px box, so that Cycles' sample 0 (always at the pixel centre) samples the same
#: image as every other sample and the expectation of a pass cannot depend on spp through the filter (`pixel_filter`).
POINT_FILTER = ("BOX", 0.01)

#: Ablation variants: label and `fog_scene` arguments (each one change from the minimal scene).
VARIANTS: dict[str, tuple[str, dict]] = {
    "minimal": ("minimal scene", {}),
    "isotropic": ("isotropic fog (g = 0)", {"anisotropy": 0.0}),
    "dof": ("+ depth of field", {"depth_of_field": True}),
    "color": ("+ scattering colour", {"scatter_color": SCATTER_COLOR}),
    "principled": ("Principled Volume instead of Volume Scatter", {"shader": "PRINCIPLED"}),
    "reported": ("as first reported: Principled, colour, DoF, g = 0",
                 {"shader": "PRINCIPLED", "scatter_color": SCATTER_COLOR, "depth_of_field": True, "anisotropy": 0.0}),
    "area": ("area light (0.5 m) instead of point", {"light": "AREA"}),
    "sun": ("sun light instead of point", {"light": "SUN"}),
    "world": ("white world instead of a lamp", {"light": None, "world_light": True}),
    "noise": ("noise-driven density (heterogeneous)", {"noise_density": True}),
    "bounces": ("1024 volume bounces (multiple scattering)", {"volume_bounces": 1024}),
    "bounces_isotropic": ("1024 volume bounces, g = 0", {"volume_bounces": 1024, "anisotropy": 0.0}),
}  # fmt: skip


# ---------------------------------------------------------------------------------------------------------------
# The scene


def fog_scene(
    anisotropy: float = ANISOTROPY,
    density: float = DENSITY,
    light: str | None = "POINT",
    volume_bounces: int = 0,
    depth_of_field: bool = False,
    scatter_color: tuple[float, float, float] | None = None,
    shader: str = "SCATTER",
    noise_density: bool = False,
    world_light: bool = False,
    name: str = "fog",
) -> bpy.types.Scene:
    """Build the fog scene into the current file and make it the active scene.

    Parameters
    ----------
    anisotropy : float
        Henyey-Greenstein g of the fog.
    density : float
        Density of the fog (its mean, with `noise_density`).
    light : {'POINT', 'AREA', 'SUN'} or None
        The one lamp; None for none.
    volume_bounces : int
        ``cycles.volume_bounces``; 0 (Cycles' default) renders single scattering.
    depth_of_field : bool
        Focus on the cube's front at f/0.5.
    scatter_color : (r, g, b) or None
        The fog's colour; None for white.
    shader : {'SCATTER', 'PRINCIPLED'}
        A Volume Scatter node named "Volume Scatter", or a Principled Volume named "Principled Volume".
    noise_density : bool
        Density driven by a noise texture (a heterogeneous volume).
    world_light : bool
        A white world (strength 1) instead of the black one.
    name : str

    Returns
    -------
    bpy.types.Scene
        128x128 pixels, Cycles with the project's unbiased settings (no clamping, no denoising, ...), the sampling
        pattern left for the render job to set.
    """
    scene = scenes.new_scene(name)
    scene.render.resolution_x = scene.render.resolution_y = RESOLUTION
    # _new_scene raises every bounce limit but this one: 0 is Cycles' default and the bias is largest there.
    scene.cycles.volume_bounces = volume_bounces

    material = bpy.data.materials.new("Fog")
    tree = scenes.node_tree(material)
    tree.nodes.clear()
    if shader == "SCATTER":
        fog = tree.nodes.new("ShaderNodeVolumeScatter")
        fog.name = FOG_NODE
    elif shader == "PRINCIPLED":
        fog = tree.nodes.new("ShaderNodeVolumePrincipled")
        fog.name = "Principled Volume"
    else:
        raise ValueError(f"unknown shader {shader!r}")
    fog.inputs["Density"].default_value = density
    fog.inputs["Anisotropy"].default_value = anisotropy
    if scatter_color is not None:
        fog.inputs["Color"].default_value = (*scatter_color, 1.0)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(fog.outputs["Volume"], out.inputs["Volume"])
    if noise_density:
        scenes.noise_density(tree, fog.inputs["Density"], 2.0 * density, 2.0)  # the noise's Fac averages about 0.5
    scenes.add_box(scene, "Fog", (0.0, 0.0, 0.0), CUBE_HALF, material)

    if light is not None:
        lamp = bpy.data.lights.new("Light", light)
        if light == "SUN":
            lamp.energy = 3.0  # W/m2, shining straight down
        else:
            lamp.energy = LIGHT_ENERGY
        if light == "AREA":
            lamp.size = 0.5
        scenes.link_object(scene, "Light", lamp).location = LIGHT_LOCATION
    if world_light:
        scenes.node_tree(scene.world).nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)

    camera = bpy.data.cameras.new("Camera")
    camera.lens = 50.0
    if depth_of_field:
        camera.dof.use_dof = True
        camera.dof.focus_distance = -CAMERA_LOCATION[1] - CUBE_HALF
        camera.dof.aperture_fstop = 0.5
    cam = scenes.link_object(scene, "Camera", camera)
    cam.location = CAMERA_LOCATION
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)  # from -Z (Blender's camera axis) to +Y
    scene.camera = cam
    return scene


def fresh_scene(**kwargs) -> bpy.types.Scene:
    """`fog_scene` in an empty file (nothing of an earlier scene left), the developer patterns enabled."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    enable_developer_patterns()
    return fog_scene(**kwargs)


def enable_developer_patterns() -> None:
    """Offer SOBOL_BURLEY, BLUE_NOISE_FIRST and BLUE_NOISE_ROUND: the Cycles add-on lists them only with the
    developer UI and the Cycles debug option on, and Cycles renders anything but Tabulated Sobol and blue noise as
    blue noise unless they were on before the first render of the scene (measured: enabled later, SOBOL_BURLEY gave
    BLUE_NOISE's bias). `read_factory_settings` turns them off again."""
    prefs = bpy.context.preferences
    prefs.view.show_developer_ui = True
    prefs.experimental.use_cycles_debug = True


# ---------------------------------------------------------------------------------------------------------------
# Rendering runs and comparing them


@dataclass
class Run:
    """One sampling pattern and spp per pass over a block of seeds: per-pass means of the fog region and tiles."""

    pattern: str
    spp: int
    means: np.ndarray
    stats: wc.TileStats
    seconds: float
    subset: tuple[int, int] | str | None = None  # (offset, length) of ``use_sample_subset``, or "split"


@dataclass
class Seeds:
    """Hands out disjoint blocks of seeds, so that every two runs of this script are unpaired."""

    next: int = 1

    def block(self, n: int) -> range:
        seeds = range(self.next, self.next + n)
        self.next += n
        return seeds


def render_run(
    scene, pattern: str, spp: int, seeds: range, b: Budget, mask: np.ndarray, subset: tuple[int, int] | None = None
) -> Run:
    """Render one pass per seed; `subset` = (offset, length) renders only those samples of a `spp`-sample render."""
    render.configure_unbiased(scene, "CPU", spp, (b.resolution, b.resolution), sampling_pattern=pattern)
    cycles = scene.cycles
    cycles.use_sample_subset = subset is not None  # configure_unbiased leaves it alone: reset it every run
    if subset is not None:
        cycles.sample_offset, cycles.sample_subset_length = subset
    scene.update_tag()
    stats = wc.TileStats(b.resolution, b.resolution, b.tile, 3)
    means = np.empty(len(seeds))
    start = time.perf_counter()
    with quiet_stdout(), render.PassRenderer(scene) as renderer:
        for i, seed in enumerate(seeds):
            image = renderer.render(seed)
            means[i] = image[mask].sum(axis=-1).mean()  # R+G+B over the fog region
            stats.add_pass(image, seed)
    return Run(pattern, spp, means, stats, time.perf_counter() - start, subset)


def render_split(scene, pattern: str, spp: int, seeds: range, b: Budget, mask: np.ndarray) -> Run:
    """`spp`-sample passes assembled from their samples rendered one per render (``use_sample_subset``, the same
    seed): the same random numbers as an `spp`-sample render, but no sample of a render sees another."""
    total = np.zeros((len(seeds), b.resolution, b.resolution, 3), np.float32)
    start = time.perf_counter()
    for sample in range(spp):
        render.configure_unbiased(scene, "CPU", spp, (b.resolution, b.resolution), sampling_pattern=pattern)
        scene.cycles.use_sample_subset = True
        scene.cycles.sample_offset, scene.cycles.sample_subset_length = sample, 1
        scene.update_tag()
        with quiet_stdout(), render.PassRenderer(scene) as renderer:
            for i, seed in enumerate(seeds):
                total[i] += renderer.render(seed)
    scene.cycles.use_sample_subset = False
    stats = wc.TileStats(b.resolution, b.resolution, b.tile, 3)
    means = np.empty(len(seeds))
    for i, seed in enumerate(seeds):
        image = total[i] / spp
        means[i] = image[mask].sum(axis=-1).mean()
        stats.add_pass(image, seed)
    return Run(pattern, spp, means, stats, time.perf_counter() - start, "split")


def fog_mask(scene, b: Budget) -> np.ndarray:
    """The pixels that see fog: non-zero in a 64-spp pass (everything else looks into the black world)."""
    render.configure_unbiased(scene, "CPU", 64, (b.resolution, b.resolution), sampling_pattern="TABULATED_SOBOL")
    with quiet_stdout(), render.PassRenderer(scene) as renderer:
        image = renderer.render(0)  # seed 0 is never handed out by `Seeds`
    return image.sum(axis=-1) > 0


def _region(run: Run) -> wc.TileStats:
    """The fog region's mean of every pass, as the Welch samples of a one-tile run."""
    return wc.TileStats.from_sums(run.means.reshape(-1, 1, 1, 1), run.stats.seeds, 1, 1, 1)


def difference(ref: Run, test: Run) -> dict:
    """(test - ref) / ref of the region mean with its 99 % interval and Welch's p (`compare` on the one-tile runs of
    the region means); the tile test at every scale."""
    region = wc.compare(_region(ref), _region(test), alpha=ALPHA, test_kind="welch")
    result, ref_mean = region.result, float(ref.means.mean())
    low, high = region.effect.ci_low, region.effect.ci_high
    tiles = wc.compare(ref.stats, test.stats, alpha=ALPHA)
    rel = tiles.effect.rel_diff
    return {
        "rel_diff_pct": 100 * float(result.mean_difference) / ref_mean,
        "ci_low_pct": 100 * float(low),
        "ci_high_pct": 100 * float(high),
        "p_value": float(result.pvalue),
        "tile_verdict": tiles.verdict.label,
        "tile_p_value": float(tiles.p_value),
        "tile_min_pct": 100 * float(np.nanmin(rel)) if np.isfinite(rel).any() else None,
        "tile_max_pct": 100 * float(np.nanmax(rel)) if np.isfinite(rel).any() else None,
    }


def row(kind: str, case: str, ref: Run, test: Run, note: str = "") -> dict:
    subset = test.subset if test.subset is None or isinstance(test.subset, str) else "+".join(map(str, test.subset))
    return {
        "kind": kind, "case": case, "pattern": test.pattern, "spp": test.spp, "passes": len(test.means),
        "subset": subset,
        "ref_pattern": ref.pattern, "ref_spp": ref.spp, "ref_passes": len(ref.means),
        **difference(ref, test), "seconds": ref.seconds + test.seconds, "note": note,
    }  # fmt: skip


def show(r: dict) -> None:
    tiles = ""
    if r.get("tile_min_pct") is not None:
        spread = f"{r['tile_min_pct']:+.2f}..{r['tile_max_pct']:+.2f} %"
        tiles = f"tiles {r['tile_verdict']} (p {r['tile_p_value']:.1e}, {spread})"
    say(
        f"  {r['case']:>18} {r['pattern']:>16} {r['spp']:3d} spp x {r['passes']:4d}: {r['rel_diff_pct']:+7.3f} % "
        f"[{r['ci_low_pct']:+.3f}, {r['ci_high_pct']:+.3f}] p {r['p_value']:.1e}  {tiles}"
    )


# ---------------------------------------------------------------------------------------------------------------
# The four parts


def sweep_and_reference(b: Budget, seeds: Seeds, mask: np.ndarray) -> list[dict]:
    """Each pattern at 1 to 64 spp per pass against Tabulated Sobol at 1 spp (the reference), and each other.

    The reference's passes have one sample: the first sample of a render has no earlier sample to be guided by
    (Cycles' volume scattering probability guiding; see the write-up), and with `POINT_FILTER` the pixel filter
    cannot make a pass depend on its spp either."""
    scene = fresh_scene()
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = POINT_FILTER
    say(f"reference: TABULATED_SOBOL, 1 spp x {b.ref_passes} passes")
    ref = render_run(scene, "TABULATED_SOBOL", 1, seeds.block(b.ref_passes), b, mask)
    rows = []
    for pattern, spp, passes, note in (
        ("SOBOL_BURLEY", 1, b.samples_per_point, "a third generator, 1 spp"),
        ("TABULATED_SOBOL", b.high_spp, b.high_passes, "the reference pattern at a high spp per pass"),
    ):
        rows.append(row("reference", "cross-check", ref, render_run(scene, pattern, spp, seeds.block(passes), b, mask),
                        note))  # fmt: skip
        show(rows[-1])
    say("sweep: each pattern at each spp per pass against the reference, and against each other")
    for spp in b.sweep_spp:
        passes = max(b.samples_per_point // spp, b.min_passes)
        runs = {}
        for pattern in ("TABULATED_SOBOL", "BLUE_NOISE"):
            runs[pattern] = render_run(scene, pattern, spp, seeds.block(passes), b, mask)
            rows.append(row("sweep", "minimal", ref, runs[pattern]))
            show(rows[-1])
        rows.append(row("direct", "minimal", runs["TABULATED_SOBOL"], runs["BLUE_NOISE"], "same spp per pass"))
        show(rows[-1])
    return rows


def pixel_filter(b: Budget, seeds: Seeds, mask: np.ndarray) -> list[dict]:
    """Why the sweep uses `POINT_FILTER`: Cycles takes sample 0 of every render at the pixel centre (no filter
    offset), so with the default filter (Blackman-Harris, 1.5 px) a 1-spp pass point-samples the image while a
    256-spp pass filters it. Tabulated Sobol at 1 spp against `high_spp`, default filter; the sweep's reference rows
    have the same comparison with the point filter."""
    scene = fresh_scene()
    high = render_run(scene, "TABULATED_SOBOL", b.high_spp, seeds.block(b.high_passes), b, mask)
    low = render_run(scene, "TABULATED_SOBOL", 1, seeds.block(b.samples_per_point), b, mask)
    rows = [row("filter", "Blackman-Harris 1.5 px", high, low, "default pixel filter: 1 spp against high spp")]
    show(rows[-1])
    return rows


def controls(b: Budget, seeds: Seeds, mask: np.ndarray) -> list[dict]:
    """What the bias needs: blue noise and its variants against Tabulated Sobol, both at 2 spp per pass."""
    scene = fresh_scene()
    n = b.control_passes
    rows = []
    # AUTOMATIC is blue noise in final renders: the same seed gives the same image. The developer patterns must not
    # (Cycles would silently render them as blue noise).
    images = {}
    for pattern in ("AUTOMATIC", "BLUE_NOISE", "BLUE_NOISE_FIRST", "SOBOL_BURLEY"):
        render.configure_unbiased(scene, "CPU", 2, (b.resolution, b.resolution), sampling_pattern=pattern)
        with quiet_stdout(), render.PassRenderer(scene) as renderer:
            images[pattern] = renderer.render(0)
    same = {p: bool(np.array_equal(images[p], images["BLUE_NOISE"])) for p in images}
    say(f"  bit-identical to BLUE_NOISE at the same seed: {same}")
    if same["BLUE_NOISE_FIRST"] or same["SOBOL_BURLEY"]:
        raise RuntimeError("Cycles rendered a developer pattern as BLUE_NOISE: the controls would be meaningless")

    tab = render_run(scene, "TABULATED_SOBOL", 2, seeds.block(n), b, mask)
    blue = render_run(scene, "BLUE_NOISE", 2, seeds.block(n), b, mask)
    rows.append(row("control", "blue noise", tab, blue))
    blue_again = render_run(scene, "BLUE_NOISE", 2, seeds.block(n), b, mask)
    rows.append(row("control", "blue vs blue", blue, blue_again, "A/A: the test on blue noise's own passes"))
    auto = render_run(scene, "AUTOMATIC", 2, seeds.block(n), b, mask)
    rows.append(row("control", "automatic", tab, auto, f"bit-identical to BLUE_NOISE at one seed: {same['AUTOMATIC']}"))
    for pattern, note in (
        ("BLUE_NOISE_FIRST", "sample 0 from a 1-spp blue-noise sequence, sample 1 from another"),
        ("SOBOL_BURLEY", "the blue-noise generator with one sequence per pixel"),
    ):
        rows.append(row("control", pattern.lower(), tab, render_run(scene, pattern, 2, seeds.block(n), b, mask), note))
    # Each sample of a 2-sample render alone: no earlier sample of the same render exists.
    for offset in (0, 1):
        ref = render_run(scene, "TABULATED_SOBOL", 2, seeds.block(n), b, mask, subset=(offset, 1))
        test = render_run(scene, "BLUE_NOISE", 2, seeds.block(n), b, mask, subset=(offset, 1))
        rows.append(row("control", f"sample {offset} alone", ref, test, "use_sample_subset, offset and length 1"))
    for r in rows:
        show(r)
    return rows


def split(b: Budget, seeds: Seeds, mask: np.ndarray) -> list[dict]:
    """Is it the sampling pattern or the coupling of the samples of a render? Each pattern at 2 and 4 spp per pass,
    once as one render and once with its samples rendered apart (`render_split`), against Tabulated Sobol at 1 spp
    (`POINT_FILTER`, so that only the coupling differs). The minimal scene, and at 2 spp the variant where blue noise
    renders darker than Tabulated Sobol (1024 volume bounces, isotropic)."""
    rows = []
    for variant, spps in (("minimal", (2, 4)), ("bounces_isotropic", (2,))):
        scene = fresh_scene(**VARIANTS[variant][1])
        scene.cycles.pixel_filter_type, scene.cycles.filter_width = POINT_FILTER
        ref = render_run(scene, "TABULATED_SOBOL", 1, seeds.block(b.split_samples), b, mask)
        for spp in spps:
            n = b.split_samples // spp
            for pattern in ("TABULATED_SOBOL", "BLUE_NOISE"):
                together = render_run(scene, pattern, spp, seeds.block(n), b, mask)
                rows.append(row("split", f"{variant}, one render", ref, together, "the samples in one render"))
                show(rows[-1])
                apart = render_split(scene, pattern, spp, seeds.block(n), b, mask)
                rows.append(row("split", f"{variant}, apart", ref, apart, "each sample rendered alone, same seed"))
                show(rows[-1])
    return rows


def coupling(b: Budget, seeds: Seeds, mask: np.ndarray) -> list[dict]:
    """Does a sample depend on the other samples of its render? A 2-sample render against the mean of its two
    samples rendered alone (``use_sample_subset``), same seed: equal when every sample depends only on its own
    random numbers. The fog against the project's corner scene (surfaces only)."""
    rows = []
    for name, build in (("fog", fresh_scene), ("corner (surfaces)", _corner)):
        scene = build()
        for pattern in ("TABULATED_SOBOL", "BLUE_NOISE"):
            images = []
            for subset in (None, (0, 1), (1, 1)):
                render.configure_unbiased(scene, "CPU", 2, (b.resolution, b.resolution), sampling_pattern=pattern)
                scene.cycles.use_sample_subset = subset is not None
                if subset is not None:
                    scene.cycles.sample_offset, scene.cycles.sample_subset_length = subset
                scene.update_tag()
                with quiet_stdout(), render.PassRenderer(scene) as renderer:
                    images.append(renderer.render(0))
            full, alone = images[0], (images[1] + images[2]) / 2
            share = float(np.mean(~np.isclose(full, alone, rtol=1e-5, atol=1e-7)))
            note = (
                f"2-sample render vs mean of its samples rendered alone, seed 0: {share:.1%} of pixel values differ, "
                f"mean {alone.mean():.5g} -> {full.mean():.5g}"
            )
            rows.append({"kind": "coupling", "case": name, "pattern": pattern, "spp": 2, "passes": 1, "note": note})
            say(f"  {name:>18} {pattern:>16}: {note}")
    return rows


def _corner() -> bpy.types.Scene:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return scenes.build_scene("corner")


def ablation(b: Budget, seeds: Seeds, mask: np.ndarray) -> list[dict]:
    """Blue noise against Tabulated Sobol at 2 spp per pass, one ingredient changed at a time."""
    rows = []
    for name in b.ablation:
        label, kwargs = VARIANTS[name]
        scene = fresh_scene(**kwargs)
        tab = render_run(scene, "TABULATED_SOBOL", 2, seeds.block(b.ablation_passes), b, mask)
        blue = render_run(scene, "BLUE_NOISE", 2, seeds.block(b.ablation_passes), b, mask)
        rows.append(row("ablation", name, tab, blue, label))
        show(rows[-1])
    return rows


# ---------------------------------------------------------------------------------------------------------------
# Output


def _p(p: float) -> str:
    return "< 1e-300" if p == 0 else f"{p:.0e}"


def plot(path: Path, rows: list[dict]) -> str:
    fig, (left, right) = plt.subplots(1, 2, figsize=(16, 6.2), width_ratios=[1.1, 1], layout="constrained")
    colors = {"BLUE_NOISE": "#d62728", "TABULATED_SOBOL": "#1f77b4"}
    for pattern, shift in (("TABULATED_SOBOL", 0.94), ("BLUE_NOISE", 1.06)):
        pts = [r for r in rows if r["kind"] == "sweep" and r["pattern"] == pattern]
        x = np.array([r["spp"] for r in pts]) * shift
        y = np.array([r["rel_diff_pct"] for r in pts])
        err = [y - [r["ci_low_pct"] for r in pts], [r["ci_high_pct"] for r in pts] - y]
        left.errorbar(x, y, yerr=err, fmt="o-", color=colors[pattern], capsize=3, label=pattern)
    pts = [r for r in rows if r["kind"] == "direct"]
    x = np.array([r["spp"] for r in pts], dtype=float)
    y = np.array([r["rel_diff_pct"] for r in pts])
    err = [y - [r["ci_low_pct"] for r in pts], [r["ci_high_pct"] for r in pts] - y]
    left.errorbar(x, y, yerr=err, fmt="o--", mfc="white", color=colors["BLUE_NOISE"], capsize=3, alpha=0.7,
                  label="BLUE_NOISE vs TABULATED_SOBOL at the same spp")  # fmt: skip
    # The split control: the same spp, each sample rendered alone (no sample of a render steered by another).
    for pattern, shift, color in (("TABULATED_SOBOL", 0.94, "#17becf"), ("BLUE_NOISE", 1.06, "#ff7f0e")):
        pts = [r for r in rows if r["kind"] == "split" and r["pattern"] == pattern and r["case"] == "minimal, apart"]
        if pts:
            x = np.array([r["spp"] for r in pts]) * shift
            y = np.array([r["rel_diff_pct"] for r in pts])
            err = [y - [r["ci_low_pct"] for r in pts], [r["ci_high_pct"] for r in pts] - y]
            left.errorbar(x, y, yerr=err, fmt="^", color=color, capsize=3, ms=8,
                          label=f"{pattern}, its samples rendered apart")  # fmt: skip
    for r, marker in zip([r for r in rows if r["kind"] == "reference"], "sD", strict=False):
        left.errorbar([r["spp"]], [r["rel_diff_pct"]], yerr=[[r["rel_diff_pct"] - r["ci_low_pct"]],
                      [r["ci_high_pct"] - r["rel_diff_pct"]]], fmt=marker, color="#7f7f7f", capsize=3,
                      label=f"{r['pattern']}, {r['spp']} spp x {r['passes']} (cross-check)")  # fmt: skip
    ref = rows[0]
    left.axhline(0.0, color="black", lw=0.8)
    left.set_xscale("log", base=2)
    left.set_xlabel("samples per pixel per pass (one render)")
    left.set_ylabel("fog region: (pattern - reference) / reference, %")
    left.set_title(
        f"Against TABULATED_SOBOL at {ref['ref_spp']} spp x {ref['ref_passes']} passes, 0.01 px box filter "
        "(99 % intervals)",
        fontsize=10,
    )
    left.grid(alpha=0.3, which="both", lw=0.4)
    left.legend(fontsize=8)

    abl = [r for r in rows if r["kind"] == "ablation"]
    y = np.arange(len(abl))[::-1]
    val = np.array([r["rel_diff_pct"] for r in abl])
    err = [val - [r["ci_low_pct"] for r in abl], [r["ci_high_pct"] for r in abl] - val]
    significant = np.array([r["p_value"] <= ALPHA for r in abl])
    right.barh(y, val, color=np.where(significant, "#d62728", "#bbbbbb"), xerr=err, capsize=3)
    for yi, r in zip(y, abl, strict=True):
        if r["tile_min_pct"] is not None:
            right.plot([r["tile_min_pct"], r["tile_max_pct"]], [yi - 0.3] * 2, "|-", color="black", lw=0.8, ms=6)
    right.set_yticks(y, [f"{r['note']}\n(tiles: {r['tile_verdict']}, p {_p(r['tile_p_value'])})" for r in abl],
                     fontsize=7)  # fmt: skip
    right.axvline(0.0, color="black", lw=0.8)
    right.set_xlabel("BLUE_NOISE vs TABULATED_SOBOL at 2 spp per pass, %  (bar: region, 99 %; line: tile range)")
    right.set_title("One change at a time (red: region p <= 0.01)", fontsize=10)
    right.grid(alpha=0.3, axis="x", lw=0.4)
    fig.suptitle(f"Cycles {bpy.app.version_string}: a cube of fog by sampling pattern and samples per render")
    return save(fig, path)


def save_blend(path: Path) -> None:
    """The minimal scene as a .blend for ``python -m batch render``."""
    fresh_scene()
    path.parent.mkdir(parents=True, exist_ok=True)
    with quiet_stdout():
        bpy.ops.wm.save_as_mainfile(filepath=str(path.resolve()), compress=True)
    say(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")


#: The parts in the order they run and are written; each writes rows of its own kinds.
PARTS = {
    "sweep": (sweep_and_reference, ("reference", "sweep", "direct"),
              "each pattern at 1-64 spp per pass against Tabulated Sobol at 1 spp, and each other"),
    "filter": (pixel_filter, ("filter",), "Tabulated Sobol at 1 spp against high spp, Cycles' default pixel filter"),
    "controls": (controls, ("control",), "blue noise and its variants against Tabulated Sobol at 2 spp per pass"),
    "split": (split, ("split",), "2 and 4 spp per pass as one render and with the samples rendered apart"),
    "coupling": (coupling, ("coupling",), "does a sample depend on the other samples of its render?"),
    "ablation": (ablation, ("ablation",), "blue noise against Tabulated Sobol at 2 spp per pass, one change at a time"),
}  # fmt: skip


def read_rows(path: Path) -> list[dict]:
    """The rows of an earlier run's CSV, numbers as numbers."""

    def value(text: str):
        for kind in (int, float):
            try:
                return kind(text)
            except ValueError:
                pass
        return text or None

    with open(path, newline="") as f:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(f)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.studies.blue_noise_volume",
        description="Blue noise against Tabulated Sobol on a cube of fog (docs/findings/blue_noise_volume.md).",
    )
    parser.add_argument("--quick", action="store_true", help="tiny budget (checks the pipeline, not the figures)")
    parser.add_argument("--out", type=Path, help="output folder (default docs/findings, or a temp folder with --quick)")
    parser.add_argument("--parts", nargs="+", choices=list(PARTS), help="run these parts only and replace their rows "
                        "in the existing CSV (default: all)")  # fmt: skip
    parser.add_argument("--save-blend", type=Path, metavar="PATH", help="only save the minimal scene as a .blend")
    parser.add_argument("--plot-only", action="store_true", help="only redraw the chart from the existing CSV")
    args = parser.parse_args(argv)
    if args.save_blend is not None:
        save_blend(args.save_blend)
        return 0
    b = QUICK if args.quick else FULL
    out = args.out or (Path(tempfile.gettempdir()) / "blue_noise_volume" if args.quick else REPO / "docs" / "findings")
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "blue_noise_volume.csv"
    if args.plot_only:
        say(f"wrote {out / plot(out / 'blue_noise_volume.png', read_rows(csv_path))}")
        return 0
    parts = args.parts or list(PARTS)
    rows = []
    if args.parts and csv_path.exists():
        rerun = {kind for name in parts for kind in PARTS[name][1]}
        rows = [r for r in read_rows(csv_path) if r["kind"] not in rerun]
    start = time.perf_counter()
    say(f"Cycles {bpy.app.version_string} ({bpy.app.build_hash.decode()}), {b.resolution}^2 pixels, {b.tile} px tiles")
    mask = fog_mask(fresh_scene(), b)
    say(f"fog region: {mask.mean():.0%} of the frame")
    for index, name in enumerate(PARTS):
        if name in parts:
            say(f"{name}: {PARTS[name][2]}")
            # Each part its own range of seeds: every two runs of this script are disjoint, whatever was re-run.
            rows += PARTS[name][0](b, Seeds(1 + index * 10_000_000), mask)
    order = [kind for _, kinds, _ in PARTS.values() for kind in kinds]
    rows.sort(key=lambda r: order.index(r["kind"]))  # stable: each part's rows keep their order
    files = [write_csv(csv_path, rows), plot(out / "blue_noise_volume.png", rows)]
    say(f"done in {time.perf_counter() - start:.0f} s: {', '.join(str(out / f) for f in files)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
