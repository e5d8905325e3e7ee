"""Synthetic photographs: for the realistic query protocol, and quick ones from a view.

:func:`composite_photo` stages a rendered view as a photo: turned in the image plane,
scaled and shifted, on a plain background (``viewdb demo``'s query, and the tests');
:func:`table_photo` puts several views side by side on a table-coloured top (photos of
several objects).

For the realistic query protocol a photo is a stored object seen from a random direction
off the grid through a **perspective** camera (random field of view and distance), lit by
a random directional light plus ambient light (pyrender's physically based shader, not
the views' head-light), on a plain background of a random colour, with Gaussian pixel
noise and JPEG compression.  Everything random is drawn into a :class:`PhotoSpec` first,
so the same spec always gives the same image.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import camera_pose
from ..catalogue.gl import pyrender_module
from ..catalogue.mesh import NormalisedMesh
from ..catalogue.render import RenderedView, offscreen, pyrender_mesh, reraise_interrupt
from ..errors import RenderError

__all__ = [
    "PhotoSpec", "composite_photo", "decoded_photo", "draw_photo_spec", "encode_jpeg", "parse_seeds",
    "photo_series", "render_photo", "table_photo", "true_silhouette",
]

#: A wooden table top's colour (RGB).
TABLE = (176, 132, 92)


@dataclass(frozen=True)
class PhotoSpec:
    """Everything that decides one synthetic photo."""

    object: str
    #: Viewing direction (camera convention); the camera stays upright.
    azimuth: float
    elevation: float
    #: Vertical field of view, degrees, and camera distance from the model's centre.
    fov: float
    distance: float
    #: Directional light: offset from the viewing direction, degrees, and intensity.
    light_azimuth: float
    light_elevation: float
    light_intensity: float
    ambient: float
    background: tuple[int, int, int]
    #: Gaussian noise sd in grey levels, and its seed.
    noise: float
    noise_seed: int
    jpeg_quality: int
    image_size: int

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["background"] = list(self.background)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PhotoSpec:
        return cls(**{**data, "background": tuple(int(x) for x in data["background"])})


def draw_photo_spec(rng: np.random.Generator, name: str, image_size: int = 256) -> PhotoSpec:
    """A random photo of object ``name``: direction uniform on the sphere, the model's
    bounding sphere filling 55–85 % of the frame height."""
    azimuth = float(rng.uniform(0.0, 360.0))
    elevation = float(np.degrees(np.arcsin(rng.uniform(-0.97, 0.97))))
    fov = float(rng.uniform(30.0, 55.0))
    fill = float(rng.uniform(0.55, 0.85))
    distance = 1.0 / math.sin(math.radians(fov / 2.0)) / fill
    return PhotoSpec(
        object=name, azimuth=azimuth, elevation=elevation, fov=fov, distance=distance,
        light_azimuth=float(rng.uniform(-60.0, 60.0)),
        light_elevation=float(rng.uniform(-30.0, 60.0)),
        light_intensity=float(rng.uniform(2.0, 5.0)), ambient=float(rng.uniform(0.25, 0.6)),
        background=tuple(int(x) for x in rng.integers(0, 256, 3)),  # type: ignore[arg-type]
        noise=float(rng.uniform(1.0, 6.0)), noise_seed=int(rng.integers(2**31)),
        jpeg_quality=int(rng.integers(60, 96)), image_size=image_size,
    )


def parse_seeds(text: str) -> list[int]:
    """The seeds of :func:`photo_series` a benchmark's ``--seeds`` names: ``"1-6"`` or
    ``"1,3,5"`` (or both: ``"1-4,7"``; ``""`` is none)."""
    out: list[int] = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    return out


def photo_series(names: Sequence[str], seed: int, count: int, image_size: int = 256) -> list[PhotoSpec]:
    """The ``count`` photos of the synthetic photo benchmarks (``benchmarks/photo_accuracy.py``,
    ``benchmarks/miss_analysis.py``) for ``seed``: each a random object of ``names`` (in the
    catalogue's order) and a random photo of it (:func:`draw_photo_spec`); same seed, same
    photos."""
    rng = np.random.default_rng(seed)
    return [draw_photo_spec(rng, names[int(rng.integers(len(names)))], image_size) for _ in range(count)]


def seed_photos(db: Any, seeds: str, count: int) -> list[tuple[PhotoSpec, NDArray[np.uint8]]]:
    """Each photo of :func:`photo_series` for every seed ``seeds`` names (:func:`parse_seeds`),
    ``count`` per seed, of the objects of ``db`` (a :class:`~viewdb.ViewDB`): its spec and
    the photo as a query decodes it (:func:`decoded_photo`)."""
    names = [o.name for o in db.objects()]
    return [(spec, decoded_photo(db.mesh(spec.object), spec))
            for seed in parse_seeds(seeds) for spec in photo_series(names, seed, count)]


def render_photo(mesh: NormalisedMesh, spec: PhotoSpec) -> NDArray[np.uint8]:
    """The photo ``spec`` describes, as RGB uint8 (before JPEG; see :func:`encode_jpeg`)."""
    pyrender = pyrender_module()
    size = spec.image_size
    bg = np.array(spec.background, dtype=np.float64) / 255.0
    try:
        scene = pyrender.Scene(bg_color=[*bg, 1.0], ambient_light=[spec.ambient] * 3)
        scene.add(pyrender_mesh(mesh))
        camera = pyrender.PerspectiveCamera(
            yfov=math.radians(spec.fov), aspectRatio=1.0, znear=max(0.05, spec.distance - 1.5),
            zfar=spec.distance + 1.5,
        )
        scene.add(camera, pose=camera_pose(spec.azimuth, spec.elevation, spec.distance))
        light = pyrender.DirectionalLight(color=np.ones(3), intensity=spec.light_intensity)
        scene.add(light, pose=camera_pose(spec.azimuth + spec.light_azimuth,
                                          spec.elevation + spec.light_elevation, 1.0))
        gl = offscreen(size)
        flags = pyrender.RenderFlags
        color, _ = gl.render(scene, flags=flags.SKIP_CULL_FACES)
    except Exception as exc:
        reraise_interrupt(exc)
        raise RenderError(f"rendering a photo of {mesh.name!r} failed: {exc}") from exc
    rgb = np.asarray(color)[:, :, :3].astype(np.float64)
    noise = np.random.default_rng(spec.noise_seed).normal(0.0, spec.noise, rgb.shape)
    return np.clip(rgb + noise + 0.5, 0, 255).astype(np.uint8)


def encode_jpeg(rgb: NDArray[np.uint8], quality: int) -> bytes:
    """JPEG bytes of an RGB image at ``quality`` (OpenCV's encoder, deterministic)."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR),
                           [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RenderError("JPEG encoding failed")
    return bytes(buf)


def decoded_photo(mesh: NormalisedMesh, spec: PhotoSpec) -> NDArray[np.uint8]:
    """The photo ``spec`` describes as a user would have it: rendered, JPEG-compressed at the
    spec's quality and decoded again (RGB uint8)."""
    jpeg = encode_jpeg(render_photo(mesh, spec), spec.jpeg_quality)
    bgr = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    assert bgr is not None  # the JPEG encoded just above
    return np.ascontiguousarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def true_silhouette(mesh: NormalisedMesh, spec: PhotoSpec) -> NDArray[np.bool_]:
    """The photo's exact silhouette: the same perspective camera, rendered depth > 0."""
    pyrender = pyrender_module()
    try:
        scene = pyrender.Scene()
        scene.add(pyrender_mesh(mesh))
        camera = pyrender.PerspectiveCamera(
            yfov=math.radians(spec.fov), aspectRatio=1.0, znear=max(0.05, spec.distance - 1.5),
            zfar=spec.distance + 1.5,
        )
        scene.add(camera, pose=camera_pose(spec.azimuth, spec.elevation, spec.distance))
        flags = pyrender.RenderFlags.DEPTH_ONLY | pyrender.RenderFlags.SKIP_CULL_FACES
        depth = offscreen(spec.image_size).render(scene, flags=flags)
    except Exception as exc:
        reraise_interrupt(exc)
        raise RenderError(f"rendering the silhouette of {mesh.name!r} failed: {exc}") from exc
    return np.asarray(depth) > 0


def composite_photo(
    view: RenderedView, *, turn: float = 0.0, scale: float = 1.0,
    shift: tuple[float, float] = (0.0, 0.0), background: int | tuple[int, int, int] = 200,
) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
    """A view staged as a photo, and the object's mask in it.

    The view's render is turned by ``turn`` degrees counter-clockwise (as seen on screen)
    and scaled by ``scale`` about the image centre, shifted by ``shift`` pixels (x right,
    y down), and pasted on a plain ``background`` (a grey level or an RGB triple) in an
    image of the view's size: colours interpolated linearly, the mask by nearest
    neighbour. Without a turn, scale or shift the render is pasted as it is.
    """
    size = view.mask.shape[0]
    color, mask = view.color, view.mask
    if turn != 0.0 or scale != 1.0 or any(shift):
        m = np.asarray(cv2.getRotationMatrix2D((size / 2, size / 2), turn, scale), np.float64)
        m[:, 2] += shift
        color = np.asarray(cv2.warpAffine(view.color, m, (size, size), flags=cv2.INTER_LINEAR), np.uint8)
        mask = cv2.warpAffine(view.mask.astype(np.uint8), m, (size, size), flags=cv2.INTER_NEAREST) > 0
    photo = np.empty((size, size, 3), np.uint8)
    photo[:] = background
    photo[mask] = color[mask]
    return photo, mask


def table_photo(
    views: list[RenderedView], size: tuple[int, int], places: list[tuple[int, int]], *,
    background: tuple[int, int, int] = TABLE, grain: float = 6.0, seed: int = 0,
) -> tuple[NDArray[np.uint8], list[NDArray[np.bool_]]]:
    """Several views on a table top: ``size`` (width, height); each view's render pasted
    with its top-left corner at ``places[i]`` (x, y) over a ``background`` with a soft
    light gradient and wood-like grain (noise of sd ``grain``, stretched along x); and each
    object's mask in the photo (a later view covers an earlier one)."""
    w, h = size
    rng = np.random.default_rng(seed)
    shade = np.linspace(0.92, 1.06, w, dtype=np.float32)[None, :, None] * np.linspace(
        1.04, 0.94, h, dtype=np.float32)[:, None, None]
    streaks = cv2.resize(rng.normal(0.0, grain, (h, max(2, w // 16))).astype(np.float32), (w, h),
                         interpolation=cv2.INTER_LINEAR)
    lit = np.asarray(background, np.float32)[None, None, :] * shade + streaks[:, :, None]
    photo = np.clip(lit + rng.normal(0.0, 1.5, lit.shape), 0, 255).astype(np.uint8)
    masks: list[NDArray[np.bool_]] = []
    for view, (x, y) in zip(views, places, strict=True):
        vh, vw = view.mask.shape
        if x < 0 or y < 0 or x + vw > w or y + vh > h:
            raise ValueError(f"a {vw}x{vh} view at ({x}, {y}) does not fit a {w}x{h} photo")
        mask = np.zeros((h, w), dtype=bool)
        mask[y:y + vh, x:x + vw] = view.mask
        photo[mask] = view.color[view.mask]
        masks = [m & ~mask for m in masks] + [mask]
    return photo, masks
