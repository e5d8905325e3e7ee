"""Pure summaries of per-query records: CMC curves and timing statistics.

The cumulative match characteristic (CMC) at rank r is the share of queries whose true
object is among the first r objects returned (section IV.B, Fig. 6); a query that failed
(e.g. no object found in a photo) counts as a miss at every rank.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

__all__ = ["cmc", "rank_of", "timing_summary"]


def rank_of(truth: str, results: Sequence[str]) -> int | None:
    """1-based rank of ``truth`` in ``results`` (None if absent)."""
    for i, name in enumerate(results, 1):
        if name == truth:
            return i
    return None


def cmc(ranks: Iterable[int | None], max_rank: int) -> list[float]:
    """Identification rate at ranks 1..max_rank: non-decreasing, in [0, 1]."""
    ranks = list(ranks)
    if not ranks:
        return [0.0] * max_rank
    hits = np.zeros(max_rank + 1)
    for r in ranks:
        if r is not None and r <= max_rank:
            hits[r] += 1
    return [float(x) for x in np.cumsum(hits)[1:] / len(ranks)]


def timing_summary(records: Sequence[dict[str, Any]]) -> dict[str, float]:
    """Medians and means of a group of records' client, server and total milliseconds,
    and mean payload bytes each way."""
    out: dict[str, float] = {"n": len(records)}
    for field in ("client_ms", "server_ms", "total_ms", "bytes_sent", "bytes_received"):
        values = np.array([r[field] for r in records if r.get(field) is not None], dtype=np.float64)
        if field.endswith("_ms"):
            out[f"{field[:-3]}_median_ms"] = float(np.median(values)) if len(values) else float("nan")
            out[f"{field[:-3]}_mean_ms"] = float(np.mean(values)) if len(values) else float("nan")
        else:
            out[f"{field}_mean"] = float(np.mean(values)) if len(values) else float("nan")
    return out
