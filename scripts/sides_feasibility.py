#!/usr/bin/env python3
"""Which ``jaxmatch mesh --sides`` requests of 1..MAX edges per side can be met, shape by shape.

    .venv/bin/python scripts/sides_feasibility.py [SHAPES...] [--max 8] [--limit 10]
        [--full-up-to 512] [--sample 300] [--place 6] [--seed 0] [--out report.json]

Default shapes: the 3-, 4-, 5- and 6-sided convex shapes (examples/triangle, square, hexagon,
labels/shapes/pentagon) and every labelled shape in examples/labels/shapes/.

For each shape the templates are :func:`jaxmatch.placement.templates.patch_templates` (``--limit``
per size, by default the same as ``jaxmatch mesh --sides``, so the feasible requests counted here
are those the command meets). Per request ``c`` in ``{1..MAX}^n``:

* **feasible** (the reference): ``c`` is ``A @ m`` for some template's side matrix ``A`` and
  integers ``m >= 1``, found by enumerating the multiplicities (no integer programming);
* **solver** (checked on every request when there are at most ``--full-up-to`` of them, else on
  ``--sample`` ones, half drawn from the feasible requests and half uniformly): for a feasible request, :func:`solve_multiplicities` on the first
  template that reaches it must return ``m >= 1`` with ``A @ m == c`` exactly, and
  :func:`feasible` must agree with the enumeration on every template before it; for an
  infeasible one, :func:`feasible` must say no on every template;
* **placed** (``--place`` random feasible and as many infeasible requests): :func:`refine_mesh`
  must return exactly ``c`` edges per side with no inverted quad, or raise
  :class:`InfeasibleRequest` whose nearest counts are feasible (None when no template keeps
  every corner).

Prints one row per shape; ``--out`` writes the JSON report atomically. Exit status 1 when a
check fails.
"""

from __future__ import annotations

import itertools
import json
import sys
import time
from pathlib import Path
from typing import List, Optional

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from jaxmatch.catalogue.store import default_catalogue  # noqa: E402
from jaxmatch.cli import enable_compile_cache, run_typer  # noqa: E402
from jaxmatch.files import write_text_atomic  # noqa: E402
from jaxmatch.placement import refine as R  # noqa: E402
from jaxmatch.placement import templates as T  # noqa: E402
from jaxmatch.scoring.lattice import load_lattice  # noqa: E402
from jaxmatch.io.readers import load_shape  # noqa: E402

app = typer.Typer(add_completion=False)
out = Console(soft_wrap=True, width=None if sys.stdout.isatty() else 140)

CONVEX = [ROOT / "examples" / "triangle.json", ROOT / "examples" / "square.json",
          ROOT / "examples" / "labels" / "shapes" / "pentagon.json", ROOT / "examples" / "hexagon.json"]


def reachable(A: np.ndarray, cap: int) -> set:
    """Every count vector ``A @ m`` (integers ``m >= 1``) with all counts <= cap."""
    n = A.shape[0]
    states = {tuple([0] * n)}
    for c in range(A.shape[1]):
        col = A[:, c]
        if not col.any():
            continue
        nxt = set()
        for s in states:
            for k in range(1, cap + 1):
                v = tuple(int(a + k * b) for a, b in zip(s, col))
                if max(v) > cap:
                    break
                nxt.add(v)
        states = nxt
    return states


def check_shape(path: Path, cat, lat, *, cap: int, limit: int, full_up_to: int, sample: int, place: int, seed: int) -> dict:
    t0 = time.perf_counter()
    shp = load_shape(path)
    n = max(shp.n_corners, 1)
    ts = T.patch_templates(shp, cat, lat, limit=limit)
    reach = [reachable(t.side_matrix(), cap) for t in ts]
    union = set().union(*reach) if reach else set()
    total = cap ** n
    everything = total <= full_up_to
    rng = np.random.default_rng(seed)
    if everything:
        requests = list(itertools.product(range(1, cap + 1), repeat=n))
    else:  # half feasible ones, half uniformly random ones (mostly infeasible)
        feas0 = sorted(union)
        half = [feas0[i] for i in rng.choice(len(feas0), size=min(sample // 2, len(feas0)), replace=False)] if feas0 else []
        requests = half + [tuple(int(x) for x in rng.integers(1, cap + 1, n)) for _ in range(sample - len(half))]
    failures: list = []
    for c in requests:
        first = next((i for i, r in enumerate(reach) if c in r), None)
        upto = len(ts) if first is None else first
        for i in range(upto):  # the integer program agrees that earlier templates cannot
            if R.feasible(ts[i], c):
                failures.append({"request": c, "template": ts[i].mesh_id, "problem": "milp feasible, enumeration not"})
        if first is not None:
            m = R.solve_multiplicities(ts[first], counts=c)
            if m.min() < 1 or not np.array_equal(ts[first].side_matrix() @ m, c):
                failures.append({"request": c, "template": ts[first].mesh_id, "problem": "counts not met"})
    placed = {"feasible": 0, "infeasible": 0}
    feas = sorted(union)
    infeas = [c for c in (tuple(int(x) for x in rng.integers(1, cap + 1, n)) for _ in range(20 * place)) if c not in union]
    picks = [feas[i] for i in rng.choice(len(feas), size=min(place, len(feas)), replace=False)] if feas else []
    for c in picks + infeas[:place]:
        try:
            ch = R.refine_mesh(shp, sides=list(c), templates=ts)
        except R.InfeasibleRequest as e:
            if c in union or (union and e.nearest not in union) or (not union and e.nearest is not None):
                failures.append({"request": c, "problem": f"refused: {e}"})
            placed["infeasible"] += 1
            continue
        if c not in union or tuple(ch.mesh.counts.tolist()) != c or ch.mesh.inverted:
            failures.append({"request": c, "problem": f"placed {ch.mesh.counts.tolist()} with {ch.mesh.inverted} inverted"})
        placed["feasible"] += 1
    return {"shape": str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path), "sides": n,
            "templates": len(ts), "requests": total, "feasible": len(union),
            "solver_checked": len(requests), "solver_checked_all": everything, "placed": placed,
            "failures": [{k: (list(v) if isinstance(v, tuple) else v) for k, v in f.items()} for f in failures],
            "seconds": time.perf_counter() - t0}


@app.command()
def main(shapes: Optional[List[Path]] = typer.Argument(None, help="Shape files (default: convex 3-6 sided examples and the labelled shapes)."),
         cap: int = typer.Option(8, "--max", min=1, max=12, help="Largest count per side."),
         limit: int = typer.Option(R.DEFAULT_LIMIT, "--limit", min=1, help="Templates per size (patch_templates; default as 'mesh --sides')."),
         full_up_to: int = typer.Option(512, "--full-up-to", help="Check the solver on every request when there are at most this many."),
         sample: int = typer.Option(300, "--sample", help="Random requests checked otherwise."),
         place: int = typer.Option(6, "--place", help="Feasible (and as many infeasible) requests placed end to end."),
         seed: int = typer.Option(0, "--seed"),
         report: Optional[Path] = typer.Option(None, "--out", help="JSON report (written atomically).")) -> None:
    """Count the feasible --sides requests per shape and check the solver against enumeration."""
    enable_compile_cache()
    paths = list(shapes) if shapes else CONVEX + sorted((ROOT / "examples" / "labels" / "shapes").glob("*.json"))
    cat, lat = default_catalogue(), load_lattice("fine")
    table = Table()
    for col in ("shape", "sides", "templates", "feasible / requests", "solver checked", "placed ok", "failures", "s"):
        table.add_column(col, justify="right")
    rows = []
    for p in paths:
        r = check_shape(Path(p).resolve(), cat, lat, cap=cap, limit=limit, full_up_to=full_up_to, sample=sample,
                        place=place, seed=seed)
        rows.append(r)
        print(json.dumps({k: r[k] for k in ("shape", "sides", "templates", "feasible", "requests", "solver_checked")}),
              file=sys.stderr, flush=True)
        table.add_row(Path(r["shape"]).name, str(r["sides"]), str(r["templates"]), f"{r['feasible']} / {r['requests']}",
                      f"{r['solver_checked']}{' (all)' if r['solver_checked_all'] else ''}",
                      f"{r['placed']['feasible']} + {r['placed']['infeasible']} refused", str(len(r["failures"])),
                      f"{r['seconds']:.0f}")
    out.print(table)
    if report is not None:
        write_text_atomic(report, json.dumps({"max": cap, "limit": limit, "shapes": rows}, indent=1) + "\n")
    if any(r["failures"] for r in rows):
        out.print(f"FAILURES: {sum(len(r['failures']) for r in rows)} (see the JSON report)")
        raise typer.Exit(1)


if __name__ == "__main__":
    run_typer(app)
