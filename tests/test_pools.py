"""The process's shared worker threads (:mod:`viewdb.pools`): one pool per kind and size,
made once, and a forked child's own."""

import os
import signal
import threading
import time

import numpy as np
import pytest

from viewdb.pools import thread_pool
from viewdb.search.knn import TierArrays, brute_force_knn, knn_stack


def test_one_pool_per_kind_and_size_made_once():
    a = thread_pool("viewdb-test", 2)
    assert thread_pool("viewdb-test", 2) is a
    assert thread_pool("viewdb-test", 1) is not a and thread_pool("viewdb-other", 2) is not a
    names = {a.submit(lambda: threading.current_thread().name).result() for _ in range(8)}
    assert names and all(n.startswith("viewdb-test") for n in names)


def test_a_pool_needs_a_thread():
    with pytest.raises(ValueError, match="at least one thread"):
        thread_pool("viewdb-test", 0)


def _tier(rng, objects=6, views=150, n=32):
    owner = np.repeat(np.arange(objects), views)
    curves = np.clip(1 + 0.3 * rng.standard_normal((objects * views, n)), 0.05, None)
    return TierArrays([f"o{i}" for i in range(objects)], owner, curves / curves.mean(axis=1, keepdims=True),
                      group_views=1)


def test_searches_on_shared_threads_answer_as_the_brute_force_and_a_forked_child_searches_too():
    """Two threads share one search's bounds, and the pool outlives the search: the next
    search (and a child forked after it, which has none of the parent's threads) answers
    all the same."""
    rng = np.random.default_rng(4)
    arrays = _tier(rng)
    for _ in range(3):
        q = arrays.curves[int(rng.integers(len(arrays.curves)))] + rng.normal(0, 0.05, 32)
        found, _ = knn_stack(q[None, :], arrays, 3, 2, threads=2)
        expected = brute_force_knn(q, arrays, 3, 2)
        assert [nb.object for nb in found] == [nb.object for nb in expected]
        np.testing.assert_allclose([nb.distance for nb in found], [nb.distance for nb in expected], atol=1e-9)
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        signal.alarm(20)  # a hang ends the child with SIGALRM
        again, _ = knn_stack(q[None, :], arrays, 3, 2, threads=2)
        os._exit(0 if [nb.object for nb in again] == [nb.object for nb in found] else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


class _FailingSource:
    """A source whose rows of object 0 cannot be read; each other read takes a while and
    is counted while it lasts."""

    def __init__(self, inner):
        self.inner, self.reading, self.last_read = inner, 0, 0.0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def rows(self, groups):
        if np.any(self.inner.group_owner[np.asarray(groups, dtype=np.int64)] == 0):
            raise OSError("object 0's rows are unreadable")
        self.reading += 1
        time.sleep(0.02)
        try:
            return self.inner.rows(groups)
        finally:
            self.reading -= 1
            self.last_read = time.perf_counter()


def test_a_failing_part_of_a_search_fails_it_only_after_every_part_has_stopped():
    """The caller may close the source once the search returns or raises: no part of it
    may still be reading then."""
    rng = np.random.default_rng(9)
    arrays = _tier(rng, objects=4, views=40)
    source = _FailingSource(arrays)
    q = arrays.curves[45] + rng.normal(0, 0.05, 32)  # a view of object 1: the other part reads
    with pytest.raises(OSError, match="unreadable"):
        knn_stack(q[None, :], source, 4, 2, threads=2)  # every object found: object 0 is read
    failed_at = time.perf_counter()
    assert source.reading == 0 and 0.0 < source.last_read <= failed_at
