"""Exclusive locks that name their holder: one writer per dataset, one owner per simulated-rig folder.

A lock is a file holding one JSON object ``{"host", "pid", "since_utc", "purpose"}``, locked with ``flock(2)``
(exclusive, non-blocking) for as long as it is held. The kernel releases ``flock`` when the holding process dies,
even by SIGKILL, so a lock file that can be locked has no live holder on this host: whatever pid it still names is
stale and the lock is taken over. A file naming *another* host is refused even when it can be locked (``flock``
may not reach across hosts on a network file system, so that holder may still be running there); the refusal
names the file to delete once that process is known to be gone. Releasing empties the file before unlocking, so
an empty file is a free lock. A lock path that is not a regular file (a FIFO, a device, planted by mistake or
malice) is refused in one line, never waited on or read; a holder record is read bounded (`MAX_HOLDER_BYTES`) — the
rule of `uwlab.model.data.read_bytes`, which this layer sits below.

>>> import tempfile, pathlib
>>> path = pathlib.Path(tempfile.mkdtemp()) / "lock"
>>> with OwnerLock(path, "doctest") as lock:
...     try:
...         OwnerLock(path, "second writer").acquire()
...     except LockHeld as refused:
...         refused.holder.pid == os.getpid()
True
"""

from __future__ import annotations

import fcntl
import json
import os
import typing
import socket
import stat
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path

from uwlab.errors import ConfigError, UwlabError

# A holder record is one short JSON line; anything longer is not one (and is not read further)
MAX_HOLDER_BYTES = 4096
# O_NONBLOCK: opening a FIFO never waits for a writer (a regular file's reads are unaffected)
_OPEN_FLAGS = os.O_NONBLOCK | os.O_CLOEXEC


@dataclass(frozen=True)
class Holder:
    """Who holds (or last held) a lock."""

    host: str
    pid: int
    since_utc: str
    purpose: str

    def describe(self) -> str:
        return f"pid {self.pid} on host {self.host} ({self.purpose}, since {self.since_utc})"


class LockHeld(UwlabError):
    """The lock is held by another live process (``holder``; None when it could not be read)."""

    def __init__(self, path: Path, holder: Holder | None, message: str):
        self.path = path
        self.holder = holder
        super().__init__(message)


def read_holder(path: str | os.PathLike) -> Holder | None:
    """The holder named in a lock file (None: no file, an empty file, one that is not a holder record, or not a
    regular file at all); at most `MAX_HOLDER_BYTES` are read."""
    try:
        fd = os.open(path, os.O_RDONLY | _OPEN_FLAGS)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        text = os.read(fd, MAX_HOLDER_BYTES + 1).decode()
        return Holder(**json.loads(text)) if text.strip() and len(text) <= MAX_HOLDER_BYTES else None
    except (OSError, ValueError, TypeError):
        return None
    finally:
        os.close(fd)


def _check_regular(fd: int, path: Path) -> None:
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        raise ConfigError("lock", str(path), "not a regular file (a device or pipe), not a lock file")


def _try_flock(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


class OwnerLock:
    """An exclusive lock at ``path`` for ``purpose`` (said in refusals); a context manager."""

    def __init__(self, path: str | os.PathLike, purpose: str):
        self.path = Path(path)
        self.purpose = purpose
        self._file: typing.BinaryIO | None = None  # the open lock file; closing it (or its collection) unlocks

    @property
    def held(self) -> bool:
        return self._file is not None

    def acquire(self) -> Holder | None:
        """Take the lock; returns the stale holder taken over (None if the lock was free).

        Raises `LockHeld` naming the live holder, and `OSError` when the lock file cannot be created (a read-only
        folder)."""
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | _OPEN_FLAGS, 0o666)
        try:
            _check_regular(fd, self.path)
            if not _try_flock(fd):
                holder = read_holder(self.path)
                who = holder.describe() if holder else "another process (starting or stopping)"
                raise LockHeld(self.path, holder, f"{self.path.parent}: in use by {who}")
            previous = read_holder(self.path)
            if previous is not None and previous.host != socket.gethostname():
                raise LockHeld(
                    self.path,
                    previous,
                    f"{self.path.parent}: locked by {previous.describe()}, another host; if that process "
                    f"is gone, delete {self.path}",
                )
            record = Holder(socket.gethostname(), os.getpid(), _utc_now(), self.purpose)
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(asdict(record)) + "\n").encode(), 0)
            os.fsync(fd)
        except BaseException:
            os.close(fd)
            raise
        self._file = os.fdopen(fd, "r+b", buffering=0)
        return previous

    def release(self) -> None:
        """Empty the lock file and unlock it (nothing if not held)."""
        if self._file is None:
            return
        file, self._file = self._file, None
        with file:
            try:
                file.truncate(0)
            except OSError:
                pass  # a lock that cannot be emptied is still unlocked on closing: stale, taken over next time

    def __enter__(self) -> OwnerLock:
        self.acquire()
        return self

    def __exit__(self, *exc_info) -> None:
        self.release()


def is_stale(path: str | os.PathLike) -> bool:
    """True when the lock file at ``path`` names a holder on this host that no longer holds it (its process died
    without releasing it). A free (empty) lock, a live holder or another host's holder are not stale."""
    try:
        fd = os.open(path, os.O_RDONLY | _OPEN_FLAGS)
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        holder = read_holder(path)
        if holder is None or holder.host != socket.gethostname() or not _try_flock(fd):
            return False
        return read_holder(path) == holder  # not released (emptied) or re-acquired meanwhile
    finally:
        os.close(fd)


def _utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")
