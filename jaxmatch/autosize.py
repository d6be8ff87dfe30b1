"""Automatic sizing: the size field a part's own features ask for, on top of the user's size.

Three kinds of feature make the mesh finer than the size ``H``, each an entry
``Near("curve", polyline, s, REACH * H)`` of a :class:`~jaxmatch.field.Field` (the size grows back
to ``H`` over :data:`REACH` ``* H``), the way gmsh's curvature sizing and Cubit's proximity sizing
do:

* **thin parts** (proximity): a boundary point whose inward normal meets the boundary again at
  ``t < H`` (a fin, a tooth, the neck of a keyhole, a web between two holes) asks for
  ``s = t / ACROSS`` there (:data:`ACROSS` elements across);
* **curvature**: a point of a curved stretch (no corner) of radius ``r`` asks for
  ``s = r * ARC_ANGLE`` (radians; :data:`ARC_ANGLE` degrees of arc per edge);
* **small holes**: a hole of perimeter ``P < RING_EDGES * H`` asks for ``s = P / RING_EDGES`` on it.

Each run of consecutive boundary samples asking for less than ``H`` becomes one entry per
:data:`CHUNK` samples (its smallest ``s``). ``jaxmatch mesh --auto-size`` and
``jaxmatch.mesh(..., auto_size=True)`` apply it; a region without such features keeps its uniform
size.
"""

from __future__ import annotations

import math

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.field import Field, Near
from jaxmatch.geometry import turning_angles
from jaxmatch.lazy import Later

__all__ = ["ACROSS", "ARC_ANGLE", "CHUNK", "REACH", "RING_EDGES", "SAMPLES_PER_SIZE", "auto_field", "feature_sizes"]

ACROSS = 1.0
"""Elements across a part thinner than the size, at least."""

ARC_ANGLE = 30.0
"""Degrees of arc an edge of a curved stretch spans at most (12 edges on a full circle)."""

RING_EDGES = 8
"""Edges around a small hole, at least."""

REACH = 2.0
"""A feature's size grows back to ``H`` over this many ``H``."""

SAMPLES_PER_SIZE = 4
"""Boundary samples per ``H`` along straight runs (besides every outline point), for the
thickness test."""

CHUNK = 8
"""Consecutive samples of one entry of the field, at most."""

later = Later(shapely="shapely")  # geometry: only when automatic sizing is asked for


def _loops(shape) -> list[np.ndarray]:
    """The region's loops in user coordinates, region on the left: the outer loop, then the holes."""
    return [np.asarray(shape.given_points, np.float64)] + [np.asarray(h, np.float64) for h in shape.holes]


def _samples(loop: np.ndarray, H: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(points (n, 2), inward normals (n, 2), vertex index or -1 (n,))`` along the closed
    ``loop``: every loop point, and points :data:`SAMPLES_PER_SIZE` per ``H`` along longer edges."""
    nxt = roll(loop, -1)
    out, normals, at = [], [], []
    for i, (a, b) in enumerate(zip(loop, nxt)):
        e = b - a
        L = float(np.linalg.norm(e))
        if L == 0.0:
            continue
        n = np.array([-e[1], e[0]]) / L  # left normal: into the region
        k = max(1, int(math.ceil(L * SAMPLES_PER_SIZE / H)))
        t = np.arange(k) / k
        out.append(a + t[:, None] * e)
        normals.append(np.repeat(n[None], k, axis=0))
        at.append(np.where(t == 0, i, -1))
    pts, nrm, idx = np.concatenate(out), np.concatenate(normals), np.concatenate(at)
    vert = idx >= 0  # at a loop point: the mean of its two edges' normals
    prev = roll(nrm, 1)
    mean = nrm[vert] + prev[vert]
    norm = np.linalg.norm(mean, axis=1, keepdims=True)
    nrm[vert] = np.where(norm > 1e-12, mean / np.maximum(norm, 1e-300), nrm[vert])
    return pts, nrm, idx


def _thickness(points: np.ndarray, normals: np.ndarray, boundary, H: float, ext: float) -> np.ndarray:
    """``(n,)`` the distance along each inward normal to the next boundary crossing, or ``inf``
    beyond ``H``."""
    shapely = later.shapely
    start = points + 1e-9 * ext * normals
    rays = shapely.linestrings(np.stack([start, points + H * normals], axis=1))
    hits = shapely.intersection(rays, boundary)
    out = np.full(points.shape[0], np.inf)
    for k, hit in enumerate(hits):
        if hit.is_empty:
            continue
        c = shapely.get_coordinates(hit)
        d = np.linalg.norm(c - points[k], axis=1)
        d = d[d > 1e-7 * ext]
        if d.size:
            out[k] = float(d.min())
    return out


def _curvature_sizes(loop: np.ndarray, corners: set[int]) -> np.ndarray:
    """``(P,)`` the size the curvature at each loop point asks for (``inf`` at corners and on
    straight runs): ``r * ARC_ANGLE`` with ``r`` the radius through the point and its neighbours."""
    turn = np.abs(turning_angles(loop))
    a = np.linalg.norm(loop - roll(loop, 1), axis=1)
    b = np.linalg.norm(roll(loop, -1) - loop, axis=1)
    r = np.where(turn > 1e-6, 0.5 * (a + b) / np.maximum(turn, 1e-300), np.inf)
    s = r * math.radians(ARC_ANGLE)
    if corners:
        s[list(corners)] = np.inf
    return s


def feature_sizes(shape, H: float) -> list[tuple[np.ndarray, float]]:
    """``[(polyline (m, 2), s)]``: the stretches of the region's loops that ask for a size
    ``s < H`` (thin parts, curvature), each at most :data:`CHUNK` samples, and the small holes
    (the whole hole, closed)."""
    shapely = later.shapely
    loops = _loops(shape)
    ext = float(np.max(np.ptp(loops[0], axis=0)))
    boundary = shapely.MultiLineString([np.vstack([x, x[:1]]) for x in loops])
    out = []
    for k, loop in enumerate(loops):
        pts, nrm, idx = _samples(loop, H)
        s = _thickness(pts, nrm, boundary, H, ext) / ACROSS
        corners = _corner_indices(shape, k, loop)
        curv = _curvature_sizes(loop, corners)
        s[idx >= 0] = np.minimum(s[idx >= 0], curv[idx[idx >= 0]])
        small = s < H
        if k > 0:
            per = float(np.sum(np.linalg.norm(roll(loop, -1) - loop, axis=1)))
            if per < RING_EDGES * H:
                out.append((np.vstack([loop, loop[:1]]), per / RING_EDGES))
        if not small.any():
            continue
        n = small.size
        start = 0 if small.all() else int(np.flatnonzero(~small)[0])
        run: list[int] = []
        for j in range(n + 1):
            i = (start + j) % n
            if j < n and small[i] and len(run) < CHUNK:
                run.append(i)
                continue
            if run:
                poly = pts[run] if len(run) > 1 else np.vstack([pts[run[0]], pts[run[0]]])
                out.append((poly, float(s[run].min())))
            run = [i] if j < n and small[i] else []
    return out


def _corner_indices(shape, k: int, loop: np.ndarray) -> set[int]:
    """The corners of loop ``k`` (0: the outer loop) as indices into ``loop``, by coordinates."""
    if k == 0:
        if shape.n_corners == 0:
            return set()
        user = shape.to_user(shape.points[np.asarray(shape.corners, np.int64)])
    else:
        corners = shape.hole_corners[k - 1]
        if len(corners) == 0:
            return set()
        user = np.asarray(shape.holes[k - 1], np.float64)[np.asarray(corners, np.int64)]
    return {int(np.argmin(np.linalg.norm(loop - u, axis=1))) for u in np.atleast_2d(user)}


def auto_field(shape, H: float, user: Field | None = None) -> Field | None:
    """The size field of ``shape`` at largest size ``H``: ``user``'s entries (a
    :class:`~jaxmatch.field.Field` or None) and one ``Near("curve", ...)`` per feature of
    :func:`feature_sizes`; None when there is neither (the uniform size ``H`` stands)."""
    near = [Near("curve", tuple(map(tuple, poly.tolist())), min(s, H), REACH * H) for poly, s in feature_sizes(shape, H)]
    if user is None and not near:
        return None
    return Field(H, tuple(user.near if user is not None else ()) + tuple(near),
                 source=user.source if user is not None else None)
