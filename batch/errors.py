"""The batch tool's one exception for bad input: a message of one line for the user, exit code 2."""

from __future__ import annotations


class BatchError(Exception):
    """A job that can't start or go on because of its input (a file, an argument, a scene); one line for the user.

    welch_core's own input errors (`welch_core.WelchInputError`) and failed file operations (`OSError`) are
    input errors too; the command line treats all three alike.
    """
