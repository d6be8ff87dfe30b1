"""The exact DP's problem contract: what the exact host (:mod:`jaxmatch.scoring.exact`) hands a
backend, and what every backend (:mod:`jaxmatch.kernels.backends`, :mod:`jaxmatch.kernels.dp_xla`,
:mod:`jaxmatch.scoring.bulk`) computes from it.

* :class:`DPKind` and :class:`DPProblem`: the padded shapes and the compiled model in the DP
  number type (built by :func:`jaxmatch.scoring.exact.dp_problem`);
* :class:`Backend`: the seam between the host and a kernel (``mesh_lanes``, ``run``);
* :data:`UNROLL`, :data:`_INVALID`, :func:`_rotation_index`: conventions the kernels share;
* :func:`run_calls`: calls dispatched on host threads (:func:`default_threads`).

Part of the bottom floor (:mod:`jaxmatch.kernels`): numpy only, and it imports no other jaxmatch
module, so the host and the kernels import it without importing each other.
:mod:`jaxmatch.scoring.exact` re-exports every name here. Conventions (orientations, the shifted
frame, number types): :mod:`jaxmatch.scoring.exact`.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple, Protocol

import numpy as np

__all__ = ["Backend", "DPKind", "DPProblem", "UNROLL", "default_threads", "run_calls"]

UNROLL = 1
"""``lax.scan`` unroll factor (1, 2, 4, 8 measured on XLA:CPU: 1 is fastest, and compiles fastest)."""

_INVALID = 3
"""Code of a padded input point: every weight is the sentinel, so the point is skipped."""


def _rotation_index(n: int) -> np.ndarray:
    return (np.arange(n)[:, None] + np.arange(n)[None, :]) % n  # [r, j] -> (r + j) % n


class DPKind(NamedTuple):
    """The exact DP's number type for a model and boundary length (:func:`jaxmatch.scoring.exact.dp_kind`)."""

    dtype: type
    neg: float


class DPProblem(NamedTuple):
    """What a backend computes: the shapes and the compiled model in the DP number type.

    codes: ``(S, m_pad) int32`` (3 = padding); lengths: ``(S,)`` true ``m`` of each shape;
    offset: ``(S,) float64`` the skip weights added back (:func:`jaxmatch.kernels.model.skip_frame`);
    tab: ``(4, 64)`` and gate: ``(4,)`` in ``kind.dtype`` (:func:`jaxmatch.scoring.exact.dp_table`,
    :func:`jaxmatch.scoring.exact.dp_gate`); strict: some type must be matched (selects the kernel
    variant); kind: the number type; n: boundary length.
    """

    codes: np.ndarray
    lengths: np.ndarray
    offset: np.ndarray
    tab: np.ndarray
    gate: np.ndarray
    strict: bool
    kind: DPKind
    n: int


class Backend(Protocol):
    """Runs the exact DP on padded chunks (the seam between
    :func:`jaxmatch.scoring.exact.exact_values` and a kernel).

    mesh_lanes: how many devices the meshes of one call are split over (the host makes each
    call hold ``mesh_lanes * blocks per call`` blocks). run(problem, vals): ``vals (calls,
    mesh_lanes * per_call, block, n) int32`` (padding meshes are all-2 sequences) ->
    ``(S, calls * mesh_lanes * per_call * block, 2n)`` raw values in ``problem.kind.dtype``
    (the shifted-frame ``E[m][n]`` of :func:`jaxmatch.kernels.dp_xla.final_blocks`, mesh-major).
    """

    mesh_lanes: int

    def run(self, problem: DPProblem, vals: np.ndarray) -> np.ndarray: ...


def default_threads() -> int:
    """Host threads that dispatch blocks concurrently (the CPUs this process may use)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


_POOL: dict[int, ThreadPoolExecutor] = {}


def _pool(threads: int) -> ThreadPoolExecutor:
    if threads not in _POOL:
        _POOL[threads] = ThreadPoolExecutor(threads, thread_name_prefix="jaxmatch-score")
    return _POOL[threads]


def run_calls(fn, items, threads: int | None = None) -> list:
    """``[fn(x) for x in items]``, on ``threads`` host threads when there are several items
    (each jitted call releases the GIL, so XLA:CPU runs them on separate cores)."""
    items = list(items)
    threads = default_threads() if threads is None else max(1, int(threads))
    if threads == 1 or len(items) < 2:
        return [fn(x) for x in items]
    return list(_pool(threads).map(fn, items))
