"""Scene settings that make Cycles biased by design, make passes dependent, or are worth knowing before a test.

The rules are a table: each names a setting by its override path (``batch.overrides`` syntax, so a finding can
be fixed with ``--set PATH=VALUE``), says when it is flagged, what the unbiased value is and why it matters.
Effects quoted are those measured in ``BLENDER_FACTS.md`` (64², 200 passes of 1 spp per side). Settings that act
only above some samples per render are `batch.jobs.samples`' table; `sample_findings` names those a scene's own
renders reach.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from ..jobs.rna import jsonable
from ..jobs.samples import acting, scene_samples
from .scenes import CYCLES_MAX_BOUNCES as MAX_BOUNCES

BIASED = "biased"  # the converged image differs from the unbiased one
NOT_INDEPENDENT = "not-independent"  # passes are not independent or not reproducible: the test's assumptions fail
INFO = "info"  # unbiased, but it changes the variance or must match on both sides
SAMPLES = "samples"  # acts only above some samples per render: passes of fewer do not show it
SEVERITIES = (BIASED, NOT_INDEPENDENT, INFO, SAMPLES)


@dataclass(frozen=True)
class Finding:
    """One flagged setting: its override path, current value, unbiased value, severity and what it does."""

    path: str
    value: object
    unbiased: object
    severity: str
    explanation: str

    def format(self) -> str:
        """One line for the terminal."""
        unbiased = f" (unbiased: {self.unbiased!r})" if self.severity != SAMPLES else ""
        return f"{self.severity:<15} {self.path} = {self.value!r}{unbiased}: {self.explanation}"


@dataclass(frozen=True)
class Rule:
    """`path` relative to the scene (``view_layers[*]`` stands for every view layer); flagged when `flagged(value)`
    and, if given, `applies(scene)` (a setting that has no effect unless another one is on)."""

    path: str
    flagged: Callable[[object], bool]
    unbiased: object
    severity: str
    explanation: str
    applies: Callable[[object], bool] | None = None


def _on(value) -> bool:
    return bool(value)


def _off(value) -> bool:
    return not value


def _positive(value) -> bool:
    return value > 0


def _below(limit: float) -> Callable[[object], bool]:
    return lambda value: value < limit


_TURNED_OFF = "the batch tool turns it off for its passes, final renders keep it"

RULES: tuple[Rule, ...] = (
    Rule("cycles.sample_clamp_indirect", _positive, 0.0, BIASED,
         "clamps indirect samples (Blender's default is 10): bright indirect paths lose energy, mean x0.94 at 10"),
    Rule("cycles.sample_clamp_direct", _positive, 0.0, BIASED,
         "clamps direct-light samples: bright highlights lose energy, mean x0.82 at 0.5"),
    Rule("cycles.blur_glossy", _positive, 0.0, BIASED,
         "Filter Glossy (Blender's default is 1.0) roughens glossy surfaces seen after a rough bounce, mean x0.94"),
    Rule("cycles.caustics_reflective", _off, True, BIASED,
         "reflective caustics off drops light paths, mean x0.91"),
    Rule("cycles.caustics_refractive", _off, True, BIASED,
         "refractive caustics off drops light paths, mean x0.93"),
    Rule("cycles.use_fast_gi", _on, False, BIASED,
         "fast GI replaces indirect light after a few bounces with an approximation"),
    Rule("cycles.volume_biased", _on, False, BIASED,
         "biased volume rendering: cheaper, but not converging to the exact volume integral"),
    Rule("cycles.use_denoising", _on, False, BIASED,
         f"the denoiser changes the expected image (mean x0.91) and is 10x slower per pass; {_TURNED_OFF}"),
    Rule("view_layers[*].cycles.use_denoising", _on, False, BIASED,
         f"the view layer's denoising switch, with the scene's denoising on; {_TURNED_OFF}",
         applies=lambda scene: scene.cycles.use_denoising),
    Rule("cycles.use_adaptive_sampling", _on, False, BIASED,
         f"per-pixel sample counts depend on the rendered values, so the estimate is biased; {_TURNED_OFF}"),
    Rule("cycles.time_limit", _positive, 0.0, NOT_INDEPENDENT,
         f"the sample count depends on machine speed and load: passes are not reproducible; {_TURNED_OFF}"),
    Rule("cycles.use_sample_subset", _on, False, NOT_INDEPENDENT,
         "passes taken as sample subsets (sample_offset) of one seed are jointly stratified, not independent "
         "(variance ratio 0.4-0.66); use different seeds"),
    Rule("cycles.scrambling_distance", _below(1.0), 1.0, INFO,
         "unbiased, but correlates pixels within a pass: tile-sum variance rose 8.8x at 0.1, so the test loses power"),
    Rule("cycles.auto_scrambling_distance", _on, False, INFO,
         "unbiased, but correlates pixels within a pass (see scrambling_distance)"),
    Rule("cycles.use_animated_seed", _on, False, INFO,
         "the seed is hashed with the frame number: passes still differ by seed, but Cycles does not use the "
         "recorded seed literally"),
    # Bounce limits truncate paths: biased against the true solution, fine when both sides use the same limits.
    # Blender's defaults truncate too: -0.7 % with bright walls (docs/benchmarks); the built-in scenes use the maximum.
    *(
        Rule(f"cycles.{name}", _below(MAX_BOUNCES), MAX_BOUNCES, INFO,
             f"{what} bounce limit truncates light paths (max_bounces 2: mean x0.83; Blender's defaults: x0.993 with "
             "bright walls); fine when both sides use the same limits")
        for name, what in (("max_bounces", "the overall"), ("diffuse_bounces", "the diffuse"),
                           ("glossy_bounces", "the glossy"), ("transmission_bounces", "the transmission"),
                           ("transparent_max_bounces", "the transparent"))
    ),
    # Not listed because measured unbiased: light_sampling_threshold (Russian roulette with reweighting),
    # use_light_tree, the sampling pattern, use_guiding; direct_light_sampling_type is ignored in release builds.
)  # fmt: skip


def lint_scene(scene, rules: tuple[Rule, ...] = RULES) -> list[Finding]:
    """Check `scene` against `rules`.

    Parameters
    ----------
    scene : bpy.types.Scene
    rules : tuple of Rule
        Defaults to `RULES`. A rule whose property this Blender lacks is skipped.

    Returns
    -------
    list of Finding
        In the order of `rules`; empty when nothing is flagged.
    """
    findings = []
    for rule in rules:
        if rule.applies is not None and not rule.applies(scene):
            continue
        for path, value in _values(scene, rule.path):
            if rule.flagged(value):
                findings.append(Finding(path, jsonable(value), rule.unbiased, rule.severity, rule.explanation))
    return findings


def sample_findings(scene) -> list[Finding]:
    """The settings of `scene` that act only above some samples per render (`batch.jobs.samples`) and do act at
    its own samples: passes of fewer samples (``check --spp``) cannot show them. Severity `SAMPLES`, no unbiased
    value (they are not biased for it)."""
    own = scene_samples(scene)
    return [
        Finding(path, found.value, None, SAMPLES,
                f"acts only from {found.fewest} samples per render and the scene renders {own.samples}: passes of "
                f"fewer samples (check --spp) do not show it; {found.setting.documented}")
        for path, found in acting(own.settings).items()
        if found.fewest <= own.samples
    ]  # fmt: skip


def _values(scene, path: str) -> Iterator[tuple[str, object]]:
    """(concrete path, value) for a rule path; ``view_layers[*].`` repeats it for every view layer."""
    head, star, rest = path.partition("view_layers[*].")
    if star:
        for layer in scene.view_layers:
            value = _get(layer, rest)
            if value is not _MISSING:
                yield f"view_layers[{json.dumps(layer.name)}].{rest}", value
        return
    value = _get(scene, head)
    if value is not _MISSING:
        yield path, value


_MISSING = object()


def _get(struct, dotted: str):
    for name in dotted.split("."):
        if name not in struct.bl_rna.properties:
            return _MISSING
        struct = getattr(struct, name)
    return struct
