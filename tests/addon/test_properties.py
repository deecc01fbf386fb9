"""The add-on's settings against the options' one declaration (batch.jobs.options): each registered property's
default and hard limits, read back from its bl_rna, are the declared ones at ``addon``; where the declared limit
excludes itself (alpha's 0 and 1) the property's own limits lie inside it."""

import pytest

bpy = pytest.importorskip("bpy")

from batch.jobs.options import OPTIONS  # noqa: E402

pytestmark = pytest.mark.usefixtures("addon")  # registered for the module (tests/addon/conftest.py)

#: The panel's property of each option it sets, and the factor it shows the value with (a tolerance in percent).
PROPERTIES = {"spp": 1, "tile": 1, "max_passes": 1, "tolerance": 100.0, "alpha": 1, "device": 1, "seed_offset": 1}


def prop(name: str):
    return bpy.types.Scene.bl_rna.properties["welch_bias"].fixed_type.properties[name]


def test_every_option_the_panel_sets_is_declared_for_it():
    assert {dest for dest, option in OPTIONS.items() if "addon" in option.uses} == set(PROPERTIES)


@pytest.mark.parametrize(("dest", "scale"), PROPERTIES.items())
def test_a_property_has_the_declared_default_and_limits(dest, scale):
    option, found = OPTIONS[dest], prop(dest)
    if option.kind == "choice":
        assert found.default == option.default_for("addon")
        assert {item.identifier for item in found.enum_items} <= set(option.choices)
        return
    if option.use("addon").auto:  # 0 is auto, the default: the command resolves it
        assert (found.default, found.hard_min) == (0, 0) and option.default_for("addon") is None
    elif option.open_low:  # a property includes its limits: it takes one inside the declared one (or 0: off)
        assert found.default == pytest.approx(option.default_for("addon") * scale, rel=1e-6)
        assert found.hard_min == 0.0 if option.off else option.admits(found.hard_min / scale)
    else:
        assert found.default == pytest.approx(option.default_for("addon") * scale, rel=1e-6)
        assert found.hard_min == option.low * scale
    if option.open_high:
        assert found.hard_max <= option.high * scale and option.admits(found.hard_max / scale * (1 - 1e-6))
    else:
        assert found.hard_max == option.high * scale
    assert found.hard_min <= found.soft_min <= found.default <= found.soft_max <= found.hard_max


def test_the_panels_tolerance_is_checked_as_the_command_lines(scene_settings):
    from batch.errors import BatchError
    from blender_addon import session

    scene_settings.tolerance = 0.0
    assert session.tolerance_of(scene_settings) is None
    scene_settings.tolerance = 2.5
    assert session.tolerance_of(scene_settings) == 0.025
    scene_settings.tolerance = OPTIONS["tolerance"].high * 100.0
    with pytest.raises(BatchError, match="Tolerance must be a percentage such as 0.5%, got '1000%'"):
        session.tolerance_of(scene_settings)


@pytest.fixture
def scene_settings():
    scene = bpy.data.scenes.new("Welch Options Scene")
    yield scene.welch_bias
    bpy.data.scenes.remove(scene)
