"""Settings that act only above some samples per render (batch.jobs.samples): the table, `check --spp auto`'s
choice, what the summary and the next step say where the passes have too few samples."""

from __future__ import annotations

import subprocess
import sys

import pytest

import welch_core as wc
from batch.cli.commands import build_parser
from batch.decide.check_job import CheckRequest, check_job
from batch.jobs import samples
from batch.jobs.samples import BUILTIN, SceneSamples, acting, auto_samples, differing, side_settings
from batch.present import summary, words
from tests.helpers.synthetic import grey_stats


def fewest(**settings) -> dict[str, int]:
    return {path: a.fewest for path, a in acting({f"cycles.{k}": v for k, v in settings.items()}).items()}


def test_the_table_holds_the_measured_counts():
    """docs/findings/sample_dependent.md: the first sample count at which each setting changes a render."""
    assert fewest(use_guiding=True) == {"cycles.use_guiding": 2}
    assert fewest(use_guiding=False) == {}
    for pattern, count in (("BLUE_NOISE", 2), ("AUTOMATIC", 2), ("SOBOL_BURLEY", 2), ("BLUE_NOISE_FIRST", 3),
                           ("TABULATED_SOBOL", 257)):  # fmt: skip
        assert fewest(sampling_pattern=pattern) == {"cycles.sampling_pattern": count}
    tabulated = {"cycles.sampling_pattern": 257}
    assert fewest(sampling_pattern="TABULATED_SOBOL", auto_scrambling_distance=True) == tabulated | {
        "cycles.auto_scrambling_distance": 17
    }
    assert fewest(sampling_pattern="TABULATED_SOBOL", auto_scrambling_distance=True, scrambling_distance=0.5)[
        "cycles.auto_scrambling_distance"
    ] == 5  # fmt: skip
    assert fewest(sampling_pattern="BLUE_NOISE", auto_scrambling_distance=True) == {"cycles.sampling_pattern": 2}
    assert fewest(use_adaptive_sampling=True, adaptive_threshold=0.01, adaptive_min_samples=0) == {
        "cycles.use_adaptive_sampling": 81
    }
    assert fewest(use_adaptive_sampling=True, adaptive_min_samples=8)["cycles.use_adaptive_sampling"] == 17
    assert fewest(use_adaptive_sampling=True, adaptive_min_samples=40)["cycles.use_adaptive_sampling"] == 49
    assert fewest(use_adaptive_sampling=True, adaptive_min_samples=2)["cycles.use_adaptive_sampling"] == 17
    assert {s.path for s in samples.SAMPLE_DEPENDENT} <= set(samples.READS)


def test_a_sides_settings_take_its_pattern_and_overrides():
    scene = SceneSamples(4096, {"cycles.use_guiding": False, "cycles.sampling_pattern": "AUTOMATIC"})
    assert side_settings(scene) == scene.settings
    overrides = ["cycles.use_guiding=true", "scene.cycles.auto_scrambling_distance=1", "cycles.scrambling_distance=0.5",
                 "cycles.blur_glossy=0"]  # fmt: skip
    got = side_settings(scene, "TABULATED_SOBOL", overrides)
    assert got == {"cycles.use_guiding": True, "cycles.sampling_pattern": "TABULATED_SOBOL",
                   "cycles.auto_scrambling_distance": True, "cycles.scrambling_distance": 0.5}  # fmt: skip
    assert side_settings(scene, overrides=["cycles.sampling_pattern=BLUE_NOISE"])["cycles.sampling_pattern"] == (
        "BLUE_NOISE"
    )


def test_auto_renders_more_samples_only_where_the_sides_differ_in_such_a_setting():
    room = SceneSamples(4096, {"cycles.use_guiding": False, "cycles.sampling_pattern": "TABULATED_SOBOL"})
    guided = side_settings(room, overrides=["cycles.use_guiding=True"])
    # the sides agree: 1 sample, whatever the files render
    assert auto_samples(room, room, room.settings, side_settings(room, overrides=["cycles.max_bounces=4"])).spp == 1
    chosen = auto_samples(room, room, room.settings, guided)
    assert (chosen.spp, chosen.files) == (4096, 4096)
    guiding = {"name": "use_guiding", "values": [False, True], "fewest": 2}
    assert chosen.to_json() == {"spp": 4096, "files": 4096, "differing": [guiding]}
    # a built-in scene has no samples of its own: the fewest at which the setting acts
    assert auto_samples(BUILTIN, BUILTIN, BUILTIN.settings, side_settings(BUILTIN, "BLUE_NOISE")).spp == 2
    # a file of fewer samples than the setting needs: never fewer than it acts at
    one = SceneSamples(1, room.settings)
    assert auto_samples(one, one, one.settings, side_settings(one, overrides=["cycles.use_guiding=1"])).spp == 2
    # the fog files: Tabulated Sobol and blue noise, both 2 samples
    sobol, blue = (SceneSamples(2, {"cycles.sampling_pattern": p}) for p in ("TABULATED_SOBOL", "BLUE_NOISE"))
    assert auto_samples(sobol, blue, sobol.settings, blue.settings).spp == 2
    (found,) = differing(sobol.settings, blue.settings)
    assert (found.name, found.values, found.fewest) == ("sampling_pattern", ("TABULATED_SOBOL", "BLUE_NOISE"), 2)


def requested(tmp_path, *argv) -> CheckRequest:
    return CheckRequest.from_args(build_parser().parse_args(["check", *map(str, argv), "--out", str(tmp_path / "c")]))


class Probe:
    """A stand-in for the probe of scene files: what each file asks, and which were read."""

    def __init__(self, scene: SceneSamples):
        self.scene, self.read = scene, []

    def __call__(self, jobs):
        self.read += [(name, job.blend) for name, job in jobs]
        return [self.scene for _ in jobs]


def test_check_resolves_auto_before_anything_renders(tmp_path):
    blend = tmp_path / "room.blend"
    blend.write_bytes(b"BLENDER")
    probe = Probe(SceneSamples(64, {"cycles.use_guiding": False, "cycles.sampling_pattern": "TABULATED_SOBOL"}))
    job = check_job(requested(tmp_path, blend, "--set", "cycles.use_guiding=True"), probe)
    assert (job.reference.spp, job.test.spp) == (64, 64) and job.paired
    assert probe.read == [("reference", str(blend))]  # one file, read once for both sides
    assert job.auto_samples["spp"] == 64
    # nothing sample-dependent differs: 1, as before
    assert check_job(requested(tmp_path, blend, "--set", "cycles.max_bounces=4"), probe).reference.spp == 1
    # a number given is taken as it is, and nothing is read
    probe.read.clear()
    job = check_job(requested(tmp_path, blend, "--set", "cycles.use_guiding=True", "--spp", 1), probe)
    assert (job.reference.spp, job.auto_samples, probe.read) == (1, None, [])
    # --test-spp stays the test side's own
    job = check_job(requested(tmp_path, blend, "--set", "cycles.use_guiding=True", "--test-spp", 8), probe)
    assert (job.reference.spp, job.test.spp) == (64, 8)
    # a built-in scene is known without reading anything
    probe.read.clear()
    job = check_job(requested(tmp_path, "--scene", "corner", "--set", "cycles.use_guiding=True"), probe)
    assert (job.reference.spp, probe.read) == (2, [])


def test_check_reads_each_file_with_its_own_build(tmp_path):
    blend, other = tmp_path / "a.blend", tmp_path / "b.blend"
    for path in (blend, other):
        path.write_bytes(b"BLENDER")
    probe = Probe(SceneSamples(2, {"cycles.sampling_pattern": "BLUE_NOISE"}))
    check_job(requested(tmp_path, blend, "--test-blend", other), probe)
    assert probe.read == [("reference", str(blend)), ("test", str(other))]


def test_auto_is_a_value_of_check_spp_only():
    assert build_parser().parse_args(["check", "--spp", "auto", "--out", "x"]).spp is None
    assert build_parser().parse_args(["check", "--out", "x"]).spp is None
    with pytest.raises(SystemExit):
        build_parser().parse_args(["render", "--seeds", "0:2", "--spp", "auto", "--out", "x"])


def test_render_probe_reads_a_scene_and_renders_nothing(tmp_path):
    pytest.importorskip("bpy")
    done = subprocess.run([sys.executable, "-m", "batch", "render", "--scene", "volume", "--seeds", "0:1", "--spp", "1",
                           "--probe", "--json-progress", "--out", str(tmp_path / "x.npz")],
                          capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    events = [e for e in map(samples_event, done.stdout.splitlines()) if e is not None]
    assert [(e.samples, e.settings["cycles.sampling_pattern"]) for e in events] == [(1, "TABULATED_SOBOL")]
    assert set(events[0].settings) == set(samples.READS) and not (tmp_path / "x.npz").exists()


def samples_event(line: str):
    from batch.jobs import protocol

    event = protocol.parse(line)
    return event if isinstance(event, protocol.Probed) else None


# -- what the summary says ---------------------------------------------------------------------------------------


def info(spp: int, samples_in_file: int | None = 4096, **settings) -> wc.RunInfo:
    cycles = {"cycles.use_guiding": False, "cycles.sampling_pattern": "TABULATED_SOBOL"}
    cycles |= {f"cycles.{k}": v for k, v in settings.items()}
    fixed = {"cycles.samples": [samples_in_file, spp]} if samples_in_file is not None else {}
    scene_id = "sha256:0" if samples_in_file is not None else "builtin:corner:1"
    return wc.RunInfo(spp=spp, scene="room.blend/Scene", scene_id=scene_id, settings=cycles, fixed=fixed,
                      settings_hash=repr(sorted(cycles.items())))  # fmt: skip


def test_a_setting_that_does_not_act_at_the_passes_samples_is_a_hidden_difference():
    notes, hidden = summary.sample_notes(info(1), info(1, use_guiding=True))
    assert hidden == ["use_guiding: off → on, acting from 2 samples per render, 1 in the passes"]
    assert notes[0] == (
        "the verdict holds at 1 sample per pass only: the sides differ in use_guiding (off → on), which acts only "
        "from 2 samples per render (the scene files render 4096: --spp 4096 renders the passes as they do)"
    )
    # it acts at the passes' samples: the test sees it, nothing to say of it
    assert summary.sample_notes(info(64), info(64, use_guiding=True))[1] == []
    # passes left bit-identical say that it did not act, whatever the table says (a small image)
    notes, hidden = summary.sample_notes(info(2, None), info(2, None, use_guiding=True), identical=True)
    assert hidden == ["use_guiding: off → on, acting from 2 samples per render, 2 in the passes"]
    assert notes == ["the verdict holds at 2 samples per pass only: the sides differ in use_guiding (off → on), which "
                     "left every pass as it was at these samples (it acts from 2 at best); more samples per pass "
                     "(--spp 4 or more) may show it"]  # fmt: skip


def test_a_setting_both_files_have_is_named_where_their_renders_reach_it():
    notes, hidden = summary.sample_notes(info(1, sampling_pattern="BLUE_NOISE"), info(1, sampling_pattern="BLUE_NOISE"))
    assert hidden == [] and notes == [
        "the verdict holds at 1 sample per pass only: both scenes have sampling_pattern BLUE_NOISE, which acts only "
        "from 2 samples per render (the scene files render 4096: --spp 4096 renders the passes as they do)",
        ]  # fmt: skip
    # built-in scenes render what the tool gives them: nothing to say
    assert summary.sample_notes(info(1, None, sampling_pattern="BLUE_NOISE"),
                                info(1, None, sampling_pattern="BLUE_NOISE")) == ([], [])  # fmt: skip
    # another renderer's runs record no Cycles settings
    assert summary.sample_notes(wc.RunInfo(spp=1), wc.RunInfo(spp=1)) == ([], [])


def test_nothing_to_do_is_never_said_of_a_change_the_passes_cannot_show():
    ref, test = grey_stats(range(48)), grey_stats(range(48))
    ref.info, test.info = info(1), info(1, use_guiding=True)
    report = summary.summarize(wc.compare(ref, test, tolerance=0.01), ref, test)
    assert report["outcome"]["reason"] == "identical"
    assert report["hidden_differences"] == ["use_guiding: off → on, acting from 2 samples per render, 1 in the passes"]
    assert report["next_step"] == (
        "The passes agree, but they have too few samples to show use_guiding (settings that act only above some "
        "samples per render; see the notes): run the same command with --spp at the scene files' samples, or at "
        "least those the notes give, and another --out."
    )
    assert "Nothing to do" not in report["next_step"]
    assert "next: The passes agree, but they have too few samples" in "\n".join(summary.console_lines(report))


def test_the_next_step_of_files_that_differ_in_what_the_passes_replace_is_unchanged():
    outcome = {"reason": "identical"}
    hidden = ["samples: 4096 → 2 in the files, 1 in the passes"]
    assert words.next_step(outcome, hidden=hidden).startswith(
        "The passes agree, but the scene files differ in what the passes replace (samples)"
    )


def test_a_check_notes_the_samples_auto_chose():
    guiding = {"name": "use_guiding", "values": [False, True], "fewest": 2}
    record = {"auto_samples": {"spp": 4096, "files": 4096, "differing": [guiding]}}
    assert summary.check_notes(record) == [
        "--spp auto: 4096 samples per pass, the scene files' own, since the sides differ in what acts only from "
        "some samples per render: use_guiding (off → on, from 2)"
    ]
    record["auto_samples"]["files"] = None
    record["auto_samples"]["spp"] = 2
    assert summary.check_notes(record)[0].startswith("--spp auto: 2 samples per pass, the fewest at which that acts")
    assert summary.check_notes({"auto_samples": None}) == summary.check_notes(None) == []
