"""Run the batch tool inside Blender, or in another environment's Python with bpy; the tool's arguments follow
``--``:

    blender -b SCENE.blend --python-exit-code 4 --python batch/blender_entry.py -- render --seeds 0:64 --spp 1 \
        --out ref.npz
    /opt/bpy-4.5/bin/python batch/blender_entry.py -- render --scene corner --seeds 0:64 --spp 1 --out ref.npz

The tool's own packages, ``batch`` and ``welch_core``, import as top-level packages from the folder that holds
them (the repository, the installed extension, or an installed tool's site-packages), and nothing else of that
folder does: in a pip-installed tool it is a venv's site-packages, whose numpy is built for another Python than
the Blender's. Everything else (numpy) comes from the Blender's own Python. The process exits with the tool's exit
code. Rendering needs nothing a stock Blender (3.4 or later) lacks: numpy is bundled (Debian's blender package
needs python3-numpy), and scipy is imported only by commands that compare. A Python that can't import what the
tool needs ends in one line naming that Blender and its Python, exit 2.
"""

from __future__ import annotations

import importlib.machinery
import os
import sys

#: The folder that holds the tool's packages, and the packages imported from it (only these).
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGES = ("batch", "welch_core")

# Run as a plain script (``python batch/blender_entry.py``), Python puts the script's folder first on sys.path,
# which would make batch's modules top-level names: it goes (Blender puts nothing there).
if sys.path and sys.path[0] and os.path.abspath(sys.path[0]) == os.path.join(ROOT, "batch"):
    del sys.path[0]


class ToolPackages:
    """A finder of `PACKAGES` in `ROOT`, and of nothing else: ROOT itself never goes on sys.path."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        if path is None and name in PACKAGES:
            return importlib.machinery.PathFinder.find_spec(name, [ROOT])
        return None


sys.meta_path.insert(0, ToolPackages)


def missing_module(exc: BaseException) -> str | None:
    """The top-level module an import failed at (numpy for numpy's own "No module named 'numpy._core...'" under
    a message of its own), from `exc` or the exceptions it was raised from; None: none named."""
    while exc is not None:
        name = getattr(exc, "name", None)
        if name:
            return name.split(".")[0]
        exc = exc.__cause__ or exc.__context__
    return None


def this_blender() -> str:
    """This Blender and its Python, for a message: ``Blender 5.2.2 LTS (/usr/bin/blender) runs Python 3.14.1
    (/usr/bin/python3.14)``, or a Python with the bpy module (``Python 3.13.0 (PATH) with bpy 5.2.3 LTS``). The
    Python is named by its executable where that lies in its prefix, else by its prefix (Debian's Blender 3.4
    reports whichever python3.11 is first on PATH)."""
    inside = bool(sys.executable) and os.path.abspath(sys.executable).startswith(os.path.abspath(sys.prefix) + os.sep)
    python = f"Python {sys.version.split()[0]} ({sys.executable if inside else f'in {sys.prefix}'})"
    try:
        import bpy

        version, binary = bpy.app.version_string, bpy.app.binary_path
    except Exception:
        return f"this Blender runs {python}"
    if not binary:  # the bpy module in a Python of its own
        return f"{python} with bpy {version}"
    return f"Blender {version} ({binary}) runs {python}"


def cannot_start(message: str, argv: list[str]) -> None:
    """Say `message` in one line on stderr, and as the job's error event where its starter reads events."""
    print(f"error: {message}", file=sys.stderr)
    if "--json-progress" in argv:
        from batch.jobs import protocol  # the standard library only

        print(protocol.to_line(protocol.Failed(message)), flush=True)


if __name__ == "__main__":
    from batch.errors import Exit  # the standard library only: it imports where the tool can't

    tail = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    try:
        from batch.cli import argv_after_dashdash, main
    except ImportError as exc:  # this Blender's Python, not the tool: Debian's blender needs python3-numpy
        module = missing_module(exc)
        if module is None or module in PACKAGES:
            cannot_start(f"internal error: the batch tool can't start: {type(exc).__name__}: {exc}", tail)
            sys.exit(Exit.INTERNAL)
        cause = exc
        while cause.__cause__ or cause.__context__:  # the innermost reason, not numpy's page of advice
            cause = cause.__cause__ or cause.__context__
        reason = str(cause).strip().splitlines()[0] if str(cause).strip() else type(cause).__name__
        cannot_start(
            f"{this_blender()}, which can't import {module} ({reason}): install {module} for that Python "
            f"(Debian's blender package: apt-get install python3-{module})",
            tail,
        )
        sys.exit(Exit.USAGE)
    except BaseException as exc:  # any other failure to start is internal
        cannot_start(f"internal error: the batch tool can't start: {type(exc).__name__}: {exc}", tail)
        sys.exit(Exit.INTERNAL)
    sys.exit(main(argv_after_dashdash(sys.argv)))
