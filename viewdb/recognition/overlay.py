"""Overlays: each recognised object's posed mesh drawn over the photo it was found in.

For every result with a pose, the stored (normalised) mesh is projected into the photo
with that pose and drawn: its outline (the silhouette, holes included), its internal
edges (creases, and parts in front of others), its model axes (x red, y green, z blue
from the model's origin) and a label with its rank, name and score, over a lightly
shaded fill of the mesh. Results are drawn worst first, so the best is on top.

Projection follows the pose's frame (:mod:`viewdb.pose.estimate`, public contract):

* ``frame == "viewdb"`` (no intrinsics): the scaled-orthographic pose in normalised
  model units: the camera point ``x = R·X + t`` lands at
  ``u = scale·x·W/2 + W/2 − ½``, ``w = H/2 − ½ − scale·y·W/2`` (pixel centres on
  integers, as OpenCV's keypoints).
* ``frame == "opencv"`` (intrinsics ``(fx, fy, cx, cy)``): a pinhole pose,
  ``u = fx·x/z + cx``, ``w = fy·y/z + cy``; with ``units == "mesh"`` the pose maps the
  mesh file's own coordinates (``centre + scale·normalised``), as a query with
  intrinsics reports it.

The drawing is NumPy, OpenCV and one numba kernel, no renderer: the triangles are
scan-converted (:mod:`.raster`) into a face-index image with a depth buffer (a pixel
shows the nearest face whose projection holds its centre, as a GPU rasterises, at the
drawn image's resolution), from which the outline, the visible creases and depth steps
and the shading are read. The photo may be shrunk or enlarged first
(:attr:`viewdb.config.OverlayConfig.max_side`, ``min_side``).

>>> layer = draw_overlay(photo, poses_from_json(result.to_dict()), db.mesh)  # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..catalogue.mesh import NormalisedMesh
from ..config import OverlayConfig
from ..errors import QueryError
from ..pose.estimate import PoseEstimate
from ..typed import Intrinsics
from .results import QueryMatch, QueryResult

__all__ = [
    "OverlayPose",
    "Placement",
    "display_size",
    "draw_overlay",
    "draw_result",
    "overlay_layer",
    "poses_from_json",
    "project_silhouette",
    "resized_photo",
    "result_poses",
]

#: Colours of the model's x, y and z axes.
AXIS_COLOURS = ((255, 64, 64), (64, 220, 64), (72, 128, 255))
#: Sub-pixel bits of the line coordinates handed to OpenCV.
_SHIFT = 4
#: Projected coordinates beyond this many pixels (a vertex next to the camera plane) are
#: not drawn: OpenCV's fixed-point coordinates would overflow.
_FAR_PIXELS = 1 << 20
#: Vertices nearer the pinhole camera than this (in its units) are behind it.
_NEAR = 1e-6
#: Share of the fill colour given by the light facing the camera (the rest is ambient).
_LIGHT = 0.65


@dataclass(frozen=True)
class OverlayPose:
    """One result to draw: the object's name, its model-to-camera pose, and its label."""

    name: str
    #: 3×3 model-to-camera rotation.
    rotation: NDArray[np.float64] = field(repr=False)
    #: (3,) model-to-camera translation.
    translation: NDArray[np.float64] = field(repr=False)
    #: Magnification of a ``viewdb``-frame pose (ignored for ``opencv``).
    scale: float = 1.0
    #: "viewdb" (scaled orthographic) or "opencv" (pinhole, needs intrinsics).
    frame: str = "viewdb"
    #: "normalised" (model space of the views) or "mesh" (the mesh file's own units).
    units: str = "normalised"
    score: float | None = None
    rank: int | None = None

    def __post_init__(self) -> None:
        r = np.asarray(self.rotation, dtype=np.float64)
        t = np.asarray(self.translation, dtype=np.float64).reshape(-1)
        if r.shape != (3, 3) or t.shape != (3,) or not (np.isfinite(r).all() and np.isfinite(t).all()):
            raise QueryError(f"the pose of {self.name!r} is not a finite 3x3 rotation and 3-vector")
        if self.frame not in ("viewdb", "opencv"):
            raise QueryError(f"unknown pose frame {self.frame!r} (expected viewdb or opencv)")
        if self.units not in ("normalised", "mesh"):
            raise QueryError(f"unknown pose units {self.units!r} (expected normalised or mesh)")
        if self.frame == "viewdb" and not (math.isfinite(self.scale) and self.scale > 0):
            raise QueryError(f"the pose of {self.name!r} has no positive scale")
        object.__setattr__(self, "rotation", r)
        object.__setattr__(self, "translation", t)

    @classmethod
    def from_estimate(cls, name: str, pose: PoseEstimate, score: float | None = None,
                      rank: int | None = None) -> OverlayPose:
        return cls(name, pose.rotation, pose.translation, float(pose.scale), pose.frame, pose.units,
                   score, rank)

    @classmethod
    def from_json(cls, result: Mapping[str, Any]) -> OverlayPose | None:
        """The pose of one result of a query's JSON (``viewdb query --json``), or None
        when it was not posed."""
        pose = result.get("pose")
        if not pose:
            return None
        return cls(str(result["object"]), np.asarray(pose["rotation"], dtype=np.float64),
                   np.asarray(pose["translation"], dtype=np.float64),
                   float(pose.get("scale") or 1.0), str(pose.get("frame", "viewdb")),
                   str(pose.get("units", "normalised")),
                   None if result.get("score") is None else float(result["score"]),
                   None if result.get("rank") is None else int(result["rank"]))


def poses_from_json(data: Mapping[str, Any]) -> list[OverlayPose]:
    """Every posed result of a query's JSON (:meth:`viewdb.QueryResult.to_dict`), in
    order: the top-level ``results``, then those of each entry of ``objects`` (a query
    of several objects)."""
    results = list(data.get("results") or [])
    for entry in data.get("objects") or []:
        results += list(entry.get("results") or [])
    return [p for p in (OverlayPose.from_json(r) for r in results) if p is not None]


# ------------------------------------------------------------------------ geometry
def display_size(shape: Sequence[int], config: OverlayConfig | None = None) -> tuple[int, int]:
    """``(height, width)`` of the drawn image for a photo of ``shape`` (H, W, ...): the
    photo's, shrunk to ``config.max_side`` or enlarged to ``config.min_side``."""
    height, width = int(shape[0]), int(shape[1])
    config = config or OverlayConfig()
    longer = max(height, width)
    if config.max_side is not None and longer > config.max_side:
        f = config.max_side / longer
    elif config.min_side is not None and longer < config.min_side:
        f = config.min_side / longer
    else:
        return height, width
    return max(1, round(height * f)), max(1, round(width * f))


def resized_photo(photo: NDArray[np.uint8], config: OverlayConfig | None = None) -> NDArray[np.uint8]:
    """The photo (RGB) resized to the size its overlay is drawn at (:func:`display_size`)."""
    arr = np.asarray(photo)
    rgb = arr[:, :, :3] if arr.ndim == 3 else np.repeat(arr[:, :, None], 3, axis=2)
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w = display_size(rgb.shape, config)
    if (h, w) == rgb.shape[:2]:
        return rgb
    smaller = h * w < rgb.shape[0] * rgb.shape[1]
    return np.asarray(cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA if smaller else cv2.INTER_CUBIC),
                      np.uint8)


@dataclass(frozen=True)
class _Projection:
    """Points of one pose projected into the drawn image."""

    uv: NDArray[np.float64]  # (n, 2) pixel coordinates, centres on integers
    depth: NDArray[np.float64]  # (n,) distance from the camera, in bounding radii
    valid: NDArray[np.bool_]  # (n,) in front of the camera
    #: (n,) grows with the distance from the camera, and is linear across a face's
    #: projection (the depth for an orthographic camera, −1/depth for a pinhole)
    key: NDArray[np.float64]


#: Where a normalised mesh sits in its file: ``original = centre + scale · normalised``.
Placement = tuple[Sequence[float] | NDArray[np.floating], float]


def _project(pose: OverlayPose, place: Placement, points: NDArray[np.float64],
             photo_shape: tuple[int, int], drawn_shape: tuple[int, int],
             intrinsics: Intrinsics | None) -> _Projection:
    """``points`` (normalised model space) in the drawn image's pixels."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    unit = 1.0
    if pose.units == "mesh":
        unit = float(place[1])
        pts = np.asarray(place[0], dtype=np.float64) + unit * pts
    cam = pts @ pose.rotation.T + pose.translation
    height, width = photo_shape
    if pose.frame == "viewdb":
        q = cam[:, :2] * pose.scale
        u = q[:, 0] * width / 2.0 + width / 2.0 - 0.5
        w = height / 2.0 - 0.5 - q[:, 1] * width / 2.0
        depth, valid = -cam[:, 2], np.ones(len(cam), dtype=bool)
        key = depth
    else:
        if intrinsics is None:
            raise QueryError(f"the pose of {pose.name!r} is a pinhole (OpenCV frame) pose: "
                             "drawing it needs the camera intrinsics")
        fx, fy, cx, cy = (float(x) for x in intrinsics)
        z = cam[:, 2]
        valid = z > _NEAR * unit
        safe = np.where(valid, z, 1.0)
        u, w = fx * cam[:, 0] / safe + cx, fy * cam[:, 1] / safe + cy
        depth, key = z, -1.0 / safe
    dh, dw = drawn_shape
    uv = np.stack([(u + 0.5) * dw / width - 0.5, (w + 0.5) * dh / height - 0.5], axis=1)
    valid = valid & np.isfinite(uv).all(axis=1) & (np.abs(uv) < _FAR_PIXELS).all(axis=1)
    return _Projection(uv, depth / unit, valid, key)


def _face_ids(proj: _Projection, faces: NDArray[np.int64], shape: tuple[int, int]) -> NDArray[np.int32]:
    """The index of the face seen at each pixel (−1: none), by a depth buffer: a pixel
    belongs to the nearest face whose projection holds its centre
    (:func:`viewdb.recognition.raster.face_ids`)."""
    from .raster import face_ids

    h, w = shape
    if len(faces) == 0:
        return np.full((h, w), -1, dtype=np.int32)
    tri = proj.uv[faces]
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    ok = proj.valid[faces].all(axis=1)
    ok &= (hi[:, 0] >= 0) & (hi[:, 1] >= 0) & (lo[:, 0] <= w - 1) & (lo[:, 1] <= h - 1)
    index = np.flatnonzero(ok)
    tri = tri[index]
    return face_ids(tri, _planes(tri, proj.key[faces[index]]), index, (h, w))


def _planes(tri: NDArray[np.float64], depth: NDArray[np.float64]) -> NDArray[np.float64]:
    """Per triangle ``(a, b, c)`` with depth ``a·u + b·w + c`` over its projection (the
    corners' mean depth for a degenerate one)."""
    m = np.concatenate([tri, np.ones((len(tri), 3, 1))], axis=2)
    det = np.linalg.det(m) if len(tri) else np.zeros(0)
    solvable = np.abs(det) > 1e-9
    out = np.zeros((len(tri), 3))
    out[:, 2] = depth.mean(axis=1) if len(tri) else 0.0
    if solvable.any():
        out[solvable] = np.linalg.solve(m[solvable], depth[solvable][:, :, None])[:, :, 0]
    return out


def project_silhouette(
    pose: OverlayPose, mesh: NormalisedMesh, shape: Sequence[int],
    intrinsics: Intrinsics | None = None, placement: Placement | None = None,
) -> NDArray[np.bool_]:
    """The silhouette (bool, H × W) of ``mesh`` at ``pose`` in a photo of ``shape``.
    ``placement``: ``(centre, scale)`` of the mesh in its file, for a pose in the mesh's
    units (default the mesh's own: a mesh read from a database file has none, see
    :func:`draw_overlay`)."""
    from ..catalogue.coverage import cover

    photo = (int(shape[0]), int(shape[1]))
    geometry = mesh.geometry
    place = placement or (mesh.centre, mesh.scale)
    proj = _project(pose, place, np.asarray(geometry.vertices), photo, photo, intrinsics)
    points = np.where(proj.valid[:, None], proj.uv, np.nan)
    return cover(points, np.asarray(geometry.faces, dtype=np.int64), photo)


def _corners(geometry: Any) -> NDArray[np.int64]:
    """Each face's corners as indices of distinct vertex positions (a mesh split at its
    texture seams shares positions, not vertices)."""
    vertices = np.asarray(geometry.vertices, dtype=np.float64)
    _, welded = np.unique(np.round(vertices, 6), axis=0, return_inverse=True)
    return welded.reshape(-1)[np.asarray(geometry.faces, dtype=np.int64)]


def _edges(ids: NDArray[np.int32], normals: NDArray[np.float64], planes: NDArray[np.float64],
           corners: NDArray[np.int64], config: OverlayConfig) -> NDArray[np.bool_]:
    """Pixels where two visible faces meet at a crease, or where faces that share no
    corner meet at a step in depth (one part in front of another); the step must exceed
    what the faces' own slopes make across a pixel (a surface seen edge-on)."""
    edges = np.zeros(ids.shape, dtype=bool)
    cos_crease = math.cos(math.radians(config.crease_degrees))
    for axis in (0, 1):
        a = ids[:-1, :] if axis == 0 else ids[:, :-1]
        b = ids[1:, :] if axis == 0 else ids[:, 1:]
        pair = (a >= 0) & (b >= 0) & (a != b)
        rows, cols = np.nonzero(pair)
        if len(rows) == 0:
            continue
        fa, fb = a[rows, cols], b[rows, cols]
        crease = np.abs(np.einsum("ij,ij->i", normals[fa], normals[fb])) < cos_crease
        # depth of both faces where the two pixels meet
        u = cols + (0.5 if axis == 1 else 0.0)
        w = rows + (0.5 if axis == 0 else 0.0)
        pa, pb = planes[fa], planes[fb]
        step = np.abs((pa[:, 0] - pb[:, 0]) * u + (pa[:, 1] - pb[:, 1]) * w + pa[:, 2] - pb[:, 2])
        slope = np.abs(pa[:, :2]).sum(axis=1) + np.abs(pb[:, :2]).sum(axis=1)
        apart = ~(corners[fa][:, :, None] == corners[fb][:, None, :]).any(axis=(1, 2))
        hit = crease | (apart & (step > config.occlusion_depth + slope))
        edges[rows[hit], cols[hit]] = True
    return edges


# ------------------------------------------------------------------------ painting
class _Canvas:
    """Premultiplied RGBA in [0, 1]; paint = the "over" operator."""

    def __init__(self, shape: tuple[int, int]) -> None:
        self.rgb = np.zeros((*shape, 3), dtype=np.float32)
        self.alpha = np.zeros(shape, dtype=np.float32)

    def paint(self, coverage: NDArray[np.generic], colour: Sequence[float] | NDArray[np.floating],
              opacity: float = 1.0) -> None:
        """Paint ``colour`` (RGB 0–255: one for all, or (n, 3), one per covered pixel in
        ``np.nonzero`` order) where ``coverage`` (H, W; uint8 0–255 or bool) says, times
        ``opacity``."""
        cover = np.asarray(coverage).reshape(-1)  # flat indices: half the cost of (ys, xs)
        at = np.flatnonzero(cover)
        if len(at) == 0:
            return
        scale = opacity / 255.0 if cover.dtype == np.uint8 else opacity
        a = cover[at].astype(np.float32) * np.float32(scale)
        c = np.asarray(colour, dtype=np.float32) / 255.0
        rgb, alpha = self.rgb.reshape(-1, 3), self.alpha.reshape(-1)
        rgb[at] = rgb[at] * (1.0 - a[:, None]) + c * a[:, None]
        alpha[at] = alpha[at] * (1.0 - a) + a

    def over(self, photo: NDArray[np.uint8]) -> NDArray[np.uint8]:
        out = self.rgb * 255.0 + photo.astype(np.float32) * (1.0 - self.alpha[:, :, None])
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)

    def rgba(self) -> NDArray[np.uint8]:
        out = np.zeros((self.alpha.size, 4), dtype=np.uint8)
        at = np.flatnonzero(self.alpha > 0)
        a = self.alpha.reshape(-1)[at]
        rgb = self.rgb.reshape(-1, 3)[at] / a[:, None]
        out[at] = np.clip(np.rint(np.concatenate([rgb, a[:, None]], axis=1) * 255.0), 0, 255)
        return out.reshape(*self.alpha.shape, 4)


def _width(value: float, shape: tuple[int, int]) -> int:
    return max(1, round(value * max(shape) / 1000.0))


def _lighter(colour: Sequence[int]) -> tuple[float, ...]:
    return tuple(c + (255 - c) * 0.55 for c in colour)


def _draw_one(canvas: _Canvas, pose: OverlayPose, mesh: NormalisedMesh, place: Placement,
              colour: Sequence[int], photo_shape: tuple[int, int],
              intrinsics: Intrinsics | None, config: OverlayConfig) -> None:
    shape = canvas.alpha.shape
    geometry = mesh.geometry
    faces = np.asarray(geometry.faces, dtype=np.int64)
    proj = _project(pose, place, np.asarray(geometry.vertices), photo_shape, shape, intrinsics)
    ids = _face_ids(proj, faces, shape)
    seen = ids >= 0
    if not seen.any():
        return
    normals = np.asarray(geometry.face_normals, dtype=np.float64)
    if config.fill_opacity > 0:
        facing = np.abs((normals @ pose.rotation.T)[:, 2])
        shade = (1.0 - _LIGHT) + _LIGHT * facing
        light = shade[ids[seen]][:, None] * np.asarray(colour, np.float32)[None, :]
        canvas.paint(seen, light, config.fill_opacity)
    if config.edge_width > 0:
        edges = _edges(ids, normals, _planes(proj.uv[faces], proj.depth[faces]), _corners(geometry), config)
        width = _width(config.edge_width, shape)
        if width > 1:
            edges = cv2.dilate(edges.astype(np.uint8), np.ones((width, width), np.uint8)) > 0
        canvas.paint(edges, _lighter(colour), 0.9)
    if config.outline_width > 0:
        contours, _ = cv2.findContours(seen.astype(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
        line = np.zeros(shape, dtype=np.uint8)
        cv2.polylines(line, contours, True, 255, _width(config.outline_width, shape), cv2.LINE_AA)
        canvas.paint(line, colour)
    if config.axis_length > 0:
        _draw_axes(canvas, pose, place, photo_shape, intrinsics, config)
    if config.labels:
        _draw_label(canvas, pose, seen, colour, config)


def _draw_axes(canvas: _Canvas, pose: OverlayPose, place: Placement, photo_shape: tuple[int, int],
               intrinsics: Intrinsics | None, config: OverlayConfig) -> None:
    shape = canvas.alpha.shape
    ends = np.vstack([np.zeros(3), np.eye(3) * config.axis_length])
    proj = _project(pose, place, ends, photo_shape, shape, intrinsics)
    if not proj.valid[0]:
        return
    width = _width(config.outline_width, shape)
    origin = tuple(int(round(x * (1 << _SHIFT))) for x in proj.uv[0])
    for axis in (2, 1, 0):  # z under y under x
        if not proj.valid[axis + 1]:
            continue
        tip = tuple(int(round(x * (1 << _SHIFT))) for x in proj.uv[axis + 1])
        line = np.zeros(shape, dtype=np.uint8)
        cv2.arrowedLine(line, origin, tip, 255, width, cv2.LINE_AA, _SHIFT, 0.2)
        canvas.paint(line, AXIS_COLOURS[axis])


def _label_text(pose: OverlayPose) -> str:
    text = pose.name if pose.rank is None else f"{pose.rank}. {pose.name}"
    return text if pose.score is None else f"{text}  {pose.score:.3g}"


def _draw_label(canvas: _Canvas, pose: OverlayPose, seen: NDArray[np.bool_], colour: Sequence[int],
                config: OverlayConfig) -> None:
    h, w = seen.shape
    px = max(9.0, config.label_size * max(h, w) / 1000.0)
    font = cv2.FONT_HERSHEY_SIMPLEX
    scale = px / 22.0
    thick = max(1, round(scale * 1.6))
    text = _label_text(pose)
    (tw, th), base = cv2.getTextSize(text, font, scale, thick)
    pad = max(2, round(px * 0.25))
    bw, bh = tw + 2 * pad, th + base + 2 * pad
    rows, cols = np.flatnonzero(seen.any(axis=1)), np.flatnonzero(seen.any(axis=0))
    x0 = int(min(max(cols[0], 0), max(w - bw, 0)))
    y0 = int(rows[0]) - bh - pad  # above the object, else below it, else inside its top
    if y0 < 0:
        y0 = int(rows[-1]) + pad if rows[-1] + pad + bh <= h else max(int(rows[0]), 0)
    y0 = int(min(max(y0, 0), max(h - bh, 0)))
    box = np.zeros((h, w), dtype=np.uint8)
    cv2.rectangle(box, (x0, y0), (x0 + bw - 1, y0 + bh - 1), 255, cv2.FILLED)
    canvas.paint(box, colour, 0.85)
    letters = np.zeros((h, w), dtype=np.uint8)
    cv2.putText(letters, text, (x0 + pad, y0 + pad + th), font, scale, 255, thick, cv2.LINE_AA)
    luminance = 0.299 * colour[0] + 0.587 * colour[1] + 0.114 * colour[2]
    canvas.paint(letters, (0, 0, 0) if luminance > 140 else (255, 255, 255))


# ------------------------------------------------------------------------ public
def _paint_all(canvas: _Canvas, photo_shape: tuple[int, int], poses: Sequence[OverlayPose],
               mesh_of: Callable[[str], NormalisedMesh], placement: Callable[[str], Placement] | None,
               intrinsics: Intrinsics | None, config: OverlayConfig) -> None:
    if any(p.frame == "opencv" for p in poses) and intrinsics is None:
        raise QueryError("a pinhole (OpenCV frame) pose is drawn with the camera intrinsics: give them")
    for i in reversed(range(len(poses))):  # the best last, on top
        colour = config.colours[i % len(config.colours)]
        mesh = mesh_of(poses[i].name)
        place = (mesh.centre, mesh.scale) if placement is None else placement(poses[i].name)
        _draw_one(canvas, poses[i], mesh, place, colour, photo_shape, intrinsics, config)


def overlay_layer(
    shape: Sequence[int],
    poses: Sequence[OverlayPose],
    mesh_of: Callable[[str], NormalisedMesh],
    *,
    intrinsics: Intrinsics | None = None,
    placement: Callable[[str], Placement] | None = None,
    config: OverlayConfig | None = None,
) -> NDArray[np.uint8]:
    """The overlay alone, as straight-alpha RGBA (uint8, at :func:`display_size`) over
    a transparent background, for a photo of ``shape`` (H, W, ...): to lay over the
    photo elsewhere (a web page). The arguments are those of :func:`draw_overlay`."""
    config = config or OverlayConfig()
    photo_shape = (int(shape[0]), int(shape[1]))
    canvas = _Canvas(display_size(photo_shape, config))
    _paint_all(canvas, photo_shape, poses, mesh_of, placement, intrinsics, config)
    return canvas.rgba()


def draw_overlay(
    photo: NDArray[np.uint8],
    poses: Sequence[OverlayPose],
    mesh_of: Callable[[str], NormalisedMesh],
    *,
    intrinsics: Intrinsics | None = None,
    placement: Callable[[str], Placement] | None = None,
    config: OverlayConfig | None = None,
) -> NDArray[np.uint8]:
    """The photo (RGB or RGBA uint8, H × W) with each pose's mesh drawn over it (see the
    module doc); RGB uint8 at :func:`display_size`. The photo is not changed.

    ``poses`` best first, each in its own colour (``config.colours``); ``mesh_of(name)``
    gives each object's normalised mesh (e.g. :meth:`viewdb.ViewDB.mesh`).
    ``intrinsics`` ``(fx, fy, cx, cy)`` are needed for pinhole (``opencv``) poses, and
    ``placement(name)`` (the ``(centre, scale)`` of :class:`viewdb.ObjectInfo`) for poses
    in the mesh's own units when ``mesh_of`` gives meshes without their placement, as a
    database's stored meshes are."""
    config = config or OverlayConfig()
    photo = np.asarray(photo)
    if photo.dtype != np.uint8 or photo.ndim not in (2, 3):
        raise QueryError(f"the photo must be an 8-bit grey or RGB(A) image, got {photo.dtype} "
                         f"of shape {photo.shape}")
    base = resized_photo(photo, config)
    canvas = _Canvas(base.shape[:2])
    _paint_all(canvas, (int(photo.shape[0]), int(photo.shape[1])), poses, mesh_of, placement, intrinsics,
               config)
    return canvas.over(base)


def result_poses(result: QueryResult, top: int = 1) -> list[OverlayPose]:
    """The poses of each object's best ``top`` posed results in a query's answer (one
    object, or each of ``result.objects``), each object's best first."""
    groups: list[list[QueryMatch]] = (
        [result.results] if result.objects is None else [o.results for o in result.objects])
    poses = []
    for matches in groups:
        posed = [m for m in matches if m.pose is not None][:top]
        poses += [OverlayPose.from_estimate(m.object, m.pose, m.score, m.rank) for m in posed
                  if m.pose is not None]
    return poses


def draw_result(
    photo: NDArray[np.uint8], result: QueryResult, mesh_of: Callable[[str], NormalisedMesh],
    placement: Callable[[str], Placement], intrinsics: Intrinsics | None,
    top: int = 1, config: OverlayConfig | None = None,
) -> NDArray[np.uint8]:
    """A query's answer drawn over its photo (:func:`draw_overlay` of :func:`result_poses`):
    each object's best ``top`` posed results, in its own colour."""
    return draw_overlay(photo, result_poses(result, top), mesh_of, intrinsics=intrinsics,
                        placement=placement, config=config)
