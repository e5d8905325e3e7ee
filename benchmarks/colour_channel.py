"""How far a photo's colours alone find its object, and how far its outline alone: the
LM-O box cut-outs against the stored colour signatures of every coloured object, and
against every object's outlines.

    python benchmarks/colour_channel.py --db CATALOGUE [--step 2] [--min-visibility 0.5] [--core 0.1]

Each LM-O photo (every ``--step``-th) is cut from the boxes of its annotated objects as a
query cuts it; each cut-out's colour signature, read from its core as a query reads it
(:func:`viewdb.recognition.colour.core_signature`; ``--core`` another share)
is ranked by the colour channel a query uses (:meth:`StoredCatalogue.colour_index`:
every coloured object's stored views on its default grid), an object's colour distance
being its best view's. Printed: the rank of the right object (or its twin) among the coloured objects by
that distance, as shares at ranks 1, 3, 5 and 10. It measures whether a colour channel
could bring an object the outline search misses into the re-ranked pool
(docs/results/real-clutter.md). Beside it, the rank of the right object by the outline
alone: the exact search of the cut-out's turned curves for its best 60 objects, as a
query's plan searches them (beyond 60: counted as 61).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

import viewdb
from viewdb.bench.groundtruth import TWINS, read_frames
from viewdb.config import RecognitionConfig
from viewdb.recognition.colour import core_signature
from viewdb.recognition.image import load_image
from viewdb.recognition.options import QueryOptions
from viewdb.recognition.pipeline import region_shape
from viewdb.recognition.regions import Prompts, find_regions
from viewdb.search.plans import RefineRequest

#: How deep the outline's ranking is read.
OUTLINE_DEPTH = 60

ROOT = Path(__file__).resolve().parent.parent
SHARED = Path(os.environ.get("VIEWDB_SHARED", ROOT.parent / "shared"))
LMO = SHARED / "real" / "lmo_dev"


def outline_rank(db: viewdb.ViewDB, image, region, same: tuple[str, ...]) -> int:
    """The right object's rank by the cut-out's outline alone (``OUTLINE_DEPTH + 1`` beyond)."""
    options = QueryOptions()
    shape = region_shape(image, region, db.config.features.curve_samples, options)
    stack = np.stack([curve for _, curve in shape.curves])
    reply, _ = db.server_tier().refine(RefineRequest.of_stack(stack, options.band, OUTLINE_DEPTH, []))
    return next((i + 1 for i, c in enumerate(reply.results) if c.object in same), OUTLINE_DEPTH + 1)


def _shares(name: str, ranks: list[int]) -> str:
    r = np.asarray(ranks)
    return (f"by {name} alone first {np.mean(r <= 1):.0%}, best 3 {np.mean(r <= 3):.0%}, "
            f"best 5 {np.mean(r <= 5):.0%}, best 10 {np.mean(r <= 10):.0%}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, required=True)
    parser.add_argument("--step", type=int, default=2, help="every N-th photo")
    parser.add_argument("--min-visibility", type=float, default=0.5)
    parser.add_argument("--core", type=float, default=RecognitionConfig().colour_core,
                        help="the cut-out's colours from its core: eroded by this share of sqrt(area) "
                             "(default: the query's)")
    args = parser.parse_args()
    with viewdb.open(args.db, create=False, read_only=True) as db:
        start = time.perf_counter()
        index = db._catalogue.colour_index()
        print(f"{len(index.objects)} coloured objects of {len(db.objects())}, signatures read in "
              f"{time.perf_counter() - start:.1f} s", flush=True)
        ranks, outline = [], []
        for frame in read_frames(LMO)[::args.step]:
            image = load_image(str(frame.photo))
            chosen = [i for i in frame.instances if (i.visibility or 0.0) >= args.min_visibility
                      and min(i.box[2] - i.box[0], i.box[3] - i.box[1]) >= 4]
            regions = find_regions(image, Prompts.of(boxes=[list(i.box) for i in chosen]))
            for inst, region in zip(chosen, regions, strict=True):
                same = (inst.mesh.stem, *TWINS.get(inst.mesh.stem, ()))
                query = core_signature(image.rgb, region.mask, args.core)
                order = [m.object for m in index.nearest(query, len(index.objects))]
                ranks.append(next((i + 1 for i, n in enumerate(order) if n in same), len(order) + 1))
                outline.append(outline_rank(db, image, region, same))
                print(f"{frame.name} {inst.name}: colour rank {ranks[-1]} (best {order[0]}), "
                      f"outline rank {outline[-1]}", flush=True)
    print(f"{len(ranks)} objects: {_shares('colour', ranks)}; {_shares('outline', outline)}")


if __name__ == "__main__":
    main()
