"""The command line: ``python -m batch COMMAND`` (and the same arguments after ``--`` inside Blender). The
parser and the commands are in ``commands``; ``demo`` is the main job on the built-in default scene.

May import every other part of batch: it is where they meet.
"""

from .commands import COMMANDS, argv_after_dashdash, build_parser, main

__all__ = ["COMMANDS", "argv_after_dashdash", "build_parser", "main"]
