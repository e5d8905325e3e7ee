"""The process's shared worker threads (:mod:`viewdb.pools`): one pool per kind and size,
made once, and a forked child's own."""

import os
import signal
import threading

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
