"""Soft (differentiable) relaxation of the exact scorer, for tuning lattice weights.

Same DP core as :mod:`jaxmatch.scoring.exact` (:func:`jaxmatch.kernels.dp_xla.dp_scan`), with ``max``
replaced by the smoothed maximum ``smax_gamma(a, b) = gamma * logaddexp(a / gamma, b / gamma)``,
and the maximum over the ``2n`` orientations replaced by ``gamma * logsumexp(. / gamma)``.
Since log-sum-exp distributes over ``+``, the result is exactly the log-partition function

    soft = gamma * log( sum over orientations o and alignments a of exp(U(o, a) / gamma) )

so ``exact <= soft <= exact + gamma * log(2n * C(m, n))`` and ``soft -> exact`` as
``gamma -> 0``. Its gradient w.r.t. a table entry is the expected number of times the entry
is used under the Gibbs distribution ``exp(U / gamma)`` (each matchable mesh's gradient sums
to ``n``; for any mesh it is nonnegative with sum at most ``n``: the smoothed maxima use
normalised weights in their derivatives, see :func:`smax2`).

The model is a :class:`jaxmatch.kernels.model.Weights` (match table, forbidden mask, skip
weights, must-match mask); the free values (``table``, ``skip``) may be given separately as JAX
arrays to differentiate in them. Skip weights enter as in the exact scorer (the shifted frame
of :mod:`jaxmatch.scoring.exact`: ``W' = W - skip[c]`` in the DP, ``sum_i skip[codes[i]]``
added at the end, which is exact for a log-sum-exp over alignments too); the gradient w.r.t.
``skip[c]`` is the expected number of skipped points of type ``c``.

Forbidden entries and ``-inf`` skip weights are fixed at the finite ``NEG`` (never ``-inf``)
and get exactly zero gradient. Values ``<= NEG / 2`` mean *unmatchable* (no finite alignment or
``n > m``); they stay finite so gradients stay finite (at any ``gamma > 0``, 1e-3 included).

The computation dtype follows ``table_free`` (float32 normally; float64 under
``jax.enable_x64`` for finite-difference checks).
"""

from __future__ import annotations

from functools import partial
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero

from jaxmatch.kernels.dp_xla import dp_scan, orientation_weights
from jaxmatch.kernels.model import NEG, weights_of
from jaxmatch.kernels.problem import UNROLL
from jaxmatch.scoring.exact import bucket_length

__all__ = [
    "smax",
    "smax2",
    "smooth_max",
    "soft_batch",
    "soft_parts",
    "soft_table",
    "soft_utility",
    "soft_utility_batch",
    "pad_shapes",
    "table_parts",
]


def _entropy(p):
    """Binary entropy ``-p log p - (1 - p) log(1 - p)`` (nats), 0 at ``p`` in {0, 1}."""
    return jax.scipy.special.entr(p) + jax.scipy.special.entr(1.0 - p)


@jax.custom_jvp
def smax2(a, b, gamma):
    """``gamma * log(exp(a / gamma) + exp(b / gamma))``, elementwise, finite inputs.

    Custom JVP: the weights are ``p = sigmoid((a - b) / gamma)`` and ``1 - p``, which sum to 1
    even where ``a`` and ``b`` are of the size of ``NEG`` (the generic ``exp(a - out)`` form
    rounds there and lets gradient mass grow exponentially along the DP). ``d/dgamma`` is
    the entropy of ``(p, 1 - p)``.
    """
    return jnp.maximum(a, b) + gamma * jnp.log1p(jnp.exp(-jnp.abs(a - b) / gamma))


def _tangent(terms, like):
    """Sum of the ``coefficient * tangent`` terms whose tangent is not a symbolic zero."""
    out = None
    for coef, t in terms:
        if isinstance(t, SymbolicZero):
            continue
        out = coef * t if out is None else out + coef * t
    return jnp.zeros_like(like) if out is None else out


def _smax2_jvp(primals, tangents):
    a, b, gamma = primals
    da, db, dg = tangents
    d = a - b
    e = jnp.exp(-jnp.abs(d) / gamma)
    out = jnp.maximum(a, b) + gamma * jnp.log1p(e)
    r = 1.0 / (1.0 + e)
    p = jnp.where(d >= 0, r, e * r)  # sigmoid(d / gamma), sharing exp with the value
    terms = [(p, da), (1.0 - p, db)]
    if not isinstance(dg, SymbolicZero):
        terms.append((_entropy(p), dg))
    return out, _tangent(terms, out)


smax2.defjvp(_smax2_jvp, symbolic_zeros=True)


@partial(jax.custom_jvp, nondiff_argnums=(2,))
def smax(x, gamma, axis: int = -1):
    """``gamma * logsumexp(x / gamma, axis)`` with normalised softmax weights in its JVP."""
    return gamma * jax.nn.logsumexp(x / gamma, axis=axis)


def _smax_jvp(axis, primals, tangents):
    x, gamma = primals
    dx, dg = tangents
    out = smax(x, gamma, axis)
    p = jax.nn.softmax(x / gamma, axis=axis)
    terms = []
    if not isinstance(dx, SymbolicZero):
        terms.append((1.0, jnp.sum(p * dx, axis=axis)))
    if not isinstance(dg, SymbolicZero):
        ent = -jnp.sum(jnp.where(p > 0, p * jnp.log(jnp.where(p > 0, p, 1.0)), 0.0), axis=axis)
        terms.append((ent, dg))
    return out, _tangent(terms, out)


smax.defjvp(_smax_jvp, symbolic_zeros=True)


def smooth_max(gamma) -> Callable[[jnp.ndarray, jnp.ndarray], jnp.ndarray]:
    """The reduction ``(a, b) -> gamma * logaddexp(a / gamma, b / gamma)`` for :func:`dp_scan`."""

    def reduce(a, b):
        return smax2(a, b, gamma)

    return reduce


def soft_table(table_free, forbidden_mask) -> jnp.ndarray:
    """``table_free`` with forbidden entries set to ``NEG`` (no gradient flows to them)."""
    t = jnp.asarray(table_free)
    if not jnp.issubdtype(t.dtype, jnp.floating):
        t = t.astype(jnp.float32)
    return jnp.where(jnp.asarray(forbidden_mask, bool), jnp.asarray(NEG, t.dtype), t)


def table_parts(table) -> tuple[np.ndarray, np.ndarray]:
    """Split a lattice table with ``-inf`` into ``(table_free float32, forbidden_mask bool)``;
    forbidden entries of ``table_free`` are 0."""
    t = np.asarray(table, dtype=np.float32)
    forbidden = ~np.isfinite(t) | (t <= NEG)
    return np.where(forbidden, 0.0, t).astype(np.float32), forbidden


def soft_parts(weights) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(table_free (3, 4, 4, 4) float32, forbidden (3, 4, 4, 4) bool, skip_free (3,) float32,
    must (3,) bool)`` of a model (:func:`jaxmatch.kernels.model.weights_of`); forbidden entries
    of ``table_free`` and must-match entries of ``skip_free`` are 0."""
    w = weights_of(weights)
    return (np.where(w.forbidden, 0.0, w.table).astype(np.float32).reshape(3, 4, 4, 4), w.forbidden.reshape(3, 4, 4, 4).copy(),
            np.where(w.must, 0.0, w.skip).astype(np.float32), w.must.copy())


def _shifted(table, forbidden, skip, must):
    """Shifted-frame weights ``(3, 4, 4, 4)``, skip gate ``(3,)`` and shift ``(3,)`` (exact.py's frame)."""
    t = jnp.asarray(table)
    dt = t.dtype if jnp.issubdtype(t.dtype, jnp.floating) else jnp.float32
    t = t.astype(dt).reshape(3, 64)
    must = jnp.asarray(must, bool)
    shift = jnp.where(must, jnp.asarray(0.0, dt), jnp.asarray(skip, dt))
    tw = jnp.where(jnp.asarray(forbidden, bool).reshape(3, 64), jnp.asarray(NEG, dt), t - shift[:, None])
    gate = jnp.where(must, jnp.asarray(NEG, dt), jnp.asarray(0.0, dt))
    return tw.reshape(3, 4, 4, 4), gate, shift


def _soft_core(codes, valid, vals, tw, gate, shift, gamma, unroll):
    """``(N,)`` soft utilities of meshes ``vals: (N, n)`` for one padded shape."""
    wc = orientation_weights(vals, tw)  # (3, n, N, 2n)
    last = dp_scan(wc, codes, valid, smooth_max(gamma), gate=gate, unroll=unroll)
    offset = jnp.sum(jnp.where(valid, shift[codes], 0.0))
    return smax(last[-1], gamma, -1) + offset  # over the 2n orientations of each mesh


@partial(jax.jit, static_argnames=("unroll",))
def _soft_one(codes, valid, vals, table, forbidden, skip, must, gamma, unroll=UNROLL):
    tw, gate, shift = _shifted(table, forbidden, skip, must)
    return _soft_core(codes, valid, vals, tw, gate, shift, jnp.asarray(gamma, tw.dtype), unroll)


@partial(jax.jit, static_argnames=("unroll",))
def soft_batch(codes, valid, vals, table, forbidden, skip, must, gamma, unroll=UNROLL):
    """Array form of :func:`soft_utility_batch` (for use inside a traced loss): ``table (3, 4, 4,
    4)``, ``forbidden`` like it, ``skip (3,)``, ``must (3,)`` as in :func:`soft_parts`."""
    tw, gate, shift = _shifted(table, forbidden, skip, must)
    g = jnp.asarray(gamma, tw.dtype)
    return jax.vmap(lambda c, v: _soft_core(c, v, vals, tw, gate, shift, g, unroll))(codes, valid)


def _model_arrays(weights, table, skip):
    tf, forbidden, sf, must = soft_parts(weights)
    return (tf if table is None else table), forbidden, (sf if skip is None else skip), must


def soft_utility(codes, vals, weights, gamma, *, table=None, skip=None, m_pad: int | None = None, unroll: int = UNROLL):
    """Soft utilities ``(N,)`` of meshes ``vals: (N, n)`` against one shape ``codes: (m,)``.

    weights: the model (:func:`jaxmatch.kernels.model.weights_of`); ``table (3, 4, 4, 4)`` and
    ``skip (3,)``, when given, replace its free values (forbidden / must-match entries stay
    fixed at NEG). Differentiable in ``table``, ``skip`` and ``gamma``; traceable
    (``codes``/``vals`` may be traced, their shapes are static). ``m`` is padded to
    :func:`bucket_length` (or ``m_pad``) with padded points skipped, which does not change the value.
    """
    c = jnp.asarray(codes, jnp.int32).reshape(-1)
    m = c.shape[0]
    mp = bucket_length(m) if m_pad is None else int(m_pad)
    if mp < m:
        raise ValueError(f"m_pad={mp} < m={m}")
    v = jnp.asarray(vals, jnp.int32)
    if v.ndim == 1:
        v = v[None]
    c = jnp.pad(c, (0, mp - m))
    valid = jnp.arange(mp) < m
    return _soft_one(c, valid, v, *_model_arrays(weights, table, skip), gamma, unroll=unroll)


def pad_shapes(shapes: Sequence, m_pad: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Stack shape annotations of different lengths: ``(codes (S, m_pad) int32, valid (S, m_pad) bool)``.

    ``m_pad`` defaults to :func:`bucket_length` of the longest shape.
    """
    lens = [len(np.asarray(s).reshape(-1)) for s in shapes]
    mp = bucket_length(max(lens, default=1)) if m_pad is None else int(m_pad)
    if lens and max(lens) > mp:
        raise ValueError(f"m_pad={mp} < longest shape {max(lens)}")
    codes = np.zeros((len(shapes), mp), np.int32)
    valid = np.zeros((len(shapes), mp), bool)
    for k, s in enumerate(shapes):
        s = np.asarray(s, np.int32).reshape(-1)
        codes[k, : s.shape[0]] = s
        valid[k, : s.shape[0]] = True
    return codes, valid


def soft_utility_batch(codes, valid, vals, weights, gamma, *, table=None, skip=None, unroll: int = UNROLL):
    """Soft utilities ``(S, N)`` of meshes ``vals: (N, n)`` against ``S`` padded shapes.

    codes, valid: ``(S, m_pad)`` from :func:`pad_shapes` (invalid points are skipped);
    weights, table, skip: as in :func:`soft_utility`. ``vmap`` over shapes of the same DP;
    differentiable in ``table`` and ``skip``. Entry ``[s, k]`` equals ``soft_utility(shape s,
    vals[k:k+1], ...)``; ``n`` greater than shape ``s``'s length gives a value ``<= NEG / 2``.
    """
    v = jnp.asarray(vals, jnp.int32)
    if v.ndim == 1:
        v = v[None]
    return soft_batch(jnp.asarray(codes, jnp.int32), jnp.asarray(valid, bool), v, *_model_arrays(weights, table, skip), gamma,
                      unroll=unroll)
