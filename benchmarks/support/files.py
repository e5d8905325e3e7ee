"""Copies of a catalogue for benchmarks that change one: the database and the files beside it."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

from viewdb.storage.ann_file import ann_file_path
from viewdb.storage.tier_file import tier_file_path


def copy_catalogue(src: Path, dst: Path, fast_index: bool = True) -> Path:
    """``src`` copied to ``dst`` by SQLite's backup (whole and consistent while others read
    it), with its tier files and, if ``fast_index``, its ``fast`` index; ``dst``."""
    a, b = sqlite3.connect(src), sqlite3.connect(dst)
    try:
        a.backup(b)
    finally:
        a.close()
        b.close()
    beside = [tier_file_path(src, "full"), tier_file_path(src, "sparse")]
    if fast_index:
        beside.append(ann_file_path(src, "full"))
    for path in beside:
        if path.exists():
            shutil.copy(path, dst.with_name(dst.name + path.name[len(src.name):]))
    return dst
