"""What the benchmarks render and how many trials they draw: the full run and the quick (CI) run.

Model no more than a scene needs: 128×128 px at 1 spp per pass is the smallest image that still holds a 2×2 grid
of 64×64 tiles (the largest tile the paper tries), and 400 passes are enough for the slowest case to be found by
the Welch test with 200 passes a side. The bright corner (walls 0.8, light 600 W) exists because in the paper's
grey corner (walls 0.2, 60 W) no indirect sample reaches the clamp of 10 and paths beyond two bounces carry almost
nothing, so clamping and bounce limits would have no effect to detect (measured: identical means to 7 digits).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from batch.blender.scenes import LIGHT_ENERGY, LIGHT_ENERGY_PATH, WALL_COLOR_PATH

from .pools import PoolSpec


def _grey(value: float) -> str:
    return f"{WALL_COLOR_PATH}={value},{value},{value},1"


#: Cycles' default bounce limits (the built-in scenes use the hard maximum, which Russian roulette never reaches).
DEFAULT_BOUNCES = ("cycles.max_bounces=12", "cycles.diffuse_bounces=4", "cycles.glossy_bounces=4",
                   "cycles.transmission_bounces=12")  # fmt: skip
BRIGHT = (_grey(0.8), f"{LIGHT_ENERGY_PATH}={10 * LIGHT_ENERGY:g}")
CONVERGED_FIRST_SEED = 1_000_000  # seeds of the converged references: disjoint from every pool's


@dataclass(frozen=True)
class Case:
    """A biased variant against its unbiased reference."""

    name: str
    label: str
    group: str  # name of the reference configuration
    ref: PoolSpec
    test: PoolSpec
    converged: PoolSpec  # the RMSE baseline's reference


@dataclass(frozen=True)
class Budget:
    """Sizes of one run of the benchmarks."""

    resolution: int
    passes: int  # per pool
    converged_spp: int  # spp of one pass of a converged reference
    converged_passes: int
    n_grid: tuple[int, ...]  # passes a side
    trials: int  # trials per point of a biased case
    null_trials: int  # trials per n of the tool's tests on unbiased pairs
    calibration_trials: int  # unbiased trials per n for the baselines: half calibrate, half measure
    stability_trials: int
    pixel_trials: int  # per-pixel tests (16k tiles a compare)
    pvalue_grid: tuple[int, int]  # nu values, |t| values for the mpmath reference
    pvalue_size: int  # tile-channel tests per timing
    cost_resolutions: tuple[int, ...]
    cost_passes: int
    verdict_passes: tuple[int, ...]
    tile_counts: tuple[int, ...]
    overhead_passes: int
    heavy_subdivisions: int  # icosphere subdivisions of the heavy mesh: 20 * 4**(s - 1) triangles
    heavy_passes: int
    decision_runs: int  # simulated `check` runs per case and test (chart 5)
    aa_runs: int  # simulated A/A `check` runs on the corner (chart 6)
    aa_other_runs: int  # the same on the other unbiased pairs
    scale_trials: int  # trials per pass count and tile size on the glass sphere's A/A (chart 7)
    scale_n: tuple[int, ...]  # those pass counts, a side
    stability_check_trials: int  # simulated `check` runs per situation of chart 3
    equivalence_runs: int  # simulated `check` runs per scale and case (chart 8)
    equivalence_passes: int  # their budget, passes a side

    def pool(self, scene: str, *overrides: str, **changes) -> PoolSpec:
        spec = PoolSpec(scene, tuple(overrides), self.resolution, 1, self.passes)
        return replace(spec, **changes)

    def converged(self, ref: PoolSpec) -> PoolSpec:
        return replace(ref, spp=self.converged_spp, passes=self.converged_passes, first_seed=CONVERGED_FIRST_SEED)


FULL = Budget(
    resolution=128,
    passes=400,
    converged_spp=64,
    converged_passes=16,
    n_grid=(2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192),
    trials=300,
    null_trials=300,
    calibration_trials=1000,
    stability_trials=1000,
    pixel_trials=100,
    pvalue_grid=(41, 81),
    pvalue_size=1_000_000,
    cost_resolutions=(64, 128, 256, 512, 1024),
    cost_passes=5,
    verdict_passes=(8, 16, 32, 64, 128, 200),
    tile_counts=(16, 64, 256, 1024, 4096, 8040),
    overhead_passes=100,
    heavy_subdivisions=8,
    heavy_passes=12,
    decision_runs=400,
    aa_runs=1000,
    aa_other_runs=300,
    scale_trials=300,
    scale_n=(8, 16, 24, 32, 48, 64, 96, 128, 192),
    stability_check_trials=1000,
    equivalence_runs=200,
    equivalence_passes=2048,
)

QUICK = Budget(
    resolution=64,
    passes=24,
    converged_spp=16,
    converged_passes=2,
    n_grid=(2, 4, 8),
    trials=8,
    null_trials=8,
    calibration_trials=20,
    stability_trials=8,
    pixel_trials=3,
    pvalue_grid=(5, 7),
    pvalue_size=10_000,
    cost_resolutions=(64, 128),
    cost_passes=2,
    verdict_passes=(4, 8),
    tile_counts=(16, 64),
    overhead_passes=3,
    heavy_subdivisions=4,
    heavy_passes=2,
    decision_runs=6,
    aa_runs=8,
    aa_other_runs=4,
    scale_trials=6,
    scale_n=(4, 8),
    stability_check_trials=6,
    equivalence_runs=4,
    equivalence_passes=64,
)


def cases(b: Budget) -> list[Case]:
    """Chart 1's bias cases, each with its reference and the converged reference for the RMSE baseline."""
    corner = b.pool("corner")
    bright = b.pool("corner", *BRIGHT)
    glossy = b.pool("glossy")
    light = f"{LIGHT_ENERGY_PATH}={LIGHT_ENERGY * 1.005:g}"
    spec = [
        ("walls", "walls 0.20 → 0.21 (paper Fig. 16)", corner, b.pool("corner", _grey(0.21))),
        ("light", "light ×1.005", corner, b.pool("corner", light)),
        ("clamp", "indirect clamp 10 vs off (bright corner)", bright,
         b.pool("corner", *BRIGHT, "cycles.sample_clamp_indirect=10")),
        ("bounces", "max bounces 2 vs unlimited (bright corner)", bright,
         b.pool("corner", *BRIGHT, "cycles.max_bounces=2")),
        ("default_bounces", "Cycles' default bounce limits vs unlimited (bright)", bright,
         b.pool("corner", *BRIGHT, *DEFAULT_BOUNCES)),
        ("glossy", "Filter Glossy 1.0 vs 0 (glossy scene)", glossy, b.pool("glossy", "cycles.blur_glossy=1.0")),
    ]  # fmt: skip
    groups = {corner: "corner", bright: "bright corner", glossy: "glossy"}
    return [Case(name, label, groups[ref], ref, test, b.converged(ref)) for name, label, ref, test in spec]


#: The glossy scene's metal sphere: its base colour is (0.9, 0.6, 0.3).
METAL_COLOR_PATH = 'materials["Metal"].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value'


def local_case(b: Budget) -> Case:
    """A local bias: one small object's material changed (the metal sphere's red 0.9 -> 0.85, about -6 % in the
    sphere's two tiles of 16², -1.2 % in the red of the whole image through what the sphere reflects)."""
    glossy = b.pool("glossy")
    test = b.pool("glossy", f"{METAL_COLOR_PATH}=0.85,0.6,0.3,1")
    return Case("metal", "metal sphere red 0.90 → 0.85 (glossy scene, local)", "glossy", glossy, test,
                b.converged(glossy))  # fmt: skip


def paired_null(b: Budget) -> tuple[PoolSpec, PoolSpec]:
    """An unbiased pair with the same seeds for the paired test's false-positive rate: the sampling pattern
    changes the random numbers but not the expectation (BLENDER_FACTS: measured unbiased)."""
    return b.pool("corner"), b.pool("corner", pattern="BLUE_NOISE")


def glass(b: Budget) -> PoolSpec:
    return b.pool("corner_glass")


def aa_pairs(b: Budget) -> list[dict]:
    """Chart 6's unbiased pairs (the power and moderated studies use them too): name, label, reference and test
    pool, paired or not, runs."""
    corner = b.pool("corner")
    bright = next(c.ref for c in cases(b) if c.group == "bright corner")
    _sobol, blue = paired_null(b)
    return [
        {"name": "corner", "label": "corner (paper's scene)", "ref": corner, "test": corner, "paired": False,
         "runs": b.aa_runs},
        {"name": "bright", "label": "bright corner", "ref": bright, "test": bright, "paired": False,
         "runs": b.aa_other_runs},
        {"name": "glossy", "label": "glossy scene", "ref": b.pool("glossy"), "test": b.pool("glossy"),
         "paired": False, "runs": b.aa_other_runs},
        {"name": "glass", "label": "corner + glass sphere (caustics)", "ref": glass(b), "test": glass(b),
         "paired": False, "runs": b.aa_other_runs},
        {"name": "sobol_blue", "label": "corner, Sobol vs blue noise, paired", "ref": corner, "test": blue,
         "paired": True, "runs": b.aa_other_runs},
    ]  # fmt: skip


# -- the sparse cases ---------------------------------------------------------------------------------------

#: Changes that alter a few light paths (an indirect clamp that clips only the rare bright caustic or subsurface
#: path), rendered by `benchmarks.studies.sparse`; the power and moderated studies draw from the same pools.
#: (scene, override, label), each a built-in scene at SPARSE_RESOLUTION px, 1 spp a pass.
SPARSE_CASES = (
    ("corner_glass", "cycles.sample_clamp_indirect=20", "glass caustic, indirect clamp 20"),
    ("volume", "cycles.sample_clamp_indirect=1", "fog, indirect clamp 1"),
    ("sss", "cycles.sample_clamp_indirect=3", "subsurface, indirect clamp 3"),
)
SPARSE_RESOLUTION = 64
#: Passes of each sparse pool: in the full run, in the quick one.
SPARSE_POOL, SPARSE_QUICK_POOL = 640, 48


def sparse_pools(scene: str, change: str, passes: int) -> tuple[PoolSpec, PoolSpec]:
    """A sparse case's reference and changed pool, `passes` passes each, with the same seeds."""
    return PoolSpec(scene, (), SPARSE_RESOLUTION, passes=passes), PoolSpec(scene, (change,), SPARSE_RESOLUTION,
                                                                              passes=passes)  # fmt: skip
