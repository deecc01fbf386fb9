"""Cycles settings that act only above some samples per render, as one table (`SAMPLE_DEPENDENT`): the setting
by its override path, when its value makes it act, the fewest samples per render at which it acts, and what Cycles
documents it to change. A pass of fewer samples cannot show such a setting, so ``check --spp auto`` renders the
passes at the samples its question needs (`auto_samples`), a summary says where a verdict holds at its passes'
samples only (`batch.present.summary.sample_notes`), and ``lint`` names them.

The numbers are measured (bpy 5.0.1, CPU): ``python -m benchmarks.studies.sample_dependent`` renders the same
seeds with and without a setting at 1, 2, 3, 4, ... samples (32x32 and 64x64) and finds the first count at which
the two renders are not bit-identical; for a sampling pattern, the first count at which a sample of an N-sample
render (``use_sample_subset``) differs from the same sample of the shortest render that has it
(docs/findings/sample_dependent.md).

Nothing here imports bpy: a scene is read by attribute (`scene_samples`), so a render process, ``lint`` and the
add-on read their scenes alike.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from .overrides import parse_override

#: A scene's settings by override path (``cycles.use_guiding`` -> True).
Settings = Mapping[str, Any]


@dataclass(frozen=True)
class SampleSetting:
    """A setting that acts only from `fewest(settings)` samples per render, where `on(settings)` (its value, and
    the settings it works with); `documented`: what Cycles documents it to change; `measured`: what the
    measurement found."""

    path: str
    on: Callable[[Settings], bool]
    fewest: Callable[[Settings], int]
    documented: str
    measured: str

    @property
    def name(self) -> str:
        return self.path.removeprefix("cycles.")


def _is(path: str, *values) -> Callable[[Settings], bool]:
    return lambda settings: settings.get(path) in values


def _always(count: int) -> Callable[[Settings], int]:
    return lambda _settings: count


def _scrambling(settings: Settings) -> int:
    """Automatic scrambling distance is the multiplier x 4 / sqrt(samples) (Blender's sync of the integrator):
    below 1 from more than 16 x multiplier^2 samples."""
    multiplier = float(settings.get("cycles.scrambling_distance", 1.0))
    return math.floor(16.0 * multiplier**2) + 1


#: Cycles checks which pixels have converged every this many samples once past the minimum (`AdaptiveSampling`).
ADAPTIVE_STEP = 16
#: The lowest automatic noise threshold (Cycles' max(0.001, 1 / samples) where the threshold is 0).
_LOWEST_THRESHOLD = 0.001


def _adaptive(settings: Settings) -> int:
    """Adaptive sampling's minimum samples (``adaptive_min_samples``; 0: automatic, 16 / threshold^0.3, at least
    4; Cycles' integrator.cpp), then its first convergence check, at the next multiple of 16 past it: the first
    sample it can leave out is the one after."""
    minimum = int(settings.get("cycles.adaptive_min_samples", 0) or 0)
    if minimum == 0:
        threshold = float(settings.get("cycles.adaptive_threshold", 0.01) or _LOWEST_THRESHOLD)
        minimum = math.ceil(16.0 / threshold**0.3)
    minimum = max(4, minimum)
    return ADAPTIVE_STEP * (minimum // ADAPTIVE_STEP + 1) + 1


#: Blue noise and Sobol-Burley: their sequence is as long as the render's samples (blue noise rounded up to a power
#: of two in BLUE_NOISE_ROUND; Sobol-Burley's scrambling within the next power of two). AUTOMATIC is blue noise
#: in a final render.
DIMENSIONED = ("BLUE_NOISE", "AUTOMATIC", "BLUE_NOISE_ROUND", "SOBOL_BURLEY")

SAMPLE_DEPENDENT: tuple[SampleSetting, ...] = (
    SampleSetting(
        "cycles.use_guiding", _is("cycles.use_guiding", True), _always(2),
        "path guiding (CPU) learns where light comes from out of a render's samples and steers its later ones, "
        "training over guiding_training_samples (128 by default)",
        "a 1-sample render is bit-identical to one without it (the first sample is never guided); the corner "
        "scene differs from 2 samples at 64x64, from 6 at 32x32, and not up to 16 at 16x16 (the guiding field "
        "needs enough path vertices before its first update)",
    ),
    SampleSetting(
        "cycles.sampling_pattern", _is("cycles.sampling_pattern", *DIMENSIONED), _always(2),
        "blue noise spreads a render's samples over the pixels with a sequence as long as the render's samples; "
        "Sobol-Burley scrambles within the next power of two of them",
        "the first sample of a 2-sample render differs from a 1-sample render of the same seed; the fog's blue-"
        "noise bias (docs/findings/blue_noise_volume.md) is there at 2 samples and not at 1",
    ),
    SampleSetting(
        "cycles.sampling_pattern", _is("cycles.sampling_pattern", "BLUE_NOISE_FIRST"), _always(3),
        "a pixel's first sample from a 1-sample blue-noise sequence, the rest from a sequence of samples - 1",
        "the second sample of a 3-sample render differs from that of a 2-sample render",
    ),
    SampleSetting(
        "cycles.sampling_pattern", _is("cycles.sampling_pattern", "TABULATED_SOBOL"), _always(257),
        "Tabulated Sobol draws from a table of the render's samples rounded up to a power of two, at least 256",
        "the first sample of a 257-sample render differs from a 1-sample render; up to 256 samples they are "
        "identical",
    ),
    SampleSetting(
        "cycles.auto_scrambling_distance",
        lambda s: s.get("cycles.auto_scrambling_distance") is True and s.get("cycles.sampling_pattern") ==
        "TABULATED_SOBOL", _scrambling,
        "the scrambling distance becomes the multiplier x 4 / sqrt(samples): below 1 it correlates the pixels of "
        "a render (Tabulated Sobol only)",
        "bit-identical to it off up to 16 samples, different from 17 (multiplier 1); no effect with blue noise "
        "or Sobol-Burley up to 64",
    ),
    SampleSetting(
        "cycles.use_adaptive_sampling", _is("cycles.use_adaptive_sampling", True), _adaptive,
        "adaptive sampling stops converged pixels, checking every 16 samples once past adaptive_min_samples (0: "
        "16 / threshold^0.3, 64 at the default threshold 0.01); a pass of this tool never uses it",
        "bit-identical to it off up to 80 samples at threshold 0.01, different from 81; from 17 with minimum 8, "
        "from 49 with minimum 40",
    ),
)  # fmt: skip

#: Every setting the table reads: what a scene's record of them holds (`scene_samples`).
READS = (
    "cycles.use_guiding", "cycles.guiding_training_samples", "cycles.sampling_pattern",
    "cycles.auto_scrambling_distance", "cycles.scrambling_distance", "cycles.use_adaptive_sampling",
    "cycles.adaptive_min_samples", "cycles.adaptive_threshold",
)  # fmt: skip


@dataclass(frozen=True)
class Acting:
    """A sample-dependent setting a scene has on: its `value` and the `fewest` samples per render it acts at."""

    setting: SampleSetting
    value: Any
    fewest: int

    @property
    def name(self) -> str:
        return self.setting.name


def acting(settings: Settings) -> dict[str, Acting]:
    """The sample-dependent settings `settings` (override path -> value) have on, by path."""
    found = {}
    for setting in SAMPLE_DEPENDENT:
        if setting.path not in found and setting.on(settings):
            found[setting.path] = Acting(setting, settings.get(setting.path), setting.fewest(settings))
    return found


@dataclass(frozen=True)
class SceneSamples:
    """What a scene asks of the passes: its own samples per render (None: a built-in scene, whose samples are
    the tool's) and the settings the table reads (`READS`), as a render of it has them."""

    samples: int | None
    settings: dict[str, Any] = field(default_factory=dict)


#: A built-in scene (`batch.blender.scenes.new_scene`): 1 sample, Tabulated Sobol, nothing else of the table on.
BUILTIN = SceneSamples(
    None,
    {"cycles.sampling_pattern": "TABULATED_SOBOL", "cycles.use_guiding": False,
     "cycles.auto_scrambling_distance": False, "cycles.use_adaptive_sampling": False},
)  # fmt: skip


_MISSING = object()


def scene_samples(scene) -> SceneSamples:
    """A Blender scene's own samples and the settings of `READS` it has (one this Blender lacks is left out)."""
    settings = {}
    for path in READS:
        value = scene
        for name in path.split("."):
            value = getattr(value, name, _MISSING)
            if value is _MISSING:
                break
        if value is not _MISSING:
            settings[path] = value if isinstance(value, bool | int | float | str) else str(value)
    return SceneSamples(int(scene.cycles.samples), settings)


def _value(items: tuple[str, ...]):
    """An override's value as the table compares it: a boolean, a number or an enum identifier."""
    text = items[0] if len(items) == 1 else ",".join(items)
    lowered = text.lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def side_settings(scene: SceneSamples, pattern: str | None = None, overrides: Iterable[str] = ()) -> dict:
    """The settings of `READS` a side renders with: its scene's, the job's sampling pattern and the overrides of
    them (``cycles.use_guiding=true``; a boolean given as 1 or 0 reads as an integer, which Blender takes alike)."""
    settings = dict(scene.settings)
    if pattern is not None:
        settings["cycles.sampling_pattern"] = pattern
    for text in overrides:
        override = parse_override(text)
        path = override.path.removeprefix("scene.")
        if path in READS:
            value = _value(override.items)
            is_switch = path.startswith(("cycles.use_", "cycles.auto_")) and value in (0, 1)
            settings[path] = bool(value) if is_switch else value
    return settings


@dataclass(frozen=True)
class Differing:
    """A sample-dependent setting in which the two sides differ: its path, each side's value, and the fewest
    samples per render from which what acts differs."""

    path: str
    values: tuple[Any, Any]
    fewest: int

    @property
    def name(self) -> str:
        return self.path.removeprefix("cycles.")

    def to_json(self) -> dict:
        return {"name": self.name, "values": list(self.values), "fewest": self.fewest}


def differing(reference: Settings, test: Settings) -> list[Differing]:
    """The sample-dependent settings the two sides' settings differ in (on one side only, or with other values)."""
    ref, tst = acting(reference), acting(test)
    out = []
    for path in dict.fromkeys([*ref, *tst]):
        a, b = ref.get(path), tst.get(path)
        values = (a.value if a else reference.get(path), b.value if b else test.get(path))
        if (a.value if a else None) != (b.value if b else None):  # what acts, at some samples, on each side
            fewest = min(x.fewest for x in (a, b) if x is not None)
            out.append(Differing(path, values, fewest))
    return out


@dataclass(frozen=True)
class AutoSamples:
    """The samples per pass ``--spp auto`` chose: 1, or more because the sides differ in the settings `differing`
    (then the scene files' samples, `files`: None for built-in scenes)."""

    spp: int
    differing: tuple[Differing, ...] = ()
    files: int | None = None

    def to_json(self) -> dict | None:
        """What a check's record keeps of it (None: 1 sample, nothing needed more)."""
        if not self.differing:
            return None
        return {"spp": self.spp, "files": self.files, "differing": [d.to_json() for d in self.differing]}


def auto_samples(reference: SceneSamples, test: SceneSamples, ref_settings: Settings, test_settings: Settings,
                 ) -> AutoSamples:  # fmt: skip
    """``--spp auto``: 1 sample per pass, unless the sides differ in a sample-dependent setting; then the scene
    files' samples (the larger where they differ), and never fewer than the setting acts at."""
    found = differing(ref_settings, test_settings)
    if not found:
        return AutoSamples(1)
    files = max((s.samples for s in (reference, test) if s.samples is not None), default=None)
    return AutoSamples(max(d.fewest for d in found) if files is None else max(files, *(d.fewest for d in found)),
                       tuple(found), files)  # fmt: skip
