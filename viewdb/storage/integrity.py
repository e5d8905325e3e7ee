"""``viewdb check``: verify that a database file is whole and self-consistent.

Checks, in order: the schema revision is the one this viewdb writes (or, opened
read-only, one it reads as it is: :data:`~viewdb.storage.connection.READ_ONLY_COMPATIBLE`); SQLite's own
``integrity_check`` and ``foreign_key_check``; every view has exactly one curve, Fourier
point and SIFT row; every blob decodes with the dtype and shape the schema promises; each
Fourier point is the orthonormal DFT of its stored curve; each object's mesh is a GLB and
its view count matches its grid; and both tiers' R-trees: every R-tree entry is a group
row and vice versa with the same box, each group's curves are its views' stored curves and
lie in its box, the full tier holds every view (and every perspective view) once and the
sparse tier exactly the client grid's stand-ins; and each object's appearance records
(revision 0005; none for an object stored before it): one per viewing direction of
:func:`~viewdb.catalogue.describe.appearance_views`, each decoding to what it promises, and
a stored view's silhouette giving exactly its stored curve; and a compact client file's
quantisation errors (one pair of norms per view of each sparse group, consistent; such a
file has no per-view curve or Fourier rows: its curves are in its groups).
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import sqlalchemy as sa

from ..camera import grid_views
from ..catalogue.appearance import turned_view
from ..catalogue.describe import appearance_views
from ..catalogue.features import distance_curve, fourier_point
from ..catalogue.skimming import skim_plan
from ..catalogue.symmetry import SymmetryType
from ..errors import FeatureError, NotFound, StorageError
from ..search.grouping import DIMENSION, MBR_PADDING, indexed_coordinates, tier_members
from . import schema as s
from .appearances import decode_record
from .codecs import decode_array
from .connection import READ_ONLY_COMPATIBLE
from .spatial import FourierIndex
from .store import Store
from .tiers import TIERS

__all__ = ["CheckReport", "check_store", "missing_schema"]

#: How far a stored Fourier point may be from the DFT of its stored curve.
FOURIER_TOLERANCE = 1e-9
#: Problems listed in full before the rest are only counted.
MAX_LISTED = 50


def missing_schema(store: Store) -> list[str]:
    """The tables and columns of the schema the file lacks (``"table curves"``,
    ``"column views.azimuth"``); TEMP stand-ins of a read-only open count as present. A
    file someone damaged (a table dropped) is refused on opening with these, instead of
    failing somewhere later, or worse, answering queries without its curves."""
    out = []
    with store.read() as conn:
        present = {str(r[0]) for r in conn.exec_driver_sql(
            "SELECT name FROM sqlite_master WHERE type='table' "
            "UNION SELECT name FROM sqlite_temp_master WHERE type='table'")}
        for table in s.metadata.sorted_tables:
            if table.name not in present:
                out.append(f"table {table.name}")
                continue
            columns = {str(r[1]) for r in conn.exec_driver_sql(f'PRAGMA table_info("{table.name}")')}
            out += [f"column {table.name}.{c.name}" for c in table.columns if c.name not in columns]
    return out


@dataclass
class CheckReport:
    """What ``viewdb check`` found. ``ok`` is True when ``problems`` is empty."""

    path: str
    checked: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    more_problems: int = 0

    @property
    def ok(self) -> bool:
        return not self.problems

    def add(self, problem: str) -> None:
        if len(self.problems) < MAX_LISTED:
            self.problems.append(problem)
        else:
            self.more_problems += 1


def check_store(store: Store, progress: Callable[[int, int], None] | None = None) -> CheckReport:
    """Run every check on an open store and return the report (never raises for findings)."""
    report = CheckReport(str(store.path))
    revision = store.revision()
    if revision != s.SCHEMA_REVISION and not (store.read_only and revision in READ_ONLY_COMPATIBLE):
        report.add(f"schema revision is {revision}, expected {s.SCHEMA_REVISION}")
    config = store.build_config()
    if config is None:
        report.add("settings: no build configuration stored")
        return report
    with store.read() as conn:
        result = [r[0] for r in conn.exec_driver_sql("PRAGMA integrity_check").all()]
        if result != ["ok"]:
            report.add("sqlite integrity_check: " + "; ".join(result[:5]))
        for row in conn.exec_driver_sql("PRAGMA foreign_key_check").all()[:MAX_LISTED]:
            report.add(f"foreign key broken: table {row[0]} rowid {row[1]} -> {row[2]}")
        client = store.role() == "client"
        raw = conn.connection.driver_connection
        assert raw is not None  # None only once the connection is closed or invalidated
        try:
            compact = client and raw.execute("SELECT 1 FROM curve_errors LIMIT 1").fetchone() is not None
            _check_objects(conn, config.gap, report, client)
            _check_views(conn, config, report, progress, client, compact)
            _check_tiers(raw, config, report, client)
            _check_curve_errors(raw, config.features.curve_samples, report, compact)
            _check_appearances(raw, config, report, client)
        except (sqlite3.DatabaseError, sa.exc.DatabaseError) as exc:  # pages SQLite cannot read
            report.add(f"cannot read the file's rows: {str(exc).splitlines()[0]}")
    return report


#: How far the curve of a stored silhouette may be from the view's stored curve (float32).
CURVE_TOLERANCE = 1e-5


def _check_appearances(raw, config, report: CheckReport, client: bool) -> None:  # type: ignore[no-untyped-def]
    """Appearance records: decodable, one per direction of :func:`appearance_views` (for an
    object that has any), inside their object's blob, and a stored view's silhouette gives
    its stored curve."""
    index: dict[int, list[tuple[float, float, int, int]]] = {}
    for oid, az, el, at, length in raw.execute(
        "SELECT object_id, azimuth, elevation, offset, size FROM appearances ORDER BY id"
    ):
        index.setdefault(int(oid), []).append((float(az), float(el), int(at), int(length)))
    blobs = {int(oid): n for oid, n in raw.execute("SELECT object_id, length(data) FROM appearance_blobs")}
    if client and (index or blobs):
        report.add(f"a client file holds no appearance records ({sum(map(len, index.values()))} found)")
        return
    checked = 0
    for oid, name in raw.execute("SELECT id, name FROM objects ORDER BY name").fetchall():
        records, total = index.pop(int(oid), []), blobs.pop(int(oid), None)
        if not records:
            if total is not None:
                report.add(f"object {name!r}: an appearance blob without records")
            continue  # stored before revision 0005: an ingest of its file adds them
        if total is None:
            report.add(f"object {name!r}: {len(records)} appearance records but no blob")
            continue
        checked += _check_object_appearance(raw, int(oid), name, records, config, report)
    for oid in sorted(set(index) | set(blobs)):
        report.add(f"appearances: records of object id {oid}, which does not exist")
    report.checked["appearances"] = checked


def _check_object_appearance(  # type: ignore[no-untyped-def]
    raw, oid: int, name: str, records: list[tuple[float, float, int, int]], config, report: CheckReport,
) -> int:
    """One object's records (they exist, and so does its blob); how many decode."""
    data = raw.execute("SELECT data FROM appearance_blobs WHERE object_id = ?", (oid,)).fetchone()[0]
    stored = raw.execute(
        "SELECT v.azimuth, v.elevation, c.samples FROM views v LEFT JOIN curves c ON c.view_id = v.id"
        " WHERE v.object_id = ? ORDER BY v.id", (oid,)).fetchall()
    curves = {(float(a), float(e)): blob for a, e, blob in stored}

    def pairs(views: list[tuple[float, float]]) -> set[frozenset[tuple[float, float]]]:
        return {frozenset((v, turned_view(*v))) for v in views}

    expected = pairs(appearance_views(list(curves), config.appearance))
    # any grid direction may have a record (revision 0008 records every one; a view without
    # a silhouette has none, so only the stored views' directions and their opposites must)
    allowed = pairs(grid_views(config.gap))
    found: set[frozenset[tuple[float, float]]] = set()
    checked = 0
    for az, el, at, length in records:
        where = f"object {name!r}: appearance ({az:g}, {el:g})"
        pair = frozenset(((az, el), turned_view(az, el)))
        if pair not in allowed:
            report.add(f"{where}: not a grid direction")
        elif pair in found:
            report.add(f"{where}: its direction is recorded twice")
        found.add(pair)
        if at < 0 or length <= 0 or at + length > len(data):
            report.add(f"{where}: bytes {at}..{at + length} are outside its object's blob ({len(data)})")
            continue
        problem = _record_problem(data[at:at + length], az, el, curves.get((az, el)), config)
        if problem is None:
            checked += 1
        else:
            report.add(f"{where}: {problem}")
    if len(found & expected) < len(expected):
        report.add(f"object {name!r}: {len(expected - found)} of its {len(expected)} viewing "
                   f"directions have no appearance record")
    return checked


def _record_problem(data: bytes, az: float, el: float, curve_blob: bytes | None, config) -> str | None:  # type: ignore[no-untyped-def]
    """What is wrong with one packed record, or None: it must decode, and a stored view's
    silhouette must give that view's stored curve."""
    samples = config.features.curve_samples
    try:
        record = decode_record(data, az, el, config.render.image_size)
    except StorageError as exc:
        return exc.message
    if curve_blob is None:
        return None
    try:
        curve = decode_array(curve_blob, np.float32, (samples,))
        own = distance_curve(record.mask, samples)
    except (StorageError, FeatureError):
        return "its silhouette gives no curve to compare with the view's"
    if not np.allclose(own, curve, rtol=0, atol=CURVE_TOLERANCE):
        return "its silhouette is not the stored view's (the curves differ)"
    return None


def _check_objects(conn: sa.Connection, gap: float, report: CheckReport, client: bool) -> None:
    o, v = s.objects, s.views
    grid = len(grid_views(gap))
    count = sa.select(sa.func.count(v.c.id)).where(v.c.object_id == o.c.id).scalar_subquery()
    rows = conn.execute(
        sa.select(
            o.c.name, o.c.centre, sa.func.substr(o.c.mesh_glb, 1, 4), o.c.empty_views, count,
            o.c.skimmed, o.c.symmetry,
        )
    ).all()
    report.checked["objects"] = len(rows)
    for name, centre, magic, empty, n_views, skimmed, symmetry in rows:
        expected = grid
        if symmetry is not None:
            try:
                sym = SymmetryType.from_dict(json.loads(symmetry))
            except (ValueError, KeyError, TypeError) as exc:
                report.add(f"object {name!r}: symmetry type does not decode: {exc}")
            else:
                if skimmed:
                    expected = skim_plan(sym, gap).views_stored
        elif skimmed:
            report.add(f"object {name!r}: skimmed but has no symmetry type")
        try:
            decode_array(centre, np.float64, (3,))
        except StorageError as exc:
            report.add(f"object {name!r}: centre: {exc.message}")
        if client:
            continue  # a client file has no meshes and only the client grid's views
        if magic is None or bytes(magic) != b"glTF":  # an empty blob's first bytes are NULL
            report.add(f"object {name!r}: stored mesh is not a GLB")
        if n_views + empty != expected:
            report.add(
                f"object {name!r}: {n_views} views + {empty} empty != {expected} "
                + ("kept by its skim plan" if expected != grid else "in the grid")
            )


def _check_curve_errors(raw, n: int, report: CheckReport, compact: bool) -> None:  # type: ignore[no-untyped-def]
    """A compact client file's quantisation errors: one row per sparse group, one pair of
    norms per view, consistent (L-infinity <= L2 <= sqrt(N) L-infinity); none elsewhere."""
    rows = raw.execute(
        "SELECT g.id, g.tier, g.view_ids, e.errors FROM index_groups g"
        " LEFT JOIN curve_errors e ON e.group_id = g.id").fetchall()
    for gid, tier, blob_ids, blob_errors in rows:
        where = f"{tier} tier group {gid}"
        if blob_errors is None:
            if compact:
                report.add(f"{where}: no quantisation errors (a compact client file has them for all)")
            continue
        if not compact or tier != "sparse":
            report.add(f"{where}: quantisation errors outside a compact client file's sparse tier")
            continue
        try:
            ids = decode_array(blob_ids, np.int64, (None,))
            errors = decode_array(blob_errors, np.float32, (len(ids), 2)).astype(np.float64)
        except StorageError as exc:
            report.add(f"{where}: {exc.message}")
            continue
        l2, linf = errors[:, 0], errors[:, 1]
        if not (np.all(np.isfinite(errors)) and np.all(linf >= 0)
                and np.all(l2 >= linf * (1 - 1e-6)) and np.all(l2 <= np.sqrt(n) * linf * (1 + 1e-6))):
            report.add(f"{where}: quantisation errors are not consistent norms")


def _check_views(conn, config, report: CheckReport, progress, client, compact=False) -> None:  # type: ignore[no-untyped-def]
    v, c, f, k = s.views, s.curves, s.fourier_points, s.sift_features
    n_curve, m = config.features.curve_samples, config.features.fourier_coefficients
    total = conn.execute(sa.select(sa.func.count()).select_from(v)).scalar_one()
    query = (
        sa.select(
            v.c.id, v.c.azimuth, v.c.elevation, c.c.samples, f.c.coefficients, k.c.count,
            k.c.keypoints, k.c.descriptors, k.c.points3d,
        )
        .select_from(
            v.outerjoin(c, c.c.view_id == v.c.id)
            .outerjoin(f, f.c.view_id == v.c.id)
            .outerjoin(k, k.c.view_id == v.c.id)
        )
        .order_by(v.c.id)
    )
    done = 0
    for row in conn.execute(query):
        vid, az, el, curve_blob, fourier_blob, count, kp, desc, pts = row
        where = f"view {vid} ({az:g}, {el:g})"
        if client and kp is not None:
            report.add(f"{where}: a client file holds no SIFT features")
        elif compact:
            if curve_blob is not None or fourier_blob is not None:
                report.add(f"{where}: a compact client file keeps its curves in its groups only")
        elif curve_blob is None or fourier_blob is None or (kp is None and not client):
            report.add(f"{where}: missing curve, Fourier point or SIFT row")
        else:
            try:
                curve = decode_array(curve_blob, np.float32, (n_curve,))
                fourier = decode_array(fourier_blob, np.complex128, (m,))
                if not client:
                    decode_array(kp, np.float32, (count, 5))
                    decode_array(desc, np.uint8, (count, 128))
                    decode_array(pts, np.float32, (count, 3))
            except StorageError as exc:
                report.add(f"{where}: {exc.message}")
            else:
                expected = fourier_point(curve.astype(np.float64), m)
                if not np.allclose(fourier, expected, rtol=0, atol=FOURIER_TOLERANCE):
                    report.add(f"{where}: Fourier point does not match its curve")
        done += 1
        if progress is not None and done % 1000 == 0:
            progress(done, total)
    for table in (c, f, k):
        orphans = conn.execute(
            sa.select(sa.func.count()).select_from(table).where(
                ~table.c.view_id.in_(sa.select(v.c.id))
            )
        ).scalar_one()
        if orphans:
            report.add(f"{table.name}: {orphans} rows belong to no view")
    report.checked["views"] = done


def _check_tiers(raw, config, report: CheckReport, client: bool) -> None:  # type: ignore[no-untyped-def]
    stored = _StoredViews(raw, config.features.curve_samples, report)
    objects = raw.execute("SELECT id, name, skimmed, symmetry FROM objects").fetchall()
    for tier in TIERS:
        try:
            index = FourierIndex.open(raw, tier)
        except (StorageError, NotFound) as exc:
            report.add(f"{tier} tier: R-tree cannot be opened: {exc}")
            continue
        try:
            if index.dimension != DIMENSION:
                report.add(f"{tier} tier: R-tree has dimension {index.dimension}, not {DIMENSION}")
                continue
            entries = {}
            everything = np.full(DIMENSION, 1e300)
            ids, los, his = index.intersection_boxes(-everything, everything)
            for gid, lo, hi in zip(ids.tolist(), los, his, strict=True):
                entries[gid] = (lo, hi)
            rows = raw.execute(
                "SELECT id, object_id, view_ids, curves, lo, hi FROM index_groups WHERE tier = ?",
                (tier,),
            ).fetchall()
            in_tier = _check_groups(tier, rows, entries, stored, report)
            for gid in sorted(entries):
                report.add(f"{tier} tier: R-tree entry {gid} has no group row")
            _check_members(tier, objects, in_tier, stored, config, client, report)
            report.checked[f"{tier}_groups"] = len(rows)
        finally:
            index.discard()


class _StoredViews:
    """Every stored view's curve (perspective views by their group id,
    :func:`~viewdb.storage.schema.perspective_group_id`), each object's views, and its
    perspective views (full tier only)."""

    def __init__(self, raw, n: int, report: CheckReport) -> None:  # type: ignore[no-untyped-def]
        self.n = n
        self.curves: dict[int, np.ndarray] = {}
        for vid, blob in raw.execute("SELECT view_id, samples FROM curves"):
            try:
                self.curves[int(vid)] = decode_array(blob, np.float32, (n,))
            except StorageError:
                continue  # reported with the views
        self.views: dict[int, list[tuple[int, float, float]]] = {}
        for vid, oid, az, el in raw.execute(
            "SELECT id, object_id, azimuth, elevation FROM views ORDER BY id"
        ):
            self.views.setdefault(int(oid), []).append((int(vid), float(az), float(el)))
        self.perspective: dict[int, set[int]] = {}
        for pid, oid, blob in raw.execute("SELECT id, object_id, samples FROM perspective_views"):
            gid = s.perspective_group_id(int(pid))
            self.perspective.setdefault(int(oid), set()).add(gid)
            try:
                self.curves[gid] = decode_array(blob, np.float32, (n,))
            except StorageError as exc:
                report.add(f"perspective view {pid}: {exc.message}")

    def owned(self, oid: int, tier: str) -> set[int]:
        """The ids object ``oid``'s groups in ``tier`` may name."""
        out = {vid for vid, _, _ in self.views.get(oid, [])}
        return out | self.perspective.get(oid, set()) if tier == "full" else out


def _check_groups(  # type: ignore[no-untyped-def]
    tier: str, rows, entries: dict[int, tuple[np.ndarray, np.ndarray]], stored: _StoredViews,
    report: CheckReport,
) -> dict[int, set[int]]:
    """Check each group row of ``tier`` against its R-tree entry (taken out of
    ``entries``), its box and its object's stored views; the views each object has in
    the tier."""
    n = stored.n
    in_tier: dict[int, set[int]] = {}
    for gid, oid, blob_ids, blob_curves, blob_lo, blob_hi in rows:
        where = f"{tier} tier group {gid}"
        try:
            ids_g = decode_array(blob_ids, np.int64, (None,))
            curves_g = decode_array(blob_curves, np.float32, (len(ids_g), n))
            lo = decode_array(blob_lo, np.float64, (DIMENSION,))
            hi = decode_array(blob_hi, np.float64, (DIMENSION,))
        except StorageError as exc:
            report.add(f"{where}: {exc.message}")
            continue
        entry = entries.pop(gid, None)
        if entry is None:
            report.add(f"{where}: not in the R-tree")
        elif not (np.array_equal(entry[0], lo) and np.array_equal(entry[1], hi)):
            report.add(f"{where}: R-tree box differs from the stored box")
        coords = indexed_coordinates(curves_g)
        if np.any(coords < lo - MBR_PADDING) or np.any(coords > hi + MBR_PADDING):
            report.add(f"{where}: views lie outside its box")
        owned = stored.owned(int(oid), tier)
        mine = in_tier.setdefault(int(oid), set())
        for vid, curve in zip(ids_g.tolist(), curves_g, strict=True):
            if vid not in owned:
                report.add(f"{where}: view {vid} is not a view of its object")
            elif vid in stored.curves and not np.array_equal(stored.curves[vid], curve):
                report.add(f"{where}: curve of view {vid} differs from the stored curve")
            if vid in mine:
                report.add(f"{where}: view {vid} is in the tier twice")
            mine.add(vid)
    return in_tier


def _check_members(  # type: ignore[no-untyped-def]
    tier: str, objects, in_tier: dict[int, set[int]], stored: _StoredViews, config,
    client: bool, report: CheckReport,
) -> None:
    """Each object's views in ``tier`` are exactly the ones its plan puts there."""
    for oid, name, skimmed, symmetry in objects:
        views = stored.views.get(int(oid), [])
        sym = None
        if symmetry is not None:
            try:
                sym = SymmetryType.from_dict(json.loads(symmetry))
            except (ValueError, KeyError, TypeError):
                continue  # reported with the objects
        members: Sequence[int]
        if client:  # the client file holds the sparse tier's views only
            members = range(len(views)) if tier == "sparse" else range(0)
        else:
            members = tier_members([(a, e) for _, a, e in views], config.gap,
                                   config.client_gap, sym, bool(skimmed))[tier]
        expected = {views[i][0] for i in members}
        if tier == "full":
            expected |= stored.perspective.get(int(oid), set())
        if in_tier.get(int(oid), set()) != expected:
            report.add(
                f"object {name!r}: {tier} tier holds {len(in_tier.get(int(oid), ()))} "
                f"views, expected {len(expected)}"
            )
