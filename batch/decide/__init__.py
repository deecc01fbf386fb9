"""Runs that decide: ``check`` renders both sides in chunks until welch_core's looks decide, and ``suite`` keeps
statistical regression suites (references, runs, outputs for CI) on top of it. The renders run in their own
processes through ``batch.jobs``; the verdicts are welch_core's and their words ``batch.present``'s.

May import ``batch.jobs`` and ``batch.present``; never bpy or ``batch.blender``.
"""
