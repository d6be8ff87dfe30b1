"""Graded meshes beside gmsh with the same size field: ``docs/graded.md``'s table and picture.

Every case of :data:`CASES` (``examples/graded/NAME.json`` and its field ``NAME.field.json``)
is meshed in the same run by

* jaxmatch: ``jaxmatch mesh NAME.json --size-field NAME.field.json --out jaxmatch.msh``;
* gmsh, quasi-structured quads (``Mesh.Algorithm 11``, ``RecombineAll``);
* gmsh, frontal-Delaunay for quads + Blossom recombination (``Mesh.Algorithm 8``,
  ``RecombineAll``, ``Mesh.RecombinationAlgorithm 1``),

gmsh with the same field: per entry a ``Distance`` field (to the hole's or side's own curves, 200
samples each; a point, or a curve sampled every ``s / 8``, as free points) and a
``Threshold`` field (``SizeMin s``, ``SizeMax H``, ``DistMin 0``, ``DistMax d``), their ``Min``
as the background field (sizes from points, curvature and the boundary off).

Each mesh file is read back with meshio and measured by code independent of jaxmatch
(``scripts/part_measures.py``: valid, min scaled Jacobian; the field here with shapely's
distances): the share of all edges whose length / the field at the midpoint lies in
``[0.5, 1.6]``, the same share of the edges in the refined zone (where the field is below
halfway between its smallest size and ``H``), irregular vertices, quads and seconds.

Usage: ``python scripts/graded_table.py [--out DIR] [--md docs/graded.md] [--png docs/graded.png]``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Optional

import meshio
import numpy as np
import shapely
import typer

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
from part_measures import measure  # noqa: E402

CASES = {
    "plate-hole": "a plate finer at its round hole",
    "square": "a square finer at an interior point",
    "strip": "a strip finer along one side",
    "lshape": "an L finer at its re-entrant corner",
    "rectangle": "a rectangle finer along an interior curve",
    "two-holes": "a plate with two holes, finer at each (two sizes)",
}
"""Case name -> what it is (``examples/graded/NAME.json`` + ``NAME.field.json``)."""

FOLDER = ROOT / "examples" / "graded"
BAND = (0.5, 1.6)
RECIPES = ("jaxmatch", "gmsh-qs", "gmsh-blossom")


# ---------------------------------------------------------------------------------------------
# the field, written again (shapely distances), and the region


def load_case(name: str) -> tuple[dict, dict]:
    """``(region JSON, field JSON)`` of a case."""
    return (json.loads((FOLDER / f"{name}.json").read_text()), json.loads((FOLDER / f"{name}.field.json").read_text()))


def entity_geometry(entry: dict, region: dict):
    """The shapely geometry an entry's distances are measured to."""
    if "point" in entry:
        return shapely.Point(entry["point"])
    if "curve" in entry:
        return shapely.LineString(entry["curve"])
    if "hole" in entry:
        return shapely.LinearRing(region["holes"][entry["hole"] - 1])
    i, j = (int(v) for v in entry["side"].split("-"))
    pts = region["boundary"]
    idx = list(range(i, j + 1)) if j > i else list(range(i, len(pts))) + list(range(0, j + 1))
    return shapely.LineString([pts[k] for k in idx])


def field_values(field: dict, region: dict, xy: np.ndarray) -> np.ndarray:
    """``(n,)`` the field at ``xy (n, 2)``: min(H, min over entries of s + (H - s) min(1, dist / d))."""
    H = float(field["size"])
    out = np.full(len(xy), H)
    pts = shapely.points(xy)
    for e in field.get("near", []):
        dist = shapely.distance(pts, entity_geometry(e, region))
        out = np.minimum(out, e["size"] + (H - e["size"]) * np.minimum(1.0, dist / e["distance"]))
    return out


def rings(region: dict) -> list[np.ndarray]:
    return [np.asarray(region["boundary"], float)] + [np.asarray(h, float) for h in region.get("holes", [])]


# ---------------------------------------------------------------------------------------------
# meshing


def run_jaxmatch(name: str, out: Path, png: Path | None = None) -> dict:
    cmd = [sys.executable, "-m", "jaxmatch", "mesh", str(FOLDER / f"{name}.json"), "--size-field",
           str(FOLDER / f"{name}.field.json"), "--out", str(out), "--json"]
    env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env)
    sec = time.perf_counter() - t0
    if p.returncode not in (0, 3) or not out.exists():
        return {"seconds": sec, "error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    rec = json.loads(p.stdout)
    return {"seconds": sec, "chosen": rec["chosen"], "own_field_share": rec.get("field_share")}


def run_gmsh(name: str, recipe: str, out: Path) -> dict:
    """Mesh a case with gmsh (in a subprocess: :func:`gmsh_worker`)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--gmsh-worker", name, recipe, str(out)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    sec = time.perf_counter() - t0
    if p.returncode != 0 or not out.exists():
        return {"seconds": sec, "error": (p.stderr.strip().splitlines() or ["?"])[-1]}
    return {"seconds": sec, "mesh_seconds": float(p.stdout.strip().splitlines()[-1])}


def gmsh_worker(name: str, recipe: str, out: str) -> None:
    import gmsh

    region, field = load_case(name)
    H = float(field["size"])
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
        geo = gmsh.model.geo
        loops, lines_of = [], []
        for ring in rings(region):
            tags = [geo.addPoint(float(x), float(y), 0.0, H) for x, y in ring]
            lines = [geo.addLine(tags[i], tags[(i + 1) % len(tags)]) for i in range(len(tags))]
            lines_of.append(lines)
            loops.append(geo.addCurveLoop(lines))
        geo.addPlaneSurface(loops)
        geo.synchronize()
        thresholds = []
        for e in field["near"]:
            d = gmsh.model.mesh.field.add("Distance")
            if "hole" in e:  # the hole's own curves
                gmsh.model.mesh.field.setNumbers(d, "CurvesList", lines_of[e["hole"]])
                gmsh.model.mesh.field.setNumber(d, "Sampling", 200)
            elif "side" in e:  # the outline's lines from point i to point j
                i, j = (int(v) for v in e["side"].split("-"))
                n = len(region["boundary"])
                a, b = (i, j) if (j - i) % n <= (i - j) % n else (j, i)
                gmsh.model.mesh.field.setNumbers(d, "CurvesList", [lines_of[0][k % n] for k in range(a, a + (b - a) % n)])
                gmsh.model.mesh.field.setNumber(d, "Sampling", 200)
            else:  # a point or a curve: points sampled on it every s / 8 (free points, not in the surface)
                g = entity_geometry(e, region)
                n = max(int(math.ceil(g.length / (e["size"] / 8))), 1) if g.length > 0 else 0
                pts = [g.interpolate(t, normalized=True) for t in np.linspace(0, 1, n + 1)] if n else [g]
                tags = [geo.addPoint(p.x, p.y, 0.0) for p in pts]
                geo.synchronize()
                gmsh.model.mesh.field.setNumbers(d, "PointsList", tags)
            t = gmsh.model.mesh.field.add("Threshold")
            gmsh.model.mesh.field.setNumber(t, "InField", d)
            gmsh.model.mesh.field.setNumber(t, "SizeMin", e["size"])
            gmsh.model.mesh.field.setNumber(t, "SizeMax", H)
            gmsh.model.mesh.field.setNumber(t, "DistMin", 0.0)
            gmsh.model.mesh.field.setNumber(t, "DistMax", e["distance"])
            thresholds.append(t)
        m = gmsh.model.mesh.field.add("Min")
        gmsh.model.mesh.field.setNumbers(m, "FieldsList", thresholds)
        gmsh.model.mesh.field.setAsBackgroundMesh(m)
        gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
        gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        if recipe == "gmsh-qs":
            gmsh.option.setNumber("Mesh.Algorithm", 11)
        else:
            gmsh.option.setNumber("Mesh.Algorithm", 8)
            gmsh.option.setNumber("Mesh.RecombinationAlgorithm", 1)
        t0 = time.perf_counter()
        gmsh.model.mesh.generate(2)
        sec = time.perf_counter() - t0
        gmsh.write(out)
    finally:
        gmsh.finalize()
    print(f"{sec:.6f}")


# ---------------------------------------------------------------------------------------------
# measures


def measured(name: str, path: Path) -> dict:
    """Independent figures of one mesh file of a case."""
    region, field = load_case(name)
    m = meshio.read(path)
    xy = np.asarray(m.points, float)[:, :2]
    cells = [(c.type, c.data) for c in m.cells]
    R = rings(region)
    area = shapely.Polygon(R[0], R[1:]).area
    corners = np.asarray(region["boundary"], float)  # every outline point of these cases is a corner
    smin = min(e["size"] for e in field["near"])
    rec = measure(xy, cells, R, corners, area, smin)
    quads = np.concatenate([np.asarray(d).reshape(-1, 4) for t, d in cells if t == "quad"]) if rec["quads"] else None
    if quads is None:
        return rec
    e = np.concatenate([quads[:, [k, (k + 1) % 4]] for k in range(4)])
    e = np.unique(np.sort(e, axis=1), axis=0)
    mid = 0.5 * (xy[e[:, 0]] + xy[e[:, 1]])
    f = field_values(field, region, mid)
    r = np.linalg.norm(xy[e[:, 0]] - xy[e[:, 1]], axis=1) / f
    ok = (r >= BAND[0]) & (r <= BAND[1])
    zone = f < 0.5 * (smin + float(field["size"]))
    rec.update(share=float(ok.mean()), share_refined=float(ok[zone].mean()) if zone.any() else math.nan,
               refined_edges=int(zone.sum()), short=float(np.mean(r < BAND[0])), long=float(np.mean(r > BAND[1])))
    rec["quad_ratio"] = quad_ratios(xy, quads, field, region)
    rec["xy"], rec["quad_list"] = xy, quads
    return rec


def quad_ratios(xy, quads, field, region) -> np.ndarray:
    p = xy[quads]
    mean_edge = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2).mean(axis=1)
    return mean_edge / field_values(field, region, p.mean(axis=1))


def verdict(row: dict) -> dict:
    """The issue's criteria for one case: jaxmatch valid; share of all edges >= 0.7; share in the
    refined zone >= 0.6 and >= min(0.8, the better gmsh recipe's - 0.1); min SJ >= 0.3 and >= that
    recipe's - 0.05 (the better recipe: the valid one with the higher share in the refined zone)."""
    j = row["jaxmatch"]
    gm = [row[r] for r in RECIPES[1:] if row[r].get("valid")]
    better = max(gm, key=lambda g: g["share_refined"]) if gm else None
    want_ref = 0.6 if better is None else max(0.6, min(0.8, better["share_refined"] - 0.1))
    want_sj = 0.3 if better is None else max(0.3, better["min_sj"] - 0.05)
    out = {"valid": bool(j.get("valid")), "share": j.get("share", 0) >= 0.7,
           "refined": j.get("share_refined", 0) >= want_ref - 1e-12, "sj": j.get("min_sj", -1) >= want_sj - 1e-12,
           "want_refined": want_ref, "want_sj": want_sj, "better": None if better is None else better["recipe"]}
    out["pass"] = all(out[k] for k in ("valid", "share", "refined", "sj"))
    return out


# ---------------------------------------------------------------------------------------------
# output


def cell(rec: dict) -> str:
    if "error" in rec:
        return f"error: {rec['error'][:60]}"
    if not rec.get("all_quads", True) or "share" not in rec:
        return f"{rec.get('quads', 0)} quads, {rec.get('other_cells', 0)} other cells ({rec.get('problem', '')})"
    valid = "valid" if rec["valid"] else f"INVALID ({rec['problem']})"
    return (f"{rec['quads']} q, {valid}, share {rec['share']:.2f} / refined {rec['share_refined']:.2f}, "
            f"SJ {rec['min_sj']:.2f}, {rec['irregular']} irr, {rec['seconds']:.2f} s")


def table(rows: list[dict]) -> str:
    head = ["case", "jaxmatch", "gmsh quasi-structured (11)", "gmsh frontal-quad + Blossom (8)", "criteria"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows:
        v = row["verdict"]
        crit = (("PASS" if v["pass"] else "FAIL") + f": valid {'y' if v['valid'] else 'n'}, all>=0.7 "
                f"{'y' if v['share'] else 'n'}, refined>={v['want_refined']:.2f} {'y' if v['refined'] else 'n'}, "
                f"SJ>={v['want_sj']:.2f} {'y' if v['sj'] else 'n'}")
        lines.append(f"| {row['name']} | " + " | ".join(cell(row[r]) for r in RECIPES) + f" | {crit} |")
    return "\n".join(lines)


def picture(rows: list[dict], path: Path) -> None:
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 3.0 * len(rows)), dpi=64, layout="constrained")
    axes = fig.subplots(len(rows), 3, squeeze=False)
    pc = None
    for i, row in enumerate(rows):
        for j, r in enumerate(RECIPES):
            ax = axes[i, j]
            ax.set_aspect("equal")
            ax.axis("off")
            rec = row[r]
            if "xy" not in rec:
                ax.set_title(f"{row['name']}: {r}: no quads", fontsize=8)
                continue
            pc = PolyCollection(rec["xy"][rec["quad_list"]], array=np.log2(rec["quad_ratio"]), cmap="coolwarm",
                                edgecolors="0.25", linewidths=0.25)
            pc.set_clim(-1.5, 1.5)
            ax.add_collection(pc)
            ax.autoscale_view()
            ax.set_title(f"{row['name']}: {r}\n{rec['quads']} quads, share {rec['share']:.2f} / refined "
                         f"{rec['share_refined']:.2f}, SJ {rec['min_sj']:.2f}", fontsize=8)
    if pc is not None:
        cb = fig.colorbar(pc, ax=axes, shrink=0.3, ticks=np.log2([0.35, 0.5, 1.0, 1.6, 2.8]))
        cb.ax.set_yticklabels(["0.35", "0.5", "1", "1.6", "2.8"])
        cb.set_label("mean edge length / field")
    fig.savefig(path)


def main(out: Path = typer.Option(Path("graded-out"), help="Folder for the mesh files."),
         md: Optional[Path] = typer.Option(None, help="Write the table (markdown) here."),
         png: Optional[Path] = typer.Option(None, help="Write the picture here."),
         cases: Optional[str] = typer.Option(None, help="Comma-separated case names (default: all).")):
    names = [c.strip() for c in cases.split(",")] if cases else list(CASES)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in names:
        row = {"name": name}
        for recipe in RECIPES:
            path = out / f"{name}-{recipe}.msh"
            path.unlink(missing_ok=True)
            run = run_jaxmatch(name, path) if recipe == "jaxmatch" else run_gmsh(name, recipe, path)
            rec = {**run, "recipe": recipe}
            if "error" not in run:
                rec.update(measured(name, path))
            row[recipe] = rec
        row["verdict"] = verdict(row)
        rows.append(row)
        print(f"{name}: " + "; ".join(f"{r}: {cell(row[r])}" for r in RECIPES), flush=True)
    text = table(rows)
    print(text)
    passed = sum(r["verdict"]["pass"] for r in rows)
    print(f"{passed} of {len(rows)} cases pass every criterion")
    if png is not None:
        picture(rows, png)
    if md is not None:
        md.write_text(text + "\n")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--gmsh-worker":
        gmsh_worker(*sys.argv[2:5])
    else:
        typer.run(main)
