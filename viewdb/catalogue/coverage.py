"""A mesh's silhouette through a pinhole camera, on the CPU: which pixels its triangles cover.

A silhouette fit (:mod:`viewdb.pose.silhouette`) asks for hundreds of silhouettes of one
mesh at nearby poses in a small window (80 to 160 pixels square). Through OpenGL each costs
the per-call overhead of a render and a read-back (3–4 ms for a 16,000-face scan, 0.7 ms
for a box); a silhouette needs neither depth nor shading, so here it is scan-converted
directly: project the vertices (one matrix product), then mark the pixels whose centres
lie inside each triangle's projection, with no depth test (every covered pixel is
silhouette, whichever triangle is in front). A closed mesh's faces of one winding alone
cover its silhouette (:attr:`MeshTriangles.front`), so the others are skipped: about half
the faces, 1.5–1.9x quicker fills on the YCB-Video scans, the same pixels.

Conventions are those of :class:`~viewdb.catalogue.pinhole.PinholeRenderer`: the pose is
model-to-camera in the OpenCV frame, intrinsics ``(fx, fy, cx, cy)`` with pixel centres on
integers, and a pixel is covered when its centre is inside a triangle (a centre on a
triangle's right or bottom edge is left to its neighbour, as a GPU does; rows ``y_min <=
y < y_max``). A triangle with a corner behind the near plane (camera z below ``near``) is
left out; a silhouette fit never places the object's bounding sphere that close. For its
coarse steps, in a small window, a fit uses the mesh decimated to a few thousand faces
(:meth:`MeshTriangles.simplified`): the silhouette of a 16,000-face scan at 4,096 faces
has an IoU of 0.99 or more with the full mesh's in 80 to 160 pixel windows, and fills
about 4x quicker (the fill's time grows with the triangles, not the pixels).

The loops run in numba kernels (compiled once, cached on disk, ``nogil``); :func:`cover`
fills triangles already projected (the overlay's silhouette, :mod:`viewdb.recognition.overlay`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..jit import njit
from ..typed import Intrinsics

__all__ = ["SUBPIXELS", "MeshTriangles", "cover", "overlap", "overlap_kernel", "silhouette", "snapped"]

_NO_WEIGHTS = np.zeros((0, 0))
_NO_VALID = np.zeros((0, 0), np.bool_)

#: Projected corners are put on a grid of 1/SUBPIXELS pixel first, as a GPU's rasteriser
#: does (8 bits of sub-pixel precision): an edge a hair past a pixel centre then leaves
#: it out as OpenGL does, instead of filling a whole column along a straight edge.
SUBPIXELS = 256.0


class MeshTriangles:
    """A mesh's vertices and faces as contiguous arrays, ready for :func:`silhouette`."""

    __slots__ = ("_front", "faces", "vertices")

    def __init__(self, vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= len(self.vertices)):
            raise ValueError("a face names a vertex the mesh does not have")
        self._front: int | None = None

    @property
    def front(self) -> int:
        """When the mesh is closed, the sign (−1) of the doubled area, in pixel coordinates
        (x right, y down), of the faces that alone cover its silhouette; 0 when it is not
        (no face may then be left out). Found once (:func:`_front_sign`)."""
        if self._front is None:
            self._front = _front_sign(self.vertices, self.faces)
        return self._front

    def simplified(self, max_faces: int, min_iou: float = 0.985) -> MeshTriangles:
        """At most about ``max_faces`` triangles with nearly the same silhouette: the
        vertices welded by position (a mesh split at texture seams shares positions, not
        vertices), then quadric decimation (``fast_simplification``). The decimated mesh
        is kept only if its silhouettes from 20 directions (a dodecahedron's corners), 96
        pixels across, each have an IoU of at least ``min_iou`` with this mesh's;
        otherwise (thin walls, open edges the decimation eats into), and when this mesh
        has no more than ``max_faces`` faces, it is this mesh itself."""
        if len(self.faces) <= max_faces:
            return self
        import fast_simplification

        faces, first = _welded(self.vertices, self.faces)
        try:
            vertices, faces = fast_simplification.simplify(
                self.vertices[first].astype(np.float32), faces.astype(np.int32),
                target_reduction=1.0 - max_faces / len(faces))
        except (ValueError, RuntimeError):
            return self
        small = MeshTriangles(vertices, faces)
        return small if len(small.faces) and _same_silhouettes(self, small, min_iou) else self


def _welded(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray]:
    """``faces`` over the vertices welded by position (a mesh split at texture seams shares
    positions, not vertices), the faces that lost a corner dropped; and the index of the
    first vertex at each distinct position (the welded vertices)."""
    _, first, welded = np.unique(np.round(vertices, 9), axis=0, return_index=True, return_inverse=True)
    out = welded.reshape(-1)[faces]
    a, b, c = out.T
    return out[(a != b) & (b != c) & (a != c)], first


def _front_sign(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> int:
    """:attr:`MeshTriangles.front`: −1 when the mesh is closed (a cycle: with its vertices
    welded, every edge is run as often one way as the other by its faces), else 0.

    A ray from the camera into a closed mesh enters it as often as it leaves it, so it
    meets faces that wind clockwise on the image as well as counter-clockwise ones (with
    outward normals: front faces and back faces; two faces back to back, as decimation
    leaves, are one of each): either kind alone covers the silhouette. The sign kept is
    the front faces' for outward normals (a face towards the camera winds clockwise on an
    image whose y axis points down: negative doubled area)."""
    if not len(faces):
        return 0
    welded, first = _welded(vertices, faces)
    n = len(first)
    edges = np.concatenate([welded[:, [0, 1]], welded[:, [1, 2]], welded[:, [2, 0]]])
    forward = np.sort(edges[:, 0] * n + edges[:, 1])
    backward = np.sort(edges[:, 1] * n + edges[:, 0])
    return -1 if len(forward) and np.array_equal(forward, backward) else 0


def _same_silhouettes(a: MeshTriangles, b: MeshTriangles, min_iou: float) -> bool:
    """Whether ``a`` and ``b`` look alike from the 20 corners of a dodecahedron."""
    phi = (1.0 + 5.0**0.5) / 2.0
    corners = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    for u in (-1, 1):
        for w in (-1, 1):
            corners += [(0, u / phi, w * phi), (u / phi, w * phi, 0), (u * phi, 0, w / phi)]
    camera = (110.0, 110.0, 47.5, 47.5)
    for corner in corners:
        back = np.asarray(corner, dtype=np.float64) / np.linalg.norm(corner)  # from the camera to the object
        side = np.cross(back, [0.0, 0.0, 1.0] if abs(back[2]) < 0.9 else [1.0, 0.0, 0.0])
        side /= np.linalg.norm(side)
        rotation = np.stack([side, np.cross(back, side), back])
        seen_a = silhouette(a, rotation, np.array([0.0, 0.0, 3.0]), camera, 96)
        seen_b = silhouette(b, rotation, np.array([0.0, 0.0, 3.0]), camera, 96)
        union = int((seen_a | seen_b).sum())
        if union and (seen_a & seen_b).sum() < min_iou * union:
            return False
    return True


def silhouette(
    triangles: MeshTriangles, rotation: NDArray[np.floating], translation: NDArray[np.floating],
    intrinsics: Intrinsics, size: int | tuple[int, int], near: float = 1e-3,
) -> NDArray[np.bool_]:
    """The pixels of a ``size × size`` (or ``(height, width)``) image covered by the mesh at
    the OpenCV pose ``(rotation, translation)`` through ``intrinsics`` (module doc)."""
    h, w = (size, size) if isinstance(size, int) else size
    n = len(triangles.vertices)
    px, py = np.empty(n), np.empty(n)
    _project(triangles.vertices, np.ascontiguousarray(rotation, dtype=np.float64).reshape(3, 3),
             np.ascontiguousarray(translation, dtype=np.float64).reshape(3),
             np.array([float(x) for x in intrinsics], dtype=np.float64), float(near), px, py)
    out = np.zeros((h, w), dtype=np.bool_)
    _fill_overlap(px, py, triangles.faces, out, _NO_WEIGHTS, _NO_VALID, triangles.front)
    return out


def overlap(
    triangles: MeshTriangles, rotation: NDArray[np.floating], translation: NDArray[np.floating],
    intrinsics: Intrinsics, weights: NDArray[np.float64], valid: NDArray[np.bool_], near: float = 1e-3,
) -> tuple[float, int]:
    """How the silhouette of :func:`silhouette` (its size that of ``weights``) meets an
    image, without making it: the sum of ``weights`` over the covered pixels and the
    number of covered pixels where ``valid``. A silhouette fit's IoU against a mask, in
    one compiled pass (the scan conversion counts each pixel the first time it covers it)."""
    return overlap_kernel(triangles.vertices, triangles.faces, triangles.front,
                          np.ascontiguousarray(rotation, dtype=np.float64).reshape(3, 3),
                          np.ascontiguousarray(translation, dtype=np.float64).reshape(3),
                          np.array([float(x) for x in intrinsics], dtype=np.float64), float(near),
                          weights, valid)


@njit(cache=True, nogil=True)
def overlap_kernel(vertices, faces, front, r, t, camera, near, weights, valid):  # pragma: no cover - compiled
    """:func:`overlap` on the arrays of a :class:`MeshTriangles` (``front``: its
    :attr:`~MeshTriangles.front`), the camera ``(fx, fy, cx, cy)`` as an array: callable
    from other compiled code (:mod:`viewdb.pose.silhouette`'s pose search)."""
    n = vertices.shape[0]
    px, py = np.empty(n), np.empty(n)
    _project(vertices, r, t, camera, near, px, py)
    seen = np.zeros(weights.shape, dtype=np.bool_)
    return _fill_overlap(px, py, faces, seen, weights, valid, front)


def cover(
    points: NDArray[np.floating], faces: NDArray[np.integer], shape: tuple[int, int]
) -> NDArray[np.bool_]:
    """The pixels of an image of ``shape`` covered by triangles already projected:
    ``points`` (n, 2) pixel positions ``(x, y)`` of the vertices (NaN: behind the camera,
    its triangles left out), ``faces`` (m, 3) vertex indices."""
    p = snapped(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    out = np.zeros((int(shape[0]), int(shape[1])), dtype=np.bool_)
    _fill(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]),
          np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3), out)
    return out


@njit(cache=True, nogil=True)
def _project(vertices, r, t, camera, near, px, py):  # pragma: no cover - compiled
    fx, fy, cx, cy = camera[0], camera[1], camera[2], camera[3]
    for i in range(vertices.shape[0]):
        x, y, z = vertices[i, 0], vertices[i, 1], vertices[i, 2]
        zc = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z + t[2]
        if zc > near:
            px[i] = _snap(fx * (r[0, 0] * x + r[0, 1] * y + r[0, 2] * z + t[0]) / zc + cx)
            py[i] = _snap(fy * (r[1, 0] * x + r[1, 1] * y + r[1, 2] * z + t[1]) / zc + cy)
        else:
            px[i] = np.nan
            py[i] = np.nan


def snapped(points: NDArray[np.floating]) -> NDArray[np.float64]:
    """Projected positions put on the grid of 1/:data:`SUBPIXELS` pixel a GPU puts
    corners on (what :func:`silhouette`'s projection does to each; NaN stays NaN)."""
    p = np.asarray(points, dtype=np.float64)
    return _snap(p.ravel()).reshape(p.shape)  # one compiled signature, whatever the shape


@njit(cache=True, nogil=True)
def _snap(x):  # pragma: no cover - compiled
    """``x`` on the grid of 1/256 pixel a GPU puts projected corners on (NaN stays NaN)."""
    return np.floor(x * SUBPIXELS + 0.5) / SUBPIXELS


@njit(cache=True, nogil=True)
def _crossing(ax, ay, bx, by, y, left, right):  # pragma: no cover - compiled
    """``(left, right)`` widened by where edge a–b crosses row ``y``, if it does."""
    dy = by - ay
    if dy != 0.0 and (ay - y) * (by - y) <= 0.0:
        x = ax + (y - ay) * (bx - ax) / dy
        left = min(left, x)
        right = max(right, x)
    return left, right


@njit(cache=True, nogil=True)
def _fill(px, py, faces, out):  # pragma: no cover - compiled
    """Mark the pixels whose centres lie in each triangle of corners already snapped."""
    _fill_overlap(px, py, faces, out, np.zeros((0, 0)), np.zeros((0, 0), np.bool_), 0)


@njit(cache=True, nogil=True)
def _fill_overlap(px, py, faces, out, weights, valid, front):  # pragma: no cover - compiled
    """:func:`_fill`, and with ``weights`` (else empty) the sum of ``weights`` over the
    newly marked pixels and the count of those ``valid``. ``front`` (±1, 0: none): the
    sign of a front face's doubled area; the faces of the other sign are left out (a
    closed mesh's front faces cover its silhouette: :attr:`MeshTriangles.front`)."""
    h, w = out.shape
    counting = weights.shape[0] > 0
    total = 0.0
    count = 0
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, x1, y1, x2, y2 = px[i0], py[i0], px[i1], py[i1], px[i2], py[i2]
        if front != 0 and ((x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)) * front < 0.0:
            continue  # a back face of a closed mesh: front faces cover whatever it covers
        ymin = min(y0, min(y1, y2))
        ymax = max(y0, max(y1, y2))
        if not (ymax >= 0.0 and ymin <= h):  # off the image, or a corner behind the camera (NaN)
            continue
        r0 = max(np.ceil(ymin), 0.0)
        r1 = min(np.ceil(ymax) - 1.0, float(h - 1))
        if r0 > r1:  # no row of pixel centres crosses it
            continue
        xmin = min(x0, min(x1, x2))
        xmax = max(x0, max(x1, x2))
        if not (xmax >= 0.0 and xmin <= w) or np.ceil(xmin) >= xmax:
            continue  # off the image, or no column of pixel centres inside it (NaN too)
        for row in range(int(r0), int(r1) + 1):
            y = float(row)
            left, right = _crossing(x0, y0, x1, y1, y, np.inf, -np.inf)
            left, right = _crossing(x1, y1, x2, y2, y, left, right)
            left, right = _crossing(x2, y2, x0, y0, y, left, right)
            if not left <= right:
                continue
            c0 = int(min(max(np.ceil(left), 0.0), float(w)))
            c1 = int(min(max(np.ceil(right) - 1.0, -1.0), float(w - 1)))
            for x in range(c0, c1 + 1):
                if counting and not out[row, x]:
                    total += weights[row, x]
                    if valid[row, x]:
                        count += 1
                out[row, x] = True
    return total, count
