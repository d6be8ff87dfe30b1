"""Size fields: a target element size that varies over the region (graded meshes).

A :class:`Field` is data only: a largest size ``H`` and entries :class:`Near` (finer near a hole,
a point, a side of the outline or a curve). Bound to a region (:meth:`Field.bind`, or
:func:`bind` for anything the meshing accepts as a size) it is a :class:`SizeField`, a callable
``(n, 2) float64 points -> (n,) float64 sizes`` (user units)::

    size(x) = min(H, min over entries of s + (H - s) * min(1, dist(x, entity) / d))

the same as gmsh's ``Distance`` + ``Threshold`` fields with ``SizeMin s``, ``SizeMax H``,
``DistMin 0``, ``DistMax d`` (one ``Threshold`` per entry, their ``Min``).

Entities (the JSON form ``{"size": H, "near": [{KIND: ENTITY, "size": s, "distance": d}, ...]}``):

========== ============================= ==================================================
kind       entity                        the set distances are measured to
========== ============================= ==================================================
``hole``   ``k`` (1 = first in the file)  the hole's ring (closed polyline)
``point``  ``[x, y]``                     the point
``side``   ``"i-j"``                      the outline's side between consecutive corners
                                         ``i`` and ``j`` (points of the outline as numbered
                                         in the file, 0 first; as the mesh file's
                                         ``side i-j`` groups), either direction
``curve``  ``[[x, y], ...]``              the polyline (at least two points)
========== ============================= ==================================================

A user's callable ``size(points (n, 2)) -> (n,)`` is bound as :class:`CallableSize`, which checks
every answer (shape, finite, positive). :func:`line_integral` (``integral of 1 / size ds`` along a
polyline: the number of edges a side wants) and :func:`graded_points` (a side's vertices at equal
steps of that integral) are what the meshing reads.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Sequence

import numpy as np
import shapely

from jaxmatch.errors import InputError

__all__ = ["KINDS", "CallableSize", "Field", "Near", "SizeField", "bind", "edge_ratios",
           "field_share", "graded_points", "kept_on_field", "line_integral", "load_field", "outline_size", "parse_field",
           "segment_distance", "segment_distances", "smallest_size"]

KINDS = ("hole", "point", "side", "curve")
"""The kinds of entity a :class:`Near` entry refines towards."""

SHARE_BAND = (0.5, 1.6)
"""An edge follows the field when its length / the field at its midpoint lies in this band
(``field_share``; the issue's criterion)."""


def _positive(value, what: str, where: str | None) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not (v > 0 and math.isfinite(v)):
        raise InputError(f"{what} must be a positive number, got {value!r:.40}", where)
    return v


def _xy(value, what: str, where: str | None) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a point [x, y], got {value!r:.60}", where) from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise InputError(f"{what} must be finite, got {value!r:.60}", where)
    return x, y


@dataclass(frozen=True)
class Near:
    """One refinement: size ``size`` at ``entity`` growing linearly to the field's largest size at
    ``distance`` from it (user units). kind: one of :data:`KINDS`; entity: a hole number (int,
    1 first), a point ``(x, y)``, a side ``"i-j"`` or a curve ``((x, y), ...)``."""

    kind: str
    entity: object
    size: float
    distance: float

    def __post_init__(self):
        if self.kind not in KINDS:
            raise InputError(f"size field: unknown entity kind {self.kind!r} (expected one of {', '.join(KINDS)})")
        object.__setattr__(self, "size", _positive(self.size, f"size field: {self.kind} entry's size", None))
        object.__setattr__(self, "distance", _positive(self.distance, f"size field: {self.kind} entry's distance", None))
        e = self.entity
        if self.kind == "hole":
            if isinstance(e, bool) or not isinstance(e, (int, np.integer)) or e < 1:
                raise InputError(f"size field: hole must be a hole number >= 1 (1 = first in the file), got {e!r:.40}")
            object.__setattr__(self, "entity", int(e))
        elif self.kind == "point":
            object.__setattr__(self, "entity", _xy(e, "size field: point", None))
        elif self.kind == "side":
            parts = str(e).split("-") if isinstance(e, str) else []
            if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
                raise InputError(f"size field: side must be \"i-j\" (the outline's points i and j), got {e!r:.40}")
            object.__setattr__(self, "entity", f"{int(parts[0])}-{int(parts[1])}")
        else:
            try:
                pts = tuple(_xy(p, "size field: curve point", None) for p in e)
            except TypeError:
                raise InputError(f"size field: curve must be a list of points [[x, y], ...], got {e!r:.60}") from None
            if len(pts) < 2:
                raise InputError("size field: a curve needs at least two points")
            object.__setattr__(self, "entity", pts)


@dataclass(frozen=True)
class Field:
    """A size field as given (data only): the largest size ``size`` (``H``, user units) and the
    refinements ``near``; source: the file it was read from (named in errors). Raises :class:`InputError` for a size that is not positive or an entry
    whose size exceeds ``H``."""

    size: float
    near: tuple[Near, ...] = ()
    source: str | None = field(default=None, compare=False)

    def __post_init__(self):
        object.__setattr__(self, "size", _positive(self.size, "size field: size", None))
        near = tuple(self.near)
        for e in near:
            if not isinstance(e, Near):
                raise InputError(f"size field: near entries must be Near, got {type(e).__name__}")
            if e.size > self.size:
                raise InputError(f"size field: a {e.kind} entry's size {e.size:g} is larger than the field's size "
                                 f"{self.size:g}")
        object.__setattr__(self, "near", near)

    def bind(self, shape) -> "SizeField":
        """This field on ``shape`` (a :class:`~jaxmatch.shape.Shape`): holes and sides resolved to
        polylines. Raises :class:`InputError` for a hole or side the shape does not have."""
        H = float(self.size)
        entries = []
        for e in self.near:
            entries.append((float(e.size), float(e.distance), _segments(e, shape, self.source or "size field")))
        return SizeField(H, tuple(entries), smallest=min([H] + [s for s, _, _ in entries]))


def _outline_sides(shape) -> dict[tuple[int, int], np.ndarray]:
    """``{(i, j): (k, 2) polyline}`` of the outline's sides between consecutive corners, ``i``
    and ``j`` numbered as the points of the file (both directions keyed)."""
    pts = np.asarray(shape.given_points, np.float64)
    P = pts.shape[0]
    corners = [int(c) for c in _input_corners(shape)]
    out = {}
    if len(corners) < 2:
        return out
    for a, b in zip(corners, corners[1:] + corners[:1]):
        idx = np.arange(a, (b if b > a else b + P) + 1) % P
        out[(a, b)] = pts[idx]
        out[(b, a)] = pts[idx][::-1].copy()
    return out


def _input_corners(shape) -> list[int]:
    """The shape's corners as indices of the points in the file's order (by coordinates),
    ascending."""
    if shape.n_corners == 0:
        return []
    pts = np.asarray(shape.given_points, np.float64)
    user = shape.to_user(shape.points[np.asarray(shape.corners, np.int64)])
    return sorted(int(np.argmin(np.linalg.norm(pts - u, axis=1))) for u in user)


def _segments(e: Near, shape, where: str) -> np.ndarray:
    """``(m, 2, 2)`` the segments of entry ``e``'s entity on ``shape`` (a point: one segment of
    length 0)."""
    if e.kind == "point":
        p = np.asarray(e.entity, np.float64)
        return np.stack([p, p])[None]
    if e.kind == "curve":
        poly = np.asarray(e.entity, np.float64)
    elif e.kind == "hole":
        holes = tuple(getattr(shape, "holes", ()))
        if not 1 <= e.entity <= len(holes):
            raise InputError(f"hole {e.entity} does not exist in {getattr(shape, 'source', 'the region')} (it has "
                             f"{len(holes)} hole{'s' if len(holes) != 1 else ''})", where)
        ring = np.asarray(holes[e.entity - 1], np.float64)
        poly = np.concatenate([ring, ring[:1]])
    else:
        sides = _outline_sides(shape)
        i, j = (int(v) for v in e.entity.split("-"))
        if (i, j) not in sides:
            names = list(dict.fromkeys(f"{a}-{b}" for a, b in list(sides)[::2]))  # (a, b) as the outline runs
            raise InputError(f"side {e.entity} is not a side of {getattr(shape, 'source', 'the region')}'s outline "
                             f"(its sides: {', '.join(names) or 'none: it has no corners'})", where)
        poly = sides[(i, j)]
    return np.stack([poly[:-1], poly[1:]], axis=1)


@dataclass(frozen=True, eq=False)
class SizeField:  # (eq=False: hashed by identity, so a Quality holding one is a cache key)
    """A :class:`Field` bound to a region: ``field(points (n, 2)) -> (n,) float64`` sizes (user
    units). entries: per refinement ``(s, d, segments (m, 2, 2))``; smallest: the least size it
    can take (``min(H, every s)``)."""

    size: float
    entries: tuple = ()
    smallest: float = math.nan

    def __call__(self, points) -> np.ndarray:
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        H = self.size
        if not self.entries or not pts.shape[0]:
            return np.full(pts.shape[0], H)
        segments, starts, s, d = self._segments
        if segments.shape[0] == starts.shape[0] and not np.any(segments[:, 0] - segments[:, 1]):  # points only
            a = segments[:, 0]
            dist = np.sqrt((pts[:, 0:1] - a[:, 0]) ** 2 + (pts[:, 1:2] - a[:, 1]) ** 2)
        elif len(self.entries) > FEW_ENTRIES:
            dist = np.concatenate([self._pair_distances(pts[i:i + PAIR_BLOCK // len(self.entries) + 1])
                                   for i in range(0, pts.shape[0], PAIR_BLOCK // len(self.entries) + 1)])
        elif pts.shape[0] >= NUMPY_POINTS and self._few_segments:
            dist = np.minimum.reduceat(segment_distances(pts, segments), starts, axis=1)  # every entry at once, numpy
        else:
            dist = self._distances(pts)
        return np.minimum(H, (s + (H - s) * np.minimum(1.0, dist / d)).min(axis=1))

    def _distances(self, pts: np.ndarray) -> np.ndarray:
        """``(n, E) float64`` (a field of at most :data:`FEW_ENTRIES` entries): each of
        ``pts (n, 2)``'s distance to each entry: numpy's (GEOS's
        arithmetic, :func:`segment_distances`) for at least :data:`NUMPY_POINTS` points on at most
        :data:`NUMPY_SEGMENTS` segments, else shapely's (GEOS, per point in C; both give the same
        numbers), there ``inf`` for the points beyond the entry's reach when there are
        :data:`PRUNE_POINTS` or more (:attr:`_reach`: its distance ``d`` and more from the entry's
        bounding box, where ``dist / d >= 1`` and the size is the entry's largest whatever the
        exact distance)."""
        n = pts.shape[0]
        dist = np.full((n, len(self.entries)), np.inf)
        where = None  # the points as shapely's, made once
        for e, (lo, hi, reach2, seg, geom) in enumerate(self._reach):
            if n >= NUMPY_POINTS and seg.shape[0] <= NUMPY_SEGMENTS:  # a few pairs a point: all of them
                dist[:, e] = segment_distances(pts, seg).min(axis=1)
                continue
            if where is None:
                where = shapely.points(pts)
            if n >= PRUNE_POINTS:
                near = np.flatnonzero(_within_reach(pts[:, 0], pts[:, 1], lo, hi, reach2))
                if near.size:
                    dist[near, e] = shapely.distance(where[near], geom)
            else:
                dist[:, e] = shapely.distance(where, geom)
        return dist

    def _pair_distances(self, pts: np.ndarray) -> np.ndarray:
        """``(n, E) float64`` (a field of many entries): each of ``pts (n, 2)``'s distance to
        each entry whose reach it lies in (:attr:`_reach`), ``inf`` to the others (there
        ``dist / d >= 1`` whatever the exact distance): numpy's (:func:`_point_segment`) on the
        (point, segment) pairs of those (point, entry) pairs only, the least of each."""
        lo, hi, reach2, first, count = self._boxes
        near = _within_reach(pts[:, 0:1], pts[:, 1:2], lo.T, hi.T, reach2)  # (n, E)
        dist = np.full((pts.shape[0], len(self.entries)), np.inf)
        pi, ei = np.nonzero(near)
        entries = np.flatnonzero(near.any(axis=0))
        pairs = float(count[ei].sum())
        if NUMPY_NS[0] + NUMPY_NS[1] * pairs > (SHAPELY_NS[0] * entries.size + SHAPELY_NS[1] * pi.size
                                                + SHAPELY_NS[2] * pairs + SHAPELY_NS[3] * pts.shape[0]):
            where = shapely.points(pts)  # shapely's per entry, on the points within its reach
            for e in entries.tolist():
                at = np.flatnonzero(near[:, e])
                dist[at, e] = shapely.distance(where[at], self._geometries[e])
            return dist
        if pi.size:
            cnt = count[ei]
            run = np.cumsum(cnt) - cnt  # where each (point, entry) pair's segments start
            seg = np.arange(int(cnt.sum())) - np.repeat(run - first[ei], cnt)
            at = np.repeat(pi, cnt)
            sg = self._segments[0]
            d = _point_segment(pts[at, 0], pts[at, 1], sg[seg, 0, 0], sg[seg, 0, 1], sg[seg, 1, 0], sg[seg, 1, 1])
            dist[pi, ei] = np.minimum.reduceat(d, run)
        return dist

    @cached_property
    def _boxes(self) -> tuple:
        """The entries' :attr:`_reach` as arrays: ``lo, hi (E, 2)``, ``reach2 (E,)``, and where
        each entry's segments start among :attr:`_segments`' ``(E,)`` and how many ``(E,)``."""
        seg, starts = self._segments[:2]
        count = np.diff(np.append(starts, seg.shape[0]))
        return (np.array([r[0] for r in self._reach]), np.array([r[1] for r in self._reach]),
                np.array([r[2] for r in self._reach]), np.asarray(starts, np.int64), count.astype(np.int64))

    @cached_property
    def _few_segments(self) -> bool:
        """Whether every entry has at most :data:`NUMPY_SEGMENTS` segments."""
        return all(seg.shape[0] <= NUMPY_SEGMENTS for _, _, seg in self.entries)

    @cached_property
    def _reach(self) -> tuple:
        """Per entry ``(lo (2,), hi (2,), reach2, segments (m, 2, 2), geometry)``: the bounding
        box of its segments and the squared distance from that box beyond which a point is
        further than ``d`` from every segment, rounding included (``d`` plus ``1e-8`` of the
        larger of ``d``, the box's size and its coordinates: a distance's rounding error is
        some units in the last place of these), its segments and its shapely geometry."""
        out = []
        for (_, d, seg), geom in zip(self.entries, self._geometries):
            ends = seg.reshape(-1, 2)
            lo, hi = ends.min(axis=0), ends.max(axis=0)
            scale = max(float(d), float(np.abs(ends).max()), float((hi - lo).max()))
            reach = float(d) + 1e-8 * scale
            out.append((lo, hi, reach * reach, seg, geom))
        return tuple(out)

    @cached_property
    def _memo(self) -> dict:
        """What :func:`line_integral` and :func:`graded_points` worked out on this field, by
        polyline (:func:`_remembered`)."""
        return {}

    @cached_property
    def _segments(self) -> tuple:
        """Every entry's segments together ``(M, 2, 2)``, where each entry's start ``(E,)``, and
        the entries' sizes and distances ``(E,)`` each."""
        seg = [e[2] for e in self.entries]
        starts = np.cumsum([0] + [x.shape[0] for x in seg[:-1]])
        return (np.concatenate(seg), starts, np.array([e[0] for e in self.entries]),
                np.array([e[1] for e in self.entries]))

    @cached_property
    def _geometries(self) -> tuple:
        """Per entry one shapely geometry: a point, its polylines as a line string, or a
        multi-line string where the segments do not join end to end."""
        out = []
        for _, _, seg in self.entries:
            if seg.shape[0] == 1 and np.array_equal(seg[0, 0], seg[0, 1]):
                out.append(shapely.Point(seg[0, 0]))
            elif np.array_equal(seg[1:, 0], seg[:-1, 1]):
                out.append(shapely.LineString(np.concatenate([seg[:, 0], seg[-1:, 1]])))
            else:
                out.append(shapely.MultiLineString([x for x in seg]))
        return tuple(out)


def _within_reach(px: np.ndarray, py: np.ndarray, lo: np.ndarray, hi: np.ndarray, reach2) -> np.ndarray:
    """Whether each point ``(px, py)`` lies within the reach of each box (``lo``, ``hi``: its
    corners' x and y first, ``reach2`` the squared reach, :attr:`SizeField._reach`): its squared
    distance from the box is not above ``reach2`` (a NaN point counts as within, measured). The
    arguments broadcast: ``(n,)`` points against one box, or ``(n, 1)`` against ``(2, E)`` boxes,
    ``(n, E)``."""
    gx = np.maximum(np.maximum(lo[0] - px, px - hi[0]), 0.0)
    gy = np.maximum(np.maximum(lo[1] - py, py - hi[1]), 0.0)
    return ~(gx * gx + gy * gy > reach2)


FEW_ENTRIES = 4
"""A field of more entries (an automatic size field's features: tens of short curves) takes
numpy's distances on the (point, segment) pairs of the (point, entry) pairs within the entry's
reach only (:meth:`SizeField._pair_distances`: a point is near few of them); a field of fewer
entries (a user's) has the way chosen per entry (:meth:`SizeField._distances`)."""

NUMPY_NS = (30000.0, 45.0)
SHAPELY_NS = (4000.0, 174.0, 6.6, 100.0)
"""What a field of many entries' distances cost (ns, fitted to calls of the automatic fields of
examples/parts' flange, slotted link, star and gear on their meshes' points and on random
points): numpy's arithmetic a call and a (point, segment) pair within reach
(:data:`NUMPY_NS`); shapely's an entry called, a (point, entry) pair, a (point, segment) pair
and a point made (:data:`SHAPELY_NS`). :meth:`SizeField._pair_distances` takes the cheaper:
numpy's where points are within reach of few segments, shapely's per entry where of many (the
gear's mesh, 1,375 points, 55 entries: 15.8 ms by numpy's pairs, 4.0 by shapely's; 60 of its
points 0.14 and 0.23 ms)."""

PAIR_BLOCK = 1 << 16
"""(point, entry) pairs :meth:`SizeField._pair_distances` looks at in one go (the points in
blocks: its arrays stay a few MB)."""

PRUNE_POINTS = 64
"""From this many points a call measures shapely's distances to an entry only for the points
within its reach (:meth:`SizeField._distances`): on fewer, the look costs about what it saves."""

NUMPY_POINTS = 128
NUMPY_SEGMENTS = 8
"""An entry's distances are numpy's (:func:`segment_distances`, the whole array at once) for
at least :data:`NUMPY_POINTS` points and at most :data:`NUMPY_SEGMENTS` segments; shapely's
otherwise (GEOS in C, per point: no fixed cost of some twenty array operations, and ~10 ns a
pair against numpy's ~25). Measured one entry at a time: numpy / shapely 21 / 3 us at 5 points
and one segment, 22 / 18 at 80, 25 / 74 at 320; 27 / 5, 68 / 50 and 433 / 198 us at 5, 80 and
320 points on 48 segments. Both give the same numbers; a field of points only is numpy's at
any size."""


def segment_distances(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """``(n, m) float64``: each of ``points (n, 2)``'s distance to each of ``segments (m, 2, 2)``
    (a segment of length 0 is a point), with GEOS's arithmetic (:func:`_point_segment`), so the
    values are those ``shapely.distance`` gives."""
    return _point_segment(points[:, 0:1], points[:, 1:2], segments[:, 0, 0], segments[:, 0, 1], segments[:, 1, 0],
                          segments[:, 1, 1])


def _point_segment(px, py, ax, ay, bx, by) -> np.ndarray:
    """The distance from point ``(px, py)`` to segment ``(ax, ay)-(bx, by)``, elementwise over
    arrays that broadcast together, with GEOS's arithmetic (``Distance::pointToSegment``: the
    projection's parameter, then the nearer end or the perpendicular distance)."""
    dx, dy = bx - ax, by - ay
    len2 = dx * dx + dy * dy
    safe = np.where(len2 > 0, len2, 1.0)
    r = ((px - ax) * dx + (py - ay) * dy) / safe
    s = ((ay - py) * dx - (ax - px) * dy) / safe
    return np.where((r <= 0) | (len2 == 0), np.sqrt((px - ax) ** 2 + (py - ay) ** 2),
                    np.where(r >= 1, np.sqrt((px - bx) ** 2 + (py - by) ** 2), np.abs(s) * np.sqrt(len2)))


def segment_distance(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """``(n,) float64``: each of ``points (n, 2)``'s distance to the nearest of ``segments
    (m, 2, 2)`` (:func:`segment_distances`' least)."""
    return segment_distances(points, segments).min(axis=1)


@dataclass(frozen=True, eq=False)
class CallableSize:
    """A user's ``size(points (n, 2)) -> (n,)`` checked on every call: an answer of another
    shape, not finite or not positive raises :class:`InputError` naming ``name``. smallest: the
    least size seen on the region's outline when bound (:func:`bind`)."""

    function: Callable
    name: str = "size"
    smallest: float = math.nan

    def __call__(self, points) -> np.ndarray:
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        try:
            raw = self.function(pts.copy())
        except InputError:
            raise
        except Exception as e:  # noqa: BLE001 - the user's code: named, one line
            raise InputError(f"{self.name}: the size function failed on {pts.shape[0]} points: "
                             f"{type(e).__name__}: {e}") from None
        try:
            out = np.asarray(raw, np.float64)
        except (TypeError, ValueError):
            raise InputError(f"{self.name}: the size function must return numbers, got {type(raw).__name__}") from None
        if out.shape != (pts.shape[0],):
            raise InputError(f"{self.name}: the size function must map ({pts.shape[0]}, 2) points to "
                             f"({pts.shape[0]},) sizes, got shape {out.shape}")
        bad = ~(np.isfinite(out) & (out > 0))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(f"{self.name}: the size function must return positive sizes, got {out[i]!r} at "
                             f"({pts[i, 0]:.6g}, {pts[i, 1]:.6g})")
        return out


def _outline_samples(shape) -> np.ndarray:
    """Points along the region's loops (their points and 8 per segment) where a callable's
    smallest size is looked for."""
    loops = [np.asarray(shape.given_points, np.float64)] + [np.asarray(h, np.float64) for h in getattr(shape, "holes", ())]
    out = []
    t = np.linspace(0.0, 1.0, 8, endpoint=False)
    for ring in loops:
        nxt = np.roll(ring, -1, axis=0)
        out.append((ring[:, None, :] + t[None, :, None] * (nxt - ring)[:, None, :]).reshape(-1, 2))
    return np.concatenate(out)


def bind(size, shape, name: str = "size"):
    """What the meshing takes for ``size``: a number stays a number; a :class:`Field` is bound
    to ``shape`` (:meth:`Field.bind`); a :class:`SizeField` / :class:`CallableSize` is kept; any
    other callable becomes a :class:`CallableSize` (checked on the region's outline once here).
    name: the option or argument named in errors."""
    if isinstance(size, Field):
        return size.bind(shape)
    if isinstance(size, (SizeField, CallableSize)):
        return size
    if callable(size):
        f = CallableSize(size, name)
        return CallableSize(size, name, smallest=float(f(_outline_samples(shape)).min()))
    return size


def smallest_size(f) -> float:
    """The least size a bound field takes (:class:`SizeField`: exact; :class:`CallableSize`: on
    the outline)."""
    return float(f.smallest)


def outline_size(f, shape) -> float:
    """The one size that stands for a bound field where the meshing needs one number (the
    corners judged at the size, a ring layer's depth, the record's ``size``): the region's loops'
    total length over the integral of ``1 / f`` along them, the mean edge length the outline
    gets."""
    loops = [np.asarray(shape.given_points, np.float64)] + [np.asarray(h, np.float64) for h in getattr(shape, "holes", ())]
    length = wanted = 0.0
    for ring in loops:
        closed = np.concatenate([ring, ring[:1]])
        length += float(np.linalg.norm(np.diff(closed, axis=0), axis=1).sum())
        wanted += float(line_integral(f, closed)[-1])
    return length / wanted


def _remembered(f, key: tuple, compute):
    """``compute()``, kept on a bound :class:`SizeField` under ``key`` (its integrals along the
    sides the candidates share: each polyline's worked out once per field; a field is bound
    anew by every meshing call); computed every time for another callable. Not to be written
    to."""
    memo = getattr(f, "_memo", None) if isinstance(f, SizeField) else None
    if memo is None:
        return compute()
    if key not in memo:
        memo[key] = compute()
    return memo[key]


def kept_on_field(f, what: str, owners: tuple, compute):
    """``compute()`` (not to be written to), kept on a bound :class:`SizeField` for the objects
    ``owners`` (by identity: they are kept with the answer, so no other object takes their ids
    while it is kept), as its integrals are (:func:`_remembered`: a field is bound anew by every
    meshing call); computed every time for another callable. what: names the quantity."""
    memo = getattr(f, "_memo", None) if isinstance(f, SizeField) else None
    if memo is None:
        return compute()
    key = (what,) + tuple(id(o) for o in owners)
    if key not in memo:
        memo[key] = (owners, compute())
    return memo[key][1]


def _inverse_at_starts(f, p: np.ndarray, starts: np.ndarray, more: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(1 / f(starts), 1 / f(more))``: ``starts (n, 2)`` the starts of the pieces
    :func:`line_integral` (``per_size`` 4) and :func:`graded_points` both cut polyline ``p``
    into (the same points: the same formula on the same numbers), ``more (k, 2)`` what else one
    of them asks for. The field's values at the starts are kept on a bound :class:`SizeField`
    (as :func:`_remembered`), so the second of the two along the same polyline, in the same
    direction, asks only for ``more`` (the field at a point does not depend on the other points
    of the call)."""
    memo = getattr(f, "_memo", None) if isinstance(f, SizeField) else None
    key = ("starts", p.tobytes(), p.shape)
    known = None if memo is None else memo.get(key)
    if known is not None:
        return known, 1.0 / f(more)
    inv = 1.0 / f(np.concatenate([starts, more]))
    n = starts.shape[0]
    if memo is not None:
        memo[key] = inv[:n]
    return inv[:n], inv[n:]


def line_integral(f, polyline: np.ndarray, *, per_size: int = 4) -> np.ndarray:
    """``(k,) float64`` cumulative ``integral of 1 / f ds`` along ``polyline (k, 2)`` at its
    points (0 at the first): the number of edges of size ``f`` that fit along it. Each segment is
    cut into pieces no longer than ``smallest / per_size`` (at most 512 a segment) and integrated
    by the trapezoidal rule on ``1 / f``."""
    p = np.asarray(polyline, np.float64)

    def integrate():
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        small = smallest_size(f)
        step = small / per_size if small > 0 and math.isfinite(small) else (seg.max() if seg.size else 1.0) / 64
        k = np.clip(np.ceil(seg / max(step, 1e-300)), 1, 512).astype(np.int64)
        pieces = np.repeat(np.arange(seg.size), k)
        j = np.arange(pieces.size) - np.repeat(np.cumsum(k) - k, k)
        t0, t1 = j / k[pieces], (j + 1) / k[pieces]
        a, d = p[:-1][pieces], (p[1:] - p[:-1])[pieces]
        # a piece ends where the next one of its segment starts (the same a + t d): the field is
        # asked at every start and at each segment's last end only
        last = np.cumsum(k) - 1
        starts, ends = a + t0[:, None] * d, a[last] + t1[last][:, None] * d[last]
        if per_size == 4:  # (graded_points' pieces: the field at their starts asked for once)
            inv = np.concatenate(_inverse_at_starts(f, p, starts, ends))
        else:
            inv = 1.0 / f(np.concatenate([starts, ends]))
        n = pieces.size
        end = np.empty(n)
        end[:-1] = inv[1:n]
        end[last] = inv[n:]
        part = 0.5 * (inv[:n] + end) * seg[pieces] / k[pieces]
        cum = np.concatenate([[0.0], np.cumsum(np.bincount(pieces, weights=part, minlength=seg.size))])
        return cum

    return _remembered(f, ("integral", per_size, p.tobytes(), p.shape), integrate).copy()


def graded_points(f, polyline: np.ndarray, count: int) -> np.ndarray:
    """``(count + 1, 2)`` points on ``polyline (k, 2)`` at equal steps of ``integral of 1 / f``
    (:func:`line_integral`), both ends exact: a side's vertices where the field wants them.
    Computed from the lexicographically smaller end whatever the direction (as
    :func:`jaxmatch.placement.refine.side_points`), so that two patches sharing a side get
    bit-identical points."""
    poly = np.asarray(polyline, dtype=np.float64)
    N = int(count)
    first, last = poly[0].tolist(), poly[-1].tolist()
    flip = first != last and last < first
    p = poly[::-1] if flip else poly

    # the polyline cut finely, then the integral's inverse by linear interpolation
    def cut():
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        small = smallest_size(f)
        step = small / 4 if small > 0 and math.isfinite(small) else (seg.max() if seg.size else 1.0) / 64
        k = np.clip(np.ceil(seg / max(step, 1e-300)), 1, 512).astype(np.int64)
        pieces = np.repeat(np.arange(seg.size), k)
        j = np.arange(pieces.size) - np.repeat(np.cumsum(k) - k, k)
        starts = p[:-1][pieces] + (j / k[pieces])[:, None] * (p[1:] - p[:-1])[pieces]
        fine = np.concatenate([starts, p[-1:]])
        inv = np.concatenate(_inverse_at_starts(f, p, starts, p[-1:]))  # already fine: the trapezoidal rule
        return fine, np.concatenate([[0.0], np.cumsum(0.5 * (inv[:-1] + inv[1:]) * np.linalg.norm(np.diff(fine, axis=0),
                                                                                                 axis=1))])

    fine, cum = _remembered(f, ("graded", p.tobytes(), p.shape), cut)
    t = np.arange(N + 1, dtype=np.float64) / N * cum[-1]
    idx = np.minimum(np.maximum(np.searchsorted(cum, t, side="right") - 1, 0), fine.shape[0] - 2)
    dc = cum[idx + 1] - cum[idx]
    w = np.where(dc > 0, (t - cum[idx]) / np.where(dc > 0, dc, 1.0), 0.0)
    out = fine[idx] + w[:, None] * (fine[idx + 1] - fine[idx])
    out[0], out[-1] = p[0], p[-1]
    return out[::-1].copy() if flip else out


def edge_ratios(f, xy: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``(E,) float64`` each edge's length / the field at its midpoint (``edges (E, 2)`` vertex
    ids into ``xy (V, 2)``)."""
    a, b = xy[edges[:, 0]], xy[edges[:, 1]]
    return np.linalg.norm(b - a, axis=1) / f(0.5 * (a + b))


def field_share(f, xy: np.ndarray, edges: np.ndarray, band: tuple[float, float] = SHARE_BAND) -> float:
    """Share of ``edges`` whose :func:`edge_ratios` lies in ``band`` (NaN without edges)."""
    r = edge_ratios(f, xy, edges)
    return float(np.mean((r >= band[0]) & (r <= band[1]))) if r.size else math.nan


def parse_field(obj, where: str | None = None) -> Field:
    """A :class:`Field` from its JSON form ``{"size": H, "near": [{KIND: ENTITY, "size": s,
    "distance": d}, ...]}`` (KIND one of :data:`KINDS`); ``where`` names the file in errors."""
    if not isinstance(obj, dict):
        raise InputError("a size field must be a JSON object {\"size\": H, \"near\": [...]}", where)
    unknown = sorted(set(obj) - {"size", "near"})
    if unknown:
        raise InputError(f"size field: unknown key {unknown[0]!r} (expected \"size\", \"near\")", where)
    if "size" not in obj:
        raise InputError("size field: missing key \"size\" (the largest size H)", where)
    near = obj.get("near", [])
    if not isinstance(near, list):
        raise InputError("size field: \"near\" must be a list of entries", where)
    entries = []
    for n, e in enumerate(near, start=1):
        if not isinstance(e, dict):
            raise InputError(f"size field: near entry {n} must be an object", where)
        kinds = [k for k in KINDS if k in e]
        extra = sorted(set(e) - set(KINDS) - {"size", "distance"})
        if len(kinds) != 1 or extra:
            raise InputError(f"size field: near entry {n} needs exactly one of {', '.join(KINDS)} and "
                             f"\"size\", \"distance\"" + (f" (unknown key {extra[0]!r})" if extra else ""), where)
        for key in ("size", "distance"):
            if key not in e:
                raise InputError(f"size field: near entry {n} misses key {key!r}", where)
        try:
            entries.append(Near(kinds[0], e[kinds[0]], e["size"], e["distance"]))
        except InputError as err:
            raise InputError(f"near entry {n}: {err.problem}", where) from None
    try:
        return Field(obj["size"], tuple(entries), source=where)
    except InputError as err:
        raise InputError(err.problem, where) from None


def load_field(path: str | os.PathLike) -> Field:
    """:func:`parse_field` of a JSON file (errors name the file)."""
    where = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            obj = json.load(fh)
    except FileNotFoundError:
        raise InputError("size field file not found", where) from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"cannot read the size field: {e}", where) from None
    except json.JSONDecodeError as e:
        raise InputError(f"not valid JSON: {e.msg} (line {e.lineno})", where) from None
    return parse_field(obj, where)
