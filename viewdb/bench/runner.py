"""Running the paper's experiments: databases, queries, per-query measurements.

:func:`run_bench` builds (or reuses) the databases, draws the queries, measures every
(query, configuration) pair not yet in the results log, and writes the report. It never
prints: it tells ``progress`` what it is doing.

Measured per query (section IV.B–C):

* accuracy, S1–S6 at the accuracy client gap (30°) and the largest k, on every protocol;
* time, CS1 and CS2 (skimmed and not) at every client gap and k = 1..k, plus the server
  alone at every k, on the timing protocols (the paper's ``grid`` by default). Time is
  split into the client half and the server half (``Recognition.client_ms/server_ms``)
  and the payload bytes each way.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from ..api import ViewDB
from ..api import open as open_db
from ..catalogue.ingest import IngestProgress
from ..config import RecognitionConfig
from ..errors import ViewDBError
from ..recognition.options import QueryOptions
from .cache import CachedDb, client_db, full_db, index_row, select_models
from .config import BenchConfig
from .log import ResultLog
from .queries import GridQuery, PhotoQuery, grid_queries, photo_queries
from .report import write_report
from .tasks import Task, plan_tasks

#: The paper's CS2 (Algorithm 4, the neighbour walk), which S3 and S6 reproduce, rather
#: than the shortlist search ``cs2`` uses by default.
PAPER_CS2 = "walk"

__all__ = ["BenchProgress", "BenchRun", "run_bench"]


@dataclass(frozen=True)
class BenchProgress:
    """What a progress callback is told: a stage, and how far it is."""

    stage: str
    done: int
    total: int | None
    detail: str = ""


@dataclass
class BenchRun:
    """What a finished run wrote and measured."""

    out: Path
    files: dict[str, Path] = field(default_factory=dict)
    summary: dict[str, Any] = field(default_factory=dict)
    #: Measurements made by this call (the rest came from the log).
    measured: int = 0
    skipped: int = 0


def _check_out(config: BenchConfig, names: list[str]) -> None:
    config.out.mkdir(parents=True, exist_ok=True)
    run = config.out / "run.json"
    fingerprint = config.fingerprint(names)
    if run.exists():
        try:
            old = json.loads(run.read_text()).get("fingerprint")
        except ValueError:
            old = None
        if old is not None and old != fingerprint:
            changed = sorted(k for k in fingerprint if old.get(k) != fingerprint[k])
            raise ViewDBError(
                f"holds results of another run (different {', '.join(changed)}); "
                "use another `out` or delete it", config.out,
            )
    run.write_text(json.dumps({"fingerprint": fingerprint, "config": config.to_dict()}, indent=2))


def run_bench(
    config: BenchConfig, progress: Callable[[BenchProgress], None] | None = None
) -> BenchRun:
    """Run (or continue) the benchmark ``config`` describes; see the module doc."""
    def tell(stage: str, done: int, total: int | None, detail: str = "") -> None:
        if progress is not None:
            progress(BenchProgress(stage, done, total, detail))

    files = select_models(config.models, config.subset)
    _check_out(config, sorted(f.stem for f in files))
    fulls: dict[bool, CachedDb] = {}
    for skim in (True, False):
        stage = f"ingest {'skimmed' if skim else 'full grid'}"

        def on_ingest(p: IngestProgress, stage: str = stage) -> None:
            tell(stage, p.views_done, p.views_total or None, f"{p.files_done}/{p.files_total} files")

        fulls[skim] = full_db(config, files, skim, on_ingest)
    clients: dict[tuple[bool, float], CachedDb] = {}
    for skim in (True, False):
        for gap in config.client_gaps:
            stage = f"export {gap:g}° client ({'skimmed' if skim else 'full grid'})"

            def on_export(d: int, t: int, stage: str = stage) -> None:
                tell(stage, d, t)

            clients[skim, gap] = client_db(config, fulls[skim], gap, on_export)
    with ExitStack() as stack:
        dbs = {skim: stack.enter_context(open_db(c.path, create=False)) for skim, c in fulls.items()}
        sides = {key: stack.enter_context(open_db(c.path, create=False)) for key, c in clients.items()}
        present = [{o.name for o in db.objects()} for db in dbs.values()]
        names = sorted(set.intersection(*present) & {f.stem for f in files})
        if not names:
            raise ViewDBError("no model could be ingested", config.models)
        queries = _queries(config, dbs[True], names, tell)
        log = stack.enter_context(ResultLog(config.out / "results.jsonl"))
        measured, skipped = _measure(config, plan_tasks(config), queries, dbs, sides, log, tell)
        rows = [index_row(fulls[s]) for s in (True, False)] + \
               [index_row(clients[key]) for key in sorted(clients, key=lambda x: (not x[0], x[1]))]
        tell("report", 0, 1)
        files_out, summary = write_report(config, log, queries, rows, names)
        tell("report", 1, 1)
    return BenchRun(config.out, files_out, summary, measured, skipped)


class _Tell(Protocol):
    """``run_bench``'s progress callback, whose ``detail`` may be left out."""

    def __call__(self, stage: str, done: int, total: int | None, detail: str = "") -> None: ...


def _queries(config: BenchConfig, db: ViewDB, names: list[str], tell: _Tell) -> dict[str, list[Any]]:
    folder = config.out / "queries"
    wanted = set(config.protocols) | set(config.timing_protocols)
    out: dict[str, list[Any]] = {}
    if "grid" in wanted:
        out["grid"] = grid_queries(db, names, config.queries, config.seed, folder,
                                   lambda d, t: tell("queries grid", d, t))
    if "photo" in wanted:
        out["photo"] = photo_queries(db, names, config.queries, config.seed, folder,
                                     config.image_size, lambda d, t: tell("queries photo", d, t))
    return out


def _groups(tasks: list[Task]) -> Iterator[list[Task]]:
    """Consecutive tasks of one (protocol, skim, plan, client gap, k)."""
    group: list[Task] = []
    for t in tasks:
        if group and (t.protocol, t.skim, t.plan, t.client_gap, t.k) != \
                (group[0].protocol, group[0].skim, group[0].plan, group[0].client_gap, group[0].k):
            yield group
            group = []
        group.append(t)
    if group:
        yield group


def _measure(
    config: BenchConfig, tasks: list[Task], queries: dict[str, list[Any]],
    dbs: dict[bool, ViewDB], sides: dict[tuple[bool, float], ViewDB], log: ResultLog,
    tell: Callable[[str, int, int | None, str], None],
) -> tuple[int, int]:
    total = len(tasks)
    done = sum(t.key in log for t in tasks)
    skipped = done
    measured = 0
    tell("measure", done, total, "")
    for group in _groups(tasks):
        todo = [t for t in group if t.key not in log]
        if not todo:
            continue
        first = todo[0]
        db = dbs[first.skim]
        client = None if first.client_gap is None else sides[first.skim, first.client_gap]
        detail = (f"{first.protocol} {'skimmed' if first.skim else 'full'} {first.plan}"
                  + ("" if first.client_gap is None else f" {first.client_gap:g}°") + f" k={first.k}")
        _warm_up(config, db, client, first, queries)
        for task in todo:
            log.append(_one(config, db, client, task, queries[task.protocol][task.query]))
            measured += 1
            done += 1
            tell("measure", done, total, detail)
    return measured, skipped


def _warm_up(config: BenchConfig, db: ViewDB, client: ViewDB | None, task: Task,
             queries: dict[str, list[Any]]) -> None:
    """One untimed search first, so compiled kernels and opened tiers are not timed."""
    q = queries.get("grid")
    if q:
        db.recognise(q[0].curve, task.k, band=config.band, plan=task.plan, client=client, cs2=PAPER_CS2)


def _one(config: BenchConfig, db: ViewDB, client: ViewDB | None, task: Task,
         query: GridQuery | PhotoQuery) -> dict[str, Any]:
    record: dict[str, Any] = {
        "key": task.key, "protocol": task.protocol, "query": task.query, "truth": query.object,
        "skim": task.skim, "plan": task.plan, "client_gap": task.client_gap, "k": task.k,
    }
    start = time.perf_counter()
    try:
        if isinstance(query, GridQuery):
            found = db.recognise(query.curve, task.k, band=config.band, plan=task.plan, client=client,
                                 cs2=PAPER_CS2)
            wall = (time.perf_counter() - start) * 1e3
            record.update(
                results=[c.object for c in found.results],
                distances=[round(c.distance, 6) for c in found.results],
                client_ms=found.client_ms, server_ms=found.server_ms,
                total_ms=found.client_ms + found.server_ms, wall_ms=wall,
                bytes_sent=found.bytes_sent, bytes_received=found.bytes_received, error=None,
            )
        else:
            options = QueryOptions(k=task.k, plan=task.plan, band=config.band, rotations=config.rotations,
                                   pose=False, recognition=RecognitionConfig(cs2=PAPER_CS2))
            result = db.query(str(query.path), client=client, options=options)
            t = result.timing_ms
            record.update(
                results=[m.object for m in result.results],
                distances=[round(m.distance, 6) for m in result.results],
                client_ms=t["client"], server_ms=t["server"], total_ms=t["client"] + t["server"],
                wall_ms=t["total"], segment_ms=t["segment"],
                bytes_sent=result.transfer.get("bytes_sent", 0),
                bytes_received=result.transfer.get("bytes_received", 0), error=None,
            )
    except ViewDBError as exc:
        record.update(results=[], distances=[], client_ms=None, server_ms=None, total_ms=None,
                      wall_ms=(time.perf_counter() - start) * 1e3, bytes_sent=None,
                      bytes_received=None, error=exc.message)
    return record
