"""Compiled (numba) canonical keys: the same keys as :func:`jaxmatch.catalogue.canon.canonical`.

The catalogue generator computes a canonical key for every candidate disk, which dominates
its run time in pure Python. This module computes the *identical* key (so mesh ids are the
same) with numba: dense ``(V, V)`` edge-owner tables instead of dicts, and the breadth-first
traversal from each minimal boundary start compiled. ``tests/test_canon.py`` checks it against
the pure-Python implementation, which the independent shelling enumerator keeps using.
"""

from __future__ import annotations

import numba
import numpy as np

from jaxmatch.catalogue.canon import Canonical


@numba.njit(cache=True)
def _min_rot_starts(seq):
    """Starts of the lexicographically smallest rotations of seq (n,) -> (starts, count)."""
    n = seq.shape[0]
    starts = np.empty(n, np.int64)
    count = 0
    best = 0
    for i in range(n):
        if i == 0:
            starts[0] = 0
            count = 1
            continue
        cmp = 0
        for j in range(n):
            a = seq[(i + j) % n]
            b = seq[(best + j) % n]
            if a != b:
                cmp = -1 if a < b else 1
                break
        if cmp < 0:
            best = i
            starts[0] = i
            count = 1
        elif cmp == 0:
            starts[count] = i
            count += 1
    return starts, count


@numba.njit(cache=True)
def _codes(quads, boundary, vals):
    """Minimal ccw code over minimal-sequence starts: (best_seq, best_code, first start, ties)."""
    nq = quads.shape[0]
    nv = 0
    for q in range(nq):
        for c in range(4):
            if quads[q, c] + 1 > nv:
                nv = quads[q, c] + 1
    own = np.full((nv, nv), -1, np.int64)
    for q in range(nq):
        for c in range(4):
            own[quads[q, c], quads[q, (c + 1) % 4]] = q * 4 + c
    nbr = np.full(nq * 4, -1, np.int64)
    for q in range(nq):
        for c in range(4):
            o = own[quads[q, (c + 1) % 4], quads[q, c]]
            nbr[q * 4 + c] = o
    n = boundary.shape[0]
    seq = np.empty(n, np.int64)
    for i in range(n):
        seq[i] = vals[boundary[i]]
    starts, count = _min_rot_starts(seq)
    best_seq = np.empty(n, np.int64)
    for j in range(n):
        best_seq[j] = seq[(starts[0] + j) % n]
    best = np.empty(4 * nq, np.int64)
    code = np.empty(4 * nq, np.int64)
    label = np.empty(nv, np.int64)
    seen = np.empty(nq, np.bool_)
    qq = np.empty(nq, np.int64)
    qc = np.empty(nq, np.int64)
    have = False
    first = -1
    ties = 0
    for s in range(count):
        i = starts[s]
        o = own[boundary[i], boundary[(i + 1) % n]]
        label[:] = -1
        seen[:] = False
        head = 0
        tail = 1
        qq[0] = o // 4
        qc[0] = o % 4
        seen[o // 4] = True
        nl = 0
        pos = 0
        while head < tail:
            q = qq[head]
            c = qc[head]
            head += 1
            for j in range(4):
                v = quads[q, (c + j) % 4]
                if label[v] < 0:
                    label[v] = nl
                    nl += 1
                code[pos] = label[v]
                pos += 1
            for j in range(4):
                other = nbr[q * 4 + (c + j) % 4]
                if other >= 0 and not seen[other // 4]:
                    seen[other // 4] = True
                    qq[tail] = other // 4
                    qc[tail] = (other % 4 + 1) % 4
                    tail += 1
        if not have:
            best[:] = code
            have = True
            first = i
            ties = 1
        else:
            cmp = 0
            for j in range(4 * nq):
                if code[j] != best[j]:
                    cmp = -1 if code[j] < best[j] else 1
                    break
            if cmp < 0:
                best[:] = code
                first = i
                ties = 1
            elif cmp == 0:
                ties += 1
    return best_seq, best, first, ties


def canonical_key(quads, boundary, vals):
    """``(key, aut, aut_rot, chiral, start)`` exactly as :func:`jaxmatch.catalogue.canon.canonical`.

    quads: (F, 4) ccw vertex ids; boundary: (n,) ccw loop; vals: (V,) ints (valences,
    possibly with marks added).
    """

    q = np.ascontiguousarray(quads, dtype=np.int64).reshape(-1, 4)
    b = np.ascontiguousarray(boundary, dtype=np.int64)
    v = np.ascontiguousarray(vals, dtype=np.int64)
    s1, c1, i1, aut_rot = _codes(q, b, v)
    s2, c2, i2, _ = _codes(np.ascontiguousarray(q[:, ::-1]), np.ascontiguousarray(b[::-1]), v)
    k1 = (tuple(s1.tolist()), tuple(c1.tolist()))
    k2 = (tuple(s2.tolist()), tuple(c2.tolist()))
    chiral = k1 != k2
    if k1 <= k2:
        key, start = k1, (int(i1), False)
    else:
        key, start = k2, (int(i2), True)
    return Canonical(key=key, aut=int(aut_rot) * (1 if chiral else 2), aut_rot=int(aut_rot), chiral=chiral, start=start)
