"""Chart 4: how the cost grows. Seconds per pass against resolution, seconds per verdict against pass count, the
statistics' own time and memory against tile count, the pipeline's overhead over Cycles' bare render call, and the
persistent-data speed-up on a heavy scene. Every render goes through the batch tool's own code (one process, CPU).
"""

from __future__ import annotations

import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

import welch_core as wc

from ..common import plan
from ..common.cache import digest, memo_json, source_digest
from ..common.measure import best_time
from ..common.plotting import plt, save, write_csv
from ..common.pools import load_or_render, quiet_stdout, say

#: Part of the cached measurements' key: bump it when a change here changes what is measured.
COST_VERSION = 2

#: Tile grids for the statistics' own cost; the last is a 4K frame (3840×2160) at 32² tiles.
GRIDS = {16: (4, 4), 64: (8, 8), 256: (16, 16), 1024: (32, 32), 4096: (64, 64), 8040: (67, 120)}


def _scene(resolution: int, scene: str = "corner"):
    from batch.blender.run import prepare_scene
    from batch.jobs.job import RenderJob

    job = RenderJob(out="", seeds=[0], spp=1, scene=scene, resolution=(resolution, resolution))
    return prepare_scene(job)


def pass_cost(resolutions, passes: int) -> list[dict]:
    """Median seconds per pass (render call, EXR write + read, accumulation) per resolution, corner, 1 spp."""
    from batch.blender.render import PassRenderer

    rows = []
    for res in resolutions:
        with quiet_stdout():
            scene, info = _scene(res)
            stats = wc.TileStats(res, res, min(32, res), 3, info)
            times = []
            with PassRenderer(scene) as renderer:
                for seed in range(passes + 1):  # the first pass loads kernels and builds the BVH: not counted
                    image = renderer.render(seed)
                    start = time.perf_counter()
                    stats.add_pass(image, seed)
                    times.append((renderer.render_seconds, renderer.io_seconds, time.perf_counter() - start))
        render_s, io_s, acc_s = np.median(times[1:], axis=0)
        rows.append({"resolution": res, "passes": passes, "render_s": render_s, "io_s": io_s, "accumulate_s": acc_s,
                     "total_s": render_s + io_s + acc_s})  # fmt: skip
        say(f"  {res}²: {render_s:.3f} s render, {io_s * 1e3:.1f} ms I/O, {acc_s * 1e3:.2f} ms accumulate")
    return rows


def verdict_cost(pool, ns) -> list[dict]:
    """Seconds of `compare` and of writing the report (batch.present.report) against passes a side, 32² tiles."""
    from batch.present.report import write_report
    from batch.present.summary import summarize

    rows = []
    for n in ns:
        n = min(n, pool.n // 2)
        ref, test = pool.stats(np.arange(n), 32), pool.stats(np.arange(n, 2 * n), 32)
        compare_s = best_time(lambda ref=ref, test=test: wc.compare(ref, test), 3)
        result = wc.compare(ref, test)
        with tempfile.TemporaryDirectory() as folder:
            report_s = best_time(
                lambda folder=folder, r=result, a=ref, b=test: write_report(folder, summarize(r, a, b), r, a, b), 2
            )
        rows.append({"passes": n, "tiles": int(result.tile_pvalues.size), "compare_s": compare_s, "report_s": report_s})
    return rows


def core_cost(tile_counts, n: int = 32) -> list[dict]:
    """welch_core's `compare` on synthetic tile grids: seconds and peak Python memory (tracemalloc)."""
    rng = np.random.default_rng(4)
    rows = []
    for count in tile_counts:
        ty, tx = GRIDS[count]
        mean = rng.uniform(100.0, 1000.0, (ty, tx, 3))
        a = wc.TileStats.from_sums(mean + rng.normal(0, 10, (n, ty, tx, 3)), range(n), 32 * ty, 32 * tx, 32)
        b = wc.TileStats.from_sums(mean + rng.normal(0, 10, (n, ty, tx, 3)), range(n, 2 * n), 32 * ty, 32 * tx, 32)
        seconds = best_time(lambda a=a, b=b: wc.compare(a, b), 3)
        tracemalloc.start()
        wc.compare(a, b)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        rows.append({"tiles": ty * tx, "passes_a_side": n, "compare_s": seconds, "peak_bytes": peak,
                     "input_bytes": a.sums.nbytes + b.sums.nbytes})  # fmt: skip
    return rows


def overhead(passes: int, resolution: int = 256) -> dict:
    """The pipeline (re-seed, render, write, read, accumulate) against the bare render call, interleaved."""
    import bpy

    from batch.blender.render import PassRenderer

    with quiet_stdout():
        scene, info = _scene(resolution)
        stats = wc.TileStats(resolution, resolution, 32, 3, info)
        bare, pipeline, io, accumulate = [], [], [], []
        with PassRenderer(scene) as renderer:
            for seed in range(3):  # warm-up: kernels, BVH, first sync
                renderer.render(seed)
                bpy.ops.render.render(scene=scene.name)
            for seed in range(3, 3 + passes):
                # Alternate the two so that the load of other jobs on the machine falls on both alike.
                start = time.perf_counter()
                bpy.ops.render.render(scene=scene.name)
                bare.append(time.perf_counter() - start)
                start = time.perf_counter()
                image = renderer.render(seed)
                middle = time.perf_counter()
                stats.add_pass(image, seed)
                pipeline.append(time.perf_counter() - start)
                io.append(renderer.io_seconds)
                accumulate.append(time.perf_counter() - middle)
    b, p = float(np.median(bare)), float(np.median(pipeline))
    return {"resolution": resolution, "spp": 1, "passes": passes, "bare_s": b, "pipeline_s": p, "overhead": p / b - 1,
            "io_s": float(np.median(io)), "accumulate_s": float(np.median(accumulate))}  # fmt: skip


def persistent_speedup(subdivisions: int, passes: int, resolution: int = 64) -> dict:
    """Seconds per pass with persistent data off and on, corner scene plus a heavy mesh (20·4^(s-1) triangles)."""
    import bmesh
    import bpy

    from batch.blender.render import PassRenderer

    with quiet_stdout():
        scene, _info = _scene(resolution)
        bm = bmesh.new()
        bmesh.ops.create_icosphere(bm, subdivisions=subdivisions, radius=0.35)
        mesh = bpy.data.meshes.new("Heavy")
        bm.to_mesh(mesh)
        bm.free()
        mesh.materials.append(bpy.data.materials["Walls"])
        obj = bpy.data.objects.new("Heavy", mesh)
        obj.location = (0.9, 1.1, 0.35)
        scene.collection.objects.link(obj)
        triangles = len(mesh.polygons)
        out = {"resolution": resolution, "spp": 1, "triangles": triangles, "passes": passes}
        for state in (False, True):
            scene.render.use_persistent_data = state
            times = []
            with PassRenderer(scene) as renderer:
                for seed in range(passes + 1):
                    renderer.render(seed)
                    times.append(renderer.render_seconds)
            key = "on" if state else "off"
            out[f"first_{key}_s"] = times[0]
            out[f"median_{key}_s"] = float(np.median(times[1:]))
    out["speedup"] = out["median_off_s"] / out["median_on_s"]
    return out


def run(b: plan.Budget, cache_dir: Path, out_dir: Path) -> dict:
    pool = load_or_render(b.pool("corner"), cache_dir)
    key = digest(b.cost_resolutions, b.cost_passes, b.verdict_passes, b.tile_counts, b.overhead_passes,
                 b.heavy_subdivisions, b.heavy_passes, pool.spec.key, source_digest("welch_core"),
                 source_digest("batch"), COST_VERSION)  # fmt: skip

    def compute():
        say("chart 4: seconds per pass against resolution")
        passes = pass_cost(b.cost_resolutions, b.cost_passes)
        say("chart 4: seconds per verdict against passes")
        verdicts = verdict_cost(pool, b.verdict_passes)
        say("chart 4: welch_core time and memory against tiles")
        core = core_cost(b.tile_counts)
        say("chart 4: pipeline overhead at 256², 1 spp")
        over = overhead(b.overhead_passes)
        say(
            f"  bare {over['bare_s'] * 1e3:.1f} ms, pipeline {over['pipeline_s'] * 1e3:.1f} ms: "
            f"{100 * over['overhead']:+.1f} %"
        )
        say("chart 4: persistent data on a heavy mesh")
        heavy = persistent_speedup(b.heavy_subdivisions, b.heavy_passes)
        say(f"  {heavy['triangles']} triangles: {heavy['speedup']:.1f}x")
        return {"passes": passes, "verdicts": verdicts, "core": core, "overhead": over, "persistent": heavy}

    m = memo_json(cache_dir, "cost", key, compute)
    files = [
        write_csv(out_dir / "chart4_pass_cost.csv", m["passes"]),
        write_csv(out_dir / "chart4_verdict_cost.csv", m["verdicts"]),
        write_csv(out_dir / "chart4_core_cost.csv", m["core"]),
        write_csv(out_dir / "chart4_overhead.csv", [m["overhead"]]),
        write_csv(out_dir / "chart4_persistent_data.csv", [m["persistent"]]),
        _plot(out_dir / "chart4_cost.png", m),
    ]
    return {"files": files, **m}


def _plot(path: Path, m: dict) -> str:
    fig, axes = plt.subplots(1, 4, figsize=(21, 4.4))
    ax = axes[0]
    res = [r["resolution"] for r in m["passes"]]
    for key, label in (
        ("render_s", "render call"),
        ("io_s", "EXR write + read"),
        ("accumulate_s", "tile sums + Welford"),
        ("total_s", "total"),
    ):
        ax.plot(res, [r[key] for r in m["passes"]], "o-", label=label)
    ax.set(xscale="log", yscale="log", xlabel="resolution (square, px)", ylabel="seconds per pass (median)",
           title="per pass, corner, 1 spp")  # fmt: skip
    ax.set_xticks(res, [str(r) for r in res])
    ax = axes[1]
    n = [r["passes"] for r in m["verdicts"]]
    ax.plot(n, [r["compare_s"] for r in m["verdicts"]], "o-", label="compare (test + diagnostics + verdict)")
    ax.plot(n, [r["report_s"] for r in m["verdicts"]], "o-", label="report (PNGs, EXR, JSON, HTML)")
    ax.set(
        xscale="log",
        yscale="log",
        xlabel="passes a side",
        ylabel="seconds per verdict",
        title="per verdict, 128² px, 32² tiles",
    )
    ax = axes[2]
    tiles = [r["tiles"] for r in m["core"]]
    ax.plot(tiles, [r["compare_s"] for r in m["core"]], "o-", color="C0", label="compare seconds")
    ax.set(
        xscale="log",
        yscale="log",
        xlabel="tiles (×3 channels), N = 32 a side",
        ylabel="seconds",
        title="welch_core alone",
    )
    twin = ax.twinx()
    twin.plot(tiles, [r["peak_bytes"] / 2**20 for r in m["core"]], "s--", color="C3", label="peak MiB (tracemalloc)")
    twin.set_yscale("log")
    twin.set_ylabel("peak memory, MiB")
    ax.legend(loc="upper left", fontsize=8)
    twin.legend(loc="lower right", fontsize=8)
    ax = axes[3]
    o, h = m["overhead"], m["persistent"]
    bars = [("bare render\n256², 1 spp", o["bare_s"]), ("pipeline\n256², 1 spp", o["pipeline_s"]),
            (f"persistent off\n{h['triangles'] // 1000}k tris", h["median_off_s"]),
            ("persistent on", h["median_on_s"])]  # fmt: skip
    ax.bar(range(4), [v * 1e3 for _, v in bars], color=["C0", "C1", "C2", "C3"])
    ax.set_xticks(range(4), [name for name, _ in bars], fontsize=8)
    ax.set_ylabel("ms per pass (median)")
    ax.set_title(f"overhead {100 * o['overhead']:+.1f} %; persistent data ×{h['speedup']:.1f}")
    for a in axes[:2]:
        a.legend(fontsize=8)
        a.grid(alpha=0.3, which="both", lw=0.4)
    fig.suptitle("Chart 4: how the cost grows (2 cores, Cycles on CPU)")
    fig.tight_layout()
    return save(fig, path)


# -- its section of docs/benchmarks/README.md --------------------------------------------------------------------------


def section(f: dict) -> list[str]:
    """Chart 4's section of docs/benchmarks/README.md from the figures `f`."""
    return [CHART4, *chart4_lines(f["chart4"])]


CHART4 = """
## Chart 4: how the cost grows

![chart 4](chart4_cost.png)
"""


def chart4_lines(c4: dict) -> list[str]:
    o, h = c4["overhead"], c4["persistent"]
    passes = ", ".join(f"{r['resolution']}²: {r['total_s']:.3g} s" for r in c4["passes"])
    verdicts = "; ".join(
        f"N = {r['passes']}: {r['compare_s'] * 1e3:.0f} ms + {r['report_s']:.2f} s" for r in c4["verdicts"]
    )
    core = ", ".join(
        f"{r['tiles']} tiles: {r['compare_s'] * 1e3:.0f} ms, {r['peak_bytes'] / 2**20:.1f} MiB" for r in c4["core"]
    )
    return [
        f"- Seconds per pass (corner, 1 spp; render + EXR write/read + accumulation): {passes}.",
        f"- Seconds per verdict (compare + report) at 128² px and 32² tiles: {verdicts}. The report (PNG maps and "
        "histograms written by matplotlib) is almost all of it; the statistics take milliseconds.",
        f"- welch_core's `compare` alone (N = 32 a side): {core}.",
        f"- Pipeline overhead at {o['resolution']}², 1 spp, corner: the bare `bpy.ops.render.render()` takes "
        f"{o['bare_s'] * 1e3:.1f} ms, a whole pass (re-seed, render, EXR write and read, accumulate) "
        f"{o['pipeline_s'] * 1e3:.1f} ms: "
        f"**{100 * o['overhead']:+.1f} %** (medians of {o['passes']} interleaved passes; the target was below 10 %)"
        + (
            f", of which the EXR write and read are {o['io_s'] * 1e3:.1f} ms and the accumulation "
            f"{o['accumulate_s'] * 1e3:.1f} ms."
            if "io_s" in o
            else "."
        ),
        f"- Persistent data on a heavy scene (corner + {h['triangles']:,} triangles, {h['resolution']}², 1 spp): "
        f"{h['median_off_s'] * 1e3:.0f} ms per pass off, {h['median_on_s'] * 1e3:.0f} ms on: **×{h['speedup']:.1f}** "
        f"(first pass {h['first_off_s']:.2f} s off, {h['first_on_s']:.2f} s on).",
    ]
