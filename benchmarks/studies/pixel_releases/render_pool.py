"""Render one pool (N passes, seeds 0..N-1) with the project's own code; save N x H x W x 3 float32 .npy + meta.

From the repository (render_all.sh runs it for every release):
bpy module:   PYTHONPATH=$PWD VENV/bin/python $STUDY/render_pool.py SCENE PATTERN PASSES OUT.npy
Blender 3.4:  PYTHONPATH=$PWD blender -b --factory-startup --python-exit-code 1 --python $STUDY/render_pool.py --
              SCENE PATTERN PASSES OUT.npy

Uses batch.blender.run.prepare_scene (built-in scene, configure_unbiased: 1 spp, 64x64, denoise off, adaptive
off, persistent data, EXR 32-bit) and batch.blender.render.PassRenderer (seed + update_tag TIME, save_render,
read back). Then fixes scrambling distance 1, auto scrambling off, 1 CPU thread, and checks them.
"""

import json
import os
import sys
import time

argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]
scene_name, pattern, passes, out = argv[0], argv[1], int(argv[2]), argv[3]
first_seed = int(argv[4]) if len(argv) > 4 else 0

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from batch.blender.render import PassRenderer  # noqa: E402
from batch.blender.run import limit_threads, prepare_scene  # noqa: E402
from batch.jobs.job import RenderJob  # noqa: E402

job = RenderJob(
    out=os.devnull,
    seeds=list(range(first_seed, first_seed + passes)),
    spp=1,
    scene=scene_name,
    resolution=(64, 64),
    sampling_pattern=pattern,
    overrides=[],
)
scene, info = prepare_scene(job)
c = scene.cycles
c.scrambling_distance = 1.0
c.auto_scrambling_distance = False
limit_threads(scene, "1")
c.device = "CPU"
check = {
    "bpy": bpy.app.version_string,
    "pattern": c.sampling_pattern,
    "samples": c.samples,
    "scrambling_distance": c.scrambling_distance,
    "auto_scrambling_distance": c.auto_scrambling_distance,
    "use_denoising": c.use_denoising,
    "use_adaptive_sampling": c.use_adaptive_sampling,
    "threads": (scene.render.threads_mode, scene.render.threads),
    "device": c.device,
    "res": (scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage),
    "persistent": scene.render.use_persistent_data,
}
assert check["pattern"] == pattern and check["samples"] == 1 and not check["use_denoising"], check
assert not check["use_adaptive_sampling"] and not check["auto_scrambling_distance"], check
assert abs(check["scrambling_distance"] - 1.0) < 1e-9, check
images = np.empty((passes, 64, 64, 3), np.float32)
t0 = time.perf_counter()
with PassRenderer(scene) as r:
    for i, seed in enumerate(job.seeds):
        images[i] = r.render(seed)
check["seconds"] = time.perf_counter() - t0
np.save(out, images)
with open(out.replace(".npy", ".json"), "w") as f:
    json.dump(check, f)
print("POOL", json.dumps(check), flush=True)
