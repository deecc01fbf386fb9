"""Command line of the batch tool.

    python -m batch render [SCENE.blend] [--scene NAME] --seeds A:B|S1,S2,... --spp N [--tile 32]
                           [--resolution W H] [--device CPU] [--set RNA.PATH=VALUE ...] [--blender PATH]
                           [--resume] [--json-progress] --out STATS
    python -m batch ingest PASS.exr [PASS.exr ...] --spp N [--tile 32] [--seeds ...] --out STATS
    python -m batch compare REF TEST [--alpha 0.01] [--paired|--unpaired] --out REPORT_DIR
    python -m batch selftest RUN [--alpha 0.01] --out REPORT_DIR
    python -m batch merge STATS [STATS ...] --out STATS
    python -m batch lint SCENE.blend
    python -m batch demo [--out REPORT_DIR]

Inside Blender the same arguments follow ``--``:

    blender -b SCENE.blend --python-exit-code 4 --python batch/blender_entry.py -- render --seeds 0:64 ...

Exit codes (`batch.errors.Exit`): 0 = done / no evidence of bias / equivalent / lint clean (demo: always 0
when it ran), 1 = biased / lint found biased settings, 2 = usage or input error, 3 = inconclusive, 4 = internal
error, 130 = interrupted (the checkpoint is kept).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import os
import sys
import time
import traceback

from .._siblings import welch_core as wc
from ..errors import INTERRUPTED_LINE, BatchError, Exit, Undecided
from ..jobs import job as jobs
from ..jobs.options import TEST_SIDE, add_options
from ..jobs.protocol import CaseStatus, Interrupts, Probed, verdict_exit

INPUT_ERRORS = (BatchError, wc.WelchInputError, OSError)


class Parser(argparse.ArgumentParser):
    """argparse with a usage error in one line (its usage block of a dozen lines hid the reason), also as an
    ``error`` event when the command line asks for JSON progress (a caller reading events learns why)."""

    json_progress = False  # set by `main` from the command line, for every (sub)parser

    def error(self, message: str):
        text = f"{self.prog}: error: {message} (see {self.prog} --help)"
        if Parser.json_progress:
            from ..present.progress import Progress

            Progress(0, json_lines=True).error(" ".join(text.split()))
        self.exit(Exit.USAGE, text + "\n")


#: The console script (pyproject.toml's [project.scripts]): the same commands as ``python -m batch``.
PROG = "welch-bias"


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser; `command`: only that command's (what `main` parses a command's line with: its
    start-up does not build the others'), None or a name that is no command: every command's."""
    parser = Parser(
        prog=PROG if os.path.basename(sys.argv[0]) == PROG else "python -m batch",
        description="Detect bias in Monte Carlo renderers with Welch's t-test: render passes with different seeds, "
        "collect per-tile statistics, compare two runs.",
        epilog="Exit codes: 0 no evidence of bias / done, 1 biased, 2 usage or input error, 3 inconclusive, "
        "4 internal error, 130 interrupted.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    adders = _PARSERS.get(command) or dict.fromkeys(_PARSERS.values())
    for add in (adders,) if callable(adders) else adders:
        add(sub)
    return parser


def _add_render(sub) -> None:
    """``render``: passes of one run into a statistics file."""
    r = sub.add_parser(
        "render",
        help="render passes with Cycles into a statistics file",
        description="Render one pass per seed with Cycles (denoising, adaptive sampling, time limit, "
        "compositing off; everything else as the scene has it) and accumulate per-tile statistics. One process "
        "writes an output at a time (a lock file next to it); Ctrl-C or SIGTERM stops after the current pass "
        "and keeps what was rendered (continue with --resume).",
    )
    jobs.add_arguments(r)
    add_options(r, "render", ("json_progress", "serve", "probe"))
    add_options(r, "render", ("workers", "scheduler"))
    add_options(r, "render", ("chunk",))


def _add_check(sub) -> None:
    """``check``: both sides rendered until the data decide."""
    k = sub.add_parser(
        "check",
        help="render both sides in chunks until the data decide: biased, equivalent, or the budget is spent",
        description="Render the reference and the test side in interleaved chunks and look at the data after each "
        "chunk, with group-sequential boundaries that keep the false-positive rate of `biased` (and of "
        "`equivalent` at a true bias equal to the tolerance) at alpha however many looks it takes. Stops at "
        "`biased` or `equivalent`; at the budget the verdict is `inconclusive` and the report says which bias "
        "it rules out. Same build on both sides: paired (identical seeds) unless --unpaired; two builds: "
        "disjoint seeds. Ctrl-C keeps everything; --resume continues.",
    )
    add_options(k, "check", ("blend", "scene"))
    add_options(k, "check", ("blend_scene", "overrides"))
    add_options(k, "check", ("test_blend",))
    add_options(k, "check", ("blend_scene",), side="test")
    add_options(k, "check", ("blender", "python"))
    add_options(k, "check", ("blender", "python"), side="test")
    add_options(k, "check", ("pass_command",))
    add_options(k, "check", ("pass_command",), side="test")
    add_options(k, "check", ("command_dir",))
    add_options(k, "check", ("tolerance", "equivalence_tile", "pixel_variance"))
    add_options(k, "check", ("futility",))
    add_options(k, "check", ("alpha",))
    add_options(k, "check", ("max_passes", "max_seconds", "min_passes"))
    add_options(k, "check", ("spp", "tile", "resolution", "device", "sampling_pattern", "lobes"))
    add_options(k, "check", TEST_SIDE, side="test")
    add_options(k, "check", ("unpaired",))
    add_options(k, "check", ("seed_offset",))
    add_options(k, "check", ("workers", "scheduler"))
    add_options(k, "check", ("resume",))
    add_options(k, "check", ("json_progress",))
    add_options(k, "check", ("out",))
    add_options(k, "check")  # the rest of check's options: those declared since, in the declaration's order


def _add_ingest(sub) -> None:
    """``ingest``: passes another renderer wrote as EXR files."""
    i = sub.add_parser(
        "ingest",
        help="turn EXR passes of any renderer into a statistics file",
        description="One EXR file per independent pass (its own seed), all the same size.",
    )
    add_options(i, "ingest", ("pass_files", "spp", "tile", "seeds", "renderer", "layers", "on_nan"))
    add_options(i, "ingest", ("out",))


def _add_compare(sub) -> None:
    """``compare`` and ``selftest``: reports of statistics files."""
    for name, text in (
        ("compare", "compare two runs: is TEST biased against REF?"),
        ("selftest", "A/A test: one run's two halves against each other"),
    ):
        c = sub.add_parser(name, help=text, description=text + " Writes report.json, maps, histogram, report.html.")
        add_options(c, name, ("ref", "test") if name == "compare" else ("run",))
        add_options(c, name, ("alpha",))
        add_options(c, name, ("pvalue_method",))
        add_options(c, name, ("out",))
        add_options(c, name, ("tolerance", "equivalence_tile", "tile"))
        if name == "compare":  # a selftest's halves are subsets, which keep no pixel moments
            add_options(c, name, ("pixel_variance",))
        add_options(c, name, ("full_maps",))
        if name == "compare":
            add_options(c, name, ("pairing",))


def _add_merge(sub) -> None:
    """``merge`` and ``lint``."""
    m = sub.add_parser(
        "merge",
        help="merge statistics files of one configuration (other seeds, other machines) into one",
        description="Runs merge when they are one configuration (scene, renderer and build, device, spp, tile, "
        "sampling pattern, settings and overrides) and have disjoint seeds.",
    )
    add_options(m, "merge", ("runs", "out"))

    lint = sub.add_parser("lint", help="list settings that make Cycles biased or passes dependent")
    add_options(lint, "lint", ("blend", "blend_scene"))


def _add_suite(sub) -> None:
    """``suite bless`` and ``suite run``."""
    s = sub.add_parser(
        "suite",
        help="a statistical render regression suite for CI: bless references once, run every case against them",
        description="A suite file (TOML) lists cases: a scene, overrides, resolution, spp, tile, a budget, devices "
        "and an optional tolerance (see batch/decide/suite.py or docs/suite.md). `suite bless` renders each case's "
        "reference; `suite run` renders each case with the current build on new seeds and decides it against "
        "its reference with the render-until-decided engine, writing junit.xml, summary.json and a dashboard "
        "(index.html). SUITE may be `builtin`: one minimal scene per Cycles feature, with shipped references.",
        epilog="Exit codes of run: 0 every case passed, 1 a case is `biased` where it should not be, 2 a usage "
        "error or a case that could not run, 3 a case is inconclusive or an expected difference was not found. "
        "bless: 1 when a re-bless was refused (the new render is biased against the stored one).",
    )
    suite_sub = s.add_subparsers(dest="suite_command", required=True, metavar="ACTION")
    for action, text in (
        ("bless", "render each case's reference into --refs (a changed reference is refused without --force)"),
        ("run", "render each case with the current build and decide it against its reference"),
    ):
        a = suite_sub.add_parser(action, help=text, description=text)
        add_options(a, f"suite {action}", ("suite_file", "refs", "blender", "python", "device", "filter"))
        add_options(a, f"suite {action}", ("json_progress",))
        if action == "bless":
            add_options(a, "suite bless", ("force", "missing"))
        else:
            add_options(a, "suite run", ("out",))
            add_options(a, "suite run", ("overrides",))
            add_options(a, "suite run", ("resume", "workers", "scheduler", "seed_offset"))


def _add_matrix(sub) -> None:
    """``matrix`` and ``bisect``: many releases."""
    for name, text in (
        ("matrix", "render one scene with several builds and compare each adjacent pair, and each against a baseline"),
        ("bisect", "find the first build of an ordered list where a difference appears"),
    ):
        m = sub.add_parser(
            name,
            help=text,
            description=text + ". A build is `current` (this bpy), a full bpy release such as 4.5.4 (its "
            "environment is made once: see `bpy`), or the path of a Blender binary or of a Python with bpy. Every "
            "build renders the same passes count on its own seeds into --out/<build>.npz (resumed where it "
            "stopped); each comparison is `compare` of two of them, with its report."
            + (" Without --test-set/--test-sampling-pattern the difference is against the first build; with them "
               "it is within each build (the job against the job with the change, on the same seeds). Each step "
               "is decided at alpha / steps, so the chance of following a difference that is not there is at most "
               "alpha." if name == "bisect" else " Each cell is decided at alpha on its own."),
        )  # fmt: skip
        add_options(m, name, ("blend", "scene", "builds"))
        add_options(m, name, ("blend_scene", "resolution", "device", "sampling_pattern", "overrides", "spp", "tile",
                              "passes", "alpha", "tolerance"))  # fmt: skip
        if name == "matrix":
            add_options(m, "matrix", ("baseline",))
        else:
            add_options(m, "bisect", ("overrides", "sampling_pattern"), side="test")
        add_options(m, name, ("out",))


def _add_audit(sub) -> None:
    """``audit``: every setting documented to change only the noise against its default, on every scene."""
    a = sub.add_parser(
        "audit",
        help="audit a Cycles release: every setting documented to change only the noise against its default, on "
        "every scene, each difference confirmed on fresh seeds and explained",
        description="Audit one release (this bpy, --release VERSION, --python or --blender): every change of the "
        "shipped list (batch/decide/audits/cycles.toml: path guiding, the light tree, the sampling pattern, "
        "scrambling, BVH options, threads, persistent data, tiling, the light threshold, the GPU; and, as "
        "controls the audit must find, the indirect clamp, Filter Glossy and the caustics switches) and of "
        "--changes FILE against its default, on every scene (the built-in ones, or the .blend files given), and "
        "the default against itself on disjoint seeds. Each cell is a `check` with an equal budget; alpha is "
        "split evenly over the cells (Bonferroni), each cell's first check and its confirmation on fresh seeds "
        "(tile sums alone) both at alpha / cells, and a cell is reported biased only where both reject. A "
        "confirmed difference of a noise-only setting is explained: the light component that carries it, the "
        "change with the biased-by-design settings off (clamps 0, Filter Glossy 0, caustics on, light threshold "
        "0), and with --releases the first release that shows it. Says up front how long it expects to take, "
        "prints a line per cell, writes summary.json, junit.xml and index.html (the audit page); --resume reuses "
        "every cell already decided.",
        epilog="Exit codes: 0 no noise-only setting is confirmed biased beyond float rounding, 1 one is (the default "
        "against itself included), 2 a usage error or a cell that could not run, 3 a control was found in no scene "
        "(the audit could not have found a bias).",
    )
    add_options(a, "audit", ("blends", "scenes", "changes_file", "only"))
    build = a.add_mutually_exclusive_group()
    add_options(build, "audit", ("blender", "python"))
    add_options(build, "audit", ("release",))
    add_options(a, "audit", ("releases", "bisect_passes"))
    add_options(
        a,
        "audit",
        ("resolution", "tile", "max_passes", "max_seconds", "min_passes", "alpha", "tolerance", "seed_offset"),
    )
    add_options(a, "audit", ("workers", "scheduler", "plan"))
    add_options(a, "audit", ("resume", "out"))


def _add_bpy(sub) -> None:
    """``bpy`` and ``demo``."""
    r = sub.add_parser(
        "bpy",
        help="a Python with another Cycles release's bpy module, for --python (made once, then cached)",
        description="Make (once) and print the Python of a virtual environment with bpy==VERSION, to render with "
        "that release: `render --python`, `check --python/--test-python`, `suite run --python`. Each takes about "
        "1 GB on disk, in $WELCH_BPY_CACHE (default ~/.cache/welch-bias/bpy). Each release line runs one Python, "
        "found on PATH (python3.13) or among pyenv's, or named with --base-python: 4.2.x LTS to 5.0.x need 3.11, "
        "5.1 and 5.2.x LTS need 3.13. `bpy --list` says which each cached one has.",
        epilog='Example: python -m batch check --scene corner --python "$(python -m batch bpy 4.5.4)" --out c/',
    )
    add_options(r, "bpy", ("version", "list", "base_python"))

    d = sub.add_parser("demo", help="the built-in corner scene against a biased variant (walls 0.21 instead of 0.2)")
    add_options(d, "demo", ("out", "passes", "square"))


def argv_after_dashdash(argv: list[str]) -> list[str]:
    """Blender passes the script's own arguments after ``--``; everything before is Blender's."""
    return argv[argv.index("--") + 1 :] if "--" in argv else []


#: Each command's name and the function that adds its parser (some add two: compare and selftest, merge and lint,
#: matrix and bisect, bpy and demo), in the order of `--help`.
_PARSERS = {
    "render": _add_render,
    "check": _add_check,
    "ingest": _add_ingest,
    "compare": _add_compare,
    "selftest": _add_compare,
    "merge": _add_merge,
    "lint": _add_merge,
    "suite": _add_suite,
    "matrix": _add_matrix,
    "bisect": _add_matrix,
    "audit": _add_audit,
    "bpy": _add_bpy,
    "demo": _add_bpy,
}


def main(argv: list[str] | None = None) -> int:
    # Paths with undecodable bytes and terminals that can't show every character must not cost a traceback.
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
    given = sys.argv[1:] if argv is None else argv
    Parser.json_progress = "--json-progress" in given
    args = build_parser(given[0] if given else None).parse_args(argv)
    interrupts = Interrupts()
    try:
        with interrupts:
            code = COMMANDS[args.command](args)
    except BaseException as exc:  # an interrupt is one wherever it lands, whatever it surfaced as
        if interrupts.interrupted(exc):
            print(INTERRUPTED_LINE, file=sys.stderr)
            return Exit.INTERRUPTED
        if isinstance(exc, Undecided):
            print(f"verdict: inconclusive: {exc}")
            return Exit.INCONCLUSIVE
        if isinstance(exc, INPUT_ERRORS):
            _report_error(args, _describe(exc))
            return Exit.USAGE
        if not isinstance(exc, Exception):
            raise
        traceback.print_exc()
        _report_error(args, f"internal error: {type(exc).__name__}: {exc}")
        return Exit.INTERNAL
    if interrupts.interrupted():  # a library swallowed the KeyboardInterrupt and the command ran on
        print(INTERRUPTED_LINE, file=sys.stderr)
        return Exit.INTERRUPTED
    return code


def _describe(exc: Exception) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    return str(exc)


def _report_error(args, message: str) -> None:
    message = " ".join(message.split())  # one line
    if getattr(args, "json_progress", False):
        from ..present.progress import Progress

        Progress(0, json_lines=True).error(message)
    print(f"error: {message}", file=sys.stderr)


def _refuse_existing(path: str) -> None:
    if os.path.exists(path):
        raise BatchError(f"{path} already exists: choose another --out or remove it first")


# -- commands ----------------------------------------------------------------------------------------------


def cmd_render(args) -> int:
    from ..present.progress import Progress

    job = jobs.RenderJob.from_args(args)
    progress = Progress(len(job.seeds), args.json_progress)
    if args.probe:
        _probe(job, progress)
    elif args.workers or args.scheduler:
        if args.serve:
            raise BatchError("--serve renders in this process: it does not go with --workers or --scheduler")
        from ..jobs.distributed import cluster, render_distributed

        with cluster(args.workers, args.scheduler, work=len(job.seeds)) as where:
            render_distributed(job, progress, where, chunk=args.chunk)
    elif args.chunk:
        raise BatchError("--chunk goes with --workers or --scheduler")
    elif job.blender or job.python:
        from ..jobs.side import run_job

        run_job(job, progress)
    else:
        from ..jobs.launch import require_bpy

        require_bpy(job)
        from ..blender.run import chunk_requests, render_run

        render_run(job, progress, chunk_requests(sys.stdin) if args.serve else None)
    return Exit.OK


def _probe(job: jobs.RenderJob, progress) -> None:
    """``render --probe``: what the job's scene asks of the passes (`batch.jobs.samples.SceneSamples`), read in
    this process or in the job's own build."""
    if job.command is not None:
        raise BatchError("--probe reads a Cycles scene: another renderer's --command has none")
    if job.blender or job.python:
        from ..jobs.side import Side

        side = Side(None, job, warn=progress.warning)
        side.start_probe()
        found = side.probed()
    else:
        from ..jobs.launch import require_bpy

        require_bpy(job)
        from ..blender.render import open_scene
        from ..jobs.samples import scene_samples

        found = scene_samples(open_scene(job.blend, job.scene, job.blend_scene))
        if job.overrides or job.sampling_pattern or job.device != "CPU":
            # The settings it was given too, set up as its passes would be: a setting, sampling pattern or device
            # this build lacks is refused now, as a render would refuse it (an audit learns what a release has).
            from ..blender.run import prepare_scene

            prepare_scene(job)
    progress.emit(Probed(samples=found.samples, settings=found.settings))


def cmd_ingest(args) -> int:
    from ..jobs.lock import OutputLock
    from ..jobs.passes import add_layered_pass, channel_layers
    from ..present.progress import Progress

    if args.seeds is not None and len(args.seeds) != len(args.pass_files):
        raise BatchError(f"--seeds gives {len(args.seeds)} seeds for {len(args.pass_files)} files")
    _refuse_existing(args.out)
    with OutputLock(args.out):
        first = wc.read_exr(args.pass_files[0])
        info = wc.RunInfo(spp=args.spp, renderer=args.renderer)
        stats = wc.TileStats(first.shape[0], first.shape[1], args.tile, 3, info, keep_pixel_moments=True)
        layers = {name: wc.TileStats(first.shape[0], first.shape[1], args.tile, 3, info) for name in args.layers}
        progress = Progress(len(args.pass_files), label="ingest")
        progress.start(0, args.out)
        negative = False

        def read(index: int) -> tuple[dict, int]:
            """A pass's images and seed (its file's hash where no seed is given)."""
            path = args.pass_files[index]
            images = {"combined": first if index == 0 else wc.read_exr(path)}
            if layers:
                images |= channel_layers(wc.read_exr_channels(path), args.layers, path)
            return images, args.seeds[index] if args.seeds is not None else _content_seed(path)

        start = time.perf_counter()
        # The next file is read while this one is added (reading and hashing release the GIL).
        for index, (images, seed) in enumerate(wc.parallel.one_ahead(read, range(len(args.pass_files)))):
            path, image = args.pass_files[index], images["combined"]
            if not negative and (image < 0).any():
                negative = True
                progress.warning(f"{path} has negative pixel values (a filter with negative lobes?): they are kept")
            try:
                added = add_layered_pass(
                    stats, layers, images, seed, args.on_nan, lambda text, p=path: progress.warning(f"{p}: {text}")
                )
            except wc.WelchInputError as exc:
                raise wc.WelchInputError(f"{path}: {exc}") from None
            if added:  # its seconds: since the pass before it was added (its file read meanwhile)
                progress.pass_done(seed, time.perf_counter() - start)
            start = time.perf_counter()
        _refuse_existing(args.out)
        wc.save_stats(args.out, stats, layers)
    progress.finished(args.out, stats.n)
    return Exit.OK


def _content_seed(path: str) -> int:
    """An id for a pass of unknown seed: 62 bits of the hash of its file (identical files get the same id)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return int.from_bytes(digest.digest()[:8], "little") >> 2


def cmd_check(args) -> int:
    from ..decide.check import run_check
    from ..decide.check_job import check_job_from_args
    from ..present.pipeline import lines
    from ..present.progress import Progress

    job = check_job_from_args(args)
    verdict, report = run_check(job, Progress(0, args.json_progress, label="check"))
    print("\n".join(lines(report, job.out)))
    return verdict_exit(verdict)


def cmd_compare(args) -> int:
    from ..present.pipeline import compare_files, lines

    report = compare_files(
        args.ref,
        args.test,
        args.out,
        alpha=args.alpha,
        kind=args.pairing,
        pvalue_method=args.pvalue_method,
        tile=args.tile,
        tolerance=args.tolerance,
        equivalence_tile=args.equivalence_tile,
        pixel_variance=args.pixel_variance,
        full_maps=args.full_maps,
    )
    print("\n".join(lines(report, args.out)))
    return verdict_exit(report["verdict"])


def cmd_selftest(args) -> int:
    from ..present.pipeline import lines, present

    run = wc.load_stats(args.run)
    if run.n < 4:
        raise BatchError(f"selftest needs at least 4 passes to split into halves, {args.run} has {run.n}")
    first, second = wc.split_halves(run)
    result = wc.compare(
        first, second, args.alpha, "welch", args.pvalue_method, args.tile, args.tolerance, args.equivalence_tile
    )
    name = os.path.basename(args.run)
    names = (f"{name} (even passes)", f"{name} (odd passes)")
    report = present(args.out, result, first, second, names=names, full_maps=args.full_maps)
    print("\n".join(lines(report, args.out)))
    return verdict_exit(result.verdict)


def cmd_merge(args) -> int:
    _refuse_existing(args.out)
    merged, layers = wc.load_stats(args.runs[0]), wc.load_layers(args.runs[0])
    for path in args.runs[1:]:
        more = wc.load_layers(path)
        if list(more) != list(layers):
            raise BatchError(f"{path}: its layers ({', '.join(more) or 'none'}) differ from {args.runs[0]}'s "
                             f"({', '.join(layers) or 'none'})")  # fmt: skip
        try:
            merged = merged.merge(wc.load_stats(path))
            layers = {name: layer.merge(more[name]) for name, layer in layers.items()}
        except wc.WelchInputError as exc:
            raise wc.WelchInputError(f"{path}: {exc}") from None
    from ..jobs.lock import OutputLock

    with OutputLock(args.out):
        _refuse_existing(args.out)
        wc.save_stats(args.out, merged, layers)
    print(f"merge: {merged.n} passes from {len(args.runs)} files in {args.out}")
    return Exit.OK


def cmd_lint(args) -> int:
    from ..blender.lint import lint_scene, sample_findings
    from ..blender.render import open_scene

    scene = open_scene(args.blend, None, args.blend_scene)
    findings = lint_scene(scene) + sample_findings(scene)
    for finding in findings:
        print(finding.format())
    biased = [f for f in findings if f.severity in ("biased", "not-independent")]
    print(f"{len(findings)} findings, {len(biased)} that bias the image or make passes dependent")
    return Exit.BIASED if biased else Exit.OK


def cmd_suite(args) -> int:
    from pathlib import Path

    from ..decide import audit as audits
    from ..decide import suite as suites
    from ..present.progress import Progress

    if audits.is_audit_file(suites.suite_path(args.suite_file)):
        return _suite_audit(args)
    suite = suites.load_suite(args.suite_file)
    cases = suite.select(args.filter)
    refs = Path(args.refs) if args.refs else suites.default_refs(suite)
    if refs is None:
        raise BatchError(f"--refs is required for {suite.path} (the folder of its references)")

    def progress(total: int) -> Progress:
        return Progress(total, args.json_progress, label="suite", brief=True)

    def say(line: str) -> None:
        print(line, file=sys.stderr if args.json_progress else sys.stdout, flush=True)

    if args.suite_command == "bless":
        done = suites.bless(suite, cases, refs, progress, args.force, args.blender, args.device, say, args.missing,
                            args.python)  # fmt: skip
        for item in done:
            say(f"{item.case}: {item.status}: {item.message}" + (f" (report: {item.report})" if item.report else ""))
        return Exit.BIASED if any(item.status == "refused" for item in done) else Exit.OK
    out = Path(args.out)
    outcomes = suites.run_suite(
        suite,
        cases,
        refs,
        out,
        progress,
        args.blender,
        args.device,
        tuple(args.overrides),
        args.resume,
        say,
        args.seed_offset,
        (args.workers, args.scheduler),
        args.python,
    )
    summary = suites.write_outputs(suite, outcomes, out, refs)
    failed = [o.label for o in outcomes if o.status == CaseStatus.FAILED]
    say(
        "suite: "
        + ", ".join(f"{v} {k}" for k, v in summary["counts"].items() if v)
        + (f"; failed: {', '.join(failed)}" if failed else "")
    )
    say(f"dashboard: {out / 'index.html'}")
    return summary["exit_code"]


def _suite_audit(args) -> int:
    """``suite run`` of an audit file (an ``[audit]`` table): the audit it describes, with the release given."""
    from pathlib import Path

    from ..decide.audit import load_audit_file
    from ..decide.matrix import Build, build_of

    if args.suite_command == "bless":
        raise BatchError(f"{args.suite_file} is an audit: it has no references to bless (suite run runs it)")
    given = [flag for flag, value in (("--refs", args.refs), ("--filter", args.filter), ("--device", args.device),
                                      ("--set", args.overrides)) if value]  # fmt: skip
    if given:
        raise BatchError(f"{given[0]} does not apply to an audit file ({args.suite_file}): its cells are its own")
    found = load_audit_file(args.suite_file)
    build = build_of(args.python or args.blender) if (args.python or args.blender) else Build("current")
    spec = dataclasses.replace(found.spec, build=build, seed_offset=args.seed_offset)
    return _run_audit(spec, Path(args.out), args.resume, (args.workers, args.scheduler))


def cmd_matrix(args) -> int:
    from pathlib import Path

    from ..decide import matrix
    from ..decide.suite import exit_code
    from ..present.junit import junit_xml
    from ..present.matrix_page import write_bisect_page, write_matrix_page
    from ..present.progress import Progress

    if (args.blend is None) == (args.scene is None):
        raise BatchError("give a .blend file or a built-in scene (--scene), one of them")
    builds = matrix.unique([matrix.build_of(spec) for spec in args.builds])
    labels = [b.label for b in builds]
    job = jobs.RenderJob(out="x.npz", seeds=(0,), spp=args.spp, blend=args.blend and os.path.abspath(args.blend),
                         scene=args.scene, blend_scene=args.blend_scene, tile=args.tile,
                         resolution=tuple(args.resolution) if args.resolution else None, device=args.device,
                         sampling_pattern=args.sampling_pattern, overrides=tuple(args.overrides))  # fmt: skip
    out = Path(args.out)
    say = lambda line: print(line, flush=True)  # noqa: E731
    scene = args.scene or os.path.basename(args.blend)

    def progress(total: int) -> Progress:
        return Progress(total, label=args.command, brief=True)

    if args.command == "matrix":
        baseline = args.baseline or labels[0]
        if baseline not in labels:
            raise BatchError(f"--baseline {baseline} is not one of the builds ({', '.join(labels)})")
        paths = matrix.render_builds(job, builds, args.passes, out / "renders", progress, say)
        pairs = matrix.run_matrix(paths, labels, baseline, out, args.alpha, args.tolerance)
        for pair in pairs:
            say(f"{pair.reference} vs {pair.test}: {pair.sentence}")
        results = [pair.result(scene) for pair in pairs]
        matrix.write_json(out / "matrix.json", {"builds": labels, "baseline": baseline, "pairs": pairs})
        wc.formats.atomic_write(out / "junit.xml", lambda f: f.write(junit_xml(f"matrix {scene}", results)))
        note = f"{args.passes} passes a build, alpha {args.alpha:g} a cell, baseline {baseline}"
        write_matrix_page(out / "index.html", f"Release matrix: {scene}", labels, pairs, note)
        say(f"matrix: {out / 'index.html'}")
        return exit_code(results)  # the suites' rule: a cell is a case expected to converge
    changes = {}
    if args.test_overrides:
        changes["overrides"] = job.overrides + tuple(args.test_overrides)
    if args.test_sampling_pattern:
        changes["sampling_pattern"] = args.test_sampling_pattern
    found = matrix.run_bisect(job, builds, args.passes, out, args.alpha, args.tolerance, progress, say, changes or None)
    matrix.write_json(out / "bisect.json", {"builds": labels, **found.to_json()})
    write_bisect_page(out / "index.html", f"Bisect: {scene}", found)
    say(f"bisect: {found.message}")
    say(f"bisect: {out / 'index.html'}")
    return Exit.OK if found.first is not None else Exit.INCONCLUSIVE


def cmd_audit(args) -> int:
    from pathlib import Path

    from ..decide import audit
    from ..decide.matrix import Build, build_of

    changes = list(audit.load_changes(audit.BUILTIN_CHANGES))
    if args.changes_file:
        changes += audit.load_changes(args.changes_file, tuple(c.name for c in changes))
    if args.only:
        names = {c.name for c in changes} | {audit.AA.name}
        unknown = [n for n in args.only if n not in names]
        if unknown:
            raise BatchError(f"--only {unknown[0]}: no such change (the changes are {', '.join(sorted(names))})")
        changes = [c for c in changes if c.name in args.only]
    scenes = audit.scenes_of(args.scenes or ([] if args.blends else ["all"]), args.blends)
    if args.release:
        build = build_of(args.release)
    elif args.python or args.blender:
        build = build_of(args.python or args.blender)
    else:
        build = Build("current")
    releases = tuple(build_of(spec) for spec in args.releases or ())
    spec = audit.AuditSpec(name="cycles", scenes=scenes, changes=(audit.AA, *changes), build=build,
                           max_passes=args.max_passes, max_seconds=args.max_seconds, min_passes=args.min_passes,
                           alpha=args.alpha,
                           tolerance=args.tolerance, resolution=tuple(args.resolution) if args.resolution else None,
                           tile=args.tile, seed_offset=args.seed_offset, releases=releases,
                           bisect_passes=args.bisect_passes)  # fmt: skip
    return _run_audit(spec, Path(args.out), args.resume, (args.workers, args.scheduler), args.plan)


def _run_audit(spec, out, resume: bool, cluster, plan_only: bool = False) -> int:
    """An audit (``audit``, or ``suite run`` of an audit file): planned, said, run, its outputs written."""
    from ..decide.audit import estimate
    from ..decide.audit_run import prepare, run_audit

    say = lambda line: print(line, flush=True)  # noqa: E731
    plan, support = prepare(spec, out, resume, say)
    if plan_only:
        for cell, why in plan.not_applicable[:: len(spec.scenes)]:
            say(f"audit: {cell.change.name} is not applicable: {why}")
        say(f"audit: {plan.k} cells; {plan.alpha_text()}")
        say(f"audit: {estimate(plan).text()}")
        return Exit.OK
    _results, summary = run_audit(plan, out, support, resume, cluster, say)
    from ..present import fmt

    found = sum(len(scenes) for scenes in summary["controls_found"].values())
    rounding = len(summary["rounding"])
    counts = dict(summary["counts"], biased=summary["counts"]["biased"] - found - rounding)  # a control found is no
    counts = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v)  # finding
    counts += f", {rounding} biased at the scale of float rounding" if rounding else ""
    counts += f", {fmt.count(found, 'control')} found" if found else ""
    say(f"audit: {counts}; findings: {', '.join(summary['findings']) or 'none'}"
        + (f"; controls found nowhere: {', '.join(summary['unfound_controls'])}" if summary["unfound_controls"]
           else ""))  # fmt: skip
    say(f"audit: {out / 'index.html'}")
    return summary["exit_code"]


def cmd_bpy(args) -> int:
    from ..jobs import releases

    if args.list:
        found = releases.installed()
        for r in found:
            print(f"{r.version}\tPython {releases.python_needed(r.version)}\t{r.python}\t{r.banner}\t"
                  f"{r.size / 1e9:.1f} GB")  # fmt: skip
        if not found:
            print(
                f"no bpy release in {releases.cache_folder()} (python -m batch bpy VERSION makes one)", file=sys.stderr
            )
        return Exit.OK
    if args.version is None:
        raise BatchError("give a release (python -m batch bpy 4.5.4), or --list")
    say = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
    python = releases.ensure(args.version, say=say, base=args.base_python)
    print(python)
    return Exit.OK


def cmd_demo(args) -> int:
    from .demo import run_demo

    run_demo(args.out, passes=args.passes, resolution=args.square)
    return Exit.OK  # the demo's bias is planted: finding it is the demo working, not a failure


COMMANDS = {
    "check": cmd_check,
    "render": cmd_render,
    "ingest": cmd_ingest,
    "compare": cmd_compare,
    "selftest": cmd_selftest,
    "merge": cmd_merge,
    "lint": cmd_lint,
    "suite": cmd_suite,
    "matrix": cmd_matrix,
    "bisect": cmd_matrix,
    "audit": cmd_audit,
    "bpy": cmd_bpy,
    "demo": cmd_demo,
}
