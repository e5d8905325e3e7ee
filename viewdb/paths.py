"""Opening input files safely: only regular files are read.

A FIFO named like a texture or a photo blocks the reader until some other process writes
to it (forever, with Ctrl-C held while trimesh reads); a device such as ``/dev/zero``
never ends. Every file viewdb reads goes through :func:`not_regular` (before a library
such as trimesh opens it) or :func:`open_regular` (which cannot block even if the file is
swapped for a FIFO after the check: it opens non-blocking and checks what it opened).
"""

from __future__ import annotations

import os
import stat
from typing import IO, Any

__all__ = ["not_regular", "open_regular"]


def not_regular(path: str | os.PathLike[str]) -> str | None:
    """Why ``path`` (symbolic links followed) is not a regular file: ``"does not exist"``,
    ``"is a folder"``, ``"is a FIFO (named pipe), not a regular file"``, ...; None if it is
    one."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "does not exist"
    except OSError as exc:
        return f"cannot be read: {exc.strerror or exc}"
    return _kind(mode)


def open_regular(path: str | os.PathLike[str], mode: str = "rb", **kwargs: Any) -> IO[Any]:
    """``open(path, mode, **kwargs)`` (a reading mode) for a regular file only; OSError
    (its ``strerror`` saying what the file is) for anything else. Opening never blocks."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        why = _kind(os.fstat(fd).st_mode)
        if why is not None:
            raise OSError(0, why, str(path))
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return open(fd, mode, **kwargs)  # owns fd from here, closing it even if this fails


def _kind(mode: int) -> str | None:
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a folder, not a file"
    if stat.S_ISFIFO(mode):
        return "is a FIFO (named pipe), not a regular file"
    if stat.S_ISSOCK(mode):
        return "is a socket, not a regular file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "is a device, not a regular file"
    return "is not a regular file"
