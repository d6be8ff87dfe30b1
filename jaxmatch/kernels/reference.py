"""Plain-Python reference scorers (no JAX, deliberately simple and slow).

Same problem and orientation convention as :mod:`jaxmatch.scoring.exact`: orientation ``s = vals``
(or ``vals[::-1]`` when reflected), rotated so ``s_r[0] = s[r]``; triple of ``s_r[j]`` is
``[s_r[j+1], s_r[j], s_r[j-1]]``; ``table[code][u-2][v-2][w-2]`` with ``-inf`` = forbidden;
``skip[code]`` (default 0) is added for every shape point left without a mesh vertex, ``-inf``
= that point must get one. The DP here is the plain recurrence
``D[i][j] = max(D[i-1][j] + skip[code[i-1]], D[i-1][j-1] + W[i-1, j-1])`` (no shifted frame).
Orientations are tried in the order rotations ``0..n-1`` of ``vals``, then of ``vals[::-1]``,
alignments in :func:`itertools.combinations` order; only a strictly better utility replaces
the incumbent, so ties keep the first.
"""

from __future__ import annotations

import itertools
import math


def _table(table):
    """Nested lists of Python floats ``t[c][u][v][w]``."""
    if hasattr(table, "tolist"):
        table = table.tolist()
    return [[[[float(x) for x in row] for row in plane] for plane in cube] for cube in table]


def orientations(vals):
    """``[(rotation, reflected, sequence)]``: all ``2n`` oriented valence sequences."""
    vals = [int(v) for v in vals]
    n = len(vals)
    out = []
    for reflected in (False, True):
        s = vals[::-1] if reflected else vals
        for r in range(n):
            out.append((r, reflected, s[r:] + s[:r]))
    return out


def triples(seq):
    """``[[s[j+1], s[j], s[j-1]] for j]`` (cyclic)."""
    n = len(seq)
    return [[seq[(j + 1) % n], seq[j], seq[(j - 1) % n]] for j in range(n)]


def _skip(skip):
    """Three Python floats (0 when None)."""
    if skip is None:
        return [0.0, 0.0, 0.0]
    if hasattr(skip, "tolist"):
        skip = skip.tolist()
    return [float(x) for x in skip]


def _weights(codes, seq, t):
    """``W[i][j]`` = weight of input point ``i`` against oriented vertex ``j``."""
    tr = triples(seq)
    return [[t[int(c)][u - 2][v - 2][w - 2] for (u, v, w) in tr] for c in codes]


def all_utilities(codes, vals, table, skip=None):
    """Every ``(utility, rotation, reflected, alignment)``, over all orientations and all
    strictly increasing alignments (empty when ``n > m``); utility = matched weights + skip
    weights of the points not in the alignment."""
    t = _table(table)
    sk = _skip(skip)
    codes = [int(c) for c in codes]
    out = []
    for r, reflected, seq in orientations(vals):
        w = _weights(codes, seq, t)
        for alignment in itertools.combinations(range(len(codes)), len(seq)):
            taken = set(alignment)
            u = sum(w[i][j] for j, i in enumerate(alignment)) + sum(sk[c] for i, c in enumerate(codes) if i not in taken)
            out.append((u, r, reflected, alignment))
    return out


def brute_force(codes, vals, table, skip=None):
    """``(best_utility, rotation, reflected, alignment)`` by enumeration.

    ``(-inf, None, None, None)`` when unmatchable (no finite alignment, or ``n > m``).
    """
    best = (-math.inf, None, None, None)
    for u, r, reflected, alignment in all_utilities(codes, vals, table, skip):
        if u > best[0]:
            best = (u, r, reflected, list(alignment))
    return best


def brute_force_soft(codes, vals, table, gamma, skip=None):
    """``gamma * log(sum over all (orientation, alignment) of exp(utility / gamma))``.

    Forbidden alignments contribute ``exp(-inf) = 0``; ``-inf`` when none is finite.
    """
    us = [u for u, *_ in all_utilities(codes, vals, table, skip) if u > -math.inf]
    if not us:
        return -math.inf
    top = max(us)
    return top + gamma * math.log(sum(math.exp((u - top) / gamma) for u in us))


def dp_reference(codes, vals, table, skip=None):
    """Best utility by the plain ``O(n * n * m)`` DP over all ``2n`` orientations; ``-inf``
    when unmatchable."""
    t = _table(table)
    sk = _skip(skip)
    codes = [int(c) for c in codes]
    m = len(codes)
    best = -math.inf
    for _, _, seq in orientations(vals):
        n = len(seq)
        if n > m:
            return -math.inf
        w = _weights(codes, seq, t)
        d = [0.0] + [-math.inf] * n
        for i in range(m):
            s = sk[codes[i]]
            new = [d[0] + s] + [max(d[j] + s, d[j - 1] + w[i][j - 1]) for j in range(1, n + 1)]
            d = new
        best = max(best, d[n])
    return best
