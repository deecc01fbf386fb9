"""What the add-on uses of the sibling packages ``welch_core`` and ``batch``, imported here with plain imports so
its dependencies show in one place: relative inside the extension (this package is
``bl_ext.<repository>.<id>.blender_addon``, and the add-on Blender knows is its parent), top-level from the
repository, where pytest imports this package on its own. Only light modules are imported at registration (no
bpy rendering code, no scipy): `check` and `pipeline` are imported when first used.
"""

import importlib
from typing import TYPE_CHECKING

try:
    from .. import welch_core
    from ..batch import errors
    from ..batch.jobs import job, launch, lobes, options, overrides, protocol, rna, samples, seeds
    from ..batch.present import fmt
except ImportError:  # top-level from the repository: there is no parent package
    import welch_core
    from batch import errors
    from batch.jobs import job, launch, lobes, options, overrides, protocol, rna, samples, seeds
    from batch.present import fmt

#: The add-on's module name as Blender knows it (the extension's root package, or this package in tests).
ADDON_MODULE = __package__.rpartition(".")[0] or __package__


if TYPE_CHECKING:  # what an editor's go-to-definition follows; at run time `__getattr__` imports them
    from batch.decide import check
    from batch.present import pipeline

#: The heavy modules, imported when first used (`__getattr__`): the check engine (batch.decide.check) when a run
#: starts, a comparison's way to people (batch.present.pipeline: the assessment, its summary) when a result is made.
_LATER = {"check": "batch.decide.check", "pipeline": "batch.present.pipeline"}


def __getattr__(name: str):
    """A module of `_LATER`, imported on first use: ``_siblings.check``."""
    if name not in _LATER:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    root = __package__.rpartition(".")[0]  # the extension's root package; none in the repository
    return importlib.import_module(f"{root}.{_LATER[name]}" if root else _LATER[name])


__all__ = [
    "ADDON_MODULE",
    "check",
    "errors",
    "fmt",
    "job",
    "launch",
    "lobes",
    "options",
    "overrides",
    "pipeline",
    "protocol",
    "rna",
    "samples",
    "seeds",
    "welch_core",
]
