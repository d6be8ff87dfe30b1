#!/usr/bin/env python3
"""Regions with holes: ``jaxmatch.mesh`` beside gmsh's quasi-structured quad meshing
(Algorithm 11, its size calibrated so that its mean edge comes out ~h) on ``examples/holes/``
at h = outer perimeter / 40 and / 80, in one run. Every figure is measured here from the
mesh's points and quads and the input file, independently of jaxmatch's own code.

    .venv/bin/python scripts/holes_table.py [--divisions 40,80] [--json OUT.jsonl] [--png FILE] [--no-gmsh]

Valid: all quads, no fold (every quad corner turns left), one boundary loop per input ring,
every corner of every ring a vertex, area within 1 %, every boundary vertex on an input ring
(within 1e-9 of the outer loop's extent). Also: min / mean scaled Jacobian, irregular internal
vertices, Euler's lower bound ``|4 (1 - holes) - sum over boundary vertices (3 - valence)|``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

sys.path.insert(0, str(Path(__file__).resolve().parent))

from jaxmatch.cli import run_typer  # noqa: E402
from jaxmatch.geometry import cumulative_length  # noqa: E402
from mesh_table import scaled_jacobian, write_outputs  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
HOLES = ROOT / "examples" / "holes"

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def boundary_loops(quads: np.ndarray) -> list[list[int]]:
    """Loops of the edges used by one quad, walked from the directed edges."""
    d = np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2)
    key = np.sort(d, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    b = d[cnt[inv.ravel()] == 1]
    nxt = {int(a): int(c) for a, c in b}
    loops, seen = [], set()
    for s in nxt:
        if s in seen:
            continue
        loop, v = [], s
        while v not in seen and v in nxt:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(loop)
    return loops


def seg_distance(p: np.ndarray, ring: np.ndarray) -> np.ndarray:
    """Distance of each point of ``p (k, 2)`` to the closed polyline ``ring``."""
    a, b = ring, np.roll(ring, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("kmj,mj->km", p[:, None, :] - a[None], ab) / np.sum(ab * ab, axis=1), 0, 1)
    proj = a[None] + t[..., None] * ab[None]
    return np.min(np.linalg.norm(p[:, None, :] - proj, axis=2), axis=1)


def check(xy: np.ndarray, quads: np.ndarray, outer: np.ndarray, holes: list[np.ndarray], corners: np.ndarray,
          h: float) -> dict:
    """Validity and quality of one mesh of the region, from its points and quads alone."""
    import shapely

    quads = np.asarray(quads, np.int64)
    sj = scaled_jacobian(xy, quads)
    loops = boundary_loops(quads)
    e = np.unique(np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2), axis=1), axis=0)
    val = np.bincount(e.ravel(), minlength=len(xy))
    bnd = np.zeros(len(xy), bool)
    for lp in loops:
        bnd[lp] = True
    used = np.zeros(len(xy), bool)
    used[quads.ravel()] = True
    irregular = int(np.sum(used & ~bnd & (val != 4)))
    bound = abs(4 * (1 - len(holes)) - int(np.sum(3 - val[bnd])))
    p = xy[quads]
    area = 0.5 * float(np.sum(p[:, :, 0] * np.roll(p[:, :, 1], -1, 1) - np.roll(p[:, :, 0], -1, 1) * p[:, :, 1]))
    region = shapely.Polygon(outer, holes=holes).area
    ext = float(np.ptp(outer, axis=0).max())
    missed = int(sum(np.min(np.linalg.norm(xy - c, axis=1)) > 1e-9 * ext for c in corners))
    on_ring = np.min(np.stack([seg_distance(xy[bnd], r) for r in [outer, *holes]]), axis=0) if bnd.any() else np.zeros(0)
    edge = np.linalg.norm(xy[e[:, 0]] - xy[e[:, 1]], axis=1)
    ok = (len(loops) == 1 + len(holes) and int(np.sum(sj <= 0)) == 0 and missed == 0
          and abs(area / region - 1) <= 0.01 and bool(np.all(on_ring <= 1e-9 * ext)))
    return {"quads": int(len(quads)), "min_sj": float(sj.min()), "mean_sj": float(sj.mean()),
            "inverted": int(np.sum(sj <= 0)), "loops": len(loops), "rings": 1 + len(holes), "missed_corners": missed,
            "area_ratio": area / region, "off_ring": float(on_ring.max()) / ext if on_ring.size else 0.0,
            "irregular": irregular, "irregular_bound": bound, "mean_edge_over_h": float(edge.mean() / h), "valid": ok}


@app.command()
def main(divisions: str = typer.Option("40,80", help="h = outer perimeter / each of these."),
         json_out: Optional[Path] = typer.Option(None, "--json", help="Also write one JSON line per mesh."),
         png: Optional[Path] = typer.Option(None, "--png", help="Draw jaxmatch beside gmsh for --picture at the first size."),
         picture: str = typer.Option("plate-bolt,washer,frame,letter-B", help="Regions drawn with --png."),
         no_gmsh: bool = typer.Option(False, "--no-gmsh", help="jaxmatch only.")) -> None:
    import jaxmatch
    from compare_gmsh import gmsh_calibrated

    cat = jaxmatch.load_catalogue()
    rows, panels = [], []
    draw = set(picture.split(",")) if png else set()
    divs = [int(d) for d in divisions.split(",")]
    for path in sorted(HOLES.glob("*.json")):
        name = path.stem
        shp = jaxmatch.load_shape(path)
        outer = shp.input_points
        holes = [np.asarray(r) for r in shp.holes]
        corners = np.concatenate([outer[shp.corners]] + [r[c] for r, c in zip(holes, shp.hole_corners)])
        per = float(cumulative_length(outer)[-1])
        for div in divs:
            h = per / div
            t0 = time.perf_counter()
            try:
                m = jaxmatch.mesh(shp, size=h, catalogue=cat)
                rec = {"region": name, "div": div, "method": "jaxmatch", "chosen": m.chosen,
                       "seconds": time.perf_counter() - t0, **check(m.xy, m.quads, outer, holes, corners, h)}
                if name in draw and div == divs[0]:
                    panels.append((f"{name}, P/{div}: jaxmatch ({m.chosen})", m.xy, m.quads, m.patch, None, corners))
            except Exception as e:  # a failure is a row
                rec = {"region": name, "div": div, "method": "jaxmatch", "error": str(e), "valid": False}
            rows.append(rec)
            if no_gmsh:
                continue
            t0 = time.perf_counter()
            try:
                g = gmsh_calibrated(outer, h, holes=holes)
                rec = {"region": name, "div": div, "method": "gmsh-qs", "chosen": "", "seconds": time.perf_counter() - t0,
                       **check(g["xy"], g["quads"], outer, holes, corners, h)}
                if name in draw and div == divs[0]:
                    panels.append((f"{name}, P/{div}: gmsh quasi-structured", g["xy"], g["quads"], None, None, corners))
            except Exception as e:
                rec = {"region": name, "div": div, "method": "gmsh-qs", "error": str(e), "valid": False}
            rows.append(rec)
    print("| region | P/h | method | chosen | quads | min SJ | mean SJ | irregular (bound) | edge/h | valid |")
    print("|---|---:|---|---|---:|---:|---:|---:|---:|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['region']} | {r['div']} | {r['method']} | error: {r['error'][:70]} | | | | | | no |")
            continue
        print(f"| {r['region']} | {r['div']} | {r['method']} | {r['chosen']} | {r['quads']} | {r['min_sj']:.3f} | "
              f"{r['mean_sj']:.3f} | {r['irregular']} ({r['irregular_bound']}) | {r['mean_edge_over_h']:.2f} | "
              f"{'yes' if r['valid'] else 'NO'} |")
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        ok = [r for r in mine if "error" not in r]
        if not ok:
            continue
        print(f"{method}: valid {sum(r['valid'] for r in mine)}/{len(mine)}; mean of min SJ "
              f"{np.mean([r['min_sj'] for r in ok]):.3f}; worst {min(r['min_sj'] for r in ok):.3f}; irregular per mesh "
              f"{np.mean([r['irregular'] for r in ok]):.2f} (above the bound {np.mean([r['irregular'] - r['irregular_bound'] for r in ok]):.2f}); "
              f"median time {np.median([r['seconds'] for r in ok]) * 1000:.0f} ms")
    write_outputs(rows, panels, png, json_out)


if __name__ == "__main__":
    run_typer(app)
