"""The batch tool's exception for bad input, and for a renderer that failed: a message of one line for the user,
exit code 2."""

from __future__ import annotations


class BatchError(Exception):
    """A job that can't start or go on because of its input (a file, an argument, a scene); one line for the user.

    welch_core's own input errors (`welch_core.WelchInputError`) and failed file operations (`OSError`) are
    input errors too; the command line treats all three alike.
    """


class RendererFailed(BatchError):
    """A renderer (a Blender, a Python with bpy, a render command) ended without the passes asked for: one line
    quoting its own reason where it gave one (`batch.jobs.launch.JobProcess.error_message`)."""
