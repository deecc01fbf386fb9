"""The one declaration of the options (batch.jobs.options) against what uses it: every command's parser (its
defaults read back from parse_args, its limits by the values it refuses, no flag of a declared option declared
again by hand) and a suite file's cases (their defaults and limits). The add-on's properties are held to it in
tests/addon/test_properties.py."""

from __future__ import annotations

import argparse

import pytest

from batch.cli.commands import build_parser
from batch.decide import suite as suites
from batch.errors import BatchError
from batch.jobs import options
from batch.jobs.options import CASE_OPTIONS, OPTIONS, TEST_SIDE, default

#: Each command's shortest command line: what every other option is defaulted in.
ARGV = {
    "render": ["render", "--seeds", "0:2", "--spp", "1", "--out", "x"],
    "check": ["check", "--out", "x"],
    "ingest": ["ingest", "a.exr", "--spp", "1", "--out", "x"],
    "compare": ["compare", "a", "b", "--out", "x"],
    "selftest": ["selftest", "a", "--out", "x"],
    "merge": ["merge", "a", "--out", "x"],
    "lint": ["lint", "a"],
    "suite bless": ["suite", "bless", "builtin"],
    "suite run": ["suite", "run", "builtin", "--out", "x"],
    "matrix": ["matrix", "--builds", "current", "--out", "x"],
    "bisect": ["bisect", "--builds", "current", "--out", "x"],
    "audit": ["audit", "--out", "x"],
    "bpy": ["bpy"],
    "demo": ["demo"],
}
#: The places that are not commands: a suite file's case and [suite] table, the add-on's panel.
NOT_COMMANDS = {"case", "suite", "addon"}
USES = [(dest, place) for dest, o in OPTIONS.items() for place in o.uses if place not in NOT_COMMANDS]


def parsers() -> dict[str, argparse.ArgumentParser]:
    """Every command's parser by its name (``suite run`` for the nested ones)."""
    found = {}

    def walk(parser, prefix):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    found[f"{prefix} {name}".strip()] = sub
                    walk(sub, f"{prefix} {name}")

    walk(build_parser(), "")
    return found


def parse(*argv) -> argparse.Namespace:
    return build_parser().parse_args([str(a) for a in argv])


def test_every_command_of_the_parser_has_a_short_command_line():
    assert set(ARGV) == {name for name in parsers() if name != "suite"}


@pytest.mark.parametrize(("dest", "command"), USES)
def test_a_command_parses_the_declared_default(dest, command):
    option = OPTIONS[dest]
    use = option.use(command)
    if use.required:
        assert dest in vars(parse(*ARGV[command]))  # given in its short command line
        return
    parsed = getattr(parse(*ARGV[command]), dest)
    expected = None if use.deferred else option.default_for(command)
    listed = option.many or use.nargs == "*"
    assert (list(parsed) if listed else parsed) == (list(expected) if listed else expected)
    if "test" in option.sides and use.test_help is not None:
        assert getattr(parse(*ARGV[command]), f"test_{dest}") in (None, [])


@pytest.mark.parametrize(("dest", "command"), USES)
def test_a_command_takes_the_declared_limits(dest, command, capsys):
    option = OPTIONS[dest]
    argv = ARGV[command]
    if option.kind == "integer":
        assert getattr(parse(*argv, option.flag, option.high), dest) == option.high
        assert getattr(parse(*argv, option.flag, option.low), dest) == option.low
        for wrong in (option.low - 1, option.high + 1):
            with pytest.raises(SystemExit):
                parse(*argv, option.flag, wrong)
            assert f"must be an integer in {option.low}..{option.high}" in capsys.readouterr().err
    elif option.kind == "choice":
        for value in option.choices:
            assert getattr(parse(*argv, option.flag, value), dest) == value
        with pytest.raises(SystemExit):
            parse(*argv, option.flag, "TPU")
    elif option.kind in ("probability", "seconds"):
        with pytest.raises(SystemExit):
            parse(*argv, option.flag, option.low)
        assert getattr(parse(*argv, option.flag, option.high / 2), dest) == option.high / 2
    elif option.kind == "percentage":
        assert getattr(parse(*argv, option.flag, f"{option.high * 50:g}%"), dest) == option.high / 2
        for wrong in ("0%", f"{option.high * 100:g}%"):
            with pytest.raises(SystemExit):
                parse(*argv, option.flag, wrong)
        assert getattr(parse(*argv, option.flag, "off"), dest) is None


def test_no_command_declares_a_declared_option_again():
    """A flag of a declared option (or of its test side) is on a command's parser only where the declaration
    says the command takes it."""
    flags = {}
    for option in OPTIONS.values():
        for flag in (option.flag, *(switch for switch, _const, _help in option.switches)):
            flags.setdefault(flag, []).append(option)
        if "test" in option.sides:
            flags.setdefault("--test-" + option.flag.removeprefix("--"), []).append(option)
    for command, parser in parsers().items():
        for action in parser._actions:
            for flag in action.option_strings:
                if flag in flags:
                    assert any(command in o.uses for o in flags[flag]), f"{command} {flag} is declared by hand"


def test_every_argument_of_every_command_is_declared():
    """No parser is given an argument but through the declaration (`options.add_options`): every flag and
    positional argument of every command is an option's, or argparse's own --help."""
    for command, parser in parsers().items():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                continue
            option = OPTIONS[action.dest.removeprefix("test_") if action.dest not in OPTIONS else action.dest]
            assert command in option.uses, f"{command} {action.dest}"
            shown = {option.flag, "--test-" + option.flag.removeprefix("--")} | {s for s, _c, _h in option.switches}
            assert set(action.option_strings or [action.metavar]) <= shown, f"{command} {action.dest}"


def test_the_test_side_of_a_check():
    assert TEST_SIDE == ("spp", "device", "sampling_pattern")
    parsed = parse(*ARGV["check"], "--test-spp", 4, "--test-blender", "b", "--test-python", "p")
    assert (parsed.test_spp, parsed.test_blender, parsed.test_python, parsed.test_device) == (4, "b", "p", None)
    assert parse(*ARGV["bisect"], "--test-set", "cycles.samples=2").test_overrides == ["cycles.samples=2"]


def write_suite(tmp_path, case: str = "", header: str = "") -> suites.Suite:
    path = tmp_path / "suite.toml"
    path.write_text(f'{header}[[case]]\nname = "a"\nscene = "corner"\n{case}')
    return suites.load_suite(str(path))


def test_a_case_has_the_declared_defaults(tmp_path):
    loaded = write_suite(tmp_path)
    case = loaded.cases[0]
    fields = {"max_passes": "passes", "max_seconds": "seconds"}
    for option in CASE_OPTIONS:
        assert getattr(case, fields.get(option.dest, option.dest)) == option.default_for("case"), option.key
    assert (loaded.alpha, loaded.tolerance) == (default("alpha", "suite"), default("tolerance", "suite"))
    assert {o.key for o in CASE_OPTIONS} <= suites._CASE_KEYS


@pytest.mark.parametrize("option", [o for o in CASE_OPTIONS if o.kind == "integer"], ids=lambda o: o.key)
def test_a_case_takes_the_declared_limits(tmp_path, option):
    extra = 'tolerance = "1%"\n' if option.dest == "equivalence_tile" else ""  # a claim needs a tolerance
    high = option.high if option.dest != "equivalence_tile" else 16 * (option.high // 16)  # a multiple of the tile
    if option.dest != "tile":  # a tile as large as the limit is larger than the image
        case = write_suite(tmp_path, f"{extra}{option.key} = {high}\n").cases[0]
        assert getattr(case, {"max_passes": "passes"}.get(option.dest, option.dest)) == high
    for wrong in (option.low - 1, option.high + 1):
        with pytest.raises(BatchError, match=f"'{option.key}' must be an integer in {option.low}..{option.high}"):
            write_suite(tmp_path, f"{extra}{option.key} = {wrong}\n")


def test_the_suite_table_takes_the_declared_limits(tmp_path):
    with pytest.raises(BatchError, match=r"\[suite\] alpha must be a number in \(0, 1\)"):
        write_suite(tmp_path, header="[suite]\nalpha = 1.0\n")
    with pytest.raises(BatchError, match=r"\[suite\] tolerance must be a percentage"):
        write_suite(tmp_path, header=f'[suite]\ntolerance = "{OPTIONS["tolerance"].high * 100:g}%"\n')


def test_the_suite_table_goes_through_the_declaration_as_a_case_does(tmp_path):
    """`[suite] alpha = "0.01"` (text) was accepted while a case's `spp = "1"` was refused: the table's values
    skipped the declaration's check. Every option declared for the place ``suite`` is a key of the table, checked
    by the case's function with the case's messages, each problem said once."""
    assert [o.key for o in options.SUITE_OPTIONS] == ["tolerance", "alpha"]
    for option in options.SUITE_OPTIONS:
        assert option.dest in OPTIONS and "suite" in option.uses
    message = r"a problem, nothing rendered: \[suite\] alpha must be a number, not text: '0.01'$"
    with pytest.raises(BatchError, match=message):
        write_suite(tmp_path, header='[suite]\nalpha = "0.01"\n')
    with pytest.raises(BatchError, match=r"^'alpha' must be a number, not text: '0.01'$"):
        options.from_file(OPTIONS["alpha"], "'alpha'", "0.01")  # a case's spelling of the same check
    both = r"2 problems, nothing rendered: \[suite\] tolerance must be a percentage such as 0.5%, got 0.02; \[suite\] "
    with pytest.raises(BatchError, match=both):
        write_suite(tmp_path, header='[suite]\nalpha = "0.01"\ntolerance = 0.02\n')
    assert write_suite(tmp_path, header='[suite]\nalpha = 0.05\ntolerance = "2%"\n').alpha == 0.05


def test_the_pixel_variance_modes_are_the_statistics_ones():
    import welch_core as wc
    from batch.jobs import options

    assert options.OPTIONS["pixel_variance"].choices == options.PIXEL_MODES == wc.PIXEL_MODES


def test_the_smallest_tolerance_is_the_statistics_own():
    """The declaration stays free of numpy (the add-on registers it), so it writes the limit again."""
    import welch_core.comparison

    assert options.MIN_TOLERANCE == welch_core.comparison.MIN_TOLERANCE


def test_an_option_declared_for_a_command_is_on_its_parser_without_naming_it_there():
    """`add_options(parser, command)` adds the options declared for `command` that no call before named, in the
    declaration's order: what a new option of `check` needs of the command line is its declaration."""
    parser = argparse.ArgumentParser()
    options.add_options(parser, "check", ("alpha", "spp"))
    options.add_options(parser, "check")
    declared = [d for d, o in options.OPTIONS.items() if "check" in o.uses]
    dests = [a.dest for a in parser._actions if a.dest != "help"]
    assert dests[:2] == ["alpha", "spp"] and sorted(dests) == sorted(declared)
    assert dests[2:] == [d for d in declared if d not in ("alpha", "spp")]


@pytest.mark.parametrize("command", sorted(ARGV))
def test_a_command_parses_the_same_with_its_parser_alone(command):
    """`main` builds only the parser of the command it runs (a command's start-up); it reads the same."""
    argv = ARGV[command]
    alone = build_parser(argv[0])
    assert vars(alone.parse_args(argv)) == vars(parse(*argv))
    assert set(parsers()) >= {command} and alone.format_usage() == build_parser().format_usage()


def test_the_pvalue_methods_are_the_statistics_ones():
    import welch_core as wc

    assert options.OPTIONS["pvalue_method"].choices == options.PVALUE_METHODS == wc.PVALUE_METHODS


@pytest.mark.parametrize(
    "argv",
    [
        ["--out", "x"],
        ["a.blend", "--set", "cycles.blur_glossy=1", "--set", "cycles.seed=2", "--test-spp", "4", "--out", "x"],
        ["--scene", "corner", "--tolerance", "off", "--no-futility", "--unpaired", "--resolution", "64", "32",
         "--lobes", "all", "--max-seconds", "30", "--min-passes", "4", "--alpha", "0.001", "--out", "x"],
        ["--command", "r {seed} {out}", "--test-command", "s {seed} {out}", "--command-dir", "d", "--out", "x"],
        ["a.blend", "--test-blend", "b.blend", "--test-blend-scene", "S", "--test-python", "p", "--workers", "2",
         "--spp", "auto", "--equivalence-tile", "64", "--pixel-variance", "on", "--resume", "--out", "x"],
    ],
)  # fmt: skip
def test_a_check_request_writes_the_command_line_that_asks_for_it(argv):
    """`CheckRequest.to_argv` (what an audit prints to reproduce a check) is read back to the same request."""
    from batch.decide.check_job import CheckRequest

    request = CheckRequest.from_args(parse("check", *argv))
    assert CheckRequest.from_args(parse("check", *request.to_argv())) == request
    assert len(request.to_argv()) <= len(argv)  # what is the default is left out
