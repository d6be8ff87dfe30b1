"""A region as a reader finds it, before :func:`~jaxmatch.shape.make_shape` checks it: the
:class:`Outline` every reader returns, and the steps between a file's curves and that outline.

* :func:`chain`: pieces of outline (a CAD file's lines, arcs and curves, each sampled) joined end
  to end into closed loops, within a tolerance relative to the drawing's size;
* :func:`regions`: closed loops nested into outer rings and their holes (shapely), each loop
  checked against crossing itself and the others;
* :func:`nested`: the one region of a few closed loops (SVG subpaths and shapes, DXF polylines);
* :func:`tidy`: repeated consecutive points merged, outlines over the point limit simplified,
  each with one :class:`~jaxmatch.errors.InputWarning` (the step :func:`jaxmatch.io.readers.parse_shape`
  runs on every format's outline);
* :func:`warn_ignored`: one warning counting the entities of a file that became no part of the
  region.

Lengths are the file's units; tolerances are fractions of the drawing's (or the part's) larger
bounding-box extent.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from typing import Any, NamedTuple

import numpy as np
import shapely

from jaxmatch.errors import InputError, InputWarning
from jaxmatch.lazy import Later
from jaxmatch.shape import MAX_COORDINATE, MAX_POINTS, MIN_EXTENT

later = Later(spatial="scipy.spatial",  # scipy (a command's start-up): only to chain a CAD file's pieces
              sparse="scipy.sparse", csgraph="scipy.sparse.csgraph")

__all__ = [
    "CHAIN_TOLERANCE",
    "CURVE_TOLERANCE",
    "MAX_CURVE_TURN",
    "MAX_READ_POINTS",
    "MERGE_TOLERANCE",
    "MAX_SIMPLIFY",
    "MIN_CURVE_SAMPLES",
    "SVG_SAMPLES",
    "Outline",
    "Piece",
    "Ring",
    "SIMPLIFY_START",
    "chain",
    "nested",
    "regions",
    "short",
    "as_text",
    "tidy",
    "warn_ignored",
]

CURVE_TOLERANCE = 1e-4
"""Curves of a CAD file (DXF arcs, circles, ellipses, splines, bulges in a drawing of lines and
arcs; STEP/IGES/BREP edges) are sampled with points on the curve and chords that stray at most
this fraction of the drawing's size from it ..."""

MAX_CURVE_TURN = 5.0
"""... and turn by at most this many degrees from one chord to the next (so that a curve is a
curved stretch, never a row of corners: the corner angle is 30 degrees)."""

CHAIN_TOLERANCE = 1e-6
"""Ends of two pieces of a CAD outline closer than this fraction of the drawing's size meet."""

MERGE_TOLERANCE = 1e-9
"""Consecutive points of a loop closer than this fraction of the part's size (or equal) are one
point (merged with a warning)."""

MAX_READ_POINTS = 1_000_000
"""Most points one loop of a file may have as read; above :data:`~jaxmatch.shape.MAX_POINTS` it
is simplified (:func:`tidy`)."""

SVG_SAMPLES = 200
"""Points per loop perimeter used to sample the curved segments of an SVG shape (and the bulges
of a DXF drawn with closed polylines only)."""

MIN_CURVE_SAMPLES = 4
"""Fewest intervals one curved SVG segment (or polyline bulge) is cut into."""

SIMPLIFY_START = 1e-5
"""A loop over :data:`~jaxmatch.shape.MAX_POINTS` points is simplified (Douglas-Peucker, keeping
the region valid) within this fraction of the part's size, doubled until every loop fits ..."""

MAX_SIMPLIFY = 1.5e-3
"""... up to this fraction (at most a 40th of the default element size, a 32nd of the perimeter:
corners, which stand out of the chords by more, stay); beyond it the limit stands."""


class Outline(NamedTuple):
    """A region as read, before validation: ``points`` the outer loop ``(P, 2)`` (user
    coordinates, possibly closed), ``corners`` explicit corner indices or None, ``holes`` the
    holes' loops, ``hole_corners`` per hole explicit corner indices or None (or None for all),
    ``tags`` and ``periodic`` as the file gives them (or None; :func:`jaxmatch.shape.check_groups`)."""

    points: Any
    corners: Any = None
    holes: tuple = ()
    hole_corners: Any = None
    tags: Any = None
    periodic: Any = None


class Piece(NamedTuple):
    """One entity of a CAD outline, sampled: ``points (k, 2)`` along it (its ends first and
    last; a closed piece, a circle, ends where it starts), ``name`` how errors call it
    (``"ARC 2F (layer 0)"``), ``handle`` and ``layer`` what ``FILE#ELEMENT`` may name."""

    points: np.ndarray
    name: str
    handle: str = ""
    layer: str = ""


class Ring(NamedTuple):
    """A closed loop made of pieces: ``points (P, 2)`` (first point not repeated), ``pieces``
    the indices of its pieces in order, ``owner (P,) int`` the piece of the segment from each point."""

    points: np.ndarray
    pieces: tuple
    owner: np.ndarray


def short(value, limit: int = 40) -> str:
    """``repr(value)``, cut to ``limit`` characters with ``...``."""
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def as_text(data, source: str) -> str:
    """A file's bytes as text (UTF-8, a byte-order mark dropped); :class:`InputError` otherwise."""
    if isinstance(data, str):
        return data
    try:
        return bytes(data).decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise InputError(f"not UTF-8 text (byte {err.start})", where=source) from None


def _where(p) -> str:
    return f"({float(p[0]):.6g}, {float(p[1]):.6g})"


# ---------------------------------------------------------------------------------------------
# chaining and nesting


def chain(pieces: list[Piece], tol: float, source: str) -> list[Ring]:
    """The closed loops ``pieces`` make, joined end to end where ends lie within ``tol``
    (length); a joint is the mean of the ends that meet there, so loops close exactly.

    Raises :class:`InputError` naming the entity (its handle and layer) at an end no other end
    meets (an open outline) and the entities at a point where more than two ends meet (a branch).
    """
    rings, open_ = [], []
    for i, pc in enumerate(pieces):
        p = pc.points
        if p.shape[0] >= 3 and np.linalg.norm(p[-1] - p[0]) <= tol:
            body = p[:-1]
            rings.append(Ring(body, (i,), np.full(body.shape[0], i)))
        else:
            open_.append(i)
    if not open_:
        return rings
    ends = np.array([pieces[i].points[k] for i in open_ for k in (0, -1)], np.float64)
    pairs = later.spatial.cKDTree(ends).query_pairs(tol, output_type="ndarray")
    m = ends.shape[0]
    graph = later.sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    _, node = later.csgraph.connected_components(graph, directed=False)
    degree = np.bincount(node)
    joint = np.zeros((degree.size, 2))
    np.add.at(joint, node, ends)
    joint /= degree[:, None]
    for k in np.flatnonzero(degree[node] == 1)[:1]:
        others = np.delete(ends, k, axis=0)
        gap = float(np.min(np.linalg.norm(others - ends[k], axis=1))) if others.size else math.inf
        raise InputError(f"{pieces[open_[k // 2]].name} ends at {_where(ends[k])} where no other entity meets it "
                         f"(an open outline; the nearest other end is {gap:.3g} away)", where=source)
    for n in np.flatnonzero(degree > 2)[:1]:
        names = ", ".join(pieces[open_[k // 2]].name for k in np.flatnonzero(node == n)[:4])
        raise InputError(f"{names} meet at {_where(joint[n])}: the outline branches there", where=source)
    at = {}  # node -> the two end slots there
    for k in range(m):
        at.setdefault(int(node[k]), []).append(k)
    seen = np.zeros(len(open_), bool)
    for start in range(len(open_)):
        if seen[start]:
            continue
        pts, order, owner = [], [], []
        slot = 2 * start  # enter piece `start` at its first end
        while not seen[slot // 2]:
            j = slot // 2
            seen[j] = True
            p = pieces[open_[j]].points
            p = p if slot % 2 == 0 else p[::-1]
            body = np.vstack([joint[node[slot]], p[1:-1]])
            pts.append(body)
            order.append(open_[j])
            owner.append(np.full(body.shape[0], open_[j]))
            out = slot ^ 1  # leave by its other end, enter the piece that meets it there
            slot = next(k for k in at[int(node[out])] if k != out)
        ring = np.vstack(pts)
        if ring.shape[0] < 3:
            raise InputError(f"{', '.join(pieces[i].name for i in order)} close a loop of less than 3 points "
                             "(zero area)", where=source)
        rings.append(Ring(ring, tuple(order), np.concatenate(owner)))
    return rings


def _crossing(ring: Ring, pieces: list[Piece], source: str) -> None:
    line = shapely.LinearRing(ring.points)
    if shapely.is_simple(line):
        return
    segs = shapely.linestrings(np.stack([ring.points, np.roll(ring.points, -1, axis=0)], axis=1))
    tree = shapely.STRtree(segs)
    n = len(segs)
    a, b = tree.query(segs, predicate="intersects")
    bad = [(i, j) for i, j in zip(a.tolist(), b.tolist()) if i < j and (j - i) % n not in (1, n - 1)]
    if not bad:  # adjacent segments folding back over each other
        bad = [(i, j) for i, j in zip(a.tolist(), b.tolist())
               if i < j and shapely.intersection(segs[i], segs[j]).length > 0] or [(0, 0)]
    i, j = bad[0]
    first, second = pieces[ring.owner[i]].name, pieces[ring.owner[j]].name
    what = f"{first} crosses itself" if first == second else f"{first} and {second} cross"
    raise InputError(f"{what} at {_where(np.asarray(shapely.intersection(segs[i], segs[j]).representative_point().coords[0]))}",
                     where=source)


def regions(rings: list[Ring], pieces: list[Piece], source: str) -> list[tuple[Ring, list[Ring]]]:
    """Closed loops as regions: ``[(outer ring, [hole rings]), ...]``, largest first. A loop
    inside one other loop is a hole of it; inside two (an island in a hole), a region of its own.

    Raises :class:`InputError` naming the entities where a loop crosses itself or another loop
    (or touches it)."""
    for r in rings:
        _crossing(r, pieces, source)
    polys = [shapely.Polygon(r.points) for r in rings]
    tree = shapely.STRtree([shapely.LinearRing(r.points) for r in rings])
    a, b = tree.query([shapely.LinearRing(r.points) for r in rings], predicate="intersects")
    for i, j in zip(a.tolist(), b.tolist()):
        if i < j:
            touch = shapely.intersection(shapely.LinearRing(rings[i].points), shapely.LinearRing(rings[j].points))
            pt = np.asarray(touch.representative_point().coords[0])
            name = [pieces[r.owner[int(np.argmin(shapely.distance(
                shapely.linestrings(np.stack([r.points, np.roll(r.points, -1, axis=0)], axis=1)), shapely.Point(pt))))]].name
                for r in (rings[i], rings[j])]
            raise InputError(f"{name[0]} and {name[1]} cross or touch at {_where(pt)} (two loops meet)", where=source)
    order = sorted(range(len(rings)), key=lambda i: -polys[i].area)
    inside = {i: [j for j in order if j != i and polys[j].contains(polys[i])] for i in order}
    out = []
    for i in order:
        if len(inside[i]) % 2 == 0:  # an outer ring (at depth 0, or an island at depth 2, ...)
            holes = [rings[j] for j in order if len(inside[j]) == len(inside[i]) + 1 and i in inside[j]]
            out.append((rings[i], holes))
    return out


def nested(loops: list[np.ndarray], rule: str, source: str, strict: bool = False) -> Outline:
    """One region from closed loops: the loop of largest area is the outer one, the loops inside
    it are holes (``rule`` ``"nonzero"``: only those that run the other way round, as the SVG
    fill rule says; one that runs the same way is filled and adds nothing). Raises
    :class:`InputError` for a loop outside the outer one or inside a hole (an island); with
    ``strict`` (separate drawing elements) also for a loop that is not wholly inside the outer
    one, clear of its boundary."""
    if len(loops) == 1:
        return Outline(loops[0])

    def signed(p):
        return 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))

    areas = [signed(p) for p in loops]
    order = sorted(range(len(loops)), key=lambda i: -abs(areas[i]))
    outer = loops[order[0]]
    outer_poly = shapely.Polygon(outer)
    if not outer_poly.is_valid:
        raise InputError("the outer loop crosses itself", where=source)
    holes = []
    for i in order[1:]:
        poly = shapely.Polygon(loops[i])
        if strict and not (outer_poly.contains(poly) and outer_poly.exterior.distance(poly) > 0):
            raise InputError(f"loop {i + 1} is not inside the largest loop", where=source)
        if not outer_poly.contains(poly.representative_point()):
            raise InputError(f"{len(loops)} loops that are not one region (loop {i + 1} lies outside the largest)",
                             where=source)
        if rule == "nonzero" and np.sign(areas[i]) == np.sign(areas[order[0]]):
            continue  # filled by the nonzero rule: part of the region
        if any(shapely.Polygon(h).contains(poly.representative_point()) for h in holes):
            raise InputError(f"loop {i + 1} lies inside a hole (an island): mesh it as a region of its own", where=source)
        holes.append(loops[i])
    return Outline(outer, None, tuple(holes))


# ---------------------------------------------------------------------------------------------
# after reading: repeated points, dense outlines, what was left out


def warn_ignored(kinds, source: str) -> None:
    """One :class:`InputWarning` counting ``kinds`` (an entity type per entity that became no
    part of the region): ``3 entities ignored: TEXT x2, DIMENSION x1``; nothing when empty."""
    count = Counter(kinds)
    if count:
        total = sum(count.values())
        listing = ", ".join(f"{k} x{n}" for k, n in sorted(count.items(), key=lambda kv: (-kv[1], kv[0])))
        warnings.warn(InputWarning(f"{total} entit{'y' if total == 1 else 'ies'} ignored: {listing}", where=source),
                      stacklevel=3)


def _as_loop(points, what: str, source: str) -> np.ndarray | None:
    """``points`` as a finite ``(P, 2)`` array, or None where :func:`make_shape` gives the error."""
    try:
        p = np.asarray(points, np.float64)
    except (TypeError, ValueError, OverflowError):
        return None
    if p.ndim != 2 or p.shape[1] != 2 or p.shape[0] < 3 or not np.isfinite(p).all():
        return None
    if p.shape[0] > MAX_READ_POINTS + 1:
        raise InputError(f"{what} has {p.shape[0]} points, more than the {MAX_READ_POINTS} read", where=source)
    return p


def _merge(p: np.ndarray, corners, tol: float) -> tuple[np.ndarray, Any, int]:
    """``p (P, 2)`` without the points within ``tol`` of the point kept before them (cyclically; a
    last point repeating the first, as a closed ring has, is dropped without counting), corner
    indices mapped onto the kept points; and how many were merged. Unchanged when none is."""
    def dist(a, b):
        return np.hypot(a[..., 0] - b[..., 0], a[..., 1] - b[..., 1])  # (no square to underflow or overflow)

    closed = dist(p[-1], p[0]) <= tol
    body = p[:-1] if closed else p
    if not np.any(dist(np.roll(body, -1, axis=0), body) <= tol):
        return p, corners, 0
    keep = [0]
    owner = np.zeros(len(p), np.int64)
    for i in range(1, body.shape[0]):
        if dist(body[i], body[keep[-1]]) > tol:
            keep.append(i)
        owner[i] = len(keep) - 1
    if len(keep) > 1 and dist(body[keep[-1]], body[0]) <= tol:
        owner[owner == len(keep) - 1] = 0
        keep.pop()
    merged = body.shape[0] - len(keep)
    if corners is not None and isinstance(corners, list) and all(isinstance(c, int) and 0 <= c < len(p) for c in corners):
        mapped = []
        for c in corners:
            k = int(owner[c]) if c < body.shape[0] else 0
            if k not in mapped:
                mapped.append(k)
        corners = mapped
    return body[keep], corners, merged


def tidy(outline: Outline, source: str) -> Outline:
    """``outline`` ready for :func:`~jaxmatch.shape.make_shape`: repeated consecutive points
    (within :data:`MERGE_TOLERANCE` of the part's size) merged, then loops over
    :data:`~jaxmatch.shape.MAX_POINTS` points simplified (Douglas-Peucker through shapely's
    topology-preserving simplifier, so the region stays valid; within :data:`SIMPLIFY_START` of
    the part's size, doubled up to :data:`MAX_SIMPLIFY` until every loop fits), each with one
    :class:`InputWarning`. An outline with neither is returned as it is; one that is not a list
    of finite pairs is left to :func:`make_shape`'s errors."""
    outer = _as_loop(outline.points, "boundary", source)
    holes = [_as_loop(h, f"hole {k + 1}", source) for k, h in enumerate(outline.holes)]
    if outer is None or any(h is None for h in holes):
        return outline
    size = float(np.max(outer.max(axis=0) - outer.min(axis=0)))
    if not (math.isfinite(size) and MIN_EXTENT <= size and np.abs(outer).max() <= MAX_COORDINATE):
        return outline  # make_shape says what is wrong
    tol = MERGE_TOLERANCE * size
    outer, corners, merged = _merge(outer, outline.corners, tol)
    hole_corners = list(outline.hole_corners) if outline.hole_corners is not None else [None] * len(holes)
    for k, h in enumerate(holes):
        if len(hole_corners) == len(holes):
            holes[k], hole_corners[k], n = _merge(h, hole_corners[k], tol)
        else:
            holes[k], _, n = _merge(h, None, tol)
        merged += n
    if merged:
        warnings.warn(InputWarning(f"merged {merged} repeated point{'s' if merged > 1 else ''} (equal to the one "
                                   f"before or closer than {MERGE_TOLERANCE:g} of the part's size)", where=source),
                      stacklevel=3)
    hole_corners = tuple(hole_corners) if outline.hole_corners is not None else None
    loops = [outer, *holes]
    def count(p):  # points, a closing repeat of the first not counted
        return len(p) - int(bool(np.hypot(*(p[-1] - p[0])) <= tol))

    if max(count(p) for p in loops) > MAX_POINTS and corners is None and not any(c is not None for c in hole_corners or ()):
        outer, holes = _simplify(loops, size, source)
    return Outline(outer, corners, tuple(holes), hole_corners, outline.tags, outline.periodic)


def _simplify(loops: list[np.ndarray], size: float, source: str) -> tuple[np.ndarray, list[np.ndarray]]:
    """The loops (outer first) simplified until each has at most ``MAX_POINTS`` points (see
    :func:`tidy`); loops that cannot be, or a region that is not valid, are left to
    :func:`make_shape`'s errors."""
    poly = shapely.Polygon(loops[0], loops[1:])
    if not poly.is_valid:
        return loops[0], loops[1:]
    before = sum(len(p) for p in loops)
    frac, most = SIMPLIFY_START, max(len(p) for p in loops)
    tried = frac
    while frac <= MAX_SIMPLIFY * (1 + 1e-9):
        tol, tried = frac * size, frac
        simple = poly.simplify(tol, preserve_topology=True)
        if isinstance(simple, shapely.Polygon) and simple.is_valid and not simple.is_empty:
            rings = [np.asarray(simple.exterior.coords)[:-1]] + [np.asarray(r.coords)[:-1] for r in simple.interiors]
            most = max(len(r) for r in rings)
            if len(rings) == len(loops) and most <= MAX_POINTS:
                after = sum(len(r) for r in rings)
                warnings.warn(InputWarning(f"outline of {before} points simplified: {after} kept (each point left out "
                                           f"within {tol:.3g} of it, {frac:.3g} of the part's size)", where=source),
                              stacklevel=4)
                return rings[0], rings[1:]
        frac *= 2
    raise InputError(f"a loop has {max(len(p) for p in loops)} points, more than the maximum {MAX_POINTS}, and still {most} "
                     f"simplified within {tried:.3g} of the part's size", where=source)
