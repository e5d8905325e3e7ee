"""Writing one rendered view to an image file (``viewdb render``).

``color`` is the shaded image, ``mask`` the silhouette (255 = object), ``depth`` a 16-bit
image (near = bright; 0 = background), so depth needs a format with 16 bits (PNG, TIFF).
The file is written under a temporary name beside the target and renamed into place: a
failed write leaves no partial file.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from ..errors import ViewDBError
from ..paths import not_regular
from .render import RenderedView

__all__ = ["KINDS", "check_output", "view_image", "write_view"]

#: What ``viewdb render --what`` can write.
KINDS = ("color", "mask", "depth")
#: Formats that keep 16 bits per pixel (a depth image).
SIXTEEN_BIT = (".png", ".tif", ".tiff")


def check_output(path: str | Path, what: str) -> None:
    """Refuse, before any rendering, an output OpenCV cannot write: an unknown kind, a
    file type without a writer, a depth image in an 8-bit format, or a path that exists
    and is not a regular file."""
    path = Path(path)
    if what not in KINDS:
        raise ViewDBError(f"cannot write {what!r}; choose one of {', '.join(KINDS)}", path)
    suffix = path.suffix.lower()
    if not suffix or not cv2.haveImageWriter(str(path)):
        raise ViewDBError(f"cannot write images of type {suffix or '(none)'!r}; use .png", path)
    if what == "depth" and suffix not in SIXTEEN_BIT:
        raise ViewDBError(f"a depth image needs 16 bits: use {', '.join(SIXTEEN_BIT)}, not {suffix}",
                          path)
    why = not_regular(path)
    if why not in (None, "does not exist"):
        raise ViewDBError(why or "", path)
    if not path.parent.is_dir():
        raise ViewDBError("its folder does not exist", path)


def view_image(view: RenderedView, what: str) -> NDArray[np.uint8] | NDArray[np.uint16]:
    """The array OpenCV writes for ``what``: BGR uint8, a uint8 mask or a uint16 depth."""
    if what == "color":
        return np.asarray(cv2.cvtColor(view.color, cv2.COLOR_RGB2BGR), dtype=np.uint8)
    if what == "mask":
        return view.mask.astype(np.uint8) * np.uint8(255)
    depth = view.depth
    image = np.zeros(depth.shape, np.uint16)
    if view.mask.any():
        lo, hi = depth[view.mask].min(), depth[view.mask].max()
        image[view.mask] = (65535 - (depth[view.mask] - lo) / max(hi - lo, 1e-9) * 60000).astype(np.uint16)
    return image


def write_view(view: RenderedView, path: str | Path, what: str = "color") -> None:
    """Write ``what`` of ``view`` to ``path`` (checked by :func:`check_output`), whole or
    not at all."""
    path = Path(path)
    check_output(path, what)
    image = view_image(view, what)
    # a fresh name beside the target, its suffix kept (OpenCV picks the format by it)
    temporary: Path | None
    temporary = path.with_name(f".{path.stem}.{os.getpid()}.{secrets.token_hex(4)}{path.suffix}")
    try:
        try:
            written = cv2.imwrite(str(temporary), image)
        except cv2.error as exc:
            raise ViewDBError(f"cannot write the image: {' '.join(str(exc).split())[-160:]}", path) from exc
        if not written:
            raise ViewDBError("cannot write the image", path)
        os.replace(temporary, path)
        temporary = None
    except OSError as exc:
        raise ViewDBError(f"cannot write the image: {exc.strerror or exc}", path) from exc
    finally:
        if temporary is not None:
            temporary.unlink(missing_ok=True)
