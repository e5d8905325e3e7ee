"""Recognition and pose accuracy on synthetic photographs, per plan.

    python benchmarks/photo_accuracy.py DB [--photos 40] [--seed 1] [-k 5] [--plans fast,server,cs1,cs2]
                                           [--pose-photos 20] [--pnp] [--true-mask] [--outline]
                                           [--unverified] [--iou-rerank] [--rotations 8]
                                           [--shifts all|step=S|roll=DEG]

Each photo is a random object of DB seen from a random direction off the grid through a
perspective camera, with random lighting, a plain random background, pixel noise and
JPEG compression (:mod:`viewdb.bench.photos`, the same generator as ``viewdb bench``'s
photo protocol; same seed ⇒ same photos). The photo is segmented automatically, as a user's
would be, and queried with every plan (8 in-plane turns; ``--shifts``: one search over
circular shifts of the upright curve instead, every shift, every S-th, or those near the
in-plane turn a gravity hint gives, :class:`viewdb.search.shifts.ShiftWindow`); reported per plan: the CMC
(rank 1..k identification rate) and the median query time; ``--true-mask`` also queries
each photo with its exact silhouette (rendered depth > 0) as the mask, to separate
segmentation errors from recognition errors; ``--outline`` also queries without the colour
and shape re-rankings (:mod:`viewdb.recognition.colour`,
:mod:`viewdb.recognition.verify`), ranking by outline alone as the paper does, and
``--unverified`` without the shape re-ranking only; ``--iou-rerank`` also queries with the
camera's intrinsics and ``rerank=True`` (the k results posed by perspective silhouette fits
and re-ranked by their IoU, what real photos with intrinsics can ask for). With ``--pose-photos N`` the
first N photos of **textured, asymmetric** objects (symmetry type with no generator; a
texture image on the mesh) also get the pose of their top result when it is the right
object (``server`` plan), and the report gives the median viewing-direction error (angle
between the true and the estimated camera directions) and the median full rotation error
(the upright camera makes the true in-plane angle 0), with the pose's method and time;
``--pnp`` poses them again with the camera's intrinsics (the SIFT pose by PnP, or the
perspective silhouette fit for texture-less views) and reports the median rotation error
and the translation error as a share of the camera's distance.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

import viewdb
from viewdb.bench.photos import PhotoSpec, decoded_photo, photo_series, true_silhouette
from viewdb.config import DEFAULT_PLAN
from viewdb.pose.frames import GL_TO_CV, rotation_angle, view_rotation
from viewdb.search.shifts import ShiftWindow


def direction(azimuth: float, elevation: float) -> np.ndarray:
    h, v = math.radians(azimuth), math.radians(elevation)
    return np.array([math.sin(h) * math.cos(v), math.sin(v), math.cos(h) * math.cos(v)])


def photo_intrinsics(spec: PhotoSpec) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of the camera that took the photo (OpenCV pixel centres on
    integers)."""
    f = spec.image_size / 2.0 / math.tan(math.radians(spec.fov) / 2.0)
    c = (spec.image_size - 1) / 2.0
    return f, f, c, c


def pnp_pose(db, photo: np.ndarray, spec: PhotoSpec) -> tuple[float, float, str, str, float]:
    """The top result's pose with the photo's intrinsics (OpenCV frame, mesh units):
    ``(rotation error deg, translation error % of the camera distance, method, why not,
    seconds)``, NaN errors when the top result is wrong or has no pose."""
    start = time.perf_counter()
    result = db.query(photo, k=1, plan="server", intrinsics=photo_intrinsics(spec))
    seconds = time.perf_counter() - start
    top = result.results[0] if result.results else None
    if top is None or top.object != spec.object or top.pose is None:
        return math.nan, math.nan, "", "pnp: top result wrong or no pose", seconds
    p, info = top.pose, db.object(spec.object)
    truth = GL_TO_CV @ view_rotation(spec.azimuth, spec.elevation, 0.0)
    # back to normalised units (mesh = centre + scale * normalised): t_n = (t + R c) / scale
    t_n = (np.asarray(p.translation) + np.asarray(p.rotation) @ np.asarray(info.centre)) / info.scale
    t_err = float(np.linalg.norm(t_n - np.array([0.0, 0.0, spec.distance])) / spec.distance * 100.0)
    return rotation_angle(p.rotation, truth), t_err, p.method, "", seconds


def textured(mesh) -> bool:
    for g in mesh.scene.geometry.values():
        material = getattr(g.visual, "material", None)
        if g.visual.kind == "texture" and material is not None and (
            getattr(material, "baseColorTexture", None) is not None
            or getattr(material, "image", None) is not None
        ):
            return True
    return False


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--pose-photos", type=int, default=0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--plans", default=",".join(dict.fromkeys([DEFAULT_PLAN, "server", "cs1", "cs2"])))
    parser.add_argument("--rotations", type=int, default=viewdb.QueryOptions().rotations,
                        help="in-plane turns of the silhouette tried (1: upright only; the photos "
                             "are upright, as a camera that knows gravity would take them)")
    parser.add_argument("--shifts", default=None,
                        help="search circular shifts of the upright curve instead of turns: 'all' (every "
                             "shift), 'step=S' (every S-th) or 'roll=DEG' (a gravity hint)")
    parser.add_argument("--true-mask", action="store_true", help="also query with the exact silhouette")
    parser.add_argument("--pnp", action="store_true",
                        help="also pose the pose photos with the camera's intrinsics (PnP, or the "
                             "perspective silhouette fit): full rotation and translation errors")
    parser.add_argument("--outline", action="store_true",
                        help="also query without the colour and shape re-rankings (outline alone, the "
                             "paper's way)")
    parser.add_argument("--unverified", action="store_true",
                        help="also query without the shape re-ranking (outline and colour)")
    parser.add_argument("--iou-rerank", action="store_true",
                        help="also query with the camera's intrinsics and rerank=True: the k results "
                             "re-ranked by the IoU of their perspective silhouette fits (with pose)")
    args = parser.parse_args()
    plans = args.plans.split(",")
    search = shift_options(args.shifts)
    db = viewdb.open(args.db, read_only=True)
    names = [o.name for o in db.objects()]
    runs = (plans + ([f"{p}+mask" for p in plans] if args.true_mask else [])
            + ([f"{p}+outline" for p in plans] if args.outline else [])
            + ([f"{p}+unverified" for p in plans] if args.unverified else [])
            + ([f"{p}+iou" for p in plans] if args.iou_rerank else []))
    ranks = {p: [] for p in runs}
    times = {p: [] for p in runs}
    pose_rows = []
    pnp_rows: list[tuple[float, float, str, str, float]] = []
    eligible: dict[str, bool] = {}
    for i, spec in enumerate(photo_series(names, args.seed, args.photos)):
        name = spec.object
        mesh = db.mesh(name)
        photo = decoded_photo(mesh, spec)
        line = [f"{i:3d} {name:32s}"]
        exact = true_silhouette(mesh, spec) if args.true_mask else None
        for run in runs:
            plan = run.split("+")[0]
            start = time.perf_counter()
            try:
                iou = {"intrinsics": photo_intrinsics(spec), "rerank": True} if run.endswith("+iou") else {}
                result = db.query(photo, k=args.k, plan=plan, pose=bool(iou), rotations=args.rotations,
                                  mask=exact if run.endswith("+mask") else None,
                                  colour=not run.endswith("+outline"),
                                  verify=not run.endswith(("+outline", "+unverified")), **iou, **search)
                found = [m.object for m in result.results]
                rank = found.index(name) + 1 if name in found else 0
            except viewdb.ViewDBError as exc:
                rank, found = 0, [f"error: {exc}"]
            times[run].append(time.perf_counter() - start)
            ranks[run].append(rank)
            line.append(f"{run} {rank or '-'}")
        if name not in eligible:
            sym = db.symmetry(name)
            eligible[name] = bool(sym is not None and not sym.generators and textured(mesh))
        if eligible[name] and len(pose_rows) < args.pose_photos:
            start = time.perf_counter()
            result = db.query(photo, k=1, plan="server")
            seconds = time.perf_counter() - start
            top = result.results[0] if result.results else None
            if top is not None and top.object == name and top.pose is not None:
                p = top.pose
                view_err = math.degrees(math.acos(np.clip(
                    direction(p.azimuth, p.elevation) @ direction(spec.azimuth, spec.elevation), -1, 1)))
                rot_err = rotation_angle(p.rotation, view_rotation(spec.azimuth, spec.elevation, 0.0))
                pose_rows.append((name, view_err, rot_err, p.method, seconds))
                line.append(f"pose {p.method} view {view_err:.1f} deg, rotation {rot_err:.1f} deg, "
                            f"{seconds:.1f} s")
            else:
                pose_rows.append((name, math.nan, math.nan, "not recognised" if top is None
                                  or top.object != name else "no pose", seconds))
                line.append("pose: top result wrong or no pose")
            if args.pnp:
                pnp_rows.append(pnp_pose(db, photo, spec))
                r_err, t_err, method, why_not, pnp_seconds = pnp_rows[-1]
                line.append(why_not or f"pnp {method} rotation {r_err:.1f} deg, "
                                       f"translation {t_err:.1f} %, {pnp_seconds:.1f} s")
        print("  ".join(line), flush=True)
    print(f"\n{args.photos} photos, {len(names)} objects, seed {args.seed}, k = {args.k}")
    for run in runs:
        r = np.array(ranks[run])
        cmc = " ".join(f"{np.mean((r >= 1) & (r <= j)) * 100:.1f}%" for j in range(1, args.k + 1))
        turns = f"{args.rotations} turns" if args.shifts is None else f"shifts {args.shifts}"
        print(f"{run:14s} CMC rank 1..{args.k}: {cmc}; median query {np.median(times[run]) * 1e3:.0f} ms "
              f"(segmentation + {turns}{STAGES[run.split('+')[-1]]}"
              f"{', poses' if run.endswith('+iou') else ', no pose'})")
    if pose_rows:
        ok = [row for row in pose_rows if not math.isnan(row[1])]
        print(f"pose, textured asymmetric objects: {len(ok)}/{len(pose_rows)} top-1 right with a pose; "
              f"median viewing-direction error {median(r[1] for r in ok):.1f} deg, "
              f"median rotation error {median(r[2] for r in ok):.1f} deg; "
              f"methods {sorted({r[3] for r in pose_rows})}; "
              f"median query with pose {median(r[4] for r in pose_rows) * 1e3:.0f} ms")
    if pnp_rows:
        ok = [row for row in pnp_rows if not math.isnan(row[0])]
        print(f"pose with intrinsics: {len(ok)}/{len(pnp_rows)} top-1 right with a pose; "
              f"median rotation error {median(r[0] for r in ok):.1f} deg, "
              f"median translation error {median(r[1] for r in ok):.1f} % "
              f"of the camera distance; methods {sorted({r[2] for r in ok})}; "
              f"median query {median(r[4] for r in pnp_rows):.1f} s")


#: What a run's query does after the search, by the run's suffix.
STAGES = {"outline": "", "unverified": " + colour", "mask": " + colour + shape fit",
          "iou": " + colour + shape fit + IoU fits"}
STAGES.update({p: " + colour + shape fit" for p in ("server", "cs1", "cs2")})


def shift_options(text: str | None) -> dict:
    """``db.query`` keywords for ``--shifts``."""
    if text is None:
        return {}
    if text == "all":
        return {"shifts": ShiftWindow()}
    name, _, value = text.partition("=")
    if name == "step":
        return {"shifts": ShiftWindow(step=int(value))}
    if name == "roll":
        return {"roll": float(value)}
    raise SystemExit(f"--shifts: expected all, step=S or roll=DEG, got {text!r}")


def median(values) -> float:
    """The median, NaN for none."""
    v = list(values)
    return float(np.median(v)) if v else math.nan


if __name__ == "__main__":
    main()
