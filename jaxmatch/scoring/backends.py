"""Compiled CPU backend for the exact host: the max-plus DP as a numba kernel.

:class:`NumbaBackend` implements the backend seam of :func:`jaxmatch.scoring.exact.exact_values`
(``mesh_lanes`` and ``run(problem, vals)``): it receives the padded problem (shifted-frame
weights ``tab (4, 64)``, ``gate (4,)``, codes ``(S, m_pad)`` with their true lengths) and
returns the raw ``E[m][n]`` of every orientation, the same numbers' classification as
:func:`jaxmatch.scoring.exact.final_blocks` (valid values bit for bit; invalid ones, at or below
``kind.neg / 2``, may differ in their exact sentinel value, which the host maps to ``-inf``).

Kernel (:mod:`jaxmatch.scoring._numba_dp`, int16 models only; others go to the XLA kernel), per
chunk of :data:`LANES` meshes of one boundary length and one shape, chunks spread over all cores
with ``numba.prange`` (problems under :data:`PARALLEL_CELLS` on the calling thread):

* lanes = meshes, innermost and contiguous, int16 (32 lanes per AVX-512 op); per-vertex weights ``(2, 4, n, lanes)`` of the sequence
  and of its mirror are built once per chunk, and orientation ``r`` reads row ``(r + j) % n``
  of them (no per-orientation weight copies);
* per orientation the DP row ``d (n + 1, lanes)`` stays in L1;
* banded: after input point ``i`` only rows ``max(1, n - m + i + 1) .. min(n, i + 1)`` are
  updated (row ``j > i`` is unreachable, and a row below ``n - (m - i)`` cannot reach ``D[m][n]``);
  for ``m = 2n`` that is ``(n + 1) / (2n)`` of the cells, about half;
* padded input points (code 3) are not visited at all (``problem.lengths``).

Measurements and the alternatives tried: ``docs/perf.md``.
"""

from __future__ import annotations

import threading

import numpy as np

__all__ = ["BACKENDS", "LANES", "PARALLEL_CELLS", "NumbaBackend", "default_backend", "jax_on_cpu", "numba_values"]

BACKENDS = ("auto", "numba", "xla")
"""Values of ``JAXMATCH_BACKEND`` (:func:`default_backend`)."""

LANES = 256
"""Meshes per chunk (vector lanes of one DP row; 64 / 128 / 256 / 512 measured: docs/perf.md)."""

_LOCK = threading.Lock()

PARALLEL_CELLS = 1 << 22
"""Smallest problem (DP cells) run on all cores; smaller ones (e.g. the pruned search's rounds)
run on the calling thread: waking the thread pool costs milliseconds on a loaded machine."""


def _kernel(parallel: bool):
    """The compiled int16 kernel (:mod:`jaxmatch.scoring._numba_dp`, imported on first use)."""
    from jaxmatch.scoring import _numba_dp

    return _numba_dp.dp_kernel_i16 if parallel else _numba_dp.dp_kernel_i16_serial


def numba_values(codes, lengths, vals, tab, gate, strict: bool = False, lanes: int = LANES) -> np.ndarray:
    """Raw shifted-frame ``E[m][n]`` of every orientation: ``(S, N, 2n)`` in ``tab.dtype``.

    codes: ``(S, m_pad) int32`` (3 = padding, never visited); lengths: ``(S,)`` true lengths;
    vals: ``(N, n)`` valences 2..5; tab: ``(4, 64)`` and gate: ``(4,)`` in the DP number type
    (:func:`jaxmatch.scoring.exact.dp_table`, :func:`~jaxmatch.scoring.exact.dp_gate`); strict: some
    type must be matched. Values at or below ``tab[3, 0] / 2`` mean no finite alignment.
    """
    tab = np.ascontiguousarray(tab)
    if tab.dtype != np.int16:
        raise ValueError(f"the numba kernel is int16 only, got {tab.dtype}")
    v = np.ascontiguousarray(vals, dtype=np.int32)
    big_n, n = v.shape
    c = np.ascontiguousarray(codes, dtype=np.int32).reshape(-1, np.shape(codes)[-1])
    lens = np.minimum(np.asarray(lengths, np.int64).reshape(-1), c.shape[1])
    out = np.empty((c.shape[0], big_n, 2 * n), tab.dtype)
    if big_n == 0 or c.shape[0] == 0:
        return out
    import numba

    jobs = c.shape[0] * -(-big_n // max(int(lanes), 1))
    parallel = jobs > 1 and numba.get_num_threads() > 1 and 2 * n * n * int(lens.sum()) * big_n >= PARALLEL_CELLS
    _kernel(parallel)(c, lens, v, tab, np.ascontiguousarray(gate, dtype=tab.dtype), bool(strict), int(lanes), out)
    return out


class NumbaBackend:
    """Backend of :func:`jaxmatch.scoring.exact.exact_values` running :func:`numba_values` on all
    cores of this process (``numba.set_num_threads``: ``threads``, default all)."""

    mesh_lanes = 1

    def __init__(self, threads: int | None = None, lanes: int = LANES):
        self.threads = threads
        self.lanes = int(lanes)

    def run(self, problem, vals: np.ndarray) -> np.ndarray:
        if np.dtype(problem.kind.dtype) != np.int16:  # int32 / float32 models: the XLA kernel
            from jaxmatch.scoring.exact import CPUBackend

            return CPUBackend(self.threads).run(problem, vals)
        import numba

        flat = np.asarray(vals).reshape(-1, problem.n)
        top = numba.config.NUMBA_NUM_THREADS
        with _LOCK:  # one parallel kernel at a time (numba's workqueue layer, its fallback, is not re-entrant)
            numba.set_num_threads(top if self.threads is None else max(1, min(int(self.threads), top)))
            return numba_values(problem.codes, problem.lengths, flat, problem.tab, problem.gate, problem.strict, self.lanes)


def _numba_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("numba") is not None


def _jax_plugins_installed() -> bool:
    """Whether a JAX accelerator platform could be present: a PJRT plugin (the ``jax_plugins``
    namespace package or its entry points, as :func:`jax._src.xla_bridge.discover_pjrt_plugins`
    finds them: CUDA, ROCm, Metal, ...) or ``libtpu``. Answered without importing JAX."""
    import importlib.util
    from importlib.metadata import entry_points

    if importlib.util.find_spec("jax_plugins") is not None or importlib.util.find_spec("libtpu") is not None:
        return True
    return bool(entry_points(group="jax_plugins"))


def jax_on_cpu() -> bool:
    """Whether JAX computes on the CPU (``jax.default_backend() == "cpu"``), without importing
    JAX when the answer is certain anyway: ``JAX_PLATFORMS=cpu``, or no accelerator plugin
    installed (:func:`_jax_plugins_installed`). Otherwise (JAX already imported, another
    ``JAX_PLATFORMS``, a plugin present) JAX itself is asked."""
    import os
    import sys

    if "jax" not in sys.modules:
        platforms = os.environ.get("JAX_PLATFORMS", "").strip().lower()
        if platforms == "cpu" or (not platforms and not _jax_plugins_installed()):
            return True
    import jax

    return jax.default_backend() == "cpu"


def default_backend(threads: int | None = None, unroll: int | None = None):
    """The exact host's backend when none is given.

    ``JAXMATCH_BACKEND`` = ``auto`` (default): :class:`NumbaBackend` when JAX computes on the CPU
    (:func:`jax_on_cpu`) and numba is installed (int16 models; others fall back to the XLA
    kernel), else the XLA kernel :class:`jaxmatch.scoring.exact.CPUBackend` (GPUs, TPUs);
    ``numba`` or ``xla`` force one. Both give identical utilities (tests/test_backends.py).
    The numba choice does not import JAX. InputError for another value.
    """
    import os

    from jaxmatch.errors import InputError

    choice = os.environ.get("JAXMATCH_BACKEND", "auto").strip().lower() or "auto"
    if choice not in BACKENDS:
        raise InputError(f"must be one of {', '.join(BACKENDS)}, got {choice!r}", "JAXMATCH_BACKEND")
    if choice == "auto":
        choice = "numba" if _numba_available() and jax_on_cpu() else "xla"
    if choice == "numba":
        return NumbaBackend(threads)
    from jaxmatch.scoring.exact import UNROLL, CPUBackend

    return CPUBackend(threads, UNROLL if unroll is None else int(unroll))
