"""The sparse and full tiers in the database: groups of views and their R-trees.

Writing: :func:`write_groups` adds one object's groups to both tiers (rows of
``index_groups`` and an R-tree entry per group) inside the caller's transaction, and
:func:`delete_groups` takes them out again; the ingest calls both in the transaction
that writes the object, so an object is in the index exactly when it is in the file.

Reading: :class:`StoredTier` is a :class:`~viewdb.search.knn.TierSource` over one tier
of an open file: the R-tree answers "which groups lie within distance d of the query
box" (a box query widened by d, then the exact MINDIST); the groups' MBRs and curve
ranges are read when the tier is opened, and a group's curves (one row) the first time
a search reaches it, into arrays kept for the life of the open tier.
"""

from __future__ import annotations

import json
import sqlite3
import stat
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import BuildConfig, FastConfig, SearchConfig
from ..errors import QueryError, StorageError
from ..search.bounds import paa_edges, paa_means, rounded32
from ..search.fast import FastIndex
from ..search.grouping import (
    DIMENSION,
    group_points,
    indexed_coordinates,
    padded_mbr,
    tier_members,
)
from ..search.knn import QueryBoxes, TierArrays
from .ann_file import open_fast_index
from .codecs import decode_array, decode_many, encode_array, encode_quantised, quantised_blobs
from .spatial import FourierIndex, raw_connection
from .tier_file import map_tier_file, new_generation, tier_file_path, tier_key, write_tier_file

__all__ = [
    "TIERS",
    "StoredTier",
    "TierReader",
    "create_tiers",
    "delete_groups",
    "index_stored_objects",
    "orthographic_angles",
    "write_groups",
]

#: The two tiers: every stored view (server grid) and the client grid's stand-ins.
TIERS = ("full", "sparse")

#: Views whose coordinates and segment means are computed together when curves are read:
#: small enough for BLAS to stay on one thread (a few thousand rows at once made OpenBLAS
#: spread the thin product over threads and cost ten times the CPU on a loaded machine).
_BLOCK = 256


def rows_with_ids(conn: sqlite3.Connection, sql: str, ids: Sequence[int]) -> Iterator[tuple[Any, ...]]:
    """The rows of ``sql`` (``... WHERE id IN ({})``) for ``ids``, queried in chunks:
    SQLite caps the variables of one statement."""
    for start in range(0, len(ids), 900):
        chunk = list(ids[start : start + 900])
        yield from conn.execute(sql.format(",".join("?" * len(chunk))), chunk)


def orthographic_angles(conn: sqlite3.Connection, view_ids: Sequence[int]) -> dict[int, tuple[float, float]]:
    """``view id -> (azimuth, elevation)`` of stored orthographic views (ids not stored are
    left out)."""
    return {int(i): (float(a), float(e)) for i, a, e in rows_with_ids(
        conn, "SELECT id, azimuth, elevation FROM views WHERE id IN ({})", [int(i) for i in view_ids])}


def _stacked(blobs: list[Any], dtype: type) -> NDArray[Any]:
    """Equal-length 1-D arrays, one BLOB each, as the rows of one ``(len(blobs), n)`` array."""
    data, shapes = decode_many(blobs, dtype, 1)
    if len(shapes) and (shapes[:, 0] != shapes[0, 0]).any():
        raise StorageError("index groups hold arrays of different lengths in one column")
    return data.reshape(len(shapes), int(shapes[0, 0]) if len(shapes) else 0)


def _group_columns(conn: sqlite3.Connection, tier: str) -> dict[str, NDArray[Any]]:
    """Every group's id, owner, MBR, curve range and view ids in tier ``tier``, each
    column decoded in one go (the arrays :class:`StoredTier` keeps but its curves)."""
    rows = conn.execute(
        "SELECT id, object_id, lo, hi, curve_lo, curve_hi, view_ids FROM index_groups"
        " WHERE tier = ? ORDER BY id",
        (tier,),
    ).fetchall()
    object_ids, owner = np.unique(np.array([r[1] for r in rows], dtype=np.int64), return_inverse=True)
    # copies, writable as a tier file's arrays are (the kernels are compiled for those)
    lo, hi = (np.array(_stacked([r[i] for r in rows], np.float64)) for i in (2, 3))
    curve_lo, curve_hi = (np.array(_stacked([r[i] for r in rows], np.float32)) for i in (4, 5))
    views, shapes = decode_many([r[6] for r in rows], np.int64, 1)
    return {"ids": np.array([r[0] for r in rows], dtype=np.int64), "object_ids": object_ids,
            "group_owner": owner.astype(np.int64).reshape(-1), "group_count": shapes[:, 0].copy(),
            "views": views, "lo": lo, "hi": hi, "curve_lo": curve_lo, "curve_hi": curve_hi}


def create_tiers(conn: Any) -> None:
    """Create the empty R-trees of both tiers (the tables must exist)."""
    for tier in TIERS:
        FourierIndex.create(conn, tier, DIMENSION).close()


def write_groups(
    conn: Any,
    object_id: int,
    view_ids: Sequence[int],
    curves: NDArray[np.floating],
    members: Mapping[str, Sequence[int]],
    group_views: int,
    curve_bits: int = 0,
) -> dict[str, int]:
    """Group one object's views of each tier and index the groups; returns group counts.

    ``members[tier]`` are positions in ``view_ids``/``curves`` of the views in that tier.
    ``curve_bits`` > 0 stores each group's curves quantised to that many bits (a compact
    client file) with their error norms in ``curve_errors``; the boxes are then those of
    the decoded curves, which are what a search reads. Runs in the caller's transaction;
    on an error the caller must roll back.
    """
    raw = raw_connection(conn)
    new_generation(raw)
    ids = np.asarray(view_ids, dtype=np.int64)
    all_curves = np.asarray(curves, dtype=np.float32)
    counts = {}
    for tier in TIERS:
        sel = np.asarray(members.get(tier, ()), dtype=np.int64)
        counts[tier] = 0
        if not len(sel):
            continue
        tier_curves = all_curves[sel]
        coords = indexed_coordinates(tier_curves)
        index = FourierIndex.open(raw, tier)
        try:
            for group in group_points(coords, group_views):
                grouped = tier_curves[group]
                blob, errors = encode_array(grouped), None
                if curve_bits:
                    blob, errors = encode_quantised(grouped, curve_bits)
                    grouped = decode_array(blob, np.float32, grouped.shape)
                    lo, hi = padded_mbr(indexed_coordinates(grouped))
                else:
                    lo, hi = padded_mbr(coords[group])
                gid = raw.execute(
                    "INSERT INTO index_groups (tier, object_id, view_ids, curves, lo, hi,"
                    " curve_lo, curve_hi) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                    (tier, int(object_id), encode_array(ids[sel][group]), blob,
                     encode_array(lo), encode_array(hi), encode_array(grouped.min(axis=0)),
                     encode_array(grouped.max(axis=0))),
                ).lastrowid
                assert gid is not None  # an INSERT's row
                if errors is not None:
                    raw.execute("INSERT INTO curve_errors (group_id, errors) VALUES (?, ?)",
                                (gid, encode_array(rounded32(errors, up=True))))
                index.insert_box(int(gid), lo, hi)
                counts[tier] += 1
            index.close()
        except BaseException:
            index.discard()
            raise
    return counts


def delete_groups(conn: Any, object_ids: Iterable[int], tiers: Sequence[str] = TIERS) -> None:
    """Take the objects' groups out of ``tiers`` (default both; caller's transaction)."""
    raw = raw_connection(conn)
    new_generation(raw)
    for object_id in object_ids:
        rows = [r for r in raw.execute(
            "SELECT id, tier, lo, hi FROM index_groups WHERE object_id = ?", (int(object_id),)
        ) if r[1] in tiers]
        for tier in tiers:
            mine = [r for r in rows if r[1] == tier]
            if not mine:
                continue
            index = FourierIndex.open(raw, tier)
            try:
                for gid, _, lo, hi in mine:
                    index.delete_box(
                        gid, decode_array(lo, np.float64, (DIMENSION,)),
                        decode_array(hi, np.float64, (DIMENSION,)),
                    )
                index.close()
            except BaseException:
                index.discard()
                raise
        raw.executemany("DELETE FROM index_groups WHERE id = ?", [(int(r[0]),) for r in rows])


#: Groups :meth:`StoredTier.groups_meeting` tests to estimate a browse's share.
SCAN_SAMPLE = 256


def _meeting(
    lo: NDArray[np.float64], hi: NDArray[np.float64], los: NDArray[np.float64], his: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Whether each MBR ``[lo[g], hi[g]]`` meets any of the closed boxes ``[los[i], his[i]]``
    (as the R-tree decides: every coordinate's intervals overlap, ends included)."""
    meets = np.zeros(len(lo), dtype=np.bool_)
    for box_lo, box_hi in zip(los, his, strict=True):
        meets |= ((lo <= box_hi) & (hi >= box_lo)).all(axis=1)
    return meets


class StoredTier:
    """One tier of an open database as a search source (see the module doc).

    Reads through ``conn`` (a plain :class:`sqlite3.Connection`), which the caller keeps
    in one read transaction per search so the R-tree pages and rows agree.
    """

    def __init__(self, conn: sqlite3.Connection, tier: str,
                 mapped: Mapping[str, NDArray[Any]] | None = None) -> None:
        """``mapped``: the tier's arrays from its tier file (:mod:`~viewdb.storage.tier_file`),
        every group loaded; else the groups' columns are read and their curves on demand."""
        if tier not in TIERS:
            raise ValueError(f"tier must be one of {', '.join(TIERS)}, got {tier!r}")
        self.conn = conn
        self.tier = tier
        #: whether the arrays are a tier file's (else decoded from the groups)
        self.mapped = mapped is not None
        #: the tier's key (:func:`~viewdb.storage.tier_file.tier_key`) when a reader opened it
        self.key = ""
        self.index = FourierIndex.open(conn, tier)
        columns = _group_columns(conn, tier) if mapped is None else mapped
        self._ids = columns["ids"]
        self._object_ids = columns["object_ids"]
        self.group_owner = columns["group_owner"]
        self.n_groups = len(self._ids)
        self.n_objects = len(self._object_ids)
        self._lo, self._hi = columns["lo"], columns["hi"]
        self._curve_lo, self._curve_hi = columns["curve_lo"], columns["curve_hi"]
        self._views = columns["views"]
        self.group_count = columns["group_count"]
        self.group_start = np.concatenate([[0], np.cumsum(self.group_count)[:-1]]).astype(np.int64)
        self.row_owner = np.repeat(self.group_owner, self.group_count)
        samples = self._curve_lo.shape[1] if self.n_groups else 0
        self._edges = paa_edges(max(samples, 1))
        if mapped is None:
            # curves and coordinates of every view, filled in group by group as searches need them
            self._curves = np.empty((len(self._views), samples), dtype=np.float32)
            self._coords = np.empty((len(self._views), DIMENSION), dtype=np.float64)
            self._means = np.empty((len(self._views), len(self._edges) - 1), dtype=np.float64)
            self._loaded = np.zeros(self.n_groups, dtype=np.bool_)
        else:
            self._curves, self._coords, self._means = mapped["curves"], mapped["coords"], mapped["means"]
            self._loaded = np.ones(self.n_groups, dtype=np.bool_)
        #: per view row: its quantisation error norms (L2, L-infinity); zero for exact curves
        self.errors = np.zeros((len(self._views), 2), dtype=np.float64)
        if mapped is None:
            self._read_errors()
        self.quantised = bool(self.errors.any())
        self._row_of_view = {int(v): r for r, v in enumerate(self._views.tolist())} if self.quantised else {}
        names: dict[int, str] = dict(conn.execute("SELECT id, name FROM objects"))
        self._names = [names[int(i)] for i in self._object_ids]
        self._index_by_name = {name: i for i, name in enumerate(self._names)}
        #: the last answer of :meth:`groups_within`: (its boxes, its group rows)
        self._last_within: tuple[tuple[bytes, bytes], NDArray[np.int64]] | None = None
        #: a browse estimated to meet more than this share of the groups scans their MBRs
        #: instead of asking the R-tree (:meth:`groups_meeting`)
        self.scan_share = SearchConfig().scan_share
        self._sample = np.arange(0, self.n_groups, max(1, self.n_groups // SCAN_SAMPLE), dtype=np.int64)

    def _read_errors(self) -> None:
        at = {int(gid): g for g, gid in enumerate(self._ids.tolist())}
        for gid, blob in self.conn.execute(
            "SELECT e.group_id, e.errors FROM curve_errors e JOIN index_groups g"
            " ON g.id = e.group_id WHERE g.tier = ?", (self.tier,)
        ):
            g = at[int(gid)]
            a, n = int(self.group_start[g]), int(self.group_count[g])
            self.errors[a : a + n] = decode_array(blob, np.float32, (n, 2))

    def file_arrays(self) -> dict[str, NDArray[Any]]:
        """Every array a tier file holds (:data:`~viewdb.storage.tier_file.ARRAYS`), every
        group loaded first."""
        self.rows(np.arange(self.n_groups, dtype=np.int64))
        return {"ids": self._ids, "object_ids": self._object_ids, "group_owner": self.group_owner,
                "group_count": self.group_count, "views": self._views, "lo": self._lo,
                "hi": self._hi, "curve_lo": self._curve_lo, "curve_hi": self._curve_hi,
                "curves": self._curves, "coords": self._coords, "means": self._means}

    def close(self) -> None:
        self.index.discard()

    def groups_within(
        self, query: QueryBoxes, radius: float, seen: NDArray[np.bool_]
    ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
        los = np.stack([query.box[0], query.mirrored_box[0]]) - radius
        his = np.stack([query.box[1], query.mirrored_box[1]]) + radius
        # the threads of one search (knn.py) ask for the same boxes in turn, each for its own
        # objects' groups: the R-tree's last answer serves the next ask for the same boxes
        boxes = (los.tobytes(), his.tobytes())
        if self._last_within is not None and self._last_within[0] == boxes:
            at = self._last_within[1]
        else:
            at = self.groups_meeting(los, his)
            self._last_within = (boxes, at)
        at = at[~seen[at]]
        if not len(at):
            return at, np.zeros(0)
        _, keys = query.group_keys(self._lo, self._hi, self._curve_lo, self._curve_hi, at)
        return at, keys

    def groups_meeting(self, los: NDArray[np.float64], his: NDArray[np.float64]) -> NDArray[np.int64]:
        """The groups (rows, ascending) whose MBR meets any of the closed boxes ``[los[i],
        his[i]]``: the R-tree's answer, or the same groups found by comparing every group's
        MBR with the boxes when a strided sample of the groups says the boxes meet more
        than :attr:`scan_share` of them. An R-tree pays when it can skip most of its
        nodes; a browse wide enough to meet most groups reads nearly every node, one page
        at a time, where the comparison is one pass over arrays already in memory."""
        if len(self._sample) and _meeting(self._lo[self._sample], self._hi[self._sample], los, his).mean() \
                > self.scan_share:
            return np.flatnonzero(_meeting(self._lo, self._hi, los, his)).astype(np.int64)
        return np.searchsorted(self._ids, self.index.intersection_many(los, his)).astype(np.int64)

    def rows(
        self, groups: NDArray[np.int64]
    ) -> tuple[NDArray[np.float32], NDArray[np.float64], NDArray[np.float64]]:
        if self.mapped:  # a tier file's: every group is loaded
            return self._curves, self._coords, self._means
        missing = np.unique(groups[~self._loaded[groups]])
        if len(missing):
            found = dict(rows_with_ids(self.conn, "SELECT id, curves FROM index_groups WHERE id IN ({})",
                                       self._ids[missing].tolist()))
            self._fill(missing, [found.get(int(i)) for i in self._ids[missing]])
        return self._curves, self._coords, self._means

    def _fill(self, groups: NDArray[np.int64], blobs: list[Any]) -> None:
        """Decode the curves of ``groups`` (one BLOB each) into their rows, with their
        indexed coordinates and segment means, all groups at once."""
        if not self.quantised and quantised_blobs(blobs):
            raise StorageError("holds quantised curves without their error bounds (curve_errors): "
                               "export the client file again")
        data, shapes = decode_many(blobs, np.float32, 2)
        counts = self.group_count[groups]
        samples = self._curves.shape[1]
        if not ((shapes[:, 0] == counts).all() and (shapes[:, 1] == samples).all()):
            bad = int(np.argmin((shapes[:, 0] == counts) & (shapes[:, 1] == samples)))
            raise StorageError(f"index group {int(self._ids[groups[bad]])} holds curves of shape "
                               f"{tuple(shapes[bad])}, expected ({int(counts[bad])}, {samples})")
        # the rows of the groups, in the order their curves arrived
        at = np.repeat(self.group_start[groups] - np.cumsum(counts) + counts, counts) + np.arange(
            int(counts.sum()))
        curves = data.reshape(-1, samples)
        self._curves[at] = curves
        for start in range(0, len(curves), _BLOCK):
            block = curves[start : start + _BLOCK].astype(np.float64)
            rows = at[start : start + _BLOCK]
            self._coords[rows] = indexed_coordinates(block)
            self._means[rows] = paa_means(block, self._edges)
        self._loaded[groups] = True
    def group_boxes(
        self,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float32], NDArray[np.float32]]:
        """Every group's MBR and per-sample curve range (read when the tier was opened)."""
        return self._lo, self._hi, self._curve_lo, self._curve_hi

    def view_id(self, row: int) -> int:
        return int(self._views[row])

    def view_errors(self, view_id: int) -> NDArray[np.float64]:
        """The quantisation error norms (L2, L-infinity) of view ``view_id``'s stored curve
        (zero for an exact curve; :mod:`viewdb.search.quantised`)."""
        row = self._row_of_view.get(int(view_id))
        return self.errors[row] if row is not None else np.zeros(2)

    def object_name(self, index: int) -> str:
        return self._names[index]

    def object_index(self, name: str) -> int | None:
        """The source's index of object ``name`` (None if it has none)."""
        return self._index_by_name.get(name)

    def orthographic_views(self, name: str) -> tuple[NDArray[np.int64], NDArray[np.float32]] | None:
        """The view ids and curves of object ``name``'s orthographic views in this tier (its
        rows of positive view id), or None for an object it does not hold or a tier whose
        curves are not all loaded (read from the groups on demand)."""
        o = self._index_by_name.get(name)
        if o is None or not self.mapped:
            return None
        rows = np.flatnonzero((self.row_owner == o) & (self._views > 0))
        return np.asarray(self._views[rows], np.int64), self._curves[rows]


def index_stored_objects(conn: Any, config: BuildConfig) -> int:
    """Index every stored object's views in both tiers (for files from before the
    R-trees; the tiers must be empty). Returns the number of objects indexed."""
    from ..catalogue.symmetry import SymmetryType

    raw = raw_connection(conn)
    objects = raw.execute("SELECT id, skimmed, symmetry FROM objects ORDER BY id").fetchall()
    for object_id, skimmed, symmetry in objects:
        rows = raw.execute(
            "SELECT v.id, v.azimuth, v.elevation, c.samples FROM views v"
            " JOIN curves c ON c.view_id = v.id WHERE v.object_id = ? ORDER BY v.id",
            (object_id,),
        ).fetchall()
        if not rows:
            continue
        sym = None if symmetry is None else SymmetryType.from_dict(json.loads(symmetry))
        positions = [(float(r[1]), float(r[2])) for r in rows]
        members = tier_members(positions, config.gap, config.client_gap, sym, bool(skimmed))
        curves = np.stack([decode_array(r[3], np.float32, (None,)) for r in rows])
        write_groups(raw, object_id, [r[0] for r in rows], curves, members,
                     config.index.group_views)
    return len(objects)


class TierReader:
    """A read connection for searches, with the tiers opened on it.

    Each :meth:`snapshot` is one read transaction (WAL: a consistent view of the file while
    an ingest writes). If another connection committed since the last snapshot (SQLite's
    ``data_version``), the opened tiers are dropped and reopened, so a long-lived reader
    (a server) sees new objects and never mixes cached R-tree pages of two versions.
    Thread-safe: snapshots are serialised.
    """

    def __init__(self, path: str | Path, connect: Callable[[], sqlite3.Connection] | None = None,
                 *, write_files: bool = False) -> None:
        """``connect`` makes the connection (e.g. a read-only one); default: open ``path``.
        ``write_files``: write a tier's file (:mod:`~viewdb.storage.tier_file`) when it opens
        the tier without a valid one (a tier file is used whenever valid, either way)."""
        self.path = Path(path)
        self.write_files = write_files
        try:
            self.conn = (connect() if connect is not None else
                         sqlite3.connect(self.path, check_same_thread=False, isolation_level=None))
            self.conn.execute("PRAGMA query_only = 1")
            self.conn.execute("PRAGMA busy_timeout = 5000")
        except sqlite3.Error as exc:
            raise StorageError(f"cannot open for reading: {exc}", self.path) from exc
        self._lock = threading.Lock()
        self._tiers: dict[str, StoredTier] = {}
        #: the ``fast`` indexes of the opened tiers (None: none valid, none written)
        self._fast: dict[tuple[str, str], FastIndex | None] = {}
        self._version: int | None = None
        self._versions: dict[str, str] | None = None
        #: this process wrote the file since the last snapshot (:meth:`written`)
        self._written = False

    def close(self) -> None:
        with self._lock:
            self._drop()
            self.conn.close()

    def _drop(self) -> None:
        for tier in self._tiers.values():
            tier.close()
        self._tiers = {}
        self._fast = {}
        self._versions = None

    @contextmanager
    def snapshot(self) -> Iterator[TierReader]:
        with self._lock:
            try:
                self.conn.execute("BEGIN")
                self.conn.execute("SELECT 1 FROM rtree_meta LIMIT 1").fetchall()  # starts the read
                version = int(self.conn.execute("PRAGMA data_version").fetchone()[0])
            except sqlite3.Error as exc:
                if self.conn.in_transaction:
                    self.conn.execute("ROLLBACK")
                raise StorageError(f"database error: {exc}", self.path) from exc
            if version != self._version:
                self._drop()
                self._version = version
            self._written = False
            try:
                yield self
            except sqlite3.Error as exc:
                raise StorageError(f"database error: {exc}", self.path) from exc
            finally:
                self.conn.execute("ROLLBACK")

    def loaded(self, name: str) -> StoredTier | None:
        """Tier ``name`` as the last :meth:`snapshot` left it, if one opened it and this
        process has not written the file since (no lock taken, nothing read: for reads of
        what the last search saw)."""
        return None if self._written else self._tiers.get(name)

    def written(self) -> None:
        """This process wrote the file: :meth:`loaded` answers nothing until the next
        :meth:`snapshot` (which sees the new version)."""
        self._written = True

    def tier(self, name: str) -> StoredTier:
        """Tier ``name`` (call inside :meth:`snapshot`)."""
        tier = self._tiers.get(name)
        if tier is None:
            tier = self._tiers[name] = self._open_tier(name)
        return tier

    def _open_tier(self, name: str) -> StoredTier:
        """Tier ``name`` from its tier file if it has a valid one; else from its groups,
        writing the file if this reader writes files and the folder allows."""
        if name not in TIERS:
            raise ValueError(f"tier must be one of {', '.join(TIERS)}, got {name!r}")
        path, key = tier_file_path(self.path, name), tier_key(self.conn, name)
        mapped = map_tier_file(path, key, name)
        tier = StoredTier(self.conn, name, mapped)
        tier.key = key
        if mapped is None and self.write_files and tier.n_groups and not tier.quantised:
            try:
                write_tier_file(path, key, name, tier.file_arrays(), self._cache_mode())
            except OSError:
                pass  # a folder this process may not write: the tier is read as before
        return tier

    def _cache_mode(self) -> int:
        """The permissions of the files written beside the database (tier files, ``fast``
        indexes): its own, less any execute bit. Raises OSError if it cannot be read."""
        return stat.S_IMODE(self.path.stat().st_mode) & 0o666

    def write_tier_files(self) -> None:
        """Open every tier (inside :meth:`snapshot`), writing the files of those without a
        valid one (``write_files`` readers only), and the full tier's ``fast`` index
        (:mod:`~viewdb.storage.ann_file`)."""
        for name in TIERS:
            self.tier(name)
        self.fast_index("full")

    def fast_index(self, name: str = "full", config: FastConfig | None = None) -> FastIndex | None:
        """The ``fast`` plan's index of tier ``name`` (inside :meth:`snapshot`): its file's
        if valid for this version of the database; else built (and its file written) by a
        reader that writes files; else None, and the plan searches exactly. None too for
        an empty tier or quantised curves (a client file)."""
        config = config or FastConfig()
        slot = (name, config.index_key())
        if slot not in self._fast:
            tier = self.tier(name)
            index = None
            if tier.n_groups and not tier.quantised:
                mode = self._cache_mode() if self.write_files else 0o644
                index = open_fast_index(tier, self.path, name, tier.key, config, self.write_files, mode)
            self._fast[slot] = index
        found = self._fast[slot]
        return None if found is None else replace(found, config=config)

    def view_angles(self, view_ids: Sequence[int]) -> dict[int, tuple[float, float]]:
        """``view id -> (azimuth, elevation)`` (inside :meth:`snapshot`); a perspective
        view's (negative) id gives its direction, the same as the orthographic view's."""
        return {i: (a, e) for i, (a, e, _) in self.view_projections(view_ids).items()}

    def view_projections(self, view_ids: Sequence[int]) -> dict[int, tuple[float, float, float | None]]:
        """``view id -> (azimuth, elevation, distance)``, distance None for an orthographic
        view and the camera distance in bounding radii for a perspective one."""
        ids = [int(i) for i in view_ids]
        orthographic = orthographic_angles(self.conn, [i for i in ids if i > 0])
        out: dict[int, tuple[float, float, float | None]] = {
            i: (a, e, None) for i, (a, e) in orthographic.items()}
        for i, a, e, d in rows_with_ids(
            self.conn, "SELECT id, azimuth, elevation, distance FROM perspective_views WHERE id IN ({})",
            [-i for i in ids if i < 0],
        ):
            out[-int(i)] = (float(a), float(e), float(d))
        return out

    def object_versions(self) -> dict[str, str]:
        """``object name -> version`` of every object (inside :meth:`snapshot`; read once
        per version of the file, like the tiers): its content hash, the file's
        :meth:`~viewdb.config.BuildConfig.curve_key` and whether its views were skimmed,
        so a client's bounds count only where both files hold the same curves."""
        if self._versions is None:
            row = self.conn.execute("SELECT value FROM settings WHERE key = 'build'").fetchone()
            key = "" if row is None else BuildConfig.from_dict(json.loads(row[0])).curve_key()
            self._versions = {
                name: f"{content_hash}{key}{'s' if skimmed else 'a'}" for name, content_hash, skimmed
                in self.conn.execute("SELECT name, content_hash, skimmed FROM objects")}
        return self._versions

    def tier_arrays(self, name: str) -> tuple[TierArrays, list[tuple[int, float, float]]]:
        """Every view of tier ``name`` in memory (the brute-force reference and the flat
        scan), with ``(view id, azimuth, elevation)`` per row; inside :meth:`snapshot`."""
        rows = self.conn.execute(
            "SELECT o.name, g.view_ids, g.curves FROM index_groups g"
            " JOIN objects o ON o.id = g.object_id WHERE g.tier = ? ORDER BY o.name, g.id",
            (name,),
        ).fetchall()
        names: list[str] = []
        owner: list[int] = []
        ids: list[int] = []
        curves = []
        for object_name, blob_ids, blob_curves in rows:
            if not names or names[-1] != object_name:
                names.append(object_name)
            views = decode_array(blob_ids, np.int64, (None,))
            curves.append(decode_array(blob_curves, np.float32, (len(views), None)))
            ids.extend(views.tolist())
            owner.extend([len(names) - 1] * len(views))
        if not ids:
            raise QueryError(f"the {name} tier holds no views", self.path)
        angles = self.view_angles(ids)
        arrays = TierArrays(names, np.array(owner, np.int64), np.concatenate(curves))
        return arrays, [(i, *angles[i]) for i in ids]
