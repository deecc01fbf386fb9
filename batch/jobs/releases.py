"""Other Cycles releases to render with: a cached virtual environment per bpy release (``python -m batch bpy
VERSION``), whose Python a job takes as ``--python PATH`` (`batch.jobs.launch.bpy_version` checks it).

A bpy release is a Python module of about 1 GB (Cycles and all); its environment holds that module and what pip
brings with it (numpy) and nothing of the tool: it runs the tool's entry script (``batch/blender_entry.py``), which
imports the tool's own packages from where they are. The environments live in ``$WELCH_BPY_CACHE``, else
``$XDG_CACHE_HOME/welch-bias/bpy``, else ``~/.cache/welch-bias/bpy``, one folder per release; one is built in a
temporary folder and renamed when it works, so an interrupted or failed install leaves nothing half made.
Nothing here imports bpy.
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

#: The Python each line of releases is built for, newest first: (from major, from minor, Python). A bpy module
#: installs into that Python only (Blender 5.1 moved to 3.13; 4.2 LTS to 5.0 run 3.11; 4.0 and 4.1 ran 3.10).
PYTHONS = ((5, 1, "3.13"), (4, 2, "3.11"), (4, 0, "3.10"))


def python_needed(version: str) -> str:
    """The Python (``3.13``) that bpy `version` is built for."""
    major, minor = (int(x) for x in version.split(".")[:2])
    for first_major, first_minor, python in PYTHONS:
        if (major, minor) >= (first_major, first_minor):
            return python
    raise BatchError(f"bpy {version} is older than the releases this tool renders with (4.0 and later)")


def base_python(version: str, given: str | None = None) -> str:
    """A Python to make the environment of bpy `version` with: `given` (checked), this one where it is the one
    the release needs, else ``python3.13`` (say) on PATH or one that pyenv installed; one line where none is."""
    need = python_needed(version)
    if given is not None:
        found = _python_version(given)
        if found != need:
            raise BatchError(
                f"--base-python {given}: bpy {version} needs Python {need}, this is {found or 'no Python'}"
            )
        return given
    if f"{sys.version_info[0]}.{sys.version_info[1]}" == need:
        return sys.executable
    pyenv = Path(os.environ.get("PYENV_ROOT") or Path.home() / ".pyenv") / "versions"
    candidates = [shutil.which(f"python{need}"), *sorted(pyenv.glob(f"{need}.*/bin/python{need}"), reverse=True)]
    for candidate in candidates:
        if candidate and _python_version(str(candidate)) == need:
            return str(candidate)
    raise BatchError(f"bpy {version} needs Python {need} (its Blender runs it) and there is no python{need} on PATH: "
                     "install one, or name it with --base-python PATH")  # fmt: skip


def _python_version(python: str) -> str | None:
    """'3.13' for a Python executable, None for anything that does not answer as one."""
    try:
        done = subprocess.run([python, "-c", "import sys; print('%d.%d' % sys.version_info[:2])"],
                              capture_output=True, text=True, timeout=60)  # fmt: skip
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


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


def ensure(version: str, say=print, base: str | None = None) -> Path:
    """The Python of the environment with bpy `version`, made (and cached) if it is not there yet, with `base`
    (default: `base_python`'s choice, the Python the release needs)."""
    if not _VERSION.match(version):
        raise BatchError(f"a bpy release is a full version such as 4.5.4 (4.5 would mean 4.5.0), got {version!r}")
    folder = cache_folder() / version
    if python_of(folder).exists():
        bpy_version(str(python_of(folder)))
        return python_of(folder)
    base = base_python(version, base)
    folder.parent.mkdir(parents=True, exist_ok=True)
    building = folder.with_name(f".{version}.building-{os.getpid()}")
    shutil.rmtree(building, ignore_errors=True)
    try:
        say(f"bpy {version}: making a Python {python_needed(version)} environment in {folder} (about 1 GB)")
        _run([base, "-m", "venv", str(building)], "can't make a virtual environment")
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
