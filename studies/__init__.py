"""Findings studies: measurements that pinned down a behaviour of a renderer, each written up in docs/findings/
with the commands that reproduce it. Not benchmarks of this tool (those are in benchmarks/); they use the tool
through its public modules only."""
