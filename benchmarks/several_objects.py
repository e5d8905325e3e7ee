"""N objects of one photo in one query, against N separate queries.

    python benchmarks/several_objects.py [--db FILE] [--repeat 2] [--no-pose]

Two photos: three sample objects on a table (``sample_models/``, a 30° catalogue built
in a temporary folder) queried with ``every=True``, and, with ``--db`` (a catalogue
holding the YCB-Video meshes, as ``benchmarks/real_photos.py`` uses), YCB-Video frame
000002 with its four boxes and intrinsics. Each is queried

* **together**: one ``ViewDB.query`` with every object (one decode of the photo, one
  set of tier loads), on a freshly opened file;
* **apart, fresh**: one query per object, each on a freshly opened file, as N ``viewdb
  query`` runs would do (less the interpreter's start);
* **apart, warm**: one query per object on one open file (tiers already loaded).

So that both do the same work per object, the objects are first cut out once (``every``
or the boxes), and then given as a label map: together with ``every=True``, apart with
each ``label`` (each object then knows the others as possible occluders either way).

Prints the wall-clock time of each (best of ``--repeat``) and the ratios apart / together.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import viewdb
from viewdb.bench.photos import table_photo

ROOT = Path(__file__).resolve().parent.parent
SHARED = Path(os.environ.get("VIEWDB_SHARED", ROOT.parent / "shared"))
YCB = SHARED / "real" / "ycb_video_2frames"


def _best(run: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def compare(name: str, db_path: Path, photo: object, found: dict, repeat: int, options: dict) -> None:
    """Time the objects ``found`` (the prompts that cut them out) together and apart."""
    with viewdb.open(db_path, create=False) as db:
        regions = db.query(photo, **found, pose=False, k=1).objects
    labels = np.zeros(regions[0].region.mask.shape, np.uint16)
    for i, entry in enumerate(regions, 1):
        labels[entry.region.mask] = i

    def one_call() -> None:
        with viewdb.open(db_path, create=False) as db:
            db.query(photo, label_map=labels, every=True, **options)

    def fresh() -> None:
        for i in range(1, len(regions) + 1):
            with viewdb.open(db_path, create=False) as db:
                db.query(photo, label_map=labels, label=i, **options)

    with viewdb.open(db_path, create=False) as warm_db:
        warm_db.query(photo, label_map=labels, label=1, **options)  # load the tiers

        def warm() -> None:
            for i in range(1, len(regions) + 1):
                warm_db.query(photo, label_map=labels, label=i, **options)

        t_one, t_fresh, t_warm = _best(one_call, repeat), _best(fresh, repeat), _best(warm, repeat)
    n = len(regions)
    print(f"{name}: {n} objects: together {t_one:.2f} s ({t_one / n:.2f} s per object); apart, fresh "
          f"{t_fresh:.2f} s ({t_fresh / t_one:.2f}x); apart, warm {t_warm:.2f} s ({t_warm / t_one:.2f}x)",
          flush=True)


def table_scene(folder: Path) -> tuple[Path, np.ndarray]:
    from support.samples import sample

    path = folder / "scene.db"
    with viewdb.open(path, gap=30, image_size=256) as db:
        db.ingest([sample(n) for n in ("cube_dice", "car", "mug", "l_bracket", "chair", "arrow")])
        scene = (("car", 40, 20), ("mug", 130, 25), ("cube_dice", 200, 35))
        views = [db.render(n, h, v) for n, h, v in scene]
    photo, _ = table_photo(views, (800, 320), [(10, 40), (280, 20), (540, 50)])
    return path, photo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None, help="a catalogue with the YCB-Video meshes")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--no-pose", action="store_true")
    args = parser.parse_args()
    options = {"k": 3, "pose": not args.no_pose}
    with tempfile.TemporaryDirectory(prefix="viewdb-several-") as folder:
        db_path, photo = table_scene(Path(folder))
        compare("table, every object", db_path, photo, {"every": True}, args.repeat, options)
    if args.db is not None:
        gt = json.loads((YCB / "gt.json").read_text())["frames"]["000002"]
        k = np.asarray(gt["K"])
        intrinsics = (k[0, 0], k[1, 1], k[0, 2], k[1, 2])
        boxes = [[float(v) for v in line.split()[1:]]
                 for line in (YCB / "000002-box.txt").read_text().splitlines() if line.strip()]
        compare("YCB-Video 000002, boxes", args.db, YCB / "000002-color.png", {"boxes": boxes}, args.repeat,
                {**options, "intrinsics": intrinsics})


if __name__ == "__main__":
    main()
