import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from viewdb.errors import StorageError
from viewdb.storage.codecs import DTYPE_CODES, decode_array, encode_array

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
