"""Passes per second against the number of Dask workers on this machine, the start-up cost of a worker, and a
model of the speed-up on N machines.

Run from the repository root (needs the ``workers`` extra)::

    python -m benchmarks.studies.workers                      # corner scene, 64x64, 16 spp a pass, 96 passes, twice
    python -m benchmarks.studies.workers --passes 192 --spp 32 --workers 1 2

Measured, each on a fresh statistics file: one process without Dask (``python -m batch render``, Cycles' threads
on every core), then ``render_distributed`` with a LocalCluster of 1, 2, ... workers (one Dask thread each, the
cores split among their render processes). For each: the wall time, passes per second end to end (start-up
included) and in steady state (after each worker's first chunk), the cluster's start-up and each worker's render
process start-up (importing bpy, building the scene: its first chunk's time less its passes' render time).

The model: a run of P passes on N machines takes ``T(N) = C + R + P * t / N`` where C is starting (or reaching) the
cluster, R a worker's render start-up (the workers start in parallel) and t a worker's steady seconds per pass
with all of a machine's cores, its chunk overhead o a pass included (measured here with one worker); one process
takes ``S + P * (t - o)``, S its start-up. Its own measured pass time t1 is printed but not used: on a shared
machine the speed drifts more between runs than Dask costs a pass. The speed-up ``(S + P * (t - o)) / T(N)`` is
printed for a few P and N with the assumptions it rests on.

Nothing is asserted: the figures go into docs/manual.md (Rendering on several processes or machines). The machine
may be shared: repeat before trusting a difference of a few per cent.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import tempfile
import time

from batch.jobs import distributed
from batch.jobs.distributed import PassPool, default_chunk, local_threads
from batch.jobs.job import RenderJob
from batch.jobs.side import run_job
from batch.present.progress import Progress

MACHINES = (1, 2, 4, 8, 16, 64)
RUN_PASSES = (1_000, 10_000)


class _Quiet(Progress):
    """Progress that keeps its events instead of printing them."""

    def __init__(self, total: int):
        super().__init__(total, live=False)
        self.events: list = []

    def emit(self, event) -> None:
        self.events.append(event)


def one_process(job: RenderJob) -> dict:
    """``python -m batch render`` in one process: wall time, start-up (wall less the passes' own seconds)."""
    progress = _Quiet(len(job.seeds))
    start = time.perf_counter()
    run_job(job, progress)
    wall = time.perf_counter() - start
    seconds = [e.seconds for e in progress.events if type(e).__name__ == "PassDone"]
    return {"wall": wall, "startup": wall - sum(seconds), "per_pass": statistics.mean(seconds), "passes": len(seconds)}


def pool_run(job: RenderJob, workers: int, chunk: int) -> dict:
    """The passes of `job` on a LocalCluster of `workers`, in chunks of `chunk`, timed from before the cluster."""
    start = time.perf_counter()
    with distributed.cluster(workers, None) as where, PassPool(job, where) as pool:
        cluster = time.perf_counter() - start
        for first in range(0, len(job.seeds), chunk):
            pool.submit(job.seeds[first : first + chunk])
        arrivals = [(time.perf_counter() - start, result) for result in pool]
    wall = arrivals[-1][0]
    by_worker: dict[str, list] = {}
    for _arrived, result in arrivals:
        by_worker.setdefault(result.worker, []).append(result)
    # A worker's first chunk includes starting its render process; the later ones are its steady state.
    startups = [chunks[0].wall_seconds - sum(chunks[0].seconds) for chunks in by_worker.values()]
    later = {worker: chunks[1:] for worker, chunks in by_worker.items() if len(chunks) > 1}
    rates = [sum(len(r.seeds) for r in chunks) / sum(r.wall_seconds for r in chunks) for chunks in later.values()]
    overheads = [r.wall_seconds - sum(r.seconds) for chunks in later.values() for r in chunks]
    return {
        "wall": wall,
        "cluster": cluster,
        "render_startup": statistics.mean(startups),
        "rate": sum(len(r.seeds) for _, r in arrivals) / wall,
        "steady": sum(rates) if rates else math.nan,
        "per_pass": len(rates) / sum(rates) if rates else math.nan,  # one worker's seconds a pass
        "chunk_overhead": statistics.mean(overheads) if overheads else math.nan,
        "chunk": chunk,
        "bytes": max(r.sums.nbytes + (0 if r.pixel_sum is None else r.pixel_sum.nbytes) for _, r in arrivals),
    }


def _medians(found: list[dict]) -> dict:
    return {key: statistics.median(row[key] for row in found) for key in found[0]}


def speedup(s: float, c: float, r: float, t: float, o: float, passes: int, machines: int) -> float:
    """One process (start-up `s`, `t - o` a pass) against `machines` workers (`c + r` start-up, `t` a pass each)."""
    return (s + passes * (t - o)) / (c + r + passes * t / machines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.studies.workers", description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="corner")
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--tile", type=int, default=16)
    parser.add_argument("--passes", type=int, default=96)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--chunk", type=int, help="passes per chunk (default: 4 chunks a worker, as --workers)")
    parser.add_argument("--repeats", type=int, default=2, help="interleaved repeats; medians are printed")
    args = parser.parse_args(argv)

    cores = local_threads(1)
    print(
        f"{args.scene} {args.resolution}x{args.resolution}, {args.spp} spp a pass, {args.passes} passes, "
        f"{cores} cores, medians of {args.repeats} interleaved repeats; Python {sys.version.split()[0]}"
    )
    with tempfile.TemporaryDirectory() as folder:

        def job(name: str) -> RenderJob:
            return RenderJob(
                out=os.path.join(folder, f"{name}.npz"),
                seeds=tuple(range(args.passes)),
                spp=args.spp,
                scene=args.scene,
                tile=args.tile,
                resolution=(args.resolution, args.resolution),
            )

        # Interleaved repeats, medians: the machine may be shared, and its speed drifts.
        singles, runs = [], {w: [] for w in args.workers}
        for repeat in range(args.repeats):
            singles.append(one_process(job(f"one-{repeat}")))
            for w in args.workers:
                runs[w].append(pool_run(job(f"w{w}-{repeat}"), w, args.chunk or default_chunk(args.passes, w)))
        single = _medians(singles)
        rows = {w: _medians(found) for w, found in runs.items()}

    print()
    print(f"{'':34} {'wall s':>7} {'passes/s':>9} {'steady':>8} {'cluster s':>10} {'render start s':>15}")
    rate = single["passes"] / single["wall"]
    print(
        f"{'one process, no Dask (' + str(cores) + ' threads)':34} {single['wall']:7.2f} {rate:9.2f} "
        f"{1 / single['per_pass']:8.2f} {'-':>10} {single['startup']:15.2f}"
    )
    for workers, row in rows.items():
        name = f"{workers} worker{'s' if workers > 1 else ''} x {local_threads(workers)} threads"
        print(
            f"{name:34} {row['wall']:7.2f} {row['rate']:9.2f} {row['steady']:8.2f} {row['cluster']:10.2f} "
            f"{row['render_startup']:15.2f}"
        )
    base = rows[min(rows)]
    for workers, row in rows.items():
        if workers != min(rows):
            print(
                f"  {workers} workers against {min(rows)}: {row['rate'] / base['rate']:.2f}x end to end, "
                f"{row['steady'] / base['steady']:.2f}x in steady state"
            )
    print(
        f"  chunk overhead (request, save and read the chunk file, Dask): {base['chunk_overhead'] * 1000:.0f} ms; "
        f"largest chunk result {base['bytes'] / 1024:.0f} KiB"
    )

    c, r, t = base["cluster"], base["render_startup"], base["per_pass"]
    o, one = base["chunk_overhead"] / base["chunk"], single["startup"]
    print()
    print("Model: T(N) = C + R + P * t / N   against one process S + P * (t - o)")
    print(f"  C = {c:.2f} s  starting the cluster (LocalCluster here; reaching a running one: ~0)")
    print(f"  R = {r:.2f} s  a worker's render start-up (import bpy, build the scene), all workers in parallel")
    print(f"  t = {t * 1000:.1f} ms a pass of one worker with all {cores} cores, steady state, o included")
    print(f"  o = {o * 1000:.2f} ms a pass: the chunk overhead ({base['chunk']} passes a chunk)")
    t1 = single["per_pass"] * 1000
    print(f"  S = {one:.2f} s  one process's start-up (its own pass time t1 = {t1:.1f} ms is not used)")
    print(f"Predicted speed-up over one process on N machines like this one ({args.scene}, {args.resolution}^2):")
    print(f"  {'passes':>8} " + " ".join(f"{f'N={n}':>7}" for n in MACHINES))
    for passes in RUN_PASSES:
        print(f"  {passes:8d} " + " ".join(f"{speedup(one, c, r, t, o, passes, n):7.1f}" for n in MACHINES))
    print("Assumptions: every machine is like this one and runs one worker with all its cores; passes take the same")
    print("time everywhere; P is many chunks per worker, so chunks balance and the last one ends with the others;")
    print("the client (accumulating, checkpoints) and the network keep up (a chunk's result is its tile sums and")
    print("one pixel sum); the .blend and its textures are already on every machine; no worker dies.")
    return 0


if __name__ == "__main__":  # the workers are spawned processes that import this module: run only in the parent
    sys.exit(main())
