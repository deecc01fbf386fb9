"""The sibling packages ``welch_core`` and ``batch``, and the add-on's module name, wherever this package sits.

Inside the extension this package is ``bl_ext.<repository>.<id>.blender_addon`` and the add-on Blender knows is its
parent; pytest imports it top-level from the repository, where the add-on is this package itself. Only the light
modules of ``batch`` are imported here (no bpy rendering code, no scipy): registering must stay instant.
"""

import importlib

if "." in __package__:  # inside the extension: welch_core and batch are sibling packages
    _PARENT = __package__.rpartition(".")[0]
    ADDON_MODULE = _PARENT
else:  # imported top-level from the repository (tests)
    _PARENT = ""
    ADDON_MODULE = __package__


def _sibling(name: str):
    return importlib.import_module(f"{_PARENT}.{name}" if _PARENT else name)


welch_core = _sibling("welch_core")
batch = _sibling("batch")
for _module in ("errors", "events", "fmt", "job", "launch", "overrides", "rna", "seeds"):
    _sibling(f"batch.{_module}")  # makes batch.<module> an attribute of batch

__all__ = ["ADDON_MODULE", "batch", "welch_core"]
