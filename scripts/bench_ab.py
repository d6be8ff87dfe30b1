#!/usr/bin/env python3
"""Exact-kernel throughput of several scoring models, alternated in one process, in CPU time.

    .venv/bin/python scripts/bench_ab.py ROOT NAME=LATTICE [NAME=LATTICE ...]   (REPS=3 by default)

ROOT is a jaxmatch checkout (this one, or e.g. ``git archive main | tar -x -C /tmp/main`` to
measure another version with the same interpreter). Workload: the one of ``scripts/bench.py``
(every mesh of the shipped catalogue, k = 0..5, against the 9 benchmark shapes at m = 64).
Each model is compiled and warmed, then timed ``REPS`` times, models alternated, with
``score_bucket(..., threads=1)`` and ``time.process_time()``: on a machine shared with other
work, process CPU time varies far less than wall time. Prints cells per CPU-second (min and
median). Models are lattices (name or TOML path; their skip weights included when the
checkout knows them).
"""
import os
import sys
import time
from pathlib import Path

ROOT = Path(sys.argv[1]).resolve()
sys.path.insert(0, str(ROOT))
os.environ.setdefault("JAX_PLATFORMS", "cpu")

import numpy as np  # noqa: E402

from jaxmatch.catalogue import store as cat_mod  # noqa: E402
from jaxmatch.scoring.exact import score_bucket  # noqa: E402
from jaxmatch.scoring.lattice import load_lattice  # noqa: E402
from jaxmatch.io.readers import load_shape  # noqa: E402
from jaxmatch.shape import annotate  # noqa: E402

EXAMPLES = ["circle.json", "curved.json", "dshape.json", "hexagon.json", "lshape.json", "lshape.txt", "square.json",
            "triangle.json", "tshape.json"]

cat = cat_mod.default_catalogue()
buckets = list(cat.buckets(list(range(6))))
shapes = [annotate(load_shape(ROOT / "examples" / n), 64).codes for n in EXAMPLES]
cells = sum(len(b.ids) * 2 * b.n * b.n * len(c) for b in buckets for c in shapes)
models = {}
for spec in sys.argv[2:]:
    name, path = spec.split("=", 1)
    lat = load_lattice(path)
    models[name] = lat.weights() if hasattr(lat, "weights") else lat.table()


def one(model) -> float:
    t = time.process_time()
    for c in shapes:
        for b in buckets:
            score_bucket(c, b.valences, model, threads=1)
    return time.process_time() - t


for m in models.values():
    one(m)
    one(m)  # compile, then warm
times: dict = {n: [] for n in models}
for _ in range(int(os.environ.get("REPS", "3"))):
    for name, m in models.items():
        times[name].append(one(m))
for name, ts in times.items():
    print(f"{ROOT} {name}: CPU s min {min(ts):.3f} median {np.median(ts):.3f} -> {cells / min(ts):.3g} cells per CPU-s (min), "
          f"{cells / np.median(ts):.3g} (median); load {os.getloadavg()[0]:.1f}")
