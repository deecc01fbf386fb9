"""Checks of the setup before a run, each problem as one line for ``report``.

They read scene settings only through attribute access (``scene.camera``, ``scene.render``), so they need no
operator context; errors stop a run, warnings are reported and the run goes on.
"""

from __future__ import annotations

import os

from ._siblings import overrides, rna

render_size = rna.render_size


def scene_problems(scene, tile: int, label: str) -> list[str]:
    if scene is None:
        return [f"Choose the {label.lower()} scene"]
    problems = []
    if scene.camera is None:
        problems.append(f"Scene '{scene.name}' has no camera")
    width, height = render_size(scene)
    if tile > min(width, height):
        problems.append(f"Tile size {tile} exceeds the render size {width}x{height} of scene '{scene.name}'")
    return problems


def override_problems(texts: list[str]) -> list[str]:
    """Syntax errors of the overrides; whether a path resolves is only known in the scene the batch tool opens."""
    problems = []
    for text in texts:
        try:
            overrides.parse_override(text)
        except ValueError as ex:
            reason = " ".join(str(ex).split()).removeprefix(f"--set {text}: ")
            problems.append(f"Override '{text}': {reason}")
    return problems


def file_problems(path: str, label: str) -> list[str]:
    if not path:
        return [f"Choose the {label.lower()} statistics file"]
    if not os.path.isfile(path):
        return [f"{label} statistics file not found: {path}"]
    return []


def setup_problems(settings, scene, abspath=os.path.abspath) -> list[str]:
    """Everything that stops a run of ``settings`` (the scene's add-on settings) before it starts."""
    if settings.mode == "STATS_FILES":
        paths = [abspath(p) if p else "" for p in (settings.reference_file, settings.test_file)]
        return file_problems(paths[0], "Reference") + file_problems(paths[1], "Test")
    reference, test = sides(settings, scene)
    problems = scene_problems(reference, settings.tile, "Reference")
    if test is None or test != reference:
        problems += scene_problems(test, settings.tile, "Test")
    if reference is not None and test is not None and render_size(reference) != render_size(test):
        (rw, rh), (tw, th) = render_size(reference), render_size(test)
        problems.append(f"The reference and test scenes render at different sizes: {rw}x{rh} and {tw}x{th}")
    if settings.mode == "CURRENT_WITH_OVERRIDES" and not settings.enabled_overrides() and settings.paired:
        problems.append(
            "No overrides: both sides would be the same renders; add an override, or turn Paired off to check the "
            "scene against itself on other seeds"
        )
    return problems + override_problems(settings.enabled_overrides())


def setup_warnings(settings, scene) -> list[str]:
    """What is worth knowing but does not stop a run."""
    if settings.mode == "STATS_FILES":
        return []
    warnings = []
    reference, test = sides(settings, scene)
    for side in dict.fromkeys(s for s in (reference, test) if s is not None):
        if side.render.engine != "CYCLES":
            warnings.append(f"Scene '{side.name}' uses {side.render.engine}: the passes are rendered with Cycles")
    if settings.mode == "CURRENT_WITH_OVERRIDES" and not settings.enabled_overrides() and not settings.paired:
        warnings.append("No overrides: the scene against itself on other seeds (a check of the test itself)")
    if settings.mode == "TWO_SCENES" and reference is not None and reference == test:
        warnings.append("Reference and test are the same scene")
    return warnings


def sides(settings, scene):
    """The (reference, test) scenes of a render mode."""
    if settings.mode == "TWO_SCENES":
        return settings.reference_scene, settings.test_scene
    return scene, scene
