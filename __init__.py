"""Blender add-on entry point: a 5.0 extension through ``blender_manifest.toml``, a legacy add-on through
``bl_info`` (Blender 3.4 to 4.1, from the zip ``python -m blender_addon.build --legacy`` writes).

Blender reads ``bl_info`` as a literal without running this file; extensions ignore it.
"""

bl_info = {
    "name": "Welch Bias Test",
    "author": "welch-bias contributors",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Render and Image Editor > Sidebar > Welch",
    "description": "Find biased regions of Cycles renders with Welch's t-test",
    "category": "Render",
}


def register():
    from .blender_addon import register as _register

    _register()


def unregister():
    from .blender_addon import unregister as _unregister

    _unregister()
