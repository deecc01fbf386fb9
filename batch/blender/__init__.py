"""The bpy side: what runs inside Blender or the bpy module. Scenes (the built-in ones and .blend files), the
unbiased render settings and their record (``render``), rendering a job's passes with checkpoints and resume
(``run``), and the settings that bias an image (``lint``).

May import bpy, ``batch.jobs`` and ``batch.present.progress``; nothing else of batch. Only the command line
and the render processes it starts import this package.
"""
