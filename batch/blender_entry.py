"""Run the batch tool inside Blender; the tool's arguments follow ``--``:

    blender -b SCENE.blend --python-exit-code 4 --python batch/blender_entry.py -- render --seeds 0:64 --spp 1 \
        --out ref.npz

The folder that holds ``batch`` and ``welch_core`` (the repository, or the installed extension) is put on sys.path
so both import as top-level packages; the process exits with the tool's exit code. Rendering needs nothing a
stock Blender (3.4 or later) lacks: numpy is bundled, and scipy is imported only by commands that compare.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

if __name__ == "__main__":
    from batch.errors import Exit  # the standard library only: it imports where the tool can't

    try:
        from batch.cli import argv_after_dashdash, main
    except ModuleNotFoundError as exc:  # this Blender's Python, not the tool: Debian's blender needs python3-numpy
        print(f"error: this Blender's Python {sys.version.split()[0]} has no module {exc.name!r}, which the tool "
              f"needs (Debian's blender package: apt-get install python3-{exc.name})", file=sys.stderr)  # fmt: skip
        sys.exit(Exit.USAGE)
    except BaseException as exc:  # any other failure to start is internal
        print(f"error: internal error: the batch tool can't start: {type(exc).__name__}: {exc}", file=sys.stderr)
        sys.exit(Exit.INTERNAL)
    sys.exit(main(argv_after_dashdash(sys.argv)))
