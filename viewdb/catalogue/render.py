"""Rendering views of a normalised mesh: shaded image, silhouette mask and depth map.

One pyrender ``OffscreenRenderer`` per process, created on first use and reused: creating
and destroying EGL contexts repeatedly fails intermittently, and contexts are per thread.
Workers of a parallel ingest are separate processes, each with its own renderer.

Shading. The camera convention (:mod:`viewdb.camera`) fixes geometry; for shading viewdb
renders the unlit albedo (base colour, textures and vertex colours) with pyrender's FLAT
mode and lights it with a head-light in image space: normals come from the depth map, and
each pixel gets ``albedo · (ambient + (1 − ambient) · n·l)`` with ``l`` pointing at the
camera. On Mesa's software rasteriser this is about 3× faster than pyrender's PBR shader,
and being a function of geometry and albedo alone it is identical across machines.
"""

from __future__ import annotations

import atexit
import math
import threading
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..camera import GL_TO_CV, camera_pose
from ..config import RenderConfig
from ..errors import RenderError
from ..interrupts import interrupts_held
from .coverage import MeshTriangles, silhouette
from .gl import pyrender_module
from .mesh import NormalisedMesh

__all__ = [
    "RenderedView", "Renderer", "get_renderer", "headlight_shading", "offscreen", "render_depth",
    "reraise_interrupt",
]

#: A depth step larger than this many pixel widths between neighbours is an occlusion edge.
DEPTH_JUMP_PIXELS = 6.0


@dataclass(frozen=True, eq=False)
class RenderedView:
    """One rendered view in the documented camera convention."""

    azimuth: float
    elevation: float
    #: Lit RGB image, uint8 (S, S, 3); background black.
    color: NDArray[np.uint8] = field(repr=False)
    #: Silhouette, bool (S, S).
    mask: NDArray[np.bool_] = field(repr=False)
    #: Distance along the viewing axis, float32 (S, S); 0 on the background.
    depth: NDArray[np.float32] = field(repr=False)
    #: Camera-to-world pose (4, 4).
    pose: NDArray[np.float64] = field(repr=False)

    @property
    def image_size(self) -> int:
        return int(self.mask.shape[0])


def headlight_shading(
    depth: NDArray[np.floating], mask: NDArray[np.bool_], pixel_size: float, ambient: float
) -> NDArray[np.float32]:
    """Per-pixel light factor in [ambient, 1] for a head-light, from an orthographic depth map.

    The camera-frame surface is ``z = −depth(x, y)``, so its normal is proportional to
    ``(∂depth/∂x, ∂depth/∂y, 1)`` and ``n·l = 1/√(1 + |∇depth|²)`` for ``l`` towards the
    camera. Differences across occlusion edges or onto the background are not used.
    """
    d = depth.astype(np.float64)
    limit = DEPTH_JUMP_PIXELS * pixel_size

    def axis_gradient(axis: int) -> NDArray[np.float64]:
        fwd = np.zeros_like(d)
        bwd = np.zeros_like(d)
        ok_f = np.zeros(d.shape, dtype=bool)
        ok_b = np.zeros(d.shape, dtype=bool)
        lo = [slice(None), slice(None)]
        hi = [slice(None), slice(None)]
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        diff = d[tuple(hi)] - d[tuple(lo)]
        valid = mask[tuple(hi)] & mask[tuple(lo)] & (np.abs(diff) < limit)
        fwd[tuple(lo)] = diff
        ok_f[tuple(lo)] = valid
        bwd[tuple(hi)] = diff
        ok_b[tuple(hi)] = valid
        both = ok_f & ok_b
        grad = np.where(both, (fwd + bwd) / 2.0, np.where(ok_f, fwd, np.where(ok_b, bwd, 0.0)))
        return grad / pixel_size

    gx = axis_gradient(1)
    gy = axis_gradient(0)
    lambert = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
    light = ambient + (1.0 - ambient) * lambert
    return np.where(mask, light, 0.0).astype(np.float32)


def orthographic_depth(
    reported: NDArray[np.floating], mask: NDArray[np.bool_], znear: float, zfar: float
) -> NDArray[np.float32]:
    """Undo pyrender's perspective depth linearisation, which it applies to every camera.

    pyrender returns ``2nf / (f + n − z(f − n))`` for the NDC depth ``z``; for an
    orthographic camera ``z`` is linear in distance, ``d = n + (z + 1)(f − n)/2``.
    """
    d = reported.astype(np.float64)
    out = np.zeros(d.shape, dtype=np.float64)
    valid = d[mask]
    z_ndc = (zfar + znear - 2.0 * znear * zfar / valid) / (zfar - znear)
    out[mask] = znear + (z_ndc + 1.0) * (zfar - znear) / 2.0
    return out.astype(np.float32)


def reraise_interrupt(exc: Exception) -> None:
    """Ctrl-C inside a ctypes call into GL surfaces as ``ctypes.ArgumentError`` naming
    KeyboardInterrupt; it must stay an interrupt, not become a RenderError."""
    if "KeyboardInterrupt" in str(exc):
        raise KeyboardInterrupt from exc


class Renderer:
    """Renders views of one mesh at a time; keeps that mesh's GL scene between calls."""

    def __init__(self, config: RenderConfig | None = None) -> None:
        self.config = config or RenderConfig()
        self._mesh: NormalisedMesh | None = None
        self._scene = None
        self._camera_node = None
        #: The mesh whose triangles :meth:`perspective_mask` scan-converts, and them.
        self._triangles: tuple[NormalisedMesh, MeshTriangles] | None = None

    def _use_mesh(self, mesh: NormalisedMesh) -> None:
        if self._mesh is mesh:
            return
        pyrender = pyrender_module()
        cfg = self.config
        try:
            scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[1.0, 1.0, 1.0])
            scene.add(pyrender_mesh(mesh))
        except Exception as exc:
            reraise_interrupt(exc)
            raise RenderError(f"cannot build a render scene for {mesh.name!r}: {exc}") from exc
        camera = pyrender.OrthographicCamera(
            xmag=cfg.xmag, ymag=cfg.xmag, znear=cfg.znear, zfar=cfg.zfar
        )
        self._camera_node = scene.add(camera, pose=np.eye(4))
        scene.main_camera_node = self._camera_node
        self._scene = scene
        self._mesh = mesh

    def perspective_mask(
        self, mesh: NormalisedMesh, azimuth: float, elevation: float, distance: float
    ) -> NDArray[np.bool_]:
        """The silhouette of ``mesh`` seen from ``(azimuth, elevation)`` through a pinhole
        camera ``distance`` bounding radii from the centre, on the view's axis, upright as
        the orthographic view is; the field of view just holds the bounding sphere (5 %
        margin). Scan-converted on the CPU (:mod:`viewdb.catalogue.coverage`: the pixels
        OpenGL covers, with no GL call; 10–30x quicker than a depth render)."""
        if not distance > 1.0:
            raise ValueError(f"distance must be greater than 1 (bounding radii), got {distance}")
        if self._triangles is None or self._triangles[0] is not mesh:
            geometry = mesh.geometry
            self._triangles = (mesh, MeshTriangles(geometry.vertices, geometry.faces))
        size = self.config.image_size
        rotation = GL_TO_CV @ camera_pose(azimuth, elevation, distance)[:3, :3].T
        focal = (size / 2.0) / math.tan(math.asin(1.0 / distance) * 1.05)
        centre = (size - 1) / 2.0  # pixel centres on integers
        return silhouette(self._triangles[1], rotation, np.array([0.0, 0.0, distance]),
                          (focal, focal, centre, centre), size)

    def render(
        self, mesh: NormalisedMesh, azimuth: float, elevation: float, *, shaded: bool = True
    ) -> RenderedView:
        """Render ``mesh`` from ``(azimuth, elevation)``.

        With ``shaded=False`` only the depth map is rasterised (about 5× faster) and
        ``color`` is all zeros; mask and depth are the same.
        """
        pyrender = pyrender_module()
        flags = pyrender.RenderFlags
        self._use_mesh(mesh)
        cfg = self.config
        pose = camera_pose(azimuth, elevation, cfg.camera_distance)
        assert self._scene is not None
        self._scene.set_pose(self._camera_node, pose)
        gl = offscreen(cfg.image_size)
        try:
            if shaded:
                albedo, depth = gl.render(
                    self._scene, flags=flags.FLAT | flags.SKIP_CULL_FACES
                )
            else:
                depth = gl.render(
                    self._scene, flags=flags.DEPTH_ONLY | flags.SKIP_CULL_FACES
                )
                albedo = None
        except Exception as exc:
            reraise_interrupt(exc)
            raise RenderError(f"rendering {mesh.name!r} failed: {exc}") from exc
        mask = np.asarray(depth) > 0
        depth = orthographic_depth(np.asarray(depth), mask, cfg.znear, cfg.zfar)
        size = cfg.image_size
        if albedo is None:
            color = np.zeros((size, size, 3), dtype=np.uint8)
        else:
            light = headlight_shading(depth, mask, 2.0 * cfg.xmag / size, cfg.ambient)
            lit = albedo[:, :, :3].astype(np.float32) * light[:, :, None]
            color = np.clip(lit + 0.5, 0, 255).astype(np.uint8)
        return RenderedView(azimuth, elevation, color, mask, depth, pose)


def render_depth(scene, size: int, name: str) -> NDArray[np.float32]:  # type: ignore[no-untyped-def]
    """Depth only (both faces) of ``scene`` through its main camera, ``size`` pixels square;
    GL failures become a :class:`RenderError` naming the object ``name``."""
    pyrender = pyrender_module()
    gl = offscreen(size)
    try:
        depth = gl.render(scene, flags=pyrender.RenderFlags.DEPTH_ONLY
                          | pyrender.RenderFlags.SKIP_CULL_FACES)
    except Exception as exc:
        reraise_interrupt(exc)
        raise RenderError(f"rendering {name!r} failed: {exc}") from exc
    return np.asarray(depth, dtype=np.float32)


def pyrender_mesh(mesh: NormalisedMesh):  # type: ignore[no-untyped-def]
    """The whole model as ONE pyrender mesh: every geometry's primitives, in the scene's
    order. pyrender draws the meshes of a scene in set order (it changes from run to
    run), so parts with coplanar faces (z-fighting) would win at random and the colours,
    hence the SIFT features, of the same view would differ between renders; the
    primitives of one mesh are drawn in list order.

    The scene's transforms are baked into its geometry (:mod:`viewdb.catalogue.mesh`); normals do
    not matter in FLAT mode, and face colours need unshared (non-smooth) vertices.
    Ctrl-C is held meanwhile: trimesh's visuals swallow ``BaseException`` in places.
    """
    pyrender = pyrender_module()
    primitives = []
    with interrupts_held():
        for geometry in mesh.scene.geometry.values():
            smooth = geometry.visual.kind != "face"
            primitives += pyrender.Mesh.from_trimesh(geometry, smooth=smooth).primitives
    return pyrender.Mesh(primitives=primitives)


_LOCAL = threading.local()


def offscreen(size: int):  # type: ignore[no-untyped-def]
    """This thread's one pyrender OffscreenRenderer, resized to ``size`` if needed.

    Several EGL renderers in one process share a display, and deleting one terminates it
    for all; so there is exactly one, kept for the thread's life and resized in place.
    """
    gl = getattr(_LOCAL, "offscreen", None)
    if gl is None:
        pyrender = pyrender_module()
        try:
            gl = pyrender.OffscreenRenderer(size, size)
        except Exception as exc:
            raise RenderError(f"cannot create an offscreen renderer: {exc}") from exc
        _LOCAL.offscreen = gl
        atexit.register(_release, gl)
    elif gl.viewport_width != size or gl.viewport_height != size:
        gl.viewport_width = gl.viewport_height = size
    return gl


def _release(gl) -> None:  # type: ignore[no-untyped-def]
    try:
        gl.delete()
    except Exception:  # noqa: S110 - the process is exiting; GL may already be gone
        pass


def get_renderer(config: RenderConfig | None = None) -> Renderer:
    """The renderer of this thread for ``config`` (created once, then reused)."""
    config = config or RenderConfig()
    cache: dict[RenderConfig, Renderer] = getattr(_LOCAL, "renderers", None) or {}
    _LOCAL.renderers = cache
    renderer = cache.get(config)
    if renderer is None:
        renderer = cache[config] = Renderer(config)
    return renderer
