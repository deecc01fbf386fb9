"""``python -m batch ARGS``: see batch.cli."""

import sys

from .cli import main

sys.exit(main())
