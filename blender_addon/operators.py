"""Operators: turn the scene settings into runs and results; the work itself is in session.py, runner.py and
results.py.

``welch_bias.run`` is modal when started from the UI (a timer polls the background renders, Blender stays
usable) and blocking when called from a script, which is also how it is tested headless.
"""

import atexit

import bpy
from bpy.app.handlers import persistent
from bpy.props import BoolProperty, IntProperty, StringProperty

from . import _siblings, checks, overlay, results, runner, session
from ._siblings import errors, fmt, welch_core
from .state import current

TIMER_SECONDS = 0.25
REDRAW_AREAS = {"PROPERTIES", "IMAGE_EDITOR"}


def compare_and_show(context, reference_path: str, test_path: str, alpha: float) -> dict:
    assessment, reference, test = _siblings.pipeline.assess_files(reference_path, test_path, alpha)
    sources = {"reference": reference_path, "test": test_path}
    summary = results.store(assessment, reference, test, sources)
    show(context)
    return summary


def show(context) -> None:
    """Draw the stored result and show it where the image is (the overlay, or an Image Editor)."""
    image = results.refresh(context)
    if not overlay.shown_anywhere(context):  # else the map is over the render someone looks at already
        results.show_in_image_editor(context, image)


def conclude_check(context, run: runner.CheckRun) -> dict:
    """The finished check's report (written into its folder, as ``python -m batch check`` writes it) and its
    result shown: the verdict and numbers of its final look, the map of its final passes."""
    look, reference, test = run.result
    check = _siblings.check
    report, assessment = check.report_check(run.check, look, reference, test)
    sources = {"reference": run.job.reference.out, "test": run.job.test.out}
    summary = results.store(assessment, reference, test, sources, report=report)
    image = results.refresh(context)
    results.show_in_image_editor(context, image, sidebar=True)  # the result's place: the editor's sidebar
    results.save_with_file(context.scene, current.run.key)
    return summary


def show_look(context, run: runner.CheckRun) -> None:
    """The map of the last look's passes while the check goes on (the verdict is the look's)."""
    taken = run.take_look()
    if taken is None:
        return
    look, reference, test = taken
    check = _siblings.check
    sources = {"reference": run.job.reference.out, "test": run.job.test.out}
    comparison = check.look_comparison(run.job, reference, test, run.check.pixel_pairs, run.check.plan.pixel_variance)
    assessment = _siblings.pipeline.assess(
        comparison, reference, test, names=tuple(sources.values()), outcome=look.outcome
    )
    results.store(assessment, reference, test, sources)
    show(context)


def verdict_message(summary: dict) -> str:
    """The verdict's sentence, capitalised, as the status bar shows it."""
    return fmt.one_line(summary["sentence"][:1].upper() + summary["sentence"][1:])


def tag_redraw(context) -> None:
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type in REDRAW_AREAS:
                area.tag_redraw()


def tag_redraw_status_bar(context) -> None:
    """Redraw the status bar, which ``screen.areas`` does not list (it belongs to the window): Blender redraws it
    when the workspace's status text is set, here to none, as every modal tool leaves it when it ends."""
    if context.workspace is not None:
        context.workspace.status_text_set_internal(None)


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
    _status = ""  # the status line last shown, so the status bar is redrawn only when it changes

    @classmethod
    def poll(cls, context):
        return context.scene is not None and not current.running()

    def _start(self, context) -> str:
        """'SESSION' when background renders started, else the operator's result: 'FINISHED' or 'CANCELLED'."""
        settings = context.scene.welch_bias
        problems = checks.setup_problems(settings, context.scene, abspath=bpy.path.abspath)
        if problems:
            return self._fail(problems[0])
        for warning in checks.setup_warnings(settings, context.scene):
            self.report({"WARNING"}, warning)
        resumable = current.resumable
        if self.resume and (resumable is None or resumable.key != session.settings_key(settings, context.scene)):
            return self._fail("Nothing to resume with these settings")
        current.clear_result()
        if settings.mode == "STATS_FILES":
            return self._compare_files(context, settings)
        try:
            session.start(context, settings, self.resume)
        except (OSError, RuntimeError, ValueError, errors.BatchError) as ex:
            return self._fail(f"Could not start the run: {ex}")
        return "SESSION"

    def _compare_files(self, context, settings) -> str:
        ref, test = bpy.path.abspath(settings.reference_file), bpy.path.abspath(settings.test_file)
        try:
            summary = compare_and_show(context, ref, test, session.alpha_of(settings))
        except (welch_core.WelchInputError, OSError) as ex:
            return self._fail(str(ex))
        self.report({"INFO"}, verdict_message(summary))
        return "FINISHED"

    def _fail(self, message: str) -> str:
        current.last_error = fmt.one_line(message)
        self.report({"ERROR"}, current.last_error)
        return "CANCELLED"

    def _conclude(self, context) -> set:
        """Turn the ended session into a result, an error or a resumable checkpoint."""
        ended, run = current.session, current.run
        tag_redraw(context)
        tag_redraw_status_bar(context)
        if ended.state == runner.FINISHED:
            try:
                summary = conclude_check(context, ended)
            except (welch_core.WelchInputError, OSError, errors.BatchError) as ex:
                self._fail(str(ex))
                return {"CANCELLED"}
            session.prune_old_runs(context)
            for warning in ended.warnings + summary["warnings"]:
                self.report({"WARNING"}, warning)
            self.report({"INFO"}, verdict_message(summary))
            return {"FINISHED"}
        current.resumable = run
        if ended.state == runner.FAILED:
            self._fail(ended.error)
        else:
            self.report({"INFO"}, f"Cancelled; the statistics so far are kept in {run.dir}")
        return {"CANCELLED"}

    def execute(self, context):
        outcome = self._start(context)
        if outcome != "SESSION":
            return {outcome}
        current.session.wait()
        return self._conclude(context)

    def invoke(self, context, _event):
        outcome = self._start(context)
        if outcome != "SESSION":
            return {outcome}
        if not current.running():  # ended at once, e.g. the subprocess could not start
            return self._conclude(context)
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        tag_redraw(context)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        if current.session is not None and current.session.poll() == runner.RUNNING:
            try:
                show_look(context, current.session)
            except (welch_core.WelchInputError, OSError) as ex:  # a live map is a view: the run goes on
                current.overlay_error = fmt.one_line(str(ex))
            tag_redraw(context)
            if current.session.status_text() != self._status:
                self._status = current.session.status_text()
                tag_redraw_status_bar(context)
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        self._timer = None
        if current.session is None:
            return {"CANCELLED"}
        return self._conclude(context)


class WELCH_BIAS_OT_cancel(bpy.types.Operator):
    bl_idname = "welch_bias.cancel"
    bl_label = "Cancel"
    bl_description = "Stop the background render; the statistics written so far are kept for resuming"

    @classmethod
    def poll(cls, _context):
        return current.running()

    def execute(self, context):
        current.session.cancel()
        current.resumable = current.run
        tag_redraw(context)
        return {"FINISHED"}


class WELCH_BIAS_OT_show_result(bpy.types.Operator):
    bl_idname = "welch_bias.show_result"
    bl_label = "Show Result"
    bl_description = "Rebuild the p-value map image with the current display settings and show it"

    @classmethod
    def poll(cls, _context):
        return current.comparison is not None

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
        return current.comparison is not None

    def execute(self, context):
        tiles_y, tiles_x = current.comparison.tile_pvalues.shape
        if not (self.row < tiles_y and self.col < tiles_x):
            self.report({"ERROR"}, f"No tile at row {self.row}, column {self.col}")
            return {"CANCELLED"}
        current.highlight = (self.row, self.col)
        image = results.refresh(context)
        results.show_in_image_editor(context, image)
        tile = current.comparison.tile
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
    if current.running():
        current.session.cancel()


@persistent
def _stop_on_load(*_args):
    # A run belongs to the file it was started from.
    _stop_running()
    current.reset()


@persistent
def _restore_on_load(*_args):
    # The last result was saved with the file: the panel shows it again (marked when the settings changed since).
    scene = bpy.context.scene
    if scene is not None and hasattr(scene, "welch_bias"):
        results.restore_from_file(scene)


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
    bpy.app.handlers.load_post.append(_restore_on_load)
    atexit.register(_stop_running)


def unregister():
    _stop_on_load(None)
    atexit.unregister(_stop_running)
    bpy.app.handlers.load_pre.remove(_stop_on_load)
    bpy.app.handlers.load_post.remove(_restore_on_load)
    _unregister_classes()
