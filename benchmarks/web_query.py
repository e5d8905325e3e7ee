"""A query through the web page's endpoint against the same query through the CLI's
remote path, on a warm server on loopback.

    python benchmarks/web_query.py [--db FULL.db] [--repeats 7] [--k 5] [--plans fast,server,cs1]

Without ``--db`` the demo's database is built (every model in ``sample_models/``, 30°
grid) in a temporary folder. The photo is the demo's (the mug off the grid, turned,
scaled and moved). One ``viewdb serve`` (one worker) is started on a free loopback port
and warmed up (two queries each way); then, alternating, ``--repeats`` times each:

* **web**: ``POST /query`` with the photo as a browser's form upload sends it, on a new
  connection, then ``GET`` of each result's thumbnail as the page fetches them (kept by
  the server after the first time); the whole query runs on the server and the reply
  carries the overlays;
* **remote**: what ``viewdb query PHOTO --client CLIENT --server URL`` runs: the client
  file (exported from the same database) segments the photo and runs the plan's client
  half here, :class:`viewdb.RemoteServer` sends the server half, colours, fits and
  poses to the server. Every result is posed (``pose_top=None``, ``--pose-top K`` on
  the CLI), as the page poses every result it shows.

Both give the same ranking (checked). Printed: the median wall time of each, the ratios
web / remote with and without the thumbnails, and what each way spends that the other
does not (the server drawing the overlay; the remote path's time on the network).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import viewdb
from support.serving import ServerProcess, multipart, request
from viewdb.recognition.options import QueryOptions
from viewdb_cli.main import _demo_photo

ROOT = Path(__file__).resolve().parents[1]


def build(folder: Path) -> Path:
    path = folder / "demo.db"
    models = viewdb.describe_paths([ROOT / "sample_models"])
    with viewdb.open(path, gap=30) as db:
        db.ingest(models, jobs=2)
    return path


def web_query(url: str, photo: Path, plan: str, k: int) -> tuple[float, float, list[str], float]:
    """Seconds for POST /query, and for it plus the thumbnails; the ranked objects; the
    server's milliseconds drawing the overlay."""
    body, headers = multipart({"plan": plan, "k": str(k)},
                              {"photo": (photo.name, photo.read_bytes(), "image/png")})
    start = time.perf_counter()
    status, answer = request(url, "POST", "/query", body, headers=headers)
    queried = time.perf_counter()
    if status != 200:
        raise SystemExit(f"POST /query answered {status}: {answer}")
    for result in answer["results"]:
        status, _ = request(url, "GET", "/" + result["thumbnail"])
        if status != 200:
            raise SystemExit(f"GET {result['thumbnail']} answered {status}")
    done = time.perf_counter()
    ranked = [r["object"] for r in answer["results"]]
    return queried - start, done - start, ranked, answer["timing_ms"]["overlay"]


def remote_query(client: viewdb.ViewDB, server: viewdb.RemoteServer, photo: Path, plan: str,
                 k: int) -> tuple[float, list[str], float]:
    """Seconds, the ranked objects, and the milliseconds spent on the network."""
    start = time.perf_counter()
    result = client.query(str(photo), k=k, plan=plan, server=server, pose_top=None)  # as the page
    return time.perf_counter() - start, [r.object for r in result.results], result.timing_ms["network"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--db", type=Path, help="a full database (default: the demo's, built here)")
    parser.add_argument("--repeats", type=int, default=7)
    # the page's defaults (the library's): its plan first, then the exact ones
    parser.add_argument("--k", type=int, default=QueryOptions().k)
    parser.add_argument("--plans", default=",".join(dict.fromkeys([QueryOptions().plan, "server", "cs1"])))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="viewdb-web-bench-") as tmp:
        folder = Path(tmp)
        db_path = args.db or build(folder)
        client_path = folder / "client.db"
        with viewdb.open(db_path, read_only=True) as db:
            db.export_client(client_path)
            names = [o.name for o in db.objects()]
        photo = folder / "query.png"
        _demo_photo(db_path, "mug" if "mug" in names else names[0], photo)
        print(f"database {db_path} ({len(names)} objects), photo {photo.name}, k={args.k}, "
              f"{args.repeats} repeats after 2 warm-up queries each way")
        with ServerProcess(db_path, workers=1) as srv, \
                viewdb.open(client_path, read_only=True) as client, \
                viewdb.RemoteServer(srv.url) as server:
            for plan in args.plans.split(","):
                for _ in range(2):
                    web_query(srv.url, photo, plan, args.k)
                    remote_query(client, server, photo, plan, args.k)
                web, web_all, remote, drawing, network = [], [], [], [], []
                for _ in range(args.repeats):
                    w, w_all, web_objects, drawn = web_query(srv.url, photo, plan, args.k)
                    r, remote_objects, wire = remote_query(client, server, photo, plan, args.k)
                    drawing.append(drawn)
                    network.append(wire)
                    if web_objects != remote_objects:
                        raise SystemExit(f"the rankings differ: web {web_objects}, remote {remote_objects}")
                    web.append(w)
                    web_all.append(w_all)
                    remote.append(r)
                mw, mwa, mr = (statistics.median(x) for x in (web, web_all, remote))
                print(f"plan {plan:6s}  web POST /query {mw * 1e3:7.0f} ms   "
                      f"+ thumbnails {mwa * 1e3:7.0f} ms   remote (CLI's path) {mr * 1e3:7.0f} ms   "
                      f"ratio web/remote {mw / mr:.2f} (with thumbnails {mwa / mr:.2f})")
                print(f"             of which: web drawing the overlay {statistics.median(drawing):5.0f} ms, "
                      f"remote on the network {statistics.median(network):5.0f} ms")


if __name__ == "__main__":
    main()
