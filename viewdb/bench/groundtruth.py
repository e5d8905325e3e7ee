"""Real photos with official 6-D ground truth: frames, visible masks and BOP pose errors.

The photo sets of ``../shared/real`` that have poses (``lmo_dev``, ``ycb_video_2frames``)
describe each frame in a ``gt.json``: the intrinsics ``K`` and, per object, its mesh, ``R``
and ``t`` with ``x_cam = R · x_obj + t`` (OpenCV camera, the mesh's units). This module
reads them (:func:`read_frames`), renders each object's mask and visible part from its
pose (:func:`visible_masks`: depth-tested against the frame's other annotated objects;
clutter that is not annotated is not modelled, so a modelled visible mask can be larger
than the true one) and scores a pose the way the BOP benchmark does:

* **ADD** (asymmetric objects): the mean distance between the mesh's points moved by the
  estimated and by the true pose; **ADD-S** (symmetric ones): the mean distance from
  each point moved by the estimate to the nearest point moved by the truth. A pose is
  right when it is within ``0.1 ×`` the mesh's diameter (the largest distance between
  two of its vertices).
* **Symmetry-aware rotation error** (:func:`pose_errors`): the smallest angle between the
  estimate and the truth over the rotations that map the mesh onto itself
  (:func:`symmetries`), and the translation error of the bounding-box centre.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..camera import GL_TO_CV
from ..catalogue.gl import pyrender_module
from ..catalogue.render import render_depth
from ..pose.frames import rotation_angle

__all__ = [
    "TWINS", "Frame", "Instance", "MeshModel", "Symmetry", "add_error", "load_model", "mask_iou",
    "pose_errors", "read_frames", "symmetries", "visible_masks",
]

#: The catalogue's other copies of the real objects (the same scan from another source,
#: in ``../shared/models``): no silhouette tells such twins apart.
TWINS = {
    "lm_obj_000001_ape": ("linemod_ape",),
    "002_master_chef_can": ("ycb_master_chef_can",),
    "004_sugar_box": ("ocrtoc_sugar_box",),
    "009_gelatin_box": ("ocrtoc_gelatin_box",),
    "010_potted_meat_can": ("ycb_potted_meat_can",),
    "019_pitcher_base": ("ocrtoc_pitcher",),
    "025_mug": ("ocrtoc_mug",),
    "061_foam_brick": ("ycb_foam_brick",),
}


@dataclass(frozen=True)
class Instance:
    """One annotated object of a frame."""

    name: str
    mesh: Path
    R: NDArray[np.float64] = field(repr=False)
    t: NDArray[np.float64] = field(repr=False)
    #: The BOP visible fraction (None where the set does not give it).
    visibility: float | None
    #: The box of its visible part ``(x1, y1, x2, y2)`` in pixels, end exclusive.
    box: tuple[int, int, int, int]


@dataclass(frozen=True)
class Frame:
    """One photo with its intrinsics and annotated objects."""

    name: str
    photo: Path
    K: NDArray[np.float64] = field(repr=False)
    width: int
    height: int
    instances: tuple[Instance, ...]
    #: Its depth image, aligned with the photo, or None.
    depth: Path | None = None
    #: One unit of ``depth`` in the meshes' units (``gt.json``'s ``depth_scale`` is units
    #: per metre, its meshes in metres).
    depth_scale: float | None = None

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        return float(self.K[0, 0]), float(self.K[1, 1]), float(self.K[0, 2]), float(self.K[1, 2])


def _xywh(box: Any) -> tuple[int, int, int, int]:
    x, y, w, h = (int(v) for v in box)
    return x, y, x + w, y + h


def read_frames(folder: Path) -> list[Frame]:
    """The frames of a photo set's ``gt.json`` (``lmo_dev``'s layout; ``ycb_video_2frames``'
    boxes come from its ``*-box.txt`` files)."""
    data = json.loads((folder / "gt.json").read_text())
    frames = []
    for name, entry in sorted(data["frames"].items()):
        boxes = _box_file(folder, name)
        instances = []
        for obj in entry["objects"]:
            box = _xywh(obj["bbox_visib_xywh"]) if "bbox_visib_xywh" in obj else boxes[obj["name"]]
            r, t = np.asarray(obj["R"], np.float64), np.asarray(obj["t"], np.float64).reshape(3)
            instances.append(Instance(obj["name"], folder / obj["mesh"], r, t, obj.get("visib_fract"), box))
        photo = folder / entry.get("color", f"{name}-color.png")
        height, width = entry.get("height"), entry.get("width")
        if height is None or width is None:
            image = cv2.imread(str(photo), cv2.IMREAD_UNCHANGED)
            assert image is not None, f"cannot read {photo}"
            height, width = image.shape[:2]
        depth = folder / entry["depth"] if "depth" in entry else None
        frames.append(Frame(name, photo, np.asarray(entry["K"], np.float64), int(width), int(height),
                            tuple(instances), depth, 1.0 / float(entry["depth_scale"]) if depth else None))
    return frames


def _box_file(folder: Path, frame: str) -> dict[str, tuple[int, int, int, int]]:
    path = folder / f"{frame}-box.txt"
    if not path.exists():
        return {}
    out = {}
    for line in path.read_text().split("\n"):
        parts = line.split()
        if len(parts) == 5:
            x1, y1, x2, y2 = (float(v) for v in parts[1:])
            out[parts[0]] = (math.floor(x1), math.floor(y1), math.ceil(x2), math.ceil(y2))
    return out


# ---------------------------------------------------------------------- meshes
@dataclass(frozen=True)
class Symmetry:
    """The rotations (about ``centre``) that map a mesh onto itself: a finite ``group``, or
    every turn about ``axis`` (and a half turn across it when ``flip``)."""

    centre: NDArray[np.float64]
    group: tuple[NDArray[np.float64], ...]
    axis: NDArray[np.float64] | None = None
    flip: bool = False

    @property
    def symmetric(self) -> bool:
        return self.axis is not None or len(self.group) > 1

    def describe(self) -> str:
        if self.axis is not None:
            return "continuous axis" + (" + flip" if self.flip else "")
        return "none" if len(self.group) == 1 else f"{len(self.group)} rotations"


@dataclass(frozen=True)
class MeshModel:
    """A mesh in its own units: its vertices, points sampled on it (for ADD), its diameter
    and its symmetries."""

    vertices: NDArray[np.float64] = field(repr=False)
    faces: NDArray[np.int64] = field(repr=False)
    points: NDArray[np.float64] = field(repr=False)
    diameter: float
    symmetry: Symmetry


@cache
def load_model(path: Path, samples: int = 2000) -> MeshModel:
    """A mesh's :class:`MeshModel` (read once per process)."""
    mesh = trimesh.load(str(path), force="mesh", process=False)
    assert isinstance(mesh, trimesh.Trimesh)  # what force="mesh" returns
    vertices = np.asarray(mesh.vertices, np.float64)
    hull = np.asarray(trimesh.convex.convex_hull(vertices).vertices) if len(vertices) > 3 else vertices
    diameter = float(max(np.linalg.norm(hull - p, axis=1).max() for p in hull))
    points, _ = trimesh.sample.sample_surface(mesh, samples, seed=1)
    return MeshModel(vertices, np.asarray(mesh.faces, np.int64), np.asarray(points, np.float64), diameter,
                     symmetries(mesh))


def _turn(axis: NDArray[np.float64], degrees: float) -> NDArray[np.float64]:
    r, _ = cv2.Rodrigues(np.asarray(axis, np.float64) * math.radians(degrees))
    return np.asarray(r, np.float64)


def symmetries(mesh: trimesh.Trimesh, tolerance: float = 0.02, samples: int = 10000) -> Symmetry:
    """The rotations about the bounding-box centre and principal axes that map the mesh's
    surface onto itself within ``tolerance`` × its diameter: the mean nearest-neighbour
    distance between ``samples`` surface points and their turned copy, both ways (the
    samples' own spacing is about 1 %). Every turn about an axis (a cylinder): that axis;
    else the finite group found, closed under composition."""
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2.0
    pts, _ = trimesh.sample.sample_surface(mesh, samples, seed=0)
    x = np.asarray(pts) - centre
    diameter = 2.0 * float(np.linalg.norm(x, axis=1).max())
    tree = cKDTree(x)
    _, vecs = np.linalg.eigh(np.cov(x.T))
    axes = [vecs[:, i] for i in range(3)]

    def fits(r: NDArray[np.float64]) -> bool:
        y = x @ r.T
        d1, _ = tree.query(y)
        d2, _ = cKDTree(y).query(x)
        return bool((d1.mean() + d2.mean()) / 2.0 < tolerance * diameter)

    for a in axes:
        if all(fits(_turn(a, deg)) for deg in (20, 45, 90, 135, 180, 250, 310)):
            flip = any(fits(_turn(b, 180.0)) for b in axes if abs(float(b @ a)) < 0.5)
            return Symmetry(centre, (np.eye(3),), a, flip)
    group = [np.eye(3)]
    for a in axes:
        for deg in (90.0, 120.0, 180.0):
            r = _turn(a, deg)
            if fits(r):
                group.append(r)
    closed = list(group)
    for _ in range(2):
        for p in list(closed):
            for q in list(closed):
                c = p @ q
                if all(rotation_angle(c, e) > 1.0 for e in closed):
                    closed.append(c)
    return Symmetry(centre, tuple(closed), None, False)


def pose_errors(sym: Symmetry, r_est: NDArray[np.float64], t_est: NDArray[np.float64],
                r_gt: NDArray[np.float64], t_gt: NDArray[np.float64], units_per_mm: float = 1e-3
                ) -> dict[str, float]:
    """Rotation error (degrees; symmetry-aware and plain) and translation error (mm, of
    the bounding-box centre, and of the origin: ``..._plain``); ``units_per_mm``: the
    mesh's units per millimetre (metres: 0.001)."""
    if sym.axis is not None:
        c = float(np.clip((r_est @ sym.axis) @ (r_gt @ sym.axis), -1.0, 1.0))
        angle = math.degrees(math.acos(c))
        rot = min(angle, 180.0 - angle) if sym.flip else angle
    else:
        rot = min(rotation_angle(r_est @ s, r_gt) for s in sym.group)
    centre_est = r_est @ sym.centre + t_est
    centre_gt = r_gt @ sym.centre + t_gt
    return {"rotation_deg": rot, "rotation_plain_deg": rotation_angle(r_est, r_gt),
            "translation_mm": float(np.linalg.norm(centre_est - centre_gt)) / units_per_mm,
            "translation_plain_mm": float(np.linalg.norm(t_est - t_gt)) / units_per_mm}


def add_error(model: MeshModel, r_est: NDArray[np.float64], t_est: NDArray[np.float64],
              r_gt: NDArray[np.float64], t_gt: NDArray[np.float64], symmetric: bool) -> float:
    """ADD (``symmetric`` False) or ADD-S of an estimated pose, in the mesh's units."""
    est = model.points @ np.asarray(r_est).T + np.asarray(t_est).reshape(3)
    gt = model.points @ np.asarray(r_gt).T + np.asarray(t_gt).reshape(3)
    if not symmetric:
        return float(np.linalg.norm(est - gt, axis=1).mean())
    distances, _ = cKDTree(gt).query(est)
    return float(distances.mean())


# ---------------------------------------------------------------------- masks
def visible_masks(frame: Frame) -> list[tuple[NDArray[np.bool_], NDArray[np.bool_]]]:
    """Per instance of ``frame``: its whole mask and its visible part (not behind another
    annotated object's surface by more than a millimetre, and within the annotated box of
    its visible part, which accounts for the clutter that is not annotated), rendered
    from the poses through viewdb's own offscreen renderer (a square as wide as the
    photo's longer side, cropped to the photo)."""
    pyrender = pyrender_module()
    fx, fy, cx, cy = frame.intrinsics
    side = max(frame.width, frame.height)
    depths = []
    for inst in frame.instances:
        model = load_model(inst.mesh)
        scene = pyrender.Scene()
        pose = np.eye(4)
        pose[:3, :3] = GL_TO_CV @ inst.R
        pose[:3, 3] = GL_TO_CV @ inst.t
        scene.add(pyrender.Mesh.from_trimesh(trimesh.Trimesh(model.vertices, model.faces, process=False)),
                  pose=pose)
        # the principal point as given: the masks then span BOP's boxes to the pixel
        camera = pyrender.IntrinsicsCamera(fx, fy, cx, cy, znear=0.01, zfar=100.0)
        scene.add(camera, pose=np.eye(4))
        rendered = render_depth(scene, side, inst.name)
        depths.append(np.asarray(rendered[:frame.height, :frame.width], np.float64))
    stack = np.stack([np.where(d > 0, d, np.inf) for d in depths])
    nearest = stack.min(axis=0)
    out = []
    for inst, depth in zip(frame.instances, depths, strict=True):
        x1, y1, x2, y2 = inst.box
        in_box = np.zeros(depth.shape, dtype=bool)
        in_box[max(0, y1):y2 + 1, max(0, x1):x2 + 1] = True
        out.append((depth > 0, (depth > 0) & (depth <= nearest + 1e-3) & in_box))
    return out


def mask_iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    """Intersection over union of two masks (0 when both are empty)."""
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b) / union) if union else 0.0
