"""``python -m batch ARGS``: see batch.cli. A failure before the tool runs (a broken installation) exits 4, not 1,
which is the exit code of a `biased` verdict."""

import sys

try:
    from .cli import main
except BaseException as exc:  # any failure to start is internal
    print(f"error: internal error: the batch tool can't start: {type(exc).__name__}: {exc}", file=sys.stderr)
    sys.exit(4)

sys.exit(main())
