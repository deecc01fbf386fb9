"""pytest run in a renderer project's folder with the installed package's plugin (batch/cli/pytest_plugin.py)."""

from __future__ import annotations

import subprocess
import sys
from importlib import metadata

import pytest


def skip_unless_plugin_installed():
    """Skips the calling test where the welch-bias package (and so its pytest11 entry point) is not installed."""
    if not any(e.name == "welch" for e in metadata.entry_points(group="pytest11")):
        pytest.skip("the welch-bias package is not installed (./dev installs it): its pytest11 entry point is missing")


def pytest_in(folder, *args) -> subprocess.CompletedProcess:
    """pytest in `folder`, its temporary files (the reports) inside it: not among this run's, which it would prune."""
    argv = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-rA", "--basetemp", str(folder / "tmp")]
    return subprocess.run([*argv, *args], cwd=folder, capture_output=True, text=True, timeout=600)
