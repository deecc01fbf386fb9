"""The extension package: manifest consistency, build + validate with the bpy wheel's blender_ext.py, and a
sandboxed install that enables, disables and re-enables it."""

import json
import os
import platform
import re
import subprocess
import sys
import textwrap
import tomllib
import zipfile
from pathlib import Path

import pytest

from blender_addon import build

ROOT = Path(__file__).resolve().parents[2]
MANIFEST = tomllib.loads((ROOT / "blender_manifest.toml").read_text(encoding="utf-8"))
EXTENSION_TOP_LEVEL = {"__init__.py", "blender_manifest.toml", "blender_addon", "welch_core", "batch", "wheels"}


def host_platform() -> str:
    machine = {"x86_64": "x64", "amd64": "x64", "aarch64": "arm64", "arm64": "arm64"}.get(platform.machine().lower())
    system = {"linux": "linux", "darwin": "macos", "windows": "windows"}.get(platform.system().lower())
    return f"{system}-{machine}"


def test_manifest_version_is_the_package_version():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert MANIFEST["version"] == project["version"]


def test_manifest_wheels_are_the_pinned_runtime_dependencies_for_every_platform():
    from packaging.requirements import Requirement

    pins = {}
    for text in tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["dependencies"]:
        requirement = Requirement(text)
        pins[requirement.name.lower()] = requirement.specifier
    ext = build.load_blender_ext()
    for platform_name in MANIFEST["platforms"]:
        for python, (tag, _low, _high) in build.PYTHONS.items():
            wheels = [w for w in build.wheels_for(ext, MANIFEST, [platform_name]) if build.python_of_wheel(w) == python]
            names = sorted(Path(w).name.split("-")[0] for w in wheels)
            if python == "3.14" and platform_name != "linux-x64":  # only Linux distributions build on 3.14
                assert names == [], platform_name
                continue
            assert names == ["openexr", "scipy"], (platform_name, python)  # numpy is Blender's own
            for wheel in wheels:
                name, version, python_tag, abi_tag = Path(wheel).name.split("-")[:4]
                assert python_tag == abi_tag == tag, wheel
                # the versions bundled are the package's own, but scipy for the Blenders with an older numpy
                assert version in pins[name] or (name, python, version) == ("scipy", "3.11", "1.15.3"), wheel
    assert all(w.startswith("./wheels/") for w in MANIFEST["wheels"])


def test_manifest_fields_follow_blender_rules():
    assert re.fullmatch(r"[a-z][a-z0-9_]*", MANIFEST["id"]) and "__" not in MANIFEST["id"]
    tagline = MANIFEST["tagline"]
    assert len(tagline) <= 64 and tagline[-1].isalnum()
    assert (MANIFEST["blender_version_min"], MANIFEST["blender_version_max"]) == ("4.2.0", "5.4.0")
    assert MANIFEST["type"] == "add-on"
    assert MANIFEST["permissions"]["files"]


def test_build_rules_select_only_the_extension_packages():
    files = build.select_files(build.load_blender_ext(), ROOT, MANIFEST)
    assert {f.split("/")[0] for f in files} <= EXTENSION_TOP_LEVEL
    assert "__init__.py" in files and "blender_addon/__init__.py" in files and "blender_addon/build.py" not in files
    assert not [f for f in files if "__pycache__" in f or f.endswith(".pyc")]


def test_pip_command_fetches_exactly_the_listed_wheel(tmp_path):
    command = build.pip_download_command("scipy-1.17.1-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl",
                                         tmp_path)  # fmt: skip
    assert command[1:] == [
        "-m", "pip", "download", "scipy==1.17.1", "--only-binary=:all:", "--no-deps", "--python-version", "3.11",
        "--implementation", "cp", "--abi", "cp311", "--dest", str(tmp_path),
        "--platform", "manylinux_2_27_x86_64", "--platform", "manylinux_2_28_x86_64",
    ]  # fmt: skip


def test_limited_manifest_keeps_the_rest():
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    limited = tomllib.loads(build.limited_manifest(text, ["linux-x64"], ["./wheels/a-1-cp311-cp311-linux_x86_64.whl"]))
    assert limited["platforms"] == ["linux-x64"] and limited["wheels"] == ["./wheels/a-1-cp311-cp311-linux_x86_64.whl"]
    assert {k: v for k, v in limited.items() if k not in ("platforms", "wheels")} == {
        k: v for k, v in MANIFEST.items() if k not in ("platforms", "wheels")
    }


def test_build_rejects_an_unknown_platform(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "blender_addon.build", "--platform", "plan9-x64", "--dist-dir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 1
    assert done.stderr.startswith("error: platform 'plan9-x64' is not in the manifest's platforms")


INSTALL_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import bpy

    zip_path, ext_id = sys.argv[1], sys.argv[2]
    module = f"bl_ext.user_default.{ext_id}"
    report = {}

    def enabled():
        return module in bpy.context.preferences.addons and hasattr(bpy.types.Scene, "welch_bias")

    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    report["installed_enabled"] = enabled()
    siblings = sys.modules[module + ".blender_addon._siblings"]
    report["addon_module"] = siblings.ADDON_MODULE
    report["welch_core"] = siblings.welch_core.__name__
    report["operator"] = bpy.ops.welch_bias.run.idname()
    prefs = bpy.context.preferences.addons[module].preferences
    report["prefs"] = [prefs.keep_temporary_files, prefs.runs_to_keep]
    import scipy.stats  # the bundled wheel, loaded by this Blender's Python and numpy

    report["scipy"] = scipy.__version__
    report["user_dir"] = str(sys.modules[module + ".blender_addon.session"].user_dir())
    bpy.ops.preferences.addon_disable(module=module)
    report["disabled"] = not enabled()
    bpy.ops.preferences.addon_enable(module=module)
    report["reenabled"] = enabled()
    print("REPORT " + json.dumps(report))
    """
)


@pytest.mark.slow
def test_extension_builds_validates_and_installs(tmp_path):
    target = host_platform()
    if target not in MANIFEST["platforms"]:
        pytest.skip(f"no wheels for {target} in the manifest")
    done = subprocess.run(
        [sys.executable, "-m", "blender_addon.build", "--platform", target, "--dist-dir", str(tmp_path / "dist")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr
    stem = f"{MANIFEST['id']}-{MANIFEST['version']}"
    lines = ("py311", "py313", "py314") if target == "linux-x64" else ("py311", "py313")
    zips = {line: tmp_path / "dist" / f"{stem}-{line}-{target.replace('-', '_')}.zip" for line in lines}
    assert [Path(p) for p in done.stdout.split()] == list(zips.values())
    for line, zip_path in zips.items():
        with zipfile.ZipFile(zip_path) as archive:
            names = archive.namelist()
            inner = tomllib.loads(archive.read("blender_manifest.toml").decode())
        assert {n.split("/")[0] for n in names} == EXTENSION_TOP_LEVEL
        assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]
        assert inner["platforms"] == [target] and inner["build"]["generated"]["platforms"] == [target]
        assert sorted(n for n in names if n.startswith("wheels/")) == sorted(w[2:] for w in inner["wheels"])
        assert all(f"-cp{line[2:]}-" in w for w in inner["wheels"])
        low, high = build.PYTHONS[f"3.{line[3:]}"][1:]
        assert (inner["blender_version_min"], inner["blender_version_max"]) == (low, high)

    # Each zip installs and runs in a release of its range (bpy 5.0.1 here; 5.2.3 LTS on Python 3.13 and 4.5.4
    # LTS where ./dev test made them), and a release outside it refuses it at install.
    module = f"bl_ext.user_default.{MANIFEST['id']}"
    from scipy import __version__ as own_scipy

    # This Python has its own scipy before the extension's; the releases' environments have none but the wheel's.
    for python, line, scipy in ((sys.executable, "py311", own_scipy), (release_python("5.2.3"), "py313", "1.17.1"),
                                (release_python("4.5.4"), "py311", "1.15.3")):  # fmt: skip
        if python is None:
            continue
        done = install(python, zips[line], tmp_path / f"user-{line}-{Path(python).parents[1].name}")
        report = json.loads(done)
        assert report == {
            "installed_enabled": True,
            "addon_module": module,
            "welch_core": module + ".welch_core",
            "operator": "WELCH_BIAS_OT_run",
            "prefs": [False, 10],
            "scipy": scipy,
            "user_dir": report["user_dir"],
            "disabled": True,
            "reenabled": True,
        }
        assert Path(report["user_dir"]).is_dir()
    refused = install(sys.executable, zips["py313"], tmp_path / "user-refused", expect_failure=True)
    assert "This Blender version (5.0.1) doesn't meet the minimum supported version (5.1.0)" in refused


def release_python(version: str) -> str | None:
    """The Python of a cached bpy release (``python -m batch bpy VERSION``), or None."""
    from batch.jobs import releases

    python = releases.python_of(releases.cache_folder() / version)
    return str(python) if python.exists() else None


def install(python: str, zip_path: Path, user: Path, expect_failure: bool = False) -> str:
    """Install and enable the zip in the bpy module of `python` (its own user folder): the report's JSON, or
    with `expect_failure` what Blender printed."""
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    done = subprocess.run([python, "-c", INSTALL_SCRIPT, str(zip_path), MANIFEST["id"]], cwd=user.parent, env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip
    if expect_failure:
        assert done.returncode != 0
        return done.stdout + done.stderr
    lines = [line for line in done.stdout.splitlines() if line.startswith("REPORT ")]
    assert done.returncode == 0 and lines, done.stdout[-2000:] + done.stderr[-2000:]
    return lines[-1][len("REPORT ") :]


# -- the legacy add-on (Blender 3.4 to 4.1) ------------------------------------------------------------------

LEGACY_TOP_LEVEL = {"__init__.py", "blender_addon", "welch_core", "batch"}


def test_bl_info_is_a_literal_blender_can_read():
    info = build.read_bl_info((ROOT / "__init__.py").read_text(encoding="utf-8"))
    assert info["name"] == MANIFEST["name"] and info["category"] == "Render"
    assert info["blender"] == (3, 4, 0) and ".".join(map(str, info["version"])) == MANIFEST["version"]
    assert info["description"] == MANIFEST["tagline"] and info["location"]


def test_legacy_zip_is_one_package_without_wheels(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "blender_addon.build", "--legacy", "--dist-dir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr
    path = Path(done.stdout.strip())
    assert path == tmp_path / f"{MANIFEST['id']}-{MANIFEST['version']}-legacy.zip"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        info = build.read_bl_info(archive.read(f"{MANIFEST['id']}/__init__.py").decode())
    assert {n.split("/")[0] for n in names} == {MANIFEST["id"]}
    assert {n.split("/")[1] for n in names} == LEGACY_TOP_LEVEL
    package = MANIFEST["id"]
    for required in ("batch/blender_entry.py", "blender_addon/overlay.py", "welch_core/__init__.py"):
        assert f"{package}/{required}" in names
    assert not [n for n in names if "__pycache__" in n or n.endswith((".pyc", ".whl", ".toml", "/build.py"))]
    assert info["blender"] == (3, 4, 0)


def test_legacy_build_refuses_an_init_blender_cannot_read(tmp_path):
    root = tmp_path / "root"
    (root / "blender_addon").mkdir(parents=True)
    (root / "blender_addon" / "__init__.py").write_text("")
    (root / "blender_manifest.toml").write_text((ROOT / "blender_manifest.toml").read_text(encoding="utf-8"))
    for init, message in [
        ("def register():\n    pass\n", "__init__.py has no bl_info"),
        ('bl_info = {"name": "Welch Bias Test", "version": (0, 0, 9)}\n', "bl_info version 0.0.9 differs"),
        ('bl_info = {"name": NAME}\n', "bl_info in __init__.py is not a literal"),
    ]:
        (root / "__init__.py").write_text(init)
        with pytest.raises(build.BuildError, match=message):
            build.build_legacy(tmp_path / "dist", root=root)
        assert list((tmp_path / "dist").iterdir()) == []  # nothing half-written is left


def test_legacy_build_has_no_platforms(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "blender_addon.build", "--legacy", "--platform", "linux-x64"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2 and "--legacy has no platforms or Pythons" in done.stderr


LEGACY_INSTALL_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import bpy

    zip_path, module = sys.argv[1], sys.argv[2]
    report = {}

    def enabled():
        return module in bpy.context.preferences.addons and hasattr(bpy.types.Scene, "welch_bias")

    report["install"] = sorted(bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True))
    report["enable"] = sorted(bpy.ops.preferences.addon_enable(module=module))
    report["enabled"] = enabled()
    report["addon_module"] = sys.modules[module + ".blender_addon._siblings"].ADDON_MODULE
    report["operator"] = bpy.ops.welch_bias.run.idname()
    report["prefs"] = bpy.context.preferences.addons[module].preferences.runs_to_keep
    report["draw_handler"] = sys.modules[module + ".blender_addon.overlay"]._handle is not None
    bpy.ops.preferences.addon_disable(module=module)
    report["disabled"] = not enabled()
    print("REPORT " + json.dumps(report))
    """
)


@pytest.mark.slow
def test_legacy_zip_installs_in_blender_50_too(tmp_path):
    """Blender 4.2 and later still install legacy add-ons: the one zip serves every Blender from 3.4."""
    path = build.build_legacy(tmp_path / "dist")
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    done = subprocess.run(
        [sys.executable, "-c", LEGACY_INSTALL_SCRIPT, str(path), MANIFEST["id"]],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("REPORT ")]
    assert done.returncode == 0 and lines, done.stdout[-2000:] + done.stderr[-2000:]
    assert json.loads(lines[-1][len("REPORT ") :]) == {
        "install": ["FINISHED"],
        "enable": ["FINISHED"],
        "enabled": True,
        "addon_module": MANIFEST["id"],
        "operator": "WELCH_BIAS_OT_run",
        "prefs": 10,
        "draw_handler": True,
        "disabled": True,
    }
    assert (tmp_path / "user").is_dir() and list((tmp_path / "user").rglob("overlay.py"))
