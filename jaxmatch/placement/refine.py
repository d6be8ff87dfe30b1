"""Meshes of the size the user asks for: refinement of a catalogue template by chord multiplicities.

A quad mesh of a disk is a union of *chords*: strips of quads that cross the mesh through
opposite edges of each quad (the classes of the relation "opposite edges of one quad"). A
chord either runs from one boundary edge to another or closes on itself; it may cross itself
(a quad whose two edge pairs belong to the same chord). Giving every chord ``c`` an integer
multiplicity ``mult[c] >= 1`` and splitting each quad whose chords are ``(a, b)`` into a
``mult[a] x mult[b]`` grid refines the mesh without new irregular vertices; side ``i`` of the
shape then has ``sum_c A[i, c] * mult[c]`` edges, ``A`` the side matrix
(:meth:`PatchTemplate.side_matrix`: how many template boundary edges of chord ``c`` lie on
side ``i``). Every chord with boundary ends has two of them, so the total is always even.

Pipeline (:func:`refine_mesh` runs it all):

1. :func:`patch_templates`: ranked catalogue meshes fitted to the shape (placed by
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
from typing import TYPE_CHECKING, Callable, Iterator, NamedTuple

import numpy as np

from jaxmatch.catalogue.mesh import edges
from jaxmatch.defaults import QUALITY
from jaxmatch.errors import InputError, UnmatchableError
from jaxmatch.arrays import roll
from jaxmatch.placement.milp import LayoutInfeasible, one_patch_sides, solve_counts
from jaxmatch.placement.embed import DENSE_TUTTE, Placement, smooth_in_frame, smooth_near, tutte
from jaxmatch.quality import quad_areas, quality, sj_inverted
from jaxmatch.shape import Shape

if TYPE_CHECKING:  # pragma: no cover
    import scipy.sparse

    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice
    from jaxmatch.scoring.rank import LazyMatches, Match

__all__ = [
    "DEFAULT_LIMIT",
    "InfeasibleRequest",
    "PatchTemplate",
    "RefineChoice",
    "RefinedMesh",
    "SIZE_TOLERANCE",
    "SJ_FLOOR",
    "SMOOTH_ALWAYS",
    "BAD_RINGS",
    "SMOOTH_LOCAL",
    "patch_templates",
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

SMOOTH_ITERS_LARGE = 50
"""Iterations per round for larger meshes, which are smoothed only when the interpolated
placement has an inverted quad or a scaled Jacobian below :data:`SJ_FLOOR` (each objective
evaluation costs about 1.5 ms per 1000 quads)."""

SMOOTH_LOCAL = 20_000
"""Refined meshes with more quads are smoothed only near their bad quads (inverted or below
:data:`SJ_FLOOR`): the vertices within :data:`BAD_RINGS` rings of them
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

FACTOR_CACHE_SIZE = 1
"""Factorisations of the harmonic extension's system kept above :data:`SMOOTH_LOCAL` quads
(:func:`_harmonic_solve`): the system depends on the refined topology only, and the patches of
one decomposition (and the same patch in two decompositions) are often the same template at the
same multiplicities (the L-shape at 100,000 quads: 5 of 10 solves). One: a 100,000-vertex
factor is ~70 MB, and the one kept is dropped before the next is made."""

BAD_RINGS = 6
"""Rings of quads around the bad quads smoothed above :data:`SMOOTH_LOCAL` quads."""

SCAN_PER_LIMIT = (3, 30)
"""Candidates per size scanned for templates, as multiples of ``limit``: a first scan, and a
deeper one when the first finds fewer than ``limit`` templates in all (shapes with many corners,
whose best-ranked meshes skip some)."""

TEMPLATE_SJ_MIN = 0.01
"""Templates whose placement has a quad with a smaller scaled Jacobian are not used: a corner of
about 180 degrees (e.g. a valence-2 boundary vertex on a straight side) stays one in every
refinement and ends up inverted or degenerate."""

SJ_FLOOR = QUALITY.good_sj
"""Minimum scaled Jacobian under which a large refined mesh is smoothed."""

SIZE_ROUNDS = 6
"""Calibration rounds of a ``size`` request (see :func:`solve_multiplicities`)."""

SIZE_CHORD_WEIGHT = 0.5
"""Weight, for a ``size`` request, of each chord's deviation from ``width / size`` (interior
edges of about the size) against each side's deviation from ``length / size`` (in edges)."""



# ---------------------------------------------------------------------------------------------
# the user's sides


def _side_frame(shape: Shape) -> tuple[tuple[int, bool], ...]:
    """For each user side ``i``: ``(j, reversed)``, the ccw side ``j`` of ``shape`` (from
    ``shape.corners[j]`` to ``corners[j + 1]``) it is, and whether the user runs it backwards
    (worked out once per shape object and kept on it: placement asks for every template).

    Raises :class:`InputError` when explicit corners are not listed in boundary order."""
    frame = shape.__dict__.get("_side_frame")
    if frame is None:
        frame = shape.__dict__["_side_frame"] = tuple(_make_side_frame(shape))
    return frame


def _make_side_frame(shape: Shape) -> list[tuple[int, bool]]:
    """:func:`_side_frame`, computed."""
    n = shape.n_corners
    if n == 0:
        return [(0, False)]
    order = np.arange(n) if shape.corner_order is None else np.asarray(shape.corner_order, np.int64)
    step = (roll(order, -1) - order) % n
    forward = bool(np.all(step == 1 % n))
    backward = bool(np.all(step == (n - 1) % n))
    if forward and backward:  # n <= 2: the file's orientation decides
        forward = not shape.input_clockwise
    elif not (forward or backward):
        raise InputError("corners are not listed in boundary order (side i must run from corner i to corner i + 1)",
                         where=shape.source)
    if forward:
        return [(int(order[i]), False) for i in range(n)]
    return [(int(order[(i + 1) % n]), True) for i in range(n)]


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
    for j, rev in _side_frame(shape):
        a, b = int(shape.corners[j]), int(shape.corners[(j + 1) % n])
        stop = b if b > a else b + P
        idx = np.arange(a, stop + 1) % P
        poly = xy[idx]
        out.append(poly[::-1].copy() if rev else poly)
    return tuple(out)


def side_lengths(shape: Shape) -> np.ndarray:
    """``(n_sides,) float64`` arc length of each user side (user units)."""
    return np.array([float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in side_polylines(shape)])


def side_points(polyline: np.ndarray, count: int) -> np.ndarray:
    """``(count + 1, 2)`` points evenly spaced by arc length on ``polyline (k, 2)``, from its
    first point to its last, both ends exact.

    Computed from the lexicographically smaller end whatever the direction, so that two
    patches sharing a side with the same count get bit-identical points. On a straight
    two-point side, point ``j`` (counted from the smaller end ``p0``) is
    ``p0 + (j / count) * (p1 - p0)``."""
    poly = np.asarray(polyline, dtype=np.float64)
    N = int(count)
    first, last = poly[0], poly[-1]
    closed = bool(np.array_equal(first, last))
    flip = (not closed) and tuple(last) < tuple(first)
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


class PatchTemplate(NamedTuple):
    """A catalogue mesh fitted to an n-sided shape with every corner on a template vertex,
    seen as chords (strips of quads). Sides are in the USER's order: side i runs from the
    user's corner i to corner i+1 (corners as listed in the input, also for clockwise input;
    for a Shape made with explicit corners c_0..c_{n-1}, corner i is c_i).

    shape: the shape it is fitted to; mesh_id: catalogue id of the template.
    side_chords: side i: ``(e_i,) int64`` chord of each template boundary edge along side i,
        from corner i to i+1.
    n_chords: number of chords (closed chords included; they have no boundary edge).
    match: the ranked :class:`~jaxmatch.scoring.rank.Match`; rank: its 1-based position in the
        candidate order of :func:`patch_templates` (of the deeper scan, when one was needed).
    placement: the template placed in the shape (user coordinates; ``placement.mesh`` is the
        oriented mesh whose quads the chords refer to).
    quad_chords: ``(F, 2) int64`` chord of edges 0/2 and of edges 1/3 of each quad.
    edge_list: ``(E, 2) int64`` undirected edges (sorted pairs, :func:`edges` order);
        edge_chord: ``(E,) int64`` chord of each.
    side_path: side i: ``(e_i + 1,) int64`` template vertex ids from corner i to corner i+1.
    """

    shape: Shape
    mesh_id: str
    side_chords: tuple
    n_chords: int
    match: "Match"
    rank: int
    placement: Placement
    quad_chords: np.ndarray
    edge_list: np.ndarray
    edge_chord: np.ndarray
    side_path: tuple

    def side_matrix(self) -> np.ndarray:
        """``(n_sides, n_chords) int64``: ``A[i, c]`` = edges of chord ``c`` on side ``i``."""
        A = np.zeros((len(self.side_chords), self.n_chords), np.int64)
        for i, ch in enumerate(self.side_chords):
            np.add.at(A[i], np.asarray(ch, np.int64), 1)
        return A

    @property
    def n_sides(self) -> int:
        return len(self.side_chords)

    def chord_widths(self) -> np.ndarray:
        """``(n_chords,) float64`` mean placed length of each chord's edges (user units): the
        width of the strip, which multiplicity ``m`` splits into ``m`` edges."""
        xy = self.placement.xy
        ln = np.linalg.norm(xy[self.edge_list[:, 0]] - xy[self.edge_list[:, 1]], axis=1)
        tot = np.bincount(self.edge_chord, weights=ln, minlength=self.n_chords)
        cnt = np.bincount(self.edge_chord, minlength=self.n_chords)
        return tot / np.maximum(cnt, 1)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of the undirected graph on ``n`` nodes with the edges ``a[i]-b[i]``
    (``a``, ``b``: (m,) ints): ``(n,) int64``, each node's component named by its smallest node.

    A union-find over the few hundred edges of a template (what :func:`_chords` joins: a quad's
    opposite edges), rather than ``scipy.sparse.csgraph.connected_components``, whose import
    (with ``scipy.sparse.linalg`` it loads) costs the command ~0.1 s (docs/perf.md, "Fourth pass")."""
    parent = list(range(int(n)))

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]  # path halving
            x = parent[x]
        return x

    for x, y in zip(np.asarray(a).tolist(), np.asarray(b).tolist()):
        rx, ry = root(x), root(y)
        if rx != ry:
            parent[max(rx, ry)] = min(rx, ry)  # the smaller node is the root
    return np.asarray([root(x) for x in range(int(n))], np.int64)


class _ChordTopology(NamedTuple):
    """What :func:`_chords` needs of a quad mesh whatever the numbering: ``edges (E, 2) int64``
    (sorted pairs, each once), ``key (E,)`` their sorted codes ``a * V + b``, ``V``, ``quad_edges
    (F, 4)`` each quad's edge ids, ``label (E,)`` each edge's chord in ``0 .. n - 1`` (by smallest
    root edge) and ``n``."""

    edges: np.ndarray
    key: np.ndarray
    V: int
    quad_edges: np.ndarray
    label: np.ndarray
    n: int


def _chord_topology(quads: np.ndarray) -> _ChordTopology:
    """:class:`_ChordTopology` of ``quads (F, 4)``."""
    q = np.asarray(quads, np.int64)
    e = edges(q).astype(np.int64)
    V = int(q.max()) + 1
    key = e[:, 0] * V + e[:, 1]
    qe = np.stack([_edge_id(key, V, q[:, k], q[:, (k + 1) % 4]) for k in range(4)], axis=1)  # (F, 4)
    label = _components(e.shape[0], np.concatenate([qe[:, 0], qe[:, 1]]), np.concatenate([qe[:, 2], qe[:, 3]]))
    roots, label = np.unique(label, return_inverse=True)  # components 0 .. ncomp - 1
    return _ChordTopology(e, key, V, qe, label, int(roots.size))


def _edge_id(key: np.ndarray, V: int, a, b):
    """Ids of the edges ``a-b`` (either order) among the sorted edge codes ``key``."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.searchsorted(key, lo * V + hi)


def _kept_topology(mesh, reflected: bool) -> _ChordTopology:
    """:func:`_chord_topology` of catalogue ``mesh`` as matched (quads mirrored when
    ``reflected``, as :func:`~jaxmatch.placement.embed.oriented_boundary` does; a rotation keeps
    the quads), kept on the mesh object, read-only, when its quads are read-only (the catalogue's:
    a template scan fits a hundred matches of a few dozen meshes)."""
    kept = mesh.__dict__.get("_chord_topology")
    if kept is not None and kept[bool(reflected)] is not None:
        return kept[bool(reflected)]
    q = np.asarray(mesh.quads)
    topo = _chord_topology(q[:, ::-1] if reflected else q)
    if not q.flags.writeable:
        for a in (topo.edges, topo.key, topo.quad_edges, topo.label):
            a.setflags(write=False)
        kept = list(kept) if kept is not None else [None, None]
        kept[bool(reflected)] = topo
        object.__setattr__(mesh, "_chord_topology", tuple(kept))
    return topo


def _chords(quads: np.ndarray, boundary: np.ndarray, first_edges: Sequence[tuple[int, int]],
            topology: _ChordTopology | None = None):
    """Chords of a quad mesh of a disk.

    quads: (F, 4) ccw; first_edges: boundary edges ``(u, w)`` in the order chords should be
    numbered by (a chord's number is the position of its first boundary edge in this order;
    closed chords follow, by their smallest edge); topology: :func:`_chord_topology` of
    ``quads`` when the caller has it. Returns ``(edge_list (E, 2), edge_chord (E,), quad_chords
    (F, 2), n_chords)``."""
    t = _chord_topology(quads) if topology is None else topology
    E = t.edges.shape[0]
    # renumber: by first boundary edge along the sides, then the rest by smallest edge
    rename = np.full(t.n, -1, np.int64)
    nxt = 0
    fe = np.asarray(first_edges, np.int64).reshape(-1, 2)
    order = np.concatenate([_edge_id(t.key, t.V, fe[:, 0], fe[:, 1]), np.arange(E)])
    for eid in order.tolist():
        c = t.label[eid]
        if rename[c] < 0:
            rename[c] = nxt
            nxt += 1
    chord = rename[t.label]
    return t.edges, chord, np.stack([chord[t.quad_edges[:, 0]], chord[t.quad_edges[:, 1]]], axis=1), int(t.n)


def _corner_positions(shape: Shape, annotation, alignment: np.ndarray) -> np.ndarray | None:
    """Position in the matched boundary loop of each ccw shape corner, ``(c,) int64``, or None
    when a corner has no template vertex."""
    al = np.asarray(alignment, np.int64)
    codes = np.asarray(annotation.codes)
    side = np.asarray(annotation.side)
    n = shape.n_corners
    first = np.searchsorted(side, np.arange(n))  # annotation index of corner j
    if n and np.any(codes[first] == 0):
        return None
    where = {int(a): j for j, a in enumerate(al.tolist())}
    pos = [where.get(int(i)) for i in first]
    if any(p is None for p in pos):
        return None
    return np.asarray(pos, np.int64)


def _fit(shape: Shape, annotation, match: "Match", catalogue: "Catalogue", rank: int) -> PatchTemplate | None:
    """An unplaced :class:`PatchTemplate` (``placement`` None) from a ranked match, or None when
    a corner of the shape has no mesh vertex. The chords and sides do not depend on the
    placement: :func:`~jaxmatch.placement.choose.place_match` re-spreads the alignment only over
    points of the same type, and a match with every corner matched uses every corner point."""
    from jaxmatch.placement.embed import oriented_boundary

    om, loop32 = oriented_boundary(catalogue.mesh(match.mesh_id), match.rotation, match.reflected)
    loop = np.asarray(loop32, np.int64)
    nb = loop.shape[0]
    if shape.n_corners == 0:
        paths = [np.concatenate([loop, loop[:1]])]
    else:
        pos = _corner_positions(shape, annotation, match.alignment)
        if pos is None:
            return None
        n = shape.n_corners
        paths = []
        for j, rev in _side_frame(shape):
            a, b = int(pos[j]), int(pos[(j + 1) % n])
            stop = b if b > a else b + nb
            path = loop[np.arange(a, stop + 1) % nb]
            paths.append(path[::-1].copy() if rev else path)
    first = [(int(p[k]), int(p[k + 1])) for p in paths for k in range(p.shape[0] - 1)]
    topo = _kept_topology(catalogue.mesh(match.mesh_id), match.reflected)
    e, chord, qc, nc = _chords(om.quads, loop, first, topo)
    side_chords = [chord[_edge_id(topo.key, topo.V, p[:-1], p[1:])].astype(np.int64) for p in paths]
    return PatchTemplate(shape, match.mesh_id, tuple(side_chords), nc, match, rank, None, qc, e, chord,
                         tuple(p.astype(np.int64) for p in paths))


def _candidates(shape: Shape, catalogue: "Catalogue", lattice: "Lattice", *, limit: int,
                internal=None) -> tuple[object, "LazyMatches"]:
    """(annotation, matches): the best ``limit`` matches of every selected size (k), merged
    best utility first (then fewer internal vertices, then id); each match aligned when first
    asked for (:class:`~jaxmatch.scoring.rank.LazyMatches`, whose ``head`` names it without that)."""
    from jaxmatch.scoring.rank import rank

    ranking = rank(shape, catalogue, lattice, internal=internal, top=max(int(limit), 1), per_size=True, prune=True,
                   lazy=True)  # a scan aligns only the matches it reaches
    ms = ranking.results.reordered(lambda r: (-r[0], r[1], r[3]))  # utility, internal vertices, id
    return ranking.annotation, ms


_UNFITTED = object()


def _try_candidate(shape, ann, m: "Match", catalogue, r: int,
                   check: Callable[[PatchTemplate], str | None] | None = None,
                   fitted=_UNFITTED) -> tuple[PatchTemplate | None, str | None]:
    """``(template, None)``: ranked match ``m`` (at ``r``) fitted and placed on ``shape`` with
    every corner a mesh vertex and no folded or degenerate quad; else ``(fitted or None,
    reason)``. ``check(unplaced template)``: a reason to skip it before placing (None: go on).
    ``fitted``: :func:`_fit`'s answer for ``m`` when the caller has it."""
    from jaxmatch.placement.choose import place_match

    t = _fit(shape, ann, m, catalogue, r) if fitted is _UNFITTED else fitted
    if t is None:
        return None, "leaves a corner without a mesh vertex"
    reason = check(t) if check is not None else None
    if reason is not None:
        return t, reason
    pl = place_match(shape, ann, catalogue, m)
    if pl.inverted:
        return t, f"folds when placed ({pl.inverted} inverted quads)"
    if not pl.min_scaled_jacobian >= TEMPLATE_SJ_MIN:
        return t, (f"has a degenerate quad when placed (min scaled Jacobian {pl.min_scaled_jacobian:.3f}: "
                   "a straight angle, e.g. a valence-2 vertex on a side)")
    return t._replace(placement=pl), None


class _Memo:
    """What the walks of one shape's templates share (:func:`lazy_patch_templates`): each
    candidate's fit and placement, computed once whichever walk asks first (their rankings are
    kept by :func:`jaxmatch.scoring.rank.rank`'s own memo). ``lock``: held while one is computed
    (callers may share the template cache across threads)."""

    def __init__(self):
        import threading

        self.lock = threading.RLock()
        self.fits: dict = {}
        self.placed: dict = {}

    def fit(self, shape, ann, m: "Match", catalogue, r: int) -> PatchTemplate | None:
        """:func:`_fit` of candidate ``m`` (ranked ``r``)."""
        key = (m.mesh_id, m.rotation, m.reflected, r)
        with self.lock:
            if key not in self.fits:
                self.fits[key] = _fit(shape, ann, m, catalogue, r)
            return self.fits[key]

    def place(self, shape, ann, m: "Match", catalogue, r: int) -> tuple[PatchTemplate | None, str | None]:
        """:func:`_try_candidate` of candidate ``m`` (ranked ``r``), its fit from :meth:`fit`."""
        key = (m.mesh_id, m.rotation, m.reflected, r)
        with self.lock:
            if key not in self.placed:
                t = self.fit(shape, ann, m, catalogue, r)
                self.placed[key] = _try_candidate(shape, ann, m, catalogue, r, fitted=t)
            return self.placed[key]


def _iter_templates(shape, catalogue, lattice, *, limit: int, internal=None, rejected: list | None = None,
                    check: Callable[[PatchTemplate], str | None] | None = None,
                    memo: _Memo | None = None) -> Iterator[PatchTemplate]:
    """Placed templates in candidate order (see :func:`patch_templates`), at most ``limit`` per
    size. ``check(unplaced template)``: a reason to skip it before placing (None: go on).
    Skipped candidates are appended to ``rejected`` as ``(rank, mesh_id, reason)``. ``memo``:
    fits and placements shared with other walks of the shape (without ``check``)."""
    taken: dict[int, int] = {}
    seen: set = set()
    for scan in SCAN_PER_LIMIT:
        if scan > SCAN_PER_LIMIT[0] and sum(taken.values()) >= limit:
            break  # the deeper scan only when the first found fewer than `limit` templates
        ann, ms = _candidates(shape, catalogue, lattice, limit=scan * max(int(limit), 1), internal=internal)
        for r in range(1, len(ms) + 1):
            mid, k, rot, refl = ms.head(r - 1)  # skipped ones are not aligned
            key = (mid, rot, refl)
            if taken.get(k, 0) >= limit or key in seen:
                continue
            m = ms[r - 1]
            seen.add(key)
            if memo is not None and check is None:
                t, reason = memo.place(shape, ann, m, catalogue, r)
            else:
                t, reason = _try_candidate(shape, ann, m, catalogue, r, check)
            if reason is not None:
                if rejected is not None and (scan == SCAN_PER_LIMIT[0] or t is not None):  # not every corner-skipper twice
                    rejected.append((r, m.mesh_id, reason))
                continue
            taken[m.internal_vertices] = taken.get(m.internal_vertices, 0) + 1
            yield t


def _iter_checked(shape, catalogue, lattice, *, limit: int, internal, check: Callable[[PatchTemplate], str | None],
                  memo: _Memo, passed: list) -> Iterator[PatchTemplate]:
    """The templates of :func:`_iter_templates` (same arguments, no ``check``) that pass
    ``check``, in their order: what walking them all and skipping those ``check`` refuses gives
    (:func:`_given`), with fewer placements. A candidate ``check`` refuses is never handed out,
    so it is placed only when whether it folds decides which later candidates are templates
    (the per-size ``limit``, and whether the deeper scan runs); until then it waits in its
    size's queue. The refused are appended to ``passed`` as ``(rank, mesh_id, reason)`` when
    met (also those that, placed, would have folded: not templates at all)."""
    limit = int(limit)
    sure: dict[int, int] = {}  # per size: candidates known to be templates
    waiting: dict[int, list] = {}  # per size: refused candidates not yet placed, in order

    def place_waiting(k: int, *, all_of_them: bool = False) -> None:
        """Place size k's waiting candidates in order until the next candidate's fate no longer
        depends on them (the limit reached, or out of reach of all of them together), or with
        ``all_of_them`` until none waits (how many are templates); the rest are dropped once the
        limit is reached (beyond it: not templates)."""
        q = waiting.setdefault(k, [])
        while q and sure.get(k, 0) < limit and (all_of_them or limit <= sure.get(k, 0) + len(q)):
            ann, m, r = q.pop(0)
            if memo.place(shape, ann, m, catalogue, r)[1] is None:
                sure[k] = sure.get(k, 0) + 1
        if sure.get(k, 0) >= limit:
            q.clear()

    def at_least_limit() -> bool:
        """Whether the walk has ``limit`` templates in all sizes together (placing waiting
        candidates only while that is undecided)."""
        while True:
            low = sum(sure.values())
            high = low + sum(min(len(q), limit - sure.get(j, 0)) for j, q in waiting.items())
            if low >= limit or high < limit:
                return low >= limit
            place_waiting(next(j for j, q in waiting.items() if q), all_of_them=True)

    seen: set = set()
    for scan in SCAN_PER_LIMIT:
        if scan > SCAN_PER_LIMIT[0] and at_least_limit():
            break
        ann, ms = _candidates(shape, catalogue, lattice, limit=scan * max(limit, 1), internal=internal)
        for r in range(1, len(ms) + 1):
            mid, k, rot, refl = ms.head(r - 1)  # skipped ones are not aligned
            key = (mid, rot, refl)
            if key in seen or sure.get(k, 0) >= limit:
                continue
            m = ms[r - 1]
            t = memo.fit(shape, ann, m, catalogue, r)
            if t is None:  # leaves a corner without a vertex: never a template
                seen.add(key)
                continue
            why = check(t)
            if why is not None:
                seen.add(key)
                waiting.setdefault(k, []).append((ann, m, r))
                passed.append((r, m.mesh_id, why))
                continue
            place_waiting(k)
            if sure.get(k, 0) >= limit:
                continue
            seen.add(key)
            placed, reason = memo.place(shape, ann, m, catalogue, r)
            if reason is None:
                sure[k] = sure.get(k, 0) + 1
                yield placed._replace(shape=shape)


def _longest_boundary(catalogue: "Catalogue", k: int) -> int:
    """The longest boundary loop of the catalogue's meshes with ``k`` internal vertices (0: none)."""
    from jaxmatch.scoring.bulk import prepared  # the grouping the ranking of size k uses, kept on the catalogue

    return max((int(p.n) for p in prepared(catalogue, [int(k)])), default=0)


def _iter_by_size(shape, catalogue, lattice, *, limit: int, internal: Sequence[int]) -> Iterator[PatchTemplate]:
    """The templates of :func:`_iter_templates` fewest internal vertices first, made one at a
    time: each size ``k`` of ``internal`` (ascending) is ranked alone and its candidates placed in
    ranked order until ``limit`` are kept (``rank``: the place in that size's ranking); the deeper
    scan of :data:`SCAN_PER_LIMIT` when all sizes kept fewer than ``limit`` in all. A size no
    catalogue mesh can match is passed over, and so is one whose boundary loops are all shorter
    than the shape's corners (none of its meshes could keep every corner: not ranked at all)."""
    kept: dict[int, int] = {}
    seen: set = set()
    whole: set = set()  # sizes whose every match a scan has gone through (a deeper one finds no other)
    for scan in SCAN_PER_LIMIT:
        if scan > SCAN_PER_LIMIT[0] and sum(kept.values()) >= limit:
            break  # the deeper scan only when the first found fewer than `limit` templates
        for k in sorted(int(k) for k in internal):
            if kept.get(k, 0) >= limit or k in whole or _longest_boundary(catalogue, k) < shape.n_corners:
                continue  # (every corner needs its own boundary vertex: no mesh of size k keeps them all)
            try:
                ann, ms = _candidates(shape, catalogue, lattice, limit=scan * max(int(limit), 1), internal=[k])
            except UnmatchableError:
                continue
            if len(ms) < scan * max(int(limit), 1):
                whole.add(k)
            for r in range(1, len(ms) + 1):
                mid, _, rot, refl = ms.head(r - 1)  # skipped ones are not aligned
                key = (mid, rot, refl)
                if key in seen:
                    continue
                m = ms[r - 1]
                seen.add(key)
                t, reason = _try_candidate(shape, ann, m, catalogue, r)
                if reason is None:
                    kept[k] = kept.get(k, 0) + 1
                    yield t
                    if kept[k] >= limit:
                        break


class _Walk:
    """A template walk and the templates it has made so far (shared by every
    :class:`LazyTemplates` of one patch)."""

    def __init__(self, start: Callable[[], Iterator[PatchTemplate]]):
        import threading

        self.start: Callable[[], Iterator[PatchTemplate]] | None = start  # called on the first ask
        self.produce: Iterator[PatchTemplate] | None = None
        self.made: list[PatchTemplate] = []
        self.error: Exception | None = None
        self.lock = threading.Lock()  # one thread advances the walk at a time (callers may share a cache)
        self.checked: Callable | None = None  # (shape, check, passed) -> the templates passing check (_iter_checked)

    def fill(self, n: float) -> None:
        """Place candidates until ``n`` templates exist or none is left; an error of the walk
        (e.g. :class:`~jaxmatch.errors.UnmatchableError`) is raised again on every later ask
        beyond what was made before it."""
        if len(self.made) >= n:
            return
        with self.lock:
            while len(self.made) < n:
                if self.error is not None:
                    raise self.error
                if self.produce is None and self.start is None:
                    return
                try:
                    if self.start is not None:
                        self.produce, self.start = self.start(), None
                    self.made.append(next(self.produce))
                except StopIteration:
                    self.produce = None
                except Exception as e:  # noqa: BLE001 - kept and raised again
                    self.produce, self.error = None, e
                    raise


class LazyTemplates(Sequence):
    """A patch's templates (:class:`PatchTemplate`), placed only when asked for: ``t[j]`` places
    candidates until the ``j``-th template exists; ``len(t)`` places all, ``bool(t)`` the first.
    Each template handed out carries ``shape`` (the caller's)."""

    def __init__(self, walk: _Walk, shape: Shape):
        self._walk = walk
        self._shape = shape

    def __getitem__(self, j):
        whole = isinstance(j, slice) or j < 0
        self._walk.fill(math.inf if whole else j + 1)
        items = self._walk.made[j]
        if isinstance(j, slice):
            return [t._replace(shape=self._shape) for t in items]
        return items._replace(shape=self._shape)

    def __len__(self) -> int:
        self._walk.fill(math.inf)
        return len(self._walk.made)

    def __bool__(self) -> bool:
        self._walk.fill(1)
        return bool(self._walk.made)

    def checked(self, check: Callable[[PatchTemplate], str | None], passed: list) -> Iterator[PatchTemplate] | None:
        """The templates that pass ``check(unplaced template)`` (None: go on) in order, each
        refused one appended to ``passed`` as ``(rank, mesh_id, reason)``, placing as few
        candidates as that allows (:func:`_iter_checked`); None for a walk by size."""
        if self._walk.checked is None:
            return None
        return self._walk.checked(self._shape, check, passed)


def lazy_patch_templates(shape: Shape, catalogue: "Catalogue", lattice: "Lattice", *, limit: int,
                         internal: Sequence[int] | None = None, by_size: bool = True) -> LazyTemplates:
    """The templates of :func:`patch_templates` placed only as far as they are used
    (:class:`LazyTemplates`), kept per catalogue (:data:`TEMPLATE_CACHE_SIZE` shapes, an error
    of the walk kept with them). ``by_size``: fewest internal vertices
    first, then ranked (:func:`_iter_by_size`; ``internal`` required); else in the candidate
    order of :func:`patch_templates` (:func:`_iter_templates`). A shape no mesh matches raises
    :class:`~jaxmatch.errors.UnmatchableError` when the first template is asked for."""
    ks = None if internal is None else tuple(sorted(int(k) for k in internal))
    key = ("lazy", by_size, _shape_key(shape), lattice, int(limit), ks)
    cache = _template_cache(catalogue)
    hit = cache.get(key)
    if hit is None:
        if by_size:
            hit = _Walk(lambda: _iter_by_size(shape, catalogue, lattice, limit=limit, internal=ks))
        else:
            memo = _Memo()
            hit = _Walk(lambda: _iter_templates(shape, catalogue, lattice, limit=limit, internal=ks, memo=memo))
            hit.checked = lambda caller, check, passed: _iter_checked(caller, catalogue, lattice, limit=limit,
                                                                      internal=ks, check=check, memo=memo, passed=passed)
        cache[key] = hit
        while len(cache) > TEMPLATE_CACHE_SIZE:
            cache.pop(next(iter(cache)))
    else:
        cache[key] = cache.pop(key, hit)  # most recently used last (another thread may have moved it)
    return LazyTemplates(hit, shape)


def catalogue_oriented_quads(catalogue: "Catalogue", match: "Match") -> np.ndarray:
    """``(F, 4)`` quads of ``match``'s mesh oriented as matched (mirrored when reflected)."""
    from jaxmatch.placement.embed import oriented_boundary

    return oriented_boundary(catalogue.mesh(match.mesh_id), match.rotation, match.reflected)[0].quads


def patch_templates(shape: Shape, catalogue: "Catalogue", lattice: "Lattice", *, limit: int = 20,
                    internal=None) -> list[PatchTemplate]:
    """Ranked templates (best first) whose placement keeps every corner and has no folded quad
    (nor a degenerate one: min scaled Jacobian >= :data:`TEMPLATE_SJ_MIN`).

    Candidates: the best ``3 * limit`` meshes of each size k (``internal``: the sizes; None:
    every size of the catalogue; ``30 * limit`` when that finds fewer than ``limit`` templates,
    see :data:`SCAN_PER_LIMIT`) by :func:`jaxmatch.scoring.rank.rank`, merged by utility (then
    fewer internal vertices, then id); each is placed
    (:func:`jaxmatch.placement.choose.place_match`) and kept when every corner of the shape is
    a mesh vertex and no quad is inverted or degenerate; at most ``limit`` are kept per size. Sizes are mixed
    because a request for few edges needs a small template and raw utilities favour large ones.
    """
    return lazy_patch_templates(shape, catalogue, lattice, limit=limit, internal=internal, by_size=False)[:]


TEMPLATE_CACHE_SIZE = 512
"""Shapes whose :func:`patch_templates` are kept per catalogue (least recently used dropped):
ranking and placing candidates is most of a meshing call, and the same patch recurs across the
pipeline's strategies, its size groups and across calls (a size slider, a batch of parts)."""


def _array_key(a) -> tuple | None:
    if a is None:
        return None
    a = np.ascontiguousarray(a)
    return a.dtype.str, a.shape, a.tobytes()


def _shape_key(shape: Shape) -> tuple:
    """Everything of ``shape`` its templates depend on (all but ``source``: the cached templates
    are given the caller's shape)."""
    return (_array_key(shape.points), _array_key(shape.corners), _array_key(shape.convex), float(shape.scale),
            _array_key(shape.offset), _array_key(shape.input_points), _array_key(shape.corner_order),
            bool(shape.input_clockwise), tuple(_array_key(h) for h in shape.holes),
            tuple(_array_key(c) for c in shape.hole_corners), bool(shape.explicit_corners))


def _template_cache(catalogue: "Catalogue") -> dict:
    """The catalogue's cache of :func:`patch_templates` (held by the catalogue object, so it
    lives as long as the catalogue; the shipped catalogue is opened once per process)."""
    cache = catalogue.__dict__.get("_patch_template_cache")
    if cache is None:
        cache = {}
        catalogue.__dict__["_patch_template_cache"] = cache
    return cache


def clear_template_cache(catalogue: "Catalogue") -> None:
    """Forget the templates :func:`patch_templates` cached for ``catalogue``, the layouts
    :func:`jaxmatch.placement.layout.mesh_layout` meshed with it, the rankings
    :func:`jaxmatch.scoring.rank.rank` kept for it and the refined meshes (for
    timings of a first call on a shape; :func:`jaxmatch.placement.layout.clear_caches` forgets
    the layouts' integer programs, sides and patch shapes)."""
    from jaxmatch.scoring.rank import clear_memo

    catalogue.__dict__.pop("_patch_template_cache", None)
    catalogue.__dict__.pop("_mesh_layout_cache", None)
    clear_memo(catalogue)
    _REFINED.clear()
    _TOPOLOGY.clear()


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


FEASIBLE_STATES = 100_000
"""Largest number of count vectors :func:`feasible` enumerates (every vector below the counts);
beyond it the integer program answers."""


def _reachable(A: np.ndarray, target: np.ndarray) -> bool | None:
    """Whether ``A @ x == target`` for some integer ``x >= 0`` (``A``: ``(S, C)`` nonnegative
    integers, ``target``: ``(S,)``), by marking every vector ``<= target`` that sums of columns
    reach, one column at a time: the marks shifted by ``a``, ``2a``, ``4a``, ... (each a slice of
    the ``target + 1`` box) close them under adding any number of copies of column ``a``; None
    when there are more than :data:`FEASIBLE_STATES` such vectors."""
    t = np.asarray(target, np.int64)
    if np.any(t < 0):
        return False
    dims = tuple(int(d) for d in t + 1)
    if math.prod(dims) > FEASIBLE_STATES:
        return None
    reach = np.zeros(dims, bool)
    reach[(0,) * len(dims)] = True
    goal = tuple(t.tolist())
    for a in np.asarray(A, np.int64).T.tolist():  # Python ints: a few steps of tiny boxes
        step = a
        while any(step) and all(s <= g for s, g in zip(step, goal)):
            dst = tuple(slice(s, None) for s in step)
            src = tuple(slice(0, d - s) for d, s in zip(dims, step))
            reach[dst] |= reach[src]
            step = [2 * s for s in step]
        if reach[goal]:  # marks are only ever added
            return True
    return bool(reach[goal])


def feasible(template: PatchTemplate, counts) -> bool:
    """Whether some multiplicities give exactly ``counts`` ``(n_sides,)`` edges per side: every
    chord at least once (``A @ 1``), the rest any sums of chords (:func:`_reachable`), or the
    integer program when there are too many count vectors to enumerate."""
    c = np.asarray(counts, np.int64)
    if c.sum() % 2:
        return False
    A = template.side_matrix()
    found = _reachable(A, c - A.sum(axis=1))
    if found is not None:
        return found
    return _exact(template, c, 1.0, widths=np.ones(A.shape[1])) is not None


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
        from jaxmatch.catalogue.mesh import QuadMesh, valences

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
    edge_base = V + np.concatenate([[0], np.cumsum(me - 1)[:-1]])
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
    w_rows.append(np.stack([1 - s, s, np.zeros_like(s), np.zeros_like(s)], axis=1))
    v_rows.append(np.stack([edge_list[eidx, 0], edge_list[eidx, 1], edge_list[eidx, 0], edge_list[eidx, 1]], axis=1))
    span = int(mb_all.max(initial=0)) + 1  # (ma, mb) pairs in lexicographic order, as np.unique(axis=0) gives them
    pairs = [divmod(int(c), span) for c in np.unique(ma_all.astype(np.int64) * span + mb_all)]
    base = nv
    for ma, mb in pairs:
        f = np.flatnonzero((ma_all == ma) & (mb_all == mb))
        nf = f.size
        Q = q[f]
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


TOPOLOGY_CACHE_SIZE = 256
"""Refined topologies (:func:`_refined_topology`) kept between calls (least recently used
dropped; only those of at most :data:`REFINED_CACHE_QUADS` quads)."""

_TOPOLOGY: dict = {}


def _refined_topology(tq: np.ndarray, template: PatchTemplate, m: np.ndarray):
    """:func:`_refine_topology` of the oriented template quads ``tq (F, 4)`` at multiplicities
    ``m (C,)``, and the refined vertices of each template side ``(counts[i] + 1,) int64`` in
    the side's order: ``(n_vertices, quads (Q, 4), weights (V', 4), corners (V', 4),
    side_vertices)``. A function of the template's combinatorics alone, kept in
    :data:`_TOPOLOGY` (patches of one layout often share it: the arrays are shared, not to be
    written to)."""
    key = (_array_key(tq), _array_key(template.edge_list), _array_key(template.edge_chord),
           _array_key(template.quad_chords), tuple(_array_key(np.asarray(p)) for p in template.side_path), _array_key(m))
    hit = _TOPOLOGY.pop(key, None)
    if hit is None:
        nv, quads, along, W, VV = _refine_topology(tq, template.edge_list, template.edge_chord, template.quad_chords, m)
        V0 = int(tq.max()) + 1
        ekey = template.edge_list[:, 0] * V0 + template.edge_list[:, 1]
        side_vertices = []
        for path in template.side_path:  # template edge by template edge
            ids = []
            for a, b in zip(path[:-1].tolist(), path[1:].tolist()):
                eid = int(np.searchsorted(ekey, min(a, b) * V0 + max(a, b)))
                me = int(m[template.edge_chord[eid]])
                ids.extend(along(np.int64(a), np.int64(b), np.arange(me), me).tolist())
            ids.append(int(path[-1]))
            side_vertices.append(np.asarray(ids, np.int64))
        hit = (nv, quads, W, VV, tuple(side_vertices))
    if hit[1].shape[0] > REFINED_CACHE_QUADS:  # a large mesh is not asked twice: not kept
        return hit
    while len(_TOPOLOGY) >= TOPOLOGY_CACHE_SIZE:
        _TOPOLOGY.pop(next(iter(_TOPOLOGY)))
    _TOPOLOGY[key] = hit
    return hit


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


REFINED_CACHE_SIZE = 512
"""Refined meshes of :func:`refine_and_place` kept between calls (least recently used dropped)."""

REFINED_CACHE_QUADS = 20_000
"""Only refined meshes of at most this many quads are kept (a large mesh is not asked twice)."""

REFINED_CACHE_TOTAL_QUADS = 200_000
"""At most this many quads in all the refined meshes kept (tens of MB), whatever their number."""

_REFINED: dict = {}


def refine_and_place(template: PatchTemplate, mult, *, smooth_iters: int | None = None) -> RefinedMesh:
    """:func:`_refine_and_place`, answered from a cache when the same template (same shape,
    match and placement) was refined at the same multiplicities before (the result names the
    given template; its arrays are shared, not to be written to)."""
    m = template.match
    key = (_shape_key(template.shape), template.mesh_id, int(m.rotation), bool(m.reflected),
           _array_key(m.alignment), _array_key(template.placement.xy), _array_key(np.asarray(mult, np.int64)),
           None if smooth_iters is None else int(smooth_iters))
    rm = _REFINED.pop(key, None)
    if rm is None:
        rm = _refine_and_place(template, mult, smooth_iters=smooth_iters)
        if rm.quads.shape[0] > REFINED_CACHE_QUADS:
            return rm
        total = sum(r.quads.shape[0] for r in _REFINED.values()) + rm.quads.shape[0]
        while _REFINED and (len(_REFINED) >= REFINED_CACHE_SIZE or total > REFINED_CACHE_TOTAL_QUADS):
            total -= _REFINED.pop(next(iter(_REFINED))).quads.shape[0]
    _REFINED[key] = rm
    return rm._replace(template=template)


def _refine_and_place(template: PatchTemplate, mult, *, smooth_iters: int | None = None) -> RefinedMesh:
    """Split every quad by the multiplicities of its two chords, put the refined boundary
    vertices on the user's boundary by arc length, place and smooth the interior.

    Raises :class:`InputError` when the mesh would have more than :data:`MAX_QUADS` quads.

    mult: ``(n_chords,)`` ints >= 1. Boundary: side i gets ``counts[i] = side_matrix[i] @ mult``
    edges, its vertices evenly spaced by arc length on the user's side (:func:`side_points`;
    corners exactly the input points). Interior: bilinear interpolation of the template's
    placement in each template quad, moved by the harmonic (uniform-weight) extension of the
    boundary vertices' displacement, then :func:`jaxmatch.placement.embed.smooth`
    in a normalised frame (``smooth_iters`` L-BFGS iterations per round; default:
    :data:`SMOOTH_ITERS` up to :data:`SMOOTH_ALWAYS` quads; above, :data:`SMOOTH_ITERS_LARGE`
    and only when the interpolated placement folds or has a scaled Jacobian below
    :data:`SJ_FLOOR`; above :data:`SMOOTH_LOCAL` quads, only within :data:`BAD_RINGS` rings of
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
    nv, quads, W, VV, side_vertices = _refined_topology(tq, template, m)
    V0 = int(tq.max()) + 1
    xy = np.empty((nv, 2))
    xy[:V0] = pl.xy[:V0]
    xy[V0:] = np.einsum("ik,ikd->id", W, pl.xy[VV])
    # boundary
    counts = template.side_matrix() @ m
    polys = side_polylines(template.shape)
    bpos = [side_points(p, int(c)) for p, c in zip(polys, counts)]
    bverts = np.concatenate([sv[:-1] for sv in side_vertices])
    bxy = np.concatenate([bp[:-1] for bp in bpos])
    # ccw loop
    loop = _ccw_loop(side_vertices, template)
    # harmonic extension of the boundary displacement
    xy = xy + harmonic_displacement(quads, nv, bverts, bxy - xy[bverts])
    xy[bverts] = bxy
    sj, inv = sj_inverted(xy, quads)
    bad = bad_quads(sj, inv)
    local = smooth_iters is None and quads.shape[0] > SMOOTH_LOCAL
    if smooth_iters is not None:
        iters = int(smooth_iters)
    elif quads.shape[0] <= SMOOTH_ALWAYS:
        iters = SMOOTH_ITERS
    else:
        iters = SMOOTH_ITERS_LARGE if bad.any() else 0
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
        xy=xy, quads=quads, side_vertices=tuple(side_vertices), counts=counts.astype(np.int64), mult=m,
        boundary=loop, scaled_jacobian=sj, inverted=int(inv.sum()), edge_ratio=ratio,
        region_area=template.shape.user_area, mesh_area=float(quad_areas(xy, quads).sum()),
        template=template,
    )


def bad_quads(sj: np.ndarray, inverted: np.ndarray) -> np.ndarray:
    """``(Q,) bool``: the quads a large mesh smooths around: inverted, or a scaled Jacobian
    below :data:`SJ_FLOOR` (``sj``, ``inverted``: :func:`~jaxmatch.quality.sj_inverted`)."""
    return inverted | (sj < SJ_FLOOR)


def smooth_near_bad(xy: np.ndarray, quads: np.ndarray, bad: np.ndarray, fixed: np.ndarray, *, frame: np.ndarray,
                    iters: int = SMOOTH_ITERS_LARGE) -> np.ndarray:
    """A large mesh smoothed only within :data:`BAD_RINGS` rings of its ``bad (Q,) bool`` quads
    (:func:`~jaxmatch.placement.embed.smooth_near`; ``fixed`` vertex ids kept, ``frame`` as
    there): the refinement's and :func:`jaxmatch.placement.layout.fit_sides`'s policy above
    :data:`SMOOTH_LOCAL` quads. Returns ``(V, 2) float64``."""
    return smooth_near(xy, quads, quads[bad].ravel(), fixed, rings=BAD_RINGS, frame=frame, iters=iters)


def harmonic_displacement(quads: np.ndarray, nv: int, bverts: np.ndarray, bdisp: np.ndarray) -> np.ndarray:
    """``(nv, 2) float64``: ``bdisp (b, 2)`` on the vertices ``bverts (b,)``, elsewhere its
    uniform-weight harmonic extension over ``quads (Q, 4)`` (one linear solve; user units).

    Up to :data:`~jaxmatch.placement.embed.DENSE_TUTTE` free vertices it is the Tutte embedding
    of the displacement (:func:`~jaxmatch.placement.embed.tutte`: a dense compiled solve, and no
    ``scipy.sparse`` to import); beyond, one sparse solve: up to :data:`SMOOTH_ALWAYS` quads
    SuperLU's default ordering, then :data:`LARGE_ORDERING`;
    above :data:`SMOOTH_LOCAL` quads the Laplacian and its factorisation are kept for the next
    solve on the same topology (:func:`_harmonic_solve`; also
    :func:`jaxmatch.placement.layout.fit_sides`'s)."""
    is_free = np.ones(nv, bool)
    is_free[np.asarray(bverts, np.int64)] = False
    free = np.flatnonzero(is_free)  # = np.setdiff1d(np.arange(nv), bverts), without its sort
    disp = np.zeros((nv, 2))
    disp[bverts] = bdisp
    if not free.size:
        return disp
    if quads.shape[0] > SMOOTH_LOCAL:
        disp[free] = _harmonic_solve(quads, nv, free, disp)
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


_FACTORS: dict = {}


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


def _harmonic_solve(quads: np.ndarray, nv: int, free: np.ndarray, disp: np.ndarray) -> np.ndarray:
    """``(n, 2) float64`` the harmonic extension on the ``free (n,)`` vertices of a large refined
    mesh ``quads (Q, 4)`` of ``nv`` vertices, ``disp (nv, 2)`` given on the others (0 on ``free``):
    ``Lf^-1 (-(L disp)[free])``, ``L`` the uniform Laplacian (:func:`_laplacian`), ``Lf`` its rows and
    columns ``free``.

    ``L`` and the solver of ``Lf`` (:func:`_large_solver`: an LDL^T or SuperLU's factorisation)
    depend on the topology alone and are kept for the next call on it (:data:`FACTOR_CACHE_SIZE`),
    so both coordinates and every patch of the same refinement share one."""
    import hashlib

    key = hashlib.sha1(np.ascontiguousarray(quads, np.int64).tobytes()
                       + np.ascontiguousarray(free, np.int64).tobytes()).digest()
    kept = _FACTORS.pop(key, None)
    if kept is None:
        while len(_FACTORS) >= FACTOR_CACHE_SIZE and _FACTORS:  # dropped before the next is made (peak memory)
            _FACTORS.pop(next(iter(_FACTORS)))
        L = _laplacian(quads, nv)
        kept = (L, _large_solver(L[free][:, free].tocsc()))
    if FACTOR_CACHE_SIZE > 0:
        _FACTORS[key] = kept
    L, solver = kept
    return solver.solve(np.ascontiguousarray(-(L @ disp)[free], np.float64))


def _ccw_loop(side_vertices, template: PatchTemplate) -> np.ndarray:
    """The refined boundary as one ccw loop, ``(n,) int64``."""
    frame = _side_frame(template.shape)
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
                explain: bool = True) -> RefineChoice:
    """A quad mesh of ``shape`` with the requested number of edges per side, or edges of about
    the requested length: the Python API of ``jaxmatch mesh --sides/--size``.

    sides: one edge count per user side (side i from corner i to corner i+1, corners in the
    order of the file or of its ``corners`` list; a shape without corners takes one total
    count), met exactly. size: target edge length in the shape's units: per-side counts
    closest to ``side length / size``. Exactly one of the two.

    The templates (:func:`patch_templates`: ranked catalogue meshes of every size, ``limit``
    per size, default :data:`DEFAULT_LIMIT`, that keep every corner and place without folds)
    are tried best first; the first whose refinement meets the request
    (:func:`solve_multiplicities`) and places without inverted quads with a min scaled Jacobian
    >= :data:`SJ_FLOOR` (:func:`refine_and_place`) is taken; better-ranked ones passed over are
    listed with the reason. When every refinement that meets the request is below that quality, the best of them is taken and ``note`` says
    so. For ``size``, "meets" means an estimated mean edge length (:func:`estimated_mean_edge`)
    within :data:`SIZE_TOLERANCE` of ``size``; when no template does, the closest is taken and
    ``note`` says so.

    Raises :class:`InfeasibleRequest` when no template can meet ``sides`` (the message names the
    sides and the nearest feasible counts over all templates), :class:`InputError` for malformed
    requests, :class:`jaxmatch.errors.UnmatchableError` when no mesh matches the shape.

    templates: already fitted templates of ``shape`` (e.g. from :func:`patch_templates`, to
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
        walk = _iter_templates(shape, catalogue, lattice, limit=limit, internal=internal, rejected=passed, check=check)
    else:
        walk = _given(templates, passed, check, lazy=not explain)
    for t in walk:
        mult = solve_multiplicities(t, counts=sides, size=size)
        if size is not None:
            est = estimated_mean_edge(t, mult)
            dev = abs(est - float(size)) / float(size)
            if dev > SIZE_TOLERANCE:
                if best_size is None or dev < best_size[0]:
                    best_size = (dev, t, mult)
                passed.append((t.rank, t.mesh_id, f"mean edge about {est:.4g}, {100 * dev:.0f}% from the size"))
                continue
        rm = refine_and_place(t, mult)
        if rm.valid and rm.min_scaled_jacobian >= SJ_FLOOR:
            return RefineChoice(rm, t, _merge(passed, rejected, t.rank))
        why = (f"refined mesh folds ({rm.inverted} inverted quads)" if not rm.valid
               else f"refined mesh has min scaled Jacobian {rm.min_scaled_jacobian:.3f} < {SJ_FLOOR}")
        key = (rm.inverted, -rm.min_scaled_jacobian)
        if fallback is None or key < fallback[0]:
            fallback = (key, t, rm, why)
        passed.append((t.rank, t.mesh_id, why))
    if fallback is not None:
        _, t, rm, why = fallback
        return RefineChoice(rm, t, _merge([p for p in passed if p[0] != t.rank], rejected, t.rank),
                            f"no refinement that meets the request has min scaled Jacobian >= {SJ_FLOOR} without "
                            f"folds; kept the best, {t.mesh_id} ({why})")
    if size is not None and best_size is not None:
        _, t, mult = best_size
        rm = refine_and_place(t, mult)
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


def _given(templates, passed: list, check, *, lazy: bool = False) -> Iterator[PatchTemplate]:
    """The given ``templates`` that pass ``check``, the others appended to ``passed`` with the
    reason. ``lazy`` (a cheap ``check``, whose reasons need not be limited to templates):
    lazily placed templates place only what that needs (:meth:`LazyTemplates.checked`)."""
    walk = templates.checked(check, passed) if lazy and isinstance(templates, LazyTemplates) else None
    if walk is not None:
        yield from walk
        return
    for t in templates:
        why = check(t)
        if why is None:
            yield t
        else:
            passed.append((t.rank, t.mesh_id, why))


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
