"""How well a pinhole pose explains the photo *inside* the object: the gradients of a
render of the mesh's own colours against the photo's.

A cut from a box in clutter is a guess at the object's outline, and poses whose
silhouettes fit it about equally well can be far apart: the object turned half round
about an axis in the image, seen from behind. Their insides differ: a coloured mesh's
paint, print and parts' boundaries land elsewhere. So a silhouette fit
(:func:`viewdb.pose.silhouette.search_silhouette_pose`) ranks its hypotheses by IoU plus
:attr:`~viewdb.config.SilhouetteConfig.texture_weight` × this score.

The score (:class:`TextureScore`) is the agreement of gradient directions, in ``[0, 1]``:
the mesh is rendered with its colours under ambient light alone
(:meth:`~viewdb.catalogue.pinhole.PinholeRenderer.colour`) in a window around the
query's silhouette, and over the render's interior (its silhouette eroded by two pixels,
the pixels that may hide the object left out) each pixel's ``|cos|`` of the angle
between the render's grey gradient and the photo's is averaged, weighted by the
render's gradient magnitude (a pixel where the photo is flat agrees 0). It compares
where brightness changes and in which direction, not the colours themselves, so a
camera's colour response and the scene's lighting matter little. A mesh without colour
of its own renders flat, and is not scored; nor is any pose where the mesh cannot be
rendered (no GL: the IoU alone decides).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from ..catalogue.mesh import NormalisedMesh
from ..catalogue.pinhole import Window, get_pinhole_renderer
from ..errors import PoseError, RenderError
from ..typed import Intrinsics
from .views import QueryView

__all__ = ["TextureScore"]

#: Fewer interior pixels than this: no score (0).
MIN_PIXELS = 20
#: A photo gradient (Sobel, grey levels) weaker than this has no direction to agree with
#: (a step of 2 grey levels): the pixel agrees 0, so a flat photo scores every pose alike.
#: On the LM-O poses, 0, 8, 20 and 40 pose within 3 of 173 objects of each other.
MIN_PHOTO_GRADIENT = 8.0


def _gradients(grey: NDArray[np.float32]) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    return (np.asarray(cv2.Sobel(grey, cv2.CV_32F, 1, 0), np.float32),
            np.asarray(cv2.Sobel(grey, cv2.CV_32F, 0, 1), np.float32))


class TextureScore:
    """The texture score of poses of ``mesh`` in ``query`` (module doc), in a ``size``
    pixel window around the query's silhouette; call it with a pose (OpenCV frame,
    normalised units)."""

    def __init__(self, mesh: NormalisedMesh, query: QueryView, intrinsics: Intrinsics, size: int) -> None:
        self.mesh = mesh
        #: Set when the mesh cannot be rendered: every pose then scores 0.
        self.unavailable = False
        mask = np.asarray(query.mask, dtype=bool)
        if not mask.any():
            raise PoseError("the query mask is empty: no object to score a pose against")
        self.window = Window.around(mask, size)
        fx, fy, cx, cy = (float(x) for x in intrinsics)
        self.camera = self.window.intrinsics(fx, fy, cx, cy)
        color, window = self.window.part(np.asarray(query.color))  # the window's part of the photo
        grey = color.astype(np.float32) if color.ndim == 2 else color.astype(np.float32).mean(axis=2)
        self.gx, self.gy = _gradients(window.crop(grey))
        if query.ignore is not None and np.asarray(query.ignore).any():
            self.hidden = self.window.crop(np.asarray(query.ignore)) > 0.5
        else:
            self.hidden = np.zeros((size, size), dtype=bool)

    def __call__(self, rotation: NDArray[np.float64], translation: NDArray[np.float64]) -> float:
        if self.unavailable or not float(np.asarray(translation).reshape(3)[2]) > 1e-6:
            return 0.0
        try:
            rgb, covered = get_pinhole_renderer().colour(self.mesh, rotation, translation, self.camera,
                                                        self.window.size)
        except RenderError:
            # no GL here (the silhouette fit itself needs none): every pose scores 0, the IoU decides
            self.unavailable = True
            return 0.0
        inner = cv2.erode(covered.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & ~self.hidden
        if np.count_nonzero(inner) < MIN_PIXELS:
            return 0.0
        rx, ry = _gradients(rgb.astype(np.float32).mean(axis=2))
        rx, ry, px, py = rx[inner], ry[inner], self.gx[inner], self.gy[inner]
        strength = np.hypot(rx, ry)
        total = float(strength.sum())
        if total <= 0.0:
            return 0.0  # flat inside: nothing to compare
        photo = np.hypot(px, py)
        cosine = np.abs(rx * px + ry * py) / (strength * photo + 1e-6)
        agree = np.where(photo >= MIN_PHOTO_GRADIENT, cosine, 0.0)
        return float((strength * agree).sum() / total)
