"""Other Cycles releases to render with: a cached virtual environment per bpy release (``python -m batch bpy
VERSION``), whose Python a job takes as ``--python PATH`` (`batch.jobs.launch.bpy_version` checks it).

A bpy release is a Python module of about 1 GB (Cycles and all); its environment holds that module and what pip
brings with it (numpy) and nothing of the tool, whose code reaches it on PYTHONPATH. The environments live in
``$WELCH_BPY_CACHE``, else ``$XDG_CACHE_HOME/welch-bias/bpy``, else ``~/.cache/welch-bias/bpy``, one folder per
release; one is built in a temporary folder and renamed when it works, so an interrupted or failed install
leaves nothing half made. Nothing here imports bpy.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from ..errors import BatchError
from .launch import bpy_version

#: A release in full: 4.5.4, 5.0.0, ... (pip reads 4.5 as 4.5.0, not as the latest 4.5)
_VERSION = re.compile(r"^\d+\.\d+\.\d+$")


def cache_folder() -> Path:
    """Where the environments live (see the module docstring)."""
    if os.environ.get("WELCH_BPY_CACHE"):
        return Path(os.environ["WELCH_BPY_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "welch-bias" / "bpy"


def python_of(folder: Path) -> Path:
    return folder / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


@dataclass(frozen=True)
class Release:
    """A cached environment: its release, its Python, what it reports and its size on disk."""

    version: str
    python: Path
    banner: str
    size: int  # bytes


def installed() -> list[Release]:
    """The cached environments that work, oldest release first."""
    folder = cache_folder()
    found = []
    for entry in sorted(folder.iterdir() if folder.is_dir() else (), key=lambda p: _key(p.name)):
        if not _VERSION.match(entry.name) or not python_of(entry).exists():
            continue
        try:
            banner = bpy_version(str(python_of(entry)))
        except BatchError as exc:
            banner = f"broken: {exc}"
        found.append(Release(entry.name, python_of(entry), banner, _size(entry)))
    return found


def ensure(version: str, say=print) -> Path:
    """The Python of the environment with bpy `version`, made (and cached) if it is not there yet."""
    if not _VERSION.match(version):
        raise BatchError(f"a bpy release is a full version such as 4.5.4 (4.5 would mean 4.5.0), got {version!r}")
    folder = cache_folder() / version
    if python_of(folder).exists():
        bpy_version(str(python_of(folder)))
        return python_of(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    building = folder.with_name(f".{version}.building-{os.getpid()}")
    shutil.rmtree(building, ignore_errors=True)
    try:
        say(f"bpy {version}: making a Python environment in {folder} (about 1 GB)")
        _run([sys.executable, "-m", "venv", str(building)], "can't make a virtual environment")
        say(f"bpy {version}: pip install bpy=={version}")
        _run([str(python_of(building)), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
              f"bpy=={version}"], f"pip could not install bpy=={version}")  # fmt: skip
        bpy_version(str(python_of(building)))
        building.rename(folder)  # a venv's scripts name its folder: fix them for the final place
        _relocate(building, folder)
    except BaseException:
        shutil.rmtree(building, ignore_errors=True)
        raise
    return python_of(folder)


def _run(argv: list[str], failure: str) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    done = subprocess.run(argv, capture_output=True, text=True, errors="replace", env=env)
    if done.returncode != 0:
        lines = [line for line in (done.stderr + done.stdout).splitlines() if line.strip()]
        raise BatchError(f"{failure}: {lines[-1].strip() if lines else f'exit code {done.returncode}'}")


def _relocate(old: Path, new: Path) -> None:
    """Point the environment's activation scripts and its pyvenv.cfg-free entry points at its final folder
    (the interpreter itself finds its environment from its own path)."""
    scripts = new / ("Scripts" if os.name == "nt" else "bin")
    for script in scripts.iterdir():
        if script.is_file() and not script.is_symlink() and script.stat().st_size < 1_000_000:
            try:
                text = script.read_text()
            except (UnicodeDecodeError, OSError):
                continue
            if str(old) in text:
                script.write_text(text.replace(str(old), str(new)))


def _size(folder: Path) -> int:
    total = 0
    for root, _dirs, files in os.walk(folder):
        for name in files:
            path = os.path.join(root, name)
            if not os.path.islink(path):
                total += os.path.getsize(path)
    return total


def _key(name: str) -> tuple:
    return tuple(int(x) for x in name.split(".")) if _VERSION.match(name) else (10**9,)
