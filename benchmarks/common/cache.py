"""On-disk cache under ``benchmarks/cache/``: keys are hashes of what produced a result, so a changed input renders or
computes afresh and an unchanged one is read back.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import importlib
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

BENCHMARKS = Path(__file__).resolve().parents[1]
DEFAULT_DIR = BENCHMARKS / "cache"
REPO = BENCHMARKS.parent


def study_arguments(module: str, doc: str, quick: str, argv: list[str] | None) -> argparse.Namespace:
    """The options every study beside the charts takes (``python -m benchmarks.studies.<module>``): ``--quick``
    (`quick` says what it runs), ``--out`` (default docs/benchmarks) and ``--cache`` (its pools, default this
    cache)."""
    parser = argparse.ArgumentParser(prog=f"python -m benchmarks.studies.{module}", description=doc.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=quick)
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "benchmarks", help="output folder")
    parser.add_argument("--cache", type=Path, default=DEFAULT_DIR, help="pool cache folder")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def digest(*parts: Any) -> str:
    """A short SHA-256 of `parts` as sorted, compact JSON."""
    text = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def source_digest(*folders: str) -> str:
    """Hash of the Python sources of repository `folders`: results computed by that code are stale when it changes."""
    h = hashlib.sha256()
    for folder in folders:
        for path in sorted((REPO / folder).glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


#: welch_core's modules that cannot change a statistical result (file formats, pictures, the lazy-import table):
#: an edit there keeps the cached trials.
NOT_RESULTS = frozenset({"__init__.py", "exr.py", "formats.py", "png.py", "colormap.py"})


@functools.cache
def welch_digest() -> str:
    """Hash of the welch_core sources that compute results (all but `NOT_RESULTS`): the key of cached trials. Taken
    once per process, with every welch_core module imported at that moment (`load_welch_core`), so the key names
    the code that runs even while the files are edited."""
    load_welch_core()
    h = hashlib.sha256()
    for path in sorted((REPO / "welch_core").glob("*.py")):
        if path.name not in NOT_RESULTS:
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def load_welch_core() -> None:
    """Import every welch_core module now (welch_core imports its modules on first use)."""
    for path in sorted((REPO / "welch_core").glob("*.py")):
        if path.stem != "__init__":
            importlib.import_module(f"welch_core.{path.stem}")


def memo_json(cache_dir: Path, name: str, key: str, compute: Callable[[], Any]) -> Any:
    """Return the JSON result stored as ``name-key.json``, or compute, store and return it."""
    path = Path(cache_dir) / f"{name}-{key}.json"
    if path.exists():
        with open(path) as f:
            return json.load(f)
    result = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    with open(tmp, "w") as f:
        json.dump(result, f)
    tmp.replace(path)  # atomic: an interrupted run never leaves a half-written entry
    return result
