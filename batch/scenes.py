"""Built-in test scenes, built in code with bpy (no asset files).

``corner`` is the paper's corner scene (Jung et al. 2020, Fig. 11 left): the lower-left corner of an empty grey
box lit by a constant square light. ``corner_glass`` adds a glass sphere (the caustic failure case, §5.1).
``glossy`` gives Filter Glossy and the caustics toggles something to act on.

Every builder leaves Cycles' biased-by-default settings at their unbiased values, so the built-in scenes are
unbiased as built; the batch tool's render settings (device, spp, output format) are applied separately. The
builders run in Blender 3.4 to 5.0 (node trees are created where an older Blender starts without one).
"""

from __future__ import annotations

from collections.abc import Callable

import bpy
from mathutils import Vector

from .errors import BatchError

# Override paths for the corner scene's knobs (the syntax of ``batch.overrides``).
WALL_COLOR_PATH = 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value'
LIGHT_ENERGY_PATH = 'lights["Light"].energy'

#: Part of a built-in scene's identity in a run record: raise it whenever a builder changes what it builds.
BUILDER_VERSION = 1

WALL_GREY = 0.2  # the paper's corner scene: diffuse grey 0.2 walls
BOX = 2.0  # edge length of the box, metres
LIGHT_SIZE = 0.5
CYCLES_MAX_BOUNCES = 1024  # the properties' hard maximum
LIGHT_ENERGY = 60.0  # watts; the mean pixel of ``corner`` comes out near 0.17
MESH_LIGHT_STRENGTH = 15.0  # the emitter of ``corner_mesh_light``; the mean pixel comes out near 0.11


def _new_scene(name: str) -> bpy.types.Scene:
    """A new scene in the current file, made active, with unbiased Cycles settings."""
    scene = bpy.data.scenes.new(name)
    bpy.context.window.scene = scene
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = scene.render.resolution_y = 64
    scene.render.resolution_percentage = 100
    cycles = scene.cycles
    # Cycles' defaults clamp indirect light at 10 and blur glossy at 1.0: both biased by design.
    cycles.sample_clamp_direct = 0.0
    cycles.sample_clamp_indirect = 0.0
    cycles.blur_glossy = 0.0
    cycles.caustics_reflective = cycles.caustics_refractive = True
    # The default bounce limits (12 in all, 4 diffuse, 4 glossy) truncate paths: a bias of 0.7 % with bright walls
    # (measured). At the hard maximum, Russian roulette ends paths long before a limit does.
    for bounces in (
        "max_bounces",
        "diffuse_bounces",
        "glossy_bounces",
        "transmission_bounces",
        "transparent_max_bounces",
    ):
        setattr(cycles, bounces, CYCLES_MAX_BOUNCES)
    cycles.use_denoising = False
    cycles.use_adaptive_sampling = False
    # The sampling pattern is the render job's to set (scenes.new() gives 'AUTOMATIC', blue noise, in 5.0).
    cycles.samples = 1
    for layer in scene.view_layers:
        layer.cycles.use_denoising = False
    # Black background: nothing but the light illuminates the box.
    world = bpy.data.worlds.new("World")
    world.color = (0.0, 0.0, 0.0)
    node_tree(world).nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    scene.world = world
    return scene


def node_tree(block) -> bpy.types.NodeTree:
    """The node tree of a material or world: Blender 5.0 always has one, 3.4 only once `use_nodes` is set."""
    if block.node_tree is None:
        block.use_nodes = True
    return block.node_tree


def _diffuse(name: str, grey: float) -> bpy.types.Material:
    """A Lambertian material; its colour is the input 'Color' of the node 'Diffuse BSDF'."""
    material = bpy.data.materials.new(name)
    nodes = node_tree(material).nodes
    nodes.clear()
    bsdf = nodes.new("ShaderNodeBsdfDiffuse")
    bsdf.name = "Diffuse BSDF"
    bsdf.inputs["Color"].default_value = (grey, grey, grey, 1.0)
    out = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    return material


def _emission(name: str, strength: float) -> bpy.types.Material:
    """A white emitter; its strength is the input 'Strength' of the node 'Emission'."""
    material = bpy.data.materials.new(name)
    nodes = node_tree(material).nodes
    nodes.clear()
    emission = nodes.new("ShaderNodeEmission")
    emission.name = "Emission"
    emission.inputs["Strength"].default_value = strength
    out = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(emission.outputs["Emission"], out.inputs["Surface"])
    return material


def _link(scene: bpy.types.Scene, name: str, data, material=None) -> bpy.types.Object:
    obj = bpy.data.objects.new(name, data)
    if material is not None:
        data.materials.append(material)
    scene.collection.objects.link(obj)
    return obj


def _quad(scene, name: str, corners, material) -> bpy.types.Object:
    """A single-face mesh object through four corners (counter-clockwise seen from the lit side)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(corners, [], [(0, 1, 2, 3)])
    return _link(scene, name, mesh, material)


def _sphere(scene, name: str, center, radius: float, material) -> bpy.types.Object:
    import bmesh  # importable only once bpy is

    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=radius)
    bm.to_mesh(mesh)
    bm.free()
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))  # shade_smooth() is 3.6+
    obj = _link(scene, name, mesh, material)
    obj.location = center
    return obj


def _corner(name: str, floor: bpy.types.Material | None = None, mesh_light: bool = False) -> bpy.types.Scene:
    """Floor (z=0), left wall (x=0) and back wall (y=BOX) of a grey box, a square light and a camera.

    The light is an area light, or with `mesh_light` an emissive quad of the same size and place.
    """
    scene = _new_scene(name)
    walls = _diffuse("Walls", WALL_GREY)
    b = BOX
    _quad(scene, "Floor", [(0, 0, 0), (b, 0, 0), (b, b, 0), (0, b, 0)], floor or walls)
    _quad(scene, "LeftWall", [(0, 0, 0), (0, b, 0), (0, b, b), (0, 0, b)], walls)
    _quad(scene, "BackWall", [(0, b, 0), (b, b, 0), (b, b, b), (0, b, b)], walls)

    center = (0.8 * b / 2, 1.2 * b / 2, 0.9 * b)  # under the (absent) ceiling, shining down into the corner
    if mesh_light:
        h = LIGHT_SIZE / 2
        corners = [(center[0] + dx, center[1] + dy, center[2]) for dx, dy in ((-h, -h), (-h, h), (h, h), (h, -h))]
        _quad(scene, "Light", corners, _emission("LightEmission", MESH_LIGHT_STRENGTH))  # faces -Z
    else:
        light = bpy.data.lights.new("Light", "AREA")
        light.shape = "SQUARE"
        light.size = LIGHT_SIZE
        light.energy = LIGHT_ENERGY
        light.color = (1.0, 1.0, 1.0)
        _link(scene, "Light", light).location = center  # an area light faces -Z

    camera = bpy.data.cameras.new("Camera")
    camera.lens = 28.0
    cam = _link(scene, "Camera", camera)
    cam.location = (1.3 * b, -0.3 * b, 0.7 * b)
    # Aim at a point just in front of the corner so the three planes fill the frame.
    target = (0.35 * b, 0.75 * b, 0.3 * b)
    direction = [t - c for t, c in zip(target, cam.location, strict=True)]
    cam.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    return scene


def _corner_scene() -> bpy.types.Scene:
    return _corner("corner")


def _corner_mesh_light_scene() -> bpy.types.Scene:
    return _corner("corner_mesh_light", mesh_light=True)


def _corner_glass_scene() -> bpy.types.Scene:
    scene = _corner("corner_glass")
    glass = bpy.data.materials.new("Glass")
    nodes = node_tree(glass).nodes
    nodes.clear()
    bsdf = nodes.new("ShaderNodeBsdfGlass")
    bsdf.inputs["Roughness"].default_value = 0.0
    bsdf.inputs["IOR"].default_value = 1.5
    out = nodes.new("ShaderNodeOutputMaterial")
    glass.node_tree.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    _sphere(scene, "GlassSphere", (0.45 * BOX, 0.55 * BOX, 0.2 * BOX), 0.2 * BOX, glass)
    return scene


def _checker_floor() -> bpy.types.Material:
    """A glossy Principled floor whose base colour is a procedural checker."""
    material = bpy.data.materials.new("CheckerFloor")
    tree = node_tree(material)
    bsdf = tree.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = 0.15
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 6.0
    checker.inputs["Color1"].default_value = (0.6, 0.6, 0.6, 1.0)
    checker.inputs["Color2"].default_value = (0.1, 0.1, 0.1, 1.0)
    tree.links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    return material


def _glossy_scene() -> bpy.types.Scene:
    scene = _corner("glossy", floor=_checker_floor())
    metal = bpy.data.materials.new("Metal")
    bsdf = node_tree(metal).nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.9, 0.6, 0.3, 1.0)
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.05
    _sphere(scene, "GlossySphere", (0.45 * BOX, 0.55 * BOX, 0.2 * BOX), 0.2 * BOX, metal)
    return scene


SCENES: dict[str, Callable[[], bpy.types.Scene]] = {
    "corner": _corner_scene,
    "corner_glass": _corner_glass_scene,
    "corner_mesh_light": _corner_mesh_light_scene,
    "glossy": _glossy_scene,
}


def build_scene(name: str) -> bpy.types.Scene:
    """Build a built-in scene into the current file and make it the active scene.

    Parameters
    ----------
    name : str
        A key of `SCENES`.

    Returns
    -------
    bpy.types.Scene
        The new scene, with a camera, 64×64 pixels and unbiased Cycles settings.
    """
    try:
        builder = SCENES[name]
    except KeyError:
        raise BatchError(f"unknown built-in scene {name!r}; choose from {', '.join(SCENES)}") from None
    return builder()
