"""Compiled L-BFGS smoothing of :func:`jaxmatch.placement.embed.smooth` in numba: the fallback of
:mod:`jaxmatch.kernels.placement` where the C library was not built (imported on first use,
cached on disk after the first compile).

The same objective, parametrisation and optimiser as the numpy reference in
:mod:`jaxmatch.placement.embed` (``_energy``, ``_Params``, ``_lbfgs``), written as loops: the
meshes placed while ranking have 4-60 quads, where numpy spends its time in per-call overhead
(about 200 us per energy evaluation against 1-3 us here; ``scripts/bench.py`` reports the
placement time, and ``tests/test_embed_numba.py`` checks this code against the reference).

Flat encoding of the optimisation vector ``x``: the free vertices' ``(x, y)`` (``2 * nf``),
then for every slide ``s`` its ``r_s + 1`` gap logits; slide ``s`` has end points
``sa[s]``, ``sb[s]`` ``(2,)`` and vertices ``sv[sp[s]:sp[s + 1]]``.
"""

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _corner(pos, quads, q, c):  # pragma: no cover - compiled
    """Corner ``c`` of quad ``q``: its vertex, the next and previous vertex ids, and the edge
    vectors to them ``e1 = pos[next] - pos[vertex]``, ``e2 = pos[previous] - pos[vertex]``."""
    p = quads[q, c]
    nx = quads[q, (c + 1) % 4]
    pv = quads[q, (c + 3) % 4]
    return p, nx, pv, pos[nx, 0] - pos[p, 0], pos[nx, 1] - pos[p, 1], pos[pv, 0] - pos[p, 0], pos[pv, 1] - pos[p, 1]


@numba.njit(cache=True, nogil=True, inline="always")
def _softmax_norm(x, off, count):  # pragma: no cover - compiled
    """``(max, sum of exp(z - max))`` of the logits ``x[off:off + count]``: softmax weight ``i``
    is ``exp(x[off + i] - max) / sum``."""
    zmax = -np.inf
    for i in range(count):
        zmax = max(zmax, x[off + i])
    tot = 0.0
    for i in range(count):
        tot += math.exp(x[off + i] - zmax)
    return zmax, tot


@numba.njit(cache=True, nogil=True)
def _positions(x, base, free, sa, sb, sp, sv, pos):  # pragma: no cover - compiled
    """Fill ``pos (V, 2)`` from ``x``: base, free vertices, slid vertices."""
    pos[:, :] = base
    nf = free.shape[0]
    for i in range(nf):
        pos[free[i], 0] = x[2 * i]
        pos[free[i], 1] = x[2 * i + 1]
    off = 2 * nf
    for s in range(sa.shape[0]):
        r = sp[s + 1] - sp[s]
        zmax, tot = _softmax_norm(x, off, r + 1)
        u = 0.0
        dx, dy = sb[s, 0] - sa[s, 0], sb[s, 1] - sa[s, 1]
        for i in range(r):
            u += math.exp(x[off + i] - zmax) / tot
            v = sv[sp[s] + i]
            pos[v, 0] = sa[s, 0] + u * dx
            pos[v, 1] = sa[s, 1] + u * dy
        off += r + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _pow(x, power, squarings):  # pragma: no cover - compiled
    """``x ** power``; by repeated squaring when ``power == 2 ** squarings`` (the smoothing
    powers 1, 2, 4, 8, 16: several times faster than ``pow``, same value to a few ulp)."""
    if squarings < 0:
        return x ** power
    for _ in range(squarings):
        x = x * x
    return x


@numba.njit(cache=True, nogil=True)
def _energy(pos, quads, delta, power, grad, k, r, h):  # pragma: no cover - compiled
    """Power mean of the regularised corner condition numbers (see ``embed._energy``); fills
    ``grad (V, 2)``; returns ``inf`` (grad zero) where not finite. ``k``, ``r``, ``h``: (F, 4)
    scratch."""
    F = quads.shape[0]
    d2 = 4.0 * delta * delta
    kmax = -np.inf
    for q in range(F):
        for c in range(4):
            p, nx, pv, e1x, e1y, e2x, e2y = _corner(pos, quads, q, c)
            a = e1x * e2y - e1y * e2x
            rr = math.sqrt(a * a + d2)
            hh = 0.5 * (a + rr) if a >= 0 else d2 / (2.0 * (rr - a))
            N = e1x * e1x + e1y * e1y + e2x * e2x + e2y * e2y
            kk = N / (2.0 * hh)
            r[q, c] = rr
            h[q, c] = hh
            k[q, c] = kk
            if not kk <= kmax:  # NaN propagates to kmax
                kmax = kk
    grad[:, :] = 0.0
    if not (np.isfinite(kmax) and kmax > 0):
        return np.inf
    C = 4 * F
    sq = -1
    for e in range(7):
        if power == 2.0 ** e:
            sq = e
    acc = 0.0
    for q in range(F):
        for c in range(4):
            acc += _pow(k[q, c] / kmax, power, sq)
    f = kmax * (acc / C) ** (1.0 / power)
    if not np.isfinite(f):
        return np.inf
    for q in range(F):
        for c in range(4):
            p, nx, pv, e1x, e1y, e2x, e2y = _corner(pos, quads, q, c)
            x = k[q, c] / f
            dk = _pow(x, power, sq) / x / C if x > 0 else (k[q, c] / f) ** (power - 1.0) / C
            gN = dk / (2.0 * h[q, c])
            ga = -dk * k[q, c] / r[q, c]
            g1x = 2.0 * gN * e1x + ga * e2y
            g1y = 2.0 * gN * e1y - ga * e2x
            g2x = 2.0 * gN * e2x - ga * e1y
            g2y = 2.0 * gN * e2y + ga * e1x
            grad[p, 0] -= g1x + g2x
            grad[p, 1] -= g1y + g2y
            grad[nx, 0] += g1x
            grad[nx, 1] += g1y
            grad[pv, 0] += g2x
            grad[pv, 1] += g2y
    for v in range(grad.shape[0]):
        if not (np.isfinite(grad[v, 0]) and np.isfinite(grad[v, 1])):
            grad[:, :] = 0.0
            return np.inf
    return f


@numba.njit(cache=True, nogil=True)
def _pull(x, gpos, free, sa, sb, sp, sv, g):  # pragma: no cover - compiled
    """Gradient w.r.t. ``x`` (into ``g``) from the gradient w.r.t. positions ``gpos (V, 2)``."""
    nf = free.shape[0]
    for i in range(nf):
        g[2 * i] = gpos[free[i], 0]
        g[2 * i + 1] = gpos[free[i], 1]
    off = 2 * nf
    for s in range(sa.shape[0]):
        r = sp[s + 1] - sp[s]
        zmax, tot = _softmax_norm(x, off, r + 1)
        dx, dy = sb[s, 0] - sa[s, 0], sb[s, 1] - sa[s, 1]
        gu = np.zeros(r + 1)
        u = 0.0
        dot = 0.0  # sum_k g_k u_k
        for i in range(r):
            u += math.exp(x[off + i] - zmax) / tot
            v = sv[sp[s] + i]
            gu[i] = gpos[v, 0] * dx + gpos[v, 1] * dy
            dot += gu[i] * u
        tail = 0.0
        for i in range(r, -1, -1):
            tail += gu[i]
            g[off + i] = math.exp(x[off + i] - zmax) / tot * (tail - dot)
        off += r + 1


@numba.njit(cache=True, nogil=True)
def _objective(x, base, free, sa, sb, sp, sv, quads, delta, power, pos, gpos, g, k, r, h):  # pragma: no cover
    _positions(x, base, free, sa, sb, sp, sv, pos)
    f = _energy(pos, quads, delta, power, gpos, k, r, h)
    if not np.isfinite(f):
        g[:] = 0.0
        return np.inf
    _pull(x, gpos, free, sa, sb, sp, sv, g)
    return f


@numba.njit(cache=True, nogil=True)
def lbfgs(x0, base, free, sa, sb, sp, sv, quads, delta, power, maxiter, mem, ftol, gtol):  # pragma: no cover
    """L-BFGS with Armijo backtracking, step for step as ``embed._lbfgs``; returns the last
    accepted ``x``."""
    n = x0.shape[0]
    V = base.shape[0]
    F = quads.shape[0]
    pos = np.empty((V, 2))
    gpos = np.empty((V, 2))
    k = np.empty((F, 4))
    r = np.empty((F, 4))
    h = np.empty((F, 4))
    x = x0.copy()
    g = np.empty(n)
    f = _objective(x, base, free, sa, sb, sp, sv, quads, delta, power, pos, gpos, g, k, r, h)
    if not np.isfinite(f):
        return x
    S = np.zeros((mem, n))
    Y = np.zeros((mem, n))
    cnt = 0  # stored pairs; pair i (0 = oldest) lives in row (head + i) % mem
    head = 0
    q = np.empty(n)
    coef_rho = np.empty(mem)
    coef_a = np.empty(mem)
    xn = np.empty(n)
    gn = np.empty(n)
    for _ in range(maxiter):
        gmax = 0.0
        for i in range(n):
            gmax = max(gmax, abs(g[i]))
        if gmax <= gtol:
            break
        q[:] = g
        for t in range(cnt - 1, -1, -1):
            row = (head + t) % mem
            rho = 1.0 / np.dot(Y[row], S[row])
            a = rho * np.dot(S[row], q)
            q -= a * Y[row]
            coef_rho[t] = rho
            coef_a[t] = a
        if cnt > 0:
            last = (head + cnt - 1) % mem
            q *= np.dot(S[last], Y[last]) / np.dot(Y[last], Y[last])
        else:
            q *= 0.05 / max(gmax, 1e-300)
        for t in range(cnt):
            row = (head + t) % mem
            q += S[row] * (coef_a[t] - coef_rho[t] * np.dot(Y[row], q))
        slope = -np.dot(g, q)
        if not slope < 0:
            cnt = 0
            head = 0
            q[:] = g * (0.05 / max(gmax, 1e-300))
            slope = -np.dot(g, q)
        step = 1.0
        while True:
            for i in range(n):
                xn[i] = x[i] - step * q[i]
            fn = _objective(xn, base, free, sa, sb, sp, sv, quads, delta, power, pos, gpos, gn, k, r, h)
            if np.isfinite(fn) and fn <= f + 1e-4 * step * slope:
                break
            step *= 0.5
            if step < 1e-12:
                return x
        sy = 0.0
        ss = 0.0
        for i in range(n):
            si = xn[i] - x[i]
            sy += si * (gn[i] - g[i])
            ss += si * si
        if sy > 1e-12 * ss:
            if cnt < mem:
                row = (head + cnt) % mem
                cnt += 1
            else:
                row = head
                head = (head + 1) % mem
            for i in range(n):
                S[row, i] = xn[i] - x[i]
                Y[row, i] = gn[i] - g[i]
        done = f - fn <= ftol * max(1.0, abs(f))
        x[:] = xn
        g[:] = gn
        f = fn
        if done:
            break
    return x


@numba.njit(cache=True, nogil=True)
def _start(xy, free, sa, sb, sp, sv):  # pragma: no cover - compiled
    """Flat vector of positions ``xy (V, 2)``, as ``embed._Params.start``."""
    nf = free.shape[0]
    x = np.empty(2 * nf + sv.shape[0] + sa.shape[0])
    for i in range(nf):
        x[2 * i] = xy[free[i], 0]
        x[2 * i + 1] = xy[free[i], 1]
    off = 2 * nf
    for s in range(sa.shape[0]):
        r = sp[s + 1] - sp[s]
        dx, dy = sb[s, 0] - sa[s, 0], sb[s, 1] - sa[s, 1]
        dd = dx * dx + dy * dy
        gaps = np.empty(r + 1)
        prev = 0.0
        for i in range(r):
            v = sv[sp[s] + i]
            u = ((xy[v, 0] - sa[s, 0]) * dx + (xy[v, 1] - sa[s, 1]) * dy) / dd
            gaps[i] = max(u - prev, 1e-12)
            prev = u
        gaps[r] = max(1.0 - prev, 1e-12)
        tot = gaps.sum()
        for i in range(r + 1):
            x[off + i] = math.log(gaps[i] / tot)
        off += r + 1
    return x


@numba.njit(cache=True, nogil=True)
def _key(xy, quads):  # pragma: no cover - compiled
    """``(inverted quads, min scaled Jacobian, mean scaled Jacobian)`` as ``embed._key``."""
    F = quads.shape[0]
    inv = 0
    lo = np.inf
    tot = 0.0
    tiny = np.finfo(np.float64).tiny
    for q in range(F):
        sj = np.inf
        bad = False
        for c in range(4):
            _, _, _, e1x, e1y, e2x, e2y = _corner(xy, quads, q, c)
            a = e1x * e2y - e1y * e2x
            if a <= 0:
                bad = True
            ln = math.sqrt(e1x * e1x + e1y * e1y) * math.sqrt(e2x * e2x + e2y * e2y)
            v = a / ln if ln > tiny else 0.0
            sj = min(sj, v)
        sj = min(max(sj, -1.0), 1.0)
        inv += bad
        lo = min(lo, sj)
        tot += sj
    return inv, lo, tot / F


@numba.njit(cache=True, nogil=True)
def _better(k, best, tol):  # pragma: no cover - compiled
    """``embed._pick``'s order: fewer inverted, then higher min SJ, then higher mean (by > tol)."""
    if k[0] != best[0]:
        return k[0] < best[0]
    if abs(k[1] - best[1]) > tol:
        return k[1] > best[1]
    return k[2] > best[2] + tol


@numba.njit(cache=True, nogil=True)
def smooth(xy, quads, free, sa, sb, sp, sv, iters, powers, untangle_rounds, mem, ftol, gtol):  # pragma: no cover
    """Untangling rounds, then the power continuation, keeping the best positions seen: the
    loop of ``embed.smooth`` (its docstring) with every round compiled. Returns ``(V, 2)``."""
    F = quads.shape[0]
    V = xy.shape[0]
    area = 0.0
    for q in range(F):
        a = 0.0
        for c in range(4):
            p0 = quads[q, c]
            p1 = quads[q, (c + 1) % 4]
            a += xy[p0, 0] * xy[p1, 1] - xy[p0, 1] * xy[p1, 0]
        area += abs(0.5 * a)
    if area == 0.0:
        area = 1.0
    eps = 1e-2 * area / F
    floor = 1e-4 * eps
    best = xy.copy()
    bk = _key(best, quads)
    cur = xy.copy()
    base = xy.copy()
    pos = np.empty((V, 2))
    for _ in range(untangle_rounds):
        s_min = np.inf
        for q in range(F):
            for c in range(4):
                _, _, _, e1x, e1y, e2x, e2y = _corner(cur, quads, q, c)
                a = e1x * e2y - e1y * e2x
                s_min = min(s_min, a)
        if s_min >= eps:
            break
        delta = math.sqrt(eps * (eps - s_min))
        x = lbfgs(_start(cur, free, sa, sb, sp, sv), base, free, sa, sb, sp, sv, quads, delta, 1.0, iters, mem, ftol, gtol)
        _positions(x, base, free, sa, sb, sp, sv, pos)
        cur[:, :] = pos
        k = _key(cur, quads)
        if _better(k, bk, 1e-9):
            best[:, :] = cur
            bk = k
    cur[:, :] = best
    for pw in powers:
        x = lbfgs(_start(cur, free, sa, sb, sp, sv), base, free, sa, sb, sp, sv, quads, floor, pw, iters, mem, ftol, gtol)
        _positions(x, base, free, sa, sb, sp, sv, pos)
        cur[:, :] = pos
        k = _key(cur, quads)
        if _better(k, bk, 1e-9):
            best[:, :] = cur
            bk = k
    return best


@numba.njit(cache=True, nogil=True)
def energy(pos, quads, delta, power):  # pragma: no cover - compiled
    """``(f, grad (V, 2))`` of the objective at positions ``pos``, for tests against the
    numpy reference."""
    F = quads.shape[0]
    grad = np.empty_like(pos)
    f = _energy(pos, quads, delta, power, grad, np.empty((F, 4)), np.empty((F, 4)), np.empty((F, 4)))
    return f, grad


@numba.njit(cache=True, nogil=True)
def objective(x, base, free, sa, sb, sp, sv, quads, delta, power):  # pragma: no cover - compiled
    """``(f, grad)`` w.r.t. the flat vector ``x``, for tests against the numpy reference."""
    V = base.shape[0]
    F = quads.shape[0]
    g = np.empty(x.shape[0])
    f = _objective(x, base, free, sa, sb, sp, sv, quads, delta, power, np.empty((V, 2)), np.empty((V, 2)), g,
                   np.empty((F, 4)), np.empty((F, 4)), np.empty((F, 4)))
    return f, g


@numba.njit(cache=True, nogil=True)
def tutte_dense(quads, n_vertices, boundary, boundary_xy):  # pragma: no cover - compiled
    """``embed.tutte`` for small meshes: uniform-weight Laplacian built from the quads' edges
    (each once), free vertices solved densely. Returns ``(V, 2)``."""
    V = n_vertices
    A = np.zeros((V, V))
    for q in range(quads.shape[0]):
        for c in range(4):
            a, b = quads[q, c], quads[q, (c + 1) % 4]
            A[a, b] = 1.0
            A[b, a] = 1.0
    xy = np.zeros((V, 2))
    fixed = np.zeros(V, np.bool_)
    for j in range(boundary.shape[0]):
        xy[boundary[j]] = boundary_xy[j]
        fixed[boundary[j]] = True
    free = np.flatnonzero(~fixed)
    nf = free.shape[0]
    if nf == 0:
        return xy
    L = np.zeros((nf, nf))
    rhs = np.zeros((nf, 2))
    for i in range(nf):
        v = free[i]
        L[i, i] = A[v].sum()
        for i2 in range(nf):
            if i2 != i:
                L[i, i2] = -A[v, free[i2]]
        for w in range(V):
            if fixed[w] and A[v, w] != 0.0:
                rhs[i, 0] += xy[w, 0]
                rhs[i, 1] += xy[w, 1]
    sol = np.linalg.solve(L, rhs)
    for i in range(nf):
        xy[free[i]] = sol[i]
    return xy
