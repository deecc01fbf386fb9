"""Run the batch tool inside Blender; the tool's arguments follow ``--``:

    blender -b SCENE.blend --python-exit-code 1 --python batch/blender_entry.py -- render --seeds 0:64 --spp 1 \
        --out ref.npz

The folder that holds ``batch`` and ``welch_core`` (the repository, or the installed extension) is put on sys.path
so both import as top-level packages; the process exits with the tool's exit code.
"""

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from batch.cli import argv_after_dashdash, main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(argv_after_dashdash(sys.argv)))
