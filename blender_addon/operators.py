"""Operators: turn the scene settings into runs and results; the work itself is in runner.py and results.py.

``welch_bias.run`` is modal when started from the UI (a timer polls the background renders, Blender stays
usable) and blocking when called from a script, which is also how it is tested headless.
"""

import atexit
import sys
import tempfile
import time
from pathlib import Path

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, IntProperty, StringProperty

from . import checks, preferences, results, runner, state
from ._siblings import ADDON_MODULE, welch_core

EXTENSION_ROOT = Path(__file__).resolve().parent.parent  # holds the batch and welch_core packages
TIMER_SECONDS = 0.25
REDRAW_AREAS = {"PROPERTIES", "IMAGE_EDITOR", "STATUSBAR"}


def user_dir() -> Path:
    """Writable folder of the extension; a temporary folder when the package is not installed as one."""
    try:
        return Path(bpy.utils.extension_path_user(ADDON_MODULE, create=True))
    except ValueError:
        path = Path(tempfile.gettempdir()) / "welch_bias"
        path.mkdir(parents=True, exist_ok=True)
        return path


def new_run_dir() -> Path:
    """A fresh folder per run; its name starts with the time so the newest sort last."""
    stem = Path(bpy.data.filepath).stem or "untitled"
    runs = user_dir() / "runs"
    for attempt in range(100):
        path = runs / f"{time.strftime('%Y%m%d-%H%M%S')}-{attempt:02d}-{stem}"
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            continue
    raise OSError(f"cannot create a run folder in {runs}")


def blender_binary(context) -> str:
    prefs = preferences.get(context)
    if prefs is not None and prefs.blender_binary:
        return bpy.path.abspath(prefs.blender_binary)
    return bpy.app.binary_path  # empty with the bpy module: the batch tool then runs under this Python


def extension_wheel_paths() -> list[str]:
    """Where Blender installs extension wheels, for a batch tool started with this Python (bpy module)."""
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    path = bpy.utils.user_resource("EXTENSIONS", path=f".local/lib/{version}/site-packages")
    return [path] if Path(path).is_dir() else []


def alpha_of(settings) -> float:
    """Alpha as typed: the property is single precision (0.01 reads back as 0.0099999998)."""
    return float(f"{settings.alpha:.6g}")


def settings_key(settings, scene) -> tuple:
    """What must be unchanged for a stopped run to be continued with --resume."""
    reference, test = checks.sides(settings, scene)
    names = tuple(s.name if s is not None else "" for s in (reference, test))
    return (
        bpy.data.filepath, settings.mode, names, tuple(settings.enabled_overrides()), settings.passes,
        settings.first_seed, settings.paired, settings.spp, settings.tile, settings.device,
    )  # fmt: skip


def run_specs(settings, scene, blend: str, folder: Path, resume: bool) -> list[runner.RunSpec]:
    reference, test = checks.sides(settings, scene)
    seeds = runner.seed_ranges(settings.first_seed, settings.passes, settings.paired)
    common = {"blend": blend, "spp": settings.spp, "tile": settings.tile, "resume": resume, "device": settings.device}
    return [
        runner.RunSpec("Reference", out=str(folder / "reference.npz"), seeds=seeds[0], blend_scene=reference.name,
                       **common),
        runner.RunSpec("Test", out=str(folder / "test.npz"), seeds=seeds[1], blend_scene=test.name,
                       overrides=tuple(settings.enabled_overrides()), **common),
    ]  # fmt: skip


def start_session(context, settings, resume: bool) -> runner.Session:
    """Save a copy of the file (the user's file is never touched) and start the reference side."""
    folder = Path(state.resumable["dir"]) if resume else new_run_dir()
    blend = folder / "scene.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True, check_existing=False)
    specs = run_specs(settings, context.scene, str(blend), folder, resume)
    binary = blender_binary(context)
    commands = [runner.command_for(s, EXTENSION_ROOT, binary, python_paths=extension_wheel_paths()) for s in specs]
    prefs = preferences.get(context)
    keep = prefs is not None and prefs.keep_temporary_files
    session = runner.Session(specs, commands, temporary_files=[] if keep else [str(blend)])
    state.session, state.last_error, state.resumable = session, "", None
    state.run_context = {
        "dir": str(folder),
        "reference": specs[0].out,
        "test": specs[1].out,
        "alpha": alpha_of(settings),
        "key": settings_key(settings, context.scene),
    }
    session.poll()
    return session


def compare_and_show(context, reference_path: str, test_path: str, alpha: float) -> dict:
    comparison, reference, test = results.compare_files(reference_path, test_path, alpha)
    summary = results.store(comparison, reference, test, {"reference": reference_path, "test": test_path})
    image = results.refresh(context)
    results.show_in_image_editor(context, image)
    return summary


def verdict_message(summary: dict) -> str:
    p = summary["p_value"]
    p_text = "n/a" if p is None else f"{p:.3g}"
    return f"{summary['verdict_text']} (alpha {summary['alpha']:g}, global p {p_text})"


def tag_redraw(context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type in REDRAW_AREAS:
                area.tag_redraw()


def prune_old_runs(context) -> None:
    prefs = preferences.get(context)
    keep = prefs.runs_to_keep if prefs is not None else 10
    runner.prune_runs(user_dir() / "runs", keep, protect=[state.run_context.get("dir", "")])


class WELCH_BIAS_OT_run(bpy.types.Operator):
    bl_idname = "welch_bias.run"
    bl_label = "Run Bias Test"
    bl_description = "Render the reference and test sides in the background and test whether they differ"

    resume: BoolProperty(
        name="Resume",
        description="Continue the stopped run's statistics instead of starting new ones",
        default=False,
        options={"SKIP_SAVE", "HIDDEN"},
    )

    _timer = None

    @classmethod
    def poll(cls, context):
        return context.scene is not None and not state.running()

    def _start(self, context) -> str:
        """'SESSION' when background renders started, else the operator's result: 'FINISHED' or 'CANCELLED'."""
        settings = context.scene.welch_bias
        problems = checks.setup_problems(settings, context.scene, abspath=bpy.path.abspath)
        if problems:
            return self._fail(problems[0])
        for warning in checks.setup_warnings(settings, context.scene):
            self.report({"WARNING"}, warning)
        if self.resume and (state.resumable is None or state.resumable["key"] != settings_key(settings, context.scene)):
            return self._fail("Nothing to resume with these settings")
        state.clear_result()
        if settings.mode == "STATS_FILES":
            return self._compare_files(context, settings)
        try:
            start_session(context, settings, self.resume)
        except (OSError, RuntimeError, ValueError) as ex:
            return self._fail(f"Could not start the run: {ex}")
        return "SESSION"

    def _compare_files(self, context, settings) -> str:
        ref, test = bpy.path.abspath(settings.reference_file), bpy.path.abspath(settings.test_file)
        try:
            summary = compare_and_show(context, ref, test, alpha_of(settings))
        except (welch_core.WelchInputError, OSError) as ex:
            return self._fail(str(ex))
        self.report({"INFO"}, verdict_message(summary))
        return "FINISHED"

    def _fail(self, message: str) -> str:
        state.last_error = runner.one_line(message)
        self.report({"ERROR"}, state.last_error)
        return "CANCELLED"

    def _conclude(self, context) -> set:
        """Turn the ended session into a result, an error or a resumable checkpoint."""
        session = state.session
        tag_redraw(context)
        if session.state == runner.FINISHED:
            ctx = state.run_context
            try:
                summary = compare_and_show(context, ctx["reference"], ctx["test"], ctx["alpha"])
            except (welch_core.WelchInputError, OSError) as ex:
                self._fail(str(ex))
                return {"CANCELLED"}
            prune_old_runs(context)
            for warning in session.warnings:
                self.report({"WARNING"}, warning)
            self.report({"INFO"}, verdict_message(summary))
            return {"FINISHED"}
        state.resumable = dict(state.run_context)
        if session.state == runner.FAILED:
            self._fail(session.error)
        else:
            self.report({"INFO"}, f"Cancelled; the statistics so far are kept in {state.run_context['dir']}")
        return {"CANCELLED"}

    def execute(self, context):
        outcome = self._start(context)
        if outcome != "SESSION":
            return {outcome}
        state.session.wait()
        return self._conclude(context)

    def invoke(self, context, _event):
        outcome = self._start(context)
        if outcome != "SESSION":
            return {outcome}
        if not state.running():  # ended at once, e.g. the subprocess could not start
            return self._conclude(context)
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        tag_redraw(context)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if state.session is not None and state.session.poll() == runner.RUNNING:
            tag_redraw(context)
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        self._timer = None
        if state.session is None:
            return {"CANCELLED"}
        return self._conclude(context)


class WELCH_BIAS_OT_cancel(bpy.types.Operator):
    bl_idname = "welch_bias.cancel"
    bl_label = "Cancel"
    bl_description = "Stop the background render; the statistics written so far are kept for resuming"

    @classmethod
    def poll(cls, _context):
        return state.running()

    def execute(self, context):
        state.session.cancel()
        state.resumable = dict(state.run_context)
        tag_redraw(context)
        return {"FINISHED"}


class WELCH_BIAS_OT_show_result(bpy.types.Operator):
    bl_idname = "welch_bias.show_result"
    bl_label = "Show Result"
    bl_description = "Rebuild the p-value map image with the current display settings and show it"

    @classmethod
    def poll(cls, _context):
        return state.comparison is not None

    def execute(self, context):
        image = results.refresh(context)
        if not results.show_in_image_editor(context, image):
            self.report({"INFO"}, f"Open '{image.name}' in an Image Editor to see the map")
        return {"FINISHED"}


class WELCH_BIAS_OT_frame_tile(bpy.types.Operator):
    bl_idname = "welch_bias.frame_tile"
    bl_label = "Frame Tile"
    bl_description = "Outline this tile in the p-value map and centre the Image Editor on it"

    row: IntProperty(name="Row", min=0)
    col: IntProperty(name="Column", min=0)

    @classmethod
    def poll(cls, _context):
        return state.comparison is not None

    def execute(self, context):
        tiles_y, tiles_x = state.comparison.tile_pvalues.shape
        if not (self.row < tiles_y and self.col < tiles_x):
            self.report({"ERROR"}, f"No tile at row {self.row}, column {self.col}")
            return {"CANCELLED"}
        state.highlight = (self.row, self.col)
        image = results.refresh(context)
        results.show_in_image_editor(context, image)
        tile = state.comparison.tile
        results.frame_tile(context, self.col * tile, self.row * tile, tile)
        return {"FINISHED"}


class WELCH_BIAS_OT_override_add(bpy.types.Operator):
    bl_idname = "welch_bias.override_add"
    bl_label = "Add Override"
    bl_description = "Add a property override applied to the test side"
    bl_options = {"REGISTER", "UNDO"}

    text: StringProperty(name="Override", description="Property path and value, e.g. cycles.blur_glossy=0")

    def execute(self, context):
        item = context.scene.welch_bias.overrides.add()
        item.text = self.text
        return {"FINISHED"}


class WELCH_BIAS_OT_override_remove(bpy.types.Operator):
    bl_idname = "welch_bias.override_remove"
    bl_label = "Remove Override"
    bl_description = "Remove this property override"
    bl_options = {"REGISTER", "UNDO"}

    index: IntProperty(name="Index", min=0)

    def execute(self, context):
        overrides = context.scene.welch_bias.overrides
        if self.index >= len(overrides):
            self.report({"ERROR"}, f"No override number {self.index + 1}")
            return {"CANCELLED"}
        overrides.remove(self.index)
        return {"FINISHED"}


def _stop_running() -> None:
    # A background render must not outlive the Blender that started it (file load, add-on disabled, quit).
    if state.running():
        state.session.cancel()


@persistent
def _stop_on_load(_filepath):
    # A run belongs to the file it was started from.
    _stop_running()
    state.session, state.resumable = None, None
    state.clear_result()


classes = (
    WELCH_BIAS_OT_run,
    WELCH_BIAS_OT_cancel,
    WELCH_BIAS_OT_show_result,
    WELCH_BIAS_OT_frame_tile,
    WELCH_BIAS_OT_override_add,
    WELCH_BIAS_OT_override_remove,
)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(classes)


def register():
    _register_classes()
    bpy.app.handlers.load_pre.append(_stop_on_load)
    atexit.register(_stop_running)


def unregister():
    _stop_on_load(None)
    atexit.unregister(_stop_running)
    bpy.app.handlers.load_pre.remove(_stop_on_load)
    _unregister_classes()
