"""``python -m batch ARGS`` and the ``welch-bias`` command: see batch.cli. A failure before the tool runs (a broken
installation) exits `Exit.INTERNAL`, not `Exit.BIASED`, the exit code of a `biased` verdict; Ctrl-C or SIGTERM
exits `Exit.INTERRUPTED` in one line from the first line of `run` on, also while the tool's modules import
(`batch.jobs.protocol.Interrupts`, standard library only like `batch.errors`)."""

import logging
import os
import sys

# numpy asks the kernel for huge pages for every array of 4 MB or more. Where the kernel then compacts memory to find
# them (transparent_hugepage/defrag "madvise", its default), a new array's first write can stall 50-100 ms on a
# machine that has run for a while: measured, `compare` at 1024x576 with pixel moments took 0.27-0.71 s with them
# and 0.33 s without, every time. Before numpy is imported; inherited by the processes the tool starts.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

from .errors import INTERRUPTED_LINE, Exit


def run() -> int:
    code = _run()
    if code == Exit.INTERRUPTED:
        _handled_interrupt()
    return code


def _handled_interrupt() -> None:
    """The process was interrupted and said so: what the interrupt left half done says nothing more on the way
    out (a Dask cluster it cut short in its start, closed at exit, fails and logs), and CPython is told that the
    interrupt was handled. It ends a process by SIGINT at its exit, whatever the process returns, once a
    KeyboardInterrupt left code run with ``PyRun_String`` (pybind11 modules, scipy's among them, run their
    initialisation so, and an interrupt there surfaces as an ImportError or is swallowed), and the next such run
    forgets it. Where that can't be done, a shell still sees 130 (128 + SIGINT)."""
    logging.disable(logging.CRITICAL)
    sys.unraisablehook = lambda _unraisable: None
    try:
        import ctypes

        ctypes.pythonapi.PyRun_SimpleString(b"pass")
    except (ImportError, AttributeError, OSError):
        pass


def _run() -> int:
    interrupts, started = None, False
    try:
        from .jobs.protocol import Interrupts

        with (interrupts := Interrupts()):
            # An interrupt while the tool's modules import waits for the imports' end: raised inside the import
            # machinery's own C code, it is printed there as a traceback before it reaches the handler below.
            with Interrupts.held():
                from .cli import main

            started = True
            code = main()  # which answers its own interrupts and errors
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt) or (interrupts is not None and interrupts.interrupted(exc)):
            print(INTERRUPTED_LINE, file=sys.stderr)
            return Exit.INTERRUPTED
        if started or isinstance(exc, SystemExit):
            raise
        # any other failure to start is internal
        print(f"error: internal error: the batch tool can't start: {type(exc).__name__}: {exc}", file=sys.stderr)
        return Exit.INTERNAL
    if code != Exit.INTERRUPTED and interrupts.interrupted():  # came while the tool imported, and was swallowed
        print(INTERRUPTED_LINE, file=sys.stderr)
        return Exit.INTERRUPTED
    return code


if __name__ == "__main__":
    sys.exit(run())
