"""The scoring model: what a lattice compiles to, and what every scorer takes.

A :class:`Weights` holds, for the three point types ``s`` (0), ``x`` (1), ``v`` (2):

* ``table: (3, 64) float32`` finite match weights ``[type, triple]`` (triple index
  ``16 (u-2) + 4 (v-2) + (w-2)``), :data:`NEG` where the pairing is forbidden;
* ``forbidden: (3, 64) bool``, the ``-inf`` (weeded or forbidden) entries;
* ``skip: (3,) float32`` finite skip weights (the cost of leaving a shape point of that type
  without a mesh vertex), :data:`NEG` where skipping is forbidden;
* ``must: (3,) bool``, the types whose skip weight is ``-inf`` (every such point must get a
  mesh vertex).

The utility of an alignment is ``sum over matched points of table[code, triple] + sum over
skipped points of skip[code]``; the exact DP is
``D[i][j] = max(D[i-1][j] + skip[code[i-1]], D[i-1][j-1] + W[i-1, j-1])``
(:mod:`jaxmatch.scoring.exact`). With ``skip = 0`` it is the paper's modified LCS.

Every scorer (exact, soft, bulk, tuning) takes a :class:`Weights`, or anything
:func:`weights_of` turns into one (a :class:`jaxmatch.scoring.lattice.Lattice`, or a
``(3, 4, 4, 4)`` table with ``-inf`` entries and skip weights 0). This module is the only
place :data:`NEG` is defined.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

__all__ = ["NEG", "SkipFrame", "Weights", "make_weights", "skip_frame", "skip_offset", "skipped_weight", "weights_of"]

NEG = -1e9
"""Finite stand-in for ``-inf`` in the scorers (forbidden pairings and forbidden skips).

Values ``<= NEG / 2`` mean "no finite alignment"; this assumes ``m * max|weight| << |NEG| / 2``
(lattice weights are small integers, at most ``MAX_WEIGHT``)."""


@dataclass(frozen=True, eq=False)
class Weights:
    """A compiled scoring model (module docstring). Arrays are read-only.

    table: ``(3, 64) float32`` finite match weights, NEG where forbidden.
    forbidden: ``(3, 64) bool``.
    skip: ``(3,) float32`` finite skip weights, NEG where skipping is forbidden.
    must: ``(3,) bool`` (skip weight ``-inf``).
    name: the lattice's name (for messages), may be empty.
    """

    table: np.ndarray
    forbidden: np.ndarray
    skip: np.ndarray
    must: np.ndarray
    name: str = ""

    @property
    def cube(self) -> np.ndarray:
        """``(3, 4, 4, 4) float32`` finite table ``[type, u-2, v-2, w-2]`` (NEG where forbidden)."""
        return self.table.reshape(3, 4, 4, 4)

    def table_inf(self) -> np.ndarray:
        """``(3, 4, 4, 4) float32`` match weights with ``-inf`` where forbidden."""
        return np.where(self.forbidden, -np.inf, self.table).astype(np.float32).reshape(3, 4, 4, 4)

    def skip_inf(self) -> np.ndarray:
        """``(3,) float32`` skip weights with ``-inf`` where skipping is forbidden."""
        return np.where(self.must, -np.inf, self.skip).astype(np.float32)

    @cached_property
    def frame(self) -> "SkipFrame":
        """The model in the shifted frame (:func:`skip_frame`), computed once."""
        return _frame(self)

    @property
    def has_skip(self) -> bool:
        """Whether any skip weight differs from 0 (the paper's free skipping)."""
        return bool(self.must.any() or np.any(self.skip != 0))

    def skip_json(self) -> dict:
        """``{"s": w or None, "x": ..., "v": ...}``: integer (or float) skip weights, None for -inf."""
        out = {}
        for k, kind in enumerate("sxv"):
            w = float(self.skip[k])
            out[kind] = None if self.must[k] else (int(w) if w == round(w) else w)
        return out


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def make_weights(table, skip=None, name: str = "") -> Weights:
    """:class:`Weights` from a ``(3, 4, 4, 4)`` (or ``(3, 64)``) table with ``-inf`` (or values
    ``<= NEG``) for forbidden pairings, and skip weights ``(3,)`` (default 0; ``-inf`` or values
    ``<= NEG`` = must match). ValueError on wrong shapes or NaN."""
    t = np.asarray(table, dtype=np.float32)
    if t.size != 192 or t.shape not in ((3, 4, 4, 4), (3, 64)):
        raise ValueError(f"table must have shape (3, 4, 4, 4), got {t.shape}")
    t = t.reshape(3, 64)
    s = np.zeros(3, np.float32) if skip is None else np.asarray(skip, dtype=np.float32).reshape(-1)
    if s.shape != (3,):
        raise ValueError(f"skip weights must have shape (3,), got {s.shape}")
    if np.isnan(t).any() or np.isnan(s).any():
        raise ValueError("weights must not be NaN")
    forbidden = t <= NEG
    must = s <= NEG
    return Weights(
        table=_frozen(np.where(forbidden, np.float32(NEG), t).astype(np.float32)),
        forbidden=_frozen(forbidden),
        skip=_frozen(np.where(must, np.float32(NEG), s).astype(np.float32)),
        must=_frozen(must),
        name=str(name),
    )


def weights_of(model, skip=None) -> Weights:
    """The :class:`Weights` of ``model``: a :class:`Weights` (returned as is), a lattice (anything
    with a ``weights()`` method), or a ``(3, 4, 4, 4)`` table (``-inf`` = forbidden) with
    ``skip (3,)`` (default 0, the paper's free skipping). ``skip`` is only accepted with a table."""
    if isinstance(model, Weights):
        if skip is not None:
            raise ValueError("skip weights belong to the Weights object already")
        return model
    if hasattr(model, "weights") and callable(model.weights):
        if skip is not None:
            raise ValueError("skip weights belong to the lattice already")
        return model.weights()
    return make_weights(model, skip)


def skipped_weight(codes, matched, weights: Weights) -> float:
    """``sum of skip[codes[i]]`` over the points ``i`` not in ``matched`` (``-inf`` when one of
    them must be matched). codes: ``(m,)`` ints 0/1/2; matched: ``(n,)`` indices."""
    c = np.asarray(codes, np.int64).reshape(-1)
    keep = np.ones(c.shape[0], bool)
    keep[np.asarray(matched, np.int64).reshape(-1)] = False
    skipped = c[keep]
    if np.any(weights.must[skipped]):
        return -np.inf
    return float(np.sum(weights.skip.astype(np.float64)[skipped]))


class SkipFrame(NamedTuple):
    """The model in the shifted frame of :mod:`jaxmatch.scoring.exact`.

    table: ``(3, 64) float64`` ``W' = table - skip[c]`` for finite-skip types (the table itself for
    must-match types), NEG where forbidden. gate: ``(3,) bool``, the must-match types (their skip
    branch is closed). shift: ``(3,) float64``, ``skip[c]`` for finite-skip types, 0 otherwise:
    the utility is ``E[m][n] + sum_i shift[codes[i]]``.
    """

    table: np.ndarray
    gate: np.ndarray
    shift: np.ndarray


def skip_frame(weights) -> SkipFrame:
    """:class:`SkipFrame` of a model (anything :func:`weights_of` takes; cached on a :class:`Weights`)."""
    return weights_of(weights).frame


def _frame(w: Weights) -> SkipFrame:
    shift = np.where(w.must, 0.0, w.skip.astype(np.float64))
    t = np.where(w.forbidden, NEG, w.table.astype(np.float64) - shift[:, None])
    return SkipFrame(t, w.must.copy(), shift)


def skip_offset(codes, weights) -> float:
    """``sum_i shift[codes[i]]``: what the shifted frame adds back (:func:`skip_frame`)."""
    fr = skip_frame(weights)
    c = np.asarray(codes, np.int64).reshape(-1)
    return float(np.sum(fr.shift[c])) if c.size else 0.0
