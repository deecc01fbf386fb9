"""Run a render job in another process: this Python (``python -m batch render``), any Blender binary
(``blender -b ... --python batch/blender_entry.py -- render ...``) or another environment's Python with bpy
(``python batch/blender_entry.py -- render ...``), built from the job contract, with its
progress events read back as they come.

The driver of a render side (`batch.jobs.side`) starts its processes here. Nothing here imports bpy.
"""

from __future__ import annotations

import collections
import os
import queue
import re
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

from ..errors import BatchError, Exit
from . import protocol
from .job import RenderJob
from .protocol import ChunkRequest

#: A line in which Blender states why it stopped ("Error: Failed to read blend file ..."), and a Python exception's.
_BLENDER_ERROR = re.compile(r"^Error: \S")
_PYTHON_ERROR = re.compile(r"^[A-Za-z_.]*(Error|Exception|Interrupt): \S")

#: The longest a pass may run: this many times the slowest pass so far, and at least PASS_LIMIT_FLOOR seconds;
#: the environment variable WELCH_PASS_TIMEOUT (seconds) sets it outright. A pass that runs past it hangs.
PASS_LIMIT_FACTOR = 20
PASS_LIMIT_FLOOR = 600.0


def pass_limit(slowest: float) -> tuple[float, str]:
    """Seconds a pass may run before it is taken for hung, given the `slowest` pass so far (0: none yet), and
    where the number comes from."""
    text = os.environ.get("WELCH_PASS_TIMEOUT", "").strip()
    if text:
        try:
            limit = float(text)
        except ValueError:
            limit = 0.0
        if not 0.0 < limit < float("inf"):
            raise BatchError(f"WELCH_PASS_TIMEOUT must be a positive number of seconds, got {text!r}")
        return limit, "WELCH_PASS_TIMEOUT"
    why = (
        f"{PASS_LIMIT_FACTOR} x the slowest pass so far, at least {PASS_LIMIT_FLOOR:.0f} s; WELCH_PASS_TIMEOUT sets it"
    )
    return max(PASS_LIMIT_FLOOR, PASS_LIMIT_FACTOR * slowest), why


#: The folder that holds the ``batch`` and ``welch_core`` packages (the repository or the installed extension).
ROOT = Path(__file__).resolve().parents[2]
ENTRY_SCRIPT = ROOT / "batch" / "blender_entry.py"


TAIL_LINES = 20  # output lines kept per stream for error messages

#: Cycles' CPU threads of a render process, from its environment (`batch.run.limit_threads`): set by a worker
#: that runs several render processes on one machine (`batch.distributed`). Unset: Cycles' own choice (all cores).
THREADS_ENV = "WELCH_RENDER_THREADS"


@dataclass(frozen=True)
class Command:
    """A process to start: its arguments, environment and working folder (None: the caller's)."""

    argv: list[str]
    env: dict[str, str]
    cwd: str | None = None


def job_command(
    job: RenderJob,
    python: str = sys.executable,
    python_paths: tuple[str, ...] | list[str] = (),
    base_env: dict[str, str] | None = None,
    serve: bool = False,
    probe: bool = False,
) -> Command:
    """The command that renders `job` with ``--json-progress`` (and ``--serve``: in chunks asked for on stdin;
    ``--probe``: no pass, only what its scene asks of the passes, `protocol.Probed`).

    With ``job.blender``: that Blender opens the .blend (or starts from factory settings for a built-in scene)
    and runs the entry script with the job after ``--``; with ``job.python``, that Python runs the entry script the
    same way. Without either: ``python -m batch render`` with `python`, the tool's folder and `python_paths`
    (where extra packages live) on ``PYTHONPATH``.
    """
    env = dict(os.environ if base_env is None else base_env)
    env["PYTHONUNBUFFERED"] = "1"  # progress lines must arrive as they are printed, not when a buffer fills
    child = job.replace(blender=None)
    mode = ["--json-progress", *(["--serve"] if serve else []), *(["--probe"] if probe else [])]
    if job.blender:
        # Blender's own Python must not pick up another Python's packages: a pip OpenEXR crashes Blender 3.4.
        for name in ("PYTHONPATH", "PYTHONHOME"):
            env.pop(name, None)
        opened = [child.blend] if child.blend else ["--factory-startup"]
        # An entry script that fails before the tool runs (an import error, say) exits as an internal error.
        argv = [job.blender, "-b", *opened, "--python-exit-code", str(int(Exit.INTERNAL))]
        argv += ["--python", str(ENTRY_SCRIPT), "--", "render", *child.replace(blend=None).to_argv(), *mode]
        return Command(argv, env)
    if job.python:
        # Another environment's Python runs the entry script as a Blender does: the tool's own packages reach it,
        # nothing else of this one's (installed, ROOT is a site-packages whose numpy is built for this Python).
        for name in ("PYTHONPATH", "PYTHONHOME"):
            env.pop(name, None)
        argv = [job.python, str(ENTRY_SCRIPT), "--", "render", *job.replace(python=None).to_argv(), *mode]
        return Command(argv, env)
    if python == sys.executable:
        require_bpy(job)
    paths = [str(ROOT), *python_paths, *filter(None, env.get("PYTHONPATH", "").split(os.pathsep))]
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths))
    return Command([python, "-m", "batch", "render", *child.to_argv(), *mode], env)


#: Seconds a `--blender` has to answer ``--version`` (a binary that hangs is refused, not waited for).
VERSION_TIMEOUT = 60.0

#: Seconds of silence at start-up after which the user is told what the run waits for (a render process that
#: has not started rendering, a program that has not answered what it is).
START_NOTICE = 15.0


def _ask(option: str, argv: list[str], asking: str, notice=None) -> subprocess.CompletedProcess:
    """Run a program the user named (`option` PATH) to ask it what it is, in one line of BatchError when it can't
    be run or does not answer within `VERSION_TIMEOUT`; `notice`, where given, is called with one line saying what
    the run waits for once it has been silent for `START_NOTICE` seconds. It runs in a process group of its own,
    killed whole when it does not answer (or the wait is interrupted): a wrapper script's children too. No
    PYTHONPATH or PYTHONHOME of this Python reaches it."""
    path = argv[0]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    try:
        process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, errors="replace",
                                   env=env, start_new_session=True)  # fmt: skip
    except FileNotFoundError:
        raise BatchError(f"{option} {path}: no such program") from None
    except PermissionError:
        raise BatchError(f"{option} {path}: not executable") from None
    except OSError as exc:
        raise BatchError(f"{option} {path}: can't run it ({exc.strerror or exc})") from None
    with process:
        try:
            first = min(START_NOTICE, VERSION_TIMEOUT) if notice is not None else VERSION_TIMEOUT
            try:
                out, err = process.communicate(timeout=first)
            except subprocess.TimeoutExpired:
                if notice is None or first >= VERSION_TIMEOUT:
                    raise
                notice(f"waiting for {path} to answer {asking} ({first:.0f} s so far; stopped at "
                       f"{VERSION_TIMEOUT:.0f} s; Ctrl-C stops it now)")  # fmt: skip
                out, err = process.communicate(timeout=VERSION_TIMEOUT - first)
        except subprocess.TimeoutExpired:
            raise BatchError(f"{option} {path} did not answer {asking} within {VERSION_TIMEOUT:.0f} s") from None
        finally:
            if process.poll() is None:
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
    return subprocess.CompletedProcess(argv, process.returncode, out, err)


#: The bpy release that runs on each Python, as the `cycles` extra of pyproject.toml installs it
#: (tests/test_packaging.py holds the two to each other).
BPY_RELEASES = {(3, 11): "5.0.1", (3, 13): "5.2.3"}


def no_bpy(version: tuple[int, int] | None = None) -> str:
    """What a Cycles render in a Python without bpy says, in one line: the bpy release for that Python (this one's
    `version` by default) and the command that installs it, or that none runs there; and the other ways."""
    major, minor = version or sys.version_info[:2]
    ways = "render with --blender PATH (a Blender binary) or --python PATH (a Python with bpy)"
    release = BPY_RELEASES.get((major, minor))
    if release is None:
        known = ", ".join(f"{bpy} runs on {a}.{b}" for (a, b), bpy in sorted(BPY_RELEASES.items()))
        return (
            f"rendering with Cycles needs the bpy module, which this Python {major}.{minor} lacks, and no bpy release "
            f"the tool installs runs on it (bpy {known}): {ways}; welch-bias bpy VERSION makes such a Python"
        )
    return (
        f"rendering with Cycles needs the bpy module, which this Python {major}.{minor} lacks: install bpy {release} "
        f"with {sys.executable} -m pip install bpy=={release} (from a checkout of welch-bias: pip install "
        f"'.[cycles]'), or {ways}"
    )


def require_bpy(job: RenderJob) -> None:
    """BatchError (`no_bpy`) when `job` renders with Cycles in this Python and it has no bpy module."""
    import importlib.util

    if job.command is None and not job.blender and not job.python and importlib.util.find_spec("bpy") is None:
        raise BatchError(no_bpy())


#: What `blender_version` and `bpy_version` found, by path: each program is asked once.
_ANSWERS: dict[tuple[str, str], str] = {}


def blender_version(path: str, notice=None) -> str:
    """The version a Blender binary reports (``Blender 4.5.4 LTS``), checked once per path: BatchError in one line
    when `path` can't be run, hangs, crashes, or answers ``--version`` with anything but a Blender's banner.
    `notice`: see `_ask`."""
    if ("blender", path) not in _ANSWERS:
        _ANSWERS["blender", path] = _blender_banner(path, notice)
    return _ANSWERS["blender", path]


def _blender_banner(path: str, notice) -> str:
    done = _ask("--blender", [path, "--version"], "--version", notice)
    banner = next((line.strip() for line in done.stdout.splitlines() if line.startswith("Blender ")), None)
    if done.returncode != 0 or banner is None or not any(c.isdigit() for c in banner):
        said = " ".join(done.stdout.split())[:80] or f"nothing, exit code {done.returncode}"
        raise BatchError(f"--blender {path} is not Blender: --version printed {said!r}")
    return banner


#: The oldest bpy module release the tool drives (the Python API of its render settings and light groups).
OLDEST_BPY = (4, 2)

#: What `bpy_version` runs in the interpreter: its Python and bpy versions, or why there is no bpy.
_PROBE = """
import sys
print("python", sys.version.split()[0])
try:
    import bpy
except Exception as exc:
    print("no-bpy", type(exc).__name__, exc)
else:
    print("bpy", ".".join(map(str, bpy.app.version)), bpy.app.build_hash.decode() if bpy.app.build_hash else "")
"""


def bpy_version(path: str, notice=None) -> str:
    """The bpy release of the Python interpreter `path` (``bpy 4.5.4 (build a1b2c3)``), checked once per path:
    BatchError in one line when `path` can't be run, hangs, is not a Python, has no bpy module, or one older than
    `OLDEST_BPY`. `notice`: see `_ask`."""
    if ("python", path) not in _ANSWERS:
        _ANSWERS["python", path] = _bpy_release(path, notice)
    return _ANSWERS["python", path]


def _bpy_release(path: str, notice) -> str:
    done = _ask("--python", [path, "-c", _PROBE], "which bpy it has", notice)
    said = dict(line.split(" ", 1) for line in done.stdout.splitlines() if " " in line)
    if "python" not in said:
        text = " ".join((done.stdout + done.stderr).split())[:80] or f"nothing, exit code {done.returncode}"
        raise BatchError(f"--python {path} is not a Python interpreter: it answered {text!r}")
    if "no-bpy" in said:
        raise BatchError(
            f"--python {path} (Python {said['python']}) has no bpy module ({said['no-bpy']}): install one into its "
            "environment (pip install bpy==VERSION), or make one with python -m batch bpy VERSION"
        )
    version, _, build = said.get("bpy", "").partition(" ")
    numbers = tuple(int(x) for x in version.split(".") if x.isdigit())
    if not numbers or numbers[:2] < OLDEST_BPY:
        oldest = ".".join(map(str, OLDEST_BPY))
        raise BatchError(f"--python {path} has bpy {version or '?'}: the tool drives bpy {oldest} and later")
    return f"bpy {version}" + (f" (build {build})" if build else "")


class JobProcess:
    """A started job whose stdout (events) and stderr are read by threads, so polling never blocks. With
    `requests`, its stdin stays open for `request` (a job started with ``serve=True``)."""

    def __init__(self, command: Command, requests: bool = False):
        self.events: queue.Queue[protocol.Event] = queue.Queue()
        self.stdout_tail: collections.deque[str] = collections.deque(maxlen=TAIL_LINES)
        self.stderr_tail: collections.deque[str] = collections.deque(maxlen=TAIL_LINES)
        self.last_error = ""
        self._told_to_stop = False
        try:
            self.popen = subprocess.Popen(
                command.argv,
                cwd=command.cwd,
                env=command.env,
                stdin=subprocess.PIPE if requests else subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                encoding="utf-8",
                errors="replace",
                bufsize=1,
                # Its own process group: a wrapper script's children (the real Blender) get our signals too, and
                # none is left holding the output pipes once it is stopped.
                start_new_session=True,
            )
        except OSError as exc:
            raise BatchError(f"can't start {command.argv[0]}: {exc.strerror or exc}") from None
        self._threads = [
            threading.Thread(target=self._read_stdout, daemon=True),
            threading.Thread(target=self._read, args=(self.popen.stderr, self.stderr_tail), daemon=True),
        ]
        for thread in self._threads:
            thread.start()

    def _read_stdout(self) -> None:
        for line in self.popen.stdout:
            event = protocol.parse(line)
            if event is None:
                if line.strip():
                    self.stdout_tail.append(line.rstrip())
                continue
            if isinstance(event, protocol.Failed):
                self.last_error = event.message
            self.events.put(event)

    @staticmethod
    def _read(stream, tail: collections.deque) -> None:
        for line in stream:
            if line.strip():
                tail.append(line.rstrip())

    def request(self, passes: int) -> None:
        """Ask a serving job for its next `passes` passes (it answers with a `Saved` event)."""
        try:
            self.popen.stdin.write(f"{passes}\n")
            self.popen.stdin.flush()
        except (BrokenPipeError, OSError):
            pass  # it has ended: its exit code tells why

    def request_chunk(self, chunk: ChunkRequest) -> None:
        """Ask a serving job for exactly the passes of `chunk` (it answers with a `Saved` event for `chunk.out`)."""
        try:
            self.popen.stdin.write(chunk.to_line() + "\n")
            self.popen.stdin.flush()
        except (BrokenPipeError, OSError, ValueError):  # ValueError: its requests were closed meanwhile
            pass  # it has ended: its exit code tells why

    def close_requests(self) -> None:
        """No more chunks: a serving job finishes and exits."""
        if self.popen.stdin is not None and not self.popen.stdin.closed:
            try:
                self.popen.stdin.close()
            except (BrokenPipeError, OSError):
                pass

    def drain(self) -> list[protocol.Event]:
        """Events received since the last call."""
        out = []
        while True:
            try:
                out.append(self.events.get_nowait())
            except queue.Empty:
                return out

    def poll(self) -> int | None:
        """The exit code once the process has ended and its output has been read, else None."""
        code = self.popen.poll()
        if code is None or any(t.is_alive() for t in self._threads):
            return None
        return code

    def wait(self, timeout: float | None = None) -> int:
        code = self.popen.wait(timeout)
        for thread in self._threads:
            thread.join(timeout)
        return code

    def ask_to_stop(self) -> None:
        """Ask the job to stop after its current pass (it saves and exits 130), without waiting. A serving job
        waiting for its next chunk just sees its requests end."""
        self.close_requests()
        if self.popen.poll() is None and not self._told_to_stop:
            self._told_to_stop = True  # once: a second signal would cut short what the first one started
            self.signal(signal.SIGTERM)

    def stop(self, timeout: float = 30.0) -> None:
        """Ask the job to stop after its current pass (`ask_to_stop`); kill it if it has not ended within
        `timeout` seconds."""
        self.ask_to_stop()
        self.end(timeout)

    def end(self, timeout: float) -> int:
        """Wait up to `timeout` seconds for the job to exit, then kill what is left of its process group."""
        try:
            code = self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            code = None
        self.signal(signal.SIGKILL)  # the job, if it is still there, and anything it started and left behind
        code = self.popen.wait() if code is None else code
        for thread in self._threads:
            thread.join(timeout)
        return code

    def signal(self, sig: int) -> None:
        """Send `sig` to the job's process group (its own children included)."""
        try:
            os.killpg(self.popen.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass  # all of it has ended

    def error_message(self) -> str:
        """The most telling line about a failure: the job's error event, else the renderer's own reason (Blender's
        last "Error: ..." line, a Python exception's last line), else stderr's last line, else stdout's."""
        if self.last_error:
            return self.last_error
        lines = [*self.stdout_tail, *self.stderr_tail]
        for telling in (_BLENDER_ERROR, _PYTHON_ERROR):
            found = [line.strip() for line in lines if telling.match(line.strip())]
            if found:
                return found[-1].removeprefix("Error: ")
        for tail in (self.stderr_tail, self.stdout_tail):
            if tail:
                return tail[-1].removeprefix("error: ")  # the job's own one-line error, said again by the caller
        return ""
