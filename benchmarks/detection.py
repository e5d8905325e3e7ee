"""Every known object in a real photo, with no prompt: ``query(photo, every=True)``.

    python benchmarks/detection.py --db CATALOGUE [--sets lmo_dev,ycb_video_2frames]
                                   [--frames N] [--out DIR]

Each photo of the real sets with official ground truth (``../shared/real``, as
``benchmarks/real_clutter.py`` reads them) is queried **once, with default options** and
its intrinsics, asking for every object: ``db.query(photo, every=True, intrinsics=K)``.
An answered object is its region's top result. It **finds** an annotated object when its
name is the object's (or a twin's, another copy of the same scan) and its region's box
has IoU ≥ 0.5 with the object's visible-part box; each annotated object is found at most
once. Every other answer is **false**: a catalogue object reported where there is none,
or under the wrong name.

Reported per set: recall of the objects at least half visible (and per visibility band),
false answers per photo, and seconds per photo (median). The table goes to
``OUT/detection.md``, the rows to ``OUT/detection.json``.
"""

from __future__ import annotations

import time

import viewdb
from support.real import band_of, each_frame, median, set_arguments, share, visibility, write_results
from viewdb.bench.groundtruth import TWINS, Frame, visible_masks

#: An answer's box must overlap the object's visible box by this IoU to find it.
MIN_BOX_IOU = 0.5


def box_iou(a, b) -> float:
    """IoU of two boxes ``(x1, y1, x2, y2)`` (``x2``, ``y2`` exclusive)."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    inter = w * h
    return inter / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter)


def match(answers: list[tuple[str, tuple[int, int, int, int]]], frame: Frame) -> tuple[list[bool], int]:
    """Which annotated objects of ``frame`` the ``answers`` (name, box) find, and how many
    answers are false (module doc); answers are matched greedily, best box IoU first."""
    found = [False] * len(frame.instances)
    used = [False] * len(answers)
    pairs = []
    for i, inst in enumerate(frame.instances):
        names = (inst.mesh.stem, *TWINS.get(inst.mesh.stem, ()))
        for j, (name, box) in enumerate(answers):
            if name in names:
                iou = box_iou(box, inst.box)
                if iou >= MIN_BOX_IOU:
                    pairs.append((iou, i, j))
    for _, i, j in sorted(pairs, reverse=True):
        if not found[i] and not used[j]:
            found[i] = used[j] = True
    return found, used.count(False)


def visibilities(frame: Frame) -> list[float]:
    """Each annotated object's visible fraction (:func:`support.real.visibility`; the
    masks are rendered only for a set that gives none)."""
    if all(inst.visibility is not None for inst in frame.instances):
        return [float(inst.visibility) for inst in frame.instances]
    return [visibility(inst, whole, visible)
            for inst, (whole, visible) in zip(frame.instances, visible_masks(frame), strict=True)]


def run_frame(db: viewdb.ViewDB, set_name: str, frame: Frame) -> dict:
    """One photo's query for every object: what it found, its false answers, its time."""
    start = time.perf_counter()
    try:
        result = db.query(frame.photo, every=True, intrinsics=frame.intrinsics)
        error = None
        answers = [(o.results[0].object, tuple(o.region.box)) for o in result.objects or [] if o.results]
    except viewdb.ViewDBError as exc:
        answers, error = [], str(exc)
    seconds = time.perf_counter() - start
    found, false = match(answers, frame)
    objects = [{"object": inst.name, "visibility": vis, "band": band_of(vis), "found": hit}
               for inst, vis, hit in zip(frame.instances, visibilities(frame), found, strict=True)]
    return {"set": set_name, "frame": frame.name, "seconds": seconds, "error": error,
            "answers": [{"object": n, "box": list(b)} for n, b in answers], "false": false,
            "objects": objects}


def summarise(rows: list[dict]) -> dict:
    out: dict = {}
    for set_name in sorted({r["set"] for r in rows}):
        mine = [r for r in rows if r["set"] == set_name]
        objects = [o for r in mine for o in r["objects"]]
        half = [o for o in objects if (o["visibility"] or 0.0) >= 0.5]
        bands = {}
        for band in sorted({o["band"] for o in objects}):
            group = [o for o in objects if o["band"] == band]
            bands[band] = {"n": len(group), "found": sum(o["found"] for o in group)}
        out[set_name] = {"photos": len(mine),
                         "visible ≥ 50 %": {"n": len(half), "found": sum(o["found"] for o in half)},
                         "bands": bands, "false_per_photo": sum(r["false"] for r in mine) / len(mine),
                         "answers_per_photo": sum(len(r["answers"]) for r in mine) / len(mine),
                         "median_seconds": median([r["seconds"] for r in mine]),
                         "refused": sum(r["error"] is not None for r in mine)}
    return out


def markdown(summary: dict, catalogue: str, objects: int) -> str:
    lines = [f"Catalogue: `{catalogue}`, {objects} objects; every photo queried once for every object "
             "(`every=True`) with its intrinsics, default options.", "",
             "| set | photos | found, ≥ 50 % visible | by band | false answers per photo "
             "| answers per photo | s per photo (median) |",
             "|---|---|---|---|---|---|---|"]
    for set_name, s in summary.items():
        half = s["visible ≥ 50 %"]
        bands = "; ".join(f"{band}: {b['found']}/{b['n']}" for band, b in s["bands"].items())
        lines.append(f"| {set_name} | {s['photos']} | {share(half['found'], half['n'])} | {bands} | "
                     f"{s['false_per_photo']:.2f} | {s['answers_per_photo']:.2f} | "
                     f"{s['median_seconds']:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    args = set_arguments("detection", __doc__)
    rows: list[dict] = []
    with viewdb.open(args.db, create=False, read_only=True) as db:
        objects = len(db.objects())
        for set_name, _, frame in each_frame(args.sets, args.frames, "detection"):
            row = run_frame(db, set_name, frame)
            rows.append(row)
            hits = sum(o["found"] for o in row["objects"])
            print(f"{set_name} {frame.name}: found {hits}/{len(row['objects'])}, {row['false']} false, "
                  f"{row['seconds']:.2f} s", flush=True)
    summary = summarise(rows)
    write_results(args.out, "detection", summary, rows, markdown(summary, str(args.db), objects))


if __name__ == "__main__":
    main()
