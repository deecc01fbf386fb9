"""Benchmarks: run one with ``python -m benchmarks.<name>`` from the repository root.

``python -m benchmarks`` regenerates the charts, CSVs and README in ``docs/benchmarks/`` (detection rate against
render time, p-value methods, stability on unbiased pairs, cost); ``--quick`` is the small CI version. Render pools
and trial results are cached in ``benchmarks/cache/``.
"""
