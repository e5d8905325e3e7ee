"""Tier files: a tier's arrays written next to the database, mapped by a fresh process
instead of decoded from the groups; the same arrays, the same answers, never a stale or
damaged file."""

import sqlite3

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import copy_db, sample
from viewdb.catalogue.features import distance_curve, mirror_curve
from viewdb.search.shifts import ShiftWindow
from viewdb.storage.codecs import decode_array
from viewdb.storage.schema import SCHEMA_REVISION
from viewdb.storage.tier_file import ARRAYS, map_tier_file, tier_file_path, tier_key
from viewdb.storage.tiers import TIERS, StoredTier

_copy = copy_db


def _copy_with_tier_files(src, dst):
    """A copy of ``src`` with its tier files, as they were written for it."""
    _copy(src, dst)
    for tier in TIERS:
        tier_file_path(dst, tier).write_bytes(tier_file_path(src, tier).read_bytes())
    return dst


@pytest.fixture(scope="module")
def mapped_db(tiered_db, tmp_path_factory):
    """A copy of the tiered file with its tier files written (a writable reader's first
    search of each tier)."""
    path = _copy(tiered_db, tmp_path_factory.mktemp("mapped") / "copy.db")
    with viewdb.open(path, create=False) as db:
        for tier in TIERS:
            db.search(np.ones(128), k=1, tier=tier)
    return path


@pytest.fixture(scope="module")
def plain_db(tiered_db, tmp_path_factory):
    """A copy of the tiered file without tier files, opened read-only only (never gets one)."""
    return _copy(tiered_db, tmp_path_factory.mktemp("plain") / "copy.db")


def _decoded_and_mapped(path, tier):
    conn = sqlite3.connect(path)
    try:
        conn.execute("BEGIN")
        mapped = map_tier_file(tier_file_path(path, tier), tier_key(conn, tier), tier)
        decoded = StoredTier(conn, tier).file_arrays()
        conn.execute("ROLLBACK")
    finally:
        conn.close()
    return decoded, mapped


@pytest.mark.parametrize("tier", TIERS)
def test_a_tier_file_holds_exactly_the_arrays_decoded_from_the_groups(mapped_db, tier):
    decoded, mapped = _decoded_and_mapped(mapped_db, tier)
    assert mapped is not None and set(mapped) == set(ARRAYS)
    for name in ARRAYS:
        assert mapped[name].dtype == decoded[name].dtype, name
        np.testing.assert_array_equal(mapped[name], decoded[name], err_msg=name)
    assert mapped["curves"].flags.writeable  # as the compiled search's signatures expect


def _curve(db, rng, turned):
    name = db.objects()[int(rng.integers(len(db.objects())))].name
    q = distance_curve(db.render(name, *rng.uniform(0, 360, 2)).mask, 128)
    q = q + rng.normal(0, 0.02, 128)
    q = mirror_curve(q) if turned % 2 else q
    return np.roll(q, int(turned))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.integers(0, 2**32 - 1), st.integers(0, 127), st.sampled_from(TIERS), st.integers(1, 4),
       st.booleans())
def test_searches_through_a_tier_file_answer_as_through_the_groups(
    mapped_db, plain_db, seed, turned, tier, k, shifts,
):
    with viewdb.open(mapped_db, read_only=True) as mapped, viewdb.open(plain_db, read_only=True) as plain:
        q = _curve(plain, np.random.default_rng(seed), turned)
        window = ShiftWindow() if shifts else None
        a, _ = mapped.search(q, k=k, tier=tier, shifts=window)
        b, _ = plain.search(q, k=k, tier=tier, shifts=window)
        with mapped._catalogue.tier_reader().snapshot() as reader:
            assert reader.tier(tier).mapped  # the tier file answered
        with plain._catalogue.tier_reader().snapshot() as reader:
            assert not reader.tier(tier).mapped  # the groups answered
    assert a == b


def test_a_read_only_open_writes_no_tier_file_and_answers_without_one(tiered_db, tmp_path):
    path = _copy(tiered_db, tmp_path / "copy.db")
    q = distance_curve(viewdb.render_model(sample("mug"), 20, 30, image_size=96).mask, 128)
    with viewdb.open(path, read_only=True) as db:
        hits, _ = db.search(q, k=2)
    assert not [p.name for p in tmp_path.iterdir() if ".tier-" in p.name]
    assert hits[0].object == "mug"


def test_a_stale_tier_file_is_not_used_and_is_written_again(mapped_db, tmp_path):
    path = _copy_with_tier_files(mapped_db, tmp_path / "copy.db")  # the tier files before the ingest
    old = tier_file_path(path, "full").read_bytes()
    with viewdb.open(path, create=False) as db:
        db.ingest([sample("sphere")])
    assert tier_file_path(path, "full").read_bytes() != old
    q = distance_curve(viewdb.render_model(sample("sphere"), 10, 10, image_size=96).mask, 128)
    with viewdb.open(path, read_only=True) as db:
        hits, _ = db.search(q, k=1)
    assert hits[0].object == "sphere"
    decoded, mapped = _decoded_and_mapped(path, "full")
    assert mapped is not None and len(mapped["ids"]) == len(decoded["ids"])
    # the old file, put back, no longer matches the file's content: not used
    tier_file_path(path, "full").write_bytes(old)
    assert _decoded_and_mapped(path, "full")[1] is None


def test_groups_written_again_under_the_same_ids_make_the_tier_file_stale(mapped_db, tmp_path):
    """The last object's groups deleted and written again, with different curves, in one
    transaction: SQLite gives them the same ids, so the groups' count, id sum and maximum
    and the objects' names and hashes are what they were; the index's generation tells the
    tier file is stale."""
    from viewdb.storage.tiers import delete_groups, write_groups

    path = _copy_with_tier_files(mapped_db, tmp_path / "copy.db")
    assert _decoded_and_mapped(path, "full")[1] is not None
    conn = sqlite3.connect(path, isolation_level=None)
    try:
        last = conn.execute("SELECT object_id FROM index_groups ORDER BY id DESC LIMIT 1").fetchone()[0]
        before = conn.execute("SELECT count(*), total(id), max(id) FROM index_groups").fetchone()
        views = {}
        for tier in TIERS:
            ids, curves = [], []
            for view_ids, blob in conn.execute("SELECT view_ids, curves FROM index_groups WHERE object_id = ?"
                                               " AND tier = ? ORDER BY id", (last, tier)):
                v = decode_array(view_ids, np.int64, (None,))
                ids += v.tolist()
                curves.append(decode_array(blob, np.float32, (len(v), 128)))
            views[tier] = (ids, np.concatenate(curves))
        ids, curves = views["full"]
        members = {"full": range(len(ids)), "sparse": [ids.index(v) for v in views["sparse"][0]]}
        conn.execute("BEGIN IMMEDIATE")
        delete_groups(conn, [last])
        write_groups(conn, last, ids, curves * 1.01, members, 32)
        conn.execute("COMMIT")
        assert conn.execute("SELECT count(*), total(id), max(id) FROM index_groups").fetchone() == before
    finally:
        conn.close()
    assert _decoded_and_mapped(path, "full")[1] is None


@pytest.mark.parametrize("damage", ["truncated", "garbage", "empty", "other tier"])
def test_a_damaged_tier_file_is_ignored(mapped_db, tmp_path, damage):
    path = _copy(mapped_db, tmp_path / "copy.db")
    good = tier_file_path(mapped_db, "full").read_bytes()
    bad = {"truncated": good[: len(good) // 2], "garbage": b"VDBTIER1\xff\xff\x00\x00{not json",
           "empty": b"", "other tier": tier_file_path(mapped_db, "sparse").read_bytes()}[damage]
    tier_file_path(path, "full").write_bytes(bad)
    assert _decoded_and_mapped(path, "full")[1] is None
    q = distance_curve(viewdb.render_model(sample("car"), 50, 20, image_size=96).mask, 128)
    with viewdb.open(path, read_only=True) as db, viewdb.open(mapped_db, read_only=True) as ref:
        assert db.search(q, k=3)[0] == ref.search(q, k=3)[0]


def test_stored_curves_come_from_the_mapped_tier_as_the_file_holds_them(mapped_db, tmp_path):
    """Once a search has mapped the full tier, an object's stored curves (the pose's
    nearest views) are read from it: the same curves, in the same order, as the file's
    rows; an object written again since then is read from the file."""
    path = _copy_with_tier_files(mapped_db, tmp_path / "copy.db")
    with viewdb.open(path, create=False) as db:
        catalogue = db._catalogue
        names = [o.name for o in db.objects()]
        assert all(catalogue._tier_curves(n) is None for n in names)  # nothing mapped yet
        db.search(np.ones(128), k=1)
        assert catalogue._reader.loaded("full").mapped
        for name in names:
            from_tier, from_rows = catalogue._tier_curves(name), catalogue._store.object_curves(name)
            assert from_tier is not None and list(from_tier) == list(from_rows)
            assert all(np.array_equal(from_tier[key], from_rows[key]) for key in from_rows)
        db.ingest([sample("sphere")])  # the tier that search mapped is out of date
        assert all(catalogue._tier_curves(n) is None for n in [*names, "sphere"])
        curves, rows = catalogue.stored_curves("sphere"), catalogue._store.object_curves("sphere")
        assert list(curves) == list(rows) and all(np.array_equal(curves[k], rows[k]) for k in rows)
    with viewdb.open(path, read_only=True) as db:  # the tier file written again, mapped
        db.search(np.ones(128), k=1)
        curves = db._catalogue._tier_curves("sphere")
        assert list(curves) == list(rows) and all(np.array_equal(curves[k], rows[k]) for k in rows)


def _statements(path, call):
    """``call(conn)`` inside a read transaction of ``path`` (read-only) and the SQL statements it ran."""
    conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    ran = []
    try:
        conn.execute("BEGIN")
        conn.set_trace_callback(ran.append)
        out = call(conn)
        conn.set_trace_callback(None)
        conn.execute("ROLLBACK")
    finally:
        conn.close()
    return out, ran


def test_an_ingest_stamps_each_tiers_key_and_a_fresh_open_reads_it_in_one_statement(tmp_path):
    from tests.test_readonly import _downgrade
    from viewdb.storage.tier_file import _unmarked_key, generation, write_tier_file

    path = tmp_path / "s.db"
    with viewdb.open(path, gap=90, image_size=64) as db:
        db.ingest([sample("cone"), sample("pyramid")])
    for tier in TIERS:
        key, ran = _statements(path, lambda c, t=tier: tier_key(c, t))
        assert len(ran) == 1, ran  # the stamp of the current generation: one read
        with sqlite3.connect(path) as conn:
            stamped = conn.execute("SELECT generation, key FROM tier_stamps WHERE tier = ?", (tier,)).fetchone()
            assert stamped == (generation(conn), key)
        assert map_tier_file(tier_file_path(path, tier), key, tier) is not None  # the ingest's file

    # a write renews the generation and the stamp: the old files no longer match
    old = {tier: tier_key(sqlite3.connect(path), tier) for tier in TIERS}
    with viewdb.open(path) as db:
        db.ingest([sample("torus")])
    for tier in TIERS:
        assert tier_key(sqlite3.connect(path), tier) != old[tier]

    # a file from before the stamps (revision 0008) opens read-only as it is (its tier files
    # used), is migrated by a normal open, and computes its keys until a write stamps them
    before = tmp_path / "before.db"
    copy_db(path, before)
    _downgrade(before, "0008")
    with sqlite3.connect(before) as conn:
        computed = {tier: tier_key(conn, tier) for tier in TIERS}
        assert computed != {tier: _unmarked_key(conn, tier) for tier in TIERS}  # it has a generation
    for tier in TIERS:  # its tier files, as a viewdb before the stamps wrote them
        write = tier_file_path(before, tier)
        with sqlite3.connect(before) as conn:
            conn.execute("BEGIN")
            write_tier_file(write, computed[tier], tier, StoredTier(conn, tier).file_arrays())
            conn.execute("ROLLBACK")
    for tier in TIERS:  # read as it is, its files are used
        key, _ = _statements(before, lambda c, t=tier: tier_key(c, t))
        assert key == computed[tier] and map_tier_file(tier_file_path(before, tier), key, tier) is not None
    with viewdb.open(before, read_only=True) as db:
        assert db.info().schema_revision == "0008"
        assert db.recognise(np.ones(128), 2).results == viewdb.open(path, read_only=True).recognise(
            np.ones(128), 2).results
    with viewdb.open(before, create=False) as db:  # migrated
        assert db.info().schema_revision == SCHEMA_REVISION
    for tier in TIERS:  # no stamp yet: computed (for the new revision, as after every migration)
        key, ran = _statements(before, lambda c, t=tier: tier_key(c, t))
        assert len(ran) > 1 and key != computed[tier]
    with viewdb.open(before) as db:
        db.ingest([sample("box_long")])
    for tier in TIERS:
        _, ran = _statements(before, lambda c, t=tier: tier_key(c, t))
        assert len(ran) == 1
