"""``python -m batch ARGS`` and the ``welch-bias`` command: see batch.cli. A failure before the tool runs (a broken
installation) exits `Exit.INTERNAL`, not `Exit.BIASED`, the exit code of a `biased` verdict."""

import sys

from .errors import Exit


def run() -> int:
    try:
        from .cli import main
    except BaseException as exc:  # any failure to start is internal
        print(f"error: internal error: the batch tool can't start: {type(exc).__name__}: {exc}", file=sys.stderr)
        return Exit.INTERNAL
    return main()


if __name__ == "__main__":
    sys.exit(run())
