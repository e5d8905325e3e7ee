"""Ctrl-C while libspatialindex calls back into Python (viewdb.interrupts).

The R-tree's pages are read and written by Python callbacks that C++ calls.  A Ctrl-C
whose handler ran inside one used to be swallowed by ctypes (the ingest went on), turned
into "cannot insert into the R-tree" (the object counted as failed), or hand
libspatialindex garbage (the process aborted).  Here SIGINT is raised *inside* a chosen
callback, the worst moment, and must come out as KeyboardInterrupt with the tree whole.
"""

from __future__ import annotations

import signal
import sqlite3
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import sample
from tests.interrupting import ctrl_c_in, sigint_raises
from viewdb.interrupts import interrupts_held
from viewdb.storage.spatial import FourierIndex

D = 6


@pytest.fixture(name="sigint_raises")
def _sigint_raises() -> Iterator[None]:
    with sigint_raises():
        yield


# ------------------------------------------------------------------ interrupts_held
def test_ctrl_c_in_the_block_is_raised_when_the_block_ends(sigint_raises) -> None:
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            signal.raise_signal(signal.SIGINT)
            steps.append("went on")
    assert steps == ["went on"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_replaces_the_blocks_own_error(sigint_raises) -> None:
    with pytest.raises(KeyboardInterrupt) as info:
        with interrupts_held():
            signal.raise_signal(signal.SIGINT)
            raise ValueError("the block's own error")
    assert isinstance(info.value.__context__, ValueError)


def test_nested_holds_raise_once_at_the_outer_end(sigint_raises) -> None:
    steps = []
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held():
            with interrupts_held():
                signal.raise_signal(signal.SIGINT)
            steps.append("inner over")
    assert steps == ["inner over"]


def test_without_ctrl_c_nothing_happens(sigint_raises) -> None:
    with interrupts_held():
        inside = signal.getsignal(signal.SIGINT)
    assert inside is not signal.default_int_handler  # it was held
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_other_threads_and_ignored_sigint_are_left_alone(sigint_raises) -> None:
    seen = []

    def worker() -> None:
        with interrupts_held():
            seen.append(signal.getsignal(signal.SIGINT))

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert seen == [signal.default_int_handler]
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    with interrupts_held():
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN


# ------------------------------------------------------------------ inside the R-tree
@contextmanager
def no_unraisable() -> Iterator[list[str]]:
    """Collects what Python could only print ("Exception ignored ..."), as ctypes does
    with an exception raised in a callback."""
    seen: list[str] = []
    previous = sys.unraisablehook
    sys.unraisablehook = lambda u: seen.append(f"{u.exc_type.__name__} in {u.object!r}")
    try:
        yield seen
    finally:
        sys.unraisablehook = previous


def brute(P: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list[int]:
    return np.flatnonzero(((P >= lo) & (P <= hi)).all(axis=1)).tolist()


BOX = (np.full(D, -0.7), np.full(D, 0.9))


@given(callback=st.sampled_from(["loadByteArray", "storeByteArray"]),
       nth=st.integers(1, 120), query=st.booleans())
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_ctrl_c_inside_a_page_callback_is_an_interrupt_and_the_tree_stays_whole(
    tmp_path: Path, sigint_raises, callback: str, nth: int, query: bool
) -> None:
    rng = np.random.default_rng(nth)
    old, new = rng.normal(size=(400, D)), rng.normal(size=(200, D))
    path = tmp_path / f"t{callback}{nth}{query}.db"
    path.unlink(missing_ok=True)
    conn = sqlite3.connect(path)
    FourierIndex.bulk_create(conn, "f", np.arange(len(old)), old).close()
    conn.commit()
    interrupted, idx = False, None
    # two cached pages: inserts and queries keep loading and storing
    with no_unraisable() as unraisable, ctrl_c_in(callback, nth) as calls:
        try:
            idx = FourierIndex.open(conn, "f", buffer_pages=2)
            if query:
                hits = idx.intersection(*BOX).tolist()
            else:
                with idx.transaction():
                    for i, p in enumerate(new, start=len(old)):
                        idx.insert(i, p)
        except KeyboardInterrupt:
            interrupted = True
    assert unraisable == []
    assert interrupted == (calls[0] >= nth)
    if idx is None:  # interrupted while opening
        idx = FourierIndex.open(conn, "f", buffer_pages=2)
    both = np.vstack([old, new])
    expected = old if (interrupted or query) else both
    assert idx.count == len(expected)
    assert idx.intersection(*BOX).tolist() == brute(expected, *BOX)
    if query and not interrupted:
        assert hits == brute(old, *BOX)
    # and the tree takes the rest as usual
    if len(expected) < len(both):
        with idx.transaction():
            for i, p in enumerate(new, start=len(old)):
                idx.insert(i, p)
        assert idx.intersection(*BOX).tolist() == brute(both, *BOX)
    idx.close()
    conn.close()


# ------------------------------------------------------------------ inside trimesh
def test_ctrl_c_while_trimesh_reads_a_texture_is_an_interrupt(sigint_raises, monkeypatch) -> None:
    """trimesh reads an OBJ's texture inside ``except BaseException`` ("failed to load
    image"; the mesh goes on untextured): a Ctrl-C there used to vanish, and the ingest
    went on. It found this in CI: the second sample object's texture is the first image
    the process opens, so PIL imports its plugins right after the first commit."""
    from PIL import Image

    from viewdb.catalogue.mesh import load_mesh

    opened = []
    original = Image.open

    def open_then_ctrl_c(*args: object, **kwargs: object) -> object:
        opened.append(args)
        signal.raise_signal(signal.SIGINT)
        return original(*args, **kwargs)

    monkeypatch.setattr(Image, "open", open_then_ctrl_c)
    with pytest.raises(KeyboardInterrupt):
        load_mesh(sample("bottle"))
    assert opened  # the interrupt came from inside trimesh's texture loading
    monkeypatch.setattr(Image, "open", original)
    textured = load_mesh(sample("bottle"))  # and nothing stuck: the texture loads
    assert any(getattr(g.visual, "kind", None) == "texture" for g in textured.scene.geometry.values())
