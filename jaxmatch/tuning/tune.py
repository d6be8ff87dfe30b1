"""Tune a lattice's level weights on labelled shapes (soft scorer, optax).

What is tuned
-------------
The *level weights* of a lattice (:func:`jaxmatch.scoring.lattice.level_structure`), never the
192 table entries one by one: every triple keeps its level, and ``-inf`` entries (weeded and
forbidden) stay ``-inf`` (they are fixed at ``NEG`` inside the soft scorer and get exactly zero
gradient). And the three *skip weights* (``[skip]``; ``tune_skip=False`` keeps them): finite
ones are free parameters, ``-inf`` ones stay ``-inf``. The order of the levels survives by construction: per point type, the parameters
are the best level's weight ``a`` and one number ``d_l`` per lower level, and

    w_0 = a,    w_l = w_{l-1} - softplus(d_l)        (l = 1, 2, ...)

so a lower level always weighs strictly less (before rounding; rounding to integers keeps
``w_l <= w_{l-1}``). Levels that were equal start ``MIN_GAP`` apart.

Loss
----
Each example is a shape and its preferred mesh of size ``k`` (internal vertices); the
*candidates* are the catalogue meshes of that size (the size the user fixes with
``--internal k``). At most ``max_candidates`` (default 256) take part in training: all 96
meshes of k = 3; for k = 4 (1283 meshes) every preferred mesh of the training examples plus a
sample drawn with the seed (:func:`candidates`). Evaluation always uses all. With the soft utilities
``U_q`` at temperature ``gamma`` (:func:`jaxmatch.scoring.soft.soft_utility_batch`: a log-sum-exp
over all orientations and alignments of mesh ``q``) the loss is the softmax cross-entropy

    loss = mean over examples of [ logsumexp_q(U_q / gamma) - U_p / gamma ]
           + l2 * mean over levels of (w - w_initial) ** 2

i.e. ``-log P(preferred)`` under the Gibbs distribution over (mesh, orientation, alignment)
pairs with energy ``-utility / gamma``. Meshes with the preferred mesh's boundary valence
cycle (up to rotation and reflection: *twins*, which every lattice scores alike) are left out
of the competition; examples whose preferred mesh cannot be matched at all (the fixed
``-inf`` entries forbid it) are reported and get no weight. Optimiser: optax Adam on
mini-batches; examples are shuffled by ``numpy.random.default_rng(seed)``; JAX on CPU is
deterministic, so the same seed and data give the same weights. Every gradient is checked
with ``isfinite`` (a :class:`FloatingPointError` stops the run).

Rounding
--------
Lattice files hold integers. Utilities are compared within one shape only, so multiplying
all weights by a positive scale changes no ranking: the tuned weights ``w`` are written as
``round(scale * w)`` with the scale (from :data:`SCALES`, keeping ``|weight| <= MAX_WEIGHT``)
whose rounded lattice ranks the *training* examples best with the exact scorer
(pessimistic top-1, then top-5, then the smaller scale). The report evaluates the rounded
lattice, i.e. exactly what is written (and, for comparison, the unrounded weights).

Evaluation (exact scorer)
-------------------------
For each example, the shape is annotated with ``m = default_points(shape, longest boundary of
the size-k meshes)`` points, as ``jaxmatch score --internal k`` does, and every catalogue
mesh of size ``k`` is scored with the exact DP (same recurrence as
:func:`jaxmatch.scoring.exact.score_bucket`). A competitor *beats* the preferred mesh ``p`` when its
utility is higher, and, at equal utility:

* ``top1`` / ``top5`` (**pessimistic**): every tie counts against ``p``;
* ``top1_by_id`` / ``top5_by_id``: a tie counts against ``p`` only when the competitor comes
  first in ``jaxmatch score``'s order (shorter boundary, then smaller id).

Twins of ``p`` are not competitors. ``top1`` is the fraction of examples that no competitor
beats, ``top5`` the fraction beaten by at most four. An unmatchable preferred mesh is beaten
by every competitor.

Skip weights: only their differences to the match weights of the same type matter for a
ranking within one size up to a constant per shape (a mesh of ``n`` vertices always skips
``m - n`` points), so a uniform skip weight changes nothing; per type they make a skipped
corner cost more than a skipped straight point. The exact evaluation uses the one exact host
(:func:`jaxmatch.scoring.exact.exact_values`).
"""

from __future__ import annotations

import math
import time
from typing import Callable, NamedTuple, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmatch.catalogue.store import Catalogue
from jaxmatch.tuning.labels import Example, MeshIndex, boundary_key, mesh_index
from dataclasses import replace

from jaxmatch.scoring.exact import exact_values
from jaxmatch.scoring.lattice import MAX_WEIGHT, Lattice, LevelStructure, level_structure, table_from_levels, with_level_weights
from jaxmatch.kernels.model import NEG, make_weights, weights_of
from jaxmatch.scoring.soft import pad_shapes, soft_batch, soft_parts
from jaxmatch.shape import annotate, default_points

__all__ = [
    "Candidates",
    "Encoded",
    "MIN_GAP",
    "SCALES",
    "TIE_RULE",
    "TuneResult",
    "candidates",
    "choose_scale",
    "encode",
    "evaluate",
    "exact_utilities",
    "init_params",
    "params_to_weights",
    "rank_positions",
    "run_tuning",
    "split_examples",
    "train",
]

MIN_GAP = 0.01
"""Starting gap between levels that had equal weights (softplus never reaches 0)."""

SCALES = (1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 25, 32, 50, 64, 100)
"""Scales tried before rounding the tuned weights to integers."""

TIE_RULE = (
    "top1/top5: pessimistic (every competitor with an equal utility beats the preferred mesh); "
    "top1_by_id/top5_by_id: ties go to jaxmatch score's order (shorter boundary, then smaller id); "
    "meshes with the preferred mesh's boundary valence cycle (twins) are not competitors"
)

_SHAPE_CHUNK = 32  # shapes per compiled exact-scoring call


# ---------------------------------------------------------------------------------------------
# parametrisation


def _segments(structure: LevelStructure) -> list[tuple[int, int]]:
    """``[start, stop)`` of each type's levels in :func:`level_structure` order."""
    out = []
    types = np.asarray(structure.types)
    for t in range(3):
        idx = np.flatnonzero(types == t)
        if idx.size:
            out.append((int(idx[0]), int(idx[-1]) + 1))
    return out


def init_params(structure: LevelStructure, weights=None) -> np.ndarray:
    """Parameters ``(L,) float32`` that give ``weights`` (default: the lattice's own)."""
    w = np.asarray(structure.weights if weights is None else weights, np.float64)
    p = np.empty_like(w)
    for a, b in _segments(structure):
        p[a] = w[a]
        gap = np.maximum(w[a:b - 1] - w[a + 1:b], MIN_GAP)
        p[a + 1:b] = gap + np.log(-np.expm1(-gap))  # softplus^-1
    return p.astype(np.float32)


def params_to_weights(params, structure: LevelStructure):
    """Level weights ``(L,)`` from parameters (JAX-differentiable; see the module docstring)."""
    return _weights(jnp.asarray(params), tuple(_segments(structure)))


# ---------------------------------------------------------------------------------------------
# data


class Candidates(NamedTuple):
    """The competing meshes of one size ``k``, in ``jaxmatch score`` order (n, then id).

    buckets: ``[(n, vals (N_n, n) int32)]``; their concatenation is ``ids``.
    max_n: the longest boundary of *all* size-k meshes (sets the number of shape points).
    keys: boundary valence cycle of each id (:func:`jaxmatch.tuning.labels.boundary_key`).
    """

    k: int
    ids: list
    buckets: list
    max_n: int
    keys: list


def candidates(index: MeshIndex, k: int, *, keep: Sequence[str] = (), max_candidates: int | None = None, seed: int = 0) -> Candidates:
    """All meshes of size ``k``; with ``max_candidates`` smaller than their number, the ids in
    ``keep`` plus a sample drawn with ``numpy.random.default_rng(seed)`` from the others (same
    seed, same sample), still in ranking order."""
    ids = list(index.by_k.get(k, []))
    if not ids:
        raise ValueError(f"no catalogue mesh with {k} internal vertices")
    max_n = max(index.where[i][1] for i in ids)
    if max_candidates is not None and len(ids) > max_candidates:
        must = sorted(set(keep) & set(ids))
        rest = [i for i in ids if i not in set(must)]
        extra = max(int(max_candidates) - len(must), 0)
        pick = np.random.default_rng(seed).choice(len(rest), size=min(extra, len(rest)), replace=False)
        chosen = set(must) | {rest[j] for j in pick}
        ids = [i for i in ids if i in chosen]
    buckets = []
    for n in sorted({index.where[i][1] for i in ids}):
        sel = [i for i in ids if index.where[i][1] == n]
        buckets.append((n, np.stack([index.vals[i] for i in sel]).astype(np.int32)))
    ids = [i for n, _ in buckets for i in ids if index.where[i][1] == n]
    return Candidates(k, ids, buckets, max_n, [boundary_key(index.vals[i]) for i in ids])


class Encoded(NamedTuple):
    """Examples of one size, annotated: ``codes``, ``valid`` ``(S, m_pad)``; ``pos (S,)`` index
    of the preferred mesh in the candidates; ``twin (S, N) bool`` twins of it (excluded)."""

    codes: np.ndarray
    valid: np.ndarray
    pos: np.ndarray
    twin: np.ndarray


def encode(examples: Sequence[Example], cands: Candidates) -> Encoded:
    """Annotate each shape with ``default_points(shape, cands.max_n)`` points (as
    ``jaxmatch score --internal k``) and locate its preferred mesh among ``cands``."""
    where = {mid: j for j, mid in enumerate(cands.ids)}
    codes, pos, twin = [], [], []
    for ex in examples:
        if ex.k != cands.k:
            raise ValueError(f"{ex.where}: preferred mesh has size {ex.k}, candidates {cands.k}")
        if ex.preferred not in where:
            raise ValueError(f"{ex.where}: preferred mesh {ex.preferred} is not among the candidates")
        m = default_points(ex.shape, cands.max_n)
        codes.append(annotate(ex.shape, m).codes)
        p = where[ex.preferred]
        pos.append(p)
        key = cands.keys[p]
        row = np.array([kk == key for kk in cands.keys])
        row[p] = False
        twin.append(row)
    c, v = pad_shapes(codes) if codes else (np.zeros((0, 16), np.int32), np.zeros((0, 16), bool))
    return Encoded(c, v, np.asarray(pos, np.int32), np.asarray(twin, bool).reshape(len(examples), len(cands.ids)))


def _group_by_k(examples: Sequence[Example]) -> dict:
    groups: dict = {}
    for i, ex in enumerate(examples):
        groups.setdefault(ex.k, []).append(i)
    return dict(sorted(groups.items()))


def split_examples(examples: Sequence[Example], fraction: float, seed: int) -> tuple[list[int], list[int]]:
    """Deterministic train / held-out split ``(train indices, heldout indices)``.

    Split by preferred mesh: all examples of one preferred mesh go to the same side, so the
    held-out meshes are never seen in training. Preferred ids (sorted) are shuffled with
    ``numpy.random.default_rng(seed)`` and moved to the held-out side until it holds at least
    ``round(fraction * N)`` examples (at least one when ``fraction > 0``), keeping one group
    for training.
    """
    if not 0.0 <= fraction < 1.0:
        raise ValueError(f"held-out fraction must be in [0, 1), got {fraction}")
    n = len(examples)
    target = int(round(fraction * n))
    if fraction > 0:
        target = max(target, 1)
    groups: dict = {}
    for i, ex in enumerate(examples):
        groups.setdefault(ex.preferred, []).append(i)
    order = sorted(groups)
    perm = np.random.default_rng(seed).permutation(len(order))
    held: list[int] = []
    for j in perm[: max(len(order) - 1, 0)]:
        if len(held) >= target:
            break
        held.extend(groups[order[j]])
    hs = set(held)
    return [i for i in range(n) if i not in hs], sorted(held)


# ---------------------------------------------------------------------------------------------
# exact evaluation


def exact_utilities(enc: Encoded, cands: Candidates, weights) -> np.ndarray:
    """``(S, N) float32`` exact utilities (``-inf`` when unmatchable) under a model (a
    :class:`Lattice`, :class:`jaxmatch.kernels.model.Weights` or a ``(3, 4, 4, 4)`` table with
    ``-inf`` = excluded and skip weights 0), by the exact host, in chunks of a fixed number of
    shapes (one compilation per (m_pad, bucket))."""
    w = weights_of(weights)
    s_total = enc.codes.shape[0]
    shapes = [enc.codes[i][enc.valid[i]] for i in range(s_total)]
    out = []
    for start in range(0, s_total, _SHAPE_CHUNK):
        chunk = shapes[start:start + _SHAPE_CHUNK]
        s = len(chunk)
        chunk = chunk + [np.zeros(0, np.int32)] * (_SHAPE_CHUNK - s)  # all-padding shapes
        cols = [exact_values(chunk, vals, w, m_pad=enc.codes.shape[1]).max(axis=2) for _, vals in cands.buckets]
        out.append(np.concatenate(cols, axis=1)[:s])
    if not out:
        return np.zeros((0, len(cands.ids)), np.float32)
    return np.concatenate(out).astype(np.float32)


def rank_positions(util: np.ndarray, pos: np.ndarray, twin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(pessimistic rank, rank by id)`` (1 = first) of each preferred mesh; see the module
    docstring. ``util (S, N)`` in candidate (ranking) order."""
    s, n = util.shape
    rows = np.arange(s)
    up = util[rows, pos][:, None]
    comp = ~twin
    comp[rows, pos] = False
    earlier = np.arange(n)[None, :] < pos[:, None]
    higher = util > up
    tie = util == up
    pess = 1 + np.sum(comp & (higher | tie), axis=1)
    by_id = 1 + np.sum(comp & (higher | (tie & earlier)), axis=1)
    return pess.astype(np.int64), by_id.astype(np.int64)


def _metrics(pess: np.ndarray, by_id: np.ndarray) -> dict:
    n = int(pess.shape[0])
    if n == 0:
        return {"top1": None, "top5": None, "top1_by_id": None, "top5_by_id": None, "mean_rank": None, "examples": 0}
    return {
        "top1": float(np.mean(pess == 1)),
        "top5": float(np.mean(pess <= 5)),
        "top1_by_id": float(np.mean(by_id == 1)),
        "top5_by_id": float(np.mean(by_id <= 5)),
        "mean_rank": float(np.mean(pess)),
        "examples": n,
    }


class _Group(NamedTuple):
    k: int
    members: list  # indices into the example list
    cands: Candidates
    enc: Encoded


def _groups(examples, index, *, max_candidates=None, seed=0) -> list[_Group]:
    out = []
    for k, members in _group_by_k(examples).items():
        keep = sorted({examples[i].preferred for i in members})
        cands = candidates(index, k, keep=keep, max_candidates=max_candidates, seed=seed)
        out.append(_Group(k, members, cands, encode([examples[i] for i in members], cands)))
    return out


def _ranks(groups: list[_Group], n_examples: int, weights) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pess = np.zeros(n_examples, np.int64)
    by_id = np.zeros(n_examples, np.int64)
    unmatchable = np.zeros(n_examples, bool)
    for g in groups:
        u = exact_utilities(g.enc, g.cands, weights)
        p, b = rank_positions(u, g.enc.pos, g.enc.twin)
        idx = np.asarray(g.members)
        pess[idx], by_id[idx] = p, b
        unmatchable[idx] = ~np.isfinite(u[np.arange(len(idx)), g.enc.pos])
    return pess, by_id, unmatchable


def evaluate(examples: Sequence[Example], catalogue_or_index, table, *, detail: bool = False) -> dict:
    """Exact-scorer accuracy of a model ``table`` (a :class:`Lattice`, its
    :class:`jaxmatch.kernels.model.Weights`, or a ``(3, 4, 4, 4)`` array with skip weights 0) on
    ``examples``: ``{"top1", "top5", "top1_by_id", "top5_by_id", "mean_rank", "examples",
    "unmatchable"}`` over *all* catalogue meshes of each example's size (tie rule: module
    docstring); with ``detail`` also ``"ranks"`` (pessimistic rank per example)."""
    index = catalogue_or_index if isinstance(catalogue_or_index, MeshIndex) else mesh_index(catalogue_or_index)
    groups = _groups(examples, index)
    pess, by_id, unm = _ranks(groups, len(examples), weights_of(table))
    out = _metrics(pess, by_id)
    out["unmatchable"] = int(unm.sum())
    if detail:
        out["ranks"] = [int(r) for r in pess]
    return out


# ---------------------------------------------------------------------------------------------
# training


class TuneResult(NamedTuple):
    """weights: ``(L,) float64`` tuned level weights (unrounded); losses: mean loss per epoch;
    ignored: indices (into the training examples) whose preferred mesh is unmatchable;
    skip: ``(3,) float64`` tuned skip weights (unrounded; ``-inf`` where the lattice has ``-inf``)."""

    weights: np.ndarray
    losses: list
    ignored: list
    skip: np.ndarray = np.zeros(3)


def _weights(params, segments):
    """:func:`params_to_weights` with static ``segments`` (jit-friendly)."""
    parts = []
    for a, b in segments:
        top = params[a]
        parts.append(jnp.concatenate([top[None], top - jnp.cumsum(jax.nn.softplus(params[a + 1:b]))]))
    return jnp.concatenate(parts)


def _loss(params, fixed, batch, gamma, segments):
    """Mini-batch loss (module docstring). ``params``: ``(L + 3,)`` level parameters, then the
    three skip weights.

    fixed: ``(masks (L, 192), base (192,), forbidden (3, 4, 4, 4), must (3,), buckets (tuple of
    (N_n, n)), w0 (L + 3,), l2)``; batch: ``(codes, valid, pos, keep (B, N), ex_w (B,))``.
    """
    masks, base, forbidden, must, buckets, w0, l2 = fixed
    codes, valid, pos, keep, ex_w = batch
    n_levels = masks.shape[0]
    w = _weights(params[:n_levels], segments)
    skip = params[n_levels:]
    table = (w @ masks + base).reshape(3, 4, 4, 4)  # = table_from_levels(structure, w)
    u = jnp.concatenate([soft_batch(codes, valid, vals, table, forbidden, skip, must, gamma) for vals in buckets], axis=1)
    logits = jnp.where(keep, u / gamma, -jnp.inf)
    lp = jnp.take_along_axis(logits, pos[:, None], axis=1)[:, 0]
    ce = jax.nn.logsumexp(logits, axis=1) - lp
    data = jnp.sum(ce * ex_w) / jnp.maximum(jnp.sum(ex_w), 1.0)
    return data + l2 * jnp.mean((jnp.concatenate([w, jnp.where(must, 0.0, skip)]) - w0) ** 2)


_value_and_grad = jax.jit(jax.value_and_grad(_loss), static_argnames=("segments",))
"""``(params, fixed, batch, gamma, segments) -> (loss, gradient)``; compiled once per shapes."""


@jax.jit
def _adam_step(params, state, grads, learning_rate):
    upd, state = optax.adam(learning_rate).update(grads, state, params)
    return optax.apply_updates(params, upd), state


def train(
    lattice: Lattice,
    examples: Sequence[Example],
    catalogue_or_index,
    *,
    epochs: int = 10,
    temperature: float = 1.0,
    seed: int = 0,
    learning_rate: float = 0.05,
    batch_size: int = 32,
    l2: float = 1e-3,
    max_candidates: int | None = 256,
    progress: Callable[[int, int, float], None] | None = None,
    tune_skip: bool = True,
) -> TuneResult:
    """Tune the level weights (and, with ``tune_skip``, the finite skip weights) of ``lattice``
    on ``examples`` (module docstring).

    progress(step, total_steps, loss): called after every optimiser step.
    Raises FloatingPointError when a loss or gradient is not finite.
    """
    if temperature <= 0 or not math.isfinite(temperature):
        raise ValueError(f"temperature must be a positive number, got {temperature}")
    if epochs < 0 or batch_size < 1:
        raise ValueError("epochs must be >= 0 and batch_size >= 1")
    index = catalogue_or_index if isinstance(catalogue_or_index, MeshIndex) else mesh_index(catalogue_or_index)
    structure = level_structure(lattice)
    model = weights_of(lattice)
    _, forbidden, skip0, must = soft_parts(model)
    n_levels = structure.weights.shape[0]
    w0 = jnp.asarray(np.concatenate([structure.weights, skip0]), jnp.float32)
    params = jnp.asarray(np.concatenate([init_params(structure), skip0]).astype(np.float32))
    # gradient mask: -inf skip weights never move; with tune_skip=False none of them does
    free = jnp.asarray(np.concatenate([np.ones(n_levels), (~must) & bool(tune_skip)]).astype(np.float32))
    groups = _groups(examples, index, max_candidates=max_candidates, seed=seed)
    # examples whose preferred mesh no weights can match get no weight
    ignored = []
    weight_of = {}
    for g in groups:
        u = exact_utilities(g.enc, g.cands, model)
        ok = np.isfinite(u[np.arange(len(g.members)), g.enc.pos])
        ignored += [i for i, good in zip(g.members, ok) if not good]
        weight_of[g.k] = ok.astype(np.float32)
    segments = tuple(_segments(structure))
    masks = jnp.asarray(structure.masks.reshape(structure.masks.shape[0], -1).astype(np.float32))
    base = jnp.asarray(np.where(structure.masks.any(axis=0), 0.0, NEG).astype(np.float32).reshape(-1))
    fixed = {
        g.k: (masks, base, jnp.asarray(forbidden), jnp.asarray(must), tuple(jnp.asarray(v) for _, v in g.cands.buckets), w0,
              jnp.float32(l2))
        for g in groups
    }
    state = optax.adam(learning_rate).init(params)
    rng = np.random.default_rng(seed)
    gamma = jnp.float32(temperature)
    total = epochs * sum(-(-len(g.members) // batch_size) for g in groups)
    step = 0
    losses = []

    for epoch in range(epochs):
        epoch_loss, epoch_n = 0.0, 0
        for g in groups:
            s = len(g.members)
            order = rng.permutation(s)
            for start in range(0, s, batch_size):
                sel = order[start:start + batch_size]
                b = len(sel)
                pad = np.concatenate([sel, np.repeat(sel[:1], batch_size - b)])  # fixed batch shape
                ex_w = np.concatenate([weight_of[g.k][sel], np.zeros(batch_size - b, np.float32)])
                keep = ~g.enc.twin[pad]
                batch = (jnp.asarray(g.enc.codes[pad]), jnp.asarray(g.enc.valid[pad]), jnp.asarray(g.enc.pos[pad]),
                         jnp.asarray(keep), jnp.asarray(ex_w))
                value, grads = _value_and_grad(params, fixed[g.k], batch, gamma, segments)
                grads = grads * free
                value = float(value)
                gnp = np.asarray(grads)
                if not math.isfinite(value) or not np.all(np.isfinite(gnp)):
                    raise FloatingPointError(f"non-finite loss or gradient at epoch {epoch + 1}, step {step + 1} (loss {value}); try a larger --temperature")
                params, state = _adam_step(params, state, grads, jnp.float32(learning_rate))
                step += 1
                epoch_loss += value * b
                epoch_n += b
                if progress is not None:
                    progress(step, total, value)
        losses.append(epoch_loss / max(epoch_n, 1))
    w = np.asarray(params_to_weights(params[:n_levels], structure), np.float64)
    skip = np.where(must, -np.inf, np.asarray(params[n_levels:], np.float64))
    return TuneResult(w, losses, ignored, skip)


# ---------------------------------------------------------------------------------------------
# rounding and the whole job


def choose_scale(lattice: Lattice, weights, examples: Sequence[Example], catalogue_or_index, scales: Sequence[int] = SCALES,
                 skip=None) -> tuple[Lattice, int, list]:
    """The rounded lattice ``with_level_weights(lattice, scale * weights, scale * skip)`` whose
    exact ranking of ``examples`` is best (pessimistic top-1, then top-5, then the smaller
    scale); returns ``(lattice, scale, [{"scale", "top1", "top5", ...}, ...])``. ``skip``:
    ``(3,)`` tuned skip weights (None: the lattice's own)."""
    index = catalogue_or_index if isinstance(catalogue_or_index, MeshIndex) else mesh_index(catalogue_or_index)
    w = np.asarray(weights, np.float64)
    sk = None if skip is None else np.asarray(skip, np.float64)
    finite_skip = np.zeros(0) if sk is None else sk[np.isfinite(sk)]
    biggest = float(np.max(np.abs(np.concatenate([w, finite_skip])))) if w.size + finite_skip.size else 0.0
    groups = _groups(examples, index)
    best = None
    rows = []
    for s in scales:
        if s * biggest > MAX_WEIGHT:
            break
        lat = with_level_weights(lattice, s * w, None if sk is None else s * sk)
        pess, by_id, _ = _ranks(groups, len(examples), lat)
        m = _metrics(pess, by_id)
        rows.append({"scale": int(s), **{k: m[k] for k in ("top1", "top5", "top1_by_id", "top5_by_id", "mean_rank")}})
        key = (m["top1"] or 0.0, m["top5"] or 0.0, m["top1_by_id"] or 0.0)
        if best is None or key > best[0]:
            best = (key, s, lat)
    if best is None:  # weights too large for any scale: clip at scale 1
        return with_level_weights(lattice, w, sk), 1, rows
    return best[2], int(best[1]), rows


def _weights_json(lattice: Lattice) -> dict:
    out = {kind: [int(lev.weight) for lev in levels] for kind, levels in zip("sxv", lattice.levels)}
    out["skip"] = weights_of(lattice).skip_json()
    return out


def run_tuning(
    lattice: Lattice,
    examples: Sequence[Example],
    catalogue: Catalogue,
    *,
    heldout: float = 0.25,
    seed: int = 0,
    epochs: int = 10,
    temperature: float = 1.0,
    learning_rate: float = 0.05,
    batch_size: int = 32,
    l2: float = 1e-3,
    max_candidates: int | None = 256,
    name: str | None = None,
    extra: dict | None = None,
    progress: Callable[[int, int, float], None] | None = None,
    stage: Callable[[str], None] | None = None,
    tune_skip: bool = True,
) -> tuple[Lattice, dict]:
    """Split, evaluate before, train, round, evaluate after. Returns ``(tuned lattice, report)``.

    extra: optional ``{name: examples}`` evaluated before and after as well (e.g. another
    label file); their examples take no part in training or scale choice.
    The report holds ``train`` and ``heldout`` (and each extra set), each with ``before``,
    ``after`` (the rounded lattice, as written) and ``after_unrounded`` metrics
    (:func:`evaluate`), plus settings, the split, the scale search and the losses.
    """
    t0 = time.perf_counter()
    say = stage or (lambda text: None)
    index = mesh_index(catalogue)
    train_idx, held_idx = split_examples(examples, heldout, seed)
    tr = [examples[i] for i in train_idx]
    he = [examples[i] for i in held_idx]
    if not tr:
        raise ValueError("no training examples")
    say("evaluating the input lattice")
    sets = {"train": tr, "heldout": he, **(extra or {})}
    before = {key: evaluate(ex, index, lattice) if ex else evaluate([], index, lattice) for key, ex in sets.items()}
    say(f"training on {len(tr)} examples")
    result = train(
        lattice, tr, index, epochs=epochs, temperature=temperature, seed=seed, learning_rate=learning_rate,
        batch_size=batch_size, l2=l2, max_candidates=max_candidates, progress=progress, tune_skip=tune_skip,
    )
    say("rounding to integers")
    tuned, scale, scale_rows = choose_scale(lattice, result.weights, tr, index, skip=result.skip if tune_skip else None)
    tuned = replace(tuned, name=name or f"{lattice.name}-tuned")
    say("evaluating the tuned lattice")
    structure = level_structure(lattice)
    float_table = make_weights(np.asarray(table_from_levels(structure, result.weights.astype(np.float32))),
                               result.skip if tune_skip else weights_of(lattice).skip_inf())
    report = {
        "lattice": {"input": lattice.name, "output": tuned.name},
        "tie_rule": TIE_RULE,
        "settings": {
            "epochs": int(epochs), "temperature": float(temperature), "seed": int(seed),
            "learning_rate": float(learning_rate), "batch_size": int(batch_size), "l2": float(l2),
            "max_candidates": None if max_candidates is None else int(max_candidates), "tune_skip": bool(tune_skip),
            "heldout_fraction": float(heldout),
        },
        "split": {
            "by": "preferred mesh", "train": len(tr), "heldout": len(he),
            "heldout_where": [examples[i].where for i in held_idx],
        },
        "sizes": {str(k): len(v) for k, v in _group_by_k(examples).items()},
        "ignored_unmatchable": [tr[i].where for i in result.ignored],
        "scale": int(scale),
        "scales": scale_rows,
        "loss": [float(x) for x in result.losses],
        "weights": {"before": _weights_json(lattice), "after": _weights_json(tuned),
                    "after_unrounded": {**{kind: [float(result.weights[i]) for i in range(a, b)] for kind, (a, b) in zip("sxv", _segments(structure))},
                                        "skip": {kind: (None if not np.isfinite(x) else float(x)) for kind, x in zip("sxv", result.skip)}}},
    }
    for key, ex in sets.items():
        report[key] = {
            "before": before[key],
            "after": evaluate(ex, index, tuned),
            "after_unrounded": evaluate(ex, index, float_table),
        }
    report["seconds"] = round(time.perf_counter() - t0, 1)
    return tuned, report
