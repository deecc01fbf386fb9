"""Built-in test scenes, built in code with bpy (no asset files).

``corner`` is the paper's corner scene (Jung et al. 2020, Fig. 11 left): the lower-left corner of an empty grey
box lit by a constant square light. ``corner_glass`` adds a glass sphere (the caustic failure case, §5.1).
``glossy`` gives Filter Glossy and the caustics toggles something to act on.

Every builder leaves Cycles' biased-by-default settings at their unbiased values, so the built-in scenes are
unbiased as built; the batch tool's render settings (device, spp, output format) are applied separately. The
builders run in Blender 3.4 to 5.2 LTS (node trees are created where an older Blender starts without one).
"""

from __future__ import annotations

from collections.abc import Callable

import bpy
import numpy as np
from mathutils import Vector

from ..errors import BatchError
from ..jobs.job import DEFAULT_SAMPLING_PATTERNS

# Override paths for the corner scene's knobs (the syntax of ``batch.overrides``).
WALL_COLOR_PATH = 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value'
LIGHT_ENERGY_PATH = 'lights["Light"].energy'

#: Part of a built-in scene's identity in a run record: raise it whenever the builders change what they build
#: (one scene's change: its revision in `batch.jobs.job.SCENE_REVISIONS`, so the others keep their identity).
BUILDER_VERSION = 1

WALL_GREY = 0.2  # the paper's corner scene: diffuse grey 0.2 walls
BOX = 2.0  # edge length of the box, metres
LIGHT_SIZE = 0.5
CYCLES_MAX_BOUNCES = 1024  # the properties' hard maximum
LIGHT_ENERGY = 60.0  # watts; the mean pixel of ``corner`` comes out near 0.17
MESH_LIGHT_STRENGTH = 15.0  # the emitter of ``corner_mesh_light``; the mean pixel comes out near 0.11


def default_sampling_pattern(cycles) -> str:
    """Set and return the first of `DEFAULT_SAMPLING_PATTERNS` this Blender has (`cycles`: a scene's Cycles
    settings); 5.0 fills its pattern items at run time, so a pattern is tried by setting it."""
    for pattern in DEFAULT_SAMPLING_PATTERNS:
        try:
            cycles.sampling_pattern = pattern
        except TypeError:
            continue
        return pattern
    return cycles.sampling_pattern


def new_scene(name: str) -> bpy.types.Scene:
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
    # scenes.new() gives 'AUTOMATIC' (blue noise) in 5.0, the startup file Tabulated Sobol: set, not inherited.
    default_sampling_pattern(cycles)
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
    return _one_shader(name, "ShaderNodeBsdfDiffuse", "Diffuse BSDF", "Color", (grey, grey, grey, 1.0), "BSDF")


def _emission(name: str, strength: float) -> bpy.types.Material:
    """A white emitter; its strength is the input 'Strength' of the node 'Emission'."""
    return _one_shader(name, "ShaderNodeEmission", "Emission", "Strength", strength, "Emission")


def _one_shader(name: str, kind: str, node: str, socket: str, value, output: str) -> bpy.types.Material:
    """A material of one shader node (its `kind`, named `node`, its input `socket` set to `value`) whose `output`
    is the material's surface: the node's name and input are the override paths the suite and the tests set."""
    material = bpy.data.materials.new(name)
    nodes = node_tree(material).nodes
    nodes.clear()
    shader = nodes.new(kind)
    shader.name = node
    shader.inputs[socket].default_value = value
    out = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(shader.outputs[output], out.inputs["Surface"])
    return material


def link_object(scene: bpy.types.Scene, name: str, data, material=None) -> bpy.types.Object:
    obj = bpy.data.objects.new(name, data)
    if material is not None:
        data.materials.append(material)
    scene.collection.objects.link(obj)
    return obj


def _quad(scene, name: str, corners, material) -> bpy.types.Object:
    """A single-face mesh object through four corners (counter-clockwise seen from the lit side)."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(corners, [], [(0, 1, 2, 3)])
    return link_object(scene, name, mesh, material)


def _sphere(scene, name: str, center, radius: float, material) -> bpy.types.Object:
    import bmesh  # importable only once bpy is

    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=radius)
    bm.to_mesh(mesh)
    bm.free()
    mesh.polygons.foreach_set("use_smooth", [True] * len(mesh.polygons))  # shade_smooth() is 3.6+
    obj = link_object(scene, name, mesh, material)
    obj.location = center
    return obj


def _corner(name: str, floor: bpy.types.Material | None = None, mesh_light: bool = False) -> bpy.types.Scene:
    """Floor (z=0), left wall (x=0) and back wall (y=BOX) of a grey box, a square light and a camera.

    The light is an area light, or with `mesh_light` an emissive quad of the same size and place.
    """
    scene = new_scene(name)
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
        link_object(scene, "Light", light).location = center  # an area light faces -Z

    camera = bpy.data.cameras.new("Camera")
    camera.lens = 28.0
    cam = link_object(scene, "Camera", camera)
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


# -- one feature each: the built-in regression suite's scenes (batch/decide/suites/builtin.toml) ---------------------
# The corner box with one object or setting that exercises one part of Cycles, nothing else: a change in that part
# shows in a few tiles of a small image, where the rest of the box is a control.

OBJECT_CENTER = (0.45 * BOX, 0.55 * BOX, 0.25 * BOX)
OBJECT_RADIUS = 0.25 * BOX


def _principled(name: str, inputs: dict) -> bpy.types.Material:
    """A Principled BSDF material; `inputs` maps an input's name, or a tuple of the names it had in different
    Blenders, to its value."""
    material = bpy.data.materials.new(name)
    bsdf = node_tree(material).nodes["Principled BSDF"]
    for names, value in inputs.items():
        names = (names,) if isinstance(names, str) else names
        next(bsdf.inputs[n] for n in names if n in bsdf.inputs).default_value = value
    return material


def _object_scene(name: str, material: bpy.types.Material) -> bpy.types.Scene:
    scene = _corner(name)
    _sphere(scene, "Object", OBJECT_CENTER, OBJECT_RADIUS, material)
    return scene


def _glossy_rough_scene() -> bpy.types.Scene:
    return _object_scene("glossy_rough", _principled("Object", {"Metallic": 1.0, "Roughness": 0.3}))


def _glossy_sharp_scene() -> bpy.types.Scene:
    return _object_scene("glossy_sharp", _principled("Object", {"Metallic": 1.0, "Roughness": 0.02}))


def _sss_scene() -> bpy.types.Scene:
    weight = ("Subsurface Weight", "Subsurface")  # 'Subsurface' before 4.0
    return _object_scene("sss", _principled("Object", {weight: 1.0, "Roughness": 0.5}))


def _textured_scene() -> bpy.types.Scene:
    """A Principled sphere with a checker base colour and a tangent-space normal map from a wave texture."""
    material = _principled("Object", {"Roughness": 0.4})
    tree = material.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    tree.links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    waves = tree.nodes.new("ShaderNodeTexWave")
    waves.inputs["Scale"].default_value = 3.0
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    normal_map.name = "Normal Map"
    normal_map.inputs["Strength"].default_value = 0.5
    tree.links.new(waves.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    scene = _object_scene("textured", material)
    sphere = scene.objects["Object"]
    sphere.data.uv_layers.new(name="UVMap")  # a normal map needs tangents, tangents need UVs
    return scene


def _volume_material(name: str, density: float, noise: bool) -> bpy.types.Material:
    """Volume Scatter of `density`, or with `noise` its density times a noise texture (heterogeneous)."""
    material = bpy.data.materials.new(name)
    tree = node_tree(material)
    tree.nodes.clear()
    scatter = tree.nodes.new("ShaderNodeVolumeScatter")
    scatter.name = "Volume Scatter"
    scatter.inputs["Density"].default_value = density
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(scatter.outputs["Volume"], out.inputs["Volume"])
    if noise:
        noise_density(tree, scatter.inputs["Density"], density, 3.0)
    return material


def noise_density(tree, density_input, factor: float, scale: float) -> None:
    """Drive a volume's density input with a noise texture (of `scale`) times `factor`, through a Math node named
    "Density" (whose second input the overrides change)."""
    texture = tree.nodes.new("ShaderNodeTexNoise")
    texture.inputs["Scale"].default_value = scale
    multiply = tree.nodes.new("ShaderNodeMath")
    multiply.name = "Density"
    multiply.operation = "MULTIPLY"
    multiply.inputs[1].default_value = factor
    tree.links.new(texture.outputs["Fac"], multiply.inputs[0])
    tree.links.new(multiply.outputs["Value"], density_input)


def add_box(scene, name: str, center, half: float, material) -> bpy.types.Object:
    mesh = bpy.data.meshes.new(name)
    corners = [(x, y, z) for x in (-half, half) for y in (-half, half) for z in (-half, half)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh.from_pydata(corners, [], faces)
    obj = link_object(scene, name, mesh, material)
    obj.location = center
    return obj


def _volume_scene(name: str, noise: bool) -> bpy.types.Scene:
    scene = _corner(name)
    add_box(scene, "Fog", OBJECT_CENTER, OBJECT_RADIUS, _volume_material("Fog", 2.0, noise))
    scene.cycles.volume_bounces = CYCLES_MAX_BOUNCES
    return scene


def _many_lights_scene() -> bpy.types.Scene:
    """The corner lit by a 4x4 grid of small point lights instead of one area light (the light tree picks one),
    every one inside the box, in front of the back wall (y = BOX)."""
    scene = _corner("many_lights")
    bpy.data.objects.remove(scene.objects["Light"])
    for i in range(16):
        light = bpy.data.lights.new(f"Small{i:02d}", "POINT")
        light.energy = LIGHT_ENERGY / 16 * (1 + i % 3)  # unequal powers: the tree's importance has work to do
        light.shadow_soft_size = 0.02
        position = (0.2 + 0.2 * (i % 4), 0.25 + 0.2 * (i // 4), 0.85)
        link_object(scene, f"Small{i:02d}", light).location = tuple(p * BOX for p in position)
    return scene


def _environment_scene() -> bpy.types.Scene:
    """The corner without its light, lit by an environment image (dim sky, a bright small sun): the world's
    importance map and multiple importance sampling at work."""
    scene = _corner("environment")
    bpy.data.objects.remove(scene.objects["Light"])
    width, height = 64, 32
    image = bpy.data.images.new("Sky", width, height, float_buffer=True)
    y, x = np.mgrid[0:height, 0:width]
    sky = np.stack([0.2 + 0.3 * y / height, 0.3 + 0.3 * y / height, 0.6 + 0.2 * y / height, np.ones_like(y)], -1)
    sun = ((x - 40) ** 2 + (y - 24) ** 2) <= 2
    sky[sun, :3] = 200.0
    image.pixels.foreach_set(sky.astype(np.float32).ravel())
    image.pack()  # a generated image with pixels set is kept in the file, so a saved .blend renders it too
    tree = node_tree(scene.world)
    texture = tree.nodes.new("ShaderNodeTexEnvironment")
    texture.image = image
    tree.links.new(texture.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    return scene


def _depth_of_field_scene() -> bpy.types.Scene:
    scene = _object_scene("depth_of_field", _diffuse("Object", 0.6))
    camera = scene.camera.data
    camera.dof.use_dof = True  # focused at 0.5 m, the sphere at 2.6 m: a circle of confusion of 5 % of the frame
    camera.dof.focus_distance = 0.5
    camera.dof.aperture_fstop = 0.5
    return scene


def _motion_blur_scene() -> bpy.types.Scene:
    """A bright sphere moving across the frame during the shutter (frame 2 of a move from frame 1 to 3)."""
    scene = _object_scene("motion_blur", _diffuse("Object", 0.8))
    sphere = scene.objects["Object"]
    x, y, z = OBJECT_CENTER
    for frame, dx in ((1, -0.3), (3, 0.3)):
        sphere.location = (x + dx * BOX, y, z)
        sphere.keyframe_insert("location", frame=frame)
    scene.frame_set(2)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = 0.5
    return scene


def _hair_scene() -> bpy.types.Scene:
    """Particle hair (curves in Cycles) growing from a patch of the floor."""
    scene = _corner("hair")
    mesh = bpy.data.meshes.new("Patch")
    h = 0.25 * BOX
    cx, cy = OBJECT_CENTER[:2]
    mesh.from_pydata([(cx - h, cy - h, 0.001), (cx + h, cy - h, 0.001), (cx + h, cy + h, 0.001),
                      (cx - h, cy + h, 0.001)], [], [(0, 1, 2, 3)])  # fmt: skip
    patch = link_object(scene, "Patch", mesh, _diffuse("Patch", 0.2))
    hair = bpy.data.materials.new("Hair")
    tree = node_tree(hair)
    tree.nodes.clear()
    bsdf = tree.nodes.new("ShaderNodeBsdfHairPrincipled")
    bsdf.name = "Hair BSDF"
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    mesh.materials.append(hair)
    modifier = patch.modifiers.new("Hair", "PARTICLE_SYSTEM")
    settings = modifier.particle_system.settings
    settings.type = "HAIR"
    settings.count = 400
    settings.hair_length = 0.3 * BOX
    settings.material = 2  # the second slot: Hair
    settings.display_step = settings.render_step = 2
    return scene


SCENES: dict[str, Callable[[], bpy.types.Scene]] = {
    "corner": _corner_scene,
    "corner_glass": _corner_glass_scene,
    "corner_mesh_light": _corner_mesh_light_scene,
    "glossy": _glossy_scene,
    "glossy_rough": _glossy_rough_scene,
    "glossy_sharp": _glossy_sharp_scene,
    "many_lights": _many_lights_scene,
    "environment": _environment_scene,
    "volume": lambda: _volume_scene("volume", noise=False),
    "volume_noise": lambda: _volume_scene("volume_noise", noise=True),
    "sss": _sss_scene,
    "depth_of_field": _depth_of_field_scene,
    "motion_blur": _motion_blur_scene,
    "hair": _hair_scene,
    "textured": _textured_scene,
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
