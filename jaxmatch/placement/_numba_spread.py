"""Compiled forward pass and tie walk of :func:`jaxmatch.placement.choose.spread_optimal_alignment`
(numba; imported on first use, cached on disk after the first compile).

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
