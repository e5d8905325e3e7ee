"""The real photo sets with official 6-D ground truth (``../shared/real``, or
``$VIEWDB_SHARED/real``): where they are, the visibility bands the benchmarks report, which
objects count as symmetric, and a pose's BOP-style errors against the ground truth."""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Iterator
from functools import cache
from pathlib import Path

import numpy as np

from viewdb.bench.groundtruth import Frame, Instance, add_error, load_model, pose_errors, read_frames
from viewdb.bench.twins import rigid_alignment

ROOT = Path(__file__).resolve().parent.parent.parent
SHARED = Path(os.environ.get("VIEWDB_SHARED", ROOT.parent / "shared"))
REAL = SHARED / "real"
SETS = ("lmo_dev", "ycb_video_2frames")
BANDS = ((0.8, 1.01, "≥ 80 %"), (0.5, 0.8, "50–80 %"), (0.2, 0.5, "20–50 %"), (0.0, 0.2, "< 20 %"))


def band_of(visibility: float) -> str:
    return next(name for lo, hi, name in BANDS if lo <= visibility < hi)


def visibility(inst: Instance, whole: np.ndarray, visible: np.ndarray) -> float:
    """An annotated object's visible fraction: the set's, else the share of its
    silhouette ``whole`` that is ``visible`` (the other annotated objects removed)."""
    if inst.visibility is not None:
        return float(inst.visibility)
    return float(np.count_nonzero(visible) / max(1, np.count_nonzero(whole)))


def symmetric_names(folder: Path) -> set[str]:
    """The objects a set's ``gt.json`` lists as symmetric."""
    return set(json.loads((folder / "gt.json").read_text()).get("symmetric", []))


def is_symmetric(inst: Instance, symmetric: set[str]) -> bool:
    """ADD-S for ``inst``: its set lists it, or (a set listing none) its mesh maps onto
    itself under a rotation (:func:`viewdb.bench.groundtruth.symmetries`)."""
    return inst.name in symmetric or (not symmetric and load_model(inst.mesh).symmetry.symmetric)


def pose_row(inst: Instance, rotation, translation, symmetric: bool) -> dict:
    """The errors of the pose ``(rotation, translation)`` (OpenCV frame, the mesh's units)
    against ``inst``: ADD (asymmetric) or ADD-S (symmetric) and whether it is within 0.1 ×
    the mesh's diameter, the symmetry-aware rotation error, the translation error."""
    if rotation is None or translation is None:
        return {"posed": False}
    model = load_model(inst.mesh)
    r, t = np.asarray(rotation, np.float64), np.asarray(translation, np.float64).reshape(3)
    add = add_error(model, r, t, inst.R, inst.t, symmetric)
    return {"posed": True, "add": add, "add_ok": add < 0.1 * model.diameter, "diameter": model.diameter,
            "metric": "ADD-S" if symmetric else "ADD", **pose_errors(model.symmetry, r, t, inst.R, inst.t)}


@cache
def twin_alignment(db, twin: str, exact: str) -> tuple[float, np.ndarray, np.ndarray]:
    """``(residual, Q, c)``: ``x @ Q + c`` maps the exact mesh's normalised frame onto its
    twin's (another copy of the same scan, :data:`viewdb.bench.groundtruth.TWINS`, perhaps
    in other axes and units; :func:`viewdb.bench.twins.rigid_alignment`), leaving
    ``residual`` (normalised units, bounding radius 1)."""
    return rigid_alignment(db.mesh(exact), db.mesh(twin))


def twin_pose(db, twin: str, exact: str, rotation, translation) -> tuple[np.ndarray, np.ndarray]:
    """A pose of ``twin`` (OpenCV frame, its mesh's units) as the same pose of ``exact``
    (its mesh's units), through their alignment (:func:`twin_alignment`)."""
    _, q, c = twin_alignment(db, twin, exact)
    r = np.asarray(rotation, np.float64)
    t = np.asarray(translation, np.float64).reshape(3)
    info_t, info_e = db.object(twin), db.object(exact)
    t_n = (t + r @ np.asarray(info_t.centre)) / float(info_t.scale)
    r_e = r @ q.T  # x_twin = Qᵀ x_exact + c (column vectors)
    t_en = r @ c + t_n
    return r_e, float(info_e.scale) * t_en - r_e @ np.asarray(info_e.centre)


def set_arguments(name: str, doc: str, extra: Callable[[argparse.ArgumentParser], None] | None = None
                  ) -> argparse.Namespace:
    """The command line of the real-set benchmark ``name`` (``doc``: its module doc): ``--db``,
    ``--sets``, ``--frames`` and ``--out`` (default ``benchmarks/out/NAME``, made), and what
    ``extra`` adds."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--db", type=Path, required=True, help="the catalogue (every real mesh ingested)")
    parser.add_argument("--sets", default=",".join(SETS), help="photo sets of ../shared/real")
    parser.add_argument("--frames", type=int, default=None, help="only the first N frames of each set")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / name)
    if extra is not None:
        extra(parser)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def each_frame(sets: str, frames: int | None, name: str) -> Iterator[tuple[str, set[str], Frame]]:
    """``(set, its symmetric objects, frame)`` for the first ``frames`` frames of each of the
    comma-separated ``sets``; exits naming the benchmark ``name`` when a set is missing."""
    for set_name in sets.split(","):
        folder = REAL / set_name
        if not (folder / "gt.json").is_file():
            sys.exit(f"{name}: {folder / 'gt.json'} not found")
        symmetric = symmetric_names(folder)
        for frame in read_frames(folder)[:frames]:
            yield set_name, symmetric, frame


def by_group(rows: list[dict], stats: Callable[[list[dict]], dict]) -> dict:
    """``stats`` of each set's rows: all of them, those at least half visible, and each
    visibility band's (``{set: {group: stats}}``)."""
    out: dict = {}
    for set_name in sorted({r["set"] for r in rows}):
        mine = [r for r in rows if r["set"] == set_name]
        half = [r for r in mine if r["visibility"] >= 0.5]
        out[set_name] = {"all": stats(mine), "visible ≥ 50 %": stats(half)}
        for _, _, name in BANDS:
            out[set_name][name] = stats([r for r in mine if r["band"] == name])
    return out


def median(values: list[float]) -> float | None:
    """The median, or None of nothing."""
    return float(np.median(values)) if values else None


def share(part: int, n: int) -> str:
    """``part`` of ``n`` with its percentage, as the tables print it."""
    return f"{part} ({100.0 * part / n:.0f} %)" if n else "–"


def write_results(out: Path, name: str, summary: dict, rows: list[dict], table: str) -> None:
    """``OUT/NAME.json`` (the summary and every row) and ``OUT/NAME.md`` (the table), and the
    table printed."""
    (out / f"{name}.json").write_text(json.dumps({"summary": summary, "rows": rows}, indent=1, default=float))
    (out / f"{name}.md").write_text(table)
    print(table)
