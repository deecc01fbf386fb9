"""Headless batch tool: render Cycles passes with different seeds, compare runs, report bias.

The subpackages are the tool's roles; each says in its docstring what it may import, and no import goes the other
way (there are no import circles):

- ``jobs``: what a render job is and how it runs in other processes: the job and its options, seeds, layers,
  overrides, the process protocol (events, chunk requests, exit codes), the driver of a render side, locks, the
  Dask workers. No bpy, no scipy, nothing of the other roles.
- ``blender``: the bpy side, run inside Blender or the bpy module: scenes, the unbiased settings, passes, lint.
  May import ``jobs`` and ``present.progress``.
- ``present``: everything people read: numbers in words, the verdict's sentence, the summary, the report page,
  the dashboard, JUnit, progress lines. Reads welch_core's outcome and decides nothing. May import ``jobs``'s
  protocol and definitions.
- ``decide``: runs that decide: ``check`` (render until decided) and regression suites. May import ``jobs`` and
  ``present``.
- ``cli``: the command line, which may import everything.

``errors`` (the exit codes and the one input error) and ``_siblings`` (welch_core, wherever batch sits) serve them all.
"""
