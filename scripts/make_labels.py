#!/usr/bin/env python3
"""Write label files for lattice tuning (JSON lines; see jaxmatch/labels.py).

    scripts/make_labels.py designer --shapes examples/labels/shapes --internal 3 --out examples/labels/designer-k3.jsonl
    scripts/make_labels.py synthetic --internal 3 --variants 2 --seed 0 --out examples/labels/synthetic-k3.jsonl

designer: label every shape file of a folder with the designer rule (jaxmatch.tuning.labels.design_ranking:
turning-function fit of the meshes' ideal outlines, then fewest irregular internal vertices, then id).
It never looks at a lattice. synthetic: perturbed ideal outlines of every catalogue mesh of size k,
labelled with their source mesh (jaxmatch.tuning.labels.synthetic_examples).
"""

from __future__ import annotations

import os
from pathlib import Path

import typer
from rich.console import Console

from jaxmatch.catalogue.store import default_catalogue, load
from jaxmatch.cli import run_typer
from jaxmatch.errors import InputError
from jaxmatch.files import write_text_atomic
from jaxmatch.tuning.labels import design_ranking, dump_labels, example_record, mesh_index, synthetic_examples
from jaxmatch.io.readers import load_shape

app = typer.Typer(add_completion=False, no_args_is_help=True, help=__doc__.split("\n\n")[0])
err = Console(stderr=True)


def _catalogue(path: Path | None):
    return default_catalogue() if path is None else load(path)


@app.command()
def designer(
    shapes: Path = typer.Option(Path("examples/labels/shapes"), metavar="FOLDER", help="folder of shape files (*.json, *.txt, *.csv)"),
    k: int = typer.Option(3, "--internal", min=0, metavar="K", help="mesh size (internal vertices), as jaxmatch's --internal"),
    out: Path = typer.Option(..., metavar="FILE", help="label file to write (JSON lines)"),
    tolerance: float = typer.Option(0.10, help="relative fit tolerance before regularity decides"),
    catalogue: Path = typer.Option(None, metavar="FILE", help="catalogue file (default: the shipped one)"),
) -> None:
    """Label each shape of a folder with the designer rule."""
    cat = _catalogue(catalogue)
    index = mesh_index(cat)
    files = sorted(p for p in shapes.iterdir() if p.suffix.lower() in (".json", ".txt", ".csv"))
    if not files:
        raise InputError("no shape files (*.json, *.txt, *.csv)", where=str(shapes))
    records = []
    base = out.resolve().parent
    for path in files:
        shape = load_shape(path)
        rows = design_ranking(shape, cat, k, index=index, tolerance=tolerance)
        best = rows[0]
        within = sum(r.within_tolerance for r in rows)
        note = (f"designer rule, k={k}: turning fit {best.distance:.3f} rad (best {min(r.distance for r in rows):.3f}), "
                f"{within} meshes within {tolerance:.0%}, {best.irregular} irregular internal vertices; "
                f"boundary valences {''.join(map(str, index.vals[best.mesh_id]))}")
        rel = os.path.relpath(path.resolve(), base)
        records.append(example_record(rel, best.mesh_id, rotation=best.rotation, reflected=best.reflected, note=note))
        err.print(f"{path.name:28s} {best.mesh_id}  {note}")
    write_text_atomic(out, dump_labels(records))
    err.print(f"wrote {len(records)} labels to {out}")


@app.command()
def synthetic(
    k: int = typer.Option(3, "--internal", min=0, metavar="K", help="mesh size (internal vertices), as jaxmatch's --internal"),
    variants: int = typer.Option(2, min=1, metavar="N", help="shapes per catalogue mesh (at least 1)"),
    seed: int = typer.Option(0, metavar="N", help="random seed (same seed, same file)"),
    out: Path = typer.Option(..., metavar="FILE", help="label file to write (JSON lines)"),
    catalogue: Path = typer.Option(None, metavar="FILE", help="catalogue file (default: the shipped one)"),
) -> None:
    """Perturbed outlines of every catalogue mesh of size k, labelled with their source."""
    cat = _catalogue(catalogue)
    records, skipped = synthetic_examples(cat, k, variants=variants, seed=seed)
    if not records:
        raise InputError(f"no labels: the catalogue has no mesh with {k} internal vertices that gives a valid outline "
                         f"(it has k = {', '.join(map(str, cat.internal))})", "--internal")
    write_text_atomic(out, dump_labels(records))
    if skipped:
        err.print(f"no valid outline for {len(set(skipped))} meshes: {' '.join(sorted(set(skipped)))}")
    err.print(f"wrote {len(records)} labels to {out}")


def main() -> None:
    """Bad input: one line on stderr, exit 2 (as the jaxmatch command)."""
    run_typer(app)


if __name__ == "__main__":
    main()
