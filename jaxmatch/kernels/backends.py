"""The scoring DP's CPU kernels and the choice among them (``JAXMATCH_BACKEND``, read here and
nowhere else; the role of each kernel: :mod:`jaxmatch.kernels`).

:class:`NumbaBackend` implements the backend seam of :func:`jaxmatch.scoring.exact.exact_values`
(``mesh_lanes`` and ``run(problem, vals)``): it receives the padded problem (shifted-frame
weights ``tab (4, 64)``, ``gate (4,)``, codes ``(S, m_pad)`` with their true lengths) and
returns the raw ``E[m][n]`` of every orientation, the same numbers' classification as
:func:`jaxmatch.scoring.exact.final_blocks` (valid values bit for bit; invalid ones, at or below
``kind.neg / 2``, may differ in their exact sentinel value, which the host maps to ``-inf``).

Kernel (:mod:`jaxmatch.kernels.dp_numba`, int16 models only; others go to the XLA kernel), per
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

Start-up: importing numba and loading its cached kernel costs ~0.45 s per process, far more than
the pruned search of one shape computes (a few million DP cells). So the default backend
(:func:`default_backend`, ``auto``) runs small problems in a light kernel until the process has
spent :data:`NUMPY_CELLS` cells on them, and numba from then on (or at once for a larger problem,
or when the kernel is already loaded). The light kernel is :func:`c_values`, the numba kernel's
steps in C (``jaxmatch/kernels/_dp.c``, built with the package, loaded with ctypes in
milliseconds; bit for bit the numba kernel's values, ~7x numpy's speed on a small ranking), or,
where that library was not built, :func:`numpy_values` (the same recurrence as the XLA kernel,
vectorised over meshes x orientations). All kernels give the same utilities
(tests/test_backends.py). The same library holds one orientation's alignment (:func:`c_align`,
for :func:`jaxmatch.scoring.exact.align`).

Measurements and the alternatives tried: ``docs/perf.md``.
"""

from __future__ import annotations

import ctypes
import functools
import importlib.util
import os
import sys
import threading

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.kernels.problem import UNROLL, DPProblem

try:  # the C library, built with the package where a C compiler exists (loaded with ctypes on first use)
    from jaxmatch.kernels import _dp
except ImportError:  # pragma: no cover - installed without a C compiler
    _dp = None

__all__ = ["BACKENDS", "LANES", "NUMPY_CELLS", "PARALLEL_CELLS", "NumbaBackend", "c_align", "c_kernel", "c_values",
           "default_backend", "jax_on_cpu", "numba_values", "numpy_values", "serial_only"]

BACKENDS = ("auto", "numba", "xla")
"""Values of ``JAXMATCH_BACKEND`` (:func:`default_backend`)."""

LANES = 256
"""Meshes per chunk (vector lanes of one DP row; 64 / 128 / 256 / 512 measured: docs/perf.md)."""

_LOCK = threading.Lock()

PARALLEL_CELLS = 1 << 22
"""Smallest problem (DP cells) run on all cores; smaller ones (e.g. the pruned search's rounds)
run on the calling thread: waking the thread pool costs milliseconds on a loaded machine."""


NUMPY_CELLS = 1 << 28
"""DP cells (``S * N * 2n * n * m`` summed over calls) the default backend computes with
:func:`numpy_values` per process before it loads the numba kernel (~0.13 s of numpy at 2e9
cells/s, against ~0.45 s to import numba and load its kernel; a single pruned ranking needs
~3-5e6). A call above what is left goes to numba at once."""

_NUMPY_SPENT = [0]  # cells computed by numpy_values for NumbaBackend(numpy_cells=...) in this process
_NUMBA_LOADED = [False]  # the numba kernel has been loaded in this process (_kernel)


def numpy_values(codes, lengths, vals, tab, gate, strict: bool = False) -> np.ndarray:
    """:func:`numba_values` in numpy, for any DP number type: ``(S, N, 2n)`` in ``tab.dtype``.

    Arguments as :func:`numba_values`. The recurrence of the XLA kernel
    (:func:`jaxmatch.kernels.dp_xla._final_block`: ``E[i][j] = max(min(E[i-1][j], gate[c]),
    E[i-1][j-1] + W'[c, j])``, ``E[i][0]`` capped by the gate) on one array ``(n + 1, N * 2n)``
    (rows ``j``; lanes = meshes x orientations), one vector step per input point; padded points
    (beyond ``lengths``) are not visited. Same operations in the same number type, so valid values
    are bit for bit those of the other kernels (invalid ones, at or below ``tab[3, 0] / 2``, may
    differ in their sentinel value). Memory: ``~(4 * 2 + 8) * N * 2n * n`` bytes.
    """
    tab = np.ascontiguousarray(tab)
    v = np.asarray(vals, np.int64)
    big_n, n = v.shape
    c = np.asarray(codes, np.int64).reshape(-1, np.shape(codes)[-1])
    lens = np.minimum(np.asarray(lengths, np.int64).reshape(-1), c.shape[1])
    out = np.empty((c.shape[0], big_n, 2 * n), tab.dtype)
    if big_n == 0 or c.shape[0] == 0:
        return out
    rot = (np.arange(n)[:, None] + np.arange(n)[None, :]) % n  # [r, j]: vertex j of rotation r is vertex (r + j) % n

    def per_vertex(s):  # triple index of [s[k+1], s[k], s[k-1]]: (N, n)
        return (np.roll(s, -1, 1) - 2) * 16 + (s - 2) * 4 + (np.roll(s, 1, 1) - 2)

    f = np.concatenate([per_vertex(v)[:, rot], per_vertex(v[:, ::-1])[:, rot]], axis=1)  # (N, 2n, n), orientation o
    wc = tab[:, f.transpose(2, 0, 1)].reshape(4, n, big_n * 2 * n)  # [code, j, b * 2n + o]
    g = np.asarray(gate, tab.dtype)
    d = np.empty((n + 1, big_n * 2 * n), tab.dtype)
    for s in range(c.shape[0]):
        d[0] = 0
        d[1:] = tab[3, 0]
        for i in range(int(lens[s])):
            ci = c[s, i]
            match = d[:-1] + wc[ci]  # from E[i-1] (row 0 = E[i-1][0])
            if strict:
                np.minimum(d, g[ci], out=d)  # skip branch capped (must-match codes), E[i][0] too
            np.maximum(d[1:], match, out=d[1:])
        out[s] = d[n].reshape(big_n, 2 * n)
    return out


_SERIAL_ONLY = [False]


def serial_only() -> None:
    """Use only the single-thread kernel in this process from now on: for worker processes of
    :func:`jaxmatch.parallel.ordered_map` (one core each; and numba's OpenMP layer is not
    fork-safe once the parent has used it)."""
    _SERIAL_ONLY[0] = True


def _kernel(parallel: bool):
    """The compiled int16 kernel (:mod:`jaxmatch.kernels.dp_numba`, imported on first use: importing
    numba costs ~0.45 s)."""
    from jaxmatch.kernels import dp_numba

    _NUMBA_LOADED[0] = True
    return dp_numba.dp_kernel_i16 if parallel else dp_numba.dp_kernel_i16_serial


def _load_c_dp():
    """The C library of :func:`c_values` (and of :func:`jaxmatch.scoring.exact.align`'s rows)
    through ctypes, or None when it was not built (it is optional: a machine without a C
    compiler installs the package without it)."""
    if _dp is None:
        return None
    lib = ctypes.CDLL(_dp.__file__)
    P, L = ctypes.c_void_p, ctypes.c_int64
    lib.jm_dp_i16.restype = ctypes.c_int
    lib.jm_dp_i16.argtypes = [P, L, L, P, P, L, L, P, P, ctypes.c_int, L, P]
    lib.jm_align_f32.restype = ctypes.c_int
    lib.jm_align_f32.argtypes = [P, L, P, L, P, P, ctypes.c_float, P]
    return lib


_C_DP = [None, False]  # [the library or None, whether loading was tried]


def c_kernel():
    """The C library of :func:`c_values`, loaded on first use (None when not built)."""
    if not _C_DP[1]:
        _C_DP[0], _C_DP[1] = _load_c_dp(), True
    return _C_DP[0]


def c_align(codes, seq, table, must, neg: float) -> np.ndarray | None:
    """One orientation's best alignment in C (``jm_align_f32``): the float32 rows of
    :func:`jaxmatch.scoring.exact.dp_rows` and the backtrack of :func:`jaxmatch.scoring.exact.align`,
    the same operations in the same order, so the same alignment. ``(n,) int32``, or None when
    no alignment of this orientation is finite.

    codes: ``(m,)`` ints 0/1/2; seq: ``(n,)`` valences in matched order; table: ``(3, 64)`` the
    shifted-frame weights (:func:`jaxmatch.kernels.model.skip_frame`), ``neg`` where forbidden;
    must: ``(3,)`` bool, the must-match types. RuntimeError when the library was not built,
    MemoryError when it runs out."""
    lib = c_kernel()
    if lib is None:
        raise RuntimeError("the C kernel (jaxmatch.kernels._dp) is not built")
    c = np.ascontiguousarray(codes, dtype=np.int32).reshape(-1)
    s = np.ascontiguousarray(seq, dtype=np.int64).reshape(-1)
    tab = np.ascontiguousarray(table, dtype=np.float32).reshape(3, 64)
    mu = np.ascontiguousarray(must, dtype=np.uint8)
    out = np.empty(s.shape[0], np.int32)
    rc = lib.jm_align_f32(c.ctypes.data, c.shape[0], s.ctypes.data, s.shape[0], tab.ctypes.data, mu.ctypes.data,
                          float(neg), out.ctypes.data)
    if rc < 0:
        raise MemoryError("alignment kernel: out of memory")
    return None if rc == 1 else out


def c_values(codes, lengths, vals, tab, gate, strict: bool = False, lanes: int = LANES) -> np.ndarray:
    """:func:`numba_values` in C on the calling thread: ``(S, N, 2n) int16``, the same steps in
    the same order (``jaxmatch/kernels/_dp.c``, chunks of ``lanes`` meshes as the lanes of one
    row), so the same values bit for bit, invalid ones included. Arguments as
    :func:`numba_values`; int16 only. Raises RuntimeError when the library was not built,
    MemoryError when it runs out."""
    tab = np.ascontiguousarray(tab)
    if tab.dtype != np.int16:
        raise ValueError(f"the C kernel is int16 only, got {tab.dtype}")
    lib = c_kernel()
    if lib is None:
        raise RuntimeError("the C kernel (jaxmatch.kernels._dp) is not built")
    v = np.ascontiguousarray(vals, dtype=np.int32)
    big_n, n = v.shape
    c = np.ascontiguousarray(codes, dtype=np.int32).reshape(-1, np.shape(codes)[-1])
    lens = np.ascontiguousarray(np.minimum(np.asarray(lengths, np.int64).reshape(-1), c.shape[1]))
    g = np.ascontiguousarray(gate, dtype=np.int16)
    out = np.empty((c.shape[0], big_n, 2 * n), np.int16)
    if big_n == 0 or c.shape[0] == 0:
        return out
    if lib.jm_dp_i16(c.ctypes.data, c.shape[0], c.shape[1], lens.ctypes.data, v.ctypes.data, big_n, n,
                     tab.ctypes.data, g.ctypes.data, int(bool(strict)), max(int(lanes), 1), out.ctypes.data) != 0:
        raise MemoryError("scoring kernel: out of memory")
    return out


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
    parallel = not _SERIAL_ONLY[0] and jobs > 1 and numba.get_num_threads() > 1 and 2 * n * n * int(lens.sum()) * big_n >= PARALLEL_CELLS
    _kernel(parallel)(c, lens, v, tab, np.ascontiguousarray(gate, dtype=tab.dtype), bool(strict), int(lanes), out)
    return out


class NumbaBackend:
    """Backend of :func:`jaxmatch.scoring.exact.exact_values` running :func:`numba_values` on all
    cores of this process (``numba.set_num_threads``: ``threads``, default all).

    numpy_cells: run a problem with the light kernel instead (:func:`c_values` for int16 models
    when its library is built, else :func:`numpy_values`) while the numba kernel is not loaded in
    this process and the problems so run (by any instance) stay within this many DP cells in all
    (:data:`NUMPY_CELLS` for :func:`default_backend`'s choice; 0: always numba).
    int32 / float32 models go to the XLA kernel (or numpy within that budget)."""

    mesh_lanes = 1

    def __init__(self, threads: int | None = None, lanes: int = LANES, numpy_cells: int = 0):
        self.threads = threads
        self.lanes = int(lanes)
        self.numpy_cells = int(numpy_cells)

    def _numpy_first(self, problem, big_n: int) -> bool:
        """Whether this problem runs in numpy (and book its cells): see ``numpy_cells``."""
        if self.numpy_cells <= 0 or _NUMBA_LOADED[0]:
            return False
        cells = 2 * problem.n * problem.n * big_n * int(np.minimum(problem.lengths, problem.codes.shape[1]).sum())
        with _LOCK:
            if _NUMPY_SPENT[0] + cells > self.numpy_cells:
                return False
            _NUMPY_SPENT[0] += cells
        return True

    def run(self, problem: DPProblem, vals: np.ndarray) -> np.ndarray:
        flat = np.asarray(vals).reshape(-1, problem.n)
        if self._numpy_first(problem, flat.shape[0]):
            if np.dtype(problem.kind.dtype) == np.int16 and c_kernel() is not None:
                return c_values(problem.codes, problem.lengths, flat, problem.tab, problem.gate, problem.strict, self.lanes)
            return numpy_values(problem.codes, problem.lengths, flat, problem.tab, problem.gate, problem.strict)
        if np.dtype(problem.kind.dtype) != np.int16:  # int32 / float32 models: the XLA kernel
            from jaxmatch.kernels.dp_xla import CPUBackend  # imports JAX

            return CPUBackend(self.threads).run(problem, vals)
        import numba

        top = numba.config.NUMBA_NUM_THREADS
        with _LOCK:  # one parallel kernel at a time (numba's workqueue layer, its fallback, is not re-entrant)
            numba.set_num_threads(top if self.threads is None else max(1, min(int(self.threads), top)))
            return numba_values(problem.codes, problem.lengths, flat, problem.tab, problem.gate, problem.strict, self.lanes)


@functools.lru_cache(maxsize=1)
def _numba_available() -> bool:
    """Whether numba is installed (asked once per process: finding the spec stats the path,
    about 1 ms a call, once per scored bucket)."""
    return importlib.util.find_spec("numba") is not None


@functools.lru_cache(maxsize=1)
def _jax_plugins_installed() -> bool:
    """Whether a JAX accelerator platform could be present: a PJRT plugin (the ``jax_plugins``
    namespace package or its entry points, as :func:`jax._src.xla_bridge.discover_pjrt_plugins`
    finds them: CUDA, ROCm, Metal, ...) or ``libtpu``. Answered without importing JAX, once per
    process (reading every installed package's metadata took ~2 ms a call, 48 calls a mesh)."""
    from importlib.metadata import entry_points  # ~70 ms to import: only when this is asked

    if importlib.util.find_spec("jax_plugins") is not None or importlib.util.find_spec("libtpu") is not None:
        return True
    return bool(entry_points(group="jax_plugins"))


def jax_on_cpu() -> bool:
    """Whether JAX computes on the CPU (``jax.default_backend() == "cpu"``), without importing
    JAX when the answer is certain anyway: ``JAX_PLATFORMS=cpu``, or no accelerator plugin
    installed (:func:`_jax_plugins_installed`). Otherwise (JAX already imported, another
    ``JAX_PLATFORMS``, a plugin present) JAX itself is asked."""
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
    kernel), small problems first in the light kernel, C or numpy (``numpy_cells=NUMPY_CELLS``,
    module docstring),
    else the XLA kernel :class:`jaxmatch.kernels.dp_xla.CPUBackend` (GPUs, TPUs); ``numba``
    (always the numba kernel) or ``xla`` force one. Both give identical utilities (tests/test_backends.py).
    The numba choice does not import JAX. InputError for another value.
    """
    choice = os.environ.get("JAXMATCH_BACKEND", "auto").strip().lower() or "auto"
    if choice not in BACKENDS:
        raise InputError(f"must be one of {', '.join(BACKENDS)}, got {choice!r}", "JAXMATCH_BACKEND")
    if choice == "auto":
        if _numba_available() and jax_on_cpu():
            return NumbaBackend(threads, numpy_cells=NUMPY_CELLS)
        choice = "xla"
    if choice == "numba":
        return NumbaBackend(threads)
    from jaxmatch.kernels.dp_xla import CPUBackend  # imports JAX

    return CPUBackend(threads, UNROLL if unroll is None else int(unroll))
