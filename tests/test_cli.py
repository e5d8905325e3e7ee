"""The CLI as users meet it: exit codes, one-line errors, JSON shape, docs."""

import json
import re
import subprocess

import cv2
import pytest
import typer
from typer.testing import CliRunner

import viewdb
from tests.conftest import ROOT, sample
from viewdb.config import SearchConfig
from viewdb_cli.main import app, main

COMMANDS = sorted(typer.main.get_command(app).commands)


def run(capsys, *args):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_ingest_info_render_round_trip(tmp_path, capsys):
    db = tmp_path / "cli.db"
    code, out, err = run(capsys, "ingest", sample("cone"), sample("pyramid"), "--db", db,
                         "--gap", 90, "--image-size", 64)
    assert code == 0, err
    assert "2 added" in out
    code, out, _ = run(capsys, "ingest", sample("cone"), "--db", db, "--json")
    assert code == 0 and json.loads(out)["unchanged"] == 1
    code, out, _ = run(capsys, "info", "--db", db, "--json")
    data = json.loads(out)
    assert code == 0
    assert {o["name"] for o in data["objects"]} == {"cone", "pyramid"}
    for o in data["objects"]:
        assert o["views_grid"] == 16 and 0 < o["views_stored"] < 16 and o["skimmed"]
        assert o["h_type"] in ("H1", "H2", "H3", "H4") and o["v_type"] in ("V1", "V2", "V3", "V4")
    assert next(o for o in data["objects"] if o["name"] == "cone")["h_type"] == "H1"
    code, out, _ = run(capsys, "ingest", sample("cone"), "--db", tmp_path / "full.db", "--gap", 90,
                       "--image-size", 64, "--no-skim", "--json")
    assert code == 0 and json.loads(out)["views"] == 16
    assert data["schema_version"] and data["file_bytes"] > 0
    png = tmp_path / "cone.png"
    code, _, err = run(capsys, "render", "cone", "--azimuth", 30, "--elevation", 10, "--db", db, "--out", png)
    assert code == 0, err
    assert cv2.imread(str(png)).shape == (64, 64, 3)


def test_render_a_mesh_file_without_db(tmp_path, capsys):
    png = tmp_path / "m.png"
    code, _, err = run(capsys, "render", sample("mug"), "--azimuth", 0, "--elevation", 0, "--out", png,
                       "--image-size", 96, "--what", "mask")
    assert code == 0, err
    assert cv2.imread(str(png), cv2.IMREAD_GRAYSCALE).max() == 255


def test_a_failed_file_exits_1_with_one_line_naming_it(tmp_path, capsys):
    bad = tmp_path / "bad.stl"
    bad.write_bytes(b"nonsense")
    code, out, err = run(capsys, "ingest", bad, sample("cone"), "--db", tmp_path / "x.db", "--gap", 90,
                         "--image-size", 64)
    assert code == 1
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and str(bad) in lines[0] and lines[0].startswith("viewdb: ")
    assert "1 added" in out


@pytest.mark.parametrize("content", [b"", b"random bytes " * 50])
def test_corrupt_db_exits_1_with_one_line(tmp_path, capsys, content):
    db = tmp_path / "corrupt.db"
    db.write_bytes(content)
    code, out, err = run(capsys, "info", "--db", db)
    assert code == 1
    assert len(err.strip().splitlines()) == 1 and str(db) in err and "Traceback" not in err


def test_usage_errors_exit_2(capsys):
    assert run(capsys, "ingest")[0] == 2
    assert run(capsys, "no-such-command")[0] == 2
    assert run(capsys, "render", "x", "--azimuth", "north", "--elevation", 0, "--out", "a.png")[0] == 2


@pytest.mark.parametrize("value", ["two", "0", "-1"])
def test_a_bad_search_threads_variable_is_a_usage_error(tmp_path, capsys, monkeypatch, value):
    monkeypatch.setenv("VIEWDB_SEARCH_THREADS", value)
    code, out, err = run(capsys, "info", "--db", tmp_path / "nope.db")
    assert code == 2 and "VIEWDB_SEARCH_THREADS" in err and "Traceback" not in err


def test_the_search_threads_variable_sets_the_default(monkeypatch):
    monkeypatch.setenv("VIEWDB_SEARCH_THREADS", "3")
    assert SearchConfig().threads == 3
    monkeypatch.delenv("VIEWDB_SEARCH_THREADS")
    assert SearchConfig().threads == 2


def test_console_script_is_installed_and_reports_errors(tmp_path):
    db = tmp_path / "nope.db"
    proc = subprocess.run(["viewdb", "info", "--db", str(db)], capture_output=True, text=True)
    assert proc.returncode == 1
    assert proc.stderr.strip() == f"viewdb: {db}: no such database"


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_has_help_and_is_in_the_readme(command):
    result = CliRunner().invoke(app, [command, "--help"])
    assert result.exit_code == 0 and "Usage" in result.output
    readme = (ROOT / "README.md").read_text()
    assert re.search(rf"viewdb {command}\b", readme), f"README does not document `viewdb {command}`"


def test_export_client_writes_a_small_checked_file(tmp_path, small_db, capsys):
    out = tmp_path / "client.db"
    assert main(["export-client", "--db", str(small_db), "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(["check", "--db", str(out)]) == 0
    capsys.readouterr()
    assert main(["export-client", "--db", str(small_db), "--out", str(out)]) == 1  # exists
    assert capsys.readouterr().err.strip().endswith("already exists; remove it or choose another --out")
    assert main(["export-client", "--db", str(small_db), "--out", str(tmp_path / "x.db"), "--gap", "45"]) == 1
    assert not (tmp_path / "x.db").exists()
    assert main(["ingest", str(sample("cone")), "--db", str(out)]) == 1  # a client file takes no ingest


def test_a_mesh_over_max_faces_fails_alone_and_nothing_stored_is_lost(tmp_path, capsys):
    db = tmp_path / "x.db"
    assert run(capsys, "ingest", sample("cone"), "--db", db, "--gap", 90, "--image-size", 64)[0] == 0
    code, out, err = run(capsys, "ingest", sample("torus"), sample("cube_dice"), "--db", db,
                         "--max-faces", 200)
    assert code == 1
    lines = [line for line in err.splitlines() if line.strip()]
    assert any(str(sample("torus")) in line and "more than the cap of 200" in line for line in lines)
    with viewdb.open(db, create=False) as vdb:
        names = {o.name for o in vdb.objects()}
    assert "cone" in names and "torus" not in names  # the earlier object is untouched


def test_missing_textures_refused_unless_allowed(tmp_path, capsys):
    obj = tmp_path / "skinned.obj"
    obj.write_text("mtllib skinned.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\nvt 1 0\nvt 0 1\n"
                   "usemtl a\nf 1/1 2/2 3/3\nf 1/1 2/2 4/3\nf 2/1 3/2 4/3\nf 1/1 3/2 4/3\n")
    (tmp_path / "skinned.mtl").write_text("newmtl a\nmap_Kd gone.jpg\n")
    db = tmp_path / "x.db"
    code, _, err = run(capsys, "ingest", obj, "--db", db, "--gap", 90, "--image-size", 64)
    assert code == 1 and "gone.jpg" in err and str(obj) in err
    code, out, _ = run(capsys, "ingest", obj, "--db", db, "--allow-missing-textures")
    assert code == 0 and "1 added" in out


def _script(*args, **kwargs):
    """The ``viewdb`` console script in a fresh process, as a user runs it."""
    import sys

    return subprocess.run([sys.executable, "-c", "from viewdb_cli.main import run; run()", *map(str, args)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT, **kwargs)


def test_the_console_script_exits_with_the_command_s_code_and_all_its_output(small_db, tmp_path):
    """The script ends the process without the interpreter's teardown: the exit code, the
    whole output and the one-line errors are still what ``main`` gives."""
    ok = _script("info", "--db", small_db, "--json")
    assert ok.returncode == 0, ok.stderr
    assert len(json.loads(ok.stdout)["objects"]) == 4
    missing = _script("info", "--db", tmp_path / "missing.db")
    assert missing.returncode == 1 and missing.stdout == ""
    assert missing.stderr.strip().count("\n") == 0 and "missing.db" in missing.stderr
    assert _script().returncode == 2
    assert _script("query", "--bogus-option").returncode == 2


def test_exit_now_runs_the_exit_handlers_and_flushes_the_streams(tmp_path):
    import sys

    flag = tmp_path / "handler-ran"
    program = (f"import atexit, sys\nfrom viewdb_cli.main import exit_now\n"
               f"atexit.register(lambda: open({str(flag)!r}, 'w').write('ran'))\n"
               f"sys.stdout.write('x' * 100000)\nsys.stderr.write('y' * 5000)\nexit_now(3)\n")
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, timeout=120)
    assert done.returncode == 3
    assert done.stdout == "x" * 100000 and done.stderr == "y" * 5000
    assert flag.read_text() == "ran"


def _raised_messages() -> list[tuple[str, str]]:
    """``(where, text)`` of every string in a ``raise`` statement of the library."""
    import ast

    found = []
    for path in sorted((ROOT / "viewdb").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Raise) and node.exc is not None:
                found += [(f"{path.relative_to(ROOT)}:{sub.lineno}", sub.value) for sub in ast.walk(node.exc)
                          if isinstance(sub, ast.Constant) and isinstance(sub.value, str)]
    return found


def test_library_errors_name_python_parameters_not_flags():
    messages = _raised_messages()
    assert any("`gap`" in text for _, text in messages)  # the scan sees the messages
    flags = [f"{where}: {text!r}" for where, text in messages if re.search(r"(?<![\w-])--[a-z]", text)]
    assert not flags, "library errors naming a command line flag:\n" + "\n".join(flags)


def test_the_cli_has_a_flag_for_every_parameter_a_library_error_names():
    from viewdb_cli.main import PARAMETER_FLAGS, as_flags

    named = {name for _, text in _raised_messages() for name in re.findall(r"`\w+`", text)}
    missing = {name for name in named if not any(name in form for form in PARAMETER_FLAGS)}
    assert not missing, f"no flag for {sorted(missing)} in viewdb_cli.main.PARAMETER_FLAGS"
    assert as_flags("was built with `gap` 10, not 30") == "was built with --gap 10, not 30"
    assert as_flags("ingest with `allow_missing_textures`=True") == "ingest with --allow-missing-textures"


def test_a_setting_the_file_was_not_built_with_is_named_as_a_parameter_or_a_flag(tmp_path, capsys):
    db = tmp_path / "g.db"
    assert run(capsys, "ingest", sample("cone"), "--db", db, "--gap", 90, "--image-size", 64)[0] == 0
    with pytest.raises(viewdb.ViewDBError, match=r"was built with `gap` 90, not 45"):
        viewdb.open(db, gap=45)
    code, _, err = run(capsys, "ingest", sample("cone"), "--db", db, "--gap", 45)
    assert code == 1 and "was built with --gap 90, not 45" in err and "`" not in err
