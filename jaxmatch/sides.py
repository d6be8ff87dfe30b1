"""The sides of a region named as its input file numbers them, the user's tags and periodic pairs.

A :class:`~jaxmatch.shape.Shape` carries, from its reader, how the file numbers each of its loops
(:class:`LoopNumbers`, kept through every reordering: :func:`jaxmatch.shape.make_shape` makes the
loop counter-clockwise from its first corner, :func:`jaxmatch.meshing.region.canonical` from its
smallest point). :func:`named_sides` names every side between consecutive corners ``side i-j``
(outer loop) or ``hole h side i-j``: from the file's corner ``i`` to the next one ``j`` in the
file's order, ``i``, ``j`` point numbers or positions in the file's ``corners`` list. The output's
line groups (:mod:`jaxmatch.meshing.groups`), ``--sides`` and ``side_counts`` use these names.
Tags and periodic pairs name sides this way (:func:`check_groups`).

This module reads shapes by their attributes only (no import of :mod:`jaxmatch.shape`, which
imports it).
"""

from __future__ import annotations

import re
import warnings
from typing import NamedTuple

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.errors import InputError, InputWarning

__all__ = ["LoopNumbers", "NamedSide", "RESERVED_GROUP", "check_groups", "named_sides", "periodic_lines",
           "resolve_side", "side_lengths", "side_polyline", "warn_unordered"]


def _short(value, limit: int = 40) -> str:
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


class LoopNumbers(NamedTuple):
    """How the input file numbers one loop of a region, kept through every reordering so that
    side groups carry the file's names.

    numbers: ``(P,) int64`` the file's point number of each point, in the stored order.
    corners: the file's explicit corner list (point numbers, in the file's order) or None.
    clockwise: the file lists the loop clockwise.
    hole: 0 for the outer loop, ``h`` for the file's ``h``-th hole (1-based).
    """

    numbers: np.ndarray
    corners: tuple | None
    clockwise: bool
    hole: int


class NamedSide(NamedTuple):
    """One side of a region's loop named as the input file numbers it.

    name: ``"side i-j"`` (outer loop) or ``"hole h side i-j"``: from the file's corner ``i`` to
        the next one in the file's order, ``j``; ``i``, ``j`` are point numbers, or positions
        in the file's ``corners`` (``hole_corners``) list where it gives one.
    loop: 0 the outer loop, ``k + 1`` the shape's ``holes[k]`` (stored order).
    start, stop: indices of its end corners into that loop's stored points (outer:
        ``points``; holes: ``holes[k]``), ``stop`` after ``start`` in the stored direction
        (the outer loop ccw, holes cw: the region on the left); equal for a loop of one corner.
    """

    name: str
    loop: int
    start: int
    stop: int


def _loop_numbers(shape, loop: int, n_points: int) -> LoopNumbers:
    if loop < len(shape.numbering):
        return shape.numbering[loop]
    return LoopNumbers(np.arange(n_points), None, False if loop == 0 else True, loop)


def named_sides(shape) -> list[NamedSide]:
    """Every side of ``shape``'s loops (between consecutive corners) named in the input file's
    numbering (:class:`NamedSide`), outer sides first, then each hole's in the file's hole
    order, each loop's sides in the file's order. A loop without corners has no sides.

    A loop whose explicit corners are not listed in boundary order (``[0, 2, 1, 3]``) has its
    sides named by point numbers instead (:func:`make_shape` warns once)."""
    out: list[tuple[tuple[int, int], NamedSide]] = []
    loops = [(shape.points, shape.corners)] + list(zip(shape.holes, shape.hole_corners))
    for loop, (ring, corners) in enumerate(loops):
        corners = np.sort(np.asarray(corners, np.int64))
        n = corners.size
        if n == 0:
            continue
        nb = _loop_numbers(shape, loop, len(ring))
        numbers = np.asarray(nb.numbers, np.int64)[corners]
        if nb.corners is not None:
            place = {int(c): i for i, c in enumerate(nb.corners)}
            labels = np.array([place.get(int(c), int(c)) for c in numbers], np.int64)
        else:
            labels = numbers
        forward = (not nb.clockwise) if loop == 0 else nb.clockwise  # the file runs the stored direction
        if nb.corners is not None and n >= 3:
            step = (roll(labels, -1) - labels) % n
            if np.all(step == 1):
                forward = True
            elif np.all(step == n - 1):
                forward = False
            else:  # no side runs from corner i to i + 1: point numbers
                labels = numbers
        prefix = "side" if loop == 0 else f"hole {nb.hole} side"
        for k in range(n):
            a, b = int(labels[k]), int(labels[(k + 1) % n])
            first, second = (a, b) if forward else (b, a)
            out.append(((nb.hole, first), NamedSide(f"{prefix} {first}-{second}", loop, int(corners[k]),
                                                    int(corners[(k + 1) % n]))))
    return [side for _, side in sorted(out, key=lambda kv: kv[0])]


def warn_unordered(shape) -> None:
    """One :class:`InputWarning` when a loop's explicit corners are not listed in boundary order."""
    loops = [(shape.corners, 0)] + [(hc, k + 1) for k, hc in enumerate(shape.hole_corners)]
    bad = []
    for corners, loop in loops:
        if loop >= len(shape.numbering) or shape.numbering[loop].corners is None or len(corners) < 3:
            continue
        nb = shape.numbering[loop]
        listed = nb.corners
        if all(a < b for a, b in zip(listed, listed[1:])):  # (an increasing list is in boundary order: the
            continue  # loop's numbers run around it one way or the other; a patch's corners, every time)
        place = {int(c): i for i, c in enumerate(listed)}
        labels = np.array([place.get(int(c), -1) for c in np.asarray(nb.numbers)[np.sort(corners)]])
        step = (roll(labels, -1) - labels) % len(labels)
        if not (np.all(step == 1) or np.all(step == len(labels) - 1)):
            bad.append("corners" if loop == 0 else f"hole {nb.hole}'s corners")
    if bad:
        warnings.warn(InputWarning(f"{' and '.join(bad)} are not listed in boundary order: the output's side groups "
                                   "are named by point numbers", where=shape.source), stacklevel=3)


RESERVED_GROUP = re.compile(r"^(boundary|(side|hole|patch|cut|periodic) .*)$")
"""Names of the groups jaxmatch writes itself: a tag may not take one."""


def side_polyline(shape, side: NamedSide) -> np.ndarray:
    """``(k, 2) float64`` the points of ``side`` in user coordinates, in its name's direction
    (from its file corner ``i`` to ``j``)."""
    ring = _ring(shape, side.loop)
    pts = ring[_along(side, len(ring))]
    return pts if _named_forward(shape, side) else pts[::-1]


def side_lengths(shape, sides: list[NamedSide]) -> list[float]:
    """Per side, its length (user units) as :func:`side_polyline`'s points give it: the sum of its
    edges' lengths in its name's direction (the same sum, bit for bit), each loop's edges measured
    once."""
    seg: dict[int, np.ndarray] = {}
    out = []
    for side in sides:
        if side.loop not in seg:
            ring = _ring(shape, side.loop)
            seg[side.loop] = np.linalg.norm(roll(ring, -1) - ring, axis=1)  # (edge i: point i to i + 1)
        e = seg[side.loop]
        lengths = e[_along(side, len(e))[:-1]]
        out.append(float((lengths if _named_forward(shape, side) else lengths[::-1].copy()).sum()))
    return out


def _ring(shape, loop: int) -> np.ndarray:
    """``(n, 2) float64`` loop ``loop``'s points in user coordinates (0: the outer loop)."""
    return shape.given_points if loop == 0 else np.asarray(shape.holes[loop - 1], np.float64)


def _along(side: NamedSide, n: int) -> np.ndarray:
    """The point indices of ``side`` on its loop of ``n`` points, in the stored direction."""
    return (side.start + np.arange(((side.stop - side.start) % n or n) + 1)) % n


def _named_forward(shape, side: NamedSide) -> bool:
    """Whether ``side``'s name runs the stored direction (its first corner is its ``start``)."""
    return _label_at(shape, side, side.start) == side.name.rsplit(" ", 1)[1].split("-")[0]


def _label_at(shape, side: NamedSide, point: int) -> str:
    ring_n = shape.n_points if side.loop == 0 else len(shape.holes[side.loop - 1])
    nb = _loop_numbers(shape, side.loop, ring_n)
    num = int(np.asarray(nb.numbers)[point])
    if nb.corners is not None and num in nb.corners:
        return str(list(nb.corners).index(num))
    return str(num)


def resolve_side(shape, text: str, sides: list[NamedSide] | None = None) -> tuple[list[NamedSide], bool]:
    """The sides ``text`` names: ``"i-j"`` or ``"side i-j"`` (an outer side), ``"hole h side
    i-j"``, ``"hole h"`` (every side of hole ``h``; a hole without corners: ``[]`` with the hole
    named), each ``i-j`` in either order. Returns ``(sides, reversed)``: ``reversed`` when
    ``text`` names one side as ``j-i``. Raises :class:`InputError` (no ``where``) for a name that
    is no side of the region."""
    sides = named_sides(shape) if sides is None else sides
    t = " ".join(str(text).split())
    m = re.fullmatch(r"hole (\d+)", t)
    if m:
        h = int(m.group(1))
        holes = [nb.hole for nb in shape.numbering[1:]] or list(range(1, len(shape.holes) + 1))
        if h not in holes:
            raise InputError(f"{_short(text)} is not a hole of the region (it has {len(shape.holes)})")
        return [s for s in sides if s.name.startswith(f"hole {h} side ")], False
    if re.fullmatch(r"\d+-\d+", t):
        t = "side " + t
    m = re.fullmatch(r"((?:hole \d+ )?side) (\d+)-(\d+)", t)
    if m:
        for name, rev in ((t, False), (f"{m.group(1)} {m.group(3)}-{m.group(2)}", True)):
            hit = [s for s in sides if s.name == name]
            if hit:
                return hit, rev and m.group(2) != m.group(3)
    known = ", ".join(s.name.replace("side ", "", 1) if s.loop == 0 else s.name for s in sides[:12])
    raise InputError(f"{_short(text)} is not a side of the region (sides: {known or 'none, it has no corners'})")


def check_groups(shape, tags, periodic) -> tuple[tuple, tuple]:
    """``tags`` and ``periodic`` checked against ``shape``'s sides, as stored on the shape.

    tags: ``{name: [side, ...]}`` (or None): each name a new line group (not empty, at most 80
        printable characters without quotes, not one of jaxmatch's own group names
        :data:`RESERVED_GROUP`), each side as :func:`resolve_side` reads it. Stored as ``((name,
        (side name, ...)), ...)``.
    periodic: ``[[a, b], ...]`` (or None): two distinct sides (no side in two pairs) that are
        translates of each other within ``1e-9`` of the region's extent: ``a`` from its corner
        ``i`` to ``j`` onto ``b`` as written (``"3-2"``: from corner 3 to 2), or onto ``b``
        reversed when only that matches. Stored as ``((a, b, reversed), ...)`` with ``a``, ``b``
        the sides' names and ``reversed`` whether ``b`` runs against ``a``.
    Raises :class:`InputError` naming the source and the tag or pair."""
    src = shape.source
    sides = named_sides(shape)
    out_tags = []
    if tags is not None:
        if not isinstance(tags, dict):
            raise InputError('"tags" must be an object {"name": ["i-j", ...], ...}', where=src)
        for name, members in tags.items():
            if not isinstance(name, str) or not name.strip() or len(name) > 80 or not name.isprintable() \
                    or '"' in name or name != name.strip():
                raise InputError(f"tag {_short(name)}: a tag name must be 1 to 80 printable characters without "
                                 "quotes or outer blanks", where=src)
            if RESERVED_GROUP.match(name):
                raise InputError(f"tag {name!r} clashes with a group jaxmatch writes itself (boundary, side ..., "
                                 "hole ..., patch ..., cut ..., periodic ...)", where=src)
            if isinstance(members, str) or not isinstance(members, (list, tuple)) or not members:
                raise InputError(f"tag {name!r}: expected a non-empty list of sides like [\"0-1\", \"hole 1\"]",
                                 where=src)
            names: list[str] = []
            for mem in members:
                if not isinstance(mem, str):
                    raise InputError(f"tag {name!r}: {_short(mem)} is not a side name like \"0-1\"", where=src)
                try:
                    hit, _ = resolve_side(shape, mem, sides)
                except InputError as e:
                    raise InputError(f"tag {name!r}: {e.problem}", where=src) from None
                whole = " ".join(mem.split())
                names += [whole] if re.fullmatch(r"hole \d+", whole) else [s.name for s in hit]
            out_tags.append((name, tuple(dict.fromkeys(names))))
    out_pairs = []
    if periodic is not None:
        if not isinstance(periodic, (list, tuple)):
            raise InputError('"periodic" must be a list of side pairs [["0-1", "3-2"], ...]', where=src)
        used: set[str] = set()
        ext = float(np.ptp(shape.given_points, axis=0).max())
        for k, pair in enumerate(periodic):
            what = f"periodic pair {k + 1}"
            if not isinstance(pair, (list, tuple)) or len(pair) != 2 or not all(isinstance(x, str) for x in pair):
                raise InputError(f"{what}: expected two side names like [\"0-1\", \"3-2\"], got {_short(pair)}", where=src)
            got = []
            for x in pair:
                try:
                    hit, rev = resolve_side(shape, x, sides)
                except InputError as e:
                    raise InputError(f"{what}: {e.problem}", where=src) from None
                if len(hit) != 1:
                    raise InputError(f"{what}: {x!r} names a whole hole, not one side", where=src)
                got.append((hit[0], rev))
            (a, ra), (b, rb) = got
            if a.name == b.name or {a.name, b.name} & used:
                raise InputError(f"{what}: {a.name if a.name in used or a.name == b.name else b.name} is in two "
                                 "periodic pairs or paired with itself", where=src)
            pa, pb = side_polyline(shape, a), side_polyline(shape, b)
            pa, pb = (pa[::-1] if ra else pa), (pb[::-1] if rb else pb)
            rev = _translate_match(pa, pb, ext)
            if rev is None:
                raise InputError(f"{what}: {pair[0]} and {pair[1]} are not translates of each other (within 1e-9 of "
                                 "the region's extent); only translation-periodic sides are supported", where=src)
            used |= {a.name, b.name}
            out_pairs.append((a.name, b.name, bool(rev != (ra != rb))))
    return tuple(out_tags), tuple(out_pairs)


def _translate_match(a: np.ndarray, b: np.ndarray, extent: float) -> bool | None:
    """Whether polyline ``b (k, 2)`` is polyline ``a (j, 2)`` moved by one translation (``False``:
    ``a[0]`` onto ``b[0]``; ``True``: onto ``b[-1]``, ``b`` reversed; None: neither), within
    ``1e-9 * extent`` (every point of each within that of the other, by shapely's Hausdorff
    distance of the moved lines)."""
    import shapely

    tol = 1e-9 * extent
    for rev in (False, True):
        bb = b[::-1] if rev else b
        t = bb[0] - a[0]
        if np.linalg.norm(bb[-1] - (a[-1] + t)) > tol:
            continue
        if shapely.hausdorff_distance(shapely.LineString(a + t), shapely.LineString(bb)) <= tol:
            return rev
    return None


def periodic_lines(shape) -> tuple:
    """``((pa (k, 2), pb (j, 2)), ...)`` the two sides of each periodic pair of ``shape`` in user
    coordinates (for the integer program's equal counts: :func:`jaxmatch.placement.milp.solve_counts`)."""
    if not shape.periodic:
        return ()
    by_name = {s.name: s for s in named_sides(shape)}
    out = []
    for a, b, _ in shape.periodic:
        if a not in by_name or b not in by_name:
            missing = a if a not in by_name else b
            raise InputError(f"periodic side {missing} is not a side of the region at this size (its corners are "
                             "judged again at the size: give them explicitly, \"corners\")", where=shape.source)
        out.append((side_polyline(shape, by_name[a]), side_polyline(shape, by_name[b])))
    return tuple(out)
