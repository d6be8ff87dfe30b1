"""The ``jaxmatch`` command line (typer app only: parse, call the library, print).

Bad input ends with one line on stderr and exit status 2 (see :mod:`jaxmatch.errors`).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from jaxmatch.catalogue import store as cat_mod
from jaxmatch.errors import EXIT_BAD_INPUT, EXIT_INVERTED, EXIT_UNMATCHABLE, InputError, UnmatchableError

try:  # typer >= 0.2x vendors click as typer._click and no longer installs click
    from typer._click.exceptions import ClickException
except ImportError:  # pragma: no cover - older typer with click
    from click.exceptions import ClickException

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False, no_args_is_help=True,
                  help="Pick the best quadrilateral mesh from a catalogue for a planar shape.")
lattice_app = typer.Typer(no_args_is_help=True, help="Inspect lattice weight files.")
catalogue_app = typer.Typer(no_args_is_help=True, help="Build and inspect mesh catalogues.")
app.add_typer(lattice_app, name="lattice")
app.add_typer(catalogue_app, name="catalogue")

out = Console(soft_wrap=True, width=None if sys.stdout.isatty() else 120)
err = Console(stderr=True)


def _progress() -> Progress:
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    console=err, transient=True, disable=not err.is_terminal and not os.environ.get("JAXMATCH_PROGRESS"))


def enable_compile_cache() -> None:
    """JAX's persistent compilation cache, so a second run does not compile again."""
    import jax

    cache = Path(os.environ.get("JAXMATCH_CACHE", Path.home() / ".cache" / "jaxmatch")) / "xla"
    try:
        cache.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(cache))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    except Exception:  # a read-only home: run without the cache
        pass


def _inputs(shape: Optional[Path], corner_angle: float, lattice: str, catalogue: Optional[Path], internal: Optional[str]):
    """(shape or None, lattice, catalogue, k list or None): the inputs every scoring command reads."""
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.shape import load_shape

    shp = load_shape(shape, corner_angle=corner_angle) if shape is not None else None
    ks = cat_mod.parse_range(internal) if internal is not None else None
    return shp, load_lattice(lattice), _open_catalogue(catalogue), ks


def _open_catalogue(path: Optional[Path]):
    return cat_mod.load(path) if path is not None else cat_mod.default_catalogue()


TIE_BREAK_HELP = ("Order among equal utilities: 'geometry' places the tied meshes and prefers the higher min scaled "
                  "Jacobian, then fewer irregular internal vertices (beyond the paper); 'id' keeps the paper's "
                  "combinatorial order (fewer internal vertices, shorter boundary, id).")


def _tie_break(text: str) -> str:
    from jaxmatch.api import TIE_BREAKS

    if text not in TIE_BREAKS:
        raise InputError(f"expected one of {', '.join(TIE_BREAKS)}, got {text!r}", "--tie-break")
    return text


@app.command()
def score(
    shape: Path = typer.Argument(..., help="Shape file: JSON {boundary, corners} or text rows 'x y'."),
    catalogue: Optional[Path] = typer.Option(None, help="Catalogue file (default: the shipped k=0..5 catalogue)."),
    internal: Optional[str] = typer.Option(None, help="Mesh size: K or K1..K2 internal vertices. Without it all sizes compete, "
                                           "and larger meshes (more boundary vertices, more matched points) get larger raw utilities."),
    lattice: str = typer.Option("fine", help="Lattice: fine, coarse, or a TOML path."),
    top: int = typer.Option(5, min=1, help="How many meshes to show."),
    points: Optional[int] = typer.Option(None, min=1, help="Number m of annotated shape points (default: 2 x longest boundary)."),
    per_size: bool = typer.Option(False, "--per-size", help="Show the best --top meshes of each size k (utilities only compare within a size)."),
    corner_angle: float = typer.Option(30.0, help="Corner threshold (degrees from straight) when the shape lists no corners."),
    tie_break: str = typer.Option("geometry", "--tie-break", help=TIE_BREAK_HELP),
    png: Optional[Path] = typer.Option(None, "--png", help="Also draw the listed meshes placed in the shape, side by side, to this .png file."),
    svg: Optional[Path] = typer.Option(None, "--svg", help="Same picture as --png, as .svg."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object instead of a table."),
    devices: Optional[int] = typer.Option(None, min=1, help="Shard the scoring over N JAX devices (GPUs, or N CPU host devices)."),
    exhaustive: bool = typer.Option(False, "--exhaustive", help="Score every mesh instead of the pruned top-K search (same results, slower)."),
) -> None:
    """Rank catalogue meshes for SHAPE by the paper's modified LCS utility."""
    if devices is not None:
        from jaxmatch.scoring.bulk import configure_host_devices

        configure_host_devices(devices)  # before JAX is imported
    from jaxmatch.api import rank
    from jaxmatch.scoring.rank import ranking_json
    from jaxmatch.placement.choose import check_outputs, draw_placements, panel_title, place_top

    check_outputs(png=png, svg=svg)
    tb = _tie_break(tie_break)
    enable_compile_cache()
    shp, lat, cat, ks = _inputs(shape, corner_angle, lattice, catalogue, internal)
    with _progress() as prog:
        task = prog.add_task("scoring meshes", total=None)
        ranking = rank(shp, cat, lat, internal=ks, top=top, points=points, per_size=per_size, tie_break=tb,
                       prune=not exhaustive, devices=devices,
                       progress=lambda d, t: prog.update(task, completed=d, total=t))
    written = []
    if png is not None or svg is not None:
        placed = place_top(shp, ranking, cat)
        items = [(panel_title(i, r), pl) for i, (r, pl) in enumerate(zip(ranking.results, placed), 1)]
        head = f"{shape.name}: {'best per size' if per_size else f'top {len(items)}'}"
        written = [str(draw_placements(p, shp, ranking.annotation, items, title=head)) for p in (png, svg) if p is not None]
    if as_json:
        print(json.dumps(ranking_json(str(shape), ranking, lat.name, tb)))
        for w in written:
            print(f"wrote {w}", file=sys.stderr)
        return
    out.print(f"shape [bold]{shape}[/]: {len(ranking.annotation.codes)} points [cyan]{ranking.annotation.symbols}[/]")
    skipped = f", {ranking.pruned} skipped by the bound" if ranking.pruned else ""
    out.print(f"lattice {lat.name}; {ranking.scored} meshes, {ranking.unmatchable} unmatchable{skipped}")
    table = Table(title="best per size" if per_size else f"top {top}")
    for col in ("rank", "mesh id", "internal", "boundary", "utility", "rotation", "reflected"):
        table.add_column(col, justify="right" if col not in ("mesh id",) else "left", no_wrap=True, min_width=15 if col == "mesh id" else None)
    for i, r in enumerate(ranking.results, 1):
        table.add_row(str(i), r.mesh_id, str(r.internal_vertices), str(r.boundary_length), f"{r.utility:g}",
                      str(r.rotation), "yes" if r.reflected else "no")
    out.print(table)
    for w in written:
        out.print(f"wrote {w}", markup=False, highlight=False)


@app.command("score-many")
def score_many(
    shapes: list[Path] = typer.Argument(..., help="Shape files."),
    out_path: Path = typer.Option(..., "--out", help="Results as JSON lines (one per shape, the fields of score --json), written atomically."),
    catalogue: Optional[Path] = typer.Option(None, help="Catalogue file (default: the shipped k=0..5 catalogue)."),
    internal: Optional[str] = typer.Option(None, help="Mesh size: K or K1..K2 internal vertices."),
    lattice: str = typer.Option("fine", help="Lattice: fine, coarse, or a TOML path."),
    top: int = typer.Option(5, min=1, help="How many meshes per shape."),
    points: Optional[int] = typer.Option(None, min=1, help="Number m of annotated points per shape."),
    per_size: bool = typer.Option(False, "--per-size", help="The best --top meshes of each size k."),
    corner_angle: float = typer.Option(30.0, help="Corner threshold in degrees."),
    tie_break: str = typer.Option("id", "--tie-break", help=TIE_BREAK_HELP),
    devices: Optional[int] = typer.Option(None, min=1, help="Shard the scoring over N JAX devices."),
    coordinator: Optional[str] = typer.Option(None, help="HOST:PORT of process 0: share the shapes among --num-processes "
                                              "processes (jax.distributed; start the same command once per process)."),
    num_processes: int = typer.Option(1, min=1, help="Processes sharing the run (with --coordinator)."),
    process_id: int = typer.Option(0, min=0, help="This process's id, 0..N-1 (with --coordinator); process 0 writes --out."),
) -> None:
    """Score many shapes in one run (bulk mode); every shape is read and checked before scoring."""
    cluster = _cluster(coordinator, num_processes, process_id, devices)
    if devices is not None:
        from jaxmatch.scoring.bulk import configure_host_devices

        configure_host_devices(devices)
    from jaxmatch.scoring.bulk import write_jsonl
    from jaxmatch.api import rank
    from jaxmatch.scoring.rank import ranking_json
    from jaxmatch.shape import load_shape

    tb = _tie_break(tie_break)
    if out_path.suffix.lower() not in (".jsonl", ".json", ".ndjson"):
        raise InputError("results are JSON lines: use a .jsonl file", str(out_path))
    enable_compile_cache()
    loaded = [(p, load_shape(p, corner_angle=corner_angle)) for p in shapes]  # bad input fails before any work
    _, lat, cat, ks = _inputs(None, corner_angle, lattice, catalogue, internal)
    from jaxmatch.scoring import distributed

    distributed.initialize(cluster)
    mine = distributed.share(len(loaded), cluster)
    records = []
    with _progress() as prog:
        task = prog.add_task("shapes", total=len(mine))
        for i in mine:
            p, shp = loaded[i]
            ranking = rank(shp, cat, lat, internal=ks, top=top, points=points, per_size=per_size, tie_break=tb,
                           prune=True, devices=devices)
            records.append(ranking_json(str(p), ranking, lat.name, tb))
            prog.advance(task)
    records = distributed.gather_records(records, mine, len(loaded), cluster)
    if cluster.process_id == 0:
        write_jsonl(out_path, records)
        err.print(f"wrote {out_path}: {len(records)} shapes", markup=False, highlight=False)
    distributed.shutdown(cluster)


def _cluster(coordinator: Optional[str], num_processes: int, process_id: int, devices: Optional[int]):
    """The :class:`jaxmatch.scoring.distributed.Cluster` of score-many's options (one process without --coordinator)."""
    from jaxmatch.scoring.distributed import Cluster, make_cluster

    if coordinator is None:
        if num_processes != 1 or process_id != 0:
            raise InputError("needs --coordinator HOST:PORT", "--num-processes/--process-id")
        return Cluster("", 1, 0)
    if devices is not None:
        raise InputError("use either --devices or --coordinator, not both", "--devices")
    try:
        return make_cluster(coordinator, num_processes, process_id)
    except InputError as e:
        raise InputError(e.problem, "--coordinator/--num-processes/--process-id") from None


@app.command()
def mesh(
    shape: Path = typer.Argument(..., help="Shape file: JSON {boundary, corners} or text rows 'x y'."),
    catalogue: Optional[Path] = typer.Option(None, help="Catalogue file (default: the shipped k=0..5 catalogue)."),
    internal: Optional[str] = typer.Option(None, help="Mesh size: K or K1..K2 internal vertices (default: all sizes compete)."),
    lattice: str = typer.Option("fine", help="Lattice: fine, coarse, or a TOML path."),
    points: Optional[int] = typer.Option(None, min=1, help="Number m of annotated shape points (default: 2 x longest boundary)."),
    rank_: int = typer.Option(1, "--rank", min=1, help="Place the R-th ranked mesh."),
    out_path: Optional[Path] = typer.Option(None, "--out", help="Mesh file: .vtk .vtu .obj .msh or .json (written atomically)."),
    png: Optional[Path] = typer.Option(None, "--png", help="Picture of the placed mesh in the shape (.png)."),
    svg: Optional[Path] = typer.Option(None, "--svg", help="Picture of the placed mesh in the shape (.svg)."),
    require_valid: bool = typer.Option(False, "--require-valid", help="Walk down the ranking (up to 50 meshes) and place the first "
                                       "mesh that embeds with zero inverted quads."),
    tie_break: str = typer.Option("geometry", "--tie-break", help=TIE_BREAK_HELP),
    corner_angle: float = typer.Option(30.0, help="Corner threshold (degrees from straight) when the shape lists no corners."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Rank like 'score', place the R-th mesh in SHAPE and write it (and/or a picture).

    Exit status 3 when the placed mesh has inverted quads (the files are written anyway).
    """
    from jaxmatch.io.meshfile import write_mesh
    from jaxmatch.placement.choose import DEFAULT_WALK, check_outputs, choose_mesh, draw_placements, panel_title

    check_outputs(out_path, png, svg)
    tb = _tie_break(tie_break)
    enable_compile_cache()
    shp, lat, cat, ks = _inputs(shape, corner_angle, lattice, catalogue, internal)
    with _progress() as prog:
        task = prog.add_task("scoring meshes", total=None)
        choice = choose_mesh(shp, cat, lat, rank=rank_, internal=ks, points=points, tie_break=tb,
                             require_valid=require_valid, walk=DEFAULT_WALK,
                             progress=lambda d, t: prog.update(task, completed=d, total=t))
    m, pl, ann = choice.match, choice.placement, choice.ranking.annotation
    written = {}
    if out_path is not None:
        written["out"] = str(write_mesh(out_path, pl))
    for key, path in (("png", png), ("svg", svg)):
        if path is not None:
            written[key] = str(draw_placements(path, shp, ann, [(panel_title(choice.rank, m), pl)], title=shape.name))
    notes = []
    if choice.rank != choice.requested_rank:
        notes.append(f"mesh #{choice.requested_rank} folds; placed #{choice.rank} {m.mesh_id}, the first mesh of the ranking "
                     "that embeds without inverted quads")
    if not choice.valid:
        notes.append(f"FOLDED: {pl.inverted} of {pl.mesh.n_quads} quads of mesh #{choice.rank} {m.mesh_id} are inverted "
                     "(a corner of zero or negative area: the placed mesh folds over itself or is degenerate); "
                     "files were written anyway")
        if choice.alternative is not None:
            ar, am, apl = choice.alternative
            notes.append(f"next-ranked mesh that embeds without folds: #{ar} {am.mesh_id} (utility {am.utility:g}, "
                         f"min scaled Jacobian {apl.min_scaled_jacobian:.3f}); use --rank {ar} or --require-valid")
        else:
            last = choice.requested_rank + choice.searched
            more = "" if choice.searched >= DEFAULT_WALK - 1 else " (no further meshes match)"
            notes.append(f"no mesh ranked #{choice.requested_rank}..#{last} embeds without folds{more}")
    if as_json:
        alt = choice.alternative
        print(json.dumps({
            "shape": str(shape), "sequence": ann.symbols, "lattice": lat.name, "tie_break": tb,
            "rank": choice.rank, "requested_rank": choice.requested_rank, "mesh_id": m.mesh_id,
            "internal_vertices": int(m.internal_vertices), "boundary_length": int(m.boundary_length),
            "utility": float(m.utility), "rotation": int(m.rotation), "reflected": bool(m.reflected),
            "quads": int(pl.mesh.n_quads), "min_scaled_jacobian": pl.min_scaled_jacobian,
            "mean_scaled_jacobian": pl.mean_scaled_jacobian, "inverted": int(pl.inverted),
            "irregular": int(len(pl.irregular)), "area_ratio": pl.area_ratio, "valid": choice.valid,
            "alignment": [int(i) for i in pl.alignment],
            "out": written.get("out"), "png": written.get("png"), "svg": written.get("svg"),
            "next_valid": None if alt is None else {"rank": alt[0], "mesh_id": alt[1].mesh_id, "utility": float(alt[1].utility),
                                                    "min_scaled_jacobian": alt[2].min_scaled_jacobian},
        }))
        for note in notes:
            print(note, file=sys.stderr)
    else:
        out.print(f"shape [bold]{shape}[/]: {len(ann.codes)} points [cyan]{ann.symbols}[/]")
        out.print(f"lattice {lat.name}; scored {choice.ranking.scored} meshes, {choice.ranking.unmatchable} unmatchable; "
                  f"ties broken by {tb}", highlight=False)
        out.print(f"mesh #{choice.rank} {m.mesh_id}: {m.internal_vertices} internal, {m.boundary_length} boundary vertices, "
                  f"{pl.mesh.n_quads} quads, {len(pl.irregular)} irregular internal; utility {m.utility:g}, rotation {m.rotation}, "
                  f"{'reflected' if m.reflected else 'not reflected'}", markup=False, highlight=False)
        out.print(f"scaled Jacobian: min {pl.min_scaled_jacobian:.3f}, mean {pl.mean_scaled_jacobian:.3f}; "
                  f"inverted quads: {pl.inverted}; mesh area / shape area {pl.area_ratio:.3f}", markup=False, highlight=False)
        for note in notes:
            out.print(note, markup=False, highlight=False)
        for path in written.values():
            out.print(f"wrote {path}", markup=False, highlight=False)
    if not choice.valid:
        raise typer.Exit(EXIT_INVERTED)


@app.command()
def annotate(
    shape: Path = typer.Argument(..., help="Shape file."),
    points: Optional[int] = typer.Option(None, min=1, help="Number m of points (default: for the default catalogue)."),
    corner_angle: float = typer.Option(30.0, help="Corner threshold in degrees."),
    as_json: bool = typer.Option(False, "--json"),
) -> None:
    """Print the shape's s/x/v sequence and where each point lies (user coordinates)."""
    from jaxmatch.shape import annotate as annotate_shape, default_points, load_shape

    shp = load_shape(shape, corner_angle=corner_angle)
    m = points if points is not None else default_points(shp, max(_open_catalogue(None).lengths))
    ann = annotate_shape(shp, m)
    xy = shp.to_user(ann.positions)
    if as_json:
        print(json.dumps({"shape": str(shape), "sequence": ann.symbols,
                          "points": [{"index": i, "symbol": s, "x": float(p[0]), "y": float(p[1]), "side": int(sd)}
                                     for i, (s, p, sd) in enumerate(zip(ann.symbols, xy, ann.side))]}))
        return
    out.print(ann.symbols)
    table = Table()
    for col in ("index", "symbol", "x", "y", "side"):
        table.add_column(col, justify="right")
    for i, (s, p, sd) in enumerate(zip(ann.symbols, xy, ann.side)):
        table.add_row(str(i), s, f"{p[0]:.6g}", f"{p[1]:.6g}", str(int(sd)))
    out.print(table)


@lattice_app.command("show")
def lattice_show(name: str = typer.Argument(..., help="fine, coarse, or a TOML path."),
                 as_json: bool = typer.Option(False, "--json", help="All 64 triples per type; null means -inf.")) -> None:
    """Show a lattice's weight table."""
    from jaxmatch.scoring.lattice import lattice_json, lattice_text, load_lattice

    lat = load_lattice(name)
    if as_json:
        print(json.dumps(lattice_json(lat)))
    else:
        out.print(lattice_text(lat), markup=False)


@catalogue_app.command("build")
def catalogue_build(internal: str = typer.Option(..., help="K or K1..K2."),
                    out_path: Path = typer.Option(..., "--out", help="Output .npz file (written atomically)."),
                    workers: int = typer.Option(os.cpu_count() or 1, min=1, help="Processes used to expand each level."),
                    allow_large: bool = typer.Option(False, "--allow-large", help=f"Allow k > {cat_mod.LARGE_K} (hours and many GB).")) -> None:
    """Enumerate every catalogue mesh for the given numbers of internal vertices."""
    ks = cat_mod.parse_range(internal)
    if max(ks) > cat_mod.LARGE_K and not allow_large:
        raise InputError(f"k up to {max(ks)} would take hours or days (counts grow about 15x per k); "
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
def catalogue_info(path: Path = typer.Argument(...), as_json: bool = typer.Option(False, "--json")) -> None:
    """Counts per number of internal vertices and per boundary length."""
    c = cat_mod.load(path).counts()
    if as_json:
        print(json.dumps(c))
        return
    out.print(f"format version {c['format_version']}")
    t = Table(title="per k")
    for col in ("k", "meshes (up to rotation and reflection)", "up to rotation only"):
        t.add_column(col, justify="right")
    for k, d in c["per_k"].items():
        t.add_row(k, str(d["meshes"]), str(d["up_to_rotation"]))
    out.print(t)
    t2 = Table(title="per boundary length")
    t2.add_column("n", justify="right")
    t2.add_column("meshes", justify="right")
    for n, cnt in c["per_boundary_length"].items():
        t2.add_row(n, str(cnt))
    out.print(t2)


@catalogue_app.command("export")
def catalogue_export(path: Path = typer.Argument(...), mesh_id: str = typer.Option(..., "--id"),
                     fmt: str = typer.Option("json", "--format", help="json")) -> None:
    """Print one mesh: {id, internal_vertices, quads, boundary, triples}."""
    if fmt != "json":
        raise InputError(f"unknown format {fmt!r} (supported: json)", "--format")
    print(json.dumps(cat_mod.export(cat_mod.load(path), mesh_id)))


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
        code = typer_app(standalone_mode=False)  # a command's typer.Exit(code) comes back as the return value
    except InputError as e:
        _fail(f"error: {e}", EXIT_BAD_INPUT)
    except UnmatchableError as e:
        _fail(f"no match: {e}{_unmatchable_hint(e)}", EXIT_UNMATCHABLE)
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
