"""Bulk scoring: each distinct boundary sequence once, pruned top-K, streaming, several devices.

Everything here returns exactly what the exhaustive scorer (:func:`jaxmatch.scoring.exact.score_bucket`
on every mesh) gives; the tests compare them (``tests/test_bulk.py``).

* **Distinct sequences** (:func:`group_sequences`): meshes whose boundary valence sequences are
  equal up to rotation and reflection get the same ``2n`` orientation values, permuted. Each
  distinct sequence is scored once and its values are fanned out to the meshes that share it
  (:func:`fan_out`), so ties between orientations break exactly as for the mesh itself.
* **Pruning** (:func:`upper_bounds`, :func:`top_k`): a cheap upper bound per sequence (each
  vertex's best weight over the point types the shape has, capped by how many points of each
  type there are) lets a top-K search skip sequences that cannot reach the K-th best utility.
  Sequences are scored in bound order, in rounds; a sequence is skipped only when its bound is
  *strictly* below the current K-th best utility of every group it could enter, so ties at the
  cut-off are still found.
* **Streaming** (:func:`prepare`): the catalogue is read one bucket (boundary length) at a time
  and only the grouped sequences, ids and k are kept; device memory per call depends on the
  batch size, never on the catalogue size.
* **Devices** (:class:`ShardedBackend`, :func:`score_sharded`, :func:`score_many`): a backend of
  the exact host (:func:`jaxmatch.scoring.exact.exact_values`, which does all the padding and
  chunking) running the same blocks of :func:`jaxmatch.scoring.exact.final_blocks`, sharded
  over a 1-D ``jax.sharding.Mesh`` with ``shard_map``: meshes over devices (one shape), or
  shapes over devices (many shapes). Inputs
  are built with ``jax.make_array_from_callback`` and outputs gathered with
  ``multihost_utils.process_allgather``, so the same code runs on several hosts after
  ``jax.distributed.initialize()`` (docs/perf.md). On CPU, :func:`configure_host_devices` splits
  the host into N XLA devices (before jax is imported).

This module imports JAX lazily (inside functions), so :func:`configure_host_devices` can run
first.
"""

from __future__ import annotations

import json
import os
import re
import sys
from typing import Callable, Iterable, NamedTuple, Sequence

import numpy as np

from jaxmatch.files import atomic_open
from jaxmatch.kernels.backends import default_backend
from jaxmatch.kernels.model import NEG, skip_frame, skip_offset, weights_of
from jaxmatch.scoring.exact import (  # numpy only: no JAX import here
    DEFAULT_BATCH,
    UNROLL,
    block_size,
    dp_kinds,
    dp_problem,
    exact_values,
    final_values,
    reduce_orientations,
)

__all__ = [
    "SequenceGroups",
    "ShardedBackend",
    "Part",
    "TopK",
    "configure_host_devices",
    "group_sequences",
    "fan_out",
    "upper_bounds",
    "part_bounds",
    "prepare",
    "prepared",
    "score_distinct",
    "top_k",
    "top_k_many",
    "device_mesh",
    "sharded_values",
    "score_sharded",
    "score_many",
    "write_jsonl",
]



# --------------------------------------------------------------------------- devices


def configure_host_devices(n: int) -> None:
    """Make the CPU platform show ``n`` XLA devices (``--xla_force_host_platform_device_count``).

    Must run before JAX is imported (the flag is read once). If JAX is already imported, only
    checks that at least ``n`` devices exist and raises ``RuntimeError`` otherwise. Accelerator
    platforms (GPU, TPU) ignore the flag: their devices are the accelerators.
    """
    n = int(n)
    if n < 1:
        raise ValueError(f"device count must be >= 1, got {n}")
    if "jax" in sys.modules:
        import jax

        have = len(jax.devices())
        if have < n:
            raise RuntimeError(
                f"{n} devices requested but JAX was imported with {have}; call "
                "configure_host_devices before importing jax (or set XLA_FLAGS="
                f"--xla_force_host_platform_device_count={n})")
        return
    flags = re.sub(r"--xla_force_host_platform_device_count=\S+", "", os.environ.get("XLA_FLAGS", "")).split()
    os.environ["XLA_FLAGS"] = " ".join(flags + [f"--xla_force_host_platform_device_count={n}"])


def device_mesh(devices=None):
    """A 1-D ``jax.sharding.Mesh`` (axis ``"d"``): all devices (None), the first ``devices``
    (int), or the given device list."""
    import jax
    from jax.sharding import Mesh

    if devices is None:
        devs = jax.devices()
    elif isinstance(devices, (int, np.integer)):
        all_devs = jax.devices()
        if not 1 <= int(devices) <= len(all_devs):
            raise ValueError(f"asked for {int(devices)} devices, {len(all_devs)} available")
        devs = all_devs[: int(devices)]
    else:
        devs = list(devices)
    return Mesh(np.array(devs), ("d",))


def _global(x: np.ndarray, mesh, spec):
    """A global ``jax.Array`` of host data ``x`` (the same on every process) laid out as ``spec``."""
    import jax
    from jax.sharding import NamedSharding

    return jax.make_array_from_callback(x.shape, NamedSharding(mesh, spec), lambda idx: x[idx])


def _to_host(a) -> np.ndarray:
    """The whole of a global array on this host (an all-gather across processes if needed)."""
    import jax

    if jax.process_count() == 1:
        return np.asarray(a)
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(a, tiled=True))


# --------------------------------------------------------------------------- distinct sequences


class SequenceGroups(NamedTuple):
    """Meshes of one boundary length grouped by boundary sequence up to rotation and reflection.

    seqs: ``(U, n) int32`` representatives (the lexicographically smallest orientation);
    index: ``(N,)`` representative of each input sequence; orient: ``(N, 2n)``: orientation ``o``
    of input sequence ``i`` is orientation ``orient[i, o]`` of ``seqs[index[i]]`` (the same
    oriented valence sequence; orientation numbering of :mod:`jaxmatch.scoring.exact`).
    """

    seqs: np.ndarray
    index: np.ndarray
    orient: np.ndarray


def _orientations(v: np.ndarray) -> np.ndarray:
    n = v.shape[1]
    rot = (np.arange(n)[:, None] + np.arange(n)[None, :]) % n
    return np.concatenate([v[:, rot], v[:, ::-1][:, rot]], axis=1)


_KEY_DIGITS = 31
"""Longest sequence :func:`group_sequences` packs into one int64 key (2 bits per valence 2..5)."""


def _rotation_keys(d: np.ndarray) -> np.ndarray:
    """``(N, n)`` digits 0..3 -> ``(N, n) int64``: column ``r`` is the base-4 number of
    ``np.roll(d, -r, axis=1)``, first digit most significant (``n <= 31``)."""
    big_n, n = d.shape
    d = d.astype(np.int64)
    k = np.zeros(big_n, np.int64)
    for j in range(n):
        k = k * 4 + d[:, j]
    out = np.empty((big_n, n), np.int64)
    out[:, 0] = k
    top = np.int64(4) ** (n - 1)
    for r in range(1, n):  # drop the leading digit d[r - 1], append it at the end
        k = (k - d[:, r - 1] * top) * 4 + d[:, r - 1]
        out[:, r] = k
    return out


def group_sequences(vals) -> SequenceGroups:
    """Group ``(N, n)`` boundary sequences by equality up to rotation and reflection."""
    v = np.asarray(vals, np.int32)
    if v.ndim != 2 or v.shape[1] == 0:
        raise ValueError(f"vals must be (N, n) with n >= 1, got shape {v.shape}")
    big_n, n = v.shape
    if big_n == 0:
        return SequenceGroups(np.zeros((0, n), np.int32), np.zeros(0, np.int64), np.zeros((0, 2 * n), np.int64))
    if n <= _KEY_DIGITS and v.min() >= 2 and v.max() <= 5:
        # each orientation as one int64, base 4, first vertex most significant: integer order is
        # the lexicographic order of the sequences, so argmin / unique on the keys give what the
        # row-wise loop and np.unique(axis=0) below give (tests/test_bulk.py), without the
        # (N, 2n, n) array
        key = np.concatenate([_rotation_keys(v - 2), _rotation_keys(v[:, ::-1] - 2)], axis=1)  # (N, 2n), orientation o
        star = key.argmin(axis=1)  # first smallest orientation o* = (h*, a)
        _, rep, index = np.unique(key[np.arange(big_n), star], return_index=True, return_inverse=True)
        o1 = star[rep]
        base = np.where((o1 >= n)[:, None], v[rep][:, ::-1], v[rep])
        seqs = np.take_along_axis(base, ((o1 % n)[:, None] + np.arange(n)[None, :]) % n, axis=1)  # the keys' rows
    else:
        o = _orientations(v)  # (N, 2n, n)
        cand = np.ones(o.shape[:2], bool)
        for j in range(n):  # lexicographic argmin over the 2n orientations
            col = np.where(cand, o[:, :, j], np.iinfo(np.int32).max)
            cand &= col == col.min(axis=1, keepdims=True)
        star = cand.argmax(axis=1)  # first smallest orientation o* = (h*, a)
        canon = o[np.arange(big_n), star]
        seqs, index = np.unique(canon, axis=0, return_inverse=True)
    h, a = (star >= n)[:, None], (star % n)[:, None]
    r = np.arange(n)[None, :]
    minus, plus = (r - a) % n, (r + a) % n
    # vals = roll(c, a) (h* = 0) or roll(c[::-1], -a) (h* = 1), c the representative:
    # rotation r of vals is rotation r - a of c (of c[::-1] when h* = 1), and rotation r of
    # vals[::-1] is rotation r + a of c[::-1] (of c when h* = 1)
    first = np.where(h, n + plus, minus)
    second = np.where(h, minus, n + plus)
    orient = np.concatenate([first, second], axis=1).astype(np.int64)
    return SequenceGroups(seqs.astype(np.int32), index.reshape(-1).astype(np.int64), orient)


def fan_out(rep_values: np.ndarray, groups: SequenceGroups, rows=None) -> np.ndarray:
    """Per-orientation values of the meshes (``(N, 2n)``, or only ``rows``) from the values
    ``(U, 2n)`` of their representatives."""
    idx = groups.index if rows is None else groups.index[rows]
    orient = groups.orient if rows is None else groups.orient[rows]
    return np.asarray(rep_values)[idx[:, None], orient]


def score_distinct(codes, vals, weights, **kw):
    """:func:`jaxmatch.scoring.exact.score_bucket`, scoring each distinct sequence once (same result).
    Keyword arguments go to :func:`jaxmatch.scoring.exact.final_values` (or, with ``devices``, to
    :func:`sharded_values`)."""
    g = group_sequences(np.asarray(vals).reshape(-1, np.shape(vals)[-1]))
    rep = _values(codes, g.seqs, weights, **kw)
    return reduce_orientations(fan_out(rep, g))


# --------------------------------------------------------------------------- bounds


_MIRROR = np.array([(w * 16 + v * 4 + u) for u in range(4) for v in range(4) for w in range(4)])
"""Triple index of ``[u, v, w]`` -> index of ``[w, v, u]`` (the triple in the mirrored mesh)."""


def triple_histograms(seqs) -> np.ndarray:
    """``(U, 64) int32``: how often each triple ``[s[j+1], s[j], s[j-1]]`` (table order) occurs in
    each sequence ``seqs (U, n)``. Rotations keep it; reflection permutes it (``[:, _MIRROR]``)."""
    s = np.asarray(seqs, np.int64)
    u, n = s.shape
    f = (np.roll(s, -1, 1) - 2) * 16 + (s - 2) * 4 + (np.roll(s, 1, 1) - 2)
    return np.bincount((f + 64 * np.arange(u)[:, None]).reshape(-1), minlength=64 * u).reshape(u, 64).astype(np.int32)


def upper_bounds(seqs, codes, weights, *, hist: np.ndarray | None = None) -> np.ndarray:
    """``(U,) float64`` upper bound of the best utility of each sequence ``seqs (U, n)`` against
    ``codes (m,)`` under the model ``weights`` (the utility with forbidden weights as ``NEG``,
    so a bound ``<= NEG / 2`` means unmatchable; ``-inf`` when ``n > m``). ``hist``:
    :func:`triple_histograms` of ``seqs`` if already known.

    Skip weights: in the shifted frame (:func:`jaxmatch.scoring.exact.skip_frame`) the utility
    is ``sum of the matched points' W' + sum_i shift[codes[i]]``, the second term the same for
    every alignment; the bound below is computed on ``W'`` and the offset added. Must-match
    types only remove alignments, so the bound stays an upper bound.

    Per orientation family (``vals`` and ``vals[::-1]``; rotations keep the multiset of triples)
    each vertex ``j`` has weights ``w_c(j)`` for the types ``c`` the shape has. The bound is the
    smaller of ``sum_j max_c w_c(j)`` and, for each present type ``b``,
    ``sum_j w_b(j) + sum_{c != b} (largest count_c values of max(w_c(j) - w_b(j), 0))`` (at most
    ``count_c`` vertices can take a point of type ``c``). Computed on triple histograms: the
    largest gains are taken greedily over the triples in decreasing gain order.
    """
    s = np.asarray(seqs, np.int64)
    if s.ndim != 2:
        raise ValueError(f"seqs must be (U, n), got shape {s.shape}")
    u, n = s.shape
    c = np.asarray(codes, np.int64).reshape(-1)
    out = np.full(u, -np.inf)
    if u == 0 or n > c.shape[0]:
        return out
    count = np.bincount(c, minlength=3)[:3]
    present = np.flatnonzero(count > 0)
    w = skip_frame(weights).table  # (3, 64) W', NEG where forbidden
    h0 = np.ascontiguousarray((triple_histograms(s) if hist is None else np.asarray(hist, np.int32)).T)  # (64, U)
    # numpy only, no BLAS (einsum's own loops; a row-by-row running sum): BLAS threads fight
    # with XLA's under load, and np.cumsum along axis 0 is ~15x slower than the loop below
    for h in (h0, h0[_MIRROR]):
        bound = np.einsum("tu,t->u", h, w[present].max(axis=0))
        for b in present:
            total = np.einsum("tu,t->u", h, w[b])
            for cc in present:
                if cc == b:
                    continue
                gain = w[cc] - w[b]
                pos = np.flatnonzero(gain > 0)
                if pos.size == 0:
                    continue
                pos = pos[np.argsort(-gain[pos], kind="stable")]
                run = h[pos].astype(np.int64)  # vertices with the largest gains first
                for i in range(1, run.shape[0]):
                    run[i] += run[i - 1]
                np.minimum(run, int(count[cc]), out=run)  # at most count_cc of them take type cc
                run[1:] -= run[:-1].copy()
                total = total + np.einsum("ku,k->u", run, gain[pos])
            bound = np.minimum(bound, total)
        out = np.maximum(out, bound)
    return out + skip_offset(c, weights)


_STACKED: list = []  # [(the hist arrays, (distinct histograms, inverse))], a few recent ones


def _stacked_hist(hists: list) -> tuple[np.ndarray, np.ndarray]:
    """The distinct rows of several parts' ``(U, 64)`` histograms, stacked: ``(D, 64) int32`` as
    the transpose of a contiguous ``(64, D)`` array (the layout :func:`upper_bounds` works in, so
    it copies nothing), and ``(U,)`` the row of each sequence. The k <= 5 catalogue has 21822
    sequences but 5230 distinct histograms (the bound depends only on the histogram). Kept for the
    last few part lists, so many shapes against one catalogue compute it once."""
    for key, value in _STACKED:
        if len(key) == len(hists) and all(a is b for a, b in zip(key, hists)):
            return value
    h = np.ascontiguousarray(np.concatenate(hists))
    # rows as raw bytes (~20x faster than np.unique(axis=0); for the uint8 histograms of
    # prepare the same row order, and any consistent order gives the same bounds)
    rows = h.view(np.dtype((np.void, h.shape[1] * h.itemsize))).reshape(-1)
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    distinct = h[first]
    value = (np.ascontiguousarray(distinct.T, dtype=np.int32).T, inverse.reshape(-1))
    _STACKED.insert(0, (list(hists), value))
    del _STACKED[4:]
    return value


def part_bounds(parts, codes, weights) -> list[np.ndarray]:
    """:func:`upper_bounds` of the distinct sequences of every part (:class:`Part`), the same
    values, in one call on the distinct stacked triple histograms (the bound depends on the
    histogram, and on ``n`` only through ``n > m``): one pass of numpy calls per shape instead of
    one per boundary length, on a quarter of the columns."""
    m = int(np.asarray(codes).reshape(-1).shape[0])
    out: list = [None] * len(parts)
    stack = [i for i, p in enumerate(parts) if p.hist is not None and p.n <= m and len(p.groups.seqs)]
    for i, p in enumerate(parts):
        if i not in stack:
            out[i] = upper_bounds(p.groups.seqs, codes, weights, hist=p.hist)
    if stack:
        hist, inverse = _stacked_hist([parts[i].hist for i in stack])
        one = upper_bounds(np.broadcast_to(np.full((1, 1), 2, np.int32), (hist.shape[0], 1)), codes, weights, hist=hist)[inverse]
        for i, piece in zip(stack, np.split(one, np.cumsum([len(parts[i].hist) for i in stack])[:-1])):
            out[i] = piece
    return out


# --------------------------------------------------------------------------- parts (streamed)


class Part(NamedTuple):
    """One bucket of the catalogue, grouped: ``n``, mesh ``ids``/``k``/``valences``, the
    :class:`SequenceGroups` of the valences and the :func:`triple_histograms` ``(U, 64) uint8``
    of the distinct sequences (shape independent, reused by every :func:`upper_bounds`)."""

    n: int
    ids: np.ndarray
    k: np.ndarray
    valences: np.ndarray
    groups: SequenceGroups
    hist: np.ndarray | None = None


def prepare(buckets: Iterable) -> list[Part]:
    """Group each bucket (anything with ``n``, ``ids``, ``k``, ``valences``, e.g.
    ``Catalogue.buckets(internal)``, consumed one at a time) into a :class:`Part`. Shape
    independent: prepare once, score many shapes."""
    parts = []
    for b in buckets:
        if len(b.ids) == 0:
            continue
        vals = np.asarray(b.valences)
        g = group_sequences(vals)
        hist = triple_histograms(g.seqs).astype(np.uint8)  # counts <= n <= 255
        parts.append(Part(int(b.n), np.asarray(b.ids), np.asarray(b.k).astype(np.int64), vals, g,
                          hist if int(b.n) < 256 else None))
    return parts


def prepared(catalogue, internal=None) -> list[Part]:
    """:func:`prepare` of ``catalogue.buckets(internal)``, computed once per catalogue object and
    k selection and kept in the catalogue's cache (store ``prepared``), so ranking many shapes
    against one catalogue (``score-many``, the Python API) pays for the grouping only once."""
    key = None if internal is None else tuple(sorted({int(k) for k in internal}))
    cache = getattr(catalogue, "cache", None)
    if cache is None:
        return prepare(catalogue.buckets(internal))
    return cache.get("prepared", key, lambda: prepare(catalogue.buckets(internal)))


def _values(codes, seqs, weights, *, devices=None, plan=None, **kw) -> np.ndarray:
    """Per-orientation values of ``seqs`` on one device (threads) or sharded over ``devices``."""
    if devices is not None and not (isinstance(devices, (int, np.integer)) and int(devices) == 1):
        kw.pop("threads", None)
        kw.pop("problem", None)
        return sharded_values(codes, seqs, weights, devices=devices, plan=plan, **kw)
    return final_values(codes, seqs, weights, plan=plan, **kw)


# --------------------------------------------------------------------------- top K


class TopK(NamedTuple):
    """Result of :func:`top_k`.

    rows: ``(utility, k, n, id, rotation, reflected, valences)`` tuples, the rows of
    :func:`jaxmatch.scoring.rank.rank`, in its order (utility descending, then k, n, id): the best
    ``top`` of all meshes (of each k with ``per_size``) plus every further mesh tied with the
    last of them (the meshes a geometric tie-break needs). Equal to the same selection from the
    exhaustive ranking.
    total: meshes considered; scored: meshes whose sequence was scored exactly; pruned: meshes
    skipped by their bound (utility unknown, below the cut-off); unmatchable: meshes known to be
    unmatchable (n > m, bound, or scored); sequences / sequences_scored: distinct sequences.
    """

    rows: list
    total: int
    scored: int
    pruned: int
    unmatchable: int
    sequences: int
    sequences_scored: int


def _select(rows: list, top: int, per_size: bool) -> list:
    """The best ``top`` rows (per k with ``per_size``) plus ties with the last one, in order."""
    rows = sorted(rows, key=lambda r: (-r[0], r[1], r[2], r[3]))
    groups: dict = {}
    for r in rows:
        groups.setdefault(r[1] if per_size else None, []).append(r)
    keep = []
    for g in groups.values():
        if len(g) > top:
            cut = g[top - 1][0]
            g = [r for i, r in enumerate(g) if i < top or r[0] == cut]
        keep.extend(g)
    return sorted(keep, key=lambda r: (-r[0], r[1], r[2], r[3]))


def top_k(
    codes,
    parts,
    weights,
    *,
    top: int = 5,
    per_size: bool = False,
    prune: bool = True,
    batch: int | None = None,
    round_size: int = 64,
    threads: int | None = None,
    devices=None,
    progress: Callable[[int, int], None] | None = None,
) -> TopK:
    """Exact top ``top`` meshes for one shape ``codes (m,)``, optionally pruned.

    parts: from :func:`prepare` (or buckets, prepared here). prune=False scores every distinct
    sequence (each bucket in chunks of ``batch`` meshes). prune=True scores sequences in
    decreasing bound order in rounds (``round_size`` sequences first, doubling; one block per
    call) and skips every sequence whose bound is below the current cut-off of each group it
    could enter. Only the rows that can still be selected are kept, so memory does not grow with
    the catalogue. devices: None or 1 = this process's default device with ``threads`` host
    threads; an int or a device list = :func:`sharded_values` over those devices.
    progress(done, total): meshes settled (scored, pruned or unmatchable) so far.
    """
    weights = weights_of(weights)  # compiled once for all calls
    top = max(int(top), 1)
    batch = DEFAULT_BATCH if batch is None else int(batch)
    parts = _as_parts(parts)
    codes = np.asarray(codes, np.int32).reshape(-1)
    total = sum(len(p.ids) for p in parts)
    keys = sorted({int(k) for p in parts for k in p.k}) if per_size else [0]
    key_pos = {k: i for i, k in enumerate(keys)}
    st = dict(rows=[], scored=0, unmatchable=0, seq_scored=0, done=0)

    def group_of(k: np.ndarray) -> np.ndarray:
        if not per_size:
            return np.zeros(len(k), np.int64)
        return np.searchsorted(np.asarray(keys), k)

    def cutoffs() -> np.ndarray:
        """Current utility of the ``top``-th row of each group (``-inf`` while fewer)."""
        thr = np.full(len(keys), -np.inf)
        by: dict = {}
        for r in st["rows"]:
            by.setdefault(key_pos[r[1]] if per_size else 0, []).append(r[0])
        for g, us in by.items():
            if len(us) >= top:
                thr[g] = sorted(us, reverse=True)[top - 1]
        return thr

    backend: list = []  # the default backend (final_values'), chosen once for every part
    kinds: dict = {}  # boundary length -> DP number type (dp_kinds), read once
    problems: dict = {}  # DP number type -> the shape's DP problem (dp_problem), its n set per part

    def problem(n: int):
        """``dp_problem([codes], weights, n)``: the shape padded and the model compiled once per
        number type (only ``n`` differs between the parts' problems)."""
        if not kinds:
            kinds.update(dp_kinds(weights, sorted({int(p.n) for p in parts})))
        kind = kinds[int(n)]
        if kind not in problems:
            problems[kind] = dp_problem([codes], weights, int(n), kind=kind)
        return problems[kind]._replace(n=int(n))

    def score_some(p: Part, sel: np.ndarray, plan) -> None:
        every = len(sel) == len(p.groups.seqs)  # (sel sorted, distinct: every sequence)
        one = devices is None or (isinstance(devices, (int, np.integer)) and int(devices) == 1)
        if one and not backend:
            backend.append(default_backend(threads, UNROLL))
        rep = _values(codes, p.groups.seqs if every else p.groups.seqs[sel], weights, plan=plan, batch=batch,
                      threads=threads, devices=devices, problem=problem(p.n),
                      **({"backend": backend[0]} if one else {}))
        if every:  # every mesh, as below
            mesh_rows = np.arange(len(p.groups.index))
            at, orient, ks = np.asarray(p.groups.index), p.groups.orient, p.k
        else:
            mesh_rows = np.flatnonzero(np.isin(p.groups.index, sel))
            # fan_out of the scored rows only (sel is sorted): no (U, 2n) array per call
            at = np.searchsorted(sel, p.groups.index[mesh_rows])
            orient, ks = p.groups.orient[mesh_rows], p.k[mesh_rows]
        res = reduce_orientations(np.asarray(rep)[at[:, None], orient])
        ok = np.isfinite(res.utility)
        keep = ok & (res.utility >= cutoffs()[group_of(ks)])  # the others cannot be selected
        st["rows"] = _select(st["rows"] + [
            (float(res.utility[i]), int(p.k[r]), p.n, str(p.ids[r]), int(res.rotation[i]), bool(res.reflected[i]), p.valences[r])
            for i, r in zip(np.flatnonzero(keep), mesh_rows[keep])], top, per_size)
        st["seq_scored"] += len(sel)
        st["scored"] += len(mesh_rows)
        st["unmatchable"] += int((~ok).sum())
        st["done"] += len(mesh_rows)
        if progress is not None:
            progress(st["done"], total)

    fits = [p for p in parts if p.n <= codes.shape[0]]
    if prune and sum(len(p.groups.seqs) for p in fits) <= max(int(round_size), 1):
        # the first round would score every sequence whatever the bounds (no cut-off yet): score
        # them without bounds; an unmatchable one (a vertex with no allowed point type) scores -inf
        for p in parts:
            if p.n > codes.shape[0]:  # longer than the shape: unmatchable, never scored
                st["unmatchable"] += len(p.ids)
                st["done"] += len(p.ids)
        for p in fits:
            score_some(p, np.arange(len(p.groups.seqs)), (min(block_size(p.n), batch), 1))
        if progress is not None:
            progress(total, total)
        return TopK(st["rows"], total, st["scored"], total - st["done"], st["unmatchable"],
                    sum(len(p.groups.seqs) for p in parts), st["seq_scored"])

    bounds = part_bounds(parts, codes, weights)
    hopeless = [b <= NEG / 2 for b in bounds]  # n > m, or a vertex with no allowed point type
    for p, h in zip(parts, hopeless):
        dead = int(h[p.groups.index].sum())
        st["unmatchable"] += dead
        st["done"] += dead

    if not prune:
        for p, h in zip(parts, hopeless):
            sel = np.flatnonzero(~h)
            if sel.size:
                score_some(p, sel, None)
    else:
        # which ranking groups (k values with per_size) each sequence can enter
        member = _membership(parts, keys, group_of)
        live = [np.flatnonzero(~h) for h in hopeless]
        ob = np.concatenate([b[lv] for b, lv in zip(bounds, live)] + [np.zeros(0)])
        op = np.concatenate([np.full(lv.size, i, np.int64) for i, lv in enumerate(live)] + [np.zeros(0, np.int64)])
        os_ = np.concatenate(live + [np.zeros(0, np.int64)]).astype(np.int64)
        order = np.lexsort((os_, op, -ob))  # decreasing bound; ties by part, then sequence
        ob, op, os_ = ob[order], op[order], os_[order]
        offsets = np.cumsum([0] + [len(p.groups.seqs) for p in parts])
        mem_all = member[offsets[op] + os_]
        pending = np.ones(ob.size, bool)
        size = max(int(round_size), 1)
        while True:
            thr = cutoffs()
            # skip a sequence when its bound is below the cut-off of every group it can enter
            pending &= ~np.all(~mem_all | (ob[:, None] < thr[None, :]), axis=1)
            todo = np.flatnonzero(pending)[:size]
            if todo.size == 0:
                break
            pending[todo] = False
            for pi in np.unique(op[todo]):
                p = parts[int(pi)]
                score_some(p, np.sort(os_[todo][op[todo] == pi]), (min(block_size(p.n), batch), 1))
            size = min(2 * size, 8192)
    if progress is not None:
        progress(total, total)
    return TopK(st["rows"], total, st["scored"], total - st["done"], st["unmatchable"],
                sum(len(p.groups.seqs) for p in parts), st["seq_scored"])


_MEMBERS: list = []  # [((the parts' index arrays, keys), membership)], a few recent ones


def _membership(parts, keys: list, group_of) -> np.ndarray:
    """``(sum U, len(keys)) bool``: which ranking groups (k values with ``per_size``, else the
    one group) each distinct sequence of the stacked parts can enter. Shape independent, so kept
    for the last few part lists."""
    ident = [p.groups.index for p in parts]
    for (key, kk), value in _MEMBERS:
        if kk == keys and len(key) == len(ident) and all(a is b for a, b in zip(key, ident)):
            return value
    member = []
    for p in parts:
        mem = np.zeros((len(p.groups.seqs), len(keys)), bool)
        mem[p.groups.index, group_of(p.k)] = True
        member.append(mem)
    value = np.concatenate(member + [np.zeros((0, len(keys)), bool)])
    _MEMBERS.insert(0, ((ident, list(keys)), value))
    del _MEMBERS[4:]
    return value


def _as_parts(parts) -> list:
    if isinstance(parts, list) and all(isinstance(p, Part) for p in parts):
        return parts
    return prepare(parts)


def top_k_many(codes_list: Sequence, parts, weights, *, devices=None, **kw) -> list[TopK]:
    """:func:`top_k` for several shapes (``codes_list``), sharing one :func:`prepare`.

    devices None or 1: each shape is a (pruned, unless ``prune=False``) :func:`top_k` on this
    process's device. Several devices: the shapes are sharded over them (:func:`score_many`;
    every distinct sequence is scored, no pruning). ``kw``: ``top``, ``per_size``, ``batch``
    (and for one device also ``prune``, ``threads``, ``round_size``). Same rows either way."""
    parts = _as_parts(parts)
    weights = weights_of(weights)
    if _mesh_size(devices) <= 1:
        return [top_k(c, parts, weights, devices=None, **kw) for c in codes_list]
    top, per_size = max(int(kw.get("top", 5)), 1), bool(kw.get("per_size", False))
    total = sum(len(p.ids) for p in parts)
    rows: list[list] = [[] for _ in codes_list]
    unmatchable = [0] * len(codes_list)
    for p in parts:
        values = score_many(codes_list, p.groups.seqs, weights, devices=devices, values=True, batch=kw.get("batch"))
        for s, v in enumerate(values):
            res = reduce_orientations(fan_out(v, p.groups))
            ok = np.flatnonzero(np.isfinite(res.utility))
            unmatchable[s] += len(p.ids) - len(ok)
            rows[s] = _select(rows[s] + [
                (float(res.utility[i]), int(p.k[i]), p.n, str(p.ids[i]), int(res.rotation[i]), bool(res.reflected[i]), p.valences[i])
                for i in ok], top, per_size)
    seqs = sum(len(p.groups.seqs) for p in parts)
    return [TopK(r, total, total, 0, u, seqs, seqs) for r, u in zip(rows, unmatchable)]


def _mesh_size(devices) -> int:
    if devices is None:
        return 1
    if isinstance(devices, (int, np.integer)):
        return int(devices)
    return len(list(devices))


# --------------------------------------------------------------------------- sharded backend

_FNS: dict = {}


def _sharded_fn(mesh, unroll: int, over: str, strict: bool):
    """jit(shard_map(...)) of the block kernel: ``over="meshes"`` shards the blocks axis,
    ``over="shapes"`` the shapes axis."""
    key = (mesh, unroll, over, strict)
    if key in _FNS:
        return _FNS[key]
    import jax
    from jax.sharding import PartitionSpec as P

    from jaxmatch.kernels.dp_xla import _blocks  # imports JAX

    def body(codes, vals, tab, gate):
        return _blocks(codes, vals, tab, gate, strict, unroll)

    specs = (P(), P("d"), P(), P()) if over == "meshes" else (P("d"), P(), P(), P())
    out_spec = P(None, "d") if over == "meshes" else P("d")
    fn = jax.jit(jax.shard_map(body, mesh=mesh, in_specs=specs, out_specs=out_spec, check_vma=False))
    _FNS[key] = fn
    return fn


class ShardedBackend:
    """A backend of the exact host (:class:`jaxmatch.scoring.exact.Backend`): the blocks of
    :func:`jaxmatch.scoring.exact.final_blocks` sharded over ``devices`` (:func:`device_mesh`).

    over="meshes": each call's blocks are split over the devices (one or a few shapes);
    over="shapes": the shapes are split over the devices, every device scores all meshes of the
    call (many shapes). Inputs are global arrays (:func:`_global`), outputs gathered on every
    host (:func:`_to_host`), so it runs unchanged on several hosts.
    """

    def __init__(self, devices=None, over: str = "meshes", unroll: int | None = None):
        if over not in ("meshes", "shapes"):
            raise ValueError(f"over must be 'meshes' or 'shapes', got {over!r}")
        self.mesh = device_mesh(devices)
        self.over = over
        self.unroll = UNROLL if unroll is None else int(unroll)
        self.mesh_lanes = self.mesh.size if over == "meshes" else 1

    def run(self, problem, vals: np.ndarray) -> np.ndarray:
        from jax.sharding import PartitionSpec as P

        d, s, n = self.mesh.size, problem.codes.shape[0], problem.n
        codes = problem.codes
        if self.over == "shapes":  # whole shapes per device: pad with all-padding shapes
            s_pad = -(-s // d) * d
            codes = np.concatenate([codes, np.full((s_pad - s, codes.shape[1]), 3, np.int32)])
        fn = _sharded_fn(self.mesh, self.unroll, self.over, problem.strict)
        cj = _global(codes, self.mesh, P() if self.over == "meshes" else P("d"))
        tab = _global(problem.tab, self.mesh, P())
        gate = _global(problem.gate, self.mesh, P())
        vspec = P("d") if self.over == "meshes" else P()
        outs = [fn(cj, _global(vals[k], self.mesh, vspec), tab, gate) for k in range(vals.shape[0])]  # asynchronous
        if not outs:
            return np.empty((s, 0, 2 * n), problem.kind.dtype)
        return np.concatenate([_to_host(o).reshape(codes.shape[0], -1, 2 * n)[:s] for o in outs], axis=1)


def sharded_values(
    codes,
    vals,
    weights,
    *,
    devices=None,
    batch: int | None = None,
    m_pad: int | None = None,
    unroll: int | None = None,
    plan: tuple[int, int] | None = None,
) -> np.ndarray:
    """:func:`jaxmatch.scoring.exact.final_values` with the meshes sharded over ``devices``
    (:class:`ShardedBackend`): ``(N, 2n) float32``, ``-inf`` for orientations without a finite
    alignment. Each call holds ``devices x blocks per call x block`` meshes."""
    be = ShardedBackend(devices, "meshes", unroll)
    return exact_values([codes], vals, weights, backend=be, batch=DEFAULT_BATCH if batch is None else batch,
                        m_pad=m_pad, plan=plan)[0]


def score_sharded(codes, vals, weights, *, devices=None, **kw):
    """:func:`jaxmatch.scoring.exact.score_bucket` with the meshes sharded over ``devices`` (same result)."""
    return reduce_orientations(sharded_values(codes, vals, weights, devices=devices, **kw))


def score_many(
    codes_list: Sequence,
    vals,
    weights,
    *,
    devices=None,
    batch: int | None = None,
    unroll: int | None = None,
    values: bool = False,
) -> list:
    """Score meshes ``vals (N, n)`` against several shapes, the shapes sharded over ``devices``.

    Returns one :class:`jaxmatch.scoring.exact.ScoreResult` per shape (with ``values``: the ``(N, 2n)``
    per-orientation values of :func:`jaxmatch.scoring.exact.final_values` instead). Shapes are padded to
    the longest one's :func:`jaxmatch.scoring.exact.bucket_length` (padding points are skipped) and to a
    multiple of the device count; meshes go in chunks of ``batch``.
    """
    if not len(codes_list):
        return []
    be = ShardedBackend(devices, "shapes", unroll)
    out = exact_values(list(codes_list), vals, weights, backend=be, batch=DEFAULT_BATCH if batch is None else batch)
    return [v if values else reduce_orientations(v) for v in out]


# --------------------------------------------------------------------------- output


def write_jsonl(path, records: Iterable[dict]) -> None:
    """Write one JSON object per line, atomically (temp file + rename: readers see the old file
    or the complete new one, never a partial one)."""
    with atomic_open(path, "w") as fh:
        for rec in records:
            fh.write(json.dumps(rec, sort_keys=False) + "\n")
