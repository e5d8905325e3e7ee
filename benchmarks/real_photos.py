"""Real photographs: recognise and pose the YCB-Video objects against the whole catalogue.

    python benchmarks/real_photos.py [--gap 10] [--out DIR] [--subset N] [--plans server,cs1,cs2]
                                     [-k 10] [--no-extras] [--jobs 2]

Ingests the 7 YCB-Video meshes (``../shared/real/ycb_video_2frames/meshes``), the ViSP tea
box and cube and the phone box, together with all of ``../shared/models`` (``--subset N``:
only the first N, for development) into ``DIR/catalogue_g{gap}[_sN].db`` (kept: a rerun
only re-ingests what changed). Then, for every labelled object of both YCB-Video frames
(the mask from the label map, other labelled objects as possible occluders, the
intrinsics from ``gt.json``):

* **recognition**, per plan: the rank of the object's mesh among the catalogue by the
  silhouette curve alone (``curve``), and after re-ranking the plan's top k by the IoU of
  each object's perspective silhouette fit (``verified``, ``viewdb query --rerank``).
  The catalogue holds a second copy of every one of these 7 objects (the same YCB scan
  from another source, in another frame: :data:`TWINS`); ``rank`` is that of the exact
  mesh, ``rank_same`` that of the first copy of the same object;
* **pose** (of the exact mesh, ``ViewDB.estimate_pose``: the object given, no
  recognition): rotation error in degrees, symmetry-aware (below), and the translation
  error in mm, against ``gt.json``;

and writes ``DIR/real_photos.md`` and ``.json`` (the table), and overlays under
``DIR/overlays/``: the estimated pose's silhouette outline (green) and the ground truth's
(blue) drawn on each photo, rendered through the intrinsics. The ViSP tea box and cube
and the phone box (no ground truth; automatic segmentation) are queried too and their
overlays written for eyeballing (the segmentation outline in yellow).

Symmetry-aware rotation error. The meshes are untextured, so a pose can only be known up
to the mesh's own shape symmetries. These are found from the mesh (:func:`symmetries`):
rotations about the bounding-box centre, about its principal axes, that map the surface
onto itself within 2 % of its diameter (mean nearest-neighbour distance between 10,000
surface samples and their turned copy, both ways; the samples' own spacing is about 1 %). If
every turn about an axis does (a cylinder), the error is the angle between the estimated
and true directions of that axis (also up to a flip when a half turn across it is a
symmetry); otherwise it is the smallest rotation angle of ``R_estᵀ · R_gt · S`` over the
finite group ``S`` found. The plain error (no symmetry) is reported too. Translation error:
distance between the estimated and true positions of the bounding-box centre in the camera
(which the symmetries fix); the plain ``|t_est − t_gt|`` is in the JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import trimesh
from scipy.spatial import cKDTree

import viewdb
from viewdb.catalogue.mesh import load_mesh
from viewdb.catalogue.pinhole import Window, get_pinhole_renderer
from viewdb.pose.frames import rotation_angle
from viewdb.recognition.image import load_image
from viewdb.recognition.segmentation import segment
from viewdb.typed import Intrinsics

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
REAL = SHARED / "real"
YCB = REAL / "ycb_video_2frames"
MODELS = SHARED / "models"

#: The catalogue's other copy of each YCB-Video object (same YCB scan, another source).
TWINS = {
    "002_master_chef_can": ("ycb_master_chef_can",),
    "004_sugar_box": ("ocrtoc_sugar_box",),
    "009_gelatin_box": ("ocrtoc_gelatin_box",),
    "010_potted_meat_can": ("ycb_potted_meat_can",),
    "019_pitcher_base": ("ocrtoc_pitcher",),
    "025_mug": ("ocrtoc_mug",),
    "061_foam_brick": ("ycb_foam_brick",),
}

#: The cases without ground truth: mesh, photos, intrinsics (from each case's notes.md).
EXTRAS = {
    "visp_teabox": ("teabox.glb", ["frame_000.png", "frame_024.png"],
                    (839.21470, 839.44555, 325.66776, 243.69727)),
    "visp_cube": ("cube.glb", ["color_image_0000.jpg"], (614.9616699219, 614.9281005859, 320.1971435547,
                                                         241.4553680420)),
    "lumia_box": ("box.glb", ["box5.jpg"], (863.8, 864.5, 500.7, 372.6)),
}

GREEN, BLUE, YELLOW, RED = (0, 220, 0), (255, 80, 0), (0, 230, 255), (0, 0, 255)  # BGR


# ---------------------------------------------------------------------- symmetry
@dataclass(frozen=True)
class Symmetry:
    """A mesh's shape symmetries about its bounding-box centre (object frame)."""

    centre: np.ndarray
    #: Finite rotations (3×3) including the identity.
    group: tuple[np.ndarray, ...]
    #: Unit axis of a continuous symmetry, or None.
    axis: np.ndarray | None
    #: With ``axis``: a half turn across it is a symmetry too (the axis may flip).
    flip: bool

    def describe(self) -> str:
        if self.axis is not None:
            return "continuous axis" + (" + flip" if self.flip else "")
        return "none" if len(self.group) == 1 else f"{len(self.group)} rotations"


def _turn(axis: np.ndarray, degrees: float) -> np.ndarray:
    r, _ = cv2.Rodrigues(np.asarray(axis, np.float64) * math.radians(degrees))
    return r


def symmetries(path: Path, tolerance: float = 0.02, samples: int = 10000) -> Symmetry:
    """The rotations about the bounding-box centre and principal axes that map the mesh's
    surface onto itself within ``tolerance`` × its diameter (module doc)."""
    mesh = trimesh.load(str(path), force="mesh", process=False)
    lo, hi = mesh.bounds
    centre = (lo + hi) / 2.0
    pts, _ = trimesh.sample.sample_surface(mesh, samples, seed=0)
    x = np.asarray(pts) - centre
    diameter = 2.0 * float(np.linalg.norm(x, axis=1).max())
    tree = cKDTree(x)
    _, vecs = np.linalg.eigh(np.cov(x.T))
    axes = [vecs[:, i] for i in range(3)]

    def fits(r: np.ndarray) -> bool:
        y = x @ r.T
        d1, _ = tree.query(y)
        d2, _ = cKDTree(y).query(x)
        return (d1.mean() + d2.mean()) / 2.0 < tolerance * diameter

    for a in axes:
        if all(fits(_turn(a, deg)) for deg in (20, 45, 90, 135, 180, 250, 310)):
            flip = any(fits(_turn(b, 180.0)) for b in axes if abs(float(b @ a)) < 0.5)
            return Symmetry(centre, (np.eye(3),), a, flip)
    group = [np.eye(3)]
    for a in axes:
        for deg in (90.0, 120.0, 180.0):
            r = _turn(a, deg)
            if fits(r):
                group.append(r)
    closed = list(group)
    for _ in range(2):  # close under composition
        for p in list(closed):
            for q in list(closed):
                c = p @ q
                if all(rotation_angle(c, e) > 1.0 for e in closed):
                    closed.append(c)
    return Symmetry(centre, tuple(closed), None, False)


def pose_errors(sym: Symmetry, r_est: np.ndarray, t_est: np.ndarray, r_gt: np.ndarray,
                t_gt: np.ndarray) -> dict[str, float]:
    """Rotation error (degrees; symmetry-aware and plain) and translation error (mm)."""
    if sym.axis is not None:
        c = float(np.clip((r_est @ sym.axis) @ (r_gt @ sym.axis), -1.0, 1.0))
        angle = math.degrees(math.acos(c))
        rot = min(angle, 180.0 - angle) if sym.flip else angle
    else:
        rot = min(rotation_angle(r_est @ s, r_gt) for s in sym.group)
    centre_est = r_est @ sym.centre + t_est
    centre_gt = r_gt @ sym.centre + t_gt
    return {"rotation_deg": rot, "rotation_plain_deg": rotation_angle(r_est, r_gt),
            "translation_mm": 1000.0 * float(np.linalg.norm(centre_est - centre_gt)),
            "translation_plain_mm": 1000.0 * float(np.linalg.norm(t_est - t_gt))}


# ---------------------------------------------------------------------- overlays
def silhouette(mesh_path: Path, rotation: np.ndarray, translation: np.ndarray,
               intrinsics: Intrinsics, shape: tuple[int, int]) -> np.ndarray:
    """The mesh (own units) rendered at an OpenCV pose through the intrinsics: bool (H, W)."""
    mesh = load_mesh(mesh_path)  # normalised; pose it as original = c + s·n
    t_n = (np.asarray(rotation) @ mesh.centre + np.asarray(translation)) / mesh.scale
    h, w = shape
    side = max(h, w)
    window = Window(0.0, 0.0, float(side), side)
    mask, _ = get_pinhole_renderer().render(mesh, np.asarray(rotation), t_n,
                                            window.intrinsics(*intrinsics), side)
    return mask[:h, :w]


def draw_outline(image: np.ndarray, mask: np.ndarray, colour: tuple[int, int, int], width: int = 2) -> None:
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(image, contours, -1, colour, width, lineType=cv2.LINE_AA)


# ---------------------------------------------------------------------- the run
def build(db_path: Path, gap: float, subset: int | None, extras: bool, jobs: int) -> float:
    paths = [YCB / "meshes"]
    if extras:
        paths += [REAL / case / mesh for case, (mesh, _, _) in EXTRAS.items()]
    paths = viewdb.describe_paths(paths)
    models = viewdb.describe_paths([MODELS])
    paths += models[:subset] if subset is not None else models
    start = time.perf_counter()
    with viewdb.open(db_path, gap=gap) as db:
        report = db.ingest(paths, jobs=jobs)
        for o in report.failed:
            print(f"warning: {o.path}: {o.error}", file=sys.stderr)
    return time.perf_counter() - start


def _rank(results: list, names: tuple[str, ...]) -> int | None:
    for r in results:
        if r.object in names:
            return r.rank
    return None


def run_ycb(db: viewdb.ViewDB, plans: list[str], k: int, out: Path, objects: list[str] | None = None,
            progress=print) -> list[dict]:
    gt = json.loads((YCB / "gt.json").read_text())
    rows = []
    for frame_id, frame in gt["frames"].items():
        K = np.asarray(frame["K"])
        intr = (K[0, 0], K[1, 1], K[0, 2], K[1, 2])
        color, labels = YCB / frame["color"], YCB / frame["label"]
        photo = cv2.imread(str(color))
        drawn = False
        for obj in frame["objects"]:
            name = obj["name"]
            if objects is not None and name not in objects:
                continue
            same = (name, *TWINS.get(name, ()))
            row: dict = {"frame": frame_id, "object": name, "plans": {}}
            label = int(obj["class_index"])
            sym = symmetries(YCB / obj["mesh"])
            row["symmetry"] = sym.describe()
            r_gt, t_gt = np.asarray(obj["R"]), np.asarray(obj["t"])
            t0 = time.perf_counter()
            est = db.estimate_pose(color, name, intr, label_map=labels, label=label)
            row["pose_seconds"] = time.perf_counter() - t0
            row["pose"] = {**pose_errors(sym, est.rotation, est.translation, r_gt, t_gt), "iou": est.iou}
            for plan in plans:
                # the ranks before any re-ranking by a rendered view's fit
                curve = db.query(color, k=max(k, 20), plan=plan, label_map=labels, label=label, pose=False,
                                 verify=False)
                t0 = time.perf_counter()
                verified = db.query(color, k=k, plan=plan, label_map=labels, label=label, intrinsics=intr,
                                    rerank=True)
                seconds = time.perf_counter() - t0
                entry = {
                    "curve_rank": _rank(curve.results, (name,)),
                    "curve_rank_same": _rank(curve.results, same),
                    "rank": _rank(verified.results, (name,)), "rank_same": _rank(verified.results, same),
                    "top": verified.results[0].object if verified.results else None,
                    "seconds": seconds,
                }
                mine = [r for r in verified.results if r.object == name and r.pose is not None]
                if mine:
                    p = mine[0].pose
                    entry["pose"] = pose_errors(sym, p.rotation, p.translation, r_gt, t_gt)
                row["plans"][plan] = entry
            rows.append(row)
            progress(f"{frame_id} {name}: pose {row['pose']['rotation_deg']:.1f} deg "
                     f"{row['pose']['translation_mm']:.1f} mm; "
                     + ", ".join(f"{p} rank {e['rank']}/{e['rank_same']} (curve {e['curve_rank']})"
                                 for p, e in row["plans"].items()))
            draw_outline(photo, silhouette(YCB / obj["mesh"], r_gt, t_gt, intr, photo.shape[:2]), BLUE, 1)
            draw_outline(photo, silhouette(YCB / obj["mesh"], est.rotation, est.translation, intr,
                                           photo.shape[:2]), GREEN, 2)
            drawn = True
        if drawn:
            cv2.imwrite(str(out / "overlays" / f"ycb_{frame_id}.png"), photo)
    return rows


def run_extras(db: viewdb.ViewDB, k: int, out: Path, progress=print) -> list[dict]:
    rows = []
    for case, (mesh_file, photos, intr) in EXTRAS.items():
        name = Path(mesh_file).stem
        for photo_name in photos:
            path = REAL / case / photo_name
            row: dict = {"case": case, "photo": photo_name, "object": name}
            try:
                loaded = load_image(path)
                seg = segment(loaded)
                result = db.query(path, k=k, intrinsics=intr, rerank=True)
                row["rank"] = _rank(result.results, (name,))
                row["top"] = result.results[0].object
                est = db.estimate_pose(path, name, intr, mask=seg.mask)
                row["iou"] = est.iou
                image = cv2.cvtColor(loaded.rgb, cv2.COLOR_RGB2BGR)
                draw_outline(image, seg.mask, YELLOW, 1)
                draw_outline(image, silhouette(REAL / case / mesh_file, est.rotation, est.translation, intr,
                                               image.shape[:2]), GREEN, 2)
                file = out / "overlays" / f"{case}_{Path(photo_name).stem}.png"
                cv2.imwrite(str(file), image)
                row["overlay"] = str(file.relative_to(out))
            except viewdb.ViewDBError as exc:
                row["error"] = str(exc)
            rows.append(row)
            progress(f"{case} {photo_name}: {row}")
    return rows


def _fmt(x: float | int | None, spec: str = "") -> str:
    return "–" if x is None else format(x, spec)


def markdown(summary: dict) -> str:
    plans = summary["plans"]
    lines = [f"Catalogue: {summary['objects']} objects, gap {summary['gap']:g}°; re-rank shortlist k = "
             f"{summary['k']}. Rank: exact mesh / first copy of the same object (the catalogue's twin); "
             "'curve' = silhouette curve only, 'verified' = after re-ranking by perspective silhouette IoU.",
             ""]
    head = "| frame | object | symmetry | rot. err (°) | plain (°) | trans. err (mm) | IoU |"
    sep = "|---|---|---|---|---|---|---|"
    for p in plans:
        head += f" {p} curve | {p} verified |"
        sep += "---|---|"
    lines += [head, sep]
    for r in summary["ycb"]:
        pe = r["pose"]
        line = (f"| {r['frame']} | {r['object']} | {r['symmetry']} | {pe['rotation_deg']:.1f} | "
                f"{pe['rotation_plain_deg']:.1f} | {pe['translation_mm']:.1f} | {_fmt(pe['iou'], '.3f')} |")
        for p in plans:
            e = r["plans"][p]
            line += (f" {_fmt(e['curve_rank'])} / {_fmt(e['curve_rank_same'])} | "
                     f"{_fmt(e['rank'])} / {_fmt(e['rank_same'])} |")
        lines.append(line)
    s = summary["totals"]
    lines += ["", f"Median rotation error {s['median_rotation_deg']:.1f}° (symmetry-aware), median "
              "translation "
              f"error {s['median_translation_mm']:.1f} mm, max {s['max_translation_mm']:.1f} mm; "
              f"pose {s['median_pose_seconds']:.1f} s per object (median)."]
    for p in plans:
        t = s["plans"][p]
        lines.append(f"- {p}: ranked first {t['first']}/{t['n']} (exact mesh), {t['first_same']}/{t['n']} "
                     f"(same object); by curve alone {t['curve_first']}/{t['n']} and {t['curve_first_same']}/"
                     f"{t['n']}; {t['median_seconds']:.1f} s per verified query (median)")
    if summary.get("extras"):
        lines += ["", "| case | photo | rank of its mesh | top result | IoU of its pose |",
                  "|---|---|---|---|---|"]
        for r in summary["extras"]:
            lines.append(f"| {r['case']} | {r['photo']} | {_fmt(r.get('rank'))} | {r.get('top', '–')} | "
                         f"{_fmt(r.get('iou'), '.3f')} |" + (f" {r['error']}" if "error" in r else ""))
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gap", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "real_photos")
    parser.add_argument("--subset", type=int, default=None, help="only the first N catalogue models")
    parser.add_argument("--plans", default="server,cs1,cs2")
    parser.add_argument("-k", type=int, default=10, help="shortlist re-ranked by silhouette fit")
    parser.add_argument("--objects", default=None, help="comma-separated YCB objects (default: all)")
    parser.add_argument("--no-extras", action="store_true", help="skip the ViSP and phone-box cases")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args()
    if not YCB.is_dir():
        sys.exit(f"real_photos: {YCB} not found")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "overlays").mkdir(exist_ok=True)
    db_path = args.out / f"catalogue_g{args.gap:g}{'' if args.subset is None else f'_s{args.subset}'}.db"
    build_s = build(db_path, args.gap, args.subset, not args.no_extras, args.jobs)
    print(f"catalogue {db_path} ready in {build_s:.0f} s", flush=True)
    plans = args.plans.split(",")
    objects = args.objects.split(",") if args.objects else None
    with viewdb.open(db_path, create=False) as db:
        n_objects = len(db.objects())
        ycb = run_ycb(db, plans, args.k, args.out, objects, progress=lambda m: print(m, flush=True))
        extras = [] if args.no_extras else run_extras(db, args.k, args.out, lambda m: print(m, flush=True))
    totals: dict = {
        "median_rotation_deg": float(np.median([r["pose"]["rotation_deg"] for r in ycb])),
        "median_translation_mm": float(np.median([r["pose"]["translation_mm"] for r in ycb])),
        "max_translation_mm": float(np.max([r["pose"]["translation_mm"] for r in ycb])),
        "median_pose_seconds": float(np.median([r["pose_seconds"] for r in ycb])),
        "plans": {},
    }
    for p in plans:
        es = [r["plans"][p] for r in ycb]
        totals["plans"][p] = {
            "n": len(es), "first": sum(e["rank"] == 1 for e in es),
            "first_same": sum(e["rank_same"] == 1 for e in es),
            "curve_first": sum(e["curve_rank"] == 1 for e in es),
            "curve_first_same": sum(e["curve_rank_same"] == 1 for e in es),
            "median_seconds": float(np.median([e["seconds"] for e in es])),
        }
    summary = {"gap": args.gap, "k": args.k, "objects": n_objects, "subset": args.subset, "plans": plans,
               "build_seconds": build_s, "ycb": ycb, "extras": extras, "totals": totals}
    (args.out / "real_photos.json").write_text(json.dumps(summary, indent=1))
    table = markdown(summary)
    (args.out / "real_photos.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
