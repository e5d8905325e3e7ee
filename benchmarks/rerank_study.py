"""How the re-ranking's pool and weights decide rank-1, measured on the synthetic photos.

    python benchmarks/rerank_study.py DB [--seeds 1-6] [--photos 40] [--shortlist 30]
                                         [--pools 5,10,15,20] [--colour-weights 0,0.5,1,2]
                                         [--shape-weights 0,4,8,12] [--fits view]
                                         [--cache FILE.json]

Each photo of ``benchmarks/photo_accuracy.py`` (same seed, same photos) is segmented and
searched once by outline (``server`` plan, ``--rotations`` in-plane turns, no re-ranking) for its best
``--shortlist`` objects; the colour distance and the shape fit of each one's matched view
are measured once (:meth:`viewdb.recognition.local_tier.LocalServerTier.view_colours`,
``view_fits``: what the query's re-rankings compute). Every variant (pool × colour weight ×
shape weight) then re-ranks the first ``pool`` objects of the shortlist exactly as the query
does (:func:`viewdb.recognition.colour.rerank_by_colour`, then
:func:`viewdb.recognition.verify.rerank_by_fit`), so the variants are compared on the same
searches. ``--fits`` names the shape fits compared (each another variant): ``view``, the
query's (the matched grid view's outline and internal edges); ``outline``, the same view's
outline alone; ``perspective``, the outline of the silhouette the search matched (a
perspective view's, scan-converted from the mesh; an orthographic match's grid view).
Printed: rank-1 and rank-5 per variant and seed group, and how many of the right
objects the shortlist holds at each pool size (the ceiling a re-ranking of that pool can
reach). ``--cache`` keeps the measured shortlists (JSON) and reads them back when the file
exists with the same settings.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

import viewdb
from viewdb.bench.photos import decoded_photo, parse_seeds, photo_series
from viewdb.catalogue.render import get_renderer
from viewdb.config import PoseConfig
from viewdb.errors import PoseError
from viewdb.pose.matched import appearance_view
from viewdb.pose.shape_pose import shape_fit
from viewdb.pose.views import CandidateView, QueryView
from viewdb.recognition.colour import colour_distance, colour_signature, has_colour, rerank_by_colour
from viewdb.recognition.pipeline import segment_photo
from viewdb.recognition.verify import physical_view, rerank_by_fit
from viewdb.search.plans import Candidate
from viewdb.storage.stored_catalogue import StoredCatalogue

#: The shape fits ``--fits`` can compare.
FITS = ("view", "outline", "perspective")
POSE = PoseConfig()


def floats(text: str) -> list[float]:
    return [float(x) for x in text.split(",")]


def ints(text: str) -> list[int]:
    return [int(x) for x in text.split(",")]


def outline_fit(
    catalogue: StoredCatalogue, query: QueryView, match: Candidate, perspective: bool
) -> float | None:
    """How well the match's silhouette explains the query's outline (its internal edges
    left out): the grid view's (:func:`physical_view`) or, with ``perspective``, the
    perspective silhouette the search matched, mirrored when the match was."""
    azimuth, elevation = physical_view(match)
    try:
        grid = appearance_view(catalogue, match.object, azimuth, elevation, POSE)
        mask = grid.mask
        if perspective and match.camera_distance is not None:
            renderer = get_renderer(catalogue.config.render)
            seen = renderer.perspective_mask(catalogue.mesh(match.object), match.azimuth, match.elevation,
                                             match.camera_distance)
            mask = np.ascontiguousarray(seen[:, ::-1] if match.mirrored else seen)
        view = CandidateView(azimuth, elevation, False, grid.keypoints, grid.descriptors, grid.points3d,
                             mask=mask, image_size=grid.image_size)
        return shape_fit(query, view, POSE)
    except PoseError:
        return None


def measure(
    db: viewdb.ViewDB, seed: int, photos: int, shortlist: int, rotations: int, fits_wanted: list[str]
) -> list[dict[str, Any]]:
    """Each photo's object and its outline shortlist with colour distances and fits."""
    names = [o.name for o in db.objects()]
    tier = db.server_tier()
    out = []
    for i, spec in enumerate(photo_series(names, seed, photos)):
        photo = decoded_photo(db.mesh(spec.object), spec)
        start = time.perf_counter()
        found = db.query(photo, k=shortlist, pose=False, colour=False, verify=False,
                         rotations=rotations).results
        searched = time.perf_counter()
        view = segment_photo(photo)[2]
        views = [(m.object, *physical_view(m)) for m in found]  # type: ignore[arg-type]
        colours = tier.view_colours(views)
        query = colour_signature(view.color, view.mask)
        fits = {"view": tier.view_fits(view, views)}
        reranked = time.perf_counter()  # what the query's re-rankings take; the other fits are extra
        for source in fits_wanted:
            if source != "view":
                fits[source] = [outline_fit(tier.catalogue, view, m, source == "perspective") for m in found]
        out.append({
            "seed": seed, "index": i, "object": spec.object, "coloured": has_colour(view.color),
            "search_ms": (searched - start) * 1e3, "rerank_ms": (reranked - searched) * 1e3,
            "shortlist": [{"object": m.object, "distance": m.distance,
                           "colour": None if s is None else colour_distance(query, s),
                           **{f"fit_{source}": f[j] for source, f in fits.items()}}
                          for j, (m, s) in enumerate(zip(found, colours, strict=True))],
        })
        print(f"seed {seed} {i:3d} {spec.object:32s} outline rank "
              f"{next((m.rank for m in found if m.object == spec.object), '-')}", flush=True)
    return out


def ranked(photo: dict[str, Any], pool: int, colour_weight: float, shape_weight: float,
           source: str = "view") -> list[str]:
    """The photo's answer under one variant: the shortlist's first ``pool`` re-ranked as the
    query re-ranks them, then the rest of the shortlist by outline."""
    head = photo["shortlist"][:pool]
    names = [c["object"] for c in head]
    distances = [c["distance"] for c in head]
    scores = distances
    if photo["coloured"] and colour_weight > 0:
        order, coloured = rerank_by_colour(distances, [c["colour"] for c in head], colour_weight)
        names, scores = [names[i] for i in order], [coloured[i] for i in order]
        head = [head[i] for i in order]
    if shape_weight > 0 and len(head) > 1:
        order, _ = rerank_by_fit(scores, [c[f"fit_{source}"] for c in head], shape_weight)
        names = [names[i] for i in order]
    return names + [c["object"] for c in photo["shortlist"][pool:]]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--seeds", default="1-6")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--shortlist", type=int, default=30)
    parser.add_argument("--rotations", type=int, default=viewdb.QueryOptions().rotations,
                        help="in-plane turns searched (1: upright)")
    parser.add_argument("--pools", default="5,10,15,20")
    parser.add_argument("--colour-weights", default="0,0.5,1,2")
    parser.add_argument("--shape-weights", default="0,4,8,12")
    parser.add_argument("--fits", default="view",
                        help=f"the shape fits compared, any of {','.join(FITS)}")
    parser.add_argument("--cache")
    args = parser.parse_args()
    sources = args.fits.split(",")
    if not set(sources) <= set(FITS):
        parser.error(f"--fits: expected some of {','.join(FITS)}, got {args.fits!r}")
    key = {"db": str(Path(args.db).resolve()), "seeds": parse_seeds(args.seeds), "photos": args.photos,
           "shortlist": args.shortlist, "rotations": args.rotations, "fits": sorted(sources)}
    cache = Path(args.cache) if args.cache else None
    if cache is not None and cache.exists() and json.loads(cache.read_text())["key"] == key:
        photos = json.loads(cache.read_text())["photos"]
    else:
        db = viewdb.open(args.db, read_only=True)
        photos = [p for s in key["seeds"]
                  for p in measure(db, s, args.photos, args.shortlist, args.rotations, sources)]
        if cache is not None:
            cache.write_text(json.dumps({"key": key, "photos": photos}))
    by_seed: dict[int, list[dict[str, Any]]] = {}
    for p in photos:
        by_seed.setdefault(p["seed"], []).append(p)
    print(f"\n{len(photos)} photos; outline shortlist of {args.shortlist}")
    for pool in ints(args.pools):
        inside = np.mean([answer_rank(p, pool, 0.0, 0.0, "view") in range(1, pool + 1) for p in photos])
        print(f"right object within the outline's best {pool}: {inside * 100:.1f} %")
    per_seed = " | ".join(f"seed {s} r1" for s in by_seed)
    print(f"\n| fit | pool | colour w | shape w | rank-1 | rank-5 | {per_seed} |")
    print("|---|---|---|---|---|---|" + "---|" * len(by_seed))
    variants = itertools.product(sources, ints(args.pools), floats(args.colour_weights),
                                 floats(args.shape_weights))
    for source, pool, wc, ws in variants:
        r = np.array([answer_rank(p, pool, wc, ws, source) for p in photos])
        per = " | ".join(f"{np.mean([answer_rank(p, pool, wc, ws, source) == 1 for p in ps]) * 100:.0f}"
                         for ps in by_seed.values())
        print(f"| {source} | {pool} | {wc:g} | {ws:g} | {np.mean(r == 1) * 100:.1f} % | "
              f"{np.mean((r >= 1) & (r <= 5)) * 100:.1f} % | {per} |")


def answer_rank(photo: dict[str, Any], pool: int, wc: float, ws: float, source: str) -> int:
    names = ranked(photo, pool, wc, ws, source)
    return names.index(photo["object"]) + 1 if photo["object"] in names else 0


if __name__ == "__main__":
    main()
