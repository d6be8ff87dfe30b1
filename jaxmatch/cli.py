"""The ``jaxmatch`` command line (typer app only: parse, call the library, hand the results to
:mod:`jaxmatch.report`, which prints them).

Bad input ends with one line on stderr and exit status 2 (see :mod:`jaxmatch.errors`).
"""

from __future__ import annotations

import json
import os
import sys
import time
import warnings
from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console

from jaxmatch import __version__, report
from jaxmatch.catalogue import store as cat_mod
from jaxmatch.errors import EXIT_BAD_INPUT, EXIT_INVERTED, EXIT_UNMATCHABLE, InputError, InputWarning, SolverError, UnmatchableError
from jaxmatch.defaults import DEFAULT_BUDGET_S, DEFAULT_LATTICE, DEFAULT_TIE_BREAK, DEFAULT_TOP, QUALITY, SEARCHES, TIE_BREAKS
from jaxmatch.io.meshfile import MESH_FORMATS, mesh_format, write_mesh
from jaxmatch.field import load_field
from jaxmatch.io.output import MeshOutput, PictureOutput, parse_png_size
from jaxmatch.lazy import Later
from jaxmatch.meshing.region import canonical, default_size, load_region
from jaxmatch.scoring import distributed
from jaxmatch.model import Model
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, Shape, check_corner_angle, default_points
from jaxmatch.shape import annotate as annotate_shape

try:  # typer >= 0.2x vendors click as typer._click and no longer installs click
    from typer._click.exceptions import ClickException
except ImportError:  # pragma: no cover - older typer with click
    from click.exceptions import ClickException

later = Later(
    # the library behind the commands that score, read shapes or mesh (not for --help, 'lattice', 'catalogue')
    api="jaxmatch.api",  # rank, check_sizes, load_shape, load_lattice
    lattice="jaxmatch.scoring.lattice",  # 'lattice show'
    rank="jaxmatch.scoring.rank",  # ranking records
    build="jaxmatch.meshing.build",  # placements as QuadMeshes ('score --png')
    bulk="jaxmatch.scoring.bulk", backends="jaxmatch.kernels.backends", parallel="jaxmatch.parallel",  # many at once
    batch="jaxmatch.batch",  # 'mesh' of many regions: workers, --resume, --region-budget, --dask
    # the meshing stack (placement, integer programs): only the commands that mesh or place
    pipeline="jaxmatch.meshing.pipeline",
    layout="jaxmatch.placement.layout",  # a layout's named sides (--sides-file)
    refine="jaxmatch.placement.refine",  # the sides table of 'annotate'
    choose="jaxmatch.placement.choose",  # 'score --png' places the ranked meshes
    # modules that load heavy third-party ones
    plot="jaxmatch.io.plot",  # matplotlib: only with --png/--svg
    label="jaxmatch.label.cli",  # starlette and uvicorn: only 'label'
)
"""Modules a command imports when it runs (:class:`jaxmatch.lazy.Later`), so that the others
start without them: ``jaxmatch --help``, ``lattice`` and ``catalogue`` load no scoring or
meshing, ``mesh`` no matplotlib or web server (``tests/test_cli_mesh.py`` checks that)."""

ENV_HELP = ("Environment: JAXMATCH_PROGRESS=1 shows progress bars even when stderr is not a terminal, 0 hides all "
            "progress; JAXMATCH_CACHE=DIR holds the compiled-code cache (default ~/.cache/jaxmatch); "
            "JAXMATCH_DEBUG=1 shows a traceback for internal errors.")


def _version(value: bool) -> None:
    if value:
        print(f"jaxmatch {__version__}")
        raise typer.Exit()


app = typer.Typer(add_completion=False, pretty_exceptions_enable=False, no_args_is_help=True,
                  help="Pick the best quadrilateral mesh from a catalogue for a planar shape.\n\n" + ENV_HELP)
lattice_app = typer.Typer(no_args_is_help=True, help="Inspect lattice weight files.")
catalogue_app = typer.Typer(no_args_is_help=True, help="Build and inspect mesh catalogues.")
app.add_typer(lattice_app, name="lattice")
app.add_typer(catalogue_app, name="catalogue")


@app.callback()
def _main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")) -> None:
    """Pick the best quadrilateral mesh from a catalogue for a planar shape."""


out = Console(soft_wrap=True, width=None if sys.stdout.isatty() else 120)
err = Console(stderr=True)

HEARTBEAT_S = 10.0
"""Seconds between the plain progress lines printed when stderr is not a terminal."""


class Heartbeat:
    """Progress for a stderr that is not a terminal (a pipe, a log file): one plain line
    ``"<task>: <done>/<total> (<seconds> s)"`` at most every ``interval`` seconds, so that a
    long piped run shows it is alive. Same calls as :class:`rich.progress.Progress`."""

    def __init__(self, interval: float | None = None, stream=None):
        self.interval = HEARTBEAT_S if interval is None else float(interval)
        self.stream = stream
        self.tasks: dict[int, list] = {}
        self.start = self.last = time.monotonic()

    def __enter__(self) -> "Heartbeat":
        return self

    def __exit__(self, *exc) -> bool:
        return False

    def add_task(self, description: str, total=None, **_) -> int:
        self.tasks[len(self.tasks)] = [description, 0, total]
        return len(self.tasks) - 1

    def update(self, task: int, *, completed=None, total=None, description=None, advance=None, **_) -> None:
        t = self.tasks[task]
        if description is not None:
            t[0] = description
        if total is not None:
            t[2] = total
        if completed is not None:
            t[1] = completed
        if advance is not None:
            t[1] += advance
        now = time.monotonic()
        if now - self.last >= self.interval:
            self.last = now
            done = f"{t[1]:g}/{t[2]:g}" if t[2] else f"{t[1]:g}"
            print(f"{t[0]}: {done} ({now - self.start:.0f} s)", file=self.stream or sys.stderr, flush=True)

    def advance(self, task: int, advance: float = 1) -> None:
        self.update(task, advance=advance)


def _progress():
    """A progress display: rich bars on a terminal (or with JAXMATCH_PROGRESS=1), else
    :class:`Heartbeat` lines; JAXMATCH_PROGRESS=0 shows nothing."""
    env = os.environ.get("JAXMATCH_PROGRESS", "").strip()
    if not (err.is_terminal or env):
        return Heartbeat()
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn  # only here (start-up)

    if env == "0":
        return Progress(console=err, disable=True)
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=err, transient=True)


COMPILE_CACHE_SETTINGS = {"jax_persistent_cache_min_compile_time_secs": 0.0, "jax_persistent_cache_min_entry_size_bytes": 0}
"""JAX options set with the cache folder (every compiled kernel is kept)."""


def enable_compile_cache() -> None:
    """JAX's persistent compilation cache (``JAXMATCH_CACHE``, default ``~/.cache/jaxmatch``),
    so a second run does not compile again.

    Does not import JAX (the default CPU path never does): if JAX is not loaded yet, the
    settings go into the environment variables JAX reads when it is imported
    (``JAX_COMPILATION_CACHE_DIR``, ...); if it is, into ``jax.config``."""
    cache = Path(os.environ.get("JAXMATCH_CACHE", Path.home() / ".cache" / "jaxmatch")) / "xla"
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except OSError:  # a read-only home: run without the cache
        return
    settings = {"jax_compilation_cache_dir": str(cache), **COMPILE_CACHE_SETTINGS}
    if "jax" not in sys.modules:
        for name, value in settings.items():
            os.environ[name.upper()] = str(value)
        return
    try:
        for name, value in settings.items():
            sys.modules["jax"].config.update(name, value)
    except Exception:  # an older JAX without one of the options: run without the cache
        pass


def _corner_angle(value) -> float:
    try:
        return check_corner_angle(value)
    except InputError as e:
        raise InputError(e.problem.replace("corner angle must be", "must be"), "--corner-angle") from None


def _sizes(cat, internal: Optional[str]):
    try:
        return later.api.check_sizes(cat, internal)
    except InputError as e:
        raise InputError(e.problem, "--internal") from None


def _quietly(read, *args, **kwargs):
    """``read(*args, **kwargs)`` with its warnings (ignored keys) shown only when it succeeds, so
    that bad input stays one line."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputWarning)
        value = read(*args, **kwargs)
    for w in caught:
        warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    return value


def _load(shape: Path, corner_angle: float):
    """The shape file, read (:func:`_quietly`)."""
    return _quietly(later.api.load_shape, shape, corner_angle=corner_angle)


def _inputs(shape: Optional[Path], corner_angle: float, lattice: str, catalogue: Optional[Path], internal: Optional[str]):
    """(shape or None, lattice, catalogue, k list or None): the inputs every scoring command
    reads, options checked first (the option is named in errors)."""
    angle = _corner_angle(corner_angle)
    cat = _open_catalogue(catalogue)
    ks = _sizes(cat, internal)
    shp = _load(shape, angle) if shape is not None else None
    return shp, later.api.load_lattice(lattice), cat, ks


def _open_catalogue(path: Optional[Path]):
    return cat_mod.load(path) if path is not None else cat_mod.default_catalogue()


SHAPE_HELP = ("Shape file: jaxmatch JSON {boundary, corners}, GeoJSON polygon, CSV/TSV/text rows 'x y' (header optional), "
              "SVG, DXF, STEP/IGES; FILE#ID picks one element of an SVG/DXF/GeoJSON/STEP file.")
CATALOGUE_HELP = "Catalogue file (default: the shipped k=0..5 catalogue)."
INTERNAL_HELP = ("Mesh size: K or K1..K2 internal vertices. Without it all sizes compete, and larger meshes "
                 "(more boundary vertices, more matched points) get larger raw utilities.")
LATTICE_HELP = "Lattice: fine, coarse, or a TOML path."
POINTS_HELP = "Number m of annotated shape points (default: 2 x longest boundary of the selected sizes)."
ANGLE_HELP = "Corner threshold: a point is a corner when the outline turns there by more than this many degrees (shapes without explicit corners)."
JSON_HELP = "Print one JSON object instead of a table."
TIE_BREAK_HELP = ("Order among equal utilities: 'geometry' places the tied meshes and prefers the higher min scaled "
                  "Jacobian, then fewer irregular internal vertices (beyond the paper); 'id' keeps the paper's "
                  "combinatorial order (fewer internal vertices, shorter boundary, id).")


REGION_HELP = ("Region file(s): a shape (jaxmatch JSON {boundary, corners, holes}, GeoJSON, CSV/TSV/text 'x y' rows, SVG, DXF, "
               "STEP/IGES/BREP; "
               "FILE#ID picks an element) or a layout JSON {points, patches}.")


def _tie_break(text: str) -> str:
    if text not in TIE_BREAKS:
        raise InputError(f"expected one of {', '.join(TIE_BREAKS)}, got {text!r}", "--tie-break")
    return text


@app.command()
def score(
    shape: Path = typer.Argument(..., metavar="SHAPE", help=SHAPE_HELP),
    catalogue: Optional[Path] = typer.Option(None, metavar="FILE", help=CATALOGUE_HELP),
    internal: Optional[str] = typer.Option(None, metavar="K|K1..K2", help=INTERNAL_HELP),
    lattice: str = typer.Option(DEFAULT_LATTICE, metavar="NAME|FILE", help=LATTICE_HELP),
    top: int = typer.Option(DEFAULT_TOP, min=1, metavar="N", help="How many meshes to show."),
    points: Optional[int] = typer.Option(None, min=1, metavar="M", help=POINTS_HELP),
    per_size: bool = typer.Option(False, "--per-size", help="Show the best --top meshes of each size k (utilities only compare within a size)."),
    corner_angle: float = typer.Option(DEFAULT_CORNER_ANGLE, metavar="DEGREES", help=ANGLE_HELP),
    tie_break: str = typer.Option(DEFAULT_TIE_BREAK, "--tie-break", metavar="geometry|id", help=TIE_BREAK_HELP),
    png: Optional[Path] = typer.Option(None, "--png", metavar="FILE", help="Also draw the listed meshes placed in the shape, side by side, to this .png file."),
    svg: Optional[Path] = typer.Option(None, "--svg", metavar="FILE", help="Same picture as --png, as .svg."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
    devices: Optional[int] = typer.Option(None, min=1, metavar="N", help="Shard the scoring over N JAX devices (GPUs, or N CPU host devices)."),
    exhaustive: bool = typer.Option(False, "--exhaustive", help="Score every mesh instead of the pruned top-K search (same results, slower)."),
) -> None:
    """Rank catalogue meshes for SHAPE by the paper's modified LCS utility."""
    if devices is not None:
        later.bulk.configure_host_devices(devices)  # before JAX is imported
    pictures = png is not None or svg is not None
    check_outputs(png=png, svg=svg)
    tb = _tie_break(tie_break)
    enable_compile_cache()
    shp, lat, cat, ks = _inputs(shape, corner_angle, lattice, catalogue, internal)
    with _progress() as prog:
        task = prog.add_task("scoring meshes", total=None)
        ranking = later.api.rank(shp, cat, lat, internal=ks, top=top, points=points, per_size=per_size, tie_break=tb,
                           prune=not exhaustive, devices=devices,
                           progress=lambda d, t: prog.update(task, completed=d, total=t))
    written = []
    if pictures:  # each ranked mesh placed (placement, and scipy, load only then), drawn as a QuadMesh
        placed = later.choose.place_top(shp, ranking, cat, lattice=lat)
        items = [(report.panel_title(i, r, pl), later.build.from_placement(shp, pl, r.mesh_id))
                 for i, (r, pl) in enumerate(zip(ranking.results, placed), 1)]
        head = f"{shape.name}: {'best per size' if per_size else f'top {len(items)}'}"
        written = [str(later.plot.draw_in_shape(p, shp, ranking.annotation, items, title=head))
                   for p in (png, svg) if p is not None]
    if as_json:
        print(json.dumps(later.rank.ranking_json(str(shape), ranking, lat.name, tb)))
        for w in written:
            print(f"wrote {w}", file=sys.stderr)
        return
    report.print_ranking(out, shape, ranking, lat.name, top=top, per_size=per_size, all_sizes=ks is None and not per_size,
                         written=written)


@app.command("score-many")
def score_many(
    shapes: list[Path] = typer.Argument(..., metavar="SHAPES...", help="Shape files (any format 'score' reads)."),
    out_path: Path = typer.Option(..., "--out", metavar="FILE", help="Results as JSON lines (one per shape, the fields of score --json), written atomically."),
    catalogue: Optional[Path] = typer.Option(None, metavar="FILE", help=CATALOGUE_HELP),
    internal: Optional[str] = typer.Option(None, metavar="K|K1..K2", help=INTERNAL_HELP),
    lattice: str = typer.Option(DEFAULT_LATTICE, metavar="NAME|FILE", help=LATTICE_HELP),
    top: int = typer.Option(DEFAULT_TOP, min=1, metavar="N", help="How many meshes per shape."),
    points: Optional[int] = typer.Option(None, min=1, metavar="M", help=POINTS_HELP),
    per_size: bool = typer.Option(False, "--per-size", help="The best --top meshes of each size k."),
    corner_angle: float = typer.Option(DEFAULT_CORNER_ANGLE, metavar="DEGREES", help=ANGLE_HELP),
    tie_break: str = typer.Option(DEFAULT_TIE_BREAK, "--tie-break", metavar="geometry|id", help=TIE_BREAK_HELP),
    devices: Optional[int] = typer.Option(None, min=1, metavar="N", help="Shard the scoring over N JAX devices."),
    skip_bad: bool = typer.Option(False, "--skip-bad", help="Record a bad or unmatchable shape as {shape, error} and go on "
                                  "(exit 0); without it the first bad shape stops the run before any scoring (exit 2)."),
    coordinator: Optional[str] = typer.Option(None, metavar="HOST:PORT", help="Address of process 0: share the shapes among "
                                              "--num-processes processes (jax.distributed; start the same command once per process)."),
    num_processes: int = typer.Option(1, min=1, metavar="P", help="Processes sharing the run (with --coordinator)."),
    process_id: int = typer.Option(0, min=0, metavar="I", help="This process's id, 0..P-1 (with --coordinator); process 0 writes --out."),
    jobs: Optional[int] = typer.Option(None, "--jobs", min=1, metavar="N", help="Worker processes on this machine "
                                       "(default: its CPUs; 1 with --coordinator or --devices, which load JAX)."),
) -> None:
    """Score many shapes in one run (bulk mode), with the same defaults and records as 'score --json'.

    Every shape is read and checked before scoring. A summary line goes to stderr at the end.
    With --coordinator, each process ranks every P-th shape and process 0 writes all records.
    On one machine the shapes are shared among --jobs worker processes (results in input order).
    """
    cluster = _cluster(coordinator, num_processes, process_id, devices)
    if devices is not None:
        later.bulk.configure_host_devices(devices)
    tb = _tie_break(tie_break)
    if out_path.suffix.lower() not in (".jsonl", ".json", ".ndjson"):
        raise InputError("results are JSON lines: use a .jsonl file", str(out_path))
    enable_compile_cache()
    _, lat, cat, ks = _inputs(None, corner_angle, lattice, catalogue, internal)
    angle = _corner_angle(corner_angle)
    loaded = []  # (path, Shape or the error message); bad input fails before any work unless --skip-bad
    for p in shapes:
        try:
            loaded.append((p, _load(p, angle)))
        except InputError as e:
            if not skip_bad:
                raise
            loaded.append((p, str(e)))
    distributed.initialize(cluster)
    mine = distributed.share(len(loaded), cluster)

    def one(i: int):
        """(record, None) or (None, message of an unmatchable shape without --skip-bad)."""
        p, shp = loaded[i]
        if isinstance(shp, str):
            return {"shape": str(p), "error": shp}, None
        try:
            ranking = later.api.rank(shp, cat, lat, internal=ks, top=top, points=points, per_size=per_size, tie_break=tb,
                               prune=True, devices=devices)
            return later.rank.ranking_json(str(p), ranking, lat.name, tb), None
        except UnmatchableError as e:
            if not skip_bad:
                return None, f"{p}: {e}"
            return {"shape": str(p), "error": f"no match: {e}"}, None

    workers = 1 if (coordinator is not None or devices is not None) else (later.parallel.available_cpus() if jobs is None else jobs)
    records = []
    with _progress() as prog:
        task = prog.add_task("shapes", total=len(mine))
        def worker_start():  # in each worker process
            later.backends.serial_only()
            cat.reopen()
            sys.stdout, sys.stderr = sys.__stdout__, sys.__stderr__  # not the progress display's proxies (their lock)

        if workers > 1:
            later.backends.serial_only()  # one core per process (and numba's OpenMP layer must not start before fork)
        for record, fatal in later.parallel.ordered_map(one, list(mine), workers, initializer=worker_start, warm_first=True):
            if fatal is not None:
                raise UnmatchableError(fatal)
            records.append(record)
            prog.advance(task)
    records = distributed.gather_records(records, mine, len(loaded), cluster)
    if cluster.process_id == 0:
        failed = sum(1 for r in records if "error" in r)
        later.bulk.write_jsonl(out_path, records)
        note = f", {failed} failed (records with \"error\")" if failed else ""
        print(f"wrote {out_path}: {len(records)} shapes, {len(records) - failed} scored{note}", file=sys.stderr)  # one line
    distributed.shutdown(cluster)


def _cluster(coordinator: Optional[str], num_processes: int, process_id: int, devices: Optional[int]):
    """The :class:`jaxmatch.scoring.distributed.Cluster` of score-many's options (one process without --coordinator)."""
    if coordinator is None:
        if num_processes != 1 or process_id != 0:
            raise InputError("needs --coordinator HOST:PORT", "--num-processes/--process-id")
        return distributed.Cluster("", 1, 0)
    if devices is not None:
        raise InputError("use either --devices or --coordinator, not both", "--devices")
    try:
        return distributed.make_cluster(coordinator, num_processes, process_id)
    except InputError as e:
        raise InputError(e.problem, "--coordinator/--num-processes/--process-id") from None


@app.command()
def mesh(
    regions: List[Path] = typer.Argument(..., metavar="REGION...", help=REGION_HELP),
    size: Optional[float] = typer.Option(None, "--size", metavar="H", help="Target edge length in the region's units "
                                         "(default: the outer perimeter / 32, printed)."),
    divisions: Optional[int] = typer.Option(None, "--divisions", min=1, metavar="N", help="Instead of --size: edge "
                                            "length = each region's outer perimeter / N (one size per region in bulk)."),
    size_field: Optional[Path] = typer.Option(None, "--size-field", metavar="FIELD.json", help='Instead of --size: a '
                                              'graded mesh, {"size": H, "near": [{"hole": k | "point": [x, y] | "side": '
                                              '"i-j" | "curve": [[x, y], ...], "size": s, "distance": d}, ...]} '
                                              "(docs/graded.md)."),
    auto_size: bool = typer.Option(False, "--auto-size", help="Also finer where the part asks for it: thin parts (an "
                                   "element across), curved stretches (30 degrees of arc an edge), small holes (8 edges "
                                   "around), back to the size within 2 sizes (docs/graded.md)."),
    sides: Optional[str] = typer.Option(None, "--sides", help="Edges per side, e.g. 4,2,4,2: the sides in the file's order, "
                                        "each from a corner to the next (the output's groups 'side i-j': i, j point numbers, "
                                        "or positions in \"corners\"); one total count for a shape without corners. One "
                                        "template meets them exactly."),
    sides_file: Optional[Path] = typer.Option(None, "--sides-file", help='Layouts: JSON {"i-j": count, ...}, edges on the '
                                              "named sides (i, j: the side's end points)."),
    template: bool = typer.Option(False, "--template", help="The paper's answer instead: the best-ranked catalogue mesh "
                                  "placed as is (no size; see --internal, --rank, --band)."),
    out_path: Optional[Path] = typer.Option(None, "--out", help="Mesh file, written atomically: .msh "
                                            "(physical groups) .inp .xdmf .bdf .e/.exo .vtu .vtk .mesh .obj .json."),
    out_dir: Optional[Path] = typer.Option(None, "--out-dir", metavar="DIR", help="Many regions: one mesh file per region "
                                           "in DIR (named after it) and DIR/summary.jsonl."),
    fmt: Optional[str] = typer.Option(None, "--format", metavar="SUFFIX", help="The mesh file's format (default: --out's "
                                      "suffix; msh with --out-dir): " + ", ".join(s[1:] for s in MESH_FORMATS) + "."),
    msh_version: str = typer.Option("4.1", "--msh-version", metavar="4.1|2.2", help=".msh: Gmsh file version."),
    ascii_: bool = typer.Option(False, "--ascii", help=".msh/.vtk: ASCII instead of binary."),
    element_type: Optional[str] = typer.Option(None, "--element-type", metavar="TYPE", help=".inp: CPS4 (default), CPE4, "
                                               "CAX4, S4R; C3D8, C3D8R, C3D8I with --extrude."),
    order: int = typer.Option(1, "--order", metavar="1|2", help="2: quad9 (hex27) with mid-side nodes on the outline."),
    serendipity: bool = typer.Option(False, "--serendipity", help="--order 2: quad8 instead of quad9."),
    extrude: Optional[float] = typer.Option(None, "--extrude", metavar="DZ", help="Hexahedra: the mesh swept along z by DZ."),
    layers: int = typer.Option(1, "--layers", metavar="N", help="--extrude: element layers."),
    grading: float = typer.Option(1.0, "--grading", metavar="R", help="--extrude: top layer / bottom layer thickness."),
    png_size: Optional[str] = typer.Option(None, "--png-size", metavar="W,H", help="Picture size in pixels."),
    dpi: Optional[int] = typer.Option(None, "--dpi", help="Picture resolution (default 120; the size then fits the region)."),
    color: str = typer.Option("patch", "--color", metavar="patch|quality|size", help="Picture: quads by patch, by scaled "
                              "Jacobian or by edge length / size (the size field's where one is given)."),
    histogram: bool = typer.Option(False, "--histogram", help="Picture: add the scaled Jacobians' histogram."),
    png: Optional[Path] = typer.Option(None, "--png", help="Picture of the mesh (.png)."),
    svg: Optional[Path] = typer.Option(None, "--svg", help="Picture of the mesh (.svg)."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
    jobs: Optional[int] = typer.Option(None, "--jobs", min=1, metavar="N", help="With many regions: worker processes "
                                       "(default: the CPUs)."),
    skip_bad: bool = typer.Option(False, "--skip-bad", help="With many regions: a bad region becomes a record "
                                  "{shape, error} in the summary and the rest go on (exit 0)."),
    resume: bool = typer.Option(False, "--resume", help="With --out-dir: keep the regions whose record in DIR/summary.jsonl "
                                "has the same input file contents and options and whose mesh file exists."),
    region_budget: Optional[float] = typer.Option(None, "--region-budget", metavar="SECONDS", help="With many regions: "
                                                  "a region still meshing after this long gets a record with "
                                                  "\"status\": \"timed out\" and the run goes on (default: --budget)."),
    dask: Optional[str] = typer.Option(None, "--dask", metavar="ADDRESS", envvar="JAXMATCH_DASK", show_envvar=False,
                                       help="With many regions: run them as tasks of the Dask scheduler at ADDRESS "
                                       "(or $JAXMATCH_DASK; needs pip install 'jaxmatch[dask]')."),
    strategy: Optional[str] = typer.Option(None, "--strategy", metavar="NAMES", help="Candidates to try, comma-separated: "
                                           "single, continuations, bisectors, recursive, radial, fillets, rings (default: all)."),
    search: str = typer.Option("best", "--search", metavar="best|fast", help="best: every candidate that could win; "
                               "fast: stop at the first good mesh (about 2x the regions/s, some quality lost: docs/perf.md)."),
    budget: float = typer.Option(DEFAULT_BUDGET_S, "--budget", metavar="SECONDS", help="Stop trying candidates after "
                                 "this long once one valid mesh exists (the best so far is kept)."),
    catalogue: Optional[Path] = typer.Option(None, metavar="FILE", help=CATALOGUE_HELP),
    lattice: str = typer.Option(DEFAULT_LATTICE, metavar="NAME|FILE", help=LATTICE_HELP),
    corner_angle: float = typer.Option(DEFAULT_CORNER_ANGLE, metavar="DEGREES", help=ANGLE_HELP),
    internal: Optional[str] = typer.Option(None, metavar="K|K1..K2", help="--template: mesh size (default: chosen by the "
                                           "fit of the best mesh of each size; the rule that decided is printed)."),
    points: Optional[int] = typer.Option(None, min=1, metavar="M", help="--template: " + POINTS_HELP),
    rank_: int = typer.Option(1, "--rank", min=1, metavar="R", help="--template: place the R-th ranked mesh."),
    require_valid: bool = typer.Option(False, "--require-valid", help="--template: walk down the ranking (up to 50 meshes) "
                                       "to the first mesh that keeps every corner, has no inverted quad and passes "
                                       "--min-quality and --max-edge-ratio."),
    min_quality: float = typer.Option(QUALITY.min_sj, "--min-quality", help="--template: smallest acceptable min scaled Jacobian."),
    max_edge_ratio: float = typer.Option(QUALITY.max_edge_ratio, "--max-edge-ratio", help="--template: largest acceptable "
                                         "longest/shortest edge of a quad."),
    band: float = typer.Option(QUALITY.band, "--band", help="--template: when the mesh falls short of min scaled Jacobian "
                               f"{QUALITY.good_sj:g}, place the first following mesh whose utility is within this fraction "
                               "of its utility and that reaches it (0: the ranked mesh as is)."),
    tie_break: str = typer.Option(DEFAULT_TIE_BREAK, "--tie-break", metavar="geometry|id", help="--template: " + TIE_BREAK_HELP),
) -> None:
    """Mesh a region with quads of about --size: the best of one template and every decomposition.

    Candidates: the region as one catalogue template, and split into patches at its concave
    corners and around its holes (continuations, bisectors, recursive, radial, fillets: also from the ends of a rounded inner corner); each is meshed
    with one integer program for all side counts, and the best is kept by one rule (no fold,
    corners, area, quality floor, size conformity, quality band, quality, size fit, irregular
    vertices, fewer patches); the rule that decided and the runner-up are printed. Corners are judged at
    the size (wiggles shorter than about it are no corners). A layout file ({points, patches}) is meshed as that layout. Several
    regions (or --out-dir) mesh in bulk. Exit status 3 when a mesh folds or misses a corner (the
    files are written anyway).
    """
    template_opts = {"--internal": internal is not None, "--points": points is not None, "--rank": rank_ != 1,
                     "--require-valid": require_valid, "--min-quality": min_quality != QUALITY.min_sj,
                     "--max-edge-ratio": max_edge_ratio != QUALITY.max_edge_ratio, "--band": band != QUALITY.band,
                     "--tie-break": tie_break != DEFAULT_TIE_BREAK}
    check_outputs(out_path, png, svg, fmt)
    writing = MeshOutput(fmt, msh_version, not ascii_, element_type, order, serendipity, extrude, layers, grading)
    drawing = PictureOutput(parse_png_size(png_size), dpi, color, histogram)
    if size is not None and not (size > 0 and size < float("inf")):
        raise InputError(f"must be a positive length, got {size:g}", "--size")
    if sides is not None and size is not None:
        raise InputError("give either --sides or --size, not both", "--size")
    if not budget > 0:
        raise InputError(f"must be a positive number of seconds, got {budget:g}", "--budget")
    if size_field is not None:
        for opt, given in (("--size", size is not None), ("--divisions", divisions is not None), ("--sides", sides is not None),
                           ("--sides-file", sides_file is not None), ("--template", template)):
            if given:
                raise InputError(f"give --size-field or {opt}, not both", "--size-field")
        size = load_field(size_field)
    if template:
        for opt, given in (("--size", size is not None), ("--divisions", divisions is not None),
                           ("--sides", sides is not None), ("--auto-size", auto_size), ("--search", search != "best"),
                           ("--sides-file", sides_file is not None), ("--strategy", strategy is not None),
                           ("--out-dir", out_dir is not None), ("--png-size/--dpi/--color/--histogram",
                                                                    drawing != PictureOutput())):
            if given:
                raise InputError("does not apply with --template (the template is placed as is)", opt)
        if len(regions) != 1:
            raise InputError("--template meshes one region at a time", "REGION")
        _mesh_template(regions[0], writing, catalogue=catalogue, internal=internal, lattice=lattice, points=points, rank_=rank_,
                       out_path=out_path, png=png, svg=svg, require_valid=require_valid, min_quality=min_quality,
                       max_edge_ratio=max_edge_ratio, band=band, tie_break=tie_break, corner_angle=corner_angle,
                       as_json=as_json)
        return
    for opt, given in template_opts.items():
        if given:
            raise InputError("applies with --template only", opt)
    names = None
    if strategy is not None:
        known = later.pipeline.strategy_names()
        names = [n.strip() for n in strategy.split(",") if n.strip()]
        bad = [n for n in names if n not in known]
        if bad or not names:
            raise InputError(f"expected names among {', '.join(known)}, got {strategy!r}", "--strategy")
    angle = _corner_angle(corner_angle)
    enable_compile_cache()
    cat, lat = _open_catalogue(catalogue), later.api.load_lattice(lattice)
    for opt, given in (("--size", size is not None), ("--sides", sides is not None), ("--sides-file", sides_file is not None)):
        if divisions is not None and given:
            raise InputError(f"give --divisions or {opt}, not both", "--divisions")
    options = dict(size=size, divisions=divisions, catalogue=cat, lattice=lat, strategies=names, budget_s=budget)
    if auto_size:
        options["auto_size"] = True
    if search != "best":
        if search not in SEARCHES:
            raise InputError(f"expected one of {', '.join(SEARCHES)}, got {search!r}", "--search")
        options["search"] = search
    if len(regions) > 1 or out_dir is not None:
        for opt, given in (("--out", out_path is not None), ("--png", png is not None), ("--svg", svg is not None),
                           ("--sides", sides is not None), ("--sides-file", sides_file is not None),
                           ("--json", as_json)):
            if given:
                raise InputError("is for one region; with several use --out-dir", opt)
        _mesh_many(regions, out_dir, writing, angle, options, jobs, skip_bad, resume,
                   budget if region_budget is None else region_budget, dask or None)
        return
    for opt, given in (("--resume", resume), ("--region-budget", region_budget is not None)):
        if given:
            raise InputError("is for many regions (--out-dir)", opt)
    _mesh_one(regions[0], angle, options, sides, sides_file, out_path, png, svg, as_json, writing, drawing)


def check_outputs(out: str | os.PathLike | None = None, png: str | os.PathLike | None = None,
                  svg: str | os.PathLike | None = None, fmt: str | None = None) -> None:
    """Refuse unsupported output suffixes before any work is done (:class:`InputError`, where
    is the option): ``out`` a mesh file (.vtk .vtu .obj .msh .json), ``png`` a .png file,
    ``svg`` a .svg file."""
    if out is not None:
        try:
            mesh_format(out, fmt)
        except InputError as e:
            if e.where == "--format":
                raise
            raise InputError(f"{e}", "--out") from None
    for opt, path, suffix in (("--png", png, ".png"), ("--svg", svg, ".svg")):
        if path is not None and Path(path).suffix.lower() != suffix:
            raise InputError(f"{path}: picture file must end in {suffix}", opt)


def _write(m, out_path, png, svg, draw, writing=None) -> dict:
    """Write the mesh ``m`` (a QuadMesh) to ``out_path`` (as ``writing`` says) and its pictures
    (``draw(picture path)``) to ``png``/``svg``, each given one; ``{option: path written}``."""
    written = {}
    if out_path is not None:
        written["out"] = str(write_mesh(out_path, m, writing))
    for key, pic in (("png", png), ("svg", svg)):
        if pic is not None:
            written[key] = str(draw(pic))
    return written


def _load_region(path: Path, corner_angle: float):
    """A shape or layout file, read (:func:`_quietly`)."""
    return _quietly(load_region, path, corner_angle=corner_angle)


def _mesh_one(path: Path, angle: float, options: dict, sides, sides_file, out_path, png, svg, as_json, writing,
              drawing) -> None:
    region = _load_region(path, angle)
    is_layout = not isinstance(region, (Shape, Model))  # (an assembly is meshed at a size, like a shape)
    counts = None
    if sides is not None:
        if is_layout:
            raise InputError("a layout takes edge counts per side with --sides-file", "--sides")
        counts = _parse_sides(sides, max(region.n_corners, 1))
    named = None
    if sides_file is not None:
        if not is_layout:
            raise InputError("edge counts per named side are for layout files; use --sides for a shape", "--sides-file")
        named = later.layout.load_counts(sides_file, later.layout.layout_sides(region))
    elif is_layout and options["size"] is None and options["divisions"] is None and not region.requested:
        options = {**options, "size": default_size(region)}
    defaulted = options["size"] is None and options["divisions"] is None and counts is None and not is_layout
    with _progress() as prog:
        task = prog.add_task("meshing candidates", total=None)
        try:
            m = later.pipeline.mesh(region, sides=counts, counts=named,
                                    progress=lambda d, t, name: prog.update(task, completed=d, total=t, description=name),
                                    **options)
        except InputError as e:
            if counts is not None:
                raise InputError(str(e), "--sides") from None
            raise
    written = _write(m, out_path, png, svg, lambda pic: later.plot.draw_quadmesh(
        pic, m, title=path.name, y_down=_y_down(path), **drawing.__dict__), writing)
    rec = report.mesh_record(path, m)
    if as_json:
        if counts is not None:
            rec["sides"] = counts
        print(json.dumps({**rec, "default_size": defaulted, "out": written.get("out"), "png": written.get("png"),
                          "svg": written.get("svg")}))
    else:
        report.print_mesh(out, path, m, rec, defaulted)
        for pic in written.values():
            out.print(f"wrote {pic}", markup=False, highlight=False)
    for w in rec["warnings"]:  # a poor mesh is never silent (also in --json's record)
        err.print(f"warning: {path}: {w}", markup=False, highlight=False, soft_wrap=True)
    if not m.valid:
        err.print(f"NOT A MESH OF THE REGION: {m.inverted} inverted quads, {m.missed_corners.shape[0]} corners without a "
                  "vertex; files were written anyway", markup=False, highlight=False)
        raise typer.Exit(EXIT_INVERTED)


def _y_down(path: Path) -> bool:
    """SVG coordinates run y down: pictures of SVG input are flipped to show it as drawn."""
    return str(path).split("#", 1)[0].lower().endswith(".svg")


def _mesh_many(regions: List[Path], out_dir: Optional[Path], writing, angle: float, options: dict, jobs, skip_bad,
               resume: bool, region_budget: float, dask: Optional[str]) -> None:
    """Bulk meshing (:func:`jaxmatch.batch.run`): every region read and checked first, then
    meshed by local workers or Dask; one mesh file each (as ``writing`` says) and
    DIR/summary.jsonl. Exit 3 when a mesh folds or misses a corner."""
    if out_dir is None:
        raise InputError("several regions need a folder for their meshes", "--out-dir")
    if dask is not None and jobs is not None:
        warnings.warn("--jobs ignored with --dask (the cluster's workers mesh the regions)", InputWarning)

    def warm() -> None:  # in this process, before the workers fork: they inherit what it loads
        try:
            later.pipeline.warm_up(options["catalogue"], options["lattice"])
        except Exception:  # noqa: BLE001 - only a head start: the regions themselves report any problem
            pass

    result = later.batch.run(regions, out_dir, writing, angle, options, jobs=jobs, skip_bad=skip_bad, resume=resume,
                             region_budget=region_budget, dask=dask, read=lambda p: _load_region(Path(p), angle),
                             progress=_progress(), warm=warm, initializer=options["catalogue"].reopen)
    if result.folded:
        raise typer.Exit(EXIT_INVERTED)


def _parse_sides(text: str, n_sides: int) -> list[int]:
    """``"4,2,4,2"`` -> ``[4, 2, 4, 2]``; InputError naming --sides otherwise."""
    try:
        counts = [int(tok) for tok in text.replace(" ", "").split(",")]
    except ValueError:
        raise InputError(f"expected comma-separated whole numbers like 4,2,4,2, got {text!r}", "--sides") from None
    if len(counts) != n_sides:
        what = "one total count (the shape has no corners)" if n_sides == 1 else f"one count per side ({n_sides} sides)"
        raise InputError(f"{len(counts)} counts given, expected {what}", "--sides")
    if any(c < 1 for c in counts):
        raise InputError(f"every count must be at least 1, got {text!r}", "--sides")
    return counts


def _mesh_template(shape: Path, writing, *, catalogue, internal, lattice, points, rank_, out_path, png, svg, require_valid,
                   min_quality, max_edge_ratio, band, tie_break, corner_angle, as_json) -> None:
    """``mesh --template``: the paper's answer, the best-ranked catalogue mesh placed as is
    (``jaxmatch.mesh(..., template=True)``), with the ranking's report (rank, utility, the
    quality band, the next valid mesh: the :class:`~jaxmatch.placement.choose.MeshChoice` in
    the mesh's ``detail``)."""
    tb = _tie_break(tie_break)
    if not -1.0 <= min_quality <= 1.0:
        raise InputError(f"must lie in [-1, 1] (a scaled Jacobian), got {min_quality:g}", "--min-quality")
    if not max_edge_ratio >= 1.0:
        raise InputError(f"must be at least 1, got {max_edge_ratio:g}", "--max-edge-ratio")
    if not 0.0 <= band <= 1.0:
        raise InputError(f"must lie in [0, 1] (a fraction of the utility), got {band:g}", "--band")
    enable_compile_cache()
    shp, lat, cat, ks = _inputs(shape, corner_angle, lattice, catalogue, internal)
    with _progress() as prog:
        task = prog.add_task("scoring meshes", total=None)
        m = later.pipeline.mesh(shp, template=True, catalogue=cat, lattice=lat, internal=ks, rank=rank_, points=points,
                                tie_break=tb, require_valid=require_valid, min_quality=min_quality,
                                max_edge_ratio=max_edge_ratio, band=band,
                                progress=lambda d, t, name: prog.update(task, completed=d, total=t))
    choice = m.detail
    title = report.panel_title(choice.rank, choice.match, choice.placement)
    written = _write(m, out_path, png, svg, lambda pic: later.plot.draw_in_shape(
        pic, shp, choice.ranking.annotation, [(title, m)], title=shape.name), writing)
    notes = report.template_notes(choice, min_quality=min_quality, max_edge_ratio=max_edge_ratio, band=band)
    if as_json:
        print(json.dumps(report.template_json(shape, choice, lattice_name=lat.name, tie_break=tb, min_quality=min_quality,
                                              max_edge_ratio=max_edge_ratio, band=band, written=written)))
        for note in notes:
            print(note, file=sys.stderr)
    else:
        report.print_template(out, err, shape, choice, lattice_name=lat.name, tie_break=tb, notes=notes, written=written)
    if not choice.valid:
        raise typer.Exit(EXIT_INVERTED)


@app.command()
def annotate(
    shape: Path = typer.Argument(..., metavar="SHAPE", help=SHAPE_HELP),
    catalogue: Optional[Path] = typer.Option(None, metavar="FILE", help=CATALOGUE_HELP + " Sets the default --points."),
    internal: Optional[str] = typer.Option(None, metavar="K|K1..K2", help="Mesh size scored (as in 'score'); sets the default --points."),
    points: Optional[int] = typer.Option(None, min=1, metavar="M", help=POINTS_HELP),
    corner_angle: float = typer.Option(DEFAULT_CORNER_ANGLE, metavar="DEGREES", help=ANGLE_HELP),
    size: Optional[float] = typer.Option(None, "--size", metavar="H", help="Judge the corners at this target edge "
                                         "length, as 'mesh --size H' does (wiggles shorter than about H are no corners)."),
    as_json: bool = typer.Option(False, "--json", help=JSON_HELP),
) -> None:
    """Print the s/x/v sequence 'score' would use for SHAPE (same options) and where each point lies (user coordinates)."""
    angle = _corner_angle(corner_angle)
    if size is not None and not (size > 0 and size < float("inf")):
        raise InputError(f"must be a positive length, got {size:g}", "--size")
    cat = _open_catalogue(catalogue)
    ks = _sizes(cat, internal)
    shp = _load(shape, angle)
    if size is not None:
        shp = canonical(shp, size, angle)
        err.print(f"corners judged at size {size:g}: {shp.n_corners}", highlight=False)
    if points is None:
        points = default_points(shp, max(b.n for b in cat.buckets(ks)))
    ann = annotate_shape(shp, points)
    xy = shp.to_user(ann.positions)
    polys, lengths = later.refine.side_polylines(shp), later.refine.side_lengths(shp)
    if as_json:
        print(json.dumps(report.annotation_json(shape, ann, xy, polys, lengths)))
        return
    report.print_annotation(out, shp.n_corners, ann, xy, polys, lengths)


@lattice_app.command("show")
def lattice_show(name: str = typer.Argument(..., metavar="NAME|FILE", help="fine, coarse, or a TOML path."),
                 as_json: bool = typer.Option(False, "--json", help="All 64 triples per type; null means -inf.")) -> None:
    """Show a lattice's weight table."""
    lat = later.lattice.load_lattice(name)
    if as_json:
        print(json.dumps(later.lattice.lattice_json(lat)))
    else:
        out.print(later.lattice.lattice_text(lat), markup=False)


@catalogue_app.command("build")
def catalogue_build(internal: str = typer.Option(..., metavar="K|K1..K2", help="Numbers of internal vertices to enumerate: K or K1..K2."),
                    out_path: Path = typer.Option(..., "--out", metavar="FILE", help="Output .npz file (written atomically)."),
                    workers: int = typer.Option(os.cpu_count() or 1, min=1, metavar="N", help="Processes used to expand each level."),
                    allow_large: bool = typer.Option(False, "--allow-large", help=f"Allow k > {cat_mod.LARGE_K} (hours and many GB).")) -> None:
    """Enumerate every catalogue mesh for the given numbers of internal vertices."""
    ks = cat_mod.parse_range(internal)
    if max(ks) > cat_mod.LARGE_K and not allow_large:
        raise InputError(f"k up to {max(ks)} would take hours or days (counts grow about 19x per k); "
                         f"pass --allow-large to try anyway", "--internal")
    with _progress() as prog:
        task = prog.add_task("closing vertices", total=max(ks))
        info = cat_mod.build(ks, out_path, workers=workers, progress=lambda j, states, found: (prog.update(
            task, completed=j, description=f"k={j}: {found} meshes"), err.print(f"k={j}: {found} meshes") if not err.is_terminal else None))
    cat = cat_mod.load(out_path)
    for k, d in cat.counts()["per_k"].items():
        err.print(f"k={k}: {d['meshes']} meshes ({d['up_to_rotation']} up to rotation only)")
    err.print(f"wrote {out_path}: {info['meshes']} meshes in {info['generate_s']:.1f} s")


@catalogue_app.command("info")
def catalogue_info(path: Path = typer.Argument(..., metavar="FILE", help="Catalogue file (.npz)."),
                   as_json: bool = typer.Option(False, "--json", help=JSON_HELP)) -> None:
    """Counts per number of internal vertices and per boundary length."""
    c = cat_mod.load(path).counts()
    if as_json:
        print(json.dumps(c))
        return
    report.print_catalogue_counts(out, c)


@catalogue_app.command("export")
def catalogue_export(path: Path = typer.Argument(..., metavar="FILE", help="Catalogue file (.npz)."),
                     mesh_id: str = typer.Option(..., "--id", metavar="ID", help="Mesh id, e.g. k2-045f3977f5d8 (from 'score')."),
                     fmt: str = typer.Option("json", "--format", metavar="json", help="Output format (only json).")) -> None:
    """Print one mesh: {id, internal_vertices, quads, boundary, triples}."""
    if fmt != "json":
        raise InputError(f"unknown format {fmt!r} (supported: json)", "--format")
    print(json.dumps(cat_mod.export(cat_mod.load(path), mesh_id)))


@app.command()
def label(shapes: Optional[list[Path]] = typer.Argument(None, help="Shape files to label (more can be drawn or dropped on the page)."),
          labels: Path = typer.Option(..., "--labels", metavar="FILE", help="Labels file (JSON lines, appended; the format scripts/tune_lattice.py reads)."),
          internal: Optional[str] = typer.Option(None, metavar="K|K1..K2", help=INTERNAL_HELP),
          size: Optional[float] = typer.Option(None, "--size", help="Show the meshes refined to edges of about this length (shape units)."),
          top: int = typer.Option(DEFAULT_TOP, min=1, max=9, help="Meshes shown per shape (1..9)."),
          port: int = typer.Option(8765, min=0, max=65535, help="Port (0: a free one, printed)."),
          host: str = typer.Option("127.0.0.1", help="Address to listen on (default: loopback only)."),
          lattice: str = typer.Option(DEFAULT_LATTICE, metavar="NAME|FILE", help=LATTICE_HELP),
          catalogue: Optional[Path] = typer.Option(None, help=CATALOGUE_HELP),
          corner_angle: float = typer.Option(DEFAULT_CORNER_ANGLE, metavar="DEGREES", help=ANGLE_HELP),
          tune: bool = typer.Option(False, "--tune", help="Tune the lattice on the labels file instead of serving; needs --out."),
          out_path: Optional[Path] = typer.Option(None, "--out", metavar="FILE", help="Tuned lattice TOML (default: <labels>.tuned.toml)."),
          epochs: int = typer.Option(10, min=0, help="Tuning passes over the labels.")) -> None:
    """A local web page to pick the preferred mesh for shapes; appends labels, tunes the lattice."""
    enable_compile_cache()
    later.label.run_label(shapes or [], labels, internal=internal, size=size, top=top, port=port, host=host, lattice=lattice,
              catalogue=catalogue, corner_angle=_corner_angle(corner_angle), tune=tune, out=out_path, epochs=epochs)


def _fail(line: str, code: int) -> None:
    """One unwrapped line on stderr, then exit."""
    print(" ".join(line.split()), file=sys.stderr)
    sys.exit(code)


def _interrupted(e: BaseException) -> bool:
    """A Ctrl-C that arrived wrapped (e.g. as SystemError from compiled code)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one line on stderr: ``warning: <file>: <what>`` (no source location)."""
    print(" ".join(f"warning: {message}".split()), file=sys.stderr)


def _no_type(ctx=None) -> None:
    return None


_METAVARS = {"path": "FILE", "str": "TEXT", "int": "INTEGER", "int range": "INTEGER", "float": "NUMBER", "float range": "NUMBER"}
"""Option value placeholders in help (typer's type labels -> conventional metavars)."""


def tidy_help(command) -> None:
    """Conventional help and usage for a typer/click command tree: flags show no ``<bool>``
    type (they take no value), options without a metavar show one from their type (``FILE``,
    ``TEXT``, ``INTEGER``, ``NUMBER``), arguments show as their metavar (``SHAPE``, ``SHAPES...``;
    optional ones in brackets) instead of ``{shape}`` and ``<list[Path]>``."""
    for param in getattr(command, "params", []):
        if getattr(param, "is_flag", False):
            param.display_type_rich = _no_type
        elif getattr(param, "param_type_name", "") == "option" and param.metavar is None and hasattr(param, "display_type"):
            def placeholder(ctx=None, _param=param):
                kind = str(_param.display_type(ctx)).strip("<>")
                return _METAVARS.get(kind, kind.split()[0].upper())

            param.display_type_rich = placeholder
        elif getattr(param, "param_type_name", "") == "argument":
            name = param.metavar or (param.name.upper() + ("..." if param.nargs != 1 else ""))
            param.metavar = name
            param.display_type_rich = _no_type
            param._usage_display_name = (lambda n=name: n) if param.required else (lambda n=name: f"[{n}]")
    get_help = getattr(command, "get_help_option", None)
    if get_help is not None and not getattr(get_help, "_tidy", False):
        def get_help_option(ctx, _orig=get_help):
            opt = _orig(ctx)
            if opt is not None:
                opt.display_type_rich = _no_type
            return opt

        get_help_option._tidy = True
        command.get_help_option = get_help_option
    for sub in getattr(command, "commands", {}).values():
        tidy_help(sub)


def main() -> None:
    """Console entry point: run the app; bad input -> one line on stderr, exit 2."""
    run_typer(app)


def _unmatchable_hint(err: Exception) -> str:
    """The options that change what an :class:`UnmatchableError` names (core messages name concepts)."""
    cause = getattr(err, "cause", None)
    if cause == "points":
        return f" (raise --points to at least {err.points})" if getattr(err, "points", None) else " (--points)"
    if cause == "internal":
        return " (--internal)"
    if cause == "forbidden":
        return " (--points, --internal, --lattice)"
    return ""


def run_typer(typer_app: typer.Typer) -> None:
    """Run a typer app (``jaxmatch`` or a script) with jaxmatch's exit conventions.

    InputError and usage errors: one line on stderr, exit 2; UnmatchableError: exit 4;
    Ctrl-C: "aborted", exit 130; anything unexpected: one line, exit 1 (``JAXMATCH_DEBUG=1``
    shows the traceback).
    """
    try:
        command = typer.main.get_command(typer_app)
        tidy_help(command)
        with warnings.catch_warnings():
            warnings.simplefilter("always", InputWarning)
            warnings.showwarning = _show_warning
            code = command(standalone_mode=False, prog_name="jaxmatch" if typer_app is app else None)  # typer.Exit(code) comes back
    except InputError as e:
        _fail(f"error: {e}", EXIT_BAD_INPUT)
    except UnmatchableError as e:
        _fail(f"no match: {e}{_unmatchable_hint(e)}", EXIT_UNMATCHABLE)
    except SolverError as e:  # the solver failed, the request may be fine
        _fail(f"solver error: {e} (the request was not judged infeasible; try another --size)", 1)
    except (typer.Abort, KeyboardInterrupt):
        _fail("aborted", 130)
    except ClickException as e:  # usage errors: unknown option, bad value, missing argument
        if type(e).__name__ == "NoArgsIsHelpError":
            print(e.format_message())
            sys.exit(0)
        _fail(f"error: {e.format_message()}", e.exit_code)
    except typer.Exit as e:
        if e.exit_code == 130:  # typer turns Ctrl-C into Exit(130)
            _fail("aborted", 130)
        sys.exit(e.exit_code)
    except Exception as e:  # anything unexpected: still one line
        if _interrupted(e):
            _fail("aborted", 130)
        if os.environ.get("JAXMATCH_DEBUG"):
            raise
        _fail(f"internal error: {type(e).__name__}: {e} (set JAXMATCH_DEBUG=1 for a traceback)", 1)
    if code == 130:  # typer turns Ctrl-C into Exit(130), returned in non-standalone mode
        _fail("aborted", 130)
    if isinstance(code, int) and code:
        sys.exit(code)


if __name__ == "__main__":
    main()
