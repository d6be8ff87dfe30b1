#!/usr/bin/env python3
"""The meshing table: ``jaxmatch.mesh`` on the example shapes at h = perimeter/16 and /32,
every figure measured here from the mesh's points and quads and the input file, independently
of jaxmatch's own quality code.

    .venv/bin/python scripts/mesh_table.py [--divisions 16,32] [--json OUT.jsonl] [--compare-old]

Per mesh: valid (no inverted quad, every input corner within 1e-9 of a vertex, |area ratio - 1|
<= 0.01), min / mean Verdict scaled Jacobian, irregular internal vertices (valence != 4, not on
a boundary edge) and Euler's lower bound for the boundary valences used, the worst side's
|edges / (length / h) - 1|. ``--compare-old`` adds the two older paths (``refine_mesh``: one
template refined to the size; ``mesh_shape``: the first decompose-and-choose) where they exist.
Prints a Markdown table and the summary line per method.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

from jaxmatch.cli import run_typer
from jaxmatch.geometry import cumulative_length

ROOT = Path(__file__).resolve().parent.parent
EX, LAB = ROOT / "examples", ROOT / "examples" / "labels" / "shapes"
SHAPES = {"square": EX / "square.json", "rectangle-3x1": LAB / "rectangle-3x1.json", "hexagon": EX / "hexagon.json",
          "L": EX / "lshape.json", "T": EX / "tshape.json", "U": LAB / "ushape.json", "plus": EX / "plus.json",
          "notched": LAB / "notched-rectangle.json", "quarter-disk": LAB / "quarter-disk.json",
          "triangle": EX / "triangle.json", "trapezoid": LAB / "trapezoid.json", "Z": LAB / "zshape.json",
          "stairs": LAB / "stairs.json"}

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def scaled_jacobian(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Verdict's quad scaled Jacobian: min over the 4 corners of the cross product of the two
    unit edge vectors leaving the corner (ccw)."""
    p = xy[quads]
    a = np.roll(p, -1, axis=1) - p
    b = np.roll(p, 1, axis=1) - p
    na, nb = np.linalg.norm(a, axis=2), np.linalg.norm(b, axis=2)
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where((na > 0) & (nb > 0), cross / (na * nb), -1.0)
    return s.min(axis=1)


def measure(xy: np.ndarray, quads: np.ndarray, corners: np.ndarray, outline: np.ndarray, h: float,
            holes=()) -> dict:
    """Figures of one mesh from its points and quads and the input outline/corners (and holes:
    loops ``(H_k, 2)`` cut out of the region, their corners among ``corners``) only. Euler's
    bound on irregular vertices: ``|4 (1 - holes) - sum over boundary vertices (3 - valence)|``."""
    import shapely

    quads = np.asarray(quads, np.int64)
    sj = scaled_jacobian(xy, quads)
    e = np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2)
    key = np.sort(e, axis=1)
    uniq, cnt = np.unique(key, axis=0, return_counts=True)
    val = np.bincount(uniq.ravel(), minlength=len(xy))
    bnd = np.zeros(len(xy), bool)
    bnd[uniq[cnt == 1].ravel()] = True
    used = np.zeros(len(xy), bool)
    used[quads.ravel()] = True
    irregular = int(np.sum(used & ~bnd & (val != 4)))
    bound = abs(4 * (1 - len(holes)) - int(np.sum(3 - val[bnd])))
    p = xy[quads]
    area = 0.5 * np.sum(p[:, :, 0] * np.roll(p[:, :, 1], -1, 1) - np.roll(p[:, :, 0], -1, 1) * p[:, :, 1])
    region = shapely.Polygon(outline, holes=[np.asarray(r) for r in holes]).area
    ext = float(np.ptp(outline, axis=0).max())
    miss = 0
    for c in corners:
        if np.min(np.linalg.norm(xy - c, axis=1)) > 1e-9 * ext:
            miss += 1
    inverted = int(np.sum(sj <= 0))
    edge_len = np.linalg.norm(xy[uniq[:, 0]] - xy[uniq[:, 1]], axis=1)
    ratio = float(area / region)
    return {"quads": len(quads), "min_sj": float(sj.min()), "mean_sj": float(sj.mean()), "inverted": inverted,
            "missed_corners": miss, "area_ratio": ratio, "irregular": irregular, "irregular_bound": bound,
            "mean_edge_over_h": float(edge_len.mean() / h),
            "valid": inverted == 0 and miss == 0 and abs(ratio - 1) <= 0.01}


def _outline(shape) -> tuple[np.ndarray, np.ndarray]:
    pts = shape.input_points if shape.input_points is not None else shape.user_points
    corners = shape.to_user(shape.points[shape.corners]) if shape.n_corners else np.zeros((0, 2))
    return np.asarray(pts, np.float64), corners


@app.command()
def main(divisions: str = typer.Option("16,32", help="h = perimeter / each of these."),
         json_out: Optional[Path] = typer.Option(None, "--json", help="Also write one JSON line per mesh."),
         compare_old: bool = typer.Option(False, "--compare-old", help="Add the older refine/decompose paths."),
         png: Optional[Path] = typer.Option(None, "--png", help="Also draw the meshes of --picture-shapes at the first "
                                            "division count (.png)."),
         picture_shapes: str = typer.Option("L,plus,trapezoid,quarter-disk", help="Shapes drawn with --png.")) -> None:
    import jaxmatch

    cat = jaxmatch.load_catalogue()
    rows, panels = [], []
    draw = [n.strip() for n in picture_shapes.split(",")] if png is not None else []
    for name, path in SHAPES.items():
        shp = jaxmatch.load_shape(path)
        outline, corners = _outline(shp)
        per = float(cumulative_length(outline)[-1])
        for div in (int(d) for d in divisions.split(",")):
            h = per / div
            methods = {"mesh": lambda: jaxmatch.mesh(shp, size=h, catalogue=cat)}
            if compare_old:
                methods.update(_old_methods(shp, h, cat))
            for method, run in methods.items():
                t0 = time.perf_counter()
                try:
                    res = run()
                except Exception as e:  # a failure is a row
                    rows.append({"shape": name, "div": div, "method": method, "error": str(e)})
                    continue
                dt = time.perf_counter() - t0
                rec = {"shape": name, "div": div, "method": method, "seconds": dt,
                       "chosen": getattr(res, "chosen", ""), **measure(res.xy, res.quads, corners, outline, h)}
                rows.append(rec)
                if method == "mesh" and name in draw and div == int(divisions.split(",")[0]):
                    panels.append((f"{name}, h = P/{div}: {res.chosen}", res.xy, res.quads, res.patch, None, corners))
    print("| shape | P/h | method | chosen | quads | min SJ | mean SJ | irregular (bound) | valid | s |")
    print("|---|---:|---|---|---:|---:|---:|---:|---|---:|")
    for r in rows:
        if "error" in r:
            print(f"| {r['shape']} | {r['div']} | {r['method']} | error: {r['error'][:60]} | | | | | no | |")
            continue
        print(f"| {r['shape']} | {r['div']} | {r['method']} | {r['chosen']} | {r['quads']} | {r['min_sj']:.3f} | "
              f"{r['mean_sj']:.3f} | {r['irregular']} ({r['irregular_bound']}) | {'yes' if r['valid'] else 'NO'} | "
              f"{r['seconds']:.2f} |")
    for method in dict.fromkeys(r["method"] for r in rows):
        ok = [r for r in rows if r["method"] == method and "error" not in r]
        n = sum(1 for r in rows if r["method"] == method)
        if not ok:
            continue
        print(f"{method}: meshed {sum(r['valid'] for r in ok)}/{n} valid; mean of min SJ "
              f"{np.mean([r['min_sj'] for r in ok]):.3f}; worst min SJ {min(r['min_sj'] for r in ok):.3f}; "
              f"irregular per mesh {np.mean([r['irregular'] for r in ok]):.2f}; above the bound "
              f"{np.mean([r['irregular'] - r['irregular_bound'] for r in ok]):.2f}")
    write_outputs(rows, panels, png, json_out, ncols=len(panels))


def write_outputs(rows: list[dict], panels: list, png: Optional[Path], json_out: Optional[Path], ncols: int = 2) -> None:
    """The picture of ``panels`` (:func:`jaxmatch.io.plot.draw_meshes`) and the rows as JSON
    lines, each when asked for (the table scripts share this)."""
    if png is not None and panels:
        from jaxmatch.io.plot import draw_meshes

        print(f"wrote {draw_meshes(png, panels, ncols=ncols)}")
    if json_out is not None:
        from jaxmatch.files import write_text_atomic

        write_text_atomic(json_out, "".join(json.dumps(r) + "\n" for r in rows))


def _old_methods(shp, h, cat) -> dict:
    out = {}
    try:
        from jaxmatch.placement.refine import refine_mesh

        out["refine"] = lambda: _Chosen(refine_mesh(shp, cat, jaxmatch_lattice(), size=h).mesh, "refine")
    except ImportError:
        pass
    try:
        from jaxmatch.placement.decompose import mesh_shape

        def run():
            c = mesh_shape(shp, cat, jaxmatch_lattice(), size=h)
            return _Chosen(c.mesh, c.chosen)

        out["layout"] = run
    except ImportError:
        pass
    return out


def jaxmatch_lattice():
    from jaxmatch.scoring.lattice import load_lattice

    return load_lattice("fine")


class _Chosen:
    def __init__(self, m, chosen):
        self.xy, self.quads, self.chosen = m.xy, m.quads, chosen


if __name__ == "__main__":
    run_typer(app)
