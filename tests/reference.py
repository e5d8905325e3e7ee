"""Slow, obvious oracles for :mod:`viewdb.catalogue.features` (used only by the tests).

Nothing here shares code with the fast implementation: the contour is found by a
pure-Python marching squares pass over every 2x2 cell with the segments linked into
loops by hand (no OpenCV), the centroid and the start point are computed in exact
rational arithmetic (:class:`fractions.Fraction`), the curve is sampled by walking the
polygon edge by edge, and the DFT is the textbook double sum.  Only the *conventions*
(documented in :mod:`viewdb.catalogue.features`) are shared.
"""

from __future__ import annotations

import cmath
import math
from fractions import Fraction

import numpy as np

__all__ = [
    "largest_area",
    "largest_is_unique",
    "naive_contour",
    "naive_distance_curve",
    "naive_dft",
    "naive_face_ids",
]

# Corner order of a cell whose top-left pixel centre is (x, y): TL, TR, BR, BL.
_CORNERS = ((0, 0), (1, 0), (1, 1), (0, 1))
# Side k of a cell joins corner k and corner k+1 (top, right, bottom, left).
_SIDES = ((0, 1), (1, 2), (2, 3), (3, 0))


def _loops(mask: np.ndarray) -> list[list[tuple[int, int]]]:
    """Every level-1/2 iso-line loop of ``mask``, in doubled coordinates (2x, 2y).

    A vertex is the midpoint of a side joining an object and a background pixel.  In a
    cell with two diagonal object pixels (a saddle) the object pixels are joined, i.e.
    each background corner is cut off on its own, so regions are 8-connected.
    """
    fg = np.pad(np.asarray(mask) != 0, 1)
    h, w = fg.shape
    neighbours: dict[tuple[int, int], list[tuple[int, int]]] = {}

    def link(a: tuple[int, int], b: tuple[int, int]) -> None:
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)

    for y in range(h - 1):
        for x in range(w - 1):
            corners = [(x + dx, y + dy) for dx, dy in _CORNERS]
            inside = [bool(fg[cy, cx]) for cx, cy in corners]
            if all(inside) or not any(inside):
                continue
            mids = []
            for a, b in _SIDES:
                (ax, ay), (bx, by) = corners[a], corners[b]
                mids.append((ax + bx, ay + by))  # doubled midpoint
            crossing = [k for k, (a, b) in enumerate(_SIDES) if inside[a] != inside[b]]
            if len(crossing) == 2:
                link(mids[crossing[0]], mids[crossing[1]])
            else:  # saddle: cut off each background corner (corner k touches sides k-1, k)
                for k in range(4):
                    if not inside[k]:
                        link(mids[(k - 1) % 4], mids[k])
    loops = []
    seen: set[tuple[int, int]] = set()
    for start in sorted(neighbours):
        if start in seen:
            continue
        assert len(neighbours[start]) == 2, "iso-line vertices have degree 2"
        loop = [start]
        seen.add(start)
        prev, cur = start, neighbours[start][0]
        while cur != start:
            loop.append(cur)
            seen.add(cur)
            a, b = neighbours[cur]
            prev, cur = cur, (b if a == prev else a)
        loops.append(loop)
    # shift back: doubled coordinates of the padded grid -> doubled original coordinates
    return [[(u - 2, v - 2) for u, v in loop] for loop in loops]


def _twice_area(loop: list[tuple[int, int]]) -> int:
    n = len(loop)
    return sum(
        loop[i][0] * loop[(i + 1) % n][1] - loop[(i + 1) % n][0] * loop[i][1] for i in range(n)
    )


def largest_area(mask: np.ndarray) -> float:
    """Area in square pixels enclosed by the largest iso-line loop (0.0 for a blank mask)."""
    loops = _loops(mask)
    return max((abs(_twice_area(lp)) for lp in loops), default=0) / 8.0  # doubled coords


def largest_is_unique(mask: np.ndarray) -> bool:
    """True if exactly one iso-line loop encloses the largest area (no tie to break)."""
    areas = [abs(_twice_area(lp)) for lp in _loops(mask)]
    return bool(areas) and areas.count(max(areas)) == 1


def naive_contour(mask: np.ndarray) -> np.ndarray | None:
    """The largest iso-line loop, clockwise on screen, as (P, 2) float (x, y); None if none.

    The loop of largest |area| is always an outer boundary (a hole is enclosed by its
    region's outer loop, which is larger).
    """
    loops = _loops(mask)
    if not loops:
        return None
    loop = max(loops, key=lambda lp: abs(_twice_area(lp)))
    if _twice_area(loop) < 0:  # make the shoelace area positive = clockwise with y down
        loop = loop[::-1]
    return np.array(loop, dtype=np.float64) / 2.0


def naive_distance_curve(mask: np.ndarray, n_samples: int, start: str = "top") -> np.ndarray:
    """Centroid distance curve by the documented convention, computed the slow way.

    ``start="bottom"`` starts instead at the *lowest* point of the contour on the
    vertical line through the centroid (what a 180-degree rotation turns into the top).
    """
    contour = naive_contour(mask)
    assert contour is not None
    pts = [(Fraction(int(round(2 * x))), Fraction(int(round(2 * y)))) for x, y in contour]
    n = len(pts)
    # area centroid of the polygon (Green's theorem), exactly
    a2 = Fraction(0)
    sx = Fraction(0)
    sy = Fraction(0)
    for i in range(n):
        (x0, y0), (x1, y1) = pts[i], pts[(i + 1) % n]
        cross = x0 * y1 - x1 * y0
        a2 += cross
        sx += (x0 + x1) * cross
        sy += (y0 + y1) * cross
    cx, cy = sx / (3 * a2), sy / (3 * a2)
    # start: the topmost (or lowest) point of the contour on the vertical line x = cx
    best = None  # (y, edge index, fraction along the edge)
    for i in range(n):
        (x0, y0), (x1, y1) = pts[i], pts[(i + 1) % n]
        if x0 == x1:
            if x0 == cx:
                upper = (y0, i, Fraction(0)) if y0 <= y1 else (y1, i, Fraction(1))
                lower = (y1, i, Fraction(1)) if y0 <= y1 else (y0, i, Fraction(0))
                cand = upper if start == "top" else lower
            else:
                continue
        else:
            t = (cx - x0) / (x1 - x0)
            if not 0 <= t <= 1:
                continue
            cand = (y0 + t * (y1 - y0), i, t)
        if best is None or (cand[0] < best[0] if start == "top" else cand[0] > best[0]):
            best = cand
    assert best is not None
    lengths = [
        math.hypot(float(pts[(i + 1) % n][0] - pts[i][0]), float(pts[(i + 1) % n][1] - pts[i][1]))
        for i in range(n)
    ]
    total = sum(lengths)
    _, k, t = best
    # walk clockwise from the start point, one sample every total / n_samples
    step = total / n_samples
    curve = []
    edge, offset = k, float(t) * lengths[k]  # offset: distance already walked along `edge`
    for i in range(n_samples):
        target = step if i else 0.0
        offset += target
        while offset > lengths[edge]:
            offset -= lengths[edge]
            edge = (edge + 1) % n
        f = offset / lengths[edge]
        (x0, y0), (x1, y1) = pts[edge], pts[(edge + 1) % n]
        x = float(x0) + f * float(x1 - x0)
        y = float(y0) + f * float(y1 - y0)
        curve.append(math.hypot(x - float(cx), y - float(cy)))
    mean = sum(curve) / n_samples
    return np.array([c / mean for c in curve])


def naive_dft(x: np.ndarray, m: int) -> np.ndarray:
    """First ``m`` orthonormal DFT coefficients, X_k = sum_t x_t exp(-2 pi i k t / N) / sqrt(N)."""
    n = len(x)
    return np.array(
        [
            sum(complex(x[t]) * cmath.exp(-2j * math.pi * k * t / n) for t in range(n))
            / math.sqrt(n)
            for k in range(m)
        ]
    )


# ---------------------------------------------------------------------------------------
# Oracle for viewdb.catalogue.skimming: brute-force view relations of a finite symmetry group.
# Shares nothing with the module but the camera contract (viewdb.camera.camera_pose):
# the group is closed by multiplying all pairs until nothing new appears, and every pair
# of grid views is compared with every g·C·M directly as matrices (no decomposition into
# angles, no grid snapping).
# ---------------------------------------------------------------------------------------

__all__ += ["naive_group_closure", "naive_view_relations"]


def naive_group_closure(generators: list[np.ndarray], limit: int = 2000) -> list[np.ndarray]:
    """Every product of the (orthogonal) generators; raises if the group exceeds ``limit``."""
    def key(m: np.ndarray) -> tuple[int, ...]:
        return tuple(int(x) for x in np.rint(np.asarray(m) * 1e6).ravel())

    elems: dict[tuple[int, ...], np.ndarray] = {}
    for e in [np.eye(3)] + [np.asarray(g, dtype=float) for g in generators]:
        elems.setdefault(key(e), e)
    grew = True
    while grew:
        grew = False
        for a in list(elems.values()):
            for b in list(elems.values()):
                m = a @ b
                if key(m) not in elems:
                    elems[key(m)] = m
                    grew = True
                    if len(elems) > limit:
                        raise ValueError("group too large for the oracle")
    return list(elems.values())


def naive_view_relations(
    generators: list[np.ndarray], gap: float
) -> dict[tuple[float, float], tuple[int, int, bool]]:
    """For every grid view: (class id, parity relative to the class root, self-mirror class).

    Two views are related when some group element g and some M in diag(+-1, 1, +-1) with
    det(g)·det(M) = +1 give g·C_a·M == C_b (mirrored when M's x-entry is -1); classes are
    the transitive closure (plain union-find with a parity bit, a parity conflict marking
    the class self-mirror).
    """
    from viewdb.camera import camera_pose, grid_views

    views = [(float(h), float(v)) for h, v in grid_views(gap)]
    cams = np.array([camera_pose(h, v)[:3, :3] for h, v in views])
    ms = [np.diag([sx, 1.0, sz]) for sx in (1.0, -1.0) for sz in (1.0, -1.0)]
    parent = list(range(len(views)))
    par = [0] * len(views)  # parity to parent
    conflict: set[int] = set()

    def find(i: int) -> tuple[int, int]:
        p = 0
        while parent[i] != i:
            p ^= par[i]
            i = parent[i]
        return i, p

    def union(a: int, b: int, p: int) -> None:
        ra, pa = find(a)
        rb, pb = find(b)
        if ra == rb:
            if pa ^ pb != p:
                conflict.add(ra)
            return
        parent[rb] = ra
        par[rb] = pa ^ pb ^ p
        if rb in conflict:
            conflict.add(ra)

    for g in naive_group_closure(generators):
        for m in ms:
            if np.linalg.det(g) * np.linalg.det(m) < 0:
                continue
            mapped = np.einsum("ij,ajk,kl->ail", g, cams, m)
            close = np.all(np.abs(mapped[:, None] - cams[None, :]) < 1e-7, axis=(2, 3))
            for a, b in zip(*np.nonzero(close), strict=True):
                union(int(a), int(b), 1 if m[0, 0] < 0 else 0)
    out = {}
    for i, view in enumerate(views):
        r, p = find(i)
        out[view] = (r, p, r in conflict)
    return out


# ---------------------------------------------------------------------------------------
# Oracles for viewdb.search.bounds: the textbook full-matrix DTW recursion in plain Python
# floats, brute-force window min/max, the envelope distance cell by cell, and the range of
# a linear functional over a box by enumerating every vertex of the box (small N only).
# ---------------------------------------------------------------------------------------

__all__ += ["naive_dtw", "naive_envelope", "naive_lb_keogh", "naive_box_by_vertices"]


def naive_dtw(q, c, r: int | None = None) -> float:
    """sqrt of the least squared-cost warping path, cells |i - j| <= r (None: no band)."""
    q = [float(v) for v in q]
    c = [float(v) for v in c]
    n, mm = len(q), len(c)
    inf = math.inf
    D = [[inf] * (mm + 1) for _ in range(n + 1)]
    D[0][0] = 0.0
    for i in range(1, n + 1):
        for j in range(1, mm + 1):
            if r is not None and abs(i - j) > r:
                continue
            cost = (q[i - 1] - c[j - 1]) ** 2
            D[i][j] = cost + min(D[i - 1][j - 1], D[i - 1][j], D[i][j - 1])
    return math.sqrt(D[n][mm])


def naive_envelope(q, r: int) -> tuple[np.ndarray, np.ndarray]:
    """U_i = max of q over |t - i| <= r, L_i = min (window clipped to the sequence)."""
    n = len(q)
    window = [[float(q[t]) for t in range(n) if abs(t - i) <= r] for i in range(n)]
    return np.array([min(w) for w in window]), np.array([max(w) for w in window])


def naive_lb_keogh(lower, upper, c) -> float:
    """Distance from c to the envelope, one sample at a time."""
    s = 0.0
    for lo, hi, v in zip(lower, upper, c, strict=True):
        if v > hi:
            s += (v - hi) ** 2
        elif v < lo:
            s += (lo - v) ** 2
    return math.sqrt(s)


def naive_box_by_vertices(lower, upper, F) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of each row of F . x over all 2^N vertices x of the box [lower, upper]."""
    import itertools

    n = len(lower)
    verts = np.array(
        [
            [upper[t] if bit else lower[t] for t, bit in enumerate(bits)]
            for bits in itertools.product((0, 1), repeat=n)
        ]
    )
    vals = verts @ np.asarray(F).T
    return vals.min(axis=0), vals.max(axis=0)


# ---------------------------------------------------------------------------------------
# search over several query curves (in-plane shifts)
# ---------------------------------------------------------------------------------------

__all__ += ["naive_knn_over_curves", "naive_shifted"]


def naive_shifted(q, s: int) -> list[float]:
    """The curve started at sample s: out[i] = q[(i + s) mod N]."""
    n = len(q)
    return [float(q[(i + s) % n]) for i in range(n)]


def naive_knn_over_curves(queries, curves, owner, names, k: int, r: int):
    """Top-k distinct objects by the smallest DTW of any query curve against any stored
    curve or its mirror (c'[i] = c[-i mod N]), every pair computed: [(distance, name,
    view, mirrored, query)], best first (ties: name)."""
    best: dict[int, tuple[float, int, bool, int]] = {}
    for view, c in enumerate(curves):
        n = len(c)
        mirrored = [float(c[(-i) % n]) for i in range(n)]
        for t, q in enumerate(queries):
            for flip, cc in ((False, c), (True, mirrored)):
                d = naive_dtw(q, cc, r)
                o = int(owner[view])
                if o not in best or d < best[o][0]:
                    best[o] = (d, view, flip, t)
    ranked = sorted(((d, names[o], v, m, t) for o, (d, v, m, t) in best.items()), key=lambda x: (x[0], x[1]))
    return ranked[:k]


def naive_face_ids(tri, planes, faces, shape) -> np.ndarray:
    """Which triangle each pixel shows, pixel by pixel and triangle by triangle: the
    nearest whose projection holds the pixel's centre, ``y_min <= y < y_max`` and, where
    row ``y`` crosses its edges, ``left <= x < right``; the depth ``a·x + b·y + c`` is
    taken as the kernel takes it, from the row's first pixel on the image; on a tie the
    later triangle. The corners are first rounded to the nearest 1/256 pixel (half up),
    as a GPU's 8 sub-pixel bits put them."""
    h, w = shape
    ids = np.full((h, w), -1, dtype=np.int32)
    best = np.full((h, w), np.inf)
    tri = [[(math.floor(float(x) * 256 + 0.5) / 256, math.floor(float(y) * 256 + 0.5) / 256) for x, y in t]
           for t in tri]
    for f in range(len(tri)):
        ys = [float(p[1]) for p in tri[f]]
        a, b, c = (float(v) for v in planes[f])
        for row in range(h):
            if not min(ys) <= row < max(ys):
                continue
            crossings = []
            for k in range(3):
                (px, py), (qx, qy) = tri[f][k], tri[f][(k + 1) % 3]
                if qy != py and (py - row) * (qy - row) <= 0:
                    crossings.append(px + (row - py) * (qx - px) / (qy - py))
            if not crossings:
                continue
            left, right = min(crossings), max(crossings)
            first = min(max(math.ceil(left), 0), w)
            for x in range(w):
                if left <= x < right:
                    z = (a * first + b * row + c) + a * (x - first)
                    if z <= best[row, x]:
                        best[row, x] = z
                        ids[row, x] = faces[f]
    return ids


# ---------------------------------------------------------------------------------------
# The border colour model's k-means (viewdb.recognition.segmentation), every update run.
# ---------------------------------------------------------------------------------------

__all__ += ["naive_kmeans"]


def naive_kmeans(x: np.ndarray, k: int, min_share: float, iterations: int) -> np.ndarray:
    """Farthest-point start (the median, then the sample farthest from every centre so far),
    then exactly ``iterations`` updates, each sample to the centre of least
    ``|c|^2 - 2 x . c`` (the first on a tie), each centre to its samples' mean summed in
    sample order (kept when it has none); clusters of under ``min_share`` of the samples
    dropped (the largest kept if none is left)."""
    rows = [np.asarray(r, dtype=np.float64) for r in x]
    centres = [np.median(x, axis=0)]
    nearest = [float(((r - centres[0]) ** 2).sum()) for r in rows]
    for _ in range(1, k):
        far = max(range(len(rows)), key=lambda i: (nearest[i], -i))
        centres.append(rows[far].copy())
        nearest = [min(d, float(((r - centres[-1]) ** 2).sum())) for d, r in zip(nearest, rows, strict=True)]

    def assign() -> list[int]:
        c = np.array(centres)
        scores = (c * c).sum(axis=1)[None, :] - 2.0 * np.asarray(x, np.float64) @ c.T
        return [min(range(len(centres)), key=lambda j: (s[j], j)) for s in scores]

    for _ in range(iterations):
        labels = assign()
        for j in range(len(centres)):
            members = [r for r, label in zip(rows, labels, strict=True) if label == j]
            if members:
                total = np.zeros(x.shape[1])
                for r in members:
                    total = total + r
                centres[j] = total / len(members)
    labels = assign()
    share = np.array([labels.count(j) for j in range(len(centres))]) / len(rows)
    keep = [j for j in range(len(centres)) if share[j] >= min_share]
    return np.array([centres[j] for j in keep] if keep else [centres[int(np.argmax(share))]])
