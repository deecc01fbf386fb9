"""What the add-on uses of the sibling packages ``welch_core`` and ``batch``, imported here with plain imports so
its dependencies show in one place: relative inside the extension (this package is
``bl_ext.<repository>.<id>.blender_addon``, and the add-on Blender knows is its parent), top-level from the
repository, where pytest imports this package on its own. Only light modules are imported at registration (no
bpy rendering code, no scipy): `presenting` imports what makes a result, when one is made.
"""

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


def presenting():
    """A comparison's way to people (batch.present.pipeline: the assessment, its summary), imported when a
    result is made."""
    try:
        from ..batch.present import pipeline
    except ImportError:
        from batch.present import pipeline
    return pipeline


def checking():
    """The check engine (batch.decide.check), imported when a run starts."""
    try:
        from ..batch.decide import check
    except ImportError:
        from batch.decide import check
    return check


__all__ = [
    "ADDON_MODULE",
    "checking",
    "errors",
    "fmt",
    "job",
    "launch",
    "lobes",
    "options",
    "overrides",
    "presenting",
    "protocol",
    "rna",
    "samples",
    "seeds",
    "welch_core",
]
