"""Fuzz of the CLI's numeric options and arguments: whatever number (or non-number) is
given, ``viewdb`` answers, exits 1 with one line naming the problem, or exits 2 with a
usage error; never a traceback, never an escaped exception, and an option refused leaves
no file behind.

The commands run in one child process (:class:`CliRunner`) with bounded memory, so a
guard that fails (a grid gap of 1e-9 asks for 1.3e23 views) cannot take the machine
down with it; each example has a time limit too.
"""

from __future__ import annotations

import itertools
import json
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import viewdb
from tests.conftest import ROOT, sample

#: The child runs ``viewdb_cli.main.main(argv)`` for each JSON line it reads and answers
#: with the exit code, what it printed, and the traceback of anything that escaped.
RUNNER = textwrap.dedent("""
    import contextlib, io, json, sys, traceback
    from viewdb_cli.main import main
    for line in sys.stdin:
        argv = json.loads(line)
        out, err, escaped = io.StringIO(), io.StringIO(), None
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except BaseException:
                code, escaped = None, traceback.format_exc()
        print(json.dumps({"code": code, "out": out.getvalue()[-4000:], "err": err.getvalue()[-4000:],
                          "escaped": escaped}), flush=True)
""")


class CliRunner:
    """One long-lived child running CLI commands, with at most ``memory_gb`` of address
    space."""

    def __init__(self, memory_gb: float = 10.0) -> None:
        def limit() -> None:
            size = int(memory_gb * 2**30)
            resource.setrlimit(resource.RLIMIT_AS, (size, size))

        self.proc = subprocess.Popen([sys.executable, "-c", RUNNER], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     cwd=ROOT, preexec_fn=limit)

    def __call__(self, argv: list[str], timeout: float = 120.0) -> dict:
        assert self.proc.poll() is None, f"the CLI child died: {self.proc.stderr.read()[-3000:]}"
        self.proc.stdin.write(json.dumps(argv) + "\n")
        self.proc.stdin.flush()
        import selectors

        with selectors.DefaultSelector() as sel:
            sel.register(self.proc.stdout, selectors.EVENT_READ)
            if not sel.select(timeout):
                self.proc.kill()
                pytest.fail(f"viewdb {' '.join(argv)} took more than {timeout:g} s")
        line = self.proc.stdout.readline()
        if not line:
            self.proc.wait()
            pytest.fail(f"viewdb {' '.join(argv)} killed the CLI child (exit {self.proc.returncode}): "
                        f"{self.proc.stderr.read()[-3000:]}")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.stdin.close()
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        for pipe in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
            pipe.close()


@pytest.fixture(scope="module")
def runner():
    r = CliRunner()
    yield r
    r.close()


@pytest.fixture(scope="module")
def place(small_db, tmp_path_factory):
    """A folder with the small db, a client file, a photo of the car, a label map, an
    empty models folder."""
    folder = tmp_path_factory.mktemp("fuzzcli")
    with viewdb.open(small_db, read_only=True) as db:
        view = db.render("car", 37, 22)
        db.export_client(folder / "client.db")
    image = np.full(view.color.shape, 200, np.uint8)
    image[view.mask] = view.color[view.mask]
    cv2.imwrite(str(folder / "q.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    cv2.imwrite(str(folder / "labels.png"), view.mask.astype(np.uint8) * 3)
    (folder / "models").mkdir()
    return {"db": small_db, "folder": folder, "client": folder / "client.db"}


#: What a user might type where a number goes.
FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["nan", "-nan", "inf", "-inf", "1e-9", "1e308", "1e999", "-0", "5e-324", "0", "1", "2",
                     "10", "30", "45", "60", "90", "180", "360", "7", "0.5", "1_0", "0x10", "", " ", "1e",
                     "١", "3,4", "--1"]),
    st.integers(-10**30, 10**30).map(str),
)
INTS = st.one_of(st.integers(-10**25, 10**25).map(str), st.integers(-3, 130).map(str),
                 st.sampled_from(["nan", "1.5", "1e3", "", "0x1f", "99999999999999999999999"]))
DISTANCES = st.one_of(st.lists(FLOATS, min_size=1, max_size=4).map(",".join),
                      st.sampled_from(["none", "3,4,6", "3,3", "1", "1000", "1000.0001", "inf", "nan"]))
INTRINSICS = st.one_of(st.lists(FLOATS, min_size=4, max_size=4).map(",".join),
                       st.tuples(*[st.sampled_from(["1", "100", "500", "1e7", "64", "-1e7", "0.999"])] * 4)
                       .map(",".join), st.lists(FLOATS, max_size=6).map(",".join))


def _options(draw, spec: dict[str, st.SearchStrategy]) -> list[str]:
    chosen = draw(st.lists(st.sampled_from(sorted(spec)), min_size=1, max_size=3, unique=True))
    out = []
    for name in chosen:
        out.append(f"{name}={draw(spec[name])}")  # the '=' form: values like "-1" stay values
    return out


_SERIAL = itertools.count()


@st.composite
def commands(draw, place: dict) -> tuple[list[str], Path | None]:
    """``(argv, file that must not exist if the options are refused)``."""
    folder = place["folder"]
    kind = draw(st.sampled_from(["ingest", "render", "query", "export-client", "serve", "bench"]))
    n = next(_SERIAL)  # a fresh output path for every example
    if kind == "ingest":
        target = folder / f"i{n}.db"
        options = _options(draw, {"--gap": FLOATS, "--image-size": INTS, "--client-gap": FLOATS,
                                  "--perspective": DISTANCES, "--jobs": INTS, "--max-faces": INTS})
        return ["ingest", str(folder / "missing.off"), "--db", str(target), *options], target
    if kind == "render":
        target = folder / f"r{n}.png"
        options = _options(draw, {"--azimuth": FLOATS, "--elevation": FLOATS, "--image-size": INTS})
        given = {o.split("=")[0] for o in options}
        base = [f"--{a}=0" for a in ("azimuth", "elevation") if f"--{a}" not in given]
        if draw(st.booleans()):
            return ["render", "car", "--db", str(place["db"]), "--out", str(target), *base, *options], target
        return ["render", str(sample("cone")), "--out", str(target), *base, *options], target
    if kind == "query":
        spec = {"-k": INTS, "--rotations": INTS, "--band": INTS, "--pose-top": INTS,
                "--intrinsics": INTRINSICS, "--label": INTS, "--timeout": FLOATS}
        options = _options(draw, spec)
        if any(o.startswith("--label=") for o in options):
            options.append(f"--label-map={folder / 'labels.png'}")
        if any(o.startswith("--timeout=") for o in options):  # with --server: one that is not there
            return ["query", str(folder / "q.png"), "--client", str(place["client"]),
                    "--server", "http://127.0.0.1:9", *options], None
        return ["query", str(folder / "q.png"), "--db", str(place["db"]), "--no-colour", "--no-verify",
                *options], None
    if kind == "export-client":
        target = folder / f"c{n}.db"
        return ["export-client", "--db", str(place["db"]), "--out", str(target),
                *_options(draw, {"--gap": FLOATS})], target
    if kind == "serve":  # a database that is not there: every check of the options, no server
        options = _options(draw, {"--port": INTS, "--workers": INTS, "--max-body": INTS,
                                  "--max-image-body": INTS, "--header-timeout": FLOATS,
                                  "--body-timeout": FLOATS})
        return ["serve", "--db", str(folder / "absent.db"), *options], None
    target = folder / f"b{n}"
    options = _options(draw, {"--queries": INTS, "--seed": INTS, "--gaps": DISTANCES, "-k": INTS,
                              "--jobs": INTS, "--subset": INTS, "--gap": FLOATS, "--client-gap": FLOATS,
                              "--image-size": INTS})
    return ["bench", str(folder / "models"), "--out", str(target), *options], target


def check(result: dict, argv: list[str], target: Path | None) -> None:
    shown = " ".join(argv)
    assert result["escaped"] is None, f"viewdb {shown} raised:\n{result['escaped']}"
    assert result["code"] in (0, 1, 2), (shown, result)
    text = result["out"] + result["err"]
    assert "Traceback" not in text, (shown, text)
    event(f"{argv[0]} exit {result['code']}")
    if result["code"] == 1:
        lines = [line for line in result["err"].splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("viewdb: "), (shown, result["err"])
    if result["code"] == 2 and target is not None:
        assert not target.exists(), f"viewdb {shown} was refused but left {target}"


CLI_FUZZ = settings(max_examples=60, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                           HealthCheck.too_slow])


@CLI_FUZZ
@given(data=st.data())
def test_fuzz_numeric_options_exit_cleanly(runner, place, data):
    argv, target = data.draw(commands(place))
    check(runner(argv), argv, target)


@pytest.mark.slow
@settings(CLI_FUZZ, max_examples=1000)
@given(data=st.data())
def test_fuzz_numeric_options_long(runner, place, data):
    argv, target = data.draw(commands(place))
    check(runner(argv), argv, target)


def test_the_harness_sees_what_escapes(runner, tmp_path):
    """The checks can fail: ``--debug`` lets the error of a missing db escape as a
    traceback, which the runner reports; without it, one line and exit 1."""
    missing = str(tmp_path / "none.db")
    result = runner(["info", "--db", missing])
    assert result["code"] == 1 and result["err"].startswith("viewdb: ") and result["escaped"] is None
    result = runner(["--debug", "info", "--db", missing])
    assert result["escaped"] is not None and "StorageError" in result["escaped"]
    with pytest.raises(AssertionError, match="raised"):
        check(result, ["--debug", "info"], None)
