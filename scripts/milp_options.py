"""Time HiGHS on the integer programs the tables solve, with and without its feasibility jump.

Runs ``scripts/mesh_table.py``, ``scripts/holes_table.py --no-gmsh`` and ``scripts/dense_table.py``
in this process with :func:`jaxmatch.placement.milp._highs` recorded (a copy of every program),
then solves each program alone, best of ``--reps``, twice: HiGHS's defaults (the feasibility
jump on) and without the feasibility jump; prints the totals by number of integer variables.
What set :data:`jaxmatch.placement.milp.FEASIBILITY_JUMP` (docs/perf.md, "Integer programs").

    .venv/bin/python scripts/milp_options.py [--reps 2] [--tables mesh,holes,dense]
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import runpy
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

TABLES = {"mesh": ("mesh_table.py", []), "holes": ("holes_table.py", ["--no-gmsh"]), "dense": ("dense_table.py", [])}
BINS = ((0, 20), (20, 40), (40, 60), (60, 100), (100, 10**9))


def collect(names) -> list[tuple]:
    """``[(args, kwargs)]`` of every ``_highs`` call the named tables make, in order (copies)."""
    import jaxmatch
    from jaxmatch.placement import milp

    jaxmatch.load_catalogue().cache.clear()  # every program solved again, as in a new process
    progs, real = [], milp._highs

    def record(*args, **kwargs):
        progs.append((copy.deepcopy(args), dict(kwargs)))
        return real(*args, **kwargs)

    milp._highs = record
    try:
        for name in names:
            script, argv = TABLES[name]
            sys.argv = [script, *argv]
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                try:
                    runpy.run_path(str(ROOT / "scripts" / script), run_name="__main__")
                except SystemExit:
                    pass
    finally:
        milp._highs = real
    return progs


def solve_time(args, kwargs, jump: bool, reps: int) -> float:
    """Best of ``reps`` seconds of ``_highs`` with ``FEASIBILITY_JUMP = jump``."""
    from jaxmatch.placement import milp

    old, milp.FEASIBILITY_JUMP = milp.FEASIBILITY_JUMP, jump
    try:
        best = float("inf")
        for _ in range(reps):
            t = time.perf_counter()
            milp._highs(*args, **kwargs)
            best = min(best, time.perf_counter() - t)
        return best
    finally:
        milp.FEASIBILITY_JUMP = old


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=2, help="solves of each program and variant, best kept (default 2)")
    ap.add_argument("--tables", default="mesh,holes,dense", help="tables whose programs are collected")
    a = ap.parse_args(argv)
    progs = collect([t.strip() for t in a.tables.split(",") if t.strip()])
    rows = []
    for args, kwargs in progs:
        n_int = int(np.count_nonzero(np.asarray(args[4])))
        rows.append((n_int, solve_time(args, kwargs, True, a.reps), solve_time(args, kwargs, False, a.reps)))
    print(f"{len(progs)} programs from {a.tables}; best of {a.reps}; milliseconds in all")
    print("| integer variables | programs | defaults | without the feasibility jump |")
    print("|---|---:|---:|---:|")
    for lo, hi in BINS:
        sel = [r for r in rows if lo <= r[0] < hi]
        if sel:
            label = f"{lo}-{hi - 1}" if hi < 10**9 else f"{lo}-{max(r[0] for r in sel)}"
            print(f"| {label} | {len(sel)} | {1000 * sum(r[1] for r in sel):.0f} | {1000 * sum(r[2] for r in sel):.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
