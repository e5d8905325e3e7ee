"""What a careful attacker or an unlucky user tries: numbers out of any sane range, files
that are not files, names that talk to the terminal, output into a pipe. Each test fails
without the guard it checks."""

from __future__ import annotations

import json
import os
import resource
import shutil
import sqlite3
import subprocess
import sys
import textwrap

import cv2
import numpy as np
import pytest

import viewdb
from tests.conftest import ROOT, sample
from viewdb_cli.main import main


def run(capsys, *args):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _limited(gigabytes: float):
    """preexec_fn: cap the child's address space, so a guard that fails cannot take the
    machine's memory with it."""
    def limit() -> None:
        size = int(gigabytes * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (size, size))
    return limit


def cli(*args, timeout=120, memory_gb=4.0):
    """``viewdb ARGS`` in a child process with bounded memory and time."""
    return subprocess.run([sys.executable, "-m", "viewdb_cli.main", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, cwd=ROOT,
                          preexec_fn=_limited(memory_gb))


def one_line_error(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def photo_of(db_path, name, h, v, out):
    with viewdb.open(db_path, read_only=True) as db:
        view = db.render(name, h, v)
    image = np.full(view.color.shape, 200, np.uint8)
    image[view.mask] = view.color[view.mask]
    cv2.imwrite(str(out), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    return out


# ----------------------------------------------------------------------------- numbers
def test_a_tiny_gap_is_refused_before_it_can_eat_the_memory(tmp_path):
    db = tmp_path / "g.db"
    done = cli("ingest", sample("cone"), "--db", db, "--gap", "1e-9", memory_gb=3.0)
    assert done.returncode == 2, done.stderr[-2000:]
    assert "--gap" in done.stderr and "must be a finite number in [1, 180]" in done.stderr
    assert not db.exists()


@pytest.mark.parametrize("option, value, problem", [
    ("--gap", "nan", "finite number"),
    ("--gap", "inf", "finite number"),
    ("--gap", "0.5", "[1, 180]"),
    ("--client-gap", "inf", "finite number"),
    ("--client-gap", "nan", "finite number"),
    ("--perspective", "inf", "at most 1000"),
    ("--perspective", "1e308", "at most 1000"),
    ("--perspective", "nan", "greater than 1"),
    ("--image-size", "99999", "4096"),
    ("--jobs", "100000", "64"),
])
def test_out_of_range_ingest_options_are_usage_errors_and_touch_no_file(tmp_path, capsys, option, value, problem):
    db = tmp_path / "x.db"
    code, _, err = run(capsys, "ingest", sample("cone"), "--db", db, option, value)
    assert code == 2 and problem in err, err
    assert not db.exists()


def test_the_library_refuses_the_same_settings_before_creating_a_file(tmp_path):
    """(In a child with bounded memory: without the guard, gap=1e-9 exhausts it.)"""
    script = textwrap.dedent(f"""
        import json, pathlib, viewdb
        cases = [{{"gap": 1e-9}}, {{"gap": float("inf")}}, {{"client_gap": float("inf")}},
                 {{"client_gap": float("nan")}}, {{"perspective": (float("inf"),)}},
                 {{"perspective": (1e308,)}}, {{"image_size": 10**30}}]
        out = []
        for i, settings in enumerate(cases):
            path = pathlib.Path({str(tmp_path)!r}) / f"{{i}}.db"
            try:
                viewdb.open(path, **settings).close()
                out.append("opened")
            except viewdb.ViewDBError as exc:
                out.append("refused" if str(path) in str(exc) and not path.exists() else str(exc))
        print(json.dumps(out))
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120,
                          cwd=ROOT, preexec_fn=_limited(3.0))
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout) == ["refused"] * 7


def test_a_file_built_with_settings_now_refused_gives_one_line(small_db, tmp_path, capsys):
    """A file an older viewdb created with --perspective 1e308 (which it accepted) can be
    read, and refuses in one line to be ingested into."""
    path = tmp_path / "far.db"
    shutil.copy(small_db, path)
    with sqlite3.connect(path) as conn:
        build = json.loads(conn.execute("SELECT value FROM settings WHERE key='build'").fetchone()[0])
        build["perspective"]["distances"] = [1e308]
        conn.execute("UPDATE settings SET value=? WHERE key='build'", (json.dumps(build),))
    for args in (["info", "--db", path], ["ingest", sample("cone"), "--db", path]):
        code, _, err = run(capsys, *args)
        assert code == 1 and "unusable build settings" in one_line_error(err)


def test_render_angles_must_be_finite(tmp_path, small_db, capsys):
    out = tmp_path / "v.png"
    code, _, err = run(capsys, "render", "mug", "--db", small_db, "--azimuth", "nan", "--elevation", 0,
                       "--out", out)
    assert code == 2 and "finite" in err and not out.exists()
    with viewdb.open(small_db, read_only=True) as db, pytest.raises(viewdb.ViewDBError, match="azimuth"):
        db.render("mug", float("nan"), 0)
    with pytest.raises(viewdb.ViewDBError, match="elevation"):
        viewdb.render_model(sample("cone"), 0, float("inf"))


@pytest.mark.parametrize("jobs", [0, 65, 2.5, True])
def test_ingest_jobs_must_be_a_sane_count(tmp_path, jobs):
    with viewdb.open(tmp_path / "j.db", gap=90) as db, pytest.raises(viewdb.ViewDBError, match="jobs"):
        db.ingest([sample("cone")], jobs=jobs)


@pytest.mark.parametrize("intrinsics", ["1e20,1e20,128,128", "5e-324,5e-324,128,128",
                                        "500,500,1e300,0", "0.5,500,64,64"])
def test_intrinsics_out_of_range_get_one_line_not_a_traceback(small_db, tmp_path, capsys, intrinsics):
    img = photo_of(small_db, "car", 37, 22, tmp_path / "q.png")
    code, _, err = run(capsys, "query", img, "--db", small_db, "-k", 1, "--no-colour", "--no-verify",
                       "--intrinsics", intrinsics)
    assert code == 1 and "intrinsics" in one_line_error(err)
    with pytest.raises(viewdb.QueryError, match=r"must be a finite number in"):
        viewdb.parse_intrinsics(intrinsics)


def _bomb_png(path, width, height):
    """A PNG whose header claims ``width`` x ``height`` pixels (its data is a stub)."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(b"\x00" * 1000)) + chunk(b"IEND", b""))
    return path


def test_a_label_map_bomb_is_one_line_like_the_photo(small_db, tmp_path, capsys):
    img = photo_of(small_db, "car", 37, 22, tmp_path / "q.png")
    bomb = _bomb_png(tmp_path / "labels.png", 30000, 30000)
    code, _, err = run(capsys, "query", img, "--db", small_db, "--label-map", bomb, "--label", 1)
    assert code == 1 and "too large" in one_line_error(err) and str(bomb) in err
    code, _, err = run(capsys, "query", bomb, "--db", small_db)  # the photo path, as before
    assert code == 1 and "too large" in one_line_error(err)


# ----------------------------------------------------------------------------- files
def _obj_with_texture(folder, texture="tex.png"):
    (folder / "s.obj").write_text("mtllib s.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvt 1 0\n"
                                  "vt 0 1\nusemtl a\nf 1/1 2/2 3/3\nf 1/1 2/2 4/3\nf 2/1 3/2 4/3\nf 1/1 3/2 4/3\n")
    (folder / "s.mtl").write_text(f"newmtl a\nmap_Kd {texture}\n")
    return folder / "s.obj"


@pytest.mark.parametrize("fifo", ["tex.png", "s.mtl"])
def test_a_fifo_texture_or_library_is_refused_not_waited_on(tmp_path, fifo):
    obj = _obj_with_texture(tmp_path)
    (tmp_path / fifo).unlink(missing_ok=True)
    os.mkfifo(tmp_path / fifo)
    try:
        done = cli("ingest", obj, "--db", tmp_path / "f.db", "--gap", 90, "--image-size", 64,
                   "--allow-missing-textures", timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the ingest waited on the FIFO {fifo}")
    assert done.returncode == 1
    assert fifo in done.stderr and "FIFO" in one_line_error(done.stderr)


def test_files_that_are_not_regular_files_are_named_as_such(tmp_path, capsys):
    os.mkfifo(tmp_path / "pipe.obj")
    code, out, err = run(capsys, "ingest", tmp_path / "pipe.obj", "/dev/zero", "--db", tmp_path / "n.db",
                         "--gap", 90)
    assert code == 1 and "2 failed" in out
    assert "pipe.obj: is a FIFO" in err and "/dev/zero: is a device" in err


def test_an_intrinsics_file_must_be_a_small_regular_file(tmp_path):
    os.mkfifo(tmp_path / "k.json")
    with pytest.raises(viewdb.QueryError, match="is a FIFO"):
        viewdb.parse_intrinsics(tmp_path / "k.json")
    big = tmp_path / "big.json"
    big.write_text('{"fx": 500, "fy": 500, "cx": 1, "cy": 1, "pad": "' + "x" * (2 << 20) + '"}')
    with pytest.raises(viewdb.QueryError, match="not an intrinsics file"):
        viewdb.parse_intrinsics(big)


def test_every_failed_file_says_why_duplicates_and_missing_ones_too(tmp_path, capsys):
    twin = tmp_path / "cone.stl"
    shutil.copy(sample("l_bracket"), twin)
    code, out, err = run(capsys, "ingest", sample("cone"), twin, tmp_path / "gone.off", "--db",
                         tmp_path / "d.db", "--gap", 90, "--image-size", 64)
    assert code == 1 and "2 failed" in out
    lines = [line for line in err.splitlines() if line.strip()]
    assert any(str(twin) in line and "already taken" in line for line in lines), err
    assert any("gone.off" in line and "no such file" in line for line in lines), err


@pytest.mark.parametrize("out_name, what, problem", [
    ("x.weird", "color", "cannot write images of type '.weird'"),
    ("x", "color", "cannot write images of type '(none)'"),
    ("x.jpg", "depth", "needs 16 bits"),
    ("missing/x.png", "color", "its folder does not exist"),
])
def test_render_refuses_an_output_it_cannot_write_in_one_line(tmp_path, capsys, out_name, what, problem):
    code, _, err = run(capsys, "render", sample("cone"), "--azimuth", 0, "--elevation", 0,
                       "--out", tmp_path / out_name, "--what", what)
    assert code == 1 and problem in one_line_error(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- output
ESC = "\x1b"


def test_control_characters_in_names_never_reach_the_terminal(tmp_path, capsys):
    evil = tmp_path / f"evil{ESC}]0;owned{chr(7)}{ESC}[2J.off"
    shutil.copy(sample("cone"), evil)
    db = tmp_path / "e.db"
    code, out, err = run(capsys, "ingest", evil, tmp_path / f"gone{ESC}[31m.off", "--db", db,
                         "--gap", 90, "--image-size", 64)
    assert code == 1 and ESC not in out + err and "gone\\x1b[31m.off" in err
    code, out, err = run(capsys, "info", "--db", db)
    assert code == 0 and ESC not in out and chr(7) not in out and "evil\\x1b]0;owned\\x07\\x1b[2J" in out
    code, out, err = run(capsys, "render", f"nope{ESC}[2J", "--db", db, "--azimuth", 0, "--elevation", 0,
                         "--out", tmp_path / "x.png")
    assert code == 1 and ESC not in err


def test_tables_in_a_pipe_keep_whole_values(tmp_path, capsys):
    long_name = "a_rather_long_object_name_that_no_table_column_should_cut"
    mesh = tmp_path / f"{long_name}{sample('l_bracket').suffix}"
    shutil.copy(sample("l_bracket"), mesh)
    db = tmp_path / "t.db"
    assert run(capsys, "ingest", mesh, "--db", db, "--gap", 60, "--image-size", 96)[0] == 0
    code, out, _ = run(capsys, "info", "--db", db)
    assert code == 0 and long_name in out and "…" not in out
    header = next(line for line in out.splitlines() if line.startswith("object"))
    assert "no silhouette" in header and "perspective" in header
    img = photo_of(db, long_name, 37, 22, tmp_path / "q.png")
    code, out, _ = run(capsys, "query", img, "--db", db, "-k", 1, "--no-pose")
    assert code == 0 and long_name in out and "…" not in out
    assert "distance" in out


def test_a_terminal_table_never_cuts_a_value(tmp_path):
    """The same on an 80-column terminal (a pseudo-terminal): whole values, in a rich
    table when they fit and in plain columns when they do not."""
    script = textwrap.dedent(f"""
        import os, pty, sys
        pid, fd = pty.fork()
        if pid == 0:
            os.environ["COLUMNS"] = "80"
            os.execv(sys.executable, [sys.executable, "-m", "viewdb_cli.main", "info", "--db", {str(tmp_path / "t.db")!r}])
        out = b""
        while True:
            try:
                chunk = os.read(fd, 65536)
            except OSError:
                break
            if not chunk:
                break
            out += chunk
        os.waitpid(pid, 0)
        sys.stdout.write(out.decode(errors="replace"))
    """)
    long_name = "an_object_whose_name_is_far_too_long_for_eighty_columns_of_table"
    mesh = tmp_path / f"{long_name}.off"
    shutil.copy(sample("cone"), mesh)
    with viewdb.open(tmp_path / "t.db", gap=90, image_size=64) as db:
        assert not db.ingest([mesh]).failed
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert long_name in done.stdout and "…" not in done.stdout, done.stdout


# ----------------------------------------------------------------------------- database files
def _cli_script(commands: list[list[str]]) -> str:
    """A child's script running each command through the CLI, printing their exit codes
    and stderr as JSON."""
    return textwrap.dedent(f"""
        import contextlib, io, json
        from viewdb_cli.main import main
        out = []
        for argv in {commands!r}:
            err = io.StringIO()
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
                code = main(argv)
            out.append([code, err.getvalue()])
        print(json.dumps(out))
    """)


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_the_cli_uses_a_file_on_read_only_storage(small_db, tmp_path):
    """A prebuilt file shipped to a device, on a read-only mount: every command that only
    reads it works from the CLI (they failed with "unable to open database file")."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("a read-only bind mount needs root and unshare")
    folder, mount, out = tmp_path / "shipped", tmp_path / "mnt", tmp_path / "out"
    for d in (folder, mount, out):
        d.mkdir()
    shutil.copy(small_db, folder / "full.db")
    with viewdb.open(small_db, read_only=True) as db:
        db.export_client(folder / "client.db")
    img = photo_of(small_db, "car", 37, 22, out / "q.png")
    before = _snapshot(folder)
    full, client = str(mount / "full.db"), str(mount / "client.db")
    commands = [["info", "--db", full], ["check", "--db", full], ["info", "--db", client],
                ["query", str(img), "--db", full, "-k", "1", "--pose-top", "1"],
                ["query", str(img), "--db", full, "--client", client, "--plan", "cs1", "-k", "1", "--no-pose"],
                ["export-client", "--db", full, "--out", str(out / "c.db")],
                ["render", "mug", "--db", full, "--azimuth", "30", "--elevation", "20", "--out", str(out / "m.png")]]
    shell = f"mount --bind {folder} {mount} && mount -o remount,bind,ro {mount} && exec \"$@\""
    probe = subprocess.run(["unshare", "-m", "sh", "-c", shell, "sh", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot make a read-only mount here: {probe.stderr.decode()[:200]}")
    done = subprocess.run(["unshare", "-m", "sh", "-c", shell, "sh", sys.executable, "-c", _cli_script(commands)],
                          capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-3000:]
    results = json.loads(done.stdout)
    assert [code for code, _ in results] == [0] * len(commands), results
    assert _snapshot(folder) == before  # not a byte written, no -wal or -shm left
    assert (out / "c.db").exists() and (out / "m.png").exists()


def test_an_old_file_is_still_upgraded_by_a_reading_command(tmp_path, capsys):
    """A file from schema 0001 cannot be read as it is: ``info`` opens it normally once,
    upgrading it in place, as before."""
    path = tmp_path / "old.db"
    shutil.copy(ROOT / "tests" / "data" / "schema_0001.db", path)
    with pytest.raises(viewdb.UpgradeNeeded):
        viewdb.open(path, read_only=True)
    code, out, err = run(capsys, "info", "--db", path)
    assert code == 0 and "2 objects" in out, err
    with viewdb.open(path, read_only=True) as db:
        assert len(db.objects()) == 2


def _foreign(path):
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE contacts (name TEXT, phone TEXT)")
    conn.execute("INSERT INTO contacts VALUES ('ada', '555')")
    conn.commit()
    conn.close()
    return path


@pytest.mark.parametrize("command", ["info", "check", "query", "ingest", "export-client", "render"])
def test_another_programs_database_is_refused_untouched(tmp_path, capsys, command):
    path = _foreign(tmp_path / "contacts.db")
    before = _snapshot(tmp_path)
    img = tmp_path.parent / f"{tmp_path.name}-q.png"
    cv2.imwrite(str(img), np.full((32, 32, 3), 200, np.uint8))
    argv = {"info": ["info", "--db", path], "check": ["check", "--db", path],
            "query": ["query", img, "--db", path], "ingest": ["ingest", sample("cone"), "--db", path],
            "export-client": ["export-client", "--db", path, "--out", tmp_path.parent / f"{tmp_path.name}-c.db"],
            "render": ["render", "cone", "--db", path, "--azimuth", 0, "--elevation", 0,
                       "--out", tmp_path.parent / f"{tmp_path.name}-r.png"]}[command]
    code, _, err = run(capsys, *argv)
    assert code == 1 and "not a viewdb database" in one_line_error(err)
    assert _snapshot(tmp_path) == before  # header bytes 19, 20, 28, 96 and all: unchanged


@pytest.mark.parametrize("table", ["rtree_pages", "index_groups", "perspective_views", "curves",
                                   "sift_features", "views"])
def test_a_file_with_a_table_dropped_is_refused_in_one_line_by_every_command(small_db, tmp_path, capsys, table):
    path = tmp_path / "damaged.db"
    shutil.copy(small_db, path)
    with sqlite3.connect(path) as conn:
        conn.execute(f"DROP TABLE {table}")
    img = photo_of(small_db, "car", 37, 22, tmp_path / "q.png")
    for argv in (["info", "--db", path], ["check", "--db", path], ["query", img, "--db", path, "--no-pose"],
                 ["ingest", sample("cone"), "--db", path], ["export-client", "--db", path, "--out", tmp_path / "c.db"]):
        code, _, err = run(capsys, *argv)
        assert code == 1 and f"is damaged: it lacks table {table}" in one_line_error(err), (argv, err)
    done = cli("serve", "--db", path, "--port", "0", timeout=120)
    assert done.returncode == 1 and f"lacks table {table}" in one_line_error(done.stderr)


def test_a_fifo_named_as_the_database_is_refused_not_waited_on(tmp_path):
    os.mkfifo(tmp_path / "fifo.db")
    try:
        done = cli("ingest", sample("cone"), "--db", tmp_path / "fifo.db", "--gap", 90, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("the ingest waited on a FIFO named as its database")
    assert done.returncode == 1 and "is a FIFO" in one_line_error(done.stderr)


# ----------------------------------------------------------------------------- odd arguments
@pytest.mark.parametrize("url, token, problem", [
    ("http://[::1", None, "is not a server URL"),
    ("http://127.0.0.1:8765", "é", "printable ASCII"),
    ("http://127.0.0.1:8765", "a\nb", "printable ASCII"),
    ("http://127.0.0.1:8765", "two words", "printable ASCII"),
])
def test_a_bad_server_url_or_token_is_one_line(small_db, tmp_path, capsys, url, token, problem):
    with viewdb.open(small_db, read_only=True) as db:
        db.export_client(tmp_path / "c.db")
    img = photo_of(small_db, "car", 37, 22, tmp_path / "q.png")
    code, _, err = run(capsys, "query", img, "--client", tmp_path / "c.db", "--server", url,
                       *(["--token", token] if token else []))
    assert code == 1 and problem in one_line_error(err)


def test_serve_refuses_a_token_no_client_could_send(small_db):
    try:
        done = cli("serve", "--db", small_db, "--port", 0, "--token", "pässword", timeout=90)
    except subprocess.TimeoutExpired:
        pytest.fail("the server started with a token no client can send")
    assert done.returncode == 1 and "printable ASCII" in one_line_error(done.stderr)


def test_demo_and_export_name_an_output_they_cannot_use(small_db, tmp_path, capsys):
    (tmp_path / "taken").write_text("a file, not a folder")
    code, _, err = run(capsys, "demo", "--out", tmp_path / "taken")
    assert code == 1 and "cannot be made a folder" in one_line_error(err)
    code, _, err = run(capsys, "export-client", "--db", small_db, "--out", tmp_path / "nowhere" / "c.db")
    assert code == 1 and one_line_error(err).endswith("nowhere/c.db: its folder does not exist")
