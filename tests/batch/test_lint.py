"""batch.blender.lint on real scenes: Blender's biased defaults, the unbiased built-in scenes, each rule."""

from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from batch.blender.lint import (  # noqa: E402
    BIASED,
    INFO,
    NOT_INDEPENDENT,
    RULES,
    SAMPLES,
    SEVERITIES,
    Finding,
    Rule,
    lint_scene,
    sample_findings,
)
from batch.blender.scenes import SCENES, build_scene  # noqa: E402
from batch.jobs.overrides import apply_overrides  # noqa: E402


@pytest.fixture
def factory():
    """bpy is one global state per process: every test starts from an empty file and leaves one (a scene left
    built would shadow the data-blocks of the next module's scenes by name)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_factory_scene_has_the_biased_defaults(factory):
    findings = lint_scene(bpy.context.scene)
    assert [(f.path, f.value, f.unbiased, f.severity) for f in findings] == [
        ("cycles.sample_clamp_indirect", 10.0, 0.0, BIASED),
        ("cycles.blur_glossy", 1.0, 0.0, BIASED),
        ("cycles.use_denoising", True, False, BIASED),
        ('view_layers["ViewLayer"].cycles.use_denoising', True, False, BIASED),
        ("cycles.use_adaptive_sampling", True, False, BIASED),
        ("cycles.max_bounces", 12, 1024, INFO),
        ("cycles.diffuse_bounces", 4, 1024, INFO),
        ("cycles.glossy_bounces", 4, 1024, INFO),
        ("cycles.transmission_bounces", 12, 1024, INFO),
        ("cycles.transparent_max_bounces", 8, 1024, INFO),
    ]


@pytest.mark.parametrize("name", sorted(SCENES))
def test_builtin_scenes_are_clean(factory, name):
    assert lint_scene(build_scene(name)) == []


@pytest.mark.parametrize(
    ("override", "path", "severity"),
    [
        ("cycles.sample_clamp_direct=0.5", "cycles.sample_clamp_direct", BIASED),
        ("cycles.caustics_reflective=false", "cycles.caustics_reflective", BIASED),
        ("cycles.caustics_refractive=false", "cycles.caustics_refractive", BIASED),
        ("cycles.use_fast_gi=true", "cycles.use_fast_gi", BIASED),
        ("cycles.volume_biased=true", "cycles.volume_biased", BIASED),
        ("cycles.time_limit=2", "cycles.time_limit", NOT_INDEPENDENT),
        ("cycles.use_sample_subset=true", "cycles.use_sample_subset", NOT_INDEPENDENT),
        ("cycles.scrambling_distance=0.1", "cycles.scrambling_distance", INFO),
        ("cycles.auto_scrambling_distance=true", "cycles.auto_scrambling_distance", INFO),
        ("cycles.use_animated_seed=true", "cycles.use_animated_seed", INFO),
        ("cycles.max_bounces=2", "cycles.max_bounces", INFO),
        ("cycles.diffuse_bounces=1", "cycles.diffuse_bounces", INFO),
        ("cycles.transparent_max_bounces=0", "cycles.transparent_max_bounces", INFO),
    ],
)
def test_each_rule_fires_on_its_setting(factory, override, path, severity):
    scene = build_scene("corner")
    apply_overrides(scene, [override])
    (finding,) = lint_scene(scene)
    assert (finding.path, finding.severity) == (path, severity)


def test_every_view_layer_is_checked(factory):
    scene = build_scene("corner")
    scene.view_layers.new('Layer "2"').cycles.use_denoising = True
    scene.cycles.use_denoising = True
    paths = [finding.path for finding in lint_scene(scene)]
    assert paths == ["cycles.use_denoising", 'view_layers["Layer \\"2\\""].cycles.use_denoising']


def test_a_view_layer_denoising_flag_does_nothing_while_the_scenes_is_off(factory):
    """New view layers have denoising on, but it only denoises with the scene's on too: a correct scene is clean."""
    scene = build_scene("corner")
    assert scene.view_layers.new("Layer 2").cycles.use_denoising
    assert lint_scene(scene) == []


def test_rules_are_well_formed_and_missing_properties_are_skipped(factory):
    assert {rule.severity for rule in RULES} <= set(SEVERITIES)
    cycles = bpy.context.scene.cycles.bl_rna.properties
    assert all(rule.path.rpartition(".")[2] in cycles for rule in RULES if rule.path.startswith("cycles."))
    ghost = Rule("cycles.no_such_setting", bool, False, BIASED, "a setting of another Blender version")
    assert lint_scene(bpy.context.scene, (ghost,)) == []


def test_finding_format():
    finding = Finding("cycles.blur_glossy", 1.0, 0.0, BIASED, "blurs")
    assert finding.format() == "biased          cycles.blur_glossy = 1.0 (unbiased: 0.0): blurs"


def test_settings_that_act_only_above_some_samples_are_named_where_the_scene_reaches_them(factory):
    """Blender's factory scene renders 4096 samples: its sampling pattern (Tabulated Sobol's table in bpy 5.0, the
    Automatic pattern's blue noise in 5.2) and adaptive sampling act there, not in a pass of 1 sample; path guiding
    and blue noise from 2 samples."""
    scene = bpy.context.scene
    assert [(f.path, f.value, f.severity) for f in sample_findings(scene)] == [
        ("cycles.sampling_pattern", scene.cycles.sampling_pattern, SAMPLES),
        ("cycles.use_adaptive_sampling", True, SAMPLES),
    ]
    scene.cycles.use_guiding, scene.cycles.sampling_pattern = True, "BLUE_NOISE"
    found = {f.path: f for f in sample_findings(scene)}
    assert list(found) == ["cycles.use_guiding", "cycles.sampling_pattern", "cycles.use_adaptive_sampling"]
    assert (
        found["cycles.use_guiding"]
        .format()
        .startswith(
            "samples         cycles.use_guiding = True: acts only from 2 samples per render and the scene renders "
            "4096: passes of fewer samples (check --spp) do not show it; path guiding"
        )
    )
    scene.cycles.samples = 1  # its own renders do not reach them either
    assert [f.path for f in sample_findings(scene)] == []


@pytest.mark.parametrize("name", ["corner", "volume"])
def test_builtin_scenes_ask_nothing_of_the_samples_and_are_known_without_reading_them(factory, name):
    from batch.jobs.samples import BUILTIN, acting, scene_samples

    scene = build_scene(name)
    assert sample_findings(scene) == []
    read = scene_samples(scene)
    assert read.samples == 1 and acting(read.settings) == acting(BUILTIN.settings)
