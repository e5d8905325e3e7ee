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

import viewdb
from viewdb.catalogue.features import mirror_curve
from viewdb.storage.codecs import decode_array
from viewdb.storage.stored_catalogue import StoredCatalogue


def object_curves(
    catalogue: StoredCatalogue, conn: sqlite3.Connection, name: str
) -> tuple[np.ndarray, dict[float, np.ndarray]]:
    """The object's orthographic curves with their mirrors, and its perspective curves by distance."""
    ortho = np.stack(list(catalogue.stored_curves(name).values())).astype(np.float64)
    by_distance: dict[float, list[np.ndarray]] = {}
    for distance, blob in conn.execute(
            "SELECT distance, samples FROM perspective_views JOIN objects ON objects.id = object_id"
            " WHERE objects.name = ?", (name,)):
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
    catalogue = viewdb.open(args.db, read_only=True).server_tier().catalogue
    # an object's perspective curves all at once: no API reads them so
    conn = sqlite3.connect(f"file:{args.db}?mode=ro", uri=True)
    names = [o.name for o in catalogue.objects()]
    if 0 < args.objects < len(names):
        names = list(np.random.default_rng(args.seed).choice(names, args.objects, replace=False))
    start = time.perf_counter()
    total, found = 0, dict.fromkeys(tolerances, 0)
    for name in names:
        ortho, perspective = object_curves(catalogue, conn, str(name))
        total += sum(len(c) for c in perspective.values())
        for t in tolerances:
            found[t] += repeats(ortho, perspective, t)
    print(f"{args.db}: {len(names)} objects, {total} perspective views "
          f"({time.perf_counter() - start:.0f} s)")
    for t in tolerances:
        print(f"within {t:g} of a view kept before: {found[t]} ({found[t] / max(total, 1) * 100:.1f} %)")


if __name__ == "__main__":
    main()
