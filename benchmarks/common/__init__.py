"""What the charts and the studies share. Nothing here imports a chart or a study.

- ``cache``: the on-disk cache (``benchmarks/cache/``), its keys, and the options every study takes.
- ``pools``: pools of render passes, rendered once with the batch tool's own code.
- ``plan``: what is rendered and how many trials are drawn (the full run and the quick one): the bias cases, the
  unbiased pairs, the sparse cases.
- ``trials``: trials drawn from pools, the detection methods they run, rates with their intervals.
- ``fixed_designs``: every fixed design on the bias cases (chart 1's trials; charts 5 and 7 compare against them).
- ``checks``: `check` simulated on pools, look by look.
- ``measure``: the best of several wall times, and mpmath's exact Student-t p-value.
- ``plotting``: matplotlib without a display, CSV files, the colours of the methods.
- ``words``: how figures are written in the README; ``readme``: the README's writer.
- ``whatif``: the tool with one piece switched off (a what-if, or the tool before a change), for a measurement.
"""
