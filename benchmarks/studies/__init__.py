"""One-off measurements beside the charts, each its own command run from the repository root,
``python -m benchmarks.studies.<name>`` (``--help`` for its options; most take ``--quick``, which checks the
pipeline in minutes). Their figures and findings are quoted in README.md, docs/benchmarks/README.md and
docs/findings/.

- ``core_speed``: speed and precision of welch_core's statistics, as ratios.
- ``speed``: the tool's four speed goals, each against a baseline measured in the same run.
- ``workers``: passes per second against the number of Dask workers, and a model of the speed-up on N machines.
- ``production``: a production-size `check`: where its wall time goes besides rendering.
- ``suite_cases``: whether each case of the built-in suite does its job at its size and budget.
- ``unequal``: `biased` on unbiased pairs whose sides differ in passes, before and after the permutation test.
- ``futility``: the futility stop of `equivalent`: the passes it saves and the verdicts it gives away.
- ``sparse``: changes that alter a few light paths: the paired test alone, Welch's test and the default.
- ``power``: passes a side to `biased`: `check` against the best fixed design and a matched-filter oracle.
- ``moderated``: moderated variances (limma's empirical Bayes) against `check`'s t-tests at small n.
- ``pixel_variance``: a tile's variance from its pixels' variances (issue 32): calibration, the dependence ratio
  D, broken sampling settings and power, against the tile test.
- ``blue_noise_volume``: Cycles' blue-noise pattern against Tabulated Sobol on a cube of fog, the measurement
  behind docs/findings/blue_noise_volume.md (a finding about a renderer, not a benchmark of this tool).
- ``sample_dependent``: the sample count per render from which each Cycles setting of `batch.jobs.samples` acts,
  the measurement behind docs/findings/sample_dependent.md.
"""
