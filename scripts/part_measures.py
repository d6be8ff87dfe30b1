"""Measures of a quad mesh of a part, independent of jaxmatch's code (numpy, shapely, meshio only):
the yardstick of ``scripts/parts_table.py``.

:func:`measure` takes the mesh's points and 2D cells (as meshio reads them) and the part's truth
(its rings, corner points, exact area) and returns one flat dict of figures:

* ``all_quads``: every 2D cell a quad (no triangle, no polygon);
* ``folded``: quads with a corner whose Jacobian (the cross product of its two edges) is not
  positive, after orienting the whole mesh anticlockwise by the sign of its total area (so a
  quad listed in the other orientation than the rest counts as folded);
* ``loops`` / ``rings`` / ``loops_ok``: the edges used by exactly one quad, walked into closed
  loops; ``loops_ok`` when no edge is used by more than two quads, every boundary vertex has two
  boundary edges, and the loops match the input rings one to one (each loop is assigned the ring
  nearest its vertices);
* ``corners_kept`` of ``corners``: corner points within ``1e-6`` of the part's extent of a mesh
  vertex;
* ``off_ring``: largest distance of a boundary vertex to the input rings (their polygons),
  over ``h``; on the rings when it is at most :data:`RING_TOL` (a spline through the samples
  strays from their polygon by a small fraction of the sampling step);
* ``area_ratio``: the quads' total area over the exact area;
* ``min_sj`` / ``mean_sj``: per quad the smallest scaled Jacobian of its four corners (cross
  product over the product of the two edge lengths), then the min and mean over quads;
* ``irregular``: interior vertices with a valence other than 4;
* ``longest`` (longest edge / h), ``mean_edge`` (over h), ``in_band`` (share of edges with
  length in ``[0.5 h, 1.5 h]``);
* ``valid``: all quads, none folded, ``loops_ok``, every corner kept, on the rings, area within
  :data:`AREA_TOL`.
"""

from __future__ import annotations

import numpy as np
import shapely

AREA_TOL = 0.01
"""Largest relative difference of the mesh area from the exact area."""
RING_TOL = 0.01
"""Largest distance of a boundary vertex from the input rings, as a fraction of h."""
CORNER_TOL = 1e-6
"""Largest distance of a corner from a mesh vertex, as a fraction of the part's extent."""
QUAD_TYPES = ("quad",)
"""meshio cell types counted as quads; other 2D types make ``all_quads`` false."""
SURFACE_TYPES = ("triangle", "quad", "polygon", "triangle6", "triangle7", "quad8", "quad9")
"""meshio cell types of 2D cells (lines and vertices of the mesh file are ignored)."""


def quads_of(cells: dict) -> tuple[np.ndarray, int]:
    """``(quads (Q, 4) int, other)``: the quads of ``cells`` (meshio type -> ``(n, k)`` array, or
    a list of ``(type, array)``) and the number of other 2D cells."""
    items = cells.items() if isinstance(cells, dict) else cells
    quads, other = [], 0
    for kind, data in items:
        data = np.asarray(data)
        if kind in QUAD_TYPES:
            quads.append(data.reshape(-1, 4))
        elif kind in SURFACE_TYPES or kind.startswith("polygon"):
            other += len(data)
    q = np.concatenate(quads).astype(np.int64) if quads else np.zeros((0, 4), np.int64)
    return q, other


def corner_jacobians(xy: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cross (Q, 4), scaled (Q, 4))``: at each corner ``i`` of each quad the cross product
    ``(p[i+1] - p[i]) x (p[i-1] - p[i])`` (positive for an anticlockwise convex corner) and that
    over the product of the two edge lengths."""
    p = xy[quads]
    a = np.roll(p, -1, axis=1) - p
    b = np.roll(p, 1, axis=1) - p
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    norm = np.linalg.norm(a, axis=2) * np.linalg.norm(b, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled = np.where(norm > 0, cross / np.where(norm > 0, norm, 1.0), -1.0)
    return cross, scaled


def quad_areas(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Signed area of each quad ``(Q,)`` (shoelace; anticlockwise positive)."""
    p = xy[quads]
    x, y = p[..., 0], p[..., 1]
    return 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)


def edges_of(quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(edges (E, 2), uses (E,))``: every distinct edge (sorted vertex pair) and how many quads
    use it."""
    e = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    edges, uses = np.unique(e, axis=0, return_counts=True)
    return edges, uses


def boundary_loops(boundary_edges: np.ndarray) -> tuple[list[list[int]], bool]:
    """``(loops, manifold)``: the boundary edges ``(B, 2)`` walked into closed loops of vertex
    indices; ``manifold`` is false when some vertex has other than two boundary edges."""
    adj: dict[int, list[int]] = {}
    for a, b in boundary_edges.tolist():
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    manifold = all(len(v) == 2 for v in adj.values())
    seen: set[int] = set()
    loops = []
    for start in adj:
        if start in seen:
            continue
        loop, prev, v = [start], None, start
        seen.add(start)
        while True:
            nxt = [w for w in adj[v] if w != prev]
            if not nxt:
                break
            prev, v = v, nxt[0]
            if v == start or v in seen:
                break
            seen.add(v)
            loop.append(v)
        loops.append(loop)
    return loops, manifold


def measure(xy, cells, rings: list, corners, area: float, h: float) -> dict:
    """Figures of one mesh (see the module docstring).

    xy: ``(V, 2+)`` points (a z column is dropped); cells: meshio cells (type -> array, or
    ``(type, array)`` pairs); rings: the input rings, each ``(P, 2)`` (the boundary first);
    corners: ``(C, 2)`` corner points; area: the exact area; h: the element size (user units).
    """
    xy = np.asarray(xy, float)[:, :2]
    quads, other = quads_of(cells)
    rings = [np.asarray(r, float) for r in rings]
    corners = np.asarray(corners, float).reshape(-1, 2)
    extent = float(np.ptp(np.concatenate(rings), axis=0).max())
    out = {"quads": int(len(quads)), "other_cells": int(other), "all_quads": other == 0 and len(quads) > 0,
           "corners": int(len(corners)), "rings": len(rings)}
    if len(quads) == 0:
        return {**out, "valid": False, "problem": "no quads"}
    signed = quad_areas(xy, quads)
    if signed.sum() < 0:  # orient the whole mesh anticlockwise
        quads = quads[:, ::-1]
        signed = -signed
    cross, scaled = corner_jacobians(xy, quads)
    per_quad = scaled.min(axis=1)
    folded = int(np.sum(np.any(cross <= 0, axis=1)))
    edges, uses = edges_of(quads)
    loops, manifold = boundary_loops(edges[uses == 1])
    bnd = np.unique(edges[uses == 1])
    used = np.unique(quads)
    interior = np.setdiff1d(used, bnd)
    valence = np.bincount(edges.ravel(), minlength=len(xy))
    # boundary vertices against the rings
    lines = [shapely.LinearRing(r) for r in rings]
    pts = shapely.points(xy[bnd]) if len(bnd) else None
    dist = np.stack([shapely.distance(pts, ln) for ln in lines]) if len(bnd) else np.zeros((len(rings), 0))
    off = float(dist.min(axis=0).max()) / h if len(bnd) else 0.0
    owners = [int(np.argmin(np.median(dist[:, np.searchsorted(bnd, lp)], axis=1))) for lp in loops]
    loops_ok = bool(manifold and np.all(uses <= 2) and sorted(owners) == list(range(len(rings))))
    # corners
    tol = CORNER_TOL * extent
    near = [float(np.min(np.linalg.norm(xy[used] - c, axis=1))) for c in corners]
    kept = int(sum(d <= tol for d in near))
    length = np.linalg.norm(xy[edges[:, 0]] - xy[edges[:, 1]], axis=1) / h
    ratio = float(signed.sum()) / area
    out.update({
        "folded": folded, "loops": len(loops), "loops_ok": loops_ok, "corners_kept": kept, "off_ring": off,
        "area_ratio": ratio, "min_sj": float(per_quad.min()), "mean_sj": float(per_quad.mean()),
        "irregular": int(np.sum(valence[interior] != 4)), "vertices": int(len(used)), "edges": int(len(edges)),
        "longest": float(length.max()), "mean_edge": float(length.mean()),
        "in_band": float(np.mean((length >= 0.5) & (length <= 1.5))),
    })
    problems = [name for name, bad in (("not all quads", not out["all_quads"]), (f"{folded} folded", folded > 0),
                                       (f"{len(loops)} boundary loops for {len(rings)} rings", not loops_ok),
                                       (f"{len(corners) - kept} corners missed", kept < len(corners)),
                                       (f"boundary {off:.3g} h off the rings", off > RING_TOL),
                                       (f"area ratio {ratio:.4f}", abs(ratio - 1) > AREA_TOL)) if bad]
    out["valid"] = not problems
    out["problem"] = "; ".join(problems)
    return out
