"""Assemblies meshed by jaxmatch and by gmsh (docs/assemblies.md).

gmsh: the regions as OpenCASCADE plane surfaces (holes as inner loops), fragmented into one
conforming partition (``occ.fragment``), meshed by the quasi-structured quad mesher
(``Mesh.Algorithm = 11``) with ``lc`` calibrated so that its mean edge comes near ``h`` (it splits
each triangle into three quads: ``lc = h`` gives edges of about h / 2); embedded points and
curves embedded in the surface. The time is one gmsh run's at the ``lc`` kept. Both meshes are measured by the same numpy code, written
here: per region quads and min scaled Jacobian, irregular internal vertices (valence not 4, off
every region's boundary), whether the interfaces are conforming (every boundary edge of a
region's cells is on the union's outline or on exactly one other region's), area per region.

    python scripts/assembly_gmsh.py --png docs/assemblies.png     # the table on stdout
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import jaxmatch  # noqa: E402
from jaxmatch.meshing.pipeline import warm_up  # noqa: E402
from part_measures import corner_jacobians  # noqa: E402

SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]
LUG = {"regions": [{"name": "block", "boundary": [[0, 0], [4, 0], [4, 1], [0, 1]]},
                   {"name": "lug", "boundary": [[1.5, 1], [2.5, 1], [2.5, 1.6], [1.5, 1.6]]}]}
TWO_L = {"regions": [{"name": "a", "boundary": [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]},
                     {"name": "b", "boundary": [[2, 0], [3, 0], [3, 2], [1, 2], [1, 1], [2, 1]]}]}
CASES = [  # (name, document or example file, h)
    ("inclusion in a plate", ROOT / "examples/assemblies/inclusion.json", 0.1),
    ("laminate, thin core", ROOT / "examples/assemblies/laminate.json", 0.1),
    ("lug on a block's side (DXF layers)", ("dxf", LUG), 0.1),
    ("two L shapes", TWO_L, 0.2),
    ("motor section", ROOT / "examples/assemblies/motor.json", 0.1),
    ("crack and load point", ROOT / "examples/assemblies/crack.json", 0.1),
]


def _doc(src) -> dict:
    if isinstance(src, tuple):
        return src[1]
    return json.loads(Path(src).read_text()) if isinstance(src, Path) else src


def _file(src, tmp: Path) -> Path:
    if isinstance(src, Path):
        return src
    if isinstance(src, tuple):
        import ezdxf

        dxf = ezdxf.new()
        for r in src[1]["regions"]:
            dxf.modelspace().add_lwpolyline(r["boundary"], close=True, dxfattribs={"layer": r["name"]})
        path = tmp / "model.dxf"
        dxf.saveas(path)
        return path
    path = tmp / "model.json"
    path.write_text(json.dumps(src))
    return path


def mean_edge(xy: np.ndarray, quads: np.ndarray) -> float:
    e = np.unique(_edges(quads), axis=0)
    return float(np.linalg.norm(xy[e[:, 0]] - xy[e[:, 1]], axis=1).mean())


def gmsh_calibrated(doc: dict, h: float, tries: int = 4):
    """:func:`gmsh_assembly` with ``lc`` scaled by ``h / mean edge`` after each run (at most
    ``tries`` runs), the run whose mean edge is nearest ``h`` kept; its seconds are the last run's."""
    lc, best = h, None
    for _ in range(tries):
        t0 = time.perf_counter()
        out = gmsh_assembly(doc, lc)
        seconds = time.perf_counter() - t0
        edge = mean_edge(out[0], out[1])
        if best is None or abs(edge - h) < abs(best[1] - h):
            best = (out, edge, lc, seconds)
        lc *= h / edge
    return best


def gmsh_assembly(doc: dict, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str], int]:
    """gmsh's quasi-structured quads of the regions of ``doc`` (fragmented): ``(xy, quads,
    region per quad, region names, triangles left)``. Embedded curves and points: embedded in the
    surface (``mesh.embed``)."""
    import gmsh

    items = doc["regions"] if "regions" in doc else [dict(doc, name="region")]
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("assembly")
        occ = gmsh.model.occ
        surfaces = []
        for r in items:
            loops = []
            for ring in [r["boundary"]] + r.get("holes", []):
                pts = [occ.addPoint(float(x), float(y), 0.0, h) for x, y in ring]
                lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
                loops.append(occ.addCurveLoop(lines))
            surfaces.append(occ.addPlaneSurface(loops))
        _, mapping = occ.fragment([(2, s) for s in surfaces], [])
        occ.synchronize()
        owner = {}
        for k, dimtags in enumerate(mapping):
            for _, tag in dimtags:
                owner.setdefault(tag, k)
        if not owner:  # (one region: nothing to fragment)
            owner = {s: k for k, s in enumerate(surfaces)}
        emb = doc.get("embedded", {})
        for p in emb.get("points", []):
            t = occ.addPoint(p[0], p[1], 0.0, h)
            occ.synchronize()
            gmsh.model.mesh.embed(0, [t], 2, next(iter(owner)))
        for c in emb.get("curves", []):
            pts = [occ.addPoint(x, y, 0.0, h) for x, y in c]
            lines = [occ.addLine(pts[i], pts[i + 1]) for i in range(len(pts) - 1)]
            occ.synchronize()
            gmsh.model.mesh.embed(1, lines, 2, next(iter(owner)))
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0)
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.Algorithm", 11)
        gmsh.model.mesh.generate(2)
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        xy = coords.reshape(-1, 3)[:, :2]
        index = np.full(int(node_tags.max()) + 1, -1, np.int64)
        index[node_tags.astype(np.int64)] = np.arange(node_tags.size)
        quads, region, tris = [], [], 0
        for _, tag in gmsh.model.getEntities(2):
            for etype, _, enodes in zip(*gmsh.model.mesh.getElements(2, tag)):
                nn = gmsh.model.mesh.getElementProperties(int(etype))[3]
                conn = index[np.asarray(enodes, np.int64)].reshape(-1, nn)
                if nn == 4:
                    quads.append(conn)
                    region.append(np.full(len(conn), owner[tag]))
                else:
                    tris += len(conn)
    finally:
        gmsh.finalize()
    q = np.concatenate(quads)
    p = xy[q]
    signed = 0.5 * np.sum(p[..., 0] * np.roll(p[..., 1], -1, axis=1) - np.roll(p[..., 0], -1, axis=1) * p[..., 1], axis=1)
    q = np.where((signed < 0)[:, None], q[:, ::-1], q)
    return xy, q, np.concatenate(region), [r["name"] for r in items], tris


def scaled_jacobian(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """``(Q,)`` each quad's smallest corner scaled Jacobian (:func:`part_measures.corner_jacobians`)."""
    return corner_jacobians(xy, quads)[1].min(axis=1)


def _edges(quads: np.ndarray) -> np.ndarray:
    return np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)


def _once(quads: np.ndarray) -> set:
    keys, counts = np.unique(_edges(quads), axis=0, return_counts=True)
    return {tuple(k) for k in keys[counts == 1].tolist()}


def measure(xy, quads, region, names) -> dict:
    sj = scaled_jacobian(xy, quads)
    free = _once(quads)
    own = {r: _once(quads[region == r]) for r in range(len(names))}
    conforming = all((e in free) != (sum(e in own[o] for o in own if o != r) == 1) for r in own for e in own[r])
    on_boundary = np.zeros(len(xy), bool)
    for r in own:
        for a, b in own[r]:
            on_boundary[[a, b]] = True
    val = np.bincount(quads.ravel(), minlength=len(xy))
    irregular = int(np.sum(~on_boundary & (val != 4) & (val > 0)))
    return {"quads": len(quads), "min_sj": float(sj.min()), "irregular": irregular, "conforming": conforming,
            "per_region": {n: (int(np.sum(region == r)), float(sj[region == r].min())) for r, n in enumerate(names)}}


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--png", type=Path, help="the meshes side by side")
    args = ap.parse_args()
    warm_up()
    rows, drawn = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, src, h in CASES:
            doc = _doc(src)
            t0 = time.perf_counter()
            m = jaxmatch.mesh(str(_file(src, Path(tmp))), size=h)
            t_jm = time.perf_counter() - t0
            jm = measure(m.xy, m.quads, m.patch, list(m.regions))
            (gx, gq, gr, gnames, tris), g_edge, lc, t_g = gmsh_calibrated(doc, h)
            gm = measure(gx, gq, gr, gnames)
            rows.append((name, h, "jaxmatch", jm | {"edge": mean_edge(m.xy, m.quads)}, t_jm, 0))
            rows.append((name, h, f"gmsh-qs (lc {lc:.3g})", gm | {"edge": g_edge}, t_g, tris))
            drawn.append((name, (m.xy, m.quads, m.patch), (gx, gq, gr)))
    print("| assembly | h | mesher | quads | mean edge / h | min SJ | min SJ per region | irregular | conforming | "
          "triangles | s |")
    print("|---|---:|---|---:|---:|---:|---|---:|---|---:|---:|")
    for name, h, who, r, t, tris in rows:
        per = ", ".join(f"{n} {sj:.2f}" for n, (_, sj) in r["per_region"].items())
        print(f"| {name} | {h:g} | {who} | {r['quads']} | {r['edge'] / h:.2f} | {r['min_sj']:.3f} | {per} | {r['irregular']} | "
              f"{'yes' if r['conforming'] else 'no'} | {tris} | {t:.2f} |")
    if args.png:
        _draw(args.png, drawn)


def _draw(path: Path, drawn) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    fig, axes = plt.subplots(len(drawn), 2, figsize=(9, 2.6 * len(drawn)))
    colours = plt.get_cmap("tab20").colors[1::2] + plt.get_cmap("Pastel2").colors
    for row, (name, *meshes) in zip(axes, drawn):
        for ax, (xy, quads, region), who in zip(row, meshes, ("jaxmatch", "gmsh quasi-structured")):
            ax.add_collection(PolyCollection(xy[quads], facecolors=[colours[int(r) % len(colours)] for r in region],
                                             edgecolors="k", linewidths=0.15))
            ax.set_xlim(xy[:, 0].min(), xy[:, 0].max())
            ax.set_ylim(xy[:, 1].min(), xy[:, 1].max())
            ax.set_aspect("equal")
            ax.axis("off")
            ax.set_title(f"{name}: {who}, {len(quads)} quads", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=60)


if __name__ == "__main__":
    main()
