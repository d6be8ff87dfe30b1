"""The JAX side of the exact scorer (imported on first use: the default CPU path runs the numba
kernel and never imports JAX). :mod:`jaxmatch.scoring.exact` re-exports every public name here,
so ``from jaxmatch.scoring.exact import dp_scan, CPUBackend`` keeps working; it loads this module
(and JAX) only when such a name is first asked for.

* :func:`dp_scan`: the generic recurrence (one ``jax.lax.scan`` over input points, any
  reduction; :mod:`jaxmatch.scoring.soft` passes a smoothed maximum);
* :func:`final_blocks` and :class:`CPUBackend`: the XLA kernel behind the exact host
  :func:`jaxmatch.scoring.exact.exact_values` (``JAXMATCH_BACKEND=xla``, accelerators, and
  models that need int32 / float32), and the blocks :class:`jaxmatch.scoring.bulk.ShardedBackend`
  shards over devices;
* :func:`oriented_sequences`, :func:`orientation_triples`, :func:`orientation_weights`,
  :func:`orientation_slabs`, :func:`finite_table`: the weights of every orientation as arrays.

Conventions (orientations, the shifted frame, number types): :mod:`jaxmatch.scoring.exact`.
"""

from __future__ import annotations

from functools import partial
from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np

from jaxmatch.kernels.model import NEG
from jaxmatch.kernels.problem import _INVALID, UNROLL, DPProblem, _rotation_index, run_calls

__all__ = ["CPUBackend", "dp_scan", "final_blocks", "finite_table", "orientation_slabs", "orientation_triples",
           "orientation_weights", "oriented_sequences"]


def finite_table(table) -> jnp.ndarray:
    """``(3, 4, 4, 4) float32`` with ``-inf`` (and anything ``<= NEG``) replaced by ``NEG``."""
    t = jnp.asarray(table, dtype=jnp.float32)
    if t.shape != (3, 4, 4, 4):
        raise ValueError(f"table must have shape (3, 4, 4, 4), got {t.shape}")
    return jnp.where(t > NEG, t, jnp.float32(NEG))


def oriented_sequences(vals) -> jnp.ndarray:
    """``(N, n) -> (N, 2n, n)``: all rotations of ``vals``, then all rotations of ``vals[:, ::-1]``."""
    v = jnp.asarray(vals)
    n = v.shape[-1]
    rot = _rotation_index(n)
    return jnp.concatenate([v[..., rot], v[..., ::-1][..., rot]], axis=-2)


def orientation_triples(vals) -> jnp.ndarray:
    """``(N, n) -> (N, 2n, n, 3)`` triples ``[u, v, w]`` of every oriented sequence (orientation ``o``)."""
    s = oriented_sequences(vals)
    return jnp.stack([jnp.roll(s, -1, axis=-1), s, jnp.roll(s, 1, axis=-1)], axis=-1)


def orientation_weights(vals, table_finite) -> jnp.ndarray:
    """Weights per input code ``(3, n, N, 2n)``: ``[c, j, b, o] = table[c, t_{b,o,j}]``
    (triple of vertex ``j`` of orientation ``o`` of mesh ``b``)."""
    t = orientation_triples(vals) - 2  # (N, 2n, n, 3)
    flat = t[..., 0] * 16 + t[..., 1] * 4 + t[..., 2]  # (N, 2n, n)
    return table_finite.reshape(3, 64)[:, jnp.transpose(flat, (2, 0, 1))]


# --------------------------------------------------------------------------- the one DP


def dp_scan(
    wc: jnp.ndarray,
    codes: jnp.ndarray,
    valid: jnp.ndarray,
    reduce: Callable[[jnp.ndarray, jnp.ndarray], jnp.ndarray],
    *,
    gate=None,
    keep_rows: bool = False,
    unroll: int = UNROLL,
):
    """The modified-LCS recurrence in the shifted frame (module docstring), once, for any reduction.

    wc: ``(3, n, *batch)`` finite shifted weights per input code (``W'[i, j] = wc[codes[i], j]``);
    codes: ``(m,)`` int; valid: ``(m,)`` bool, invalid (padding) input points are skipped
    (the row is carried unchanged); reduce: elementwise ``(skip, match) -> value``
    (``jnp.maximum`` exact, a smoothed maximum soft); gate: ``(3,)`` added to the skip branch
    per code (0, or NEG for a point that must be matched; None: zeros). ``D[i][0]`` starts at 0
    and takes the gate too.

    One ``lax.scan`` over input points; the carry is the row array ``(n, *batch)`` (rows
    ``j = 1..n``) and ``D[i][0]`` (the weights are gathered inside the step, so no
    ``(m, n, *batch)`` array is built). Returns the last row ``D[m]`` ``(n + 1, *batch)``, and
    with ``keep_rows`` also all rows ``(m + 1, n + 1, *batch)``.
    """
    n = wc.shape[1]
    batch = wc.shape[2:]
    # the carry holds rows j = 1..n only: the shifted row is a padded slice, which XLA:CPU
    # fuses into one vectorised loop (a concatenate in the step fusion was ~5x slower, docs/perf.md)
    d0 = jnp.full((n, *batch), NEG, wc.dtype)
    z0 = jnp.zeros((), wc.dtype)
    pad = [(1, 0)] + [(0, 0)] * len(batch)
    g = None if gate is None else jnp.asarray(gate, wc.dtype)

    def step(carry, x):
        d, z = carry
        c, ok = x
        wi = jax.lax.dynamic_index_in_dim(wc, c, axis=0, keepdims=False)
        shifted = jnp.pad(d[:-1], pad, constant_values=z) + wi
        if g is None:
            new, z_new = reduce(d, shifted), z
        else:
            gi = g[c]
            new, z_new = reduce(d + gi, shifted), z + gi
        new = jnp.where(ok, new, d)
        z_new = jnp.where(ok, z_new, z)
        return (new, z_new), ((new, z_new) if keep_rows else None)

    (last, z_last), rows = jax.lax.scan(step, (d0, z0), (codes, valid), unroll=unroll)
    last = jnp.concatenate([jnp.broadcast_to(z_last, (1, *batch)), last], axis=0)
    if keep_rows:
        r, zs = rows
        m = r.shape[0]
        r = jnp.concatenate([jnp.broadcast_to(zs.reshape((m, 1) + (1,) * len(batch)), (m, 1, *batch)), r], axis=1)
        first = jnp.concatenate([jnp.zeros((1, *batch), wc.dtype), d0], axis=0)
        return last, jnp.concatenate([first[None], r], axis=0)
    return last


# --------------------------------------------------------------------------- the XLA kernel


def orientation_slabs(vals, tab) -> jnp.ndarray:
    """``(B, n)`` valences, ``(4, 64)`` weights -> ``(4, n, 2n * B)``: ``[c, j, o * B + b]`` is the
    weight of code ``c`` against vertex ``j`` of orientation ``o`` of mesh ``b`` (the weights of
    :func:`orientation_weights`, orientation-major, mesh-minor).

    Built without a gather per orientation: per-vertex weights ``x[c, k, b]`` (of ``vals`` and of
    ``vals[::-1]``), tiled ``n + 1`` times along ``k`` and read as ``(n, n + 1)``, give the
    circulant ``[j, r] = x[(j + r) % n]`` (vertex ``j`` of rotation ``r`` is vertex ``(r + j) % n``).
    """
    v = jnp.asarray(vals, jnp.int32)
    b, n = v.shape

    def per_vertex(s):  # triple [s[k+1], s[k], s[k-1]] -> (4, n, B)
        s = s.T
        return tab[:, (jnp.roll(s, -1, 0) - 2) * 16 + (s - 2) * 4 + (jnp.roll(s, 1, 0) - 2)]

    halves = [jnp.tile(x, (1, n + 1, 1)).reshape(4, n, n + 1, b)[:, :, :n, :]
              for x in (per_vertex(v), per_vertex(v[:, ::-1]))]
    return jnp.concatenate(halves, 2).reshape(4, n, 2 * n * b)


def _final_block(codes, vals, tab, gate, strict: bool, unroll: int):
    """``E[m][n]`` of every orientation: ``(B, n)`` -> ``(B, 2n)`` in ``tab.dtype``.

    The max-plus recurrence of :func:`dp_scan` (shifted frame) on the flat layout
    ``(n, 2n * B)``; padded input points carry code 3 (all weights the sentinel), which never
    changes a valid value. ``strict`` (some type must be matched): the skip branch is capped at
    ``gate[c]`` (the sentinel for a must-match code, a no-op otherwise) and ``E[i][0]`` is carried
    (0 until the first must-match point, then the sentinel); without it the step is the plain
    ``max(d, shift(d) + w)``. Values never leave ``[2 * sentinel, n * max|W'|]``.
    """
    b, n = vals.shape
    wc = orientation_slabs(vals, tab)
    neg = tab[_INVALID, 0]
    d0 = jnp.full(wc.shape[1:], neg, tab.dtype)
    pad = ((1, 0), (0, 0))

    if not strict:
        def step(d, c):
            wi = jax.lax.dynamic_index_in_dim(wc, c, axis=0, keepdims=False)
            return jnp.maximum(d, jnp.pad(d[:-1], pad) + wi), None

        last = jax.lax.scan(step, d0, codes, unroll=unroll)[0]
    else:
        def step(carry, c):
            d, z = carry
            wi = jax.lax.dynamic_index_in_dim(wc, c, axis=0, keepdims=False)
            g = gate[c]
            new = jnp.maximum(jnp.minimum(d, g), jnp.pad(d[:-1], pad, constant_values=z) + wi)
            return (new, jnp.minimum(z, g)), None

        last = jax.lax.scan(step, (d0, jnp.zeros((), tab.dtype)), codes, unroll=unroll)[0][0]
    return last[-1].reshape(2 * n, b).T


def _blocks(codes, vals, tab, gate, strict: bool, unroll: int):
    """``codes (S, m_pad)``, ``vals (C, B, n)`` -> ``(S, C, B, 2n)``: shapes and blocks one after
    another (``lax.map``), so each block's working set stays in cache."""
    def one(c):
        return jax.lax.map(lambda v: _final_block(c, v, tab, gate, strict, unroll), vals)

    if codes.shape[0] == 1:
        return one(codes[0])[None]
    return jax.lax.map(one, codes)


@partial(jax.jit, static_argnames=("strict", "unroll"))
def final_blocks(codes, vals, tab, gate, strict: bool = False, unroll: int = UNROLL):
    """``codes (S, m_pad)`` (3 = padding), ``vals (C, B, n)``, ``tab (4, 64)``, ``gate (4,)`` ->
    ``(S, C, B, 2n)`` raw shifted-frame values (:func:`_final_block`)."""
    return _blocks(codes, vals, tab, gate, strict, unroll)


class CPUBackend:
    """:func:`final_blocks` on this process's default device, calls dispatched on ``threads``
    host threads (default :func:`jaxmatch.kernels.problem.default_threads`)."""

    mesh_lanes = 1

    def __init__(self, threads: int | None = None, unroll: int = UNROLL):
        self.threads = threads
        self.unroll = int(unroll)

    def run(self, problem: DPProblem, vals: np.ndarray) -> np.ndarray:
        s, n = problem.codes.shape[0], problem.n

        def call(k):
            return np.asarray(final_blocks(problem.codes, vals[k], problem.tab, problem.gate,
                                           strict=problem.strict, unroll=self.unroll)).reshape(s, -1, 2 * n)

        outs = run_calls(call, range(vals.shape[0]), self.threads)
        if not outs:
            return np.empty((s, 0, 2 * n), problem.kind.dtype)
        return np.concatenate(outs, axis=1)
