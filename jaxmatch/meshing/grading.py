"""Moving a mesh's inner vertices towards the size field (the last step of a graded mesh).

The smoother of the solve (:func:`jaxmatch.placement.embed.smooth`) minimises the quads' corner
condition numbers: it is blind to size, so it keeps the grading the side counts and the side
vertices give only where the topology forces it. :func:`follow_field` then treats every edge as
a spring whose rest length is the field along it and relaxes the inner vertices (the outline's
vertices, spaced by the field already, stay) by stress majorization (SMACOF): each step solves
one sparse linear system, the graph Laplacian of the inner vertices (by conjugate gradients in
numpy: no ``scipy.sparse`` to import), whose solution is where every spring would be at its
rest length in its current direction; the vertices move a fraction of the way there, each
vertex's step taken only where no quad around it falls below the quality it must keep. Of the
steps, the mesh that follows the field best is kept (the share of its edges within the field's
band, :attr:`QuadMesh.field_share`, plus the same share in the refined zone: relaxing towards the
overall band can stretch the finest edges), the mesh as given when none does better.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from jaxmatch.catalogue.mesh import edges as mesh_edges
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.field import SHARE_BAND
from jaxmatch.meshing.result import QuadMesh
from jaxmatch.quality import sj_inverted

__all__ = ["CG_TOL", "FOLLOW_ITERS", "FOLLOW_STEP", "HALVINGS", "PERFECT", "REVERTS", "SETTLED", "follow_field", "laplacian_solve", "refined_cut"]

FOLLOW_ITERS = 5
"""Relaxation steps of :func:`follow_field` (each one linear solve)."""

SETTLED = 1e-3
"""The relaxation stops when no vertex moves by more than this fraction of the field there."""

REVERTS = 8
"""Rounds of putting back the vertices of quads a step took below their floor."""

FOLLOW_STEP = 0.3
"""Fraction of the way to the linear solve's positions a vertex moves by in one step."""

HALVINGS = 3
"""A step whose every vertex is put back (its quads below their floors) is halved, up to this
many times."""

PERFECT = 2.0
"""The largest key of :func:`follow_field` (share 1 and refined share 1): a mesh there is kept
as it is, and the relaxation stops at the first step that reaches it."""

CG_TOL = 1e-6
"""Conjugate gradients stop at this residual relative to the right-hand side's norm."""


def _quad_floor(sj0: np.ndarray, quality: Quality) -> np.ndarray:
    """Per quad, the scaled Jacobian it must keep: its own, or the mesh's worst if higher than the
    quality band (``Quality.high_sj``), else the band, whichever is lower: the mesh's min scaled
    Jacobian never drops, nor does a quad fall out of the quality band."""
    return np.minimum(sj0, max(float(sj0.min()), quality.high_sj))


def laplacian_solve(degree: np.ndarray, ea: np.ndarray, eb: np.ndarray, rhs: np.ndarray, x0: np.ndarray,
                    tol: float = CG_TOL, max_iter: int = 1000) -> np.ndarray:
    """``(n, 2) float64`` x with ``degree[i] x_i - sum of x_j over the edges (i, j) = rhs_i``
    (``degree (n,)``: each unknown's edge count, including the edges to fixed vertices;
    ``ea, eb (k,)``: the edges between unknowns; ``rhs, x0 (n, 2)``): the Laplacian of a mesh's
    inner vertices, symmetric positive definite when every connected part touches a fixed
    vertex. Conjugate gradients from ``x0``, both columns at once, until the residual is below
    ``tol`` times the right-hand side's norm."""
    n = degree.shape[0]

    def apply(x):
        out = degree[:, None] * x
        for k in range(2):
            out[:, k] -= np.bincount(ea, weights=x[eb, k], minlength=n) + np.bincount(eb, weights=x[ea, k], minlength=n)
        return out

    x = np.array(x0, np.float64)
    r = rhs - apply(x)
    p = r.copy()
    rr = (r * r).sum(axis=0)
    stop = tol * tol * float((rhs * rhs).sum(axis=0).max())
    for _ in range(int(max_iter)):
        if rr.max() <= stop:
            break
        Ap = apply(p)
        alpha = rr / np.maximum((p * Ap).sum(axis=0), 1e-300)
        x += alpha * p
        r -= alpha * Ap
        rn = (r * r).sum(axis=0)
        p = r + (rn / np.maximum(rr, 1e-300)) * p
        rr = rn
    return x


def _shares(f, xy: np.ndarray, e: np.ndarray, cut: float | None) -> tuple[float, float, float]:
    """``(share, refined share, cut)`` of positions ``xy`` (edges ``e``, field ``f``): the share
    of the edges whose length / the field at the midpoint lies in :data:`SHARE_BAND`
    (:attr:`QuadMesh.field_share`), the same share over the refined zone's edges (the field below
    ``cut``; all edges where none is) and ``cut``: as given, or (None) halfway between the
    field's least and largest value there (:func:`refined_cut`)."""
    a, b = xy[e[:, 0]], xy[e[:, 1]]
    fm = np.asarray(f(0.5 * (a + b)), np.float64)
    r = np.linalg.norm(b - a, axis=1) / fm
    ok = (r >= SHARE_BAND[0]) & (r <= SHARE_BAND[1])
    cut = refined_cut(fm) if cut is None else cut
    zone = fm < cut
    return float(ok.mean()), float(ok[zone].mean() if zone.any() else ok.mean()), cut


def refined_cut(values: np.ndarray) -> float:
    """The size below which the field's refined zone lies: halfway between the least and the
    largest of ``values`` (the field at the mesh's edge midpoints; for a
    :class:`~jaxmatch.field.Field` about its smallest size and ``H``, as in
    ``scripts/graded_table.py``'s criteria), the same for a field and a callable giving the
    same sizes."""
    return 0.5 * (float(values.min()) + float(values.max()))


def _step(xy: np.ndarray, trial: np.ndarray, quads: np.ndarray, floor: np.ndarray) -> np.ndarray | None:
    """``trial (V, 2)`` with the vertices of every quad below its ``floor (Q,)`` (or folded) put
    back to ``xy`` (:data:`REVERTS` rounds); None when no vertex moves or the rounds do not
    settle."""
    for _ in range(REVERTS):
        sj, inv = sj_inverted(trial, quads)
        bad_q = (sj < floor) | inv
        if not bad_q.any():
            return None if np.array_equal(trial, xy) else trial
        trial[quads[bad_q].ravel()] = xy[quads[bad_q].ravel()]
    return None


def follow_field(m: QuadMesh, quality: Quality = QUALITY, iters: int = FOLLOW_ITERS, step: float = FOLLOW_STEP) -> QuadMesh:
    """``m`` with its inner vertices relaxed towards edges as long as the field along them
    (``m.field``, the mean of its values at the edge's ends; ``m`` itself without one). Each step
    solves, for the inner vertices ``x``, ``sum over i's edges of (x_i - x_j) = sum over i's edges
    of t_ij (old x_i - old x_j) / old length`` (stress majorization of ``sum (length - t)^2``;
    :func:`laplacian_solve`) and moves every inner vertex ``step`` of the way to it, until none
    moves by more than :data:`SETTLED` of the field there or every edge is in the band
    (:data:`PERFECT`; ``m`` itself when it starts there); a vertex whose move would fold a quad
    around it or take one below its floor (:func:`_quad_floor`: the quality band is kept where
    it was reached) stays, and a step where none moves is halved (:data:`HALVINGS` times at
    most). The outline's vertices do not move, so corners, sides and area along
    them are kept. Of ``m`` and every step's mesh, the one with the largest sum of its field share
    and its share in the refined zone (:func:`_shares`; ties: the later) is returned, a new
    :class:`QuadMesh` (its choice fields kept) or ``m``."""
    if m.field is None or not m.quads.size:
        return m
    xy = np.array(m.xy, np.float64)
    quads = np.asarray(m.quads, np.int64)
    e = mesh_edges(quads)
    V = xy.shape[0]
    boundary = np.zeros(V, bool)
    for loop in m._loops:
        boundary[np.asarray(loop, np.int64)] = True
    free = ~boundary
    if not free.any():
        return m
    sj0, _ = sj_inverted(xy, quads)
    floor = _quad_floor(sj0, quality)
    inner = np.flatnonzero(free)
    index = np.full(V, -1, np.int64)
    index[inner] = np.arange(inner.size)
    both = free[e[:, 0]] & free[e[:, 1]]
    ea, eb = index[e[both, 0]], index[e[both, 1]]
    degree = np.bincount(e.ravel(), minlength=V).astype(np.float64)[inner]
    fixed_sum = np.zeros((V, 2))  # per vertex, the sum of its fixed neighbours' positions (they do not move)
    for k in range(2):
        fixed_sum[:, k] = (np.bincount(e[:, 0], weights=np.where(boundary[e[:, 1]], xy[e[:, 1], k], 0.0), minlength=V)
                           + np.bincount(e[:, 1], weights=np.where(boundary[e[:, 0]], xy[e[:, 0], k], 0.0), minlength=V))
    fv = np.asarray(m.field(xy), np.float64)  # at the vertices: an edge's rest length is its ends' mean
    share, zone_share, cut = _shares(m.field, xy, e, None)
    start = best_key = share + zone_share
    if start >= PERFECT:  # every edge in the band already: no step can do better
        return m
    best = xy
    for it in range(int(iters)):
        if it:  # (only the inner vertices move: the field is evaluated again there only)
            fv[free] = np.asarray(m.field(xy[free]), np.float64)
        d = xy[e[:, 0]] - xy[e[:, 1]]
        L = np.linalg.norm(d, axis=1)
        u = (0.5 * (fv[e[:, 0]] + fv[e[:, 1]]) / np.maximum(L, 1e-300))[:, None] * d  # rest length along b -> a
        rhs = fixed_sum.copy()
        for k in range(2):
            rhs[:, k] += np.bincount(e[:, 0], weights=u[:, k], minlength=V) - np.bincount(e[:, 1], weights=u[:, k], minlength=V)
        way = np.zeros_like(xy)
        way[inner] = laplacian_solve(degree, ea, eb, rhs[inner], xy[inner]) - xy[inner]
        if not np.any(step * np.linalg.norm(way, axis=1) > SETTLED * fv):
            break
        trial = None
        for halving in range(HALVINGS + 1):  # a step that every quad's floor undoes: a shorter one
            trial = _step(xy, xy + (step / 2 ** halving) * way, quads, floor)
            if trial is not None:
                break
        if trial is None:
            break
        xy = trial
        share, zone_share, _ = _shares(m.field, xy, e, cut)
        key = share + zone_share
        if key >= best_key:
            best, best_key = xy, key
        if key >= PERFECT:  # every edge in the band: no later step can do better
            break
    return m if best_key < start or best is m.xy else replace(m, xy=best)
