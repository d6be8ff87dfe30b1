"""The one template walk: catalogue meshes ranked for a patch (:func:`jaxmatch.scoring.rank.rank`),
fitted to its corners (:func:`fit_template`: the chords and the template edges along each side)
and placed (:func:`jaxmatch.placement.choose.place_match`), as :class:`PatchTemplate` s.

Every user of templates walks them here: the pipeline's per-patch rounds
(:func:`first_group_templates`, the layouts' solve), ``--sides`` and the conforming candidates
(:func:`walk`), the labelling page (:func:`fit_template`). :func:`walk` takes the order (ranked
over all sizes, or fewest internal vertices first) and an optional check as parameters; a walk is
kept in the catalogue's cache (:mod:`jaxmatch.cache`, store ``templates``) and places candidates
only as far as they are asked for (:class:`LazyTemplates`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import TYPE_CHECKING, Callable, Iterator, NamedTuple

import numpy as np

from jaxmatch.cache import key as cache_key
from jaxmatch.catalogue.mesh import edges
from jaxmatch.errors import UnmatchableError
from jaxmatch.placement.choose import place_match
from jaxmatch.placement.embed import Placement, oriented_boundary, oriented_loop
from jaxmatch.scoring.bulk import prepared
from jaxmatch.scoring.rank import rank
from jaxmatch.shape import Shape

if TYPE_CHECKING:  # pragma: no cover
    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice
    from jaxmatch.scoring.rank import LazyMatches, Match

__all__ = ["SCAN_PER_LIMIT", "TEMPLATE_SJ_MIN", "LazyTemplates", "PatchTemplate", "first_group_templates",
           "fit_template", "lazy_patch_templates", "patch_templates", "walk"]

SCAN_PER_LIMIT = (3, 30)
"""Candidates per size scanned for templates, as multiples of ``limit``: a first scan, and a
deeper one when the first finds fewer than ``limit`` templates in all (shapes with many corners,
whose best-ranked meshes skip some)."""

TEMPLATE_SJ_MIN = 0.01
"""Templates whose placement has a quad with a smaller scaled Jacobian are not used: a corner of
about 180 degrees (e.g. a valence-2 boundary vertex on a straight side) stays one in every
refinement and ends up inverted or degenerate."""


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
        ns, nc = len(self.side_chords), self.n_chords
        if ns == 0:
            return np.zeros((0, nc), np.int64)
        sc = self.side_chords  # (one count of all sides' edges, at side i's chord c + i * nc: a third of np.add.at's time)
        flat = np.concatenate(sc).astype(np.int64, copy=False) + np.repeat(np.arange(0, ns * nc, nc), [len(c) for c in sc])
        return np.bincount(flat, minlength=ns * nc).astype(np.int64, copy=False).reshape(ns, nc)

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

    def chord_targets(self, f) -> np.ndarray:
        """``(n_chords,) float64`` what :meth:`chord_widths` ``/ size`` is under a size field ``f``
        (``(n, 2)`` points to ``(n,)`` sizes): the mean over each chord's edges of the integral of
        ``1 / f`` along the placed edge (composite Simpson's rule on 4 pieces)."""
        xy = self.placement.xy
        a, b = xy[self.edge_list[:, 0]], xy[self.edge_list[:, 1]]
        t = np.linspace(0.0, 1.0, 5)
        pts = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
        inv = 1.0 / np.asarray(f(pts.reshape(-1, 2)), np.float64).reshape(-1, 5)
        ln = np.linalg.norm(b - a, axis=1)
        integral = ln * (inv[:, 0] + 4 * inv[:, 1] + 2 * inv[:, 2] + 4 * inv[:, 3] + inv[:, 4]) / 12.0
        tot = np.bincount(self.edge_chord, weights=integral, minlength=self.n_chords)
        cnt = np.bincount(self.edge_chord, minlength=self.n_chords)
        return tot / np.maximum(cnt, 1)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of the undirected graph on ``n`` nodes with the edges ``a[i]-b[i]``
    (``a``, ``b``: (m,) ints): ``(n,) int64``, each node's component named by its smallest node.

    A union-find over the few hundred edges of a template (what :func:`_chords` joins: a quad's
    opposite edges), rather than ``scipy.sparse.csgraph.connected_components``, whose import
    (with ``scipy.sparse.linalg`` it loads) costs the command ~0.1 s (docs/perf.md, "Start-up")."""
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


def _kept_topology(catalogue: "Catalogue", mesh_id: str, reflected: bool) -> _ChordTopology:
    """:func:`_chord_topology` of catalogue mesh ``mesh_id`` as matched (quads mirrored when
    ``reflected``, as :func:`~jaxmatch.placement.embed.oriented_boundary` does; a rotation keeps
    the quads), kept in the catalogue's cache (store ``chords``; read-only arrays: a template scan
    fits a hundred matches of a few dozen meshes)."""

    def make() -> _ChordTopology:
        q = np.asarray(catalogue.mesh(mesh_id).quads)
        topo = _chord_topology(q[:, ::-1] if reflected else q)
        for a in (topo.edges, topo.key, topo.quad_edges, topo.label):
            a.setflags(write=False)
        return topo

    return catalogue.cache.get("chords", (mesh_id, bool(reflected)), make)


def _chords(quads: np.ndarray, boundary: np.ndarray, first_edges: Sequence[tuple[int, int]],
            topology: _ChordTopology | None = None):
    """Chords of a quad mesh of a disk.

    quads: (F, 4) ccw; first_edges: boundary edges ``(u, w)`` in the order chords should be
    numbered by (a chord's number is the position of its first boundary edge in this order;
    closed chords follow, by their smallest edge); topology: :func:`_chord_topology` of
    ``quads`` when the caller has it. Returns ``(edge_list (E, 2), edge_chord (E,), quad_chords
    (F, 2), n_chords)``."""
    t = _chord_topology(quads) if topology is None else topology
    fe = np.asarray(first_edges, np.int64).reshape(-1, 2)
    chord = _chord_numbers(t, _edge_id(t.key, t.V, fe[:, 0], fe[:, 1]))
    return t.edges, chord, np.stack([chord[t.quad_edges[:, 0]], chord[t.quad_edges[:, 1]]], axis=1), int(t.n)


def _chord_numbers(t: _ChordTopology, first_ids: np.ndarray) -> np.ndarray:
    """``(E,) int64`` chord number of each edge of ``t``: the chords of the edges ``first_ids``
    (edge ids, in order) numbered by their first one there, then the other chords by their
    smallest edge (what ranking the first occurrences in ``first_ids`` followed by every edge
    gives). ``t.label`` numbers the chords by their smallest edge already (:func:`_components`
    names each by its smallest edge), so the others keep their order."""
    met = list(dict.fromkeys(t.label[first_ids].tolist()))  # chords in order of first meeting
    rest = np.ones(t.n, bool)
    rest[met] = False
    rename = np.empty(t.n, np.int64)
    rename[met] = np.arange(len(met))
    rename[rest] = np.arange(len(met), t.n)
    return rename[t.label]


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
    where = np.full(max(int(codes.shape[0]), int(al.max(initial=-1)) + 1), -1, np.int64)
    where[al] = np.arange(al.shape[0])  # point -> its position in the loop (the last, were one twice)
    pos = where[first]
    if np.any(pos < 0):
        return None
    return pos


def fit_template(shape: Shape, annotation, match: "Match", catalogue: "Catalogue", rank: int) -> PatchTemplate | None:
    """An unplaced :class:`PatchTemplate` (``placement`` None) from a ranked match, or None when
    a corner of the shape has no mesh vertex. The chords and sides do not depend on the
    placement: :func:`~jaxmatch.placement.choose.place_match` re-spreads the alignment only over
    points of the same type, and a match with every corner matched uses every corner point."""
    loop = oriented_loop(catalogue.mesh(match.mesh_id), match.rotation, match.reflected).tolist()
    nb = len(loop)
    if shape.n_corners == 0:
        spans = [(0, nb, False)]
    else:
        pos = _corner_positions(shape, annotation, match.alignment)
        if pos is None:
            return None
        n = shape.n_corners
        at = pos.tolist()
        spans = []  # side i: loop positions a_i .. stop_i (mod nb), backwards when the user runs it so
        for j, backwards in shape.side_frame:
            a, b = at[j], at[(j + 1) % n]
            spans.append((a, b if b > a else b + nb, bool(backwards)))
    # (a patch's few sides in plain numbers)
    paths = [[loop[i % nb] for i in (range(stop, a - 1, -1) if backwards else range(a, stop + 1))]
             for a, stop, backwards in spans]
    heads = np.array([v for p in paths for v in p[:-1]], np.int64)  # the side edges in order
    tails = np.array([v for p in paths for v in p[1:]], np.int64)
    topo = _kept_topology(catalogue, match.mesh_id, match.reflected)
    ids = _edge_id(topo.key, topo.V, heads, tails)
    chord = _chord_numbers(topo, ids)  # (what _chords gives for these first edges)
    qc = np.stack([chord[topo.quad_edges[:, 0]], chord[topo.quad_edges[:, 1]]], axis=1)
    along = chord[ids]
    edge_ends = np.cumsum([len(p) - 1 for p in paths]).tolist()  # side i's edges end here in `along`
    side_chords = tuple(along[i:j] for i, j in zip([0] + edge_ends[:-1], edge_ends))
    return PatchTemplate(shape, match.mesh_id, side_chords, int(topo.n), match, rank, None, qc, topo.edges, chord,
                         tuple(np.array(p, np.int64) for p in paths))


def _candidates(shape: Shape, catalogue: "Catalogue", lattice: "Lattice", *, limit: int,
                internal=None) -> tuple[object, "LazyMatches"]:
    """(annotation, matches): the best ``limit`` matches of every selected size (k), merged
    best utility first (then fewer internal vertices, then id); each match aligned when first
    asked for (:class:`~jaxmatch.scoring.rank.LazyMatches`, whose ``head`` names it without that)."""
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
    ``fitted``: :func:`fit_template`'s answer for ``m`` when the caller has it."""
    t = fit_template(shape, ann, m, catalogue, r) if fitted is _UNFITTED else fitted
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
        self.lock = threading.RLock()
        self.fits: dict = {}
        self.placed: dict = {}

    def fit(self, shape, ann, m: "Match", catalogue, r: int) -> PatchTemplate | None:
        """:func:`fit_template` of candidate ``m`` (ranked ``r``)."""
        key = (m.mesh_id, m.rotation, m.reflected, r)
        with self.lock:
            if key not in self.fits:
                self.fits[key] = fit_template(shape, ann, m, catalogue, r)
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
    (:class:`LazyTemplates`), kept in the catalogue's cache (store ``templates``, an error of the
    walk kept with it). ``by_size``: fewest internal vertices
    first, then ranked (:func:`_iter_by_size`; ``internal`` required); else in the candidate
    order of :func:`patch_templates` (:func:`_iter_templates`). A shape no mesh matches raises
    :class:`~jaxmatch.errors.UnmatchableError` when the first template is asked for."""
    ks = None if internal is None else tuple(sorted(int(k) for k in internal))

    def make() -> _Walk:
        if by_size:
            return _Walk(lambda: _iter_by_size(shape, catalogue, lattice, limit=limit, internal=ks))
        memo = _Memo()
        made = _Walk(lambda: _iter_templates(shape, catalogue, lattice, limit=limit, internal=ks, memo=memo))
        made.checked = lambda caller, check, passed: _iter_checked(caller, catalogue, lattice, limit=limit,
                                                                   internal=ks, check=check, memo=memo, passed=passed)
        return made

    k = cache_key("walk", by_size, shape, lattice, int(limit), ks, ignore=("source",))
    return LazyTemplates(catalogue.cache.get("templates", k, make), shape)


def walk(shape: Shape, catalogue: "Catalogue", lattice: "Lattice", *, limit: int, internal=None,
         order: str = "ranked", check: Callable[[PatchTemplate], str | None] | None = None,
         passed: list | None = None, templates: Sequence[PatchTemplate] | None = None,
         lazy_check: bool = False) -> Iterator[PatchTemplate] | LazyTemplates:
    """The one way to walk a patch's templates.

    order: ``"ranked"``: every size merged in the candidate order of :func:`patch_templates`
      (at most ``limit`` per size); ``"by_size"``: fewest internal vertices first, each size in
      its ranked order (``internal`` required).
    check: ``check(unplaced template)``, a reason to skip it (None: go on); the skipped are
      appended to ``passed`` as ``(rank, mesh_id, reason)``. Without a check the walk is the
      kept one (:func:`lazy_patch_templates`, a :class:`LazyTemplates`). With one, ``limit``
      counts the templates that pass it (the candidates it refuses are not placed), unless
      ``lazy_check``: then the kept walk's templates that pass it, as few placed as that allows
      (:meth:`LazyTemplates.checked`).
    templates: walk these (already made) instead, skipping those ``check`` refuses.
    """
    if order not in ("ranked", "by_size"):
        raise ValueError(f"order must be 'ranked' or 'by_size', got {order!r}")
    if templates is not None:
        return _given(templates, passed if passed is not None else [], check, lazy=lazy_check)
    if check is None:
        return lazy_patch_templates(shape, catalogue, lattice, limit=limit, internal=internal,
                                    by_size=order == "by_size")
    if order == "by_size":
        raise ValueError("a walk by size takes no check")
    if lazy_check:
        lazy = lazy_patch_templates(shape, catalogue, lattice, limit=limit, internal=internal, by_size=False)
        return _given(lazy, passed if passed is not None else [], check, lazy=True)
    return _iter_templates(shape, catalogue, lattice, limit=limit, internal=internal, rejected=passed, check=check)


def catalogue_oriented_quads(catalogue: "Catalogue", match: "Match") -> np.ndarray:
    """``(F, 4)`` quads of ``match``'s mesh oriented as matched (mirrored when reflected)."""
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



def first_group_templates(shape: Shape, catalogue: "Catalogue", lattice: "Lattice", limit: int,
                          sizes: Sequence[Sequence[int]]):
    """Candidate templates for one patch: those of the first group of ``sizes`` (groups of
    internal-vertex counts) that has one (at most ``limit`` per size), fewest internal vertices
    first, then in their ranked order; a :class:`LazyTemplates` (a template is placed when it is
    first used: most patches use their first one). Empty when no group has one."""
    for group in sizes:
        ks = [k for k in group if k in catalogue.internal]
        if not ks:
            continue
        found = lazy_patch_templates(shape, catalogue, lattice, limit=limit, internal=ks)
        if found:
            return found
    return []
