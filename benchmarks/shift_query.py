"""The whole query with today's 12 in-plane turns against one search over the shifts.

    python benchmarks/shift_query.py DB [--photos 40] [--seed 1] [-k 5] [--plan fast]
                                       [--searches turns12,all,roll=0]

Each synthetic photo (:mod:`viewdb.bench.photos`, same seed ⇒ same photos) is queried once
per search, in the same loop, by outline alone (no colour, no shape fit, no pose):
``turns12`` is ``rotations=12`` (the old search), ``all`` every circular shift of the
upright curve (``ShiftWindow()``), ``step=S`` every S-th shift, ``roll=DEG`` the shifts
near a gravity hint. Printed per search: rank-1 / rank-5, p50 / p95 of the query's
``timing_ms`` stages (``segment``, which for ``turns12`` includes turning the silhouette,
and ``search``, the plan's client + server time) and of the whole query, and the ratio of
the p50s against ``turns12``.
"""

from __future__ import annotations

import argparse
import os

import cv2
import numpy as np

import viewdb
from viewdb.bench.photos import draw_photo_spec, encode_jpeg, render_photo
from viewdb.config import DEFAULT_PLAN
from viewdb.search.shifts import ShiftWindow


def search_options(search: str) -> dict:
    """The query() keywords of a search named on the command line."""
    if search.startswith("turns"):
        return {"rotations": int(search[len("turns"):])}
    if search == "all":
        return {"shifts": ShiftWindow()}
    if search.startswith("step="):
        return {"shifts": ShiftWindow(step=int(search[len("step="):]))}
    if search.startswith("roll="):
        return {"roll": float(search[len("roll="):])}
    raise SystemExit(f"shift_query.py: unknown search {search!r} (turnsN, all, step=S, roll=DEG)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--photos", type=int, default=40)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("-k", type=int, default=5)
    parser.add_argument("--plan", default=DEFAULT_PLAN)
    parser.add_argument("--searches", default="turns12,all,roll=0")
    args = parser.parse_args()
    searches = args.searches.split(",")
    options = {s: search_options(s) for s in searches}
    db = viewdb.open(args.db, read_only=True)
    names = [o.name for o in db.objects()]
    rng = np.random.default_rng(args.seed)
    ranks: dict[str, list[int]] = {s: [] for s in searches}
    stages: dict[str, dict[str, list[float]]] = {
        s: {"segment": [], "search": [], "total": []} for s in searches}
    for i in range(args.photos):
        name = names[rng.integers(len(names))]
        spec = draw_photo_spec(rng, name)
        jpeg = encode_jpeg(render_photo(db.mesh(name), spec), spec.jpeg_quality)
        photo = cv2.cvtColor(cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        line = [f"{i:3d} {name:32s}"]
        for s in searches:
            result = db.query(photo, k=args.k, plan=args.plan, pose=False, colour=False, verify=False,
                              **options[s])
            found = [m.object for m in result.results]
            rank = found.index(name) + 1 if name in found else 0
            ranks[s].append(rank)
            t = result.timing_ms
            stages[s]["segment"].append(t["segment"])
            stages[s]["search"].append(t["client"] + t["server"])
            stages[s]["total"].append(t["total"])
            line.append(f"{s} {rank or '-'} {t['client'] + t['server']:.0f} ms")
        print("  ".join(line), flush=True)
    load = os.getloadavg()
    print(f"\n{args.photos} photos, {len(names)} objects, seed {args.seed}, k = {args.k}, plan {args.plan}, "
          f"outline alone; load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    base = searches[0]
    for s in searches:
        r = np.array(ranks[s])
        cols = []
        for stage, values in stages[s].items():
            p50, p95 = np.percentile(values, [50, 95])
            ratio = np.median(stages[base][stage]) / p50 if p50 > 0 else float("nan")
            cols.append(f"{stage} p50 {p50:.0f} / p95 {p95:.0f} ms ({ratio:.2f}x vs {base})")
        top5 = np.mean((r >= 1) & (r <= 5)) * 100
        print(f"{s:10s} rank-1 {np.mean(r == 1) * 100:.1f}% rank-5 {top5:.1f}%; " + "; ".join(cols))


if __name__ == "__main__":
    main()
