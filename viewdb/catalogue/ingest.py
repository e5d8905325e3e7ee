"""Running an ingest: which files to describe, in how many processes, and reporting.

Workers (``jobs > 1``) are spawned processes: each imports pyrender itself and keeps one
renderer for its life. With ``ray`` the workers are Ray tasks anywhere in a cluster
(:mod:`viewdb.catalogue.distributed`). Either way they only compute
(:func:`~viewdb.catalogue.describe.describe_object`); the calling process writes each object
in one transaction, so an interrupted ingest leaves every object either complete or absent.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import os
import queue as queue_module
import signal
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..camera import grid_views
from ..config import LIMITS, BuildConfig, RayIngestConfig, integer
from ..errors import MeshError, ViewDBError
from ..paths import not_regular
from .appearance import Appearance
from .describe import (
    ObjectDescription,
    PerspectiveView,
    appearance_scope,
    describe_appearance,
    describe_object,
    describe_perspective,
    lacking_views,
    perspective_grid,
)
from .mesh import LoadOptions, file_hash, load_mesh

__all__ = ["FileOutcome", "IngestProgress", "IngestReport", "IngestTarget", "Upgrade", "checked_options",
           "run_ingest"]


@dataclass(frozen=True)
class IngestProgress:
    """What a progress callback is told, after every rendered view and finished file."""

    views_done: int
    views_total: int
    files_done: int
    files_total: int
    #: The file just finished (None for a per-view tick).
    outcome: FileOutcome | None = None
    #: Objects written so far (added, replaced or upgraded), and the seconds since the
    #: ingest began: their ratio is the throughput of all workers, local or on Ray.
    written: int = 0
    seconds: float = 0.0

    @property
    def objects_per_second(self) -> float:
        return self.written / self.seconds if self.seconds > 0 else 0.0


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


def _init_worker(ticks: Any, parent: int) -> None:
    global _TICKS
    _TICKS = ticks
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    die_with_parent(parent)


#: Linux's prctl option: the signal a process gets when its parent dies.
PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """End this worker when the process ``parent`` dies, however it dies (SIGKILL too):
    otherwise a killed ingest leaves its workers (about 300 MB each) and multiprocessing's
    resource tracker waiting on a pipe for good. Linux: the kernel sends SIGKILL at the
    parent's death (``prctl(PR_SET_PDEATHSIG)``); elsewhere a thread checks the parent
    every second."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        armed = libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) == 0 and sys.platform == "linux"
    except (OSError, AttributeError):
        armed = False
    if os.getppid() != parent:  # it died before the signal was armed
        os._exit(1)
    if not armed:
        def watch() -> None:
            while os.getppid() == parent:
                time.sleep(1.0)
            os._exit(1)

        threading.Thread(target=watch, name="viewdb-parent-watch", daemon=True).start()


def _tick(n: int) -> None:
    if _TICKS is not None:
        _TICKS.put(n)


@dataclass(frozen=True)
class Upgrade:
    """What an object stored by an older viewdb lacked: its perspective views and/or its
    appearance records (None: it had them)."""

    name: str
    perspective: list[PerspectiveView] | None
    #: The records it lacked (added to those it has).
    appearance: list[Appearance] | None
    seconds: float
    #: The scope its records now have (:func:`~viewdb.catalogue.describe.recorded_views`).
    appearance_scope: str | None = None

    @property
    def views(self) -> list[Any]:
        return [*(self.perspective or ()), *(self.appearance or ())]


def _describe(
    job: _Job, config: BuildConfig, skim: bool, options: LoadOptions,
    on_view: Callable[[int], None],
) -> ObjectDescription | Upgrade:
    start = time.perf_counter()
    if job.upgrade == {"appearance"} and job.stored and not job.records:
        # every view it should have a record of has one: only its scope is written
        return Upgrade(job.name, None, [], time.perf_counter() - start, appearance_scope(config))
    mesh = load_mesh(job.path, job.name, job.digest, options)
    if job.upgrade:
        perspective = (describe_perspective(mesh, config, on_view=on_view)
                       if "perspective" in job.upgrade else None)
        appearance, scope = (describe_appearance(mesh, config, job.stored, on_view=on_view,
                                                 recorded=job.recorded)
                             if "appearance" in job.upgrade else (None, None))
        return Upgrade(job.name, perspective, appearance, time.perf_counter() - start, scope)
    return describe_object(mesh, config, skim=skim, on_view=on_view)


def _describe_file(
    job: _Job, config: BuildConfig, skim: bool, options: LoadOptions
) -> ObjectDescription | Upgrade:
    return _describe(job, config, skim, options, _tick)


@dataclass(frozen=True)
class IngestTarget:
    """Where an ingest writes: the objects already stored (name → content hash), how it
    writes a described object and an upgrade (each in one transaction), and what objects
    stored by an older viewdb lack (:func:`run_ingest`)."""

    existing_hashes: dict[str, str]
    write: Callable[[ObjectDescription], None]
    lacking_perspective: set[str] | frozenset[str]
    #: name → (its stored views, the views it has appearance records of).
    lacking_appearance: dict[str, tuple[list[tuple[float, float]], list[tuple[float, float]]]]
    write_upgrade: Callable[[Upgrade], None]


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
    #: The object's stored views, and those it has appearance records of (for an
    #: appearance upgrade).
    stored: list[tuple[float, float]] = field(default_factory=list)
    recorded: list[tuple[float, float]] = field(default_factory=list)
    #: Appearance records to make (an appearance upgrade).
    records: int = 0

    def views(self, grid: int, perspective: int) -> int:
        """Views to render for this job (the progress total)."""
        if not self.upgrade:
            return grid + perspective
        return (perspective if "perspective" in self.upgrade else 0) + self.records


def checked_options(jobs: int, max_faces: int | None, allow_missing_textures: bool) -> LoadOptions:
    """The mesh loading options of an ingest, ``jobs`` checked too; a bad value raises
    :class:`~viewdb.errors.ViewDBError`."""
    try:
        integer(jobs, "jobs", 1, LIMITS.max_jobs)
        return LoadOptions(max_faces, allow_missing_textures)
    except ValueError as exc:
        raise ViewDBError(str(exc)) from exc


def run_ingest(
    paths: Sequence[str | Path],
    config: BuildConfig,
    target: IngestTarget,
    *,
    jobs: int = 1,
    skim: bool = True,
    progress: Callable[[IngestProgress], None] | None = None,
    options: LoadOptions = LoadOptions(),  # noqa: B008 - frozen, shared on purpose
    ray: str | None = None,
    ray_config: RayIngestConfig | None = None,
) -> IngestReport:
    """Describe every file new to ``target`` or changed, and hand each result to its
    ``write``.

    An unchanged file whose object is in the target's ``lacking_perspective`` (stored by
    an older viewdb) gets only its perspective views rendered, when the configuration asks
    for perspective views; one in ``lacking_appearance`` (name → its stored views) only
    its appearance records; either is handed to ``write_upgrade``.

    ``ray`` (``"auto"`` or a head node's ``HOST:PORT``) describes the files as Ray tasks
    across that cluster instead of in ``jobs`` local processes (``ray_config``: retries
    and queue depth); they are written here all the same.

    A file that fails (unreadable, no area, …) is reported as ``failed`` and the others
    still go in. ``KeyboardInterrupt`` stops the workers and propagates; objects already
    written stay, the one being written is rolled back by ``write``'s transaction.
    """
    start = time.perf_counter()
    report = IngestReport()
    lacking = _Lacking(target.lacking_perspective if config.perspective.enabled else frozenset(),
                       target.lacking_appearance, config)
    todo = _plan_jobs(paths, target.existing_hashes, lacking, report)
    run = _Run(report, todo, config, target.write, target.write_upgrade, progress)
    run.report_planned()
    if ray is not None and todo:
        run.on_ray(todo, skim, options, ray, ray_config)
    elif jobs <= 1 or len(todo) <= 1:
        run.serial(todo, skim, options)
    else:
        run.pooled(todo, jobs, skim, options)
    report.seconds = time.perf_counter() - start
    return report


@dataclass(frozen=True)
class _Lacking:
    """What objects stored by an older viewdb lack: perspective views, appearance records
    (name → its stored views and the views it has records of)."""

    perspective: set[str] | frozenset[str]
    appearance: dict[str, tuple[list[tuple[float, float]], list[tuple[float, float]]]]
    config: BuildConfig

    def job(self, path: Path, name: str, digest: str) -> _Job | None:
        """The upgrade of an unchanged file's object, or None if it lacks nothing."""
        adds = frozenset(({"perspective"} if name in self.perspective else set())
                         | ({"appearance"} if name in self.appearance else set()))
        if not adds:
            return None
        stored, recorded = self.appearance.get(name, ([], []))
        return _Job(str(path), name, digest, True, adds, list(stored), list(recorded),
                    self._records(stored, recorded) if "appearance" in adds else 0)

    def _records(self, stored: list[tuple[float, float]], recorded: list[tuple[float, float]]) -> int:
        """The records an appearance upgrade makes (the progress total; views without a
        silhouette make none)."""
        return len(lacking_views(self.config, stored, recorded)[0])


def _plan_jobs(
    paths: Sequence[str | Path], existing_hashes: dict[str, str], lacking: _Lacking,
    report: IngestReport,
) -> list[_Job]:
    """The files to describe (new, changed, or unchanged but lacking what ``lacking``
    says); the others go in ``report`` as unchanged or failed."""
    todo: list[_Job] = []
    seen: dict[str, str] = {}
    for raw in paths:
        path = Path(raw)
        name = path.stem
        if name in seen:
            report.outcomes.append(FileOutcome(
                str(path), name, "failed",
                error=f"{path}: object name {name!r} is already taken by {seen[name]} in this batch",
            ))
            continue
        seen[name] = str(path)
        try:
            why = not_regular(path)
            if why is not None:
                raise MeshError("no such file" if why == "does not exist" else why, path)
            digest = file_hash(path)
        except (OSError, ViewDBError) as exc:
            report.outcomes.append(FileOutcome(str(path), name, "failed", error=str(exc)))
            continue
        if existing_hashes.get(name) == digest:
            upgrade = lacking.job(path, name, digest)
            if upgrade is not None:
                todo.append(upgrade)
            else:
                report.outcomes.append(FileOutcome(str(path), name, "unchanged"))
            continue
        todo.append(_Job(str(path), name, digest, name in existing_hashes))
    return todo


class _Run:
    """One ingest's progress and outcomes: the views done, and each finished file written
    and reported."""

    def __init__(
        self, report: IngestReport, todo: list[_Job], config: BuildConfig,
        write: Callable[[ObjectDescription], None],
        write_upgrade: Callable[[Upgrade], None],
        progress: Callable[[IngestProgress], None] | None,
    ) -> None:
        self.report, self.config = report, config
        self.write, self.write_upgrade, self.progress = write, write_upgrade, progress
        self.grid = len(grid_views(config.gap))
        self.perspective = len(perspective_grid(config))
        self.total_views = sum(job.views(self.grid, self.perspective) for job in todo)
        self.done_views = 0
        self.files_total = len(report.outcomes) + len(todo)
        self.written = 0
        self.start = time.perf_counter()

    def notify(self, outcome: FileOutcome | None = None, files_done: int | None = None) -> None:
        if self.progress is not None:
            done = len(self.report.outcomes) if files_done is None else files_done
            self.progress(IngestProgress(self.done_views, self.total_views, done, self.files_total,
                                         outcome, self.written, time.perf_counter() - self.start))

    def report_planned(self) -> None:
        """Report the files dealt with while planning (refused, or unchanged) now, so a
        failed one's reason is known at once, not only in the final report."""
        for i, outcome in enumerate(list(self.report.outcomes)):
            self.notify(outcome, i + 1)

    def tick(self, n: int) -> None:
        self.done_views += n
        self.notify()

    def finish(self, job: _Job, result: ObjectDescription | Upgrade | BaseException) -> None:
        """Write a described file (or record its failure) and report it."""
        if isinstance(result, ViewDBError):
            outcome = FileOutcome(job.path, job.name, "failed", error=str(result))
        elif isinstance(result, BaseException):
            outcome = FileOutcome(
                job.path, job.name, "failed",
                error=f"{job.path}: unexpected {type(result).__name__}: {result}",
            )
        else:
            outcome = self._write(job, result)
            self.written += outcome.status != "failed"
        self.report.outcomes.append(outcome)
        self.notify(outcome)

    def _write(self, job: _Job, result: ObjectDescription | Upgrade) -> FileOutcome:
        try:
            if isinstance(result, Upgrade):
                self.write_upgrade(result)
            else:
                self.write(result)
        except ViewDBError as exc:
            return FileOutcome(job.path, job.name, "failed", error=str(exc))
        status = ("upgraded" if isinstance(result, Upgrade)
                  else "replaced" if job.replaces else "added")
        return FileOutcome(job.path, job.name, status, views=len(result.views), seconds=result.seconds)

    def serial(self, todo: list[_Job], skim: bool, options: LoadOptions) -> None:
        """Describe the files one after the other in this process."""
        for job in todo:
            expected_done = self.done_views + job.views(self.grid, self.perspective)
            try:
                result: ObjectDescription | Upgrade | BaseException = _describe(
                    job, self.config, skim, options, self.tick
                )
            except ViewDBError as exc:
                result = exc
            self.done_views = expected_done  # a failed file counts as dealt with
            self.finish(job, result)

    def on_ray(self, todo: list[_Job], skim: bool, options: LoadOptions, address: str,
               config: RayIngestConfig | None) -> None:
        """Describe the files as Ray tasks (:mod:`viewdb.catalogue.distributed`); write
        them here as they come back. A task's views are counted when it comes back."""
        from .distributed import describe_on_ray

        def finish(job: _Job, result: ObjectDescription | Upgrade | BaseException) -> None:
            self.done_views += job.views(self.grid, self.perspective)
            self.finish(job, result)

        describe_on_ray(_describe_file, todo, (self.config, skim, options), finish,
                        address=address, config=config)

    def pooled(self, todo: list[_Job], jobs: int, skim: bool, options: LoadOptions) -> None:
        """Describe the files in ``jobs`` spawned worker processes; write them here."""
        ctx = mp.get_context("spawn")
        ticks = ctx.Queue()
        pool = ProcessPoolExecutor(
            max_workers=min(jobs, len(todo)), mp_context=ctx,
            initializer=_init_worker, initargs=(ticks, os.getpid()),
        )
        futures: dict[Future[ObjectDescription | Upgrade], _Job] = {}
        try:
            for job in todo:
                futures[pool.submit(_describe_file, job, self.config, skim, options)] = job
            pending = set(futures)
            while pending:
                finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                drained = _drain(ticks)
                if drained:
                    self.tick(drained)
                for fut in finished:
                    exc = fut.exception()
                    self.finish(futures[fut], exc if exc is not None else fut.result())
        except BaseException:
            # the workers first: the pool's manager thread then finds them gone and ends,
            # so the join below is short. A manager thread left running (``wait=False``)
            # could read pipes that the exit handlers are closing, and print a stray
            # "Bad file descriptor" traceback after "interrupted".
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                proc.terminate()
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown(wait=True)
        if self.done_views != self.total_views:  # files that failed part-way
            self.done_views = self.total_views
            self.notify()


def _drain(ticks: Any) -> int:
    """The views the workers reported since the last call."""
    drained = 0
    while True:
        try:
            drained += ticks.get_nowait()
        except queue_module.Empty:
            return drained
