"""Compiled forward pass and tie walk of :func:`jaxmatch.placement.choose.spread_optimal_alignment`
in numba: the fallback of :mod:`jaxmatch.kernels.placement` where the C library was not built
(imported on first use, cached on disk after the first compile).

The numpy version (``spread_optimal_alignment(..., reference=True)``) builds ``(S, m, m)``
arrays per vertex; here the same lexicographic recurrence runs as loops, and the walk over
tied alignments is an explicit depth-first search in the same order (tests compare both).
"""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def forward(E, between, gq, U0, ties_wanted):  # pragma: no cover - compiled
    """Lexicographic DP: best utility, then least gap cost.

    E: ``(n, m)`` pair weights (``-inf`` allowed); between: ``(m, m)`` ``[i', i]`` skip weight of
    the points strictly between ``i'`` and ``i``; gq: ``(m, m)`` ``[i', i]`` integer-valued gap
    costs; U0: ``(S, m)`` utilities of vertex 0 on each point for each start (``-inf`` off the
    start). Returns ``(U (S, m), G (S, m), back (n, S, m) int64, ties (n, S, m, m) bool)``, as
    the numpy version: ``back[j, s, i]`` the first ``i'`` of least gap cost among those of best
    utility; ``ties[j, s, i, i']`` all of them (only when ``ties_wanted``; else shape
    ``(n, S, m, 0)``).
    """
    n, m = E.shape
    S = U0.shape[0]
    U = U0.copy()
    G = np.zeros((S, m))
    back = np.zeros((n, S, m), np.int64)
    ties = np.zeros((n, S, m, m if ties_wanted else 0), np.bool_)
    Un = np.empty((S, m))
    Gn = np.empty((S, m))
    tot = np.empty(m)
    for j in range(1, n):
        for s in range(S):
            for i in range(m):
                bu = -np.inf
                for ip in range(m):
                    t = U[s, ip] + between[ip, i] + E[j, i]
                    tot[ip] = t
                    if t > bu:
                        bu = t
                gmin = np.inf
                arg = 0
                for ip in range(m):
                    if tot[ip] == bu:
                        tg = G[s, ip] + gq[ip, i]
                        if tg < gmin:
                            gmin = tg
                            arg = ip
                Un[s, i] = bu
                Gn[s, i] = gmin
                back[j, s, i] = arg
                if ties_wanted and np.isfinite(gmin):
                    for ip in range(m):
                        if tot[ip] == bu and G[s, ip] + gq[ip, i] == gmin:
                            ties[j, s, i, ip] = True
        U[:, :] = Un
        G[:, :] = Gn
    return U, G, back, ties


@numba.njit(cache=True, nogil=True)
def walk(ties, ends, limit):  # pragma: no cover - compiled
    """Every tied alignment, depth first (smaller points first), at most ``limit``.

    ties: ``(n, S, m, m)`` from :func:`forward`; ends: ``(e, 2)`` ``(start, last point)`` pairs
    to walk back from, in order. Returns ``(count, n) int64`` alignments.
    """
    n = ties.shape[0]
    m = ties.shape[2]
    out = np.empty((limit, n), np.int64)
    count = 0
    p = np.empty(n, np.int64)
    nxt = np.zeros(n, np.int64)
    for e in range(ends.shape[0]):
        s = ends[e, 0]
        p[n - 1] = ends[e, 1]
        if n == 1:
            if count >= limit:
                return out[:count]
            out[count, 0] = p[0]
            count += 1
            continue
        j = n - 1
        nxt[j] = 0
        while j < n:
            found = -1
            for ip in range(nxt[j], m):
                if ties[j, s, p[j], ip]:
                    found = ip
                    break
            if found < 0:
                j += 1
                continue
            nxt[j] = found + 1
            p[j - 1] = found
            if j - 1 == 0:
                if count >= limit:
                    return out[:count]
                out[count, :] = p
                count += 1
            else:
                j -= 1
                nxt[j] = 0
    return out[:count]


@numba.njit(cache=True, nogil=True)
def candidates(codes, seqs, table, between, prefix, suffix, gq, tt, perimeter, unit, limit):  # pragma: no cover
    """:func:`forward` and :func:`walk` for several orientations of one mesh at once (what
    ``choose.match_candidates`` asks of ``spread_optimal_alignment(..., all_ties=True)`` for
    each orientation).

    codes: ``(m,) int64``; seqs: ``(O, n) int64`` oriented valence sequences; table: ``(3, 64)``
    pairing weights (``-inf`` forbidden); between / prefix / suffix / gq / tt / perimeter / unit:
    as in ``choose._SpreadSetup``. Returns ``(utility (O,), gap cost (O,), orientation (K,),
    alignments (K, n))``: per orientation its best utility and least gap cost, and its tied
    alignments (at most ``limit`` each) in walk order; ``-inf`` utility: no alignment.
    """
    O, n = seqs.shape
    m = codes.shape[0]
    util = np.full(O, -np.inf)
    gap = np.zeros(O)
    outs = []
    owner = []
    for o in range(O):
        E = np.empty((n, m))
        for j in range(n):
            f = 16 * (seqs[o, (j + 1) % n] - 2) + 4 * (seqs[o, j] - 2) + (seqs[o, (j - 1 + n) % n] - 2)
            for i in range(m):
                E[j, i] = table[codes[i], f]
        B = E[n - 1] + suffix
        for j in range(n - 2, -1, -1):
            Bn = np.empty(m)
            for i in range(m):
                mx = -np.inf
                for ip in range(m):
                    v = between[i, ip] + B[ip]
                    if v > mx:
                        mx = v
                Bn[i] = E[j, i] + mx
            B = Bn
        total = prefix + B
        best = total.max()
        if not np.isfinite(best):
            continue
        starts = np.flatnonzero(total == best)
        S = starts.shape[0]
        U0 = np.full((S, m), -np.inf)
        for s in range(S):
            U0[s, starts[s]] = prefix[starts[s]] + E[0, starts[s]]
        U, G, back, ties = forward(E, between, gq, U0, True)
        g_min = np.inf
        for s in range(S):
            for i in range(m):
                g = G[s, i] + np.rint((perimeter - tt[i] + tt[starts[s]]) ** 2 / unit)
                G[s, i] = g if U[s, i] + suffix[i] == best else np.inf
                if G[s, i] < g_min:
                    g_min = G[s, i]
        cnt = 0
        for s in range(S):
            for i in range(m):
                if G[s, i] == g_min:
                    cnt += 1
        ends = np.empty((cnt, 2), np.int64)
        cnt = 0
        for s in range(S):
            for i in range(m):
                if G[s, i] == g_min:
                    ends[cnt, 0] = s
                    ends[cnt, 1] = i
                    cnt += 1
        util[o] = best
        gap[o] = g_min
        als = walk(ties, ends, limit)
        for r in range(als.shape[0]):
            outs.append(als[r].copy())
            owner.append(o)
    K = len(outs)
    A = np.empty((K, n), np.int64)
    own = np.empty(K, np.int64)
    for r in range(K):
        A[r] = outs[r]
        own[r] = owner[r]
    return util, gap, own, A


@numba.njit(cache=True, nogil=True)
def orientation_utilities(codes, vals, table, skip):  # pragma: no cover - compiled
    """Best utility of every orientation of one mesh (``choose.orientation_utilities``):
    codes ``(m,) int64``, vals ``(n,) int64``, table ``(3, 64)`` and skip ``(3,)`` float64
    with ``-inf``. Returns ``(2n,)``: rotation ``o``, then reflected rotations."""
    n = vals.shape[0]
    m = codes.shape[0]
    out = np.empty(2 * n)
    seq = np.empty(n, np.int64)
    W = np.empty((n, m))
    D = np.empty(n + 1)
    for o in range(2 * n):
        for j in range(n):
            seq[j] = vals[(j + o) % n] if o < n else vals[n - 1 - (j + o - n) % n]
        for j in range(n):
            f = 16 * (seq[(j + 1) % n] - 2) + 4 * (seq[j] - 2) + (seq[(j - 1 + n) % n] - 2)
            for i in range(m):
                W[j, i] = table[codes[i], f]
        D[0] = 0.0
        for j in range(1, n + 1):
            D[j] = -np.inf
        for i in range(m):
            sk = skip[codes[i]]
            for j in range(n, 0, -1):
                a = D[j] + sk
                b = D[j - 1] + W[j - 1, i]
                D[j] = a if a > b else b
            D[0] = D[0] + sk
        out[o] = D[n]
    return out
