"""The pose, colour and shape-fit messages between a client and ``viewdb serve``, and
the query image codec.

A client holds no meshes and no SIFT features, so it sends the server the query image
already segmented: one lossless PNG whose alpha channel is the object mask (the server
gets exactly the pixels and the mask the client has), the matches to pose, and the
camera intrinsics if any. The server answers a pose, or why there is none, per match.
Like :mod:`viewdb.search.plans`, every message is a dataclass with ``to_dict`` /
``from_dict``; ``from_dict`` validates and raises :class:`~viewdb.errors.QueryError`.
"""

from __future__ import annotations

import base64
import binascii
import io
import math
import struct
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from PIL import Image

from ..catalogue.look import LOOK_DIMS
from ..config import ImageConfig
from ..errors import QueryError
from ..pose.estimate import PoseEstimate, QueryView
from ..pose.intrinsics import check_intrinsics
from ..recognition.colour import BINS
from ..search.colour_index import ColourMatch
from ..search.plans import (
    MAX_K,
    Candidate,
    candidates_from_json,
    curve_from_json,
    json_number,
    stats_from_dict,
)
from ..typed import Intrinsics

__all__ = [
    "ColourRankingReply", "ColourRankingRequest", "ColourReply", "ColourRequest", "FitReply", "FitRequest",
    "LookReply", "LookRequest", "PoseReply", "PoseRequest",
    "decode_query", "encode_query",
    "pose_from_dict", "pose_to_dict", "shrink_query",
]

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def encode_query(query: QueryView) -> bytes:
    """The query's pixels with its mask as the alpha channel (255 = object), as PNG."""
    rgb = np.asarray(query.color, np.uint8)
    mask = np.asarray(query.mask, bool)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or mask.shape != rgb.shape[:2]:
        raise QueryError(f"query image {rgb.shape} and mask {mask.shape} do not match")
    bgra = np.dstack([rgb[:, :, ::-1], mask.astype(np.uint8) * np.uint8(255)])
    ok, data = cv2.imencode(".png", bgra, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 BGRA array
        raise QueryError("cannot encode the query image")
    return data.tobytes()


def shrink_query(
    query: QueryView, max_pixels: int, intrinsics: Intrinsics | None = None,
) -> tuple[QueryView, Intrinsics | None]:
    """``query`` scaled down (same aspect ratio, area-averaged colour, the mask thresholded
    at half) to at most ``max_pixels`` pixels, and ``intrinsics`` scaled with it, so that
    the pose found in the smaller image is the one of the larger: the ``viewdb`` frame is
    measured in image widths (:mod:`viewdb.pose.frames`), the ``opencv`` frame through the
    intrinsics. ``query`` itself when it is small enough."""
    height, width = query.mask.shape
    if width * height <= max_pixels:
        return query, intrinsics
    factor = math.sqrt(max_pixels / (width * height))
    w = max(_IMAGE.min_side, math.floor(width * factor))
    h = max(_IMAGE.min_side, math.floor(height * factor))
    while w * h > max_pixels and min(w, h) > _IMAGE.min_side:
        w, h = w - 1, max(_IMAGE.min_side, round(w * height / width) - 1)
    color = np.asarray(cv2.resize(np.asarray(query.color, np.uint8), (w, h), interpolation=cv2.INTER_AREA),
                       np.uint8)
    mask = cv2.resize(np.asarray(query.mask, np.uint8) * np.uint8(255), (w, h),
                      interpolation=cv2.INTER_AREA) > 127
    if intrinsics is not None:
        sx, sy = w / width, h / height
        fx, fy, cx, cy = (float(v) for v in intrinsics)
        intrinsics = (fx * sx, fy * sy, (cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5)
    return QueryView(color, mask), intrinsics


#: The query image limits (the same as the library's loader).
_IMAGE = ImageConfig()

def decode_query(data: bytes, max_pixels: int = _IMAGE.max_pixels) -> QueryView:
    """The inverse of :func:`encode_query`: an RGBA PNG (size checked before decoding)."""
    if not data.startswith(PNG_SIGNATURE):
        raise QueryError("image must be a PNG")
    if len(data) >= 24 and data[12:16] == b"IHDR":  # refuse a bomb before Pillow sees it
        width, height = struct.unpack(">II", data[16:24])
        if width * height > max_pixels:
            raise QueryError(f"image too large: {width}x{height}, more than {max_pixels:,} pixels")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(data)) as im:
                width, height, mode = int(im.size[0]), int(im.size[1]), im.mode
    except Exception as exc:  # Pillow's many ways of saying the header is bad
        raise QueryError(f"image is not a readable PNG ({type(exc).__name__})") from exc
    if width * height > max_pixels:
        raise QueryError(f"image too large: {width}x{height}, more than {max_pixels:,} pixels")
    if min(width, height) < _IMAGE.min_side:
        raise QueryError(f"image too small: {width}x{height}, at least {_IMAGE.min_side} on each side")
    if mode != "RGBA":
        raise QueryError(f"image must be RGBA (8 bits, alpha = object mask), not {mode}")
    arr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if arr is None or arr.dtype != np.uint8 or arr.shape != (height, width, 4):
        raise QueryError("image is not a readable 8-bit RGBA PNG")
    mask = arr[:, :, 3] > 127
    if not mask.any():
        raise QueryError("image mask (alpha channel) is empty")
    return QueryView(np.ascontiguousarray(arr[:, :, 2::-1]), mask)


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None  # JSON has no NaN or infinity


def _back(x: Any, what: str) -> float:
    """A pose number as sent (null for a non-finite one)."""
    return math.nan if x is None else json_number(x, f"pose {what}")


def pose_to_dict(p: PoseEstimate) -> dict[str, Any]:
    """Every field of a pose, JSON-able (non-finite numbers as null)."""
    return {
        "azimuth": _number(p.azimuth), "elevation": _number(p.elevation),
        "inplane": _number(p.inplane), "scale": _number(p.scale),
        "rotation": [[_number(x) for x in row] for row in np.asarray(p.rotation, float)],
        "translation": [_number(x) for x in np.asarray(p.translation, float)],
        "method": p.method, "inliers": int(p.inliers), "candidate": int(p.candidate),
        "frame": p.frame, "score": _number(p.score),
    }


def pose_from_dict(data: Any) -> PoseEstimate:
    if not isinstance(data, dict):
        raise QueryError("a pose must be an object")
    try:
        rotation = np.array([[_back(x, "rotation") for x in row] for row in data["rotation"]], float)
        translation = np.array([_back(x, "translation") for x in data["translation"]], float)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise QueryError("pose rotation must be 3x3 and translation 3 numbers")
        for key in ("method", "frame"):
            if not isinstance(data[key], str):
                raise QueryError(f"pose {key} must be a string")
        for key in ("inliers", "candidate"):
            if isinstance(data[key], bool) or not isinstance(data[key], int):
                raise QueryError(f"pose {key} must be an integer")
        return PoseEstimate(
            azimuth=_back(data["azimuth"], "azimuth"), elevation=_back(data["elevation"], "elevation"),
            inplane=_back(data["inplane"], "inplane"), scale=_back(data["scale"], "scale"),
            rotation=rotation, translation=translation, method=data["method"],
            inliers=data["inliers"], candidate=data["candidate"], frame=data["frame"],
            score=_back(data["score"], "score"),
        )
    except (KeyError, TypeError) as exc:
        raise QueryError(f"malformed pose ({type(exc).__name__}: {exc})") from exc


def _intrinsics(x: Any) -> Intrinsics | None:
    if x is None:
        return None
    if not isinstance(x, list):
        raise QueryError("intrinsics must be null or [fx, fy, cx, cy]")
    return check_intrinsics(x)


@dataclass(frozen=True)
class PoseRequest:
    """Client → server: the segmented query (RGBA PNG) and the matches to pose."""

    image: bytes = field(repr=False)
    matches: list[Candidate]
    intrinsics: Intrinsics | None = None
    #: Per match, the query's distance curve at the in-plane turn that matched (its
    #: nearest views add pose candidates, :class:`viewdb.config.MatchedPoseConfig`), or None.
    curves: list[np.ndarray | None] | None = field(default=None, repr=False)
    #: Fit every match so they can be ranked by silhouette IoU (with intrinsics).
    rerank: bool = False

    @classmethod
    def from_query(
        cls, query: QueryView, matches: Sequence[Candidate],
        intrinsics: Intrinsics | None = None,
        curves: Sequence[np.ndarray | None] | None = None, rerank: bool = False,
    ) -> PoseRequest:
        return cls(encode_query(query), list(matches), _intrinsics(
            None if intrinsics is None else [float(v) for v in intrinsics]),
            None if curves is None else list(curves), rerank)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"image": base64.b64encode(self.image).decode("ascii"),
                               "matches": [c.to_dict() for c in self.matches],
                               "intrinsics": None if self.intrinsics is None else list(self.intrinsics),
                               "curves": None if self.curves is None else [
                                   None if c is None else [float(x) for x in c] for c in self.curves]}
        if self.rerank:
            out["rerank"] = True
        return out

    @classmethod
    def from_dict(cls, data: Any) -> PoseRequest:
        if not isinstance(data, dict):
            raise QueryError("request must be an object")
        try:
            raw = _image(data)
            matches = candidates_from_json(data["matches"], MAX_K)
            if not matches:
                raise QueryError("matches must not be empty")
            curves = data.get("curves")
            if curves is not None:
                if not isinstance(curves, list) or len(curves) != len(matches):
                    raise QueryError("curves must be null or one per match")
                curves = [None if c is None else curve_from_json(c) for c in curves]
            rerank = data.get("rerank", False)
            if not isinstance(rerank, bool):
                raise QueryError("rerank must be true or false")
            return cls(raw, matches, _intrinsics(data.get("intrinsics")), curves, rerank)
        except KeyError as exc:
            raise QueryError(f"request lacks {exc.args[0]!r}") from exc


@dataclass(frozen=True)
class PoseReply:
    """Server → client: per match, its pose or why there is none."""

    poses: list[tuple[PoseEstimate | None, str | None]]
    stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"poses": [{"pose": None if p is None else pose_to_dict(p), "error": e}
                          for p, e in self.poses],
                "stats": dict(self.stats)}

    @classmethod
    def from_dict(cls, data: Any) -> PoseReply:
        if not isinstance(data, dict) or not isinstance(data.get("poses"), list):
            raise QueryError("reply must be an object with a poses list")
        out: list[tuple[PoseEstimate | None, str | None]] = []
        for item in data["poses"]:
            if not isinstance(item, dict):
                raise QueryError("each pose entry must be an object")
            pose, error = item.get("pose"), item.get("error")
            if error is not None and not isinstance(error, str):
                raise QueryError("pose error must be a string")
            out.append((None if pose is None else pose_from_dict(pose), error))
        return cls(out, stats_from_dict(data.get("stats")))


def _image(data: dict[str, Any]) -> bytes:
    image = data["image"]
    if not isinstance(image, str):
        raise QueryError("image must be a base64 string")
    try:
        return base64.b64decode(image, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise QueryError("image is not valid base64") from exc


def _views(items: Any) -> list[tuple[str, float, float]]:
    if not isinstance(items, list):
        raise QueryError("views must be a list")
    if not 1 <= len(items) <= MAX_K:
        raise QueryError(f"views must hold 1 to {MAX_K} entries, not {len(items)}")
    views = []
    for item in items:
        if not isinstance(item, dict) or not isinstance(item.get("object"), str):
            raise QueryError("each view must be an object with an object name")
        try:
            views.append((item["object"], json_number(item["azimuth"], "azimuth"),
                          json_number(item["elevation"], "elevation")))
        except KeyError as exc:
            raise QueryError(f"view lacks {exc.args[0]!r}") from exc
    return views


def _views_to_list(views: Sequence[tuple[str, float, float]]) -> list[dict[str, Any]]:
    return [{"object": o, "azimuth": h, "elevation": v} for o, h, v in views]


@dataclass(frozen=True)
class ColourRequest:
    """Client → server: the views ``(object, azimuth, elevation)`` whose colour signatures
    (:mod:`viewdb.recognition.colour`) the client needs to re-rank its results."""

    views: list[tuple[str, float, float]]

    def to_dict(self) -> dict[str, Any]:
        return {"views": _views_to_list(self.views)}

    @classmethod
    def from_dict(cls, data: Any) -> ColourRequest:
        if not isinstance(data, dict) or not isinstance(data.get("views"), list):
            raise QueryError("request must be an object with a views list")
        return cls(_views(data["views"]))


@dataclass(frozen=True)
class ColourReply:
    """Server → client: one colour signature (``BINS`` × ``BINS``, row by row) per view,
    or None for an object whose mesh has no colour."""

    signatures: list[np.ndarray | None]
    stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"signatures": [None if s is None else [float(x) for x in np.asarray(s, np.float32).ravel()]
                               for s in self.signatures],
                "stats": dict(self.stats)}

    @classmethod
    def from_dict(cls, data: Any) -> ColourReply:
        if not isinstance(data, dict) or not isinstance(data.get("signatures"), list):
            raise QueryError("reply must be an object with a signatures list")
        out: list[np.ndarray | None] = []
        for item in data["signatures"]:
            if item is None:
                out.append(None)
                continue
            out.append(_signature(item))
        return cls(out, stats_from_dict(data.get("stats")))


def _signature(item: Any) -> np.ndarray:
    """A colour signature from JSON: ``BINS × BINS`` numbers, none negative."""
    if not isinstance(item, list) or len(item) != BINS * BINS:
        raise QueryError(f"a signature must be a list of {BINS * BINS} numbers")
    values = np.array([json_number(x, "signature") for x in item], np.float32)
    if (values < 0).any():
        raise QueryError("signature values must not be negative")
    return values.reshape(BINS, BINS)


@dataclass(frozen=True)
class ColourRankingRequest:
    """Client → server: a cut-out's colour signature, and how many objects the colour
    channel should name (:mod:`viewdb.search.colour_index`)."""

    signature: np.ndarray = field(repr=False)
    n: int

    def to_dict(self) -> dict[str, Any]:
        return {"signature": [float(x) for x in np.asarray(self.signature, np.float32).ravel()], "n": self.n}

    @classmethod
    def from_dict(cls, data: Any) -> ColourRankingRequest:
        if not isinstance(data, dict) or "signature" not in data:
            raise QueryError("request must be an object with a signature")
        n = data.get("n")
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_K:
            raise QueryError(f"n must be an integer in [1, {MAX_K}], got {n!r}"[:120])
        return cls(_signature(data["signature"]), n)


@dataclass(frozen=True)
class ColourRankingReply:
    """Server → client: the objects whose stored colours lie nearest, nearest first."""

    matches: list[ColourMatch]
    stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"matches": [m.to_dict() for m in self.matches], "stats": dict(self.stats)}

    @classmethod
    def from_dict(cls, data: Any) -> ColourRankingReply:
        if not isinstance(data, dict) or not isinstance(data.get("matches"), list):
            raise QueryError("reply must be an object with a matches list")
        matches = []
        for item in data["matches"]:
            if not isinstance(item, dict) or not isinstance(item.get("object"), str):
                raise QueryError("each match must be an object with an object name")
            try:
                matches.append(ColourMatch(item["object"], json_number(item["distance"], "distance"),
                                           json_number(item["azimuth"], "azimuth"),
                                           json_number(item["elevation"], "elevation")))
            except KeyError as exc:
                raise QueryError(f"match lacks {exc.args[0]!r}") from exc
        return cls(matches, stats_from_dict(data.get("stats")))


@dataclass(frozen=True)
class LookRequest:
    """Client → server: the look of a cut-out's box (:func:`viewdb.catalogue.look.look_features`)."""

    look: np.ndarray = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"look": [float(x) for x in np.asarray(self.look, np.float32).ravel()]}

    @classmethod
    def from_dict(cls, data: Any) -> LookRequest:
        if not isinstance(data, dict) or not isinstance(data.get("look"), list):
            raise QueryError("request must be an object with a look list")
        if len(data["look"]) != LOOK_DIMS:
            raise QueryError(f"a look must be a list of {LOOK_DIMS} numbers, got {len(data['look'])}")
        return cls(np.array([json_number(x, "look") for x in data["look"]], np.float32))


@dataclass(frozen=True)
class LookReply:
    """Server → client: each coloured object's look distance (none without a look model)."""

    distances: dict[str, float]
    stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"distances": dict(self.distances), "stats": dict(self.stats)}

    @classmethod
    def from_dict(cls, data: Any) -> LookReply:
        if not isinstance(data, dict) or not isinstance(data.get("distances"), dict):
            raise QueryError("reply must be an object with a distances object")
        return cls({str(k): json_number(v, "distance") for k, v in data["distances"].items()},
                   stats_from_dict(data.get("stats")))


@dataclass(frozen=True)
class FitRequest:
    """Client → server: the segmented query (RGBA PNG) and the stored views
    ``(object, azimuth, elevation)`` to fit to its shape (:mod:`viewdb.recognition.verify`)."""

    image: bytes = field(repr=False)
    views: list[tuple[str, float, float]]

    @classmethod
    def from_query(cls, query: QueryView, views: Sequence[tuple[str, float, float]]) -> FitRequest:
        return cls(encode_query(query), list(views))

    def to_dict(self) -> dict[str, Any]:
        return {"image": base64.b64encode(self.image).decode("ascii"),
                "views": _views_to_list(self.views)}

    @classmethod
    def from_dict(cls, data: Any) -> FitRequest:
        if not isinstance(data, dict):
            raise QueryError("request must be an object")
        try:
            return cls(_image(data), _views(data["views"]))
        except KeyError as exc:
            raise QueryError(f"request lacks {exc.args[0]!r}") from exc


@dataclass(frozen=True)
class FitReply:
    """Server → client: per view, its shape fit in [0, 1], or None (no silhouette)."""

    fits: list[float | None]
    stats: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"fits": [None if f is None else float(f) for f in self.fits], "stats": dict(self.stats)}

    @classmethod
    def from_dict(cls, data: Any) -> FitReply:
        if not isinstance(data, dict) or not isinstance(data.get("fits"), list):
            raise QueryError("reply must be an object with a fits list")
        out: list[float | None] = []
        for item in data["fits"]:
            if item is None:
                out.append(None)
                continue
            value = json_number(item, "fit")
            if not 0.0 <= value <= 1.0:
                raise QueryError(f"each fit must be in [0, 1], not {value}")
            out.append(value)
        return cls(out, stats_from_dict(data.get("stats")))
