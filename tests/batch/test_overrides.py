"""batch.jobs.overrides: the --set syntax (pure Python) and resolving, validating and applying it with bpy."""

from __future__ import annotations

import pytest

from batch.jobs.overrides import Override, OverrideError, Step, parse_override

# The corner scene's wall colour (batch.blender.scenes.WALL_COLOR_PATH); written out so parsing is tested without bpy.
WALL_COLOR_PATH = 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value'

# -- parsing, no Blender ----------------------------------------------------------------------------------------


def test_parse_simple_and_keyed_paths():
    override = parse_override("cycles.sample_clamp_indirect=0")
    assert override == Override(
        "cycles.sample_clamp_indirect=0", (Step("cycles"), Step("sample_clamp_indirect")), "0", ("0",)
    )
    override = parse_override(
        "materials[\"Walls\"].node_tree.nodes['Diffuse BSDF'].inputs[0].default_value = 0.2, 0.2,0.2,1"
    )
    assert override.steps == (
        Step("materials", ("Walls",)),
        Step("node_tree"),
        Step("nodes", ("Diffuse BSDF",)),
        Step("inputs", (0,)),
        Step("default_value"),
    )
    assert override.items == ("0.2", "0.2", "0.2", "1")
    assert override.path == 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs[0].default_value'


def test_parse_quotes_escapes_and_string_values():
    override = parse_override(r'objects["a \"b\". c=d]"].name="x, y"')
    assert override.steps[0] == Step("objects", ('a "b". c=d]',))
    assert override.items == ("x, y",) and override.value == '"x, y"'
    assert parse_override(WALL_COLOR_PATH + "=1,1,1,1").path == WALL_COLOR_PATH


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("cycles.samples", "malformed override at the end: expected '=' after the path"),
        ("cycles..samples=1", "malformed override at character 8: expected a property name"),
        ("_private=1", "malformed override at character 1: expected a property name"),
        ("=1", "malformed override at character 1: expected a property name"),
        ("cycles samples=1", "malformed override at character 8: expected '=' after the path"),
        ('objects["Light.energy=1', "malformed override at character 9: unterminated quote"),
        (
            "objects[Light].energy=1",
            "malformed override at character 9: expected a quoted name or an integer inside [ ]",
        ),
        ('objects["Light".energy=1', "malformed override at character 16: expected ']'"),
        ("__class__.x=1", "malformed override at character 1: expected a property name"),
    ],
)
def test_malformed_syntax(text, reason):
    with pytest.raises(OverrideError) as info:
        parse_override(text)
    assert str(info.value) == f"--set {text}: {reason} (syntax: PATH=VALUE, e.g. cycles.samples=16)"


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("cycles.samples=", "no value after '='"),
        ("world.color=1,,1", "empty item in the value"),
        ('objects["A"].name="x" y', "expected ',' between items of the value"),
    ],
)
def test_malformed_values(text, reason):
    with pytest.raises(OverrideError) as info:
        parse_override(text)
    assert str(info.value) == f"--set {text}: {reason}"


# -- applying, with bpy ---------------------------------------------------------------------------------------


@pytest.fixture
def corner():
    """A fresh corner scene in an empty file (bpy is one global state per process)."""
    bpy = pytest.importorskip("bpy")
    from batch.blender.scenes import build_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    return build_scene("corner")


def apply(scene, *texts):
    from batch.jobs.overrides import apply_overrides

    return apply_overrides(scene, texts)


def test_scene_paths_resolve(corner):
    from batch.blender import scenes

    assert scenes.WALL_COLOR_PATH == WALL_COLOR_PATH
    changes = apply(corner, f"{scenes.WALL_COLOR_PATH}=0.3,0.3,0.3,1", f"{scenes.LIGHT_ENERGY_PATH}=5")
    assert [c["path"] for c in changes] == [scenes.WALL_COLOR_PATH, scenes.LIGHT_ENERGY_PATH]


def test_apply_returns_old_and_new_values(corner):
    changes = apply(
        corner,
        "cycles.sample_clamp_indirect=0.5",
        "render.resolution_x=128",
        'objects["Light"].data.energy=100',
        "lights['Light'].shape=DISK",
        'view_layers["ViewLayer"].cycles.use_denoising=TRUE',
        "scene.cycles.caustics_refractive=false",
        f"{WALL_COLOR_PATH}=0.21,0.21,0.21,1",
        'world.node_tree.nodes["Background"].inputs["Strength"].default_value=2',
    )
    assert changes[0] == {
        "override": "cycles.sample_clamp_indirect=0.5",
        "path": "cycles.sample_clamp_indirect",
        "old": 0.0,
        "new": 0.5,
    }
    assert [(c["old"], c["new"]) for c in changes[1:6]] == [
        (64, 128),
        (60.0, 100.0),
        ("SQUARE", "DISK"),
        (False, True),
        (True, False),
    ]
    assert changes[6]["new"] == pytest.approx([0.21, 0.21, 0.21, 1.0])
    assert corner.render.resolution_x == 128 and corner.cycles.sample_clamp_indirect == 0.5
    assert corner.world.node_tree.nodes["Background"].inputs["Strength"].default_value == 2.0


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        # unknown property, with the closest name as a hint
        (
            "cycles.sample_clampp_indirect=0",
            "'CyclesRenderSettings' has no property 'sample_clampp_indirect' (did you mean 'sample_clamp_indirect'?)",
        ),
        ("render.nothing_like_this=1", "'RenderSettings' has no property 'nothing_like_this'"),
        ("cycles.rna_type=1", "'CyclesRenderSettings' has no property 'rna_type' (did you mean 'bake_type'?)"),
        # read-only
        ("render.is_movie_format=1", "'RenderSettings.is_movie_format' is read-only"),
        # bad values: range, enum, vector length, boolean word, non-finite
        ("cycles.samples=0", "0 is outside the range of 'CyclesRenderSettings.samples' [1, 16777216]"),
        ("cycles.blur_glossy=11", "11 is outside the range of 'CyclesRenderSettings.blur_glossy' [0, 10]"),
        ("cycles.device=TPU", "'TPU' is not a value of 'CyclesRenderSettings.device' (choose from 'CPU', 'GPU')"),
        (f"{WALL_COLOR_PATH}=0.2,0.2,0.2", "'NodeSocketColor.default_value' takes 4 comma-separated values, got 3"),
        ("cycles.samples=1,2", "'CyclesRenderSettings.samples' takes one value, got 2"),
        ("cycles.use_denoising=yes", "'CyclesRenderSettings.use_denoising' expects true/false/1/0, got 'yes'"),
        ("cycles.blur_glossy=nan", "'CyclesRenderSettings.blur_glossy' expects a finite number, got 'nan'"),
        # bad types: of the value, of the property
        ("render.resolution_x=abc", "'RenderSettings.resolution_x' expects an integer, got 'abc'"),
        ("cycles.samples=1.5", "'CyclesRenderSettings.samples' expects an integer, got '1.5'"),
        ("cycles.blur_glossy=high", "'CyclesRenderSettings.blur_glossy' expects a number, got 'high'"),
        (
            "camera=Camera",
            "'Scene.camera' is a pointer property; only booleans, numbers, enums and strings can be set",
        ),
        ('objects["Camera"].matrix_world=1', "'Object.matrix_world' is a 4×4 array; only vectors can be set"),
        # collection keys that do not resolve
        ('materials["Wall"].diffuse_color=1,1,1,1', 'no "Wall" in \'BlendData.materials\' (has: "Walls")'),
        ('objects["Light"].data.nodes["X"].name=y', "'AreaLight' has no property 'nodes' (did you mean 'use_nodes'?)"),
        ("view_layers[3].use=0", "index 3 is out of range for 'Scene.view_layers' (1 items)"),
        ('cycles["x"].samples=1', "'Scene.cycles' is not a collection, it cannot take [\"x\"]"),
        ('objects["Light"]=1', 'the path must end with a property name, not with a key (objects["Light"])'),
    ],
)
def test_errors_name_the_override_and_the_reason(corner, text, reason):
    with pytest.raises(OverrideError) as info:
        apply(corner, text)
    assert str(info.value) == f"--set {text}: {reason}"


def test_unset_pointer_in_the_path(corner):
    corner.world = None
    with pytest.raises(OverrideError) as info:
        apply(corner, 'world.node_tree.nodes["Background"].inputs[0].default_value=0,0,0,1')
    assert str(info.value).endswith(": 'Scene.world' is not set (None)")


def test_nothing_is_applied_when_one_override_fails(corner):
    with pytest.raises(OverrideError, match="no_such"):
        apply(corner, "cycles.sample_clamp_indirect=3", "cycles.no_such=1")
    assert corner.cycles.sample_clamp_indirect == 0.0


def test_no_python_is_reachable(corner):
    # Only RNA properties resolve: Python attributes and methods of the structs are not steps.
    for text in ("id_data.name=x", "bl_rna.name=x", "render.keys=1", "cycles.as_pointer=1"):
        with pytest.raises(OverrideError, match="has no property"):
            apply(corner, text)
