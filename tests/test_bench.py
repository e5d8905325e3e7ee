"""`viewdb bench` at a small scale: the same code as the paper-scale run, on four sample
models with a 30° server grid, a handful of queries and two client grids."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import viewdb
from tests.conftest import sample
from viewdb.bench import BenchConfig, run_bench
from viewdb.bench.log import ResultLog
from viewdb.bench.metrics import cmc, rank_of
from viewdb.bench.queries import grid_queries, photo_queries
from viewdb.bench.tasks import plan_tasks
from viewdb.camera import grid_views
from viewdb.config import BuildConfig, IndexConfig
from viewdb.search.grouping import tier_members
from viewdb_cli.main import main

MODELS = ("car", "mug", "l_bracket", "chair")


def small_config(models, out, **kw) -> BenchConfig:
    args = dict(models=models, out=out, queries=4, seed=3, gaps=(60.0, 90.0), client_gap=60.0,
                k=3, gap=30.0, image_size=96)
    return BenchConfig(**{**args, **kw})


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    for name in MODELS:
        src = sample(name)
        shutil.copy(src, folder / src.name)
    return folder


@pytest.fixture(scope="module")
def bench_run(models, tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    stages = []
    run = run_bench(small_config(models, out), progress=lambda p: stages.append(p.stage))
    return run, out, stages


def test_a_small_run_writes_every_output(bench_run):
    run, out, stages = bench_run
    for name in ("results.json", "accuracy.csv", "timing.csv", "index.md", "report.md",
                 "cmc.png", "time_vs_gap.png", "time_split.png"):
        assert (out / name).stat().st_size > 0, name
        assert run.files[name] == out / name
    for png in ("cmc.png", "time_vs_gap.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert {"ingest skimmed", "ingest full grid", "measure", "report"} <= set(stages)
    summary = json.loads((out / "results.json").read_text())
    assert summary["objects"] == len(MODELS)
    assert set(summary["accuracy"]) == {"grid", "photo"}
    assert set(summary["accuracy"]["grid"]) == {"S1", "S2", "S3", "S4", "S5", "S6"}
    # every planned measurement is in the log exactly once
    keys = [json.loads(line)["key"] for line in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(keys) == sorted(t.key for t in plan_tasks(small_config(None, out)))
    assert run.measured == len(keys) and run.skipped == 0
    # the time experiment covers every client gap and k for CS1 and CS2, both settings
    combos = {(r["skim"], r["plan"], r["client_gap"], r["k"]) for r in summary["timing"]}
    for skim in (True, False):
        for k in (1, 2, 3):
            assert (skim, "server", None, k) in combos
            for plan in ("cs1", "cs2"):
                assert {(skim, plan, 60.0, k), (skim, plan, 90.0, k)} <= combos


def test_cmc_curves_are_monotone_rates_and_cs1_is_exact(bench_run):
    _, out, _ = bench_run
    summary = json.loads((out / "results.json").read_text())
    for protocol, rows in summary["accuracy"].items():
        for label, row in rows.items():
            curve = row["cmc"]
            assert len(curve) == 3 and all(0.0 <= x <= 1.0 for x in curve), (protocol, label)
            assert all(a <= b for a, b in zip(curve, curve[1:], strict=False)), (protocol, label)
            assert row["n"] == 4
        # grid queries are views of the db itself: the server finds each one first
        # (no two of these models share a silhouette)
    assert summary["accuracy"]["grid"]["S4"]["cmc"][0] == 1.0
    for protocol in ("grid", "photo"):
        f = summary["findings"][protocol]
        assert f["S2_equals_S1_results"] == 1.0 and f["S5_equals_S4_results"] == 1.0, f
    records = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines()]
    cs = [r for r in records if r["plan"] != "server" and r["error"] is None]
    assert cs and all(r["bytes_sent"] > 0 and r["bytes_received"] > 0 for r in cs)
    assert all(r["client_ms"] > 0 and r["server_ms"] > 0 for r in cs)


def test_index_table_has_both_full_files_and_every_client(bench_run):
    run, out, _ = bench_run
    rows = run.summary["index"]
    full = {r["skim"]: r for r in rows if r["kind"] == "full"}
    assert full[False]["views"] == full[False]["views_grid"] == len(MODELS) * len(grid_views(30))
    assert full[True]["views"] < full[False]["views"]  # skimming stores fewer views
    assert all(r["build_seconds"] > 0 for r in rows)
    clients = sorted((r["skim"], r["gap"], r["views"]) for r in rows if r["kind"] == "client")
    assert [(s, g) for s, g, _ in clients] == [(False, 60), (False, 90), (True, 60), (True, 90)]
    assert clients[0][2] == len(MODELS) * 36 and clients[1][2] == len(MODELS) * 16
    text = (out / "index.md").read_text()
    assert text.count("\n") == 2 + len(rows)


def test_a_killed_run_resumes_from_its_log(bench_run, models):
    run, out, _ = bench_run
    log = out / "results.jsonl"
    lines = log.read_text().splitlines(keepends=True)
    # as if killed while writing: the last 5 records missing, a line cut short
    log.write_text("".join(lines[:-5]) + lines[-5][:17])
    again = run_bench(small_config(models, out))
    assert again.measured == 5 and again.skipped == len(lines) - 5
    assert len(log.read_text().splitlines()) == len(lines)
    with ResultLog(log) as reread:
        assert len(reread) == len(lines)
    # and once complete, nothing is measured again (databases and queries from the cache)
    third = run_bench(small_config(models, out))
    assert third.measured == 0 and third.skipped == len(lines)


def test_another_configuration_in_the_same_folder_is_refused(bench_run, models):
    _, out, _ = bench_run
    with pytest.raises(viewdb.ViewDBError, match="another run.*seed"):
        run_bench(small_config(models, out, seed=4))


def test_same_seed_gives_the_same_queries(bench_run, tmp_path):
    run, out, _ = bench_run
    full = next(r for r in run.summary["index"] if r["kind"] == "full" and r["skim"])
    db_path = out / "cache" / full["file"]
    names = sorted(MODELS)
    with viewdb.open(db_path, create=False) as db:
        a = grid_queries(db, names, 5, 11, tmp_path / "a")
        b = grid_queries(db, names, 5, 11, tmp_path / "b")
        c = grid_queries(db, names, 5, 12, tmp_path / "c")
        assert [(q.object, q.azimuth, q.elevation) for q in a] == [(q.object, q.azimuth, q.elevation) for q in b]
        assert all(np.array_equal(x.curve, y.curve) for x, y in zip(a, b, strict=True))
        assert [(q.object, q.azimuth, q.elevation) for q in a] != [(q.object, q.azimuth, q.elevation) for q in c]
        assert all(q.azimuth % 30 == 0 and q.elevation % 30 == 0 for q in a)
        p = photo_queries(db, names, 2, 11, tmp_path / "a", image_size=96)
        r = photo_queries(db, names, 2, 11, tmp_path / "b", image_size=96)
        assert [x.spec for x in p] == [y.spec for y in r]
        assert [x.path.read_bytes() for x in p] == [y.path.read_bytes() for y in r]
        assert all(x.path.read_bytes()[:2] == b"\xff\xd8" for x in p)  # JPEG
        # read back from the folder, not drawn again
        again = grid_queries(db, names, 5, 11, tmp_path / "a")
        assert all(np.array_equal(x.curve, y.curve) for x, y in zip(a, again, strict=True))


def test_full_databases_built_elsewhere_are_adopted(bench_run, models, tmp_path):
    run, out, _ = bench_run
    cache = tmp_path / "cache"
    cache.mkdir()
    for row in run.summary["index"]:
        if row["kind"] == "full":
            shutil.copy(out / "cache" / row["file"], cache / ("mine-skim.db" if row["skim"] else "mine-all.db"))
    again = run_bench(small_config(models, tmp_path / "out", cache=cache, protocols=("grid",),
                                   timing_protocols=()))
    full = {r["skim"]: r for r in again.summary["index"] if r["kind"] == "full"}
    assert full[True]["file"] == "mine-skim.db" and full[False]["file"] == "mine-all.db"
    assert full[True]["adopted"] and full[True]["build_seconds"] is None
    assert not list(cache.glob("full-*.db"))  # nothing was built


def test_fifty_degree_client_grid_is_the_extraction_loop():
    config = BuildConfig(gap=10, index=IndexConfig(client_gap=50))
    assert config.client_gap == 50
    positions = grid_views(10)
    sparse = [positions[i] for i in tier_members(positions, 10, 50)["sparse"]]
    rings = [0.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 350.0]
    assert sorted(sparse) == [(h, v) for h in rings for v in rings]
    with pytest.raises(ValueError, match="multiple of the gap"):
        BuildConfig(gap=10, index=IndexConfig(client_gap=190))


@given(st.lists(st.one_of(st.none(), st.integers(1, 8)), max_size=40), st.integers(1, 8))
def test_cmc_is_the_share_of_queries_found_by_each_rank(ranks, max_rank):
    curve = cmc(ranks, max_rank)
    for r in range(1, max_rank + 1):
        expected = sum(x is not None and x <= r for x in ranks) / len(ranks) if ranks else 0.0
        assert curve[r - 1] == pytest.approx(expected)


def test_rank_of():
    assert rank_of("b", ["a", "b", "c"]) == 2 and rank_of("z", ["a"]) is None


def test_cli_bench_continues_a_finished_run_and_reports_bad_input(bench_run, models, tmp_path, capsys):
    _, out, _ = bench_run
    args = ["bench", str(models), "--out", str(out), "--queries", "4", "--seed", "3",
            "--gaps", "60,90", "--client-gap", "60", "-k", "3", "--gap", "30", "--image-size", "96"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "0 measurements made" in text and "grid queries, rank-1" in text
    assert main(["bench", str(tmp_path / "nothing"), "--out", str(tmp_path / "o")]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("viewdb: ") and "nothing" in err and "\n" not in err
    assert main(["bench", str(models), "--out", str(tmp_path / "o"), "--gaps", "a,b"]) == 2
    assert main(["bench", str(models), "--out", str(tmp_path / "o"), "--gap", "30",
                 "--gaps", "45"]) == 1
    assert "multiple of the gap" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # refused before anything was written
