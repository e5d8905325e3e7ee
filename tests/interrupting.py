"""Ctrl-C for tests: SIGINT raising KeyboardInterrupt in this process for a block, and
SIGINT raised inside a chosen R-tree page callback (tests of ``viewdb.interrupts``)."""

from __future__ import annotations

import itertools
import signal
from collections.abc import Iterator
from contextlib import contextmanager

from viewdb.storage.spatial import SqlitePageStorage


@contextmanager
def sigint_raises() -> Iterator[None]:
    """In this process, for the block: SIGINT as a foreground Python in a terminal has
    it, delivered and raising KeyboardInterrupt (see :func:`benchmarks.support.serving.deliverable_sigint`)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    mask = signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        signal.signal(signal.SIGINT, previous)


@contextmanager
def ctrl_c_in(callback: str, nth: int) -> Iterator[list[int]]:
    """SIGINT raised at the start of the ``nth`` call of a page-storage callback
    (``loadByteArray`` or ``storeByteArray``) during the block: the worst moment, with
    C++ frames between the handler and the caller. Trees opened in the block keep the
    wrapper, disarmed at its end. Yields the running count of calls."""
    original = getattr(SqlitePageStorage, callback)
    counter = itertools.count(1)
    calls, armed = [0], [True]

    def wrapper(self: SqlitePageStorage, *args: object) -> object:
        if armed[0]:
            calls[0] = next(counter)
            if calls[0] == nth:
                signal.raise_signal(signal.SIGINT)
        return original(self, *args)

    setattr(SqlitePageStorage, callback, wrapper)
    try:
        yield calls
    finally:
        armed[0] = False
        setattr(SqlitePageStorage, callback, original)
