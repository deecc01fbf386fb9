"""Distributed rendering on a Dask cluster (batch.jobs.distributed): the chunk protocol and the worker's result
round-trip, the statistics of N workers equal one process's, a render process or a worker killed in the middle of its
chunk costs only that chunk, Ctrl-C keeps what arrived and --resume completes it, a SLURM job script asks for the GPU.

Skipped without the ``workers`` extra (dask[distributed], dask-jobqueue).
"""

import json
import os
import pickle
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

distributed = pytest.importorskip("distributed", reason="needs the workers extra: pip install -e '.[workers]'")

import welch_core as wc  # noqa: E402
from batch.errors import BatchError  # noqa: E402
from batch.jobs import distributed as dist  # noqa: E402
from batch.jobs import protocol  # noqa: E402
from batch.jobs.job import RenderJob  # noqa: E402
from batch.jobs.protocol import ChunkRequest, parse_request  # noqa: E402
from batch.jobs.side import run_job  # noqa: E402
from batch.present.progress import Progress  # noqa: E402
from tests.helpers.renderers import NanEverySecondPass  # noqa: E402

#: A job of passes slow enough (~0.05-0.1 s each here) that a chunk of 6 can be caught in the middle.
SEEDS = tuple(range(24))
CHUNK = 6


def make_job(out, **changes) -> RenderJob:
    job = RenderJob(out=str(out), seeds=SEEDS, spp=16, scene="corner", tile=16, resolution=(64, 64))
    return job.replace(**changes)


class Recorder(Progress):
    """Progress that keeps its events (and calls `on_pass` after each pass)."""

    def __init__(self, total: int, on_pass=None):
        super().__init__(total, live=False)
        self.events: list = []
        self.on_pass = on_pass

    def emit(self, event) -> None:
        self.events.append(event)

    def pass_done(self, seed: int, seconds: float) -> None:
        super().pass_done(seed, seconds)
        if self.on_pass is not None:
            self.on_pass(seed)


def assert_same_statistics(got: wc.TileStats, reference: wc.TileStats) -> None:
    """Same passes in the same order: the per-pass tile sums are bit-identical (the same images, whichever process
    and however many threads rendered them); the pixel sums agree to float32 rounding of the sum's order."""
    assert got.seeds == reference.seeds
    got.same_run(reference)
    np.testing.assert_array_equal(got.sums, reference.sums)
    np.testing.assert_array_equal(got.mean, reference.mean)
    np.testing.assert_array_equal(got.m2, reference.m2)
    np.testing.assert_allclose(got.pixel_sum, reference.pixel_sum, rtol=1e-5, atol=1e-5)


# -- what crosses between processes ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "request_", [ChunkRequest((4, 5, 6), "/dev/shm/chunk-3.npz"), ChunkRequest((7,), "out dir/ünï.npz")]
)
def test_chunk_request_round_trips(request_):
    line = request_.to_line()
    assert "\n" not in line
    assert parse_request(line) == request_
    assert parse_request(line + "\n") == request_


@pytest.mark.parametrize(
    "line, expected",
    [
        ("8\n", 8),
        (" 3 ", 3),
        ("", None),
        ("stop", None),
        ('{"seeds": [1, 2]}', None),
        ('{"seeds": [1, true], "out": "x.npz"}', None),
        ('{"seeds": [1, 2.5], "out": "x.npz"}', None),
        ('{"seeds": 1, "out": "x.npz"}', None),
        ('{"seeds": [1], "out": ""}', None),
        ('{"seeds": [1], "out": "x.npz", "more": 1}', None),
        ('{"seeds": [1], "out": "x.npz"', None),
    ],
)
def test_a_request_line_is_a_count_a_chunk_or_the_end(line, expected):
    assert parse_request(line) == expected


def test_chunk_result_round_trips():
    rng = np.random.default_rng(14)
    info = wc.RunInfo(spp=4, renderer="Cycles", scene="corner", settings={"cycles.max_bounces": 12})
    stats = wc.TileStats(40, 48, 16, 3, info)
    for seed in (9, 3, 5):
        stats.add_pass(rng.random((40, 48, 3), dtype=np.float32), seed)
    result = dist.ChunkResult.from_stats(stats, (0.25, 0.5, 0.75), 2.0, ("a warning",), "worker tcp://x:1")
    back = pickle.loads(pickle.dumps(result)).stats()
    assert back.seeds == [9, 3, 5] and back.info == info
    back.same_run(stats)
    np.testing.assert_array_equal(back.sums, stats.sums)
    np.testing.assert_array_equal(back.pixel_sum, stats.pixel_sum)
    assert (back.height, back.width, back.tile) == (40, 48, 16)


def test_a_chunk_handed_over_by_its_file_reads_as_one_sent(tmp_path):
    """A worker on the client's machine leaves its chunk file to the client (`path`): the client reads the same
    passes, moments and layers from it as from a chunk sent whole, and removes the file."""
    rng = np.random.default_rng(15)
    stats = wc.TileStats(40, 48, 16, 3, wc.RunInfo(spp=4, scene="corner"), keep_pixel_moments=True)
    layer = wc.TileStats(40, 48, 16, 3, wc.RunInfo(spp=4, scene="corner"))
    for seed in (9, 3, 5):
        image = rng.random((40, 48, 3), dtype=np.float32)
        stats.add_pass(image, seed)
        layer.add_pass(image / 2, seed)
    path = tmp_path / "chunk-1.npz"
    wc.save_stats(path, stats, {"diffuse": layer})
    sent = dist.ChunkResult.from_stats(wc.load_stats(path), layers=wc.load_layers(path)).arrival()
    light = wc.load_stats(path, pixels=False, moments=False), wc.load_layers(path, pixels=False)
    handed = pickle.loads(pickle.dumps(dist.ChunkResult.from_stats(light[0], layers=light[1], path=path)))
    assert handed.moments is None and handed.pixel_sum is None  # what crosses: the tile sums alone
    arrival = handed.arrival()
    assert not path.exists()
    assert arrival.seeds == sent.seeds == (9, 3, 5)
    np.testing.assert_array_equal(arrival.stats.pixels.mean, sent.stats.pixels.mean)
    np.testing.assert_array_equal(arrival.stats.pixels.m2, sent.stats.pixels.m2)
    np.testing.assert_array_equal(arrival.layers["diffuse"].pixel_sum, sent.layers["diffuse"].pixel_sum)
    # a file that holds other passes than the worker said is refused, and removed all the same
    wc.save_stats(path, stats)
    other = dist.ChunkResult.from_stats(light[0], layers=light[1], worker="worker tcp://x:1", path=path)
    with pytest.raises(wc.StatsFileError, match="the chunk file of worker tcp://x:1 holds other passes than it sent"):
        other.arrival()
    assert not path.exists()
    wc.save_stats(path, stats)
    dist.ChunkResult.from_stats(light[0], path=path).discard()  # a chunk the client drops
    assert not path.exists()


@pytest.mark.parametrize(("policy", "seeds"), [("skip", [4, 6]), ("keep", [3, 4, 5, 6])])
def test_a_served_chunk_holds_exactly_its_seeds(tmp_path, policy, seeds):
    from batch.blender.run import _render_chunk  # imports bpy

    job = make_job(tmp_path / "served.npz", on_nan=policy, seeds=tuple(range(10)))
    like = wc.TileStats(32, 32, 16, 3, wc.RunInfo(spp=16, scene="corner"))
    progress = Recorder(10)
    out = tmp_path / "chunk.npz"
    _render_chunk(job, NanEverySecondPass(), ChunkRequest((3, 4, 5, 6), str(out)), like, progress, None)
    chunk = wc.load_stats(out)
    assert chunk.seeds == seeds and chunk.info == like.info and like.n == 0
    assert progress.events[-1] == protocol.Saved(out=str(out), passes=len(seeds))
    warned = [e.message for e in progress.events if isinstance(e, protocol.Warned)]
    assert len(warned) == (2 if policy == "skip" else 0)


def test_a_served_chunk_that_fails_keeps_its_passes_and_refuses_foreign_seeds(tmp_path):
    from batch.blender.run import RunError, _render_chunk

    job = make_job(tmp_path / "served.npz", seeds=tuple(range(10)))
    like = wc.TileStats(32, 32, 16, 3, wc.RunInfo(spp=16))
    out = tmp_path / "chunk.npz"
    with pytest.raises(RunError, match="pass with seed 5 has 1 non-finite pixel values"):
        _render_chunk(job, NanEverySecondPass(), ChunkRequest((4, 5, 6), str(out)), like, Recorder(10), None)
    assert wc.load_stats(out).seeds == [4]  # the worker drops it: the chunk renders again or the run stops
    with pytest.raises(RunError, match="a chunk asks for seed 12, which is not in --seeds of this job"):
        _render_chunk(job, NanEverySecondPass(), ChunkRequest((8, 12), str(out)), like, Recorder(10), None)


class _Finished:
    """Stands in for a finished Dask future."""

    def __init__(self, value):
        self.value = value

    def result(self):
        if isinstance(self.value, Exception):
            raise self.value
        return self.value

    def release(self):
        pass


def _pool_that_finished(*chunks) -> dist.PassPool:
    """A PassPool without a cluster whose chunks (seeds, what the worker sent) have finished, in this order."""
    pool = object.__new__(dist.PassPool)
    futures = [_Finished(value) for _seeds, value in chunks]
    pool._as_completed = futures
    pool._pending = {future: seeds for future, (seeds, _value) in zip(futures, chunks, strict=True)}
    pool._counted = set()
    return pool


def _chunk(seeds, worker="worker tcp://a:1") -> dist.ChunkResult:
    stats = wc.TileStats(32, 32, 16, 3, wc.RunInfo())
    for seed in seeds:
        stats.add_pass(np.full((32, 32, 3), seed, np.float32), seed)
    return dist.ChunkResult.from_stats(stats, worker=worker)


def test_the_pool_hands_back_every_seed_once():
    empty = _chunk(())  # every pass skipped (--on-nan skip): its warnings still come back
    pool = _pool_that_finished(((0, 1), _chunk((0, 1))), ((0, 1), _chunk((0, 1), "worker tcp://b:2")), ((2,), empty))
    assert [r.seeds for r in pool] == [(0, 1), ()]
    pool = _pool_that_finished(((0, 1), _chunk((0, 1))), ((1, 2), _chunk((1, 2))))
    with pytest.raises(dist.ChunkFailed, match=r"worker tcp://a:1 sent back seeds of more than one chunk: \(1, 2\)"):
        list(pool)


def test_the_pool_raises_a_job_error_and_a_chunk_that_failed_twice():
    pool = _pool_that_finished(((4, 5), dist.ChunkError((4, 5), "x.blend: No such file", "worker tcp://a:1")))
    with pytest.raises(BatchError, match="^worker tcp://a:1: x.blend: No such file$"):
        list(pool)
    died = dist.RenderProcessDied("the render process (PID 7) ended with exit code -9")
    pool = _pool_that_finished(((0, 1, 2, 3), died))
    with pytest.raises(dist.ChunkFailed, match="the chunk of seeds 0:4 failed twice: the render process .PID 7."):
        list(pool)


def test_chunk_sizes():
    assert dist.default_chunk(1, 2) == 1
    assert dist.default_chunk(24, 2) == 3  # 4 chunks a worker
    assert dist.default_chunk(100_000, 2) == dist.MAX_CHUNK
    assert dist.default_chunk(10, 0) == 3  # a cluster whose workers are still starting
    assert dist.local_threads(64) == 1


def test_pool_arguments_are_checked_before_anything_starts(tmp_path):
    job = make_job(tmp_path / "x.npz")
    with pytest.raises(BatchError, match="give --workers or --scheduler, not both"):
        with dist.cluster(2, "tcp://127.0.0.1:1"):
            pass
    with pytest.raises(BatchError, match="--chunk must be a positive integer, got 0"):
        dist.render_distributed(job, Recorder(24), dist.Cluster("tcp://127.0.0.1:1"), chunk=0)


def test_a_pool_takes_each_seed_of_its_job_once(tmp_path):
    pool = object.__new__(dist.PassPool)  # no cluster: submit checks before it reaches one
    pool._allowed, pool._submitted = set(SEEDS), {3}
    for seeds, message in [
        ((), "a chunk needs at least one seed"),
        ((5, 99), "seed 99 is not among the job's seeds"),
        ((1, 3), "seed 3 was submitted already: every seed renders once"),
        ((7, 8, 7), "seed 7 was submitted already: every seed renders once"),
    ]:
        with pytest.raises(BatchError, match=f"^{message}$"):
            pool.submit(seeds)
    assert pool._submitted == {3}


def test_an_unreachable_scheduler_is_an_input_error(tmp_path, monkeypatch):
    monkeypatch.setattr(dist.clusters, "CONNECT_TIMEOUT", "1s")
    with pytest.raises(BatchError, match="can't reach the Dask scheduler at tcp://127.0.0.1:9"):
        dist.PassPool(make_job(tmp_path / "x.npz"), dist.Cluster("tcp://127.0.0.1:9"))


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("bogus", "--scheduler bogus: give HOST:PORT, e.g. tcp://head:8786"),
        (
            "http://127.0.0.1:8787",
            "--scheduler http://127.0.0.1:8787: Dask schedulers speak tcp:// or tls://, not http://",
        ),
        ("tcp://127.0.0.1:9", "--scheduler tcp://127.0.0.1:9: nothing answers there"),
    ],
)
def test_a_scheduler_address_is_checked_at_once(address, message):
    with pytest.raises(BatchError, match=re.escape(message)):
        dist.check_scheduler(address)


def test_slurm_job_script_requests_the_gpu():
    pytest.importorskip("dask_jobqueue", reason="needs the workers extra (dask-jobqueue)")
    cluster = dist.slurm_gpu_cluster(
        "gpu", cores=8, memory="32GB", walltime="02:00:00", account="render", python="/shared/welch/.venv/bin/python"
    )
    try:
        script = cluster.job_script()  # built, never submitted
    finally:
        cluster.close()
    lines = script.splitlines()
    for directive in ("-p gpu", "-A render", "--cpus-per-task=8", "-t 02:00:00", "--gres=gpu:1"):
        assert f"#SBATCH {directive}" in lines, script
    worker = lines[-1]
    assert worker.startswith("/shared/welch/.venv/bin/python -m distributed.cli.dask_worker tcp://"), worker
    assert "--nthreads 1" in worker and "--resources GPU=1" in worker, worker


# -- rendering on a LocalCluster --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> wc.TileStats:
    """The job rendered by one process (``python -m batch render``, Cycles' default threads)."""
    job = make_job(tmp_path_factory.mktemp("reference") / "one.npz")
    run_job(job, Recorder(len(SEEDS)))
    return wc.load_stats(job.out)


@pytest.fixture(scope="module")
def cluster():
    """Two worker processes of one thread, as ``--workers 2`` starts them; tests reach it by its address."""
    with dist.local_cluster(2) as local:
        yield local.scheduler_address


def render_processes(address: str) -> dict[str, list[dict]]:
    with distributed.Client(address, set_as_default=False) as client:
        return client.run(dist.server_status)


def kill_in_the_middle_of_a_chunk(address: str, victim: str, found: dict, timeout: float = 60.0) -> None:
    """Wait for a render process in the middle of a chunk, freeze it (SIGSTOP) and check that it is still in the
    middle (so the chunk can't finish meanwhile), then SIGKILL it, or its worker (`victim` 'worker': then the
    frozen render process too). What was killed goes into `found`."""
    with distributed.Client(address, set_as_default=False) as client:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for worker, servers in client.run(dist.server_status).items():
                for server in servers:
                    if not (server["alive"] and 1 <= server["rendered"] < len(server["chunk"])):
                        continue
                    os.kill(server["pid"], signal.SIGSTOP)
                    time.sleep(0.3)  # its last events are read meanwhile
                    now = {s["pid"]: s for s in client.run(dist.server_status, workers=[worker])[worker]}
                    still = now.get(server["pid"])
                    if still is None or still["chunk"] != server["chunk"] or still["rendered"] >= len(still["chunk"]):
                        os.kill(server["pid"], signal.SIGCONT)
                        continue
                    if victim == "worker":
                        found["worker_pid"] = client.run(os.getpid, workers=[worker])[worker]
                        os.kill(found["worker_pid"], signal.SIGKILL)
                    os.kill(server["pid"], signal.SIGKILL)
                    found.update(still, worker=worker)
                    return
            time.sleep(0.01)


@pytest.mark.slow
def test_two_local_workers_give_the_statistics_of_one_process(reference, tmp_path):
    job = make_job(tmp_path / "two.npz")
    progress = Recorder(len(SEEDS))
    with dist.cluster(2, None) as where:
        stats = dist.render_distributed(job, progress, where, chunk=5)
    assert_same_statistics(stats, reference)
    assert_same_statistics(wc.load_stats(job.out), reference)
    kinds = [type(e) for e in progress.events]
    assert kinds == [protocol.Started] + [protocol.PassDone] * len(SEEDS) + [protocol.Finished], kinds
    assert progress.events[0] == protocol.Started(total=24, todo=24, out=job.out)
    assert sorted(e.seed for e in progress.events[1:-1]) == list(SEEDS)
    assert [e.done for e in progress.events[1:-1]] == list(range(1, 25))
    assert progress.events[-1] == protocol.Finished(out=job.out, passes=24)


@pytest.mark.slow
def test_layers_render_on_workers_as_in_one_process(cluster, tmp_path):
    """``--lobes`` with a pool: each chunk carries its layers, and the file (image and layers, passes in seed order)
    is the one a single process writes; a resumed run takes the layers on."""
    job = make_job(tmp_path / "one.npz", seeds=tuple(range(10)), lobes=("diffuse", "glossy", "emission"))
    run_job(job, Recorder(10))
    one, one_layers = wc.load_stats(job.out), wc.load_layers(job.out)
    pooled = job.replace(out=str(tmp_path / "pool.npz"), seeds=tuple(range(6)))
    dist.render_distributed(pooled, Recorder(6), dist.Cluster(cluster, threads=1), chunk=2)
    resumed = pooled.replace(seeds=job.seeds, resume=True)
    stats = dist.render_distributed(resumed, Recorder(10), dist.Cluster(cluster, threads=1), chunk=3)
    assert_same_statistics(stats, one)
    layers = wc.load_layers(pooled.out)
    assert list(layers) == list(one_layers) == ["diffuse", "glossy", "emission"]
    for name, layer in layers.items():
        assert_same_statistics(layer, one_layers[name])
    other = pooled.replace(out=str(tmp_path / "other.npz"), lobes=("diffuse",), resume=True)
    shutil.copy(pooled.out, other.out)
    refused = r"can't resume .*other.npz: it has layers \['diffuse', 'glossy', 'emission'\], this run \['diffuse'\]"
    with pytest.raises(BatchError, match=refused):
        dist.render_distributed(other.replace(seeds=tuple(range(12))), Recorder(12), dist.Cluster(cluster), chunk=2)


@pytest.mark.slow
def test_render_workers_from_the_command_line(reference, tmp_path):
    out = tmp_path / "cli.npz"
    argv = [sys.executable, "-m", "batch", "render", *make_job(out).to_argv(), "--workers", "2", "--chunk", "6"]
    done = subprocess.run(argv, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert_same_statistics(wc.load_stats(out), reference)
    refused = subprocess.run(argv[:-4] + ["--chunk", "6"], capture_output=True, text=True)
    assert refused.returncode == 2 and "--chunk goes with --workers or --scheduler" in refused.stderr


@pytest.mark.slow
@pytest.mark.parametrize("victim", ["render", "worker"])
def test_a_process_killed_in_the_middle_of_its_chunk_costs_only_that_chunk(reference, cluster, tmp_path, victim):
    job = make_job(tmp_path / f"killed-{victim}.npz")
    found: dict = {}
    killer = threading.Thread(target=kill_in_the_middle_of_a_chunk, args=(cluster, victim, found), daemon=True)
    killer.start()
    progress = Recorder(len(SEEDS))
    stats = dist.render_distributed(job, progress, dist.Cluster(cluster, threads=1), chunk=CHUNK)
    killer.join(5)
    assert found, "no render process was caught in the middle of a chunk"
    assert len(set(stats.seeds)) == len(stats.seeds) == len(SEEDS)
    assert_same_statistics(stats, reference)
    assert sorted(e.seed for e in progress.events if isinstance(e, protocol.PassDone)) == list(SEEDS)
    # The pool ended its render processes; the killed one is not among any that are left.
    assert all(not servers for servers in render_processes(cluster).values())


@pytest.mark.slow
def test_ctrl_c_keeps_what_arrived_and_resume_completes_the_run(reference, cluster, tmp_path):
    job = make_job(tmp_path / "cancelled.npz")

    def terminate(_seed):  # SIGTERM, as a job scheduler's cancel; the command line treats it as Ctrl-C
        os.kill(os.getpid(), signal.SIGTERM)

    with pytest.raises(KeyboardInterrupt), protocol.Interrupts():  # as `batch.cli.main` runs every command
        dist.render_distributed(job, Recorder(len(SEEDS), on_pass=terminate), dist.Cluster(cluster), chunk=CHUNK)
    kept = wc.load_stats(job.out)
    assert CHUNK <= kept.n < len(SEEDS) and len(set(kept.seeds)) == kept.n and set(kept.seeds) <= set(SEEDS)
    # The outstanding chunks were cancelled and the job's render processes ended.
    assert all(not servers for servers in render_processes(cluster).values())
    with pytest.raises(BatchError, match="already exists: pass --resume"):
        dist.render_distributed(job, Recorder(len(SEEDS)), dist.Cluster(cluster))

    progress = Recorder(len(SEEDS))
    stats = dist.render_distributed(job.replace(resume=True), progress, dist.Cluster(cluster), chunk=CHUNK)
    assert progress.events[0] == protocol.Started(total=24, todo=24 - kept.n, out=job.out)
    rendered = [e.seed for e in progress.events if isinstance(e, protocol.PassDone)]
    assert sorted(rendered + kept.seeds) == list(SEEDS)
    assert_same_statistics(stats, reference)
    assert_same_statistics(wc.load_stats(job.out), reference)


@pytest.mark.slow
def test_ctrl_c_at_a_terminal_stops_a_workers_run_without_a_traceback(tmp_path):
    """Ctrl-C reaches the whole process group (the tool, its Dask workers, their render processes): exit 130, one
    line, what was rendered kept; no worker prints the traceback of its own interrupt."""
    line = [sys.executable, "-m", "batch", "render", "--scene", "corner", "--resolution", "64", "64", "--seeds",
            "0:3000", "--spp", "1", "--workers", "2", "--out", str(tmp_path / "w.npz")]  # fmt: skip
    process = subprocess.Popen(line, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while not (tmp_path / "w.npz").exists() and time.monotonic() < deadline:  # a chunk has arrived
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGINT)
    _out, err = process.communicate(timeout=120)
    assert process.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert err.splitlines()[-1] == "interrupted: the statistics written so far are kept (continue with --resume)"
    assert wc.load_stats(tmp_path / "w.npz", pixels=False).n > 0


@pytest.mark.slow
def test_a_blend_a_worker_cannot_open_stops_the_run_naming_the_worker(cluster, tmp_path):
    job = make_job(tmp_path / "missing.npz", scene=None, blend=str(tmp_path / "not-on-this-worker.blend"))
    with pytest.raises(BatchError, match=r"worker tcp://.*not-on-this-worker\.blend"):
        dist.render_distributed(job, Recorder(len(SEEDS)), dist.Cluster(cluster), chunk=CHUNK)
    assert not os.path.exists(job.out)


BLENDER = shutil.which("blender")


@pytest.mark.slow
@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH (apt-get install blender python3-numpy)")
def test_workers_render_with_a_blender_binary(cluster, tmp_path):
    """With --blender each worker serves the job from that Blender (``blender -b ... -- render --serve``)."""
    done = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-expr", "import numpy"], capture_output=True)
    if done.returncode != 0 or b"Error" in done.stderr:
        pytest.skip(f"{BLENDER} has no numpy in its Python (apt-get install python3-numpy)")
    job = make_job(tmp_path / "one.npz", spp=1, seeds=tuple(range(8)), blender=BLENDER)
    run_job(job, Recorder(8))
    one = wc.load_stats(job.out)
    stats = dist.render_distributed(
        job.replace(out=str(tmp_path / "two.npz")), Recorder(8), dist.Cluster(cluster), chunk=3
    )
    assert stats.info.renderer_version == one.info.renderer_version != ""
    assert_same_statistics(stats, one)


@pytest.mark.slow
def test_a_relative_blend_path_means_the_clients_folder(cluster, tmp_path, monkeypatch):
    save = "import bpy, sys; bpy.ops.wm.save_as_mainfile(filepath=sys.argv[-1])"
    subprocess.run([sys.executable, "-c", save, str(tmp_path / "cube.blend")], check=True, capture_output=True)
    monkeypatch.chdir(tmp_path)  # the workers run elsewhere
    job = RenderJob(out="cube.npz", seeds=(0, 1, 2), blend="cube.blend", resolution=(32, 32), tile=16)
    stats = dist.render_distributed(job, Recorder(3), dist.Cluster(cluster), chunk=2)
    assert stats.seeds == [0, 1, 2] and stats.info.scene == "cube.blend/Scene"


WALLS_021 = 'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value=0.21,0.21,0.21,1'


def run_cli(*args, check=None):
    done = subprocess.run([sys.executable, "-m", "batch", *map(str, args)], capture_output=True, text=True)
    if check is not None:
        assert done.returncode == check, done.stdout[-2000:] + done.stderr[-2000:]
    return done


@pytest.mark.slow
def test_check_on_workers_decides_as_one_process_does(tmp_path):
    """The same check (walls 0.21, paired) with both sides on 2 local workers and in serving processes: the same
    looks, the same passes, the same verdict. With the tile sums on both: a paired check on workers has no pass
    images to fold into each pixel's differences, so it can't take the pixel-variance test (its report says so)."""
    common = ["check", "--scene", "corner", "--set", WALLS_021, "--resolution", "32", "32", "--tile", "8",
              "--max-passes", "16", "--sampling-pattern", "TABULATED_SOBOL", "--pixel-variance", "off"]  # fmt: skip
    run_cli(*common, "--out", tmp_path / "one", check=1)
    run_cli(*common, "--workers", "2", "--out", tmp_path / "two", check=1)
    looks = [json.loads((tmp_path / name / "check.json").read_text())["looks"] for name in ("one", "two")]
    for look in looks:
        for record in look:
            record.pop("seconds")
    assert looks[0] == looks[1] and looks[0][-1]["verdict"] == "biased"
    for name in ("reference", "test"):
        one, two = (wc.load_stats(tmp_path / run / f"{name}.npz") for run in ("one", "two"))
        assert_same_statistics(two, one)


@pytest.mark.slow
def test_suite_run_on_workers(tmp_path):
    suite = tmp_path / "suite.toml"
    suite.write_text('[defaults]\nresolution = [16, 16]\ntile = 8\npasses = 8\nsampling_pattern = "TABULATED_SOBOL"\n'
                     '[[case]]\nname = "walls"\nscene = "corner"\n'
                     '[[case]]\nname = "mirror"\nscene = "glossy_sharp"\n')  # fmt: skip
    run_cli("suite", "bless", suite, "--refs", tmp_path / "refs", check=0)
    done = run_cli("suite", "run", suite, "--refs", tmp_path / "refs", "--out", tmp_path / "out", "--workers", "2",
                   "--set", "cycles.film_exposure=1.2", check=1)  # fmt: skip
    assert "failed: walls [CPU], mirror [CPU]" in done.stdout


def test_a_port_that_accepts_and_never_answers_is_not_a_scheduler(tmp_path, monkeypatch):
    """A TCP port that accepts connections and never speaks (not a Dask scheduler) made the connect wait past its
    timeout, and Ctrl-C could not end it; now it is refused in one line after the handshake's deadline."""
    import socket

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    accepted = []
    threading.Thread(target=lambda: [accepted.append(server.accept()) for _ in range(8)], daemon=True).start()
    monkeypatch.setattr(dist.clusters, "HANDSHAKE_SECONDS", 2.0)
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    started = time.monotonic()
    with pytest.raises(BatchError, match=re.escape(f"the Dask scheduler at {address} accepts connections but does")):
        dist.PassPool(make_job(tmp_path / "x.npz"), dist.Cluster(address))
    assert time.monotonic() - started < 10
    server.close()
