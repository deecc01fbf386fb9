"""A production-size `check`: where its wall time goes besides rendering.

    python -m benchmarks.studies.production                      # 1920x1080, 16 spp a pass, 4 passes a side (~6 min)
    python -m benchmarks.studies.production --resolution 320 180 --spp 1 --passes 4    # a quick try
    python -m benchmarks.studies.production --paired --pixel-variance on --set cycles.blur_glossy=1  # (~6 min)

Runs ``python -m batch check`` (unpaired A/A, or paired with ``--paired``: both sides the same seeds; ``--tolerance
off``, so it renders its whole budget and makes every look) and, as the baseline in the same run, the same passes
rendered bare: two processes at once, as the check's two sides render, each calling Cycles' render operator on the
same scene and settings with nothing else (no EXR, no statistics). Everything else is the check's wall time less the
slower bare process's render time: start-up of the render processes, EXR write and read, accumulation, the looks,
the report. Prints the split and the peak memory (resident set) of the largest process the check ran (itself or a
render process).

Everything else is then itemised from measurements of its parts in the same run: the start-up of a render process
(launch to its first render, measured by the bare processes, which also save and read each pass's EXR as a pass
does, timed apart from the render), the accumulation of a pass into the statistics and a look (timed here on a
pass of that size and on the check's final statistics), and the report (the check's last look to its exit, from
its progress events), and a side's statistics file saved after each chunk and read for each look. The two sides
render in parallel, so a side's parts count once. What is left is waiting (a look needs both sides' chunk) and
the run-to-run noise of the render times between the check and the bare renders, which on a shared machine is
several percent either way (-3.6 % and +6.1 % for "everything else" in two runs): the measured parts are the
figure to read.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from ..common.cache import REPO

#: The bare renders of one side: build the scene as `render` does, then time the render operator alone.
BARE = textwrap.dedent(
    """
    import json, sys, time
    import bpy
    from batch.blender.run import prepare_scene
    from batch.jobs.job import RenderJob

    scene_name, width, height, spp, passes, first, launched = sys.argv[1:8]
    import welch_core as wc
    from batch.blender.render import PassRenderer
    job = RenderJob(out="unused.npz", seeds=[0], spp=int(spp), scene=scene_name,
                    resolution=(int(width), int(height)))
    scene, _ = prepare_scene(job)
    renderer = PassRenderer(scene)
    seconds, io = [], []
    startup = time.time() - float(launched)
    for seed in range(int(first), int(first) + int(passes)):
        scene.cycles.seed = seed
        start = time.perf_counter()
        bpy.ops.render.render(scene=scene.name)
        seconds.append(time.perf_counter() - start)
        start = time.perf_counter()
        bpy.data.images["Render Result"].save_render(renderer.path, scene=scene)
        wc.read_exr(renderer.path)
        io.append(time.perf_counter() - start)
    print(json.dumps({"seconds": seconds, "io": io, "startup": startup}))
    """
)


def bare(scene: str, resolution: tuple[int, int], spp: int, passes: int, paired: bool = False) -> dict:
    """Two sides of `passes` passes rendered at once (`paired`: the same seeds): the slower side's seconds of
    rendering alone, and the larger start-up and EXR seconds (save and read of its passes) of the two."""
    argv = [sys.executable, "-c", BARE, scene, *map(str, resolution), str(spp), str(passes)]
    firsts = (0, 0) if paired else (0, 1_000_000)
    procs = [subprocess.Popen([*argv, str(first), repr(time.time())], cwd=REPO, stdout=subprocess.PIPE,
                              stderr=subprocess.DEVNULL, text=True) for first in firsts]  # fmt: skip
    sides = []
    for proc in procs:
        out, _ = proc.communicate()
        sides.append(json.loads(out.strip().splitlines()[-1]))
    return {"render_s": max(sum(side["seconds"]) for side in sides), "startup_s": max(s["startup"] for s in sides),
            "exr_s": max(sum(side["io"]) for side in sides)}  # fmt: skip


def in_process(out: Path, resolution: tuple[int, int], looks: int) -> dict:
    """Seconds of accumulating one pass of `resolution` into the statistics (as a render process does) and of
    the check's `looks` looks, each on its final statistics."""
    import numpy as np

    import welch_core as wc

    width, height = resolution
    image = np.random.default_rng(0).random((height, width, 3), dtype=np.float32)
    stats = wc.TileStats(height, width, 16, keep_pixel_moments=True)  # as a render process keeps them
    start = time.perf_counter()
    for seed in range(3):
        stats.add_pass(image, seed)
    accumulate = (time.perf_counter() - start) / 3
    start = time.perf_counter()
    ref, test = wc.load_stats(out / "reference.npz"), wc.load_stats(out / "test.npz")
    load = time.perf_counter() - start
    start = time.perf_counter()
    wc.save_stats(out / "again.npz", ref)
    save = time.perf_counter() - start
    plan = wc.SequentialPlan(max_passes=ref.n, tolerance=None)
    start = time.perf_counter()
    wc.sequential_look(ref, test, plan, [1.0])
    return {"accumulate_s": accumulate, "looks_s": looks * (time.perf_counter() - start),
            "files_s": looks * (save + load)}  # fmt: skip


def check(scene: str, resolution: tuple[int, int], spp: int, passes: int, out: Path, paired: bool = False,
          pixel_variance: str = "auto", overrides: tuple[str, ...] = ()) -> dict:  # fmt: skip
    argv = [sys.executable, "-m", "batch", "check", "--scene", scene, "--resolution", *map(str, resolution),
            "--spp", str(spp), "--max-passes", str(passes), "--tolerance", "off", "--pixel-variance", pixel_variance,
            "--out", str(out), "--json-progress", *([] if paired else ["--unpaired"])]  # fmt: skip
    argv += [f"--set={override}" for override in overrides]  # the test side's (a paired check needs one)
    start = time.perf_counter()
    proc = subprocess.Popen(argv, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    last_look = start
    for line in proc.stdout:
        if line.startswith('{"event": "look"'):
            last_look = time.perf_counter()
    err = proc.stderr.read()
    proc.wait()
    wall = time.perf_counter() - start
    if proc.returncode not in (0, 1, 3):
        raise SystemExit(f"check failed (exit {proc.returncode}): {err.strip()[-2000:]}")
    state = json.loads((out / "check.json").read_text())
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # MiB (Linux: KiB)
    return {"wall_s": wall, "looks": len(state["looks"]), "passes": state["looks"][-1]["passes"],
            "verdict": state["looks"][-1].get("verdict"),
            "report_s": wall - (last_look - start), "largest_process_mib": children}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.studies.production", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--scene", default="textured", help="a built-in scene (default textured)")
    parser.add_argument("--resolution", nargs=2, type=int, default=(1920, 1080), metavar=("W", "H"))
    parser.add_argument("--spp", type=int, default=16, help="samples per pass (default 16)")
    parser.add_argument("--passes", type=int, default=4, help="passes a side (default 4)")
    parser.add_argument("--paired", action="store_true", help="a paired check (the same seeds a side)")
    parser.add_argument("--pixel-variance", default="auto", choices=("auto", "on", "off"), help="check's (auto)")
    parser.add_argument("--set", action="append", default=[], metavar="RNA.PATH=VALUE",
                        help="the test side's override, as check's; repeatable (paired checks need one)")  # fmt: skip
    args = parser.parse_args(argv)
    resolution = tuple(args.resolution)
    design = "paired" if args.paired else "unpaired"
    print(f"check: {args.scene} at {resolution[0]}x{resolution[1]}, {args.spp} spp, {args.passes} passes a side, "
          f"{design}, --pixel-variance {args.pixel_variance}", flush=True)  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        measured = check(args.scene, resolution, args.spp, args.passes, Path(folder) / "check", args.paired,
                         args.pixel_variance, tuple(args.set))  # fmt: skip
        parts = in_process(Path(folder) / "check", resolution, measured["looks"])
    print(f"bare renders of the same {measured['passes']} passes a side", flush=True)
    found = bare(args.scene, resolution, args.spp, measured["passes"], args.paired)
    rendering, wall = found["render_s"], measured["wall_s"]
    other = wall - rendering
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{args.scene} at {resolution[0]}x{resolution[1]}, {args.spp} spp a pass, {measured['passes']} passes a "
          f"side, {measured['looks']} look{'s' if measured['looks'] != 1 else ''}")  # fmt: skip
    print(f"  check wall {wall:.1f} s (last look: {measured['verdict']}); bare rendering of the same passes "
          f"{rendering:.1f} s")  # fmt: skip
    print(f"  everything else {other:.1f} s = {100 * other / wall:.1f} % of the wall time")
    items = {"start-up of a render process": found["startup_s"], "EXR write and read of a side's passes":
             found["exr_s"], "accumulation of a side's passes": parts["accumulate_s"] * measured["passes"],
             "a side's statistics file saved after each chunk and read for each look": parts["files_s"],
             "the looks": parts["looks_s"], "the report (after the last look)": measured["report_s"]}  # fmt: skip
    for name, seconds in items.items():
        print(f"    {name}: {seconds:.1f} s = {100 * seconds / wall:.1f} %")
    measured_parts = sum(items.values())
    print(
        f"    these together: {measured_parts:.1f} s = {100 * measured_parts / wall:.1f} %; the rest, "
        f"{other - measured_parts:.1f} s, is waiting for the slower side and the render times' run-to-run noise"
    )
    print(
        f"  peak memory: the largest process of the check (itself or a render process) "
        f"{measured['largest_process_mib']:.0f} MiB; this one {own:.0f} MiB"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
