"""Bias suites as pytest tests: every case of a suite file named ``welch*.toml`` under pytest's test paths is an
item, decided against its reference as ``python -m batch suite run`` does (`batch.decide.suite`).

A case passes when its verdict is what it expects and it could have failed (`batch.decide.suite.status_of`), fails
with the verdict sentence, the passes it rendered, what differed between its sides and the report's path (a
reference that is not the case's: with the ``welch-bias suite bless`` command that renders it anew), and is
skipped with the reason when its device is missing; a suite file with a problem is one collection error listing
every problem. A suite file that is an audit (an ``[audit]`` table, `batch.decide.audit.load_audit_file`) is an
item per cell (a setting change on a scene: fails where a setting documented to change only the noise is confirmed
biased) and one per control (fails where it was found in no scene), run through one `batch.decide.audit_run.Audit`
whose level is the whole audit's whatever ``-k`` selects. pytest's own ``-k``, ``-x``, ``--junitxml`` and ``-ra``
work as for any test. Options:

``--welch-bless``          render and store the references that are missing (the others are kept)
``--welch-set KEY=VALUE``  a change for the test side of every case (repeatable): a case fails where it finds it
``--welch-refs DIR``       the references' folder (default: ``<suite file's stem>-refs`` next to the suite file)
``--welch-out DIR``        where each case's report goes (default: pytest's temporary folder)
``--welch-blender PATH``   the test side's Blender binary (default: the bpy module)

Registered through the ``pytest11`` entry point of the ``welch-bias`` package, so installing the package is all a
renderer project does. Importing this module imports nothing heavy: the suite machinery loads when a suite file
is collected.
"""

from __future__ import annotations

import fnmatch
import shutil
from pathlib import Path

import pytest

#: The suite files the plugin collects.
PATTERN = "welch*.toml"


def pytest_addoption(parser) -> None:
    group = parser.getgroup("welch", "bias suites (welch-bias)")
    group.addoption("--welch-bless", action="store_true", help="render the references that are missing")
    group.addoption("--welch-set", action="append", default=[], metavar="KEY=VALUE",
                    help="a change of the test side of every case (RNA.PATH=VALUE, repeatable)")  # fmt: skip
    group.addoption("--welch-refs", metavar="DIR", help="the references' folder (default: next to the suite file)")
    group.addoption("--welch-out", metavar="DIR", help="where the cases' reports go (default: pytest's tmp folder)")
    group.addoption("--welch-blender", metavar="PATH", help="the test side's Blender binary (default: bpy)")


def pytest_collect_file(file_path: Path, parent):
    if fnmatch.fnmatch(file_path.name, PATTERN):
        return SuiteFile.from_parent(parent, path=file_path)
    return None


def evidence(result) -> str:
    """What a failed case rendered and what differed between its sides, for the failure message."""
    if result.summary is None:
        return ""
    differences = result.summary["differences"] + result.summary["noise_differences"]
    return f"; {result.passes} passes" + (f"; differences: {'; '.join(differences)}" if differences else "")


class SuiteProblem(Exception):
    """A suite file or a case that can't be run: shown as its one-line message, without a traceback."""


class SuiteFile(pytest.File):
    """One suite file: its cases on each of their devices; or, for an audit file (an ``[audit]`` table), its cells
    (`AuditCellItem`) and, for each control, whether it was found anywhere (`ControlItem`)."""

    def collect(self):
        from ..decide import audit as audits
        from ..decide import suite as suites
        from ..errors import BatchError

        if audits.is_audit_file(self.path):
            yield from self._audit_items()
            return
        try:
            suite = suites.load_suite(str(self.path))
        except BatchError as exc:
            raise self.CollectError(str(exc)) from None
        for case in suite.cases:
            for device in case.devices:
                yield CaseItem.from_parent(self, name=f"{case.name}[{device}]", suite=suite, case=case, device=device)

    def _audit_items(self):
        from ..decide import audit as audits
        from ..errors import BatchError

        try:
            spec = audits.load_audit_file(self.path).spec
        except BatchError as exc:
            raise self.CollectError(str(exc)) from None
        self.spec, self._audit = spec, None
        for change in spec.changes:
            for scene in spec.scenes:
                cell = audits.Cell(change, scene)
                yield AuditCellItem.from_parent(self, name=f"{change.name}[{scene.label}]", cell=cell)
            if change.control:
                yield ControlItem.from_parent(self, name=f"{change.name}[found]", change=change)

    def audit(self):
        """The audit this file describes, planned once for all its items (the release asked what it supports) and
        run one cell at a time into ``--welch-out`` (or pytest's temporary folder), its decided cells reused."""
        if self._audit is None:
            import dataclasses

            from ..decide.audit_run import Audit, prepare
            from ..decide.matrix import Build, build_of
            from ..errors import BatchError

            blender = self.config.getoption("welch_blender")
            spec = dataclasses.replace(self.spec, build=build_of(blender) if blender else Build("current"))
            chosen = self.config.getoption("welch_out")
            base = Path(chosen) if chosen else self.config._tmp_path_factory.getbasetemp() / "welch"
            out = base / f"audit-{spec.name}"
            try:
                plan, support = prepare(spec, out, True, say=lambda _line: None)
                self._audit = Audit(plan, out, support, resume=True, say=lambda _line: None)
                self._audit.load()
            except BatchError as exc:
                raise SuiteProblem(str(exc)) from None
        return self._audit

    def write_audit(self) -> None:
        """The audit's outputs (summary.json, junit.xml, index.html) with the cells decided so far."""
        from ..decide.audit_run import CellResult, write_outputs

        audit = self._audit
        plan = audit.plan
        results = [CellResult.from_json(c, audit.records[c.key]) for c in plan.cells if c.key in audit.records]
        results += [CellResult(c, "not_applicable", f"not applicable: {why}") for c, why in plan.not_applicable]
        write_outputs(plan, results, audit.out)


class AuditCellItem(pytest.Item):
    """One cell of an audit: fails where a setting documented to change only the noise is confirmed biased (or the
    cell could not run), is skipped where the release lacks the setting, passes otherwise."""

    def __init__(self, *, cell, **kwargs):
        super().__init__(**kwargs)
        self.cell = cell

    def runtest(self) -> None:
        from ..errors import BatchError

        audit = self.parent.audit()
        skipped = {c.key: why for c, why in audit.plan.not_applicable}
        if self.cell.key in skipped:
            pytest.skip(f"not applicable: {skipped[self.cell.key]}")
        try:
            result = audit.result(self.cell)
        except BatchError as exc:
            raise SuiteProblem(str(exc)) from None
        finally:
            self.parent.write_audit()
        report = f" (report: {audit.out / result.first['report']})" if result.first else ""
        if result.status == "error":
            raise SuiteProblem(f"{result.message}{report}")
        if result.finding:
            raise SuiteProblem(f"{self.cell.change.name} documented to change only the noise: {result.message}"
                               f"{report}")  # fmt: skip

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, SuiteProblem):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, f"welch audit cell {self.name}"


class ControlItem(AuditCellItem):
    """A control of an audit (biased by design): fails where it was found in no scene, since the audit could not
    have found a bias of that size either; runs the control's cells that have not run yet."""

    def __init__(self, *, change, **kwargs):
        pytest.Item.__init__(self, **kwargs)
        self.change = change

    def runtest(self) -> None:
        audit = self.parent.audit()
        cells = [c for c in audit.plan.cells if c.change.name == self.change.name]
        if not cells:
            pytest.skip(f"not applicable: {self.change.name}")
        try:
            found = [c.scene.label for c in cells if audit.result(c).found]
        finally:
            self.parent.write_audit()
        if not found:
            raise SuiteProblem(f"the control {self.change.name} ({self.change.setting}, biased by design) was found "
                               "in no scene: the audit could not have found a bias of its size either")  # fmt: skip


class CaseItem(pytest.Item):
    """One case on one device, decided against its reference."""

    def __init__(self, *, suite, case, device, **kwargs):
        super().__init__(**kwargs)
        self.suite, self.case, self.device = suite, case, device

    def refs(self) -> Path:
        chosen = self.config.getoption("welch_refs")
        return Path(chosen) if chosen else self.path.with_name(f"{self.path.stem}-refs")

    def out(self) -> Path:
        chosen = self.config.getoption("welch_out")
        if chosen:
            return Path(chosen) / self.suite.name
        return self.config._tmp_path_factory.getbasetemp() / "welch" / self.suite.name

    def runtest(self) -> None:
        from ..decide import suite as suites
        from ..errors import BatchError
        from ..present.progress import Progress

        refs, out = self.refs(), self.out()
        blender = self.config.getoption("welch_blender")

        def progress(total: int) -> Progress:
            return Progress(total, label="welch", live=False, brief=True)  # the looks, shown when a case fails

        def say(_line: str) -> None:
            pass

        try:
            if not suites.reference_path(refs, self.case).exists():
                if not self.config.getoption("welch_bless"):
                    raise SuiteProblem(f"no reference for {self.case.name} in {refs}: run pytest with --welch-bless")
                for done in suites.bless(self.suite, [self.case], refs, progress, say=say, missing=True):
                    if done.status == "refused":
                        raise SuiteProblem(f"{done.case}: the new reference was refused: {done.message}")
            shutil.rmtree(out / self.case.name / self.device, ignore_errors=True)  # each run draws its passes anew
            (result,) = suites.run_suite(self.suite, [self.case], refs, out, progress, blender, self.device,
                                         tuple(self.config.getoption("welch_set")), say=say)  # fmt: skip
        except BatchError as exc:
            raise SuiteProblem(str(exc)) from None
        report = f" (report: {Path(result.folder) / 'report.html'})" if result.folder else ""
        if result.status == "skipped":
            pytest.skip(result.message)
        if result.status != "passed":
            raise SuiteProblem(f"{result.status}: {result.message}{evidence(result)}{report}")

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, SuiteProblem):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, f"welch case {self.name}"
