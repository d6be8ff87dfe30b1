"""Polygon helpers for closed loops, on shapely (GEOS) where it has the operation.

A *loop* is ``points (P, 2) float64``: a closed polyline, first point not repeated, the closing
segment ``points[-1] -> points[0]`` implied. Arc-length parameters ``t`` are measured from
``points[0]`` along the loop in listing order, in the loop's length unit.

What comes from shapely: area and orientation (:func:`signed_area`), simplicity with the
crossing segments named (:func:`first_crossing`, an STR-tree of the segments and GEOS's robust
predicates instead of an O(P^2) pair loop), positions at arc length (:func:`point_at`,
``shapely.line_interpolate_point``) and pieces of the loop (:func:`sub_polyline`,
``shapely.ops.substring``). Kept in numpy: :func:`cumulative_length` (shapely gives the total
length, not the length up to each vertex) and :func:`turning_angles`.
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely.ops import substring

__all__ = [
    "VERTEX_SNAP",
    "closed_line",
    "cumulative_length",
    "first_crossing",
    "point_at",
    "signed_area",
    "sub_polyline",
    "turning_angles",
]

VERTEX_SNAP = 1e-9
"""Relative tolerance (times the perimeter): parameters this close to a loop vertex give the
vertex exactly (so corners and annotated points land on input vertices without round-off)."""


def _loop(points) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 2:
        raise ValueError(f"a loop is a (P, 2) array with P >= 2, got shape {p.shape}")
    return p


def closed_line(points) -> shapely.LineString:
    """The loop ``(P, 2)`` as a shapely LineString with the first point repeated at the end."""
    p = _loop(points)
    return shapely.LineString(np.concatenate([p, p[:1]]))


def signed_area(points) -> float:
    """Area enclosed by the loop ``(P, 2)``; positive when counter-clockwise (shoelace sign).

    For a self-crossing loop this is the shoelace sum (lobes of opposite turn cancel), as the
    orientation of such a loop is not defined otherwise.
    """
    p = _loop(points)
    if p.shape[0] < 3:
        return 0.0
    ring = shapely.LinearRing(p)
    if shapely.is_simple(ring):
        area = float(shapely.Polygon(ring).area)
        return area if shapely.is_ccw(ring) else -area
    q = np.roll(p, -1, axis=0)  # GEOS has no signed area for a crossing ring
    return float(0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def cumulative_length(points) -> np.ndarray:
    """Arc length from ``points[0]`` to each point, ``(P + 1,) float64``; the last entry is the
    perimeter (closing segment back to ``points[0]`` included)."""
    p = _loop(points)
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def turning_angles(points) -> np.ndarray:
    """Signed turning angle at each point of the loop, ``(P,) float64`` radians in ``(-pi, pi]``;
    positive is a left turn (convex for a counter-clockwise loop)."""
    p = _loop(points)
    e_in = p - np.roll(p, 1, axis=0)
    e_out = np.roll(p, -1, axis=0) - p
    cross = e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]
    dot = np.sum(e_in * e_out, axis=1)
    return np.arctan2(cross, dot)


def point_at(points, t) -> np.ndarray:
    """Positions at arc-length parameters ``t`` (any shape; taken modulo the perimeter) along
    the loop ``points (P, 2)``. Returns ``t.shape + (2,) float64``.

    Parameters within :data:`VERTEX_SNAP` times the perimeter of a vertex return that vertex
    exactly.
    """
    p = _loop(points)
    cum = cumulative_length(p)
    per = float(cum[-1])
    t = np.asarray(t, dtype=np.float64)
    tt = np.mod(t, per) if per > 0 else np.zeros_like(t)
    out = shapely.get_coordinates(shapely.line_interpolate_point(closed_line(p), tt.ravel())).reshape(t.shape + (2,))
    # snap to vertices: the nearest vertex parameter on either side
    idx = np.clip(np.searchsorted(cum, tt, side="right") - 1, 0, p.shape[0] - 1)
    tol = VERTEX_SNAP * per
    out = np.where((np.abs(tt - cum[idx]) <= tol)[..., None], p[idx], out)
    out = np.where((np.abs(cum[idx + 1] - tt) <= tol)[..., None], p[(idx + 1) % p.shape[0]], out)
    return out


def sub_polyline(points, t0: float, t1: float) -> np.ndarray:
    """The loop from parameter ``t0`` to ``t1`` (``t0 <= t1 <= t0 + perimeter``; wraps past
    ``points[0]``), through every vertex in between: ``(k, 2) float64``, both ends included
    (ends within :data:`VERTEX_SNAP` of a vertex are that vertex)."""
    p = _loop(points)
    cum = cumulative_length(p)
    per = float(cum[-1])
    t0, t1 = float(t0), float(t1)
    if not (t0 <= t1 <= t0 + per * (1 + 1e-12)):
        raise ValueError(f"need t0 <= t1 <= t0 + perimeter, got t0={t0}, t1={t1}, perimeter={per}")
    start = np.mod(t0, per) if per > 0 else 0.0
    twice = shapely.LineString(np.concatenate([p, p, p[:1]]))  # two laps: pieces that wrap stay one line
    piece = substring(twice, start, start + (t1 - t0))
    xy = shapely.get_coordinates(piece)
    if xy.shape[0] == 1:
        xy = np.concatenate([xy, xy])
    ends = point_at(p, np.array([t0, t1]))
    inner = xy[1:-1]
    if inner.shape[0]:  # drop interior points that coincide with a snapped end
        tol = VERTEX_SNAP * per
        keep = (np.linalg.norm(inner - ends[0], axis=1) > tol) & (np.linalg.norm(inner - ends[1], axis=1) > tol)
        inner = inner[keep]
    return np.concatenate([ends[:1], inner, ends[1:]])


def first_crossing(points) -> tuple[int, int] | None:
    """First pair ``(i, j)``, ``i < j``, of loop segments ``i -> i+1`` and ``j -> j+1`` that
    meet where they must not, or None when the loop is simple.

    Non-adjacent segments must not touch at all; adjacent ones (sharing a vertex) must not
    overlap along a piece (a fold back at the shared vertex). Candidate pairs come from a
    shapely STR-tree query with GEOS's ``intersects`` predicate; O(P log P) for ordinary loops.
    """
    p = _loop(points)
    n = p.shape[0]
    segs = shapely.linestrings(np.stack([p, np.roll(p, -1, axis=0)], axis=1))
    tree = shapely.STRtree(segs)
    left, right = tree.query(segs, predicate="intersects")
    keep = left < right
    i, j = left[keep], right[keep]
    if i.size == 0:
        return None
    adjacent = (j == i + 1) | ((i == 0) & (j == n - 1))
    bad = ~adjacent
    if adjacent.any():  # a shared end point is fine; sharing a piece of line is a fold
        a = np.flatnonzero(adjacent)
        bad[a] = shapely.relate_pattern(segs[i[a]], segs[j[a]], "1********")
    if not bad.any():
        return None
    order = np.lexsort((j[bad], i[bad]))
    k = order[0]
    return int(i[bad][k]), int(j[bad][k])
