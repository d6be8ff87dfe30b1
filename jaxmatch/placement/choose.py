"""Placing ranked meshes in the user's shape: the glue between ranking and geometry.

:func:`rank <jaxmatch.scoring.rank.rank>` works on the combinatorics only; this module puts a
ranked mesh into the shape (:func:`place_match`: corners kept, vertices spread evenly between
them, every equally good orientation and alignment tried so that the result does not depend on
how the loop is listed; :func:`jaxmatch.placement.embed.place` on the unit-box shape, then mapped
to the user's coordinates), re-orders tied utilities by the quality of the embedding
(:func:`rerank_ties`), walks down a ranking for the first good mesh of the shape
(:func:`first_valid`, :func:`acceptable`), chooses the mesh size by fit (:func:`choose_size`,
:data:`SIZE_RULES`). The evenly spread alignments it places come from :mod:`jaxmatch.placement.spread`.

:func:`choose_mesh` is what ``jaxmatch mesh`` does; :func:`place_top` is what
``jaxmatch score --png`` does.

All placements returned here are in the user's coordinates (the shape file's unit of length).
Placements are deterministic (numpy only), so a ``placements`` cache (``mesh_id -> Placement``,
valid for one shape, annotation, catalogue and lattice) can be passed around to avoid placing a
mesh twice.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from itertools import groupby, islice, takewhile
from typing import TYPE_CHECKING, Callable, Iterable, NamedTuple, Sequence

import numpy as np

from jaxmatch.cache import Cache
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.errors import InputError
from jaxmatch.arrays import roll
from jaxmatch.catalogue.mesh import boundary_valences, mesh_valences
from jaxmatch.kernels import placement as kernels
from jaxmatch.placement.embed import Placement, exact_paths, oriented_boundary, place
from jaxmatch.placement.spread import (MAX_TIED_ALIGNMENTS, orientation_utilities, spread_alignment,
                                       spread_optimal_alignment, spread_setup)
from jaxmatch.quality import placement_measures, quad_areas
from jaxmatch.shape import S as S_CODE
from jaxmatch.shape import point_at as shape_point_at
from jaxmatch.scoring.rank import TIE_CAP, Match, Ranking, TieBreaker
from jaxmatch.scoring.rank import rank as rank_meshes

if TYPE_CHECKING:  # pragma: no cover
    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice
    from jaxmatch.shape import Annotation, Shape

__all__ = [
    "DEFAULT_WALK",
    "MeshChoice",
    "SIZE_RULES",
    "SizeChoice",
    "TIE_CAP",
    "acceptable",
    "choose_mesh",
    "choose_size",
    "corner_boundary",
    "fit_json",
    "match_candidates",
    "placement_key",
    "size_key",
    "first_valid",
    "geometry_key",
    "geometry_tie_breaker",
    "place_match",
    "place_top",
    "rerank_ties",
]

DEFAULT_WALK = 50
"""Default number of ranked candidates :func:`first_valid` tries."""

SJ_DIGITS = 6
"""Minimum scaled Jacobians are compared rounded to this many decimals (so that round-off
cannot reorder two meshes of practically equal quality; the mesh id decides then)."""


# ---------------------------------------------------------------------------------------------
# boundary positions


STRAIGHT_TOL = 1e-9
"""A piece of outline is straight when every polyline point lies within this distance (unit
box) of the chord between its ends."""


class Boundary(NamedTuple):
    """Where the boundary vertices of a match go (unit-box coordinates of the shape).

    u: ``(n,) float64`` arc-length parameters along ``shape.points`` (from ``points[0]``; may
    exceed the perimeter by less than one lap); xy: ``(n, 2)`` positions (corners exactly the
    shape's polyline vertices); slide_groups: ``(ja, jb, js)`` runs of vertices between two kept
    corners on one straight side (see :func:`jaxmatch.placement.embed.place`); missed:
    ``(c', 2)`` corners of the shape that no vertex takes.
    """

    u: np.ndarray
    xy: np.ndarray
    slide_groups: tuple
    missed: np.ndarray


def corner_boundary(shape: Shape, annotation: Annotation, alignment: np.ndarray, *, snap: bool = True) -> Boundary:
    """Boundary vertices of an alignment: vertices on corners stay there, the vertices between
    two consecutive kept corners are spread evenly by arc length along the outline between
    them (which straight point of the annotation each took does not change its utility). With
    no corner kept, the vertices are spread evenly around the whole loop, at the phase that
    best fits the aligned points (least squares).

    snap: a corner the alignment skipped, between two kept corners whose run has vertices to
    spare, takes one of them (the assignment of run vertices to skipped corners, in order, that
    is nearest to the even spacing: :func:`_snap`), and the rest are spread evenly between the
    corners; so the mesh keeps that corner too. Its vertex then stands on a corner although its
    alignment took a straight point (``Placement.alignment`` still says so).
    """
    al = np.asarray(alignment, dtype=np.int64).ravel()
    n = al.shape[0]
    codes = np.asarray(annotation.codes)
    per = float(annotation.perimeter)
    tt = np.asarray(annotation.t, dtype=np.float64)
    pts = shape.points
    J = np.flatnonzero(codes[al] != S_CODE)
    u = tt[al]  # (a new float64 array: tt is float64)
    pin = dict(zip(J.tolist(), al[J].tolist()))  # vertex -> corner point it stands on
    if J.size == 0:
        step = per / n
        phase = float(np.mean(tt[al] - step * np.arange(n)))
        u = phase + step * np.arange(n)
    elif snap and len(pin) < int(np.count_nonzero(codes != S_CODE)):  # (every corner taken: none to snap)
        corner_pts = np.flatnonzero(codes != S_CODE)
        taken = set(pin.values())
        for ja, jb, r, ta, tb in _runs(J, lambda j: al[j], tt, n, per):
            skipped = [(c, tt[c] + (per if tt[c] <= ta else 0.0)) for c in corner_pts if c not in taken]
            skipped = sorted((tc, c) for c, tc in skipped if ta < tc < tb)
            if 0 < len(skipped) <= r:
                even = ta + (tb - ta) * (np.arange(1, r + 1) / (r + 1))
                for qi, (tc, c) in zip(_snap(even, np.array([tc for tc, _ in skipped])), skipped):
                    pin[int((ja + 1 + qi) % n)] = int(c)
    groups = []
    cum = shape.arc_length
    if pin:
        P = np.array(sorted(pin))
        ja, jb, r, ta, tb = _run_arrays(P, pin, tt, n, per)
        u[ja] = ta  # the runs' vertices are disjoint: all runs set at once, as one by one
        each = np.repeat(np.arange(P.size), r)
        k = np.arange(each.size) - np.repeat(np.cumsum(r) - r, r) + 1  # 1..r within each run
        u[(ja[each] + k) % n] = ta[each] + (tb[each] - ta[each]) * (k / (r[each] + 1))
        if P.size > 1 and r.any():
            L = cum[-1]
            loop3 = (np.concatenate([cum[:-1], cum[:-1] + L, cum[:-1] + 2 * L]), np.concatenate([pts, pts, pts]))
            for q in np.flatnonzero(r).tolist():
                if _straight(pts, cum, ta[q], tb[q], loop3):
                    groups.append((int(ja[q]), int(jb[q]), (ja[q] + 1 + np.arange(r[q])) % n))
    xy = shape_point_at(pts, u, cum) if len(pin) < n else np.empty((n, 2))  # (every vertex pinned: all set below)
    if pin:
        xy[list(pin)] = np.asarray(annotation.positions)[list(pin.values())]  # corners exactly
    return Boundary(u, xy, tuple(groups), missed_corners(annotation, xy))


def _run_arrays(P: np.ndarray, pin: dict, tt: np.ndarray, n: int, per: float):
    """:func:`_runs` of the pinned vertices ``P`` (sorted) as arrays ``(ja, jb, r, ta, tb)``,
    each ``(len(P),)``: the same values (vertex ``j`` stands on point ``pin[j]``)."""
    pt = np.asarray([pin[j] for j in P.tolist()], np.int64)
    jb = roll(P, -1)
    r = (jb - P - 1) % n if P.size > 1 else np.full(1, n - 1, np.int64)
    ta = tt[pt]
    tb = tt[roll(pt, -1)] if P.size > 1 else ta + per
    return P, jb, r, ta, np.where(tb <= ta, tb + per, tb)


def _runs(J: np.ndarray, point_of, tt: np.ndarray, n: int, per: float):
    """The runs of boundary vertices between consecutive pinned vertices ``J`` (sorted, of ``n``;
    vertex ``j`` stands on point ``point_of(j)``): ``(ja, jb, r, ta, tb)`` per pinned vertex ``ja``,
    with the next pinned vertex ``jb``, the ``r`` vertices strictly between, and the arc-length
    parameters ``ta < tb`` of the two (``tb`` unwrapped past the perimeter ``per``; with one
    pinned vertex the run is the whole loop)."""
    for q, ja in enumerate(J):
        jb = J[(q + 1) % len(J)]
        r = (jb - ja - 1) % n if len(J) > 1 else n - 1
        ta = tt[point_of(ja)]
        tb = tt[point_of(jb)] if len(J) > 1 else ta + per
        if tb <= ta:
            tb += per
        yield ja, jb, r, ta, tb


def _snap(even: np.ndarray, tc: np.ndarray) -> list[int]:
    """Increasing indices ``q_1 < ... < q_p`` into ``even (r,)`` minimising
    ``sum_k (even[q_k] - tc[k])**2`` for increasing ``tc (p,)``, ``p <= r`` (a small DP; ties
    keep the smaller index)."""
    r, p = even.shape[0], tc.shape[0]
    cost = (even[None, :] - tc[:, None]) ** 2  # (p, r)
    D = cost[0].copy()
    back = np.zeros((p, r), np.int64)
    for k in range(1, p):
        new = np.full(r, np.inf)
        run, at = np.inf, 0
        for q in range(r):  # run = min over q' < q of D[q'], at its first argmin
            if run < np.inf:
                new[q] = run + cost[k, q]
                back[k, q] = at
            if D[q] < run:
                run, at = D[q], q
        D = new
    q = int(np.argmin(D))
    out = [q]
    for k in range(p - 1, 0, -1):
        q = int(back[k, q])
        out.append(q)
    return out[::-1]


def missed_corners(annotation: Annotation, bxy: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """``(c', 2)``: the annotation's corners (unit box) farther than ``tol`` from every boundary
    vertex ``bxy (n, 2)``. A vertex spread onto a corner keeps it even if its alignment skipped
    that corner's point (the outline is covered exactly all the same)."""
    corner = np.asarray(annotation.positions)[np.asarray(annotation.codes) != S_CODE]
    if corner.shape[0] == 0:
        return np.zeros((0, 2))
    d = np.linalg.norm(corner[:, None, :] - np.asarray(bxy)[None, :, :], axis=-1).min(axis=1)
    return corner[d > tol].reshape(-1, 2)


def _straight(points: np.ndarray, cum: np.ndarray, t0: float, t1: float, loop3=None) -> bool:
    """The outline between parameters ``t0 < t1`` is one straight segment. ``loop3``: the
    loop's parameters and points three times over, when the caller has them."""
    per = cum[-1]
    if loop3 is None:
        loop3 = (np.concatenate([cum[:-1], cum[:-1] + per, cum[:-1] + 2 * per]), np.concatenate([points, points, points]))
    c2, p2 = loop3
    tol = 1e-12 * per
    inner = p2[(c2 > t0 + tol) & (c2 < t1 - tol)]
    if inner.shape[0] == 0:
        return True
    a, b = shape_point_at(points, np.array([t0, t1]), cum)
    d = b - a
    ln = float(np.hypot(*d))
    if ln == 0:
        return False
    dist = np.abs((inner[:, 0] - a[0]) * d[1] - (inner[:, 1] - a[1]) * d[0]) / ln
    along = (inner - a) @ d / (ln * ln)
    return bool(np.all(dist <= STRAIGHT_TOL) and np.all((along > 0) & (along < 1)))


# ---------------------------------------------------------------------------------------------
# placing one match

MAX_CANDIDATES = 8
"""At most this many equally good orientations/alignments of one mesh are placed to choose
among them (:func:`place_match`)."""

MAX_REORIENTED = 48
"""At most this many orientations/alignments of one mesh are placed by ``place_match(...,
min_utility=...)`` (the quality band's search over orientations of lower utility)."""

SLIDE_BELOW = 0.5
"""A placement whose min scaled Jacobian is below this (or that folds) is tried again with the
vertices of straight sides free to slide along them (:func:`place_match`)."""

COORD_DIGITS = 6
"""Unit-box coordinates are compared rounded to this many decimals in the last tie-break."""


def placement_key(pl: Placement) -> tuple:
    """Order among placements of one mesh (best first): fewer missed corners, fewer inverted
    quads, higher min scaled Jacobian (:data:`SJ_DIGITS` decimals), lower max edge ratio
    (4 decimals), higher mean scaled Jacobian, then the sorted rounded vertex coordinates
    (a geometric, labelling-independent last resort: equal keys mean equal vertex positions)."""
    return _key_head(pl) + (_key_coords(pl),)


def _key_head(pl: Placement) -> tuple:
    """:func:`placement_key` less its last part, the coordinates (:func:`_key_coords`): what
    orders two placements unless it is equal."""
    sj = pl.min_scaled_jacobian
    sj = -math.inf if math.isnan(sj) else round(sj, SJ_DIGITS)
    er = pl.max_edge_ratio
    er = math.inf if math.isnan(er) else round(er, 4)
    return (pl.missed_corners.shape[0], pl.inverted, -sj, er, -round(pl.mean_scaled_jacobian, SJ_DIGITS))


def _key_coords(pl: Placement) -> tuple:
    """The last part of :func:`placement_key`: the sorted rounded vertex coordinates."""
    coords = np.round(pl.xy, COORD_DIGITS) + 0.0  # -0.0 -> 0.0
    order = np.lexsort((coords[:, 1], coords[:, 0]))
    return tuple(coords[order].ravel().tolist())


def _placed_before(a: Placement, b: Placement, keys: dict) -> bool:
    """``placement_key(a) < placement_key(b)``, the coordinates compared only when the rest of
    the keys is equal (a tuple comparison decides at the first unequal part). ``keys``: the
    parts made so far, by ``(id(placement), part)`` (the caller keeps both placements alive)."""
    def part(pl, which, make):
        k = (id(pl), which)
        if k not in keys:
            keys[k] = make(pl)
        return keys[k]

    ha, hb = part(a, 0, _key_head), part(b, 0, _key_head)
    if ha != hb:
        return ha < hb
    return part(a, 1, _key_coords) < part(b, 1, _key_coords)


def match_candidates(annotation: Annotation, vals: np.ndarray, lattice, utility: float | None = None, *,
                     reference: bool = False, min_utility: float | None = None,
                     cache: Cache | None = None) -> list[tuple[int, bool, np.ndarray]]:
    """Every orientation of a mesh with the best utility, each with its most evenly spread
    best alignments (:func:`spread_optimal_alignment`, one per first point), keeping those of
    the smallest gap cost:
    ``[(rotation, reflected, alignment (n,) int64)]``.

    Which orientation the scorer reports among equal utilities depends on where the shape's
    loop starts; this set does not (up to the loop's relabelling).

    min_utility: instead, every orientation whose utility is at least this, each with its own
    most evenly spread best alignments (no gap-cost comparison across orientations). Compiled
    (:func:`jaxmatch.kernels.placement.candidates`); ``reference``: one numpy :func:`spread_optimal_alignment`
    per orientation, which it is tested against. ``cache``: where the shape's
    :func:`~jaxmatch.placement.spread.spread_setup` is kept (the catalogue's)."""
    v = np.asarray(vals, dtype=np.int64).ravel()
    n = v.shape[0]
    ut = orientation_utilities(annotation.codes, v, lattice)
    best = float(np.max(ut)) if ut.size else -math.inf
    if utility is not None and np.isfinite(best) and abs(best - float(utility)) > 1e-6 * max(1.0, abs(best)):
        raise ValueError(f"mesh utility {utility} differs from its best orientation's {best}: wrong lattice?")
    orients = np.flatnonzero(ut == best) if min_utility is None else np.flatnonzero(ut >= float(min_utility))
    if orients.size == 0 or n == 0 or n > len(annotation.codes):
        return []
    seqs = np.stack([roll(v[::-1] if o >= n else v, -int(o % n)) for o in orients]).astype(np.int64)
    if reference or kernels.BACKEND != "c":
        cands = []
        for o, seq in zip(orients, seqs):
            u, als, g = spread_optimal_alignment(annotation.t, annotation.perimeter, annotation.codes, seq, lattice,
                                                 all_ties=True, reference=True, cache=cache)
            cands.extend((g, int(o % n), bool(o >= n), al) for al in als)
    else:  # the same, compiled, all orientations in one call
        st = spread_setup(annotation.t, annotation.perimeter, annotation.codes, lattice, cache)
        _, gap, own, A = kernels.candidates(st.c, seqs, st.table, st.between, st.prefix, st.suffix, st.gq, st.tt,
                                       float(annotation.perimeter), st.unit, MAX_TIED_ALIGNMENTS)
        gl, ol = gap.tolist(), orients.tolist()
        cands = [(int(gl[k]), ol[k] % n, ol[k] >= n, a) for k, a in zip(own.tolist(), A)]
    if not cands:
        return []
    g0 = min(c[0] for c in cands)
    return [(rot, refl, al) for g, rot, refl, al in cands if g == g0 or min_utility is not None]


def place_match(shape: Shape, annotation: Annotation, catalogue: Catalogue, match: Match, *, lattice=None,
                smooth_iters: int = 200, spread: bool = True, placements: dict | None = None,
                min_utility: float | None = None) -> Placement:
    """Place the ranked ``match`` in ``shape``; the result is in the user's coordinates.

    annotation: the annotation the match was computed for (``ranking.annotation``).

    With ``lattice`` (the one the ranking used): every orientation of the mesh with the match's
    utility is a candidate, each with its most evenly spread best alignment; those of the
    smallest spread cost are placed (:func:`match_candidates`) and the best placement by
    :func:`placement_key` is kept. So the same shape listed clockwise, counter-clockwise or
    from another point gives the same vertex positions. Without ``lattice``: the match's own
    orientation, its alignment re-spread at the same point codes (:func:`spread_alignment`).

    Boundary: vertices on corners sit exactly on them; the others are spread evenly by arc
    length between the kept corners around them (:func:`corner_boundary`). A placement that
    folds or has min scaled Jacobian below :data:`SLIDE_BELOW` is tried again with the vertices
    of straight sides sliding along them, and the better one kept (:func:`placement_key`).
    ``spread=False``: the match's orientation and alignment, vertices exactly on their
    annotated points (no spreading, no sliding).

    ``Placement.alignment``, ``rotation``, ``reflected`` hold the orientation and alignment
    used; ``missed_corners`` the corners no vertex takes. Quality is recomputed on the user
    coordinates, so it agrees with what is drawn and written. ``placements``: optional cache
    keyed by mesh id (read and filled; only for one shape, annotation, catalogue, lattice and
    ``spread``/``smooth_iters`` setting).

    min_utility (with ``lattice``): every orientation of utility at least this is a candidate
    (:func:`match_candidates`), up to :data:`MAX_REORIENTED` of them, not only those of the
    match's utility: the quality band's last resort (:func:`choose_mesh`). Such placements
    are cached under ``(mesh id, min_utility)``.
    """
    cache_key = match.mesh_id if min_utility is None else (match.mesh_id, float(min_utility))
    if placements is not None and cache_key in placements:
        return placements[cache_key]
    mesh = catalogue.mesh(match.mesh_id)
    given = np.asarray(match.alignment, dtype=np.int64)
    if spread and lattice is None and _all_pinned(annotation, given):
        user = _place_pinned(shape, annotation, mesh, match, given, smooth_iters)
    elif not spread:
        pl = place(shape.points, annotation.t, given, mesh, match.rotation, match.reflected,
                   positions=annotation.positions, smooth_iters=smooth_iters)
        miss = missed_corners(annotation, annotation.positions[given])
        user = to_user_placement(shape, dataclasses.replace(pl, missed_corners=miss, corners=shape.n_corners))
    else:
        if lattice is not None and min_utility is not None:
            cands = match_candidates(annotation, boundary_valences(mesh), lattice, min_utility=min_utility,
                                     cache=catalogue.cache)
        elif lattice is not None:
            cands = match_candidates(annotation, boundary_valences(mesh), lattice, match.utility, cache=catalogue.cache)
        else:
            cands = []
        if not cands:
            cands = [(match.rotation, match.reflected,
                      spread_alignment(annotation.t, annotation.perimeter, annotation.codes, given))]
        # one candidate per distinct boundary (orientations that differ by a symmetry of the mesh
        # give the same placement), in a geometric order, at most MAX_CANDIDATES (a single one
        # needs no signature: it is the one placed)
        unique = {}
        val = mesh_valences(mesh)
        boundaries: dict[bytes, Boundary] = {}  # corner_boundary depends on the corner points only
        loops: dict[tuple[int, bool], np.ndarray] = {}
        seen = set()
        if len(cands) == 1:
            rot, refl, al = cands[0]
            unique[()] = (rot, refl, al, corner_boundary(shape, annotation, al))
            cands = []
        for (rot, refl, al), key in zip(cands, _pin_keys(annotation, [c[2] for c in cands])):
            if (rot, refl, key) in seen:  # same boundary, same valences: same signature
                continue
            seen.add((rot, refl, key))
            if key not in boundaries:
                boundaries[key] = corner_boundary(shape, annotation, al)
            if (rot, refl) not in loops:
                loops[rot, refl] = val[oriented_boundary(mesh, rot, refl)[1]]
            sig = _boundary_signature(boundaries[key], loops[rot, refl])
            unique.setdefault(sig, (rot, refl, al, boundaries[key]))
        best = None  # (placement, u): the best by placement_key so far
        keys: dict = {}  # the parts of their keys made (_placed_before; every placement compared stays alive)
        placed = []
        for sig in sorted(unique)[:MAX_CANDIDATES if min_utility is None else MAX_REORIENTED]:
            rot, refl, al, b = unique[sig]
            for pl, u in _place_candidate(shape, annotation, mesh, rot, refl, al, smooth_iters, b):
                placed.append(pl)
                if best is None or _placed_before(pl, best[0], keys):
                    best = (pl, u)
        pl, u = best  # boundary paths only for the one kept
        user = to_user_placement(shape, pl, boundary_paths=exact_paths(shape.points, u, pl.xy[pl.mesh.boundary],
                                                                       shape.arc_length))
    if placements is not None:
        placements[cache_key] = user
    return user


def _all_pinned(annotation: Annotation, alignment: np.ndarray) -> bool:
    """Whether the alignment ``(n,)`` matches the mesh's boundary vertices one to one to the
    annotation's corner points (every corner taken): their placement is then the corner points
    themselves (:func:`_place_pinned`)."""
    corner = np.asarray(annotation.codes) != S_CODE
    return int(corner.sum()) == alignment.shape[0] and bool(np.all(corner[alignment]))


def _place_pinned(shape: Shape, annotation: Annotation, mesh, match: Match, al: np.ndarray, smooth_iters: int) -> Placement:
    """:func:`place_match` (``spread``, no ``lattice``) of a mesh whose boundary vertices stand on
    the corners, every corner taken (:func:`_all_pinned`), without its candidate search: the
    spread alignment is the match's own (no other has the same codes: :func:`spread_alignment`),
    the boundary the corner points (:func:`corner_boundary` with every vertex pinned and no run
    between them), and no boundary vertex slides (none lies between two corners); the same
    :class:`Placement`, its figures computed as :func:`place` and :func:`to_user_placement`
    compute them. Without internal vertices nothing is smoothed either: the placement is built
    directly in user coordinates (:func:`_user_fields`, what :func:`to_user_placement` sets)."""
    u = np.mod(np.asarray(annotation.t, dtype=np.float64)[al], float(shape.arc_length[-1]))
    bxy = np.asarray(annotation.positions)[al]
    miss = np.asarray(annotation.positions)[:0]  # (0, 2): every corner point is a vertex's (missed_corners: none)
    if int(mesh.n_vertices) > al.shape[0]:  # internal vertices: placed and smoothed as the search places them
        pl = place(shape.points, annotation.t, al, mesh, match.rotation, match.reflected, boundary_xy=bxy,
                   smooth_iters=smooth_iters, paths=False, region_area=shape.area)
        paths = exact_paths(shape.points, u, pl.xy[pl.mesh.boundary], shape.arc_length)
        return to_user_placement(shape, pl, missed_corners=miss, corners=shape.n_corners, boundary_paths=paths)
    om, loop = oriented_boundary(mesh, match.rotation, match.reflected)
    xy = np.empty((om.n_vertices, 2))
    xy[loop] = bxy  # (what place() puts there: no vertex is free)
    paths = exact_paths(shape.points, u, bxy, shape.arc_length)  # (bxy: xy[om.boundary])
    return Placement(mesh=om, irregular=np.zeros(0, np.int64), alignment=al, rotation=int(match.rotation),
                     reflected=bool(match.reflected), corners=shape.n_corners,
                     **_user_fields(shape, xy, om.quads, miss, paths, float(shape.area),
                                    float(quad_areas(xy, om.quads).sum())))


def _pin_keys(annotation: Annotation, alignments: Sequence[np.ndarray]) -> list[bytes]:
    """What :func:`corner_boundary` depends on, one key per alignment (all ``(n,)``, same
    ``n``): which vertices stand on which corner points (with no corner matched, the whole
    alignment). Alignments that differ only in the straight points they take share a key."""
    if not alignments:
        return []
    A = np.asarray(alignments, dtype=np.int64)  # (c, n)
    m = len(annotation.codes)
    corner = np.asarray(annotation.codes)[A] != S_CODE
    P = np.where(corner, A, -1)
    none = ~corner.any(axis=1)
    P[none] = A[none] + m  # no corner matched: the whole alignment (offset by m: no clash)
    return [row.tobytes() for row in P]


def _boundary_signature(b: Boundary, loop_valences: np.ndarray) -> tuple:
    """Sorted (rounded position, valence) of the boundary vertices of a candidate: equal for
    two orientations that differ by a symmetry of the mesh. b: its boundary; loop_valences:
    ``(n,)`` valences of the oriented boundary loop."""
    xy = np.round(b.xy, COORD_DIGITS) + 0.0
    return tuple(sorted(zip(xy[:, 0].tolist(), xy[:, 1].tolist(), np.asarray(loop_valences).tolist())))


def _place_candidate(shape, annotation, mesh, rot, refl, al, smooth_iters, b: Boundary):
    """Placements (unit box, without boundary paths) of one orientation and alignment, each with
    its boundary vertices' arc-length parameters ``(n,)``: evenly spread, and, when that folds
    or is poor, with sliding straight-side vertices too. ``b``: the alignment's
    :func:`corner_boundary` (the same for every alignment of the same :func:`_pin_keys` key)."""
    per = float(shape.arc_length[-1])

    def put(groups):
        pl = place(shape.points, annotation.t, al, mesh, rot, refl, boundary_xy=b.xy, slide_groups=groups,
                   smooth_iters=smooth_iters, paths=False, region_area=shape.area, missed_corners=b.missed,
                   corners=shape.n_corners)
        return pl, np.mod(b.u, per)

    pl, u = put(())
    yield pl, u
    if b.slide_groups and smooth_iters > 0 and (pl.inverted or pl.min_scaled_jacobian < SLIDE_BELOW):
        yield put(b.slide_groups)


def to_user_placement(shape: Shape, pl: Placement, **unit) -> Placement:
    """A unit-box placement mapped to user coordinates (``shape.to_user``), quality recomputed.
    ``unit``: fields of ``pl`` to set first (unit box; e.g. ``boundary_paths``), in the same copy."""
    def get(name):
        return unit[name] if name in unit else getattr(pl, name)

    fields = _user_fields(shape, get("xy"), pl.mesh.quads, get("missed_corners"), get("boundary_paths"),
                          get("region_area"), get("mesh_area"))
    return dataclasses.replace(pl, **{**unit, **fields})


def _user_fields(shape: Shape, xy: np.ndarray, quads: np.ndarray, missed: np.ndarray, paths: tuple,
                 region_area: float, mesh_area: float) -> dict:
    """The :class:`Placement` fields that :func:`to_user_placement` maps or measures, from the
    unit-box ``xy (V, 2)``, ``missed (c, 2)``, ``paths`` (``(k_j, 2)`` each) and areas: positions
    in user coordinates (the paths mapped as one array, sliced back), quality measured there."""
    user = shape.to_user(xy)
    sj, amin, amax, folded, ratio = placement_measures(user, quads)
    s2 = float(shape.scale) ** 2
    if paths:
        lens = np.cumsum([len(q) for q in paths]).tolist()
        flat = shape.to_user(np.concatenate(paths))
        paths = tuple(flat[i:j] for i, j in zip([0] + lens[:-1], lens))
    return dict(xy=user, edge_ratio=ratio, missed_corners=shape.to_user(missed).reshape(-1, 2),
                scaled_jacobian=sj, min_angle=amin, max_angle=amax, inverted=int(folded.sum()),
                boundary_paths=tuple(paths), region_area=region_area * s2, mesh_area=mesh_area * s2)


# ---------------------------------------------------------------------------------------------
# ties


def geometry_key(placement: Placement, mesh_id: str) -> tuple:
    """Sort key among equal utilities: fewer missed corners, then no inverted quads before
    some, then higher min scaled Jacobian (rounded to :data:`SJ_DIGITS` decimals; NaN counts as
    worst), then fewer irregular internal vertices, then the mesh id."""
    sj = placement.min_scaled_jacobian
    sj = -math.inf if math.isnan(sj) else round(sj, SJ_DIGITS)
    return (placement.missed_corners.shape[0], placement.inverted > 0, -sj, int(len(placement.irregular)), mesh_id)


def rerank_ties(shape: Shape, annotation: Annotation, catalogue: Catalogue, matches: Sequence[Match], *,
                cap: int = TIE_CAP, placements: dict | None = None, smooth_iters: int = 200, lattice=None) -> list[Match]:
    """Re-order meshes of equal utility by the quality of their embedding.

    matches: ranked best first (utilities non-increasing). Within each run of equal utility
    with more than one member, members are placed (:func:`place_match`, with ``lattice``) and
    ordered by :func:`geometry_key` (fewer missed corners, no inverted quads first, then higher
    min scaled Jacobian, then fewer irregular internal vertices, then id). At most ``cap``
    meshes are placed in all, in the given order; tied meshes beyond the cap follow the placed
    ones of their run, in the given order. Utilities never change order. ``placements``:
    cache (mesh id -> placement), read and filled. Returns a new list.
    """
    budget = max(int(cap), 0)
    cache = {} if placements is None else placements
    out: list[Match] = []
    for _, grp in groupby(matches, key=lambda m: float(m.utility)):
        grp = list(grp)
        if len(grp) < 2 or budget <= 0:
            out.extend(grp)
            continue
        head, tail = grp[:budget], grp[budget:]
        budget -= len(head)
        keyed = [(geometry_key(place_match(shape, annotation, catalogue, m, lattice=lattice, smooth_iters=smooth_iters,
                                           placements=cache), m.mesh_id), i)
                 for i, m in enumerate(head)]
        out.extend(head[i] for _, i in sorted(keyed))
        out.extend(tail)
    return out


def geometry_tie_breaker(catalogue: Catalogue, lattice=None, *, smooth_iters: int = 200) -> TieBreaker:
    """The ``tie_break`` of :func:`jaxmatch.scoring.rank.rank` that orders equal utilities by
    :func:`rerank_ties` (placed quality) for meshes of ``catalogue``; pass the ranking's
    ``lattice`` so that placements do not depend on how the shape's loop is listed."""

    def reorder(shape: Shape, annotation: Annotation, matches: Sequence[Match], cap: int, placements: dict) -> list[Match]:
        return rerank_ties(shape, annotation, catalogue, matches, cap=cap, placements=placements,
                           smooth_iters=smooth_iters, lattice=lattice)

    return reorder


# ---------------------------------------------------------------------------------------------
# what counts as a good placement

REORIENT_MESHES = 8
"""The quality band's last resort (other orientations, :func:`choose_mesh`) looks at most at
this many meshes of the band."""

def acceptable(pl: Placement, min_quality: float = QUALITY.min_sj, max_edge_ratio: float = QUALITY.max_edge_ratio) -> bool:
    """``pl`` is a mesh of the shape (every corner kept, no inverted quad, :attr:`Placement.valid`)
    with min scaled Jacobian ``>= min_quality`` and max edge ratio ``<= max_edge_ratio``."""
    return bool(pl.valid and pl.min_scaled_jacobian >= min_quality and pl.max_edge_ratio <= max_edge_ratio)


# ---------------------------------------------------------------------------------------------
# walking down a ranking


def first_valid(shape: Shape, annotation: Annotation, catalogue: Catalogue, matches: Iterable[Match], *,
                limit: int = DEFAULT_WALK, placements: dict | None = None, smooth_iters: int = 200, lattice=None,
                min_quality: float = -1.0, max_edge_ratio: float = math.inf) -> tuple[int, Match, Placement] | None:
    """The first of (at most ``limit`` of) ``matches`` whose placement is :func:`acceptable`
    (by default: valid, i.e. every corner kept and no inverted quad; pass ``min_quality`` /
    ``max_edge_ratio`` for a quality floor).

    matches: candidates in ranking order (any iterable; consumed lazily). Returns
    ``(index into matches, match, placement)`` or None when none of the first ``limit``
    is. ``placements``: cache, read and filled.
    """
    for i, m in enumerate(islice(matches, max(int(limit), 0))):
        pl = place_match(shape, annotation, catalogue, m, lattice=lattice, smooth_iters=smooth_iters, placements=placements)
        if acceptable(pl, min_quality, max_edge_ratio):
            return i, m, pl
    return None


# ---------------------------------------------------------------------------------------------
# choosing the size

AREA_BAND = 0.05
"""Mesh/shape area ratios are compared by ``|1 - ratio|`` in bands of this width when choosing a
size (polygons: exactly 1 once every corner is kept; curved outlines: the chords cut off area,
less with more boundary vertices)."""

SIZE_RULES = ("corners kept", "no inverted quads", "quality floor", "area fit band", "min scaled Jacobian band",
              "fewer quads", "fewer internal vertices")
"""The rules of :func:`choose_size`, in order."""


def size_key(pl: Placement, k: int, min_quality: float = QUALITY.min_sj, max_edge_ratio: float = QUALITY.max_edge_ratio,
             sj_step: float = QUALITY.sj_step) -> tuple:
    """One entry per rule of :data:`SIZE_RULES` (smaller is better): missed corners, inverted
    quads, 0 if the quality floor holds (min SJ and edge ratio) else 1, the area band
    (``floor(|1 - area ratio| / AREA_BAND)``), minus the min scaled Jacobian's band
    (``floor(min SJ / sj_step)``), number of quads, internal vertices."""
    sj = pl.min_scaled_jacobian
    band = -math.inf if math.isnan(sj) else math.floor(round(sj, SJ_DIGITS) / sj_step + 1e-9)
    ar = pl.area_ratio
    area = math.inf if math.isnan(ar) else math.floor(round(abs(1.0 - ar), 9) / AREA_BAND)
    ok = pl.min_scaled_jacobian >= min_quality and pl.max_edge_ratio <= max_edge_ratio
    return (pl.missed_corners.shape[0], pl.inverted, 0 if ok else 1, area, -band, pl.mesh.n_quads, int(k))


@dataclass(frozen=True, eq=False)
class SizeChoice:
    """Result of :func:`choose_size`.

    k: the chosen number of internal vertices; candidates: ``(k, match, placement)`` of the
    best mesh of every size, best first by :func:`size_key`; rule: the entry of
    :data:`SIZE_RULES` that separated the chosen size from the runner-up (``"only size"``
    when there was one candidate); points: the number of annotated points used.
    """

    k: int
    candidates: tuple
    rule: str
    points: int

    def describe(self) -> str:
        """One line: the chosen size, the rule that decided, and the runner-up."""
        k, m, pl = self.candidates[0]
        head = f"size k={k} chosen by rule '{self.rule}'"
        if len(self.candidates) < 2:
            return head
        k2, m2, pl2 = self.candidates[1]
        return (f"{head} ({SIZE_RULES_TEXT}); runner-up k={k2}: {_fit_text(pl2)}; chosen: {_fit_text(pl)}")

    def as_json(self) -> dict:
        return {"k": int(self.k), "rule": self.rule, "rules": list(SIZE_RULES),
                "candidates": [{"k": int(k), "mesh_id": m.mesh_id, "utility": float(m.utility), **fit_json(pl)}
                               for k, m, pl in self.candidates]}


SIZE_RULES_TEXT = "rules in order: " + ", ".join(SIZE_RULES)


def _fit_text(pl: Placement) -> str:
    return (f"{pl.kept_corners}/{pl.corners} corners, {pl.inverted} inverted, min SJ {pl.min_scaled_jacobian:.3f}, "
            f"max edge ratio {pl.max_edge_ratio:.2f}, {pl.mesh.n_quads} quads")


def fit_json(pl: Placement) -> dict:
    """The fit measures of a placement as JSON fields (user coordinates)."""
    return {
        "corners": int(pl.corners), "corners_kept": pl.kept_corners,
        "missed_corners": [[float(x), float(y)] for x, y in pl.missed_corners],
        "inverted": int(pl.inverted), "min_scaled_jacobian": pl.min_scaled_jacobian,
        "mean_scaled_jacobian": pl.mean_scaled_jacobian, "max_edge_ratio": pl.max_edge_ratio,
        "area_ratio": pl.area_ratio, "quads": int(pl.mesh.n_quads), "valid": pl.valid,
    }


def choose_size(shape: Shape, catalogue: Catalogue, lattice: Lattice, *, points: int | None = None,
                tie_break="geometry", tie_cap: int = TIE_CAP, min_quality: float = QUALITY.min_sj,
                max_edge_ratio: float = QUALITY.max_edge_ratio, progress: Callable[[int, int], None] | None = None,
                quality: Quality = QUALITY) -> SizeChoice:
    """Choose the number of internal vertices by the fit of the best mesh of each size.

    Raw utilities grow with the mesh (more matched points), so they cannot compare sizes. The
    best mesh of every size k (rank 1 of ``rank(per_size=True)``) is placed and the sizes are
    ordered by :func:`size_key`, i.e. by the rules of :data:`SIZE_RULES` in turn: every corner
    kept; no inverted quad; the quality floor (min scaled Jacobian ``>= min_quality`` and max
    edge ratio ``<= max_edge_ratio``); mesh area closer to the shape's (bands of
    :data:`AREA_BAND` of ``|1 - area ratio|``: matters for curved outlines); the higher band of
    min scaled Jacobian (bands of ``Quality.sj_step``); fewer quads; fewer internal vertices. ``SizeChoice.rule`` names the rule
    that decided. The annotation has the same number of points for every size (the default
    for the longest boundary), as in a ranking of all sizes.
    """
    tb = geometry_tie_breaker(catalogue, lattice) if tie_break == "geometry" else tie_break
    ranking = rank_meshes(shape, catalogue, lattice, internal=None, top=1, points=points, per_size=True,
                          tie_break=tb, tie_cap=tie_cap, progress=progress)
    cache = ranking.placements if ranking.placements is not None else {}
    cands = []
    for m in ranking.results:
        pl = place_match(shape, ranking.annotation, catalogue, m, lattice=lattice, placements=cache)
        cands.append((size_key(pl, m.internal_vertices, min_quality, max_edge_ratio, quality.sj_step), m.internal_vertices, m, pl))
    cands.sort(key=lambda c: c[0])
    if len(cands) < 2:
        rule = "only size"
    else:
        a, b = cands[0][0], cands[1][0]
        rule = next(SIZE_RULES[i] for i in range(len(a)) if a[i] != b[i])
    return SizeChoice(cands[0][1], tuple((k, m, pl) for _, k, m, pl in cands), rule, len(ranking.annotation.codes))


# ---------------------------------------------------------------------------------------------
# choosing a mesh


@dataclass(frozen=True, eq=False)
class MeshChoice:
    """Result of :func:`choose_mesh`.

    ranking: the ranking used (its ``results`` hold the first ``requested_rank`` matches);
    rank / match / placement: the mesh placed (1-based rank; placement in user coordinates);
    requested_rank: the ``--rank`` asked for (``rank`` differs only with ``require_valid``);
    alternative: when ``placement`` is not :func:`acceptable`, the next-ranked mesh that is, as
    ``(rank, match, placement)``, or None when none of the next ``walk`` is (also None when
    ``placement`` is acceptable); searched: how many ranked meshes after the requested one were
    placed looking for an acceptable one (0 when none was needed); size: the
    :class:`SizeChoice` when the size was chosen (no ``internal`` given), else None;
    min_quality / max_edge_ratio: the quality floor used; passed_over: when the quality band
    (``Quality.band``) replaced the requested mesh, that mesh as ``(rank, match,
    placement)``, else None; band: the band used; reoriented: the placed mesh is in another
    orientation or alignment than its best-utility, most evenly spread ones (its utility may be
    lower than ``match.utility``, within the band; the alignment is in ``placement``) and
    placed_utility its utility (None otherwise; see :attr:`utility`).
    """

    ranking: Ranking
    rank: int
    match: Match
    placement: Placement
    requested_rank: int
    alternative: tuple[int, Match, Placement] | None = None
    searched: int = 0
    size: SizeChoice | None = None
    min_quality: float = QUALITY.min_sj
    max_edge_ratio: float = QUALITY.max_edge_ratio
    passed_over: tuple[int, Match, Placement] | None = None
    band: float = QUALITY.band
    reoriented: bool = False
    placed_utility: float | None = None

    @property
    def utility(self) -> float:
        """Utility of what was placed: the placed orientation's when ``reoriented``, else the
        match's."""
        return float(self.match.utility) if self.placed_utility is None else float(self.placed_utility)

    @property
    def valid(self) -> bool:
        """The placed mesh is a mesh of the shape (corners kept, no inverted quad)."""
        return self.placement.valid

    @property
    def good(self) -> bool:
        """Valid and above the quality floor (:func:`acceptable`)."""
        return acceptable(self.placement, self.min_quality, self.max_edge_ratio)


def choose_mesh(shape: Shape, catalogue: Catalogue, lattice: Lattice, *, rank: int = 1,
                internal: list[int] | None = None, points: int | None = None, tie_break: str = "geometry",
                tie_cap: int = TIE_CAP, require_valid: bool = False, walk: int = DEFAULT_WALK,
                min_quality: float = QUALITY.min_sj, max_edge_ratio: float = QUALITY.max_edge_ratio, band: float = QUALITY.band,
                progress: Callable[[int, int], None] | None = None, quality: Quality = QUALITY) -> MeshChoice:
    """Rank the catalogue for ``shape``, take the ``rank``-th mesh (1-based) and place it.

    Size: with ``internal`` the meshes of those sizes compete by utility; without it the size is
    chosen first by the fit of the best mesh of each size (:func:`choose_size`), and the ranking
    is that size's (so ``rank`` counts within it).

    When the mesh is not :func:`acceptable` (a corner missed, an inverted quad, min scaled
    Jacobian below ``min_quality`` or an edge ratio above ``max_edge_ratio``): with
    ``require_valid`` the ranking is walked down (at most ``walk`` meshes from ``rank`` on, in
    ranking order) and the first acceptable mesh is placed instead (if there is none, the
    ``rank``-th is kept and ``alternative`` is None); otherwise the ``rank``-th is kept and the
    next ``walk`` meshes are searched for ``alternative``. Raises :class:`InputError` when fewer
    than ``rank`` meshes match, :class:`UnmatchableError` when none does.

    Quality band (before any of that): when the ``rank``-th mesh is not :func:`acceptable` at
    ``max(min_quality, quality.good_sj)``, the following meshes whose utility is within ``band``
    (a fraction of its utility's magnitude) below it are placed in ranking order (at most
    ``walk``), and the first that is acceptable at that quality is placed instead
    (``MeshChoice.passed_over`` keeps the requested one). When none is, the first
    :data:`REORIENT_MESHES` of those meshes (the requested one first) are placed again in every
    orientation whose utility is within the band (``place_match(..., min_utility=)``), and the
    first acceptable one is placed (``MeshChoice.reoriented``). Utilities that close are nearly
    as good a fit, and a mesh that cannot be placed well is no use to the user; ``band=0``
    turns this off.
    """
    r = int(rank)
    if r < 1:
        raise InputError(f"rank must be at least 1, got {r}", "--rank")
    size = None
    m_points = points
    if internal is None:
        size = choose_size(shape, catalogue, lattice, points=points, tie_break=tie_break, tie_cap=tie_cap,
                           min_quality=min_quality, max_edge_ratio=max_edge_ratio, progress=progress, quality=quality)
        internal = [size.k]
        m_points = size.points  # keep the annotation the sizes were compared on
    # top=0: score only; count the matchable meshes before aligning (or placing) any of them
    tb = geometry_tie_breaker(catalogue, lattice) if tie_break == "geometry" else tie_break
    ranking = rank_meshes(shape, catalogue, lattice, internal=internal, top=0, points=m_points,
                          tie_break=tb, tie_cap=tie_cap, progress=progress)
    count = ranking.scored - ranking.unmatchable
    if count < r:
        raise InputError(f"only {count} meshes match the shape, cannot take rank {r}", "--rank")
    ranking = ranking._replace(results=list(islice(ranking.following, r)))
    cache = ranking.placements if ranking.placements is not None else {}
    ann = ranking.annotation
    match = ranking.results[r - 1]
    pl = place_match(shape, ann, catalogue, match, lattice=lattice, placements=cache)
    common = dict(size=size, min_quality=min_quality, max_edge_ratio=max_edge_ratio, band=float(band))
    following = ranking.following if ranking.following is not None else iter(())
    tried: list[Match] = []  # the matches after the r-th, as far as they were looked at
    limit = max(int(walk) - 1, 0)

    def after(start: int = 0):
        i = start
        while i < limit:
            if i == len(tried):
                m = next(following, None)
                if m is None:
                    return
                tried.append(m)
            yield tried[i]
            i += 1

    good = max(min_quality, quality.good_sj)
    if band > 0 and not acceptable(pl, good, max_edge_ratio):
        floor_u = float(match.utility) - float(band) * abs(float(match.utility))
        band_matches = takewhile(lambda m: float(m.utility) >= floor_u, after())
        found = first_valid(shape, ann, catalogue, band_matches, limit=limit, placements=cache, lattice=lattice,
                            min_quality=good, max_edge_ratio=max_edge_ratio)
        if found is not None:
            return MeshChoice(ranking, r + 1 + found[0], found[1], found[2], r, None, len(tried), passed_over=(r, match, pl),
                              **common)
        # last resort: the same meshes in other orientations/alignments whose utility is within the band too
        band_list = [match, *takewhile(lambda m: float(m.utility) >= floor_u, after())][:REORIENT_MESHES]
        for i, m in enumerate(band_list):
            alt_pl = place_match(shape, ann, catalogue, m, lattice=lattice, placements=cache, min_utility=floor_u)
            if acceptable(alt_pl, good, max_edge_ratio):
                n = alt_pl.mesh.n_boundary
                o = alt_pl.rotation + (n if alt_pl.reflected else 0)
                u = float(orientation_utilities(ann.codes, boundary_valences(catalogue.mesh(m.mesh_id)), lattice)[o])
                return MeshChoice(ranking, r + i, m, alt_pl, r, None, len(tried), passed_over=(r, match, pl),
                                  reoriented=True, placed_utility=u, **common)
    if acceptable(pl, min_quality, max_edge_ratio):
        return MeshChoice(ranking, r, match, pl, r, None, len(tried), **common)
    found = first_valid(shape, ann, catalogue, after(), limit=limit, placements=cache, lattice=lattice,
                        min_quality=min_quality, max_edge_ratio=max_edge_ratio)
    alt = None if found is None else (r + 1 + found[0], found[1], found[2])
    if require_valid and alt is not None:
        return MeshChoice(ranking, alt[0], alt[1], alt[2], r, None, len(tried), **common)
    return MeshChoice(ranking, r, match, pl, r, alt, len(tried), **common)


def place_top(shape: Shape, ranking: Ranking, catalogue: Catalogue, *, placements: dict | None = None,
              lattice=None) -> list[Placement]:
    """Placements (user coordinates) of every match in ``ranking.results``, in order; reuses
    ``ranking.placements`` (meshes already placed for tie-breaking; pass the ranking's
    ``lattice``, as for the tie-break)."""
    cache = placements if placements is not None else (ranking.placements if ranking.placements is not None else {})
    return [place_match(shape, ranking.annotation, catalogue, m, lattice=lattice, placements=cache) for m in ranking.results]
