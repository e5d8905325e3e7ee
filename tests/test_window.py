"""A photo's window (:class:`viewdb.catalogue.pinhole.Window`): what it samples of a large
photo is what the whole photo, blurred and warped, would give."""

import math

import cv2
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from viewdb.catalogue.pinhole import Window


def _whole_photo_crop(window: Window, image: np.ndarray) -> np.ndarray:
    """The window's definition on the whole photo: blurred to area averages when the
    window shrinks it, then warped linearly, 0 outside the photo."""
    f = window.factor
    m = np.array([[f, 0.0, (0.5 - window.x0) * f - 0.5], [0.0, f, (0.5 - window.y0) * f - 0.5]])
    src = np.asarray(image, dtype=np.float32)
    if f < 1.0:
        k = int(math.ceil(1.0 / f)) | 1
        src = cv2.blur(src, (k, k))
    return cv2.warpAffine(src, m, (window.size, window.size), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 90), st.integers(1, 90), st.floats(-60, 120), st.floats(-60, 120),
       st.floats(0.5, 150), st.integers(1, 48), st.sampled_from(["float", "bool", "uint8"]))
def test_a_window_samples_a_photo_as_the_whole_photo_would(seed, h, w, x0, y0, side, size, kind):
    rng = np.random.default_rng(seed)
    image = rng.random((h, w)) * 255
    image = {"float": image.astype(np.float32), "bool": image > 128, "uint8": image.astype(np.uint8)}[kind]
    window = Window(x0, y0, side, size)
    # the same samples; the warp's coordinates, offset by whole pixels, may round apart
    np.testing.assert_allclose(window.crop(image), _whole_photo_crop(window, image), rtol=0, atol=0.01)
    part, inner = window.part(image)  # what a caller prepares alone: the window's part of the photo
    np.testing.assert_array_equal(inner.crop(part), window.crop(image))
    reach = side / size + 2 * (math.ceil(side / size) + 4)  # the samples' span, the blur's and the margins
    assert part.shape[0] <= min(h, side + reach) + 1 and part.shape[1] <= min(w, side + reach) + 1


def test_a_window_of_a_large_photo_reads_only_its_part():
    """Only the part near the window is read: a photo too large to convert whole in a
    test's memory budget (a view of one row broadcast) is cropped from its corner."""
    row = np.arange(20000, dtype=np.uint8)[None, :]
    huge = np.broadcast_to(row, (20000, 20000))  # 400 MB as a uint8 array, 1.6 GB as float32
    window = Window(10.0, 10.0, 40.0, 40)
    np.testing.assert_allclose(window.crop(huge), _whole_photo_crop(window, huge[:100, :100]), rtol=0, atol=0.01)
