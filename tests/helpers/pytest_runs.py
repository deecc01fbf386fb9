"""pytest run in a renderer project's folder with the installed package's plugin (batch/cli/pytest_plugin.py)."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def skip_unless_plugin_installed():
    """Skips the calling test where the welch-bias package (and so its pytest11 entry point) is not installed."""
    if not any(e.name == "welch" for e in metadata.entry_points(group="pytest11")):
        pytest.skip("the welch-bias package is not installed (./dev installs it): its pytest11 entry point is missing")


def pytest_in(folder, *args, timeout: float = 600) -> subprocess.CompletedProcess:
    """pytest in `folder`, its temporary files (the reports) inside it: not among this run's, which it would prune.
    The plugin is this tree's (first on PYTHONPATH), whichever checkout the package was installed from."""
    argv = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-rA", "--basetemp", str(folder / "tmp")]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([*argv, *args], cwd=folder, capture_output=True, text=True, timeout=timeout, env=env)
