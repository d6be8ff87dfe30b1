"""Place a matched combinatorial quad mesh in the user's planar shape.

Inputs (all in the user's coordinates, any unit of length):

* ``points``: ``(P, 2) float64``, the shape outline, a closed counter-clockwise loop
  (first point not repeated), possibly non-convex and with curved sides;
* ``t``: ``(m,) float64``, the arc-length parameter of each annotated input point along
  ``points`` measured from ``points[0]`` (increasing, in ``[0, perimeter)``);
* ``alignment``: ``(n,) int``, strictly increasing indices into ``t``: the input point of
  each mesh boundary vertex in *matched order* (see :func:`oriented_boundary`).

Steps of :func:`place`:

1. **Orientation.** The mesh is mirrored when the match is reflected (each quad's vertex
   order reversed) so that its boundary loop in matched order runs counter-clockwise like
   the input.
2. **Boundary.** Boundary vertex ``loop[j]`` sits exactly on input point ``alignment[j]``;
   mesh boundary edge ``j`` stands for the piece of the input polyline between
   ``t[alignment[j]]`` and ``t[alignment[j+1]]`` (:attr:`Placement.boundary_paths`); the
   quads themselves use the straight chord between the two vertices.
3. **Interior.** Tutte (uniform-weight harmonic) embedding: one sparse solve.
4. **Untangling and smoothing.** Minimisation of the regularised corner condition number
   (Escobar et al., "Simultaneous untangling and smoothing of tetrahedral meshes", 2003,
   applied to the four corner triangles of each quad)::

       f(x) = (mean over corners of kappa_c ** p) ** (1 / p),
       kappa_c = (|e1|^2 + |e2|^2) / (2 h(alpha_c)),   h(a) = (a + sqrt(a^2 + 4 delta^2)) / 2

   ``e1``/``e2`` are the corner's two edges, ``alpha_c = e1 x e2`` its signed area. For
   ``delta -> 0`` this is a barrier (infinite on folded corners) whose minimum, 1, is a square
   corner; a positive ``delta`` makes it finite on folded meshes so that a gradient method can
   pull folded corners through zero (untangling). ``delta`` shrinks as the mesh unfolds.
   Untangling uses ``p = 1``; smoothing uses a barrier-like ``delta`` and continues over
   ``p = 2, 4, 8, 16`` (larger ``p`` weighs the worst corner more). L-BFGS (a small numpy
   implementation) moves the internal vertices only. A result replaces the current one only
   if it has fewer inverted quads, or as many and a higher minimum scaled Jacobian (then a
   higher mean): smoothing never folds a valid mesh nor worsens its worst quad.

All geometry is done in normalised coordinates (centred, unit RMS radius) and mapped back, so
the placement moves with translations and uniform scalings of the input (up to round-off);
boundary vertices are copied from the input exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from jaxmatch.catalogue.mesh import QuadMesh, edges, mesh_valences
from jaxmatch.arrays import roll
from jaxmatch.geometry import VERTEX_SNAP, cumulative_length, point_at, signed_area, sub_polyline
from jaxmatch.kernels import placement as kernels
from jaxmatch.quality import corner_vectors, placement_measures, quad_areas, sj_inverted

__all__ = [
    "Placement",
    "Slide",
    "arc_lengths",
    "boundary_paths",
    "oriented_boundary",
    "oriented_loop",
    "place",
    "point_at",
    "polygon_area",
    "smooth",
    "smooth_near",
    "to_user",
    "tutte",
]

# ---------------------------------------------------------------------------------------------
# data


@dataclass(frozen=True, eq=False)
class Placement:
    """A quad mesh placed in a planar shape.

    mesh: the oriented :class:`QuadMesh` (mirrored when the match was reflected); its
        ``boundary`` is the ccw loop in matched order (``mesh.boundary[j]`` sits on input
        point ``alignment[j]``).
    xy: ``(V, 2) float64`` vertex positions, same coordinates as the input ``points``.
    scaled_jacobian: ``(F,) float64`` per quad, in ``[-1, 1]`` (1 for a square).
    min_angle, max_angle: ``(F,) float64`` per quad, interior angles in degrees.
    inverted: number of quads with a corner of signed area ``<= 0``.
    irregular: ``(I,) int`` internal vertices whose valence is not 4.
    alignment: ``(n,) int`` input point index of each boundary vertex (matched order).
    boundary_paths: ``n`` arrays ``(k_j, 2)``: the input polyline from boundary vertex ``j``
        to ``j+1`` (both ends included), i.e. the curve that mesh boundary edge ``j`` stands for.
    region_area: area enclosed by the input ``points`` (units of length squared).
    mesh_area: signed area covered by the quads (sum of the quads' shoelace areas; equals the
        area of the polygon of boundary vertices when nothing is folded).
    edge_ratio: ``(F,) float64`` per quad, longest over shortest edge (>= 1; inf for a
        zero-length edge), see :func:`jaxmatch.quality.edge_ratios`.
    rotation, reflected: the orientation of the match that was placed (see
        :func:`oriented_boundary`).
    missed_corners: ``(c, 2) float64`` corners of the shape that are not a mesh vertex (same
        coordinates as ``xy``); empty when every corner is kept (set by
        :func:`jaxmatch.placement.choose.place_match`; :func:`place` knows no corners).
    corners: number of corners of the shape (0 for :func:`place` called directly).
    slid: whether boundary vertices on straight sides were allowed to slide (see :func:`place`).
    """

    mesh: QuadMesh
    xy: np.ndarray
    scaled_jacobian: np.ndarray
    min_angle: np.ndarray
    max_angle: np.ndarray
    inverted: int
    irregular: np.ndarray
    alignment: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    boundary_paths: tuple = ()
    region_area: float = float("nan")
    mesh_area: float = float("nan")
    edge_ratio: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rotation: int = 0
    reflected: bool = False
    missed_corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    corners: int = 0
    slid: bool = False

    @property
    def max_edge_ratio(self) -> float:
        """Largest longest/shortest edge ratio over the quads (nan for no quads)."""
        return float(self.edge_ratio.max()) if self.edge_ratio.size else float("nan")

    @property
    def kept_corners(self) -> int:
        """Number of the shape's corners that are mesh vertices."""
        return int(self.corners - self.missed_corners.shape[0])

    @property
    def valid(self) -> bool:
        """A mesh *of the shape*: every corner is a mesh vertex and no quad is inverted."""
        return self.inverted == 0 and self.missed_corners.shape[0] == 0

    @property
    def min_scaled_jacobian(self) -> float:
        return float(self.scaled_jacobian.min()) if self.scaled_jacobian.size else float("nan")

    @property
    def mean_scaled_jacobian(self) -> float:
        return float(self.scaled_jacobian.mean()) if self.scaled_jacobian.size else float("nan")

    @property
    def area_ratio(self) -> float:
        """``mesh_area / region_area`` (1 when the mesh covers the region exactly)."""
        return float(self.mesh_area / self.region_area) if self.region_area else float("nan")


# ---------------------------------------------------------------------------------------------
# orientation


def oriented_boundary(mesh: QuadMesh, rotation: int, reflected: bool) -> tuple[QuadMesh, np.ndarray]:
    """The mesh as matched, and its boundary loop in matched order.

    The matched order is ``s = mesh.boundary`` (ccw), reversed when ``reflected``, then
    rotated: ``loop = roll(s, -rotation)`` so ``loop[0] = s[rotation]``. A reflected mesh is
    mirrored (each quad's vertex order reversed) so that ``loop`` is again its ccw boundary.

    Returns ``(oriented_mesh, loop)``, ``loop: (n,) int32``; ``oriented_mesh.boundary`` is
    ``loop`` and its quads are ccw for a placement where ``loop`` runs ccw.
    """
    quads = np.asarray(mesh.quads, dtype=np.int32)
    if reflected:
        quads = quads[:, ::-1]
    loop = oriented_loop(mesh, rotation, reflected)
    return QuadMesh(quads=np.ascontiguousarray(quads), boundary=loop), loop


def oriented_loop(mesh: QuadMesh, rotation: int, reflected: bool) -> np.ndarray:
    """The ``loop`` of :func:`oriented_boundary` alone, ``(n,) int32`` (without the oriented quads)."""
    s = np.asarray(mesh.boundary, dtype=np.int32)
    if reflected:
        s = s[::-1]
    n = s.shape[0]
    return roll(s, -(int(rotation) % n if n else 0)).astype(np.int32)


# ---------------------------------------------------------------------------------------------
# polylines


arc_lengths = cumulative_length
"""Cumulative arc length of a closed loop (:func:`jaxmatch.geometry.cumulative_length`)."""


def boundary_paths(points: np.ndarray, t_aligned: np.ndarray, cum: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """The input polyline between consecutive aligned parameters.

    points: (P, 2) closed ccw loop; t_aligned: (n,) increasing arc-length parameters; cum: the
    loop's :func:`arc_lengths` when the caller has it.
    Returns ``n`` arrays ``(k_j, 2)``: from ``t_aligned[j]`` to ``t_aligned[j+1]`` (the last one
    wraps around past ``points[0]`` back to ``t_aligned[0]``), through every polyline vertex in
    between.
    """
    p = np.asarray(points, dtype=np.float64)
    cum = arc_lengths(p) if cum is None else cum
    per = cum[-1]
    ta = np.asarray(t_aligned, dtype=np.float64).ravel()
    n = ta.shape[0]
    t0 = ta
    t1 = roll(ta, -1)
    t1 = np.where(t1 <= t0, t1 + per, t1)
    P = p.shape[0]
    if n * 3 * P > 4_000_000:  # one piece at a time: bounded memory
        return tuple(sub_polyline(p, float(a), float(b), cum) for a, b in zip(t0, t1))
    # all pieces at once, as sub_polyline cuts each (same end points, same inner vertices)
    tol = VERTEX_SNAP * per
    c3 = np.concatenate([cum[:-1], cum[:-1] + per, cum[:-1] + 2 * per])
    p3 = np.concatenate([p, p, p])
    inside = (c3[None, :] > t0[:, None] + tol) & (c3[None, :] < t1[:, None] - tol)  # (n, 3P)
    ends = point_at(p, np.concatenate([t0, t1]), cum)
    return tuple(np.concatenate([ends[j:j + 1], p3[inside[j]], ends[n + j:n + j + 1]]) for j in range(n))


polygon_area = signed_area
"""Signed area of a closed polygon, positive when ccw (:func:`jaxmatch.geometry.signed_area`)."""


def to_user(xy: np.ndarray, scale: float, offset) -> np.ndarray:
    """Map normalised positions back to user coordinates: ``xy * scale + offset`` (V, 2)."""
    return np.asarray(xy, dtype=np.float64) * float(scale) + np.asarray(offset, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# interior: Tutte embedding


DENSE_TUTTE = 300
"""Up to this many free vertices the Tutte system is solved densely (LAPACK): for the 1-60
free vertices of catalogue meshes that takes ~0.1 ms against ~1 ms for the sparse solver's
set-up; refined meshes (thousands of vertices) use the sparse solver."""


def tutte(quads: np.ndarray, n_vertices: int, boundary: np.ndarray, boundary_xy: np.ndarray, *,
          reference: bool = False) -> np.ndarray:
    """Uniform-weight (Tutte / harmonic) embedding.

    quads: (F, 4); boundary: (n,) vertex ids fixed at ``boundary_xy`` (n, 2). Every other vertex
    is the average of its edge neighbours (one linear solve: dense and compiled,
    :func:`jaxmatch.kernels.placement.tutte_dense`, up to :data:`DENSE_TUTTE` free vertices;
    sparse beyond).
    ``reference``: the numpy/scipy version (tests). Returns ``(V, 2) float64``.
    """
    V = int(n_vertices)
    if not reference and 0 < V - len(boundary) <= DENSE_TUTTE:
        return kernels.tutte_dense(np.ascontiguousarray(quads, dtype=np.int64), V, np.asarray(boundary, dtype=np.int64),
                              np.ascontiguousarray(boundary_xy, dtype=np.float64))
    xy = np.zeros((V, 2))
    b = np.asarray(boundary)
    xy[b] = boundary_xy
    free = np.setdiff1d(np.arange(V), b)
    if free.size == 0:
        return xy
    e = edges(quads)
    rows = np.concatenate([e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 1], e[:, 0]])
    if free.size <= DENSE_TUTTE:
        L = np.zeros((V, V))
        np.add.at(L, (rows, cols), -1.0)
        L[np.arange(V), np.arange(V)] = -L.sum(axis=1)
        rhs = -(L[np.ix_(free, b)] @ xy[b])
        sol = np.linalg.solve(L[np.ix_(free, free)], rhs)
    else:
        import scipy.sparse  # only here: importing it costs ~0.1 s of a ~1 s command
        import scipy.sparse.linalg

        A = scipy.sparse.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(V, V))
        deg = np.asarray(A.sum(axis=1)).ravel()
        L = (scipy.sparse.diags(deg) - A).tocsr()
        rhs = -(L[free][:, b] @ xy[b])
        sol = scipy.sparse.linalg.spsolve(L[free][:, free].tocsc(), rhs)
    xy[free] = np.asarray(sol).reshape(-1, 2)
    return xy


# ---------------------------------------------------------------------------------------------
# untangling and smoothing


def _energy(pos, quads, delta, power):
    """Power mean of the regularised corner condition numbers, ``(mean kappa**power)**(1/power)``,
    and its gradient w.r.t. every position ``(V, 2)``. Same minimisers as the sum of
    ``kappa**power``, but computed without overflow. ``(inf, zeros)`` where not finite."""
    e1, e2, a = corner_vectors(pos, quads)
    d2 = 4.0 * delta * delta
    zero = np.zeros_like(pos)
    with np.errstate(all="ignore"):
        r = np.sqrt(a * a + d2)
        h = np.where(a >= 0, 0.5 * (a + r), d2 / (2.0 * (r - a)))  # stable for a << 0
        N = np.sum(e1 * e1, axis=-1) + np.sum(e2 * e2, axis=-1)
        k = N / (2.0 * h)
        kmax = float(k.max())
        if not np.isfinite(kmax) or kmax <= 0:
            return np.inf, zero
        C = k.size
        f = kmax * float(np.mean((k / kmax) ** power)) ** (1.0 / power)
        dk = (k / f) ** (power - 1) / C  # d f / d kappa_c
        g_N = dk / (2.0 * h)
        g_a = -dk * k / r  # dk/dh = -k/h, dh/da = h/r
    g_e1 = 2.0 * g_N[..., None] * e1 + g_a[..., None] * np.stack([e2[..., 1], -e2[..., 0]], axis=-1)
    g_e2 = 2.0 * g_N[..., None] * e2 + g_a[..., None] * np.stack([-e1[..., 1], e1[..., 0]], axis=-1)
    G = -(g_e1 + g_e2) + roll(g_e1, 1, axis=1) + roll(g_e2, -1, axis=1)
    flat = quads.ravel()
    gx = np.bincount(flat, weights=G[..., 0].ravel(), minlength=pos.shape[0])
    gy = np.bincount(flat, weights=G[..., 1].ravel(), minlength=pos.shape[0])
    grad = np.stack([gx, gy], axis=-1)
    if not (np.isfinite(f) and np.all(np.isfinite(grad))):
        return np.inf, zero
    return f, grad


class Slide(NamedTuple):
    """Boundary vertices that may slide along one straight side.

    a, b: ``(2,)`` the side's fixed ends (normally two kept corners); vertices: ``(r,) int``
    the vertex ids strictly between them, in order from ``a`` to ``b``. Their positions are
    ``a + u_k (b - a)`` with ``0 < u_1 < ... < u_r < 1`` parametrised by the softmax of
    ``r + 1`` gap logits (``u_k`` = sum of the first ``k`` gaps), so they stay on the side,
    in order, whatever the optimiser does; all logits 0 is the even spacing.
    """

    a: np.ndarray
    b: np.ndarray
    vertices: np.ndarray


class _Params:
    """Flat optimisation vector <-> positions: free vertices' ``(x, y)``, then the gap logits
    of each :class:`Slide`."""

    def __init__(self, xy, free, slides):
        self.base = np.asarray(xy, dtype=np.float64)
        self.free = free
        self.slides = [Slide(np.asarray(s.a, float), np.asarray(s.b, float), np.asarray(s.vertices, np.int64)) for s in slides]
        self.nf = 2 * free.size

    @property
    def flat(self) -> tuple:
        """``(sa, sb, sp, sv)``: the slides as the compiled kernels take them
        (:func:`jaxmatch.kernels.placement.flat_slides`; the tests hand them to the kernels, the
        numpy path here does not use them)."""
        return kernels.flat_slides(self.slides)

    def start(self, xy) -> np.ndarray:
        z = [np.asarray(xy, float)[self.free].ravel()]
        for s in self.slides:
            d = s.b - s.a
            u = np.concatenate([[0.0], (np.asarray(xy, float)[s.vertices] - s.a) @ d / float(d @ d), [1.0]])
            gaps = np.maximum(np.diff(u), 1e-12)
            z.append(np.log(gaps / gaps.sum()))
        return np.concatenate(z)

    def _split(self, x):
        off = self.nf
        for s in self.slides:
            r = s.vertices.size
            z = x[off:off + r + 1]
            off += r + 1
            w = np.exp(z - z.max())
            sm = w / w.sum()
            yield s, sm, np.cumsum(sm)[:r]

    def positions(self, x) -> np.ndarray:
        pos = self.base.copy()
        pos[self.free] = x[: self.nf].reshape(-1, 2)
        for s, _, u in self._split(x):
            pos[s.vertices] = s.a + u[:, None] * (s.b - s.a)
        return pos

    def pull(self, x, gpos) -> np.ndarray:
        """Gradient w.r.t. ``x`` from the gradient w.r.t. positions ``(V, 2)``."""
        out = [gpos[self.free].ravel()]
        for s, sm, u in self._split(x):
            g = gpos[s.vertices] @ (s.b - s.a)  # d f / d u_k, (r,)
            g = np.concatenate([g, [0.0]])  # u_{r+1} = 1 is not a vertex
            tail = np.cumsum(g[::-1])[::-1]  # sum_{k >= i} g_k
            out.append(sm * (tail - float(g[:-1] @ u)))
        return np.concatenate(out)


def _objective(x, params, quads, delta, power):
    pos = params.positions(x)
    f, g = _energy(pos, quads, delta, power)
    if not np.isfinite(f):
        return np.inf, np.zeros_like(x)
    return f, params.pull(x, g)


LBFGS_MEMORY = 8
"""Correction pairs kept by the L-BFGS smoother."""

LBFGS_FTOL = 1e-11
"""L-BFGS stops when one step lowers the objective by less than this (relative)."""

LBFGS_GTOL = 1e-10
"""L-BFGS stops when the largest gradient component is at most this."""


def _lbfgs(fg, x0: np.ndarray, maxiter: int, mem: int = LBFGS_MEMORY, ftol: float = LBFGS_FTOL,
           gtol: float = LBFGS_GTOL) -> np.ndarray:
    """Minimise ``fg(x) -> (f, grad)`` from ``x0`` (flat) by L-BFGS with Armijo backtracking.

    A small numpy implementation rather than ``scipy.optimize.minimize``: for ~100 unknowns
    the Fortran/C L-BFGS-B spends its time in multi-threaded BLAS calls (10x slower on a busy
    machine). Infinite values (a folded corner under the barrier) are rejected by the line
    search. Returns the last accepted point.
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    f, g = fg(x)
    if not np.isfinite(f):
        return x
    S: list[np.ndarray] = []
    Y: list[np.ndarray] = []
    for _ in range(int(maxiter)):
        if np.max(np.abs(g)) <= gtol:
            break
        q = g.copy()
        coef = []
        for s, y in zip(reversed(S), reversed(Y)):
            rho = 1.0 / float(y @ s)
            a = rho * float(s @ q)
            q -= a * y
            coef.append((rho, a))
        if S:
            q *= float(S[-1] @ Y[-1]) / float(Y[-1] @ Y[-1])
        else:
            q *= 0.05 / max(float(np.max(np.abs(g))), 1e-300)  # first step: move at most 0.05
        for (s, y), (rho, a) in zip(zip(S, Y), reversed(coef)):
            q += s * (a - rho * float(y @ q))
        d = -q
        slope = float(g @ d)
        if not slope < 0:
            S.clear()
            Y.clear()
            d = -g * (0.05 / max(float(np.max(np.abs(g))), 1e-300))
            slope = float(g @ d)
        step = 1.0
        while True:
            xn = x + step * d
            fn, gn = fg(xn)
            if np.isfinite(fn) and fn <= f + 1e-4 * step * slope:
                break
            step *= 0.5
            if step < 1e-12:
                return x
        s, y = xn - x, gn - g
        if float(s @ y) > 1e-12 * float(s @ s):
            S.append(s)
            Y.append(y)
            if len(S) > mem:
                S.pop(0)
                Y.pop(0)
        done = f - fn <= ftol * max(1.0, abs(f))
        x, f, g = xn, fn, gn
        if done:
            break
    return x


def _minimise(xy, params, quads, delta, power, maxiter):
    """L-BFGS on the free vertices (and sliding boundary vertices); returns new (V, 2) positions
    (numpy reference of the compiled loop, :func:`jaxmatch.kernels.placement.smooth`)."""
    x = _lbfgs(lambda z: _objective(z, params, quads, delta, power), params.start(xy), maxiter)
    return params.positions(x)


SMOOTH_POWERS = (2.0, 4.0, 8.0, 16.0)
"""Continuation in the power of the smoothing objective: 2 shapes the whole mesh, 16 is close
to optimising the worst corner."""


def smooth(
    xy: np.ndarray,
    quads: np.ndarray,
    fixed: np.ndarray,
    *,
    iters: int = 200,
    powers: tuple[float, ...] = SMOOTH_POWERS,
    untangle_rounds: int = 12,
    slides: tuple[Slide, ...] = (),
    reference: bool = False,
) -> np.ndarray:
    """Untangle (if needed) and smooth, moving all vertices not in ``fixed``.

    xy: (V, 2) start positions (ideally normalised: O(1) size); quads: (F, 4) ccw;
    fixed: vertex ids that stay put. ``iters``: L-BFGS iterations per round (0: return ``xy``).
    slides: boundary vertices (listed in ``fixed``) that may nevertheless move along a straight
    side (:class:`Slide`); they stay on it, in order, so the region covered is unchanged.
    reference: run this numpy version instead of the compiled one
    (:func:`jaxmatch.kernels.placement.smooth`, the same steps; for tests).

    Untangling: rounds of the regularised objective (power 1) with ``delta`` from the worst
    corner area (Escobar et al.'s rule ``delta^2 = eps (eps - min_area)``) until every corner
    area exceeds ``eps`` (1% of the mean quad area). Smoothing: the same objective with a tiny
    ``delta`` (a barrier), powers ``powers`` in turn, each from the previous result.

    Returns the best (V, 2) positions seen, by: fewer inverted quads, then higher minimum
    scaled Jacobian, then higher mean scaled Jacobian; never worse than ``xy``.
    """
    q = np.asarray(quads)
    xy = np.asarray(xy, dtype=np.float64)
    V = xy.shape[0]
    keep = np.ones(V, bool)
    keep[np.asarray(fixed, dtype=np.int64)] = False
    free = np.flatnonzero(keep)  # = setdiff1d(arange(V), fixed), without its sort
    slides = tuple(s for s in slides if len(s.vertices))
    if (free.size == 0 and not slides) or iters <= 0 or q.size == 0:
        return xy.copy()
    if not reference:
        return kernels.smooth(xy, np.ascontiguousarray(q, dtype=np.int64), free.astype(np.int64, copy=False),
                              *kernels.flat_slides(slides), int(iters), np.asarray(powers, dtype=np.float64),
                              int(untangle_rounds), LBFGS_MEMORY, LBFGS_FTOL, LBFGS_GTOL)
    params = _Params(xy, free, slides)
    F = q.shape[0]
    area = float(np.abs(quad_areas(xy, q)).sum()) or 1.0
    eps = 1e-2 * area / F  # corner area under which a corner counts as nearly folded
    floor = 1e-4 * eps  # delta for a valid mesh: barrier-like
    best, best_key = xy.copy(), _key(xy, q)
    cur = xy.copy()
    for _ in range(untangle_rounds):
        s_min = float(corner_vectors(cur, q)[2].min())
        if s_min >= eps:
            break
        delta = np.sqrt(eps * (eps - s_min))
        cur = _minimise(cur, params, q, delta, 1.0, iters)
        best, best_key = _pick(best, best_key, cur, q)
    cur = best
    for p in powers:
        cur = _minimise(cur, params, q, floor, float(p), iters)
        best, best_key = _pick(best, best_key, cur, q)
    return best


def smooth_in_frame(xy: np.ndarray, quads: np.ndarray, fixed: np.ndarray, *, frame: np.ndarray | None = None,
                    iters: int = 200) -> np.ndarray:
    """:func:`smooth` in a normalised frame: centred on ``frame`` (default all of ``xy``), unit
    RMS radius, so that its tolerances see an O(1) mesh whatever the user's units; the
    ``fixed`` vertices come back at exactly their input positions (no round-off).

    xy: ``(V, 2) float64`` user coordinates; quads: ``(Q, 4)`` ccw; fixed: vertex ids kept;
    frame: ``(k, 2)`` points that define the frame. Returns ``(V, 2) float64``.
    """
    pts = xy if frame is None else frame
    c = pts.mean(axis=0)
    r = float(np.sqrt(np.mean(np.sum((pts - c) ** 2, axis=1)))) or 1.0
    out = smooth((xy - c) / r, quads, fixed, iters=iters) * r + c
    out[fixed] = xy[fixed]
    return out


def smooth_near(xy: np.ndarray, quads: np.ndarray, seeds: np.ndarray, fixed: np.ndarray, *, rings: int,
                frame: np.ndarray, iters: int) -> np.ndarray:
    """:func:`smooth_in_frame` of only the vertices within ``rings`` rings of quads of the
    ``seeds`` (the quads that touch one of them smoothed as a submesh whose other vertices
    stay): for large meshes whose trouble is local (cuts between patches, a few folded quads).
    Quads outside the submesh keep their shape, so it never lowers the minimum scaled Jacobian
    either.

    xy: ``(V, 2) float64``; quads: ``(Q, 4) int64`` ccw; seeds: ``(k,)`` vertex ids; fixed:
    vertex ids kept; frame: ``(m, 2)`` points that define the frame (:func:`smooth_in_frame`);
    iters: L-BFGS iterations per round. Returns ``(V, 2) float64``.
    """
    near = np.zeros(xy.shape[0], bool)
    near[np.asarray(seeds, np.int64)] = True
    for _ in range(int(rings)):
        near[quads[near[quads].any(axis=1)].ravel()] = True
    free = near.copy()
    free[fixed] = False
    sub = quads[free[quads].any(axis=1)]
    verts = np.unique(sub)
    local = np.full(xy.shape[0], -1, np.int64)
    local[verts] = np.arange(verts.shape[0])
    keep = np.flatnonzero(~free[verts])
    out = xy.copy()
    out[verts] = smooth_in_frame(xy[verts], local[sub], keep, frame=frame, iters=iters)
    return out


def _key(xy: np.ndarray, quads: np.ndarray) -> tuple[int, float, float]:
    """(inverted count, min scaled Jacobian, mean scaled Jacobian)."""
    sj, inv = sj_inverted(xy, quads)
    return int(inv.sum()), float(sj.min()), float(sj.mean())


def _pick(best, best_key, cand, quads, tol: float = 1e-9):
    """Keep the better of two placements: fewer inverted quads, then a higher min scaled
    Jacobian (by more than ``tol``), then a higher mean (by more than ``tol``; ties keep
    ``best``, so round-off cannot change the choice)."""
    k = _key(cand, quads)
    if k[0] != best_key[0]:
        better = k[0] < best_key[0]
    elif abs(k[1] - best_key[1]) > tol:
        better = k[1] > best_key[1]
    else:
        better = k[2] > best_key[2] + tol
    return (cand.copy(), k) if better else (best, best_key)


# ---------------------------------------------------------------------------------------------
# placement


def _check_alignment(alignment: np.ndarray, m: int, n: int) -> None:
    if alignment.ndim != 1 or alignment.shape[0] != n:
        raise ValueError(f"alignment has {alignment.shape[0] if alignment.ndim else 0} entries, mesh boundary has {n}")
    a = alignment.tolist()  # (a few dozen indices: plain numbers)
    if n and (min(a) < 0 or max(a) >= m):
        raise ValueError(f"alignment indices must lie in [0, {m})")
    if any(x >= y for x, y in zip(a, a[1:])):
        raise ValueError("alignment must be strictly increasing")


def place(
    points: np.ndarray,
    t: np.ndarray,
    alignment: np.ndarray,
    mesh: QuadMesh,
    rotation: int = 0,
    reflected: bool = False,
    *,
    positions: np.ndarray | None = None,
    boundary_xy: np.ndarray | None = None,
    boundary_t: np.ndarray | None = None,
    slide_groups: tuple = (),
    smooth_iters: int = 200,
    paths: bool = True,
    region_area: float | None = None,
    missed_corners: np.ndarray | None = None,
    corners: int = 0,
) -> Placement:
    """Place ``mesh`` in the shape ``points`` following a match.

    points: (P, 2) closed ccw outline; t: (m,) arc-length parameters of the annotated points;
    alignment: (n,) strictly increasing indices into ``t``, one per mesh boundary vertex in
    matched order (see :func:`oriented_boundary`); rotation/reflected: the match's orientation.
    positions: optional (m, 2) annotated points; when given, boundary vertices are put exactly
    there (otherwise at ``point_at(points, t)``, which returns polyline vertices exactly).
    boundary_xy: optional (n, 2) boundary vertex positions in matched order, used instead of
    the annotated points (``alignment`` is then only recorded; boundary paths run between these
    positions' arc-length parameters ``t[alignment]``, or ``boundary_t (n,)`` when given, so
    give positions on the outline).
    slide_groups: ``(ja, jb, js)`` triples of matched-order boundary indices: the vertices
    ``js`` (in order) lie on the straight segment from boundary vertex ``ja`` to ``jb`` and may
    slide along it during untangling and smoothing (:class:`Slide`); ``ja``/``jb`` stay put.
    smooth_iters: L-BFGS iterations per untangling/smoothing round (0: plain Tutte).
    paths: False leaves ``boundary_paths`` empty (for candidates that are only compared; the
    caller adds them to the one it keeps with :func:`exact_paths`). region_area: the area
    enclosed by ``points``, when the caller has it (else computed). missed_corners, corners: recorded
    as given (:class:`Placement`; this function knows no corners).
    """
    pts = np.asarray(points, dtype=np.float64)
    tt = np.asarray(t, dtype=np.float64).ravel()
    al = np.asarray(alignment, dtype=np.int64).ravel()
    om, loop = oriented_boundary(mesh, rotation, reflected)
    _check_alignment(al, tt.shape[0], loop.shape[0])
    if boundary_xy is not None:
        bxy = np.asarray(boundary_xy, dtype=np.float64).reshape(-1, 2).copy()
        if bxy.shape[0] != loop.shape[0]:
            raise ValueError(f"boundary_xy has {bxy.shape[0]} rows, mesh boundary has {loop.shape[0]}")
    elif positions is None:
        bxy = point_at(pts, tt[al])
    else:
        bxy = np.asarray(positions, dtype=np.float64).reshape(-1, 2)[al]
    V = om.n_vertices
    quads = om.quads

    # normalised frame: centred on the boundary vertices, unit RMS radius
    offset = np.add.reduce(bxy, axis=0) / bxy.shape[0]  # (np.mean's sum and division, without its wrapper)
    scale = float(np.sqrt(np.add.reduce(np.add.reduce((bxy - offset) ** 2, axis=1)) / bxy.shape[0])) or 1.0
    nb = (bxy - offset) / scale
    groups = [(int(ja), int(jb), np.asarray(js, np.int64)) for ja, jb, js in slide_groups if len(js)]
    slides = tuple(Slide(nb[ja], nb[jb], loop[js]) for ja, jb, js in groups)
    if V == loop.shape[0] and not slides:  # nothing can move: every vertex is a boundary vertex
        xy = np.empty((V, 2))
    else:
        x0 = tutte(quads, V, loop, nb)
        xn = smooth(x0, quads, loop, iters=smooth_iters, slides=slides)
        xy = to_user(xn, scale, offset)
    for ja, jb, js in groups:  # slid vertices: exactly on the user's segment
        d = nb[jb] - nb[ja]
        u = (xn[loop[js]] - nb[ja]) @ d / float(d @ d)
        bxy[js] = bxy[ja] + u[:, None] * (bxy[jb] - bxy[ja])
    xy[loop] = bxy  # exact boundary positions (no round-off from normalisation)

    sj, amin, amax, folded, ratio = placement_measures(xy, quads)
    val = mesh_valences(mesh)  # the oriented mesh has the same vertices
    internal = np.ones(V, bool)
    internal[loop] = False
    irregular = np.flatnonzero(internal & (val != 4))
    if not paths:
        paths = ()
    elif boundary_xy is not None or positions is not None:
        tb = tt[al] if boundary_t is None else np.asarray(boundary_t, dtype=np.float64).ravel()
        paths = exact_paths(pts, tb, bxy)
    else:
        paths = boundary_paths(pts, tt[al])
    return Placement(
        mesh=om,
        xy=xy,
        scaled_jacobian=sj,
        min_angle=amin,
        max_angle=amax,
        inverted=int(folded.sum()),
        irregular=irregular,
        alignment=al,
        boundary_paths=paths,
        region_area=polygon_area(pts) if region_area is None else float(region_area),
        mesh_area=float(quad_areas(xy, quads).sum()),
        edge_ratio=ratio,
        rotation=int(rotation),
        reflected=bool(reflected),
        slid=bool(groups),
        missed_corners=np.zeros((0, 2)) if missed_corners is None else missed_corners,
        corners=int(corners),
    )


def exact_paths(points: np.ndarray, t_aligned: np.ndarray, bxy: np.ndarray,
                cum: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """:func:`boundary_paths` between the parameters ``t_aligned (n,)`` whose end points are
    exactly the boundary vertex positions ``bxy (n, 2)`` (``cum``: as there).

    The same polyline vertices as :func:`boundary_paths` picks, gathered for all paths in one
    array (its ends never computed: they are ``bxy``); path ``j`` is a slice of it."""
    p = np.asarray(points, dtype=np.float64)
    cum = arc_lengths(p) if cum is None else cum
    ta = np.asarray(t_aligned, dtype=np.float64).ravel()
    n, P = ta.shape[0], p.shape[0]
    if n == 0 or n * 3 * P > 4_000_000:  # as boundary_paths: one piece at a time
        out = []
        for j, q in enumerate(boundary_paths(p, ta, cum)):
            q = q.copy()
            q[0] = bxy[j]
            q[-1] = bxy[(j + 1) % n]
            out.append(q)
        return tuple(out)
    per = cum[-1]
    t1 = roll(ta, -1)
    t1 = np.where(t1 <= ta, t1 + per, t1)
    tol = VERTEX_SNAP * per
    c3 = np.concatenate([cum[:-1], cum[:-1] + per, cum[:-1] + 2 * per])  # non-decreasing
    # boundary_paths' vertices of path j, c3 > ta_j + tol and c3 < t1_j - tol: the run lo_j .. hi_j - 1
    lo = np.searchsorted(c3, ta + tol, side="right").tolist()
    hi = np.searchsorted(c3, t1 - tol, side="left").tolist()
    # rows of [bxy; points]: each path's two ends and the loop's vertices between (a few dozen in all)
    pick, bounds = [], [0]
    for j in range(n):
        pick.append(j)
        pick.extend(n + i % P for i in range(lo[j], hi[j]))
        pick.append(j + 1 if j + 1 < n else 0)
        bounds.append(len(pick))
    flat = np.concatenate([np.asarray(bxy, dtype=np.float64).reshape(n, 2), p])[pick]
    return tuple(flat[i:j] for i, j in zip(bounds[:-1], bounds[1:]))
