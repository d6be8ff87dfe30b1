"""The numba kernel of :class:`jaxmatch.kernels.backends.NumbaBackend` (imported on first use,
so ``import jaxmatch`` does not pay for numba; compiled once, then loaded from numba's on-disk
cache). int16 only: the ``np.int16`` casts keep LLVM on 16-bit lanes (without them numba widens
to int64 and the loop runs on 4 lanes per 256 bits)."""

import numba
import numba.extending
import numpy as np
from numba import prange


@numba.extending.register_jitable(inline="always")
def _chunk(job, n_chunks, codes, lengths, vals, tab, gate, strict, lanes_per_chunk, out):  # pragma: no cover - compiled
    """One chunk of ``lanes_per_chunk`` meshes against one shape (``job = shape * n_chunks + chunk``)."""
    big_n, n = vals.shape
    neg = tab[3, 0]
    s = job // n_chunks
    b0 = (job % n_chunks) * lanes_per_chunk
    lanes = min(lanes_per_chunk, big_n - b0)
    m = lengths[s]
    pv = np.empty((2, 4, n, lanes), tab.dtype)  # [mirror, code, vertex, lane]
    d = np.empty((n + 1, lanes), tab.dtype)
    for bl in range(lanes):
        b = b0 + bl
        for k in range(n):
            a, v, c0 = vals[b, (k + 1) % n] - 2, vals[b, k] - 2, vals[b, (k - 1 + n) % n] - 2
            t = a * 16 + v * 4 + c0  # triple [s[k+1], s[k], s[k-1]]
            tr = c0 * 16 + v * 4 + a  # in vals[::-1] vertex k sits at n - 1 - k, neighbours swapped
            for c in range(4):
                pv[0, c, k, bl] = tab[c, t]
                pv[1, c, n - 1 - k, bl] = tab[c, tr]
    for o in range(2 * n):
        h = 0 if o < n else 1
        r = o - h * n
        for l in range(lanes):
            d[0, l] = 0
        for j in range(1, n + 1):
            dj = d[j]
            for l in range(lanes):
                dj[l] = neg
        z = d[0, 0]
        for i in range(m):
            c = codes[s, i]
            lo = max(1, n - m + i + 1)
            hi = min(n, i + 1)
            if strict:
                g = gate[c]
                for j in range(hi, lo - 1, -1):
                    dj = d[j]
                    dm = d[j - 1]
                    w = pv[h, c, (r + j - 1) % n]
                    for l in range(lanes):
                        x = np.int16(dm[l] + w[l])  # int16 arithmetic: LLVM keeps 16-bit lanes
                        y = dj[l] if dj[l] < g else g
                        dj[l] = x if x > y else y
                if z > g:
                    z = g
                    d0 = d[0]
                    for l in range(lanes):
                        d0[l] = z
            else:
                for j in range(hi, lo - 1, -1):
                    dj = d[j]
                    dm = d[j - 1]
                    w = pv[h, c, (r + j - 1) % n]
                    for l in range(lanes):
                        x = np.int16(dm[l] + w[l])  # int16 arithmetic: LLVM keeps 16-bit lanes
                        dj[l] = x if x > dj[l] else dj[l]
        dn = d[n]
        for l in range(lanes):
            out[s, b0 + l, o] = dn[l]


@numba.njit(parallel=True, nogil=True, cache=True, boundscheck=False)
def dp_kernel_i16(codes, lengths, vals, tab, gate, strict, lanes_per_chunk, out):  # pragma: no cover - compiled
    """Every (shape, chunk) job, spread over the cores (``prange``)."""
    n_chunks = (vals.shape[0] + lanes_per_chunk - 1) // lanes_per_chunk
    for job in prange(codes.shape[0] * n_chunks):
        _chunk(job, n_chunks, codes, lengths, vals, tab, gate, strict, lanes_per_chunk, out)


@numba.njit(nogil=True, cache=True, boundscheck=False)
def dp_kernel_i16_serial(codes, lengths, vals, tab, gate, strict, lanes_per_chunk, out):  # pragma: no cover - compiled
    """The same jobs on the calling thread (small problems: no thread-pool wake-up, which costs
    milliseconds on a loaded machine)."""
    n_chunks = (vals.shape[0] + lanes_per_chunk - 1) // lanes_per_chunk
    for job in range(codes.shape[0] * n_chunks):
        _chunk(job, n_chunks, codes, lengths, vals, tab, gate, strict, lanes_per_chunk, out)
