"""The code passes ruff's checks and formatting (configured in pyproject.toml)."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("args", [["check", "."], ["format", "--check", "."]])
def test_ruff(args):
    done = subprocess.run([sys.executable, "-m", "ruff", *args], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def imports_of(path: Path, module: str, modules: set[str]) -> set[str]:
    """The project's modules `module` (in `path`) imports anywhere in it, a function's lazy imports too, those
    only for type checkers left out. ``from P import m`` of a submodule imports m (P is already there)."""
    tree = ast.parse(path.read_text())
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(
        node.test) for n in ast.walk(node)}  # fmt: skip
    found = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
            source = ".".join([*base, *([node.module] if node.module else [])])
            subs = {f"{source}.{a.name}" for a in node.names} & modules
            found.update(subs or {source})
    return (found & modules) - {module}


def import_cycles(roots: list[str]) -> list[set[str]]:
    """The groups of the packages' modules that import each other in a circle (Tarjan's strongly connected
    components of the import graph, those of more than one module)."""
    files = {}
    for root in roots:
        for path in (ROOT / root).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            files[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = {m: imports_of(path, m, set(files)) for m, path in files.items()}
    index, low, stack, cycles = {}, {}, [], []

    def visit(m: str) -> None:
        index[m] = low[m] = len(index)
        stack.append(m)
        for n in graph[m]:
            if n not in index:
                visit(n)
                low[m] = min(low[m], low[n])
            elif n in stack:
                low[m] = min(low[m], index[n])
        if low[m] == index[m]:
            group = set()
            while not group or m not in group:
                group.add(stack.pop())
            if len(group) > 1:
                cycles.append(group)

    for m in sorted(graph):
        if m not in index:
            visit(m)
    return cycles


def test_no_module_imports_itself_through_others():
    """No import circle in the packages (lazy imports count: they only move the circle to the first call); the
    packages' __init__ re-exports count as imports of their submodules."""
    assert import_cycles(["welch_core", "batch", "blender_addon"]) == []


def test_every_lazy_name_of_welch_core_is_imported_for_editors_where_it_is_defined():
    """welch_core imports its names on first use (`_EXPORTS`); the imports under TYPE_CHECKING let an editor's
    go-to-definition find each: the same names from the same modules, each defined there."""
    import importlib

    import welch_core

    tree = ast.parse((ROOT / "welch_core" / "__init__.py").read_text())
    (block,) = [n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "TYPE_CHECKING"]
    shown = {a.name: node.module for node in block.body for a in node.names}
    assert shown == welch_core._EXPORTS
    for name, module in shown.items():
        assert name in vars(importlib.import_module(f"welch_core.{module}")), (name, module)


def test_the_add_ons_later_modules_are_imported_for_editors_and_on_first_use():
    """The add-on imports the check engine and the presenters' pipeline on first use (`_siblings._LATER`, not at
    registration); its imports under TYPE_CHECKING let an editor's go-to-definition find them: the same modules."""
    from blender_addon import _siblings

    tree = ast.parse((ROOT / "blender_addon" / "_siblings.py").read_text())
    (block,) = [n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "TYPE_CHECKING"]
    shown = {a.name: f"{node.module}.{a.name}" for node in block.body for a in node.names}
    assert shown == _siblings._LATER
    assert _siblings.check.__name__ == "batch.decide.check" and hasattr(_siblings.pipeline, "assess")
    with pytest.raises(AttributeError, match="has no attribute 'render'"):
        _siblings.render  # noqa: B018
