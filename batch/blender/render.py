"""Everything that touches bpy to render passes: open a scene, make it render unbiased passes, render one seed.

A pass is one Cycles render with its own seed, saved as an uncompressed 32-bit EXR into a per-process temporary
file (in ``/dev/shm`` where it exists) and read back with numpy (`welch_core.exr`): the Render Result's pixels
are empty in background mode (see ``BLENDER_FACTS.md``). Needs numpy and nothing else a stock Blender lacks;
settings are feature-detected so Blender 3.4 to 5.2 LTS work.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time
from pathlib import Path

import bpy
import numpy as np

from .._siblings import welch_core as wc
from ..errors import BatchError
from ..jobs.job import NO_GPU_MESSAGE, builtin_scene_id
from ..jobs.lobes import COMPONENTS, LIGHTGROUP_PREFIX, PASS_PROPERTIES, layers_from_channels
from ..jobs.lock import process_alive
from ..jobs.options import GPU_BACKENDS
from ..jobs.rna import jsonable, render_size
from .scenes import BUILDER_VERSION, SCENES, build_scene


class RenderSetupError(BatchError):
    """A scene that cannot be rendered (missing or corrupt file, no camera, unknown name, a refused setting)."""


# ---------------------------------------------------------------------------------------------------------------
# Opening and configuring a scene


def open_scene(
    blend_path: str | None, scene_name: str | None = None, blend_scene: str | None = None
) -> bpy.types.Scene:
    """Load a .blend file, build a built-in scene into an empty file, or take the file Blender has open.

    Parameters
    ----------
    blend_path : str or None
        A .blend file to open.
    scene_name : str or None
        A key of `batch.scenes.SCENES`, built into an empty file; only without `blend_path`.
    blend_scene : str or None
        Which scene of the file to use; None takes its active scene.

    Returns
    -------
    bpy.types.Scene
        The scene, active in the window. Its render engine is not changed here (`configure_unbiased` switches
        to Cycles and reports the switch).

    Raises
    ------
    RenderSetupError
        Missing or unreadable file, unknown scene name, scene without camera, nothing to render.
    """
    if blend_path is not None and scene_name is not None:
        raise RenderSetupError(f"give a .blend file or a built-in scene, not both ({blend_path}, {scene_name!r})")
    if scene_name is not None:
        if blend_scene is not None:
            raise RenderSetupError(f"a built-in scene has no scene {blend_scene!r} to choose")
        scene = _build_builtin(scene_name)
    else:
        if blend_path is not None:
            _load_blend(blend_path)
        elif not bpy.data.filepath:  # the bpy module starts without a file; Blender run with a .blend has one
            raise RenderSetupError(f"no scene to render: give a .blend file or a built-in scene ({', '.join(SCENES)})")
        scene = _choose_scene(blend_scene)
    if scene.camera is None:
        raise RenderSetupError(f"scene {scene.name!r} has no camera")
    return scene


def _build_builtin(name: str) -> bpy.types.Scene:
    if name not in SCENES:
        raise RenderSetupError(f"unknown built-in scene {name!r}; choose from {', '.join(SCENES)}")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return build_scene(name)


def _load_blend(path: str) -> None:
    if not os.path.isfile(path):
        raise RenderSetupError(f"{path}: no such file")
    try:
        bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
    except RuntimeError as error:
        lines = str(error).strip().splitlines()
        reason = lines[-1].strip().removeprefix("Error: ") if lines else "unreadable"
        raise RenderSetupError(f"{path}: cannot open as a .blend file ({reason})") from None


def _choose_scene(name: str | None) -> bpy.types.Scene:
    if name is None:
        return bpy.context.scene
    scene = bpy.data.scenes.get(name)
    if scene is None:
        names = ", ".join(repr(s.name) for s in bpy.data.scenes)
        raise RenderSetupError(f"{bpy.data.filepath}: no scene {name!r}; the file has {names}")
    bpy.context.window.scene = scene
    return scene


def configure_unbiased(
    scene: bpy.types.Scene,
    device: str = "CPU",
    spp: int = 1,
    resolution: tuple[int, int] | None = None,
    sampling_pattern: str | None = None,
    lobes: tuple[str, ...] = (),
) -> list[dict]:
    """Set what a pass needs: Cycles, samples, device, no denoising or adaptive sampling, float EXR output.

    The scene's own biased settings (clamping, Filter Glossy, bounces, ...) are left alone: they are what a
    user tests; ``batch.lint`` reports them. Every value is read back: a value Blender would change (clamp,
    refuse) raises RenderSetupError instead of rendering something other than what is recorded.

    Parameters
    ----------
    scene : bpy.types.Scene
    device : str
        'CPU', 'GPU' (the first backend that has a device) or a backend from `batch.job.GPU_BACKENDS`.
    spp : int
        Samples per pixel per pass.
    resolution : (int, int) or None
        Width and height in pixels; None keeps the scene's.
    sampling_pattern : str or None
        The pattern to render with, checked to be one this Blender has; None keeps the scene's own (a built-in
        scene has the first of `batch.job.DEFAULT_SAMPLING_PATTERNS` this Blender has).

    Returns
    -------
    list of dict
        Every value that changed, as ``{"path", "old", "new"}`` with override-style paths, for the run record
        (e.g. a switch of ``render.engine`` to Cycles).
    """
    if spp < 1:
        raise ValueError(f"`spp` must be a positive integer, got {spp}")
    changes: list[dict] = []
    _set(changes, scene.render, "render", "engine", "CYCLES")
    _set_device(changes, scene, device)
    pattern = None if sampling_pattern is None else _sampling_pattern(scene, sampling_pattern)
    for struct, path, value in fixed_settings(scene, spp, resolution, pattern):
        _set(changes, struct, path.rpartition(".")[0], path.rpartition(".")[2], value)
    if lobes:
        _enable_lobes(changes, scene, lobes)
    return changes


def _enable_lobes(changes: list[dict], scene: bpy.types.Scene, lobes: tuple[str, ...]) -> None:
    """The light passes of `lobes` on the active view layer, saved as one single-part multilayer EXR a pass."""
    layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    prefix = f"view_layers[{json.dumps(layer.name)}]"
    for lobe in lobes:
        for name in PASS_PROPERTIES.get(lobe, ()):
            if name.startswith("cycles."):  # Cycles' own passes (volume) live on the layer's Cycles settings
                _set(changes, layer.cycles, f"{prefix}.cycles", name.removeprefix("cycles."), True)
            else:
                _set(changes, layer, prefix, name, True)
    settings = scene.render.image_settings
    if "media_type" in settings.bl_rna.properties:  # 5.0: the media type first, or the format is refused
        _set(changes, settings, "render.image_settings", "media_type", "MULTI_LAYER_IMAGE")
    _set(changes, settings, "render.image_settings", "file_format", "OPEN_EXR_MULTILAYER")
    if "use_exr_interleave" in settings.bl_rna.properties:  # 5.0 writes multi-part files otherwise
        _set(changes, settings, "render.image_settings", "use_exr_interleave", True)
    _set(changes, settings, "render.image_settings", "exr_codec", "NONE")
    _set(changes, settings, "render.image_settings", "color_depth", "32")


def fixed_settings(scene, spp: int, resolution, pattern: str | None) -> list[tuple[object, str, object]]:
    """(struct, override path, value) of every setting a pass fixes, whatever the scene had: the job's (samples,
    the resolution and the pattern where given) and those an unbiased pass needs. Settings this Blender does not
    have are left out (they differ between 3.4 and 5.0)."""
    render, cycles = scene.render, scene.cycles
    wanted = [
        (cycles, "cycles.samples", spp),
        (cycles, "cycles.use_layer_samples", "IGNORE"),  # a view layer's samples would replace spp
        (cycles, "cycles.use_denoising", False),
        *(
            (layer.cycles, f"view_layers[{json.dumps(layer.name)}].cycles.use_denoising", False)
            for layer in scene.view_layers
        ),
        (cycles, "cycles.use_adaptive_sampling", False),
        (cycles, "cycles.time_limit", 0.0),
        *(((cycles, "cycles.sampling_pattern", pattern),) if pattern is not None else ()),
        # A compositor node tree changes the saved image; the sequencer could replace it.
        (render, "render.use_compositing", False),
        (render, "render.use_sequencer", False),
        (render, "render.use_persistent_data", True),
        (render, "render.use_single_layer", True),  # only the active view layer is saved
        *(
            ((render, "render.resolution_x", int(resolution[0])), (render, "render.resolution_y", int(resolution[1])))
            if resolution is not None
            else ()
        ),
        (render, "render.resolution_percentage", 100),
        (render, "render.use_border", False),
        (render.image_settings, "render.image_settings.file_format", "OPEN_EXR"),
        (render.image_settings, "render.image_settings.color_depth", "32"),
        (render.image_settings, "render.image_settings.exr_codec", "NONE"),
        (render.image_settings, "render.image_settings.color_mode", "RGB"),  # alpha is not tested: less to write
    ]
    return [
        (struct, path, value) for struct, path, value in wanted if path.rpartition(".")[2] in struct.bl_rna.properties
    ]


#: Settings the passes fix for speed only, which an override may turn back: persistent data (a pass with it equals
#: a fresh render of the same seed without it, tests/batch/test_render.py), so that an audit can compare the two.
MAY_OVERRIDE = ("render.use_persistent_data",)

#: The option a user should change instead of overriding a setting the job fixes.
_OPTION_FOR = {
    "cycles.samples": "--spp",
    "render.resolution_x": "--resolution",
    "render.resolution_y": "--resolution",
    "cycles.sampling_pattern": "--sampling-pattern (or --test-sampling-pattern)",
    "cycles.device": "--device",
}


def check_fixed_settings(scene, spp: int, resolution, overrides: list[dict], pattern: str | None = None) -> None:
    """Raise RenderSetupError if the overrides (as `apply_overrides` returns them) changed a setting the job
    fixes (`pattern`: the sampling pattern the job gave, None where it keeps the scene's): what is rendered must
    be what is recorded."""
    expected = {path: value for _struct, path, value in fixed_settings(scene, spp, resolution, pattern)
                if path not in MAY_OVERRIDE}  # fmt: skip
    expected["cycles.device"] = scene.cycles.device
    for change in overrides:
        path = change["path"].removeprefix("scene.")
        if path in expected and change["new"] != change["old"]:
            hint = _OPTION_FOR.get(path)
            advice = f"use {hint} instead" if hint else "every pass needs it as the batch tool sets it"
            raise RenderSetupError(
                f"--set {change['override']} changes {path} ({change['old']!r} -> {change['new']!r}), which the "
                f"job fixes: {advice}"
            )


def check_sample_subset(scene, spp: int) -> None:
    """Raise RenderSetupError where the scene renders a subset of samples that starts at or past a pass's `spp`
    (``cycles.use_sample_subset`` with ``cycles.sample_offset`` >= spp, from the .blend or an override): Cycles then
    renders no sample and every pass is black (measured, 5.0.1: offsets 2 and 4 at 2 spp), which a comparison can
    only call inconclusive. A subset within the samples renders (lint says what it does to independence)."""
    cycles = scene.cycles
    offset = getattr(cycles, "sample_offset", 0)
    if getattr(cycles, "use_sample_subset", False) and offset >= spp:
        raise RenderSetupError(
            f"cycles.use_sample_subset is on with cycles.sample_offset {offset}, at or past the {spp} samples of a "
            "pass: every pass would render black (turn it off: --set cycles.use_sample_subset=False)"
        )


def layer_names(scene: bpy.types.Scene, lobes: tuple[str, ...]) -> list[str]:
    """The layers a pass of `scene` rendered with `lobes` has (`batch.lobes.layers_from_channels` order)."""
    names = [lobe for lobe in lobes if lobe in COMPONENTS]
    if "lightgroups" in lobes:
        layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
        names += [LIGHTGROUP_PREFIX + name for name in sorted(group.name for group in layer.lightgroups)]
    return names


def add_named_lightgroups(scene: bpy.types.Scene) -> list[dict]:
    """Light groups that objects or the world name but the view layer lacks are added to it (Blender ignores a
    name the layer does not list), so ``--set objects["Lamp"].lightgroup=key`` is enough to make one. Called
    after the overrides."""
    changes: list[dict] = []
    layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    named = {obj.lightgroup for obj in scene.objects if getattr(obj, "lightgroup", "")}
    if scene.world is not None and getattr(scene.world, "lightgroup", ""):
        named.add(scene.world.lightgroup)
    existing = {group.name for group in layer.lightgroups}
    for name in sorted(named - existing):
        group = layer.lightgroups.add(name=name)
        if group.name != name:  # Blender renames what a pass name can't hold: the lights' group would be empty
            layer.lightgroups.remove(group)
            raise RenderSetupError(
                f"light group {name!r}: Blender takes it as {group.name!r} (a light group's name is a pass name: "
                "letters, digits and '_', at most 63 characters), so its lights would render into no layer; "
                "rename the group"
            )
        changes.append({"path": f"view_layers[{json.dumps(layer.name)}].lightgroups", "old": None, "new": name})
    return changes


#: What a pass fixes of a scene only to be saved and read back, and the layers' passes: not worth a reader's note.
_OUTPUT_ONLY = ("render.image_settings.", "render.use_persistent_data", "render.use_single_layer", "view_layers[")


def fixed_record(scene, spp: int, resolution, pattern: str | None, changes: list[dict]) -> dict:
    """Every setting the passes fix (`RunInfo.fixed`), by path: [the scene file's value, the passes' value], from
    the scene as `configure_unbiased` left it and the `changes` it made; the saved file's format left out."""
    passes = {path: jsonable(value) for _s, path, value in fixed_settings(scene, spp, resolution, pattern)}
    passes |= {"render.engine": scene.render.engine, "cycles.device": scene.cycles.device}
    scene_values = {c["path"]: c["old"] for c in changes}
    return {
        path: [scene_values.get(path, value), value]
        for path, value in passes.items()
        if not path.startswith(_OUTPUT_ONLY)
    }


def _sampling_pattern(scene, requested: str) -> str:
    """`requested`, checked to be a pattern of this Blender (5.0 fills the items at run time: its RNA lists none,
    so it is tried by setting it)."""
    cycles = scene.cycles
    old = cycles.sampling_pattern
    try:
        cycles.sampling_pattern = requested
    except TypeError as exc:
        choices = str(exc).rpartition(" not found in ")[2].strip("() \n").replace("'", "")
        raise RenderSetupError(
            f"--sampling-pattern {requested} is not a pattern of Blender {bpy.app.version_string} (it has {choices})"
        ) from None
    cycles.sampling_pattern = old  # configure_unbiased sets (and records) it
    return requested


def _set(changes: list[dict], struct, prefix: str, name: str, value) -> None:
    old = getattr(struct, name)
    if old != value:
        try:
            setattr(struct, name, value)
        except (TypeError, ValueError) as exc:
            raise RenderSetupError(f"{prefix}.{name}: Blender refused {value!r} ({_last_line(exc)})") from None
        new = getattr(struct, name)
        if new != value and not (isinstance(value, float) and abs(new - value) <= 1e-6 * abs(value)):
            raise RenderSetupError(f"{prefix}.{name}: Blender keeps {jsonable(new)!r} instead of {value!r}")
        changes.append({"path": f"{prefix}.{name}", "old": jsonable(old), "new": jsonable(value)})


def _last_line(exc: Exception) -> str:
    lines = str(exc).strip().splitlines()
    return lines[-1].strip() if lines else type(exc).__name__


def _set_device(changes: list[dict], scene: bpy.types.Scene, device: str) -> None:
    """'CPU'; 'GPU' (the first backend with a device); or a backend name from `GPU_BACKENDS`."""
    if device == "CPU":
        _set(changes, scene.cycles, "cycles", "device", "CPU")
        return
    if device != "GPU" and device not in GPU_BACKENDS:
        raise RenderSetupError(f"unknown device {device!r}; use CPU, GPU or one of {', '.join(GPU_BACKENDS)}")
    prefs = bpy.context.preferences.addons["cycles"].preferences
    for backend in GPU_BACKENDS if device == "GPU" else (device,):
        try:
            prefs.compute_device_type = backend
        except TypeError:  # a backend this build does not have
            continue
        prefs.refresh_devices()
        gpus = [d for d in prefs.devices if d.type == backend]
        if gpus:
            for d in prefs.devices:
                d.use = d in gpus
            _set(changes, scene.cycles, "cycles", "device", "GPU")
            return
    raise RenderSetupError(f"device {device!r}: {NO_GPU_MESSAGE}")


# ---------------------------------------------------------------------------------------------------------------
# Rendering passes


PASS_PREFIX = "welch-pass-"


def pass_bytes(width: int, height: int, channels: int = 3) -> int:
    """Size of an uncompressed float EXR pass (header aside): a line is its y, its size and its pixels."""
    return height * (8 + 8 + 4 * channels * width)


def choose_temp_dir(need: int) -> str:
    """``/dev/shm`` (memory, no disk I/O) where it is writable and has room for `need` bytes twice, else the
    system's temporary folder."""
    shm = "/dev/shm"
    if os.path.isdir(shm) and os.access(shm, os.W_OK) and _free_bytes(shm) >= 2 * need:
        return shm
    return tempfile.gettempdir()


def _free_bytes(folder: str) -> int:
    stat = os.statvfs(folder)
    return stat.f_bavail * stat.f_frsize


def remove_stale_passes(folder: str) -> list[str]:
    """Delete temporary pass files left by processes that no longer run (a killed render)."""
    removed = []
    for path in Path(folder).glob(f"{PASS_PREFIX}*.exr"):
        pid = path.name.removeprefix(PASS_PREFIX).split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not process_alive(int(pid)):
            path.unlink(missing_ok=True)
            removed.append(str(path))
    return removed


#: The tool's seeds are spread over Cycles' seeds by a bijection of 0..2**31 - 1 (`cycles_seed`).
SEED_MASK = 2**31 - 1


def cycles_seed(seed: int) -> int:
    """The Cycles seed of the tool's seed `seed`: a bijection of 0..2**31 - 1 (xor-shifts and odd multipliers, each
    invertible modulo 2**31), so that consecutive seeds are unrelated. Cycles' own seeds are not: with Tabulated
    Sobol, passes of seeds s and s + 2 were correlated (rho 0.11 between their tile sums on the diffuse corner in
    4.5-5.3; none over scattered seeds; docs/findings/pixel_variance.md), and a run of consecutive seeds then
    varies more than its passes say."""
    x = seed & SEED_MASK
    x ^= x >> 16
    x = (x * 0x045D9F3B) & SEED_MASK
    x ^= x >> 15
    x = (x * 0x119DE1F3) & SEED_MASK
    return x ^ (x >> 16)


class PassRenderer:
    """Render passes of one configured scene, one seed each.

    Use as a context manager: the temporary EXR file is removed on close.

    Parameters
    ----------
    scene : bpy.types.Scene
        A scene prepared with `configure_unbiased`.
    temp_dir : str, optional
        Folder for the temporary EXR; defaults to ``/dev/shm`` where writable with room, else the system temp
        folder. Pass files of dead processes found there are deleted. A paired check's side gives its pass
        images' folder: each pass's file is then renamed there, not written again (`batch.jobs.pairs`).

    Attributes
    ----------
    render_seconds, io_seconds : float
        Time of the last pass spent in ``render.render()`` and in saving plus reading the EXR.
    pass_file : str
        The EXR of the last pass, until the next one is rendered (it may be moved away).
    """

    def __init__(self, scene: bpy.types.Scene, temp_dir: str | None = None, lobes: tuple[str, ...] = ()):
        self.scene = scene
        self.lobes = tuple(lobes)
        width, height = render_size(scene)
        self.expected_bytes = pass_bytes(width, height, 3 + 9 * len(self.lobes))  # at most 3 passes of RGB a lobe
        folder = temp_dir or choose_temp_dir(self.expected_bytes)
        remove_stale_passes(folder)
        handle, path = tempfile.mkstemp(prefix=f"{PASS_PREFIX}{os.getpid()}-", suffix=".exr", dir=folder)
        os.close(handle)
        self.path = self.pass_file = path
        self.render_seconds = 0.0
        self.io_seconds = 0.0

    def render(self, seed: int) -> np.ndarray:
        """Render one pass with `seed`.

        Returns
        -------
        numpy.ndarray
            H×W×3 float32, scene-linear, top row first, alpha dropped.
        """
        return self._render(seed, wc.read_exr)

    def render_layers(self, seed: int) -> dict[str, np.ndarray]:
        """Render one pass with `seed` and return the image (``combined``) and the layers of the renderer's
        `lobes` (see `batch.lobes.layers_from_channels`), each H×W×3 float32."""
        return self._render(seed, lambda path: layers_from_channels(wc.read_exr_channels(path), self.lobes))

    def _render(self, seed: int, read):
        self.scene.cycles.seed = cycles_seed(seed)
        # Setting scene.cycles.* does not tag the depsgraph: with persistent data Cycles would reuse the old seed.
        # A 'TIME' refresh re-syncs the integrator without rebuilding the BVH.
        self.scene.update_tag(refresh={"TIME"})
        start = time.perf_counter()
        bpy.ops.render.render(scene=self.scene.name)
        middle = time.perf_counter()
        try:
            bpy.data.images["Render Result"].save_render(self.path, scene=self.scene)
            pixels = read(self.path)
        except (RuntimeError, wc.WelchInputError) as exc:  # a failed save raises, or leaves a short file
            raise BatchError(self._save_failure(exc)) from None
        self.render_seconds = middle - start
        self.io_seconds = time.perf_counter() - middle
        return pixels

    def _save_failure(self, exc: Exception) -> str:
        """Why a saved pass does not read back: most often a full temporary folder (Blender only prints it)."""
        folder = os.path.dirname(self.path)
        free = _free_bytes(folder)
        if free < self.expected_bytes:
            return (
                f"no space left in {folder} to save a pass ({free / 2**20:.1f} MiB free, a pass needs "
                f"{self.expected_bytes / 2**20:.1f} MiB)"
            )
        return f"Blender's saved pass does not read back: {_last_line(exc)}"

    def close(self) -> None:
        """Remove the temporary file."""
        Path(self.path).unlink(missing_ok=True)

    def __enter__(self) -> PassRenderer:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()


# ---------------------------------------------------------------------------------------------------------------
# What a run records

# Settings that change the converged image (or must match between the two sides of a test), as override paths.
# Samples and seed are left out: they change the noise, not the converged image, and runs record them anyway.
_CYCLES_SETTINGS = (
    "sampling_pattern", "scrambling_distance", "auto_scrambling_distance", "use_adaptive_sampling",
    "adaptive_threshold", "adaptive_min_samples", "time_limit", "use_denoising", "use_light_tree",
    "light_sampling_threshold", "min_light_bounces", "min_transparent_bounces", "caustics_reflective",
    "caustics_refractive", "blur_glossy", "use_guiding", "max_bounces", "diffuse_bounces", "glossy_bounces",
    "transmission_bounces", "volume_bounces", "transparent_max_bounces", "volume_step_rate", "volume_max_steps",
    "volume_biased", "sample_clamp_direct", "sample_clamp_indirect", "use_fast_gi", "fast_gi_method",
    "ao_bounces_render", "pixel_filter_type", "filter_width", "film_exposure", "film_transparent_glass",
    "film_transparent_roughness", "use_sample_subset", "sample_offset", "sample_subset_length",
    "use_animated_seed", "use_layer_samples", "texture_limit_render", "dicing_rate", "max_subdivisions",
    "use_camera_cull", "use_distance_cull",
)  # fmt: skip
_RENDER_SETTINGS = (
    "engine", "resolution_x", "resolution_y", "resolution_percentage", "pixel_aspect_x", "pixel_aspect_y",
    "film_transparent", "use_motion_blur", "motion_blur_shutter", "motion_blur_position", "use_border",
    "use_simplify", "simplify_subdivision_render", "simplify_child_particles_render", "simplify_volumes",
    "use_compositing", "use_sequencer", "use_single_layer",
)  # fmt: skip
_VIEW_LAYER_SETTINGS = (
    "use", "samples", "use_solid", "use_sky", "use_strand", "use_volumes", "use_motion_blur",
    "material_override", "world_override",
)  # fmt: skip


def scene_settings(scene: bpy.types.Scene) -> dict:
    """The settings that change the converged image, keyed by override path (``cycles.blur_glossy``).

    Values are JSON-able: enums as identifiers, vectors as lists, data blocks as names (None when unset).
    """
    out: dict = {}
    for struct, prefix, names in (
        (scene.cycles, "cycles", _CYCLES_SETTINGS),
        (scene.render, "render", _RENDER_SETTINGS),
        (scene, "", ("camera", "world", "frame_current")),
    ):
        for name in names:
            if name in struct.bl_rna.properties:  # some properties come and go between versions
                out[f"{prefix}.{name}".lstrip(".")] = jsonable(getattr(struct, name))
    for layer in scene.view_layers:
        prefix = f"view_layers[{json.dumps(layer.name)}]"
        for name in _VIEW_LAYER_SETTINGS:
            if name in layer.bl_rna.properties:
                out[f"{prefix}.{name}"] = jsonable(getattr(layer, name))
        out[f"{prefix}.cycles.use_denoising"] = layer.cycles.use_denoising
    return out


def settings_hash(settings: dict) -> str:
    """SHA-256 (hex) of `settings` as sorted, compact JSON."""
    text = json.dumps(settings, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def scene_id(builtin: str | None) -> str:
    """What fixes the scene's content: ``builtin:<name>:<builder version>``, or ``sha256:<hex>`` of the .blend
    file Blender has open (so a changed file is another configuration, whatever its name)."""
    if builtin is not None:
        return builtin_scene_id(builtin, BUILDER_VERSION)
    digest = hashlib.sha256()
    with open(bpy.data.filepath, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return f"sha256:{digest.hexdigest()}"


def renderer_info(scene: bpy.types.Scene, device: str) -> dict:
    """Which renderer made a run: name, Blender version and build, device, sampling pattern."""
    build_hash = bpy.app.build_hash
    return {
        "renderer": "Cycles",
        "version": bpy.app.version_string,  # Blender's version: Cycles has none of its own
        "build_hash": build_hash.decode() if isinstance(build_hash, bytes) else str(build_hash),
        "device": device,
        "sampling_pattern": scene.cycles.sampling_pattern,
    }
