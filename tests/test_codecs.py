import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from viewdb.errors import StorageError
from viewdb.storage.codecs import DTYPE_CODES, decode_array, decode_many, encode_array

dtypes = st.sampled_from(sorted({dt.str for dt in DTYPE_CODES.values()}))


@settings(max_examples=200, deadline=None)
@given(dtypes.flatmap(lambda dt: hnp.arrays(np.dtype(dt), hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=6))))
def test_round_trip_is_exact(arr):
    back = decode_array(encode_array(arr))
    assert back.dtype == arr.dtype and back.shape == arr.shape
    assert back.tobytes() == arr.tobytes()  # bit-exact, NaNs included


@settings(max_examples=200, deadline=None)
@given(hnp.arrays(np.float32, st.integers(1, 50)), st.data())
def test_any_truncation_or_extension_is_rejected(arr, data):
    blob = encode_array(arr)
    cut = data.draw(st.integers(0, len(blob) - 1))
    with pytest.raises(StorageError):
        decode_array(blob[:cut])
    with pytest.raises(StorageError):
        decode_array(blob + b"\0")


@given(st.binary(max_size=64))
def test_random_bytes_never_decode_silently_wrong(blob):
    try:
        arr = decode_array(blob)
    except StorageError:
        return
    assert encode_array(arr) == blob  # only a well-formed blob decodes


def test_expected_dtype_and_shape_are_enforced():
    blob = encode_array(np.zeros((3, 5), np.float32))
    assert decode_array(blob, np.float32, (None, 5)).shape == (3, 5)
    with pytest.raises(StorageError, match="dtype"):
        decode_array(blob, np.float64)
    with pytest.raises(StorageError, match="shape"):
        decode_array(blob, np.float32, (None, 4))


def test_big_endian_input_is_stored_little_endian():
    arr = np.arange(6, dtype=">f8").reshape(2, 3)
    back = decode_array(encode_array(arr))
    assert back.dtype == np.dtype("<f8")
    np.testing.assert_array_equal(back, arr)


def test_unsupported_dtype_is_a_type_error():
    with pytest.raises(TypeError):
        encode_array(np.array(["a"]))


@settings(max_examples=200, deadline=None)
@given(dtypes.flatmap(lambda dt: st.tuples(
    st.just(np.dtype(dt)), st.integers(1, 3).flatmap(lambda ndim: st.lists(
        hnp.arrays(np.dtype(dt), hnp.array_shapes(min_dims=ndim, max_dims=ndim, min_side=0, max_side=5)),
        max_size=8)))))
def test_decode_many_is_decode_array_on_each(case):
    """Many blobs decoded at once: the same data (end to end) and shapes as one by one."""
    dtype, arrays = case
    ndim = arrays[0].ndim if arrays else 1
    data, shapes = decode_many([encode_array(a) for a in arrays], dtype, ndim)
    one_by_one = [decode_array(encode_array(a), dtype, (None,) * ndim) for a in arrays]
    assert data.dtype == dtype and shapes.shape == (len(arrays), ndim)
    assert [tuple(s) for s in shapes.tolist()] == [a.shape for a in one_by_one]
    assert data.tobytes() == b"".join(a.tobytes() for a in one_by_one)  # bit-exact, NaNs included


@settings(max_examples=200, deadline=None)
@given(st.lists(hnp.arrays(np.float32, st.tuples(st.integers(0, 4), st.just(3))), min_size=1, max_size=6),
       st.data())
def test_decode_many_refuses_what_decode_array_refuses(arrays, data):
    """One bad blob among good ones (cut, lengthened, another dtype or number of
    dimensions, missing): decode_many raises decode_array's error for it."""
    blobs = [encode_array(a) for a in arrays]
    bad = data.draw(st.integers(0, len(blobs) - 1))
    kind = data.draw(st.sampled_from(["cut", "longer", "dtype", "ndim", "missing"]))
    blobs[bad] = {
        "cut": blobs[bad][: data.draw(st.integers(0, len(blobs[bad]) - 1))],
        "longer": blobs[bad] + b"\0",
        "dtype": encode_array(arrays[bad].astype(np.float64)),
        "ndim": encode_array(arrays[bad].reshape(-1)),
        "missing": None,
    }[kind]
    with pytest.raises(StorageError) as one:
        decode_array(blobs[bad], np.float32, (None, None))
    with pytest.raises(StorageError) as many:
        decode_many(blobs, np.float32, 2)
    assert str(many.value) == str(one.value)
