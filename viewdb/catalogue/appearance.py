"""A view's appearance: what the colour re-ranking, the shape verification and the shape
pose compare a photo with, computed once from the view's render and stored.

An :class:`Appearance` holds a grid view's

- **silhouette** (the mask; its outline, area and centroid are derived from it),
- **colour signature** (:func:`colour_signature`, quantised to 16 bits; none when the
  mesh has no colour of its own: :func:`carries_colour`), and
- **internal edges**: the Canny edge pixels inside the silhouette, away from its outline,
  with their gradient directions modulo π quantised to :data:`THETA_LEVELS` levels, as the
  shape pose finds them in a render (:func:`internal_edges`; :mod:`viewdb.pose.edges`
  compares them with a photo's).

:func:`appearance_of` turns a render into one; it is pure (no database, no GL). Every
record, stored or made on demand from a render, is quantised the same way, so a stored
view and the same view rendered again compare alike.

A view and its **turned twin** ``(h + 180°, 180° − v)`` see the object from the same
direction, the camera rolled by 180°: the twin's render is the view's turned by 180° in
the image (:func:`turned_render`; pixel centres map onto pixel centres), and so is its
appearance (:meth:`Appearance.turned`). One record per viewing direction serves both.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import camera_pose, normalise_angle
from ..config import AppearanceConfig
from ..interrupts import interrupts_held
from .features import mask_box
from .render import RenderedView

__all__ = [
    "BINS",
    "THETA_LEVELS",
    "Appearance",
    "appearance_of",
    "carries_colour",
    "colour_signature",
    "edge_interior",
    "internal_edges",
    "opposite_view",
    "turned_render",
    "turned_view",
]

#: Histogram bins per chromaticity channel (r and g, each over [0, 1]).
BINS = 16
#: Object pixels (after leaving out the outline) a signature is made of, at least.
MIN_PIXELS = 20
#: Pixels whose R + G + B is below this are too dark to have a colour (unless the
#: object has too few others).
DARK_SUM = 30
#: Upper end of the histogram's range: just above 1, so that pure red (r = 1) counts.
TOP = 1.0 + 1e-6
#: Levels of a stored edge direction over [0, π): 32 (at most 2.8° off; fits and colour
#: distances within 1e-3 of the render's, the tests' tolerance). 256 levels took twice
#: the bytes (zlib cannot shrink what is noise) for no closer fits.
THETA_LEVELS = 32
#: A stored colour signature's largest bin (16-bit quantisation).
SIGNATURE_TOP = 65535
#: Pixels of black border around a silhouette's box that the edge filters see (the 3×3
#: blur and Sobel reach two pixels), so edges found in the box equal those of the image.
EDGE_BORDER = 3


# --------------------------------------------------------------------------- colour
def colour_signature(rgb: NDArray[np.uint8], mask: NDArray[np.bool_]) -> NDArray[np.float32]:
    """The chromaticity histogram (``BINS`` × ``BINS``, sums to 1) of ``rgb`` where ``mask``
    (:mod:`viewdb.recognition.colour` says what it is for).

    The outline's pixels and too dark ones are left out when enough pixels remain. An
    empty mask gives an all-zero histogram (it shares no colour with anything).
    """
    mask = np.asarray(mask, bool)
    box = mask_box(mask, 2)  # what the erosion below sees, not the whole photo
    if box is not None:
        rgb, mask = rgb[box], mask[box]
    inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    if np.count_nonzero(inner) < MIN_PIXELS:
        inner = np.asarray(mask, bool)
    x = np.asarray(rgb[:, :, :3], np.float32)
    total = x.sum(axis=2)
    lit = inner & (total >= DARK_SUM)
    if np.count_nonzero(lit) >= MIN_PIXELS:
        inner = lit
    chroma = np.ascontiguousarray(x[:, :, :2] / np.maximum(total, 1.0)[:, :, None])
    hist = cv2.calcHist([chroma], [0, 1], inner.astype(np.uint8), [BINS, BINS], [0.0, TOP, 0.0, TOP])
    hist = cv2.GaussianBlur(hist, (3, 3), 0)
    mass = float(hist.sum())
    return (hist / mass if mass > 0 else hist).astype(np.float32)


def carries_colour(mesh: Any) -> bool:
    """Whether a normalised mesh (:class:`viewdb.catalogue.mesh.NormalisedMesh`) has colour of its
    own: a texture image, vertex or face colours, or a material colour that is not grey."""
    with interrupts_held():  # trimesh's visuals swallow BaseException in places
        return any(_carries_colour(geometry.visual) for geometry in mesh.scene.geometry.values())


def _carries_colour(visual: Any) -> bool:
    if visual.kind in ("vertex", "face"):
        return True
    material = getattr(visual, "material", None)
    if material is None:
        return False
    if any(getattr(material, key, None) is not None for key in ("baseColorTexture", "image")):
        return True
    factor = getattr(material, "baseColorFactor", None)
    return factor is not None and bool(np.ptp(np.asarray(factor, np.float64)[:3]) > 0)


# --------------------------------------------------------------------------- edges
def edge_interior(mask: NDArray[np.uint8], margin_px: int) -> NDArray[np.bool_]:
    """Where internal edges are looked for: ``mask`` (uint8) eroded by a disc of radius
    ``margin_px`` (outside the image counts as background)."""
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
    return cv2.erode(mask, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0


def margin_pixels(margin: float, image_size: int) -> int:
    """The edge margin in pixels of an ``image_size`` view: at least 2."""
    return max(2, int(round(margin * image_size)))


def internal_edges(
    grey: NDArray[np.uint8], interior: NDArray[np.bool_], thresholds: tuple[float, float],
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Canny edges of ``grey`` inside ``interior``: their rows, columns (row-major order)
    and gradient directions modulo π (y down), after a 3×3 Gaussian blur; Canny's
    hysteresis thresholds apply to the L2 magnitude of the 3×3 Sobel gradient."""
    blurred = cv2.GaussianBlur(grey, (3, 3), 0)
    lo, hi = thresholds
    edges = (cv2.Canny(blurred, lo, hi, L2gradient=True) > 0) & interior
    ys, xs = np.nonzero(edges)
    if len(xs) == 0:
        return ys, xs, np.zeros(0)
    gx = cv2.Sobel(blurred, cv2.CV_32F, 1, 0)[ys, xs]
    gy = cv2.Sobel(blurred, cv2.CV_32F, 0, 1)[ys, xs]
    return ys, xs, np.mod(np.arctan2(gy, gx), np.pi).astype(np.float64)


def grey_of(color: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """A grey image of RGB ``color`` (grey images as they are)."""
    return color if color.ndim == 2 else np.asarray(cv2.cvtColor(color, cv2.COLOR_RGB2GRAY), dtype=np.uint8)


# --------------------------------------------------------------------------- views
def turned_view(azimuth: float, elevation: float) -> tuple[float, float]:
    """The grid view that sees the same direction with the camera rolled by 180°:
    ``(h + 180°, 180° − v)``."""
    return normalise_angle(azimuth + 180.0), normalise_angle(180.0 - elevation)


def opposite_view(azimuth: float, elevation: float) -> tuple[float, float]:
    """The view from the opposite side, ``(h + 180°, −v)``: its orthographic silhouette is
    this one's mirror image (:func:`viewdb.recognition.verify.physical_view`)."""
    return normalise_angle(azimuth + 180.0), normalise_angle(-elevation)


def turned_render(view: RenderedView) -> RenderedView:
    """The render of ``view``'s turned twin (:func:`turned_view`): its images turned by 180°
    and the twin's camera pose. Equal to rendering the twin up to rasterisation ties."""
    h, v = turned_view(view.azimuth, view.elevation)
    distance = float(np.linalg.norm(view.pose[:3, 3]))
    return RenderedView(
        h, v, np.ascontiguousarray(view.color[::-1, ::-1]), np.ascontiguousarray(view.mask[::-1, ::-1]),
        np.ascontiguousarray(view.depth[::-1, ::-1]), camera_pose(h, v, distance),
    )


@dataclass(frozen=True, eq=False)
class Appearance:
    """One grid view's stored appearance (module doc)."""

    azimuth: float
    elevation: float
    #: The silhouette, bool (S, S).
    mask: NDArray[np.bool_] = field(repr=False)
    #: Internal edge pixels, int32 (n, 2): x (column), y (row), in row-major order.
    edge_points: NDArray[np.int32] = field(repr=False)
    #: Their gradient directions modulo π, uint8 (n,) in :data:`THETA_LEVELS` levels.
    edge_theta: NDArray[np.uint8] = field(repr=False)
    #: The colour signature as uint16 (BINS, BINS), largest bin :data:`SIGNATURE_TOP`;
    #: None when the mesh has no colour of its own.
    signature: NDArray[np.uint16] | None = field(repr=False)
    #: What the pose derives from the record (its outline), kept with it: a catalogue
    #: keeps its records, and a query fits the same views several times. So a record's
    #: arrays must not change once used.
    _derived: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def derived(self, key: Any, make: Callable[[], Any]) -> Any:
        """``make()``, computed once per ``key`` for this record."""
        if key not in self._derived:
            self._derived[key] = make()
        return self._derived[key]

    @property
    def image_size(self) -> int:
        return int(self.mask.shape[0])

    def colour(self) -> NDArray[np.float32] | None:
        """The colour signature as :func:`colour_signature` gives it (sums to 1), or None."""
        if self.signature is None:
            return None
        total = float(self.signature.sum())
        hist = self.signature.astype(np.float32)
        return hist / np.float32(total) if total > 0 else hist

    def theta(self) -> NDArray[np.float64]:
        """The edge directions in radians, in [0, π): each level's centre."""
        return (self.edge_theta.astype(np.float64) + 0.5) * (math.pi / THETA_LEVELS)

    def turned(self) -> Appearance:
        """The appearance of the turned twin (:func:`turned_view`): everything turned by
        180° in the image (an edge's direction modulo π does not change); its edge pixels
        stay in row-major order."""
        h, v = turned_view(self.azimuth, self.elevation)
        last = self.image_size - 1
        return Appearance(h, v, np.ascontiguousarray(self.mask[::-1, ::-1]),
                          np.ascontiguousarray(last - self.edge_points[::-1]),
                          np.ascontiguousarray(self.edge_theta[::-1]), self.signature)

    def mirrored(self, azimuth: float, elevation: float) -> Appearance:
        """The appearance of view ``(azimuth, elevation)`` whose render is this one's
        mirrored left to right (:func:`viewdb.catalogue.skimming.image_twins`): the images
        mirrored, an edge's direction θ becoming π − θ (level ``L − 1 − l``); its edge
        pixels in row-major order."""
        last = self.image_size - 1
        xs, ys = last - self.edge_points[:, 0], self.edge_points[:, 1]
        order = np.lexsort((xs, ys))
        points = np.stack([xs[order], ys[order]], axis=1).astype(np.int32)
        theta = (THETA_LEVELS - 1 - self.edge_theta[order]).astype(np.uint8)
        return Appearance(azimuth, elevation, np.ascontiguousarray(self.mask[:, ::-1]), points, theta,
                          self.signature)


def _quantised_signature(signature: NDArray[np.float32]) -> NDArray[np.uint16]:
    top = float(signature.max()) if signature.size else 0.0
    if top <= 0:
        return np.zeros(signature.shape, np.uint16)
    return np.rint(signature.astype(np.float64) * (SIGNATURE_TOP / top)).astype(np.uint16)


def appearance_of(view: RenderedView, config: AppearanceConfig, coloured: bool) -> Appearance:
    """The appearance of a rendered view; ``coloured``: the mesh carries colour
    (:func:`carries_colour`), else the record has no signature. Edges and signature are
    computed in the silhouette's box (plus a black border), which gives what the whole
    image would."""
    mask = np.asarray(view.mask, dtype=bool)
    size = mask.shape[0]
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        empty = np.zeros((0, 2), np.int32)
        return Appearance(view.azimuth, view.elevation, mask, empty, np.zeros(0, np.uint8),
                          np.zeros((BINS, BINS), np.uint16) if coloured else None)
    y0, x0 = max(0, int(rows[0]) - EDGE_BORDER), max(0, int(cols[0]) - EDGE_BORDER)
    y1, x1 = min(size, int(rows[-1]) + 1 + EDGE_BORDER), min(size, int(cols[-1]) + 1 + EDGE_BORDER)
    box = np.ascontiguousarray(mask[y0:y1, x0:x1])
    color = np.ascontiguousarray(view.color[y0:y1, x0:x1])
    interior = edge_interior(box.astype(np.uint8), margin_pixels(config.edge_margin, size))
    ys, xs, theta = internal_edges(np.ascontiguousarray(grey_of(color)), interior, config.edge_thresholds)
    points = np.stack([xs + x0, ys + y0], axis=1).astype(np.int32)
    levels = np.minimum(np.floor(theta * (THETA_LEVELS / math.pi)), THETA_LEVELS - 1).astype(np.uint8)
    signature = _quantised_signature(colour_signature(color, box)) if coloured else None
    return Appearance(view.azimuth, view.elevation, mask, points, levels, signature)
