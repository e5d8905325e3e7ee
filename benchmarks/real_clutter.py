"""Real photos in clutter: every annotated object queried from the box of its visible part.

    python benchmarks/real_clutter.py --db CATALOGUE [--sets lmo_dev,ycb_video_2frames]
                                      [--frames N] [--out DIR] [--overlays DIR]

The photo sets with official 6-D ground truth in ``../shared/real`` (``$VIEWDB_SHARED``):
``lmo_dev`` (40 LM-O photos of a cluttered desk, 305 posed instances, BOP visible
fractions and visible-part boxes) and ``ycb_video_2frames`` (two YCB-Video frames, boxes
from their ``*-box.txt``). Each photo is queried **once, with default options**, with the
boxes of all its annotated objects as prompts and the photo's intrinsics, as an
application with a detector would: ``db.query(photo, boxes=..., intrinsics=K)``. A photo
with a depth image (the YCB-Video frames) is queried a second time with it (``depth=``),
its rows in the set ``NAME + depth``.

Per object:

* **rank** of the right object among the answer's results: the exact mesh, and the first
  copy of the same object (the catalogue holds a second copy of some real objects from
  another source, e.g. ``linemod_ape``: no silhouette tells such twins apart);
* **pose**, when the top result is the right object (a twin's pose is carried into the
  exact mesh's frame and units through the alignment of their normalised surfaces,
  :func:`viewdb.bench.twins.rigid_alignment`: the copies differ in axes and units): ADD (asymmetric) or ADD-S
  (symmetric: those ``gt.json`` lists, else a mesh whose surface maps onto itself under a
  rotation, :func:`viewdb.bench.groundtruth.symmetries`) within 0.1 × the mesh's diameter;
  the symmetry-aware rotation error; the translation error of the bounding-box centre;
* **cut IoU**: the query's cut-out against the visible mask rendered from the ground
  truth (:func:`viewdb.bench.groundtruth.visible_masks`);
* **seconds per object**: the frame's query wall time over its objects;
* the **visibility band** (BOP's visible fraction: ≥ 80 %, 50–80 %, 20–50 %, < 20 %;
  for the YCB-Video frames the modelled one).

Each miss gets a cause: ``cut`` (the cut-out's IoU with the visible mask under 0.5),
``search`` (the right object not among the results), ``re-ranking`` (among them, not
first), ``pose`` (first, but outside 0.1 × diameter). The table goes to
``OUT/real_clutter.md``, the rows to ``OUT/real_clutter.json``; ``--overlays`` draws each
photo's answers.
"""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

import viewdb
from support.real import (
    band_of,
    by_group,
    each_frame,
    is_symmetric,
    median,
    pose_row,
    set_arguments,
    share,
    twin_pose,
    visibility,
    write_results,
)
from viewdb.bench.groundtruth import TWINS, Frame, mask_iou, visible_masks


def _rank(results: list, names: tuple[str, ...]) -> int | None:
    return next((m.rank for m in results if m.object in names), None)


def _pose_of_top(db: viewdb.ViewDB, inst, match, symmetric: bool) -> dict:
    """The errors of the top result's pose (the right object, or its twin: its pose then
    carried into the exact mesh's frame and units, :func:`support.real.twin_pose`)."""
    pose = match.pose
    if pose is None or pose.rotation is None or pose.translation is None:
        return {"posed": False}
    rotation, translation = pose.rotation, pose.translation
    if match.object != inst.mesh.stem:
        rotation, translation = twin_pose(db, match.object, inst.mesh.stem, rotation, translation)
    return pose_row(inst, rotation, translation, symmetric)


def _cause(row: dict) -> str | None:
    if row["rank_same"] == 1:
        return None if row["pose"].get("add_ok") else "pose"
    if row["cut_iou"] < 0.5:
        return "cut"
    return "search" if row["rank_same"] is None else "re-ranking"


def run_frame(db: viewdb.ViewDB, set_name: str, frame: Frame, symmetric: set[str],
              overlays: Path | None, **options) -> list[dict]:
    """Query one photo with all its boxes (``options``: its depth image, or other query
    options than the defaults, for studies); a row per annotated object."""
    masks = visible_masks(frame)
    # a box under 4 pixels wide or high (a sliver at the photo's edge) is degenerate: it
    # is refused alone, and the others are queried
    sent = [i for i, inst in enumerate(frame.instances)
            if min(inst.box[2] - inst.box[0], inst.box[3] - inst.box[1]) >= 4]
    start = time.perf_counter()
    try:
        result = db.query(frame.photo, boxes=[list(frame.instances[i].box) for i in sent],
                          intrinsics=frame.intrinsics, **options)
        error = None
    except viewdb.ViewDBError as exc:
        result, error = None, str(exc)
    wall = time.perf_counter() - start
    if result is not None and overlays is not None:
        overlays.mkdir(parents=True, exist_ok=True)
        picture = overlays / f"{set_name.replace(' + ', '_')}_{frame.name}.png"
        cv2.imwrite(str(picture), result.overlay()[:, :, ::-1])
    rows = []
    for i, (inst, (whole, visible)) in enumerate(zip(frame.instances, masks, strict=True)):
        exact = inst.mesh.stem
        same = (exact, *TWINS.get(exact, ()))
        vis = visibility(inst, whole, visible)
        row: dict = {"set": set_name, "frame": frame.name, "object": inst.name, "visibility": vis,
                     "band": band_of(vis), "box": list(inst.box), "seconds": wall / len(frame.instances),
                     "error": error, "rank": None, "rank_same": None, "top": None, "cut_iou": 0.0,
                     "pose": {}}
        if i not in sent:
            row["error"] = f"box {inst.box} is degenerate"
        elif result is not None:
            entry = result.objects[sent.index(i)]
            row.update(rank=_rank(entry.results, (exact,)), rank_same=_rank(entry.results, same),
                       top=entry.results[0].object if entry.results else None,
                       cut_iou=mask_iou(entry.region.mask, visible),
                       object_ms=entry.timing_ms.get("total"))
            if row["rank_same"] == 1:
                row["pose"] = _pose_of_top(db, inst, entry.results[0], is_symmetric(inst, symmetric))
        row["cause"] = _cause(row)
        rows.append(row)
    return rows


def summarise(rows: list[dict]) -> dict:
    """Shares per group: the ≥ 50 % visible objects, each band, and every set."""
    def stats(group: list[dict]) -> dict:
        n = len(group)
        if not n:
            return {"n": 0}
        first = sum(r["rank_same"] == 1 for r in group)
        top5 = sum(r["rank_same"] is not None and r["rank_same"] <= 5 for r in group)
        add = sum(bool(r["pose"].get("add_ok")) for r in group)
        rot = [r["pose"]["rotation_deg"] for r in group if r["pose"].get("posed")]
        shift = [r["pose"]["translation_mm"] for r in group if r["pose"].get("posed")]
        causes: dict[str, int] = {}
        for r in group:
            if r["cause"]:
                causes[r["cause"]] = causes.get(r["cause"], 0) + 1
        refused = sum(r["error"] is not None for r in group)
        return {"n": n, "first": first, "top5": top5, "add": add, "refused": refused,
                "median_rotation_deg": median(rot), "median_translation_mm": median(shift),
                "median_cut_iou": float(np.median([r["cut_iou"] for r in group])),
                "median_seconds": float(np.median([r["seconds"] for r in group])), "causes": causes}

    return by_group(rows, stats)


def markdown(summary: dict, catalogue: str, objects: int) -> str:
    lines = [f"Catalogue: `{catalogue}`, {objects} objects; every photo queried once with the boxes of its "
             "annotated objects and its intrinsics, default options.", "",
             "| set | objects | n | right object first | in the top 5 | ADD(-S) < 0.1 d "
             "| median rot. err (°) | median transl. err (mm) | median cut IoU | s per object (median) "
             "| misses: cut / search / re-ranking / pose |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for set_name, groups in summary.items():
        for group, s in groups.items():
            if not s["n"]:
                continue
            c = s["causes"]
            rot = "–" if s["median_rotation_deg"] is None else f"{s['median_rotation_deg']:.1f}"
            shift = "–" if s["median_translation_mm"] is None else f"{s['median_translation_mm']:.1f}"
            lines.append(f"| {set_name} | {group} | {s['n']} | {share(s['first'], s['n'])} | "
                         f"{share(s['top5'], s['n'])} | {share(s['add'], s['n'])} | {rot} | {shift} | "
                         f"{s['median_cut_iou']:.2f} | {s['median_seconds']:.2f} | "
                         f"{' / '.join(str(c.get(k, 0)) for k in ('cut', 'search', 're-ranking', 'pose'))} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    args = set_arguments("real_clutter", __doc__, lambda parser: parser.add_argument(
        "--overlays", type=Path, default=None, help="draw each photo's answers here"))
    rows: list[dict] = []
    with viewdb.open(args.db, create=False, read_only=True) as db:
        objects = len(db.objects())
        for set_name, symmetric, frame in each_frame(args.sets, args.frames, "real_clutter"):
            inputs = [(set_name, {})]
            if frame.depth is not None:  # the same photo again, with its depth image
                depth = {"depth": frame.depth, "depth_scale": frame.depth_scale}
                inputs.append((f"{set_name} + depth", depth))
            for name, given in inputs:
                new = run_frame(db, name, frame, symmetric, args.overlays, **given)
                rows += new
                done = ", ".join(f"{r['object']} {r['rank_same'] or '-'}" for r in new)
                print(f"{name} {frame.name}: {done} ({new[0]['seconds']:.2f} s per object)", flush=True)
    summary = summarise(rows)
    write_results(args.out, "real_clutter", summary, rows, markdown(summary, str(args.db), objects))


if __name__ == "__main__":
    main()
