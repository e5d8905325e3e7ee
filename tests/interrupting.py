"""Ctrl-C for tests: SIGINT made deliverable whatever the test runner inherited, and
SIGINT raised inside a chosen R-tree page callback (tests of ``viewdb.interrupts``)."""

from __future__ import annotations

import itertools
import signal
from collections.abc import Iterator
from contextlib import contextmanager

from viewdb.storage.spatial import SqlitePageStorage


def deliverable_sigint() -> None:
    """Run in the child before exec: SIGINT at its default disposition and unblocked,
    whatever this test process inherited. A parent that ignores SIGINT (a shell's
    background job, nohup) passes SIG_IGN on, and Python then installs no Ctrl-C handler;
    a parent that blocks it (some CI runners) passes the blocked mask on, and the signal
    stays pending. Either way a user's viewdb would rightly not be interrupted, so the
    tests give their children what a terminal gives a foreground process."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


@contextmanager
def sigint_raises() -> Iterator[None]:
    """In this process, for the block: SIGINT as a foreground Python in a terminal has
    it, delivered and raising KeyboardInterrupt (see :func:`deliverable_sigint`)."""
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
