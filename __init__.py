"""Blender extension entry point: Blender needs ``__init__.py`` next to ``blender_manifest.toml``."""


def register():
    from .blender_addon import register as _register

    _register()


def unregister():
    from .blender_addon import unregister as _unregister

    _unregister()
