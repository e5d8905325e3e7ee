"""Describing objects on Ray: each object is one task, anywhere in the cluster.

:func:`describe_on_ray` is the Ray counterpart of the local worker pool of
:mod:`viewdb.catalogue.ingest`: it only computes. Each described object comes back to the
calling process, which writes it (one transaction per object, one writer), so an
interrupted or killed ingest leaves every object complete or absent, as a local one does.

A task whose worker dies (SIGKILL, out of memory, a lost node) is run again by Ray on
another worker, up to ``RayIngestConfig.max_retries`` times; an object whose task fails
with one of viewdb's errors is reported failed at once (a bad mesh stays bad). At most
``in_flight_per_cpu`` tasks per cluster CPU are queued at a time, so a catalogue of a
million files neither floods Ray's scheduler nor piles described objects up in memory.
Ctrl-C cancels the tasks in flight and propagates.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from ..config import RayIngestConfig
from ..ray_cluster import connect

__all__ = ["describe_on_ray"]

J = TypeVar("J")

#: Seconds between checks for finished tasks (Ctrl-C is noticed between them).
POLL_SECONDS = 0.2


def describe_on_ray(
    work: Callable[..., Any],
    jobs: Sequence[J],
    args: tuple[Any, ...],
    finish: Callable[[J, Any], None],
    *,
    address: str | None = "auto",
    config: RayIngestConfig | None = None,
) -> None:
    """Run ``work(job, *args)`` for every job as a Ray task and call ``finish(job,
    result)`` in this process as each one ends, in the order they end; ``result`` is the
    task's value or the exception it raised (its original exception, not Ray's wrapper).

    ``work`` must be a module-level function (workers import it by name). ``address``
    is the Ray cluster (:func:`viewdb.ray_cluster.connect`)."""
    config = config or RayIngestConfig()
    ray = connect(address)
    task = ray.remote(work).options(num_cpus=config.task_cpus, max_retries=config.max_retries,
                                    retry_exceptions=False)
    shared = [ray.put(a) for a in args]  # sent once, not once per object
    cpus = float(ray.cluster_resources().get("CPU", 1.0))
    limit = max(1, int(cpus * config.in_flight_per_cpu))
    queue: Iterator[J] = iter(jobs)
    pending: dict[Any, J] = {}

    def fill() -> None:
        while len(pending) < limit:
            job = next(queue, None)
            if job is None:
                return
            pending[task.remote(job, *shared)] = job

    try:
        fill()
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=len(pending), timeout=POLL_SECONDS)
            for ref in ready:
                finish(pending.pop(ref), _outcome(ray, ref))
            fill()
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise


def _outcome(ray: Any, ref: Any) -> Any:
    """A finished task's value, or the exception that ended it."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as exc:  # raised by the work itself: its own error
        cause = getattr(exc, "cause", None)
        return cause if isinstance(cause, BaseException) else exc
    except ray.exceptions.RayError as exc:  # the worker died more than max_retries times, …
        return exc
