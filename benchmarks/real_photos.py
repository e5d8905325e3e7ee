"""Real photographs queried with box prompts: the YCB-Video objects, the ViSP tea box and
cube and the phone box, against the whole catalogue.

    python benchmarks/real_photos.py [--db FILE | --gap 10 [--perspective-gap 10] [--subset N] [--jobs 2]]
                                     [--out DIR] [-k 5] [--plan fast] [--objects A,B] [--no-extras]
                                     [--overlays docs/results/real] [--rerank]

The catalogue (``--db``, e.g. a copy of the 212-model 10° file with the real meshes
ingested into it; else built into ``DIR/catalogue_g{gap}[_sN].db`` from the 7 YCB-Video
meshes, the ViSP tea box and cube, the phone box and ``../shared/models``). Then:

* **YCB-Video**: each frame is queried once with the boxes of its box file
  (``*-box.txt``: ``name x1 y1 x2 y2``) as prompts, no label map, with the ``gt.json``
  intrinsics, default options (with ``--rerank``, a study: the top k fitted in the
  calibrated camera, re-ranked by silhouette IoU and every one posed). Per
  object: the rank of the exact mesh and of the first copy of the same object (the
  catalogue holds a second copy of every one of these 7 scans, from another source and
  in another frame: :data:`TWINS`), the IoU of the box's cut-out with the label map's
  object, the symmetry-aware rotation and translation errors (below) of the exact mesh's
  pose among the results, and of :meth:`viewdb.ViewDB.estimate_pose` from the box's
  cut-out (the object given), and the time per object (the call's wall and CPU time over
  its objects).
* **Without ground truth**: the tea box (two frames), the cube and the phone box, each
  queried with the box of ``benchmarks/data/real_boxes.json`` drawn around it: the rank
  of its mesh, the top result and the IoU of its pose's silhouette.

Overlays (:meth:`viewdb.QueryResult.overlay`: each object's best result drawn over the
photo) go to ``--overlays`` (default ``DIR/overlays``); the table to
``DIR/real_photos.md`` and ``.json``.

Symmetry-aware rotation error. The meshes are untextured, so a pose can only be known up
to the mesh's own shape symmetries. These are found from the mesh
(:func:`viewdb.bench.groundtruth.symmetries`):
rotations about the bounding-box centre, about its principal axes, that map the surface
onto itself within 2 % of its diameter (mean nearest-neighbour distance between 10,000
surface samples and their turned copy, both ways; the samples' own spacing is about 1 %). If
every turn about an axis does (a cylinder), the error is the angle between the estimated
and true directions of that axis (also up to a flip when a half turn across it is a
symmetry); otherwise it is the smallest rotation angle of ``R_estᵀ · R_gt · S`` over the
finite group ``S`` found. The plain error (no symmetry) is in the JSON. Translation error:
distance between the estimated and true positions of the bounding-box centre in the camera
(which the symmetries fix).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np

import viewdb
from viewdb.bench.groundtruth import TWINS, load_model, pose_errors
from viewdb.config import DEFAULT_PLAN

ROOT = Path(__file__).resolve().parent.parent
#: The shared data: ``../shared`` beside the checkout, or ``$VIEWDB_SHARED``.
SHARED = Path(os.environ.get("VIEWDB_SHARED", ROOT.parent / "shared"))
REAL = SHARED / "real"
YCB = REAL / "ycb_video_2frames"
MODELS = SHARED / "models"

#: The cases without ground truth: mesh, intrinsics (from each case's notes.md), and per
#: photo the box drawn around the object.
BOXES = ROOT / "benchmarks" / "data" / "real_boxes.json"


# ---------------------------------------------------------------------- the run
def build(db_path: Path, gap: float, subset: int | None, extras: bool, jobs: int,
          perspective_gap: float | None = None) -> float:
    paths = [YCB / "meshes"]
    if extras:
        paths += [REAL / case / entry["mesh"] for case, entry in _boxes().items()]
    paths = viewdb.describe_paths(paths)
    models = viewdb.describe_paths([MODELS])
    paths += models[:subset] if subset is not None else models
    start = time.perf_counter()
    with viewdb.open(db_path, gap=gap, perspective_gap=perspective_gap) as db:
        report = db.ingest(paths, jobs=jobs)
        for o in report.failed:
            print(f"warning: {o.path}: {o.error}", file=sys.stderr)
    return time.perf_counter() - start


def _boxes() -> dict:
    return json.loads(BOXES.read_text())["cases"]


def _rank(results: list, names: tuple[str, ...]) -> int | None:
    for r in results:
        if r.object in names:
            return r.rank
    return None


def _write_overlay(result: viewdb.QueryResult, path: Path) -> str:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(result.overlay(), cv2.COLOR_RGB2BGR))
    return str(path)


def _study(rerank: bool) -> dict:
    """The query options besides the defaults: none, or for ``--rerank`` (a study) the
    re-ranking by silhouette IoU with every result posed."""
    return {"rerank": True, "pose_top": None} if rerank else {}


def _timed_query(db: viewdb.ViewDB, photo: Path, **kwargs) -> tuple[viewdb.QueryResult, float, float]:
    wall, cpu = time.perf_counter(), time.process_time()
    result = db.query(photo, **kwargs)
    return result, time.perf_counter() - wall, time.process_time() - cpu


def run_ycb(db: viewdb.ViewDB, k: int, plan: str, overlays: Path, objects: list[str] | None = None,
            progress=print, rerank: bool = False) -> list[dict]:
    gt = json.loads((YCB / "gt.json").read_text())
    rows = []
    for frame_id, frame in gt["frames"].items():
        K = np.asarray(frame["K"])
        intr = (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        color = YCB / frame["color"]
        labels = cv2.imread(str(YCB / frame["label"]), cv2.IMREAD_UNCHANGED)
        boxes = {line.split()[0]: [float(v) for v in line.split()[1:]]
                 for line in (YCB / f"{frame_id}-box.txt").read_text().splitlines() if line.strip()}
        chosen = [o for o in frame["objects"] if objects is None or o["name"] in objects]
        if not chosen:
            continue
        result, wall, cpu = _timed_query(db, color, k=k, plan=plan, boxes=[boxes[o["name"]] for o in chosen],
                                         intrinsics=intr, **_study(rerank))
        _write_overlay(result, overlays / f"ycb_{frame_id}.png")
        for obj, entry in zip(chosen, result.objects, strict=True):
            name = obj["name"]
            same = (name, *TWINS.get(name, ()))
            sym = load_model(YCB / obj["mesh"]).symmetry
            r_gt, t_gt = np.asarray(obj["R"]), np.asarray(obj["t"])
            truth = labels == int(obj["class_index"])
            cut = entry.region.mask
            row: dict = {
                "frame": frame_id, "object": name, "symmetry": sym.describe(),
                "box_iou": float((cut & truth).sum() / (cut | truth).sum()),
                "rank": _rank(entry.results, (name,)), "rank_same": _rank(entry.results, same),
                "top": entry.results[0].object if entry.results else None,
                "seconds": entry.timing_ms["total"] / 1e3, "frame_seconds": wall, "frame_cpu_seconds": cpu,
                "objects_in_frame": len(chosen),
            }
            mine = [r for r in entry.results if r.object == name and r.pose is not None]
            if mine:
                p = mine[0].pose
                row["pose"] = {**pose_errors(sym, p.rotation, p.translation, r_gt, t_gt), "iou": p.iou}
            t0 = time.perf_counter()
            est = db.estimate_pose(color, name, intr, mask=cut)
            row["known_pose_seconds"] = time.perf_counter() - t0
            errors = pose_errors(sym, est.rotation, est.translation, r_gt, t_gt)
            row["known_pose"] = {**errors, "iou": est.iou}
            rows.append(row)
            rotation = row.get("pose", {}).get("rotation_deg")
            progress(f"{frame_id} {name}: rank {row['rank']}/{row['rank_same']} (top {row['top']}), box IoU "
                     f"{row['box_iou']:.3f}, pose {_fmt(rotation, '.1f')} deg, {row['seconds']:.1f} s")
    return rows


def run_extras(db: viewdb.ViewDB, k: int, plan: str, overlays: Path, progress=print,
               rerank: bool = False) -> list[dict]:
    rows = []
    for case, entry in _boxes().items():
        name = Path(entry["mesh"]).stem
        for photo_name, box in entry["photos"].items():
            path = REAL / case / photo_name
            row: dict = {"case": case, "photo": photo_name, "object": name, "box": box}
            try:
                result, wall, cpu = _timed_query(db, path, k=k, plan=plan, boxes=[box],
                                                 intrinsics=tuple(entry["intrinsics"]), **_study(rerank))
                found = result.objects[0]
                row.update(rank=_rank(found.results, (name,)), top=found.results[0].object,
                           seconds=wall, cpu_seconds=cpu, area=found.region.area)
                top = found.results[0].pose
                row["iou"] = None if top is None else top.iou
                file = _write_overlay(result, overlays / f"{case}_{Path(photo_name).stem}.png")
                row["overlay"] = file
            except viewdb.ViewDBError as exc:
                row["error"] = str(exc)
            rows.append(row)
            progress(f"{case} {photo_name}: rank {row.get('rank')} (top {row.get('top')}), IoU "
                     f"{_fmt(row.get('iou'), '.3f')}" + (f" {row['error']}" if "error" in row else ""))
    return rows


def _fmt(x: float | int | None, spec: str = "") -> str:
    return "–" if x is None else format(x, spec)


def _pose_cells(pose: dict | None) -> str:
    if not pose:
        return "– | – | –"
    return f"{pose['rotation_deg']:.1f} | {pose['translation_mm']:.1f} | {_fmt(pose.get('iou'), '.3f')}"


def markdown(summary: dict) -> str:
    ranking = ("re-ranked by perspective silhouette IoU (a study)" if summary.get("rerank")
               else "default options")
    lines = [f"Catalogue: {summary['objects']} objects, gap {summary['gap']:g}°; plan {summary['plan']}, "
             f"k = {summary['k']} {ranking}. Rank: exact mesh / first copy of the same object.", "",
             "| frame | object | symmetry | box IoU | rank | top result | rot. err (°) | trans. err (mm) | "
             "IoU | object given: rot. (°) | trans. (mm) | IoU | s per object |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in summary["ycb"]:
        lines.append(f"| {r['frame']} | {r['object']} | {r['symmetry']} | {r['box_iou']:.3f} | "
                     f"{_fmt(r['rank'])} / {_fmt(r['rank_same'])} | {r['top']} | "
                     f"{_pose_cells(r.get('pose'))} | {_pose_cells(r['known_pose'])} | {r['seconds']:.1f} |")
    t = summary["totals"]
    lines += ["", f"Same object first {t['first_same']}/{t['n']}, exact mesh first {t['first']}/{t['n']}; "
              f"rotation error of the exact mesh's pose among the results: median "
              f"{_fmt(t['median_rotation_deg'], '.1f')}°, max {_fmt(t['max_rotation_deg'], '.1f')}° "
              f"({t['posed']}/{t['n']} posed); translation median "
              f"{_fmt(t['median_translation_mm'], '.1f')} mm. "
              f"Object given: median {t['known_median_rotation_deg']:.1f}°, max "
              f"{t['known_max_rotation_deg']:.1f}°. Time per object: median {t['median_seconds']:.1f} s wall "
              f"({t['median_cpu_seconds']:.1f} s CPU: each frame's query over its objects)."]
    if summary.get("extras"):
        lines += ["", "| case | photo | box | rank of its mesh | top result | IoU of its pose | s |",
                  "|---|---|---|---|---|---|---|"]
        for r in summary["extras"]:
            lines.append(f"| {r['case']} | {r['photo']} | {','.join(str(v) for v in r['box'])} | "
                         f"{_fmt(r.get('rank'))} | {r.get('top', '–')} | {_fmt(r.get('iou'), '.3f')} | "
                         f"{_fmt(r.get('seconds'), '.1f')} |" + (f" {r['error']}" if "error" in r else ""))
    return "\n".join(lines) + "\n"


def _totals(ycb: list[dict]) -> dict:
    posed = [r["pose"] for r in ycb if r.get("pose")]
    rot = [p["rotation_deg"] for p in posed]

    def median(values: list[float]) -> float | None:
        return float(np.median(values)) if values else None

    return {
        "n": len(ycb), "first": sum(r["rank"] == 1 for r in ycb),
        "first_same": sum(r["rank_same"] == 1 for r in ycb), "posed": len(posed),
        "median_rotation_deg": median(rot), "max_rotation_deg": max(rot) if rot else None,
        "median_translation_mm": median([p["translation_mm"] for p in posed]),
        "known_median_rotation_deg": float(np.median([r["known_pose"]["rotation_deg"] for r in ycb])),
        "known_max_rotation_deg": float(np.max([r["known_pose"]["rotation_deg"] for r in ycb])),
        "median_seconds": float(np.median([r["seconds"] for r in ycb])),
        "median_cpu_seconds": float(np.median([r["frame_cpu_seconds"] / r["objects_in_frame"] for r in ycb])),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--db", type=Path, default=None, help="an existing catalogue (else built)")
    parser.add_argument("--gap", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "real_photos")
    parser.add_argument("--overlays", type=Path, default=None,
                        help="where the overlays go (default OUT/overlays)")
    parser.add_argument("--subset", type=int, default=None, help="only the first N catalogue models")
    parser.add_argument("--plan", default=DEFAULT_PLAN)
    parser.add_argument("-k", type=int, default=5, help="results per object (default: the library's)")
    parser.add_argument("--objects", default=None, help="comma-separated YCB objects (default: all)")
    parser.add_argument("--no-extras", action="store_true", help="skip the ViSP and phone-box cases")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--perspective-gap", type=float, default=None,
                        help="the built catalogue's perspective grid gap (default the file default, 10)")
    parser.add_argument("--rerank", action="store_true",
                        help="a study: re-rank by perspective silhouette IoU, every result posed "
                             "(the default options do not)")
    args = parser.parse_args()
    if not YCB.is_dir():
        sys.exit(f"real_photos: {YCB} not found")
    args.out.mkdir(parents=True, exist_ok=True)
    overlays = args.overlays or args.out / "overlays"
    db_path = args.db
    build_s = 0.0
    if db_path is None:
        db_path = args.out / (f"catalogue_g{args.gap:g}{'' if args.subset is None else f'_s{args.subset}'}"
                              f"{'' if args.perspective_gap is None else f'_p{args.perspective_gap:g}'}.db")
        build_s = build(db_path, args.gap, args.subset, not args.no_extras, args.jobs, args.perspective_gap)
        print(f"catalogue {db_path} ready in {build_s:.0f} s", flush=True)
    objects = args.objects.split(",") if args.objects else None
    with viewdb.open(db_path, create=False) as db:
        n_objects, gap = len(db.objects()), db.config.gap
        ycb = run_ycb(db, args.k, args.plan, overlays, objects, lambda m: print(m, flush=True),
                      args.rerank)
        extras = [] if args.no_extras else run_extras(db, args.k, args.plan, overlays,
                                                      lambda m: print(m, flush=True), args.rerank)
    summary = {"gap": gap, "k": args.k, "plan": args.plan, "rerank": args.rerank, "objects": n_objects,
               "catalogue": str(db_path),
               "build_seconds": build_s, "ycb": ycb, "extras": extras, "totals": _totals(ycb)}
    (args.out / "real_photos.json").write_text(json.dumps(summary, indent=1))
    table = markdown(summary)
    (args.out / "real_photos.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
