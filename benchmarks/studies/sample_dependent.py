"""Cycles settings that act only above some samples per render: the measurement behind the table of
``batch/jobs/samples.py`` (`SAMPLE_DEPENDENT`) and ``docs/findings/sample_dependent.md``::

    python -m benchmarks.studies.sample_dependent            # about 30 s on 2 cores (bpy 5.0.1)

Each row renders the same seeds twice on the CPU, once with the setting and once without, at the sample counts
given, and says at which count the two first stop being bit-identical: below it the setting does nothing to a
render. A sampling pattern is dimensioned for the render's sample count where a sample of an N-sample render
(``use_sample_subset``, length 1) differs from the same sample of the shortest render that has it: at 1 sample a
render is one sample of a sequence of length 1, whatever the pattern does across samples.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

import bpy
import numpy as np

from batch.blender import render

from ..common.pools import quiet_stdout, say

POWERS = (1, 2, 3, 4, 8, 16, 32, 64, 128)


@dataclass(frozen=True)
class Case:
    """One row: `on` against `off` (``cycles`` attributes) on a built-in scene, or with `sample` set, that sample of
    an N-sample render against the same sample of a render of `sample` + 1 samples (both with `on`)."""

    label: str
    scene: str
    on: dict
    off: dict = field(default_factory=dict)
    pattern: str = "TABULATED_SOBOL"
    counts: tuple[int, ...] = POWERS
    resolution: int = 32
    sample: int | None = None


CASES = (
    Case("use_guiding on/off, 64x64", "corner", {"use_guiding": True}, {"use_guiding": False}, resolution=64),
    Case("use_guiding on/off, 32x32", "corner", {"use_guiding": True}, {"use_guiding": False},
         counts=(1, 2, 3, 4, 5, 6, 8, 16)),
    Case("use_guiding on/off, 16x16", "corner", {"use_guiding": True}, {"use_guiding": False}, resolution=16,
         counts=(1, 2, 4, 8, 16)),
    Case("use_guiding, guiding_training_samples 1 against 128", "corner",
         {"use_guiding": True, "guiding_training_samples": 1}, {"use_guiding": True}),
    Case("auto_scrambling_distance on/off, Tabulated Sobol", "corner", {"auto_scrambling_distance": True},
         {"auto_scrambling_distance": False}, counts=(1, 2, 4, 8, 16, 17, 32)),
    Case("auto_scrambling_distance on/off, blue noise", "corner", {"auto_scrambling_distance": True},
         {"auto_scrambling_distance": False}, pattern="BLUE_NOISE", counts=(16, 32, 64)),
    Case("auto_scrambling_distance on/off, Sobol-Burley", "corner", {"auto_scrambling_distance": True},
         {"auto_scrambling_distance": False}, pattern="SOBOL_BURLEY", counts=(16, 32, 64)),
    Case("use_adaptive_sampling on/off (threshold 0.01, minimum automatic)", "corner",
         {"use_adaptive_sampling": True}, {"use_adaptive_sampling": False}, counts=(1, 16, 64, 65, 80, 81, 128)),
    Case("use_adaptive_sampling on/off, adaptive_min_samples 8", "corner",
         {"use_adaptive_sampling": True, "adaptive_min_samples": 8}, {"use_adaptive_sampling": False},
         counts=(1, 9, 16, 17, 32)),
    Case("use_adaptive_sampling on/off, adaptive_min_samples 40", "corner",
         {"use_adaptive_sampling": True, "adaptive_min_samples": 40}, {"use_adaptive_sampling": False},
         counts=(41, 48, 49, 64)),
    *(Case(f"{pattern}: sample 0 of N against a 1-sample render", "volume", {}, pattern=pattern, sample=0)
      for pattern in ("BLUE_NOISE", "AUTOMATIC", "SOBOL_BURLEY", "BLUE_NOISE_FIRST")),
    Case("BLUE_NOISE_FIRST: sample 1 of N against a 2-sample render", "volume", {}, pattern="BLUE_NOISE_FIRST",
         sample=1, counts=(2, 3, 4, 8, 16)),
    Case("TABULATED_SOBOL: sample 0 of N against a 1-sample render", "volume", {}, sample=0,
         counts=(1, 2, 16, 128, 256, 257, 512)),
)  # fmt: skip


def enable_developer_patterns() -> None:
    """SOBOL_BURLEY and BLUE_NOISE_FIRST render as themselves only with the developer UI and Cycles' debug option
    on before the first render (docs/findings/blue_noise_volume.md)."""
    prefs = bpy.context.preferences
    prefs.view.show_developer_ui = True
    prefs.experimental.use_cycles_debug = True


def scene_for(case: Case) -> bpy.types.Scene:
    """The case's built-in scene on the CPU, set up as the tool's passes are, its persistent data off (every
    render starts afresh: nothing is carried from one render to the next)."""
    scene = render.open_scene(None, case.scene)  # reads the factory settings: the developer patterns again
    enable_developer_patterns()
    render.configure_unbiased(scene, "CPU", 1, (case.resolution, case.resolution), case.pattern)
    scene.render.use_persistent_data = False
    return scene


def images(scene, seeds, spp: int, settings: dict) -> list[np.ndarray]:
    """A render of each seed at `spp` samples with `settings` (``cycles`` attribute -> value) applied."""
    old = {name: getattr(scene.cycles, name) for name in settings}
    for name, value in {"samples": spp, **settings}.items():
        setattr(scene.cycles, name, value)
    with quiet_stdout(), render.PassRenderer(scene) as renderer:
        out = [renderer.render(seed) for seed in seeds]
    for name, value in old.items():
        setattr(scene.cycles, name, value)
    return out


def differences(case: Case, seeds) -> list[tuple[int, float]]:
    """(samples, the largest pixel difference relative to the mean) at each of the case's sample counts."""
    scene = scene_for(case)
    rows = []
    for spp in case.counts:
        if case.sample is not None:
            alone = {"use_sample_subset": True, "sample_offset": case.sample, "sample_subset_length": 1}
            a = images(scene, seeds, spp, case.on | alone)
            b = images(scene, seeds, case.sample + 1, case.on | alone)
        else:
            a, b = images(scene, seeds, spp, case.on), images(scene, seeds, spp, case.off)
        scale = max(float(np.mean(x)) for x in b) or 1.0
        rows.append((spp, max(float(np.max(np.abs(x - y))) for x, y in zip(a, b, strict=True)) / scale))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=2, help="seeds rendered at each count (default 2)")
    args = parser.parse_args(argv)
    for case in CASES:
        rows = differences(case, range(args.seeds))
        first = next((spp for spp, diff in rows if diff > 0), None)
        shown = ", ".join(f"{spp}: {diff:.2g}" for spp, diff in rows)
        say(f"{case.label}: first differs at {first or f'none up to {case.counts[-1]}'} ({shown})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
