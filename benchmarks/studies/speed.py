"""The four speed goals of the tool, each printed as a ratio against a baseline measured in the same run (the
machine may be shared and noisy: baselines and candidates are interleaved and the medians compared).

Run from the repository root::

    python -m benchmarks.studies.speed            # all four
    python -m benchmarks.studies.speed compare    # some: compare, passes, reseed, report, lobes

compare  ``python -m batch compare`` as a whole process (statistics files of 32 passes a side, 32x32 tiles, with
         their pixel sums) against ``python -c "import numpy, scipy.special"``, at 1024x576 and 3840x2160, and
         at 1024x576 with 256 v 4 passes (the permutation test's cost, unbiased and biased), and at 1024x576 with
         the pixel moments that rendered runs keep, with the pixel-variance test (``--pixel-variance on``) and
         without it (``off``: no moments read); the project's modules compiled once before the timed runs, as an
         installed tool has them;
         and the statistics alone (`compare` at the stored tile size) against scipy's ``ttest_ind_from_stats``.
         Goals: <= 2.5x and <= 1.2x.
passes   A pass through the pipeline (`PassRenderer` + `render_passes`: render, save and read the EXR, tile sums,
         checkpoints, progress) against Cycles' bare ``bpy.ops.render.render()`` with the same re-seeding, on the
         corner scene at 128x128 and 256x256, 1 spp. Goal: <= 1.05x.
reseed   A re-seeded render of a scene with a homogeneous volume and a moving sphere under motion blur, against a
         second render with the same seed (persistent data: nothing to re-sync). Goal: <= 1.2x.
report   Writing the demo's report (summary, report.json, report.html, pvalues.exr) for its 128x128, 32-pass
         comparison. Goal: <= 0.1 s.
lobes    A pass with the six light components (``--lobes``: the passes enabled, a multilayer EXR, six more tile
         sums) against a plain pass, on the glossy scene at 128x128 and 256x256 (no goal: the cost is stated).

Nothing is asserted: the figures go into docs/results.md.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import welch_core as wc
from batch.present.progress import Progress

from ..common.cache import REPO
from ..common.measure import best_time

PYTHON = sys.executable
SIZES = {"1024x576": (576, 1024), "3840x2160": (2160, 3840)}
TILE, PASSES = 32, 32


def line(name: str, value: float, baseline: float, goal: float | None, unit: str = "s") -> None:
    ratio = value / baseline
    verdict = "" if goal is None else f"  ({'meets' if ratio <= goal else 'misses'} the goal {goal:g}x)"
    print(f"  {name:<58} {value:8.3f} {unit} / {baseline:8.3f} {unit} = {ratio:5.2f}x{verdict}")


def synthetic_run(height: int, width: int, first_seed: int, rng: np.random.Generator, passes: int = PASSES,
                  shift: float = 0.0) -> wc.TileStats:  # fmt: skip
    ty, tx = -(-height // TILE), -(-width // TILE)  # partial tiles at the edges, as the tool makes them
    sums = rng.normal(1000.0 + shift, 10.0, (passes, ty, tx, 3))
    pixels = rng.uniform(0.0, 2.0, (height, width, 3)).astype(np.float32) * passes
    return wc.TileStats.from_sums(sums, range(first_seed, first_seed + passes), height, width, TILE, pixel_sum=pixels)


#: Unequal pass counts (a blessed reference against a short test run): `biased` needs the permutation test too;
#: an unbiased pair stops drawing resamples early, a biased one draws them all (999 at alpha 0.01).
UNEQUAL = {"1024x576, 256 v 4, unbiased": 0.0, "1024x576, 256 v 4, biased": 30.0}
#: Runs with pixel moments, as `render` and `check` write them: compare with the pixel test and without.
MOMENTS = {"1024x576 with pixel moments, pixel test on": "on", "1024x576 with pixel moments, pixel test off": "off"}


def passes_run(height: int, width: int, first_seed: int, rng: np.random.Generator) -> wc.TileStats:
    """A run of `PASSES` noisy passes added as the render loop adds them: tile sums and pixel moments. Every run
    is of the same image (its own noise): an A/A pair."""
    run = wc.TileStats(height, width, TILE, 3, keep_pixel_moments=True)
    base = np.random.default_rng(0).uniform(0.05, 2.0, (height, width, 3)).astype(np.float32)
    for seed in range(first_seed, first_seed + PASSES):
        run.add_pass(base * rng.gamma(4.0, 0.25, base.shape).astype(np.float32), seed)
    return run


def interleaved(commands: dict[str, list[str]], repeats: int, bytecode: str | None = None) -> dict[str, float]:
    """Median wall time of each command, run in turn `repeats` times. `bytecode`: a folder for the project's
    compiled modules, made by a first run of each command that is not timed, as an installed tool has them (the
    baseline's numpy and scipy have theirs from their installation, even where PYTHONDONTWRITEBYTECODE is set)."""
    times: dict[str, list[float]] = {name: [] for name in commands}
    env = dict(os.environ, PYTHONPATH=str(REPO))
    if bytecode is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = bytecode
        for command in commands.values():
            subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=REPO)
    for _ in range(repeats):
        for name, command in commands.items():
            start = time.perf_counter()
            subprocess.run(command, check=name == "baseline", stdout=subprocess.DEVNULL, env=env, cwd=REPO)
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(values) for name, values in times.items()}


def bench_compare(repeats: int = 7) -> None:
    print("compare: whole process against `python -c 'import numpy, scipy.special'`")
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as tmp:
        commands = {"baseline": [PYTHON, "-c", "import numpy, scipy.special"]}
        for label, (height, width) in SIZES.items():
            for side, first in (("a", 0), ("b", 1000)):
                wc.save_stats(f"{tmp}/{label}_{side}.npz", synthetic_run(height, width, first, rng))
            commands[label] = [PYTHON, "-m", "batch", "compare", f"{tmp}/{label}_a.npz", f"{tmp}/{label}_b.npz",
                               "--out", f"{tmp}/report_{label}"]  # fmt: skip
        height, width = SIZES["1024x576"]
        for label, shift in UNEQUAL.items():
            name = label.replace(", ", "_").replace(" ", "")
            wc.save_stats(f"{tmp}/{name}_a.npz", synthetic_run(height, width, 0, rng, 256))
            wc.save_stats(f"{tmp}/{name}_b.npz", synthetic_run(height, width, 1000, rng, 4, shift))
            commands[label] = [PYTHON, "-m", "batch", "compare", f"{tmp}/{name}_a.npz", f"{tmp}/{name}_b.npz",
                               "--out", f"{tmp}/report_{name}"]  # fmt: skip
        for side, first in (("a", 0), ("b", 1000)):
            wc.save_stats(f"{tmp}/moments_{side}.npz", passes_run(height, width, first, rng))
        for label, mode in MOMENTS.items():
            commands[label] = [PYTHON, "-m", "batch", "compare", f"{tmp}/moments_a.npz", f"{tmp}/moments_b.npz",
                               "--pixel-variance", mode, "--out", f"{tmp}/report_moments_{mode}"]  # fmt: skip
        medians = interleaved(commands, repeats, bytecode=f"{tmp}/bytecode")
    for label in [*SIZES, *UNEQUAL, *MOMENTS]:
        line(f"batch compare at {label}", medians[label], medians["baseline"], 2.5)
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        print("  (PYTHONDONTWRITEBYTECODE is set here: the tool's modules were compiled once, before the timed runs)")

    from scipy import stats

    height, width = SIZES["3840x2160"]
    ref, test = synthetic_run(height, width, 0, rng), synthetic_run(height, width, 1000, rng)
    m1, s1, m2, s2 = ref.mean, np.sqrt(ref.variance), test.mean, np.sqrt(test.variance)
    base = best_time(lambda: stats.ttest_ind_from_stats(m1, s1, PASSES, m2, s2, PASSES, equal_var=False))
    ours = best_time(lambda: wc.welch_from_stats(ref.mean, ref.variance, PASSES, test.mean, test.variance, PASSES))
    line("Welch's test on the 3840x2160 tile grid vs ttest_ind_from_stats", ours * 1e3, base * 1e3, 1.2, "ms")
    # The whole decision also checks every tile's normality and tests the image (Holm, BH, KS): against scipy's
    # test on the same per-pass sums, which computes only the moments.
    base = best_time(lambda: stats.ttest_ind(ref.sums, test.sums, axis=0, equal_var=False))
    ours = best_time(lambda: wc.compare(ref, test, tile=TILE))
    print(f"  (compare at 32x32, all of it: {ours * 1e3:.1f} ms = {ours / base:.2f}x ttest_ind on the per-pass sums)")


class _Silent(Progress):
    """Progress whose events are made, not printed: a terminal is not the pipeline's cost."""

    def emit(self, event) -> None:
        pass


def _bpy_modules():
    import bpy

    from batch.blender import render, scenes

    return bpy, render, scenes


def bench_passes() -> None:
    print("passes: the pipeline against Cycles' bare render, per pass (corner scene, 1 spp)")
    for size in (128, 256):
        bare, pipeline = pass_times(size)
        line(f"pipeline per pass at {size}x{size}", pipeline * 1e3, bare * 1e3, 1.05, "ms")


def pass_times(size: int, passes: int = 24, blocks: int = 3) -> tuple[float, float]:
    """Median seconds per pass of the bare render and of the pipeline, in alternating blocks of `passes`."""
    bpy, render, scenes = _bpy_modules()
    from batch.blender.run import render_passes

    seeds = iter(range(10**6))
    scene = scenes.build_scene("corner")
    render.configure_unbiased(scene, "CPU", 1, (size, size))

    def bare():
        for _ in range(passes):
            scene.cycles.seed = next(seeds)
            scene.update_tag(refresh={"TIME"})  # the same re-seeding as the pipeline's
            bpy.ops.render.render(scene=scene.name)

    timed = {"bare": [], "pipeline": []}
    with tempfile.TemporaryDirectory() as tmp, render.PassRenderer(scene) as renderer:
        progress = _Silent(passes, json_lines=False, live=False)

        def pipeline():
            stats = wc.TileStats(size, size, 16, 3)
            render_passes(renderer, [next(seeds) for _ in range(passes)], stats, progress, out=f"{tmp}/run.npz")
            os.unlink(f"{tmp}/run.npz")

        bare()  # warm up: the first render syncs the scene
        for _ in range(blocks):
            for name, func in (("bare", bare), ("pipeline", pipeline)):
                start = time.perf_counter()
                func()
                timed[name].append((time.perf_counter() - start) / passes)
    bpy.data.scenes.remove(scene)
    return statistics.median(timed["bare"]), statistics.median(timed["pipeline"])


def bench_lobes(passes: int = 24, blocks: int = 3) -> None:
    print("lobes: a pass with every light component (--lobes all) against a plain pass (glossy scene, 1 spp)")
    bpy, render, scenes = _bpy_modules()
    from batch.blender.run import render_passes
    from batch.jobs.lobes import COMPONENTS

    for size in (128, 256):
        timed = {}
        for name, lobes in (("plain", ()), ("lobes", COMPONENTS)):
            scene = render.open_scene(None, "glossy")
            render.configure_unbiased(scene, "CPU", 1, (size, size), "TABULATED_SOBOL", lobes=lobes)
            progress = _Silent(passes, live=False)
            times = []
            with render.PassRenderer(scene, lobes=lobes) as renderer:
                for block in range(blocks):
                    stats = wc.TileStats(size, size, 16, 3)
                    layers = {n: wc.TileStats(size, size, 16, 3) for n in lobes}
                    start = time.perf_counter()
                    seeds = range(block * passes, (block + 1) * passes)
                    render_passes(renderer, seeds, stats, progress, layers=layers or None)
                    times.append((time.perf_counter() - start) / passes)
            timed[name] = statistics.median(times)
        line(f"a pass with 6 components at {size}x{size}", timed["lobes"] * 1e3, timed["plain"] * 1e3, None, "ms")


def motion_volume_scene(bpy, scenes):
    """The corner scene with a homogeneous volume cube and a sphere moving through the shutter."""
    import bmesh

    scene = scenes.build_scene("corner")
    mesh = bpy.data.meshes.new("fog")
    h = 0.4
    verts = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (0.2, 0.2 + 2 * h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh.from_pydata(verts, [], faces)
    material = bpy.data.materials.new("fog")
    nodes = scenes.node_tree(material).nodes
    nodes.clear()
    volume = nodes.new("ShaderNodeVolumeScatter")
    volume.inputs["Density"].default_value = 2.0
    output = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(volume.outputs[0], output.inputs["Volume"])
    mesh.materials.append(material)
    scene.collection.objects.link(bpy.data.objects.new("fog", mesh))
    sphere = bmesh.new()
    bmesh.ops.create_uvsphere(sphere, u_segments=24, v_segments=12, radius=0.2)
    ball = bpy.data.objects.new("ball", bpy.data.meshes.new("ball"))
    sphere.to_mesh(ball.data)
    sphere.free()
    scene.collection.objects.link(ball)
    ball.location = (-0.5, 0.3, 0.6)
    ball.keyframe_insert("location", frame=1)
    ball.location = (0.5, 0.3, 0.6)
    ball.keyframe_insert("location", frame=3)
    scene.frame_set(2)
    scene.render.use_motion_blur = True
    return scene


def bench_reseed(renders: int = 8) -> None:
    print("reseed: a re-seeded render with a volume and motion blur against a second render of the same seed")
    bpy, render, scenes = _bpy_modules()
    size = 128
    scene = motion_volume_scene(bpy, scenes)
    render.configure_unbiased(scene, "CPU", 1, (size, size))
    bpy.ops.render.render(scene=scene.name)  # the first render syncs everything
    timed = {"same seed": [], "re-seeded": []}
    for i in range(renders):
        for name in timed:
            if name == "re-seeded":
                scene.cycles.seed = 100 + i
                scene.update_tag(refresh={"TIME"})
            start = time.perf_counter()
            bpy.ops.render.render(scene=scene.name)
            timed[name].append(time.perf_counter() - start)
    same, reseeded = (statistics.median(timed[k]) for k in ("same seed", "re-seeded"))
    line(f"re-seeded render with volume + motion blur at {size}x{size}", reseeded * 1e3, same * 1e3, 1.2, "ms")
    bpy.data.scenes.remove(scene)


def bench_report(repeats: int = 5) -> None:
    print("report: writing the demo's report (128x128, 16x16 tiles, 32 passes a side)")
    from batch.present import summary
    from batch.present.report import write_report

    rng = np.random.default_rng(3)
    size, tile = 128, 16
    runs = []
    for first, scale in ((0, 1.0), (1000, 1.05)):
        pixel_sum = rng.uniform(0.0, 0.4, (size, size, 3)).astype(np.float32) * np.float32(scale * PASSES)
        sums = rng.normal(40.0 * scale, 1.0, (PASSES, size // tile, size // tile, 3))
        runs.append(wc.TileStats.from_sums(sums, range(first, first + PASSES), size, size, tile, pixel_sum=pixel_sum))
    with tempfile.TemporaryDirectory() as tmp:

        def write():
            result = wc.compare(*runs)
            write_report(tmp, summary.summarize(result, *runs), result, *runs)

        seconds = best_time(write, repeats)
    line("compare + summary + report files for the demo", seconds, 0.1, 1.0)


BENCHES = {
    "compare": bench_compare,
    "passes": bench_passes,
    "reseed": bench_reseed,
    "report": bench_report,
    "lobes": bench_lobes,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.studies.speed", description=__doc__.splitlines()[0])
    parser.add_argument("benches", nargs="*", metavar="BENCH", help=f"some of {', '.join(BENCHES)} (default: all)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.benches) - set(BENCHES))
    if unknown:
        parser.error(f"unknown benchmark {unknown[0]!r}; choose from {', '.join(BENCHES)}")
    for name in args.benches or list(BENCHES):
        BENCHES[name]()
    return 0


if __name__ == "__main__":
    sys.exit(main())
