"""This process's worker threads, made once and shared.

Starting a thread costs about half a millisecond here; a search split over two threads
for each query paid that twice per query (about 1 ms of the ``fast`` plan's 21 ms). So
each kind of work keeps one pool per size (:func:`thread_pool`), made on first use.

Two rules keep a shared pool safe. What runs on a pool never submits to the same pool
and waits (it could wait on itself), and it holds no state of one query that another
query's work could see (each submits its own work and waits for its own futures; two
queries at once share the threads, not the results). A forked child has none of its
parent's threads: it forgets the pools and makes its own.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

__all__ = ["thread_pool"]

_POOLS: dict[tuple[str, int], ThreadPoolExecutor] = {}
_LOCK = threading.Lock()


def _forget_pools() -> None:
    """In a forked child: none of the parent's threads (nor its lock's holder) is there."""
    global _LOCK
    _POOLS.clear()
    _LOCK = threading.Lock()


os.register_at_fork(after_in_child=_forget_pools)


def thread_pool(name: str, threads: int) -> ThreadPoolExecutor:
    """This process's pool of ``threads`` threads for work of kind ``name`` (also the
    threads' name prefix), made on first use (module doc for what may run on it)."""
    if threads < 1:
        raise ValueError(f"a pool needs at least one thread, got {threads}")
    with _LOCK:
        key = (name, threads)
        if key not in _POOLS:
            _POOLS[key] = ThreadPoolExecutor(threads, thread_name_prefix=name)
        return _POOLS[key]
