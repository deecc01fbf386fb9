"""Small helpers for Blender data that import nothing at module level: the add-on, lint, overrides and the
renderer share them, and tests reach them without Blender."""

from __future__ import annotations


def jsonable(value):
    """An RNA value as JSON types: data blocks by name, arrays and sets as lists, floats as Python floats."""
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, float):
        return float(value)
    if isinstance(value, set):
        return sorted(value)
    if "bpy" in type(value).__module__ and _is_id(value):  # '_bpy_types' in 5.0, 'bpy_types' before
        return value.name
    try:
        return [jsonable(v) for v in value]
    except TypeError:
        return str(value)


def _is_id(value) -> bool:
    import bpy  # only reached for RNA values, which exist only where bpy does

    return isinstance(value, bpy.types.ID)


def render_size(scene) -> tuple[int, int]:
    """Width and height in pixels of the scene's renders (after the resolution percentage), as Blender rounds."""
    render = scene.render
    scale = render.resolution_percentage / 100
    return max(int(render.resolution_x * scale), 1), max(int(render.resolution_y * scale), 1)
