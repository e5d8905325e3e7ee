"""Ctrl-C held back while native code may call back into Python.

libspatialindex calls back into Python from C++: the SQLite page storage of
:mod:`viewdb.storage.spatial` and rtree's bulk-load stream.  Python runs a signal handler
at the next bytecode boundary of the main thread, which may be inside such a callback.
A ``KeyboardInterrupt`` raised there cannot unwind through the C++ frames: ctypes
swallows it ("Exception ignored on calling ctypes callback function") and hands
libspatialindex garbage, which can abort the process, or the page storage reports it as
a failed page and it surfaces as a storage error.  Either way Ctrl-C is lost: an ingest
went on to its end with the object being written counted as failed.

:func:`interrupts_held` keeps SIGINT's Python handler from running during a block and runs
it (normally: raises ``KeyboardInterrupt``) as soon as the block is over.
"""

from __future__ import annotations

# The C module: ``signal.signal`` wraps handlers in enums, which costs ~10 µs a call, and
# every R-tree call holds interrupts.
import _signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

__all__ = ["interrupts_held"]


@contextmanager
def interrupts_held() -> Iterator[None]:
    """Run the block with SIGINT held: a Ctrl-C during it takes effect when it ends
    (after the block's own exception, if any, which it then replaces).

    Nothing is changed outside the main thread (Python runs signal handlers only there)
    or when SIGINT's handler is not a Python function (ignored, default, or set by native
    code): no ``KeyboardInterrupt`` could be raised in the block then.  Nesting is fine.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = _signal.getsignal(_signal.SIGINT)
    if not callable(handler):
        yield
        return
    held: list[FrameType | None] = []

    def hold(signum: int, frame: FrameType | None) -> None:
        held.append(frame)

    _signal.signal(_signal.SIGINT, hold)
    try:
        yield
    finally:
        _signal.signal(_signal.SIGINT, handler)
        if held:
            handler(_signal.SIGINT, held[0])
