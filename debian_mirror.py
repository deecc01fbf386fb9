"""The Debian mirror `./dev test` makes its Debian sid root from: WELCH_DEBIAN_MIRROR where set, else the URI of
the machine's own apt sources for Debian's main archive.

    python debian_mirror.py [--apt-dir DIR]

The sources are read as apt reads them from DIR (default /etc/apt): sources.list, then sources.list.d/*.list
(one-line format: ``deb [options] URI suite components``) and sources.list.d/*.sources (deb822 stanzas: ``Types``,
``URIs``, ``Suites``, ``Enabled``), in apt's order; other files there (disabled or backed-up ones) are not sources.
The first ``deb`` source over http(s) with a Debian suite (a codename such as bookworm or sid, or stable, testing,
unstable; bare or with -updates, -backports or -proposed-updates) and the component main is taken, not the security
or debug archive: other vendors' sources (their suites or components are not Debian's) and Ubuntu's do not serve
sid. Where that guess is wrong, WELCH_DEBIAN_MIRROR names the mirror.

Prints the mirror on stdout and one line on stderr saying which was used; exit code 0. Where none is found it
prints nothing on stdout, one line on stderr saying so, and exits with 1.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

VARIABLE = "WELCH_DEBIAN_MIRROR"

#: Debian's release codenames and suite names; a suite is Debian's when its part before the first "-" is one.
DEBIAN_SUITES = frozenset(
    "buzz rex bo hamm slink potato woody sarge etch lenny squeeze wheezy jessie stretch buster bullseye bookworm "
    "trixie forky duke sid stable testing unstable oldstable oldoldstable experimental rc-buggy".split()
)
#: The suffixes of the main archive's other suites (bookworm-updates); the security and debug archives' suites
#: (bookworm-security, sid-debug) are elsewhere and do not serve sid's packages.
MAIN_SUFFIXES = frozenset({"updates", "backports", "backports-sloppy", "proposed-updates"})
OTHER_ARCHIVES = ("security", "debug")


def debian_suite(suite: str) -> bool:
    """Whether `suite` is one of the main archive's: a Debian suite name, bare or with a suffix of the main
    archive's (not the security or debug archive's, nor another vendor's)."""
    suite = suite.strip("/")
    if suite in DEBIAN_SUITES:
        return True
    base, _, suffix = suite.partition("-")
    return base in DEBIAN_SUITES and suffix in MAIN_SUFFIXES


def main_archive(uri: str) -> bool:
    """Whether `uri` can be the main archive for debootstrap: http(s), its path not the security or debug archive."""
    if not re.match(r"https?://", uri):
        return False  # file:, cdrom:, mirror+...: lists or local copies debootstrap can't take as a mirror
    return not uri.rstrip("/").rsplit("/", 1)[-1].endswith(tuple(f"-{name}" for name in OTHER_ARCHIVES))


Source = tuple[str, list[str], list[str]]  # URI, suites, components


def one_line_sources(text: str) -> list[Source]:
    """(URI, [suite], components) of each ``deb`` line of a one-line sources file (``deb-src`` and comments skipped)."""
    found = []
    for line in text.splitlines():
        words = line.split("#", 1)[0].split()
        if not words or words[0] != "deb":
            continue
        words = words[1:]
        if words and words[0].startswith("["):  # options: [arch=amd64 signed-by=...], spaces allowed inside
            while words and not words[0].endswith("]"):
                words = words[1:]
            words = words[1:]
        if len(words) >= 2:
            found.append((words[0], [words[1]], words[2:]))
    return found


def deb822_sources(text: str) -> list[Source]:
    """(URI, suites, components) of each URI of each enabled ``deb`` stanza of a deb822 sources file."""
    stanzas: list[dict[str, str]] = [{}]
    key = None
    for line in text.splitlines():
        if line.startswith("#"):
            continue
        if not line.strip():
            if stanzas[-1]:
                stanzas.append({})
            key = None
        elif line[0] in " \t" and key:  # a field's continuation line
            stanzas[-1][key] += " " + line.strip()
        elif ":" in line:
            key, value = line.split(":", 1)
            key = key.strip().lower()
            stanzas[-1][key] = value.strip()
    found = []
    for stanza in stanzas:
        if "deb" not in stanza.get("types", "").split() or stanza.get("enabled", "yes").lower() == "no":
            continue
        suites, components = stanza.get("suites", "").split(), stanza.get("components", "").split()
        found += [(uri, suites, components) for uri in stanza.get("uris", "").split()]
    return found


def source_files(apt_dir: Path) -> list[Path]:
    """The files apt reads its sources from, in its order."""
    parts = apt_dir / "sources.list.d"
    found = [apt_dir / "sources.list"] if (apt_dir / "sources.list").is_file() else []
    if parts.is_dir():
        found += sorted(p for p in parts.iterdir() if p.is_file() and p.suffix in (".list", ".sources"))
    return found


def find_mirror(apt_dir: Path) -> tuple[str, Path] | None:
    """The first Debian main-archive URI of the sources under `apt_dir` and the file that names it, or None."""
    for path in source_files(apt_dir):
        try:
            text = path.read_text(errors="replace")
        except OSError:
            continue
        sources = deb822_sources(text) if path.suffix == ".sources" else one_line_sources(text)
        for uri, suites, components in sources:
            if main_archive(uri) and "main" in components and any(debian_suite(suite) for suite in suites):
                return uri.rstrip("/"), path
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--apt-dir", type=Path, default=Path("/etc/apt"), help="apt's configuration folder")
    args = parser.parse_args(argv)
    chosen = os.environ.get(VARIABLE, "").strip()
    if chosen:
        print(f"dev: Debian mirror {chosen} (from {VARIABLE})", file=sys.stderr)
    else:
        found = find_mirror(args.apt_dir)
        if found is None:
            print(f"dev: no Debian mirror in {args.apt_dir}'s sources and no {VARIABLE}: no Blender 5.2 root, "
                  "its tests will be skipped", file=sys.stderr)  # fmt: skip
            return 1
        chosen = found[0]
        print(f"dev: Debian mirror {chosen} (from {found[1]}; {VARIABLE} sets another)", file=sys.stderr)
    print(chosen)
    return 0


if __name__ == "__main__":
    sys.exit(main())
