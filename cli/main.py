"""``viewdb`` commands. Each opens the database, calls one library method and prints.

Exit codes (public contract): 0 success; 1 a reported error (bad input, failed check);
2 usage error; 130 interrupted. Errors are one line on stderr, ``viewdb: <file>: <problem>``;
``viewdb --debug ...`` shows the traceback instead.
"""

from __future__ import annotations

import json
import math
import re
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TextColumn,
    TimeRemainingColumn,
)
from rich.table import Table
from rich.text import Text

import viewdb
import viewdb.config as viewdb_config
from viewdb.typed import Intrinsics

LIMITS = viewdb_config.LIMITS

app = typer.Typer(
    name="viewdb",
    help="An embedded view database: recognise which known 3-D object a photo shows, and from where.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # plain help: rich's formatter imports rich.markdown and more, a third of --help's time
    rich_markup_mode=None,
)
out = Console(highlight=False, soft_wrap=True)
err = Console(stderr=True, highlight=False, soft_wrap=True)
_STATE = {"debug": False}

SAMPLE_MODELS = Path(__file__).resolve().parent.parent / "sample_models"


@app.callback()
def _main(
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks for errors.")] = False,
) -> None:
    _STATE["debug"] = debug
    try:  # the environment's search threads, checked before any command searches
        viewdb_config.search_threads_from_env()
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="VIEWDB_SEARCH_THREADS") from None


class _ViewsPerSecond(ProgressColumn):
    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        return Text("" if speed is None else f"{speed:5.1f} views/s")


def _progress() -> Progress:
    return Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        _ViewsPerSecond(), TimeRemainingColumn(), console=err,
        disable=not err.is_terminal, transient=False,
    )


def _echo_json(data: Any) -> None:
    sys.stdout.write(json.dumps(data, indent=2) + "\n")  # ensure_ascii: control characters escaped


#: Characters that would act on a terminal instead of showing: C0 and C1 controls (ESC
#: among them), DEL, and the bidirectional overrides that reorder what is shown.
_CONTROL = re.compile("[\x00-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")


def _shown(value: object) -> str:
    """``str(value)`` with every control character written as an escape (``\\x1b``), so
    an object name (a file stem) or a path cannot move the cursor, clear the screen or
    retitle the terminal."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}" if ord(m.group()) < 256
                        else f"\\u{ord(m.group()):04x}", str(value))


def _say(text: str, console: Console | None = None) -> None:
    """One line of output, its control characters escaped, never read as markup."""
    (console or out).print(_shown(text), markup=False)


def _table(columns: list[str], rows: list[list[str]]) -> None:
    """A table: drawn by rich on a terminal wide enough for every whole value; otherwise
    (a pipe, a file, a narrow terminal) as plain columns of whole values, never cut to
    "obje…"."""
    cells = [[_shown(c) for c in row] for row in rows]
    widths = [max([len(h), *(len(r[i]) for r in cells)]) for i, h in enumerate(columns)]
    if out.is_terminal and sum(widths) + 3 * len(widths) + 1 <= out.width:
        table = Table(*columns)
        for column, width in zip(table.columns, widths, strict=True):
            column.min_width, column.overflow = width, "fold"
        for row in cells:
            table.add_row(*(Text(c) for c in row))
        out.print(table)
        return
    for row in [columns, *cells]:
        sys.stdout.write("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() + "\n")
    sys.stdout.flush()


def _number(low: float | None = None, high: float | None = None) -> Any:
    """A typer callback refusing a float option that is not finite or not in [low, high]
    (click's ranges let NaN through) as a usage error."""
    def check(ctx: typer.Context, param: typer.CallbackParam, value: float | None) -> float | None:
        if value is None or ctx.resilient_parsing:
            return value
        try:
            return viewdb_config.finite(value, "value", -math.inf if low is None else low,
                                        math.inf if high is None else high)
        except ValueError as exc:
            raise typer.BadParameter(str(exc).removeprefix("value ")) from None
    return check


DbOption = Annotated[Path, typer.Option("--db", help="Database file.", dir_okay=False)]


def _parse_distances(text: str) -> tuple[float, ...]:
    if text.strip().lower() == "none":
        return ()
    try:
        values = tuple(float(x) for x in text.split(","))
        viewdb_config.PerspectiveConfig(distances=values)  # the library's own check
    except ValueError as exc:
        raise typer.BadParameter(str(exc) if "perspective" in str(exc) else
                                 f"expected numbers separated by commas or 'none', got {text!r}",
                                 param_hint="--perspective") from None
    return values


GAP_RANGE = (LIMITS.min_gap, 180.0)
SIZE_RANGE = {"min": LIMITS.min_image_size, "max": LIMITS.max_image_size}


@app.command()
def ingest(
    paths: Annotated[
        list[Path], typer.Argument(help="Mesh files (OBJ, PLY, STL, OFF, GLB, glTF) or folders.")
    ],
    db: Annotated[Path | None, typer.Option("--db", help="Database file (created if missing).",
                                            dir_okay=False)] = None,
    shards: Annotated[Path | None, typer.Option(
        "--shards", help="Ingest into a sharded catalogue instead of --db: each object goes to the "
                         "shard file blake2b(name) mod N of this folder (viewdb shard --out).",
        file_okay=False)] = None,
    shard_count: Annotated[int | None, typer.Option(
        "--shard-count", help="With --shards: the number of shard files of a new sharded catalogue.",
        min=1, max=4096)] = None,
    gap: Annotated[float | None, typer.Option(help="Grid gap in degrees (new db; default 10).",
                                              callback=_number(*GAP_RANGE))] = None,
    image_size: Annotated[int | None, typer.Option(help="View size in pixels (new db; default 256).",
                                                   **SIZE_RANGE)] = None,
    client_gap: Annotated[
        float | None,
        typer.Option(help="Sparse (client) tier grid gap, a multiple of --gap (new db; default 30).",
                     callback=_number(*GAP_RANGE)),
    ] = None,
    perspective: Annotated[
        str | None,
        typer.Option(help="Perspective views' camera distances in bounding radii, e.g. 3,4,6, "
                          "or 'none' (new db; default 2,3,4,6)."),
    ] = None,
    perspective_gap: Annotated[
        float | None,
        typer.Option("--perspective-gap",
                     help="Perspective views' grid gap in degrees, rounded up to a multiple of --gap "
                          "(new db; default 10). A finer grid follows close-up outlines more closely, "
                          "for more ingest time and file (docs/results/latency.md).",
                     callback=_number(*GAP_RANGE)),
    ] = None,
    jobs: Annotated[int, typer.Option(help="Worker processes.", min=1, max=LIMITS.max_jobs)] = 1,
    ray: Annotated[str | None, typer.Option(
        "--ray", help="Describe the objects as Ray tasks across a cluster instead of --jobs "
                      "processes: 'auto' (the Ray on this machine, or a new local one) or HOST:PORT "
                      "of a head node (ray start --head). This process still writes every object.")
    ] = None,
    no_skim: Annotated[
        bool, typer.Option("--no-skim", help="Store the whole grid, not just the skim plan's views.")
    ] = False,
    max_faces: Annotated[
        int, typer.Option(help="Refuse meshes with more triangles (0 = no cap).", min=0)
    ] = viewdb_config.DEFAULT_MAX_FACES,
    allow_missing_textures: Annotated[
        bool, typer.Option("--allow-missing-textures",
                           help="Ingest meshes whose texture files are missing, untextured.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the report as JSON.")] = False,
) -> None:
    """Add meshes; an object is named after its file's stem. Re-running is a no-op.

    Each object's symmetry type is found from its silhouettes, and only the views that
    are not the same as (or the mirror of) a stored one are rendered and kept, unless
    --no-skim.
    """
    if (db is None) == (shards is None):
        raise typer.BadParameter("give either --db FILE or --shards DIR", param_hint="--db")
    if shard_count is not None and shards is None:
        raise typer.BadParameter("--shard-count needs --shards", param_hint="--shard-count")
    files = viewdb.describe_paths(paths)
    distances = None if perspective is None else _parse_distances(perspective)
    settings = {"gap": gap, "image_size": image_size, "client_gap": client_gap, "perspective": distances,
                "perspective_gap": perspective_gap}
    if shards is not None:
        from viewdb.shards.writing import open_shards

        target: Any = open_shards(shards, count=shard_count, **settings)
    else:
        target = viewdb.open(db, **settings)  # type: ignore[arg-type]
    with target, _progress() as bar:
        task = bar.add_task("ingest", total=None)

        def on_progress(p: viewdb.IngestProgress) -> None:
            rate = f", {p.objects_per_second:.2f} objects/s" if p.written else ""
            bar.update(task, total=p.views_total, completed=p.views_done,
                       description=f"ingest {p.files_done}/{p.files_total} files{rate}")
            if p.outcome is not None and p.outcome.status == "failed":
                _say(f"viewdb: {as_flags(str(p.outcome.error))}", err)

        def on_look(done: int, total: int) -> None:
            bar.update(task, total=total, completed=done, description="fitting the look model")

        report = target.ingest(files, jobs=jobs, skim=not no_skim, progress=on_progress,
                               max_faces=max_faces or None,
                               allow_missing_textures=allow_missing_textures, ray=ray, look_progress=on_look)
    _print_ingest(report, as_json)


def _print_ingest(report: viewdb.IngestReport, as_json: bool) -> None:
    counts = report.counts()
    if as_json:
        _echo_json({
            **counts, "views": report.views_rendered, "seconds": round(report.seconds, 3),
            "views_per_second": round(report.views_per_second, 2),
            "files": [o.__dict__ for o in report.outcomes],
        })
    else:
        out.print(
            f"{counts['added']} added, {counts['replaced']} replaced, "
            f"{counts['unchanged']} unchanged, "
            + (f"{counts['upgraded']} upgraded (perspective views or appearance added), "
               if counts["upgraded"] else "")
            + f"{counts['failed']} failed; "
            f"{report.views_rendered} views in {report.seconds:.1f} s "
            f"({report.views_per_second:.1f} views/s)"
        )
    if report.failed:
        raise typer.Exit(1)


def _open_read(db: Path) -> viewdb.ViewDB:
    """Open a database for a command that only reads it: read-only, so a file on read-only
    storage (a prebuilt file shipped to a device) works and nothing is written; only a
    file whose schema is too old to read as it is gets opened normally, which upgrades it
    in place (as any open did before), when its storage allows."""
    try:
        return viewdb.open(db, read_only=True)
    except viewdb.UpgradeNeeded as too_old:
        try:
            return viewdb.open(db, create=False)
        except viewdb.StorageError:
            raise too_old from None


@app.command()
def info(
    db: DbOption,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Objects, views, file size and schema version of a database."""
    with _open_read(db) as vdb:
        data = vdb.info()
    if as_json:
        _echo_json(data.to_dict())
        return
    _say(
        f"{data.path}: {len(data.objects)} objects, {data.rows['views']} views, "
        f"{data.file_bytes / 1e6:.1f} MB, schema {data.schema_revision}, "
        f"grid gap {data.config.gap:g}°, {data.config.render.image_size} px"
    )
    curves = "quantised (compact client file)" if data.curve_storage == "quantised" else "float32"
    out.print(f"  size: {data.bytes_per_view:.0f} bytes per view, {data.bytes_per_object / 1e3:.1f} kB per "
              f"object; curves {curves}")
    distances = data.config.perspective.distances
    stored = data.rows.get("perspective_views", 0)
    lacking = sum(1 for o in data.objects if o.perspective_views == 0)
    out.print(f"  perspective views: {stored}"
              + (f" ({data.config.perspective_gap:g}° {data.config.perspective.grid} grid from "
                 f"{', '.join(f'{d:g}' for d in distances)} bounding radii)" if distances else " (none)")
              + (f"; {lacking} objects have none yet: ingest their files again to add them"
                 if distances and lacking else ""))
    if data.rows.get("sift_features", 0):  # a full file (a client file has no appearance)
        without = sum(1 for o in data.objects if o.appearances == 0 and o.views_stored)
        from viewdb.camera import grid_views

        directions = len(grid_views(data.config.gap)) // 2  # a view and its turned twin share one
        partial = sum(1 for o in data.objects if 0 < o.appearances < directions) \
            if data.config.appearance.every_view else 0
        out.print(f"  appearance records: {data.rows.get('appearances', 0)}"
                  + (f"; {without} objects have none yet (queries render their views): ingest "
                     "their files again to add them" if without else "")
                  + (f"; {partial} objects lack those of some views (queries render them): ingest "
                     "their files again to add them" if partial else ""))
    if data.rows.get("sift_features", 0):
        look = data.look
        out.print("  look model: " + ("none: `viewdb ingest` fits it (with two coloured objects or more)"
                                      if look is None else f"{look['objects']} coloured objects"
                                      + (", shared by every shard" if look["shared"] else "")))
    for tier, t in data.tiers.items():
        out.print(f"  {tier} tier: {t['gap']:g}° grid, {t['views']} views in {t['groups']} R-tree "
                  f"entries ({t['rtree_bytes'] / 1e3:.0f} kB of R-tree pages)")
    rows = []
    for o in data.objects:
        sym = o.symmetry
        kind = f"{sym.h_type}/{sym.v_type}" if sym else "-"
        periods = f"{sym.h_period:g}/{sym.v_period:g}" if sym else "-"
        rows.append([o.name, str(o.n_faces), kind, periods, str(o.views_stored),
                     str(o.views_grid), str(o.empty_views), str(o.perspective_views),
                     f"{o.ingest_seconds:.1f}"])
    if rows:
        _table(["object", "faces", "type", "periods", "views", "grid", "no silhouette",
                "perspective", "ingest s"], rows)


@app.command()
def warm() -> None:
    """Compile the search kernels now, not in the first query (numba keeps them): a
    throw-away catalogue is built and queried with every plan (needs viewdb[ingest])."""
    from viewdb.warm import compiling, warm_up

    _say("viewdb warm: compiling the search kernels (a minute or more, once per install)", err)
    heard: list[str] = []

    def on_compile(kernel: str) -> None:
        heard.append(kernel)
        _say(f"viewdb warm: compiling {len(heard)}: {kernel}", err)

    with compiling(on_compile):
        report = warm_up(progress=lambda step: _say(f"viewdb warm: {step}", err))
    _say(f"search kernels ready ({report.compiled} compiled, {report.cached} from the cache)")


@app.command()
def check(db: DbOption) -> None:
    """Verify a database: schema version, SQLite integrity, rows and blobs. Exit 0 or 1."""
    with _open_read(db) as vdb:
        report = vdb.check()
    counts = ", ".join(f"{n} {what}" for what, n in report.checked.items())
    if report.ok:
        _say(f"{db}: ok ({counts})")
        return
    for problem in report.problems:
        _say(f"{db}: {problem}")
    if report.more_problems:
        _say(f"{db}: ... and {report.more_problems} more problems")
    _say(f"{db}: FAILED ({len(report.problems) + report.more_problems} problems; checked {counts})")
    raise typer.Exit(1)


@app.command()
def render(
    model_or_object: Annotated[str, typer.Argument(help="A mesh file, or an object name with --db.")],
    azimuth: Annotated[float, typer.Option(help="Azimuth h in degrees.", callback=_number())],
    elevation: Annotated[float, typer.Option(help="Elevation v in degrees.", callback=_number())],
    out_path: Annotated[Path, typer.Option("--out", help="Image to write (.png; depth: .png or .tif).",
                                           dir_okay=False)],
    db: Annotated[Path | None, typer.Option("--db", help="Render a stored object.")] = None,
    image_size: Annotated[int, typer.Option(help="Size in pixels (mesh files only).", **SIZE_RANGE)] = 256,
    what: Annotated[str, typer.Option(help="color, mask or depth.")] = "color",
) -> None:
    """Render one view in the documented camera convention."""
    from viewdb.catalogue.snapshot import KINDS, check_output, write_view

    if what not in KINDS:
        raise typer.BadParameter("must be color, mask or depth", param_hint="--what")
    check_output(out_path, what)  # before the render: an unwritable type is refused at once
    if db is not None:
        with _open_read(db) as vdb:
            view = vdb.render(model_or_object, azimuth, elevation)
    else:
        view = viewdb.render_model(model_or_object, azimuth, elevation, image_size=image_size)
    write_view(view, out_path, what)
    _say(f"wrote {out_path}")


def _intrinsics(text: str | None) -> Intrinsics | None:
    if text is None:
        return None
    if Path(text).suffix.lower() in (".json", ".yaml", ".yml") or Path(text).is_file():
        return viewdb.parse_intrinsics(Path(text))  # a bad file is a reported error (exit 1)
    try:
        values = tuple(float(x) for x in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4:
        raise typer.BadParameter("must be fx,fy,cx,cy (four numbers) or a JSON/YAML file",
                                 param_hint="--intrinsics")
    return viewdb.parse_intrinsics(",".join(str(v) for v in values))


@app.command()
def query(
    image: Annotated[Path, typer.Argument(help="Query photo (PNG, JPEG, ...).", dir_okay=False)],
    db: Annotated[
        Path | None, typer.Option("--db", help="Full database file (or --client with --server).",
                                  dir_okay=False)
    ] = None,
    k: Annotated[int, typer.Option("-k", help="How many objects.", min=1, max=100)] = 5,
    plan: Annotated[str, typer.Option(help="fast, server, cs1 or cs2.")] = viewdb_config.DEFAULT_PLAN,
    fast_shortlist: Annotated[int | None, typer.Option(
        help="With --plan fast: objects the approximate index shortlists, each searched exactly "
             "(default 20).", min=1, max=100000)] = None,
    client: Annotated[
        Path | None, typer.Option(help="Client file for the client half of cs1/cs2 (default: --db).",
                                  dir_okay=False)
    ] = None,
    mask: Annotated[
        Path | None, typer.Option(help="Object mask image (non-zero = object).", dir_okay=False)
    ] = None,
    rotations: Annotated[
        int, typer.Option(help="In-plane turns of the silhouette tried (1 = upright only).", min=1, max=72)
    ] = 8,
    band: Annotated[int, typer.Option(help="DTW band in curve samples.", min=0, max=64)] = 6,
    roll: Annotated[float | None, typer.Option(
        help="Gravity hint: the camera's roll in degrees (the in-plane turn that makes the photo "
             "upright, e.g. from an IMU); the search then covers only the turns within the "
             "roll tolerance of it, instead of --rotations.", callback=_number(-360, 360))] = None,
    upright: Annotated[bool, typer.Option(
        "--upright", help="The photo is upright (gravity down): --roll 0.")] = False,
    no_pose: Annotated[bool, typer.Option("--no-pose", help="Skip pose estimation.")] = False,
    pose_top: Annotated[int, typer.Option(
        help="Pose the best N results (default: the top one; -k N poses all; 0 = --no-pose).",
        min=0)] = 1,
    intrinsics: Annotated[
        str | None, typer.Option(help="Camera intrinsics: fx,fy,cx,cy or a JSON/YAML file (fx, fy, cx, cy "
                                      "or a 3x3 K); the pose is then in that camera's OpenCV frame, "
                                      "in the mesh's own units.")
    ] = None,
    label_map: Annotated[
        Path | None, typer.Option(help="Label image (one integer label per pixel, 0 = background); "
                                       "with --label picks one object, with --all every labelled one.",
                                  dir_okay=False)
    ] = None,
    label: Annotated[int | None, typer.Option(help="The object's label in --label-map.", min=1)] = None,
    depth: Annotated[Path | None, typer.Option(
        help="With --intrinsics: the photo's depth image, aligned pixel for pixel (16-bit PNG or "
             "TIFF, float TIFF, .npy); it sets each pose's distance.", dir_okay=False)] = None,
    depth_scale: Annotated[float, typer.Option(
        help="One depth unit in the meshes' units (0.001: millimetres against meshes in metres).",
        callback=_number(viewdb_config.LIMITS.min_depth_scale, viewdb_config.LIMITS.max_depth_scale)
    )] = viewdb_config.DEFAULT_DEPTH_SCALE,
    rerank: Annotated[bool, typer.Option(
        "--rerank", help="With --intrinsics: re-rank the k results by the IoU of their perspective "
                         "silhouette fit.")] = False,
    no_colour: Annotated[bool, typer.Option(
        "--no-colour", help="Do not re-rank by colour.")] = False,
    no_verify: Annotated[bool, typer.Option(
        "--no-verify", help="Do not re-rank by how well each result's view fits the photo's shape "
                            "(with --no-colour: rank by outline alone, the paper's way).")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    server: Annotated[
        str | None, typer.Option(help="URL of a viewdb server (viewdb serve); the client half runs "
                                      "on --client, the rest on the server.")
    ] = None,
    token: Annotated[
        str | None, typer.Option(help="Bearer token for --server.", envvar="VIEWDB_TOKEN")
    ] = None,
    timeout: Annotated[float, typer.Option(
        help="With --server: seconds each exchange with the server may take in all (connecting "
             "and each read are bounded by it too).", callback=_number(0.001, 86400))
    ] = viewdb_config.HttpConfig().total_timeout,
    box: Annotated[list[str] | None, typer.Option(
        "--box", help="An object's box x1,y1,x2,y2 in pixels (repeatable: one object each).",
        metavar="X1,Y1,X2,Y2")] = None,
    point: Annotated[list[str] | None, typer.Option(
        "--point", help="A pixel x,y on an object (repeatable: one object each).", metavar="X,Y")] = None,
    every: Annotated[bool, typer.Option(
        "--all", help="Every object that stands out from the background (with --label-map: every "
                      "label).")] = False,
    max_objects: Annotated[int | None, typer.Option(
        help="With --all: at most this many objects, the largest (default 8).", min=1)] = None,
    overlay: Annotated[Path | None, typer.Option(
        help="Write the photo with each object's posed mesh drawn over it (PNG).", dir_okay=False,
        metavar="OUT.png")] = None,
) -> None:
    """Recognise the object a photo shows and estimate its pose.

    Locally on --db (the client half of cs1/cs2 on --client if given), or remotely:
    --client FILE --server URL runs the client half on the client file and calls the
    server for the rest (and the pose). --box, --point (each repeatable) and --all
    recognise several objects of one photo; the JSON then lists them in "objects".
    """
    _check_query_options(plan, fast_shortlist, mask, label_map, label)
    cam = _intrinsics(intrinsics)
    if depth is not None and cam is None:
        raise typer.BadParameter("needs --intrinsics: it sets a perspective pose's distance",
                                 param_hint="--depth")
    if upright and roll is not None:
        raise typer.BadParameter("give --roll DEG or --upright, not both", param_hint="--upright")
    roll = 0.0 if upright else roll
    prompts = _prompts(box, point, every, max_objects, mask, label, label_map)
    if overlay is not None:
        _check_overlay(overlay, server)
    with _announcing_compiles():
        if server is not None:
            if client is None or db is not None:
                raise typer.BadParameter("with --server give --client FILE (and no --db)",
                                         param_hint="--server")
            if rerank:
                raise typer.BadParameter("--rerank needs the meshes: use --db", param_hint="--rerank")
            if depth is not None:
                raise typer.BadParameter("--depth needs the meshes: use --db", param_hint="--depth")
            with _open_read(client) as side, \
                    viewdb.RemoteServer(server, token=token, config=_client_limits(timeout)) as remote:
                result = side.query(image, k=k, plan=plan, server=remote, mask=mask, band=band,
                                    rotations=rotations, pose=not no_pose, intrinsics=cam,
                                    label_map=label_map, label=label, colour=not no_colour,
                                    verify=not no_verify, pose_top=pose_top, roll=roll,
                                    fast_shortlist=fast_shortlist, **prompts)
        elif db is None:
            raise typer.BadParameter("give --db FILE, or --client FILE with --server URL", param_hint="--db")
        else:
            with _open_read(db) as vdb:
                side = _open_read(client) if client is not None else None
                try:
                    result = vdb.query(image, k=k, plan=plan, client=side, mask=mask, band=band,
                                       rotations=rotations, pose=not no_pose, intrinsics=cam,
                                       label_map=label_map, label=label, depth=depth,
                                       depth_scale=depth_scale, rerank=rerank, colour=not no_colour,
                                       verify=not no_verify, pose_top=pose_top, roll=roll,
                                       fast_shortlist=fast_shortlist, **prompts)
                    if overlay is not None:
                        _write_png(overlay, result.overlay())
                finally:
                    if side is not None:
                        side.close()
    if as_json:
        _echo_json(result.to_dict())
        return
    _print_result(result)


def _check_query_options(plan: str, fast_shortlist: int | None, mask: Path | None, label_map: Path | None,
                         label: int | None) -> None:
    """Usage errors of ``viewdb query``'s plan and segmentation options."""
    if plan not in ("server", "cs1", "cs2", "fast"):
        raise typer.BadParameter("must be server, cs1, cs2 or fast", param_hint="--plan")
    if fast_shortlist is not None and plan != "fast":
        raise typer.BadParameter("goes with --plan fast", param_hint="--fast-shortlist")
    if (label_map is None) != (label is None):
        raise typer.BadParameter("--label-map and --label go together", param_hint="--label")
    if label_map is not None and mask is not None:
        raise typer.BadParameter("give --mask or --label-map, not both", param_hint="--mask")


@contextmanager
def _announcing_compiles() -> Iterator[None]:
    """On a terminal, say so when a search kernel compiles (the first query after an
    install, unless ``viewdb warm`` ran): some seconds of CPU per plan, otherwise silent."""
    if not err.is_terminal:
        yield
        return
    from viewdb.warm import compiling

    heard: list[str] = []

    def on_compile(kernel: str) -> None:
        if not heard:
            _say("viewdb: compiling the search kernels on first use (once; `viewdb warm` does it "
                 "ahead)", err)
        heard.append(kernel)
        _say(f"viewdb: compiling {len(heard)}: {kernel}", err)

    with compiling(on_compile):
        yield


def _prompts(box: list[str] | None, point: list[str] | None, every: bool, max_objects: int | None,
             mask: Path | None, label: int | None, label_map: Path | None) -> dict[str, Any]:
    """The prompt arguments of ``ViewDB.query``, parsed (a malformed one is a usage error)."""
    if every and (box or point):
        raise typer.BadParameter("give --box/--point prompts or --all, not both", param_hint="--all")
    if (box or point or every) and mask is not None:
        raise typer.BadParameter("--mask is one object: use --label-map with --all, or prompts alone",
                                 param_hint="--mask")
    if every and label is not None:
        raise typer.BadParameter("--all queries every label: drop --label", param_hint="--label")
    if (box or point) and label_map is not None:
        raise typer.BadParameter("--label-map with prompts: give --label, or --all", param_hint="--label-map")
    if max_objects is not None and not every:
        raise typer.BadParameter("--max-objects goes with --all", param_hint="--max-objects")
    try:
        boxes = [viewdb.parse_box(b) for b in box or ()]
        points = [viewdb.parse_point(p) for p in point or ()]
    except viewdb.QueryError as exc:
        raise typer.BadParameter(exc.message, param_hint="--box" if box else "--point") from None
    return {"boxes": boxes, "points": points, "every": every, "max_objects": max_objects}


def _check_overlay(path: Path, server: str | None) -> None:
    """Refuse an overlay that cannot be written before the query runs."""
    if server is not None:
        raise typer.BadParameter("--overlay needs the meshes: query the full file with --db",
                                 param_hint="--overlay")
    if path.suffix.lower() != ".png":
        raise typer.BadParameter(f"{path}: the overlay is written as PNG: name it *.png",
                                 param_hint="--overlay")
    if not path.parent.is_dir():
        raise viewdb.ViewDBError("the folder to write the overlay in does not exist", path)


def _write_png(path: Path, rgb: Any) -> None:
    """Write an RGB image as PNG in one step (a temporary file renamed over ``path``)."""
    import cv2

    ok, data = cv2.imencode(".png", rgb[:, :, ::-1])
    if not ok:
        raise viewdb.ViewDBError("cannot encode the overlay as PNG", path)
    try:
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.", delete=False) as f:
            temporary = Path(f.name)
            f.write(data.tobytes())
        temporary.replace(path)
    except OSError as exc:
        if "temporary" in locals():
            temporary.unlink(missing_ok=True)
        raise viewdb.ViewDBError(f"cannot write the overlay: {exc.strerror or exc}", path) from exc


def _print_result(result: viewdb.QueryResult) -> None:
    t = result.timing_ms
    network = f", network {t['network']:.0f}" if "network" in t else ""
    _say(f"{result.image}: plan {result.plan}, segmented by {result.segmentation}; "
         f"{t['total']:.0f} ms (segment {t['segment']:.0f}, client {t['client']:.0f}, "
         f"server {t['server']:.0f}, colour {t['colour']:.0f}, verify {t['verify']:.0f}, "
         f"pose {t['pose']:.0f}{network})")
    if result.objects is None:
        _results_table(result.results)
        return
    if not result.objects:
        _say("no object found: nothing in the photo stands out as an object")
    for i, o in enumerate(result.objects, 1):
        region = o.region
        prompt = f" from {region.prompt}" if region.prompt is not None else (
            f" (label {region.label})" if region.label is not None else "")
        x1, y1, x2, y2 = region.box
        _say(f"object {i}{prompt}: box {x1},{y1},{x2},{y2}, {region.area} pixels, segmented by "
             f"{region.segmentation.method}; {o.timing_ms.get('total', 0.0):.0f} ms")
        _results_table(o.results)


def _results_table(results: list[viewdb.QueryMatch]) -> None:
    rows = []
    for r in results:
        p = r.pose
        rows.append([
            str(r.rank), r.object, f"{r.distance:.3f}", "-" if r.colour is None else f"{r.colour:.2f}",
            "-" if r.shape_fit is None else f"{r.shape_fit:.3f}", f"{r.score:.3f}",
            f"{r.azimuth:g}/{r.elevation:g}{' mirrored' if r.mirrored else ''}"
            + ("" if r.camera_distance is None else f" at {r.camera_distance:g} r"),
            f"{p.azimuth:.1f}/{p.elevation:.1f}/{p.inplane:.1f}" if p else as_flags(r.pose_error or "-"),
            p.method if p else "-", str(p.inliers) if p else "-",
        ])
    _table(["rank", "object", "distance", "colour", "fit", "score", "view h/v", "pose h/v/in-plane",
            "method", "inliers"], rows)


def _client_limits(total: float) -> viewdb_config.HttpConfig:
    """The remote client's limits for a total timeout of ``total`` seconds."""
    base = viewdb_config.HttpConfig()
    return viewdb_config.HttpConfig(
        connect_timeout=min(base.connect_timeout, total), read_timeout=min(base.read_timeout, total),
        total_timeout=total)


@app.command("export-client")
def export_client(
    out_path: Annotated[Path, typer.Option("--out", help="Client file to write (must not exist).",
                                           dir_okay=False)],
    db: Annotated[Path | None, typer.Option("--db", help="The full database file.", dir_okay=False)] = None,
    shards: Annotated[Path | None, typer.Option(
        "--shards", help="Export from a sharded catalogue (viewdb shard --out, ingest --shards) "
                         "instead of --db: one client file of all its shards.", file_okay=False)] = None,
    gap: Annotated[
        float | None,
        typer.Option(help="Client grid gap, a multiple of the db's gap (default: its client gap).",
                     callback=_number(*GAP_RANGE)),
    ] = None,
    curve_bits: Annotated[
        int,
        typer.Option(help="Bits per curve sample (0: exact float32 curves, a larger file).",
                     min=0, max=16),
    ] = viewdb_config.ClientFileConfig().curve_bits,
) -> None:
    """Write the small file that ships to devices: the sparse tier only (no meshes, no SIFT)."""
    if (db is None) == (shards is None):
        raise typer.BadParameter("give either --db FILE or --shards DIR", param_hint="--db")
    file = viewdb_config.ClientFileConfig(curve_bits=curve_bits)
    with _progress() as bar:
        task = bar.add_task("export", total=None)

        def on_progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        if shards is not None:
            from viewdb.shards.layout import read_manifest
            from viewdb.shards.writing import export_client_from_shards

            config = export_client_from_shards(shards, out_path, client_gap=gap, progress=on_progress,
                                               file=file)
            full_bytes = sum(f.stat().st_size for f in read_manifest(shards).files)
        else:
            with _open_read(db) as vdb:  # type: ignore[arg-type]
                config = vdb.export_client(out_path, client_gap=gap, progress=on_progress, file=file)
                full_bytes = vdb.info().file_bytes
    with _open_read(out_path) as client:
        small = client.info()
    _say(
        f"wrote {out_path}: {len(small.objects)} objects, {small.rows['views']} views on the "
        f"{config.client_gap:g}° client grid, {small.file_bytes / 1e6:.2f} MB "
        f"({small.file_bytes / max(full_bytes, 1):.1%} of {full_bytes / 1e6:.1f} MB)"
    )


@app.command()
def shard(
    db: DbOption,
    shards: Annotated[int, typer.Option("--shards", help="Number of shard files to write.",
                                        min=1, max=4096)],
    out_dir: Annotated[Path, typer.Option("--out", help="Folder to write (must not exist or be empty).",
                                          file_okay=False)],
) -> None:
    """Split a full database by object into N shard files plus manifest.json (for serve --shards).

    An object goes to shard blake2b(name) mod N; each shard is a normal database file
    (info, check and query --db work on it)."""
    from viewdb.shards.layout import split_catalogue

    with _progress() as bar:
        task = bar.add_task("shard", total=shards)
        manifest = split_catalogue(db, shards, out_dir,
                                   progress=lambda done, total: bar.update(task, completed=done, total=total))
    _say(f"wrote {out_dir}: {manifest.shards} shards holding "
         + ", ".join(str(n) for n in manifest.objects) + " objects")


@app.command()
def serve(
    db: Annotated[Path | None, typer.Option("--db", help="Database file.", dir_okay=False)] = None,
    shards: Annotated[Path | None, typer.Option(
        "--shards", help="Serve a sharded catalogue (viewdb shard --out) on Ray instead of --db.",
        file_okay=False)] = None,
    ray: Annotated[str | None, typer.Option(
        "--ray", help="With --shards: the Ray cluster, 'auto' (the one on this machine, or a new "
                      "local one) or HOST:PORT of a head node (ray start --head).")] = None,
    host: Annotated[str, typer.Option(help="Address to listen on (loopback by default).")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="Port (0 picks a free one).", min=0, max=65535)] = 8765,
    workers: Annotated[int, typer.Option(help="Worker processes, each with the db open read-only.",
                                         min=1, max=64)] = 1,
    token: Annotated[
        str | None, typer.Option(help="Require 'Authorization: Bearer TOKEN' (except /health).",
                                 envvar="VIEWDB_TOKEN")
    ] = None,
    max_body: Annotated[
        int, typer.Option(help="Largest /refine, /walk, /colours or /colour-ranking body in bytes.",
                          min=1024, max=1 << 30)
    ] = 256 * 1024,
    max_image_body: Annotated[
        int, typer.Option(help="Largest /pose, /fits or /query body (the photo) in bytes.",
                          min=1024, max=1 << 30)
    ] = 32 * 1024 * 1024,
    header_timeout: Annotated[float, typer.Option(
        help="Seconds a connection has to send each request's header (slow senders are cut off).",
        callback=_number(0.001, 86400))] = viewdb_config.HttpConfig().header_timeout,
    body_timeout: Annotated[float, typer.Option(
        help="Seconds a request's body may take to arrive (then 408).",
        callback=_number(0.001, 86400))] = viewdb_config.HttpConfig().body_timeout,
    max_pixels: Annotated[int, typer.Option(
        help="Largest image decoded (/pose, /fits, /query), in pixels; larger ones are refused "
             "from their header.", min=256, max=viewdb_config.ImageConfig().max_pixels)
    ] = viewdb_config.HttpConfig().max_pixels,
    log_level: Annotated[
        str, typer.Option(help="critical, error, warning, info (logs every request) or debug.")
    ] = "warning",
    no_ui: Annotated[bool, typer.Option("--no-ui", help="Do not serve the web page at /.")] = False,
) -> None:
    """Serve the server tier of a full database over HTTP (read-only; OpenAPI at /openapi.json).

    POST /refine (CS1), /walk (CS2), /pose; GET /info, /health. Clients run
    `viewdb query IMAGE --client CLIENT --server URL`. A web page at / recognises
    uploaded photos (POST /query) and shows the catalogue (GET /objects).
    """
    from viewdb.http.serve import run_server

    if log_level not in ("critical", "error", "warning", "info", "debug"):
        raise typer.BadParameter("must be critical, error, warning, info or debug", param_hint="--log-level")
    if (db is None) == (shards is None):
        raise typer.BadParameter("give either --db FILE or --shards DIR", param_hint="--db")
    if ray is not None and shards is None:
        raise typer.BadParameter("--ray needs --shards", param_hint="--ray")
    served = db if db is not None else shards

    def ready(url: str, objects: int) -> None:
        auth = ", bearer token required" if token else ""
        page = "" if no_ui else f"; web page at {url}/"
        _say(f"viewdb: serving {served} ({objects} objects) on {url} with {workers} "
             f"worker{'s' if workers > 1 else ''}{auth}{page}; Ctrl-C stops")
        sys.stdout.flush()

    run_server(served, host=host, port=port, workers=workers, token=token, max_body=max_body, ray=ray,
               max_image_body=max_image_body, log_level=log_level, ready=ready, ui=not no_ui,
               http=viewdb_config.HttpConfig(header_timeout=header_timeout, body_timeout=body_timeout,
                                             max_pixels=max_pixels))


@app.command()
def demo(
    out_dir: Annotated[
        Path | None, typer.Option("--out", help="Folder for the demo db (default: a temp folder).")
    ] = None,
    gap: Annotated[float, typer.Option(help="Grid gap in degrees.", callback=_number(*GAP_RANGE))] = 30.0,
    jobs: Annotated[int, typer.Option(help="Worker processes.", min=1, max=LIMITS.max_jobs)] = 2,
) -> None:
    """Build a database from the bundled sample models and show what is in it."""
    models = viewdb.describe_paths([SAMPLE_MODELS]) if SAMPLE_MODELS.is_dir() else []
    if not models:
        raise viewdb.ViewDBError("no sample models found; run python sample_models/make_samples.py",
                                 SAMPLE_MODELS)
    folder = out_dir or Path(tempfile.mkdtemp(prefix="viewdb-demo-"))
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise viewdb.ViewDBError(f"cannot be made a folder: {exc.strerror or exc}", folder) from exc
    db_path = folder / "demo.db"
    _say(f"viewdb demo: ingesting {len(models)} sample models into {db_path} (gap {gap:g}°)")
    ingest(models, db_path, gap=gap, image_size=None, jobs=jobs, no_skim=False, as_json=False)
    info(db_path, as_json=False)
    first = models[0].stem
    png = folder / f"{first}_30_20.png"
    render(first, 30.0, 20.0, png, db=db_path, image_size=256, what="color")
    photo = folder / "query.png"
    _demo_photo(db_path, "mug" if any(m.stem == "mug" for m in models) else first, photo)
    _say(f"viewdb demo: querying {photo} (an off-grid view, turned and scaled, on a grey background)")
    query(photo, db_path, k=3, plan="cs1", client=None, mask=None, rotations=8, band=6,
          roll=None, upright=False, no_pose=False, pose_top=1, intrinsics=None, label_map=None, label=None,
          rerank=False, as_json=False)


def _demo_photo(db_path: Path, name: str, out_path: Path) -> None:
    """A synthetic photo: the object at an off-grid view, turned 20° in the image plane,
    scaled 0.8 and off-centre, on a light grey background."""
    import cv2

    from viewdb.bench.photos import composite_photo

    with viewdb.open(db_path, create=False) as vdb:
        view = vdb.render(name, 37.0, 22.0)
    photo, _ = composite_photo(view, turn=20.0, scale=0.8, shift=(12, -8), background=200)
    if not cv2.imwrite(str(out_path), cv2.cvtColor(photo, cv2.COLOR_RGB2BGR)):
        raise viewdb.ViewDBError("cannot write the image", out_path)


def _floats(text: str, option: str) -> tuple[float, ...]:
    try:
        values = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        values = (math.nan,)
    if not all(math.isfinite(v) for v in values):
        raise typer.BadParameter(f"expected finite numbers separated by commas, got {_shown(text)!r}",
                                 param_hint=option) from None
    if not values:
        raise typer.BadParameter("needs at least one value", param_hint=option)
    return values


@app.command()
def bench(
    models: Annotated[Path, typer.Argument(help="Folder of mesh files (e.g. ../shared/models).",
                                           metavar="MODELS_DIR")],
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for results, plots and the log.",
                                          file_okay=False)],
    queries: Annotated[int, typer.Option(help="Queries per protocol.", min=1)] = 100,
    seed: Annotated[int, typer.Option(help="Seed of the queries (same seed, same queries).")] = 0,
    gaps: Annotated[str, typer.Option(help="Client grid gaps of the time experiment.")] = "20,30,40,50",
    k: Annotated[int, typer.Option("--k", "-k", help="Largest k (CMC ranks, time for k = 1..k).",
                                   min=1, max=100)] = 5,
    jobs: Annotated[int, typer.Option(help="Worker processes for ingest.", min=1, max=LIMITS.max_jobs)] = 1,
    subset: Annotated[int | None, typer.Option(help="Use only N models, evenly spaced by name.",
                                               min=1)] = None,
    cache: Annotated[Path | None, typer.Option(
        help="Folder of built databases (default OUT/cache); a full db built elsewhere with "
             "the same gap and image size can be put here.", file_okay=False)] = None,
    gap: Annotated[float, typer.Option(help="Server grid gap.", callback=_number(*GAP_RANGE))] = 10.0,
    client_gap: Annotated[float, typer.Option(help="Client grid gap of the accuracy run.",
                                              callback=_number(*GAP_RANGE))] = 30.0,
    image_size: Annotated[int, typer.Option(help="View size in pixels.", **SIZE_RANGE)] = 256,
    protocols: Annotated[str, typer.Option(help="Accuracy query protocols: grid, photo.")] = "grid,photo",
) -> None:
    """Reproduce the paper's experiments: S1–S6 CMC curves, time against the client gap
    for k = 1..k, index sizes. Resumable: run the same command again to continue."""
    import viewdb.bench as viewdb_bench

    config = viewdb_bench.BenchConfig(
        models=models, out=out_dir, queries=queries, seed=seed, gaps=_floats(gaps, "--gaps"),
        k=k, jobs=jobs, subset=subset, cache=cache, gap=gap, client_gap=client_gap,
        image_size=image_size, protocols=tuple(p.strip() for p in protocols.split(",") if p.strip()),
    )
    with _progress() as bar:
        tasks: dict[str, Any] = {}

        def on_progress(p: viewdb_bench.BenchProgress) -> None:
            task = tasks.get(p.stage)
            if task is None:
                task = tasks[p.stage] = bar.add_task(p.stage, total=p.total)
            bar.update(task, completed=p.done, total=p.total,
                       description=f"{p.stage} {p.detail}".strip())

        run = viewdb_bench.run_bench(config, on_progress)
    _say(f"viewdb bench: {run.measured} measurements made, {run.skipped} read from "
         f"{out_dir / 'results.jsonl'}")
    for protocol, rows in run.summary["accuracy"].items():
        out.print(f"{protocol} queries, rank-1 / rank-{k}: " + ", ".join(
            f"{label} {r['cmc'][0]:.1%}/{r['cmc'][-1]:.1%}" for label, r in rows.items()))
    _say("wrote " + ", ".join(str(p) for p in run.files.values()))


#: How the library's errors name a Python parameter (in backticks), and what the command
#: line user typed instead; the longer forms first.
PARAMETER_FLAGS = {
    "(`read_only` False)": "(e.g. viewdb info --db FILE)",
    "`allow_missing_textures`=True": "--allow-missing-textures",
    "split_catalogue's `out`": "viewdb shard --out",
    "`client_gap`": "--client-gap",
    "`count`": "--shard-count",
    "`db`": "--db",
    "`depth`": "--depth",
    "`depth_scale`": "--depth-scale",
    "`folder`": "--shards",
    "`gap`": "--gap",
    "`gaps`": "--gaps",
    "`image_size`": "--image-size",
    "`intrinsics`": "--intrinsics",
    "`jobs`": "--jobs",
    "`k`": "--k",
    "`max_faces`": "--max-faces",
    "`out`": "--out",
    "`perspective`": "--perspective",
    "`perspective_gap`": "--perspective-gap",
    "`queries`": "--queries",
    "`server`": "--server",
    "`shards`": "--shards",
    "`subset`": "--subset",
    "`workers`": "--workers",
}


def as_flags(message: str) -> str:
    """A library error's ``message`` as a command line user reads it: each parameter it
    names (:data:`PARAMETER_FLAGS`) as the flag they gave."""
    for name, flag in PARAMETER_FLAGS.items():
        message = message.replace(name, flag)
    return message


def main(argv: list[str] | None = None) -> int:
    """Run the CLI and return its exit code (the console script calls this)."""
    if not (sys.argv[1:] if argv is None else argv):
        # no command: the help on stdout, as --help prints it, with a usage error's code
        main(["--help"])
        return 2
    command = typer.main.get_command(app)
    try:
        # without standalone mode click returns typer.Exit's code instead of raising it
        code = command.main(args=argv, prog_name="viewdb", standalone_mode=False)
    except typer.Exit as exc:
        code = exc.exit_code
    except typer.TyperException as exc:  # usage errors
        exc.show()
        return exc.exit_code
    except (KeyboardInterrupt, typer.Abort):
        code = 130
    except viewdb.ViewDBError as exc:
        if _STATE["debug"]:
            raise
        _say(f"viewdb: {as_flags(str(exc))}", err)
        return 1
    except ImportError as exc:  # a module of an extra this install lacks
        from viewdb.lazy import missing_extra

        hint = missing_extra(exc)
        if hint is None or _STATE["debug"]:
            raise
        _say(f"viewdb: {hint}", err)
        return 1
    code = code if isinstance(code, int) else 0
    if code == 130:  # typer turns KeyboardInterrupt into Exit(130), returned or raised
        err.print("viewdb: interrupted", markup=False)
    return code


def run() -> None:
    """The console script: :func:`main`, then the process ends without the interpreter's
    teardown (:func:`exit_now`)."""
    exit_now(main())


def exit_now(code: int) -> None:
    """End the process with ``code`` once the exit handlers have run (temporary folders,
    logging, Ray) and the standard streams are flushed, skipping the interpreter's teardown,
    which frees every object one by one: after a query, numba's compiler state made that
    0.4–0.7 s of a 2 s command. Every command has closed its database by then."""
    import atexit
    import os

    try:
        getattr(atexit, "_run_exitfuncs", lambda: None)()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe or stream: nothing more to say
                pass
        os._exit(code)


if __name__ == "__main__":
    run()
