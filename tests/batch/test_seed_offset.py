"""Fresh seeds on request (``--seed-offset``): both sides' seeds shift, an unpaired test side's stay apart from the
reference's, a check resumes only with the offset it started with, and the report records the seeds."""

from __future__ import annotations

import pytest

import welch_core as wc
from batch.cli.commands import build_parser
from batch.decide import check_state
from batch.decide.check import Check
from batch.decide.check_job import UNPAIRED_SEEDS, check_job_from_args
from batch.errors import BatchError
from batch.present import summary
from batch.present.progress import Progress
from tests.helpers.synthetic import grey_stats


def check_args(tmp_path, *argv):
    return build_parser().parse_args(["check", "--scene", "corner", "--spp", "1", *map(str, argv), "--out",
                                      str(tmp_path / "c")])  # fmt: skip


def test_a_seed_offset_shifts_both_sides_seeds(tmp_path):
    job = check_job_from_args(check_args(tmp_path, "--set", "cycles.max_bounces=4", "--max-passes", 8))
    assert (job.reference.seeds, job.seed_offset) == (tuple(range(8)), 0)
    job = check_job_from_args(check_args(tmp_path, "--set", "cycles.max_bounces=4", "--max-passes", 8,
                                         "--seed-offset", 1000))  # fmt: skip
    assert job.reference.seeds == job.test.seeds == tuple(range(1000, 1008)) and job.seed_offset == 1000
    unpaired = check_job_from_args(check_args(tmp_path, "--unpaired", "--max-passes", 8, "--seed-offset", 1000))
    assert unpaired.reference.seeds == tuple(range(1000, 1008))
    assert unpaired.test.seeds == tuple(range(UNPAIRED_SEEDS + 1000, UNPAIRED_SEEDS + 1008))
    assert not set(unpaired.reference.seeds) & set(unpaired.test.seeds)


def test_the_largest_offset_keeps_every_seed_a_cycles_seed(tmp_path):
    from batch.jobs.options import MAX_SEED_OFFSET
    from batch.jobs.seeds import MAX_PASSES, MAX_SEED

    job = check_job_from_args(check_args(tmp_path, "--unpaired", "--max-passes", MAX_PASSES,
                                         "--seed-offset", MAX_SEED_OFFSET))  # fmt: skip
    assert max(job.test.seeds) == MAX_SEED
    with pytest.raises(SystemExit):
        check_args(tmp_path, "--seed-offset", MAX_SEED_OFFSET + 1)


def test_a_check_resumes_only_with_the_offset_it_started_with(tmp_path):
    first = check_job_from_args(check_args(tmp_path, "--set", "cycles.max_bounces=4", "--seed-offset", 5))
    (tmp_path / "c").mkdir()
    check_state.save(Check(first, Progress(0, live=False)))
    again = check_job_from_args(check_args(tmp_path, "--set", "cycles.max_bounces=4", "--seed-offset", 6, "--resume"))
    with pytest.raises(BatchError) as error:
        check_state.resume(Check(again, Progress(0, live=False)))
    assert str(error.value) == (
        f"can't resume {tmp_path / 'c'}: its reference side was started on seeds from 5, not 6 (another --seed-offset)"
    )
    same = check_job_from_args(check_args(tmp_path, "--set", "cycles.max_bounces=4", "--seed-offset", 5, "--resume"))
    check_state.resume(Check(same, Progress(0, live=False)))  # the same offset goes on


def test_the_summary_records_both_sides_seeds_and_the_offset(tmp_path):
    job = check_job_from_args(check_args(tmp_path, "--unpaired", "--max-passes", 8, "--seed-offset", 40))
    ref, test = grey_stats(job.reference.seeds[:6]), grey_stats(job.test.seeds[:6], seed=1)
    look = wc.sequential_look(ref, test, wc.SequentialPlan(max_passes=8), [6 / 8])
    record = summary.check_record(job, [], 8, look)
    report = summary.summarize(wc.compare(ref, test), ref, test, check=record)
    assert (report["reference"]["seeds"], report["test_run"]["seeds"]) == ("40:46", f"{UNPAIRED_SEEDS + 40}:"
                                                                           f"{UNPAIRED_SEEDS + 46}")  # fmt: skip
    assert report["check"]["seed_offset"] == 40


@pytest.mark.slow
def test_a_rendered_check_on_other_seeds_reports_them_and_resumes_only_on_them(tmp_path):
    """Real Cycles at 16x16: the report lists the shifted seeds, and --resume with another offset is refused in one
    line before anything renders."""
    import json
    import subprocess
    import sys

    def check(*argv):
        return subprocess.run([sys.executable, "-m", "batch", "check", "--scene", "corner", "--resolution", "16", "16",
                               "--tile", "8", "--unpaired", "--max-passes", "4", "--out", str(tmp_path / "c"),
                               *map(str, argv)], capture_output=True, text=True)  # fmt: skip

    done = check("--seed-offset", 100)
    assert done.returncode in (0, 3), done.stderr[-2000:]
    report = json.loads((tmp_path / "c" / "report.json").read_text())
    assert report["reference"]["seeds"] == "100:104" and report["check"]["seed_offset"] == 100
    assert report["test_run"]["seeds"] == f"{UNPAIRED_SEEDS + 100}:{UNPAIRED_SEEDS + 104}"
    again = check("--seed-offset", 101, "--resume")
    assert again.returncode == 2
    assert again.stderr.strip().splitlines()[-1] == (
        f"error: can't resume {tmp_path / 'c'}: its reference side was started on seeds from 100, not 101 (another "
        "--seed-offset)"
    )
