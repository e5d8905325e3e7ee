"""What an ingest of one object costs in fitting the look model again, against a whole fit.

    python benchmarks/look_refit.py --db CATALOGUE [--add car] [--keep DIR]

A copy of ``CATALOGUE`` (SQLite's backup, with its tier files and ``fast`` index) is
changed three ways, each timed with the defaults:

* ``whole fit`` (the baseline: every fit before the looks were kept): every stored look
  sample and the model removed, then ``ViewDB.fit_look_model``, which renders the
  catalogue's objects for the clutter and makes every coloured object's looks;
* ``ingest of one object``: ``ViewDB.ingest`` of the sample model ``--add`` (a coloured
  mesh), the whole command as a user runs it: the object's views, the tier files, the
  ``fast`` index and the look model fitted again;
* ``fit after one object``: that object's looks and the model removed again, then
  ``ViewDB.fit_look_model``: the look step of that ingest alone.

The copy lies in ``--keep`` (default: a temporary folder next to the catalogue) and is
removed at the end unless ``--keep`` is given.
"""

from __future__ import annotations

import argparse
import shutil
import sqlite3
import tempfile
import time
from pathlib import Path

import viewdb
from support.files import copy_catalogue
from support.samples import sample


def forget_looks(db: Path, only: str | None = None) -> None:
    """Remove the stored look model and the look samples (of object ``only``, or all)."""
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM settings WHERE key = 'look_model'")
        if only is None:
            conn.execute("DELETE FROM look_samples")
        else:
            conn.execute("DELETE FROM look_samples WHERE object_id = (SELECT id FROM objects WHERE name = ?)",
                         (only,))


def timed_fit(db: Path) -> float:
    start = time.perf_counter()
    with viewdb.open(db, create=False) as vdb:
        if not vdb.fit_look_model():
            raise SystemExit(f"{db}: no look model fitted (fewer than two coloured objects?)")
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", type=Path, required=True)
    parser.add_argument("--add", default="car", help="the sample model the ingest adds (a coloured one)")
    parser.add_argument("--keep", type=Path, help="folder for the copy (kept)")
    args = parser.parse_args()
    folder = args.keep or Path(tempfile.mkdtemp(prefix="viewdb-looks-", dir=args.db.parent))
    folder.mkdir(parents=True, exist_ok=True)
    copy = folder / "catalogue.db"
    try:
        copy_catalogue(args.db, copy)
        with viewdb.open(copy, create=False) as vdb:  # migrated if it was older
            objects = len(vdb.objects())
            if args.add in {o.name for o in vdb.objects()}:
                raise SystemExit(f"{args.db}: already holds {args.add!r}; pass another --add")
        forget_looks(copy)
        whole = timed_fit(copy)
        start = time.perf_counter()
        with viewdb.open(copy, create=False) as vdb:
            report = vdb.ingest([sample(args.add)])
        ingest = time.perf_counter() - start
        if report.failed:
            raise SystemExit(f"ingest of {args.add} failed: {report.failed}")
        forget_looks(copy, only=args.add)
        update = timed_fit(copy)
    finally:
        if args.keep is None:
            shutil.rmtree(folder, ignore_errors=True)
    print(f"{args.db.name}: {objects} objects; the ingest adds the sample model {args.add!r}")
    print(f"{'step':>26} | {'s':>7} | {'vs whole fit':>12}")
    for label, seconds in (("whole fit (before)", whole), (f"ingest of {args.add}", ingest),
                           ("fit after one object", update)):
        print(f"{label:>26} | {seconds:7.1f} | {seconds / whole:11.3f}x")


if __name__ == "__main__":
    main()
