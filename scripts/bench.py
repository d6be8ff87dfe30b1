#!/usr/bin/env python3
"""Scoring benchmark: jaxmatch's exact scorer against a compiled single-thread reference.

Fixed workload (so figures compare over time): every mesh of the shipped catalogue
(``jaxmatch/data/catalogue-k0-5.npz``, k = 0..5, 22641 meshes) against each shape of
:data:`EXAMPLES` annotated with m = 64 points, lattice ``fine``.

Work unit (the same for every scorer): one *DP cell update* is one ``D[i][j]`` of the modified
LCS for one orientation. Per mesh of boundary length n and shape of m points that is
``2n orientations x n vertices x m points = 2 n^2 m`` cells, whether or not a scorer computes
them all. ``cells/s`` = workload cells / wall time; ``meshes/s`` = (meshes x shapes) / wall time.

Printed, from one run:

* jaxmatch exact scorer (``score_bucket`` on every mesh, all host threads): compile time
  (first pass minus a warm pass) and run time (min / median of ``--reps``), meshes/s, cells/s;
* the reference (numba ``@njit``, nopython, single thread, float32; the plain recurrence of
  ``jaxmatch.kernels.reference.dp_reference`` with skip weights,
  ``D[i][j] = max(D[i-1][j] + skip[c], D[i-1][j-1] + W[i-1, j-1])``, in the unshifted frame,
  written for this benchmark), checked to give identical
  utilities for every mesh and shape; its throughput, and the ratio jaxmatch / reference
  (``ratio`` in the JSON). Also a second, SIMD-friendly numba reference (all 2n orientations in
  the innermost loop, which LLVM vectorises): ``ratio_vectorised``; and the strongest one
  (:func:`make_strongest`: int16, meshes as vector lanes, ``prange`` over chunks on all cores):
  ``ratio_strongest``. ``--refs`` picks which run. For each, the fraction of the machine's peak
  (:func:`machine_peak`: int16 lanes x cores x clock) it reaches, and the ratio of process CPU
  time (all threads; less sensitive to other users of the machine than wall time,
  ``ratio_*_cpu``);
* the same workload through ``jaxmatch.scoring.bulk``: each distinct boundary sequence once (sharing
  per k), and pruned exact top-5 against exhaustive top-5 (speed-up, sequences scored);
* peak RSS: of this process, and of a scorer-only subprocess for catalogue parts k <= 4 and
  k <= 5 (streaming: memory follows the batch size, not the catalogue);
* machine load (``os.getloadavg``) before and after, CPUs, versions.

``--mesh`` runs only the meshing benchmark (:func:`bench_mesh`): ``jaxmatch.mesh`` against gmsh's
quasi-structured quad mesher on every shape of ``scripts/mesh_table.py`` at h = perimeter / 16 and
/ 32, times and qualities of both.

``--mesh --mesh-graded`` runs only :func:`bench_graded`: graded (a size field) against uniform
meshing of ``examples/graded``, time per quad.

``--json`` prints one JSON object on the last line. ``--cli`` also times a cold and a warm
``jaxmatch score examples/lshape.json`` (fresh persistent compilation cache), and the same job
scored through ``jaxmatch.scoring.bulk.top_k`` (pruned and exhaustive) for comparison. Run from the
repository root: ``.venv/bin/python scripts/bench.py``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

EXAMPLES = ["circle.json", "curved.json", "dshape.json", "hexagon.json", "lshape.json", "lshape.txt",
            "square.json", "triangle.json", "tshape.json"]
"""The benchmark shapes (the examples/ folder when the benchmark was written; fixed)."""

POINTS = 64


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true", help="print one JSON object on the last line")
    ap.add_argument("--reps", type=int, default=5, help="jaxmatch repetitions (default 5)")
    ap.add_argument("--ref-reps", type=int, default=3, help="reference repetitions (default 3; ~15 s each)")
    ap.add_argument("--internal", default="0..5", help="catalogue part, K or K1..K2 (default 0..5)")
    ap.add_argument("--catalogue", type=Path, default=None, help="catalogue file (default: the shipped one)")
    ap.add_argument("--threads", type=int, default=None, help="jaxmatch host threads (default: all CPUs of this process)")
    ap.add_argument("--batch", type=int, default=None, help="meshes per compiled call (default score.DEFAULT_BATCH)")
    ap.add_argument("--block-cells", type=int, default=None, help="DP cells per block step (default score.BLOCK_CELLS)")
    ap.add_argument("--backend", choices=["default", "xla", "numba"], default="default",
                    help="exact host backend measured as 'jaxmatch' (default: the host's default)")
    ap.add_argument("--lanes", type=int, default=None, help="meshes per chunk of the numba backend (default backends.LANES)")
    ap.add_argument("--strong-lanes", type=int, default=None, help="meshes per chunk of the strongest reference (default STRONG_LANES)")
    ap.add_argument("--dtype", choices=["auto", "int32", "float32"], default="auto", help="force the DP number type")
    ap.add_argument("--lattice", default="fine", help="lattice name or TOML path (default fine; the model includes its skip weights)")
    ap.add_argument("--skip-reference", action="store_true", help="jaxmatch only (no ratio)")
    ap.add_argument("--refs", default="plain,vectorised,strongest",
                    help="references to run, comma-separated (default plain,vectorised,strongest; plain takes ~18 s a repetition)")
    ap.add_argument("--skip-bulk", action="store_true", help="skip the distinct-sequence and pruning measurements")
    ap.add_argument("--skip-rss", action="store_true", help="skip the per-catalogue-size RSS subprocesses")
    ap.add_argument("--cli", action="store_true", help="also time cold and warm 'jaxmatch score examples/lshape.json'")
    ap.add_argument("--k6", action="store_true", help="also rank one shape against the k <= 6 catalogue (built once into --k6-cache)")
    ap.add_argument("--k6-cache", default=str(Path(os.environ.get("JAXMATCH_CACHE", Path.home() / ".cache" / "jaxmatch")) / "bench"),
                    help="folder for the k <= 6 catalogue (default $JAXMATCH_CACHE/bench or ~/.cache/jaxmatch/bench)")
    ap.add_argument("--skip-many", action="store_true", help="skip the 50-shape score-many and API measurements")
    ap.add_argument("--rss-probe", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--many-probe", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--refine", action="store_true", help="only the refinement benchmark (bench_refine): a 10,000-quad mesh")
    ap.add_argument("--mesh", action="store_true",
                    help="only the meshing benchmark (bench_mesh): jaxmatch.mesh against gmsh's quasi-structured quads")
    ap.add_argument("--mesh-reps", type=int, default=3, help="--mesh: timed repetitions after one untimed run (default 3)")
    ap.add_argument("--mesh-shapes", default="", help="--mesh: regions, comma-separated: shapes of mesh_table.SHAPES and "
                    "holes/<stem> of examples/holes (default all of both)")
    ap.add_argument("--mesh-no-holes", action="store_true",
                    help="--mesh: leave the regions with holes out (about 15 s instead of about 9 minutes: gmsh takes "
                         "2-13 s a run on the round holes, calibration included)")
    ap.add_argument("--mesh-divisions", default="16,32", help="--mesh: h = perimeter / each of these (default 16,32)")
    ap.add_argument("--mesh-large", default="", metavar="FILE:H",
                    help="--mesh: only time one large jaxmatch.mesh (FILE at size H, after one call at 20 H) and its "
                         "peak RSS, e.g. examples/lshape.json:0.00548 (~100,000 quads)")
    ap.add_argument("--mesh-bulk", type=int, default=0, metavar="DIV",
                    help="--mesh: only the bulk benchmark: `jaxmatch mesh` of every example region at --divisions DIV "
                         "with --jobs (--mesh-jobs) against gmsh meshing the same outlines one after another, e.g. 16")
    ap.add_argument("--mesh-jobs", type=int, default=2, help="--mesh-bulk: worker processes (default 2)")
    ap.add_argument("--mesh-bulk-parts", type=int, default=0, metavar="N",
                    help="--mesh-bulk: instead of the examples, N random star-shaped parts of scripts/make_bulk_parts.py "
                         "(its fixed seed; a third with a round hole), e.g. 300")
    ap.add_argument("--mesh-bulk-ref", type=Path, default=None, metavar="ROOT",
                    help="--mesh-bulk: also time the same command run from another checkout (e.g. a worktree of main), "
                         "alternated with this one in the same run (ratio: vs_ref)")
    ap.add_argument("--mesh-bulk-reps", type=int, default=1, help="--mesh-bulk: timed runs of each command (default 1)")
    ap.add_argument("--mesh-bulk-no-gmsh", action="store_true", help="--mesh-bulk: leave out the gmsh reference")
    ap.add_argument("--mesh-bulk-search", default="best", choices=("best", "fast"),
                    help="--mesh-bulk, --mesh-bulk-profile: the --search (default best)")
    ap.add_argument("--mesh-bulk-ref-search", default=None, choices=("best", "fast"),
                    help="--mesh-bulk-ref: the reference command's --search (default: --mesh-bulk-search)")
    ap.add_argument("--mesh-graded", action="store_true",
                    help="--mesh: only graded against uniform meshing (bench_graded): time per quad of jaxmatch.mesh "
                         "with each examples/graded size field over a uniform size giving about as many quads")
    ap.add_argument("--mesh-graded-finer", type=float, default=1.0,
                    help="--mesh-graded: divide every size of the fields by this (default 1: as in docs/graded.md)")
    ap.add_argument("--mesh-profile", default="", metavar="SHAPE:DIV",
                    help="--mesh: only profile one warm jaxmatch.mesh call (cProfile: top 10 by cumulative and by own time), e.g. T:32")
    ap.add_argument("--mesh-bulk-profile", default="", metavar="N[:DIV]",
                    help="--mesh: only the bulk path's per-part work in one process, as a worker does it: the first N "
                         "random parts of scripts/make_bulk_parts.py at perimeter / DIV (default 32), CPU time per part "
                         "and per strategy, and cProfile's top 15 by cumulative and by own time, e.g. 60:32")
    return ap.parse_args(argv)


def rss_mb() -> float:
    """Peak resident set size of this process so far (MB): ``VmHWM`` of /proc/self/status (reset
    by exec, unlike ``ru_maxrss``, which a child inherits from its parent), else ``ru_maxrss``."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def summary(xs: list[float]) -> dict:
    return {"min": min(xs), "median": statistics.median(xs), "all": xs}


# --------------------------------------------------------------------------- workload


def load_workload(args):
    from jaxmatch.catalogue import store as cat_mod
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.io.readers import load_shape
    from jaxmatch.shape import annotate

    cat = cat_mod.load(args.catalogue) if args.catalogue else cat_mod.default_catalogue()
    internal = cat_mod.parse_range(args.internal)
    buckets = list(cat.buckets(internal))
    table = load_lattice(args.lattice).weights()  # the scoring model (match and skip weights)
    shapes = [annotate(load_shape(ROOT / "examples" / name), POINTS).codes for name in EXAMPLES]
    return cat, internal, buckets, table, shapes


def workload_cells(buckets, shapes) -> tuple[int, int]:
    meshes = sum(len(b.ids) for b in buckets)
    cells = sum(len(b.ids) * 2 * b.n * b.n * len(c) for b in buckets for c in shapes)
    return meshes * len(shapes), cells


def configure(args):
    from jaxmatch.scoring import exact as score

    if args.block_cells:
        score.BLOCK_CELLS = int(args.block_cells)
    if args.dtype != "auto":
        import numpy as np

        forced = score.DPKind(np.int32, float(score.NEG32)) if args.dtype == "int32" else score.DPKind(np.float32, score.NEG)
        score.dp_kind = lambda table, n: forced  # noqa: E731 - benchmark-only override


def make_backend(args):
    """The exact host's backend the benchmark measures (``--backend``); None: the host's default."""
    if args.backend == "xla":
        from jaxmatch.scoring.exact import CPUBackend

        return CPUBackend(args.threads)
    if args.backend == "numba" or args.lanes:
        from jaxmatch.kernels.backends import NumbaBackend

        return NumbaBackend(args.threads, **({"lanes": args.lanes} if args.lanes else {}))
    return None


def jax_pass(buckets, table, shapes, args) -> list:
    from jaxmatch.scoring.exact import DEFAULT_BATCH, score_bucket

    batch = args.batch or DEFAULT_BATCH
    backend = make_backend(args)
    return [[score_bucket(c, b.valences, table, batch=batch, threads=args.threads, backend=backend).utility
             for b in buckets] for c in shapes]


# --------------------------------------------------------------------------- the reference


def make_reference():
    """The recurrence, compiled with numba (nopython, one thread, float32)."""
    import numba
    import numpy as np

    from jaxmatch.kernels.model import NEG, weights_of

    neg = np.float32(NEG)

    @numba.njit(nogil=True, cache=False)
    def score_ref(codes, vals, tf, sk):  # pragma: no cover - compiled
        big_n, n = vals.shape
        m = codes.shape[0]
        out = np.empty(big_n, np.float32)
        seq = np.empty(n, np.int64)
        w = np.empty((3, n), np.float32)
        d = np.empty(n + 1, np.float32)
        for b in range(big_n):
            best = np.float32(-np.inf)
            for o in range(2 * n):
                r = o % n
                for j in range(n):  # oriented sequence: rotation r of vals (o < n) or of vals[::-1]
                    if o < n:
                        seq[j] = vals[b, (r + j) % n]
                    else:
                        seq[j] = vals[b, n - 1 - ((r + j) % n)]
                for j in range(n):  # weights of triple [s[j+1], s[j], s[j-1]] per code
                    t = (seq[(j + 1) % n] - 2) * 16 + (seq[j] - 2) * 4 + (seq[(j - 1 + n) % n] - 2)
                    for c in range(3):
                        w[c, j] = tf[c, t]
                d[0] = 0.0
                for j in range(1, n + 1):
                    d[j] = neg
                for i in range(m):  # D[i][j] = max(D[i-1][j] + skip[c], D[i-1][j-1] + W[i-1, j-1])
                    c = codes[i]
                    s = sk[c]
                    for j in range(n, 0, -1):
                        x = d[j - 1] + w[c, j - 1]
                        y = d[j] + s
                        d[j] = x if x > y else y
                    d[0] += s
                if d[n] > best:
                    best = d[n]
            out[b] = best if best > neg / 2 else -np.inf
            if n > m:
                out[b] = -np.inf
        return out

    @numba.njit(nogil=True, cache=False)
    def score_vec(codes, vals, tf, sk):  # pragma: no cover - compiled
        big_n, n = vals.shape
        m = codes.shape[0]
        out = np.empty(big_n, np.float32)
        wt = np.empty((3, n, 2 * n), np.float32)
        d = np.empty((n + 1, 2 * n), np.float32)
        for b in range(big_n):
            for o in range(2 * n):  # weights of vertex j of orientation o, orientation innermost
                r = o % n
                for j in range(n):
                    k = (r + j) % n
                    if o < n:
                        t = (vals[b, (k + 1) % n] - 2) * 16 + (vals[b, k] - 2) * 4 + (vals[b, (k - 1 + n) % n] - 2)
                    else:  # vals[::-1][k] = vals[n - 1 - k]
                        t = ((vals[b, n - 1 - ((k + 1) % n)] - 2) * 16 + (vals[b, n - 1 - k] - 2) * 4
                             + (vals[b, n - 1 - ((k - 1 + n) % n)] - 2))
                    for c in range(3):
                        wt[c, j, o] = tf[c, t]
            d[0, :] = 0.0
            d[1:, :] = neg
            for i in range(m):
                c = codes[i]
                s = sk[c]
                for j in range(n, 0, -1):
                    for o in range(2 * n):  # contiguous, independent: LLVM vectorises this loop
                        y = d[j, o] + s
                        x = d[j - 1, o] + wt[c, j - 1, o]
                        d[j, o] = x if x > y else y
                for o in range(2 * n):
                    d[0, o] += s
            best = d[n].max()
            out[b] = best if best > neg / 2 and n <= m else -np.inf
        return out

    def run(buckets, weights, shapes, fn=score_ref):
        w = weights_of(weights)
        tf = np.ascontiguousarray(w.table, np.float32)  # (3, 64), NEG where forbidden
        sk = np.ascontiguousarray(w.skip, np.float32)  # (3,), NEG where skipping is forbidden
        vals = [np.ascontiguousarray(b.valences, dtype=np.int64) for b in buckets]
        return [[fn(np.asarray(c, np.int64), v, tf, sk) for v in vals] for c in shapes]

    return {"plain": run, "vectorised": lambda b, t, s: run(b, t, s, fn=score_vec)}


# --------------------------------------------------------------------------- the strongest reference

STRONG_LANES = 128
"""Meshes per chunk of the strongest reference (lanes of one DP row; 64 / 128 / 256 measured)."""


def make_strongest():
    """The strongest reference a reader would write today: numba, int16, vectorised across the
    lanes of a chunk of same-length meshes (lanes innermost and contiguous, ``np.int16`` casts so
    LLVM keeps 16-bit lanes: 32 per AVX-512 op), chunks spread over all cores with ``prange``.
    Every cell of every orientation is computed (no band). Finite skip weights are folded into
    the match weights (its own few lines, not jaxmatch's shifted frame); a must-match (-inf) skip
    weight takes the recurrence's skip branch directly (``D[i][j] = max(D[i-1][j] + skip[c],
    D[i-1][j-1] + W)``, clamped at the sentinel). Written for the benchmark only."""
    import numba
    import numpy as np
    from numba import prange

    neg16 = np.int16(-16384)

    @numba.njit(parallel=True, nogil=True, cache=False, boundscheck=False)
    def strong(codes, vals, tab, skip, has_skip, lanes_per_chunk):  # pragma: no cover - compiled
        big_n, n = vals.shape
        m = codes.shape[0]
        n_chunks = (big_n + lanes_per_chunk - 1) // lanes_per_chunk
        out = np.empty((big_n, 2 * n), np.int16)
        for ch in prange(n_chunks):
            b0 = ch * lanes_per_chunk
            lanes = min(lanes_per_chunk, big_n - b0)
            pv = np.empty((2, 3, n, lanes), np.int16)  # per-vertex weights of vals and of vals[::-1]
            d = np.empty((n + 1, lanes), np.int16)
            for bl in range(lanes):
                b = b0 + bl
                for k in range(n):
                    t = (vals[b, (k + 1) % n] - 2) * 16 + (vals[b, k] - 2) * 4 + (vals[b, (k - 1 + n) % n] - 2)
                    tr = (vals[b, (k - 1 + n) % n] - 2) * 16 + (vals[b, k] - 2) * 4 + (vals[b, (k + 1) % n] - 2)
                    for c in range(3):
                        pv[0, c, k, bl] = tab[c, t]
                        pv[1, c, n - 1 - k, bl] = tab[c, tr]
            for o in range(2 * n):
                h = 0 if o < n else 1
                r = o % n
                d[0, :] = 0
                d[1:, :] = neg16
                for i in range(m):
                    c = codes[i]
                    if has_skip:
                        sk = skip[c]
                        for j in range(n, 0, -1):
                            dj = d[j]
                            dm = d[j - 1]
                            w = pv[h, c, (r + j - 1) % n]
                            for l in range(lanes):
                                x = np.int16(dm[l] + w[l])
                                y = np.int16(dj[l] + sk)
                                y = y if y > neg16 else neg16
                                dj[l] = x if x > y else y
                        d0 = d[0]
                        for l in range(lanes):
                            y = np.int16(d0[l] + sk)
                            d0[l] = y if y > neg16 else neg16
                    else:
                        for j in range(n, 0, -1):
                            dj = d[j]
                            dm = d[j - 1]
                            w = pv[h, c, (r + j - 1) % n]
                            for l in range(lanes):
                                x = np.int16(dm[l] + w[l])
                                dj[l] = x if x > dj[l] else dj[l]
                for bl in range(lanes):
                    out[b0 + bl, o] = d[n, bl]
        return out

    def run(buckets, model, shapes):
        """``model``: a scoring model (``.table (3, 64)``, ``.skip (3,)``, NEG = forbidden) or a
        ``(3, 4, 4, 4)`` table (-inf = forbidden, skip weights 0)."""
        if hasattr(model, "skip"):
            t, sk = np.asarray(model.table, np.float64).reshape(3, 64), np.asarray(model.skip, np.float64).reshape(3)
        else:
            t, sk = np.asarray(model, np.float64).reshape(3, 64), np.zeros(3)
        ok_t, ok_s = np.isfinite(t) & (t > -1e8), np.isfinite(sk) & (sk > -1e8)
        if not (np.all(t[ok_t] == np.round(t[ok_t])) and np.all(sk[ok_s] == np.round(sk[ok_s]))):
            raise ValueError("the int16 reference needs integer weights")
        # a finite skip weight is folded into the match weights of its type (every point is either
        # matched or skipped: utility = sum of (w - skip) over matched points + sum of all skips);
        # only a -inf one (the point must be matched) stays in the recurrence
        fold = np.where(ok_s, sk, 0.0)
        tab = np.where(ok_t, t - fold[:, None], neg16).astype(np.int16)
        skip16 = np.where(ok_s, 0, neg16).astype(np.int16)
        has_skip = bool(np.any(skip16 != 0))
        vals = [np.ascontiguousarray(b.valences, dtype=np.int32) for b in buckets]
        res = []
        for c in shapes:
            cc = np.asarray(c, np.int64)
            offset = float(fold[cc].sum())
            row = []
            for v in vals:
                raw = strong(cc, v, tab, skip16, has_skip, STRONG_LANES).max(axis=1)
                u = (raw.astype(np.float64) + offset).astype(np.float32)
                u[raw <= neg16 // 2] = -np.inf
                if v.shape[1] > len(cc):
                    u[:] = -np.inf
                row.append(u)
            res.append(row)
        return res

    return run


def machine_peak() -> dict:
    """``lanes x cores x clock``: int16 lanes per vector op from the CPU flags (AVX-512 BW: 32,
    AVX2: 16, else SSE2: 8), the cores this process may use, the clock from /proc/cpuinfo
    (the largest ``cpu MHz``; ``lscpu``'s max MHz if it is larger)."""
    flags, mhz = set(), 0.0
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key, _, val = line.partition(":")
                if key.strip() == "flags":
                    flags |= set(val.split())
                elif key.strip() == "cpu MHz":
                    mhz = max(mhz, float(val))
    except OSError:
        pass
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        for line in out.splitlines():
            if line.startswith("CPU max MHz:"):
                mhz = max(mhz, float(line.split(":")[1]))
    except (OSError, ValueError, subprocess.SubprocessError):
        pass
    lanes = 32 if "avx512bw" in flags else 16 if "avx2" in flags else 8
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        cores = os.cpu_count() or 1
    return {"int16_lanes": lanes, "isa": "avx512bw" if lanes == 32 else "avx2" if lanes == 16 else "sse2",
            "cores": cores, "clock_mhz": mhz, "peak_cells_per_s": lanes * cores * mhz * 1e6,
            "definition": "one DP cell per int16 lane per core per clock cycle"}


# --------------------------------------------------------------------------- bulk measurements


def sharing(buckets) -> dict:
    """Meshes and distinct boundary sequences (up to rotation and reflection) per k."""
    import numpy as np

    from jaxmatch.scoring import bulk

    per_k: dict = {}
    all_meshes = all_seqs = 0
    for b in buckets:
        g = bulk.group_sequences(b.valences)
        all_meshes += len(b.ids)
        all_seqs += len(g.seqs)
        for k in np.unique(b.k):
            sel = b.k == k
            d = per_k.setdefault(int(k), [0, 0])
            d[0] += int(sel.sum())
            d[1] += len(np.unique(g.index[sel]))
    out = {str(k): {"meshes": v[0], "distinct_sequences": v[1], "meshes_per_sequence": round(v[0] / v[1], 4)}
           for k, v in sorted(per_k.items())}
    out["all"] = {"meshes": all_meshes, "distinct_sequences": all_seqs, "meshes_per_sequence": round(all_meshes / all_seqs, 4)}
    return out


def bulk_measurements(buckets, table, shapes, args, cells, pairs) -> dict:
    from jaxmatch.scoring import bulk
    from jaxmatch.scoring.exact import reduce_orientations

    t = time.perf_counter()
    parts = bulk.prepare(buckets)
    prepare_s = time.perf_counter() - t

    def distinct_pass():
        return [[reduce_orientations(bulk.fan_out(bulk._values(c, p.groups.seqs, table, threads=args.threads), p.groups)).utility
                 for p in parts] for c in shapes]

    distinct_pass()  # compile (chunk sizes differ from the per-bucket ones)
    times = []
    for _ in range(args.reps):
        t = time.perf_counter()
        distinct_pass()
        times.append(time.perf_counter() - t)
    # top-5, all sizes competing, exhaustive (every distinct sequence) against pruned
    res = {}
    for prune in (False, True):
        for c in shapes:  # compile
            bulk.top_k(c, parts, table, top=5, prune=prune, threads=args.threads)
        ts, scored = [], 0
        for _ in range(args.reps):
            t = time.perf_counter()
            outs = [bulk.top_k(c, parts, table, top=5, prune=prune, threads=args.threads) for c in shapes]
            ts.append(time.perf_counter() - t)
        scored = sum(o.sequences_scored for o in outs)
        res["pruned" if prune else "exhaustive"] = {"run_s": summary(ts), "sequences_scored": scored,
                                                    "rows": [[r[:6] for r in o.rows] for o in outs]}
    same_rows = res["pruned"].pop("rows") == res["exhaustive"].pop("rows")
    best = min(times)
    return {
        "prepare_s": prepare_s,
        "distinct": {"run_s": summary(times), "cells_per_s": cells / best, "meshes_per_s": pairs / best},
        "top5": {**res, "identical": same_rows,
                 "sequences_total": sum(len(p.groups.seqs) for p in parts) * len(shapes),
                 "speedup_min": min(res["exhaustive"]["run_s"]["all"]) / min(res["pruned"]["run_s"]["all"])},
    }


# --------------------------------------------------------------------------- RSS and CLI


def rss_probe(args) -> dict:
    """Run the jaxmatch pass once in this (fresh) process and report its memory."""
    import jax  # noqa: F401

    base = rss_mb()
    configure(args)
    cat, internal, buckets, table, shapes = load_workload(args)
    jax_pass(buckets, table, shapes[:2], args)
    return {"internal": internal, "meshes": sum(len(b.ids) for b in buckets), "rss_after_import_mb": base, "peak_rss_mb": rss_mb()}


def rss_by_catalogue(args) -> dict:
    out = {}
    for internal in ("0..4", "0..5"):
        cmd = [sys.executable, str(Path(__file__).resolve()), "--rss-probe", "--internal", internal]
        if args.batch:
            cmd += ["--batch", str(args.batch)]
        if args.catalogue:
            cmd += ["--catalogue", str(args.catalogue)]
        p = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=900)
        out[f"k<={internal[-1]}"] = json.loads(p.stdout.strip().splitlines()[-1]) if p.returncode == 0 else {"error": p.stderr[-500:]}
    return out


CLI_PRUNED = """
from jaxmatch.cli import enable_compile_cache
from jaxmatch.scoring import bulk
from jaxmatch.catalogue import store as catalogue
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.scoring.exact import align
from jaxmatch.io.readers import load_shape
from jaxmatch.shape import annotate, default_points
enable_compile_cache()
shape, table, cat = load_shape("examples/lshape.json"), load_lattice("fine").weights(), catalogue.default_catalogue()
ann = annotate(shape, default_points(shape, max(cat.lengths)))
for r in bulk.top_k(ann.codes, cat.buckets(), table, top=5, prune=PRUNE).rows[:5]:
    align(ann.codes, r[6], table, r[4], r[5])
"""
"""What ``jaxmatch score examples/lshape.json --tie-break id`` does, scoring through ``bulk.top_k``."""


def _secs(x) -> str:
    """``"1.23 s"``, or ``"failed"`` for a command that did not exit 0 (None)."""
    return "failed" if x is None else f"{x:.2f} s"


def cli_times() -> dict:
    exe = Path(sys.executable).parent / "jaxmatch"
    cache = Path(tempfile.mkdtemp(prefix="jaxmatch-bench-cache-"))
    out = {}
    commands = {
        "default": [str(exe), "score", "examples/lshape.json"],
        "tie_break_id": [str(exe), "score", "examples/lshape.json", "--tie-break", "id"],
        "bulk_top_k_pruned": [sys.executable, "-c", CLI_PRUNED.replace("PRUNE", "True")],
        "bulk_top_k_exhaustive": [sys.executable, "-c", CLI_PRUNED.replace("PRUNE", "False")],
    }
    try:
        for label, cmd in commands.items():
            shutil.rmtree(cache, ignore_errors=True)
            env = dict(os.environ, JAXMATCH_CACHE=str(cache))
            runs = []
            for _ in range(2):  # cold (empty cache), then warm
                t = time.perf_counter()
                p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
                runs.append(time.perf_counter() - t if p.returncode == 0 else None)
            out[label] = {"cold_s": runs[0], "warm_s": runs[1]}
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    return out


# --------------------------------------------------------------------------- many shapes, the API


MANY = 50
"""Shapes of the bulk measurement: the examples and the labelled shapes, then rotated copies."""


def many_shapes(folder: Path) -> list[Path]:
    """:data:`MANY` shape files: ``examples/*`` (the :data:`EXAMPLES`), ``examples/labels/shapes/*``,
    then copies of the first ones rotated by 37 degrees and scaled by 1.7, written to ``folder``
    (so every file is a different shape; fixed, so runs compare)."""
    import numpy as np

    from jaxmatch.io.readers import load_shape

    files = [ROOT / "examples" / n for n in EXAMPLES] + sorted((ROOT / "examples" / "labels" / "shapes").glob("*.json"))
    a = np.deg2rad(37.0)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) * 1.7
    k = 0
    while len(files) < MANY:
        shp = load_shape(files[k])
        pts = (np.asarray(shp.points) * shp.scale + shp.offset) @ rot.T
        out = folder / f"rotated-{k:02d}-{files[k].stem}.json"
        out.write_text(json.dumps({"boundary": pts.tolist(), "corners": [int(c) for c in shp.corners]}))
        files.append(out)
        k += 1
    return files[:MANY]


def many_and_api(args) -> dict:
    """``score-many``'s loop in this process (one prepared catalogue, k <= 5, top-5, pruned,
    geometric and id tie-break) over :data:`MANY` shapes, warm (a first pass compiles and fills
    the caches): shapes/s; and one shape ranked and its top mesh placed through the Python API
    (``jaxmatch.api.rank`` + ``place_top``), warm: milliseconds per shape (min and median)."""
    from jaxmatch.api import rank
    from jaxmatch.catalogue import store as cat_mod
    from jaxmatch.placement.choose import place_top
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.scoring.rank import ranking_json
    from jaxmatch.io.readers import load_shape

    folder = Path(tempfile.mkdtemp(prefix="jaxmatch-bench-shapes-"))
    try:
        files = many_shapes(folder)
        shapes = [load_shape(f) for f in files]
        cat = cat_mod.load(args.catalogue) if args.catalogue else cat_mod.default_catalogue()
        lat = load_lattice(args.lattice)
        out: dict = {"shapes": len(shapes), "internal": "0..5 (all sizes compete)", "top": 5}
        for tb in ("geometry", "id"):
            times = []
            for rep in range(2):  # the first pass compiles and loads; the second is measured
                t = time.perf_counter()
                for p, shp in zip(files, shapes):
                    ranking_json(str(p), rank(shp, cat, lat, top=5, tie_break=tb, prune=True), lat.name, tb)
                times.append(time.perf_counter() - t)
            out[tb] = {"first_pass_s": times[0], "warm_pass_s": times[1], "shapes_per_s": len(shapes) / times[1]}
        # what score-many does by default: the shapes shared among worker processes (one per CPU);
        # in a fresh process, as this one has imported JAX (not fork-safe)
        cmd = [sys.executable, str(Path(__file__).resolve()), "--many-probe", "--lattice", args.lattice]
        if args.catalogue:
            cmd += ["--catalogue", str(args.catalogue)]
        p = subprocess.run(cmd, cwd=ROOT, env=dict(os.environ), capture_output=True, text=True, timeout=1800)
        if p.returncode == 0 and p.stdout.strip():
            out["geometry_workers"] = json.loads(p.stdout.strip().splitlines()[-1])
        api = []
        for i in range(7):
            t = time.perf_counter()
            r = rank(shapes[4], cat, lat, top=5, tie_break="geometry", prune=True)  # lshape.json
            place_top(shapes[4], r, cat)[0]
            api.append((time.perf_counter() - t) * 1e3)
        out["api_shape_ms"] = {"shape": files[4].name, "first_ms": api[0], "min_ms": min(api[1:]),
                               "median_ms": statistics.median(api[1:])}
        return out
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def many_probe(args) -> dict | None:
    """(In a fresh process.) The geometric-tie-break loop of :func:`many_and_api` run as
    ``score-many`` runs it by default: one warm pass in this process, then the shapes shared
    among one forked worker process per CPU (``jaxmatch.parallel.ordered_map``; their start-up
    is included), the records checked identical to this process's. None with one CPU or no fork."""
    from jaxmatch.api import rank
    from jaxmatch.catalogue import store as cat_mod
    from jaxmatch.parallel import available_cpus, can_fork, ordered_map
    from jaxmatch.kernels.backends import serial_only
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.scoring.rank import ranking_json
    from jaxmatch.io.readers import load_shape

    jobs = available_cpus()
    if jobs < 2 or not can_fork():
        return None
    serial_only()
    folder = Path(tempfile.mkdtemp(prefix="jaxmatch-bench-probe-"))
    try:
        files = many_shapes(folder)
        shapes = [load_shape(f) for f in files]
        cat = cat_mod.load(args.catalogue) if args.catalogue else cat_mod.default_catalogue()
        lat = load_lattice(args.lattice)

        def one(i):
            return ranking_json(str(files[i]), rank(shapes[i], cat, lat, top=5, tie_break="geometry", prune=True),
                                lat.name, "geometry")

        serial = [one(i) for i in range(len(shapes))]  # warm pass (one process)
        t = time.perf_counter()
        recs = list(ordered_map(one, list(range(len(shapes))), jobs, initializer=cat.reopen))
        dt = time.perf_counter() - t
        return {"jobs": jobs, "warm_pass_s": dt, "shapes_per_s": len(shapes) / dt, "identical_to_one_process": recs == serial}
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def score_many_cli(args) -> dict:
    """Wall time of ``jaxmatch score-many`` on the :data:`MANY` shapes (top 5, geometric
    tie-break), start-up included, with a warm compile cache (a first run fills it)."""
    exe = Path(sys.executable).parent / "jaxmatch"
    folder = Path(tempfile.mkdtemp(prefix="jaxmatch-bench-many-"))
    try:
        files = many_shapes(folder)
        env = dict(os.environ, JAXMATCH_CACHE=str(folder / "cache"))
        runs = []
        for _ in range(2):
            cmd = [str(exe), "score-many", *map(str, files), "--out", str(folder / "out.jsonl"), "--top", "5",
                   "--tie-break", "geometry"]
            t = time.perf_counter()
            p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=1800)
            runs.append(time.perf_counter() - t if p.returncode == 0 else None)
        return {"shapes": len(files), "cold_s": runs[0], "warm_s": runs[1],
                "shapes_per_s": len(files) / runs[1] if runs[1] else None}
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# --------------------------------------------------------------------------- k <= 6


K6_PROBE = """
import json, sys, time
from jaxmatch.catalogue import store
from jaxmatch.scoring import bulk
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.api import rank
from jaxmatch.io.readers import load_shape
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
cat = store.load(sys.argv[1])
lat = load_lattice("fine")
shape = load_shape("examples/lshape.json")
t = time.perf_counter()
bulk.prepared(cat, None)
prep = time.perf_counter() - t
runs = []
for _ in range(4):
    t = time.perf_counter()
    r = rank(shape, cat, lat, top=5, tie_break="id", prune=True)
    runs.append(time.perf_counter() - t)
print(json.dumps({"meshes": r.scored, "pruned": r.pruned, "prepare_s": prep, "first_s": runs[0], "warm_s": min(runs[1:]),
                  "top": [m.mesh_id for m in r.results], "peak_rss_mb": hwm()}))
"""
"""Pruned top-5 (id tie-break) of examples/lshape.json against the k <= 6 catalogue, in a fresh
process (its peak RSS is the job's): grouping once, then the first and the best warm ranking."""


def k6_measure(args) -> dict:
    """``--k6``: build ``catalogue-k0-6.npz`` into ``--k6-cache`` once (``jaxmatch catalogue build
    --internal 0..6 --workers <CPUs>``, ~10 min on 2 idle cores, 2.8 GB peak), then :data:`K6_PROBE`."""
    folder = Path(args.k6_cache)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "catalogue-k0-6.npz"
    out: dict = {"catalogue": str(path)}
    if not path.exists():
        exe = Path(sys.executable).parent / "jaxmatch"
        t = time.perf_counter()
        p = subprocess.run([str(exe), "catalogue", "build", "--internal", "0..6", "--out", str(path),
                            "--workers", str(len(os.sched_getaffinity(0)))], cwd=ROOT, capture_output=True, text=True)
        out["build_s"] = time.perf_counter() - t
        if p.returncode != 0:
            return {**out, "error": p.stderr[-500:]}
    p = subprocess.run([sys.executable, "-c", K6_PROBE, str(path)], cwd=ROOT, capture_output=True, text=True, timeout=1800,
                       env=dict(os.environ, JAXMATCH_CACHE=str(folder / "cache")))
    if p.returncode != 0:
        return {**out, "error": p.stderr[-500:]}
    return {**out, **json.loads(p.stdout.strip().splitlines()[-1])}


# --------------------------------------------------------------------------- main


REFINE_SIDES = [100, 100, 100, 100]
"""Refinement benchmark request: examples/square.json with 100 edges per side (10,000 quads)."""

REFINE_TARGET_S = 1.0
"""Goal of the refinement benchmark: a 10,000-quad mesh in under this many seconds, warm."""


def bench_refine(reps: int = 5) -> dict:
    """Time to produce a 10,000-quad refined mesh: ``examples/square.json`` with
    :data:`REFINE_SIDES`, lattice fine, default catalogue.

    ``full``: :func:`jaxmatch.placement.refine.refine_mesh` from the shape (ranking, fitting
    templates, integer program, refinement, placement), warm (after a first, compiling call);
    ``refine``: integer program + :func:`refine_and_place` for the chosen template (placement
    included: boundary, interpolation, harmonic solve, quality; smoothing only when the
    interpolated mesh needs it, the default above 2000 quads); ``refine_smoothed``: the same with
    smoothing forced (``SMOOTH_ITERS_LARGE`` iterations per round; one repetition). ``ratio_to_target``:
    :data:`REFINE_TARGET_S` / min time (above 1 meets the goal)."""
    from jaxmatch.catalogue.store import default_catalogue
    from jaxmatch.cli import enable_compile_cache
    from jaxmatch.placement import refine as R
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.io.readers import load_shape

    enable_compile_cache()
    cat, lat = default_catalogue(), load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "square.json")
    t = time.perf_counter()
    choice = R.refine_mesh(shp, cat, lat, sides=REFINE_SIDES)
    first = time.perf_counter() - t
    tpl = choice.template

    def timed(fn, n=reps):
        ts = []
        for _ in range(max(int(n), 1)):
            t = time.perf_counter()
            out = fn()
            ts.append(time.perf_counter() - t)
        return ts, out

    full, _ = timed(lambda: R.refine_mesh(shp, cat, lat, sides=REFINE_SIDES))
    ref, rm = timed(lambda: R.refine_and_place(tpl, R.solve_multiplicities(tpl, counts=REFINE_SIDES)))
    smo, rms = timed(lambda: R.refine_and_place(tpl, R.solve_multiplicities(tpl, counts=REFINE_SIDES),
                                                smooth_iters=R.SMOOTH_ITERS_LARGE), n=1)  # tens of seconds: once
    return {
        "request": {"shape": "examples/square.json", "sides": REFINE_SIDES}, "template": tpl.mesh_id,
        "quads": rm.n_quads, "min_scaled_jacobian": rm.min_scaled_jacobian, "inverted": rm.inverted,
        "first_call_s": first, "full_s": summary(full), "refine_s": summary(ref),
        "refine_smoothed_s": summary(smo), "smoothed_min_scaled_jacobian": rms.min_scaled_jacobian,
        "target_s": REFINE_TARGET_S, "ratio_to_target": REFINE_TARGET_S / min(ref),
        "ratio_to_target_full": REFINE_TARGET_S / min(full), "load": list(os.getloadavg()),
    }


MESH_DIVISIONS = (16, 32)
"""Meshing benchmark sizes: h = perimeter / each of these."""

MESH_HOLES = "examples/holes"
"""The regions with holes of the meshing benchmark (every ``*.json`` there), named ``holes/<stem>``
beside the shapes of ``mesh_table.SHAPES``."""

MESH_COMPARABLE = (0.5, 2.0)
"""A case is "comparable" when gmsh's mean edge / h lies in this range: gmsh's quasi-structured
mesher puts at least two edges on every polygon segment, so on a finely sampled curve (a round
hole given as a polygon) it cannot reach h and meshes far finer, and slower. The range
is the one the benchmark's test calls "calibrated towards h"."""

MESH_GMSH = "gmsh-qs"
"""The gmsh mesher the meshing benchmark times (``compare_gmsh.GMSH_METHODS``): quasi-structured
quads, ``Mesh.Algorithm = 11``."""


def _script(name: str):
    """A module of scripts/ (mesh_table, compare_gmsh), imported from beside this file."""
    import importlib

    here = str(Path(__file__).resolve().parent)
    if here not in sys.path:
        sys.path.insert(0, here)
    return importlib.import_module(name)


def _best_of(fn, reps: int):
    """One untimed (warming) call of ``fn``, then ``reps`` timed: ``(seconds list, last result)``."""
    out = fn()
    ts = []
    for _ in range(max(int(reps), 1)):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return ts, out


def _rss_now_mb() -> float:
    """Current resident set size of this process (MB; /proc/self/statm), NaN where unknown."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return float("nan")


def mesh_regions(holes: bool = True) -> list[str]:
    """The meshing benchmark's regions: every shape of ``mesh_table.SHAPES``, then (``holes``)
    every region of :data:`MESH_HOLES` as ``holes/<stem>``."""
    names = list(_script("mesh_table").SHAPES)
    if holes:
        names += [f"holes/{p.stem}" for p in sorted((Path(__file__).resolve().parent.parent / MESH_HOLES).glob("*.json"))]
    return names


def _mesh_region(name: str, div: int) -> tuple:
    """``(shape, outline (P, 2), holes [(H_k, 2)], corners (C, 2) of every ring, h)`` of benchmark
    region ``name`` (:func:`mesh_regions`) at h = outer perimeter / ``div``."""
    import numpy as np

    import jaxmatch
    from jaxmatch.geometry import cumulative_length

    if name.startswith("holes/"):
        shp = jaxmatch.load_shape(Path(__file__).resolve().parent.parent / MESH_HOLES / f"{name[6:]}.json")
        outline, corners = _script("mesh_table")._outline(shp)
        holes = [np.asarray(r, np.float64) for r in shp.holes]
        corners = np.concatenate([corners] + [r[c] for r, c in zip(holes, shp.hole_corners)])
        return shp, outline, holes, corners, float(cumulative_length(outline)[-1]) / div
    cg = _script("compare_gmsh")
    shp, outline, corners, _, h = cg.shape_case(cg.mesh_table.SHAPES[name], div)
    return shp, outline, [], corners, h


def mesh_case(name: str, div: int, reps: int = 3, catalogue=None) -> dict:
    """One case of the meshing benchmark: region ``name`` of :func:`mesh_regions` at
    h = (outer) perimeter / ``div``.

    ``jaxmatch``: ``jaxmatch.mesh(shape, size=h)`` (the shape loaded once, outside the timing;
    the call loads the default catalogue itself, as a user's call does); with ``catalogue``
    (loaded once by the caller) also ``seconds_catalogue``: the same call given it
    (``catalogue=``), which keeps the catalogue's verified arrays and groupings between calls.
    ``gmsh``: ``compare_gmsh.gmsh_quads`` with :data:`MESH_GMSH`'s options (gmsh initialised,
    the polygon as a plane surface, meshed, read back, finalised) at the characteristic length
    ``compare_gmsh.gmsh_calibrated`` found (untimed) to bring gmsh's mean edge length nearest h.
    Each warm (one untimed call), then best of ``reps``. Both meshes measured by
    ``mesh_table.measure`` (quads, min / mean scaled Jacobian, irregular internal vertices, mean
    edge / h, valid). ``ratio``: jaxmatch's best time / gmsh's. ``rss_growth_mb``: growth of
    the resident set over each mesher's calls (calibration included for gmsh)."""
    import jaxmatch

    cg = _script("compare_gmsh")
    mt = cg.mesh_table
    shp, outline, holes, corners, h = _mesh_region(name, div)
    opts = cg.GMSH_METHODS[MESH_GMSH]
    r0 = _rss_now_mb()
    jt, jm = _best_of(lambda: jaxmatch.mesh(shp, size=h), reps)

    def first_call():
        clear_mesh_caches()
        return jaxmatch.mesh(shp, size=h)

    jf = _best_of(first_call, reps)[0]
    jc = _best_of(lambda: jaxmatch.mesh(shp, size=h, catalogue=catalogue), reps)[0] if catalogue is not None else None
    r1 = _rss_now_mb()
    cal = cg.gmsh_calibrated(outline, h, holes=holes, **opts)
    gt, (gxy, gq, tris) = _best_of(lambda: cg.gmsh_quads(outline, cal["lc"], holes=holes, **opts), reps)
    r2 = _rss_now_mb()
    j = {"seconds": min(jt), "seconds_all": jt, "seconds_first": min(jf), "chosen": jm.chosen, "rss_growth_mb": r1 - r0,
         **mt.measure(jm.xy, jm.quads, corners, outline, h, holes)}
    if jc is not None:
        j["seconds_catalogue"] = min(jc)
    g = {"seconds": min(gt), "seconds_all": gt, "method": MESH_GMSH, "lc_over_h": cal["lc"] / h,
         "calibration": cal["tries"], "triangles": tris, "rss_growth_mb": r2 - r1,
         **mt.measure(gxy, gq, corners, outline, h, holes)}
    lo, hi = MESH_COMPARABLE
    return {"shape": name, "div": div, "h": h, "holes": len(holes), "jaxmatch": j, "gmsh": g,
            "ratio": j["seconds"] / g["seconds"], "ratio_first": j["seconds_first"] / g["seconds"],
            "comparable": bool(lo <= g["mean_edge_over_h"] <= hi)}


def clear_mesh_caches() -> None:
    """Forget what the meshing path keeps between calls (templates per patch, rankings, integer
    programs, refined patches: the catalogue's cache, :mod:`jaxmatch.cache`), so that the next
    ``jaxmatch.mesh`` call is a first call on its shape (the compiled code and the opened
    catalogue stay). A checkout from before the one cache layer is cleared its own way, so two
    trees can be timed alike."""
    import jaxmatch

    cat = jaxmatch.load_catalogue()
    if hasattr(cat, "cache"):
        cat.cache.forget_shapes()
        return
    from jaxmatch.placement import layout, refine  # an older checkout's caches

    refine.clear_template_cache(cat)
    layout.clear_caches()


def mesh_quality(cases: list[dict], who: str) -> dict:
    """Summary of ``who``'s ("jaxmatch" or "gmsh") meshes over the cases."""
    ms = [c[who] for c in cases]
    return {"mean_min_sj": statistics.fmean(m["min_sj"] for m in ms), "worst_min_sj": min(m["min_sj"] for m in ms),
            "mean_mean_sj": statistics.fmean(m["mean_sj"] for m in ms),
            "irregular_per_mesh": statistics.fmean(m["irregular"] for m in ms),
            "mean_edge_over_h": statistics.fmean(m["mean_edge_over_h"] for m in ms),
            "valid": sum(bool(m["valid"]) for m in ms), "meshes": len(ms),
            "total_s": sum(m["seconds"] for m in ms), "rss_growth_mb": sum(m["rss_growth_mb"] for m in ms)}


def bench_mesh(shapes=None, divisions=MESH_DIVISIONS, reps: int = 3, say=None, with_catalogue: bool = True,
               holes: bool = True) -> dict:
    """Meshing benchmark, in this one process: :func:`mesh_case` for every region of
    :func:`mesh_regions` (the shapes of ``scripts/mesh_table.py``'s ``SHAPES`` and, with
    ``holes``, the regions with holes; or ``shapes``) and every division.

    Returns ``{"cases": [...], "mesh_vs_gmsh": median over cases of the time ratio
    jaxmatch / gmsh with jaxmatch meshing each shape for the first time in the process (its
    caches cleared: what a user meshing a new part waits for), "mesh_vs_gmsh_shapes" /
    "mesh_vs_gmsh_holes": the same over the regions without / with holes, "mesh_vs_gmsh_comparable":
    over the cases where gmsh's mean edge came out near h (:data:`MESH_COMPARABLE`),
    "mesh_vs_gmsh_repeat": the same
    for a repeat call on the same shape and size (answered mostly from the caches), "quality": {"jaxmatch": ..., "gmsh": ...} (:func:`mesh_quality`: mean and
    worst min scaled Jacobian, irregular internal vertices per mesh, ...), "peak_rss_mb":
    ``ru_maxrss`` of this process, "load", "versions", "reps", "divisions"}``; with
    ``with_catalogue`` also ``"mesh_vs_gmsh_catalogue"``: the same median with jaxmatch given the
    catalogue loaded once (``seconds_catalogue`` of :func:`mesh_case`). gmsh's quasi-structured
    mesher leaks a few MB per run (also with one gmsh session), so the peak RSS grows with the
    number of gmsh runs; each mesher's ``rss_growth_mb`` says whose memory it is."""
    import jaxmatch

    mt = _script("mesh_table")
    cat = jaxmatch.load_catalogue() if with_catalogue else None
    names = list(shapes) if shapes else mesh_regions(holes)
    load0 = os.getloadavg()
    cases = []
    for name in names:
        for div in divisions:
            c = mesh_case(name, int(div), reps, cat)
            cases.append(c)
            if say is not None:
                j, g = c["jaxmatch"], c["gmsh"]
                cat_s = f" (catalogue passed {j['seconds_catalogue']:.4f} s)" if "seconds_catalogue" in j else ""
                say(f"{name:>21} P/{div:<3d} jaxmatch {j['seconds']:7.4f} s{cat_s} first call {j['seconds_first']:.4f} s edge/h {j['mean_edge_over_h']:.2f} "
                    f"SJ {j['min_sj']:.3f}/{j['mean_sj']:.3f} irr {j['irregular']:2d} ({j['chosen']}) | "
                    f"gmsh {g['seconds']:7.4f} s edge/h {g['mean_edge_over_h']:.2f} SJ {g['min_sj']:.3f}/"
                    f"{g['mean_sj']:.3f} irr {g['irregular']:2d} | ratio {c['ratio']:.1f}")
    import gmsh

    extra = {}
    if with_catalogue:
        extra["mesh_vs_gmsh_catalogue"] = statistics.median(c["jaxmatch"]["seconds_catalogue"] / c["gmsh"]["seconds"]
                                                            for c in cases)
    for key, pick in (("shapes", lambda c: not c["holes"]), ("holes", lambda c: c["holes"]),
                      ("comparable", lambda c: c["comparable"])):
        some = [c["ratio_first"] for c in cases if pick(c)]
        extra[f"mesh_vs_gmsh_{key}"] = statistics.median(some) if some else None
        extra[f"cases_{key}"] = len(some)
    return {"cases": cases, "mesh_vs_gmsh": statistics.median(c["ratio_first"] for c in cases), **extra,
            "mesh_vs_gmsh_repeat": statistics.median(c["ratio"] for c in cases),
            "quality": {"jaxmatch": mesh_quality(cases, "jaxmatch"), "gmsh": mesh_quality(cases, "gmsh")},
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            "load": {"before": list(load0), "after": list(os.getloadavg())}, "reps": reps,
            "divisions": [int(d) for d in divisions], "gmsh_method": MESH_GMSH,
            "versions": {"jaxmatch": jaxmatch.__version__, "gmsh": gmsh.__version__,
                         "python": platform.python_version()}, "cpus": len(os.sched_getaffinity(0))}


def mesh_large(path: str, size) -> dict:
    """One large ``jaxmatch.mesh(load_shape(path), size=size)``, after one call at 20 x the size
    (the code paths warm): seconds, quads, peak RSS of this process (``ru_maxrss``) and before."""
    import jaxmatch

    h = float(size)
    shp = jaxmatch.load_shape(path)
    jaxmatch.mesh(shp, size=20 * h)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    t = time.perf_counter()
    m = jaxmatch.mesh(shp, size=h)
    dt = time.perf_counter() - t
    return {"file": path, "size": h, "quads": int(len(m.quads)), "chosen": m.chosen, "seconds": dt,
            "min_sj": float(m.min_scaled_jacobian), "valid": bool(m.valid), "rss_before_mb": before,
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, "load": list(os.getloadavg())}


MESH_BULK_REGIONS = ("examples/*.json", "examples/labels/shapes/*.json")
"""The regions of the bulk benchmark (globs from the repository root): every example shape."""


def _bulk_command(root: Path, paths: list[str], divisions: int, jobs: int, out: Path,
                  search: str = "best") -> tuple[float, float, list[dict]]:
    """One whole ``jaxmatch mesh PATHS --divisions DIV --out-dir OUT --jobs N --skip-bad`` run from
    the checkout ``root`` (its ``jaxmatch`` package, by ``python -m`` from there), with
    ``--search SEARCH`` unless the best: wall seconds, CPU seconds (user + system of the command
    and its workers: what other users of the machine change least) and the summary's records."""
    cmd = [sys.executable, "-m", "jaxmatch", "mesh", *paths, "--divisions", str(int(divisions)), "--out-dir", str(out),
           "--jobs", str(int(jobs)), "--skip-bad"] + (["--search", search] if search != "best" else [])
    if "--msh-version" in (root / "jaxmatch" / "cli.py").read_text():  # (the format references before MSH 4.1 wrote: the same writing cost)
        cmd += ["--msh-version", "2.2"]
    env = {**os.environ, "JAXMATCH_PROGRESS": "0"}
    env.pop("PYTHONPATH", None)
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=root, env=env)
    wall = time.perf_counter() - t
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode not in (0, 3):
        raise RuntimeError(f"jaxmatch mesh failed ({run.returncode}) in {root}: {run.stderr.strip()[-500:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return wall, cpu, [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]


def mesh_bulk(divisions: int = 16, jobs: int = 2, parts: int = 0, ref: Path | None = None, reps: int = 1,
              gmsh: bool = True, search: str = "best", ref_search: str | None = None) -> dict:
    """Bulk meshing as a user runs it: one ``jaxmatch mesh REGIONS --divisions DIV --out-dir DIR
    --jobs N --skip-bad`` process over every region of :data:`MESH_BULK_REGIONS` (``parts``: over
    that many random parts of ``scripts/make_bulk_parts.py`` instead), timed as a whole
    (start-up, reading, meshing, writing): ``shapes_per_s`` (the best of ``reps`` runs; ``runs_s``
    every wall time; ``cpu_s``, ``shapes_per_cpu_s``: the CPU seconds of the command and its
    workers, which other users of the machine change least). ``ref``: the same command run from
    another checkout, alternated with this one: ``ref.shapes_per_s`` and ``vs_ref`` (this rate
    over the reference's; ``vs_ref_cpu`` the same by CPU time). ``search``: the command's
    ``--search`` (``ref_search`` the reference's, default the same; e.g. this checkout's best
    search as the reference of its fast one). Reference, same
    run: gmsh's quasi-structured quads (:data:`MESH_GMSH`) of each region's outline at the same
    h, one after another in this process (initialised, meshed, read back each; the
    characteristic length calibrated untimed, as in :func:`mesh_case`), regions with holes left
    out of it: ``gmsh.shapes_per_s``; ``bulk_vs_gmsh``: gmsh's shapes/s over jaxmatch's."""
    import glob

    import jaxmatch
    from jaxmatch.geometry import cumulative_length

    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as tmp:
        if parts:
            folder = Path(tmp) / "parts"
            folder.mkdir()
            for i, doc in enumerate(_script("make_bulk_parts").parts(int(parts))):
                (folder / f"part-{i:03d}.json").write_text(json.dumps(doc) + "\n")
            paths = sorted(str(p) for p in folder.glob("*.json"))
        else:
            paths = sorted(p for g in MESH_BULK_REGIONS for p in glob.glob(str(root / g)))
        load0 = list(os.getloadavg())
        walls, cpus, ref_walls, ref_cpus, recs = [], [], [], [], []
        for rep in range(max(int(reps), 1)):
            if ref is not None:
                wall, cpu, _ = _bulk_command(Path(ref).resolve(), paths, divisions, jobs, Path(tmp) / f"ref{rep}",
                                             search if ref_search is None else ref_search)
                ref_walls.append(wall)
                ref_cpus.append(cpu)
            wall, cpu, recs = _bulk_command(root, paths, divisions, jobs, Path(tmp) / f"out{rep}", search)
            walls.append(wall)
            cpus.append(cpu)
        load1 = list(os.getloadavg())
        gmsh_s, gmsh_n = 0.0, 0
        cg = _script("compare_gmsh") if gmsh else None
        for p in paths if gmsh else ():
            shp = jaxmatch.load_shape(p)
            if shp.holes:
                continue
            opts = cg.GMSH_METHODS[MESH_GMSH]
            outline, _ = cg.mesh_table._outline(shp)
            h = float(cumulative_length(outline)[-1]) / divisions
            cal = cg.gmsh_calibrated(outline, h, **opts)
            t = time.perf_counter()
            cg.gmsh_quads(outline, cal["lc"], **opts)
            gmsh_s += time.perf_counter() - t
            gmsh_n += 1
    per_region = sorted(r["seconds"] for r in recs if "seconds" in r)
    wall = min(walls)
    out = {"regions": len(paths), "meshed": sum(r.get("status", "meshed") == "meshed" and "error" not in r for r in recs),
           "divisions": int(divisions), "jobs": int(jobs), "search": search, "parts": int(parts), "wall_s": wall, "runs_s": walls,
           "shapes_per_s": len(paths) / wall, "cpu_s": min(cpus), "shapes_per_cpu_s": len(paths) / min(cpus),
           "per_region_s": {"median": statistics.median(per_region), "max": per_region[-1],
                            "sum": sum(per_region)} if per_region else None,
           "load": {"before": load0, "after": load1}}
    if ref is not None:
        out["ref"] = {"root": str(ref), "search": search if ref_search is None else ref_search, "runs_s": ref_walls, "shapes_per_s": len(paths) / min(ref_walls),
                      "cpu_s": min(ref_cpus), "shapes_per_cpu_s": len(paths) / min(ref_cpus)}
        out["vs_ref"] = out["shapes_per_s"] / out["ref"]["shapes_per_s"]
        out["vs_ref_cpu"] = out["shapes_per_cpu_s"] / out["ref"]["shapes_per_cpu_s"]
    if gmsh:
        out["gmsh"] = {"regions": gmsh_n, "seconds": gmsh_s, "shapes_per_s": gmsh_n / gmsh_s if gmsh_s else float("nan")}
        out["bulk_vs_gmsh"] = out["gmsh"]["shapes_per_s"] / out["shapes_per_s"]
    return out


def bench_graded(reps: int = 3, finer: float = 1.0) -> dict:
    """Graded against uniform meshing of the same regions (``scripts/graded_table.py``'s cases,
    ``examples/graded``): per case the best of ``reps`` first calls (caches cleared,
    :func:`clear_mesh_caches`) of ``jaxmatch.mesh(shape, size=Field)`` and of
    ``jaxmatch.mesh(shape, size=h)`` at the uniform ``h = sqrt(area / graded quads)`` (about as
    many quads), in the same run; ``ratio``: the graded run's seconds per quad over the uniform
    run's (the issue asks for at most 2); ``cpu_ratio``: the same of this process's CPU seconds
    (``time.process_time``: less moved by other processes on a shared machine). finer: every size of the fields (H, s) divided by this
    (distances kept): larger meshes, where the per-quad work outweighs the fixed costs."""
    import math as _math

    import jaxmatch
    from jaxmatch.field import load_field

    folder = ROOT / "examples" / "graded"
    jaxmatch.mesh(jaxmatch.load_shape(folder / "square.json"), size=0.5)  # warm (kernels, catalogue)
    cases = []
    for fpath in sorted(folder.glob("*.field.json")):
        name = fpath.name[: -len(".field.json")]
        shp, field = jaxmatch.load_shape(folder / f"{name}.json"), load_field(fpath)
        field = dataclasses.replace(field, size=field.size / finer,
                                    near=tuple(dataclasses.replace(e, size=e.size / finer) for e in field.near))

        def first(size):
            clear_mesh_caches()
            return jaxmatch.mesh(shp, size=size)

        def timed(size):  # (wall seconds, CPU seconds of this process, mesh) of one first call
            t, c = time.perf_counter(), time.process_time()
            m = first(size)
            return time.perf_counter() - t, time.process_time() - c, m

        try:
            first(field)  # (warming)
            g = [timed(field) for _ in range(max(int(reps), 1))]
            gm = g[-1][2]
            h = _math.sqrt(abs(shp.user_area) / gm.quads.shape[0])
            first(h)
            u = [timed(h) for _ in range(max(int(reps), 1))]
            um = u[-1][2]
        except jaxmatch.InputError as e:  # (named in the record, not timed)
            cases.append({"case": name, "error": str(e)[:200]})
            continue
        gq, uq = gm.quads.shape[0], um.quads.shape[0]
        gw, gc = min(x[0] for x in g), min(x[1] for x in g)
        uw, uc = min(x[0] for x in u), min(x[1] for x in u)
        cases.append({"case": name, "graded_s": gw, "graded_cpu_s": gc, "graded_quads": int(gq), "uniform_h": h,
                      "uniform_s": uw, "uniform_cpu_s": uc, "uniform_quads": int(uq),
                      "ratio": (gw / gq) / (uw / uq), "cpu_ratio": (gc / gq) / (uc / uq)})
    ratios = [c["ratio"] for c in cases if "ratio" in c] or [float("nan")]
    cpu = [c["cpu_ratio"] for c in cases if "cpu_ratio" in c] or [float("nan")]
    return {"cases": cases, "median_ratio": statistics.median(ratios), "max_ratio": max(ratios),
            "median_cpu_ratio": statistics.median(cpu), "max_cpu_ratio": max(cpu), "reps": reps, "finer": finer,
            "load": os.getloadavg()}


def profile_mesh(name: str, div: int, top: int = 10) -> dict:
    """cProfile of one warm ``jaxmatch.mesh(shape, size=h)`` call (after one untimed call): the
    wall time, the ``top`` entries by cumulative time (``"top"``) and by own time (``"top_own"``),
    each ``[function, calls, tottime, cumtime]``."""
    import cProfile
    import pstats

    import jaxmatch

    cg = _script("compare_gmsh")
    shp, _, _, _, h = cg.shape_case(cg.mesh_table.SHAPES[name], div)
    jaxmatch.mesh(shp, size=h)
    t = time.perf_counter()
    jaxmatch.mesh(shp, size=h)
    wall = time.perf_counter() - t
    prof = cProfile.Profile()
    prof.enable()
    jaxmatch.mesh(shp, size=h)
    prof.disable()
    st = pstats.Stats(prof)

    def entries(col):
        rows = sorted(st.stats.items(), key=lambda kv: -kv[1][col])[:top]
        return [[f"{Path(f).name}:{line}({fn})" if f != "~" else fn, nc, tt, ct] for (f, line, fn), (_, nc, tt, ct, _) in rows]

    return {"shape": name, "div": div, "wall_s": wall, "profiled_s": st.total_tt, "top": entries(3), "top_own": entries(2)}


def profile_bulk(parts: int, div: int = 32, top: int = 15, search: str = "best") -> dict:
    """The bulk path's per-part work in this one process, as a ``--jobs`` worker does it (the
    catalogue opened once, the kernels warmed, BLAS on one thread; one part meshed untimed): the
    first ``parts`` random parts of ``scripts/make_bulk_parts.py`` meshed at perimeter / ``div``
    twice, every meshing cache cleared before each pass. ``cpu_s``: the first pass's CPU time
    (``time.process_time``); ``profiled_s``: the second's, under cProfile with that CPU clock
    (Python code is slowed, compiled code is not: read shares, not seconds). ``strategies``: per
    strategy of :mod:`jaxmatch.meshing.strategies`, the parts it ran for, the profiled seconds of
    its candidates, and from the first pass (:func:`_strategy_outcomes`) its CPU seconds
    (``cpu_s``), the parts where one of its candidates was chosen (``chosen``), the CPU seconds
    of the parts where none was (``unchosen_cpu_s``: what a bound that skips the strategy could save
    at most), the parts where it meshed no candidate at all (``empty``; their CPU seconds
    ``empty_cpu_s``) and the parts where the layout bound would have skipped it (``bounded``,
    :func:`_bounded`); ``chosen_by``: how many chosen meshes each kind of candidate made (a larger or
    a conforming single template are both named ``single <id>``); ``layouts``: from the first
    pass (:func:`_layout_losers`), what a bound that skips a layout before it is meshed could save
    at most; ``top``, ``top_own``: as :func:`profile_mesh`."""
    import cProfile
    import pstats

    import jaxmatch
    from jaxmatch.batch import one_core, warm_kernels
    from jaxmatch.meshing import strategies

    with tempfile.TemporaryDirectory() as tmp:
        docs = _script("make_bulk_parts").parts(int(parts) + 1)
        for i, doc in enumerate(docs):
            (Path(tmp) / f"part-{i:03d}.json").write_text(json.dumps(doc) + "\n")
        shapes = [jaxmatch.load_shape(Path(tmp) / f"part-{i:03d}.json") for i in range(len(docs))]
    cat = jaxmatch.load_catalogue()
    warm_kernels(True)
    one_core()
    jaxmatch.mesh(shapes[-1], divisions=div, catalogue=cat, search=search)  # (a part not measured: the code paths warm)
    shapes = shapes[:-1]
    cat.cache.forget_shapes()
    meshes = []
    with _layout_losers() as layouts, _strategy_outcomes() as outcomes:
        t = time.process_time()
        for s in shapes:
            meshes.append(jaxmatch.mesh(s, divisions=div, catalogue=cat, search=search))
            outcomes.part(meshes[-1])
        cpu = time.process_time() - t - outcomes.bound_cpu_s
    cat.cache.forget_shapes()
    prof = cProfile.Profile(time.process_time)
    prof.enable()
    for s in shapes:
        jaxmatch.mesh(s, divisions=div, catalogue=cat, search=search)
    prof.disable()
    st = pstats.Stats(prof)
    per = {}
    for cls in (strategies.Layouts, strategies.Larger, strategies.Conforming, strategies.RingPartition,
                strategies.Bends, strategies.Smooth):
        code = cls.candidates.__code__
        _, nc, _, ct, _ = st.stats.get((code.co_filename, code.co_firstlineno, code.co_name), (0, 0, 0.0, 0.0, {}))
        per[cls.__name__] = {"parts": nc, "profiled_s": ct, **outcomes.of(cls.__name__)}
    chosen_by: dict = {}
    for m in meshes:  # the kind of the chosen candidate, by its name
        c = m.chosen
        who = ("RingPartition" if c == strategies.RINGS else "Smooth" if c == strategies.DISK
               else "Bends" if c.endswith(strategies.FINER) else "Larger or Conforming" if c.startswith(strategies.SINGLE + " ")
               else "Layouts")
        chosen_by[who] = chosen_by.get(who, 0) + 1

    def entries(col):
        rows = sorted(st.stats.items(), key=lambda kv: -kv[1][col])[:top]
        return [[f"{Path(f).name}:{line}({fn})" if f != "~" else fn, nc, tt, ct] for (f, line, fn), (_, nc, tt, ct, _) in rows]

    return {"parts": len(shapes), "div": int(div), "cpu_s": cpu, "cpu_s_per_part": cpu / max(len(shapes), 1),
            "profiled_s": st.total_tt, "strategies": per, "chosen_by": chosen_by, "layouts": layouts, "top": entries(3),
            "top_own": entries(2), "load": list(os.getloadavg())}


class _Outcomes:
    """What :func:`_strategy_outcomes` records: per strategy class name, every
    ``candidates(request, tried)`` call of the current part (CPU seconds, names of the candidates
    meshed) until :meth:`part` is told the part's chosen mesh."""

    EMPTY = {"cpu_s": 0.0, "chosen": 0, "unchosen_cpu_s": 0.0, "bounded": 0, "empty": 0, "empty_cpu_s": 0.0}

    def __init__(self):
        self.pending: list[tuple[str, float, set, bool]] = []
        self.totals: dict[str, dict] = {}
        self.bound_cpu_s = 0.0  # spent judging the bound (not meshing: the caller leaves it out)

    def part(self, mesh) -> None:
        """The part whose calls are pending was meshed as ``mesh``: each call counts as chosen when
        ``mesh.chosen`` is one of its candidates."""
        for name, cpu, names, bounded in self.pending:
            d = self.totals.setdefault(name, dict(self.EMPTY))
            d["cpu_s"] += cpu
            d["bounded"] += bounded
            if mesh.chosen in names:
                d["chosen"] += 1
            else:
                d["unchosen_cpu_s"] += cpu
            if not names:  # no candidate meshed (e.g. no template meets a conforming count vector)
                d["empty"] += 1
                d["empty_cpu_s"] += cpu
        self.pending.clear()

    def of(self, name: str) -> dict:
        return dict(self.totals.get(name, self.EMPTY))


def _bounded(cls, req, tried) -> bool:
    """Whether the pipeline's bound rules out every candidate of strategy ``cls`` before it runs:
    the best mesh so far beats (before the order tried) :func:`jaxmatch.meshing.choose.best_possible_key`
    of its layout (the single patch for :class:`~jaxmatch.meshing.strategies.Larger` and
    :class:`~jaxmatch.meshing.strategies.Conforming`, the ring layout for
    :class:`~jaxmatch.meshing.strategies.RingPartition`) with
    :func:`~jaxmatch.placement.bounds.node_sj_bound`'s cap; False for the others."""
    from jaxmatch.meshing import choose, strategies
    from jaxmatch.placement.bounds import node_sj_bound
    from jaxmatch.placement.decompose import single_patch
    from jaxmatch.placement.rings import ring_layout

    keys = [choose.mesh_key(c.mesh, i, req.quality) for i, c in enumerate(tried) if c.mesh is not None]
    if not keys or cls not in (strategies.Larger, strategies.Conforming, strategies.RingPartition):
        return False
    try:
        lay = ring_layout(req.region, req.h) if cls is strategies.RingPartition else single_patch(req.region)
        cap = node_sj_bound(lay)
    except Exception:  # noqa: BLE001 - (a layout that cannot be made: no claim)
        return False
    return min(keys)[:-1] < choose.best_possible_key(lay.n_patches, 0, cap, req.quality)[:-1]


@contextlib.contextmanager
def _strategy_outcomes():
    """While in the block, every strategy's ``candidates`` call (the classes of
    :mod:`jaxmatch.meshing.strategies` that :func:`profile_bulk` reports) is timed with
    ``time.process_time`` and its meshed candidates named; yields an :class:`_Outcomes`, told
    each part's chosen mesh (``part(mesh)``) after its ``jaxmatch.mesh`` call."""
    from jaxmatch.meshing import strategies

    out = _Outcomes()
    classes = (strategies.Layouts, strategies.Larger, strategies.Conforming, strategies.RingPartition,
               strategies.Bends, strategies.Smooth)
    saved = {cls: cls.candidates for cls in classes}

    def timed(cls):
        def candidates(self, req, tried):
            t = time.process_time()
            bounded = _bounded(cls, req, tried)
            out.bound_cpu_s += time.process_time() - t
            t = time.process_time()
            made = saved[cls](self, req, tried)
            out.pending.append((cls.__name__, time.process_time() - t, {c.name for c in made if c.mesh is not None},
                                bounded))
            return made
        return candidates

    for cls in classes:
        cls.candidates = timed(cls)
    try:
        yield out
    finally:
        for cls, f in saved.items():
            cls.candidates = f


@contextlib.contextmanager
def _layout_losers():
    """While in the block, every layout that :func:`jaxmatch.meshing.strategies.try_layouts`
    meshes is recorded with the CPU time (``time.process_time``) of its
    :func:`~jaxmatch.placement.solve.mesh_layout` call. Yields a dict filled on exit:
    ``{"meshed": layouts meshed, "cpu_s": their mesh_layout CPU seconds, "after_better": {rule:
    {"layouts", "cpu_s"}}}``, where ``after_better`` counts the layouts whose mesh lost, by
    :func:`jaxmatch.meshing.choose.mesh_key` (order: the order meshed), to a mesh made before it
    in the same ``try_layouts`` call, under the first rule of ``choose.RULES`` on which they
    differ: the layouts an exact bound there could have skipped, and the most it could save."""
    from jaxmatch.meshing import choose, strategies

    calls: list[list] = []
    last = {}
    saved = strategies.try_layouts, strategies.mesh_layout, strategies.from_layout

    def try_layouts(*a, **k):
        calls.append([])
        last["inside"] = True
        try:
            return saved[0](*a, **k)
        finally:
            last["inside"] = False

    def mesh_layout(*a, **k):
        t = time.process_time()
        try:
            return saved[1](*a, **k)
        finally:
            last["cpu"] = time.process_time() - t

    def from_layout(*a, **k):
        m = saved[2](*a, **k)
        cpu = last.pop("cpu", 0.0)
        if last.get("inside"):  # (not the larger templates' or a disk's meshes: no bound skips those)
            calls[-1].append((m, cpu))
        return m

    out = {"meshed": 0, "cpu_s": 0.0, "after_better": {}}
    strategies.try_layouts, strategies.mesh_layout, strategies.from_layout = try_layouts, mesh_layout, from_layout
    try:
        yield out
    finally:
        strategies.try_layouts, strategies.mesh_layout, strategies.from_layout = saved
    for made in calls:
        best = None
        for i, (m, cpu) in enumerate(made):
            key = choose.mesh_key(m, i)
            out["meshed"] += 1
            out["cpu_s"] += cpu
            if best is not None and best < key:
                rule = choose.RULES[next(j for j, (a, b) in enumerate(zip(best, key)) if a != b)]
                d = out["after_better"].setdefault(rule, {"layouts": 0, "cpu_s": 0.0})
                d["layouts"] += 1
                d["cpu_s"] += cpu
            best = key if best is None or key < best else best


def _report(line: str, result: dict, as_json: bool) -> int:
    """Print a benchmark's one-line summary (to stderr with --json) and, with --json, its JSON
    object on the last line; exit status 0."""
    print(line, file=sys.stderr if as_json else sys.stdout)
    if as_json:
        print(json.dumps(result))
    return 0


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.mesh and args.mesh_large:
        r = mesh_large(*args.mesh_large.rsplit(":", 1))
        return _report(f"{r['file']} at size {r['size']:g}: {r['quads']} quads ({r['chosen']}, min SJ {r['min_sj']:.3f}, "
                       f"valid {r['valid']}) in {r['seconds']:.2f} s; peak RSS {r['peak_rss_mb']:.0f} MB "
                       f"({r['rss_before_mb']:.0f} MB before the call); load {r['load'][0]:.2f}", r, args.json)
    if args.mesh and args.mesh_bulk:
        r = mesh_bulk(args.mesh_bulk, args.mesh_jobs, args.mesh_bulk_parts, args.mesh_bulk_ref, args.mesh_bulk_reps,
                      not args.mesh_bulk_no_gmsh, args.mesh_bulk_search, args.mesh_bulk_ref_search)
        ref = (f"; {r['ref']['root']} (--search {r['ref']['search']}), same regions, alternated: {r['ref']['shapes_per_s']:.1f} shapes/s, "
               f"{r['ref']['cpu_s']:.1f} CPU s (vs_ref {r['vs_ref']:.2f}, by CPU time {r['vs_ref_cpu']:.2f})") if "ref" in r else ""
        gm = (f"; gmsh, same outlines one after another in one process: {r['gmsh']['shapes_per_s']:.1f} shapes/s "
              f"({r['gmsh']['regions']} regions); bulk_vs_gmsh {r['bulk_vs_gmsh']:.1f}") if "gmsh" in r else ""
        return _report(f"bulk: {r['meshed']}/{r['regions']} regions meshed at perimeter / {r['divisions']} with --search "
                       f"{r['search']} --jobs "
                       f"{r['jobs']} in {r['wall_s']:.2f} s (whole command): {r['shapes_per_s']:.1f} shapes/s, "
                       f"{r['cpu_s']:.1f} CPU s (per region "
                       f"in the workers: median {r['per_region_s']['median']:.3f} s, max {r['per_region_s']['max']:.3f} s, "
                       f"sum {r['per_region_s']['sum']:.1f} s){ref}{gm}; load "
                       f"{r['load']['before'][0]:.2f} -> {r['load']['after'][0]:.2f}", r, args.json)
    if args.mesh and args.mesh_bulk_profile:
        n, _, div = args.mesh_bulk_profile.partition(":")
        r = profile_bulk(int(n), int(div or 32), search=args.mesh_bulk_search)
        out = sys.stderr if args.json else sys.stdout
        print(f"bulk path, {r['parts']} random parts at perimeter / {r['div']} in one process: {r['cpu_s']:.2f} CPU s "
              f"({r['cpu_s_per_part']:.3f} s a part); under cProfile (CPU clock) {r['profiled_s']:.2f} s; load "
              f"{r['load'][0]:.2f}", file=out)
        for name, v in r["strategies"].items():
            print(f"  {name:>13}: ran for {v['parts']:3d} parts, {v['profiled_s']:6.2f} s profiled; {v['cpu_s']:6.2f} CPU s, "
                  f"chosen in {v['chosen']:3d} parts, {v['unchosen_cpu_s']:6.2f} CPU s in the others, no candidate in "
                  f"{v['empty']} ({v['empty_cpu_s']:.2f} CPU s); the layout bound rules it out in {v['bounded']}", file=out)
        print("  chosen: " + ", ".join(f"{k} {v}" for k, v in r["chosen_by"].items()), file=out)
        lay = r["layouts"]
        print(f"  layouts meshed: {lay['meshed']}, {lay['cpu_s']:.2f} CPU s in mesh_layout; after a better one in the "
              "same call, by the rule they lose on: " + (", ".join(
                  f"{k} {v['layouts']} ({v['cpu_s']:.2f} s)" for k, v in
                  sorted(lay["after_better"].items(), key=lambda kv: -kv[1]["cpu_s"])) or "none"), file=out)
        for title, key in (("cumulative", "top"), ("own", "top_own")):
            print(f"top {len(r[key])} by {title} time:", file=out)
            for fn, nc, tt, ct in r[key]:
                print(f"  {ct:7.3f} s cumulative {tt:7.3f} s own {nc:7d} calls  {fn}", file=out)
        if args.json:
            print(json.dumps({"bulk_profile": r}))
        return 0
    if args.mesh and args.mesh_graded:
        r = bench_graded(args.mesh_reps, args.mesh_graded_finer)
        for c in r["cases"]:
            if "error" in c:
                print(f"{c['case']}: {c['error']}", file=sys.stderr if args.json else sys.stdout)
                continue
            print(f"{c['case']}: graded {c['graded_quads']} quads in {c['graded_s']:.3f} s ({c['graded_cpu_s']:.3f} s CPU); "
                  f"uniform h {c['uniform_h']:.4g} {c['uniform_quads']} quads in {c['uniform_s']:.3f} s "
                  f"({c['uniform_cpu_s']:.3f} s CPU); time per quad graded / uniform {c['ratio']:.2f} "
                  f"(CPU {c['cpu_ratio']:.2f})", file=sys.stderr if args.json else sys.stdout)
        return _report(f"graded / uniform time per quad: median {r['median_ratio']:.2f}, max {r['max_ratio']:.2f}; CPU "
                       f"time: median {r['median_cpu_ratio']:.2f}, max {r['max_cpu_ratio']:.2f} (first calls, best of "
                       f"{r['reps']}; sizes / {r['finer']:g}); load {r['load'][0]:.2f}", r, args.json)
    if args.mesh and args.mesh_profile:
        name, _, div = args.mesh_profile.partition(":")
        r = profile_mesh(name, int(div or 32))
        print(f"jaxmatch.mesh({name}, size=P/{r['div']}): warm {r['wall_s']:.3f} s; under cProfile {r['profiled_s']:.3f} s; "
              f"top {len(r['top'])} by cumulative time:", file=sys.stderr if args.json else sys.stdout)
        for fn, nc, tt, ct in r["top"]:
            print(f"  {ct:7.3f} s cumulative {tt:7.3f} s own {nc:6d} calls  {fn}", file=sys.stderr if args.json else sys.stdout)
        print(f"top {len(r['top_own'])} by own time:", file=sys.stderr if args.json else sys.stdout)
        for fn, nc, tt, ct in r["top_own"]:
            print(f"  {ct:7.3f} s cumulative {tt:7.3f} s own {nc:6d} calls  {fn}", file=sys.stderr if args.json else sys.stdout)
        if args.json:
            print(json.dumps({"profile": r}))
        return 0
    if args.mesh:
        say = (lambda *a: print(*a, file=sys.stderr, flush=True)) if args.json else (lambda *a: print(*a, flush=True))
        shapes = [s for s in args.mesh_shapes.split(",") if s] or None
        r = bench_mesh(shapes, [int(d) for d in args.mesh_divisions.split(",")], args.mesh_reps, say,
                       holes=not args.mesh_no_holes)
        for who in ("jaxmatch", "gmsh"):
            q = r["quality"][who]
            say(f"{who}: {q['valid']}/{q['meshes']} valid; mean of min SJ {q['mean_min_sj']:.3f}; worst min SJ "
                f"{q['worst_min_sj']:.3f}; mean SJ {q['mean_mean_sj']:.3f}; irregular per mesh "
                f"{q['irregular_per_mesh']:.2f}; mean edge/h {q['mean_edge_over_h']:.2f}; total {q['total_s']:.3f} s; "
                f"RSS growth over its calls {q['rss_growth_mb']:.0f} MB")
        say(f"mesh_vs_gmsh (median of jaxmatch / gmsh time per case, each shape meshed for the first time, caches "
            f"cleared; gmsh best of {r['reps']} warm): {r['mesh_vs_gmsh']:.1f} (a repeat call on the same shape and size: "
            f"{r['mesh_vs_gmsh_repeat']:.1f}; catalogue passed: {r.get('mesh_vs_gmsh_catalogue', float('nan')):.1f}); peak RSS {r['peak_rss_mb']:.0f} MB; load {r['load']['before'][0]:.2f} -> "
            f"{r['load']['after'][0]:.2f}")

        def part(key):
            v = r.get(f"mesh_vs_gmsh_{key}")
            return f"{v:.1f} ({r[f'cases_{key}']} cases)" if v is not None else "none"

        say(f"  without holes {part('shapes')}; with holes {part('holes')}; where gmsh's mean edge came out within "
            f"{MESH_COMPARABLE[0]}-{MESH_COMPARABLE[1]} h {part('comparable')}")
        if args.json:
            print(json.dumps(r))
        return 0
    if args.refine:
        r = bench_refine(max(args.reps, 1))
        print(f"refine: {r['quads']} quads ({r['template']}, min SJ {r['min_scaled_jacobian']:.3f}, {r['inverted']} inverted); "
              f"refine_and_place + milp min {r['refine_s']['min']:.3f} s (ratio to {r['target_s']:g} s target "
              f"{r['ratio_to_target']:.2f}); from the shape (ranking included) min {r['full_s']['min']:.3f} s; "
              f"smoothing forced min {r['refine_smoothed_s']['min']:.3f} s (min SJ {r['smoothed_min_scaled_jacobian']:.3f}); "
              f"load {r['load'][0]:.2f}", file=sys.stderr if args.json else sys.stdout)
        if args.json:
            print(json.dumps({"refine": r}))
        return 0
    if args.many_probe:
        print(json.dumps(many_probe(args)))
        return 0
    if args.rss_probe:
        print(json.dumps(rss_probe(args)))
        return 0
    load0 = os.getloadavg()
    import jax
    import numpy as np

    configure(args)
    from jaxmatch.scoring import exact as score

    cat, internal, buckets, table, shapes = load_workload(args)
    pairs, cells = workload_cells(buckets, shapes)
    threads = args.threads or score.default_threads()
    say = (lambda *a: print(*a, file=sys.stderr, flush=True)) if args.json else (lambda *a: print(*a, flush=True))
    say(f"workload: {sum(len(b.ids) for b in buckets)} meshes (k in {internal[0]}..{internal[-1]}) x {len(shapes)} shapes, "
        f"m = {POINTS}: {pairs} mesh-shape pairs, {cells:.4g} DP cell updates (2 n^2 m per pair)")
    say(f"machine: {os.cpu_count()} CPUs ({threads} jaxmatch threads), load {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}; "
        f"jax {jax.__version__}, numpy {np.__version__}, python {platform.python_version()}")

    # ---- jaxmatch: compile (first pass of one shape minus a warm pass), then repetitions
    t = time.perf_counter()
    jax_pass(buckets, table, shapes[:1], args)
    first = time.perf_counter() - t
    t = time.perf_counter()
    jax_pass(buckets, table, shapes[:1], args)
    warm = time.perf_counter() - t
    compile_s = first - warm

    if args.strong_lanes:
        global STRONG_LANES
        STRONG_LANES = int(args.strong_lanes)
    refs = {} if args.skip_reference else {**make_reference(), "strongest": make_strongest()}
    wanted = [r.strip() for r in args.refs.split(",") if r.strip()]
    unknown = sorted(set(wanted) - {"plain", "vectorised", "strongest"})
    if unknown:
        raise SystemExit(f"bench.py: --refs: unknown reference(s) {', '.join(unknown)}")
    refs = {k: v for k, v in refs.items() if k in wanted}
    peak = machine_peak()
    ref_times: dict = {name: [] for name in refs}
    ref_cpu: dict = {name: [] for name in refs}
    jax_cpu: list[float] = []
    ref_compile: dict = {}
    for name, fn in refs.items():
        t = time.perf_counter()
        fn(buckets[:1], table, shapes[:1])
        ref_compile[name] = time.perf_counter() - t
    jax_times: list[float] = []
    identical: dict = {}
    for rep in range(max(args.reps, args.ref_reps if refs else 0)):  # interleaved, so load hits all alike
        if rep < args.reps:
            t, tc = time.perf_counter(), time.process_time()
            ours = jax_pass(buckets, table, shapes, args)
            jax_times.append(time.perf_counter() - t)
            jax_cpu.append(time.process_time() - tc)
            say(f"  jaxmatch rep {rep + 1}: {jax_times[-1]:.3f} s")
        for name, fn in refs.items():
            if rep < args.ref_reps:
                t, tc = time.perf_counter(), time.process_time()
                theirs = fn(buckets, table, shapes)
                ref_times[name].append(time.perf_counter() - t)
                ref_cpu[name].append(time.process_time() - tc)
                say(f"  reference ({name}) rep {rep + 1}: {ref_times[name][-1]:.3f} s")
                if name not in identical:
                    identical[name] = all(np.array_equal(a, b) for xs, ys in zip(ours, theirs) for a, b in zip(xs, ys))
    jb = min(jax_times)
    result = {
        "workload": {"catalogue": str(cat.path.name), "internal": [internal[0], internal[-1]], "shapes": EXAMPLES,
                     "points": POINTS, "mesh_shape_pairs": pairs, "cells": cells,
                     "cell_definition": "2n orientations x n mesh vertices x m shape points per mesh and shape"},
        "jaxmatch": {"threads": threads, "first_pass_s": first, "warm_pass_s": warm, "compile_s": compile_s,
                     "run_s": summary(jax_times), "cells_per_s": cells / jb, "meshes_per_s": pairs / jb,
                     "dtype": np.dtype(score.dp_kind(table, max(b.n for b in buckets)).dtype).name, "backend": args.backend,
                     "block_cells": score.BLOCK_CELLS, "batch": args.batch or score.DEFAULT_BATCH},
    }
    result["machine_peak"] = peak
    result["jaxmatch"]["peak_fraction"] = cells / jb / peak["peak_cells_per_s"]
    result["jaxmatch"]["cpu_s"] = summary(jax_cpu)
    result["jaxmatch"]["cells_per_cpu_s"] = cells / min(jax_cpu)
    say(f"peak      : {peak['int16_lanes']} int16 lanes ({peak['isa']}) x {peak['cores']} cores x {peak['clock_mhz']:.0f} MHz "
        f"= {peak['peak_cells_per_s']:.3g} cells/s; jaxmatch reaches {result['jaxmatch']['peak_fraction']:.1%}")
    say(f"jaxmatch  : compile {compile_s:.2f} s (first pass of one shape {first:.2f} s, warm {warm:.2f} s); "
        f"run min {jb:.3f} s, median {statistics.median(jax_times):.3f} s over {len(jax_times)}; "
        f"{pairs / jb:,.0f} meshes/s, {cells / jb:.3g} cells/s")
    impl = {"plain": "numba njit, nopython, 1 thread, float32: per orientation a 1-D row, j inner (dp_reference)",
            "vectorised": "numba njit, nopython, 1 thread, float32: rows over all 2n orientations, orientation "
                          "innermost (LLVM SIMD)",
            "strongest": f"numba njit, parallel (prange over chunks of {STRONG_LANES} same-length meshes, all cores), "
                         "int16, meshes as lanes innermost (LLVM AVX-512/AVX2), every cell"}
    for name, ts in ref_times.items():
        rb = min(ts)
        key = "reference" if name == "plain" else f"reference_{name}"
        result[key] = {"impl": impl[name], "compile_s": ref_compile[name], "run_s": summary(ts),
                       "cells_per_s": cells / rb, "meshes_per_s": pairs / rb, "identical_utilities": identical[name],
                       "peak_fraction": cells / rb / peak["peak_cells_per_s"],
                       "cpu_s": summary(ref_cpu[name]), "cells_per_cpu_s": cells / min(ref_cpu[name])}
        result[f"ratio_{name}_cpu" if name != "plain" else "ratio_cpu"] = min(ref_cpu[name]) / min(jax_cpu)
        ratio, ratio_median = rb / jb, statistics.median(ts) / statistics.median(jax_times)
        result["ratio" if name == "plain" else f"ratio_{name}"] = ratio
        result["ratio_median" if name == "plain" else f"ratio_{name}_median"] = ratio_median
        say(f"reference ({name}): compile {ref_compile[name]:.2f} s; run min {rb:.3f} s, median {statistics.median(ts):.3f} s; "
            f"{pairs / rb:,.0f} meshes/s, {cells / rb:.3g} cells/s ({cells / rb / peak['peak_cells_per_s']:.1%} of peak); "
            f"utilities identical: {identical[name]}")
        say(f"ratio jaxmatch / reference ({name}): {ratio:.2f}x (min vs min), {ratio_median:.2f}x (median vs median); "
            f"CPU time (all threads): {min(ref_cpu[name]) / min(jax_cpu):.2f}x")

    if not args.skip_bulk:
        result["sharing"] = sharing(buckets)
        say("sharing   : " + ", ".join(f"k={k}: {v['meshes']} meshes / {v['distinct_sequences']} sequences"
                                       for k, v in result["sharing"].items()))
        b = bulk_measurements(buckets, table, shapes, args, cells, pairs)
        result["bulk"] = b
        say(f"distinct  : run min {b['distinct']['run_s']['min']:.3f} s, {b['distinct']['cells_per_s']:.3g} cells/s "
            f"(nominal cells){'; ratio %.2fx' % (b['distinct']['cells_per_s'] / result['reference']['cells_per_s']) if 'reference' in result else ''}")
        tp = b["top5"]
        say(f"top-5     : exhaustive min {min(tp['exhaustive']['run_s']['all']):.3f} s, pruned min "
            f"{min(tp['pruned']['run_s']['all']):.3f} s ({tp['speedup_min']:.1f}x); sequences scored "
            f"{tp['pruned']['sequences_scored']} of {tp['sequences_total']}; identical rows: {tp['identical']}")
        if "reference" in result:
            result["ratio_distinct"] = b["distinct"]["cells_per_s"] / result["reference"]["cells_per_s"]
    if not args.skip_rss:
        result["rss_by_catalogue"] = rss_by_catalogue(args)
        say("RSS       : " + ", ".join(f"{k}: {v.get('meshes')} meshes, peak {v.get('peak_rss_mb', float('nan')):.0f} MB "
                                       f"(after import {v.get('rss_after_import_mb', float('nan')):.0f} MB)"
                                       for k, v in result["rss_by_catalogue"].items()))
    if not args.skip_many:
        many = many_and_api(args)
        result["many"] = many
        w = many.get("geometry_workers")
        result["score_many_shapes_per_s"] = (w or many["geometry"])["shapes_per_s"]
        result["score_many_id_shapes_per_s"] = many["id"]["shapes_per_s"]
        result["api_shape_ms"] = many["api_shape_ms"]["min_ms"]
        say(f"many      : {many['shapes']} shapes, top 5, pruned, one prepared catalogue: geometric tie-break "
            f"{many['geometry']['shapes_per_s']:.1f} shapes/s, id tie-break {many['id']['shapes_per_s']:.1f} shapes/s (warm)")
        if w:
            say(f"many      : geometric tie-break in {w['jobs']} worker processes (score-many's default): "
                f"{w['shapes_per_s']:.1f} shapes/s; records identical to one process: {w['identical_to_one_process']}")
        say(f"API       : rank + place {many['api_shape_ms']['shape']}: {many['api_shape_ms']['min_ms']:.0f} ms min, "
            f"{many['api_shape_ms']['median_ms']:.0f} ms median (warm; first {many['api_shape_ms']['first_ms']:.0f} ms)")
    if args.cli:
        result["cli"] = cli_times()
        result["cli_cold_s"] = result["cli"]["default"]["cold_s"]
        result["cli_warm_s"] = result["cli"]["default"]["warm_s"]
        if not args.skip_many:
            result["score_many_cli"] = score_many_cli(args)
            say(f"score-many: CLI on {result['score_many_cli']['shapes']} shapes: cold {_secs(result['score_many_cli']['cold_s'])}, "
                f"warm {_secs(result['score_many_cli']['warm_s'])}")
        say("CLI       : " + ", ".join(f"{k}: cold {_secs(v['cold_s'])}, warm {_secs(v['warm_s'])}" for k, v in result["cli"].items()))
    if args.k6:
        result["k6"] = k6 = k6_measure(args)
        if "error" in k6:
            say(f"k <= 6    : failed: {k6['error']}")
        else:
            say(f"k <= 6    : {k6['meshes']} meshes, grouping {k6['prepare_s']:.2f} s once; pruned top-5 of lshape: first "
                f"{k6['first_s']:.2f} s, warm {k6['warm_s']:.3f} s ({k6['pruned']} meshes skipped by the bound); peak RSS "
                f"{k6['peak_rss_mb']:.0f} MB")
    load1 = os.getloadavg()
    result["peak_rss_mb"] = rss_mb()
    result["load"] = {"before": list(load0), "after": list(load1)}
    result["jaxmatch_cells_per_s"] = result["jaxmatch"]["cells_per_s"]
    result["jaxmatch_meshes_per_s"] = result["jaxmatch"]["meshes_per_s"]
    if "reference" in result:
        result["reference_cells_per_s"] = result["reference"]["cells_per_s"]
        result["reference_meshes_per_s"] = result["reference"]["meshes_per_s"]
    say(f"peak RSS (this process, numba included): {result['peak_rss_mb']:.0f} MB; load after {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
