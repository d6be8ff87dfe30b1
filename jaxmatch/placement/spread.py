"""Where a match's boundary vertices go along the outline: among the alignments of equal
utility, the most evenly spread one.

The utility of an alignment depends only on the codes of the points its vertices take, so a
scorer's alignment (which only maximises utility and often packs the vertices into a few
neighbouring points) can be replaced by any alignment with the same codes, or, given the
lattice, by the best-utility alignment of least squared arc-length gaps. This module holds those
dynamic programmes (numpy references of the compiled ones in :mod:`jaxmatch.kernels.placement`):
:func:`spread_alignment` (same codes), :func:`orientation_utilities` (the best utility of every
orientation of a mesh), :func:`spread_optimal_alignment` (best utility, then least gaps, with
every tie on request) and the lattice as they read it (:func:`lattice_weights`).
:func:`jaxmatch.placement.choose.place_match` uses them to place a ranked mesh.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.cache import Cache
from jaxmatch.cache import key as cache_key
from jaxmatch.kernels import placement as kernels
from jaxmatch.kernels.model import weights_of

__all__ = [
    "GAP_UNIT",
    "MAX_TIED_ALIGNMENTS",
    "SPREAD_MAX_WORK",
    "SpreadSetup",
    "gap_cost",
    "lattice_weights",
    "orientation_utilities",
    "spread_setup",
    "spread_alignment",
    "spread_optimal_alignment",
]

SPREAD_MAX_WORK = 40_000_000
"""Largest ``starts * m * m * n`` the exact :func:`spread_alignment` DP may cost; beyond it the
first vertex is only tried on the points nearest its given one (about 0.3 s of numpy)."""


def spread_alignment(t: np.ndarray, perimeter: float, codes: np.ndarray, alignment: np.ndarray) -> np.ndarray:
    """An alignment with the same utility as ``alignment`` whose vertices are spread evenly.

    t: (m,) increasing arc-length parameters of the annotated points in ``[0, perimeter)``;
    codes: (m,) point codes (s/x/v); alignment: (n,) strictly increasing indices (a match's).

    The utility of an alignment is the sum of ``weight[codes[i_j], triple_j]``, so every
    strictly increasing ``i'`` with ``codes[i'_j] == codes[alignment[j]]`` for all ``j`` has
    exactly the same utility, whatever the lattice. Among those, this returns the one that
    minimises the sum of squared arc-length gaps between cyclically consecutive vertices
    (the gap after the last vertex wraps around to the first), i.e. the most even spacing
    along the outline: the scorer's own alignment only maximises utility and often packs the
    vertices into a few neighbouring points. Exact dynamic programme over (first vertex,
    vertex, point), ``O(starts * n * m^2)``; the first vertex is tried on every point of its
    code (on the nearest ones only when that exceeds :data:`SPREAD_MAX_WORK`). Ties keep the
    smaller indices. Returns ``(n,) int64``; ``alignment`` itself when ``n < 2``.
    """
    tt = np.asarray(t, dtype=np.float64).ravel()
    c = np.asarray(codes).ravel()
    al = np.asarray(alignment, dtype=np.int64).ravel()
    n, m = al.shape[0], tt.shape[0]
    if n < 2:
        return al.copy()
    want = c[al]  # (n,) code of each vertex's point
    need = np.bincount(want, minlength=3).tolist()
    have = np.bincount(c, minlength=len(need)).tolist()  # (every wanted code is some point's: no longer than need)
    if need == [h if k > 0 else 0 for k, h in zip(need, have)]:
        return al.copy()  # as many points of each wanted code as vertices want it: no other alignment
    ok = c[None, :] == want[:, None]  # (n, m) allowed points per vertex
    starts = np.flatnonzero(ok[0])
    if starts.size * m * m * n > SPREAD_MAX_WORK:
        keep = max(SPREAD_MAX_WORK // (m * m * n), 1)
        starts = starts[np.argsort(np.abs(starts - al[0]), kind="stable")[:keep]]
        starts = np.union1d(starts, al[:1])
    if kernels.BACKEND == "c":  # the same programme compiled (the same doubles, the same ties)
        out = kernels.spread(tt, float(perimeter), ok, starts)
        return al.copy() if out is None else out
    S = starts.size
    inf = np.inf
    gap2 = (tt[:, None] - tt[None, :]) ** 2  # [i, i']
    gap2 = np.where(np.arange(m)[None, :] < np.arange(m)[:, None], gap2, inf)  # only i' < i
    D = np.full((S, m), inf)
    D[np.arange(S), starts] = 0.0
    back = np.zeros((n, S, m), dtype=np.int32)
    for j in range(1, n):
        tot = D[:, None, :] + gap2[None, :, :]  # (S, i, i')
        arg = np.argmin(tot, axis=2)
        D = tot.min(axis=2)  # the values at arg (no NaN here: sums of finite gaps and inf)
        D[:, ~ok[j]] = inf
        back[j] = arg
    closing = (perimeter - tt[None, :] + tt[starts][:, None]) ** 2
    total = D + closing
    flat = int(np.argmin(total))
    if not np.isfinite(total.flat[flat]):  # cannot happen: ``alignment`` itself is feasible
        return al.copy()
    s, i = divmod(flat, m)
    out = np.empty(n, np.int64)
    for j in range(n - 1, -1, -1):
        out[j] = i
        i = int(back[j, s, i])
    return out


def gap_cost(t: np.ndarray, perimeter: float, alignment: np.ndarray) -> float:
    """Sum of squared cyclic arc-length gaps between consecutive aligned points (what
    :func:`spread_alignment` minimises)."""
    ta = np.asarray(t, dtype=np.float64)[np.asarray(alignment, dtype=np.int64)]
    g = np.diff(np.concatenate([ta, [ta[0] + perimeter]]))
    return float(np.sum(g * g))


# ---------------------------------------------------------------------------------------------
# the lattice as the placement sees it


def lattice_weights(lattice) -> tuple[np.ndarray, np.ndarray]:
    """``(table (3, 64) float64, skip (3,) float64)`` of a lattice: the pairing weights
    ``[code, 16 (u-2) + 4 (v-2) + (w-2)]`` and the weight of skipping a point of each code
    (``-inf``: forbidden; zeros for a lattice without skip weights, the paper's free skipping).
    ``lattice``: a :class:`~jaxmatch.scoring.lattice.Lattice` or :class:`~jaxmatch.kernels.model.Weights`, or a ``(table, skip)`` pair."""
    if isinstance(lattice, tuple):
        table, skip = lattice
        tab = np.asarray(table, dtype=np.float64).reshape(3, 64)
        sk = np.zeros(3) if skip is None else np.asarray(skip, dtype=np.float64).reshape(3)
        return tab, sk
    w = weights_of(lattice)  # compiled once per lattice
    return w.table_inf().astype(np.float64).reshape(3, 64), w.skip_inf().astype(np.float64)


def _pair_weights(codes: np.ndarray, seq: np.ndarray, table: np.ndarray) -> np.ndarray:
    """``(..., n, m)``: weight of oriented vertex ``j`` (valences ``seq (..., n)``) on point ``i``."""
    t = np.stack([roll(seq, -1, axis=-1), seq, roll(seq, 1, axis=-1)], axis=-1) - 2
    flat = t[..., 0] * 16 + t[..., 1] * 4 + t[..., 2]  # (..., n)
    return table[codes[None, :], flat[..., None]]


def orientation_utilities(codes, vals, lattice, *, reference: bool = False) -> np.ndarray:
    """Utility of every orientation of one mesh, ``(2n,) float64`` (``-inf``: none).

    codes: (m,) point codes; vals: (n,) ccw boundary valences; orientation ``o < n`` is
    rotation ``o``, ``o >= n`` rotation ``o - n`` reflected (as in :mod:`jaxmatch.scoring.exact`).
    Plain numpy, the recurrence ``D[i][j] = max(D[i-1][j] + skip[code[i-1]], D[i-1][j-1] +
    W[i-1, j-1])`` for all orientations at once; compiled
    (:func:`jaxmatch.kernels.placement.orientation_utilities`), ``reference``: numpy."""
    c = np.asarray(codes, dtype=np.int64).ravel()
    v = np.asarray(vals, dtype=np.int64).ravel()
    table, skip = lattice_weights(lattice)
    n, m = v.shape[0], c.shape[0]
    if not reference and kernels.BACKEND == "c" and n > 0:
        return kernels.orientation_utilities(c, v, np.ascontiguousarray(table), np.ascontiguousarray(skip))
    rot = (np.arange(n)[:, None] + np.arange(n)[None, :]) % n
    seqs = np.concatenate([v[rot], v[::-1][rot]])  # (2n, n)
    W = _pair_weights(c, seqs, table)  # (2n, n, m)
    D = np.full((2 * n, n + 1), -np.inf)
    D[:, 0] = 0.0
    for i in range(m):
        sk = skip[c[i]]
        take = D[:, :-1] + W[:, :, i]
        D = D + sk
        D[:, 1:] = np.maximum(D[:, 1:], take)
    return D[:, n]


MAX_TIED_ALIGNMENTS = 64
"""At most this many equally good alignments of one orientation are listed
(:func:`spread_optimal_alignment` with ``all_ties``)."""

GAP_UNIT = 1e-12
"""Squared arc-length gaps are compared in integer multiples of ``GAP_UNIT * perimeter**2``,
so that equal spacings compare equal whatever the round-off of where the loop starts."""


def spread_optimal_alignment(t: np.ndarray, perimeter: float, codes: np.ndarray, seq: np.ndarray,
                             lattice, *, all_ties: bool = False, reference: bool = False,
                             cache: Cache | None = None) -> tuple[float, np.ndarray | None, int]:
    """The alignment of the oriented sequence ``seq`` with the highest utility, and among those
    the most evenly spread one.

    t: (m,) arc-length parameters in ``[0, perimeter)``, increasing; codes: (m,); seq: (n,)
    valences in matched order. Utility: pairing weights plus skip weights of unmatched points
    (cyclically all of them). Spread: sum of squared cyclic arc-length gaps between consecutive
    vertices (in units of :data:`GAP_UNIT` ``* perimeter**2``, rounded). Exact lexicographic
    dynamic programme over (first point, vertex, point); only first points that start an
    optimal alignment are tried. Returns ``(utility, alignment (n,) int64 or None, gap cost)``;
    with ``all_ties`` a list in place of the one alignment: every alignment with the best
    utility and the smallest gap cost (at most :data:`MAX_TIED_ALIGNMENTS`), since which of
    several equally good ones a single answer picks depends on where the loop is labelled to
    start.

    Compiled (:func:`jaxmatch.kernels.placement.candidates` for the one orientation);
    ``reference``: the numpy version it is tested against. ``cache``: where the shape's
    :func:`spread_setup` is kept.
    """
    sq = np.asarray(seq, dtype=np.int64).ravel()
    tt, c, table, between, prefix, suffix, unit, gq = spread_setup(t, perimeter, codes, lattice, cache)
    n, m = sq.shape[0], c.shape[0]
    if n == 0 or n > m:
        return -math.inf, ([] if all_ties else None), 0
    E = _pair_weights(c, sq, table)  # (n, m)
    # backward best utilities: B[j][i] with vertex j on point i, vertices j.. and the suffix
    B = E[n - 1] + suffix
    for j in range(n - 2, -1, -1):
        B = E[j] + np.max(between + B[None, :], axis=1)
    total = prefix + B
    best = float(np.max(total))
    if not np.isfinite(best):
        return best, ([] if all_ties else None), 0
    starts = np.flatnonzero(total == best)
    S = starts.size
    U = np.full((S, m), -np.inf)
    U[np.arange(S), starts] = prefix[starts] + E[0, starts]
    if not reference and kernels.BACKEND == "c":  # the same DP compiled; its first tied alignment is the backtrack's
        _, gap, _, A = kernels.candidates(c, sq[None, :], table, between, prefix, suffix, gq, tt, float(perimeter), unit,
                                          MAX_TIED_ALIGNMENTS if all_ties else 1)
        return best, (list(A) if all_ties else A[0].copy()), int(gap[0])
    U, G, back, ties = _spread_forward(E, between, gq, U, all_ties)
    U = U + suffix[None, :]
    G = G + np.round((perimeter - tt[None, :] + tt[starts][:, None]) ** 2 / unit)
    G = np.where(U == best, G, np.inf)
    g_min = float(G.min())
    if not all_ties:
        s_, i = divmod(int(np.argmin(G)), m)
        out = np.empty(n, np.int64)
        for j in range(n - 1, -1, -1):
            out[j] = i
            i = int(back[j, s_, i])
        return best, out, int(g_min)
    ends = np.stack(np.nonzero(G == g_min), axis=1).astype(np.int64)
    outs = _spread_walk(ties, ends)
    return best, outs, int(g_min)


class SpreadSetup(NamedTuple):
    """What :func:`spread_optimal_alignment` needs of the shape and the lattice, whatever the
    mesh: tt ``(m,)``, c ``(m,) int64``, table ``(3, 64)``, between ``(m, m)`` ``[i', i]`` (skip
    weight of the points strictly between), prefix / suffix ``(m,)`` (of the points before /
    after ``i``), unit (the gap unit), gq ``(m, m)`` ``[i', i]`` squared gaps in units."""

    tt: np.ndarray
    c: np.ndarray
    table: np.ndarray
    between: np.ndarray
    prefix: np.ndarray
    suffix: np.ndarray
    unit: float
    gq: np.ndarray


def spread_setup(t, perimeter, codes, lattice, cache: Cache | None = None) -> SpreadSetup:
    """:class:`SpreadSetup` of one shape annotation and lattice (kept in ``cache``, store
    ``spread``: every orientation of every mesh placed for one shape shares it)."""
    tt = np.ascontiguousarray(np.asarray(t, dtype=np.float64).ravel())
    c = np.ascontiguousarray(np.asarray(codes, dtype=np.int64).ravel())
    table, skip = lattice_weights(lattice)
    if cache is None:
        return _make_setup(tt, float(perimeter), c, table, skip)
    return cache.get("spread", cache_key(tt, float(perimeter), c, table, skip),
                     lambda: _make_setup(tt, float(perimeter), c, table, skip))


def _make_setup(tt: np.ndarray, perimeter: float, c: np.ndarray, table: np.ndarray, skip: np.ndarray) -> SpreadSetup:
    """:func:`spread_setup`, made."""
    tt, c, table, skip = tt.copy(), c.copy(), table.copy(), skip.copy()
    m = c.shape[0]
    sk = skip[c]
    fin = np.isfinite(sk)
    P = np.concatenate([[0.0], np.cumsum(np.where(fin, sk, 0.0))])  # finite skip sums
    Fb = np.concatenate([[0], np.cumsum(~fin)])  # forbidden-skip counts

    def skipped(a, b):  # skip weight of points a..b-1 (arrays broadcast)
        return np.where(Fb[b] - Fb[a] > 0, -np.inf, P[b] - P[a])

    idx = np.arange(m)
    between = np.where(idx[:, None] < idx[None, :], skipped(np.minimum(idx[:, None] + 1, m), np.maximum(idx[None, :], idx[:, None] + 1)), -np.inf)  # [i', i]
    prefix = skipped(np.zeros(m, np.int64), idx)  # points before i
    suffix = skipped(np.minimum(idx + 1, m), np.full(m, m))  # points after i
    unit = GAP_UNIT * perimeter * perimeter
    gq = np.round((tt[None, :] - tt[:, None]) ** 2 / unit)  # [i', i]
    out = SpreadSetup(tt, c, table, np.ascontiguousarray(between), prefix, suffix, unit, np.ascontiguousarray(gq))
    for a in out:
        if isinstance(a, np.ndarray):
            a.setflags(write=False)
    return out


def _spread_forward(E, between, gq, U, all_ties):
    """numpy forward pass of :func:`spread_optimal_alignment` (the reference of
    the compiled forward pass): ``(U, G, back, ties)`` with ``ties[j][(s, i)]`` the points ``i'``
    of vertex ``j - 1`` that tie for vertex ``j`` on ``i`` (a dict per vertex)."""
    n = E.shape[0]
    S, m = U.shape
    G = np.zeros((S, m))
    back = np.zeros((n, S, m), np.int64)
    ties = [None] * n
    for j in range(1, n):
        tot = U[:, None, :] + between.T[None, :, :] + E[j][None, :, None]  # (S, i, i')
        bu = tot.max(axis=2)
        tg = np.where(tot == bu[..., None], G[:, None, :] + gq.T[None, :, :], np.inf)
        arg = np.argmin(tg, axis=2)
        U = bu
        G = np.take_along_axis(tg, arg[..., None], axis=2)[..., 0]
        back[j] = arg
        if all_ties:
            tj: dict[tuple[int, int], list[int]] = {}
            for a, b, c in zip(*[x.tolist() for x in np.nonzero((tg == G[..., None]) & np.isfinite(tg))]):
                tj.setdefault((a, b), []).append(c)
            ties[j] = tj
    return U, G, back, ties


def _spread_walk(ties, ends) -> list[np.ndarray]:
    """Every tied alignment from the ``(start, last point)`` pairs ``ends``, depth first, at
    most :data:`MAX_TIED_ALIGNMENTS` (the reference of the compiled walk)."""
    n = len(ties)
    outs: list[np.ndarray] = []

    def walk(s_, j, i, tail):
        if len(outs) >= MAX_TIED_ALIGNMENTS:
            return
        if j == 0:
            outs.append(np.array([i, *tail], np.int64))
            return
        for ip in ties[j].get((s_, i), ()):
            walk(s_, j - 1, ip, [i, *tail])

    for s_, i in ends.tolist():
        walk(int(s_), n - 1, int(i), [])
    return outs
