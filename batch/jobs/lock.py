"""One writer per output: an exclusive lock held while a job writes a statistics file.

The lock is a small file next to the output (``.welch-lock-<hash>``, short whatever the output's name) locked
with ``flock``: the kernel releases it when the holder dies, however it dies, so a killed run never leaves the
output locked. It holds the holder's PID so the refusal can name it.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
from pathlib import Path

from ..errors import BatchError


class OutputLock:
    """``with OutputLock(path):`` — raises BatchError at once when another process holds `path`."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        digest = hashlib.sha1(self.path.name.encode("utf-8", "surrogateescape")).hexdigest()[:16]
        self.lock_path = self.path.parent / f".welch-lock-{digest}"
        self._fd: int | None = None

    def __enter__(self) -> OutputLock:
        while True:
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o666)
            except OSError as exc:
                raise BatchError(f"can't create the lock file {self.lock_path}: {exc.strerror or exc}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(fd, 32).decode("ascii", "replace").strip() or "unknown"
                os.close(fd)
                raise BatchError(
                    f"{self.path} is being written by another process (PID {holder}); wait for it to finish or "
                    "choose another --out"
                ) from None
            # The holder before us may have removed the file between our open and our lock: lock the live one.
            try:
                same = os.stat(self.lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        try:
            os.ftruncate(fd, 0)
            if os.write(fd, str(os.getpid()).encode()) == 0:
                raise OSError(28, "No space left on device")
        except OSError as exc:  # a full disk: no lock file left behind, and the error names it
            self.lock_path.unlink(missing_ok=True)
            os.close(fd)
            raise BatchError(f"can't write the lock file {self.lock_path}: {exc.strerror or exc}") from None
        self._fd = fd
        return self

    def __exit__(self, *_exc) -> None:
        if self._fd is not None:
            self.lock_path.unlink(missing_ok=True)  # while still locked: a waiter then re-checks the inode
            os.close(self._fd)
            self._fd = None


def process_alive(pid: int) -> bool:
    """Whether process `pid` exists (files named after a dead process's PID are leftovers to clean up)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def output_folder(path: str | os.PathLike) -> Path:
    """The folder `path` is written into, created where it is missing (``--out runs/x.npz`` makes ``runs/``);
    BatchError in one line where it can't be made or written into."""
    folder = Path(os.path.abspath(path)).parent
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise BatchError(f"can't create the folder {folder}: {exc.strerror or exc}") from None
    if not os.access(folder, os.W_OK):
        raise BatchError(f"can't write into {folder}: the folder is not writable")
    return folder
