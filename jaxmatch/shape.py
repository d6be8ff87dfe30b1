"""Planar shape input and its s/x/v annotation (paper, section 4).

A shape is one closed polyline loop (the first point is not repeated; a repeated first
point at the end is dropped) split into ``n`` *sides* by its *corners*. The file formats
(jaxmatch JSON with optional explicit ``corners``, GeoJSON, CSV/TSV/text, SVG, DXF) are read by
:mod:`jaxmatch.io.readers` (:func:`jaxmatch.io.readers.load_shape`, :func:`jaxmatch.io.readers.parse_shape`,
also public as ``jaxmatch.load_shape`` / ``jaxmatch.parse_shape``), which builds shapes with :func:`make_shape`.

Without explicit corners a point is a corner when its turning angle (180 degrees minus the
interior angle) exceeds ``corner_angle`` (default 30 degrees; a turn within ``1e-7`` degrees of
it is not a corner, so round-off cannot decide). The turn at a point is measured between its
neighbouring non-straight points (:func:`corner_turns`), so points added on a side change no
corner.

Normalisation done by :func:`make_shape` (every reader goes through it):

1. the loop is validated (>= 3 points, finite numbers, no repeated consecutive points, non-zero
   area, no self-intersection, corner indices valid);
2. coordinates are mapped to the unit box: ``unit = (user - offset) / scale`` where ``offset``
   is the lower-left corner of the bounding box and ``scale`` its larger extent, so the shape
   lies in ``[0, 1]^2`` and touches ``0`` and ``1`` along its longer direction;
3. clockwise loops are reversed to counter-clockwise (interior on the left), keeping the
   first point first (corner indices are remapped);
4. the loop is rotated so that ``points[0]`` is the first corner (when there are corners),
   so that the annotation sequence, which starts at the first corner, has arc-length
   parameters ``t`` measured from ``points[0]`` that increase from ``0``. A loop without
   corners is rotated so that ``points[0]`` is its lowest point (smallest ``y``, then
   smallest ``x``), so that its evenly spaced annotation does not depend on where the
   input listing starts.

Turning angles below ``1e-9`` radians count as straight (exactly 0): points on a straight run
are never corners (even with ``corner_angle=0``) and explicit corners there are convex,
whatever the round-off of translating and scaling the input.

Invariance (tested in ``tests/test_robustness.py``): translating or uniformly scaling the
input gives the same annotation; listing the loop from another point or in the other
orientation gives the same annotation up to a cyclic shift (the sequence starts at another
corner), because ties in distributing ``s`` points over sides are broken from a fixed corner
(see :func:`annotate`).

All lengths of :class:`Shape` and :class:`Annotation` (``t``, ``perimeter``) are in unit-box
units; multiply by ``shape.scale`` for user units, and map positions with
:meth:`Shape.to_user`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import NamedTuple

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.arrays import roll
from jaxmatch.sides import LoopNumbers, check_groups, warn_unordered
from jaxmatch.geometry import cumulative_length, first_crossing, point_at, ring_is_simple, signed_area, turning_angles

__all__ = [
    "scale_corners",
    "LoopNumbers",
    "Annotation",
    "DEFAULT_CORNER_ANGLE",
    "MAX_ANNOTATED",
    "MAX_COORDINATE",
    "MAX_POINTS",
    "MIN_EXTENT",
    "S",
    "SYMBOLS",
    "Shape",
    "V",
    "X",
    "annotate",
    "check_corner_angle",
    "corner_turns",
    "cumulative_length",
    "default_points",
    "interior_angles",
    "largest_remainder",
    "make_shape",
    "point_at",
    "signed_area",
    "turning_angles",
]

S, X, V = 0, 1, 2
"""Point type codes: straight, convex corner, concave corner."""

SYMBOLS = "sxv"
"""``SYMBOLS[code]`` is the paper's symbol for a point type code."""

DEFAULT_CORNER_ANGLE = 30.0
"""Degrees: a point is a corner when its interior angle differs from 180 by more than this."""

MAX_POINTS = 10_000
"""Largest accepted number of boundary points."""

MAX_BYTES = 16 * 2**20
"""Largest accepted input file (bytes)."""

MAX_COORDINATE = 1e150
"""Largest accepted absolute coordinate (user units): squares (areas) stay finite floats."""

MIN_EXTENT = 1e-150
"""Smallest accepted bounding-box extent (user units): squares (areas) stay normal floats."""

MAX_ANNOTATED = 100_000
"""Largest accepted number ``m`` of annotated points (a memory bound; scoring time grows
linearly in ``m``, and the default is twice the longest mesh boundary, a few dozen)."""

_TINY = 1e-12  # unit-box tolerance for coincident points (length) and zero area (area)
_STRAIGHT = 1e-9  # radians: smaller turns are round-off on a straight run (never corners, convex)
_ANGLE_TIE = 1e-7  # degrees: a turn this close to the corner angle is not a corner (round-off)


# ---------------------------------------------------------------------------------------------
# data


@dataclass(frozen=True, eq=False)
class Shape:
    """A validated planar shape in unit-box coordinates.

    points: ``(P, 2) float64``, counter-clockwise loop, first point not repeated, inside
        ``[0, 1]^2``; ``points[0]`` is the first corner when there are corners.
    corners: ``(c,) int32``, sorted indices into ``points`` (``c`` may be 0: a smooth loop).
    convex: ``(c,) bool``, corner is convex (interior angle <= 180 degrees; exactly 180 can
        only happen with explicit corners and counts as convex) — else concave.
    scale: float, user length per unit-box length.
    offset: ``(2,) float64``, user coordinates of the unit-box origin:
        ``user = points * scale + offset``.
    source: where the shape came from (file path), used in error messages.
    input_points: ``(P, 2) float64`` or None, the user's coordinates exactly as given, in the
        order of ``points`` (``to_user(points)`` equals them up to round-off only).
    corner_order: ``(c,) int64`` or None, the user's corner ``i`` is ``corners[corner_order[i]]``:
        the order of an explicit ``corners`` list, else the order of the input file.
    input_clockwise: the input loop was clockwise (``points`` is reversed from it).
    holes: the region's holes, each ``(H_k, 2) float64`` in user coordinates exactly as given,
        clockwise (the region on the left, as for the outer loop), starting at its first corner
        (or its lowest point); empty for a simply connected region. Scoring and template
        placement use the outer loop only; the meshing pipeline cuts holes into patches.
    hole_corners: per hole, ``(c_k,) int64`` sorted indices into ``holes[k]``: its corners.
    explicit_corners: the corners were given (the JSON ``corners`` key or ``corners=``), not
        detected from angles; the meshing pipeline re-judges detected corners at its size.
    numbering: the file's numbering of each loop (:class:`jaxmatch.sides.LoopNumbers`: the outer
        loop, then each hole in the order of ``holes``); empty: the stored order is the file's.
    tags: ``((name, (side, ...)), ...)`` user line groups (:func:`jaxmatch.sides.check_groups`).
    periodic: ``((side a, side b), ...)`` pairs of outer sides meshed as translates.
    """

    points: np.ndarray
    corners: np.ndarray
    convex: np.ndarray
    scale: float
    offset: np.ndarray
    source: str = "<shape>"
    input_points: np.ndarray | None = None
    corner_order: np.ndarray | None = None
    input_clockwise: bool = False
    holes: tuple = ()
    hole_corners: tuple = ()
    explicit_corners: bool = False
    numbering: tuple = ()
    tags: tuple = ()
    periodic: tuple = ()

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @cached_property
    def area(self) -> float:
        """Area enclosed by ``points`` (unit box; positive: the loop is ccw), computed once."""
        return float(signed_area(self.points))

    @property
    def given_points(self) -> np.ndarray:
        """``(P, 2) float64`` the points in user coordinates, exactly as given when known
        (``input_points``), else :attr:`user_points`."""
        return self.input_points if self.input_points is not None else self.user_points

    @cached_property
    def user_area(self) -> float:
        """Area enclosed by :attr:`given_points` (user units squared, unsigned), computed once."""
        return abs(signed_area(self.given_points))

    @cached_property
    def arc_length(self) -> np.ndarray:
        """``(P + 1,) float64`` :func:`cumulative_length` of ``points`` (computed once; read-only)."""
        cum = cumulative_length(self.points)
        cum.setflags(write=False)
        return cum

    @property
    def n_corners(self) -> int:
        return int(self.corners.shape[0])

    @cached_property
    def side_frame(self) -> tuple[tuple[int, bool], ...]:
        """For each user side ``i``: ``(j, reversed)``, the ccw side ``j`` (from ``corners[j]`` to
        ``corners[j + 1]``) it is, and whether the user runs it backwards (computed once: template
        placement asks for every template). Without corners: ``((0, False),)``.

        Raises :class:`InputError` when explicit corners are not listed in boundary order."""
        n = self.n_corners
        if n == 0:
            return ((0, False),)
        order = np.arange(n) if self.corner_order is None else np.asarray(self.corner_order, np.int64)
        step = (roll(order, -1) - order) % n
        forward = bool(np.all(step == 1 % n))
        backward = bool(np.all(step == (n - 1) % n))
        if forward and backward:  # n <= 2: the file's orientation decides
            forward = not self.input_clockwise
        elif not (forward or backward):
            raise InputError("corners are not listed in boundary order (side i must run from corner i to corner i + 1)",
                             where=self.source)
        if forward:
            return tuple((int(order[i]), False) for i in range(n))
        return tuple((int(order[(i + 1) % n]), True) for i in range(n))

    @property
    def perimeter(self) -> float:
        """Loop length in unit-box units."""
        return float(cumulative_length(self.points)[-1])

    @property
    def user_points(self) -> np.ndarray:
        """``(P, 2) float64`` points in the user's coordinates."""
        return self.to_user(self.points)

    def to_user(self, xy) -> np.ndarray:
        """Map unit-box positions ``(..., 2)`` to user coordinates."""
        return np.asarray(xy, dtype=np.float64) * self.scale + self.offset


class Annotation(NamedTuple):
    """The shape as a sequence of ``m`` symbols (paper: the first LCS sequence).

    symbols: str of length m over ``"sxv"``, e.g. ``"xsssxsssvss"``.
    codes: ``(m,) int32``, ``S``/``X``/``V`` (0/1/2) per point.
    t: ``(m,) float64``, arc length (unit-box units) from the sequence start along the ccw
        loop; ``t[0] = 0``, strictly increasing, ``< perimeter``. For shapes made by
        :func:`make_shape` the start is ``points[0]``.
    positions: ``(m, 2) float64``, the points in unit-box coordinates.
    side: ``(m,) int32``, the side of each point; side ``j`` runs from corner ``j`` to corner
        ``j + 1`` (cyclically), and corner ``j`` belongs to side ``j``. All 0 without corners.
    perimeter: float, loop length (unit-box units).
    """

    symbols: str
    codes: np.ndarray
    t: np.ndarray
    positions: np.ndarray
    side: np.ndarray
    perimeter: float


# ---------------------------------------------------------------------------------------------
# geometry helpers (see jaxmatch.geometry)


def interior_angles(points) -> np.ndarray:
    """Interior angle at each point of a ccw loop, ``(P,) float64`` degrees in ``[0, 360)``."""
    return 180.0 - np.degrees(turning_angles(points))


def largest_remainder(weights, total: int) -> np.ndarray:
    """Split ``total`` items over ``len(weights)`` bins in proportion to ``weights``.

    Largest-remainder (Hamilton) rounding: every bin gets the floor of its quota, the rest go
    to the largest fractional parts; ties go to the lower index. Quotas are rounded to 6
    decimals first so that the result does not depend on round-off (e.g. the four equal sides
    of a translated and scaled square). Returns ``(k,) int64`` summing to ``total``.
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.size == 0:
        return np.zeros(0, np.int64)
    quota = np.round(total * w / w.sum(), 6).tolist()
    base = [math.floor(q) for q in quota]  # (the few bins in plain numbers: the same floors and fractions)
    rest = int(total - sum(base))
    for i in sorted(range(len(base)), key=lambda i: base[i] - quota[i])[:rest]:  # (stable: ties to the lower index)
        base[i] += 1
    return np.array(base, np.int64)


def _collinear(points) -> bool:
    """All points within ``_TINY`` of the line through ``points[0]`` and the farthest point."""
    p = np.asarray(points, dtype=np.float64) - points[0]
    far = p[np.argmax(np.linalg.norm(p, axis=1))]
    length = np.linalg.norm(far)
    if length == 0:
        return True
    dist = np.abs(p[:, 0] * far[1] - p[:, 1] * far[0]) / length
    return bool(dist.max() <= _TINY)


def corner_turns(points) -> np.ndarray:
    """Turning angle used for corner detection at each point of a loop, ``(P,) float64``
    radians: exactly 0 on straight runs (local turn within ``1e-9``), elsewhere the turn
    between the neighbouring *non-straight* points, so that points added on a side change
    no corner (the turn at a vertex does not depend on how its sides are subdivided)."""
    turn = turning_angles(points)
    straight = np.abs(turn) <= _STRAIGHT
    turn[straight] = 0.0
    bent = np.flatnonzero(~straight)
    if 3 <= bent.size < turn.size:
        turn[bent] = turning_angles(np.asarray(points, dtype=np.float64)[bent])
    return turn


# ---------------------------------------------------------------------------------------------
# corners at the scale of the mesh

CORNER_WINDOW = 1.0
"""Corners at a target edge length ``h`` (:func:`scale_corners`): the turn at a point is
measured between the outline this many ``h`` before and after it, so that wiggles shorter than
about ``h`` neither become corners nor split sides."""

STRAIGHT_RUN = 2.0
"""A turn between two straight runs of the outline each at least this many ``h`` long is a
corner however small the turn (above :data:`MIN_STRAIGHT_TURN`)."""

HELD_ANGLE = 60.0
"""Degrees: a turn of a curved or noisy stretch (not a polygon's vertex between straight runs)
is a corner only above this (or the corner angle, if larger): the sharp corners of a traced
outline, not its bends."""

CONCENTRATION = 0.5
"""A turn over the window is a corner only when at least this part of it happens within a
quarter of the window (a bend: a rounded corner of radius well below ``h``), not when it is
spread over it (the end of an ellipse, a smooth coastline's curve)."""

PEAK_BAND = 5.0
"""Degrees: the points of a turn over the window within this much of its peak compete for the
corner, the sharpest of them wins (noise moves the peak, not the vertex where the sides meet)."""

SHARP_RUN = 0.5
"""A polygon vertex whose straight runs on both sides are at least this many ``w`` long is a
corner when it turns by more than the corner angle, however close the next corner is."""

MIN_STRAIGHT_TURN = 2.0
"""Degrees: the smallest turn between two long straight runs that is a corner."""

TRACED = 1 / 8
"""A point with an edge to a neighbour at least this many ``h`` long is a polygon's vertex (drawn:
a densely traced outline has at least 1 / TRACED points per ``h`` on both sides; the other edge may
be a sampled curve's, where a straight side meets a fillet): it is a corner whenever it turns by
more than the corner angle, however small the feature it belongs to (a gear's tooth, a thin fin, a
key slot); only a densely traced outline has its corners judged over the window."""


def scale_corners(points, h: float, corner_angle: float = DEFAULT_CORNER_ANGLE, *,
                  held_angle: float | None = None) -> np.ndarray:
    """Corner indices of the closed loop ``points (P, 2)`` judged at target edge length ``h``
    (same units), sorted ``(c,) int64``.

    A point is a corner when the outline turns there by more than ``corner_angle`` degrees
    measured over the stretch ``w =`` :data:`CORNER_WINDOW` ``* h`` before and after it (the
    chords from the point ``w`` back to it and from it to the point ``w`` ahead) and either at
    the point itself between straight runs at least :data:`SHARP_RUN` ``* w`` long (a polygon's
    vertex), or once per turn over the window that is concentrated (:data:`CONCENTRATION`): at
    the sharpest point among those within ``w`` of its peak and within :data:`PEAK_BAND` of its
    peak turn (a rounded or noisy corner); or
    when it joins two straight runs each at least :data:`STRAIGHT_RUN` ``* h`` long with a turn
    above :data:`MIN_STRAIGHT_TURN` degrees; or when it turns by more than ``corner_angle`` and an
    edge to a neighbour is at least :data:`TRACED` ``* h`` long (a drawn polygon's vertex, whatever
    the size of its feature). With ``h`` small against every feature this finds
    the corners of :func:`make_shape`'s angle rule. held_angle: the threshold of a turn of a
    curved stretch (default :data:`HELD_ANGLE` or ``corner_angle``, the larger).
    """
    p = np.asarray(points, np.float64)
    cum = cumulative_length(p)
    per = float(cum[-1])
    w = min(CORNER_WINDOW * float(h), per / 8)
    s = cum[:-1]
    back, ahead, near_back, near_ahead = point_at(p, np.stack([s - w, s + w, s - w / 4, s + w / 4]), cum)  # (one search)
    a, b = p - back, ahead - p
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    wide = np.degrees(np.abs(np.arctan2(cross, np.sum(a * b, axis=1))))
    local = np.degrees(np.abs(corner_turns(p)))
    held = wide > corner_angle + _ANGLE_TIE
    bent = np.flatnonzero(local > 0)
    if bent.size:  # the straight run on each side of every point: to the previous / next bent point
        k = np.searchsorted(bent, np.arange(p.shape[0]))
        prev_b = bent[(k - 1) % bent.size]
        next_b = bent[np.searchsorted(bent, np.arange(p.shape[0]), side="right") % bent.size]
        run_in, run_out = (s - s[prev_b]) % per, (s[next_b] - s) % per
    else:
        run_in = run_out = np.full(p.shape[0], per)
    sharp_runs = np.minimum(run_in, run_out) >= SHARP_RUN * w
    sharp = [int(i) for i in np.flatnonzero(held & (local > corner_angle + _ANGLE_TIE) & sharp_runs)]
    keep = list(sharp)  # a polygon's vertex between straight runs: a corner however close to the next
    qa, qb = p - near_back, near_ahead - p  # the turn over a quarter of the window
    quarter = np.degrees(np.abs(np.arctan2(qa[:, 0] * qb[:, 1] - qa[:, 1] * qb[:, 0], np.sum(qa * qb, axis=1))))
    concentrated = quarter >= CONCENTRATION * wide  # a bend, not a smooth curve's slow turn
    bend = max(corner_angle, HELD_ANGLE) if held_angle is None else held_angle
    rest = np.flatnonzero((wide > bend + _ANGLE_TIE) & (local > 0) & concentrated)
    def near(i, others, r) -> np.ndarray:
        d = np.abs(s[others] - s[i])
        return np.minimum(d, per - d) < r

    kept = set(keep)  # (a point already kept is within w of itself: no distances needed)
    for i in rest[np.argsort(-wide[rest], kind="stable")].tolist():  # a turn over the window: once, at its sharpest point
        if (w > 0 and i in kept) or (keep and np.any(near(i, np.asarray(keep), w))):
            continue
        peer = rest[near(i, rest, w) & (wide[rest] >= wide[i] - PEAK_BAND)]
        keep.append(int(peer[np.argmax(local[peer])]))
        kept.add(keep[-1])
    run = STRAIGHT_RUN * float(h)
    e_in = np.linalg.norm(p - roll(p, 1), axis=1)  # the edge arriving at each point
    e_out = roll(e_in, -1)
    straight = np.flatnonzero((np.minimum(e_in, e_out) >= run) & (local > MIN_STRAIGHT_TURN))
    drawn = np.flatnonzero((np.maximum(e_in, e_out) >= TRACED * float(h)) & (local > corner_angle + _ANGLE_TIE))
    return np.unique(np.concatenate([np.asarray(keep, np.int64), straight.astype(np.int64), drawn.astype(np.int64)]))


# ---------------------------------------------------------------------------------------------
# construction and validation


def check_corner_angle(corner_angle) -> float:
    """``corner_angle`` as a float in ``[0, 180)`` degrees; :class:`InputError` (no ``where``:
    the caller names the option or argument) otherwise."""
    try:
        a = float(corner_angle)
    except (TypeError, ValueError, OverflowError):
        a = math.nan
    if not (0.0 <= a < 180.0):
        raise InputError(f"corner angle must be a number of degrees in [0, 180), got {corner_angle!r}")
    return a


def make_shape(points, corners=None, *, corner_angle: float = DEFAULT_CORNER_ANGLE, source: str = "<shape>",
               holes=None, hole_corners=None, checked: bool = False, tags=None, periodic=None,
               holes_checked: bool = False) -> Shape:
    """Validate and normalise a loop into a :class:`Shape` (see the module docstring).

    points: ``(P, 2)`` numbers in user coordinates, a loop in either orientation; a closed
        ring (last point equal to the first, as GeoJSON and SVG write it) has its last point
        dropped (a corner index naming it means the first point).
    corners: optional sequence of int indices into ``points`` (any order); ``None`` detects
        corners from interior angles (``|angle - 180| > corner_angle`` degrees).
    holes: optional list of loops ``(H_k, 2)`` (either orientation, closed rings allowed), each
        checked like the outer loop and against it: inside it, not touching it or another hole.
    hole_corners: optional list (one entry per hole, each None or indices into that hole).
    tags: optional ``{name: [side, ...]}`` user line groups; periodic: optional ``[[side a,
        side b], ...]`` pairs of sides that are translates (see :func:`jaxmatch.sides.check_groups`;
        sides are named in the file's numbering, :func:`jaxmatch.sides.named_sides`).
    checked: the outer loop is known to be simple, of distinct points and non-zero area (a patch
        of a checked :class:`~jaxmatch.placement.layout.Layout`, or a shape's own loop listed
        from another point): its crossing and repeated-point checks are left out (a third of
        the time of a small loop). Holes are checked all the same, unless ``holes_checked``: they
        are known to be valid holes of this outer loop (a shape's own holes listed from another
        point, :func:`jaxmatch.meshing.region.canonical`): each is made as a checked loop and its
        place against the outer loop and the other holes is not tested again.
    Raises :class:`InputError` (``where=source``) for any problem; indices in messages refer
    to the input order.
    """
    angle = check_corner_angle(corner_angle)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        shape = _make_shape(points, corners, angle, str(source), checked)
        if holes is not None and len(holes) > 0:
            shape = _with_holes(shape, holes, hole_corners, angle, str(source), holes_checked)
    warn_unordered(shape)
    if tags is None and periodic is None:
        return shape
    return replace(shape, **dict(zip(("tags", "periodic"), check_groups(shape, tags, periodic))))


def _with_holes(shape: Shape, holes, hole_corners, angle: float, source: str, checked: bool = False) -> Shape:
    """``shape`` with its holes validated (each a loop checked like the outer one, then inside
    the outer loop without touching it or another hole: shapely predicates); ``checked``: holes
    known to be valid (see :func:`make_shape`'s ``holes_checked``), made without the tests."""
    import shapely

    if hole_corners is None:
        hole_corners = [None] * len(holes)
    if len(hole_corners) != len(holes):
        raise InputError(f"hole_corners has {len(hole_corners)} entries for {len(holes)} holes", where=source)
    outer = None if checked else shapely.Polygon(shape.input_points)
    rings, corner_lists, polys, numbers = [], [], [], []
    for k, (h, hc) in enumerate(zip(holes, hole_corners)):
        try:
            hs = _make_shape(h, hc, angle, source, checked)
        except InputError as e:
            raise InputError(f"hole {k + 1}: {e.problem.replace('boundary', 'hole')}", where=source) from None
        ring = hs.input_points[::-1]  # clockwise, from its first corner (or lowest point)
        ring = np.roll(ring, 1, axis=0)
        corners_k = np.sort((hs.n_points - np.asarray(hs.corners, np.int64)) % hs.n_points)
        if checked:
            rings.append(np.ascontiguousarray(ring))
            corner_lists.append(corners_k.astype(np.int64))
            nb = hs.numbering[0]
            numbers.append(nb._replace(numbers=np.roll(nb.numbers[::-1], 1), hole=k + 1))
            continue
        poly = shapely.Polygon(ring)
        if not outer.contains(poly):
            what = "lies outside the outer boundary" if not outer.intersects(poly) else \
                "crosses or touches the outer boundary"
            raise InputError(f"hole {k + 1} {what}", where=source)
        if outer.exterior.distance(poly) <= 0.0:
            raise InputError(f"hole {k + 1} touches the outer boundary", where=source)
        for j, other in enumerate(polys):
            if poly.distance(other) <= 0.0:
                what = "overlap" if poly.intersection(other).area > 0 else "touch"
                raise InputError(f"holes {j + 1} and {k + 1} {what}", where=source)
        rings.append(np.ascontiguousarray(ring))
        corner_lists.append(corners_k.astype(np.int64))
        polys.append(poly)
        nb = hs.numbering[0]
        numbers.append(nb._replace(numbers=np.roll(nb.numbers[::-1], 1), hole=k + 1))
    return replace(shape, holes=tuple(rings), hole_corners=tuple(corner_lists), numbering=shape.numbering + tuple(numbers))


def _make_shape(points, corners, angle: float, source: str, checked: bool = False) -> Shape:
    try:
        p = np.array(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as err:
        raise InputError(f"boundary is not a list of [x, y] number pairs ({err})", where=source) from None
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"boundary must be a list of [x, y] pairs, got array of shape {p.shape}", where=source)
    n = p.shape[0]
    if n > MAX_POINTS + 1 or (n == MAX_POINTS + 1 and not _closes(p)):
        raise InputError(f"boundary has {n} points, more than the maximum {MAX_POINTS}", where=source)
    if not np.isfinite(p).all():
        bad = ~np.isfinite(p).all(axis=1)
        raise InputError(f"boundary point {int(np.flatnonzero(bad)[0])} is not finite (NaN or infinity)", where=source)

    corner_idx = None
    if corners is not None:
        corner_idx = _check_corners(corners, n, source)
    if n >= 3 and not checked and _closes(p):  # closed ring (last point = first): drop the repeated point
        p, n = p[:-1], n - 1
        if corner_idx is not None:
            listed = np.where(corner_idx == n, 0, corner_idx)
            corner_idx = listed[np.sort(np.unique(listed, return_index=True)[1])]  # in the file's order
    if n < 3:
        raise InputError(f"boundary needs at least 3 points, got {n}", where=source)

    def repeated(q, tol):
        if tol == 0:
            same = np.all(roll(q, -1) == q, axis=1)
        else:
            same = ~(np.linalg.norm(roll(q, -1) - q, axis=1) > tol)
        hit = np.flatnonzero(same)
        if hit.size:
            i = int(hit[0])
            if i == n - 1:
                raise InputError(f"the first point is repeated more than once at the end (point {n - 1} equals point 0)", where=source)
            raise InputError(f"repeated consecutive points {i} and {i + 1}", where=source)

    if not checked:
        repeated(p, 0.0)
    offset = p.min(axis=0)
    top = p.max(axis=0)
    extent = top - offset
    scale = float(extent.max())
    if not np.isfinite(extent).all() or not (scale > 0):
        raise InputError("coordinates are too large (extent overflows)", where=source)
    big = max(abs(v) for v in offset.tolist() + top.tolist())  # (the largest |coordinate|: at a column's end)
    if big > MAX_COORDINATE:
        raise InputError(f"coordinates are too large ({big:.3g}; at most {MAX_COORDINATE:g} in absolute value, so that "
                         "areas and squared lengths of the placed mesh stay finite): rescale the shape", where=source)
    if scale < MIN_EXTENT:
        raise InputError(f"the shape is too small (extent {scale:.3g}; at least {MIN_EXTENT:g}, so that areas of the "
                         "placed mesh do not vanish): rescale the shape", where=source)
    unit = (p - offset) / scale
    if not np.isfinite(unit).all():
        raise InputError("coordinates cannot be normalised (extent too small)", where=source)
    if not checked:
        repeated(unit, _TINY)
    simple = True if checked else ring_is_simple(unit)  # (n >= 3 here) the same for the loop reversed below
    area = signed_area(unit)
    index = np.arange(n)  # input index of each current point
    if area < 0:  # clockwise: reverse keeping point 0 first
        index = (-index) % n
        unit = unit[index]
    hit = None if checked else first_crossing(unit, tol=_TINY, simple=simple)
    if not (abs(area) > _TINY) and (hit is None or _collinear(unit)):
        raise InputError("boundary has zero area (all points on one line)" if _collinear(unit) else "boundary has zero area", where=source)
    if hit is not None:
        i, j = hit
        si = f"{index[i]}-{index[(i + 1) % n]}"
        sj = f"{index[j]}-{index[(j + 1) % n]}"
        raise InputError(f"boundary crosses or touches itself: segment {si} meets segment {sj}", where=source)

    turn = corner_turns(unit)
    if corner_idx is None:
        is_corner = np.abs(np.degrees(turn)) > angle + _ANGLE_TIE
    else:
        inverse = np.empty(n, np.int64)
        inverse[index] = np.arange(n)
        is_corner = np.zeros(n, bool)
        is_corner[inverse[corner_idx]] = True
    found = np.flatnonzero(is_corner)
    # rotate so that points[0] is the first corner (without corners: the lowest point)
    start = int(found[0]) if found.size else _lowest(unit)
    unit = roll(unit, -start)
    turn = roll(turn, -start)
    found = found - start
    index = roll(index, -start)  # input index of each point, in the final order
    position = np.empty(n, np.int64)  # input index -> final point index
    position[index] = np.arange(n)
    corner_of_point = np.full(n, -1, np.int64)
    corner_of_point[found] = np.arange(found.size)
    user_list = corner_idx if corner_idx is not None else np.sort(index[found])
    return Shape(
        points=np.ascontiguousarray(unit),
        corners=found.astype(np.int32),
        convex=(turn[found] >= 0.0).astype(bool),
        scale=scale,
        offset=offset.astype(np.float64),
        source=str(source),
        input_points=np.ascontiguousarray(p[index]),
        corner_order=corner_of_point[position[np.asarray(user_list, np.int64)]],
        input_clockwise=bool(area < 0),
        explicit_corners=corner_idx is not None,
        numbering=(LoopNumbers(index.astype(np.int64), None if corner_idx is None else tuple(int(c) for c in corner_idx),
                               bool(area < 0), 0),),
    )


def _closes(p: np.ndarray) -> bool:
    """The last point of ``p (P, 2)`` (finite) repeats the first (exactly, or within ``_TINY`` of the
    bounding box's larger extent)."""
    if np.array_equal(p[0], p[-1]):
        return True
    scale = float(np.max(p.max(axis=0) - p.min(axis=0)))
    return bool(np.isfinite(scale) and scale > 0 and np.max(np.abs(p[-1] - p[0])) <= _TINY * scale)


def _lowest(xy) -> int:
    """Index of the lowest point of ``xy (k, 2)`` (unit box): smallest ``y``, then smallest ``x``
    among the points within ``1e-9`` of that ``y`` (so that round-off cannot reorder points at
    the same height, e.g. a flat bottom after translating or scaling)."""
    x, y = xy[:, 0].tolist(), xy[:, 1].tolist()
    cut = min(y) + 1e-9
    return min((i for i, v in enumerate(y) if v <= cut), key=x.__getitem__)  # (the first of equal x: argmin's)


def _check_corners(corners, n: int, source: str) -> np.ndarray:
    """Corner indices as ``(c,) int64``; rejects non-ints, out-of-range and duplicates."""
    if type(corners) is list and all(type(c) is int and 0 <= c < n for c in corners) and len(set(corners)) == len(corners):
        return np.array(corners, dtype=np.int64)  # (plain valid ints, a patch's every time: the loop below finds nothing)
    if isinstance(corners, (str, bytes)) or not hasattr(corners, "__len__"):
        raise InputError("corners must be a list of integer point indices", where=source)
    seen: set[int] = set()
    out = []
    for j, c in enumerate(list(corners)):
        if isinstance(c, (bool, np.bool_)) or not isinstance(c, (int, np.integer)):
            raise InputError(f"corners[{j}] must be an integer point index, got {_short(c)}", where=source)
        c = int(c)
        if not 0 <= c < n:
            raise InputError(f"corners[{j}] = {c} is out of range (the boundary has {n} points)", where=source)
        if c in seen:
            raise InputError(f"corners[{j}] = {c} is listed twice", where=source)
        seen.add(c)
        out.append(c)
    return np.asarray(out, dtype=np.int64)


def _short(value, limit: int = 40) -> str:
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


# ---------------------------------------------------------------------------------------------
# annotation


def annotate(shape: Shape, m: int) -> Annotation:
    """The shape as ``m`` annotated points: every corner once (``x`` convex, ``v`` concave),
    and ``m - c`` straight ``s`` points.

    The ``s`` points are split over the sides in proportion to side length
    (:func:`largest_remainder`) and spread evenly by arc length strictly inside each side
    (``k`` points on a side of length ``L`` sit at ``L * i / (k + 1)``, ``i = 1..k``). Ties
    (sides with equal fractional quotas) are broken in ccw side order from the lowest corner
    (smallest ``y``, then smallest ``x``; heights within ``1e-9`` count as equal), not from the
    first one, so that the annotation of a
    loop listed from another corner is the same sequence shifted cyclically. The sequence
    starts at the first corner (``shape.corners[0]``, which :func:`make_shape` puts at
    ``points[0]``); without corners all ``m`` points are ``s``, evenly spaced from
    ``points[0]`` (the lowest point). ``t`` is measured from the start of the sequence.

    Raises :class:`InputError` when ``m`` is smaller than the number of corners (or than 1),
    or larger than :data:`MAX_ANNOTATED`.
    """
    m = int(m)
    c = shape.n_corners
    if m < max(c, 1):
        raise InputError(f"{m} boundary points requested, but the shape has {c} corners (need at least {max(c, 1)})", where=shape.source)
    if m > MAX_ANNOTATED:
        raise InputError(f"{m} boundary points requested, more than the maximum {MAX_ANNOTATED}", where=shape.source)
    cum = shape.arc_length
    per = float(cum[-1])
    if c == 0:
        t = per * np.arange(m, dtype=np.float64) / m
        codes = np.full(m, S, np.int32)
        side = np.zeros(m, np.int32)
        start = 0.0
    else:
        tcu = cum[shape.corners]
        start = float(tcu[0])
        tc = tcu - start  # corner parameters, tc[0] = 0
        lengths = np.diff(np.concatenate([tc, [per]]))
        corner_xy = shape.points[shape.corners]
        low = _lowest(corner_xy)  # ties broken from here
        counts = roll(largest_remainder(roll(lengths, -low), m - c), low)
        per_side = (counts + 1).tolist()  # the corner plus its s points
        side_list = [j for j, p in enumerate(per_side) for _ in range(p)]
        k_list = [i for p in per_side for i in range(p)]  # 0 for the corner, i for the i-th s point
        side = np.array(side_list, np.int32)
        k = np.array(k_list, np.int64)
        t = tc[side] + lengths[side] * k / (counts[side] + 1)
        kinds = [X if v else V for v in shape.convex.tolist()]
        code_list = [kinds[j] if i == 0 else S for j, i in zip(side_list, k_list)]
        codes = np.array(code_list, np.int32)
    positions = point_at(shape.points, t + start, cum)
    if c:  # corners exactly on their polyline vertices
        positions[codes != S] = corner_xy
    else:
        code_list = [S] * m
    return Annotation(
        symbols="".join([SYMBOLS[k] for k in code_list]),
        codes=codes,
        t=t,
        positions=positions,
        side=side,
        perimeter=per,
    )


def default_points(shape: Shape, max_boundary: int) -> int:
    """Default number ``m`` of annotated points for scoring meshes with up to ``max_boundary``
    boundary vertices: ``max(2 * max_boundary, max_boundary + c, c, 1)``.

    Why: the modified LCS only deletes *shape* points, so ``m >= n`` is required for every
    mesh scored. ``m - c >= max_boundary`` lets a mesh put all of its vertices on ``s`` points
    (e.g. a mesh without valence-2 corners on a shape with corners). Twice the longest
    boundary gives each side about twice as many candidate points as a mesh with
    proportionally spread vertices needs, so meshes whose vertices are spread unevenly over the
    sides (up to about twice a side's share) can still match, and corners can be skipped.
    The DP cost grows linearly in ``m``, so more than ``2 n`` buys little.
    """
    n = int(max_boundary)
    if n < 0:
        raise ValueError(f"max_boundary must be >= 0, got {max_boundary}")
    c = shape.n_corners
    return max(2 * n, n + c, c, 1)
