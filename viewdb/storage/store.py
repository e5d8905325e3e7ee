"""The database file's rows: objects, views, their curves, Fourier points and SIFT
features, settings, and the tiers' index groups written with them.

Opening, schema versioning and transactions are :class:`~viewdb.storage.connection.Database`'s
job; :class:`Store` is a database with its rows. ``Store(path, read_only=True)`` never writes.
"""

from __future__ import annotations

import base64
import itertools
import json
import sqlite3
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any, TypeVar

import numpy as np
import sqlalchemy as sa
from numpy.typing import NDArray
from sqlalchemy.engine import Connection

from ..config import BuildConfig
from ..errors import NotFound, StorageError
from ..search.grouping import tier_members
from . import schema as s
from .appearances import pack_records
from .codecs import decode_array, encode_array
from .connection import Database
from .spatial import raw_connection
from .tier_file import new_generation
from .tiers import delete_groups, orthographic_angles, write_groups

_T = TypeVar("_T")

__all__ = ["ObjectRow", "Store", "StoredLook", "ViewRow"]


@dataclass(frozen=True)
class ObjectRow:
    id: int
    name: str
    source: str
    content_hash: str
    n_faces: int
    n_vertices: int
    scale: float
    centre: tuple[float, float, float]
    views: int
    empty_views: int
    ingest_seconds: float
    created_at: str
    skimmed: bool = False
    #: The symmetry type as stored (JSON of :class:`viewdb.catalogue.symmetry.SymmetryType`), or None
    #: for objects ingested before revision 0002.
    symmetry: dict[str, Any] | None = None
    #: Perspective views stored (revision 0004).
    perspective_views: int = 0
    #: Appearance records stored (revision 0005).
    appearances: int = 0


@dataclass(frozen=True)
class ViewRow:
    id: int
    azimuth: float
    elevation: float
    grid_gap: float


def _centre(blob: bytes) -> tuple[float, float, float]:
    """An object's stored centre (three float64s) as floats."""
    x, y, z = (float(v) for v in decode_array(blob, np.float64, (3,)))
    return x, y, z


def _symmetry_columns(desc: Any) -> dict[str, Any]:
    sym = getattr(desc, "symmetry", None)
    if sym is None:
        return {"skimmed": 0}
    return {
        "skimmed": int(bool(desc.skimmed)), "h_type": sym.h_type, "v_type": sym.v_type,
        "h_period": float(sym.h_period), "v_period": float(sym.v_period),
        "symmetry": json.dumps(sym.to_dict()),
    }


@dataclass(frozen=True)
class StoredLook:
    """A look model's bytes and what it was fitted for: ``key``, the catalogue it serves
    (this file, or every shard of a sharded catalogue), and ``own``, this file's objects
    when it was stored (:func:`viewdb.catalogue.look_training.look_key`)."""

    key: str
    own: str
    model: bytes = field(repr=False)


class Store(Database):
    """An open database file and its rows (the connections: :class:`Database`)."""

    # ----------------------------------------------------------------- settings
    def build_config(self) -> BuildConfig | None:
        with self.read() as conn:
            row = conn.execute(
                sa.select(s.settings.c.value).where(s.settings.c.key == "build")
            ).first()
        return None if row is None else BuildConfig.from_dict(json.loads(row[0]))

    def set_build_config(self, config: BuildConfig, role: str = "full") -> None:
        with self.transaction() as conn:
            conn.execute(sa.delete(s.settings).where(s.settings.c.key.in_(("build", "role"))))
            conn.execute(
                sa.insert(s.settings).values(key="build", value=json.dumps(config.to_dict()))
            )
            conn.execute(sa.insert(s.settings).values(key="role", value=json.dumps(role)))

    def look_model(self) -> StoredLook | None:
        """The stored look model (:mod:`viewdb.catalogue.look`) with the keys it was
        fitted for, or None (also when damaged: never trusted)."""
        with self.read() as conn:
            row = conn.execute(
                sa.select(s.settings.c.value).where(s.settings.c.key == "look_model")
            ).first()
        if row is None:
            return None
        try:
            stored = json.loads(row[0])
            return StoredLook(str(stored["key"]), str(stored["own"]),
                              base64.b64decode(stored["model"], validate=True))
        except (ValueError, KeyError, TypeError):
            return None

    def set_look_model(self, look: StoredLook | None) -> None:
        """Store ``look``, replacing any other; None removes it."""
        with self.transaction() as conn:
            conn.execute(sa.delete(s.settings).where(s.settings.c.key == "look_model"))
            if look is not None:
                value = json.dumps({"key": look.key, "own": look.own,
                                    "model": base64.b64encode(look.model).decode("ascii")})
                conn.execute(sa.insert(s.settings).values(key="look_model", value=value))

    def look_samples(self, config_key: str) -> dict[str, NDArray[np.float32]]:
        """``object name -> looks`` ``(n, d)`` stored for the look model's next fit
        (revision 0010), those made with the look settings ``config_key`` alone; a
        damaged one is left out (made again)."""
        ls, o = s.look_samples, s.objects
        with self.read() as conn:
            rows = conn.execute(sa.select(o.c.name, ls.c.looks).join(o, o.c.id == ls.c.object_id)
                                .where(ls.c.config == config_key)).all()
        out: dict[str, NDArray[np.float32]] = {}
        for name, blob in rows:
            try:
                out[name] = decode_array(blob, np.float32, (None, None))
            except ValueError:
                continue
        return out

    def set_look_samples(self, looks: Mapping[str, NDArray[np.floating]], config_key: str) -> None:
        """Store each object's ``looks`` (by name; objects not in the file are skipped),
        made with the look settings ``config_key``, replacing what it had."""
        ls, o = s.look_samples, s.objects
        with self.transaction() as conn:
            ids = dict(conn.execute(sa.select(o.c.name, o.c.id).where(o.c.name.in_(list(looks)))).all())
            for name, arr in looks.items():
                if name not in ids:
                    continue
                conn.execute(sa.delete(ls).where(ls.c.object_id == ids[name]))
                conn.execute(sa.insert(ls).values(object_id=ids[name], config=config_key,
                                                  looks=encode_array(np.asarray(arr, np.float32))))

    def mark_generation(self) -> None:
        """Give a file written before index generations one
        (:func:`~viewdb.storage.tier_file.new_generation`); a file with one keeps it."""
        with self.transaction() as conn:
            new_generation(raw_connection(conn), keep=True)

    def role(self) -> str:
        """``"full"`` (built by ingest: meshes, SIFT, both tiers) or ``"client"`` (written by
        ``export-client``: the sparse tier's curves only, the file that ships to devices)."""
        with self.read() as conn:
            row = conn.execute(
                sa.select(s.settings.c.value).where(s.settings.c.key == "role")
            ).first()
        return "full" if row is None else str(json.loads(row[0]))

    def object_curves(self, name: str) -> dict[tuple[float, float], NDArray[np.float32]]:
        """Every stored curve of object ``name``, by ``(azimuth, elevation)``, in one query."""
        v = s.views
        with self.read() as conn:
            rows = conn.execute(
                sa.select(v.c.azimuth, v.c.elevation, s.curves.c.samples)
                .select_from(
                    v.join(s.curves, s.curves.c.view_id == v.c.id).join(
                        s.objects, s.objects.c.id == v.c.object_id)
                )
                .where(s.objects.c.name == name)
            ).all()
            if not rows:  # a compact client file keeps its curves in the groups only
                return self._group_curves(conn, name)
        return {(float(a), float(e)): decode_array(b, np.float32, (None,)) for a, e, b in rows}

    def view_angles(self, view_ids: Sequence[int]) -> dict[int, tuple[float, float]]:
        """``view id -> (azimuth, elevation)`` of stored orthographic views (ids not stored
        are left out)."""
        with self.read() as conn:
            return orthographic_angles(raw_connection(conn), view_ids)

    def perspective_curves_at(
        self, name: str, directions: Sequence[tuple[float, float]]
    ) -> list[tuple[float, float, float, NDArray[np.float32]]]:
        """``(azimuth, elevation, distance, curve)`` of object ``name``'s perspective views
        at any of ``directions`` (``(azimuth, elevation)`` as stored), nearest camera
        first per direction: one walk of the (object, azimuth, elevation, distance) index
        each, which also gives the order."""
        out = []
        with self.read() as conn:
            object_id = self.object_id(conn, name)
            raw = raw_connection(conn)
            for azimuth, elevation in directions:
                rows = raw.execute(
                    "SELECT azimuth, elevation, distance, samples FROM perspective_views"
                    " WHERE object_id = ? AND azimuth = ? AND elevation = ? ORDER BY distance",
                    (object_id, float(azimuth), float(elevation)),
                ).fetchall()
                out += [(float(a), float(e), float(d), decode_array(b, np.float32, (None,)))
                        for a, e, d, b in rows]
        return out

    @staticmethod
    def _group_curves(conn: Connection, name: str) -> dict[tuple[float, float], NDArray[np.float32]]:
        raw = raw_connection(conn)
        out = {}
        for ids_blob, curves_blob in raw.execute(
            "SELECT g.view_ids, g.curves FROM index_groups g JOIN objects o ON o.id = g.object_id"
            " WHERE o.name = ? AND g.tier = 'sparse'", (name,),
        ):
            ids = decode_array(ids_blob, np.int64, (None,))
            curves = decode_array(curves_blob, np.float32, (len(ids), None))
            angles = orthographic_angles(raw, ids.tolist())
            for vid, curve in zip(ids.tolist(), curves, strict=True):
                out[angles[int(vid)]] = curve
        return out

    def curve(self, name: str, azimuth: float, elevation: float) -> NDArray[np.float32] | None:
        """The stored curve of one view (None if that view is not stored)."""
        v = s.views
        with self.read() as conn:
            row = conn.execute(
                sa.select(s.curves.c.samples)
                .select_from(
                    v.join(s.curves, s.curves.c.view_id == v.c.id).join(
                        s.objects, s.objects.c.id == v.c.object_id)
                )
                .where(s.objects.c.name == name, v.c.azimuth == float(azimuth),
                       v.c.elevation == float(elevation))
            ).first()
        return None if row is None else decode_array(row[0], np.float32, (None,))

    # ----------------------------------------------------------------- objects
    def object_hashes(self) -> dict[str, str]:
        with self.read() as conn:
            rows = conn.execute(sa.select(s.objects.c.name, s.objects.c.content_hash)).all()
        return {name: h for name, h in rows}

    def objects(self, name: str | None = None) -> list[ObjectRow]:
        """Every object by name (or just the one called ``name``)."""
        o, v = s.objects, s.views
        count = (
            sa.select(sa.func.count(v.c.id)).where(v.c.object_id == o.c.id).scalar_subquery()
        )
        p = s.perspective_views
        perspective = (
            sa.select(sa.func.count(p.c.id)).where(p.c.object_id == o.c.id).scalar_subquery()
        )
        a = s.appearances
        appearances = (
            sa.select(sa.func.count(a.c.id)).where(a.c.object_id == o.c.id).scalar_subquery()
        )
        query = sa.select(
            o.c.id, o.c.name, o.c.source, o.c.content_hash, o.c.n_faces, o.c.n_vertices,
            o.c.scale, o.c.centre, count, o.c.empty_views, o.c.ingest_seconds, o.c.created_at,
            o.c.skimmed, o.c.symmetry, perspective, appearances,
        ).order_by(o.c.name)
        if name is not None:
            query = query.where(o.c.name == name)
        with self.read() as conn:
            rows = conn.execute(query).all()
        return [
            ObjectRow(
                id=r[0], name=r[1], source=r[2], content_hash=r[3], n_faces=r[4],
                n_vertices=r[5], scale=float(r[6]),
                centre=_centre(r[7]),
                views=int(r[8]), empty_views=int(r[9]), ingest_seconds=float(r[10]),
                created_at=r[11], skimmed=bool(r[12]),
                symmetry=None if r[13] is None else json.loads(r[13]),
                perspective_views=int(r[14]), appearances=int(r[15]),
            )
            for r in rows
        ]

    def object_id(self, conn: Connection, name: str) -> int:
        row = conn.execute(sa.select(s.objects.c.id).where(s.objects.c.name == name)).first()
        if row is None:
            raise NotFound(f"no object named {name!r}", self.path)
        return int(row[0])

    def mesh_glb(self, name: str) -> bytes:
        with self.read() as conn:
            row = conn.execute(
                sa.select(s.objects.c.mesh_glb).where(s.objects.c.name == name)
            ).first()
        if row is None:
            raise NotFound(f"no object named {name!r}", self.path)
        return bytes(row[0])

    def write_object(self, desc: Any, config: BuildConfig) -> None:
        """Store one described object (replacing one of the same name), with its entries
        in both tiers' R-trees, in one transaction."""
        now = datetime.now(UTC).isoformat(timespec="seconds")
        grid_gap = config.gap
        with self.transaction() as conn:
            old = conn.execute(sa.select(s.objects.c.id).where(s.objects.c.name == desc.name)).all()
            delete_groups(raw_connection(conn), [r[0] for r in old])
            conn.execute(sa.delete(s.objects).where(s.objects.c.name == desc.name))
            inserted = conn.execute(
                sa.insert(s.objects).values(
                    name=desc.name, source=desc.source, content_hash=desc.content_hash,
                    n_faces=int(desc.n_faces), n_vertices=int(desc.n_vertices),
                    centre=encode_array(np.asarray(desc.centre, np.float64)),
                    scale=float(desc.scale), mesh_glb=desc.glb,
                    empty_views=len(desc.empty_views), ingest_seconds=float(desc.seconds),
                    created_at=now, **_symmetry_columns(desc),
                )
            ).inserted_primary_key
            assert inserted is not None  # an INSERT's row
            object_id = inserted[0]
            self._insert_appearances(conn, object_id, getattr(desc, "appearance", []))
            self._mark_scope(conn, object_id, getattr(desc, "appearance_scope", None))
            if not desc.views:
                return
            conn.execute(
                sa.insert(s.views),
                [
                    {"object_id": object_id, "azimuth": float(v.azimuth),
                     "elevation": float(v.elevation), "grid_gap": float(grid_gap)}
                    for v in desc.views
                ],
            )
            view_ids = {
                (float(a), float(e)): int(i)
                for i, a, e in conn.execute(
                    sa.select(s.views.c.id, s.views.c.azimuth, s.views.c.elevation).where(
                        s.views.c.object_id == object_id
                    )
                )
            }
            keyed = [(view_ids[(float(v.azimuth), float(v.elevation))], v) for v in desc.views]
            conn.execute(
                sa.insert(s.curves),
                [{"view_id": i, "samples": encode_array(v.curve)} for i, v in keyed],
            )
            conn.execute(
                sa.insert(s.fourier_points),
                [{"view_id": i, "coefficients": encode_array(v.fourier)} for i, v in keyed],
            )
            conn.execute(
                sa.insert(s.sift_features),
                [
                    {
                        "view_id": i, "count": len(v.sift),
                        "keypoints": encode_array(v.sift.keypoints),
                        "descriptors": encode_array(v.sift.descriptors),
                        "points3d": encode_array(v.sift.points3d),
                    }
                    for i, v in keyed
                ],
            )
            positions = [(float(v.azimuth), float(v.elevation)) for v in desc.views]
            members = tier_members(positions, config.gap, config.client_gap,
                                   getattr(desc, "symmetry", None), bool(getattr(desc, "skimmed", False)))
            perspective = getattr(desc, "perspective", [])
            ids = [i for i, _ in keyed] + self._insert_perspective(conn, object_id, perspective)
            members["full"] = list(range(len(ids)))
            write_groups(raw_connection(conn), object_id, ids,
                         np.stack([v.curve for v in (*desc.views, *perspective)]),
                         members, config.index.group_views)

    def add_perspective(self, name: str, views: Any, config: BuildConfig) -> None:
        """Give a stored object its perspective views (an older file's object) in one
        transaction; views it already has are replaced. Its full-tier groups are written
        again over all its views, as an ingest groups them."""
        with self.transaction() as conn:
            object_id = self.object_id(conn, name)
            raw = raw_connection(conn)
            delete_groups(raw, [object_id], tiers=("full",))
            conn.execute(sa.delete(s.perspective_views)
                         .where(s.perspective_views.c.object_id == object_id))
            ortho = raw.execute(
                "SELECT v.id, c.samples FROM views v JOIN curves c ON c.view_id = v.id"
                " WHERE v.object_id = ? ORDER BY v.id", (object_id,),
            ).fetchall()
            ids = [int(i) for i, _ in ortho] + self._insert_perspective(conn, object_id, views)
            curves = [decode_array(b, np.float32, (None,)) for _, b in ortho] + [v.curve for v in views]
            if ids:
                write_groups(raw, object_id, ids, np.stack(curves),
                             {"full": list(range(len(ids)))}, config.index.group_views)

    @staticmethod
    def _insert_perspective(conn: Connection, object_id: int, views: Any) -> list[int]:
        """Insert an object's perspective views; returns the ids its index groups name them
        by (:func:`~viewdb.storage.schema.perspective_group_id`), in ``views`` order. They
        go in the full tier only (client files copy the sparse one)."""
        if not views:
            return []
        p = s.perspective_views
        conn.execute(sa.insert(p), [
            {"object_id": object_id, "azimuth": float(v.azimuth), "elevation": float(v.elevation),
             "distance": float(v.distance), "samples": encode_array(v.curve)}
            for v in views
        ])
        ids = {
            (float(a), float(e), float(d)): int(i)
            for i, a, e, d in conn.execute(
                sa.select(p.c.id, p.c.azimuth, p.c.elevation, p.c.distance)
                .where(p.c.object_id == object_id)
            )
        }
        return [s.perspective_group_id(ids[(float(v.azimuth), float(v.elevation), float(v.distance))])
                for v in views]

    @staticmethod
    def _insert_appearances(conn: Connection, object_id: int, records: Any, before: bytes = b"") -> None:
        """Write an object's records as one blob, after the bytes ``before`` (records it
        keeps, whose rows stay as they are)."""
        if not records:
            return
        data, index = pack_records(records)
        conn.execute(sa.insert(s.appearance_blobs).values(object_id=object_id, data=before + data))
        conn.execute(sa.insert(s.appearances), [
            {"object_id": object_id, "azimuth": a, "elevation": e, "offset": len(before) + at, "size": size}
            for a, e, at, size in index
        ])

    @staticmethod
    def _mark_scope(conn: Connection, object_id: int, scope: str | None) -> None:
        if scope is not None:
            conn.execute(sa.delete(s.appearance_scopes).where(s.appearance_scopes.c.object_id == object_id))
            conn.execute(sa.insert(s.appearance_scopes).values(object_id=object_id, scope=scope))

    def add_appearance(self, name: str, records: Any, scope: str | None = None) -> None:
        """Add the appearance records a stored object lacks (an older file's object), and
        mark its scope, in one transaction; a record of a view it already has replaces that."""
        a, b = s.appearances, s.appearance_blobs
        with self.transaction() as conn:
            object_id = self.object_id(conn, name)
            if records:
                conn.execute(sa.delete(a).where(a.c.object_id == object_id, a.c.azimuth == sa.bindparam("h"),
                                                a.c.elevation == sa.bindparam("v")),
                             [{"h": float(r.azimuth), "v": float(r.elevation)} for r in records])
                before = conn.execute(sa.select(b.c.data).where(b.c.object_id == object_id)).scalar()
                conn.execute(sa.delete(b).where(b.c.object_id == object_id))
                self._insert_appearances(conn, object_id, records, bytes(before or b""))
            self._mark_scope(conn, object_id, scope)

    def objects_lacking_appearance(self, every_view: bool) -> dict[str, list[tuple[float, float]]]:
        """The objects whose appearance records lack views an ingest now records, each with
        the views it has records of: those with stored views but no records (stored before
        revision 0005), and with ``every_view``
        (:attr:`~viewdb.config.AppearanceConfig.every_view`) those not marked as recorded
        at every grid direction (recorded before revision 0008)."""
        o, v, a, sc = s.objects, s.views, s.appearances, s.appearance_scopes
        has_views = sa.select(v.c.id).where(v.c.object_id == o.c.id).exists()
        has = sa.select(a.c.id).where(a.c.object_id == o.c.id).exists()
        marked = sa.select(sc.c.object_id).where(sc.c.object_id == o.c.id).exists()
        with self.read() as conn:
            out: dict[str, list[tuple[float, float]]] = {
                r[0]: [] for r in conn.execute(sa.select(o.c.name).where(has_views, ~has))}
            if every_view:  # one read of the unmarked objects' records' views
                for name, h, e in conn.execute(
                        sa.select(o.c.name, a.c.azimuth, a.c.elevation)
                        .select_from(a.join(o, o.c.id == a.c.object_id)).where(~marked)):
                    out.setdefault(name, []).append((float(h), float(e)))
        return out

    def appearance_records(
        self, name: str, views: Sequence[tuple[float, float]]
    ) -> dict[tuple[float, float], bytes]:
        """The packed appearance records (:mod:`viewdb.storage.appearances`) of object
        ``name`` at any of ``views`` (normalised angles), by view; only their bytes are
        read from the object's blob."""
        wanted = {(float(h), float(e)) for h, e in views}
        if not wanted:
            return {}
        azimuths = sorted({h for h, _ in wanted})
        return self._in_snapshot(lambda raw: self._read_records(raw, name, azimuths, wanted),
                                 f"the appearance of {name!r}")

    def grid_appearance_records(self, step: float) -> list[tuple[str, float, float, bytes]]:
        """``(object, azimuth, elevation, packed record)`` of every stored appearance record
        whose direction lies on a grid of ``step`` degrees, object by object, read in one
        snapshot (only the records' bytes of each object's blob)."""
        return self._in_snapshot(lambda raw: self._read_grid_records(raw, float(step)),
                                 "the appearance records")

    def _in_snapshot(self, read: Callable[[sqlite3.Connection], _T], what: str) -> _T:
        """``read`` on the raw connection in one snapshot (offsets and blob bytes alike: a
        writer may replace both); an SQLite error says it could not read ``what``."""
        with self._errors(), self.engine.connect() as conn:
            raw = raw_connection(conn)
            began = not raw.in_transaction
            try:
                if began:
                    raw.execute("BEGIN")
                try:
                    return read(raw)
                finally:
                    if began:
                        raw.execute("COMMIT")
            except sqlite3.Error as exc:
                raise StorageError(f"cannot read {what}: {exc}", self.path) from exc

    @staticmethod
    def _read_grid_records(raw: sqlite3.Connection, step: float) -> list[tuple[str, float, float, bytes]]:
        rows = raw.execute(
            "SELECT o.name, a.azimuth, a.elevation, a.offset, a.size, a.object_id FROM appearances a"
            " JOIN objects o ON o.id = a.object_id"
            " WHERE abs(a.azimuth - ? * round(a.azimuth / ?)) < 1e-6"
            " AND abs(a.elevation - ? * round(a.elevation / ?)) < 1e-6"
            " ORDER BY a.object_id, a.offset", (step, step, step, step),
        ).fetchall()
        out: list[tuple[str, float, float, bytes]] = []
        for _, group in itertools.groupby(rows, key=lambda r: r[5]):
            records = list(group)
            with raw.blobopen("appearance_blobs", "data", int(records[0][5]), readonly=True) as blob:
                for name, a, e, at, size, _ in records:
                    blob.seek(int(at))
                    out.append((str(name), float(a), float(e), blob.read(int(size))))
        return out

    @staticmethod
    def _read_records(raw: sqlite3.Connection, name: str, azimuths: list[float],
                      wanted: set[tuple[float, float]]) -> dict[tuple[float, float], bytes]:
        rows = raw.execute(
                "SELECT a.azimuth, a.elevation, a.offset, a.size, a.object_id FROM appearances a"
            " JOIN objects o ON o.id = a.object_id WHERE o.name = ?"
            f" AND a.azimuth IN ({', '.join('?' * len(azimuths))})", (name, *azimuths),
        ).fetchall()
        found = [r for r in rows if (float(r[0]), float(r[1])) in wanted]
        out: dict[tuple[float, float], bytes] = {}
        if found:
            with raw.blobopen("appearance_blobs", "data", int(found[0][4]), readonly=True) as blob:
                for a, e, at, size, _ in found:
                    blob.seek(int(at))
                    out[(float(a), float(e))] = blob.read(int(size))
        return out

    def objects_lacking_perspective(self) -> set[str]:
        """Names of the objects with no perspective views (stored before revision 0004,
        or by a configuration without them)."""
        o, p = s.objects, s.perspective_views
        has = sa.select(p.c.id).where(p.c.object_id == o.c.id).exists()
        with self.read() as conn:
            return {r[0] for r in conn.execute(sa.select(o.c.name).where(~has))}

    # ----------------------------------------------------------------- views
    def views(self, name: str) -> list[ViewRow]:
        v = s.views
        with self.read() as conn:
            object_id = self.object_id(conn, name)
            rows = conn.execute(
                sa.select(v.c.id, v.c.azimuth, v.c.elevation, v.c.grid_gap)
                .where(v.c.object_id == object_id)
                .order_by(v.c.azimuth, v.c.elevation)
            ).all()
        return [ViewRow(int(i), float(a), float(e), float(g)) for i, a, e, g in rows]

    def view_features(self, name: str, azimuth: float, elevation: float) -> dict[str, Any]:
        """Curve, Fourier point and SIFT arrays of one stored view."""
        v = s.views
        with self.read() as conn:
            object_id = self.object_id(conn, name)
            row = conn.execute(
                sa.select(
                    s.curves.c.samples, s.fourier_points.c.coefficients,
                    s.sift_features.c.keypoints, s.sift_features.c.descriptors,
                    s.sift_features.c.points3d,
                )
                .select_from(
                    v.join(s.curves, s.curves.c.view_id == v.c.id)
                    .join(s.fourier_points, s.fourier_points.c.view_id == v.c.id)
                    .join(s.sift_features, s.sift_features.c.view_id == v.c.id)
                )
                .where(
                    v.c.object_id == object_id,
                    v.c.azimuth == float(azimuth),
                    v.c.elevation == float(elevation),
                )
            ).first()
        if row is None:
            raise NotFound(
                f"object {name!r} has no stored view at azimuth {azimuth}, elevation {elevation}",
                self.path,
            )
        return {
            "curve": decode_array(row[0], np.float32, (None,)),
            "fourier": decode_array(row[1], np.complex128, (None,)),
            "keypoints": decode_array(row[2], np.float32, (None, 5)),
            "descriptors": decode_array(row[3], np.uint8, (None, 128)),
            "points3d": decode_array(row[4], np.float32, (None, 3)),
        }

    def all_curves(self) -> tuple[list[str], list[tuple[int, float, float]], list[Any]]:
        """Every stored curve in one pass: object names, (object index, azimuth, elevation)
        per view, and the decoded curves (float32), ordered by object name then view id."""
        o, v, c = s.objects, s.views, s.curves
        query = (
            sa.select(o.c.name, v.c.azimuth, v.c.elevation, c.c.samples)
            .select_from(o.join(v, v.c.object_id == o.c.id).join(c, c.c.view_id == v.c.id))
            .order_by(o.c.name, v.c.id)
        )
        names: list[str] = []
        views: list[tuple[int, float, float]] = []
        curves = []
        with self.read() as conn:
            for name, azimuth, elevation, blob in conn.execute(query):
                if not names or names[-1] != name:
                    names.append(name)
                views.append((len(names) - 1, float(azimuth), float(elevation)))
                curves.append(decode_array(blob, np.float32, (None,)))
        return names, views, curves

    def table_counts(self) -> dict[str, int]:
        out = {}
        with self.read() as conn:
            for table in (s.objects, s.views, s.curves, s.fourier_points, s.sift_features,
                          s.perspective_views, s.appearances, s.curve_errors):
                out[table.name] = int(
                    conn.execute(sa.select(sa.func.count()).select_from(table)).scalar_one()
                )
            keypoints = sa.func.coalesce(sa.func.sum(s.sift_features.c.count), 0)
            out["sift_keypoints"] = int(conn.execute(sa.select(keypoints)).scalar_one())
            out["index_groups"] = int(
                conn.execute(sa.select(sa.func.count()).select_from(s.index_groups)).scalar_one()
            )
            out["rtree_pages"] = int(
                conn.execute(sa.select(sa.func.count()).select_from(s.rtree_pages)).scalar_one()
            )
        return out

    def tier_sizes(self) -> dict[str, dict[str, int]]:
        """Per tier: views, groups (R-tree entries) and bytes of R-tree pages."""
        g, p = s.index_groups, s.rtree_pages
        out: dict[str, dict[str, int]] = {}
        with self.read() as conn:
            for tier, blob in conn.execute(sa.select(g.c.tier, g.c.view_ids)):
                entry = out.setdefault(tier, {"views": 0, "groups": 0, "rtree_bytes": 0})
                entry["views"] += len(decode_array(blob, np.int64, (None,)))
                entry["groups"] += 1
            for tier, size in conn.execute(
                sa.select(p.c.tier, sa.func.sum(sa.func.length(p.c.data))).group_by(p.c.tier)
            ):
                out.setdefault(tier, {"views": 0, "groups": 0, "rtree_bytes": 0})
                out[tier]["rtree_bytes"] = int(size or 0)
        return out
