"""A production-size `check`: where its wall time goes besides rendering.

    python -m benchmarks.production                      # 1920x1080, 16 spp a pass, 4 passes a side (~6 min)
    python -m benchmarks.production --resolution 320 180 --spp 1 --passes 4    # a quick try

Runs ``python -m batch check`` (unpaired A/A, ``--tolerance off``, so it renders its whole budget and makes every
look) and, as the baseline in the same run, the same passes rendered bare: two processes at once, as the check's
two sides render, each calling Cycles' render operator on the same scene and settings with nothing else (no EXR,
no statistics). Everything else is the check's wall time less the slower bare process's render time: start-up of
the render processes, EXR write and read, accumulation, the looks, the report. Prints the split and the peak
memory (resident set) of the largest process the check ran (itself or a render process).
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

REPO = Path(__file__).resolve().parents[1]

#: The bare renders of one side: build the scene as `render` does, then time the render operator alone.
BARE = textwrap.dedent(
    """
    import json, sys, time
    import bpy
    from batch.blender.run import prepare_scene
    from batch.jobs.job import RenderJob

    scene_name, width, height, spp, passes, first = sys.argv[1:7]
    job = RenderJob(out="unused.npz", seeds=[0], spp=int(spp), scene=scene_name,
                    resolution=(int(width), int(height)))
    scene, _ = prepare_scene(job)
    seconds = []
    for seed in range(int(first), int(first) + int(passes)):
        scene.cycles.seed = seed
        start = time.perf_counter()
        bpy.ops.render.render(scene=scene.name)
        seconds.append(time.perf_counter() - start)
    print(json.dumps({"seconds": seconds}))
    """
)


def bare(scene: str, resolution: tuple[int, int], spp: int, passes: int) -> float:
    """Seconds of rendering alone for two sides of `passes` passes rendered at once (the slower side's)."""
    argv = [sys.executable, "-c", BARE, scene, *map(str, resolution), str(spp), str(passes)]
    procs = [subprocess.Popen([*argv, str(first)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                              text=True) for first in (0, 1_000_000)]  # fmt: skip
    totals = []
    for proc in procs:
        out, _ = proc.communicate()
        totals.append(sum(json.loads(out.strip().splitlines()[-1])["seconds"]))
    return max(totals)


def check(scene: str, resolution: tuple[int, int], spp: int, passes: int, out: Path) -> dict:
    argv = [sys.executable, "-m", "batch", "check", "--scene", scene, "--resolution", *map(str, resolution),
            "--spp", str(spp), "--max-passes", str(passes), "--unpaired", "--tolerance", "off",
            "--out", str(out)]  # fmt: skip
    start = time.perf_counter()
    done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode not in (0, 1, 3):
        raise SystemExit(f"check failed (exit {done.returncode}): {done.stderr.strip()[-2000:]}")
    state = json.loads((out / "check.json").read_text())
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # MiB (Linux: KiB)
    return {"wall_s": wall, "looks": len(state["looks"]), "passes": state["looks"][-1]["passes"],
            "largest_process_mib": children}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.production", description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="textured", help="a built-in scene (default textured)")
    parser.add_argument("--resolution", nargs=2, type=int, default=(1920, 1080), metavar=("W", "H"))
    parser.add_argument("--spp", type=int, default=16, help="samples per pass (default 16)")
    parser.add_argument("--passes", type=int, default=4, help="passes a side (default 4)")
    args = parser.parse_args(argv)
    resolution = tuple(args.resolution)
    print(f"check: {args.scene} at {resolution[0]}x{resolution[1]}, {args.spp} spp, {args.passes} passes a side",
          flush=True)  # fmt: skip
    with tempfile.TemporaryDirectory() as folder:
        measured = check(args.scene, resolution, args.spp, args.passes, Path(folder) / "check")
    print(f"bare renders of the same {measured['passes']} passes a side", flush=True)
    rendering = bare(args.scene, resolution, args.spp, measured["passes"])
    other = measured["wall_s"] - rendering
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{args.scene} at {resolution[0]}x{resolution[1]}, {args.spp} spp a pass, {measured['passes']} passes a "
          f"side, {measured['looks']} look{'s' if measured['looks'] != 1 else ''}")  # fmt: skip
    print(f"  check wall {measured['wall_s']:.1f} s; bare rendering of the same passes {rendering:.1f} s")
    print(f"  everything else {other:.1f} s = {100 * other / measured['wall_s']:.1f} % of the wall time")
    print(
        f"  peak memory: the largest process of the check (itself or a render process) "
        f"{measured['largest_process_mib']:.0f} MiB; this one {own:.0f} MiB"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
