#!/usr/bin/env python3
"""Compare jaxmatch's concave-shape meshes with gmsh's all-quad meshing on the same shapes and sizes.

    .venv/bin/python scripts/compare_gmsh.py [--sizes 0.25,0.125] [--png docs/layout-gmsh.png] [--json]

For every shape (L, T, U, plus, Z, stairs, cross, notched rectangle) and element size ``h``:

* jaxmatch: :func:`jaxmatch.placement.decompose.mesh_shape` (one template, or the shape split
  at its concave corners, whichever is better) with target edge length ``h``;
* gmsh: the polygon with characteristic length ``h`` at every point, Frontal-Delaunay for quads
  (``Mesh.Algorithm = 8``), recombined into quads by the full-quad blossom algorithm
  (``Mesh.RecombineAll = 1``, ``Mesh.RecombinationAlgorithm = 3``), gmsh's default smoothing.

Both are measured by the same code, independently of either mesher: quads (and triangles left,
if any), irregular internal vertices (valence not 4, vertices not on the boundary), min / mean
scaled Jacobian (Verdict), inverted quads. Prints a Markdown table (or JSON lines), and draws
jaxmatch beside gmsh for the shapes named by ``--picture-shapes`` at the first size.
gmsh is a dev dependency (``pip install -e .[dev]``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from jaxmatch.cli import run_typer

ROOT = Path(__file__).resolve().parent.parent
EX, LAB = ROOT / "examples", ROOT / "examples" / "labels" / "shapes"
SHAPES = {"L": EX / "lshape.json", "T": EX / "tshape.json", "U": LAB / "ushape.json", "plus": EX / "plus.json",
          "Z": LAB / "zshape.json", "stairs": LAB / "stairs.json", "cross": LAB / "cross.json",
          "notched-rectangle": LAB / "notched-rectangle.json"}

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def measures(xy: np.ndarray, quads: np.ndarray, n_triangles: int = 0) -> dict:
    """Quads, irregular internal vertices, min/mean scaled Jacobian, inverted quads."""
    from jaxmatch.catalogue.mesh import valences
    from jaxmatch.placement.embed import inverted_mask, quality
    from jaxmatch.placement.layout import boundary_edges

    sj = quality(xy, quads)[0]
    on_b = np.zeros(xy.shape[0], bool)
    on_b[boundary_edges(quads).ravel()] = True
    used = np.zeros(xy.shape[0], bool)
    used[quads.ravel()] = True
    irr = int(np.sum(used & ~on_b & (valences(quads, xy.shape[0]) != 4)))
    return {"quads": int(quads.shape[0]), "triangles": int(n_triangles), "irregular": irr,
            "min_sj": float(sj.min()), "mean_sj": float(sj.mean()), "inverted": int(inverted_mask(xy, quads).sum())}


def gmsh_quads(points: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, int]:
    """gmsh's all-quad mesh of the polygon ``points (P, 2)``: ``(xy, quads (ccw), triangles left)``."""
    import gmsh

    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("shape")
        tags = [gmsh.model.geo.addPoint(float(x), float(y), 0.0, h) for x, y in points]
        lines = [gmsh.model.geo.addLine(tags[i], tags[(i + 1) % len(tags)]) for i in range(len(tags))]
        gmsh.model.geo.addPlaneSurface([gmsh.model.geo.addCurveLoop(lines)])
        gmsh.model.geo.synchronize()
        gmsh.option.setNumber("Mesh.Algorithm", 8)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 3)
        gmsh.model.mesh.generate(2)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        xy = coords.reshape(-1, 3)[:, :2]
        index = {int(t): i for i, t in enumerate(node_tags)}
        quads, tris = [], 0
        for etype, _, enodes in zip(*gmsh.model.mesh.getElements(2)):
            name, _, _, nn, _, _ = gmsh.model.mesh.getElementProperties(int(etype))
            conn = np.array([index[int(t)] for t in enodes]).reshape(-1, nn)
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


@app.command()
def main(sizes: str = typer.Option("0.25,0.125", help="Element sizes (comma separated, the shapes' units)."),
         png: Optional[Path] = typer.Option(ROOT / "docs" / "layout-gmsh.png", "--png", help="Picture (.png)."),
         picture_shapes: str = typer.Option("U,notched-rectangle,stairs", help="Shapes drawn in the picture."),
         as_json: bool = typer.Option(False, "--json", help="JSON lines instead of a table.")) -> None:
    """Table: jaxmatch (chosen candidate) beside gmsh's all-quad mesh on the same shapes and sizes."""
    from jaxmatch.catalogue.store import default_catalogue
    from jaxmatch.cli import enable_compile_cache
    from jaxmatch.placement.decompose import mesh_shape
    from jaxmatch.placement.layout import draw_meshes, layout_panel
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.io.readers import load_shape

    enable_compile_cache()
    hs = [float(s) for s in sizes.split(",")]
    cat, lat = default_catalogue(), load_lattice("fine")
    rows, panels = [], []
    drawn = picture_shapes.split(",")
    for name, path in SHAPES.items():
        shp = load_shape(path)
        cache: dict = {}
        for h in hs:
            t = time.perf_counter()
            choice = mesh_shape(shp, cat, lat, size=h, template_cache=cache)
            tj = time.perf_counter() - t
            m = choice.mesh
            jm = measures(m.xy, m.quads)
            t = time.perf_counter()
            gxy, gq, tris = gmsh_quads(shp.input_points, h)
            tg = time.perf_counter() - t
            gm = measures(gxy, gq, tris)
            row = {"shape": name, "size": h, "chosen": choice.chosen, "patches": m.layout.n_patches,
                   "area_ratio": m.area_ratio, "jaxmatch": jm, "gmsh": gm, "seconds": {"jaxmatch": tj, "gmsh": tg}}
            rows.append(row)
            if as_json:
                print(json.dumps(row), flush=True)
            if png is not None and name in drawn and h == hs[0]:
                panels.append(layout_panel(m, f"{name}, h={h:g}: jaxmatch ({choice.chosen}, {m.layout.n_patches} patches)"))
                panels.append((f"{name}, h={h:g}: gmsh all-quad", gxy, gq, None, None))
    if not as_json:
        print("| shape | h | jaxmatch: chosen (patches) | quads | irregular | min SJ | mean SJ | gmsh: quads | irregular | min SJ | mean SJ |")
        print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            j, g = r["jaxmatch"], r["gmsh"]
            extra = f" (+{g['triangles']} tri)" if g["triangles"] else ""
            print(f"| {r['shape']} | {r['size']:g} | {r['chosen']} ({r['patches']}) | {j['quads']} | {j['irregular']} | "
                  f"{j['min_sj']:.3f} | {j['mean_sj']:.3f} | {g['quads']}{extra} | {g['irregular']} | {g['min_sj']:.3f} | "
                  f"{g['mean_sj']:.3f} |")
    if png is not None and panels:
        print(f"wrote {draw_meshes(png, panels, ncols=2)}")


if __name__ == "__main__":
    run_typer(app)
