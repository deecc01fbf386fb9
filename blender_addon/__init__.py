"""Welch bias test inside Blender: register and unregister only.

The submodules are imported on registration so ``python -m blender_addon.build`` runs without importing bpy.
"""

import importlib

_MODULES = ("preferences", "properties", "operators", "ui", "overlay")


def _modules():
    return [importlib.import_module(f".{name}", __package__) for name in _MODULES]


def register():
    for module in _modules():
        module.register()


def unregister():
    for module in reversed(_modules()):
        module.unregister()
