"""The charts of docs/benchmarks/README.md, one module each, in the order ``python -m benchmarks`` runs them:

1. ``detection``: detection rate against render seconds, per bias case and method, and the false-positive rates.
2. ``pvalues``: the p-value methods, time against their largest relative error.
3. ``stability``: unbiased pairs where the methods fail: calibrated, or flagged.
4. ``cost``: how the cost grows with resolution, passes and tiles; the pipeline's overhead.
5. ``decision``: render seconds to a decision, `check` against the best fixed design.
6. ``aa``: A/A runs of `check`, rendered until decided.
7. ``scales``: every tile scale at once against each fixed tile size.
8. ``equivalence``: the passes `check` needs to reach `equivalent` at each scale, against an oracle.

Each module has ``run(budget, cache_dir, out_dir)``, which measures (or reads back from the cache), writes its CSV
files and PNG into ``out_dir`` and returns its figures, and ``section(figures)``, its lines of the README. A chart
imports ``benchmarks.common``, never another chart.
"""
