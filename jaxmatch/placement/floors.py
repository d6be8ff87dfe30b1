"""The curved sides' floors: the fewest edges each boundary side of a layout may have so that the
chords of its curved stretches keep the region's area (:func:`curve_floors`, the integer
program's lower bounds; :func:`lean_curve_floors`, the budget allocated where it pays and by
sign), and the chord-area errors they are measured by (:func:`chord_area_errors`,
:func:`chord_piece_areas`).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from jaxmatch.placement.embed import polygon_area
from jaxmatch.placement.layout import Layout, Sides, region_area
from jaxmatch.placement.refine import side_points

__all__ = ["CURVE_BATCH", "CURVE_POINTS", "CURVE_SHARE", "CURVE_ZERO", "chord_area_error", "chord_area_errors",
           "chord_piece_areas", "curve_floors", "lean_curve_floors"]


def chord_area_error(polyline: np.ndarray, n: int) -> float:
    """Area between ``polyline (k, 2)`` and the chords through its ``n + 1`` points evenly spaced
    by arc length (:func:`jaxmatch.placement.refine.side_points`, where the mesh puts its
    vertices): the sum over the ``n`` pieces of the absolute area each piece encloses with its
    chord (user units squared; 0 for a straight side). :func:`chord_area_errors` of one count."""
    return float(chord_area_errors(polyline, [n])[0])


def chord_area_errors(polyline: np.ndarray, counts) -> np.ndarray:
    """:func:`chord_area_error` of ``polyline (k, 2)`` for each piece count of ``counts (c,)``:
    ``(c,) float64`` (user units squared), every count's pieces at once.

    Each piece's ring (its first chord point, the polyline's points strictly inside it, its last
    chord point) is laid end to end in one array and its shoelace terms summed per ring
    (``np.add.reduceat``; a piece with no point inside is its chord: 0 exactly); a count's
    absolute areas are added piece by piece, in order. The chord points are those of
    :func:`~jaxmatch.placement.refine.side_points` and the pieces' ends those of
    ``np.linspace(0, length, n + 1)``, computed by the same operations (the same doubles,
    tested), so a count's error does not depend on the other counts asked with it."""
    p = np.asarray(polyline, np.float64)
    ns = np.asarray(counts, np.int64).reshape(-1)
    k = p.shape[0]
    if k <= 2 or not ns.size:
        return np.zeros(ns.shape[0])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    flip = (not np.array_equal(p[0], p[-1])) and tuple(p[-1]) < tuple(p[0])  # (as side_points)
    f, fseg = (p[::-1], seg[::-1]) if flip else (p, seg)
    fcum = np.concatenate([[0.0], np.cumsum(fseg)]) if flip else cum
    per = ns + 1  # each count's chord points
    first = np.concatenate([[0], np.cumsum(per)[:-1]])
    of = np.repeat(first, per)
    j = np.arange(int(per.sum())) - of  # the point's place among its count's
    big_n = np.repeat(ns, per)
    t = j / big_n * fcum[-1]  # side_points: np.arange(N + 1) / N * length
    idx = np.clip(np.searchsorted(fcum, t, side="right") - 1, 0, k - 2)
    w = np.where(fseg[idx] > 0, (t - fcum[idx]) / np.where(fseg[idx] > 0, fseg[idx], 1.0), 0.0)
    q = f[idx] + w[:, None] * (f[idx + 1] - f[idx])
    q[first], q[first + ns] = f[0], f[-1]
    if flip:
        q = q[of + big_n - j]
    ends = j * (cum[-1] / big_n) + 0.0  # np.linspace(0, cum[-1], n + 1)
    ends[first + ns] = cum[-1]
    piece = np.flatnonzero(j < big_n)  # piece i of a count runs from its point i to i + 1
    cut = np.searchsorted(cum, ends[piece], side="right")  # vertices strictly after the piece start
    m = np.searchsorted(cum, ends[piece + 1], side="left") - cut  # and strictly before its end
    size = np.maximum(m, 0) + 2
    starts = np.concatenate([[0], np.cumsum(size)[:-1]])
    at = np.arange(int(size.sum())) - np.repeat(starts, size)  # place within its ring
    ring = p[np.clip(np.repeat(cut - 1, size) + at, 0, k - 1)]
    last = starts + size - 1
    ring[starts], ring[last] = q[piece], q[piece + 1]
    nxt = np.arange(1, ring.shape[0] + 1)
    nxt[last] = starts  # each ring closes on its first point
    x, y = ring[:, 0], ring[:, 1]
    area = np.abs(0.5 * np.add.reduceat(x * y[nxt] - x[nxt] * y, starts))
    table = np.zeros((ns.shape[0], int(ns.max())))  # one row a count, its pieces in order
    table[np.repeat(np.arange(ns.shape[0]), ns), j[piece]] = area
    return np.cumsum(table, axis=1)[:, -1]  # added in order, as one at a time


CURVE_SHARE = 0.8
"""The part of the area tolerance (``Quality.area_tol``) that the chords of curved sides may
use, shared among the curved boundary sides by length (:func:`curve_floors`)."""

CURVE_ZERO = 1e-9
"""A boundary side whose single chord leaves less than this fraction of the region's area is
straight (:func:`curve_floors`: no share of the area budget)."""


def _region_shares(layout: Layout, sides: Sides) -> np.ndarray:
    """``(S,) float64`` per side on a region's boundary (the outline, or between two regions of
    an assembly): the smallest over its regions of area / boundary length; inf for the others."""
    reg = np.asarray(layout.regions, np.int64)
    n = int(reg.max()) + 1
    area = np.zeros(n)
    for p, loop in enumerate(layout.patches):
        area[reg[p]] += abs(polygon_area(layout.points[loop]))
    users = sides.users
    r0 = reg[users[:, 0]]
    r1 = np.where(users[:, 1] >= 0, reg[np.maximum(users[:, 1], 0)], -1)
    on = r0 != r1
    length = np.zeros(n)
    np.add.at(length, r0[on], sides.lengths[on])
    inner = on & (r1 >= 0)
    np.add.at(length, r1[inner], sides.lengths[inner])
    share = np.full(len(users), np.inf)
    share[on] = area[r0[on]] / length[r0[on]]
    share[inner] = np.minimum(share[inner], area[r1[inner]] / length[r1[inner]])
    return share


def curve_floors(layout: Layout, sides: Sides, area_tol: float, region: float | None = None, *,
                 lean: bool = False, size: float | None = None) -> np.ndarray:
    """``(S,) int64`` the fewest edges each side may have so that its chords keep the region's
    area: a boundary side whose points do not lie on one line gets at least the edges that keep
    the area between it and its chords within its share of :data:`CURVE_SHARE` ``* area_tol`` of
    the region's area: its length over the whole boundary's; every other side 1. With ``lean``
    the curved boundary sides share the budget alone (a straight side loses no area and takes
    none: coarser curves, nearer the size, where the outline also has straight sides), allocated
    where it pays and by sign (:func:`lean_curve_floors`; ``size``: the target edge length, the
    curved sides' starting counts). ``region``: :func:`region_area` of ``layout`` when the caller
    has it. An assembly's layout (``layout.regions``): a side between two regions is kept like a
    boundary side of each, its budget the smaller of the two regions' shares (``lean`` does not
    apply)."""
    floors = np.ones(len(sides.chains), np.int64)
    own = _region_shares(layout, sides) if layout.regions is not None else None
    bound = np.flatnonzero(sides.outer if own is None else ~np.isinf(own))
    if not bound.size:
        return floors
    lean = lean and own is None
    if lean:  # (only the one chord's error: which sides are curved)
        err1 = {int(s): _one_chord_error(layout.points[sides.chains[s]]) for s in bound}
    else:
        known = {int(s): _first_errors(layout.points[sides.chains[s]]) for s in bound}  # (one chord, the doubling counts)
        err1 = {s: errs[1] for s, errs in known.items()}
    if region is None and own is None:
        region = region_area(layout)
    curved = [s for s in bound if err1[int(s)] > CURVE_ZERO * region] if lean else bound
    if lean:
        chains = [layout.points[sides.chains[s]] for s in curved]
        floors[curved] = lean_curve_floors(chains, CURVE_SHARE * area_tol * region, size)
        return floors
    total = float(np.sum(sides.lengths[curved])) if len(curved) else 1.0
    for s in bound:
        poly = layout.points[sides.chains[s]]
        if poly.shape[0] <= 2:
            continue
        if own is not None:
            budget = CURVE_SHARE * area_tol * float(own[s]) * float(sides.lengths[s])
        else:
            budget = CURVE_SHARE * area_tol * region * float(sides.lengths[s]) / total
        if err1[int(s)] <= budget:
            continue
        floors[s] = _fewest_pieces(poly, budget, known[int(s)])
    return floors


def chord_piece_areas(polyline: np.ndarray, n: int) -> np.ndarray:
    """``(n,) float64`` the signed area each of the ``n`` pieces of ``polyline (k, 2)`` encloses
    with its chord, the pieces' ends evenly spaced by arc length as in :func:`chord_area_error`
    (whose error is the sum of their absolute values; user units squared). The sign is the
    shoelace's of the ring (the piece's first chord point, the polyline's points strictly inside
    it, its last chord point): positive where the polyline runs to the right of its chord. Along
    a boundary side of a counter-clockwise patch loop (the region on its left): positive, the
    area the chord cuts off the region (a convex stretch); negative, the area it adds (a concave
    stretch, a hole's side)."""
    p0 = np.asarray(polyline, np.float64)
    k, n = p0.shape[0], int(n)
    if k <= 2:
        return np.zeros(n)
    centre = 0.5 * (p0.min(axis=0) + p0.max(axis=0))  # (cross products of small coordinates)
    p = p0 - centre
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p0, axis=0), axis=1))])
    q = side_points(p0, n) - centre
    t = np.linspace(0.0, cum[-1], n + 1)
    a = np.searchsorted(cum, t[:-1], side="right")  # each piece's points inside: p[a:b]
    b = np.searchsorted(cum, t[1:], side="left")

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    pre = np.concatenate([[0.0], np.cumsum(cross(p[:-1], p[1:]))])  # pre[j]: the polyline's terms before point j
    ai, bi = np.minimum(a, k - 1), np.clip(b - 1, 0, k - 1)
    ring = cross(q[:-1], p[ai]) + (pre[np.maximum(bi, ai)] - pre[ai]) + cross(p[bi], q[1:]) + cross(q[1:], q[:-1])
    return np.where(b > a, 0.5 * ring, 0.0)


def lean_curve_floors(chains: Sequence[np.ndarray], budget: float, size: float | None = None) -> np.ndarray:
    """``(C,) int64`` the floors of the curved boundary sides ``chains[i] (k_i, 2)`` (user units,
    each run along a counter-clockwise patch loop: the region on its left): edge counts that keep
    the region's area within ``budget`` (user units squared), the budget allocated where it pays.

    Signs: a piece's chord cuts area off the region where the side is convex there and adds area
    where it is concave (:func:`chord_piece_areas`), and the area check is signed
    (``|mesh area / region - 1| <= area_tol``). If the pieces that lose area lose at most
    ``budget`` in all and those that add area add at most ``budget``, the net change is at most
    ``budget``: each sign group has the whole budget (a side with pieces of both signs counts in
    both).

    Allocation by marginal gain: every side starts at its size count (``round(length / size)``,
    at least 1; 1 without ``size``) and, while a sign group's total exceeds ``budget``, the side
    whose next edge lowers the exceeding groups' totals most per unit of size deviation gets it
    (the deviation of ``n`` edges of length ``L / n``: ``n * log(L / (n size))^2``; without
    ``size``, per edge). Greedy: the least deviation (the fewest edges) for one sign group when
    each side's error is convex and decreasing in its count, as a circular arc's is (~ 1 / n^2).
    A small hole or slot end keeps about its size count (its error is small) and the budget goes
    to the long arcs, where an edge more stays near the size. A side stops at ``4 * k_i`` edges.
    The floors keep their meaning as long as a side's errors fall as edges are added (at or
    above its floor, whatever count is chosen)."""
    C = len(chains)
    if not C:
        return np.zeros(0, np.int64)
    lengths = np.array([float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum()) for c in chains])
    n = np.ones(C, np.int64) if size is None else np.maximum(1, np.rint(lengths / float(size))).astype(np.int64)
    cap = np.array([4 * c.shape[0] for c in chains], np.int64)
    n = np.minimum(n, cap)

    def groups(i: int, m: int) -> np.ndarray:  # (2,) area lost, area added
        a = chord_piece_areas(chains[i], m)
        return np.array([a[a > 0].sum(), -a[a < 0].sum()])

    now = np.array([groups(i, int(n[i])) for i in range(C)])  # (C, 2)
    nxt = np.array([groups(i, int(n[i]) + 1) for i in range(C)])
    total = now.sum(axis=0)
    x = None if size is None else np.maximum(lengths / float(size), 1e-12)  # (the size counts, unrounded)

    def cost(m: np.ndarray) -> np.ndarray:  # edges, or their squared log distance to the size
        return m.astype(np.float64) if x is None else m * np.log(m / x) ** 2

    while np.any(total > budget):
        over = (total > budget).astype(np.float64)
        gain = np.where(n < cap, (now - nxt) @ over / np.maximum(cost(n + 1) - cost(n), 1e-12), -np.inf)
        i = int(np.argmax(gain))
        if not np.isfinite(gain[i]):
            break
        n[i] += 1
        total += nxt[i] - now[i]
        now[i], nxt[i] = nxt[i], groups(i, int(n[i]) + 1)
    return n


CURVE_BATCH = 2048
"""Pieces measured together (:func:`chord_area_errors`) in the search for a curved side's fewest
pieces (:func:`_fewest_pieces`): the doubling counts up to this many pieces in all, then every
count between the last two if they are at most this many."""


CURVE_POINTS = 64
"""A side of at most this many points is measured at the doubling counts of
:func:`_fewest_pieces` together with its one chord (:func:`_first_errors`), before it is known to
need them: a short side's extra counts cost less than another call; a long, straight side (a
densely traced outline) is measured at one piece only."""


def _doubling(k: int) -> list[int]:
    """The counts :func:`_fewest_pieces` doubles through on a side of ``k`` points (2, 4, ... up
    to the first at least ``4 k``) that fit in :data:`CURVE_BATCH` pieces in all."""
    steps = [2]
    while steps[-1] < 4 * k:
        steps.append(steps[-1] * 2)
    return [n for n, total in zip(steps, np.cumsum(steps)) if total <= CURVE_BATCH]


def _one_chord_error(poly: np.ndarray) -> float:
    """:func:`chord_area_error` of the side ``poly (k, 2)`` at one piece (the value
    :func:`_first_errors` gives for count 1); 0.0 for a two-point side."""
    return 0.0 if poly.shape[0] <= 2 else float(chord_area_errors(poly, [1])[0])


def _first_errors(poly: np.ndarray) -> dict[int, float]:
    """``{count: error}`` (:func:`chord_area_error`) of the side ``poly (k, 2)`` at one piece and,
    up to :data:`CURVE_POINTS` points, at the counts of :func:`_doubling`, in one
    :func:`chord_area_errors` call; ``{1: 0.0}`` for a two-point side."""
    if poly.shape[0] <= 2:
        return {1: 0.0}
    counts = [1] + (_doubling(poly.shape[0]) if poly.shape[0] <= CURVE_POINTS else [])
    return dict(zip(counts, chord_area_errors(poly, counts).tolist()))


def _fewest_pieces(poly: np.ndarray, budget: float, known: dict[int, float] | None = None) -> int:
    """The pieces that :func:`curve_floors` gives the curved side ``poly (k, 2)`` for ``budget``
    (user units squared), whose one chord exceeds it: counts doubled from 2 until the error
    (:func:`chord_area_error`) keeps the budget or the count reaches ``4 k``, then halved back to
    the fewest that keep it (the error falls as pieces are added). The counts it may ask for are
    measured in two batches (:data:`CURVE_BATCH`; ``known``: :func:`_first_errors` of ``poly``,
    the first of them, when the caller has it): each costs about as much as one count alone, and
    a count's error is the same however it is asked for (the same floors, tested)."""
    most = poly.shape[0] * 4
    known = dict(_first_errors(poly) if known is None else known)

    def ask(counts) -> None:
        new = [n for n in counts if n not in known]
        if new:
            known.update(zip(new, chord_area_errors(poly, new).tolist()))

    ask(_doubling(poly.shape[0]))
    lo, hi = 1, 2
    while True:
        ask([hi])
        if not (known[hi] > budget and hi < most):
            break
        lo, hi = hi, hi * 2
    between = range(lo + 1, hi)
    if sum(between) <= CURVE_BATCH:
        ask(between)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        ask([mid])
        lo, hi = (lo, mid) if known[mid] <= budget else (mid, hi)
    return hi
