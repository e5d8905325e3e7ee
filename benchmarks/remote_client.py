"""What the remote client's HTTP library costs: httpx against a hand-written ``http.client``
transport, on the same server, in the same run.

    python benchmarks/remote_client.py [DB] [--round-trips 400] [--queries 12]

Without DB a small database is built from ``sample_models/`` (30° grid, 90° client grid,
128 px) in a temporary folder. One ``viewdb serve`` (one worker) runs on a free loopback
port. Two clients talk to it: :class:`viewdb.RemoteServer` as shipped (httpx), and the
same class with its transport replaced by a keep-alive ``http.client`` connection (what
the client was before; parsing, validation and everything else identical). Both are
timed, interleaved request by request so that drift hits both alike:

* round trips: ``/refine`` requests of real client work (the cheapest server call, so the
  transport's share is the largest it can be);
* remote queries: ``ViewDB.query(photo, plan="cs1", server=...)`` on a client file, photos
  rendered at random off-grid angles (segmentation, 12 in-plane turns, colour, shape fit
  and pose: what ``viewdb query --client --server`` does).

It prints the medians and the ratio httpx / http.client of each, for the queries also
paired by photo and for their network time alone (the round trips' wall time beyond the
server's own: what the transport can change). Stops by itself.
"""

from __future__ import annotations

import argparse
import http.client
import statistics
import tempfile
import time
import urllib.parse
from pathlib import Path

import numpy as np

import viewdb
from support.serving import ServerProcess
from viewdb.catalogue.features import distance_curve
from viewdb.errors import FeatureError, ImageError, ServerError
from viewdb.search.plans import RefineRequest

ROOT = Path(__file__).resolve().parents[1]

MODELS = ("car", "mug", "chair", "l_bracket", "arrow", "cube_dice")


class HttpClientRemote(viewdb.RemoteServer):
    """:class:`viewdb.RemoteServer` over one keep-alive ``http.client`` connection."""

    def __init__(self, url: str, **kwargs: object) -> None:
        super().__init__(url, **kwargs)  # type: ignore[arg-type]
        parts = urllib.parse.urlsplit(url)
        self._address = (parts.hostname, parts.port)
        self._headers = dict(self._client.headers)
        self._conn: http.client.HTTPConnection | None = None

    def _send(self, method: str, path: str, data: bytes | None) -> tuple[int, bytes]:
        for attempt in (0, 1):
            reused = self._conn is not None
            if self._conn is None:
                self._conn = http.client.HTTPConnection(*self._address, timeout=self.timeout)
            try:
                self._conn.request(method, path, body=data, headers=self._headers)
                response = self._conn.getresponse()
                raw = response.read()
                if response.will_close:
                    self._conn.close()
                    self._conn = None
                return response.status, raw
            except (http.client.RemoteDisconnected, BrokenPipeError, ConnectionResetError) as exc:
                self._conn.close()
                self._conn = None
                if reused and attempt == 0:
                    continue
                raise ServerError(f"the server closed the connection ({exc})", self.url) from exc
        raise AssertionError("unreachable")

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
        super().close()


def build(folder: Path) -> Path:
    from viewdb.config import BuildConfig, IndexConfig, RenderConfig

    path = folder / "full.db"
    models = [p for p in sorted((ROOT / "sample_models").iterdir()) if p.stem in MODELS]
    config = BuildConfig(gap=30, render=RenderConfig(image_size=128), index=IndexConfig(client_gap=90))
    with viewdb.open(path, config=config) as db:
        db.ingest(models, jobs=2)
    return path


def photo(db: viewdb.ViewDB, name: str, h: float, v: float) -> np.ndarray:
    view = db.render(name, h, v)
    image = np.full(view.color.shape, 200, np.uint8)
    image[view.mask] = view.color[view.mask]
    return image


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("db", nargs="?", type=Path)
    parser.add_argument("--round-trips", type=int, default=400)
    parser.add_argument("--queries", type=int, default=12)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory(prefix="viewdb-remote-") as tmp:
        folder = Path(tmp)
        db_path = args.db or build(folder)
        client_path = folder / "client.db"
        with viewdb.open(db_path, read_only=True) as db:
            db.export_client(client_path)
            names = [o.name for o in db.objects()]
            requests, photos = [], []
            while len(requests) < 50:
                view = db.render(names[rng.integers(len(names))], *rng.uniform(0, 360, 2))
                try:
                    requests.append(RefineRequest(distance_curve(view.mask, 128), 6, 5, []))
                except FeatureError:
                    continue
            while len(photos) < args.queries:
                name, (h, v) = names[rng.integers(len(names))], rng.uniform(10, 350, 2)
                if db.render(name, h, v).mask.mean() > 0.05:  # an object segmentation can find
                    photos.append(photo(db, name, h, v))
        with ServerProcess(db_path, workers=1) as server, \
                viewdb.open(client_path, read_only=True) as client, \
                viewdb.RemoteServer(server.url) as httpx_remote, HttpClientRemote(server.url) as plain:
            remotes = {"httpx": httpx_remote, "http.client": plain}
            for remote in remotes.values():  # warm up: connections, numba, GL on the server
                remote.refine(requests[0])
                for image in photos:
                    try:
                        client.query(image, plan="cs1", server=remote)
                        break
                    except ImageError:
                        continue
            trips: dict[str, list[float]] = {k: [] for k in remotes}
            for i in range(args.round_trips):
                for label in (list(remotes) if i % 2 else list(remotes)[::-1]):
                    start = time.perf_counter()
                    remotes[label].refine(requests[i % len(requests)])
                    trips[label].append((time.perf_counter() - start) * 1e3)
            queries: dict[str, list[float]] = {k: [] for k in remotes}
            network: dict[str, list[float]] = {k: [] for k in remotes}
            answers: dict[str, list[list[str]]] = {k: [] for k in remotes}
            for i, image in enumerate(photos):
                try:
                    client.query(image, plan="cs1", server=plain, pose=False)
                except ImageError:
                    continue  # a photo whose object does not stand out: not a transport matter
                for label in (list(remotes) if i % 2 else list(remotes)[::-1]):
                    start = time.perf_counter()
                    result = client.query(image, plan="cs1", server=remotes[label])
                    queries[label].append((time.perf_counter() - start) * 1e3)
                    network[label].append(result.timing_ms.get("network", 0.0))
                    answers[label].append([r.object for r in result.results])
    assert answers["httpx"] == answers["http.client"], "the two transports answered differently"
    print(f"round trips (/refine, {args.round_trips} each, interleaved), median ms:")
    for label, times in trips.items():
        print(f"  {label:12s} {statistics.median(times):7.3f}  (p90 {np.percentile(times, 90):.3f})")
    ratio = statistics.median(trips["httpx"]) / statistics.median(trips["http.client"])
    extra = statistics.median(trips["httpx"]) - statistics.median(trips["http.client"])
    print(f"  ratio httpx / http.client: {ratio:.2f} ({extra:+.3f} ms a round trip)")
    print(f"remote queries (cs1 with colour, fit and pose, {len(queries['httpx'])} photos each), "
          "median ms:")
    for label, times in queries.items():
        print(f"  {label:12s} {statistics.median(times):7.1f}")
    ratio = statistics.median(queries["httpx"]) / statistics.median(queries["http.client"])
    paired = statistics.median(a / b for a, b in zip(queries["httpx"], queries["http.client"], strict=True))
    print(f"  ratio httpx / http.client: {ratio:.3f} of the medians, {paired:.3f} paired by photo "
          "(the pose's own time varies from run to run)")
    print("  network time per query (the round trips' wall time beyond the server's own), median ms:")
    for label, times in network.items():
        print(f"  {label:12s} {statistics.median(times):7.1f}")
    ratio = statistics.median(network["httpx"]) / max(statistics.median(network["http.client"]), 1e-9)
    print(f"  ratio httpx / http.client: {ratio:.2f}")


if __name__ == "__main__":
    main()
