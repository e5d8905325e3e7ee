"""What an object looks like in a photo, learned at ingest from the catalogue's own renders.

The colour channel (:mod:`viewdb.search.colour_index`) compares a cut-out's chromaticity
with each object's; a print, a lightness pattern or which colour lies at the centre and
which at the rim is lost there. The *look* of a box is a richer description of its pixels
that no in-plane turn changes:

- CIE Lab colour histograms (a*b* and L) over the ellipse inscribed in the box, and per
  ring of it (centre, middle, rim), with each ring's colour moments;
- rotation-invariant uniform local binary patterns at two radii (the texture);
- a histogram of gradient magnitudes, and per ring of gradient orientations measured
  against the direction from the centre (so a turn of the photo changes none of them).

:func:`look_features` computes it from a crop. A :class:`LookModel` is a linear
discriminant (LDA with shrinkage) fitted to such features of every coloured object's
renders pasted in synthetic clutter (:mod:`viewdb.catalogue.look_training`): it maps a
look to a space where one object's looks lie together and apart from the others', and an
object's *look distance* to a photo is the squared distance of the photo's look from the
object's mean there. :meth:`LookModel.distances` gives them, standardised within the
photo (the smallest 0, one unit the spread of the photo's distances to every object), so
that they add to a colour distance with one weight whatever the photo.

Pure numpy and OpenCV: no GL, no database.
"""

from __future__ import annotations

import hashlib
import io
import zipfile
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["LOOK_DIMS", "LOOK_SIZE", "LookModel", "fit_look_model", "look_features"]

#: Pixels of the square a crop is resized to before its look is read.
LOOK_SIZE = 64
#: Numbers in a look (:func:`look_features`).
LOOK_DIMS = 196
#: The rings of the inscribed ellipse (outer radius of each, as a share of the ellipse's).
_RINGS = (0.45, 0.75, 1.0)
#: Gradient magnitude (Sobel, 8-bit image) below which an orientation is not counted.
_EDGE = 20.0


def _geometry() -> tuple[NDArray[np.float64], NDArray[np.float64], list[NDArray[np.bool_]]]:
    yy, xx = np.mgrid[0:LOOK_SIZE, 0:LOOK_SIZE].astype(np.float64)
    centre, half = (LOOK_SIZE - 1) / 2.0, LOOK_SIZE / 2.0
    radius = np.hypot((xx - centre) / half, (yy - centre) / half)
    bearing = np.arctan2(yy - centre, xx - centre)
    inner = 0.0
    rings = []
    for outer in _RINGS:
        rings.append((radius >= inner) & (radius <= outer) if inner else radius < outer)
        inner = outer
    return radius, bearing, rings


_RADIUS, _BEARING, _RING_MASKS = _geometry()
_ELLIPSE = _RADIUS <= 1.0


def _histograms(lab: NDArray[np.float32], where: NDArray[np.bool_], ab_bins: int,
                l_bins: int) -> list[NDArray[np.float32]]:
    """Square-rooted, normalised a*b* and L histograms of the pixels ``where``."""
    lightness, a, b = lab[..., 0][where], lab[..., 1][where] - 128.0, lab[..., 2][where] - 128.0
    ai = np.clip(((a + 64.0) / 128.0 * ab_bins).astype(np.int64), 0, ab_bins - 1)
    bi = np.clip(((b + 64.0) / 128.0 * ab_bins).astype(np.int64), 0, ab_bins - 1)
    li = np.clip((lightness / 256.0 * l_bins).astype(np.int64), 0, l_bins - 1)
    n = max(int(where.sum()), 1)
    return [np.sqrt(np.bincount(ai * ab_bins + bi, minlength=ab_bins * ab_bins) / n).astype(np.float32),
            np.sqrt(np.bincount(li, minlength=l_bins) / n).astype(np.float32)]


def _moments(lab: NDArray[np.float32], where: NDArray[np.bool_]) -> NDArray[np.float32]:
    lightness, a, b = lab[..., 0][where], lab[..., 1][where] - 128.0, lab[..., 2][where] - 128.0
    return np.array([lightness.mean() / 100.0, lightness.std() / 50.0, a.mean() / 30.0, b.mean() / 30.0,
                     a.std() / 20.0, b.std() / 20.0], dtype=np.float32)


def _binary_patterns(grey: NDArray[np.uint8], radius: int) -> NDArray[np.float32]:
    """Square-rooted histogram of rotation-invariant uniform local binary patterns (8
    neighbours at ``radius``; 0–8 the count of brighter neighbours, 9 not uniform) inside
    the ellipse."""
    h, w = grey.shape
    centre = grey[radius:h - radius, radius:w - radius].astype(np.int16)
    steps = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
    bits = np.stack([
        (grey[radius + dy * radius:h - radius + dy * radius, radius + dx * radius:w - radius + dx * radius]
         .astype(np.int16) >= centre + 2) for dy, dx in steps]).astype(np.uint8)
    changes = (bits != np.roll(bits, 1, axis=0)).sum(axis=0)
    codes = np.where(changes <= 2, bits.sum(axis=0), 9)
    inside = _ELLIPSE[radius:h - radius, radius:w - radius]
    found = codes[inside]
    return np.sqrt(np.bincount(found, minlength=10) / max(found.size, 1)).astype(np.float32)


def look_features(crop: NDArray[np.uint8]) -> NDArray[np.float32]:
    """The look of an RGB crop (uint8, (H, W, 3), at least 2 × 2 pixels): a float32 vector
    that no in-plane turn of the crop changes (up to resampling). See the module doc."""
    crop = np.asarray(crop)
    if crop.ndim != 3 or crop.shape[2] != 3 or min(crop.shape[:2]) < 2:
        raise ValueError(f"a look needs an RGB crop of at least 2 x 2 pixels, got shape {crop.shape}")
    image = cv2.resize(np.ascontiguousarray(crop, dtype=np.uint8), (LOOK_SIZE, LOOK_SIZE),
                       interpolation=cv2.INTER_AREA)
    lab = cv2.cvtColor(image, cv2.COLOR_RGB2LAB).astype(np.float32)
    parts = _histograms(lab, _ELLIPSE, 8, 8)
    for ring in _RING_MASKS:
        parts += _histograms(lab, ring, 4, 4)
    grey = np.asarray(cv2.cvtColor(image, cv2.COLOR_RGB2GRAY), np.uint8)
    parts += [_binary_patterns(grey, 1), _binary_patterns(grey, 2)]
    gx, gy = cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1)
    magnitude = np.hypot(gx, gy)
    inside = magnitude[_ELLIPSE]
    counts = np.histogram(np.clip(inside, 0, 399), bins=8, range=(0, 400))[0]
    parts.append(np.sqrt(counts / max(inside.size, 1)).astype(np.float32))
    relative = np.mod(np.arctan2(gy, gx) - _BEARING, np.pi) / np.pi
    for ring in _RING_MASKS:
        edges = ring & (magnitude > _EDGE)
        bins = np.minimum((relative[edges] * 6).astype(np.int64), 5)
        weights = np.bincount(bins, weights=magnitude[edges], minlength=6)
        parts.append(np.sqrt(weights / (magnitude[ring].sum() + 1e-6)).astype(np.float32))
    parts += [_moments(lab, ring) for ring in _RING_MASKS]
    return np.concatenate(parts).astype(np.float32)


@dataclass(frozen=True, eq=False)
class LookModel:
    """A linear discriminant over looks (see the module doc): ``mean`` and ``scale``
    standardise a look, ``projection`` maps it, ``centres`` are the objects' means there."""

    objects: tuple[str, ...]
    mean: NDArray[np.float32] = field(repr=False)
    scale: NDArray[np.float32] = field(repr=False)
    projection: NDArray[np.float32] = field(repr=False)
    centres: NDArray[np.float32] = field(repr=False)

    def distances(self, look: NDArray[np.float32]) -> dict[str, float]:
        """Each object's look distance to ``look``, standardised within it: 0 for the
        nearest object, in units of the distances' spread."""
        projected = ((np.asarray(look, dtype=np.float64) - self.mean) / self.scale) @ self.projection
        squared = ((self.centres - projected) ** 2).sum(axis=1)
        spread = float(squared.std()) or 1.0
        standard = (squared - squared.min()) / spread
        return dict(zip(self.objects, (float(d) for d in standard), strict=True))

    def to_bytes(self) -> bytes:
        out = io.BytesIO()
        np.savez(out, objects=np.array(self.objects), mean=self.mean, scale=self.scale,
                 projection=self.projection, centres=self.centres)
        return out.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes) -> LookModel:
        """Raises ValueError when ``data`` is not a model's :meth:`to_bytes`."""
        try:
            with np.load(io.BytesIO(data), allow_pickle=False) as arrays:
                model = cls(tuple(str(n) for n in arrays["objects"]), *(
                    arrays[k].astype(np.float32) for k in ("mean", "scale", "projection", "centres")))
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"not a look model: {exc}") from exc
        dims = model.mean.shape
        if (dims != (LOOK_DIMS,) or model.scale.shape != dims or model.projection.shape[0] != dims[0]
                or model.centres.shape != (len(model.objects), model.projection.shape[1])):
            raise ValueError("not a look model: its arrays do not fit together")
        return model

    def digest(self) -> str:
        return hashlib.sha256(self.to_bytes()).hexdigest()


def fit_look_model(looks: NDArray[np.float32], labels: NDArray[np.int64], objects: tuple[str, ...],
                   shrinkage: float = 0.03) -> LookModel:
    """A :class:`LookModel` of ``objects`` from training ``looks`` (one row each) and the
    index into ``objects`` of each one's object (every object needs at least one row).
    ``shrinkage`` pulls the within-object covariance towards a multiple of the identity
    (0: none, 1: all the way)."""
    import scipy.linalg  # only fitting needs it

    looks = np.asarray(looks, dtype=np.float64)
    labels = np.asarray(labels)
    if len(objects) < 2 or looks.ndim != 2 or len(looks) != len(labels):
        raise ValueError("a look model needs looks of at least two objects, one label per look")
    if not 0.0 <= shrinkage <= 1.0:
        raise ValueError(f"shrinkage must be in [0, 1], got {shrinkage}")
    if set(np.unique(labels).tolist()) != set(range(len(objects))):
        raise ValueError("every object needs at least one look")
    mean, scale = looks.mean(axis=0), looks.std(axis=0) + 1e-6
    standard = (looks - mean) / scale
    centres = np.stack([standard[labels == i].mean(axis=0) for i in range(len(objects))])
    within = standard - centres[labels]
    scatter = within.T @ within / len(standard)
    scatter = (1 - shrinkage) * scatter + shrinkage * np.trace(scatter) / len(scatter) * np.eye(len(scatter))
    between = np.cov(centres.T)
    values, vectors = scipy.linalg.eigh(between, scatter)
    keep = np.argsort(values)[::-1][:len(objects) - 1]
    projection = vectors[:, keep]
    return LookModel(tuple(objects), mean.astype(np.float32), scale.astype(np.float32),
                     projection.astype(np.float32), (centres @ projection).astype(np.float32))
