#!/usr/bin/env python3
"""Compare lattices on what the shipped default must do well (how ``lattices/fine.toml`` was chosen).

    scripts/compare_lattices.py LATTICE... [--ks 1..4] [--labels examples/labels/designer-k3.jsonl ...]
        [--shapes examples/*.json examples/labels/shapes/*.json] [--json report.json]

For each lattice (built-in name or TOML path):

* **corners** (:func:`jaxmatch.tuning.corners.corner_report`): over every shape with corners and
  every size k, does the rank-1 mesh (``jaxmatch score --internal k``, ties by id) give every
  ``x``/``v`` point a mesh vertex, where some size-k mesh can; and how many corners the rank-1
  meshes keep in all;
* **labels** (:func:`jaxmatch.tuning.tune.evaluate`, exact scorer): pessimistic top-1 / top-5 of
  the preferred mesh on each label file.

Prints a table; ``--json`` writes everything (atomically).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from jaxmatch.catalogue import store as cat_mod  # noqa: E402
from jaxmatch.cli import enable_compile_cache, run_typer  # noqa: E402
from jaxmatch.files import write_text_atomic  # noqa: E402
from jaxmatch.scoring.lattice import load_lattice  # noqa: E402
from jaxmatch.io.readers import load_shape  # noqa: E402

app = typer.Typer(add_completion=False)
out = Console(soft_wrap=True)

DEFAULT_SHAPES = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "examples").glob("*.json")) + \
    sorted(str(p.relative_to(ROOT)) for p in (ROOT / "examples" / "labels" / "shapes").glob("*.json"))
DEFAULT_LABELS = ["examples/labels/designer-k3.jsonl", "examples/labels/synthetic-k3.jsonl"]


@app.command()
def compare(
    lattices: List[str] = typer.Argument(..., help="lattices: built-in names or TOML paths"),
    ks: str = typer.Option("1..4", help="sizes K or K1..K2 for the corner measure"),
    shapes: Optional[List[Path]] = typer.Option(None, "--shapes", help="shape files (default: examples/ and examples/labels/shapes/)"),
    labels: Optional[List[Path]] = typer.Option(None, "--labels", help="label files (default: designer-k3 and synthetic-k3)"),
    json_path: Optional[Path] = typer.Option(None, "--json", help="write the full report here"),
) -> None:
    """Corner keeping and label accuracy of each lattice."""
    from jaxmatch.tuning.corners import corner_report
    from jaxmatch.tuning.labels import load_labels, mesh_index
    from jaxmatch.tuning.tune import evaluate

    enable_compile_cache()
    cat = cat_mod.default_catalogue()
    k_list = cat_mod.parse_range(ks)
    files = [ROOT / p for p in DEFAULT_SHAPES] if not shapes else list(shapes)
    shp = [(p.stem if p.parent.name != "shapes" else f"labels/{p.stem}", load_shape(p)) for p in files]
    index = mesh_index(cat)
    label_sets = {Path(p).stem: load_labels(ROOT / p if not Path(p).is_absolute() else Path(p), index).examples
                  for p in (labels or DEFAULT_LABELS)}
    report = {}
    table = Table(title=f"rank-1 corner keeping (k in {k_list[0]}..{k_list[-1]}) and label accuracy (pessimistic)")
    for col in ("lattice", "skip s/x/v", "keeps all corners", "corners kept", *[f"{n} top-1/top-5" for n in label_sets]):
        table.add_column(col, justify="right")
    for name in lattices:
        lat = load_lattice(name)
        c = corner_report(shp, cat, lat, k_list)
        acc = {n: evaluate(ex, index, lat) for n, ex in label_sets.items()}
        report[name] = {"skip": lat.weights().skip_json(), "corners": c, "labels": acc}
        skip = "/".join("-inf" if v is None else str(v) for v in lat.weights().skip_json().values())
        table.add_row(name, skip, f"{c['top_keeps_all']}/{c['possible']}", f"{c['corners_kept']}/{c['corners']}",
                      *[f"{100 * a['top1']:.1f}% / {100 * a['top5']:.1f}%" for a in acc.values()])
        print(f"{name}: missed {c['missed']}", file=sys.stderr, flush=True)
    out.print(table)
    if json_path is not None:
        write_text_atomic(json_path, json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    run_typer(app)
