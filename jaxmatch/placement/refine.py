"""Meshes of the size the user asks for: refinement of a catalogue template by chord multiplicities.

A quad mesh of a disk is a union of *chords*: strips of quads that cross the mesh through
opposite edges of each quad (the classes of the relation "opposite edges of one quad"). A
chord either runs from one boundary edge to another or closes on itself; it may cross itself
(a quad whose two edge pairs belong to the same chord). Giving every chord ``c`` an integer
multiplicity ``mult[c] >= 1`` and splitting each quad whose chords are ``(a, b)`` into a
``mult[a] x mult[b]`` grid refines the mesh without new irregular vertices; side ``i`` of the
shape then has ``sum_c A[i, c] * mult[c]`` edges, ``A`` the side matrix
(:meth:`~jaxmatch.placement.templates.PatchTemplate.side_matrix`: how many template boundary edges of chord ``c`` lie on
side ``i``). Every chord with boundary ends has two of them, so the total is always even.

Pipeline (:func:`refine_mesh` runs it all):

1. :func:`jaxmatch.placement.templates.patch_templates`: ranked catalogue meshes fitted to the shape (placed by
   :func:`jaxmatch.placement.choose.place_match`) with every corner on a template vertex and no
   folded quad, seen as chords with the template boundary edges of each side.
2. :func:`solve_multiplicities`: the multiplicities, by an integer program
   (:func:`scipy.optimize.milp`, HiGHS): per-side counts exactly, or the counts closest to
   ``side length / size``. Infeasible requests raise :class:`InfeasibleRequest` naming the
   sides and the nearest feasible counts.
3. :func:`refine_and_place`: the refined quads; boundary vertices evenly spaced by arc length
   on the user's sides (straight or curved polylines, exact input coordinates at corners);
   interior: the template's placement interpolated bilinearly in each quad, moved by the
   harmonic extension of the boundary displacement (one sparse solve), then untangled and
   smoothed by :func:`jaxmatch.placement.embed.smooth` (never makes the worst quad worse).

Sides are in the USER's order: side ``i`` runs from the user's corner ``i`` to corner ``i + 1``
(corners in the order of an explicit ``corners`` list, else of the input file; also for a
clockwise file, whose sides then run clockwise). A shape without corners has one side, the
whole loop from ``shape.points[0]`` (counter-clockwise), and takes one total count.

All lengths here are in the user's units.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from jaxmatch.cache import Cache
from jaxmatch.cache import key as cache_key
from jaxmatch.catalogue.mesh import QuadMesh, edges, valences
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.errors import InputError
from jaxmatch.field import graded_points
from jaxmatch.placement.milp import LayoutInfeasible, one_patch_sides, solve_counts
from jaxmatch.placement.reach import reachable_cols
from jaxmatch.placement.embed import DENSE_TUTTE, Placement, smooth_in_frame, smooth_near, tutte
from jaxmatch.placement.templates import PatchTemplate, walk
from jaxmatch.quality import quad_areas, quality, sj_inverted
from jaxmatch.shape import Shape

if TYPE_CHECKING:  # pragma: no cover
    import scipy.sparse

    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice

__all__ = [
    "DEFAULT_LIMIT",
    "InfeasibleRequest",
    "RefineChoice",
    "RefinedMesh",
    "SIZE_TOLERANCE",
    "SMOOTH_ALWAYS",
    "BAD_RINGS",
    "SMOOTH_LOCAL",
    "refine_and_place",
    "refine_mesh",
    "refined_json",
    "side_lengths",
    "side_polylines",
    "estimated_mean_edge",
    "feasible",
    "bad_quads",
    "harmonic_displacement",
    "smooth_near_bad",
    "nearest_counts",
    "side_points",
    "solve_multiplicities",
]

DEFAULT_LIMIT = 10
"""Templates per size (k) that :func:`refine_mesh` tries (``jaxmatch mesh --sides/--size``)."""

SIZE_TOLERANCE = 0.2
"""A ``size`` request is met when the mean boundary edge length is within this fraction of it."""

MAX_COUNT = 100_000
"""Largest accepted edge count of one side (memory bound: the mesh grows with the product of
the counts)."""

MAX_QUADS = 2_000_000
"""Largest refined mesh (quads) :func:`refine_and_place` builds (about 1 GB of working memory)."""

MAX_SIZE_EDGES = 1_000_000
"""Largest accepted ``perimeter / size`` (edges on the boundary) for a size request."""

SMOOTH_ALWAYS = 2000
"""Refined meshes with at most this many quads are always smoothed (:data:`SMOOTH_ITERS`)."""

SMOOTH_ITERS = 200
"""L-BFGS iterations per round of :func:`jaxmatch.placement.embed.smooth` for refined meshes."""

SMOOTH_ITERS_GRADED = 50
"""L-BFGS iterations per round for refined meshes (and the layout's fitted patches) with a size
field (``Quality.field``): the smoother is blind to size, the merged mesh's cuts are smoothed
with :data:`SMOOTH_ITERS` after them and the relaxation towards the field
(:func:`jaxmatch.meshing.grading.follow_field`) moves the inner vertices last; on
docs/graded.md's cases the meshes are no worse."""

SMOOTH_ITERS_LARGE = 50
"""Iterations per round for larger meshes, which are smoothed only when the interpolated
placement has an inverted quad or a scaled Jacobian below ``quality.good_sj`` (each objective
evaluation costs about 1.5 ms per 1000 quads)."""

SMOOTH_LOCAL = 20_000
"""Refined meshes with more quads are smoothed only near their bad quads (inverted or below
``quality.good_sj``): the vertices within :data:`BAD_RINGS` rings of them
(:func:`jaxmatch.placement.embed.smooth_near`). Smoothing all 100,000 vertices of a refined
L-shape took ~30 s and left 402 of its 2410 folded quads; the ~4,000 near them, ~1 s and 230
left. Up to this size the whole mesh is smoothed (a curved side's distortion spreads
further: a 12,000-quad quarter disk reached min scaled Jacobian 0.74 smoothed whole, 0.39 near
its bad quads only)."""

LARGE_ORDERING = "MMD_AT_PLUS_A"
"""Column ordering of the sparse solve of the harmonic extension above :data:`SMOOTH_ALWAYS`
quads (minimum degree on the symmetric pattern: ~35% less factor time than the default COLAMD
on a 100,000-vertex grid Laplacian, whose pattern is symmetric; up to there the default, so
small meshes come out as before to the last bit)."""

BAD_RINGS = 6
"""Rings of quads around the bad quads smoothed above :data:`SMOOTH_LOCAL` quads."""

SIZE_ROUNDS = 6
"""Calibration rounds of a ``size`` request (see :func:`solve_multiplicities`)."""

SIZE_CHORD_WEIGHT = 0.5
"""Weight, for a ``size`` request, of each chord's deviation from ``width / size`` (interior
edges of about the size) against each side's deviation from ``length / size`` (in edges)."""



# ---------------------------------------------------------------------------------------------
# the user's sides


def side_polylines(shape: Shape) -> tuple[np.ndarray, ...]:
    """The user's sides as polylines of input points, ``(k_i, 2) float64`` user coordinates,
    from corner ``i`` to corner ``i + 1`` inclusive (without corners: one closed polyline from
    ``points[0]`` around to ``points[0]``)."""
    xy = shape.given_points
    P = xy.shape[0]
    n = shape.n_corners
    if n == 0:
        return (np.concatenate([xy, xy[:1]]),)
    out = []
    for j, rev in shape.side_frame:
        a, b = int(shape.corners[j]), int(shape.corners[(j + 1) % n])
        stop = b if b > a else b + P
        poly = xy[a:stop + 1].copy() if stop < P else np.concatenate([xy[a:], xy[:stop + 1 - P]])  # (points a..stop mod P)
        out.append(poly[::-1].copy() if rev else poly)
    return tuple(out)


def side_lengths(shape: Shape) -> np.ndarray:
    """``(n_sides,) float64`` arc length of each user side (user units)."""
    return np.array([float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in side_polylines(shape)])


def side_points(polyline: np.ndarray, count: int, field=None) -> np.ndarray:
    """``(count + 1, 2)`` points evenly spaced by arc length on ``polyline (k, 2)``, from its
    first point to its last, both ends exact; with a size ``field`` (``Quality.field``) at equal
    steps of the integral of 1 / size instead (:func:`jaxmatch.field.graded_points`).

    Computed from the lexicographically smaller end whatever the direction, so that two
    patches sharing a side with the same count get bit-identical points. On a straight
    two-point side, point ``j`` (counted from the smaller end ``p0``) is
    ``p0 + (j / count) * (p1 - p0)``."""
    if field is not None:
        return graded_points(field, polyline, count)
    poly = np.asarray(polyline, dtype=np.float64)
    N = int(count)
    first, last = poly[0].tolist(), poly[-1].tolist()  # (Python floats: the same comparisons, no numpy calls)
    closed = first == last
    flip = (not closed) and last < first
    p = poly[::-1] if flip else poly
    frac = np.arange(N + 1, dtype=np.float64) / N
    if p.shape[0] == 2:
        out = p[0] + frac[:, None] * (p[1] - p[0])
    else:
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        t = frac * cum[-1]
        idx = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, p.shape[0] - 2)
        w = np.where(seg[idx] > 0, (t - cum[idx]) / np.where(seg[idx] > 0, seg[idx], 1.0), 0.0)
        out = p[idx] + w[:, None] * (p[idx + 1] - p[idx])
    out[0], out[-1] = p[0], p[-1]
    return out[::-1].copy() if flip else out


# ---------------------------------------------------------------------------------------------
# templates


# ---------------------------------------------------------------------------------------------
# multiplicities


class InfeasibleRequest(InputError):
    """A request no multiplicities can meet. The message names the side(s) and the nearest
    feasible counts; ``nearest``: those counts ``(n_sides,)`` or None."""

    def __init__(self, problem: str, where: str | None = None, nearest: Sequence[int] | None = None):
        super().__init__(problem, where)
        self.nearest = None if nearest is None else tuple(int(x) for x in nearest)


def _check_counts(counts, n_sides: int, where: str) -> np.ndarray:
    try:
        c = np.asarray(counts)
        whole = c.dtype.kind in "iu" or (c.dtype.kind == "f" and bool(np.all(np.isfinite(c) & (np.mod(c, 1) == 0))))
        ok = c.ndim == 1 and whole
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"edge counts must be a list of integers, got {counts!r}", where)
    c = c.astype(np.int64)
    if c.shape[0] != n_sides:
        what = "one total count (the shape has no corners)" if n_sides == 1 else f"one count per side ({n_sides} sides)"
        raise InputError(f"{c.shape[0]} edge counts given, expected {what}", where)
    if np.any(c < 1) or np.any(c > MAX_COUNT):
        raise InputError(f"edge counts must lie in 1..{MAX_COUNT}, got {','.join(map(str, c.tolist()))}", where)
    return c


def _tau(template: PatchTemplate, h: float) -> np.ndarray:
    """Preferred (fractional) multiplicities for edges of length ``h``: chord width / h, >= 1."""
    return np.maximum(template.chord_widths() / h, 1.0)


def solve_multiplicities(template: PatchTemplate, *, counts=None, size=None) -> np.ndarray:
    """``(n_chords,) int64 >= 1`` multiplicities.

    counts: ``(n_sides,)`` ints >= 1: ``side_matrix @ mult == counts`` exactly; among the
    solutions, the one closest (L1) to multiplicities proportional to the chords' widths (so
    that the edges are about equally long). size: target edge length (user units): the counts
    closest (L1, in edges) to ``side_length / h`` and the multiplicities closest to
    ``chord width / h`` (weight :data:`SIZE_CHORD_WEIGHT`), where ``h`` starts at ``size`` and is
    calibrated (at most :data:`SIZE_ROUNDS` solves) until the mean edge length estimated from
    the template (:func:`estimated_mean_edge`; interior edges are often shorter or longer than
    boundary ones) is within 2 % of ``size``; the closest solve is returned. Exactly one of the two. Integer programs by
    :func:`scipy.optimize.milp` (HiGHS).

    Raises :class:`InfeasibleRequest` (odd total; a side the template cannot refine finely or
    coarsely enough) with the nearest feasible counts; :class:`InputError` for malformed
    counts or sizes.
    """
    A = template.side_matrix()
    n, C = A.shape
    src = template.shape.source
    if (counts is None) == (size is None):
        raise ValueError("give exactly one of counts and size")
    lengths = side_lengths(template.shape)
    has_end = A.sum(axis=0) > 0
    if size is not None:
        try:
            h = float(size)
        except (TypeError, ValueError):
            h = math.nan
        if not (h > 0 and math.isfinite(h)):
            raise InputError(f"element size must be a positive number, got {size!r}", src)
        if lengths.sum() / h > MAX_SIZE_EDGES:
            raise InputError(f"element size {h:g} gives more than {MAX_SIZE_EDGES} boundary edges "
                             f"(perimeter {lengths.sum():g})", src)
        best = None
        h_eff = h
        for _ in range(SIZE_ROUNDS):  # calibrate: interior edges differ from boundary ones
            (m,), _ = solve_counts(one_patch_sides(lengths), [A], size=h_eff, widths=[template.chord_widths()],
                                   source=src, chord_weight=SIZE_CHORD_WEIGHT)
            est = estimated_mean_edge(template, m)
            if best is None or abs(est / h - 1) < abs(best[0] / h - 1):
                best = (est, m)
            if abs(est / h - 1) <= 0.02:
                break
            h_eff *= h / est
        return best[1]
    c = _check_counts(counts, n, src)
    h = float(lengths.sum() / c.sum())
    tau = _tau(template, h)
    m = None if c.sum() % 2 else _exact(template, c, h)
    if m is not None:
        return np.where(has_end, m, np.maximum(np.rint(tau), 1).astype(np.int64))
    near = nearest_counts(template, c)
    raise InfeasibleRequest(_infeasible_text(template, c, near), src, near)


def estimated_mean_edge(template: PatchTemplate, mult) -> float:
    """Mean edge length (user units) of the refinement by ``mult``, estimated from the
    template's placement: every template edge split into ``mult`` equal pieces, and the inner
    grid lines of each quad as long as the mean of the two quad edges they run along."""
    m = np.asarray(mult, np.int64)
    pl = template.placement
    xy = pl.xy
    q = np.asarray(pl.mesh.quads, np.int64)
    p = xy[q]
    ln = np.linalg.norm(p[:, [1, 2, 3, 0]] - p, axis=-1)  # (F, 4) edge k: q[k] -> q[k+1]
    el = np.linalg.norm(xy[template.edge_list[:, 0]] - xy[template.edge_list[:, 1]], axis=1)
    ma, mb = m[template.quad_chords[:, 0]], m[template.quad_chords[:, 1]]
    total = el.sum() + np.sum((mb - 1) * (ln[:, 0] + ln[:, 2]) / 2 + (ma - 1) * (ln[:, 1] + ln[:, 3]) / 2)
    count = m[template.edge_chord].sum() + np.sum(ma * (mb - 1) + mb * (ma - 1))
    return float(total / count)


def _exact(template: PatchTemplate, counts: np.ndarray, h: float, widths: np.ndarray | None = None) -> np.ndarray | None:
    """``(n_chords,)`` multiplicities giving exactly ``counts`` edges per side, closest (L1) to
    ``widths / h`` (default: the chords' placed widths); None when there are none
    (:func:`jaxmatch.placement.milp.solve_counts`)."""
    A = template.side_matrix()
    w = template.chord_widths() if widths is None else widths
    try:
        (m,), _ = solve_counts(one_patch_sides(side_lengths(template.shape)), [A], size=h,
                               counts={i: int(c) for i, c in enumerate(counts)}, widths=[w],
                               source=template.shape.source)
    except LayoutInfeasible:
        return None
    return m


def feasible(template: PatchTemplate, counts) -> bool:
    """Whether some multiplicities give exactly ``counts`` ``(n_sides,)`` edges per side: every
    chord at least once (``A @ 1``), the rest any sums of chords
    (:func:`jaxmatch.placement.reach.reachable_cols`), or the integer program when there are too
    many count vectors to enumerate."""
    c = [int(v) for v in np.asarray(counts, np.int64).tolist()]
    if sum(c) % 2:
        return False
    sides = template.side_chords  # (the side matrix's columns, in plain Python: most answers come from the forced moves)
    if len(c) != len(sides):
        raise ValueError(f"{len(c)} counts for {len(sides)} sides")
    cols = [[0] * len(sides) for _ in range(template.n_chords)]
    for i, ch in enumerate(sides):
        for k in ch.tolist():
            cols[k][i] += 1
    found = reachable_cols(cols, [n - len(ch) for n, ch in zip(c, sides)])
    if found is not None:
        return found
    return _exact(template, np.asarray(c, np.int64), 1.0, widths=np.ones(template.n_chords)) is not None


def nearest_counts(template: PatchTemplate, counts) -> np.ndarray:
    """``(n_sides,) int64``: feasible counts closest (L1) to ``counts`` for ``template``: the one
    integer program with the counts as targets (lengths ``counts``, size 1), fewer extra chord
    edges breaking ties. The chords' weight keeps their whole term below 1/2 for any solution
    meeting ``counts`` (each multiplicity is at most the largest count), so the answer is
    ``counts`` itself exactly when they are feasible (:func:`feasible`)."""
    A = template.side_matrix()
    c = np.asarray(counts, np.float64)
    weight = min(NEAREST_CHORD_WEIGHT, 0.5 / (A.shape[1] * (float(c.max(initial=0.0)) + 1.0)))
    _, n = solve_counts(one_patch_sides(c), [A], size=1.0, widths=[np.ones(A.shape[1])], chord_weight=weight,
                        source=template.shape.source)
    return n


NEAREST_CHORD_WEIGHT = 1e-4
"""Largest weight of the chords' deviations in :func:`nearest_counts` (the side counts' own
deviations weigh 1)."""


def _fmt(counts) -> str:
    return ",".join(str(int(x)) for x in counts)


def _infeasible_text(template: PatchTemplate, counts: np.ndarray, near: np.ndarray) -> str:
    A = template.side_matrix()
    n = len(counts)
    why = []
    if counts.sum() % 2:
        why.append(f"the total {int(counts.sum())} is odd (a quad mesh of a disk has an even number of boundary edges)")
    low = A.sum(axis=1)
    few = [i for i in range(n) if counts[i] < low[i]]
    if few:
        why.append("; ".join(f"side {i} needs at least {int(low[i])} edges" for i in few))
    off = [i for i in range(n) if counts[i] != near[i] and i not in few]
    if off:
        why.append(("side " if len(off) == 1 else "sides ") + ", ".join(map(str, off))
                   + " cannot have exactly " + _fmt(counts[off]) + " edges with the other counts")
    return (f"edge counts {_fmt(counts)} cannot be met by template {template.mesh_id}: " + "; ".join(why)
            + f"; nearest feasible counts {_fmt(near)}")


# ---------------------------------------------------------------------------------------------
# refinement and placement


class RefinedMesh(NamedTuple):
    """A refined template placed in the shape (user coordinates).

    xy: ``(V, 2) float64``; quads: ``(Q, 4) int64``, counter-clockwise.
    side_vertices: side i: vertex ids from corner i to corner i+1 inclusive,
        ``(counts[i] + 1,) int64`` (without corners: a closed loop, first id == last id).
    counts: ``(n_sides,) int64`` edges per side; mult: ``(n_chords,) int64`` multiplicities.
    boundary: ``(n,) int64`` the ccw boundary loop.
    scaled_jacobian: ``(Q,) float64`` per quad (Verdict), inverted: quads with a corner of
        signed area <= 0; edge_ratio: ``(Q,) float64`` longest / shortest edge per quad.
    region_area / mesh_area: area of the user's polygon / sum of the quads' signed areas.
    template: the :class:`PatchTemplate` refined.
    """

    xy: np.ndarray
    quads: np.ndarray
    side_vertices: tuple
    counts: np.ndarray
    mult: np.ndarray
    boundary: np.ndarray
    scaled_jacobian: np.ndarray
    inverted: int
    edge_ratio: np.ndarray
    region_area: float
    mesh_area: float
    template: PatchTemplate

    @property
    def n_quads(self) -> int:
        return int(self.quads.shape[0])

    @property
    def min_scaled_jacobian(self) -> float:
        return float(self.scaled_jacobian.min())

    @property
    def mean_scaled_jacobian(self) -> float:
        return float(self.scaled_jacobian.mean())

    @property
    def max_edge_ratio(self) -> float:
        return float(self.edge_ratio.max())

    @property
    def area_ratio(self) -> float:
        return float(self.mesh_area / self.region_area)

    @property
    def valid(self) -> bool:
        """No inverted quad."""
        return self.inverted == 0

    def as_placement(self) -> Placement:
        """The mesh as a :class:`~jaxmatch.placement.embed.Placement` (for the mesh writers and
        pictures; no alignment, no boundary paths)."""
        quads = np.ascontiguousarray(self.quads.astype(np.int32))
        sj, amin, amax = quality(self.xy, quads)
        internal = np.ones(self.xy.shape[0], bool)
        internal[self.boundary] = False
        irregular = np.flatnonzero(internal & (valences(quads, self.xy.shape[0]) != 4))
        return Placement(mesh=QuadMesh(quads=quads, boundary=self.boundary.astype(np.int32)), xy=self.xy,
                         scaled_jacobian=sj, min_angle=amin, max_angle=amax, inverted=self.inverted,
                         irregular=irregular, region_area=self.region_area, mesh_area=self.mesh_area)

    def mean_edge_length(self) -> float:
        """Mean length of the mesh's edges (each once), user units."""
        e = edges(self.quads)
        return float(np.linalg.norm(self.xy[e[:, 0]] - self.xy[e[:, 1]], axis=1).mean())


def _refine_topology(quads: np.ndarray, edge_list: np.ndarray, edge_chord: np.ndarray, quad_chords: np.ndarray,
                     mult: np.ndarray):
    """Split quads into grids.

    quads: (F, 4) template quads; edge_list (E, 2), edge_chord (E,), quad_chords (F, 2): see
    :class:`PatchTemplate`; mult: (C,) multiplicities. Vertex numbering: the template's vertices
    keep their ids; then the inner points of every template edge ``(u, w)`` (``u < w``),
    ``mult - 1`` of them from ``u`` to ``w``, edge by edge; then the inner points of each quad's
    grid. Returns ``(n_vertices, quads (Q, 4) int64, along, weights (V' , 4), corners (V', 4))``:
    ``along(a, b, k, m)`` the vertex ids at step ``k`` of ``m`` from template vertex ``a`` to
    ``b``; each new vertex ``V + r`` is ``sum_k weights[r, k] * x[corners[r, k]]`` (bilinear in
    its template quad; linear on its template edge)."""
    q = np.asarray(quads, np.int64)
    V = int(q.max()) + 1
    E = edge_list.shape[0]
    me = mult[edge_chord]
    edge_base = V + np.cumsum(me - 1) - (me - 1)  # (where each edge's inner points start)
    nv = V + int((me - 1).sum())
    key = edge_list[:, 0] * V + edge_list[:, 1]
    ma_all, mb_all = mult[quad_chords[:, 0]], mult[quad_chords[:, 1]]

    def along(a, b, k, m):
        """Vertex ids at step k (0..m) from template vertex a to b along their edge."""
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        eid = np.searchsorted(key, lo * V + hi)
        kk = np.where(a < b, k, m - k)
        return np.where(kk == 0, lo, np.where(kk == m, hi, edge_base[eid] + kk - 1))

    out_quads = []
    w_rows, v_rows = [], []
    # edge points: linear between the two ends
    ks = np.concatenate([np.arange(1, m) for m in me.tolist()]) if nv > V else np.zeros(0, np.int64)
    eidx = np.repeat(np.arange(E), me - 1)
    s = ks / me[eidx]
    we = np.zeros((s.size, 4))
    we[:, 0], we[:, 1] = 1 - s, s
    w_rows.append(we)
    v_rows.append(edge_list[eidx][:, [0, 1, 0, 1]])
    pairs = sorted(set(zip(ma_all.tolist(), mb_all.tolist())))  # (ma, mb) pairs in lexicographic order
    base = nv
    for ma, mb in pairs:
        f = np.flatnonzero((ma_all == ma) & (mb_all == mb))
        nf, Q = f.size, q[f]
        G = np.empty((nf, ma + 1, mb + 1), np.int64)
        i = np.arange(ma + 1)
        j = np.arange(mb + 1)
        G[:, :, 0] = along(Q[:, 0:1], Q[:, 1:2], i[None, :], ma)
        G[:, ma, :] = along(Q[:, 1:2], Q[:, 2:3], j[None, :], mb)
        G[:, :, mb] = along(Q[:, 3:4], Q[:, 2:3], i[None, :], ma)
        G[:, 0, :] = along(Q[:, 0:1], Q[:, 3:4], j[None, :], mb)
        ni = (ma - 1) * (mb - 1)
        if ni:
            G[:, 1:ma, 1:mb] = (base + np.arange(nf)[:, None, None] * ni
                                + (np.arange(ma - 1)[:, None] * (mb - 1) + np.arange(mb - 1)[None, :])[None])
            si = (np.arange(1, ma) / ma)[:, None] * np.ones(mb - 1)[None, :]
            tj = np.ones(ma - 1)[:, None] * (np.arange(1, mb) / mb)[None, :]
            si, tj = si.ravel(), tj.ravel()
            wq = np.stack([(1 - si) * (1 - tj), si * (1 - tj), si * tj, (1 - si) * tj], axis=1)
            w_rows.append(np.broadcast_to(wq[None], (nf, ni, 4)).reshape(-1, 4))
            v_rows.append(np.broadcast_to(Q[:, None, :], (nf, ni, 4)).reshape(-1, 4))
            base += nf * ni
        quad = np.stack([G[:, :-1, :-1], G[:, 1:, :-1], G[:, 1:, 1:], G[:, :-1, 1:]], axis=-1)
        out_quads.append(quad.reshape(-1, 4))
    return base, np.concatenate(out_quads), along, np.concatenate(w_rows), np.concatenate(v_rows)


def _refined_topology(tq: np.ndarray, template: PatchTemplate, m: np.ndarray, cache: Cache | None = None):
    """:func:`_refine_topology` of the oriented template quads ``tq (F, 4)`` at multiplicities
    ``m (C,)``, and the refined vertices of each template side ``(counts[i] + 1,) int64`` in
    the side's order: ``(n_vertices, quads (Q, 4), weights (V', 4), corners (V', 4),
    side_vertices)``. A function of the template's combinatorics alone, kept in ``cache``
    (store ``topology``; patches of one layout often share it: the arrays are shared, not to be
    written to)."""
    if cache is None:
        return _make_refined_topology(tq, template, m)
    k = cache_key(tq, template.edge_list, template.edge_chord, template.quad_chords, template.side_path, m)
    return cache.get("topology", k, lambda: _make_refined_topology(tq, template, m), quads=lambda t: t[1].shape[0])


def _make_refined_topology(tq: np.ndarray, template: PatchTemplate, m: np.ndarray):
    """:func:`_refined_topology`, made."""
    nv, quads, along, W, VV = _refine_topology(tq, template.edge_list, template.edge_chord, template.quad_chords, m)
    V0 = int(tq.max()) + 1
    ekey = template.edge_list[:, 0] * V0 + template.edge_list[:, 1]
    # every side's template edges at once: steps 0 .. me - 1 of each edge, side after side, then each side its end
    paths = [np.asarray(path, np.int64) for path in template.side_path]
    a = np.concatenate([path[:-1] for path in paths])
    b = np.concatenate([path[1:] for path in paths])
    me = np.asarray(m, np.int64)[template.edge_chord[np.searchsorted(ekey, np.minimum(a, b) * V0 + np.maximum(a, b))]]
    first = np.repeat(np.cumsum(me) - me, me)  # where each edge's steps start
    k = np.arange(int(me.sum()), dtype=np.int64) - first
    ids = along(np.repeat(a, me), np.repeat(b, me), k, np.repeat(me, me))
    steps = np.concatenate([[0], np.cumsum(me)])[np.cumsum([0] + [len(path) - 1 for path in paths])].tolist()
    side_vertices = tuple(np.concatenate([ids[s0:s1], path[-1:]]) for s0, s1, path in zip(steps, steps[1:], paths))
    return nv, quads, W, VV, side_vertices


def _laplacian(quads: np.ndarray, nv: int) -> scipy.sparse.csr_matrix:
    """``(nv, nv)`` uniform-weight graph Laplacian of the edges of ``quads (Q, 4)``: degree on
    the diagonal, -1 per edge; built in one go (canonical CSR: sorted indices, no duplicates, the
    arrays ``diags(deg) - adjacency`` gives)."""
    import scipy.sparse

    e = edges(quads)
    diag = np.arange(nv)
    rows = np.concatenate([e[:, 0], e[:, 1], diag])
    cols = np.concatenate([e[:, 1], e[:, 0], diag])
    vals = np.concatenate([np.full(2 * e.shape[0], -1.0), np.bincount(e.ravel(), minlength=nv).astype(np.float64)])
    L = scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(nv, nv))
    L.sum_duplicates()
    L.sort_indices()
    return L


def refine_and_place(template: PatchTemplate, mult, *, smooth_iters: int | None = None, quality: Quality = QUALITY,
                     cache: Cache | None = None) -> RefinedMesh:
    """:func:`_refine_and_place`, answered from ``cache`` (store ``refined``) when the same
    template (same shape, match and placement) was refined at the same multiplicities before (the
    result names the given template; its arrays are shared, not to be written to)."""
    if cache is None:
        return _refine_and_place(template, mult, smooth_iters=smooth_iters, quality=quality)
    m = template.match
    k = cache_key(template.shape, template.mesh_id, int(m.rotation), bool(m.reflected), m.alignment,
                  template.placement.xy, np.asarray(mult, np.int64), smooth_iters, quality.good_sj, ignore=("source",))
    if quality.field is not None:  # (uniform sizes: the key as it was)
        k = k + (quality.field,)
    rm = cache.get("refined", k, lambda: _refine_and_place(template, mult, smooth_iters=smooth_iters, quality=quality,
                                                            cache=cache), quads=lambda r: r.quads.shape[0])
    return rm._replace(template=template)


def _refine_and_place(template: PatchTemplate, mult, *, smooth_iters: int | None = None, quality: Quality = QUALITY,
                      cache: Cache | None = None) -> RefinedMesh:
    """Split every quad by the multiplicities of its two chords, put the refined boundary
    vertices on the user's boundary by arc length, place and smooth the interior.

    Raises :class:`InputError` when the mesh would have more than :data:`MAX_QUADS` quads.

    mult: ``(n_chords,)`` ints >= 1. Boundary: side i gets ``counts[i] = side_matrix[i] @ mult``
    edges, its vertices evenly spaced by arc length on the user's side (:func:`side_points`;
    corners exactly the input points). Interior: bilinear interpolation of the template's
    placement in each template quad, moved by the harmonic (uniform-weight) extension of the
    boundary vertices' displacement, then :func:`jaxmatch.placement.embed.smooth`
    in a normalised frame (``smooth_iters`` L-BFGS iterations per round; default:
    :data:`SMOOTH_ITERS` (with a size field :data:`SMOOTH_ITERS_GRADED`) up to :data:`SMOOTH_ALWAYS` quads; above, :data:`SMOOTH_ITERS_LARGE`
    and only when the interpolated placement folds or has a scaled Jacobian below
    ``quality.good_sj``; above :data:`SMOOTH_LOCAL` quads, only within :data:`BAD_RINGS` rings of
    those quads).
    """
    m = np.asarray(mult, np.int64).ravel()
    if m.shape[0] != template.n_chords or np.any(m < 1):
        raise ValueError(f"mult must be {template.n_chords} integers >= 1")
    n_quads = int(np.sum(m[template.quad_chords[:, 0]] * m[template.quad_chords[:, 1]]))
    if n_quads > MAX_QUADS:
        raise InputError(f"the refined mesh would have {n_quads} quads, more than the maximum {MAX_QUADS} "
                         "(ask for fewer edges or a larger size)", template.shape.source)
    pl = template.placement
    tq = np.asarray(pl.mesh.quads, np.int64)
    nv, quads, W, VV, side_vertices = _refined_topology(tq, template, m, cache)
    V0 = int(tq.max()) + 1
    xy = np.empty((nv, 2))
    xy[:V0] = pl.xy[:V0]
    xy[V0:] = np.einsum("ik,ikd->id", W, pl.xy[VV])
    # boundary
    counts = np.array([len(sv) - 1 for sv in side_vertices], np.int64)  # (= side_matrix @ m: the sides' refined edges)
    polys = side_polylines(template.shape)
    bpos = [side_points(p, int(c), quality.field) for p, c in zip(polys, counts)]
    bverts = np.concatenate([sv[:-1] for sv in side_vertices])
    bxy = np.concatenate([bp[:-1] for bp in bpos])
    # ccw loop
    loop = _ccw_loop(side_vertices, template)
    # harmonic extension of the boundary displacement
    xy = xy + harmonic_displacement(quads, nv, bverts, bxy - xy[bverts], cache=cache)
    xy[bverts] = bxy
    sj = inv = bad = None  # (the interpolated placement's figures: measured only where they decide or are the answer)
    local = smooth_iters is None and quads.shape[0] > SMOOTH_LOCAL
    if smooth_iters is not None:
        iters = int(smooth_iters)
    elif quads.shape[0] <= SMOOTH_ALWAYS:
        iters = SMOOTH_ITERS if quality.field is None else SMOOTH_ITERS_GRADED
    else:
        sj, inv = sj_inverted(xy, quads)
        bad = bad_quads(sj, inv, quality.good_sj)
        iters = SMOOTH_ITERS_LARGE if bad.any() else 0
    if iters <= 0 and sj is None:
        sj, inv = sj_inverted(xy, quads)
    if iters > 0:
        xy[bverts] = bxy  # exact boundary positions
        if local:
            xy = smooth_near_bad(xy, quads, bad, bverts, frame=bxy, iters=iters)
        else:
            xy = smooth_in_frame(xy, quads, bverts, frame=bxy, iters=iters)
        sj, inv = sj_inverted(xy, quads)
    p = xy[quads]
    el = np.linalg.norm(p[:, [1, 2, 3, 0]] - p, axis=-1)
    ratio = el.max(axis=1) / np.maximum(el.min(axis=1), np.finfo(float).tiny)
    return RefinedMesh(
        xy=xy, quads=quads, side_vertices=tuple(side_vertices), counts=counts, mult=m,
        boundary=loop, scaled_jacobian=sj, inverted=int(inv.sum()), edge_ratio=ratio,
        region_area=template.shape.user_area, mesh_area=float(quad_areas(xy, quads).sum()),
        template=template,
    )


def bad_quads(sj: np.ndarray, inverted: np.ndarray, floor: float) -> np.ndarray:
    """``(Q,) bool``: the quads a large mesh smooths around: inverted, or a scaled Jacobian
    below ``floor`` (``sj``, ``inverted``: :func:`~jaxmatch.quality.sj_inverted`)."""
    return inverted | (sj < floor)


def smooth_near_bad(xy: np.ndarray, quads: np.ndarray, bad: np.ndarray, fixed: np.ndarray, *, frame: np.ndarray,
                    iters: int = SMOOTH_ITERS_LARGE) -> np.ndarray:
    """A large mesh smoothed only within :data:`BAD_RINGS` rings of its ``bad (Q,) bool`` quads
    (:func:`~jaxmatch.placement.embed.smooth_near`; ``fixed`` vertex ids kept, ``frame`` as
    there): the refinement's and :func:`jaxmatch.placement.layout.fit_sides`'s policy above
    :data:`SMOOTH_LOCAL` quads. Returns ``(V, 2) float64``."""
    return smooth_near(xy, quads, quads[bad].ravel(), fixed, rings=BAD_RINGS, frame=frame, iters=iters)


def harmonic_displacement(quads: np.ndarray, nv: int, bverts: np.ndarray, bdisp: np.ndarray, *,
                          cache: Cache | None = None) -> np.ndarray:
    """``(nv, 2) float64``: ``bdisp (b, 2)`` on the vertices ``bverts (b,)``, elsewhere its
    uniform-weight harmonic extension over ``quads (Q, 4)`` (one linear solve; user units).

    Up to :data:`~jaxmatch.placement.embed.DENSE_TUTTE` free vertices it is the Tutte embedding
    of the displacement (:func:`~jaxmatch.placement.embed.tutte`: a dense compiled solve, and no
    ``scipy.sparse`` to import); beyond, one sparse solve: up to :data:`SMOOTH_ALWAYS` quads
    SuperLU's default ordering, then :data:`LARGE_ORDERING`;
    above :data:`SMOOTH_LOCAL` quads the Laplacian and its factorisation are kept for the next
    solve on the same topology in ``cache`` (:func:`_harmonic_solve`; also
    :func:`jaxmatch.placement.layout.fit_sides`'s)."""
    is_free = np.ones(nv, bool)
    is_free[np.asarray(bverts, np.int64)] = False
    free = np.flatnonzero(is_free)  # = np.setdiff1d(np.arange(nv), bverts), without its sort
    disp = np.zeros((nv, 2))
    disp[bverts] = bdisp
    if not free.size:
        return disp
    if quads.shape[0] > SMOOTH_LOCAL:
        disp[free] = _harmonic_solve(quads, nv, free, disp, cache)
        return disp
    if free.size <= DENSE_TUTTE:  # the Tutte embedding's system: its dense compiled solve
        return tutte(quads, nv, bverts, bdisp)
    import scipy.sparse.linalg  # only beyond DENSE_TUTTE: its import costs the command ~0.2 s (docs/perf.md)

    L = _laplacian(quads, nv)
    Lr = L[free]
    Lf = Lr[:, free].tocsc()
    rhs = -(Lr[:, bverts] @ disp[bverts])
    order = LARGE_ORDERING if quads.shape[0] > SMOOTH_ALWAYS else None  # None: SuperLU's default, COLAMD
    disp[free] = np.asarray(scipy.sparse.linalg.spsolve(Lf, rhs, permc_spec=order)).reshape(-1, 2)
    return disp


class _SuperLU:
    """The exact solver of :func:`_harmonic_solve`: SuperLU's factorisation (:data:`LARGE_ORDERING`)."""

    def __init__(self, Lf):
        import scipy.sparse.linalg

        self.lu = scipy.sparse.linalg.splu(Lf, permc_spec=LARGE_ORDERING)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self.lu.solve(rhs)


class _LDL:
    """The solver of :func:`_harmonic_solve` when the ``qdldl`` package is installed: an LDL^T
    factorisation (approximate minimum degree ordering) of the symmetric positive definite
    Laplacian on the free vertices. Exact like :class:`_SuperLU` (same solutions to ~1e-14),
    but it uses the symmetry: on the L-shape's 99,372-vertex system 0.42 s against SuperLU's
    0.64 s (docs/perf.md, "Large meshes")."""

    def __init__(self, Lf):
        import qdldl

        self.f = qdldl.Solver(Lf.tocsc())

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return np.column_stack([self.f.solve(np.ascontiguousarray(rhs[:, k])) for k in range(rhs.shape[1])])


def _large_solver(Lf):
    """The solver object of :func:`_harmonic_solve` for ``Lf``: :class:`_LDL` when qdldl is
    installed, else :class:`_SuperLU`."""
    import importlib.util

    return _LDL(Lf) if importlib.util.find_spec("qdldl") is not None else _SuperLU(Lf)


def _harmonic_solve(quads: np.ndarray, nv: int, free: np.ndarray, disp: np.ndarray,
                    cache: Cache | None = None) -> np.ndarray:
    """``(n, 2) float64`` the harmonic extension on the ``free (n,)`` vertices of a large refined
    mesh ``quads (Q, 4)`` of ``nv`` vertices, ``disp (nv, 2)`` given on the others (0 on ``free``):
    ``Lf^-1 (-(L disp)[free])``, ``L`` the uniform Laplacian (:func:`_laplacian`), ``Lf`` its rows and
    columns ``free``.

    ``L`` and the solver of ``Lf`` (:func:`_large_solver`: an LDL^T or SuperLU's factorisation)
    depend on the topology alone and are kept in ``cache`` for the next call on it (store ``factors``),
    so both coordinates and every patch of the same refinement share one."""
    import hashlib

    def make():
        L = _laplacian(quads, nv)
        return L, _large_solver(L[free][:, free].tocsc())

    if cache is None:
        L, solver = make()
    else:
        k = cache_key(hashlib.sha1(np.ascontiguousarray(quads, np.int64).tobytes()
                                   + np.ascontiguousarray(free, np.int64).tobytes()).digest())
        if cache.lookup("factors", k) is None:
            cache.clear("factors")  # the one kept is dropped before the next is made (peak memory)
        L, solver = cache.get("factors", k, make)
    return solver.solve(np.ascontiguousarray(-(L @ disp)[free], np.float64))


def _ccw_loop(side_vertices, template: PatchTemplate) -> np.ndarray:
    """The refined boundary as one ccw loop, ``(n,) int64``."""
    frame = template.shape.side_frame
    parts = sorted(zip(frame, side_vertices), key=lambda t: t[0][0])
    loop = np.concatenate([(sv[::-1] if rev else sv)[:-1] for (_, rev), sv in parts])
    return loop.astype(np.int64)


# ---------------------------------------------------------------------------------------------
# the whole job


class RefineChoice(NamedTuple):
    """Result of :func:`refine_mesh`.

    mesh: the :class:`RefinedMesh`; template: its :class:`PatchTemplate` (``template.rank``:
    1-based position among the candidates); passed_over: ``(rank, mesh_id, reason)`` of every
    better-ranked candidate not taken, in order; note: one line when the request could only be
    approximated (``size`` further than :data:`SIZE_TOLERANCE` from every template), else None.
    """

    mesh: RefinedMesh
    template: PatchTemplate
    passed_over: list
    note: str | None = None


def refine_mesh(shape: Shape, catalogue: "Catalogue" = None, lattice: "Lattice" = None, *, sides=None, size=None,
                internal=None, limit: int = None, templates: Sequence[PatchTemplate] | None = None,
                explain: bool = True, quality: Quality = QUALITY) -> RefineChoice:
    """A quad mesh of ``shape`` with the requested number of edges per side, or edges of about
    the requested length: the Python API of ``jaxmatch mesh --sides/--size``.

    sides: one edge count per user side (side i from corner i to corner i+1, corners in the
    order of the file or of its ``corners`` list; a shape without corners takes one total
    count), met exactly. size: target edge length in the shape's units: per-side counts
    closest to ``side length / size``. Exactly one of the two.

    The templates (:func:`jaxmatch.placement.templates.patch_templates`: ranked catalogue meshes of every size, ``limit``
    per size, default :data:`DEFAULT_LIMIT`, that keep every corner and place without folds)
    are tried best first; the first whose refinement meets the request
    (:func:`solve_multiplicities`) and places without inverted quads with a min scaled Jacobian
    >= ``quality.good_sj`` (:func:`refine_and_place`) is taken; better-ranked ones passed over are
    listed with the reason. When every refinement that meets the request is below that quality, the best of them is taken and ``note`` says
    so. For ``size``, "meets" means an estimated mean edge length (:func:`estimated_mean_edge`)
    within :data:`SIZE_TOLERANCE` of ``size``; when no template does, the closest is taken and
    ``note`` says so.

    Raises :class:`InfeasibleRequest` when no template can meet ``sides`` (the message names the
    sides and the nearest feasible counts over all templates), :class:`InputError` for malformed
    requests, :class:`jaxmatch.errors.UnmatchableError` when no mesh matches the shape.

    templates: already fitted templates of ``shape`` (e.g. from :func:`jaxmatch.placement.templates.patch_templates`, to
    serve many requests); then ``catalogue``, ``lattice``, ``internal`` and ``limit`` are unused.
    explain: False skips the nearest feasible counts of each template that cannot meet ``sides``
    (one integer program each; :func:`feasible` decides without one): the reasons and the
    error then name none. The mesh chosen is the same.
    """
    if (sides is None) == (size is None):
        raise ValueError("give exactly one of sides and size")
    limit = DEFAULT_LIMIT if limit is None else int(limit)
    n_sides = max(shape.n_corners, 1)
    if sides is not None:
        _check_counts(sides, n_sides, shape.source)
    passed: list = []
    rejected: list = []
    best_fail: tuple | None = None  # (distance, template, InfeasibleRequest)
    fallback: tuple | None = None  # (key, template, refined mesh, why): met the request, below the quality floor
    best_size: tuple | None = None  # (deviation, template, mult)
    def check(t: PatchTemplate) -> str | None:
        nonlocal best_fail
        if sides is None:
            return None
        if not explain:
            return None if feasible(t, sides) else "cannot meet the counts"
        near = nearest_counts(t, sides)  # one program: the counts themselves exactly when feasible
        d = int(np.abs(near - np.asarray(sides)).sum())
        if d == 0:
            return None
        if best_fail is None or d < best_fail[0]:
            best_fail = (d, t, near)
        return "cannot meet the counts: nearest feasible " + _fmt(near)

    if templates is None:
        candidates = walk(shape, catalogue, lattice, limit=limit, internal=internal, check=check, passed=passed)
    else:
        candidates = walk(shape, catalogue, lattice, limit=limit, templates=templates, check=check, passed=passed,
                          lazy_check=not explain)
    cache = catalogue.cache if catalogue is not None else None
    floor = quality.good_sj
    for t in candidates:
        mult = solve_multiplicities(t, counts=sides, size=size)
        if size is not None:
            est = estimated_mean_edge(t, mult)
            dev = abs(est - float(size)) / float(size)
            if dev > SIZE_TOLERANCE:
                if best_size is None or dev < best_size[0]:
                    best_size = (dev, t, mult)
                passed.append((t.rank, t.mesh_id, f"mean edge about {est:.4g}, {100 * dev:.0f}% from the size"))
                continue
        rm = refine_and_place(t, mult, quality=quality, cache=cache)
        if rm.valid and rm.min_scaled_jacobian >= floor:
            return RefineChoice(rm, t, _merge(passed, rejected, t.rank))
        why = (f"refined mesh folds ({rm.inverted} inverted quads)" if not rm.valid
               else f"refined mesh has min scaled Jacobian {rm.min_scaled_jacobian:.3f} < {floor}")
        key = (rm.inverted, -rm.min_scaled_jacobian)
        if fallback is None or key < fallback[0]:
            fallback = (key, t, rm, why)
        passed.append((t.rank, t.mesh_id, why))
    if fallback is not None:
        _, t, rm, why = fallback
        return RefineChoice(rm, t, _merge([p for p in passed if p[0] != t.rank], rejected, t.rank),
                            f"no refinement that meets the request has min scaled Jacobian >= {floor} without "
                            f"folds; kept the best, {t.mesh_id} ({why})")
    if size is not None and best_size is not None:
        _, t, mult = best_size
        rm = refine_and_place(t, mult, quality=quality, cache=cache)
        note = (f"no template meets size {float(size):g} within {100 * SIZE_TOLERANCE:.0f}%; "
                f"took the closest, {t.mesh_id} (mean edge {rm.mean_edge_length():.4g})")
        return RefineChoice(rm, t, _merge([p for p in passed if p[0] != t.rank], rejected, t.rank), note)
    if best_fail is not None:
        _, t, near = best_fail
        c = np.asarray(sides, np.int64)
        tried = sum(1 for p in passed if p[2].startswith("cannot meet"))
        why = _infeasible_text(t, c, near).split(": ", 1)[1].rsplit("; nearest", 1)[0]
        raise InfeasibleRequest(f"edge counts {_fmt(c)} cannot be met by any of the {tried} templates that keep the "
                                f"corners; closest template {t.mesh_id}: {why}; nearest feasible counts {_fmt(near)}",
                                shape.source, near)
    tried = sum(1 for p in passed if p[2].startswith("cannot meet"))
    if tried:  # explain=False
        raise InfeasibleRequest(f"edge counts {_fmt(np.asarray(sides, np.int64))} cannot be met by any of the {tried} "
                                "templates that keep the corners", shape.source)
    raise InfeasibleRequest("no catalogue mesh keeps every corner of the shape without folding"
                            + (f" (tried {len(passed)})" if passed else ""), shape.source)


def _merge(passed: list, rejected: list, upto: int) -> list:
    """Candidates ranked before ``upto`` that were not taken, in rank order."""
    return sorted([p for p in passed + rejected if p[0] < upto], key=lambda p: p[0])


def refined_json(choice: RefineChoice) -> dict:
    """The refinement part of ``jaxmatch mesh --json``: counts per side, quads, chords and
    multiplicities, quality figures, template and passed-over candidates."""
    rm, t = choice.mesh, choice.template
    return {
        "template": t.mesh_id, "template_rank": int(t.rank),
        "sides": [int(c) for c in rm.counts], "side_lengths": [float(x) for x in side_lengths(t.shape)],
        "quads": rm.n_quads, "vertices": int(rm.xy.shape[0]),
        "chords": [{"chord": c, "multiplicity": int(m), "edges_per_side": [int(x) for x in col]}
                   for c, (m, col) in enumerate(zip(rm.mult, t.side_matrix().T))],
        "min_scaled_jacobian": rm.min_scaled_jacobian, "mean_scaled_jacobian": rm.mean_scaled_jacobian,
        "inverted": int(rm.inverted), "area_ratio": rm.area_ratio, "max_edge_ratio": rm.max_edge_ratio,
        "mean_edge_length": rm.mean_edge_length(), "valid": rm.valid,
        "passed_over": [{"rank": int(r), "mesh_id": mid, "reason": why} for r, mid, why in choice.passed_over],
        "note": choice.note,
    }
