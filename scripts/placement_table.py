"""The placement table: is the top mesh a good mesh *of the shape*, for every polygonal shape and size?

For every polygonal shape (every outline vertex is a corner) of ``examples/*.json`` and
``examples/labels/shapes/*.json`` and every size K (internal vertices) for which some catalogue
mesh can keep all corners, places the top-ranked mesh (``choose_mesh(..., internal=[K])``, the
defaults of ``jaxmatch mesh SHAPE --internal K``) and measures it *independently of the
placement code*, from the vertex positions and quads alone:

* corners kept: shape corners within ``1e-9`` (times the shape's size) of a mesh vertex;
* inverted: quads with a corner of signed area ``<= 0``;
* area ratio: sum of the quads' shoelace areas over the shape's area (shapely);
* min scaled Jacobian (Verdict: min over corners of ``e1 x e2 / (|e1| |e2|)``);
* max edge ratio: longest over shortest edge of a quad, max over quads.

A row passes when every corner is kept, no quad is inverted, ``|area ratio - 1| <= 1e-9`` and
min scaled Jacobian ``>= 0.3``. "Some catalogue mesh keeps all corners" is decided by scoring
the catalogue with a table that counts matched corners (1 per corner pairing the lattice allows,
0 per straight pairing it allows, ``-inf`` for the pairings it forbids): the best count equals
the number of corners.

The script only uses ``choose_mesh``, ``load_lattice``, ``default_catalogue``, ``load_shape`` and
``score_bucket``, so it runs on older trees too, which is how the "before" column is produced: run
it with the other tree's ``jaxmatch`` imported (its own environment, with shapely; or this one with
``sys.path`` starting at the other tree and the editable-install finder of this tree removed from
``sys.meta_path``)::

    /path/to/main/.venv/bin/python scripts/placement_table.py --out before.json
    .venv/bin/python scripts/placement_table.py --out after.json
    .venv/bin/python scripts/placement_table.py --compare before.json after.json   # markdown table

``--lattice NAME`` (before ``--out``) scores with another lattice (default: ``fine``).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import shapely

ROOT = Path(__file__).resolve().parent.parent
SHAPES = sorted((ROOT / "examples").glob("*.json")) + sorted((ROOT / "examples" / "labels" / "shapes").glob("*.json"))
KS = range(0, 6)
MIN_SJ = 0.3
AREA_TOL = 1e-9


def measures(shape_user: np.ndarray, corners_user: np.ndarray, xy: np.ndarray, quads: np.ndarray) -> dict:
    """Independent measures of a placed mesh (see the module docstring)."""
    size = float(np.ptp(shape_user, axis=0).max())
    d = np.linalg.norm(corners_user[:, None, :] - xy[None, :, :], axis=-1).min(axis=1)
    kept = int(np.sum(d <= 1e-9 * size))
    p = xy[quads]
    e1 = np.roll(p, -1, axis=1) - p
    e2 = np.roll(p, 1, axis=1) - p
    cross = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    ln1, ln2 = np.linalg.norm(e1, axis=-1), np.linalg.norm(e2, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        sj = np.where(ln1 * ln2 > 0, cross / (ln1 * ln2), 0.0).min(axis=1)
        er = ln1.max(axis=1) / ln1.min(axis=1)
    q = np.roll(p, -1, axis=1)
    area = float(np.sum(0.5 * np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0], axis=1)))
    ratio = area / shapely.Polygon(shape_user).area
    inverted = int(np.sum((cross <= 0).any(axis=1)))
    row = {"corners": int(len(corners_user)), "kept": kept, "inverted": inverted, "area_ratio": ratio,
           "min_sj": float(sj.min()), "max_edge_ratio": float(er.max()), "quads": int(len(quads))}
    row["pass"] = bool(kept == len(corners_user) and inverted == 0 and abs(ratio - 1) <= AREA_TOL and row["min_sj"] >= MIN_SJ)
    return row


def corner_feasible(shape, catalogue, lattice, k: int, m: int) -> bool:
    """Some mesh with k internal vertices can match every corner (under the lattice's forbidden
    pairings), with ``m`` annotated points."""
    from jaxmatch.scoring.exact import score_bucket
    from jaxmatch.shape import annotate

    ann = annotate(shape, m)
    t = np.asarray(lattice.table(), np.float64)
    count = np.where(np.isfinite(t), 0.0, -np.inf)
    count[1:] = np.where(np.isfinite(t[1:]), 1.0, -np.inf)
    best = -np.inf
    for b in catalogue.buckets([k]):
        if b.n > m:
            continue
        res = score_bucket(ann.codes, b.valences, count.astype(np.float32))
        if len(res.utility):
            best = max(best, float(np.max(res.utility)))
    return best >= shape.n_corners


def run(out: Path, names: list[str] | None, lattice: str = "fine") -> list[dict]:
    from jaxmatch.catalogue.store import default_catalogue
    from jaxmatch.placement.choose import choose_mesh
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.scoring.rank import selected_lengths
    from jaxmatch.io.readers import load_shape
    from jaxmatch.shape import default_points

    cat = default_catalogue()
    lat = load_lattice(lattice)
    rows = []
    for path in SHAPES:
        rel = str(path.relative_to(ROOT))
        if names and path.stem not in names and rel not in names:
            continue
        shp = load_shape(path)
        if shp.n_corners != shp.n_points:  # curved or smooth: not a polygon
            continue
        user = shp.user_points
        corners = user[shp.corners]
        for k in KS:
            m = default_points(shp, max(selected_lengths(cat, [k])))
            if not corner_feasible(shp, cat, lat, k, m):
                rows.append({"shape": rel, "k": k, "feasible": False})
                continue
            t0 = time.perf_counter()
            c = choose_mesh(shp, cat, lat, internal=[k])
            pl = c.placement
            row = {"shape": rel, "k": k, "feasible": True, "mesh_id": c.match.mesh_id, "utility": float(c.match.utility),
                   **measures(user, corners, pl.xy, pl.mesh.quads), "seconds": round(time.perf_counter() - t0, 2)}
            rows.append(row)
            print(json.dumps(row), file=sys.stderr, flush=True)
    out.write_text(json.dumps(rows, indent=0))
    return rows


def fmt(r: dict | None) -> str:
    if r is None or not r.get("feasible"):
        return "| – | – | – | – |"
    return (f"| {r['kept']}/{r['corners']} | {r['inverted']} | {r['min_sj']:.3f} | {r['max_edge_ratio']:.2f} "
            f"| {'%.2e' % (r['area_ratio'] - 1)} | {'yes' if r['pass'] else '**no**'} |")


def compare(before: Path, after: Path) -> None:
    a = {(r["shape"], r["k"]): r for r in json.loads(before.read_text())}
    b = {(r["shape"], r["k"]): r for r in json.loads(after.read_text())}
    keys = sorted(k for k in set(a) | set(b) if (b.get(k) or a.get(k)).get("feasible"))
    print("| shape | K | before: corners kept | inverted | min SJ | max edge ratio | area ratio - 1 | pass "
          "| after: corners kept | inverted | min SJ | max edge ratio | area ratio - 1 | pass |")
    print("|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---|")
    for key in keys:
        ra, rb = a.get(key), b.get(key)
        left = fmt(ra) if ra and ra.get("feasible") else "| – | – | – | – | – | – |"
        right = fmt(rb) if rb and rb.get("feasible") else "| – | – | – | – | – | – |"
        name = key[0].removeprefix("examples/").removesuffix(".json")
        print(f"| {name} | {key[1]} |{left[1:]}{right[1:]}")
    for name, d in (("before", a), ("after", b)):
        rows = [d[k] for k in keys if k in d and d[k].get("feasible")]
        print(f"\n{name}: {sum(r['pass'] for r in rows)} of {len(rows)} pass; corners all kept in "
              f"{sum(r['kept'] == r['corners'] for r in rows)}; no inverted quad in {sum(r['inverted'] == 0 for r in rows)}; "
              f"min SJ >= {MIN_SJ} in {sum(r['min_sj'] >= MIN_SJ for r in rows)}")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--compare"] and len(argv) == 3:
        compare(Path(argv[1]), Path(argv[2]))
        return
    lattice = "fine"
    if argv[:1] == ["--lattice"] and len(argv) >= 2:
        lattice, argv = argv[1], argv[2:]
    if len(argv) >= 2 and argv[0] == "--out":
        run(Path(argv[1]), argv[2:] or None, lattice)
        return
    print("usage: placement_table.py [--lattice NAME] --out rows.json [SHAPE ...] | --compare before.json after.json",
          file=sys.stderr)
    sys.exit(2)


if __name__ == "__main__":
    main(sys.argv[1:])
