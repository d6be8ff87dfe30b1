"""Text reports of the ``jaxmatch`` commands: the tables, lines and JSON records they print.

The command line (:mod:`jaxmatch.cli`) parses, calls the library and hands the results here;
nothing here computes a mesh. Printing goes to the rich consoles the caller passes (``out`` for
the answer, ``err`` for warnings and advice), with the same markup as the commands always had.
"""

from __future__ import annotations

from jaxmatch.defaults import QUALITY
from jaxmatch.lazy import Later

__all__ = ["annotation_json", "mesh_record", "panel_title", "print_annotation", "print_catalogue_counts",
           "print_mesh", "print_ranking", "print_template", "template_json", "template_notes"]

_later = Later(choose="jaxmatch.placement.choose", rich_table="rich.table")
"""Loaded when a report needs them: the placement stack's figures and constants for a template
(loaded already by then; not at start-up) and rich's tables (not for ``jaxmatch mesh``, whose
start-up loads no table code)."""


def say(console, text: str) -> None:
    """One line as is (no markup, no highlighting)."""
    console.print(text, markup=False, highlight=False)


# ---------------------------------------------------------------------------------------------
# score


def panel_title(rank: int, match, placement=None) -> str:
    """``"#1 k5-b2b65fa5f3b0 (utility 24, rot 0, corners 4/4)"``: title line for a picture panel
    (the full mesh id, so that it can be copied into ``catalogue export --id``; with the
    :class:`~jaxmatch.placement.embed.Placement`, the orientation placed and the corners kept)."""
    if placement is None:
        refl = ", reflected" if match.reflected else ""
        return f"#{rank} {match.mesh_id} (utility {match.utility:g}, rot {match.rotation}{refl})"
    refl = ", reflected" if placement.reflected else ""
    corners = f", corners {placement.kept_corners}/{placement.corners}" if placement.corners else ""
    return f"#{rank} {match.mesh_id} (utility {match.utility:g}, rot {placement.rotation}{refl}{corners})"


def print_ranking(out, shape, ranking, lattice_name: str, *, top: int, per_size: bool, all_sizes: bool,
                  written=()) -> None:
    """``jaxmatch score``'s table: the annotation, the counts, one row per ranked mesh, the note on
    comparing sizes (``all_sizes``: no ``--internal``, not ``--per-size``) and the files written."""
    out.print(f"shape [bold]{shape}[/]: {len(ranking.annotation.codes)} points [cyan]{ranking.annotation.symbols}[/]")
    skipped = f", {ranking.pruned} skipped by the bound" if ranking.pruned else ""
    out.print(f"lattice {lattice_name}; {ranking.scored} meshes, {ranking.unmatchable} unmatchable{skipped}")
    table = _later.rich_table.Table(title="best per size" if per_size else f"top {top}")
    for col in ("rank", "mesh id", "internal", "boundary", "utility", "rotation", "reflected"):
        table.add_column(col, justify="right" if col not in ("mesh id",) else "left", no_wrap=True, min_width=15 if col == "mesh id" else None)
    for i, r in enumerate(ranking.results, 1):
        table.add_row(str(i), r.mesh_id, str(r.internal_vertices), str(r.boundary_length), f"{r.utility:g}",
                      str(r.rotation), "yes" if r.reflected else "no")
    out.print(table)
    if all_sizes:
        say(out, "all sizes compete here by raw utility, which grows with the mesh (more matched points); "
                 "'jaxmatch mesh' without --internal chooses the size by the fit of each size's best mesh "
                 "(corners kept, folds, quality, area, then fewer quads); --per-size compares sizes")
    for w in written:
        say(out, f"wrote {w}")


# ---------------------------------------------------------------------------------------------
# mesh


def mesh_record(path, m, seconds: float | None = None) -> dict:
    """The JSON record of one meshed region (``mesh --json``, a line of ``summary.jsonl``): the
    :meth:`~jaxmatch.meshing.result.QuadMesh.summary` and every candidate tried."""
    rec = {"shape": str(path), **m.summary()}
    rec["candidates"] = [{"name": c.name, "note": c.note, **({} if c.mesh is None else {
        "patches": c.mesh.n_patches, "quads": int(c.mesh.quads.shape[0]), "min_scaled_jacobian": c.mesh.min_scaled_jacobian,
        "mean_scaled_jacobian": c.mesh.mean_scaled_jacobian, "inverted": c.mesh.inverted,
        "irregular": int(c.mesh.irregular.size), "sides_off_size": len(c.mesh.sides_off_size(QUALITY.size_tol))})}
        for c in m.tried]
    if seconds is not None:
        rec["seconds"] = round(seconds, 4)
    return rec


def _patches(n: int) -> str:
    return f"{n} patch" if n == 1 else f"{n} patches"


def print_mesh(out, path, m, rec: dict, defaulted: bool) -> None:
    """``jaxmatch mesh``'s text: one line per candidate, the choice and its rule, the size, the
    figures of the mesh chosen (``rec``: :func:`mesh_record`; ``defaulted``: the size was the
    default)."""
    for c in rec["candidates"]:
        if "quads" in c:
            say(out, f"{c['name']}: {_patches(c['patches'])}, {c['quads']} quads, SJ min {c['min_scaled_jacobian']:.3f} "
                     f"mean {c['mean_scaled_jacobian']:.3f}, {c['inverted']} inverted, {c['irregular']} irregular, "
                     f"{c['sides_off_size']} sides off the size")
        else:
            say(out, f"{c['name']}: not meshed ({c['note']})")
    unmeshed = any(c.name == m.runner_up and c.mesh is None for c in m.tried)
    decided = (f" (rule that decided: {m.rule}; runner-up {m.runner_up}"
               f"{', not meshed: at its best' if unmeshed else ''})") if m.rule else ""
    say(out, f"chosen: {m.chosen}{decided}")
    if m.field is not None:
        say(out, f"size field (mean edge on the outline {m.size:.4g}): {100 * m.field_share:.0f}% of the edges within [0.5, 1.6] x the "
                 f"field at their midpoints, worst side {100 * m.size_deviation:.0f}% off its integral of 1 / size")
    elif m.size:
        how = " (default: perimeter / 32)" if defaulted else ""
        say(out, f"size {m.size:.4g}{how}: mean edge {m.mean_edge_length:.4g}, worst side {100 * m.size_deviation:.0f}% "
                 "off length / size")
    say(out, f"{path}: {_patches(m.n_patches)}, {rec['quads']} quads, {rec['vertices']} vertices, {rec['irregular']} irregular "
             f"internal (Euler's bound {rec['irregular_bound']}); scaled Jacobian min {rec['min_scaled_jacobian']:.3f} mean "
             f"{rec['mean_scaled_jacobian']:.3f}; inverted quads: {rec['inverted']}; corners kept: "
             f"{rec['corners'] - rec['missed_corners']} of {rec['corners']}; mesh area / region area {rec['area_ratio']:.6f}")


# ---------------------------------------------------------------------------------------------
# mesh --template (the paper's answer: a MeshChoice)


def template_notes(choice, *, min_quality: float, max_edge_ratio: float, band: float) -> list[str]:
    """The notes on a :class:`~jaxmatch.placement.choose.MeshChoice`: the size chosen (first,
    when it was), the quality band, the walk down the ranking, missed corners, folds, low
    quality and the next acceptable mesh."""
    choose = _later.choose
    m, pl = choice.match, choice.placement
    floor = f"min scaled Jacobian >= {min_quality:g}, max edge ratio <= {max_edge_ratio:g}"
    notes = []
    if choice.size is not None:
        notes.append(choice.size.describe())
    if choice.passed_over is not None:
        pr, pm, ppl = choice.passed_over
        how = "in another orientation or alignment, " if choice.reoriented else ""
        notes.append(f"quality band: mesh #{pr} {pm.mesh_id} (utility {pm.utility:g}) places with min scaled Jacobian "
                     f"{ppl.min_scaled_jacobian:.3f}, below {QUALITY.good_sj:g}; placed #{choice.rank} {m.mesh_id} ({how}utility "
                     f"{choice.utility:g}, within {band:g} of it) with {pl.min_scaled_jacobian:.3f} (--band 0 places #{pr})")
    elif choice.rank != choice.requested_rank:
        notes.append(f"mesh #{choice.requested_rank} is not a good mesh of the shape; placed #{choice.rank} {m.mesh_id}, the first "
                     f"mesh of the ranking that keeps every corner, has no inverted quad and {floor}")
    if pl.missed_corners.shape[0]:
        where = ", ".join(f"({x:.6g}, {y:.6g})" for x, y in pl.missed_corners)
        notes.append(f"MISSED CORNERS: {pl.missed_corners.shape[0]} of {pl.corners} corners of the shape get no vertex of mesh "
                     f"#{choice.rank} {m.mesh_id}: {where} (the mesh cuts across them)")
    if pl.inverted:
        notes.append(f"FOLDED: {pl.inverted} of {pl.mesh.n_quads} quads of mesh #{choice.rank} {m.mesh_id} are inverted "
                     "(a corner of zero or negative area: the placed mesh folds over itself or is degenerate)")
    if choice.valid and not choice.good:
        notes.append(f"LOW QUALITY: mesh #{choice.rank} {m.mesh_id} has min scaled Jacobian {pl.min_scaled_jacobian:.3f} and max "
                     f"edge ratio {pl.max_edge_ratio:.2f}; the floor is {floor}")
    if not choice.valid:
        notes.append("files were written anyway")
    if not choice.good:
        if choice.alternative is not None:
            ar, am, apl = choice.alternative
            notes.append(f"next-ranked mesh that keeps every corner, has no inverted quad and {floor}: #{ar} {am.mesh_id} "
                         f"(utility {am.utility:g}, min scaled Jacobian {apl.min_scaled_jacobian:.3f}); use --rank {ar} or --require-valid")
        else:
            last = choice.requested_rank + choice.searched
            more = "" if choice.searched >= choose.DEFAULT_WALK - 1 else " (no further meshes match)"
            notes.append(f"no mesh ranked #{choice.requested_rank}..#{last} keeps every corner, has no inverted quad and {floor}{more}")
    return notes


def template_json(shape, choice, *, lattice_name: str, tie_break: str, min_quality: float, max_edge_ratio: float,
                  band: float, written: dict) -> dict:
    """``mesh --template --json``: the ranking, the mesh placed and its fit, the size choice, the
    quality band and the next acceptable mesh (``written``: option -> file written)."""
    m, pl, ann, alt = choice.match, choice.placement, choice.ranking.annotation, choice.alternative
    return {
        "shape": str(shape), "sequence": ann.symbols, "lattice": lattice_name, "tie_break": tie_break,
        "rank": choice.rank, "requested_rank": choice.requested_rank, "mesh_id": m.mesh_id,
        "internal_vertices": int(m.internal_vertices), "boundary_length": int(m.boundary_length),
        "utility": choice.utility, "rotation": int(pl.rotation), "reoriented": choice.reoriented, "reflected": bool(pl.reflected),
        **_later.choose.fit_json(pl), "irregular": int(len(pl.irregular)), "good": choice.good,
        "min_quality": min_quality, "max_edge_ratio_allowed": max_edge_ratio,
        "alignment": [int(i) for i in pl.alignment],
        "size_choice": None if choice.size is None else choice.size.as_json(),
        "out": written.get("out"), "png": written.get("png"), "svg": written.get("svg"),
        "band": band,
        "passed_over": None if choice.passed_over is None else {
            "rank": choice.passed_over[0], "mesh_id": choice.passed_over[1].mesh_id,
            "utility": float(choice.passed_over[1].utility),
            "min_scaled_jacobian": choice.passed_over[2].min_scaled_jacobian},
        "next_valid": None if alt is None else {"rank": alt[0], "mesh_id": alt[1].mesh_id, "utility": float(alt[1].utility),
                                                "min_scaled_jacobian": alt[2].min_scaled_jacobian},
    }


def print_template(out, err, shape, choice, *, lattice_name: str, tie_break: str, notes: list[str], written: dict) -> None:
    """``mesh --template``'s text: the annotation, the ranking, the mesh placed and its fit; the
    size choice (part of the answer) on ``out``, the other notes (warnings) on ``err``; the files."""
    m, pl, ann = choice.match, choice.placement, choice.ranking.annotation
    out.print(f"shape [bold]{shape}[/]: {len(ann.codes)} points [cyan]{ann.symbols}[/]")
    out.print(f"lattice {lattice_name}; scored {choice.ranking.scored} meshes, {choice.ranking.unmatchable} unmatchable; "
              f"ties broken by {tie_break}", highlight=False)
    say(out, f"mesh #{choice.rank} {m.mesh_id}: {m.internal_vertices} internal, {m.boundary_length} boundary vertices, "
             f"{pl.mesh.n_quads} quads, {len(pl.irregular)} irregular internal; utility {choice.utility:g}, rotation {pl.rotation}, "
             f"{'reflected' if pl.reflected else 'not reflected'}")
    say(out, f"corners kept: {pl.kept_corners} of {pl.corners}; scaled Jacobian: min {pl.min_scaled_jacobian:.3f}, "
             f"mean {pl.mean_scaled_jacobian:.3f}; max edge ratio {pl.max_edge_ratio:.2f}; inverted quads: {pl.inverted}; "
             f"mesh area / shape area {pl.area_ratio:.6f}")
    if choice.size is not None:  # part of the answer: which size and why
        say(out, notes[0])
    for note in notes[1 if choice.size is not None else 0:]:  # warnings (FOLDED, next valid mesh): stderr, as with --json
        say(err, note)
    for path in written.values():
        say(out, f"wrote {path}")


# ---------------------------------------------------------------------------------------------
# annotate, catalogue info


def annotation_json(shape, ann, xy, polys, lengths) -> dict:
    """``annotate --json``: the s/x/v sequence, every point (user coordinates, side) and every
    side (ends, length)."""
    return {"shape": str(shape), "sequence": ann.symbols,
            "points": [{"index": i, "symbol": s, "x": float(p[0]), "y": float(p[1]), "side": int(sd)}
                       for i, (s, p, sd) in enumerate(zip(ann.symbols, xy, ann.side))],
            "sides": [{"side": i, "from": [float(v) for v in p[0]], "to": [float(v) for v in p[-1]],
                       "length": float(ln)} for i, (p, ln) in enumerate(zip(polys, lengths))]}


def print_annotation(out, n_corners: int, ann, xy, polys, lengths) -> None:
    """``annotate``'s text: the sequence, the table of points, the table of sides."""
    Table = _later.rich_table.Table
    out.print(ann.symbols)
    table = Table()
    for col in ("index", "symbol", "x", "y", "side"):
        table.add_column(col, justify="right")
    for i, (s, p, sd) in enumerate(zip(ann.symbols, xy, ann.side)):
        table.add_row(str(i), s, f"{p[0]:.6g}", f"{p[1]:.6g}", str(int(sd)))
    out.print(table)
    say(out, "sides for 'mesh --sides' (side i runs from corner i to corner i+1, in the file's order; "
             "the s/x/v table above numbers them counter-clockwise):" if n_corners else
             "no corners: 'mesh --sides' takes one total count")
    sides = Table()
    for col in ("side", "from", "to", "length"):
        sides.add_column(col, justify="right")
    for i, (p, ln) in enumerate(zip(polys, lengths)):
        sides.add_row(str(i), f"({p[0][0]:.6g}, {p[0][1]:.6g})", f"({p[-1][0]:.6g}, {p[-1][1]:.6g})", f"{ln:.6g}")
    out.print(sides)


def print_catalogue_counts(out, c: dict) -> None:
    """``catalogue info``'s tables (``c``: :meth:`~jaxmatch.catalogue.store.Catalogue.counts`)."""
    Table = _later.rich_table.Table
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
