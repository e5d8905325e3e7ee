"""Cold start: what a user waits for from a fresh ``viewdb`` process, and where it goes.

    python benchmarks/cold_start.py DB [--runs 7] [--photos 4] [--seed 1] [--baseline TREE]
                                       [--pyc] [--no-parts]

Cases, each a fresh process (``python -m viewdb_cli.main``, as the ``viewdb`` script runs):

* ``help``: ``viewdb --help``;
* ``query``: ``viewdb query PHOTO --db DB --json`` with default options;
* ``no-pose``: the same with ``--no-pose``.

PHOTO is one of ``--photos`` synthetic photos of DB's objects (:mod:`viewdb.bench.photos`,
the photo protocol's generator: perspective camera, random lighting, plain background,
noise, JPEG; same seed, same photos), a different one each run. For each case the
report gives the wall time (median and 90th percentile over ``--runs``), the CPU time of
the process (user + system, all threads: the share of the machine it took), and for the
queries each part's median and share of the median wall time: ``startup`` (interpreter,
imports, opening the file, writing the answer: the wall time less the query's own
``timing_ms.total``), then the query's stages from its JSON (segment, search = client +
server, colour, verify, pose).

``--baseline TREE`` measures another checkout (e.g. ``git worktree add ../base main``) in
the same run, alternating with this one run by run, and prints the ratios: its
``viewdb``, ``viewdb_cli`` and ``viewdb_migrations`` packages are put first on the path
(a folder of links), so the same interpreter and libraries run both.

Unless ``--no-parts``, a probe then times in one fresh process per tree: the interpreter
alone, importing the CLI, opening DB read-only, a first query (its stages) and a second
query of the same photo in the same process: the difference between the two is each
stage's cold cost (imports done on first use, kernels loaded, tier arrays read, caches
filled).

The machine's load average is printed with every figure: on a loaded machine wall
times stretch (CPU times much less), so compare the trees within one run. Python may not
write bytecode caches here (``PYTHONDONTWRITEBYTECODE``), so every run compiles viewdb's
own modules from source; ``--pyc`` lets the children write and use them, as an
installed package does. One round of every case runs first and is not counted (it warms
the page cache and, with ``--pyc``, writes the bytecode).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

PACKAGES = {"viewdb": "viewdb", "viewdb_cli": "cli", "viewdb_migrations": "migrations"}
STAGES = ("segment", "search", "colour", "verify", "pose")

PROBE = r"""
import json, sys, time, resource
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
out = {}
w, c = time.perf_counter(), cpu()
def mark(name):
    global w, c
    w2, c2 = time.perf_counter(), cpu()
    out[name] = [(w2 - w) * 1e3, (c2 - c) * 1e3]
    w, c = w2, c2
import viewdb_cli.main
mark("import CLI")
import viewdb
db = viewdb.open(sys.argv[1], read_only=True)
mark("open")
for n in ("first", "second"):
    result = db.query(sys.argv[2])
    mark(n + " query")
    t = result.timing_ms
    out[n] = {"segment": t["segment"], "search": t["client"] + t["server"], "colour": t["colour"],
              "verify": t["verify"], "pose": t["pose"], "total": t["total"]}
print(json.dumps(out))
"""


def make_photos(db_path: str, count: int, seed: int, folder: Path) -> list[Path]:
    import cv2

    import viewdb
    from viewdb.bench.photos import draw_photo_spec, encode_jpeg, render_photo

    paths = []
    with viewdb.open(db_path, read_only=True) as db:
        names = [o.name for o in db.objects()]
        rng = np.random.default_rng(seed)
        for i in range(count):
            name = names[rng.integers(len(names))]
            spec = draw_photo_spec(rng, name)
            jpeg = encode_jpeg(render_photo(db.mesh(name), spec), spec.jpeg_quality)
            path = folder / f"photo{i}_{name}.jpg"
            path.write_bytes(jpeg)
            assert cv2.imread(str(path)) is not None
            paths.append(path)
    return paths


def shim(tree: Path, folder: Path) -> Path:
    """A folder of links putting ``tree``'s packages first on the path."""
    folder.mkdir(parents=True, exist_ok=True)
    for package, source in PACKAGES.items():
        link = folder / package
        if not (tree / source).is_dir():
            raise SystemExit(f"{tree} has no {source}/ folder: not a viewdb checkout")
        link.symlink_to(tree / source, target_is_directory=True)
    return folder


def child_env(path: Path, pyc: bool) -> dict[str, str]:
    env = {**os.environ, "PYTHONPATH": str(path),
           "PYOPENGL_PLATFORM": os.environ.get("PYOPENGL_PLATFORM", "egl")}
    if pyc:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def run_case(argv: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float, dict | None]:
    """Wall and CPU seconds of one fresh process, and its JSON answer (queries)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "viewdb_cli.main", *argv], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=900)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(f"viewdb {' '.join(argv)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    answer = json.loads(proc.stdout) if "--json" in argv else None
    return wall, cpu, answer


def parts(wall: float, answer: dict) -> dict[str, float]:
    t = answer["timing_ms"]
    out = {"startup": wall * 1e3 - t["total"], "segment": t["segment"], "search": t["client"] + t["server"],
           "colour": t["colour"], "verify": t["verify"], "pose": t["pose"]}
    return out


def load() -> float:
    return os.getloadavg()[0]


def quantile(values: list[float], q: float) -> float:
    return float(np.quantile(values, q)) if values else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("db")
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--photos", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--baseline", type=Path, help="another viewdb checkout to measure in the same run")
    parser.add_argument("--pyc", action="store_true", help="let the children write and use bytecode caches")
    parser.add_argument("--no-parts", action="store_true", help="skip the in-process probe")
    args = parser.parse_args()
    db = str(Path(args.db).resolve())

    with tempfile.TemporaryDirectory(prefix="viewdb-cold-") as tmp:
        folder = Path(tmp)
        photos = make_photos(db, args.photos, args.seed, folder)
        trees = {"this": ROOT} | ({"baseline": args.baseline.resolve()} if args.baseline else {})
        envs = {name: child_env(shim(tree, folder / f"path-{name}"), args.pyc)
                for name, tree in trees.items()}
        cases = {
            "help": lambda photo: ["--help"],
            "query": lambda photo: ["query", str(photo), "--db", db, "--json"],
            "no-pose": lambda photo: ["query", str(photo), "--db", db, "--json", "--no-pose"],
        }
        print(f"{db}: {len(photos)} photos (seed {args.seed}), {args.runs} runs per case and tree "
              f"({', '.join(f'{n}: {t}' for n, t in trees.items())}); load average {load():.1f} at the start")
        for argv in cases.values():  # the round not counted
            for name in trees:
                run_case(argv(photos[0]), envs[name], folder)
        results: dict[tuple[str, str], list[tuple[float, float, dict | None, float]]] = {}
        for r in range(args.runs):
            order = list(trees) if r % 2 == 0 else list(trees)[::-1]  # alternate who goes first
            photo = photos[r % len(photos)]
            for case, argv in cases.items():
                for name in order:
                    wall, cpu, answer = run_case(argv(photo), envs[name], folder)
                    results.setdefault((case, name), []).append((wall, cpu, answer, load()))
            print(f"  run {r + 1}/{args.runs} done, load average {load():.1f}", flush=True)
        report(results, trees, cases)
        if not args.no_parts:
            probe(trees, envs, folder, db, photos[0])


def report(results, trees, cases) -> None:
    print(f"\n{'case':8} {'tree':9} {'wall median':>11} {'p90':>7} {'CPU median':>10} {'load':>5}   parts "
          "(median ms, share of the median wall)")
    medians: dict[tuple[str, str], tuple[float, float]] = {}
    for case in cases:
        for name in trees:
            rows = results[(case, name)]
            walls = [w for w, _, _, _ in rows]
            cpus = [c for _, c, _, _ in rows]
            wall_median = quantile(walls, 0.5)
            medians[(case, name)] = (wall_median, quantile(cpus, 0.5))
            line = (f"{case:8} {name:9} {wall_median:10.2f}s {quantile(walls, 0.9):6.2f}s "
                    f"{quantile(cpus, 0.5):9.2f}s {np.mean([x for *_, x in rows]):5.1f}  ")
            if rows[0][2] is not None:
                split = [parts(w, a) for w, _, a, _ in rows]
                line += " ".join(f"{p} {quantile([s[p] for s in split], 0.5):.0f} "
                                 f"({quantile([s[p] for s in split], 0.5) / (wall_median * 1e3):.0%})"
                                 for p in ("startup", *STAGES))
            print(line)
    if "baseline" in trees:
        print("\nthis tree against the baseline (ratio of medians; < 1 is faster)")
        for case in cases:
            (w, c), (bw, bc) = medians[(case, "this")], medians[(case, "baseline")]
            print(f"  {case:8} wall {w:.2f} s / {bw:.2f} s = {w / bw:.2f}; "
                  f"CPU {c:.2f} s / {bc:.2f} s = {c / bc:.2f}")


def probe(trees, envs, folder: Path, db: str, photo: Path) -> None:
    print(f"\nparts in one fresh process per tree (ms wall / ms CPU; load average {load():.1f})")
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    print(f"  interpreter alone: {(time.perf_counter() - start) * 1e3:.0f} ms wall")
    for name in trees:
        proc = subprocess.run([sys.executable, "-c", PROBE, db, str(photo)], env=envs[name], cwd=folder,
                              capture_output=True, text=True, timeout=900)
        if proc.returncode != 0:
            print(f"  {name}: probe failed: {proc.stderr[-1000:]}")
            continue
        out = json.loads(proc.stdout.strip().splitlines()[-1])
        steps = ", ".join(f"{k} {out[k][0]:.0f}/{out[k][1]:.0f}" for k in
                          ("import CLI", "open", "first query", "second query"))
        first, second = out["first"], out["second"]
        cold = ", ".join(f"{s} {first[s]:.0f} - {second[s]:.0f} = {first[s] - second[s]:.0f}" for s in STAGES)
        print(f"  {name}: {steps}\n  {'':{len(name)}}  first - second query, per stage (ms wall): {cold}")


if __name__ == "__main__":
    main()
