"""Build the extension zips, or the legacy add-on zip, without a Blender binary.

    python -m blender_addon.build [--platform linux-x64 ...] [--dist-dir dist] [--offline]
    python -m blender_addon.build --legacy [--dist-dir dist]

The manifest declares the whole range of Blender's extension platform (4.2 LTS to 5.2 LTS) and the wheels of
every Python those releases run. For each Python (`PYTHONS`: 3.11 for 4.2 to 5.0, 3.13 for 5.1 and 5.2) and each
chosen platform (default: all the manifest declares) the wheels the manifest lists are downloaded into
``./wheels`` (kept as a cache, nothing else in the repository is written), the files selected by the manifest's
``[build]`` rules are staged with a manifest limited to that Python's releases and wheels and to those platforms,
``blender_ext.py build --split-platforms`` (shipped inside the bpy wheel) writes one zip per platform, named
``<id>-<version>-py311-<platform>.zip``, into ``dist/``, and every zip is validated. A Blender outside a zip's
range refuses it at install, and so does one whose Python its wheels are not for ("This Python version (3.14)
isn't compatible with (3.13)"): Linux distributions that build Blender on another Python (Debian's 5.2 runs 3.14)
get a zip of their own where the wheels exist (py314), else the legacy zip with the system's scipy.

``--legacy`` writes ``dist/<id>-<version>-legacy.zip`` for Blender 3.4 to 4.1 (*Preferences > Add-ons > Install*):
the same files under one top folder named after the id, without the manifest and without wheels (those Blenders
bring numpy; scipy comes from the system, e.g. Debian's ``python3-scipy``). Blender reads its ``bl_info``.

Exit code 0 on success, 1 on failure with a one-line message on stderr.
"""

from __future__ import annotations

import argparse
import ast
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile
from pathlib import Path
from types import ModuleType

MANIFEST = "blender_manifest.toml"

#: Each Python Blender's extension releases run: its wheel tag and the releases that run it, [min, max). Blender
#: itself runs 3.11 (4.2 to 5.0) and 3.13 (5.1 to 5.3, the newest measured); Linux distributions build 5.2 on 3.14
#: (Debian's), for whose platforms alone the manifest lists wheels.
PYTHONS = {
    "3.11": ("cp311", "4.2.0", "5.1.0"),
    "3.13": ("cp313", "5.1.0", "5.4.0"),
    "3.14": ("cp314", "5.2.0", "5.3.0"),
}
ROOT = Path(__file__).resolve().parent.parent


class BuildError(RuntimeError):
    """A build step failed; the message is one line."""


def blender_scripts_dir() -> Path:
    """Blender's ``scripts`` folder inside the installed bpy wheel, found without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise BuildError("the bpy module is not installed (pip install bpy)")
    bpy_dir = Path(next(iter(spec.submodule_search_locations)))
    found = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not found:
        raise BuildError(f"no blender_ext.py inside {bpy_dir}")
    return found[-1].parents[3]


def blender_ext_script() -> Path:
    return blender_scripts_dir() / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"


def valid_tags_file() -> Path:
    return blender_scripts_dir() / "modules" / "_bpy_internal" / "extensions" / "tags.py"


def load_blender_ext() -> ModuleType:
    """The build tool as a module, so file selection and wheel platforms match what it does itself."""
    spec = importlib.util.spec_from_file_location("_blender_ext", blender_ext_script())
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_manifest(root: Path = ROOT) -> dict:
    with open(root / MANIFEST, "rb") as fh:
        return tomllib.load(fh)


def wheel_platforms(ext: ModuleType, wheel: str) -> list[str]:
    """Blender platforms a wheel file name is built for, e.g. ``win_amd64`` -> ``["windows-x64"]``."""
    return ext.blender_platforms_from_wheel_platform(Path(wheel).stem.split("-")[-1])


def wheels_for(ext: ModuleType, manifest: dict, platforms: list[str]) -> list[str]:
    """The manifest's wheel paths (``./wheels/...``) needed by any of ``platforms``."""
    return [w for w in manifest.get("wheels", []) if set(wheel_platforms(ext, w)) & set(platforms)]


def python_of_wheel(wheel: str) -> str:
    """The Python (a key of `PYTHONS`) a wheel file is built for."""
    tag = Path(wheel).stem.split("-")[-3]
    found = [python for python, (wheel_tag, _min, _max) in PYTHONS.items() if wheel_tag == tag]
    if not found:
        raise BuildError(f"wheel {Path(wheel).name} is for {tag}, which no Blender release of the range runs")
    return found[0]


def pip_download_command(wheel_filename: str, dest: Path) -> list[str]:
    """A pip command that fetches exactly this wheel file (name, version, Python and platform tags)."""
    name, version, _python_tag, abi_tag, platform_tag = Path(wheel_filename).stem.split("-")[-5:]
    python = python_of_wheel(wheel_filename)
    command = [sys.executable, "-m", "pip", "download", f"{name}=={version}", "--only-binary=:all:", "--no-deps"]
    command += ["--python-version", python, "--implementation", "cp", "--abi", abi_tag, "--dest", str(dest)]
    for tag in platform_tag.split("."):
        command += ["--platform", tag]
    return command


def ensure_wheels(root: Path, wheels: list[str], offline: bool) -> None:
    """Download the missing wheels into ``root/wheels`` and check pip produced the exact file names listed."""
    for wheel in wheels:
        path = root / wheel
        if path.is_file():
            continue
        if offline:
            raise BuildError(f"missing {wheel} and --offline was given")
        path.parent.mkdir(parents=True, exist_ok=True)
        done = subprocess.run(pip_download_command(path.name, path.parent), capture_output=True, text=True)
        if done.returncode != 0 or not path.is_file():
            tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise BuildError(f"pip could not fetch {path.name}: {tail}")


def select_files(ext: ModuleType, root: Path, manifest: dict) -> list[str]:
    """Relative paths the manifest's ``[build]`` exclusions keep, walked the way ``blender_ext`` walks them."""
    patterns = manifest.get("build", {}).get("paths_exclude_pattern")
    if not patterns:
        raise BuildError(f"{MANIFEST} needs [build] paths_exclude_pattern")
    matcher = ext.PathPatternMatch(patterns)

    def keep(path: str, is_dir: bool) -> bool:
        path = path.replace(os.sep, "/")
        return not matcher.test_path(path + "/" if is_dir else path)

    return sorted(rel for _abs, rel in ext.scandir_recursive(str(root), filter_fn=keep) if rel != MANIFEST)


def _toml_list(values: list[str]) -> str:
    return "[\n" + "".join(f'  "{v}",\n' for v in values) + "]"


def limited_manifest(text: str, platforms: list[str], wheels: list[str], python: str | None = None) -> str:
    """The manifest text with its ``platforms`` and ``wheels`` lists replaced, and with `python` its range of
    Blender releases narrowed to those that run that Python."""
    if python is not None:
        _tag, low, high = PYTHONS[python]
        for key, value in (("blender_version_min", low), ("blender_version_max", high)):
            text, count = re.subn(rf'(?m)^{key} = "[^"]*"$', f'{key} = "{value}"', text)
            if count != 1:
                raise BuildError(f"the manifest needs one {key} line")
    for key, values in (("platforms", platforms), ("wheels", wheels)):
        text, count = re.subn(rf"(?ms)^{key} = \[.*?\]", f"{key} = {_toml_list(values)}", text, count=1)
        if count != 1:
            raise BuildError(f"{MANIFEST} has no top-level {key} list")
    return text


def stage(root: Path, files: list[str], manifest_text: str, wheels: list[str], dest: Path) -> None:
    """Copy the selected files and wheels into ``dest`` and write the limited manifest there."""
    for rel in [*files, *wheels]:
        target = dest / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, target)
    (dest / MANIFEST).write_text(manifest_text, encoding="utf-8")


def run_blender_ext(*args: str) -> None:
    command = [sys.executable, str(blender_ext_script()), *args, f"--valid-tags={valid_tags_file()}"]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        lines = (done.stdout + done.stderr).strip().splitlines() or ["no output"]
        raise BuildError(f"blender_ext.py {args[0]} failed: {lines[-1]}")


def zip_name(manifest: dict, platform: str, python: str) -> str:
    line = PYTHONS[python][0].replace("cp", "py")
    return f"{manifest['id']}-{manifest['version']}-{line}-{platform.replace('-', '_')}.zip"


def build(platforms: list[str] | None, dist_dir: Path, root: Path = ROOT, offline: bool = False,
          pythons: list[str] | None = None) -> list[Path]:  # fmt: skip
    """Build and validate one zip per Python (`PYTHONS`, default all) and platform; returns their paths."""
    manifest = read_manifest(root)
    declared = manifest.get("platforms", [])
    platforms = platforms or declared
    unknown = sorted(set(platforms) - set(declared))
    if unknown:
        raise BuildError(f"platform {unknown[0]!r} is not in the manifest's platforms {declared}")
    run_blender_ext("validate", str(root))
    ext = load_blender_ext()
    dist_dir.mkdir(parents=True, exist_ok=True)
    zips = []
    for python in pythons or list(PYTHONS):
        wheels = [w for w in wheels_for(ext, manifest, platforms) if python_of_wheel(w) == python]
        served = [p for p in platforms if any(p in wheel_platforms(ext, w) for w in wheels)]
        if not served:  # a Python no Blender of these platforms runs (3.14: Linux distributions only)
            continue
        ensure_wheels(root, wheels, offline)
        text = limited_manifest((root / MANIFEST).read_text(encoding="utf-8"), served, wheels, python)
        with tempfile.TemporaryDirectory(prefix="welch_ext_") as staging, tempfile.TemporaryDirectory() as out:
            stage(root, select_files(ext, root, manifest), text, wheels, Path(staging))
            run_blender_ext("build", "--source-dir", staging, "--output-dir", out, "--split-platforms")
            for platform in served:  # blender_ext names a zip by its platform only
                built = Path(out) / f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"
                zips.append(Path(shutil.move(built, dist_dir / zip_name(manifest, platform, python))))
    for path in zips:
        run_blender_ext("validate", str(path))
    return zips


def legacy_zip_name(manifest: dict) -> str:
    return f"{manifest['id']}-{manifest['version']}-legacy.zip"


def read_bl_info(source: str) -> dict:
    """``bl_info`` the way Blender's add-on list reads it: the lines from ``bl_info`` to the first blank line,
    as a literal (the module is not run)."""
    lines = source.splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith("bl_info")), None)
    if start is None:
        raise BuildError("__init__.py has no bl_info: Blender before 4.2 can't install the add-on")
    end = next((i for i in range(start, len(lines)) if not lines[i].strip()), len(lines))
    try:
        return ast.literal_eval(ast.parse("\n".join(lines[start:end])).body[0].value)
    except (SyntaxError, ValueError, IndexError, AttributeError) as ex:
        raise BuildError(f"bl_info in __init__.py is not a literal ending at a blank line: {ex}") from None


def check_legacy(path: Path, manifest: dict) -> None:
    """The zip is one package named after the id, with a ``bl_info`` that agrees with the manifest."""
    top = manifest["id"]
    with zipfile.ZipFile(path) as archive:
        names = archive.namelist()
        outside = [n for n in names if not n.startswith(f"{top}/")]
        if outside:
            raise BuildError(f"{path.name}: {outside[0]} is outside the package folder {top}/")
        info = read_bl_info(archive.read(f"{top}/__init__.py").decode("utf-8"))
    version = ".".join(str(v) for v in info.get("version", ()))
    if version != manifest["version"]:
        raise BuildError(f"bl_info version {version} differs from the manifest's {manifest['version']}")
    if info.get("name") != manifest["name"]:
        raise BuildError(f"bl_info name {info.get('name')!r} differs from the manifest's {manifest['name']!r}")


def build_legacy(dist_dir: Path, root: Path = ROOT) -> Path:
    """Build and check the legacy add-on zip; returns its path."""
    manifest = read_manifest(root)
    files = select_files(load_blender_ext(), root, manifest)
    dist_dir.mkdir(parents=True, exist_ok=True)
    path = dist_dir / legacy_zip_name(manifest)
    partial = path.with_name(path.name + ".partial")
    with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
        for rel in files:
            archive.write(root / rel, f"{manifest['id']}/{rel}")
    try:
        check_legacy(partial, manifest)
    except BuildError:
        partial.unlink()
        raise
    os.replace(partial, path)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m blender_addon.build", description=__doc__.splitlines()[0])
    parser.add_argument("--platform", action="append", help="Blender platform, e.g. linux-x64 (repeatable)")
    parser.add_argument("--dist-dir", type=Path, default=ROOT / "dist", help="output folder (default: dist)")
    parser.add_argument("--offline", action="store_true", help="fail instead of downloading missing wheels")
    parser.add_argument("--python", action="append", choices=sorted(PYTHONS),
                        help="only the zips for the Blender releases that run this Python (repeatable)")  # fmt: skip
    parser.add_argument("--legacy", action="store_true", help="build the add-on zip for Blender 3.4 to 4.1 instead")
    args = parser.parse_args(argv)
    if args.legacy and (args.platform or args.python):
        parser.error("--legacy has no platforms or Pythons: it bundles no wheels")
    try:
        if args.legacy:
            zips = [build_legacy(args.dist_dir.resolve())]
        else:
            zips = build(args.platform, args.dist_dir.resolve(), offline=args.offline, pythons=args.python)
    except BuildError as ex:
        print(f"error: {ex}", file=sys.stderr)
        return 1
    for path in zips:
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
