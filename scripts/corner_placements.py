"""Can *any* catalogue mesh of a size be placed well in a polygon with every corner kept?

The placement table (``scripts/placement_table.py``) places the ranked mesh. When it fails, this
script answers whether another choice could have passed: for every catalogue mesh with ``k``
internal vertices, every orientation (each boundary vertex on the first corner, both mirror
images) and every assignment of the remaining corners to boundary vertices in order, it puts
those vertices exactly on the corners, spreads the other boundary vertices evenly by arc length
between them, places the mesh (Tutte, untangling, smoothing; then again with the vertices of
each side free to slide along it) and measures the result from the vertex positions alone.

    .venv/bin/python scripts/corner_placements.py examples/labels/shapes/ushape.json 1
    .venv/bin/python scripts/corner_placements.py --json SHAPE K [SHAPE K ...]

Prints, per (shape, k): meshes, placements tried, and the best fold-free placement's min scaled
Jacobian; "passes" when some placement has no inverted quad and min scaled Jacobian >= 0.3.
Only for polygons (every outline vertex a corner) and small k (the count grows as
``n * 2 * C(n - 1, c - 1)`` per mesh of ``n`` boundary vertices and ``c`` corners).
"""

from __future__ import annotations

import json
import sys
from itertools import combinations
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
TARGET = 0.3


def min_sj(xy: np.ndarray, quads: np.ndarray) -> tuple[int, float]:
    """(inverted quads, min scaled Jacobian) from positions alone."""
    p = xy[quads]
    e1, e2 = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
    cross = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    ln = np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        sj = np.where(ln > 0, cross / ln, 0.0)
    return int(np.sum((cross <= 0).any(axis=1))), float(sj.min())


def search(shape_path: Path, k: int) -> dict:
    from jaxmatch.catalogue.store import default_catalogue
    from jaxmatch.geometry import point_at
    from jaxmatch.placement.embed import place
    from jaxmatch.io.readers import load_shape

    shp = load_shape(shape_path)
    if shp.n_corners != shp.n_points:
        raise SystemExit(f"{shape_path}: not a polygon (every outline vertex must be a corner)")
    cat = default_catalogue()
    pts = shp.points
    cum = shp.arc_length
    per = float(cum[-1])
    tc = cum[np.asarray(shp.corners)]  # corner parameters, increasing
    c = tc.shape[0]
    best = {"min_sj": -np.inf, "mesh_id": None}
    meshes = tried = 0
    for b in cat.buckets([k]):
        n = b.n
        if n < c:
            continue
        for mid in b.ids:
            mesh = cat.mesh(str(mid))
            meshes += 1
            for refl in (False, True):
                for rot in range(n):
                    for rest in combinations(range(1, n), c - 1):
                        J = np.array((0, *rest))  # boundary vertex J[i] on corner i
                        u = np.empty(n)
                        groups = []
                        for i in range(c):
                            ja, jb = J[i], (J[i + 1] if i + 1 < c else n)
                            ta, tb = tc[i], (tc[i + 1] if i + 1 < c else tc[0] + per)
                            r = jb - ja - 1
                            u[ja] = ta
                            js = ja + 1 + np.arange(r)
                            u[js] = ta + (tb - ta) * np.arange(1, r + 1) / (r + 1)
                            if r:
                                groups.append((int(ja), int(jb % n), js.astype(np.int64)))
                        bxy = point_at(pts, u, cum)
                        bxy[J] = pts[np.asarray(shp.corners)]
                        t = np.mod(u, per)
                        for slide in ((), tuple(groups)):
                            tried += 1
                            al = np.arange(n)
                            pl = place(pts, u - u[0], al, mesh, rot, refl, boundary_xy=bxy, boundary_t=t, slide_groups=slide,
                                       paths=False)
                            inv, sj = min_sj(pl.xy, pl.mesh.quads)
                            if inv == 0 and sj > best["min_sj"]:
                                best = {"min_sj": sj, "mesh_id": str(mid), "rotation": rot, "reflected": refl,
                                        "corner_vertices": J.tolist(), "slid": bool(slide)}
    return {"shape": str(shape_path), "k": k, "corners": c, "meshes": meshes, "placements": tried,
            "best_fold_free": best if best["mesh_id"] else None,
            "passes": bool(best["mesh_id"] and best["min_sj"] >= TARGET)}


def main(argv: list[str]) -> None:
    as_json = argv[:1] == ["--json"]
    args = argv[1:] if as_json else argv
    if len(args) < 2 or len(args) % 2:
        print("usage: corner_placements.py [--json] SHAPE K [SHAPE K ...]", file=sys.stderr)
        sys.exit(2)
    out = [search(Path(args[i]), int(args[i + 1])) for i in range(0, len(args), 2)]
    if as_json:
        print(json.dumps(out))
        return
    for r in out:
        b = r["best_fold_free"]
        best = "none without a fold" if b is None else f"best fold-free min SJ {b['min_sj']:.3f} ({b['mesh_id']})"
        print(f"{r['shape']} k={r['k']}: {r['meshes']} meshes, {r['placements']} placements; {best}; "
              f"{'passes' if r['passes'] else 'no placement reaches ' + str(TARGET)}")


if __name__ == "__main__":
    main(sys.argv[1:])
