"""How many of a file's perspective views another distance's (or an orthographic view) repeats.

    python benchmarks/view_redundancy.py DB [--objects 25] [--seed 0] [--tolerances 0.01,0.02,0.04]

The full tier's perspective views (most of its views on the default grid) are skimmed at
ingest only against views at the *same* camera distance
(:attr:`viewdb.config.PerspectiveConfig.tolerance`). Skimming them across distances as
well would shrink what every search bounds. This measures what that would leave out: for
``--objects`` objects of DB drawn at random (``--seed``; 0 objects: all), the stored
orthographic curves and their mirrors are kept first, then each perspective view from the
farthest camera to the nearest, and a view is counted as a repeat when its curve lies
within a tolerance (Euclidean, the search's units: a photo's match is typically 0.05–0.2
away) of a curve already kept. Prints the share of repeats per tolerance.
"""

from __future__ import annotations

import argparse
import sqlite3
import time

import numpy as np

from viewdb.catalogue.features import mirror_curve
from viewdb.storage.codecs import decode_array


def object_curves(conn: sqlite3.Connection, object_id: int) -> tuple[np.ndarray, dict[float, np.ndarray]]:
    """The object's orthographic curves with their mirrors, and its perspective curves by distance."""
    ortho = np.stack([decode_array(b, np.float32, (None,)).astype(np.float64) for (b,) in conn.execute(
        "SELECT samples FROM curves JOIN views ON views.id = curves.view_id WHERE object_id = ?",
        (object_id,))])
    by_distance: dict[float, list[np.ndarray]] = {}
    for distance, blob in conn.execute(
            "SELECT distance, samples FROM perspective_views WHERE object_id = ?", (object_id,)):
        by_distance.setdefault(float(distance), []).append(
            decode_array(blob, np.float32, (None,)).astype(np.float64))
    return (np.concatenate([ortho, mirror_curve(ortho)]),
            {d: np.stack(c) for d, c in by_distance.items()})


def repeats(ortho: np.ndarray, perspective: dict[float, np.ndarray], tolerance: float) -> int:
    """How many perspective curves fall within ``tolerance`` of one kept before them."""
    kept = np.empty((len(ortho) + sum(len(c) for c in perspective.values()), ortho.shape[1]))
    kept[: len(ortho)] = ortho
    n, count = len(ortho), 0
    for distance in sorted(perspective, reverse=True):
        for curve in perspective[distance]:
            if np.sqrt(((kept[:n] - curve) ** 2).sum(axis=1)).min() < tolerance:
                count += 1
            else:
                kept[n] = curve
                n += 1
    return count


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--objects", type=int, default=25)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--tolerances", default="0.01,0.02,0.04")
    args = parser.parse_args()
    tolerances = [float(t) for t in args.tolerances.split(",")]
    conn = sqlite3.connect(f"file:{args.db}?mode=ro", uri=True)
    ids = [int(r[0]) for r in conn.execute("SELECT id FROM objects ORDER BY id")]
    if 0 < args.objects < len(ids):
        ids = sorted(np.random.default_rng(args.seed).choice(ids, args.objects, replace=False).tolist())
    start = time.perf_counter()
    total, found = 0, dict.fromkeys(tolerances, 0)
    for object_id in ids:
        ortho, perspective = object_curves(conn, object_id)
        total += sum(len(c) for c in perspective.values())
        for t in tolerances:
            found[t] += repeats(ortho, perspective, t)
    print(f"{args.db}: {len(ids)} objects, {total} perspective views "
          f"({time.perf_counter() - start:.0f} s)")
    for t in tolerances:
        print(f"within {t:g} of a view kept before: {found[t]} ({found[t] / max(total, 1) * 100:.1f} %)")


if __name__ == "__main__":
    main()
