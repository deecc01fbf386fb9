"""The sibling packages ``welch_core`` and ``batch``, and the add-on's module name, wherever this package sits.

Inside the extension this package is ``bl_ext.<repository>.<id>.blender_addon`` and the add-on Blender knows is its
parent; pytest imports it top-level from the repository, where the add-on is this package itself.
"""

if "." in __package__:  # inside the extension: welch_core and batch are sibling packages
    from .. import batch, welch_core
    from ..batch import seeds as _seeds  # noqa: F401  (makes batch.seeds an attribute of batch)

    ADDON_MODULE = __package__.rpartition(".")[0]
else:  # imported top-level from the repository (tests)
    import batch
    import batch.seeds
    import welch_core

    ADDON_MODULE = __package__

__all__ = ["ADDON_MODULE", "batch", "welch_core"]
