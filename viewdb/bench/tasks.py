"""The measurements of a bench run: one :class:`Task` per (query, configuration), in order
(:func:`plan_tasks`); the runner measures them, the report reads them back by key."""

from __future__ import annotations

from dataclasses import dataclass

from .config import CONFIGURATIONS, BenchConfig
from .log import record_key

__all__ = ["Task", "plan_tasks"]


@dataclass(frozen=True)
class Task:
    """One measurement: a query under one configuration."""

    protocol: str
    query: int
    skim: bool
    plan: str
    client_gap: float | None
    k: int

    @property
    def key(self) -> str:
        return record_key(self.protocol, self.query, self.skim, self.plan, self.client_gap, self.k)


def plan_tasks(config: BenchConfig) -> list[Task]:
    """Every measurement of a run, in order, without duplicates."""
    groups: list[tuple[str, bool, str, float | None, int]] = []
    for protocol in config.protocols:
        for c in CONFIGURATIONS:
            groups.append((protocol, c.skim, c.plan,
                           None if c.plan == "server" else config.client_gap, config.k))
    for protocol in config.timing_protocols:
        for skim in (True, False):
            for k in range(1, config.k + 1):
                groups.append((protocol, skim, "server", None, k))
                for plan in ("cs1", "cs2"):
                    for gap in config.gaps:
                        groups.append((protocol, skim, plan, float(gap), k))
    seen: set[str] = set()
    tasks = []
    for protocol, skim, plan, client_gap, k in groups:
        for q in range(config.queries):
            task = Task(protocol, q, skim, plan, client_gap, k)
            if task.key not in seen:
                seen.add(task.key)
                tasks.append(task)
    return tasks
