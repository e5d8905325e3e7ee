"""Which shards of a sharded catalogue are up, and the watcher that readmits a restarted one.

A shard actor that dies is restarted by Ray (:mod:`viewdb.shards.cluster` starts the actors
with ``ShardConfig.max_restarts``); the restarted actor reopens and checks its file in its
constructor. :class:`ShardHealth` is the server's view of that: a shard is *down* from the
moment a call to it fails or Ray reports its actor not alive, and *up* again only once the
restarted actor answers and holds the same objects in the same versions as when the
catalogue was opened. A query needing a down shard fails at once with
:class:`~viewdb.errors.ShardUnavailable` (HTTP 503 with ``Retry-After``), never with a
partial answer.

This module knows nothing of Ray: the watcher is given two functions, ``state(i)`` (Ray's
record of actor ``i``: ``"ALIVE"``, ``"RESTARTING"``, ``"DEAD"`` …, or ``None`` when
unknown) and ``readmit(i)`` (``None`` once shard ``i`` answers as before, else why not).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..errors import ShardUnavailable

__all__ = ["ShardHealth", "ShardStatus"]


@dataclass
class ShardStatus:
    """One shard as the server sees it."""

    up: bool = True
    #: Why it is down (empty when up).
    reason: str = ""
    #: ``time.monotonic()`` when it went down (None when up).
    down_since: float | None = None
    #: Times it came back after going down.
    recoveries: int = 0
    #: Seconds each recovery took, from going down to answering again.
    gaps: tuple[float, ...] = ()
    #: Ray will not restart its actor (restarts used up, or killed for good).
    final: bool = False
    #: ``time.monotonic()`` when it was last readmitted (None: up since the start).
    up_since: float | None = None

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {"up": self.up, "recoveries": self.recoveries}
        if not self.up:
            out["reason"], out["restarting"] = self.reason, not self.final
            out["down_s"] = round(time.monotonic() - (self.down_since or time.monotonic()), 3)
        return out


class ShardHealth:
    """The up/down state of ``len(files)`` shards, safe to share between threads; with
    :meth:`watch`, a daemon thread that keeps it current (module doc)."""

    def __init__(self, files: Sequence[Path], retry_after: float) -> None:
        self.files = list(files)
        self.retry_after = retry_after
        self._status = [ShardStatus() for _ in self.files]
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ------------------------------------------------------------------ state
    def down(self, shard: int, reason: str, final: bool = False, sent: float | None = None) -> None:
        """Mark ``shard`` down (a call to it failed, or Ray says its actor is not alive;
        ``final``: it will not be restarted). ``sent``: when the failed call was sent
        (``time.monotonic()``); a call sent before the shard was last readmitted failed on
        the actor that died before, and leaves the restarted one up (were it dead too, the
        watcher sees it in Ray's record)."""
        with self._lock:
            s = self._status[shard]
            if sent is not None and s.up and s.up_since is not None and sent < s.up_since and not final:
                return
            if s.up:
                s.up, s.reason, s.down_since = False, reason, time.monotonic()
            if final:
                s.final, s.reason = True, reason

    def up(self, shard: int) -> None:
        """Mark ``shard`` up again, counting the recovery and its gap."""
        with self._lock:
            s = self._status[shard]
            if not s.up:
                now = time.monotonic()
                gap = now - (s.down_since or now)
                s.up, s.reason, s.down_since, s.up_since = True, "", None, now
                s.recoveries += 1
                s.gaps = (*s.gaps, gap)

    def require(self, shards: Sequence[int]) -> None:
        """:class:`ShardUnavailable` (with ``retry_after``) if any of ``shards`` is down."""
        with self._lock:
            down = next((i for i in shards if not self._status[i].up), None)
            if down is None:
                return
            reason, final = self._status[down].reason, self._status[down].final
        if final:
            raise ShardUnavailable(f"shard {down} is down for good ({reason}); no partial answer "
                                   "is given: restart the server", self.files[down])
        raise ShardUnavailable(f"shard {down} is down ({reason}); no partial answer is given: "
                               f"it is being restarted, retry in {self.retry_after:g} s",
                               self.files[down], retry_after=self.retry_after)

    def snapshot(self) -> list[ShardStatus]:
        """A copy of every shard's status, in shard order."""
        with self._lock:
            return [ShardStatus(**vars(s)) for s in self._status]

    def all_up(self) -> bool:
        with self._lock:
            return all(s.up for s in self._status)

    # ------------------------------------------------------------------ the watcher
    def watch(self, state: Callable[[int], str | None], readmit: Callable[[int], str | None],
              interval: float) -> None:
        """Start the watcher thread: every ``interval`` seconds each shard whose actor Ray
        does not report alive is marked down, and each down shard whose actor is alive
        again is readmitted if ``readmit`` finds it answering as before."""
        def loop() -> None:
            while not self._stop.wait(interval):
                for i in range(len(self.files)):
                    try:
                        self._probe(i, state, readmit)
                    except Exception:  # noqa: BLE001, S112 - the watcher outlives a bad probe
                        continue

        self._thread = threading.Thread(target=loop, name="viewdb-shard-watch", daemon=True)
        self._thread.start()

    def _probe(self, i: int, state: Callable[[int], str | None],
               readmit: Callable[[int], str | None]) -> None:
        now = state(i)
        with self._lock:
            is_up = self._status[i].up
        if now is not None and now != "ALIVE":
            self.down(i, f"its actor is {now.lower()}", final=now == "DEAD")
            return
        if not is_up and now == "ALIVE":
            problem = readmit(i)
            if problem is None:
                self.up(i)
            else:
                with self._lock:
                    self._status[i].reason = problem

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
