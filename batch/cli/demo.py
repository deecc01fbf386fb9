"""The main job on the built-in default: the paper's corner scene against the same scene with walls of grey 0.21
instead of 0.2 (paper Fig. 16), rendered with disjoint seeds, compared, reported.

A 5 % change of the wall albedo is invisible in a difference image at these sample counts; the test finds it.
"""

from __future__ import annotations

import os
import time

from .._siblings import welch_core as wc
from ..blender.run import render_run
from ..blender.scenes import WALL_COLOR_PATH
from ..jobs.job import RenderJob
from ..jobs.options import default
from ..present.pipeline import lines, present
from ..present.progress import Progress

#: About a minute on 2 cores: 128×128 px, 32 passes of 4 spp a side, 32×32 tiles (16 tiles).
DEMO_PASSES = 32
DEMO_RESOLUTION = 128
DEMO_SPP = 4
BIASED_GREY = 0.21


def run_demo(out_dir: str, passes: int | None = None, resolution: int | None = None) -> wc.Comparison:
    """Render both runs into `out_dir`, compare them, write the report; return the comparison."""
    passes = passes or DEMO_PASSES
    size = resolution or DEMO_RESOLUTION
    os.makedirs(out_dir, exist_ok=True)
    common = {"scene": "corner", "spp": DEMO_SPP, "resolution": (size, size), "tile": 32}
    grey = f"{BIASED_GREY},{BIASED_GREY},{BIASED_GREY},1"
    ref_job = RenderJob(out=os.path.join(out_dir, "reference.npz"), seeds=list(range(passes)), **common)
    test_job = RenderJob(
        out=os.path.join(out_dir, "walls_0.21.npz"),
        seeds=list(range(passes, 2 * passes)),
        overrides=[f"{WALL_COLOR_PATH}={grey}"],
        **common,
    )
    start = time.perf_counter()
    runs = []
    for label, job in (("reference (walls 0.20)", ref_job), ("test (walls 0.21)", test_job)):
        if os.path.exists(job.out):  # a demo always starts afresh
            os.remove(job.out)
        runs.append(render_run(job, Progress(len(job.seeds), label=label)))
    result = wc.compare(*runs, alpha=0.01, pixel_variance=default("pixel_variance", "compare"))
    report = present(out_dir, result, *runs, names=("corner, walls 0.20", "corner, walls 0.21"))
    print(
        f"demo: corner scene, walls 0.20 vs 0.21, {passes} passes of {DEMO_SPP} spp a side at {size}x{size} px, "
        f"{time.perf_counter() - start:.0f} s"
    )
    print("\n".join(lines(report, os.path.abspath(out_dir))))
    return result
