"""`./dev`'s Debian mirror for the Blender 5.2 root (debian_mirror.py): the machine's own apt sources, one-line or
deb822, or WELCH_DEBIAN_MIRROR; and no package host's address written into the repository."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HELPER = ROOT / "debian_mirror.py"

#: Mirrors of the samples, on a reserved name (RFC 2606) that no package host has.
MIRROR = "http://mirror.example" + "/debian"  # a reserved example host, written in two parts like any address here
LOCAL = "https://cache.example:3142/debian"

SOURCES_DEB822 = f"""\
Types: deb
# {LOCAL}
URIs: {MIRROR}
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: {MIRROR}-security
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
"""

SECURITY_ONLY = f"""\
Types: deb
URIs: {MIRROR}-security
Suites: bookworm-security
Components: main
"""

OTHER_VENDOR = """\
Types: deb
URIs: https://vendor.example/node_22.x
Suites: nodistro
Components: main
"""


def choose(apt_dir, **env):
    """The helper's run on the apt configuration folder `apt_dir` (without WELCH_DEBIAN_MIRROR unless given)."""
    environ = {k: v for k, v in os.environ.items() if k != "WELCH_DEBIAN_MIRROR"} | env
    return subprocess.run([sys.executable, str(HELPER), "--apt-dir", str(apt_dir)], env=environ,
                          capture_output=True, text=True)  # fmt: skip


def apt(tmp_path, files):
    """An apt configuration folder holding `files` ({path under it: text})."""
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    return tmp_path


def test_deb822_main_archive_not_security_nor_other_vendors(tmp_path):
    folder = apt(tmp_path, {
        "sources.list.d/debian.sources": SOURCES_DEB822,
        "sources.list.d/a-nodesource.sources": OTHER_VENDOR,  # read first (apt's order), not Debian's suites
        "sources.list.d/0-security.sources": SECURITY_ONLY,  # read first, the security archive
        "sources.list.d/0-disabled.sources.disabled-by-admin": SOURCES_DEB822.replace(MIRROR, LOCAL),  # not a source
    })  # fmt: skip
    done = choose(folder)
    assert done.returncode == 0, done.stderr
    assert done.stdout == MIRROR + "\n"
    assert done.stderr.splitlines() == [
        f"dev: Debian mirror {MIRROR} (from {folder}/sources.list.d/debian.sources; WELCH_DEBIAN_MIRROR sets another)"
    ]


def test_deb822_disabled_stanza_and_continuation_lines(tmp_path):
    sources = f"""\
Types: deb deb-src
URIs: {LOCAL}
Suites: sid
Components: main
Enabled: no

Types: deb
URIs:
 {MIRROR}/
Suites:
 trixie
Components: main contrib
"""
    done = choose(apt(tmp_path, {"sources.list.d/debian.sources": sources}))
    assert done.returncode == 0 and done.stdout == MIRROR + "\n", done.stderr


def test_one_line_format(tmp_path):
    sources_list = f"""\
# deb {LOCAL} sid main
deb-src {LOCAL} sid main
deb [arch=amd64 signed-by=/usr/share/keyrings/vendor.gpg] https://vendor.example/apt stable-vendor main
deb https://vendor.example/ubuntu jammy main
deb [ arch=amd64 trusted=yes ] {MIRROR} bookworm main contrib  # the archive
deb {MIRROR}-security bookworm-security main
"""
    folder = apt(tmp_path, {"sources.list": sources_list, "sources.list.d/other.list": f"deb {LOCAL} sid main\n"})
    done = choose(folder)
    assert done.returncode == 0, done.stderr
    assert done.stdout == MIRROR + "\n"
    assert f"(from {folder}/sources.list;" in done.stderr


def test_one_line_list_in_sources_list_d(tmp_path):
    folder = apt(tmp_path, {
        "sources.list": "deb https://vendor.example/apt nodistro main\n",
        "sources.list.d/debian.list": f"deb {LOCAL} unstable main\ndeb {MIRROR} sid main\n",
        "sources.list.d/debian.list.save": f"deb {MIRROR} sid main\n",
    })  # fmt: skip
    done = choose(folder)
    assert done.returncode == 0 and done.stdout == LOCAL + "\n", done.stderr


def test_the_variable_overrides_the_sources(tmp_path):
    folder = apt(tmp_path, {"sources.list.d/debian.sources": SOURCES_DEB822})
    done = choose(folder, WELCH_DEBIAN_MIRROR=LOCAL)
    assert done.returncode == 0, done.stderr
    assert done.stdout == LOCAL + "\n"
    assert done.stderr.splitlines() == [f"dev: Debian mirror {LOCAL} (from WELCH_DEBIAN_MIRROR)"]
    empty = choose(tmp_path / "nothing", WELCH_DEBIAN_MIRROR=MIRROR)
    assert empty.returncode == 0 and empty.stdout == MIRROR + "\n", empty.stderr


@pytest.mark.parametrize("files", [{}, {"sources.list.d/s.sources": SECURITY_ONLY + "\n" + OTHER_VENDOR}])
def test_none_found(tmp_path, files):
    folder = apt(tmp_path, files)
    done = choose(folder)
    assert done.returncode == 1
    assert done.stdout == ""
    assert done.stderr.splitlines() == [
        f"dev: no Debian mirror in {folder}'s sources and no WELCH_DEBIAN_MIRROR: no Blender 5.2 root, "
        "its tests will be skipped"
    ]


def test_dev_takes_the_mirror_from_the_helper():
    dev = (ROOT / "dev").read_text()
    assert '"$here/debian_mirror.py"' in dev and 'sid "$root" "$mirror"' in dev


#: A package host's address: an archive or index path right after the host (Debian's and Ubuntu's archives,
#: a Python package index's /simple), or a well-known package host. Reserved names (RFC 2606) are no package host.
ADDRESS = re.compile(r"https?://(?!(?:[\w-]+\.)*(?:example|test|invalid|localhost)\b)[A-Za-z0-9.-]+(?::\d+)?"
                     r"/(?:debian|debian-security|ubuntu|simple)(?=[/\"'\s`)]|$)", re.MULTILINE)  # fmt: skip
HOSTS = re.compile(
    r"\b(?:(?:deb|security|ftp|snapshot|httpredir|cdn-fastly\.deb|ftp\.[a-z]{2})\.debian|"
    r"(?:[a-z]{2}\.)?(?:archive|security)\.ubuntu|pypi\.python|pypi|files\.pythonhosted|registry\.npmjs|"
    r"registry\.yarnpkg)\.(?:org|com)\b"
)


def test_no_package_host_in_the_repository():
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True)
    if listed.returncode != 0:
        pytest.skip("not a git checkout: no tracked files to look through")
    found = []
    for name in listed.stdout.decode().split("\0"):
        path = ROOT / name
        if not name or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data:
            continue  # binary (images, scenes)
        text = data.decode(errors="replace")
        for match in [*ADDRESS.finditer(text), *HOSTS.finditer(text)]:
            found.append(f"{name}:{text.count(chr(10), 0, match.start()) + 1}: {match.group()}")
    assert found == [], "package hosts written into the repository:\n" + "\n".join(found)


@pytest.mark.parametrize(
    "text",
    [
        "http://" + "deb.debian" + ".org/debian",
        "https://" + "ftp.de.debian" + ".org/debian/",
        "see " + "files.python" + "hosted.com",
        "--index-url https://mirror.studio.lan" + "/simple",  # in pieces: this file is looked through too
        "debootstrap sid root http://mirror.studio.lan" + "/debian &&",
        "'http://10.0.0.5:3142" + "/debian'",
    ],
)
def test_the_address_patterns_find_package_hosts(text):
    assert ADDRESS.search(text) or HOSTS.search(text)


@pytest.mark.parametrize("text", [MIRROR, LOCAL, "http://www.w3.org/2000/svg", "tcp://127.0.0.1:8786"])
def test_the_address_patterns_leave_other_addresses(text):
    assert not (ADDRESS.search(text) or HOSTS.search(text))
