"""The batch tool's exit codes, its exception for bad input and for a renderer that failed (a message of one line
for the user, exit code 2), and for a run that ended with too little to decide on (exit code 3). Standard library
only: the entry points read the exit codes even when nothing else imports."""

from __future__ import annotations

import enum


class BatchError(Exception):
    """A job that can't start or go on because of its input (a file, an argument, a scene); one line for the user.

    welch_core's own input errors (`welch_core.WelchInputError`) and failed file operations (`OSError`) are
    input errors too; the command line treats all three alike.
    """


class RendererFailed(BatchError):
    """A renderer (a Blender, a Python with bpy, a render command) ended without the passes asked for: one line
    quoting its own reason where it gave one (`batch.jobs.launch.JobProcess.error_message`)."""


class Undecided(BatchError):
    """A run that ended with too little to decide on (its time budget ended the passes before two a side were
    rendered): `inconclusive`, exit code 3, with one line saying why. The one BatchError that is no input error:
    whoever tells the two apart catches this one first."""


class Exit(enum.IntEnum):
    """The exit code of every process of the tool, one meaning each, so that CI (and the process that started
    a job) can act on it."""

    OK = 0  #: done; `no evidence of bias`; `equivalent`
    BIASED = 1  #: `biased` (lint: a setting that biases the image), and nothing else
    USAGE = 2  #: bad input: an argument, a missing, damaged or foreign file, a scene that can't render, a full disk
    INCONCLUSIVE = 3  #: `inconclusive`; a suite case that can't be confirmed
    INTERNAL = 4  #: an internal error, also when the tool can't even start
    INTERRUPTED = 130  #: Ctrl-C or SIGTERM: what was rendered is kept, ``--resume`` continues


#: What every process of the tool says, in one line on stderr, when Ctrl-C or SIGTERM stopped it (`Exit.INTERRUPTED`).
INTERRUPTED_LINE = "interrupted: the statistics written so far are kept (continue with --resume)"
