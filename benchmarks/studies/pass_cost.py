"""The tool's own cost per pass at GPU speed: passes from a renderer that costs nothing, against the floor of
getting the same pixels into Python at all, each measured in the same run (interleaved, medians).

    python -m benchmarks.studies.pass_cost                              # every size and source (~15 min)
    python -m benchmarks.studies.pass_cost --sizes 1920x1080 --sources command --runs 3
    python -m benchmarks.studies.pass_cost --sizes 64x48 --sources command ingest --runs 1 --passes 8  # a smoke run

command  ``render --command 'sh -c "cp P.exr {out}"'`` with ``--spp 1`` (P one of four prepared uncompressed float
         RGB passes in /dev/shm), pixel moments kept as always, a checkpoint every 8 passes: its passes per
         second, timed by its progress events as they arrive (the first to the last pass: start-up and the final
         save left out), against the floor: a Python loop making the same copies by the same subprocess calls
         and reading each with `welch_core.read_exr`, timed the same way.
ingest   ``ingest`` of N passes against reading them, whole processes, per pass from N = 8 and N = 40 (start-up
         and the one save cancel).
bpy      Cycles passes whose render costs nothing: one real render, then `PassRenderer` and the render loop
         (`batch.blender.run.render_passes`: re-seed, save the Render Result as EXR, read it, accumulate, a
         checkpoint every 8 passes) with the render operator replaced by a no-op, against the floor of Blender's
         `save_render` and `read_exr` of the same Render Result; both timed from the first pass to the last (the
         final save left out, as for command).
workers  ``render --command ... --workers 2 --chunk C`` (two Dask workers on this machine) against two floor loops
         at once, each timed as whole processes of N and 3N passes: the difference over the 2N passes between, so
         that start-up (the cluster's), the last chunk's wait and the last save cancel. (A chunk's passes arrive
         together, so timing them by their progress events, as *command* is, counts too few passes a chunk.)

Prints, per size and source, the floor and the tool in ms a pass and passes per second, the tool's own cost
(the difference) and that cost as a share of a 1 s GPU pass. Nothing is asserted: the figures go into
docs/results.md. Any WIDTHxHEIGHT may be given; sizes not listed run `--passes` passes (default 48).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

from ..common.cache import REPO

PYTHON = sys.executable
SIZES = {"512x512": (512, 512), "1920x1080": (1920, 1080), "3840x2160": (3840, 2160)}
SOURCES = ("command", "ingest", "bpy", "workers")
PASSES = {"512x512": 96, "1920x1080": 48, "3840x2160": 24}  # passes a timed run, by size
SHM = "/dev/shm" if os.path.isdir("/dev/shm") else tempfile.gettempdir()

#: The floor of a command's passes: the same copies, each read into an image, one line a pass.
FLOOR = textwrap.dedent(
    """
    import os, subprocess, sys
    import welch_core as wc
    prefix, out, passes = sys.argv[1], sys.argv[2], int(sys.argv[3])
    for seed in range(passes):
        subprocess.run(["sh", "-c", f"cp {prefix}{seed % 4}.exr {out}"], check=True)
        wc.read_exr(out)
        os.remove(out)
        print("pass", flush=True)
    """
)

#: The bpy passes: a render that costs nothing, through the tool's pipeline and bare. Prints JSON.
BPY = textwrap.dedent(
    """
    import json, os, statistics, sys, tempfile, time
    import bpy
    import welch_core as wc
    from batch.blender import render, scenes
    from batch.blender.run import render_passes
    from batch.jobs import protocol
    from batch.present.progress import Progress

    width, height, passes, blocks = map(int, sys.argv[1:5])

    class NoRender:  # bpy, except that the render operator leaves the Render Result as it is
        class ops:
            class render:
                render = staticmethod(lambda **_: {"FINISHED"})

        def __getattr__(self, name):
            return getattr(bpy, name)

    class Timed(Progress):  # the time each pass arrived, as the command source's events are timed
        def emit(self, event):
            if isinstance(event, protocol.PassDone):
                stamps.append(time.perf_counter())

    scene = scenes.build_scene("corner")
    render.configure_unbiased(scene, "CPU", 1, (width, height))
    bpy.ops.render.render(scene=scene.name)  # the one real render
    render.bpy = NoRender()
    timed = {"floor": [], "tool": []}
    stamps = []
    seeds = iter(range(10**6))
    with tempfile.TemporaryDirectory() as tmp, render.PassRenderer(scene) as renderer:
        def floor():
            for _ in range(passes):
                bpy.data.images["Render Result"].save_render(renderer.path, scene=scene)
                wc.read_exr(renderer.path)
                stamps.append(time.perf_counter())

        def tool():
            stats = wc.TileStats(height, width, min(32, width, height), 3, keep_pixel_moments=True)
            progress = Timed(passes, live=False)
            render_passes(renderer, [next(seeds) for _ in range(passes)], stats, progress, out=f"{tmp}/run.npz")

        for _ in range(blocks):
            for name, work in (("floor", floor), ("tool", tool)):
                stamps.clear()
                work()
                timed[name].append((stamps[-1] - stamps[0]) / (len(stamps) - 1))
    print(json.dumps({name: statistics.median(values) for name, values in timed.items()}))
    """
)


def dimensions(size: str) -> tuple[int, int]:
    """(width, height) of a WIDTHxHEIGHT size."""
    try:
        width, height = (int(part) for part in size.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a size is WIDTHxHEIGHT, got {size!r}") from None
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f"a size is WIDTHxHEIGHT of at least 1x1, got {size!r}")
    return width, height


def prepare(size: str, folder: str) -> str:
    """Four uncompressed float RGB passes of `size` in `folder`: the prefix of their paths (``<prefix>0.exr``...)."""
    import welch_core as wc

    width, height = dimensions(size)
    rng = np.random.default_rng(0)
    base = rng.uniform(0.05, 3.0, (height, width, 3)).astype(np.float32)
    prefix = os.path.join(folder, f"pass-{size}-")
    for k in range(4):
        wc.write_exr(f"{prefix}{k}.exr", base * rng.gamma(4.0, 0.25, base.shape).astype(np.float32))
    return prefix


def timed_lines(argv: list[str], marker: str, env: dict) -> float:
    """Seconds a pass of a process that prints a line with `marker` per pass: the first such line to the last,
    over the passes between."""
    times = []
    proc = subprocess.Popen(argv, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in proc.stdout:
        if marker in line:
            times.append(time.perf_counter())
    err = proc.stderr.read()
    if proc.wait() != 0:
        raise SystemExit(f"{' '.join(argv[:4])}... failed: {err.strip()[-1500:]}")
    return (times[-1] - times[0]) / (len(times) - 1)


def whole(argv: list[str], env: dict) -> float:
    start = time.perf_counter()
    subprocess.run(argv, cwd=REPO, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def command_argv(template: str, passes: int, out: str) -> list[str]:
    return [PYTHON, "-m", "batch", "render", "--command", template, "--spp", "1", "--seeds", f"0:{passes}", "--out",
            out, "--json-progress"]  # fmt: skip


def command_source(prefix: str, tmp: str, runs: int, passes: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    template = f'sh -c "cp {prefix}$(({{seed}} % 4)).exr {{out}}"'
    floors, tools = [], []
    for run in range(runs):
        out = f"{tmp}/run-{run}.npz"
        tools.append(timed_lines(command_argv(template, passes, out), '"event": "pass"', env))
        os.remove(out)
        floors.append(timed_lines([PYTHON, "-c", FLOOR, prefix, f"{tmp}/floor.exr", str(passes)], "pass", env))
    return {"floor": statistics.median(floors), "tool": statistics.median(tools)}


#: Passes a chunk of the workers' runs.
WORKER_CHUNK = 12


def workers_source(prefix: str, tmp: str, runs: int, passes: int, workers: int = 2) -> dict:
    """`workers` Dask workers against as many floor loops at once, whole processes of `passes` and 3 x `passes`
    (rounded to whole chunks a worker): the seconds a pass over the difference."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    template = f'sh -c "cp {prefix}$(({{seed}} % 4)).exr {{out}}"'
    short = max(1, round(passes / (workers * WORKER_CHUNK))) * workers * WORKER_CHUNK
    lengths = (short, 3 * short)

    def tool(n: int) -> float:
        out = f"{tmp}/workers.npz"
        seconds = whole([*command_argv(template, n, out), "--workers", str(workers), "--chunk", str(WORKER_CHUNK)],
                        env)  # fmt: skip
        os.remove(out)
        return seconds

    def floor(n: int) -> float:
        start = time.perf_counter()
        procs = [subprocess.Popen([PYTHON, "-c", FLOOR, prefix, f"{tmp}/floor-{w}.exr", str(n // workers)], cwd=REPO,
                                  env=env, stdout=subprocess.DEVNULL) for w in range(workers)]  # fmt: skip
        for proc in procs:
            proc.wait()
        return time.perf_counter() - start

    floors, tools = [], []
    for _ in range(runs):
        tools.append((tool(lengths[1]) - tool(lengths[0])) / (lengths[1] - lengths[0]))
        floors.append((floor(lengths[1]) - floor(lengths[0])) / (lengths[1] - lengths[0]))
    return {"floor": statistics.median(floors), "tool": statistics.median(tools)}


def ingest_source(prefix: str, tmp: str, runs: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    few, many = 8, 40
    files = {n: [f"{prefix}{i % 4}.exr" for i in range(n)] for n in (few, many)}
    read = "import sys, welch_core as wc\nfor path in sys.argv[1:]: wc.read_exr(path)"
    timed = {"floor": [], "tool": []}
    for run in range(runs):
        per = {}
        for n in (few, many):
            out = f"{tmp}/ingest-{run}-{n}.npz"
            per[("tool", n)] = whole([PYTHON, "-m", "batch", "ingest", *files[n], "--spp", "1", "--seeds", f"0:{n}",
                                 "--out", out], env)  # fmt: skip
            os.remove(out)
            per[("floor", n)] = whole([PYTHON, "-c", read, *files[n]], env)
        for name in timed:
            timed[name].append((per[(name, many)] - per[(name, few)]) / (many - few))
    return {name: statistics.median(values) for name, values in timed.items()}


def bpy_source(size: str, runs: int, passes: int) -> dict:
    width, height = dimensions(size)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    argv = [PYTHON, "-c", BPY, str(width), str(height), str(max(2, passes // 2)), str(runs)]
    done = subprocess.run(argv, cwd=REPO, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"the bpy passes failed: {done.stderr.strip()[-1500:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def rate(seconds: float) -> str:
    """Passes per second, or a dash where a difference of whole processes came out at or below zero (noise)."""
    return f"{1 / seconds:6.1f}/s" if seconds > 0 else "     -  "


def report(size: str, source: str, found: dict) -> None:
    floor, tool = found["floor"], found["tool"]
    own = tool - floor
    print(f"  {size:>9} {source:<8} floor {floor * 1e3:7.1f} ms ({rate(floor)})  tool {tool * 1e3:7.1f} ms "
          f"({rate(tool)})  own {own * 1e3:6.1f} ms = {100 * own:4.1f} % of a 1 s pass", flush=True)  # fmt: skip


def main(argv: list[str] | None = None) -> dict[tuple[str, str], dict]:
    """Run the study; the seconds a pass of the floor and the tool, by (size, source)."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.studies.pass_cost", description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="*", default=list(SIZES), metavar="WxH", help=f"default: {' '.join(SIZES)}")
    parser.add_argument("--sources", nargs="*", default=list(SOURCES), choices=SOURCES)
    parser.add_argument("--runs", type=int, default=3, help="runs of each, interleaved (default 3); medians")
    parser.add_argument("--passes", type=int, help="passes a timed run (default by size: 96, 48, 24; else 48)")
    args = parser.parse_args(argv)
    for size in args.sizes:
        try:
            dimensions(size)
        except argparse.ArgumentTypeError as exc:
            parser.error(str(exc))
    if args.passes is not None and args.passes < 3:
        parser.error("--passes must be at least 3 (the first pass to the last, over the passes between)")
    results = {}
    print(f"the tool's own cost per pass, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} at the start")
    with tempfile.TemporaryDirectory(dir=SHM) as shm, tempfile.TemporaryDirectory() as tmp:
        for size in args.sizes:
            passes = args.passes or PASSES.get(size, 48)
            prefix = prepare(size, shm) if set(args.sources) - {"bpy"} else ""
            for source in args.sources:
                if source == "bpy":
                    found = bpy_source(size, args.runs, passes)
                elif source == "ingest":
                    found = ingest_source(prefix, tmp, args.runs)
                elif source == "workers":
                    found = workers_source(prefix, tmp, args.runs, passes)
                else:
                    found = command_source(prefix, tmp, args.runs, passes)
                report(size, source, found)
                results[(size, source)] = found
            for k in range(4):
                Path(f"{prefix}{k}.exr").unlink(missing_ok=True)
    print(f"load {os.getloadavg()[0]:.1f} at the end")
    return results


if __name__ == "__main__":
    main()
