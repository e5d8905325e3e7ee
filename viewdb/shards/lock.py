"""One writer per shard folder: an exclusive lock held for the whole of an ingest.

The lock is the file ``.NAME.writer.lock`` beside the folder ``NAME`` (beside rather than
inside, so it also guards the creation of a new folder, which is built under a hidden
name and renamed into place). It holds the owner's pid, host and start time, for the
message a second writer gets, and is locked with ``flock``: the kernel releases it when
its owner exits, however it exits, so a killed ingest never leaves a stale lock. The
owner removes the file when it is done (a waiting writer that locked the removed file
notices and tries again on the new one).

A second writer is refused at once, in one line naming the owner
(:class:`~viewdb.errors.StorageError`), or with ``wait`` seconds it waits for the lock
first.
"""

from __future__ import annotations

import fcntl
import os
import socket
import time
from pathlib import Path

from ..errors import StorageError

__all__ = ["FolderLock", "lock_path"]


def lock_path(folder: Path) -> Path:
    """The lock file of the shard folder ``folder``."""
    return folder.with_name(f".{folder.name}.writer.lock")


class FolderLock:
    """The writer's lock of the shard folder ``folder``, taken on construction (module
    doc); :meth:`release` (or leaving the ``with`` block) gives it up."""

    def __init__(self, folder: str | Path, wait: float = 0.0) -> None:
        self.folder = Path(folder)
        self.path = lock_path(self.folder)
        deadline = time.monotonic() + wait
        while True:
            fd = self._try()
            if fd is not None:
                self._fd: int | None = fd
                return
            if time.monotonic() >= deadline:
                raise StorageError(f"is being written by another ingest ({self._owner()}); wait for it "
                                   "to finish", self.folder)
            time.sleep(0.2)

    def _try(self) -> int | None:
        """The locked file's descriptor, with this process's details written in, or None
        if another process holds it."""
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise StorageError(f"cannot make its lock file: {exc.strerror or exc}", self.path) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        try:
            same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
        except FileNotFoundError:
            same = False
        if not same:  # its owner removed it between our open and our lock: try the new one
            os.close(fd)
            return self._try()
        os.ftruncate(fd, 0)
        stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        os.write(fd, f"pid {os.getpid()} on {socket.gethostname()} since {stamp}\n".encode())
        return fd

    def _owner(self) -> str:
        try:
            text = self.path.read_text(encoding="utf-8", errors="replace").strip()
        except OSError:
            text = ""
        return text.splitlines()[0][:200] if text else "owner unknown"

    def release(self) -> None:
        """Remove the lock file and unlock it (in that order: a writer waiting on it then
        finds it gone and locks a new one)."""
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        finally:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> FolderLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()
