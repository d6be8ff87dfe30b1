"""The placement kernels: the C library built with the package (``_placement.c``, called through
ctypes), each the numpy reference of :mod:`jaxmatch.placement.embed` or
:mod:`jaxmatch.placement.choose` step for step (``tests/test_embed_numba.py`` and
``tests/test_placement.py`` check each against it). ``JAXMATCH_PLACEMENT_KERNELS`` is read here
and nowhere else.

Where the library was not built (it is optional: a machine without a C compiler installs the
package without it, and the README asks only for ``python3`` and PyPI) or
``JAXMATCH_PLACEMENT_KERNELS=numba`` is set, :data:`BACKEND` is ``"numba"``: the smoothing loop and
the dense Tutte solve run in numba (``_numba_smooth.py``, imported on first use), everything else
in the callers' numpy (they test ``BACKEND == "c"``). Why numba for the smoother and numpy for
the rest (seconds per ``jaxmatch mesh REGION --divisions 32`` process, the implementations forced
and alternated, median of 3 for the first; the numpy column is every placement kernel in numpy):

=============================  ======  ======  ======
region                         C       numba   numpy
=============================  ======  ======  ======
``examples/tshape.json``       0.39    0.98    0.41
``examples/holes/letter-A``    0.64    1.27    13.2
``examples/dense/glyph-G``     3.52    4.05    55.3
=============================  ======  ======  ======

numba pays ~0.6 s a process to load; numpy's L-BFGS loop calls its objective ~10^5 times on a
mesh with holes, so the smoother keeps its numba copy. The alignment DPs do not need one: over
the 118 meshes of ``scripts/snapshot_meshes`` (every example region at P/16 and P/32) numba
smoothing with them in numpy took 165.2 s against 163.3 s with them in numba too (alternated
region by region, the same files byte for byte), so their numba copy (``_numba_spread.py``) was
dropped. (C took 71.8 s and numba 202.8 s over those meshes, run one after the other.)

Functions (arrays C-contiguous; ``float64`` or ``int64``):

* :func:`smooth` ``(xy (V, 2), quads (F, 4), free (nf,), sa, sb (S, 2), sp (S + 1,), sv (R,),
  iters, powers (p,), untangle_rounds, mem, ftol, gtol) -> (V, 2)``: ``embed.smooth``'s loop;
* :func:`lbfgs`, :func:`energy`, :func:`objective`: its pieces (tests);
* :func:`tutte_dense` ``(quads, V, boundary (n,), boundary_xy (n, 2)) -> (V, 2)``;
* C only (the callers' numpy when :data:`BACKEND` is ``"numba"``, the same values):
  :func:`orientation_utilities` ``(codes (m,), vals (n,), table (3, 64), skip (3,)) -> (2n,)``
  (``spread.orientation_utilities``); :func:`candidates` ``(codes, seqs (O, n), table, between
  (m, m), prefix, suffix (m,), gq (m, m), tt (m,), perimeter, unit, limit) -> (utility (O,), gap
  (O,), orientation (K,), alignments (K, n))`` (``spread.spread_optimal_alignment`` for ``O``
  orientations); :func:`spread` ``(tt (m,), perimeter, ok (n, m) bool, starts (S,)) -> (n,) int64
  or None`` (``spread.spread_alignment``); :func:`sj_inverted` ``(xy (V, 2), quads (F, 4)) ->
  (sj (F,), inverted (F,) bool)`` (``quality.sj_inverted``).

After editing ``_placement.c``, rebuild it with ``.venv/bin/python -m pip install -e .`` (an
editable install puts the library next to it).
"""

from __future__ import annotations

import ctypes
import os

import numpy as np

from jaxmatch.lazy import served_from

try:  # the C library, built with the package where a C compiler exists
    from jaxmatch.kernels import _placement
except ImportError:  # pragma: no cover - installed without a C compiler
    _placement = None

__all__ = ["BACKEND", "energy", "flat_slides", "lbfgs", "objective", "smooth", "tutte_dense"]  # + the C-only ones below


def flat_slides(slides) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(sa (S, 2), sb (S, 2), sp (S + 1,) int64, sv (R,) int64)`` from ``embed.Slide`` s."""
    S = len(slides)
    sa = np.zeros((S, 2))
    sb = np.zeros((S, 2))
    sp = np.zeros(S + 1, np.int64)
    for i, s in enumerate(slides):
        sa[i] = s.a
        sb[i] = s.b
        sp[i + 1] = sp[i] + len(s.vertices)
    sv = np.concatenate([np.asarray(s.vertices, np.int64) for s in slides]) if S else np.zeros(0, np.int64)
    return sa, sb, sp, sv


def _load_c():
    if os.environ.get("JAXMATCH_PLACEMENT_KERNELS", "").strip().lower() == "numba":
        return None
    if _placement is None:
        return None
    lib = ctypes.CDLL(_placement.__file__)
    D, L, P = ctypes.c_double, ctypes.c_int64, ctypes.c_void_p
    sig = {
        "jm_smooth": (ctypes.c_int, [P, L, P, L, P, L, P, P, P, P, L, L, P, L, L, L, D, D, P]),
        "jm_energy": (D, [P, L, P, L, D, D, P]),
        "jm_objective": (D, [P, L, P, L, P, L, P, L, P, P, P, P, L, D, D, P]),
        "jm_lbfgs": (ctypes.c_int, [P, L, P, L, P, L, P, L, P, P, P, P, L, D, D, L, L, D, D]),
        "jm_tutte": (ctypes.c_int, [P, L, L, P, L, P]),
        "jm_orientation_utilities": (None, [P, L, P, L, P, P, P]),
        "jm_candidates": (L, [P, L, P, L, L, P, P, P, P, P, P, D, D, L, P, P, P, P]),
        "jm_sj_inverted": (None, [P, P, L, P, P]),
        "jm_spread": (ctypes.c_int, [P, L, D, P, L, P, L, P]),
    }
    for name, (res, args) in sig.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    return lib


_C = _load_c()
BACKEND = "c" if _C is not None else "numba"
"""``"c"`` (the library built with the package) or ``"numba"`` (the fallback: the smoother in
numba, the other kernels in the callers' numpy)."""

_NUMBA_NAMES = frozenset({"energy", "lbfgs", "objective", "smooth", "tutte_dense"})
"""What the fallback serves from ``_numba_smooth.py``."""


def _f(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)


def _p(a: np.ndarray):
    return a.__array_interface__["data"][0]  # (the address ``a.ctypes.data`` gives, a third faster to ask)


def _check(rc: int) -> None:
    if rc == -1:
        raise MemoryError("placement kernel: out of memory")
    if rc != 0:
        raise ValueError(f"placement kernel failed ({rc})")


if _C is not None:
    __all__ += ["candidates", "orientation_utilities", "sj_inverted", "spread"]

    def smooth(xy, quads, free, sa, sb, sp, sv, iters, powers, untangle_rounds, mem, ftol, gtol):
        xy, q, fr, sa, sb, sp, sv, pw = _f(xy), _i(quads), _i(free), _f(sa), _f(sb), _i(sp), _i(sv), _f(powers)
        out = np.empty_like(xy)
        _check(_C.jm_smooth(_p(xy), xy.shape[0], _p(q), q.shape[0], _p(fr), fr.shape[0], _p(sa), _p(sb), _p(sp), _p(sv),
                            sa.shape[0], int(iters), _p(pw), pw.shape[0], int(untangle_rounds), int(mem), float(ftol),
                            float(gtol), _p(out)))
        return out

    def energy(pos, quads, delta, power):
        pos, q = _f(pos), _i(quads)
        grad = np.empty_like(pos)
        f = _C.jm_energy(_p(pos), pos.shape[0], _p(q), q.shape[0], float(delta), float(power), _p(grad))
        return f, grad

    def objective(x, base, free, sa, sb, sp, sv, quads, delta, power):
        x, base, q, fr, sa, sb, sp, sv = _f(x), _f(base), _i(quads), _i(free), _f(sa), _f(sb), _i(sp), _i(sv)
        g = np.empty_like(x)
        f = _C.jm_objective(_p(x), x.shape[0], _p(base), base.shape[0], _p(q), q.shape[0], _p(fr), fr.shape[0], _p(sa),
                            _p(sb), _p(sp), _p(sv), sa.shape[0], float(delta), float(power), _p(g))
        return f, g

    def lbfgs(x0, base, free, sa, sb, sp, sv, quads, delta, power, maxiter, mem, ftol, gtol):
        x = _f(x0).copy()
        base, q, fr, sa, sb, sp, sv = _f(base), _i(quads), _i(free), _f(sa), _f(sb), _i(sp), _i(sv)
        _check(_C.jm_lbfgs(_p(x), x.shape[0], _p(base), base.shape[0], _p(q), q.shape[0], _p(fr), fr.shape[0], _p(sa),
                           _p(sb), _p(sp), _p(sv), sa.shape[0], float(delta), float(power), int(maxiter), int(mem),
                           float(ftol), float(gtol)))
        return x

    def tutte_dense(quads, n_vertices, boundary, boundary_xy):
        q, b = _i(quads), _i(boundary)
        xy = np.zeros((int(n_vertices), 2))
        xy[b] = boundary_xy
        _check(_C.jm_tutte(_p(q), q.shape[0], int(n_vertices), _p(b), b.shape[0], _p(xy)))
        return xy

    def orientation_utilities(codes, vals, table, skip):
        c, v, t, s = _i(codes), _i(vals), _f(table), _f(skip)
        out = np.empty(2 * v.shape[0])
        _C.jm_orientation_utilities(_p(c), c.shape[0], _p(v), v.shape[0], _p(t), _p(s), _p(out))
        return out

    def candidates(codes, seqs, table, between, prefix, suffix, gq, tt, perimeter, unit, limit):
        c, sq, t = _i(codes), _i(seqs), _f(table)
        bw, pre, suf, g, tt = _f(between), _f(prefix), _f(suffix), _f(gq), _f(tt)
        O, n = sq.shape
        util, gap = np.empty(O), np.empty(O)
        own = np.empty(O * int(limit), np.int64)
        A = np.empty((O * int(limit), n), np.int64)
        K = _C.jm_candidates(_p(c), c.shape[0], _p(sq), O, n, _p(t), _p(bw), _p(pre), _p(suf), _p(g), _p(tt),
                             float(perimeter), float(unit), int(limit), _p(util), _p(gap), _p(own), _p(A))
        if K < 0:
            raise MemoryError("placement kernel: out of memory")
        return util, gap, own[:K].copy(), A[:K].copy()

    def spread(tt, perimeter, ok, starts):
        """``spread.spread_alignment``'s programme: ``(n,) int64``, or None when its minimum is
        not finite."""
        tt, st = _f(tt), _i(starts)
        okb = np.ascontiguousarray(ok, dtype=np.uint8)
        out = np.empty(okb.shape[0], np.int64)
        rc = _C.jm_spread(_p(tt), tt.shape[0], float(perimeter), _p(okb), okb.shape[0], _p(st), st.shape[0], _p(out))
        if rc < 0:
            raise MemoryError("placement kernel: out of memory")
        return out if rc == 0 else None

    def sj_inverted(xy, quads):
        xy, q = _f(xy), _i(quads)
        sj, inv = np.empty(q.shape[0]), np.empty(q.shape[0], np.uint8)
        _C.jm_sj_inverted(_p(xy), _p(q), q.shape[0], _p(sj), _p(inv))
        return sj, inv.view(bool)

else:  # pragma: no cover - exercised with JAXMATCH_PLACEMENT_KERNELS=numba
    __getattr__ = served_from("jaxmatch.kernels._numba_smooth", _NUMBA_NAMES, globals())  # numba: ~0.5 s to import
