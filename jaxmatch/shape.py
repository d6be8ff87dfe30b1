"""Planar shape input and its s/x/v annotation (paper, section 4).

A shape is one closed polyline loop (the first point is not repeated) split into ``n``
*sides* by its *corners*. Input formats:

* JSON: ``{"boundary": [[x, y], ...], "corners": [i, ...]}``; ``corners`` is optional and
  lists indices into ``boundary`` where sides meet. No other keys are allowed.
* Text / CSV: one ``x y`` or ``x,y`` row per point; ``#`` starts a comment; blank lines are
  skipped. Corners are always detected from angles.

Without explicit corners a point is a corner when its interior angle differs from 180 degrees
by more than ``corner_angle`` (default 30 degrees).

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

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.files import read_limited

__all__ = [
    "Annotation",
    "DEFAULT_CORNER_ANGLE",
    "MAX_ANNOTATED",
    "MAX_POINTS",
    "S",
    "SYMBOLS",
    "Shape",
    "V",
    "X",
    "annotate",
    "cumulative_length",
    "default_points",
    "interior_angles",
    "largest_remainder",
    "load_shape",
    "make_shape",
    "parse_shape",
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
"""Largest accepted number of boundary points (keeps the O(P^2) crossing test bounded)."""

MAX_BYTES = 16 * 2**20
"""Largest accepted input file (bytes)."""

MAX_ANNOTATED = 100_000
"""Largest accepted number ``m`` of annotated points (a memory bound; scoring time grows
linearly in ``m``, and the default is twice the longest mesh boundary, a few dozen)."""

_TINY = 1e-12  # unit-box tolerance for coincident points (length) and zero area (area)
_STRAIGHT = 1e-9  # radians: smaller turns are round-off on a straight run (never corners, convex)
_ERRBOUND = 4e-16  # relative error bound of a floating 2x2 orientation determinant
_JSON_KEYS = ("boundary", "corners")
_TEXT_SUFFIXES = {".txt", ".csv", ".xy", ".dat", ".tsv"}


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

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_corners(self) -> int:
        return int(self.corners.shape[0])

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
# geometry helpers (pure, numpy)


def signed_area(points) -> float:
    """Shoelace area of the closed loop ``(P, 2)``; positive when counter-clockwise."""
    p = np.asarray(points, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    return float(0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))


def turning_angles(points) -> np.ndarray:
    """Signed turning angle at each point of a closed loop, ``(P,) float64`` radians.

    In ``(-pi, pi]``; positive is a left turn (convex for a ccw loop).
    """
    p = np.asarray(points, dtype=np.float64)
    e_in = p - np.roll(p, 1, axis=0)
    e_out = np.roll(p, -1, axis=0) - p
    cross = e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]
    dot = np.sum(e_in * e_out, axis=1)
    return np.arctan2(cross, dot)


def interior_angles(points) -> np.ndarray:
    """Interior angle at each point of a ccw loop, ``(P,) float64`` degrees in ``[0, 360)``."""
    return 180.0 - np.degrees(turning_angles(points))


def cumulative_length(points) -> np.ndarray:
    """Arc length from ``points[0]`` to each point, ``(P + 1,) float64``; the last entry is
    the perimeter (closing segment back to ``points[0]`` included)."""
    p = np.asarray(points, dtype=np.float64)
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def point_at(points, t) -> np.ndarray:
    """Positions ``(..., 2)`` at arc-length parameters ``t`` (any shape; taken modulo the
    perimeter) measured from ``points[0]`` along the closed loop ``points (P, 2)``."""
    p = np.asarray(points, dtype=np.float64)
    cum = cumulative_length(p)
    per = cum[-1]
    tt = np.mod(np.asarray(t, dtype=np.float64), per)
    idx = np.clip(np.searchsorted(cum, tt, side="right") - 1, 0, p.shape[0] - 1)
    seg = cum[idx + 1] - cum[idx]
    frac = np.where(seg > 0, (tt - cum[idx]) / np.where(seg > 0, seg, 1.0), 0.0)
    a = p[idx]
    b = p[(idx + 1) % p.shape[0]]
    return a + frac[..., None] * (b - a)


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
    quota = np.round(total * w / w.sum(), 6)
    base = np.floor(quota).astype(np.int64)
    rest = int(total - base.sum())
    order = np.lexsort((np.arange(w.size), -(quota - base)))
    base[order[:rest]] += 1
    return base


def _orient(a, b, c):
    """Orientation determinant of (a, b, c) and its error bound (broadcast ``(..., 2)``)."""
    l = (a[..., 0] - c[..., 0]) * (b[..., 1] - c[..., 1])
    r = (a[..., 1] - c[..., 1]) * (b[..., 0] - c[..., 0])
    det = l - r
    return np.where(np.abs(det) <= _ERRBOUND * (np.abs(l) + np.abs(r)), 0.0, np.sign(det))


def _on_segment(a, b, p):
    """``p`` inside the bounding box of segment ``a b`` (use with collinear points)."""
    return (
        (np.minimum(a[..., 0], b[..., 0]) <= p[..., 0])
        & (p[..., 0] <= np.maximum(a[..., 0], b[..., 0]))
        & (np.minimum(a[..., 1], b[..., 1]) <= p[..., 1])
        & (p[..., 1] <= np.maximum(a[..., 1], b[..., 1]))
    )


def _collinear(points) -> bool:
    """All points within ``_TINY`` of the line through ``points[0]`` and the farthest point."""
    p = np.asarray(points, dtype=np.float64) - points[0]
    far = p[np.argmax(np.linalg.norm(p, axis=1))]
    length = np.linalg.norm(far)
    if length == 0:
        return True
    dist = np.abs(p[:, 0] * far[1] - p[:, 1] * far[0]) / length
    return bool(dist.max() <= _TINY)


def _crossing(points) -> tuple[int, int] | None:
    """First pair ``(i, j)`` of segments ``i -> i+1`` and ``j -> j+1`` that meet, or None.

    Non-adjacent segments must not touch at all; adjacent ones must not overlap (a fold back
    at their common point). O(P^2) bounding-box filter over the pairs ``j >= i + 2`` in row
    blocks, exact-ish orientation tests on the candidates only. Worst case (every bounding box
    overlapping every other, e.g. 10,000 thin spikes meeting in the middle) a few seconds.
    """
    p = np.asarray(points, dtype=np.float64)
    n = p.shape[0]
    a, b = p, np.roll(p, -1, axis=0)
    # folds at a shared vertex: consecutive segments collinear and pointing back
    e_in, e_out = p - np.roll(p, 1, axis=0), b - p
    collinear = _orient(np.roll(p, 1, axis=0), p, b) == 0
    fold = collinear & (np.sum(e_in * e_out, axis=1) < 0)
    if fold.any():
        i = int(np.flatnonzero(fold)[0])
        return ((i - 1) % n, i)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    lox, loy, hix, hiy = (np.ascontiguousarray(v) for v in (lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1]))
    start = 0
    while start < n - 2:
        col = start + 2  # rows i >= start only need columns j >= i + 2 >= col
        stop = min(n, start + max(1, 1_000_000 // (n - col)))
        r = slice(start, stop)
        cand = (lox[r, None] <= hix[None, col:]) & (lox[None, col:] <= hix[r, None])
        cand &= (loy[r, None] <= hiy[None, col:]) & (loy[None, col:] <= hiy[r, None])
        ii, jj = np.nonzero(cand)
        ii, jj = ii + start, jj + col
        keep = (jj > ii + 1) & ~((ii == 0) & (jj == n - 1))
        ii, jj = ii[keep], jj[keep]
        start = stop
        if ii.size == 0:
            continue
        A, B, C, D = a[ii], b[ii], a[jj], b[jj]
        d1, d2 = _orient(C, D, A), _orient(C, D, B)
        d3, d4 = _orient(A, B, C), _orient(A, B, D)
        hit = ((d1 * d2 < 0) & (d3 * d4 < 0)) | (
            ((d1 == 0) & _on_segment(C, D, A))
            | ((d2 == 0) & _on_segment(C, D, B))
            | ((d3 == 0) & _on_segment(A, B, C))
            | ((d4 == 0) & _on_segment(A, B, D))
        )
        if hit.any():
            k = int(np.flatnonzero(hit)[0])
            return int(ii[k]), int(jj[k])
    return None


# ---------------------------------------------------------------------------------------------
# construction and validation


def _check_angle(corner_angle) -> float:
    try:
        a = float(corner_angle)
    except (TypeError, ValueError):
        a = math.nan
    if not (0.0 <= a < 180.0):
        raise InputError(f"corner angle must be a number in [0, 180) degrees, got {corner_angle!r}", where="corner angle")
    return a


def make_shape(points, corners=None, *, corner_angle: float = DEFAULT_CORNER_ANGLE, source: str = "<shape>") -> Shape:
    """Validate and normalise a loop into a :class:`Shape` (see the module docstring).

    points: ``(P, 2)`` numbers in user coordinates, closed loop, first point not repeated,
        either orientation.
    corners: optional sequence of int indices into ``points`` (any order); ``None`` detects
        corners from interior angles (``|angle - 180| > corner_angle`` degrees).
    Raises :class:`InputError` (``where=source``) for any problem; indices in messages refer
    to the input order.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        return _make_shape(points, corners, _check_angle(corner_angle), str(source))


def _make_shape(points, corners, angle: float, source: str) -> Shape:
    try:
        p = np.array(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as err:
        raise InputError(f"boundary is not a list of [x, y] number pairs ({err})", where=source) from None
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"boundary must be a list of [x, y] pairs, got array of shape {p.shape}", where=source)
    n = p.shape[0]
    if n < 3:
        raise InputError(f"boundary needs at least 3 points, got {n}", where=source)
    if n > MAX_POINTS:
        raise InputError(f"boundary has {n} points, more than the maximum {MAX_POINTS}", where=source)
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise InputError(f"boundary point {int(np.flatnonzero(bad)[0])} is not finite (NaN or infinity)", where=source)

    corner_idx = None
    if corners is not None:
        corner_idx = _check_corners(corners, n, source)

    def repeated(q, tol):
        if tol == 0:
            same = np.all(np.roll(q, -1, axis=0) == q, axis=1)
        else:
            same = ~(np.linalg.norm(np.roll(q, -1, axis=0) - q, axis=1) > tol)
        hit = np.flatnonzero(same)
        if hit.size:
            i = int(hit[0])
            if i == n - 1:
                raise InputError(f"last point repeats the first (point {n - 1} equals point 0); do not close the loop", where=source)
            raise InputError(f"repeated consecutive points {i} and {i + 1}", where=source)

    repeated(p, 0.0)
    offset = p.min(axis=0)
    extent = p.max(axis=0) - offset
    scale = float(extent.max())
    if not np.isfinite(extent).all() or not (scale > 0):
        raise InputError("coordinates are too large (extent overflows)", where=source)
    unit = (p - offset) / scale
    if not np.isfinite(unit).all():
        raise InputError("coordinates cannot be normalised (extent too small)", where=source)
    repeated(unit, _TINY)

    area = signed_area(unit)
    index = np.arange(n)  # input index of each current point
    if area < 0:  # clockwise: reverse keeping point 0 first
        index = (-index) % n
        unit = unit[index]
    hit = _crossing(unit)
    if not (abs(area) > _TINY) and (hit is None or _collinear(unit)):
        raise InputError("boundary has zero area (all points on one line)" if _collinear(unit) else "boundary has zero area", where=source)
    if hit is not None:
        i, j = hit
        si = f"{index[i]}-{index[(i + 1) % n]}"
        sj = f"{index[j]}-{index[(j + 1) % n]}"
        raise InputError(f"boundary crosses or touches itself: segment {si} meets segment {sj}", where=source)

    turn = turning_angles(unit)
    turn[np.abs(turn) <= _STRAIGHT] = 0.0
    if corner_idx is None:
        is_corner = np.abs(np.degrees(turn)) > angle
    else:
        inverse = np.empty(n, np.int64)
        inverse[index] = np.arange(n)
        is_corner = np.zeros(n, bool)
        is_corner[inverse[corner_idx]] = True
    found = np.flatnonzero(is_corner)
    # rotate so that points[0] is the first corner (without corners: the lowest point)
    roll = int(found[0]) if found.size else _lowest(unit)
    unit = np.roll(unit, -roll, axis=0)
    turn = np.roll(turn, -roll)
    found = found - roll
    index = np.roll(index, -roll)  # input index of each point, in the final order
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
    )


def _lowest(xy) -> int:
    """Index of the lowest point of ``xy (k, 2)`` (unit box): smallest ``y``, then smallest ``x``
    among the points within ``1e-9`` of that ``y`` (so that round-off cannot reorder points at
    the same height, e.g. a flat bottom after translating or scaling)."""
    y = xy[:, 1]
    low = np.flatnonzero(y <= y.min() + 1e-9)
    return int(low[np.argmin(xy[low, 0])])


def _check_corners(corners, n: int, source: str) -> np.ndarray:
    """Corner indices as ``(c,) int64``; rejects non-ints, out-of-range and duplicates."""
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
# readers


def load_shape(path, *, corner_angle: float = DEFAULT_CORNER_ANGLE) -> Shape:
    """Read a shape file (JSON, or text/CSV rows); see :func:`parse_shape`."""
    return parse_shape(read_limited(path, MAX_BYTES, "shape file"), str(path), corner_angle=corner_angle)


def parse_shape(data, source: str = "<input>", *, corner_angle: float = DEFAULT_CORNER_ANGLE, fmt: str | None = None) -> Shape:
    """Parse shape bytes/text into a :class:`Shape`.

    fmt: ``"json"``, ``"text"`` or None: by the suffix of ``source`` (``.json``; ``.txt``,
    ``.csv``, ``.xy``, ``.dat``, ``.tsv``), else JSON when the first non-blank character is
    ``{`` or ``[``, else text. Any problem raises :class:`InputError` with ``source``.
    """
    _check_angle(corner_angle)
    if isinstance(data, str):
        text = data
    else:
        if len(data) > MAX_BYTES:
            raise InputError(f"file is larger than {MAX_BYTES} bytes", where=source)
        try:
            text = bytes(data).decode("utf-8-sig")
        except UnicodeDecodeError as err:
            raise InputError(f"not UTF-8 text (byte {err.start})", where=source) from None
    if fmt is None:
        suffix = Path(source).suffix.lower()
        if suffix == ".json":
            fmt = "json"
        elif suffix in _TEXT_SUFFIXES:
            fmt = "text"
        else:
            fmt = "json" if text.lstrip()[:1] in ("{", "[") else "text"
    if fmt == "json":
        points, corners = _read_json(text, source)
    elif fmt == "text":
        points, corners = _read_text(text, source), None
    else:
        raise ValueError(f"unknown shape format {fmt!r}")
    return make_shape(points, corners, corner_angle=corner_angle, source=source)


def _no_duplicate_keys(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise _Dup(k)
        out[k] = v
    return out


class _Dup(Exception):
    pass


def _reject_constant(name):
    raise _Const(name)


class _Const(Exception):
    pass


def _read_json(text: str, source: str):
    try:
        doc = json.loads(text, object_pairs_hook=_no_duplicate_keys, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise InputError(f"not valid JSON: {err.msg} (column {err.colno})", where=f"{source}:{err.lineno}") from None
    except _Dup as err:
        raise InputError(f"duplicate key {_short(str(err.args[0]))}", where=source) from None
    except _Const as err:
        raise InputError(f"{err.args[0]} is not a finite number", where=source) from None
    except (ValueError, RecursionError) as err:  # huge integers, absurd nesting
        raise InputError(f"not valid JSON ({type(err).__name__}: {_short(str(err), 60)})", where=source) from None
    if not isinstance(doc, dict):
        raise InputError('top level must be a JSON object {"boundary": [[x, y], ...]}', where=source)
    unknown = [k for k in doc if k not in _JSON_KEYS]
    if unknown:
        raise InputError(f"unknown key {_short(unknown[0])} (allowed: boundary, corners)", where=source)
    if "boundary" not in doc:
        raise InputError('missing key "boundary"', where=source)
    boundary = doc["boundary"]
    if not isinstance(boundary, list):
        raise InputError('"boundary" must be a list of [x, y] pairs', where=source)
    if len(boundary) > MAX_POINTS:
        raise InputError(f"boundary has {len(boundary)} points, more than the maximum {MAX_POINTS}", where=source)
    points = []
    for i, row in enumerate(boundary):
        if not isinstance(row, list) or len(row) != 2:
            raise InputError(f"boundary[{i}] must be a pair [x, y], got {_short(row)}", where=source)
        xy = []
        for value in row:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"boundary[{i}] has a non-number {_short(value)}", where=source)
            try:
                f = float(value)
            except OverflowError:
                f = math.inf
            if not math.isfinite(f):
                raise InputError(f"boundary[{i}] has a number that is not finite", where=source)
            xy.append(f)
        points.append(xy)
    corners = doc.get("corners")
    if "corners" in doc and not isinstance(corners, list):
        raise InputError('"corners" must be a list of integer point indices', where=source)
    return points, corners


_SPLIT = re.compile(r"\s*,\s*|\s+")


def _read_text(text: str, source: str):
    points = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        if len(points) >= MAX_POINTS:
            raise InputError(f"more than the maximum {MAX_POINTS} points", where=f"{source}:{lineno}")
        tokens = _SPLIT.split(body)
        if len(tokens) != 2:
            raise InputError(f"expected two numbers 'x y' or 'x,y', got {_short(body)}", where=f"{source}:{lineno}")
        xy = []
        for tok in tokens:
            try:
                f = float(tok)
            except ValueError:
                raise InputError(f"not a number: {_short(tok)}", where=f"{source}:{lineno}") from None
            if not math.isfinite(f):
                raise InputError(f"{_short(tok)} is not a finite number", where=f"{source}:{lineno}")
            xy.append(f)
        points.append(xy)
    if not points:
        raise InputError("no points (expected rows 'x y' or 'x,y')", where=source)
    return points


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
    cum = cumulative_length(shape.points)
    per = float(cum[-1])
    if c == 0:
        t = per * np.arange(m, dtype=np.float64) / m
        codes = np.full(m, S, np.int32)
        side = np.zeros(m, np.int32)
        start = 0.0
    else:
        start = float(cum[shape.corners[0]])
        tc = cum[shape.corners] - start  # corner parameters, tc[0] = 0
        lengths = np.diff(np.concatenate([tc, [per]]))
        corner_xy = shape.points[shape.corners]
        low = _lowest(corner_xy)  # ties broken from here
        counts = np.roll(largest_remainder(np.roll(lengths, -low), m - c), low)
        per_side = counts + 1  # the corner plus its s points
        side = np.repeat(np.arange(c), per_side).astype(np.int32)
        first = np.concatenate([[0], np.cumsum(per_side)[:-1]])
        k = np.arange(m) - first[side]  # 0 for the corner, i for the i-th s point
        t = tc[side] + lengths[side] * k / (counts[side] + 1)
        codes = np.where(k == 0, np.where(shape.convex[side], X, V), S).astype(np.int32)
    positions = point_at(shape.points, t + start)
    if c:  # corners exactly on their polyline vertices
        positions[codes != S] = shape.points[shape.corners]
    return Annotation(
        symbols="".join(SYMBOLS[k] for k in codes.tolist()),
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
