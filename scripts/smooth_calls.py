"""The placement smoother on a fixed workload: mesh it, record every smoothing call, replay them.

The workload: the first 12 random parts of ``scripts/make_bulk_parts.py`` at perimeter / 32; L at
P/16, T, U and frame at P/32; the six ``examples/graded`` regions with their size fields. Each pass
is a set of first calls (every meshing cache cleared before it), after one warm-up call.

    python scripts/smooth_calls.py mesh [--passes N]      # the workload N times (instruction counts:
                                                          # run under callgrind with N = 1 and 2)
    python scripts/smooth_calls.py record CALLS.pkl       # one pass, every jm_smooth call's arguments and result
    python scripts/smooth_calls.py replay CALLS.pkl [--lib SO] [--reps 3]
        # the recorded calls through this tree's C library (or another build of _placement.c):
        # best CPU seconds of the reps, and the calls whose positions differ from the recorded ones
        # (bit for bit), with the largest change of their min scaled Jacobian

Run with PYTHONPATH set to the tree to measure (its package is the one meshed and replayed).
"""

from __future__ import annotations

import argparse
import ctypes
import importlib.util
import json
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np

import jaxmatch
from jaxmatch.kernels import placement as kernels
from jaxmatch.quality import sj_inverted

ROOT = Path(__file__).resolve().parent.parent

EXAMPLES = [("examples/lshape.json", 16), ("examples/tshape.json", 32), ("examples/labels/shapes/ushape.json", 32),
            ("examples/holes/frame.json", 32)]


def workload() -> list[tuple[str, object, dict]]:
    """``(name, shape, keyword arguments of jaxmatch.mesh)`` of every region of the workload."""
    from jaxmatch.field import load_field

    spec = importlib.util.spec_from_file_location("make_bulk_parts", ROOT / "scripts" / "make_bulk_parts.py")
    parts = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(parts)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, doc in enumerate(parts.parts(12)):
            p = Path(tmp) / f"part-{i:03d}.json"
            p.write_text(json.dumps(doc))
            out.append((p.name, jaxmatch.load_shape(p), {"divisions": 32}))
    for path, div in EXAMPLES:
        out.append((path, jaxmatch.load_shape(ROOT / path), {"divisions": div}))
    for f in sorted((ROOT / "examples" / "graded").glob("*.field.json")):
        name = f.name[: -len(".field.json")]
        out.append((name, jaxmatch.load_shape(f.with_name(f"{name}.json")), {"size": load_field(f)}))
    return out


def mesh(passes: int, record: list | None = None) -> None:
    """Mesh the workload ``passes`` times (first calls), printing each pass's CPU seconds; with
    ``record``, append every smoothing call's ``(arguments, result)`` to it."""
    from jaxmatch.batch import one_core, warm_kernels

    regions = workload()
    cat = jaxmatch.load_catalogue()
    warm_kernels(True)
    one_core()
    jaxmatch.mesh(jaxmatch.load_shape(ROOT / "examples" / "square.json"), size=0.5, catalogue=cat)
    if record is not None:
        smooth = kernels.smooth

        def recording(*args):
            out = smooth(*args)
            record.append((tuple(np.array(a) if isinstance(a, np.ndarray) else a for a in args), out.copy()))
            return out

        kernels.smooth = recording
    for p in range(passes):
        cat.cache.forget_shapes()
        t = time.process_time()
        for _, shape, kw in regions:
            jaxmatch.mesh(shape, catalogue=cat, **kw)
        print(f"pass {p}: {len(regions)} regions, {time.process_time() - t:.3f} CPU s")


def replay(calls: list, lib_path: str, reps: int) -> dict:
    """The recorded calls through the C library at ``lib_path``: best CPU seconds of ``reps``,
    calls whose positions differ from the recorded ones, the most negative change of a differing
    call's min scaled Jacobian."""
    lib = ctypes.CDLL(lib_path)
    D, L, P = ctypes.c_double, ctypes.c_int64, ctypes.c_void_p
    lib.jm_smooth.restype = ctypes.c_int
    lib.jm_smooth.argtypes = [P, L, P, L, P, L, P, P, P, P, L, L, P, L, L, L, D, D, P]
    f = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    i = lambda a: np.ascontiguousarray(a, dtype=np.int64)  # noqa: E731
    prepared = [((f(xy), i(q), i(fr), f(sa), f(sb), i(sp), i(sv), it, f(pw), ur, mem, ftol, gtol), out)
                for (xy, q, fr, sa, sb, sp, sv, it, pw, ur, mem, ftol, gtol), out in calls]
    best, results = float("inf"), []
    for _ in range(max(int(reps), 1)):
        results = []
        t = time.process_time()
        for (xy, q, fr, sa, sb, sp, sv, it, pw, ur, mem, ftol, gtol), _ in prepared:
            o = np.empty_like(xy)
            rc = lib.jm_smooth(xy.ctypes.data, xy.shape[0], q.ctypes.data, q.shape[0], fr.ctypes.data, fr.shape[0],
                               sa.ctypes.data, sb.ctypes.data, sp.ctypes.data, sv.ctypes.data, sa.shape[0], int(it),
                               pw.ctypes.data, pw.shape[0], int(ur), int(mem), float(ftol), float(gtol), o.ctypes.data)
            if rc != 0:
                raise MemoryError("jm_smooth failed")
            results.append(o)
        best = min(best, time.process_time() - t)
    differ, worst = 0, 0.0
    for (args, out), o in zip(prepared, results):
        if not np.array_equal(out, o):
            differ += 1
            worst = min(worst, float(sj_inverted(o, args[1])[0].min() - sj_inverted(out, args[1])[0].min()))
    return {"calls": len(prepared), "cpu_s": best, "differ": differ, "worst_min_sj_change": worst}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("mesh")
    m.add_argument("--passes", type=int, default=1)
    r = sub.add_parser("record")
    r.add_argument("out")
    p = sub.add_parser("replay")
    p.add_argument("calls")
    p.add_argument("--lib", default=None, help="a build of _placement.c (default: this tree's)")
    p.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    if a.cmd == "mesh":
        mesh(a.passes)
    elif a.cmd == "record":
        calls: list = []
        mesh(1, calls)
        Path(a.out).write_bytes(pickle.dumps(calls))
        print(f"{len(calls)} smoothing calls in {a.out}")
    else:
        from jaxmatch.kernels import _placement

        calls = pickle.loads(Path(a.calls).read_bytes())
        print(json.dumps(replay(calls, a.lib or _placement.__file__, a.reps)))


if __name__ == "__main__":
    main()
