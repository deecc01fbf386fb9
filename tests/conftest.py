"""Fixtures shared by several test modules."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: The Debian sid root with Blender 5.2 that ./dev test makes (as root; see its sid_root).
SID_ROOT = Path.home() / ".cache" / "welch-bias" / "debian-sid"


@pytest.fixture(scope="session")
def blender34() -> str:
    """Debian's Blender 3.4 (on the system Python 3.11) with numpy in its Python, which ./dev test installs as root."""
    blender = shutil.which("blender")
    if blender is None:
        pytest.skip("no blender on PATH (apt-get install blender python3-numpy; ./dev test does it as root)")
    done = subprocess.run([blender, "-b", "--factory-startup", "--python-expr", "import numpy"], capture_output=True)
    if done.returncode != 0 or b"Error" in done.stderr:
        pytest.skip(f"{blender} has no numpy in its Python (apt-get install python3-numpy)")
    return blender


@pytest.fixture(scope="module")
def blender52(tmp_path_factory):
    """A command that runs the root's Blender 5.2 in the caller's folder (chroot), with /tmp, /dev, /proc and this
    tree bind-mounted at their own paths for the time of the tests."""
    if not (SID_ROOT / ".ready").exists():
        pytest.skip(f"no Blender 5.2 root at {SID_ROOT} (./dev test makes it as root from a Debian mirror)")
    if os.geteuid() != 0:
        pytest.skip("entering the Blender 5.2 root needs root (chroot, mount)")
    mounted = []
    try:
        for folder in ("/proc", "/dev", "/tmp", str(ROOT)):
            target = SID_ROOT / folder.lstrip("/")
            target.mkdir(parents=True, exist_ok=True)
            if subprocess.run(["mountpoint", "-q", str(target)]).returncode != 0:
                subprocess.run(["mount", "--bind", folder, str(target)], check=True)
                mounted.append(target)
        wrapper = tmp_path_factory.mktemp("blender52") / "blender"
        wrapper.write_text(f"#!/bin/sh\nexec chroot {SID_ROOT} /bin/sh -c 'cd \"$0\" && exec /usr/bin/blender \"$@\"' "
                           '"$PWD" "$@"\n')  # fmt: skip
        wrapper.chmod(0o755)
        yield str(wrapper)
    finally:
        for target in reversed(mounted):
            subprocess.run(["umount", "-l", str(target)])
