"""Render jobs and the processes that run them: the job and the declaration of its options (``job``), seeds,
layers (``lobes``), property overrides, the process protocol every sender and receiver shares (``protocol``:
progress events, chunk requests, exit codes), starting a job in another process (``launch``) and the one driver
of a render side (``side``), output locks, accumulating passes (``passes``) and Dask workers (``distributed``).

May import ``batch.errors`` and welch_core's numpy-only modules. Never bpy (``overrides.apply_overrides`` works on
the scene it is given), never scipy, and nothing of ``blender``, ``present``, ``decide`` or ``cli``.
"""
