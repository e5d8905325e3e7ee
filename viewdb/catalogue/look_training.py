"""Fit the look model (:mod:`viewdb.catalogue.look`) from the catalogue's own renders.

Each coloured object is rendered from :attr:`~viewdb.config.LookConfig.views` random
directions. Each training crop (:func:`clutter_crop`) takes one of them, most often lit
again from another direction with more or less ambient light (:func:`relit`: its
colours divided by the render's head-light and shaded again, the surface's slopes read
from its depth), and pastes it, turned in its plane, scaled and with its colours cast (a
camera's gain per channel, brightness, saturation, gamma), into synthetic clutter: a
smooth random colour field under one to four renders of any catalogue object, and, more
often than not, another render over part of it. The crop is the box of what stays
visible, blurred and noisy as a photo is, so the model learns what survives a cluttered
box: the object's colours and texture, not its background's. Nothing is downloaded: the
catalogue is the training set.

Each object's renders and crops draw on its own seeded random stream, and the looks of
its crops (:func:`make_looks`) are kept in the file: a later fit makes only the looks of
the objects added or replaced, over clutter drawn from those and a few others, and fits
the discriminant from every object's looks (:func:`refresh_looks`, :func:`fit_looks`).

Needs GL (pyrender) for the renders: an ingest fits the model; a query only reads it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Mapping, Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from ..config import LookConfig, RenderConfig
from .look import LOOK_DIMS, LookModel, fit_look_model, look_features
from .mesh import NormalisedMesh
from .render import Renderer

__all__ = ["clutter_crop", "clutter_sample", "fit_looks", "look_key", "make_looks",
           "refresh_looks", "relit", "train_look_model"]

#: Side of the synthetic scene a training crop is cut from, in pixels.
SCENE = 160
#: A render with fewer object pixels than this is not used.
_MIN_PIXELS = 30

Render = tuple[NDArray[np.uint8], NDArray[np.bool_]]


def _directions(rng: np.random.Generator, n: int) -> list[tuple[float, float]]:
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return [(float(np.degrees(np.arctan2(y, x))), float(np.degrees(np.arcsin(np.clip(z, -1, 1)))))
            for x, y, z in v]


def _paste(scene: NDArray[np.uint8], colour: NDArray[np.uint8], mask: NDArray[np.bool_],
           x: int, y: int) -> NDArray[np.bool_]:
    """Paste ``colour`` where ``mask`` at ``(x, y)`` (clipped); the scene's pixels it covered."""
    h, w = mask.shape
    height, width = scene.shape[:2]
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + w, width), min(y + h, height)
    covered = np.zeros((height, width), bool)
    if x1 <= x0 or y1 <= y0:
        return covered
    part = mask[y0 - y:y1 - y, x0 - x:x1 - x]
    scene[y0:y1, x0:x1][part] = colour[y0 - y:y1 - y, x0 - x:x1 - x][part]
    covered[y0:y1, x0:x1] = part
    return covered


def _resized(render: Render, side: int) -> Render:
    colour, mask = render
    return (np.asarray(cv2.resize(colour, (side, side), interpolation=cv2.INTER_AREA), np.uint8),
            cv2.resize(mask.astype(np.uint8), (side, side), interpolation=cv2.INTER_NEAREST) > 0)


def relit(rng: np.random.Generator, colour: NDArray[np.uint8], mask: NDArray[np.bool_],
          depth: NDArray[np.floating], pixel_size: float, ambient: float) -> NDArray[np.uint8]:
    """``colour`` (a render lit by a head-light with share ``ambient`` of ambient light)
    lit instead from a random direction towards the camera, with a random ambient share:
    the surface's normal is ``(∂depth/∂x, ∂depth/∂y, 1)`` up to scale (slopes across
    the silhouette or a depth jump count as flat)."""
    gy, gx = np.gradient(depth.astype(np.float64), pixel_size)
    steep = ~mask | (np.hypot(gx, gy) > 8.0)
    gx, gy = np.where(steep, 0.0, gx), np.where(steep, 0.0, gy)
    length = np.sqrt(1.0 + gx * gx + gy * gy)
    albedo = colour.astype(np.float64) / (ambient + (1.0 - ambient) / length)[..., None]
    light = np.array([*rng.normal(0.0, 0.6, 2), 1.0])
    light /= np.linalg.norm(light)
    share = rng.uniform(0.15, 0.6)
    shade = share + (1.0 - share) * np.clip((gx * light[0] + gy * light[1] + light[2]) / length, 0.0, 1.0)
    out = np.clip(albedo * shade[..., None], 0, 255).astype(np.uint8)
    out[~mask] = colour[~mask]
    return out


def _background(rng: np.random.Generator, pool: Callable[[], Render]) -> NDArray[np.uint8]:
    grid = rng.integers(0, 256, size=(int(rng.integers(2, 6)), int(rng.integers(2, 6)), 3)).astype(np.uint8)
    field = cv2.resize(grid, (SCENE, SCENE), interpolation=cv2.INTER_CUBIC).astype(np.float32)
    field += rng.normal(0.0, rng.uniform(0, 12), size=field.shape)
    scene = np.clip(field, 0, 255).astype(np.uint8)
    for _ in range(int(rng.integers(1, 5))):
        side = int(SCENE * rng.uniform(0.4, 1.1))
        colour, mask = _resized(pool(), side)
        x, y = rng.integers(-side // 2, SCENE - side // 2, size=2)
        _paste(scene, colour, mask, int(x), int(y))
    return scene


def _cast(rng: np.random.Generator, colour: NDArray[np.uint8], spread: float) -> NDArray[np.uint8]:
    c = colour.astype(np.float32) / 255.0
    c = c * rng.uniform(0.55, 1.45) * rng.normal(1.0, spread, size=3)
    grey = c.mean(axis=-1, keepdims=True)
    c = grey + (c - grey) * rng.uniform(0.6, 1.3)
    c = np.clip(c, 0.0, 1.0) ** rng.uniform(0.7, 1.4)
    return np.clip(c * 255.0, 0, 255).astype(np.uint8)


def clutter_crop(rng: np.random.Generator, render: Render, pool: Callable[[], Render],
                 colour_cast: float) -> NDArray[np.uint8] | None:
    """One training crop of ``render`` (an object's colour and mask) in synthetic clutter
    whose other objects ``pool`` draws (see the module doc); None when too little of the
    object stays visible."""
    colour, mask = render
    side = mask.shape[0]
    turn = cv2.getRotationMatrix2D(((side - 1) / 2, (side - 1) / 2), float(rng.uniform(0, 360)), 1.0)
    turned = np.asarray(cv2.warpAffine(colour, turn, (side, side), flags=cv2.INTER_LINEAR), np.uint8)
    colour = _cast(rng, turned, colour_cast)
    mask = cv2.warpAffine(mask.astype(np.uint8), turn, (side, side), flags=cv2.INTER_NEAREST) > 0
    ys, xs = np.nonzero(mask)
    if len(ys) < _MIN_PIXELS:
        return None
    colour = colour[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    mask = mask[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    scale = rng.uniform(0.45, 0.8) * SCENE / max(mask.shape)
    w, h = max(int(mask.shape[1] * scale), 8), max(int(mask.shape[0] * scale), 8)
    colour = np.asarray(cv2.resize(colour, (w, h), interpolation=cv2.INTER_AREA), np.uint8)
    mask = cv2.resize(mask.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    scene = _background(rng, pool)
    x, y = (SCENE - w) // 2 + int(rng.integers(-10, 11)), (SCENE - h) // 2 + int(rng.integers(-10, 11))
    visible = _paste(scene, colour, mask, x, y)
    if rng.random() < 0.6:  # an occluder over part of it
        size = int(max(w, h) * rng.uniform(0.5, 1.2))
        occluder, shape = _resized(pool(), size)
        ox = x + int(rng.uniform(-0.9, 0.9) * w) - size // 2 + w // 2
        oy = y + int(rng.uniform(-0.9, 0.9) * h) - size // 2 + h // 2
        visible &= ~_paste(scene, occluder, shape, ox, oy)
    if visible.sum() < 0.4 * mask.sum():
        return None
    blurred = cv2.GaussianBlur(scene, (0, 0), rng.uniform(0.3, 1.5)) if rng.random() < 0.7 else scene
    photo = np.clip(blurred + rng.normal(0.0, rng.uniform(0, 6), scene.shape), 0, 255).astype(np.uint8)
    ys, xs = np.nonzero(visible)
    crop = photo[ys.min():ys.max() + 1, xs.min():xs.max() + 1]
    return crop if min(crop.shape[:2]) >= 6 else None


def train_look_model(
    meshes: Callable[[str], NormalisedMesh], coloured: Sequence[str], others: Sequence[str],
    config: LookConfig = LookConfig(),  # noqa: B008 - frozen, shared on purpose
    progress: Callable[[int, int], None] | None = None,
) -> LookModel | None:
    """The look model of the ``coloured`` objects (None with fewer than two), their
    clutter drawn from them and the ``others`` (meshes without colour), at most
    ``config.clutter_objects`` of them (:func:`clutter_sample`); ``meshes`` gives an
    object's normalised mesh. ``progress(done, total)`` after each object rendered and
    each one's crops."""
    return refresh_looks(meshes, [*coloured, *others], set(coloured), {}, config, progress)[0]


def clutter_sample(names: Sequence[str], size: int, config: LookConfig) -> list[str]:
    """``names`` in order, or a seeded sample of ``size`` of them when there are more:
    the objects whose renders are the clutter, so that memory does not grow with the
    catalogue."""
    ordered = sorted(set(names))
    if len(ordered) <= size:
        return ordered
    rng = np.random.default_rng(config.seed)
    return sorted(rng.choice(np.array(ordered), size, replace=False).tolist())


def _stream(config: LookConfig, name: str, part: int) -> np.random.Generator:
    """Object ``name``'s own seeded random stream for its renders (part 0) or its crops
    (part 1): the same whatever else the catalogue holds."""
    digest = hashlib.sha256(name.encode()).digest()
    return np.random.default_rng([config.seed, int.from_bytes(digest[:8], "little"), part])


def make_looks(
    meshes: Callable[[str], NormalisedMesh], coloured: Sequence[str], clutter: Sequence[str],
    config: LookConfig = LookConfig(),  # noqa: B008 - frozen, shared on purpose
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, NDArray[np.float32]]:
    """The looks ``(n, d)`` of the training crops of each of the ``coloured`` objects (up
    to ``config.samples``; none for an object without a usable render), each pasted into
    clutter drawn from the renders of the ``clutter`` objects (module doc). Each object's
    renders and crops draw on its own seeded stream. ``progress(done, total)`` after each
    object rendered for the clutter and each one's crops."""
    render_config = RenderConfig(image_size=config.image_size)
    renderer = Renderer(render_config)
    pixel_size = 2.0 * render_config.xmag / render_config.image_size
    total, done = len(clutter) + len(coloured), 0
    wanted = set(coloured)

    def rendered(name: str) -> tuple[list[Render], list[NDArray[np.float32]]]:
        mesh = meshes(name)
        views = [renderer.render(mesh, azimuth, elevation)
                 for azimuth, elevation in _directions(_stream(config, name, 0), config.views)]
        kept = [v for v in views if v.mask.sum() >= _MIN_PIXELS]
        return [(v.color, v.mask) for v in kept], [v.depth for v in kept]

    renders: dict[str, list[Render]] = {}
    depths: dict[str, list[NDArray[np.float32]]] = {}
    for name in clutter:
        own, own_depths = rendered(name)
        if own:
            renders[name] = own
            if name in wanted:  # only a coloured object's own crops are relit
                depths[name] = own_depths
        done += 1
        if progress:
            progress(done, total)
    drawable = sorted(renders)
    looks: dict[str, NDArray[np.float32]] = {}
    for name in coloured:
        own, own_depths = (renders[name], depths[name]) if name in depths else rendered(name)
        rng = _stream(config, name, 1)
        pool_names = drawable or [name]

        def pool(rng: np.random.Generator = rng, pool_names: list[str] = pool_names,
                 own: list[Render] = own) -> Render:
            views = renders.get(pool_names[int(rng.integers(len(pool_names)))], own)
            return views[int(rng.integers(len(views)))]

        made = (_object_looks(rng, own, own_depths, pool, config, pixel_size, render_config.ambient)
                if own else [])
        looks[name] = np.stack(made) if made else np.zeros((0, LOOK_DIMS), np.float32)
        done += 1
        if progress:
            progress(done, total)
    return looks


def fit_looks(looks: Mapping[str, NDArray[np.floating]],
              config: LookConfig = LookConfig()) -> LookModel | None:  # noqa: B008 - frozen
    """The look model of the objects with looks (:func:`make_looks`; by name), None with
    fewer than two: the same looks give the same model."""
    names = sorted(n for n, v in looks.items() if len(v))
    if len(names) < 2:
        return None
    stacked = np.concatenate([np.asarray(looks[n], np.float32) for n in names])
    labels = np.repeat(np.arange(len(names)), [len(looks[n]) for n in names])
    return fit_look_model(stacked, labels, tuple(names), config.shrinkage)


def _object_looks(
    rng: np.random.Generator, own: list[Render], own_depths: list[NDArray[np.float32]],
    pool: Callable[[], Render], config: LookConfig, pixel_size: float, ambient: float,
) -> list[NDArray[np.float32]]:
    """The looks of up to ``config.samples`` clutter crops of one object's renders."""
    looks: list[NDArray[np.float32]] = []
    tries = 0
    while len(looks) < config.samples and tries < 20 * config.samples:
        tries += 1
        at = int(rng.integers(len(own)))
        colour, mask = own[at]
        if rng.random() < config.relight:
            colour = relit(rng, colour, mask, own_depths[at], pixel_size, ambient)
        crop = clutter_crop(rng, (colour, mask), pool, config.colour_cast)
        if crop is not None:
            looks.append(look_features(crop))
    return looks


def look_key(hashes: Mapping[str, str], config: LookConfig = LookConfig()) -> str:  # noqa: B008 - frozen
    """What a look model of the objects ``hashes`` (name → content hash) with ``config``
    is fitted for: the coloured ones are its classes, all are its clutter."""
    digest = hashlib.sha256(config.key().encode())
    for name, content_hash in sorted(hashes.items()):
        digest.update(f"\n{name}\t{content_hash}".encode())
    return digest.hexdigest()


def refresh_looks(
    meshes: Callable[[str], NormalisedMesh], names: Sequence[str], coloured: set[str],
    stored: Mapping[str, NDArray[np.floating]],
    config: LookConfig = LookConfig(),  # noqa: B008 - frozen, shared on purpose
    progress: Callable[[int, int], None] | None = None,
) -> tuple[LookModel | None, dict[str, NDArray[np.float32]]]:
    """The look model of a catalogue's objects ``names`` (``coloured``: those whose meshes
    have colour; None with fewer than two) and the looks made for it. A coloured object's
    ``stored`` looks ``(n, LOOK_DIMS)`` are used as they are; the others' are made
    (:func:`make_looks`): over the clutter of a whole fit (a sample of at most
    ``config.clutter_objects`` of every object) when none is stored, else over the objects
    made and ``config.update_clutter`` others. The same looks give the same model, however
    the catalogue is split into files."""
    ordered = sorted(names)
    painted = [n for n in ordered if n in coloured]
    kept = {n: np.asarray(stored[n], np.float32) for n in painted
            if n in stored and np.ndim(stored[n]) == 2 and np.shape(stored[n])[1] == LOOK_DIMS}
    missing = [n for n in painted if n not in kept]
    made: dict[str, NDArray[np.float32]] = {}
    if missing and len(painted) >= 2:
        if kept:
            rest = [n for n in ordered if n not in set(missing)]
            others = clutter_sample(rest, config.update_clutter, config)
            clutter = clutter_sample([*missing, *others], config.clutter_objects, config)
        else:
            clutter = clutter_sample(ordered, config.clutter_objects, config)
        made = make_looks(meshes, missing, clutter, config, progress)
    return fit_looks({**kept, **made}, config), made
