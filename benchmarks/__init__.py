"""Benchmarks of the tool: the charts of docs/benchmarks/README.md and the studies beside them, run from the
repository root.

``python -m benchmarks`` regenerates the charts, CSVs and README in ``docs/benchmarks/`` (``--quick`` is the small
CI version, ``--help`` lists the charts and the studies). Render pools and trial results are cached in
``benchmarks/cache/``. Three subpackages:

- ``charts``: one module per chart (``run`` measures and draws it, ``section`` writes its part of the README).
- ``common``: what the charts and the studies share: pools of rendered passes, what is rendered (``plan``), trials
  and simulated `check` runs, the cache, plots and CSV files, the words of the README and its writer. It imports
  no chart and no study.
- ``studies``: one-off measurements, each its own command, ``python -m benchmarks.studies.<name>``.

No chart imports another chart, and no study imports a chart or another study: what two of them share is in
``common``. All of them use batch and welch_core by public names only: welch_core's top-level names
(``welch_core.__all__``) and the names without a leading underscore of batch's modules
(``batch.<subpackage>.<module>``). The exception is ``common/whatif``, the what-ifs that switch a piece of
welch_core off for a measurement: it replaces public functions in welch_core's modules, where they are looked up.
"""
