#!/usr/bin/env python3
"""Tune a lattice's level weights and skip weights on labelled shapes.

    scripts/tune_lattice.py --labels examples/labels/synthetic-k3.jsonl --lattice lattices/fine.toml \\
        --out tuned.toml --report report.json [--epochs N] [--temperature G] [--seed S] \\
        [--heldout FRACTION] [--skip-bad] [--eval-labels examples/labels/designer-k3.jsonl] [--fixed-skip]

Trains with the soft scorer (softmax cross-entropy of the preferred mesh against the other
catalogue meshes of its size), rounds to integers, evaluates with the exact scorer before and
after on the training and held-out examples, and writes the tuned lattice (TOML, the input
file's comments kept) and a JSON report, both atomically. The finite skip weights (``[skip]``) are
tuned too unless ``--fixed-skip``; ``-inf`` ones stay ``-inf``. All logic lives in
jaxmatch/tuning/tune.py.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import List, Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from jaxmatch.catalogue.store import default_catalogue, load
from jaxmatch.cli import enable_compile_cache, run_typer
from jaxmatch.errors import InputError
from jaxmatch.files import write_text_atomic
from jaxmatch.tuning.labels import load_labels, mesh_index
from jaxmatch.scoring.lattice import BUILTIN_DIR, load_lattice, save_lattice

app = typer.Typer(add_completion=False)
out = Console(soft_wrap=True)
err = Console(stderr=True)


def _template(arg: str, source_name: str, command: str) -> str | None:
    """The input lattice's TOML text with a header line about the tuning, or None."""
    path = Path(arg)
    if not path.is_file():
        path = BUILTIN_DIR / f"{arg}.toml"
    if not path.is_file():
        return None
    head = (f"# Level weights tuned from lattice \"{source_name}\" by scripts/tune_lattice.py ({command}).\n"
            "# The comments below are the original design notes; the weights are the tuned ones\n"
            "# (a common positive scale of all weights changes no ranking).\n")
    return head + path.read_text(encoding="utf-8")


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}%"


@app.command()
def tune(
    labels: Path = typer.Option(..., help="labelled shapes, JSON lines (see jaxmatch/labels.py)"),
    lattice: str = typer.Option("fine", help="lattice to start from: built-in name or TOML path"),
    out_path: Path = typer.Option(..., "--out", help="tuned lattice TOML to write"),
    epochs: int = typer.Option(10, min=0, help="passes over the training examples"),
    temperature: float = typer.Option(1.0, help="soft-max temperature G of the soft scorer (weight units)"),
    seed: int = typer.Option(0, help="seed for the split, the shuffling and any candidate sample"),
    report: Optional[Path] = typer.Option(None, help="JSON report to write"),
    skip_bad: bool = typer.Option(False, "--skip-bad", help="skip bad label lines (reported) instead of stopping"),
    heldout: float = typer.Option(0.25, help="fraction of examples held out (split by preferred mesh)"),
    learning_rate: float = typer.Option(0.05, help="Adam step size (weight units)"),
    batch_size: int = typer.Option(32, min=1, help="examples per optimiser step"),
    l2: float = typer.Option(1e-3, min=0.0, help="pull towards the input weights (mean squared difference)"),
    max_candidates: int = typer.Option(256, min=2, help="competing meshes per size at most (larger sizes: deterministic sample)"),
    eval_labels: Optional[List[Path]] = typer.Option(None, "--eval-labels", help="more label files, evaluated only"),
    name: Optional[str] = typer.Option(None, help="name of the tuned lattice (default: <input>-tuned)"),
    catalogue: Optional[Path] = typer.Option(None, help="catalogue file (default: the shipped one)"),
    fixed_skip: bool = typer.Option(False, "--fixed-skip", help="keep the lattice's skip weights as they are"),
) -> None:
    """Tune the level and skip weights of a lattice on labelled shapes; write the lattice and a report."""
    from jaxmatch.tuning.tune import run_tuning

    if not (temperature > 0):
        raise InputError(f"must be a positive number, got {temperature}", where="--temperature")
    if not 0.0 <= heldout < 1.0:
        raise InputError(f"must be in [0, 1), got {heldout}", where="--heldout")
    enable_compile_cache()
    cat = default_catalogue() if catalogue is None else load(catalogue)
    index = mesh_index(cat)
    lat = load_lattice(lattice)
    loaded = load_labels(labels, index, skip_bad=skip_bad)
    for problem in loaded.problems:
        err.print(f"skipped: {problem}", highlight=False, soft_wrap=True)
    extra = {}
    for path in eval_labels or []:
        more = load_labels(path, index, skip_bad=skip_bad)
        for problem in more.problems:
            err.print(f"skipped: {problem}", highlight=False, soft_wrap=True)
        extra[str(path)] = more.examples
    err.print(f"{len(loaded.examples)} examples from {labels}; lattice {lat.name}; held out {heldout:g}; seed {seed}")

    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TextColumn("loss {task.fields[loss]}"),
                  TimeElapsedColumn(), TimeRemainingColumn(), console=err, transient=False) as bar:
        task = bar.add_task("tuning", total=None, loss="-")

        def progress(step: int, total: int, loss: float) -> None:
            bar.update(task, completed=step, total=total, loss=f"{loss:.4f}")

        def stage(text: str) -> None:
            bar.update(task, description=text)

        tuned, rep = run_tuning(
            lat, loaded.examples, cat, heldout=heldout, seed=seed, epochs=epochs, temperature=temperature,
            learning_rate=learning_rate, batch_size=batch_size, l2=l2, max_candidates=max_candidates,
            name=name, extra=extra, progress=progress, stage=stage, tune_skip=not fixed_skip,
        )
    command = " ".join(["scripts/tune_lattice.py", *sys.argv[1:]])
    rep["command"] = command
    rep["labels"] = {"file": str(labels), "examples": len(loaded.examples), "skipped": [str(p) for p in loaded.problems]}
    rep["lattice"]["input_file"] = lattice
    rep["lattice"]["output_file"] = str(out_path)
    save_lattice(tuned, out_path, template=_template(lattice, lat.name, command))
    load_lattice(out_path)  # what was written loads
    if report is not None:
        write_text_atomic(report, json.dumps(rep, indent=2) + "\n")

    table = Table(title=f"exact-scorer accuracy, {lat.name} -> {tuned.name} (scale {rep['scale']})")
    for col in ("set", "examples", "top-1 before", "top-1 after", "top-5 before", "top-5 after"):
        table.add_column(col, justify="right" if col != "set" else "left")
    for key in ["train", "heldout", *extra]:
        b, a = rep[key]["before"], rep[key]["after"]
        table.add_row(key, str(b["examples"]), _pct(b["top1"]), _pct(a["top1"]), _pct(b["top5"]), _pct(a["top5"]))
    out.print(table)
    out.print("skip weights s/x/v: " + " -> ".join("/".join("-inf" if v is None else str(v) for v in rep["weights"][w]["skip"].values())
                                                  for w in ("before", "after")))
    out.print(f"wrote {out_path}" + (f" and {report}" if report is not None else "") + f" ({rep['seconds']} s)")


def main() -> None:
    """Bad input: one line on stderr, exit 2 (as the jaxmatch command)."""
    run_typer(app)


if __name__ == "__main__":
    main()
