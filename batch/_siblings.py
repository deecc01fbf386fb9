"""welch_core, reached the same way wherever batch runs."""

try:  # inside the Blender extension: welch_core is a sibling package
    from .. import welch_core
except ImportError:  # imported top-level from the repository (python -m batch, pytest)
    import welch_core

__all__ = ["welch_core"]
