"""Running an ingest: which files to describe, in how many processes, and reporting.

Workers (``jobs > 1``) are spawned processes: each imports pyrender itself and keeps one
renderer for its life. They only compute (:func:`~viewdb.catalogue.describe.describe_object`); the
calling process writes each object in one transaction, so an interrupted ingest leaves
every object either complete or absent.
"""

from __future__ import annotations

import multiprocessing as mp
import queue as queue_module
import signal
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..camera import grid_views
from ..config import BuildConfig
from ..errors import MeshError, ViewDBError
from .appearance import Appearance
from .describe import (
    ObjectDescription,
    PerspectiveView,
    appearance_views,
    describe_appearance,
    describe_object,
    describe_perspective,
    perspective_grid,
)
from .mesh import LoadOptions, file_hash, load_mesh

__all__ = ["FileOutcome", "IngestProgress", "IngestReport", "Upgrade", "run_ingest"]


@dataclass(frozen=True)
class IngestProgress:
    """What a progress callback is told, after every rendered view and finished file."""

    views_done: int
    views_total: int
    files_done: int
    files_total: int
    #: The file just finished (None for a per-view tick).
    outcome: FileOutcome | None = None


@dataclass(frozen=True)
class FileOutcome:
    """What happened to one input file."""

    path: str
    name: str
    #: "added", "replaced", "unchanged", "upgraded" (an unchanged file whose object gained
    #: the perspective views or the appearance records it lacked) or "failed".
    status: str
    views: int = 0
    seconds: float = 0.0
    error: str | None = None


@dataclass
class IngestReport:
    """The outcome of :meth:`viewdb.ViewDB.ingest`."""

    outcomes: list[FileOutcome] = field(default_factory=list)
    seconds: float = 0.0

    def _with(self, status: str) -> list[FileOutcome]:
        return [o for o in self.outcomes if o.status == status]

    @property
    def failed(self) -> list[FileOutcome]:
        return self._with("failed")

    @property
    def views_rendered(self) -> int:
        return sum(o.views for o in self.outcomes if o.status in ("added", "replaced", "upgraded"))

    @property
    def views_per_second(self) -> float:
        return self.views_rendered / self.seconds if self.seconds > 0 else 0.0

    def counts(self) -> dict[str, int]:
        out = {k: 0 for k in ("added", "replaced", "unchanged", "upgraded", "failed")}
        for o in self.outcomes:
            out[o.status] += 1
        return out


_TICKS: Any = None


def _init_worker(ticks: Any) -> None:
    global _TICKS
    _TICKS = ticks
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C


def _tick(n: int) -> None:
    if _TICKS is not None:
        _TICKS.put(n)


@dataclass(frozen=True)
class Upgrade:
    """What an object stored by an older viewdb lacked: its perspective views and/or its
    appearance records (None: it had them)."""

    name: str
    perspective: list[PerspectiveView] | None
    appearance: list[Appearance] | None
    seconds: float

    @property
    def views(self) -> list[Any]:
        return [*(self.perspective or ()), *(self.appearance or ())]


def _describe(
    job: _Job, config: BuildConfig, skim: bool, options: LoadOptions,
    on_view: Callable[[int], None],
) -> ObjectDescription | Upgrade:
    start = time.perf_counter()
    mesh = load_mesh(job.path, job.name, job.digest, options)
    if job.upgrade:
        perspective = (describe_perspective(mesh, config, on_view=on_view)
                       if "perspective" in job.upgrade else None)
        appearance = (describe_appearance(mesh, config, job.stored, on_view=on_view)
                      if "appearance" in job.upgrade else None)
        return Upgrade(job.name, perspective, appearance, time.perf_counter() - start)
    return describe_object(mesh, config, skim=skim, on_view=on_view)


def _describe_file(
    job: _Job, config: BuildConfig, skim: bool, options: LoadOptions
) -> ObjectDescription | Upgrade:
    return _describe(job, config, skim, options, _tick)


@dataclass
class _Job:
    path: str
    name: str
    #: The file's content hash, computed once when deciding whether to ingest it.
    digest: str
    replaces: bool
    #: The file is unchanged and its object lacks only these: "perspective" (views),
    #: "appearance" (records).
    upgrade: frozenset[str] = frozenset()
    #: The object's stored views (for an appearance upgrade).
    stored: list[tuple[float, float]] = field(default_factory=list)
    #: Appearance records to make (an appearance upgrade).
    records: int = 0

    def views(self, grid: int, perspective: int) -> int:
        """Views to render for this job (the progress total)."""
        if not self.upgrade:
            return grid + perspective
        return (perspective if "perspective" in self.upgrade else 0) + self.records


def run_ingest(
    paths: Sequence[str | Path],
    config: BuildConfig,
    existing_hashes: dict[str, str],
    write: Callable[[ObjectDescription], None],
    *,
    lacking_perspective: set[str] | frozenset[str] = frozenset(),
    lacking_appearance: dict[str, list[tuple[float, float]]] | None = None,
    write_upgrade: Callable[[Upgrade], None] | None = None,
    jobs: int = 1,
    skim: bool = True,
    progress: Callable[[IngestProgress], None] | None = None,
    options: LoadOptions = LoadOptions(),  # noqa: B008 - frozen, shared on purpose
) -> IngestReport:
    """Describe every new or changed file and hand each result to ``write``.

    An unchanged file whose object is in ``lacking_perspective`` (stored by an older
    viewdb) gets only its perspective views rendered, when the configuration asks for
    perspective views; one in ``lacking_appearance`` (name → its stored views) only its
    appearance records; either is handed to ``write_upgrade``.

    A file that fails (unreadable, no area, …) is reported as ``failed`` and the others
    still go in. ``KeyboardInterrupt`` stops the workers and propagates; objects already
    written stay, the one being written is rolled back by ``write``'s transaction.
    """
    start = time.perf_counter()
    report = IngestReport()
    grid = len(grid_views(config.gap))
    perspective = len(perspective_grid(config))
    add_perspective = write_upgrade is not None and config.perspective.enabled
    lacking_appearance = lacking_appearance if write_upgrade is not None else None
    todo: list[_Job] = []
    seen: dict[str, str] = {}
    for raw in paths:
        path = Path(raw)
        name = path.stem
        if name in seen:
            report.outcomes.append(FileOutcome(
                str(path), name, "failed",
                error=f"object name {name!r} is already taken by {seen[name]} in this batch",
            ))
            continue
        seen[name] = str(path)
        try:
            if not path.is_file():
                raise MeshError("no such file", path)
            digest = file_hash(path)
        except (OSError, ViewDBError) as exc:
            report.outcomes.append(FileOutcome(str(path), name, "failed", error=str(exc)))
            continue
        if existing_hashes.get(name) == digest:
            adds = frozenset(
                ({"perspective"} if add_perspective and name in lacking_perspective else set())
                | ({"appearance"} if lacking_appearance and name in lacking_appearance else set()))
            if adds:
                stored = list((lacking_appearance or {}).get(name, []))
                records = len(appearance_views(stored, config.appearance)) if "appearance" in adds else 0
                todo.append(_Job(str(path), name, digest, True, adds, stored, records))
            else:
                report.outcomes.append(FileOutcome(str(path), name, "unchanged"))
            continue
        todo.append(_Job(str(path), name, digest, name in existing_hashes))

    total_views = sum(job.views(grid, perspective) for job in todo)
    done_views = 0
    files_total = len(report.outcomes) + len(todo)

    def notify(outcome: FileOutcome | None = None) -> None:
        if progress is not None:
            progress(IngestProgress(
                done_views, total_views, len(report.outcomes), files_total, outcome
            ))

    def finish(job: _Job, result: ObjectDescription | Upgrade | BaseException) -> None:
        if isinstance(result, ViewDBError):
            outcome = FileOutcome(job.path, job.name, "failed", error=str(result))
        elif isinstance(result, BaseException):
            outcome = FileOutcome(
                job.path, job.name, "failed",
                error=f"{job.path}: unexpected {type(result).__name__}: {result}",
            )
        else:
            try:
                if isinstance(result, Upgrade):
                    assert write_upgrade is not None
                    write_upgrade(result)
                else:
                    write(result)
            except ViewDBError as exc:
                outcome = FileOutcome(job.path, job.name, "failed", error=str(exc))
            else:
                status = ("upgraded" if isinstance(result, Upgrade)
                          else "replaced" if job.replaces else "added")
                outcome = FileOutcome(job.path, job.name, status,
                                      views=len(result.views), seconds=result.seconds)
        report.outcomes.append(outcome)
        notify(outcome)

    if jobs <= 1 or len(todo) <= 1:
        for job in todo:
            expected_done = done_views + job.views(grid, perspective)

            def tick(n: int) -> None:
                nonlocal done_views
                done_views += n
                notify()

            try:
                result: ObjectDescription | Upgrade | BaseException = _describe(
                    job, config, skim, options, tick
                )
            except ViewDBError as exc:
                result = exc
            done_views = expected_done  # a failed file counts as dealt with
            finish(job, result)
    else:
        ctx = mp.get_context("spawn")
        ticks = ctx.Queue()
        pool = ProcessPoolExecutor(
            max_workers=min(jobs, len(todo)), mp_context=ctx,
            initializer=_init_worker, initargs=(ticks,),
        )
        futures: dict[Future[ObjectDescription | Upgrade], _Job] = {}
        try:
            for job in todo:
                futures[pool.submit(_describe_file, job, config, skim, options)] = job
            pending = set(futures)
            while pending:
                finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                drained = 0
                while True:
                    try:
                        drained += ticks.get_nowait()
                    except queue_module.Empty:
                        break
                if drained:
                    done_views += drained
                    notify()
                for fut in finished:
                    exc = fut.exception()
                    finish(futures[fut], exc if exc is not None else fut.result())
        except BaseException:
            workers = list((getattr(pool, "_processes", None) or {}).values())
            pool.shutdown(wait=False, cancel_futures=True)
            for proc in workers:
                proc.terminate()
            raise
        pool.shutdown(wait=True)
        if done_views != total_views:  # files that failed part-way
            done_views = total_views
            notify()
    report.seconds = time.perf_counter() - start
    return report
