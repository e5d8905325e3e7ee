"""Where real-photo poses are lost: the known object posed from the box's cut-out and from
its true visible silhouette.

    python benchmarks/pose_from_cut.py --db CATALOGUE [--sets lmo_dev,ycb_video_2frames]
                                       [--frames N] [--out DIR]

Recognition aside: every annotated object of the real photo sets (``../shared/real``, as
``benchmarks/real_clutter.py`` reads them) is posed as **the object it is** (the library's
``db.estimate_pose``, default options, the photo's intrinsics) twice:

* from the **cut-out** a box query makes of it (each photo queried once with all its
  visible-part boxes, default options: the mask the answer reports), and
* from its **true visible silhouette** (rendered from the ground truth, occluders removed);
* and, for a photo with a depth image (the YCB-Video frames), from the cut-out again with
  the depth image (``depth=``), which sets the pose's distance.

Per set and visibility band it reports ADD(-S) within 0.1 × diameter, the median
symmetry-aware rotation error and the median cut IoU. The gap between the two rows is what
the cut costs the pose; the second row is the silhouette fit's ceiling on these photos. The
table goes to ``OUT/pose_from_cut.md``, the rows to ``OUT/pose_from_cut.json``.
"""

from __future__ import annotations

import time

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
    visibility,
    write_results,
)
from viewdb.bench.groundtruth import Frame, mask_iou, visible_masks


def _posed(db: viewdb.ViewDB, frame: Frame, inst, mask: np.ndarray, symmetric: bool,
           depth: bool = False) -> dict:
    """The known object posed from ``mask`` (no recognition), with its errors; ``depth``:
    with the frame's depth image."""
    if not mask.any():
        return {"posed": False, "why": "empty mask"}
    start = time.perf_counter()
    with_depth = {"depth": frame.depth, "depth_scale": frame.depth_scale} if depth else {}
    try:
        est = db.estimate_pose(frame.photo, inst.mesh.stem, frame.intrinsics,
                               mask=mask.astype(np.uint8) * 255, **with_depth)
    except viewdb.ViewDBError as exc:
        return {"posed": False, "why": str(exc)}
    seconds = time.perf_counter() - start
    return {**pose_row(inst, est.rotation, est.translation, symmetric), "seconds": seconds}


def run_frame(db: viewdb.ViewDB, set_name: str, frame: Frame, symmetric: set[str]) -> list[dict]:
    masks = visible_masks(frame)
    sent = [i for i, inst in enumerate(frame.instances)
            if min(inst.box[2] - inst.box[0], inst.box[3] - inst.box[1]) >= 4]
    try:
        result = db.query(frame.photo, boxes=[list(frame.instances[i].box) for i in sent],
                          intrinsics=frame.intrinsics)
        cuts = {i: result.objects[j].region.mask for j, i in enumerate(sent)}
    except viewdb.ViewDBError:
        cuts = {}
    rows = []
    for i, (inst, (whole, visible)) in enumerate(zip(frame.instances, masks, strict=True)):
        vis = visibility(inst, whole, visible)
        sym = is_symmetric(inst, symmetric)
        cut = cuts.get(i)
        rows.append({"set": set_name, "frame": frame.name, "object": inst.name, "visibility": vis,
                     "band": band_of(vis), "cut_iou": mask_iou(cut, visible) if cut is not None else 0.0,
                     "from_cut": _posed(db, frame, inst, cut, sym) if cut is not None else {"posed": False},
                     "from_truth": _posed(db, frame, inst, visible, sym)})
        if frame.depth is not None and cut is not None:
            rows[-1]["from_cut_depth"] = _posed(db, frame, inst, cut, sym, depth=True)
    return rows


def summarise(rows: list[dict]) -> dict:
    def stats(group: list[dict]) -> dict:
        out: dict = {"n": len(group)}
        if not group:
            return out
        out["median_cut_iou"] = median([r["cut_iou"] for r in group])
        for key in ("from_cut", "from_cut_depth", "from_truth"):
            if not all(key in r for r in group):
                continue
            posed = [r[key] for r in group if r[key].get("posed")]
            out[key] = {"add": sum(bool(p["add_ok"]) for p in posed),
                        "median_rotation_deg": median([p["rotation_deg"] for p in posed]),
                        "median_translation_mm": median([p["translation_mm"] for p in posed]),
                        "median_seconds": median([p["seconds"] for p in posed])}
        return out

    return by_group(rows, stats)


def markdown(summary: dict, catalogue: str) -> str:
    lines = [f"Catalogue: `{catalogue}`; each object posed as the object it is, default options.", "",
             "| set | objects | n | median cut IoU | ADD(-S) from the cut | from the cut + depth "
             "| from the true silhouette | median rot. err (°): cut / true "
             "| median transl. err (mm): cut / cut + depth / true | s per pose (median) |",
             "|---|---|---|---|---|---|---|---|---|---|"]

    def deg(x: float | None) -> str:
        return "–" if x is None else f"{x:.1f}"

    def mm(entry: dict | None) -> str:
        return "–" if entry is None else deg(entry["median_translation_mm"])

    for set_name, groups in summary.items():
        for group, s in groups.items():
            if not s["n"]:
                continue
            cut, depth, truth = s["from_cut"], s.get("from_cut_depth"), s["from_truth"]
            seconds = truth["median_seconds"]
            lines.append(f"| {set_name} | {group} | {s['n']} | {s['median_cut_iou']:.2f} | "
                         f"{share(cut['add'], s['n'])} | "
                         f"{'–' if depth is None else share(depth['add'], s['n'])} | "
                         f"{share(truth['add'], s['n'])} | "
                         f"{deg(cut['median_rotation_deg'])} / {deg(truth['median_rotation_deg'])} | "
                         f"{mm(cut)} / {mm(depth)} / {mm(truth)} | "
                         f"{'–' if seconds is None else f'{seconds:.2f}'} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    args = set_arguments("pose_from_cut", __doc__)
    rows: list[dict] = []
    with viewdb.open(args.db, create=False, read_only=True) as db:
        for set_name, symmetric, frame in each_frame(args.sets, args.frames, "pose_from_cut"):
            new = run_frame(db, set_name, frame, symmetric)
            rows += new
            done = ", ".join(f"{r['object']} {'+' if r['from_cut'].get('add_ok') else '-'}"
                             f"{'+' if r['from_truth'].get('add_ok') else '-'}" for r in new)
            print(f"{set_name} {frame.name}: {done} (ADD from the cut, from the truth)", flush=True)
    summary = summarise(rows)
    write_results(args.out, "pose_from_cut", summary, rows, markdown(summary, str(args.db)))


if __name__ == "__main__":
    main()
