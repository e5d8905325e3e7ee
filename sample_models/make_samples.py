#!/usr/bin/env python3
"""Generate viewdb's own small sample meshes.

Run ``python sample_models/make_samples.py [OUT_DIR]`` (default: the folder holding this
script). Everything is built procedurally with numpy, trimesh and Pillow; the only
randomness comes from ``numpy.random.default_rng`` seeded per model, so running the
script twice writes byte-identical files (for a given numpy / trimesh / Pillow).

Conventions (the same as viewdb's camera): +Y is up, +Z is the model's front, +X is the
model's right-hand side as seen from the front... i.e. a camera on +Z looking down -Z sees
+X to its right. Every model is centred on its bounding-box centre.

The files cover the symmetry classes of the paper (see ``README.md`` in this folder) and
every loader path: OBJ + MTL + PNG texture, PLY with vertex or face colours, binary STL,
OFF and binary glTF (GLB) with a texture or vertex colours.
"""

from __future__ import annotations

import sys
import zlib
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image, ImageDraw, ImageFont
from trimesh.visual.material import SimpleMaterial
from trimesh.visual.texture import TextureVisuals

__all__ = ["MODELS", "main"]

HERE = Path(__file__).resolve().parent

#: Base seed; every model derives its own generator from it and its name.
SEED = 1234

#: Texture atlas size in pixels (square, <= 256 as the samples must stay small).
TEX = 256

#: Colours of the camera-convention cube, by outward face direction.
MARKED_CUBE_COLOURS = {
    "+Z": (255, 0, 0),  # red
    "-Z": (0, 255, 255),  # cyan
    "+X": (0, 255, 0),  # green
    "-X": (255, 0, 255),  # magenta
    "+Y": (0, 0, 255),  # blue
    "-Y": (255, 255, 0),  # yellow
}

DIRS = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")


# --------------------------------------------------------------------------------------
# small helpers
# --------------------------------------------------------------------------------------


def _rng(name: str) -> np.random.Generator:
    return np.random.default_rng([SEED, zlib.crc32(name.encode())])


def _translate(xyz) -> np.ndarray:
    return trimesh.transformations.translation_matrix(np.asarray(xyz, dtype=float))


def _rotate(deg: float, axis) -> np.ndarray:
    return trimesh.transformations.rotation_matrix(np.radians(deg), axis)


#: Rotation taking trimesh's default +Z primitive axis to +Y (x, y, z) -> (x, z, -y).
Z_TO_Y = _rotate(-90.0, [1, 0, 0])


def _box(lo, hi) -> trimesh.Trimesh:
    """Axis-aligned box from its min and max corner."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return trimesh.creation.box(extents=hi - lo, transform=_translate((lo + hi) / 2))


def _cylinder_y(radius: float, y0: float, y1: float, sections: int = 32, xz=(0.0, 0.0)):
    m = trimesh.creation.cylinder(radius=radius, height=y1 - y0, sections=sections)
    m.apply_transform(Z_TO_Y)
    m.apply_translation([xz[0], (y0 + y1) / 2, xz[1]])
    return m


def _concat(meshes) -> trimesh.Trimesh:
    """Plain concatenation of geometry (no visuals)."""
    vertices, faces, offset = [], [], 0
    for m in meshes:
        vertices.append(np.asarray(m.vertices, float))
        faces.append(np.asarray(m.faces, np.int64) + offset)
        offset += len(m.vertices)
    return trimesh.Trimesh(np.vstack(vertices), np.vstack(faces), process=False)


def _centre(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Move the bounding-box centre to the origin (in place) and return the mesh."""
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    return mesh


def _clean_vertices(v: np.ndarray) -> np.ndarray:
    """Round away float noise so exported text is short and stable (and -0.0 -> 0.0)."""
    v = np.round(np.asarray(v, float), 6)
    return v + 0.0


def _direction_of(normals: np.ndarray) -> np.ndarray:
    """Index into DIRS of the dominant axis of each normal."""
    axis = np.argmax(np.abs(normals), axis=1)
    sign = np.take_along_axis(normals, axis[:, None], axis=1)[:, 0] < 0
    return axis * 2 + sign.astype(int)


def _font(size: int) -> ImageFont.ImageFont:
    """Pillow's bundled font (no system fonts, so output does not depend on the host)."""
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1 has no scalable default font
        return ImageFont.load_default()


def _noise_image(rng: np.random.Generator, size, cells: int, amp: float) -> np.ndarray:
    """Smooth value noise in [-amp, amp], shape (h, w), from a cells x cells grid."""
    w, h = size
    coarse = rng.uniform(-1.0, 1.0, (cells, cells)).astype(np.float32)
    img = Image.fromarray(coarse, mode="F").resize((w, h), Image.BICUBIC)
    return np.clip(np.asarray(img), -1, 1) * amp


def _add_noise(img: Image.Image, rng: np.random.Generator, amp: float = 18.0) -> Image.Image:
    """Mottle an RGB image with two octaves of seeded value noise (gives SIFT texture)."""
    a = np.asarray(img.convert("RGB"), dtype=np.float32)
    n = _noise_image(rng, img.size, 16, amp) + _noise_image(rng, img.size, 48, amp * 0.5)
    a = a + n[:, :, None]
    return Image.fromarray(np.clip(np.round(a), 0, 255).astype(np.uint8), mode="RGB")


def _textured(mesh: trimesh.Trimesh, uv: np.ndarray, image: Image.Image, name: str):
    material = SimpleMaterial(
        name=name, image=image, diffuse=[255, 255, 255, 255], ambient=[255, 255, 255, 255]
    )
    out = trimesh.Trimesh(
        _clean_vertices(mesh.vertices),
        mesh.faces,
        visual=TextureVisuals(uv=np.round(uv, 6), image=image, material=material),
        process=False,
    )
    return out


def _unmerge(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Every face gets its own three vertices (for per-face UVs / colours)."""
    v = mesh.vertices[mesh.faces].reshape(-1, 3)
    f = np.arange(len(v)).reshape(-1, 3)
    return trimesh.Trimesh(v, f, process=False)


# --------------------------------------------------------------------------------------
# box-projection texture atlas
# --------------------------------------------------------------------------------------


class BoxAtlas:
    """A 3x3 texture atlas: one square cell per face direction (rows 0-1), swatches (row 2).

    A point is mapped into the cell of a direction by projecting the model's bounding box
    onto that face as seen from outside (image right/up = the viewer's right/up; for +Y
    the front (+Z) is at the bottom of the cell, for -Y at the top).
    """

    def __init__(self, bounds, size: int = TEX, margin: int = 2):
        self.lo = np.asarray(bounds[0], float)
        self.hi = np.asarray(bounds[1], float)
        self.size = size
        self.cell = size // 3
        self.margin = margin

    def local(self, d: str, p) -> np.ndarray:
        """(s, t) in [0, 1]^2: s to the viewer's right, t up."""
        p = np.atleast_2d(np.asarray(p, float))
        q = (p - self.lo) / (self.hi - self.lo)
        x, y, z = q[:, 0], q[:, 1], q[:, 2]
        s, t = {
            "+Z": (x, y),
            "-Z": (1 - x, y),
            "+X": (1 - z, y),
            "-X": (z, y),
            "+Y": (x, 1 - z),
            "-Y": (x, z),
        }[d]
        return np.stack([s, t], axis=1)

    def cell_box(self, index: int):
        col, row = index % 3, index // 3
        x0, y0 = col * self.cell + self.margin, row * self.cell + self.margin
        span = self.cell - 2 * self.margin
        return x0, y0, span

    def st_to_px(self, d: str, st) -> np.ndarray:
        x0, y0, span = self.cell_box(DIRS.index(d))
        st = np.atleast_2d(np.asarray(st, float))
        return np.stack([x0 + st[:, 0] * span, y0 + (1 - st[:, 1]) * span], axis=1)

    def px(self, d: str, p) -> np.ndarray:
        """Pixel position (x right, y down) of 3D point(s) p in the cell of direction d."""
        return self.st_to_px(d, self.local(d, p))

    def rect(self, d: str, p0, p1):
        """Pixel rectangle [x0, y0, x1, y1] spanned by two 3D corner points."""
        a, b = self.px(d, [p0, p1])
        return [min(a[0], b[0]), min(a[1], b[1]), max(a[0], b[0]), max(a[1], b[1])]

    def cell_rect(self, index: int):
        col, row = index % 3, index // 3
        return [col * self.cell, row * self.cell, (col + 1) * self.cell - 1, (row + 1) * self.cell - 1]

    def swatch_uv(self, k: int) -> np.ndarray:
        """UV of the centre of swatch cell k (0..2, bottom row)."""
        col, row = k, 2
        cx, cy = (col + 0.5) * self.cell, (row + 0.5) * self.cell
        return np.array([cx / self.size, 1 - cy / self.size])

    def uv_for(self, mesh: trimesh.Trimesh, solid: np.ndarray | None = None):
        """Unmerge ``mesh`` and give every face box-projected UVs.

        ``solid`` optionally maps faces to a swatch index (-1 = box projection).
        Returns (unmerged mesh, uv).
        """
        flat = _unmerge(mesh)
        dirs = _direction_of(mesh.face_normals)
        uv = np.zeros((len(flat.vertices), 2))
        corners = flat.vertices.reshape(-1, 3, 3)
        for i, d in enumerate(DIRS):
            sel = np.nonzero(dirs == i)[0]
            if len(sel) == 0:
                continue
            pts = corners[sel].reshape(-1, 3)
            pix = self.st_to_px(d, np.clip(self.local(d, pts), 0, 1))
            rows = (sel[:, None] * 3 + np.arange(3)).reshape(-1)
            uv[rows, 0] = pix[:, 0] / self.size
            uv[rows, 1] = 1 - pix[:, 1] / self.size
        if solid is not None:
            for k in np.unique(solid[solid >= 0]):
                sel = np.nonzero(solid == k)[0]
                rows = (sel[:, None] * 3 + np.arange(3)).reshape(-1)
                uv[rows] = self.swatch_uv(int(k))
        return flat, uv


# --------------------------------------------------------------------------------------
# surfaces of revolution with cylindrical UVs
# --------------------------------------------------------------------------------------


def _revolve(profile, v, sections: int, phi0: float = 0.0, u_range=(0.0, 1.0)):
    """Revolve a (r, y) polyline about +Y.

    The surface normal points to the right of the walking direction of the profile drawn
    in the (r, y) half-plane with r to the right: walk bottom -> top for an outward-facing
    outer wall, axis -> edge for a bottom disk (normal -Y), edge -> axis for a top disk. ``v`` gives the texture v of each profile point. The seam is
    duplicated so u runs continuously from u_range[0] to u_range[1]. Position at u is
    (r sin phi, y, r cos phi) with phi = phi0 + 2 pi u (phi = 0 is the front, +Z).
    Returns (vertices, faces, uv) with zero-area faces removed.
    """
    profile = np.asarray(profile, float)
    v = np.asarray(v, float)
    n_p, n_u = len(profile), sections + 1
    u = np.linspace(0.0, 1.0, n_u)
    phi = phi0 + 2 * np.pi * u
    r, y = profile[:, 0][:, None], profile[:, 1][:, None]
    verts = np.stack(
        [r * np.sin(phi)[None, :], np.broadcast_to(y, (n_p, n_u)), r * np.cos(phi)[None, :]],
        axis=2,
    ).reshape(-1, 3)
    uu = u_range[0] + (u_range[1] - u_range[0]) * u
    uv = np.stack(
        [np.broadcast_to(uu[None, :], (n_p, n_u)), np.broadcast_to(v[:, None], (n_p, n_u))],
        axis=2,
    ).reshape(-1, 2)
    idx = np.arange(n_p * n_u).reshape(n_p, n_u)
    a, b = idx[:-1, :-1], idx[:-1, 1:]
    c, d = idx[1:, :-1], idx[1:, 1:]
    faces = np.concatenate(
        [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    )
    tri = verts[faces]
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    faces = faces[area > 1e-12]
    return verts, faces, uv


def _merge_parts(parts):
    """Concatenate (vertices, faces, uv) tuples."""
    vs, fs, uvs, off = [], [], [], 0
    for v, f, uv in parts:
        vs.append(v)
        fs.append(f + off)
        uvs.append(uv)
        off += len(v)
    return np.vstack(vs), np.vstack(fs), np.vstack(uvs)


# --------------------------------------------------------------------------------------
# the models
# --------------------------------------------------------------------------------------


def make_sphere():
    return _centre(trimesh.creation.icosphere(subdivisions=3, radius=0.5))


def make_cylinder():
    return _centre(_cylinder_y(0.35, 0.0, 1.2, sections=48))


def make_cone():
    m = trimesh.creation.cone(radius=0.5, height=1.2, sections=48)
    m.apply_transform(Z_TO_Y)
    return _centre(m)


def make_pyramid():
    pts = np.array(
        [[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5], [0, 0.9, 0]], float
    )
    return _centre(trimesh.convex.convex_hull(pts))


def make_box_long():
    return trimesh.creation.box(extents=(2.0, 1.0, 0.5))


def make_table():
    parts = [_box([-0.6, 0.72, -0.6], [0.6, 0.8, 0.6])]
    for sx in (-1, 1):
        for sz in (-1, 1):
            cx, cz = 0.5 * sx, 0.5 * sz
            parts.append(_box([cx - 0.04, 0.0, cz - 0.04], [cx + 0.04, 0.72, cz + 0.04]))
    return _centre(_concat(parts))


def make_l_bracket():
    """An L-shaped angle bracket with an off-centre square hole and a corner notch.

    Base plate along +X, upright plate along +Y, both 0.8 deep in Z. The hole sits off the
    z mid-plane and the notch cuts one top corner of the upright: no mirror plane at all.
    """
    t = 0.15
    parts = [
        # base plate, built around a square hole x in [0.7, 0.95], z in [0.45, 0.65]
        _box([0, 0, 0], [1.2, t, 0.45]),
        _box([0, 0, 0.65], [1.2, t, 0.8]),
        _box([0, 0, 0.45], [0.7, t, 0.65]),
        _box([0.95, 0, 0.45], [1.2, t, 0.65]),
        # upright plate with the top-back corner (z < 0.3) notched away
        _box([0, t, 0], [t, 0.75, 0.8]),
        _box([0, 0.75, 0.3], [t, 1.0, 0.8]),
        # a triangular gusset near the z = 0.8 edge only
        trimesh.convex.convex_hull(
            np.array(
                [
                    [t, t, 0.6], [0.55, t, 0.6], [t, 0.55, 0.6],
                    [t, t, 0.7], [0.55, t, 0.7], [t, 0.55, 0.7],
                ]
            )
        ),
    ]
    return _centre(_concat(parts))


def make_chair():
    """Chair facing +Z with its backrest at -Z; mirror-symmetric about x = 0.

    Saved as PLY with per-part vertex colours (plus a little seeded per-vertex noise).
    """
    rng = _rng("chair")
    leg, half = 0.045, 0.22
    parts = []  # (mesh, rgb)
    wood, dark, pale = (150, 95, 50), (90, 55, 30), (200, 160, 110)
    for sx in (-1, 1):
        # front legs
        parts.append((_box([sx * half - leg / 2, 0, half - leg], [sx * half + leg / 2, 0.44, half]), dark))
        # rear legs continue upward as the back posts
        parts.append((_box([sx * half - leg / 2, 0, -half], [sx * half + leg / 2, 1.05, -half + leg]), dark))
    # seat overhangs the legs a little so no vertices coincide
    parts.append((_box([-0.26, 0.44, -0.25], [0.26, 0.5, 0.27]), wood))
    # backrest: two slats between the posts
    for y0, y1 in ((0.66, 0.74), (0.86, 1.0)):
        parts.append((_box([-half + leg / 2, y0, -half + 0.005], [half - leg / 2, y1, -half + 0.035]), pale))
    # stretcher between the front legs (symmetric, front only: front != back)
    parts.append((_box([-half + leg / 2, 0.12, half - 0.035], [half - leg / 2, 0.16, half - 0.01]), dark))
    mesh = _concat([m for m, _ in parts])
    colours = np.vstack([np.tile(np.r_[c, 255], (len(m.vertices), 1)) for m, c in parts])
    jitter = rng.integers(-25, 26, size=(len(colours), 1))
    colours[:, :3] = np.clip(colours[:, :3] + jitter, 0, 255)
    mesh = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=colours.astype(np.uint8), process=False)
    return _centre(mesh)


def make_torus():
    """A flat ring (axis +Y) with periodic hue / stripe vertex colours and seeded noise."""
    rng = _rng("torus")
    m = trimesh.creation.torus(major_radius=0.7, minor_radius=0.22, major_sections=64, minor_sections=24)
    m.apply_transform(Z_TO_Y)
    v = m.vertices
    major = np.arctan2(v[:, 0], v[:, 2])
    ring = np.hypot(v[:, 0], v[:, 2]) - 0.7
    minor = np.arctan2(v[:, 1], ring)
    hue = (major / (2 * np.pi)) % 1.0
    # hue wheel -> rgb (periodic in the major angle)
    k = (np.array([5, 3, 1])[None, :] + hue[:, None] * 6) % 6
    rgb = 1 - np.clip(np.minimum(k, 4 - k), 0, 1)
    stripes = 0.65 + 0.35 * (np.sin(6 * minor + 3 * major) > 0)
    checker = 0.8 + 0.2 * (np.sin(12 * major) > 0)
    rgb = rgb * 0.8 + 0.2
    rgb = rgb * (stripes * checker)[:, None] * 255 + rng.integers(-20, 21, size=(len(v), 1))
    colours = np.c_[np.clip(np.round(rgb), 0, 255), np.full(len(v), 255)].astype(np.uint8)
    mesh = trimesh.Trimesh(_clean_vertices(m.vertices), m.faces, vertex_colors=colours, process=False)
    return _centre(mesh)


def make_marked_cube():
    """Unit cube whose six faces carry distinct pure face colours (MARKED_CUBE_COLOURS).

    Face colours (not vertex colours) so that trimesh's default vertex merge on load
    (``process=True``) cannot blend them; and every triangle has its own three vertices so
    that a conversion to vertex colours (e.g. trimesh's glTF export of a mesh loaded with
    ``process=False``) cannot blend them either.
    """
    m = _unmerge(trimesh.creation.box(extents=(1.0, 1.0, 1.0)))
    dirs = _direction_of(m.face_normals)
    colours = np.array([[*MARKED_CUBE_COLOURS[DIRS[i]], 255] for i in dirs], np.uint8)
    return trimesh.Trimesh(m.vertices, m.faces, face_colors=colours, process=False)


def make_arrow():
    """An arrow along +Z with a tail fin (+Y) and a smaller side flag (+X): no symmetry.

    Vertex coloured per part (grey shaft, red head, blue fin, yellow flag).
    """
    rng = _rng("arrow")
    shaft = trimesh.creation.cylinder(radius=0.05, height=1.3, sections=24)
    shaft.apply_translation([0, 0, -0.15])  # z in [-0.8, 0.5]
    head = trimesh.creation.cone(radius=0.15, height=0.4, sections=24)
    head.apply_translation([0, 0, 0.5])  # z in [0.5, 0.9]
    fin = _box([-0.012, 0.05, -0.8], [0.012, 0.32, -0.45])
    flag = _box([0.05, -0.01, -0.72], [0.2, 0.01, -0.58])
    parts = [(shaft, (180, 180, 180)), (head, (220, 30, 30)), (fin, (30, 60, 220)), (flag, (240, 200, 20))]
    mesh = _concat([m for m, _ in parts])
    colours = np.vstack([np.tile(np.r_[c, 255], (len(m.vertices), 1)) for m, c in parts])
    colours[:, :3] = np.clip(colours[:, :3] + rng.integers(-20, 21, size=(len(colours), 1)), 0, 255)
    mesh = trimesh.Trimesh(
        _clean_vertices(mesh.vertices), mesh.faces, vertex_colors=colours.astype(np.uint8), process=False
    )
    return _centre(mesh)


def _dice_pips(n: int):
    c, lo, hi = 0.5, 0.25, 0.75
    layout = {
        1: [(c, c)],
        2: [(lo, hi), (hi, lo)],
        3: [(lo, hi), (c, c), (hi, lo)],
        4: [(lo, lo), (lo, hi), (hi, lo), (hi, hi)],
        5: [(lo, lo), (lo, hi), (c, c), (hi, lo), (hi, hi)],
        6: [(lo, lo), (lo, c), (lo, hi), (hi, lo), (hi, c), (hi, hi)],
    }
    return layout[n]


def make_cube_dice():
    """A dice: pips 1..6 (opposite faces sum to 7) on differently tinted, mottled faces."""
    rng = _rng("cube_dice")
    cube = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    atlas = BoxAtlas(cube.bounds)
    img = Image.new("RGB", (TEX, TEX), (235, 235, 225))
    draw = ImageDraw.Draw(img)
    pips = {"+Z": 1, "-Z": 6, "+Y": 2, "-Y": 5, "+X": 3, "-X": 4}
    tints = {
        "+Z": (240, 230, 200), "-Z": (200, 225, 240), "+Y": (235, 205, 205),
        "-Y": (210, 235, 205), "+X": (240, 240, 190), "-X": (225, 205, 235),
    }
    pip_colour = {1: (200, 20, 20), 2: (20, 20, 20), 3: (20, 20, 120), 4: (200, 20, 20),
                  5: (20, 90, 20), 6: (20, 20, 20)}
    font = _font(11)
    for d in DIRS:
        draw.rectangle(atlas.cell_rect(DIRS.index(d)), fill=tints[d])
        n = pips[d]
        radius = 0.11 if n > 1 else 0.16
        for s, t in _dice_pips(n):
            (x0, y0), (x1, y1) = atlas.st_to_px(d, [(s - radius, t + radius), (s + radius, t - radius)])
            draw.ellipse([x0, y0, x1, y1], fill=pip_colour[n], outline=(0, 0, 0))
        # a small engraved label in one corner and a thin frame break the pip symmetry
        (lx, ly), = atlas.st_to_px(d, [(0.06, 0.97)])
        draw.text((lx, ly), d, fill=(60, 60, 60), font=font)
        (fx0, fy0), (fx1, fy1) = atlas.st_to_px(d, [(0.03, 0.97), (0.97, 0.03)])
        draw.rectangle([fx0, fy0, fx1, fy1], outline=(120, 110, 100))
    img = _add_noise(img, rng, 14.0)
    flat, uv = atlas.uv_for(cube)
    return _textured(flat, uv, img, "cube_dice")


def make_car():
    """A car-like body: chassis box, cabin set toward the rear, four wheels.

    Front is +Z (hood longer than the trunk, headlights and grille on the texture),
    mirror-symmetric about x = 0. Box-projected texture atlas with windows, doors,
    lights, number plates and seeded paint mottling.
    """
    rng = _rng("car")
    body = _box([-0.9, 0.3, -2.0], [0.9, 1.0, 2.0])
    cabin = _box([-0.75, 1.0, -1.4], [0.75, 1.55, 0.45])
    spoiler = _box([-0.8, 1.0, -1.95], [0.8, 1.1, -1.75])
    wheels = []
    for sx in (-1, 1):
        for z in (-1.3, 1.3):
            w = trimesh.creation.cylinder(radius=0.35, height=0.3, sections=24)
            w.apply_transform(_rotate(90, [0, 1, 0]))
            w.apply_translation([sx * 0.8, 0.35, z])
            wheels.append(w)
    chassis = _concat([body, cabin, spoiler])
    mesh = _concat([chassis, *wheels])
    # wheel treads -> black swatch 0, wheel discs and the body -> box projection
    solid = np.full(len(mesh.faces), -1)
    wheel_faces = np.arange(len(chassis.faces), len(mesh.faces))
    side = np.abs(mesh.face_normals[wheel_faces, 0]) > 0.9
    solid[wheel_faces[~side]] = 0
    atlas = BoxAtlas(mesh.bounds)

    paint = (190, 30, 40)
    img = Image.new("RGB", (TEX, TEX), paint)
    draw = ImageDraw.Draw(img)
    glass, chrome, black, white = (70, 110, 150), (200, 200, 205), (25, 25, 25), (245, 245, 240)
    font = _font(9)
    # swatches: 0 tyre black, 1 chrome, 2 glass
    for k, c in enumerate((black, chrome, glass)):
        draw.rectangle(atlas.cell_rect(6 + k), fill=c)
    # underside
    draw.rectangle(atlas.cell_rect(DIRS.index("-Y")), fill=(50, 50, 50))
    # front (+Z): windscreen on the cabin, grille, headlights, plate
    d = "+Z"
    draw.rectangle(atlas.rect(d, [-0.68, 1.05, 0], [0.68, 1.5, 0]), fill=glass)
    draw.rectangle(atlas.rect(d, [-0.45, 0.4, 0], [0.45, 0.7, 0]), fill=black)
    for gy in np.linspace(0.45, 0.65, 4):
        draw.line([tuple(p) for p in atlas.px(d, [[-0.42, gy, 0], [0.42, gy, 0]])], fill=chrome)
    for sx in (-1, 1):
        draw.ellipse(atlas.rect(d, [sx * 0.55 - 0.18, 0.72, 0], [sx * 0.55 + 0.18, 0.92, 0]), fill=(255, 250, 200), outline=black)
    draw.rectangle(atlas.rect(d, [-0.3, 0.78, 0], [0.3, 0.95, 0]), fill=white, outline=black)
    draw.text(tuple(atlas.px(d, [0, 0.865, 0])[0]), "VDB 1", fill=black, font=font, anchor="mm")
    # back (-Z): rear window, tail lights, plate
    d = "-Z"
    draw.rectangle(atlas.rect(d, [-0.65, 1.12, 0], [0.65, 1.48, 0]), fill=glass)
    for sx in (-1, 1):
        draw.rectangle(atlas.rect(d, [sx * 0.55 - 0.2, 0.75, 0], [sx * 0.55 + 0.2, 0.9, 0]), fill=(255, 120, 0), outline=black)
    draw.rectangle(atlas.rect(d, [-0.3, 0.45, 0], [0.3, 0.62, 0]), fill=white, outline=black)
    draw.text(tuple(atlas.px(d, [0, 0.535, 0])[0]), "42-XY", fill=black, font=font, anchor="mm")
    # sides: windows on the cabin, door lines, handles, a stripe, wheels with hubcaps
    for d in ("+X", "-X"):
        draw.rectangle(atlas.rect(d, [0, 0.62, -2.0], [0, 0.68, 2.0]), fill=white)
        draw.polygon([tuple(p) for p in atlas.px(d, [[0, 1.08, 0.4], [0, 1.48, 0.0], [0, 1.48, -0.45], [0, 1.08, -0.45]])], fill=glass)
        draw.polygon([tuple(p) for p in atlas.px(d, [[0, 1.08, -0.55], [0, 1.48, -0.55], [0, 1.48, -1.3], [0, 1.08, -1.3]])], fill=glass)
        for z0, z1 in ((-0.5, 0.45), (-1.4, -0.5)):
            draw.rectangle(atlas.rect(d, [0, 0.35, z0], [0, 1.0, z1]), outline=(90, 10, 15))
            draw.rectangle(atlas.rect(d, [0, 0.85, z1 - 0.25], [0, 0.9, z1 - 0.08]), fill=chrome)
        for z in (-1.3, 1.3):
            draw.ellipse(atlas.rect(d, [0, 0.0, z - 0.35], [0, 0.7, z + 0.35]), fill=black)
            draw.ellipse(atlas.rect(d, [0, 0.17, z - 0.18], [0, 0.53, z + 0.18]), fill=chrome, outline=(90, 90, 90))
            for ang in range(0, 360, 72):
                a = np.radians(ang + (30 if d == "+X" else 0))
                p0 = [0, 0.35, z]
                p1 = [0, 0.35 + 0.16 * np.sin(a), z + 0.16 * np.cos(a)]
                draw.line([tuple(p) for p in atlas.px(d, [p0, p1])], fill=(60, 60, 60), width=2)
        draw.text(tuple(atlas.px(d, [0, 0.48, 0.0])[0]), "viewdb", fill=white, font=font, anchor="mm")
    # top (+Y): roof with a sunroof, hood bulge stripes
    d = "+Y"
    draw.rectangle(atlas.rect(d, [-0.4, 0, -0.9], [0.4, 0, 0.1]), fill=glass)
    for sx in (-0.15, 0.15):
        draw.rectangle(atlas.rect(d, [sx - 0.06, 0, 0.6], [sx + 0.06, 0, 1.95]), fill=white)
    img = _add_noise(img, rng, 16.0)
    flat, uv = atlas.uv_for(mesh, solid)
    out = _textured(flat, uv, img, "car")
    return _centre(out)


def make_mug():
    """A mug (open cup) with a handle on +X in the z = 0 plane; wrap-around texture.

    Only the z = 0 plane is a mirror plane of the shape. Seam of the wrap is at the handle.
    """
    rng = _rng("mug")
    R, t, H, tb = 0.42, 0.05, 1.0, 0.06
    n = 64
    phi0 = np.pi / 2  # u = 0 at +X (the handle); the front (+Z) is at u = 0.75
    # texture layout: rows with v in [0.3, 1] = outer wall, v in [0, 0.25] = plain glaze
    glaze_v = 0.12
    parts = []
    # outer wall, bottom -> top (outward normals)
    parts.append(_revolve([[R, 0], [R, H]], [0.3, 1.0], n, phi0))
    # rim, outer -> inner, then inner wall top -> bottom, then inner bottom towards the axis
    parts.append(_revolve([[R, H], [R - t, H]], [glaze_v, glaze_v], n, phi0))
    parts.append(_revolve([[R - t, H], [R - t, tb]], [glaze_v, glaze_v], n, phi0))
    parts.append(_revolve([[R - t, tb], [0, tb]], [glaze_v, glaze_v], n, phi0))
    # outside bottom, axis -> edge (normal -Y)
    parts.append(_revolve([[0, 0], [R, 0]], [glaze_v, glaze_v], n, phi0))
    # handle: a tube along an arc in the z = 0 plane, ends buried in the wall
    a, rt = 0.28, 0.06
    psi = np.radians(np.linspace(-105, 105, 25))
    theta = np.linspace(0, 2 * np.pi, 17)
    centre = np.array([R, H / 2, 0.0])
    radial = np.stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)], 1)
    spine = centre + a * radial
    ring = (
        spine[:, None, :]
        + rt * np.cos(theta)[None, :, None] * radial[:, None, :]
        + rt * np.sin(theta)[None, :, None] * np.array([0, 0, 1.0])[None, None, :]
    ).reshape(-1, 3)
    m_h, n_h = len(psi), len(theta)
    idx = np.arange(m_h * n_h).reshape(m_h, n_h)
    q0, q1, q2, q3 = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    hf = np.concatenate([np.stack([q0, q2, q3], -1).reshape(-1, 3), np.stack([q0, q3, q1], -1).reshape(-1, 3)])
    huv = np.tile([0.5, glaze_v], (len(ring), 1))
    parts.append((ring, hf, huv))
    v, f, uv = _merge_parts(parts)
    mesh = trimesh.Trimesh(v, f, process=False)
    # make the handle's winding outward-facing whatever the parametrisation gave
    h0 = len(v) - len(ring)
    hsel = np.nonzero(f.min(axis=1) >= h0)[0]
    tri_c = mesh.triangles_center[hsel]
    spine_pt = centre + a * np.c_[(tri_c - centre)[:, :2] / np.linalg.norm((tri_c - centre)[:, :2], axis=1)[:, None], np.zeros(len(hsel))]
    if np.mean(np.einsum("ij,ij->i", mesh.face_normals[hsel], tri_c - spine_pt)) < 0:
        f[hsel] = f[hsel][:, ::-1]
    mesh = trimesh.Trimesh(v, f, process=False)

    W, Hh = TEX, TEX // 2
    img = Image.new("RGB", (W, Hh), (240, 235, 220))
    draw = ImageDraw.Draw(img)

    def vpx(vv):  # texture v -> pixel row
        return (1 - vv) * Hh

    top, bottom = vpx(1.0), vpx(0.3)
    # glaze area (v < 0.25) stays plain cream; decorate the outer wall band
    draw.rectangle([0, top, W, top + 6], fill=(30, 60, 140))
    draw.rectangle([0, bottom - 6, W, bottom], fill=(30, 60, 140))
    font_big, font_small = _font(22), _font(10)
    # front (u = 0.75): logo text and a sun
    cx = 0.75 * W
    draw.text((cx - 38, top + 14), "viewdb", fill=(180, 30, 30), font=font_big)
    draw.ellipse([cx - 14, top + 44, cx + 14, top + 72], fill=(250, 190, 30), outline=(120, 60, 0))
    for k in range(10):
        ang = 2 * np.pi * k / 10
        draw.line([(cx + 17 * np.cos(ang), top + 58 + 17 * np.sin(ang)), (cx + 24 * np.cos(ang), top + 58 + 24 * np.sin(ang))], fill=(200, 120, 0), width=2)
    # back (u = 0.25): a checker badge and small text
    bx = 0.25 * W
    for i in range(4):
        for j in range(4):
            if (i + j) % 2 == 0:
                draw.rectangle([bx - 20 + 10 * i, top + 18 + 10 * j, bx - 10 + 10 * i, top + 28 + 10 * j], fill=(20, 120, 60))
    draw.text((bx - 22, top + 62), "SIFT me", fill=(20, 20, 20), font=font_small)
    # sides: scattered dots, triangles (seeded)
    for _ in range(30):
        u = rng.uniform(0.05, 0.95)
        if abs(u - 0.75) < 0.12 or abs(u - 0.25) < 0.1:
            continue
        x, y = u * W, rng.uniform(top + 12, bottom - 14)
        s = rng.uniform(3, 7)
        col = tuple(int(c) for c in rng.integers(30, 220, 3))
        if rng.random() < 0.5:
            draw.ellipse([x - s, y - s, x + s, y + s], fill=col)
        else:
            draw.polygon([(x, y - s), (x + s, y + s), (x - s, y + s)], fill=col)
    img = _add_noise(img, rng, 10.0)
    return _centre(_textured(mesh, uv, img, "mug"))


def make_bottle():
    """A revolved bottle (axis +Y) with a paper label; seam at the back (-Z)."""
    rng = _rng("bottle")
    n = 48
    phi0 = np.pi  # u = 0 at -Z (back); the front (+Z) is at u = 0.5
    rb, rn = 0.32, 0.11
    # side profile bottom -> top: body, shoulder, neck, lip
    prof = [[rb - 0.03, 0.0], [rb, 0.03], [rb, 0.65]]
    for s in np.linspace(0, 1, 9)[1:]:
        w = 0.5 - 0.5 * np.cos(np.pi * s)
        prof.append([rb + (rn - rb) * w, 0.65 + 0.3 * s])
    prof += [[rn, 1.2], [rn + 0.025, 1.22], [rn + 0.025, 1.27], [rn, 1.29]]
    prof = np.array(prof)
    # texture v: the label band y in [0.12, 0.58] maps to v in [0.25, 1]; elsewhere glass
    v = np.clip(0.25 + 0.75 * (prof[:, 1] - 0.12) / 0.46, 0.0, 1.0)
    v = np.where((prof[:, 1] < 0.12) | (prof[:, 1] > 0.58), 0.1, v)
    # insert exact label edges so the glass / label border is crisp
    side = []
    side_v = []
    for i, (p, vv) in enumerate(zip(prof, v, strict=False)):
        side.append(p)
        side_v.append(vv)
        if i + 1 < len(prof):
            for edge, (v_lo, v_hi) in ((0.12, (0.1, 0.25)), (0.58, (1.0, 0.1))):
                if p[1] < edge < prof[i + 1][1]:
                    r = p[0] + (prof[i + 1][0] - p[0]) * (edge - p[1]) / (prof[i + 1][1] - p[1])
                    side += [[r, edge], [r, edge]]
                    side_v += [v_lo, v_hi]
    side = np.array(side)
    side_v = np.array(side_v)
    # split at the duplicated points so the label edges get their own rows
    parts = []
    start = 0
    for i in range(1, len(side)):
        if np.allclose(side[i], side[i - 1]):
            parts.append(_revolve(side[start:i], side_v[start:i], n, phi0))
            start = i
    parts.append(_revolve(side[start:], side_v[start:], n, phi0))
    parts.append(_revolve([[0, 0], [rb - 0.03, 0]], [0.1, 0.1], n, phi0))  # base
    parts.append(_revolve([[rn, 1.29], [0, 1.29]], [0.05, 0.05], n, phi0))  # cap top
    v_, f_, uv_ = _merge_parts(parts)
    mesh = trimesh.Trimesh(v_, f_, process=False)

    W, H = TEX, TEX // 2
    img = Image.new("RGB", (W, H), (40, 120, 70))  # green glass
    draw = ImageDraw.Draw(img)
    draw.rectangle([0, int(0.93 * H), W, H], fill=(200, 170, 40))  # cap colour (v < 0.07)
    top, bottom = 0, (1 - 0.25) * H  # label rows
    draw.rectangle([0, top, W, bottom], fill=(245, 240, 225))
    draw.rectangle([0, top, W, top + 4], fill=(160, 20, 30))
    draw.rectangle([0, bottom - 4, W, bottom], fill=(160, 20, 30))
    font_big, font_small = _font(20), _font(9)
    cx = 0.5 * W  # front
    draw.text((cx - 40, top + 8), "VIEWDB", fill=(160, 20, 30), font=font_big)
    draw.text((cx - 30, top + 34), "sample no. 11", fill=(40, 40, 40), font=font_small)
    draw.regular_polygon((cx, top + 66, 16), 5, rotation=18, fill=(30, 70, 160))
    # back: barcode and ingredients-like text lines (u around 0 / 1 -> wrap over the seam)
    bars = rng.integers(1, 4, 40)
    x = 0.0
    for i, wdt in enumerate(bars):
        if i % 2 == 0:
            draw.rectangle([x, top + 14, x + wdt - 1, top + 50], fill=(0, 0, 0))
        x += wdt
    for k in range(4):
        draw.text((W - 70, top + 12 + 12 * k), f"lot {rng.integers(1000, 9999)}", fill=(60, 60, 60), font=font_small)
    img = _add_noise(img, rng, 10.0)
    return _centre(_textured(mesh, uv_, img, "bottle"))


#: name -> (builder, file extension). Order is the README order.
MODELS = {
    "sphere": (make_sphere, "stl"),
    "cylinder": (make_cylinder, "off"),
    "cone": (make_cone, "off"),
    "bottle": (make_bottle, "obj"),
    "torus": (make_torus, "ply"),
    "cube_dice": (make_cube_dice, "obj"),
    "marked_cube": (make_marked_cube, "ply"),
    "box_long": (make_box_long, "stl"),
    "pyramid": (make_pyramid, "off"),
    "table": (make_table, "off"),
    "car": (make_car, "glb"),
    "chair": (make_chair, "ply"),
    "mug": (make_mug, "glb"),
    "l_bracket": (make_l_bracket, "stl"),
    "arrow": (make_arrow, "glb"),
}


# --------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------


def _png_bytes(image: Image.Image) -> bytes:
    import io

    buf = io.BytesIO()
    image.save(buf, format="PNG", optimize=True)
    return buf.getvalue()


def _write(name: str, mesh: trimesh.Trimesh, ext: str, out: Path) -> list[Path]:
    written = []
    if ext == "obj":
        text, extra = trimesh.exchange.obj.export_obj(
            mesh, include_normals=False, return_texture=True, write_texture=False, digits=6,
            mtl_name=f"{name}.mtl", header="viewdb sample model (sample_models/make_samples.py)",
        )
        (out / f"{name}.obj").write_text(text)
        written.append(out / f"{name}.obj")
        for file_name, data in sorted(extra.items()):
            if file_name.lower().endswith(".png"):
                # re-encode with our own settings (stable, optimised)
                data = _png_bytes(mesh.visual.material.image)
            elif file_name.lower().endswith(".mtl") and not data.endswith(b"\n"):
                data += b"\n"
            (out / file_name).write_bytes(data)
            written.append(out / file_name)
    elif ext == "glb":
        scene = trimesh.Scene()
        scene.add_geometry(mesh, geom_name=name, node_name=name)
        (out / f"{name}.glb").write_bytes(scene.export(file_type="glb"))
        written.append(out / f"{name}.glb")
    elif ext == "ply":
        (out / f"{name}.ply").write_bytes(mesh.export(file_type="ply", encoding="binary"))
        written.append(out / f"{name}.ply")
    elif ext == "stl":
        (out / f"{name}.stl").write_bytes(mesh.export(file_type="stl"))
        written.append(out / f"{name}.stl")
    elif ext == "off":
        m = trimesh.Trimesh(_clean_vertices(mesh.vertices), mesh.faces, process=False)
        (out / f"{name}.off").write_text(trimesh.exchange.off.export_off(m, digits=6))
        written.append(out / f"{name}.off")
    else:  # pragma: no cover
        raise ValueError(ext)
    return written


def main(out_dir: Path | None = None) -> list[Path]:
    """Build every sample model into ``out_dir`` (default: this folder); return the paths."""
    out = Path(out_dir) if out_dir is not None else HERE
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for name, (builder, ext) in MODELS.items():
        written += _write(name, builder(), ext, out)
    return written


if __name__ == "__main__":
    paths = main(Path(sys.argv[1]) if len(sys.argv) > 1 else None)
    for p in paths:
        print(f"{p.stat().st_size:8d}  {p}")
