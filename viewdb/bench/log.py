"""The per-query results log: one JSON line per (query, configuration), appended and
flushed as each finishes, so a killed run loses at most the line being written and a
restart skips every key already present."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import ViewDBError

__all__ = ["ResultLog", "record_key"]


def record_key(protocol: str, query: int, skim: bool, plan: str, client_gap: float | None,
               k: int) -> str:
    """The key of one record: everything that decides what it measured."""
    gap = "-" if client_gap is None else f"{client_gap:g}"
    return f"{protocol}/{query}/{'skim' if skim else 'noskim'}/{plan}/{gap}/{k}"


class ResultLog:
    """An append-only JSONL file of records, each with a unique ``key``."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.records: dict[str, dict[str, Any]] = {}
        if path.exists():
            data = path.read_bytes()
            lines = data.split(b"\n")
            keep = len(data)
            for i, line in enumerate(lines):
                if not line.strip():
                    continue
                try:
                    record = json.loads(line)
                except ValueError:
                    if i == len(lines) - 1:  # the last line, cut short by a kill: drop it
                        keep = len(data) - len(line)
                        break
                    raise ViewDBError(f"line {i + 1} is not JSON", path) from None
                self.records[record["key"]] = record
            with path.open("r+b") as f:
                f.truncate(keep)
                if keep and data[keep - 1 : keep] != b"\n":  # a whole last line without its newline
                    f.seek(keep)
                    f.write(b"\n")
        self._file = path.open("a", encoding="utf-8")

    def __contains__(self, key: str) -> bool:
        return key in self.records

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return iter(self.records.values())

    def __len__(self) -> int:
        return len(self.records)

    def append(self, record: dict[str, Any]) -> None:
        self.records[record["key"]] = record
        self._file.write(json.dumps(record) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> ResultLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
