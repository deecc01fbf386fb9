"""Runs of the add-on: their folders, the render jobs of both sides, starting them, and old runs' clean-up.

Operators call these; nothing here draws. The user's file is never modified: each run saves a copy into its
own folder, which both sides render.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import bpy

from . import _siblings, checks, preferences, runner
from ._siblings import ADDON_MODULE, lobes, options, samples
from .state import RunFolder, current


def user_dir() -> Path:
    """Writable folder of the extension; a temporary folder when the package is not installed as one."""
    extension_path_user = getattr(bpy.utils, "extension_path_user", None)  # 4.2+
    try:
        if extension_path_user is None:
            raise ValueError
        return Path(extension_path_user(ADDON_MODULE, create=True))
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
    """The Blender that renders: the preference, else this one (empty with the bpy module: then this Python)."""
    prefs = preferences.get(context)
    if prefs is not None and prefs.blender_binary:
        return bpy.path.abspath(prefs.blender_binary)
    return bpy.app.binary_path


def extension_wheel_paths() -> list[str]:
    """Where Blender installs extension wheels, for a batch tool started with this Python (bpy module)."""
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    try:
        path = bpy.utils.user_resource("EXTENSIONS", path=f".local/lib/{version}/site-packages")
    except (TypeError, ValueError):  # Blender before 4.2 has no extensions (3.4 raises ValueError)
        return []
    return [path] if Path(path).is_dir() else []


def alpha_of(settings) -> float:
    """Alpha as typed: the property is single precision (0.01 reads back as 0.0099999998)."""
    return float(f"{settings.alpha:.6g}")


def tolerance_of(settings) -> float | None:
    """The tolerance as typed, as a fraction checked as the command line's --tolerance (None: 0, off)."""
    if settings.tolerance <= 0:
        return None
    return options.OPTIONS["tolerance"].convert("Tolerance", f"{settings.tolerance:g}%")


def settings_key(settings, scene) -> tuple:
    """What must be unchanged for a stopped run to be continued."""
    reference, test = checks.sides(settings, scene)
    names = tuple(s.name if s is not None else "" for s in (reference, test))
    return (
        bpy.data.filepath, settings.mode, names, tuple(settings.enabled_overrides()), settings.max_passes,
        settings.paired, settings.spp, settings.tile, settings.device, settings.use_lobes, settings.tolerance,
        settings.test_build, settings.seed_offset,
    )  # fmt: skip


def check_request(settings, scene, blend: str, folder: Path, resume: bool, blender: str = ""):
    """The check of a run (on the saved copy `blend`) as `batch.decide.check_job.CheckRequest`: the panel's settings,
    and the command line's defaults for everything the panel does not set."""
    reference, test = checks.sides(settings, scene)
    other = bpy.path.abspath(settings.test_build) if settings.test_build else ""
    python = other and Path(other).name.startswith("python")  # a Python with another release's bpy, or a binary
    return _siblings.check.CheckRequest(
        out=str(folder),
        blend=blend,
        blend_scene=reference.name,
        test_blend=blend if test != reference else None,
        test_blend_scene=test.name if test != reference else None,
        overrides=tuple(settings.enabled_overrides()),
        spp=settings.spp or None,  # 0: auto
        tile=settings.tile,
        device=settings.device,
        lobes=_lobes(settings, scene) if settings.use_lobes else (),
        blender=blender or None,
        test_blender=other if other and not python else None,
        test_python=other if python else None,
        max_passes=settings.max_passes,
        alpha=alpha_of(settings),
        tolerance=tolerance_of(settings),
        unpaired=not settings.paired,
        seed_offset=settings.seed_offset,
        resume=resume,
    )


def scene_samples(jobs) -> list:
    """What each side's scene asks of the passes (``--spp auto``), read from this file's own scenes: a run renders
    a copy of it (`batch.decide.check_job.check_job`'s `probe`)."""
    return [samples.scene_samples(bpy.data.scenes[job.blend_scene]) for _name, job in jobs]


def _lobes(settings, scene) -> tuple[str, ...]:
    """The components, and the light groups where the view layer has some (``--lobes``)."""
    groups = any(len(getattr(layer, "lightgroups", ())) for layer in scene.view_layers)
    components = lobes.COMPONENTS
    return (*components, "lightgroups") if groups else components


def start(context, settings, resume: bool) -> runner.CheckRun:
    """Save a copy of the file (the user's file is never touched) and start the check.

    Resuming renders the copy the run started from (kept while the run can be resumed): the statistics go on
    with the very scene they began with, whatever was edited since.
    """
    folder = Path(current.resumable.dir) if resume else new_run_dir()
    blend = folder / "scene.blend"
    if not resume:
        bpy.ops.wm.save_as_mainfile(filepath=str(blend), copy=True, check_existing=False)
    elif not blend.is_file():
        raise OSError(f"the stopped run's copy of the scene is gone ({blend}): start a new run")
    request = check_request(settings, context.scene, str(blend), folder, resume, blender_binary(context))
    # --spp auto reads the scenes: this file's own for a new run (its copy is this file), the copy on a resume
    job = _siblings.check.check_job(request, probe=None if resume else scene_samples)
    # Render processes started with this Python (the bpy module) find the extension's wheels.
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([*extension_wheel_paths(), *filter(None, [env.get("PYTHONPATH")])])
    prefs = preferences.get(context)
    keep = prefs is not None and prefs.keep_temporary_files
    session = runner.CheckRun(job, temporary_files=[] if keep else [str(blend)], env=env)
    current.session, current.last_error, current.resumable = session, "", None
    current.run = RunFolder(
        dir=str(folder),
        reference=job.reference.out,
        test=job.test.out,
        alpha=alpha_of(settings),
        key=settings_key(settings, context.scene),
    )
    session.poll()
    return session


def prune_old_runs(context) -> None:
    prefs = preferences.get(context)
    keep = prefs.runs_to_keep if prefs is not None else 10
    runner.prune_runs(user_dir() / "runs", keep, protect=[current.run.dir] if current.run else [])
