"""The render-job contract (batch.jobs.job, batch.jobs.launch): every field survives the trip through argv, bad jobs are
refused in one line, and the commands that start a job are built from it alone."""

import argparse
import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from batch import cli
from batch.errors import BatchError
from batch.jobs import launch
from batch.jobs.job import RenderJob, add_arguments

ROOT = Path(__file__).resolve().parents[2]

#: A job with every field away from its default.
FULL = RenderJob(
    out="/runs/out dir/test.npz",
    seeds=(3, 1, 2),
    spp=4,
    blend="/scenes/my scene.blend",
    blend_scene="Scene.001",
    tile=16,
    resolution=(320, 240),
    device="OPTIX",
    sampling_pattern="BLUE_NOISE",
    overrides=(
        'materials["Walls"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value=0.21,0.21,0.21,1',
        "cycles.blur_glossy=0",
    ),  # fmt: skip
    resume=True,
    on_nan="keep",
    checkpoint_every=3,
    blender="/opt/blender-4.5/blender",
    lobes=("diffuse", "glossy", "lightgroups"),
    pass_images="/runs/out dir/pairs/test",
)
#: The same job rendered by another release's bpy instead of a Blender binary (the two exclude each other).
FULL_PYTHON = dataclasses.replace(FULL, blender=None, python="/root/.cache/welch-bias/bpy/4.5.4/bin/python")
#: A job rendered by another renderer's command (which takes no Cycles setting).
FULL_COMMAND = RenderJob(
    out="/runs/out dir/mitsuba.npz",
    seeds=(3, 1, 2),
    spp=4,
    tile=16,
    overrides=("max_depth=3", "light_scale=1.5"),
    resume=True,
    on_nan="skip",
    checkpoint_every=3,
    command="{python} 'render pass.py' --seed={seed} --out {out} --spp {spp} {set}",
    command_dir="/projects/my renderer",
)


def parse(argv: list[str]) -> RenderJob:
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    return RenderJob.from_args(parser.parse_args(argv))


@pytest.mark.parametrize(
    "job",
    [
        FULL,
        FULL_PYTHON,
        FULL_COMMAND,
        RenderJob(out="a.npz", seeds=range(0, 64)),
        RenderJob(out="a.npz", seeds=[5], scene="corner", resolution=(64, 64)),
        dataclasses.replace(FULL, blend=None, scene="glossy", blend_scene=None, blender=None, seeds=range(10, 20)),
    ],
)
def test_every_field_round_trips_through_argv(job):
    assert parse(job.to_argv()) == job
    assert cli.build_parser().parse_args(["render", *job.to_argv()]).out == job.out  # the real command too


def test_the_argv_of_a_job_is_written_in_one_order():
    """A check's state records its sides' argv and resumes only the same: the order and form stay as they were."""
    assert FULL.to_argv() == [
        "/scenes/my scene.blend", "--blend-scene", "Scene.001", "--seeds", "3,1,2", "--spp", "4", "--tile", "16",
        "--resolution", "320", "240", "--device", "OPTIX", "--sampling-pattern", "BLUE_NOISE",
        "--set", FULL.overrides[0], "--set", "cycles.blur_glossy=0", "--resume", "--on-nan", "keep",
        "--checkpoint-every", "3", "--blender", "/opt/blender-4.5/blender", "--lobes", "diffuse,glossy,lightgroups",
        "--pass-images", "/runs/out dir/pairs/test", "--out", FULL.out,
    ]  # fmt: skip
    assert RenderJob(out="a.npz", seeds=range(0, 64)).to_argv() == [
        "--seeds", "0:64", "--spp", "1", "--tile", "32", "--device", "CPU", "--out", "a.npz"]  # fmt: skip


def test_every_field_is_covered():
    """A new field without a command-line form would be lost between processes."""
    changed = {f.name for f in dataclasses.fields(RenderJob) for job in (FULL, FULL_PYTHON, FULL_COMMAND)
               if getattr(job, f.name) != f.default}  # fmt: skip
    assert changed == {f.name for f in dataclasses.fields(RenderJob)} - {"scene"}


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"seeds": ()}, "a render job needs at least one seed"),
        ({"scene": "corner"}, "give a .blend file or a built-in scene, not both (/scenes/my scene.blend, 'corner')"),
        ({"spp": 2**24 + 1}, "--spp must be an integer in 1..16777216, got 16777217"),
        ({"tile": 0}, "--tile must be an integer in 1..65536, got 0"),
        ({"resolution": (70000, 16)}, "--resolution must be an integer in 1..65536, got 70000"),
        ({"resolution": (64, 16), "tile": 32}, "--tile 32 is larger than the image 64x16"),
        ({"device": "TPU"}, "--device must be one of CPU, GPU, OPTIX, CUDA, HIP, METAL, ONEAPI, got 'TPU'"),
        ({"on_nan": "ignore"}, "--on-nan must be one of stop, skip, keep, got 'ignore'"),
    ],
)
def test_bad_jobs_are_refused_in_one_line(changes, message):
    with pytest.raises(BatchError, match=re.escape(message)):
        dataclasses.replace(FULL, **changes)


def test_command_with_this_python_runs_python_m_batch():
    command = launch.job_command(FULL.replace(blender=None), python="/py", python_paths=["/wheels"], base_env={})
    assert command.argv[:4] == ["/py", "-m", "batch", "render"]
    assert command.argv[-1] == "--json-progress"
    assert parse(command.argv[4:-1]) == FULL.replace(blender=None)
    assert command.env["PYTHONPATH"].split(os.pathsep) == [str(launch.ROOT), "/wheels"]
    assert command.env["PYTHONUNBUFFERED"] == "1"
    assert command.cwd is None  # relative paths of the job stay the caller's


def test_command_with_a_blender_binary_opens_the_file_and_passes_the_job_after_dashdash():
    command = launch.job_command(FULL, base_env={"PYTHONPATH": "/venv/site-packages", "HOME": "/h"})
    assert command.argv[:8] == [
        "/opt/blender-4.5/blender", "-b", "/scenes/my scene.blend", "--python-exit-code", "4",
        "--python", str(ROOT / "batch" / "blender_entry.py"), "--",
    ]  # fmt: skip
    child = parse(cli.argv_after_dashdash(command.argv)[1:-1])
    assert child == FULL.replace(blend=None, blender=None)  # Blender opened the file; the child renders itself
    # Blender's own Python must not pick up another Python's packages (pip's OpenEXR crashes Blender 3.4).
    assert "PYTHONPATH" not in command.env and command.env["HOME"] == "/h"


def test_a_built_in_scene_starts_blender_from_factory_settings():
    job = RenderJob(out="x.npz", seeds=[1], scene="corner", blender="blender")
    argv = launch.job_command(job, base_env={}).argv
    assert argv[:3] == ["blender", "-b", "--factory-startup"]
    assert parse(cli.argv_after_dashdash(argv)[1:-1]) == job.replace(blender=None)


def test_the_render_path_imports_no_scipy_and_no_openexr():
    """Inside a stock Blender only numpy is there: parsing a render job and reading a pass must not need more."""
    code = (
        "import sys, io, contextlib\n"
        "from batch import cli\n"
        "from batch.jobs import job, launch, lock, passes, protocol\n"
        "from batch.present import progress\n"
        "import welch_core.formats, welch_core.exr, welch_core.tiles\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n"
        "        cli.main(['render', '--help'])\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = sorted(m for m in ('scipy', 'OpenEXR', 'matplotlib') if m in sys.modules)\n"
        "print(heavy)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_lobes_are_parsed_in_order_and_checked():
    assert parse(["--seeds", "0:2", "--spp", "1", "--out", "a.npz", "--lobes", "glossy, diffuse"]).lobes == (
        "diffuse",
        "glossy",
    )
    assert len(parse(["--seeds", "0:2", "--spp", "1", "--out", "a.npz", "--lobes", "all"]).lobes) == 7
    with pytest.raises(BatchError, match="--lobes takes 'all' or some of diffuse,glossy,.*got 'sss'"):
        RenderJob(out="a.npz", seeds=[1], lobes=("sss",))
