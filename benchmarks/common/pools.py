"""Pools of render passes: one configuration rendered once with the batch tool's own code, every pass kept.

A pool is N passes (seeds ``first_seed .. first_seed + N - 1``) of one scene configuration, stored as an
N×H×W×3 float32 ``.npy`` with each pass's render and I/O seconds, under ``benchmarks/cache/`` and keyed by a hash
of the configuration (scene, overrides, resolution, spp, sampling pattern, seeds, the bpy version and the source of
the built-in scenes). Trials then draw subsets of passes from pools instead of rendering again.

The reference configuration and each biased variant use the same seeds, so a paired trial takes identical seeds
from both pools and an unpaired trial takes disjoint halves.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import re
import sys
import time
from dataclasses import asdict, dataclass
from functools import cached_property
from importlib import metadata
from pathlib import Path

import numpy as np

import welch_core as wc
from batch.jobs.job import SCENE_REVISIONS

from .cache import REPO, digest


@dataclass(frozen=True)
class PoolSpec:
    """One render configuration and its seeds."""

    scene: str
    overrides: tuple[str, ...] = ()
    resolution: int = 128
    spp: int = 1
    passes: int = 400
    first_seed: int = 0
    pattern: str = "TABULATED_SOBOL"

    @property
    def seeds(self) -> list[int]:
        return list(range(self.first_seed, self.first_seed + self.passes))

    @property
    def key(self) -> str:
        revision = SCENE_REVISIONS.get(self.scene)  # a scene rebuilt on its own (its pools render again)
        extra = () if revision is None else (f"revision {revision}",)
        return digest(asdict(self), metadata.version("bpy"), _scenes_digest(), *extra, *SEEDS)


#: How a pass's seed becomes Cycles' seed (`batch.blender.render.cycles_seed`): the pools rendered before it used
#: Cycles' seeds as they were, so they render again.
SEEDS = ("cycles_seed 1",)


@functools.cache
def _scenes_digest() -> str:
    """The built-in scenes' identity, as the batch tool records it in a run: `batch.blender.scenes.BUILDER_VERSION`,
    which is raised whenever a builder changes what it builds (read from the source, without importing bpy; once per
    process, so a run's pools keep their keys while the file is edited). Adding a scene renders nothing again."""
    source = (REPO / "batch" / "blender" / "scenes.py").read_text()
    found = re.search(r"^BUILDER_VERSION\s*=\s*(\d+)", source, re.MULTILINE)
    return digest("builder", found.group(1) if found else source)


class Pool:
    """The passes of one `PoolSpec`, read from the cache (images memory-mapped)."""

    def __init__(self, spec: PoolSpec, folder: Path):
        self.spec = spec
        self.images = np.load(folder / "images.npy", mmap_mode="r")
        meta = json.loads((folder / "meta.json").read_text())
        self.render_seconds = np.asarray(meta["render_seconds"])
        self.io_seconds = np.asarray(meta["io_seconds"])
        self.info = wc.RunInfo.from_json(meta["info"])
        self.seeds = spec.seeds

    @property
    def n(self) -> int:
        return len(self.seeds)

    @property
    def seconds_per_pass(self) -> float:
        """Median render seconds of one pass (the median resists the load of other jobs on a shared machine)."""
        return float(np.median(self.render_seconds))

    @property
    def total_seconds(self) -> float:
        return float(self.render_seconds.sum())

    @cached_property
    def mean_image(self) -> np.ndarray:
        return np.asarray(self.images, dtype=np.float64).mean(axis=0)

    def sums(self, tile: int) -> np.ndarray:
        """Every pass's tile sums at `tile`, shape (N, tiles_y, tiles_x, 3), computed once."""
        cache = self.__dict__.setdefault("_sums", {})
        if tile not in cache:
            cache[tile] = np.stack([wc.tile_sums(image, tile) for image in self.images])
        return cache[tile]

    def stats(self, indices, tile: int, pixels: bool = False) -> wc.TileStats:
        """The statistics of the passes at `indices` (positions in the pool) at `tile`, with their pixel moments
        where asked for (the pixel-variance test)."""
        indices = np.asarray(indices)
        size = self.spec.resolution
        seeds = [self.seeds[i] for i in indices]
        moments = wc.PixelMoments.of_passes(self.images[np.sort(indices)]) if pixels else None
        return wc.TileStats.from_sums(self.sums(tile)[indices], seeds, size, size, tile, self.info, pixels=moments)


#: Keys of the pools rendered (not read from the cache) by this process, for the run's record.
RENDERED: list[str] = []


def load_or_render(spec: PoolSpec, cache_dir: Path, label: str = "") -> Pool:
    """The pool of `spec`, rendered now if the cache does not hold it."""
    folder = Path(cache_dir) / f"pool-{spec.key}"
    if not (folder / "meta.json").exists():
        render_pool(spec, folder, label)
        RENDERED.append(spec.key)
    return Pool(spec, folder)


def render_pool(spec: PoolSpec, folder: Path, label: str = "") -> None:
    """Render every pass of `spec` with `batch.blender.run.prepare_scene` and `batch.blender.render.PassRenderer`;
    store them."""
    from batch.blender.render import PassRenderer
    from batch.blender.run import prepare_scene
    from batch.jobs.job import RenderJob

    job = RenderJob(
        out=os.devnull,
        seeds=spec.seeds,
        spp=spec.spp,
        scene=spec.scene,
        resolution=(spec.resolution, spec.resolution),
        sampling_pattern=spec.pattern,
        overrides=list(spec.overrides),
    )
    size = spec.resolution
    images = np.empty((spec.passes, size, size, 3), np.float32)
    render_s, io_s = [], []
    start = time.perf_counter()
    with quiet_stdout():
        scene, info = prepare_scene(job)
        with PassRenderer(scene) as renderer:
            for i, seed in enumerate(spec.seeds):
                images[i] = renderer.render(seed)
                render_s.append(renderer.render_seconds)
                io_s.append(renderer.io_seconds)
                if (i + 1) % max(1, spec.passes // 4) == 0 or i + 1 == spec.passes:
                    say(
                        f"  pool {label or spec.scene}: {i + 1}/{spec.passes} passes, "
                        f"{time.perf_counter() - start:.0f} s"
                    )
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "images.npy", images)
    meta = {"spec": asdict(spec), "info": info.to_json(), "render_seconds": render_s, "io_seconds": io_s}
    tmp = folder / "meta.json.tmp"
    tmp.write_text(json.dumps(meta))
    tmp.replace(folder / "meta.json")  # written last: a pool without meta.json is rendered again


def say(text: str) -> None:
    """Progress on the real stdout, even while Blender's own output is silenced."""
    os.write(_REAL_STDOUT, (text + "\n").encode())


_REAL_STDOUT = os.dup(1)


@contextlib.contextmanager
def quiet_stdout():
    """Silence Blender's per-render lines ('Fra:1 Mem...'), which it writes to the process's stdout from C."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, 1)
            os.close(saved)
