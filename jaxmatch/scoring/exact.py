"""Exact scorer: the paper's modified LCS between a shape annotation and mesh boundaries.

Problem
-------
``codes: (m,) int`` is the shape's annotation, 0 = ``s`` straight, 1 = ``x`` convex,
2 = ``v`` concave; its start is fixed. A mesh boundary is a ccw valence sequence
``vals: (n,)`` with valences in {2, 3, 4, 5}. The scoring model is a
:class:`jaxmatch.kernels.model.Weights` (a lattice compiles to one; a bare ``(3, 4, 4, 4)``
table means skip weights 0): match weights ``table[code, u - 2, v - 2, w - 2]`` (integers or
``-inf`` = forbidden) and skip weights ``skip[code]`` (integers or ``-inf`` = the point must
get a mesh vertex).

Every mesh boundary vertex ``j`` (of an *oriented* sequence, see below) is matched to its own
input point ``i_j`` with ``i_0 < i_1 < ... < i_{n-1}`` (input points may be skipped, mesh
vertices may not). The utility is ``sum_j table[codes[i_j], t_j] + sum over skipped points i of
skip[codes[i]]`` where ``t_j`` is the boundary triple of oriented vertex ``j``. A mesh's score
is the best utility over all alignments and all ``2n`` orientations.

Orientation convention (exact; :func:`oriented_sequence`)
---------------------------------------------------------
* ``s = vals`` when not reflected, ``s = vals[::-1]`` when reflected (the mirrored mesh;
  reversing swaps the ccw and cw neighbours, i.e. ``u`` and ``w`` of every triple);
* ``s_r = np.roll(s, -r)``, so ``s_r[0] = s[r]``: mesh vertex ``r`` of ``s`` is matched first;
* triples ``t_j = [s_r[j+1], s_r[j], s_r[j-1]]`` (cyclic), as :func:`jaxmatch.catalogue.mesh.triples`;
* ``alignment[j]`` is the input index taken by ``s_r[j]``.

Orientation index ``o`` in ``0 .. 2n-1``: ``o = r`` for rotations of ``vals``, ``o = n + r``
for rotations of ``vals[::-1]``. Ties between orientations go to the smallest ``o``
(smallest rotation, non-reflected before reflected).

Dynamic programme
-----------------
``D[i][j]`` = best utility matching the first ``j`` oriented vertices into the first ``i``
input points::

    D[0][0] = 0,  D[0][j > 0] = -inf,  D[i][0] = D[i-1][0] + skip[codes[i-1]]
    D[i][j] = reduce(D[i-1][j] + skip[codes[i-1]], D[i-1][j-1] + W[i-1, j-1])

answer ``D[m][n]``. ``reduce`` is ``max`` here; :mod:`jaxmatch.scoring.soft` passes the smoothed
maximum to the very same core (:func:`dp_scan`).

*Shifted frame.* For a type with a finite skip weight, subtracting ``skip[c]`` from every match
weight of ``c`` and adding ``sum_i skip[codes[i]]`` (the same for every alignment: every point is
either matched or skipped) gives the same utility. So all scorers run the recurrence on
``E = D - S_i`` (``S_i`` the skip weights of the first ``i`` points of finite-skip types):
``E[i][j] = reduce(E[i-1][j] + gate[c], E[i-1][j-1] + W'[i-1, j-1])`` with ``W' = W - skip[c]``,
``gate[c] = 0`` (or ``-inf`` for a must-match type, which also turns ``E[i][0]`` into ``-inf``),
and add the offset ``S_m`` at the end (:func:`skip_frame`). With all skip weights 0 this is
the paper's recurrence unchanged, bit for bit.

Forbidden weights are replaced by the finite ``NEG`` (never ``-inf`` inside the DP); a mesh
whose best value is ``<= NEG / 2``, or with ``n > m``, is *unmatchable*: utility ``-inf``,
``unmatchable`` true, rotation ``-1``.

Implementation
--------------
:func:`dp_scan` is the generic form (one ``jax.lax.scan`` over input points, any reduction;
used by :mod:`jaxmatch.scoring.soft`); :func:`dp_rows` is the same recurrence in numpy for one
orientation (the rows :func:`align` backtracks). Exact scoring goes through one host,
:func:`exact_values`: it compiles the model for a DP number type (:func:`dp_problem`: the
narrowest exact one, :func:`dp_kind`: int16 for the shipped lattices), pads input lengths to
a few bucket sizes (:func:`bucket_length`) and mesh batches to a fixed chunk size
(:func:`plan_chunks`), hands the padded chunks to a *backend* and turns the raw values back
into utilities. Backends (:class:`Backend`): :class:`jaxmatch.kernels.backends.NumbaBackend`
(the default on CPUs), :class:`CPUBackend` (the XLA kernel: the max-plus recurrence in a flat
``(n, 2n * block)`` layout with cache-sized blocks, :func:`final_blocks`, calls dispatched on
several host threads) and :class:`jaxmatch.scoring.bulk.ShardedBackend` (the same blocks over
several devices). A new backend (e.g. a GPU kernel) implements ``mesh_lanes`` and ``run``; it
never sees the padding or the chunking. Weights are integers, so all number types give
identical utilities. Measurements: ``docs/perf.md``.

Layering: the problem contract (:class:`DPProblem`, :class:`DPKind`, :class:`Backend`,
:func:`run_calls`, ...) lives in :mod:`jaxmatch.kernels.problem` (re-exported here), which the
kernels (:mod:`jaxmatch.kernels.backends`, :mod:`jaxmatch.kernels.dp_xla`) import; no kernel imports
this module. This host picks the default backend from :mod:`jaxmatch.kernels.backends`.

This module imports numpy only. The JAX code (:func:`dp_scan`, :func:`final_blocks`,
:class:`CPUBackend`, :func:`orientation_weights`, ...) lives in :mod:`jaxmatch.kernels.dp_xla` and
is re-exported here on first access (:data:`XLA_NAMES`), so JAX is loaded only when one of
those names is used: the default CPU path (numba backend, numpy :func:`align`) never loads it.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.catalogue.mesh import triples
from jaxmatch.errors import UnmatchableError
from jaxmatch.kernels.backends import NumbaBackend, c_align, c_kernel, default_backend
from jaxmatch.kernels.model import (  # noqa: F401 (SkipFrame re-exported)
    NEG,
    SkipFrame,
    skip_frame,
    skip_offset,
    skipped_weight,
    weights_of,
)
from jaxmatch.lazy import served_from
from jaxmatch.kernels.problem import (  # noqa: F401 (the problem contract, re-exported)
    _INVALID,
    UNROLL,
    Backend,
    DPKind,
    DPProblem,
    _rotation_index,
    default_threads,
    run_calls,
)

DEFAULT_BATCH = 256
"""Meshes per compiled call of :func:`score_bucket`."""

_MIN_BATCH = 8


class ScoreResult(NamedTuple):
    """Scores of a bucket of meshes against one shape (all arrays ``(N,)``)."""

    utility: np.ndarray
    """float32, best utility; ``-inf`` where unmatchable."""
    rotation: np.ndarray
    """int32, ``r`` of the winning orientation (see module docstring); ``-1`` where unmatchable."""
    reflected: np.ndarray
    """bool, the winning orientation uses ``vals[::-1]``; False where unmatchable."""
    unmatchable: np.ndarray
    """bool, no alignment avoids forbidden weights (or ``n > m``)."""


# --------------------------------------------------------------------------- helpers


def bucket_length(m: int) -> int:
    """Padded input length for an input of length ``m``.

    Multiples of 16 up to 128, then multiples of 64 (so a handful of compiled lengths).
    """
    m = max(int(m), 1)
    if m <= 128:
        return 16 * -(-m // 16)
    return 64 * -(-m // 64)


def _checked_codes(codes, m_pad: int | None) -> tuple[np.ndarray, int]:
    """``(codes (m,) int32, m_pad)`` (default :func:`bucket_length`); ValueError for a code other
    than 0/1/2 or ``m_pad < m``."""
    c = np.asarray(codes, dtype=np.int32).reshape(-1)
    m = c.shape[0]
    if c.size and (c.min() < 0 or c.max() > 2):
        raise ValueError("codes must be 0 (s), 1 (x) or 2 (v)")
    m_pad = bucket_length(m) if m_pad is None else int(m_pad)
    if m_pad < m:
        raise ValueError(f"m_pad={m_pad} < m={m}")
    return c, m_pad


def pad_codes(codes, m_pad: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(codes_pad (m_pad,) int32, valid (m_pad,) bool)``; padded points are invalid (skipped)."""
    c, m_pad = _checked_codes(codes, m_pad)
    m = c.shape[0]
    out = np.zeros(m_pad, np.int32)
    out[:m] = c
    return out, np.arange(m_pad) < m


def oriented_sequence(vals_one, rotation: int, reflected: bool) -> np.ndarray:
    """The ``(n,)`` valences in matched order: ``np.roll(vals[::-1] if reflected else vals, -rotation)``."""
    s = np.asarray(vals_one, dtype=np.int32).reshape(-1)
    if reflected:
        s = s[::-1]
    return roll(s, -int(rotation))


# --------------------------------------------------------------------------- the CPU kernel

BLOCK_CELLS = 16384
"""Target DP cells per scan step of one block (``block * 2n * n``): the carry, the four weight
slabs and the new row of a block then stay in the L2 cache (docs/perf.md)."""

NEG16 = -16384
"""Sentinel for the int16 DP (``2 * NEG16`` is still an int16)."""

NEG32 = -(2**30)
"""Sentinel for the int32 DP."""

def dp_kind(weights, n: int) -> DPKind:
    """Narrowest exact number type for the DP of a model (or table) with boundary length ``n``.

    On the shifted weights ``W'`` (:func:`skip_frame`): integers with ``n * max|W'| < 2**13``
    use int16 (16 SIMD lanes on AVX2; values stay in ``[2 * NEG16, n * max|W'|]``, valid ones
    above ``NEG16 / 2``, invalid ones at or below it), integers with ``n * max|W'| < 2**29``
    int32, anything else float32 with :data:`NEG` (bit for bit the recurrence of
    :func:`dp_scan`). All three give identical utilities.
    """
    return dp_kinds(weights, [n])[int(n)]


def dp_kinds(weights, ns) -> dict[int, DPKind]:
    """:func:`dp_kind` of every boundary length in ``ns`` (``{n: kind}``), the model read once
    (a ranking scores several lengths against one model)."""
    t = skip_frame(weights).table
    w = t[t > NEG / 2]
    big = float(abs(w).max()) if w.size else 0.0
    integral = w.size == 0 or bool((w == w.round()).all())
    out = {}
    for n in ns:
        kind = DPKind(np.float32, NEG)
        if integral and int(n) * big < 2**13:
            kind = DPKind(np.int16, float(NEG16))
        elif integral and int(n) * big < 2**29:
            kind = DPKind(np.int32, float(NEG32))
        out[int(n)] = kind
    return out


def dp_table(weights, kind: DPKind) -> np.ndarray:
    """``(4, 64)`` shifted weights ``W'`` in ``kind.dtype``: rows = codes s, x, v and the padding
    code 3; forbidden entries and the whole padding row are ``kind.neg``."""
    t = skip_frame(weights).table
    out = np.full((4, 64), kind.neg, np.float64)
    out[:3] = np.where(t > NEG / 2, t, kind.neg)
    return out.astype(kind.dtype)


def dp_gate(weights, kind: DPKind) -> np.ndarray:
    """``(4,)`` in ``kind.dtype``: the cap on the skip branch per code (``kind.neg`` for a
    must-match type, the largest value of the type otherwise and for padding)."""
    top = np.inf if np.dtype(kind.dtype).kind == "f" else np.iinfo(kind.dtype).max
    g = np.full(4, top, np.float64)
    g[:3][skip_frame(weights).gate] = kind.neg
    return g.astype(kind.dtype)


def block_size(n: int, cells: int = BLOCK_CELLS) -> int:
    """Meshes per block: the largest power of two with ``block * 2n * n <= cells`` (at least 1)."""
    per = 2 * n * n
    return 1 << max(int(cells // per).bit_length() - 1, 0)


def _check_vals(vals) -> np.ndarray:
    v = np.asarray(vals, dtype=np.int32)
    if v.ndim == 1:
        v = v[None]
    if v.ndim != 2 or v.shape[1] == 0:
        raise ValueError(f"vals must be (N, n) with n >= 1, got shape {v.shape}")
    if v.size and (v.min() < 2 or v.max() > 5):
        raise ValueError("boundary valences must be in 2..5")
    return v


def dp_codes(codes, m_pad: int | None = None) -> np.ndarray:
    """``(m_pad,) int32`` codes for :func:`final_blocks`: padding points get code 3."""
    c, valid = pad_codes(codes, m_pad)
    return np.where(valid, c, _INVALID).astype(np.int32)


def plan_chunks(big_n: int, n: int, batch: int = DEFAULT_BATCH) -> tuple[int, int]:
    """``(block, blocks per call)`` for ``big_n`` meshes of boundary length ``n``: calls hold
    ``min(batch, next power of two >= big_n)`` meshes (at least 8), as blocks of
    :func:`block_size` meshes; one compilation per (padded m, n, block, blocks per call)."""
    chunk = max(_MIN_BATCH, min(int(batch), 1 << max(big_n - 1, 0).bit_length()))
    block = min(block_size(n), chunk)
    return block, -(-chunk // block)


# --------------------------------------------------------------------------- the exact host


def dp_problem(codes_list: Sequence, weights, n: int, m_pad: int | None = None, kind: DPKind | None = None) -> DPProblem:
    """:class:`DPProblem` for shapes ``codes_list`` (each ``(m_s,)`` ints 0/1/2), padded to
    ``m_pad`` (default :func:`bucket_length` of the longest), and boundary length ``n``."""
    w = weights_of(weights)
    shapes = [np.asarray(c, np.int32).reshape(-1) for c in codes_list]
    mp = bucket_length(max((len(c) for c in shapes), default=1)) if m_pad is None else int(m_pad)
    codes = np.full((len(shapes), mp), _INVALID, np.int32)
    for i, c in enumerate(shapes):
        codes[i, :c.shape[0]] = _checked_codes(c, mp)[0]  # (dp_codes: padding points get code 3)
    kind = dp_kind(w, n) if kind is None else kind
    return DPProblem(codes, np.asarray([len(c) for c in shapes], np.int64),
                     np.asarray([skip_offset(c, w) for c in shapes], np.float64),
                     dp_table(w, kind), dp_gate(w, kind), bool(w.must.any()), kind, int(n))


def exact_values(
    codes_list: Sequence,
    vals,
    weights,
    *,
    backend: Backend | None = None,
    batch: int = DEFAULT_BATCH,
    m_pad: int | None = None,
    plan: tuple[int, int] | None = None,
    problem: DPProblem | None = None,
) -> np.ndarray:
    """The exact host: best utility of every orientation of every mesh against every shape,
    ``(S, N, 2n) float32``, ``-inf`` where an orientation has no finite alignment (or ``n > m``).

    codes_list: ``S`` shapes ``(m_s,)``; vals: ``(N, n)`` boundary valences; weights: the model
    (:func:`jaxmatch.kernels.model.weights_of`). Meshes are padded to whole calls of
    ``mesh_lanes x blocks per call x block`` (:func:`plan_chunks` of ``batch``, or ``plan``),
    except for the int16 kernels of :class:`~jaxmatch.kernels.backends.NumbaBackend`, which
    take the meshes as they are;
    ``backend`` (default :func:`jaxmatch.kernels.backends.default_backend`) computes the raw values.
    ``problem``: ``dp_problem(codes_list, weights, n, m_pad)`` when the caller has it.
    """
    if backend is None:
        backend = default_backend()
    v = _check_vals(vals)
    big_n, n = v.shape
    prob = dp_problem(codes_list, weights, n, m_pad) if problem is None else problem
    if prob.n != n:
        raise ValueError(f"the problem is for boundary length {prob.n}, the meshes have {n}")
    if isinstance(backend, NumbaBackend) and np.dtype(prob.kind.dtype) == np.int16:
        # its int16 kernels (C or numba) take any number of meshes, each computed alone: no
        # padding meshes (a part of 3 meshes is not scored as a block of 64)
        raw = backend.run(prob, v.reshape(1, 1, big_n, n))
    else:
        lanes = max(int(backend.mesh_lanes), 1)
        block, per_call = plan if plan is not None else plan_chunks(-(-big_n // lanes), n, batch)
        chunk = lanes * per_call * block
        n_calls = -(-big_n // chunk)
        vp = np.full((n_calls * chunk, n), 2, np.int32)
        vp[:big_n] = v
        raw = backend.run(prob, vp.reshape(n_calls, lanes * per_call, block, n))[:, :big_n]
    out = raw.astype(np.float64) + prob.offset[:, None, None]
    out[raw <= prob.kind.neg / 2] = -np.inf
    out[prob.lengths < n] = -np.inf
    return out.astype(np.float32)


def final_values(
    codes,
    vals,
    weights,
    *,
    batch: int = DEFAULT_BATCH,
    m_pad: int | None = None,
    unroll: int = UNROLL,
    threads: int | None = None,
    plan: tuple[int, int] | None = None,
    backend: Backend | None = None,
    problem: DPProblem | None = None,
) -> np.ndarray:
    """Best utility of every orientation for one shape: ``(N, 2n) float32``, ``-inf`` where the
    orientation has no finite alignment (or ``n > m``). Column ``o`` is orientation ``o`` of the
    module docstring. :func:`exact_values` for one shape (``threads``, ``unroll``: of the
    default backend, :func:`jaxmatch.kernels.backends.default_backend`; ``problem``: as there)."""
    if backend is None:
        backend = default_backend(threads, unroll)
    return exact_values([codes], vals, weights, backend=backend, batch=batch, m_pad=m_pad, plan=plan,
                        problem=problem)[0]


def reduce_orientations(values: np.ndarray) -> ScoreResult:
    """:class:`ScoreResult` from per-orientation values ``(N, 2n)`` (:func:`final_values`): the
    best value, ties to the smallest orientation index."""
    values = np.asarray(values, np.float32)
    big_n, two_n = values.shape
    n = two_n // 2
    best = values.max(axis=1) if big_n else np.empty(0, np.float32)
    orient = values.argmax(axis=1) if big_n else np.empty(0, np.int64)
    unmatchable = ~np.isfinite(best)
    utility = np.where(unmatchable, -np.inf, best).astype(np.float32)
    rotation = np.where(unmatchable, -1, orient % max(n, 1)).astype(np.int32)
    reflected = (~unmatchable) & (orient >= n)
    return ScoreResult(utility, rotation, reflected, unmatchable)


def score_bucket(
    codes,
    vals,
    weights,
    *,
    batch: int = DEFAULT_BATCH,
    m_pad: int | None = None,
    unroll: int = UNROLL,
    threads: int | None = None,
    backend: Backend | None = None,
) -> ScoreResult:
    """Score every mesh of one bucket (all of boundary length ``n``) against ``codes``.

    codes: ``(m,)`` ints 0/1/2; vals: ``(N, n)`` ccw boundary valences; weights: the model (a
    :class:`jaxmatch.kernels.model.Weights`, a lattice, or a ``(3, 4, 4, 4)`` table with ``-inf``
    for forbidden and skip weights 0). ``m`` is padded to :func:`bucket_length` (or ``m_pad``),
    the meshes to a multiple of the chunk size ``min(batch, next power of two >= N)`` (at least
    8), cut into cache-sized blocks (:func:`block_size`); one compilation per (padded m, n,
    block, chunk). The DP runs in the narrowest exact number type (:func:`dp_kind`); chunks are
    dispatched on ``threads`` host threads (default: every CPU this process may use).
    """
    return reduce_orientations(final_values(codes, vals, weights, batch=batch, m_pad=m_pad, unroll=unroll,
                                            threads=threads, backend=backend))


# --------------------------------------------------------------------------- one mesh


def dp_rows(codes, seq, weights) -> np.ndarray:
    """All DP rows ``(m + 1, n + 1) float32`` of one oriented sequence (shifted frame).

    codes: ``(m,)`` ints 0/1/2; seq: ``(n,)`` valences in matched order
    (:func:`oriented_sequence`); weights: the model. Row ``i`` is ``E[i]`` of
    :func:`dp_scan` with ``reduce = max`` and the model's gate (``keep_rows=True``, unpadded):
    the same float32 operations in the same order, so the same values bit for bit (tested).
    numpy only (``m`` vector steps of length ``n``; no compilation).
    """
    fr = skip_frame(weights)
    s = np.asarray(seq, np.int64).reshape(-1)
    c = np.asarray(codes, np.int64).reshape(-1)
    m, n = c.shape[0], s.shape[0]
    flat = (np.roll(s, -1) - 2) * 16 + (s - 2) * 4 + (np.roll(s, 1) - 2)  # triple [s[j+1], s[j], s[j-1]]
    wc = fr.table.astype(np.float32).reshape(3, 64)[:, flat]  # (3, n): W'[code, j]
    gate = np.where(fr.gate, NEG, 0.0).astype(np.float32)
    rows = np.empty((m + 1, n + 1), np.float32)
    rows[0, 0] = 0.0
    rows[0, 1:] = NEG
    for i in range(m):
        prev, cur, g = rows[i], rows[i + 1], gate[c[i]]
        np.maximum(prev[1:] + g, prev[:-1] + wc[c[i]], out=cur[1:])  # skip point i, or match it to vertex j - 1
        cur[0] = prev[0] + g
    return rows


_NO_ALIGNMENT = "every alignment of this orientation uses a forbidden weight or skips a point that must be matched"


def align(codes, vals_one, weights, rotation: int, reflected: bool, *, m_pad: int | None = None) -> np.ndarray:
    """Best alignment for one orientation: ``(n,) int32`` strictly increasing input indices.

    ``alignment[j]`` is the input point taken by ``oriented_sequence(vals_one, rotation,
    reflected)[j]``. Backtracks the DP rows (:func:`dp_rows`, the recurrence of :func:`dp_scan`
    for this one orientation, shifted frame) from ``D[m][n]``; at a tie between skipping input
    point ``i - 1`` (allowed unless its type must be matched) and matching it, skipping wins (so
    each vertex takes the earliest best point counted from the end). Raises
    :class:`UnmatchableError` when this orientation has no finite alignment. ``m_pad`` is only
    checked (``>= m``): padded points never change the rows up to ``m``. Rows and backtrack run
    in C when its library is built (:func:`jaxmatch.kernels.backends.c_kernel`: the same float32
    operations in the same order, so the same alignment, tested), else in numpy.
    """
    seq = oriented_sequence(vals_one, rotation, reflected)
    n = seq.shape[0]
    c = np.asarray(codes, dtype=np.int32).reshape(-1)
    m = c.shape[0]
    if n > m:
        raise UnmatchableError(f"mesh has {n} boundary vertices but the shape only {m} points")
    _check_vals(seq)
    _checked_codes(c, m_pad)  # checks the codes (and m_pad)
    fr = skip_frame(weights)
    if c_kernel() is not None:  # the same rows and backtrack in C (jaxmatch/kernels/_dp.c)
        out = c_align(c, seq, fr.table, fr.gate, NEG)
        if out is None:
            raise UnmatchableError(_NO_ALIGNMENT)
        return out
    rows = dp_rows(c, seq, weights)
    if rows[m, n] <= NEG / 2:
        raise UnmatchableError(_NO_ALIGNMENT)
    out = np.empty(n, np.int32)
    i, j = m, n
    while j > 0:
        if i > j and not fr.gate[c[i - 1]] and rows[i, j] == rows[i - 1, j]:
            i -= 1  # skip input point i-1
        else:
            out[j - 1] = i - 1
            i, j = i - 1, j - 1
    return out


class UtilityParts(NamedTuple):
    """An alignment's utility split: ``match`` (sum of the matched pairs' weights) + ``skip``
    (sum of the skipped points' skip weights) = ``total``; ``-inf`` parts when forbidden."""

    total: float
    match: float
    skip: float


def utility_parts(codes, vals_one, weights, rotation: int, reflected: bool, alignment) -> UtilityParts:
    """:class:`UtilityParts` of one explicit alignment (numpy, the model's ``-inf`` entries as
    ``-inf``). ValueError when the alignment is not strictly increasing in range."""
    w = weights_of(weights)
    seq = oriented_sequence(vals_one, rotation, reflected)
    n = seq.shape[0]
    c = np.asarray(codes, dtype=np.int64).reshape(-1)
    a = np.asarray(alignment, dtype=np.int64).reshape(-1)
    if a.shape[0] != n:
        raise ValueError(f"alignment has length {a.shape[0]}, mesh has {n} boundary vertices")
    al = a.tolist()
    if n and (al[0] < 0 or al[-1] >= c.shape[0] or any(x >= y for x, y in zip(al, al[1:]))):
        raise ValueError("alignment must be strictly increasing input indices in range")
    t = triples(seq) - 2
    rows, cols = c[a], (t[:, 0] * 4 + t[:, 1]) * 4 + t[:, 2]  # each pair's entry of the (3, 64) table
    # (table_inf's entries: -inf where forbidden, the float32 weight otherwise)
    match = float(np.sum(np.where(w.forbidden[rows, cols], -np.inf, w.table[rows, cols]).astype(np.float64)))
    skip = skipped_weight(c, a, w)
    return UtilityParts(match + skip, match, skip)


def utility_of(codes, vals_one, weights, rotation: int, reflected: bool, alignment) -> float:
    """Utility of one explicit alignment, skip weights included (:func:`utility_parts`;
    ``-inf`` if it uses a forbidden weight or skips a point that must be matched)."""
    return utility_parts(codes, vals_one, weights, rotation, reflected, alignment).total


# --------------------------------------------------------------------------- the JAX side, on demand

XLA_NAMES = frozenset({"CPUBackend", "dp_scan", "final_blocks", "finite_table", "orientation_slabs",
                       "orientation_triples", "orientation_weights", "oriented_sequences", "_blocks", "_final_block"})
"""Names served from :mod:`jaxmatch.kernels.dp_xla` (importing it imports JAX) on first access."""


__getattr__ = served_from("jaxmatch.kernels.dp_xla", XLA_NAMES, globals())  # (importing it imports JAX)
