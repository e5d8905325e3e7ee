"""Rendering a mesh through a pinhole camera (intrinsics) at a given pose.

The views of a database are orthographic (:mod:`viewdb.catalogue.render`); a real photo is a
perspective one. This module renders the silhouette (and depth) of a normalised mesh as a
calibrated camera would see it, so a pose can be checked and refined against a photo's
mask and overlays can be drawn.

Frames: the pose is **model-to-camera in the OpenCV frame** (x right, y down, z forward),
``x_cam = R · x_model + t``; intrinsics ``(fx, fy, cx, cy)`` in pixels with pixel centres on
integers (OpenCV). A :class:`Window` renders a rectangle of the photo, optionally
downscaled, so a pose search renders only the pixels around the object.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..camera import GL_TO_CV
from ..errors import RenderError
from ..interrupts import interrupts_held
from ..typed import Intrinsics
from .coverage import MeshTriangles, silhouette
from .gl import pyrender_module
from .mesh import NormalisedMesh
from .render import offscreen, pyrender_mesh, render_depth, reraise_interrupt

__all__ = ["PinholeRenderer", "Window", "get_pinhole_renderer"]

#: Meshes whose triangles :meth:`PinholeRenderer.silhouette` keeps (a query re-ranking its
#: results fits each of up to k meshes, some twice; the objects of one photo share them).
TRIANGLE_CACHE_MESHES = 32


@dataclass(frozen=True)
class Window:
    """A square window of a photo: its top-left corner ``(x0, y0)`` and side in photo
    pixels, rendered at ``size × size`` pixels."""

    x0: float
    y0: float
    side: float
    size: int

    @property
    def factor(self) -> float:
        """Window pixels per photo pixel."""
        return self.size / self.side

    def intrinsics(self, fx: float, fy: float, cx: float, cy: float) -> Intrinsics:
        """The photo's intrinsics for this window (OpenCV pixel centres on integers)."""
        f = self.factor
        return (fx * f, fy * f, (cx - self.x0 + 0.5) * f - 0.5, (cy - self.y0 + 0.5) * f - 0.5)

    def crop(self, image: NDArray[np.generic]) -> NDArray[np.float32]:
        """``image`` (H, W) resampled onto this window (area average; 0 outside the photo)."""
        part, window = self.part(image)
        return window._resample(part)

    def _blur_side(self) -> int:
        """The box blur that makes the window's samples area averages (1: none)."""
        return int(math.ceil(1.0 / self.factor)) | 1 if self.factor < 1.0 else 1

    def _resample(self, image: NDArray[np.generic]) -> NDArray[np.float32]:
        import cv2

        f = self.factor
        # window pixel (i, j) centre = photo ((i + 0.5)/f - 0.5 + x0, ...)
        m = np.array([[f, 0.0, (0.5 - self.x0) * f - 0.5], [0.0, f, (0.5 - self.y0) * f - 0.5]])
        src = np.asarray(image, dtype=np.float32)
        k = self._blur_side()
        if k > 1:  # pre-blur so the nearest samples are area averages
            src = np.asarray(cv2.blur(src, (k, k)), dtype=np.float32)
        out = cv2.warpAffine(src, m, (self.size, self.size), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return np.asarray(out, dtype=np.float32)

    def part(self, image: NDArray[Any]) -> tuple[NDArray[Any], Window]:
        """The part of ``image`` this window samples, and this window in that part's
        pixels: every pixel a window pixel's linear sample reads, and what the blur of
        :meth:`crop` reads for them (the photo's own edges stay edges), so that
        ``window.crop(part)`` is :meth:`crop` of the whole image. A large photo's window
        then costs its own size, not the photo's, and so does preparing only the part
        (its grey levels, say)."""
        h, w = image.shape[:2]
        f, margin = self.factor, self._blur_side() // 2 + 2
        first_x, last_x = self.x0 + 0.5 / f - 0.5, self.x0 + (self.size - 0.5) / f - 0.5
        first_y, last_y = self.y0 + 0.5 / f - 0.5, self.y0 + (self.size - 0.5) / f - 0.5
        left = min(w, max(0, math.floor(first_x) - margin))
        top = min(h, max(0, math.floor(first_y) - margin))
        right = max(left, min(w, math.floor(last_x) + margin + 2))
        bottom = max(top, min(h, math.floor(last_y) + margin + 2))
        if right - left < 1 or bottom - top < 1:  # the window lies off the photo: one pixel to warp
            left, top = min(left, w - 1), min(top, h - 1)
            right, bottom = left + 1, top + 1
        return image[top:bottom, left:right], Window(self.x0 - left, self.y0 - top, self.side, self.size)

    @staticmethod
    def around(mask: NDArray[np.bool_], size: int, margin: float = 0.35) -> Window:
        """The square window around ``mask``'s bounding box, grown by ``margin`` of its side."""
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        y0, y1, x0, x1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
        side = max(y1 - y0, x1 - x0) * (1.0 + 2.0 * margin)
        cx, cy = (x0 + x1) / 2.0, (y0 + y1) / 2.0
        return Window(float(cx - side / 2.0), float(cy - side / 2.0), float(side), int(size))


class PinholeRenderer:
    """Renders one mesh at a time through an intrinsics camera; keeps its scene between calls."""

    def __init__(self) -> None:
        self._mesh: NormalisedMesh | None = None
        self._scene = None
        self._mesh_node = None
        self._camera_node = None
        #: Per mesh (by identity; the mesh is kept so its id stays its own): its triangles
        #: at each level of detail asked for, the least recently used dropped first.
        self._triangles: dict[int, tuple[NormalisedMesh, dict[int | None, MeshTriangles]]] = {}
        self._triangles_lock = threading.Lock()
        #: Per thread (GL buffers belong to the thread's context), the scene :meth:`colour`
        #: renders: ``mesh``, ``scene`` and its ``nodes`` (the mesh's and the camera's).
        self._colour = threading.local()

    def _use_mesh(self, mesh: NormalisedMesh) -> None:
        if self._mesh is mesh:
            return
        pyrender = pyrender_module()
        try:
            scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[1.0, 1.0, 1.0])
            with interrupts_held():  # trimesh swallows BaseException in places
                geometry = mesh.geometry
                self._mesh_node = scene.add(pyrender.Mesh.from_trimesh(geometry, smooth=False))
        except Exception as exc:
            reraise_interrupt(exc)
            raise RenderError(f"cannot build a render scene for {mesh.name!r}: {exc}") from exc
        self._scene = scene
        self._camera_node = None
        self._mesh = mesh

    def render(
        self, mesh: NormalisedMesh, rotation: NDArray[np.floating], translation: NDArray[np.floating],
        intrinsics: Intrinsics, size: int,
    ) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
        """Silhouette (bool) and depth (camera z, 0 off the object) of ``mesh`` at the
        OpenCV pose ``(rotation, translation)`` for a ``size × size`` image with
        ``intrinsics`` ``(fx, fy, cx, cy)`` (e.g. :meth:`Window.intrinsics`)."""
        self._use_mesh(mesh)
        assert self._scene is not None
        self._camera_node = _place(self._scene, self._mesh_node, self._camera_node, rotation, translation,
                                   intrinsics)
        depth = render_depth(self._scene, size, mesh.name)
        return depth > 0, depth

    def colour(
        self, mesh: NormalisedMesh, rotation: NDArray[np.floating], translation: NDArray[np.floating],
        intrinsics: Intrinsics, size: int,
    ) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
        """The mesh's own colours (ambient light only: no shading) and its silhouette, as
        :meth:`render` places it, RGB uint8 ``(size, size, 3)`` (black off the object)."""
        pyrender = pyrender_module()
        mine = self._colour
        if getattr(mine, "mesh", None) is not mesh:
            try:
                scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[1.0, 1.0, 1.0])
                node = scene.add(pyrender_mesh(mesh))
            except Exception as exc:
                reraise_interrupt(exc)
                raise RenderError(f"cannot build a render scene for {mesh.name!r}: {exc}") from exc
            mine.scene, mine.nodes, mine.mesh = scene, [node, None], mesh
        scene, nodes = mine.scene, mine.nodes
        nodes[1] = _place(scene, nodes[0], nodes[1], rotation, translation, intrinsics)
        try:
            color, depth = offscreen(size).render(scene)
        except Exception as exc:
            reraise_interrupt(exc)
            raise RenderError(f"rendering {mesh.name!r} failed: {exc}") from exc
        return np.asarray(color[..., :3], dtype=np.uint8), np.asarray(depth) > 0

    def silhouette(
        self, mesh: NormalisedMesh, rotation: NDArray[np.floating], translation: NDArray[np.floating],
        intrinsics: Intrinsics, size: int, max_faces: int | None = None,
    ) -> NDArray[np.bool_]:
        """The silhouette alone, as :meth:`render` gives it, scan-converted on the CPU
        (:mod:`viewdb.catalogue.coverage`: no GL call, 10–20x quicker for a small window);
        with ``max_faces``, of the mesh decimated to about that many faces
        (:meth:`~viewdb.catalogue.coverage.MeshTriangles.simplified`)."""
        return silhouette(self.triangles(mesh, max_faces), rotation, translation, intrinsics, size)

    def triangles(self, mesh: NormalisedMesh, max_faces: int | None = None) -> MeshTriangles:
        """The mesh's triangles as :meth:`silhouette` scan-converts them (decimated to about
        ``max_faces`` faces if given), made once per mesh and level and kept."""
        with self._triangles_lock:  # a server's threads share this renderer
            levels = self._triangles.pop(id(mesh), (None, {}))[1]
            if not levels:
                geometry = mesh.geometry
                levels[None] = MeshTriangles(geometry.vertices, geometry.faces)
            self._triangles[id(mesh)] = (mesh, levels)  # most recently used last
            while len(self._triangles) > TRIANGLE_CACHE_MESHES:
                del self._triangles[next(iter(self._triangles))]
            if max_faces not in levels:
                full = levels[None]
                levels[max_faces] = full.simplified(max_faces) if max_faces is not None else full
            return levels[max_faces]


def _place(scene, mesh_node, camera_node, rotation: NDArray[np.floating],  # type: ignore[no-untyped-def]
           translation: NDArray[np.floating], intrinsics: Intrinsics):
    """Put ``scene``'s mesh at the OpenCV pose ``(rotation, translation)`` before a camera
    with ``intrinsics``, the camera's near and far planes around the object (radius 1 in
    model units); the camera node that replaces ``camera_node``."""
    pyrender = pyrender_module()
    fx, fy, cx, cy = (float(x) for x in intrinsics)
    t = np.asarray(translation, dtype=np.float64).reshape(3)
    znear = max(1e-3, float(t[2]) - 1.5) if t[2] > 1.6 else max(1e-3, float(t[2]) * 0.05)
    zfar = float(t[2]) + 1.5
    camera = pyrender.IntrinsicsCamera(fx, fy, cx + 0.5, cy + 0.5, znear=znear, zfar=zfar)
    if camera_node is not None:
        scene.remove_node(camera_node)
    camera_node = scene.add(camera, pose=np.eye(4))
    pose = np.eye(4)
    pose[:3, :3] = GL_TO_CV @ np.asarray(rotation, dtype=np.float64)
    pose[:3, 3] = GL_TO_CV @ t
    scene.set_pose(mesh_node, pose)
    return camera_node


@dataclass
class _Cache:
    renderer: PinholeRenderer = field(default_factory=PinholeRenderer)


_CACHE = _Cache()


def get_pinhole_renderer() -> PinholeRenderer:
    """This process's pinhole renderer (created once)."""
    return _CACHE.renderer
