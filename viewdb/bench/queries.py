"""The benchmark's query sets; the same seed (and the same objects) gives the same queries.

``grid`` (the paper's protocol, section IV.B): a random object at a random pose of the
server grid. The query is the distance curve of that view **rendered from the object's
stored mesh** (not its stored curve: in a skimmed db a pruned view's stored stand-in is a
different, same-shaped view, and the query must be the same for S1–S6).

``photo``: a synthetic photograph (:mod:`viewdb.bench.photos`) written as a JPEG file and
queried through the whole image path (segmentation, in-plane turns, plan).

Query sets are kept under ``out/queries``; a later run with the same settings reads them
back instead of rendering again.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..api import ViewDB
from ..catalogue.features import distance_curve
from ..errors import FeatureError, ViewDBError
from ..recognition.options import QueryOptions
from ..recognition.pipeline import segment_query
from .photos import PhotoSpec, draw_photo_spec, encode_jpeg, render_photo

__all__ = ["GridQuery", "PhotoQuery", "grid_queries", "photo_queries", "turned_stacks"]

#: Draws allowed per query before giving up (a view without a silhouette is redrawn).
MAX_DRAWS = 50


@dataclass(frozen=True)
class GridQuery:
    object: str
    azimuth: float
    elevation: float
    curve: NDArray[np.float64]


@dataclass(frozen=True)
class PhotoQuery:
    object: str
    spec: PhotoSpec
    path: Path


def _key(kind: str, names: list[str], count: int, seed: int, extra: str) -> str:
    import hashlib

    digest = hashlib.sha256("\n".join(names).encode()).hexdigest()[:10]
    return f"{kind}-n{count}-seed{seed}-{extra}-{digest}"


def grid_queries(
    db: ViewDB, names: list[str], count: int, seed: int, folder: Path,
    progress: Callable[[int, int], None] | None = None,
) -> list[GridQuery]:
    """``count`` grid queries over objects ``names`` (sorted) of ``db``."""
    gap = db.config.gap
    samples = db.config.features.curve_samples
    path = folder / (_key("grid", names, count, seed, f"g{gap:g}") + ".npz")
    if path.exists():
        data = np.load(path, allow_pickle=False)
        spec = json.loads(str(data["spec"]))
        return [GridQuery(n, h, v, c) for (n, h, v), c in zip(spec, data["curves"], strict=True)]
    rng = np.random.default_rng(seed)
    steps = round(360.0 / gap)
    out: list[GridQuery] = []
    draws = 0
    while len(out) < count:
        draws += 1
        if draws > MAX_DRAWS * count:
            raise ViewDBError("too many grid views without a silhouette", db.path)
        name = names[int(rng.integers(len(names)))]
        h, v = float(rng.integers(steps) * gap), float(rng.integers(steps) * gap)
        try:
            curve = distance_curve(db.render(name, h, v).mask, samples)
        except FeatureError:
            continue
        out.append(GridQuery(name, h, v, curve))
        if progress is not None:
            progress(len(out), count)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".partial.npz")
    np.savez(tmp, spec=json.dumps([[q.object, q.azimuth, q.elevation] for q in out]),
             curves=np.stack([q.curve for q in out]))
    os.replace(tmp, path)
    return out


def photo_queries(
    db: ViewDB, names: list[str], count: int, seed: int, folder: Path, image_size: int = 256,
    progress: Callable[[int, int], None] | None = None,
) -> list[PhotoQuery]:
    """``count`` synthetic photos of objects ``names`` of ``db``, written as JPEG files."""
    key = _key("photo", names, count, seed, f"s{image_size}")
    where = folder / key
    index = where / "queries.json"
    if index.exists():
        specs = [PhotoSpec.from_dict(d) for d in json.loads(index.read_text())]
        return [PhotoQuery(s.object, s, where / f"{i:05d}.jpg") for i, s in enumerate(specs)]
    where.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed + 1_000_003)  # not the grid set's stream
    out: list[PhotoQuery] = []
    for i in range(count):
        spec = draw_photo_spec(rng, names[int(rng.integers(len(names)))], image_size)
        photo = where / f"{i:05d}.jpg"
        photo.write_bytes(encode_jpeg(render_photo(db.mesh(spec.object), spec), spec.jpeg_quality))
        out.append(PhotoQuery(spec.object, spec, photo))
        if progress is not None:
            progress(i + 1, count)
    tmp = index.with_suffix(".partial")
    tmp.write_text(json.dumps([q.spec.to_dict() for q in out], indent=1))
    os.replace(tmp, index)  # the set is complete only once its index exists
    return out


def turned_stacks(db: ViewDB, photos: list[NDArray[np.uint8]], turns: int = QueryOptions().rotations
                  ) -> list[NDArray[np.float64]]:
    """Each photo's ``turns`` in-plane turned query curves, ``(turns, N)``, as a query's
    search receives them; a photo that cannot be segmented is left out."""
    samples = db.config.features.curve_samples
    out = []
    for photo in photos:
        try:
            out.append(np.stack([c for _, c in segment_query(photo, samples, turns).curves]))
        except ViewDBError:
            continue
    return out
