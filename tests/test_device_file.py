"""The compact client file: quantised curves with a proven error bound, so CS1 stays
exactly ``server``; smaller than the float32 format; a client file written before it still
opens read-only and answers."""

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import viewdb
from tests.reference import naive_dtw, naive_shifted
from viewdb.config import ClientFileConfig
from viewdb.errors import StorageError
from viewdb.recognition.client_tier import ClientTier
from viewdb.search.knn import brute_force_knn
from viewdb.search.quantised import distance_bound, round_up, upper_distance
from viewdb.search.shifts import ShiftWindow
from viewdb.storage.codecs import decode_array, encode_quantised
from viewdb.storage.schema import SCHEMA_REVISION

DATA = Path(__file__).parent / "data"


def _mirror(c):
    return [c[(-i) % len(c)] for i in range(len(c))]


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 10), st.integers(0, 5), st.integers(8, 24),
       st.integers(0, 23), st.booleans())
def test_the_quantisation_bound_holds_against_brute_force_dtw(seed, bits, band, n, shift, near):
    rng = np.random.default_rng(seed)
    c = (rng.uniform(0.2, 2.5, n) * rng.choice([1e-3, 1.0, 3.0])).astype(np.float32)
    blob, errors = encode_quantised(c[None], bits)
    decoded = decode_array(blob, np.float32, (1, n))[0]
    e = decoded.astype(np.float64) - c
    assert errors[0] == pytest.approx([np.sqrt(e @ e), np.abs(e).max()], rel=1e-12, abs=0)
    bound = float(distance_bound(errors[0], n, band))
    # a query near the curve (where the error matters most) or anywhere
    q = c + rng.normal(0, 0.01, n) if near else rng.uniform(0, 3, n)
    q = naive_shifted(q, shift % n)
    for stored, exact in ((decoded, c), (_mirror(list(decoded)), _mirror(list(c)))):
        d_exact, d_quantised = naive_dtw(q, exact, band), naive_dtw(q, stored, band)
        assert abs(d_quantised - d_exact) <= bound + 1e-12
        assert upper_distance(d_quantised, bound) >= d_exact


def test_the_bound_needs_its_path_term():
    """With a band, a path visits a column several times: the L2 norm of the error alone
    is no bound (a search finds a counterexample); the bound with its path term holds."""
    rng = np.random.default_rng(0)
    beaten = 0
    for _ in range(300):
        c, q = rng.uniform(0.5, 1.5, 8), rng.uniform(0.5, 1.5, 8)
        e = np.zeros(8)
        e[rng.integers(8)] = rng.choice([-0.1, 0.1])
        moved = abs(naive_dtw(q, c, 2) - naive_dtw(q, c + e, 2))
        beaten += moved > 0.1 + 1e-12
        assert moved <= float(distance_bound(np.array([0.1, 0.1]), 8, 2)) + 1e-12
    assert beaten


@settings(max_examples=300, deadline=None)
@given(st.floats(1e-9, 1e6, allow_nan=False))
def test_round_up_is_short_and_never_below(x):
    y = round_up(x)
    assert y >= x and y <= x * (1 + 1e-6) and len(repr(y)) <= 14


def test_a_bad_quantised_blob_is_refused():
    blob, _ = encode_quantised(np.ones((2, 16), np.float32))
    with pytest.raises(StorageError, match="data bytes"):
        decode_array(blob[:-1])
    with pytest.raises(ValueError, match="bits"):
        encode_quantised(np.ones((2, 16), np.float32), 17)


@pytest.fixture(scope="module")
def clients(tiered_db, tmp_path_factory):
    """The tiered db's client file at 90°, compact and exact (float32)."""
    folder = tmp_path_factory.mktemp("device")
    with viewdb.open(tiered_db, create=False) as db:
        db.export_client(folder / "compact.db", client_gap=90)
        db.export_client(folder / "exact.db", client_gap=90, file=ClientFileConfig(curve_bits=0))
    return folder / "compact.db", folder / "exact.db"


def test_the_compact_file_is_smaller_and_checks_clean(clients):
    compact, exact = clients
    with viewdb.open(compact, read_only=True) as c, viewdb.open(exact, read_only=True) as e:
        ci, ei = c.info(), e.info()
        assert ci.curve_storage == "quantised" and ei.curve_storage == "float32"
        assert ci.rows["views"] == ei.rows["views"] > 0 and ci.rows["curves"] == 0
        assert ci.file_bytes < 0.6 * ei.file_bytes  # 36 views: pages of schema dominate
        assert ci.bytes_per_view == pytest.approx(ci.file_bytes / ci.rows["views"])
        assert c.check().ok, c.check().problems
        assert e.check().ok, e.check().problems


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.integers(0, 8),
       st.none() | st.builds(ShiftWindow, st.integers(0, 127), st.integers(0, 6), st.integers(1, 3)))
def test_the_client_sends_upper_bounds_of_the_exact_distances(clients, seed, k, band, window):
    compact, exact = clients
    rng = np.random.default_rng(seed)
    with viewdb.open(compact, read_only=True) as c, viewdb.open(exact, read_only=True) as e:
        arrays, _ = e.search_tier("sparse")
        q = arrays.curves[rng.integers(len(arrays.curves))].astype(np.float64)
        q = np.roll(q, rng.integers(128)) + rng.normal(0, rng.choice([0.0, 0.01, 0.1]), 128)
        q = np.clip(q, 0, None)
        sent = ClientTier(c._catalogue).candidates(q, k, band, window)
        shifts = [0] if window is None else window.shifts(128).tolist()
        truth: dict[str, float] = {}
        for s in shifts:
            for nb in brute_force_knn(np.roll(q, -s), arrays, arrays.n_objects, band):
                truth[nb.object] = min(truth.get(nb.object, np.inf), nb.distance)
        tier = c._catalogue.tier_reader()
        with tier.snapshot() as reader:
            worst = float(distance_bound(reader.tier("sparse").errors, 128, band).max())
        assert len(sent) == min(k, arrays.n_objects)
        for cand in sent:
            assert truth[cand.object] <= cand.distance <= truth[cand.object] + 2 * worst + 1e-6


def _sha(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_a_client_file_from_revision_0005_opens_read_only_and_cs1_stays_exact(tmp_path):
    full, old = tmp_path / "full.db", tmp_path / "client.db"
    shutil.copy(DATA / "full_0005.db", full)
    shutil.copy(DATA / "client_0005.db", old)
    before = _sha(old)
    rng = np.random.default_rng(5)
    with viewdb.open(full, create=False) as db, viewdb.open(old, read_only=True) as client:
        assert db.info().schema_revision == SCHEMA_REVISION  # the full copy was upgraded
        assert client.info().schema_revision == "0005" and client.role == "client"
        assert client.info().curve_storage == "float32"
        assert client.check().ok, client.check().problems
        db.export_client(tmp_path / "compact.db", client_gap=90)
        arrays, _ = db.search_tier("full")
        with viewdb.open(tmp_path / "compact.db", read_only=True) as compact:
            for _ in range(24):
                q = arrays.curves[rng.integers(len(arrays.curves))] + rng.normal(0, 0.05, 128)
                q = np.roll(np.clip(q, 0, None), rng.integers(128))
                window = ShiftWindow(int(rng.integers(128)), 4) if rng.random() < 0.5 else None
                for k, band in ((1, 6), (2, 0), (3, 3)):
                    server = db.recognise(q, k, band=band, plan="server", shifts=window).results
                    for side in (client, compact):
                        cs1 = db.recognise(q, k, band=band, plan="cs1", client=side, shifts=window)
                        assert [c.to_dict() for c in cs1.results] == [c.to_dict() for c in server]
                        assert cs1.client_results
    assert _sha(old) == before


_FIRST_CALL = """
import sys
import numpy as np
from viewdb.search.bounds import dtw
rng = np.random.default_rng(0)
q, c = rng.random(64), rng.random(64)
dtw(q, c, 6)
print("scipy.linalg" in sys.modules, "numpy.f2py" in sys.modules, "colorama" in sys.modules,
      "yaml" in sys.modules)
import colorama, yaml  # still there for other code
import numba
@numba.njit
def product(a, b):
    return np.dot(a, b)
a, b = rng.random((5, 4)), rng.random((4, 3))
print(bool(np.allclose(product(a, b), a @ b)))
"""


def test_a_fresh_first_kernel_call_skips_the_blas_probe_and_blas_still_works(tmp_path):
    # numba's first call would import scipy.linalg (and numpy.f2py) to probe for BLAS, and
    # numba colorama and yaml; the client half needs none of them, and a jitted np.dot
    # compiled later still finds BLAS
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", _FIRST_CALL], capture_output=True, text=True,
                          check=True, cwd=Path(__file__).parents[1])
    assert done.stdout.split() == ["False", "False", "False", "False", "True"]
    # a numba configuration file in the working folder is still read
    (tmp_path / ".numba_config.yaml").write_text("DISABLE_JIT: 0\n")
    done = subprocess.run([sys.executable, "-c", _FIRST_CALL], capture_output=True, text=True,
                          check=True, cwd=tmp_path)
    assert done.stdout.split() == ["False", "False", "False", "True", "True"]
