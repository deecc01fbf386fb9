"""The plan of an audit (batch/decide/audit.py) and what its run makes of its cells (batch/decide/audit_run.py),
without rendering: the shipped list of changes, the cells and the level, the data file's one-line messages, the
checks of a cell, the statuses and the exit code. The audit rendered for real is tests/batch/test_audit_runs.py."""

from __future__ import annotations

import dataclasses
import json
import shlex

import pytest

from batch.cli.commands import build_parser, main
from batch.decide import audit, audit_run
from batch.decide.audit import AA, AuditSpec, Cell, Change, merged, plan_audit, scenes_of
from batch.decide.audit_run import CellResult, cell_job, check_command, exit_code, status_of
from batch.decide.check_job import CheckRequest
from batch.decide.matrix import Build
from batch.errors import BatchError, Exit, Undecided
from batch.jobs import releases
from batch.jobs.job import BUILTIN_SCENES

SHIPPED = audit.load_changes(audit.BUILTIN_CHANGES)


def spec(changes=SHIPPED, scenes=("corner", "glossy"), **kwargs) -> AuditSpec:
    return AuditSpec("test", scenes_of(list(scenes), []), (AA, *changes), **kwargs)


def by_name(name: str) -> Change:
    return next(c for c in SHIPPED if c.name == name)


def test_the_shipped_list_names_the_noise_only_settings_and_the_controls():
    names = [c.name for c in SHIPPED]
    assert names == ["light_tree", "path_guiding", "blue_noise", "scrambling_distance", "auto_scrambling",
                     "spatial_splits", "compact_bvh", "bvh_time_steps", "threads", "persistent_data", "tiling",
                     "light_threshold", "gpu", "clamp_indirect", "filter_glossy", "caustics_off"]  # fmt: skip
    assert [c.name for c in SHIPPED if c.control] == ["clamp_indirect", "filter_glossy", "caustics_off"]
    assert not by_name("light_threshold").control  # measured unbiased (BLENDER_FACTS): not a control
    # each renders at least the samples its setting acts at (batch/jobs/samples.py)
    assert audit.acts_from(by_name("path_guiding")) == ("cycles.use_guiding", 2)
    assert by_name("path_guiding").samples == 16 and by_name("blue_noise").samples == 2
    assert audit.acts_from(by_name("auto_scrambling")) == ("cycles.auto_scrambling_distance", 17)
    assert by_name("auto_scrambling").samples == 32
    assert all(c.why and c.setting for c in SHIPPED)


def test_cells_are_every_change_on_every_scene_with_the_default_against_itself_first():
    plan = plan_audit(spec(), {})
    assert plan.k == 17 * 2 and plan.cells[0].change is AA and plan.cells[0].scene.label == "corner"
    assert plan.cells[1].key == "default/glossy" and plan.cells[2].key == "light_tree/corner"
    assert plan.level == pytest.approx(0.01 / 34)
    text = plan.alpha_text()
    assert "alpha 0.01 over the audit's 34 cells" in text and "alpha / 34 = 0.000294" in text
    assert "reported biased only where both reject" in text


def test_a_setting_the_release_lacks_is_not_applicable_and_leaves_the_level():
    plan = plan_audit(spec(), {"gpu": "device 'GPU': Cycles found no GPU"})
    assert plan.k == 16 * 2 and plan.level == pytest.approx(0.01 / 32)
    assert [(c.key, why) for c, why in plan.not_applicable] == [
        ("gpu/corner", "device 'GPU': Cycles found no GPU"),
        ("gpu/glossy", "device 'GPU': Cycles found no GPU"),
    ]


def test_support_asks_the_release_for_each_side_of_each_change():
    asked = []

    def probe(jobs):
        asked.extend(jobs)
        return [None] + [("no guiding here" if job.overrides == ("cycles.use_guiding=true",) else None)
                         for job in jobs[1:]]  # fmt: skip

    found = audit.support(spec(), probe)
    assert found["path_guiding"] == "no guiding here" and found["light_tree"] is None and found["default"] is None
    assert asked[0].overrides == () and len(asked) == 1 + 2 * len(SHIPPED)
    gpu = [job for job in asked if job.device == "GPU"]
    assert len(gpu) == 1 and gpu[0].overrides == ()
    pattern = [job.sampling_pattern for job in asked if job.sampling_pattern]
    assert "BLUE_NOISE" in pattern and "TABULATED_SOBOL" in pattern
    with pytest.raises(BatchError, match="^the release current can't render: no bpy$"):
        audit.support(spec(), lambda jobs: ["no bpy"] + [None] * (len(jobs) - 1))


def test_a_bad_data_file_is_one_error_with_a_line_per_problem(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("""
[[change]]
name = "Guiding"
setting = "cycles.use_guiding"
test = ["cycles.use_guiding=true"]
documented = "noise"
samples = 1
why = "x"

[[change]]
name = "guiding"
setting = "cycles.use_guiding"
reference = ["cycles.use_guiding=false"]
test = ["cycles.use_guiding=true"]
documented = "noise"
samples = 1
why = "path guiding"

[[change]]
name = "clamp"
setting = "cycles.sample_clamp_indirect"
test = ["cycles.sample_clamp_indirect 10"]
documented = "biased"
samples = 1
why = "a clamp"
colour = "red"

[[change]]
name = "same"
setting = "cycles.use_light_tree"
reference = ["cycles.use_light_tree=true"]
documented = "noise"
samples = 1
why = "nothing changes"

[[change]]
name = "light_tree"
setting = "cycles.use_light_tree"
test = ["cycles.use_light_tree=false"]
documented = "noise"
samples = 1
why = "the light tree"
""")
    with pytest.raises(BatchError) as error:
        audit.load_changes(path, ("light_tree",))
    assert str(error.value).split("; ") == [
        f"{path}: 7 problems, nothing rendered: change 'Guiding': 'name' must be lower-case letters, digits and '_' "
        "(not 'default'), got 'Guiding'",
        "change 'guiding': 'samples' 1 is fewer than cycles.use_guiding acts at (2 samples a render, "
        "batch/jobs/samples.py): its passes would render the default",
        "change 'clamp': unknown key 'colour' (a change has name, setting, reference, test, pattern, test_pattern, "
        "test_device, documented, samples, why)",
        "change 'clamp': 'documented' must be 'noise' or 'bias', got 'biased'",
        "change 'clamp': 'test' 'cycles.sample_clamp_indirect 10': malformed override at character 30: expected '=' "
        "after the path (syntax: PATH=VALUE, e.g. cycles.samples=16)",
        "change 'same': the two sides are the same: give 'test', 'test_pattern' or 'test_device' (the default "
        "against itself is part of every audit)",
        "change 'light_tree': the name is used twice",
    ]
    assert "\n" not in str(error.value)


def test_a_missing_key_and_a_bad_number_are_named():
    problems = []
    assert audit.read_changes([{"name": "x", "setting": "cycles.seed", "test": ["cycles.seed=1"],
                                "documented": "noise", "samples": 0}], problems) == ()  # fmt: skip
    assert problems == [
        "change 'x': 'why' must be text (what Cycles documents it to change), and it is missing",
        "change 'x': 'samples' (samples per render, at least what the setting acts at) must be an integer in "
        "1..16777216, got 0",
    ]
    problems = []
    assert audit.read_changes([{"name": "x", "setting": "cycles.seed", "reference": ["cycles.seed=1"],
                                "test": ["cycles.seed=1"], "documented": "bias", "samples": 1, "why": "y"}],
                              problems) == ()  # fmt: skip
    assert problems == ["change 'x': 'test' is the same as 'reference': the change changes nothing"]


def test_a_later_override_of_a_path_replaces_an_earlier_one():
    assert merged(("cycles.blur_glossy=0", "cycles.seed=3"), ("scene.cycles.blur_glossy=1",)) == (
        "cycles.seed=3", "scene.cycles.blur_glossy=1")  # fmt: skip
    reference, test = by_name("threads").sides(audit.UNBIASED_OVERRIDES)
    assert reference[-1] == "render.threads_mode=AUTO" and test[-2:] == ("render.threads_mode=FIXED",
                                                                          "render.threads=1")  # fmt: skip
    assert "render.threads_mode=AUTO" not in test and reference[: len(audit.UNBIASED_OVERRIDES)] == (
        audit.UNBIASED_OVERRIDES)  # fmt: skip


def test_the_checks_of_a_cell(tmp_path):
    plan = plan_audit(spec(max_passes=40, max_seconds=None), {})
    cell = Cell(by_name("filter_glossy"), plan.spec.scenes[0])
    first = cell_job(plan, cell, "first", tmp_path / "first")
    assert first.alpha == plan.level and first.paired and first.pixel_variance == "auto" and first.max_passes == 40
    assert first.reference.overrides == ("cycles.blur_glossy=0",) and first.test.overrides == ("cycles.blur_glossy=1",)
    assert first.reference.seeds == tuple(range(40)) and first.reference.scene == "corner"
    confirm = cell_job(plan, cell, "confirm", tmp_path / "confirm")
    assert confirm.pixel_variance == "off" and confirm.test.lobes == audit.LOBES
    assert confirm.reference.seeds == tuple(range(40, 80)) == confirm.test.seeds  # fresh seeds, paired
    explain = cell_job(plan, cell, "explain", tmp_path / "explain")
    assert explain.reference.overrides[:-1] == tuple(o for o in audit.UNBIASED_OVERRIDES if "glossy" not in o)
    assert explain.test.overrides[-1] == "cycles.blur_glossy=1" and explain.reference.seeds[0] == 80
    aa = cell_job(plan, Cell(AA, plan.spec.scenes[0]), "first", tmp_path / "aa")
    assert not aa.paired and aa.reference.overrides == aa.test.overrides == ()
    pattern = cell_job(plan, Cell(by_name("blue_noise"), plan.spec.scenes[0]), "first", tmp_path / "bn")
    assert (pattern.reference.sampling_pattern, pattern.test.sampling_pattern) == ("TABULATED_SOBOL", "BLUE_NOISE")
    assert pattern.reference.spp == pattern.test.spp == 2
    timed = plan_audit(spec(max_passes=40, max_seconds=5.0), {})
    job = cell_job(timed, cell, "confirm", tmp_path / "timed")
    assert job.max_seconds == 5.0 and job.max_passes is None and job.test.seeds == tuple(range(40, 80))  # at most 40


def test_the_command_that_reproduces_a_confirmation(tmp_path):
    plan = plan_audit(spec(max_passes=40), {})
    cell = Cell(by_name("blue_noise"), plan.spec.scenes[1])
    line = check_command(plan, cell, "confirm", tmp_path / "again")
    assert line.startswith(
        "welch-bias check --scene glossy --spp 2 --sampling-pattern TABULATED_SOBOL --lobes diffuse,glossy,"
        "transmission,volume,emission,environment --test-sampling-pattern BLUE_NOISE --max-passes 40 --max-seconds "
        "20.0 --min-passes 8 --alpha 0.00029411764705882356 --pixel-variance off --seed-offset 40 --out "
    )
    # the line is the check's request, as the command line reads it back
    for role, checked in (("confirm", cell), ("explain", Cell(by_name("filter_glossy"), plan.spec.scenes[0]))):
        request = audit_run.cell_request(plan, checked, role, tmp_path / "again")
        argv = shlex.split(check_command(plan, checked, role, tmp_path / "again"))[1:]
        parsed = CheckRequest.from_args(build_parser().parse_args(argv))
        assert dataclasses.replace(request, reference_overrides=()) == dataclasses.replace(
            parsed, overrides=tuple(parsed.overrides), lobes=tuple(parsed.lobes)
        )
    # a release's bpy by the command that prints its Python, not by this machine's path
    python = str(releases.python_of(releases.cache_folder() / "5.2.3"))
    released = plan_audit(spec(max_passes=40, build=Build("5.2.3", python=python)), {})
    line = check_command(released, cell, "first", tmp_path / "again")
    assert ' --test-sampling-pattern BLUE_NOISE --python "$(welch-bias bpy 5.2.3)" --max-passes ' in line
    assert python not in line


def record(verdict: str, **extra) -> dict:
    return {"verdict": verdict, "sentence": verdict, "passes": 12, "whole_image": None, "p_value": 1e-9,
            "tolerance": 0.01, "claim_tile": 32, "ruled_out": None, "report": "r.html", **extra}  # fmt: skip


def test_a_cell_is_biased_only_where_its_confirmation_is_too():
    assert status_of(record("biased"), record("biased")) == "biased"
    assert status_of(record("biased"), record("inconclusive")) == "unconfirmed"
    assert status_of(record("equivalent"), None) == "equivalent"
    assert status_of(record("inconclusive"), None) == "undecided"
    assert status_of(None, None) == "error"
    assert "identical" not in audit_run.STATUSES


def test_the_exit_code_of_an_audit():
    plan = plan_audit(spec(changes=(by_name("light_tree"), by_name("clamp_indirect")), scenes=("corner",)), {})
    aa, tree, clamp = plan.cells

    def results(*statuses):
        return [CellResult(cell, status) for cell, status in zip(plan.cells, statuses, strict=True)]

    assert exit_code(plan, results("undecided", "equivalent", "biased")) == Exit.OK
    assert exit_code(plan, results("equivalent", "biased", "biased")) == Exit.BIASED
    assert exit_code(plan, results("biased", "equivalent", "biased")) == Exit.BIASED  # the A/A row too
    assert exit_code(plan, results("equivalent", "unconfirmed", "biased")) == Exit.OK
    assert exit_code(plan, results("equivalent", "error", "biased")) == Exit.USAGE
    assert exit_code(plan, results("equivalent", "equivalent", "undecided")) == Exit.INCONCLUSIVE
    assert audit_run.unfound_controls(plan, results("equivalent", "equivalent", "undecided")) == ["clamp_indirect"]


def test_a_cell_in_words():
    plan = plan_audit(spec(scenes=("corner",)), {})
    cell = plan.cells[2]
    assert audit_run.cell_sentence(cell, "equivalent", record("equivalent"), None) == (
        "no difference within ±1.00 % in every 32x32 tile (12 passes a side)"
    )
    whole = {"estimate": 0.0019, "low": 0.0012, "high": 0.0027}
    said = audit_run.cell_sentence(cell, "biased", record("biased"), record("biased", whole_image=whole))
    assert said == ("biased: whole image +0.19 % [+0.12 %, +0.27 %] (confirmed on fresh seeds: 12 passes, p 1e-09; "
                    "first 12 passes a side)")  # fmt: skip
    ruled = record("inconclusive", ruled_out={"tile": 64, "bias": 0.004})
    assert audit_run.cell_sentence(cell, "undecided", ruled, None) == (
        "not decided (12 passes a side); a bias beyond 0.40 % ruled out per 64x64 tile"
    )
    assert audit_run.explain_sentence(record("equivalent")) == (
        "with the biased-by-design settings off it is equivalent within ±1.00 % in every 32x32 tile: the change "
        "moves what those settings cut, not the converged image"
    )
    assert audit_run.explain_sentence(record("biased", whole_image=whole)).startswith("the change itself moves")


def test_the_estimate_says_up_front_and_shrinks_with_decided_cells():
    plan = plan_audit(spec(scenes=BUILTIN_SCENES), {"gpu": "no GPU"})
    whole = audit.estimate(plan)
    assert whole.cells == 240 and whole.expected < whole.at_most
    assert "240 cells to run: about " in whole.text()
    half = audit.estimate(plan, {c.key for c in plan.cells[:120]})
    assert half.cells == 120 and half.expected < whole.expected
    timed = plan_audit(spec(scenes=BUILTIN_SCENES, max_seconds=0.1), {"gpu": "no GPU"})
    floor = [2 * 8 * c.change.samples * 64 * 64 * audit.SAMPLE_SECONDS for c in timed.cells]  # the floor's passes
    assert audit.estimate(timed).at_most == pytest.approx(
        2 * sum(audit.CHECK_OVERHEAD + max(0.1, f) * audit.WALL_SHARE for f in floor)
    )


def test_an_audit_file_is_the_same_audit_as_a_suite_kind(tmp_path):
    path = tmp_path / "welch_audit.toml"
    path.write_text("""
[audit]
name = "nightly"
scenes = ["corner"]
only = ["light_tree", "tight"]
resolution = [32, 32]
tile = 8
passes = 24
alpha = 0.05

[[change]]
name = "tight"
setting = "cycles.sample_clamp_indirect"
reference = ["cycles.sample_clamp_indirect=0"]
test = ["cycles.sample_clamp_indirect=0.05"]
documented = "bias"
samples = 1
why = "a tight clamp"
""")
    assert audit.is_audit_file(path) and not audit.is_audit_file(audit.BUILTIN_CHANGES.parent / "missing.toml")
    found = audit.load_audit_file(path).spec
    assert [c.name for c in found.changes] == ["default", "light_tree", "tight"]
    assert (found.name, found.resolution, found.tile, found.max_passes, found.alpha) == ("nightly", (32, 32), 8, 24,
                                                                                          0.05)  # fmt: skip
    path.write_text('[audit]\nscenes = ["nowhere"]\npasses = 1\nlights = 2\n')
    with pytest.raises(BatchError) as error:
        audit.load_audit_file(path)
    assert str(error.value) == (
        f"{path}: 3 problems, nothing rendered: unknown key 'lights' in [audit] (it takes name, scenes, blends, "
        "changes, only, resolution, tile, passes, seconds, min_passes, alpha, tolerance); [audit] 'passes' must be an "
        "integer in 2..1000000, got 1; [audit] unknown built-in scene 'nowhere'; choose from "
        + ", ".join(BUILTIN_SCENES) + " or all")  # fmt: skip


def test_the_command_line_refuses_in_one_line(tmp_path, capsys):
    assert main(["audit", "--only", "nothing", "--out", str(tmp_path / "a")]) == Exit.USAGE
    assert "--only nothing: no such change (the changes are " in capsys.readouterr().err
    assert main(["audit", "--scene", "nowhere", "--out", str(tmp_path / "a")]) == Exit.USAGE
    assert "unknown built-in scene 'nowhere'" in capsys.readouterr().err
    path = tmp_path / "welch_audit.toml"
    path.write_text('[audit]\nscenes = ["corner"]\n')
    assert main(["suite", "bless", str(path)]) == Exit.USAGE
    assert "is an audit: it has no references to bless" in capsys.readouterr().err
    assert main(["suite", "run", str(path), "--set", "cycles.seed=2", "--out", str(tmp_path / "b")]) == Exit.USAGE
    assert "--set does not apply to an audit file" in capsys.readouterr().err


def test_a_resumed_audit_must_be_the_same_audit(tmp_path):
    plan = plan_audit(spec(scenes=("corner",)), {})
    runner = audit_run.Audit(plan, tmp_path, {}, resume=False, say=lambda _line: None)
    runner.records["default/corner"] = CellResult(plan.cells[0], "equivalent", "x").to_json()
    runner.save()
    with pytest.raises(BatchError, match="holds an audit already: pass --resume"):
        audit_run.Audit(plan, tmp_path, {}).load()
    again = audit_run.Audit(plan, tmp_path, {}, resume=True)
    again.load()
    assert again.result(plan.cells[0]).reused and again.result(plan.cells[0]).status == "equivalent"
    other = plan_audit(spec(scenes=("corner",), alpha=0.05), {})
    with pytest.raises(BatchError, match="it was started with other alpha"):
        audit_run.Audit(other, tmp_path, {}, resume=True).load()
    state = json.loads((tmp_path / "audit.json").read_text())
    assert state["format"] == "welch-bias-audit" and list(state["cells"]) == ["default/corner"]


def test_identical_passes_fewer_than_rule_out_a_rare_change_are_undecided():
    """As `check` says (reason `identical_too_few`): identical passes say the change left them as they were only
    from `welch_core.identical_passes(alpha / cells)` passes on (96 at 0.01 / 240); fewer are `undecided`."""
    plan = plan_audit(spec(scenes=("corner",)), {})
    cell = Cell(by_name("persistent_data"), plan.spec.scenes[0])
    level = 0.01 / 240
    few = record("inconclusive", identical=True, alpha=level, passes=2)
    assert status_of(few, None) == "undecided"
    assert audit_run.cell_sentence(cell, "undecided", few, None) == (
        "not decided: every pass identical on both sides so far (2 passes a side; 96 would rule out a change that "
        "alters one pass in ten)"
    )
    enough = record("equivalent", identical=True, alpha=level, passes=110, identical_needed=96)
    assert audit_run.cell_sentence(cell, "equivalent", enough, None) == (
        "no difference: every pass identical on both sides (110 passes a side; 96 rule out a change that alters one "
        "pass in ten)"
    )
    # an audit recorded before this rule: its `identical` cell is said again as `undecided`
    said = "every pass identical on both sides (12 passes a side): the change left them as they were"
    old = {"status": "identical", "message": said, "first": record("inconclusive", identical=True, alpha=level)}
    again = CellResult.from_json(cell, old)
    assert again.status == "undecided"
    assert again.message == (
        "not decided: every pass identical on both sides so far (12 passes a side; 96 would rule out a change that "
        "alters one pass in ten)"
    )


TOO_FEW = ("the time budget (20 s) ended the passes of both sides still rendering at 22 s of render seconds: too few "
           "passes to look at (1 of the reference side, 1 of the test side; a look needs 2 a side)")  # fmt: skip


def test_a_cell_whose_budget_ended_its_first_passes_is_undecided_not_an_error(tmp_path, monkeypatch):
    plan = plan_audit(spec(changes=(by_name("clamp_indirect"),), scenes=("volume_noise",)), {})
    runner = audit_run.Audit(plan, tmp_path, {}, say=lambda _line: None)

    def check(self, cell, role, where):
        raise Undecided(TOO_FEW)

    monkeypatch.setattr(audit_run.Audit, "_check", check)
    aa, clamp = (runner.result(cell) for cell in plan.cells)
    assert (aa.status, aa.message) == ("undecided", f"not decided, too few passes within the budget: {TOO_FEW}")
    assert exit_code(plan, [aa, clamp]) == Exit.INCONCLUSIVE  # not 2: the tool did not fail (3: no control found)
    summary = audit_run.write_outputs(plan, [aa, clamp], tmp_path)
    assert summary["counts"]["undecided"] == 2 and summary["counts"]["error"] == 0
    assert "too few passes within the budget" in (tmp_path / "index.html").read_text()


def test_the_budget_is_equal_per_cell_with_a_floor_of_passes(tmp_path):
    plan = plan_audit(spec(scenes=("corner",)), {})
    assert plan.spec.floor == 8 and cell_job(plan, plan.cells[0], "first", tmp_path / "a").min_passes == 8
    assert audit.budget_text(plan.spec) == (
        "at most 128 passes a side and 20 s of rendering a cell (at least 8 passes a side whatever their seconds), "
        "64x64 (the built-in scenes' own size), 16-px tiles, tolerance ±1 %"
    )
    assert audit.equal_budget_text(plan.spec) == (
        "every cell's checks have the same budget: at most 128 passes a side and 20 render seconds (both sides "
        "together), whichever ends first, and at least 8 passes a side whatever their seconds (up to 10 times the "
        "budget): equal in render seconds for every cell whose first 8 passes fit in them, equal in passes for a "
        "cell whose passes are slower (a scene that builds much before its first sample); a cell's samples per "
        "pass are its change's"
    )
    untimed = plan_audit(spec(scenes=("corner",), max_seconds=None), {})
    assert untimed.spec.floor is None
    assert cell_job(untimed, untimed.cells[0], "first", tmp_path / "b").min_passes is None
    assert plan_audit(spec(scenes=("corner",), max_passes=4), {}).spec.floor == 4  # never above the budget


def test_a_resumed_audit_runs_again_what_the_floor_or_an_error_cut_short(tmp_path):
    """An audit recorded before the floor (its spec without it): the cells whose checks the time budget cut below
    8 passes a side and those that could not run are run again; every other cell is reused, said as now."""
    plan = plan_audit(spec(changes=(by_name("persistent_data"), by_name("tiling")), scenes=("volume_noise",)), {})
    runner = audit_run.Audit(plan, tmp_path, {}, say=lambda _line: None)
    aa, persistent, tiling = plan.cells
    level = 0.01 / 3
    runner.records = {
        aa.key: CellResult(aa, "error", f"error: {TOO_FEW}").to_json(),
        persistent.key: CellResult(persistent, "identical", "x", first=record("inconclusive", identical=True,
                                                                              alpha=level, passes=2)).to_json(),
        tiling.key: CellResult(tiling, "identical", "x", first=record("inconclusive", identical=True, alpha=level,
                                                                      passes=95)).to_json(),
    }  # fmt: skip
    runner.save()
    state = json.loads((tmp_path / "audit.json").read_text())
    del state["spec"]["min_passes"]
    (tmp_path / "audit.json").write_text(json.dumps(state))
    (tmp_path / "cells" / "default" / "volume_noise" / "first").mkdir(parents=True)
    said = []
    again = audit_run.Audit(plan, tmp_path, {}, resume=True, say=said.append)
    again.load()
    assert again.again == [aa.key, persistent.key] and list(again.records) == [tiling.key]
    reused = again.result(tiling)
    assert reused.reused and reused.status == "undecided"
    assert reused.message.startswith("not decided: every pass identical on both sides so far (95 passes a side; ")


def test_a_difference_no_larger_than_float_rounding_is_said_so():
    """Cycles 4.5.4 renders the built-in scenes with rounding-level differences after a BVH, thread or persistent
    data change (and between two renders of the same settings); paired passes make them significant. Such a
    confirmed cell says its size and is no finding, and a control confirmed only so is one its scene does not
    exercise."""
    plan = plan_audit(spec(changes=(by_name("compact_bvh"), by_name("clamp_indirect")), scenes=("corner",)), {})
    _aa, bvh, clamp = plan.cells
    tiny = {"estimate": 1.1e-8, "low": 2e-10, "high": 2.2e-8}
    first, confirm = record("biased", whole_image=tiny, largest=tiny), record("biased", most_significant=tiny)
    assert audit_run.rounding_only(first, confirm) and not audit_run.rounding_only(record("biased", largest={
        "estimate": 0.004, "low": 0.001, "high": 0.007}))  # fmt: skip
    said = audit_run.cell_sentence(bvh, "biased", first, confirm)
    assert said.startswith("biased at the scale of float rounding: whole image —; the largest difference estimated in "
                           "any tile is 1.1e-08 relative (below 1e-06, the size of float rounding): the passes differ "
                           "in their rounding, not in their light (confirmed on fresh seeds: 12 passes")  # fmt: skip
    cells = [CellResult(c, "biased", "x", first=first, confirm=confirm) for c in (bvh, clamp)]
    assert cells[0].rounding and not cells[0].finding and not cells[1].found
    assert audit_run.unfound_controls(plan, cells) == ["clamp_indirect"]
    summary = audit_run.summary_of(plan, [CellResult(plan.cells[0], "equivalent", "x"), *cells])
    assert summary["rounding"] == ["compact_bvh/corner", "clamp_indirect/corner"] and summary["findings"] == []
    assert summary["exit_code"] == Exit.INCONCLUSIVE  # not 1; 3: the control was found nowhere beyond rounding
    from batch.present.audit_page import headline

    assert headline(summary) == "a control was found in no scene: the audit can't vouch for its power"
    summary["exit_code"] = Exit.OK
    assert (
        headline(summary) == "no noise-only setting is confirmed biased beyond float rounding (2 at the scale of "
        "float rounding)"
    )
