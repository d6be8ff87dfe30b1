#!/usr/bin/env python3
"""Compare ``jaxmatch.mesh`` with gmsh's two all-quad meshers on the same shapes and sizes.

    .venv/bin/python scripts/compare_gmsh.py [--divisions 16,32] [--png docs/mesh-gmsh.png] [--json]

For every shape of ``scripts/mesh_table.py``'s ``SHAPES`` and h = perimeter / each of
``--divisions``:

* ``jaxmatch``: :func:`jaxmatch.mesh` (``size=h``): one template, or a decomposition, whichever
  the one choice rule prefers;
* ``gmsh-qs``: gmsh's quasi-structured quad mesher (``Mesh.Algorithm = 11``) on the polygon as a
  plane surface;
* ``gmsh-blossom``: Frontal-Delaunay for quads (``Mesh.Algorithm = 8``) recombined into quads by
  the full-quad blossom algorithm (``Mesh.RecombineAll = 1``, ``Mesh.RecombinationAlgorithm = 3``).

gmsh is given one characteristic length ``lc`` at every polygon point, **calibrated** so that its
mean edge length comes out near ``h`` (:func:`gmsh_calibrated`: a few tries scaling ``lc`` by
``h / measured mean edge``, then geometric bisection between the tries on either side of ``h``;
the try nearest ``h`` in ratio wins). Both meshers can only hit some sizes: the quasi-structured
mesher subdivides every quad of a coarse mesh (so its edge lengths come in steps of about 2) and
puts at least two edges on every polygon segment; full-quad blossom also subdivides. The table
gives each mesh's mean edge / h, so read the qualities beside it.

Every mesh is measured by the same code, ``mesh_table.measure`` (from points, quads and the
input outline only, independently of either mesher): quads, min / mean Verdict scaled Jacobian,
irregular internal vertices, mean edge / h, valid (no inverted quad, every corner a vertex, area
within 1 %; triangles left by gmsh make the area short). Prints a Markdown table and a summary
line per method (``--json``: JSON lines instead); ``--png`` draws jaxmatch beside both gmsh
meshes for ``--picture-shapes`` at ``--picture-division`` (default the last division). gmsh is a dev dependency
(``pip install -e .[dev]``).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from jaxmatch.cli import run_typer
from jaxmatch.geometry import cumulative_length

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(HERE) not in sys.path:  # mesh_table beside this file, also when imported from elsewhere
    sys.path.insert(0, str(HERE))

import mesh_table  # noqa: E402  (after the path)

GMSH_METHODS = {"gmsh-qs": {"algorithm": 11, "recombine": None},
                "gmsh-blossom": {"algorithm": 8, "recombine": 3}}
"""gmsh's all-quad meshers compared: name -> ``Mesh.Algorithm`` and ``Mesh.RecombinationAlgorithm``
(None: no recombination options; the quasi-structured mesher makes quads itself)."""

METHODS = ("jaxmatch",) + tuple(GMSH_METHODS)

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def gmsh_quads(points: np.ndarray, lc: float, algorithm: int = 11, recombine: int | None = None,
               holes=()) -> tuple[np.ndarray, np.ndarray, int]:
    """gmsh's quad mesh of the polygon ``points (P, 2)``, characteristic length ``lc`` at every
    point, ``Mesh.Algorithm = algorithm`` (``recombine``: ``Mesh.RecombineAll = 1`` with that
    ``Mesh.RecombinationAlgorithm``). Returns ``(xy, quads (ccw), triangles left)``; raises
    gmsh's exception when it cannot mesh (e.g. blossom with an odd number of boundary edges).
    holes: loops ``(H_k, 2)`` cut out of the surface (more curve loops of the plane surface)."""
    import gmsh

    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("shape")
        loops = []
        for ring in [points, *holes]:
            tags = [gmsh.model.geo.addPoint(float(x), float(y), 0.0, float(lc)) for x, y in ring]
            lines = [gmsh.model.geo.addLine(tags[i], tags[(i + 1) % len(tags)]) for i in range(len(tags))]
            loops.append(gmsh.model.geo.addCurveLoop(lines))
        gmsh.model.geo.addPlaneSurface(loops)
        gmsh.model.geo.synchronize()
        gmsh.option.setNumber("Mesh.Algorithm", algorithm)
        if recombine is not None:
            gmsh.option.setNumber("Mesh.RecombineAll", 1)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", recombine)
        gmsh.model.mesh.generate(2)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        xy = coords.reshape(-1, 3)[:, :2]
        index = np.full(int(node_tags.max()) + 1, -1, np.int64)
        index[node_tags.astype(np.int64)] = np.arange(node_tags.size)
        quads, tris = [], 0
        for etype, _, enodes in zip(*gmsh.model.mesh.getElements(2)):
            nn = gmsh.model.mesh.getElementProperties(int(etype))[3]
            conn = index[np.asarray(enodes, np.int64)].reshape(-1, nn)
            if nn == 4:
                quads.append(conn)
            else:
                tris += conn.shape[0]
    finally:
        gmsh.finalize()
    q = np.concatenate(quads) if quads else np.zeros((0, 4), np.int64)
    p = xy[q]
    signed = 0.5 * np.sum(p[..., 0] * np.roll(p[..., 1], -1, axis=1) - np.roll(p[..., 0], -1, axis=1) * p[..., 1], axis=1)
    q = np.where((signed < 0)[:, None], q[:, ::-1], q)  # gmsh's orientation follows the surface normal
    used = np.unique(q)
    remap = np.full(xy.shape[0], -1)
    remap[used] = np.arange(used.size)
    return xy[used], remap[q], tris


def mean_edge(xy: np.ndarray, quads: np.ndarray) -> float:
    """Mean length of the mesh's distinct edges."""
    e = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    e = np.unique(e, axis=0)
    return float(np.linalg.norm(xy[e[:, 0]] - xy[e[:, 1]], axis=1).mean()) if len(e) else math.nan


def gmsh_calibrated(points: np.ndarray, h: float, algorithm: int = 11, recombine: int | None = None,
                    tries: int = 10, holes=()) -> dict:
    """gmsh's mesh whose mean edge length is nearest ``h`` over at most ``tries`` runs: first
    ``lc = h``, then ``lc *= h / mean edge`` while that gives a new ``lc`` (and the last four
    tries did not all give the same mean edge), then geometric bisection between the largest
    ``lc`` that came out too fine and the smallest too coarse (none: stop; e.g. the
    quasi-structured mesher puts at least two edges on every polygon segment, so a finely
    sampled arc caps the edge length).
    A run gmsh refuses is retried with ``lc`` nudged (7 % larger, then 13 % smaller, alternately:
    full-quad blossom needs an even number of boundary edges). Returns ``{"lc", "xy", "quads",
    "triangles", "edge_over_h", "tries": [(lc / h, edge / h or None), ...]}``; raises
    RuntimeError when no run meshed."""
    log: list[tuple[float, float | None]] = []
    best = None
    lc = h
    stepping = True
    nudges = 0
    for _ in range(tries):
        try:
            xy, q, tris = gmsh_quads(points, lc, algorithm, recombine, holes=holes)
            r = mean_edge(xy, q) / h if len(q) else math.nan
        except Exception:  # gmsh refuses this lc (blossom: odd boundary edges): nudge it
            log.append((lc / h, None))
            lc *= 1.07 if nudges % 2 == 0 else 0.87
            nudges += 1
            continue
        log.append((lc / h, r))
        if math.isfinite(r) and (best is None or abs(math.log(r)) < abs(math.log(best["edge_over_h"]))):
            best = {"lc": lc, "xy": xy, "quads": q, "triangles": tris, "edge_over_h": r}
        if abs(math.log(best["edge_over_h"])) < math.log(1.05):
            break
        ok = [(s, e) for s, e in log if e is not None and math.isfinite(e)]
        nxt = lc / r if stepping and math.isfinite(r) else None
        saturated = len(ok) >= 4 and all(abs(e / ok[-1][1] - 1) < 0.005 for _, e in ok[-4:])  # the size is stuck
        if nxt is None or saturated or any(abs(nxt / h / s - 1) < 0.02 for s, _ in log):
            stepping = False
            fine = [s for s, e in ok if e < 1]
            coarse = [s for s, e in ok if e > 1]
            if not fine or not coarse or min(coarse) <= max(fine):
                break
            nxt = h * math.sqrt(max(fine) * min(coarse))
            if any(abs(nxt / h / s - 1) < 0.01 for s, _ in log):
                break
        lc = nxt
    if best is None:
        raise RuntimeError(f"gmsh (Mesh.Algorithm {algorithm}) meshed no try: lc / h = "
                           + ", ".join(f"{s:.3g}" for s, _ in log))
    return {**best, "tries": log}


def shape_case(path: Path, div: int) -> tuple:
    """``(shape, outline (P, 2), corners (C, 2), perimeter, h)`` of a shape file at h = P / div."""
    import jaxmatch

    shp = jaxmatch.load_shape(path)
    outline, corners = mesh_table._outline(shp)
    per = float(cumulative_length(outline)[-1])
    return shp, outline, corners, per, per / div


@app.command()
def main(divisions: str = typer.Option("16,32", help="h = perimeter / each of these."),
         png: Optional[Path] = typer.Option(None, "--png", help="Also draw jaxmatch beside both gmsh meshes (.png)."),
         picture_shapes: str = typer.Option("T,quarter-disk,stairs", help="Shapes drawn in the picture."),
         picture_division: Optional[int] = typer.Option(None, "--picture-division",
                                                        help="P/h of the picture (default: the last of --divisions)."),
         shapes: str = typer.Option("", help="Only these shapes of mesh_table.SHAPES (comma separated; default all)."),
         as_json: bool = typer.Option(False, "--json", help="JSON lines instead of a table.")) -> None:
    """Table: jaxmatch.mesh beside gmsh quasi-structured and Frontal-Delaunay + blossom, same shapes and sizes."""
    import jaxmatch
    from jaxmatch.cli import enable_compile_cache

    enable_compile_cache()
    divs = [int(d) for d in divisions.split(",")]
    names = [s for s in shapes.split(",") if s] or list(mesh_table.SHAPES)
    unknown = [s for s in names if s not in mesh_table.SHAPES]
    if unknown:
        raise typer.BadParameter(f"unknown shape {unknown[0]!r} (expected {', '.join(mesh_table.SHAPES)})")
    drawn = [s for s in picture_shapes.split(",") if s]
    pic_div = picture_division if picture_division is not None else divs[-1]
    rows, panels = [], []
    for name in names:
        for div in divs:
            shp, outline, corners, per, h = shape_case(mesh_table.SHAPES[name], div)
            meshes = {}
            t = time.perf_counter()
            try:
                m = jaxmatch.mesh(shp, size=h)
                meshes["jaxmatch"] = (m.xy, m.quads, 0, {"chosen": m.chosen}, m)
            except Exception as e:  # a failure is a row
                meshes["jaxmatch"] = e
            seconds = {"jaxmatch": time.perf_counter() - t}
            for method, opts in GMSH_METHODS.items():
                t = time.perf_counter()
                try:
                    g = gmsh_calibrated(outline, h, **opts)
                    meshes[method] = (g["xy"], g["quads"], g["triangles"], {"lc_over_h": g["lc"] / h,
                                                                             "tries": len(g["tries"])}, None)
                except Exception as e:
                    meshes[method] = e
                seconds[method] = time.perf_counter() - t  # calibration included
            for method in METHODS:
                res = meshes[method]
                row = {"shape": name, "div": div, "h": h, "method": method, "seconds": seconds[method]}
                if isinstance(res, Exception):
                    row["error"] = str(res)
                else:
                    xy, q, tris, extra, _ = res
                    row.update(extra, triangles=tris, **mesh_table.measure(xy, q, corners, outline, h))
                rows.append(row)
                if as_json:
                    print(json.dumps(row), flush=True)
            if png is not None and name in drawn and div == pic_div:
                for method in METHODS:
                    res = meshes[method]
                    if isinstance(res, Exception):
                        continue
                    xy, q, _, extra, m = res
                    r = rows[-len(METHODS) + METHODS.index(method)]
                    label = f"{method} ({extra['chosen']})" if method == "jaxmatch" else method
                    head = f"{name}, P/h={div}: {label}, edge/h {r['mean_edge_over_h']:.2f}"
                    patch = m.patch if m is not None else None
                    panels.append((head, xy, q, patch, None, corners))
    if not as_json:
        print(table(rows))
        print()
        print("\n".join(summaries(rows)))
    if png is not None and panels:
        from jaxmatch.io.plot import draw_meshes

        out = draw_meshes(png, panels, ncols=len(METHODS))
        if out.suffix.lower() == ".png":
            _palette(out)
        print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KB)")


def _palette(path: Path, colours: int = 128) -> None:
    """Rewrite a PNG with a ``colours``-colour palette (about a third of the bytes for these flat
    drawings; Pillow comes with matplotlib)."""
    from PIL import Image

    with Image.open(path) as im:
        small = im.convert("RGB").quantize(colours, method=Image.Quantize.FASTOCTREE)
    small.save(path, optimize=True)


def table(rows: list[dict]) -> str:
    """The Markdown table of :func:`main`'s rows."""
    out = ["| shape | P/h | method | quads | min SJ | mean SJ | irregular (bound) | edge/h | valid |",
           "|---|---:|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if "error" in r:
            out.append(f"| {r['shape']} | {r['div']} | {r['method']} | error: {r['error'][:60]} | | | | | no |")
            continue
        tri = f" (+{r['triangles']} tri)" if r.get("triangles") else ""
        out.append(f"| {r['shape']} | {r['div']} | {r['method']} | {r['quads']}{tri} | {r['min_sj']:.3f} | "
                   f"{r['mean_sj']:.3f} | {r['irregular']} ({r['irregular_bound']}) | {r['mean_edge_over_h']:.2f} | "
                   f"{'yes' if r['valid'] else 'NO'} |")
    return "\n".join(out)


def summaries(rows: list[dict]) -> list[str]:
    """One line per method: valid meshes, mean / worst min SJ, mean SJ, irregular per mesh, edge/h."""
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        ok = [r for r in mine if "error" not in r]
        if not ok:
            out.append(f"{method}: no mesh ({len(mine)} failures)")
            continue
        out.append(f"{method}: {sum(r['valid'] for r in ok)}/{len(mine)} valid; mean of min SJ "
                   f"{np.mean([r['min_sj'] for r in ok]):.3f}; worst min SJ {min(r['min_sj'] for r in ok):.3f}; "
                   f"mean SJ {np.mean([r['mean_sj'] for r in ok]):.3f}; irregular per mesh "
                   f"{np.mean([r['irregular'] for r in ok]):.2f} (above the bound "
                   f"{np.mean([r['irregular'] - r['irregular_bound'] for r in ok]):.2f}); mean edge/h "
                   f"{np.mean([r['mean_edge_over_h'] for r in ok]):.2f} (range {min(r['mean_edge_over_h'] for r in ok):.2f}"
                   f"..{max(r['mean_edge_over_h'] for r in ok):.2f})")
    return out


if __name__ == "__main__":
    run_typer(app)
