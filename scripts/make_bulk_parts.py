#!/usr/bin/env python3
"""Write random star-shaped parts for the bulk-meshing benchmark (jaxmatch JSON, fixed seed).

    .venv/bin/python scripts/make_bulk_parts.py --out parts [--count 300] [--seed 38]

Part ``i`` has 5-14 corners: angles drawn around its centre and sorted (each gap at least a
sixth of the even one), radii uniform in [0.45, 1] times a scale drawn in [1, 10], so every
corner sees the centre (star-shaped), with convex and concave corners mixed. Every third part
(``i % 3 == 0``) gets a round hole about the centre: a polygon of 32 points (no corners) whose
radius is a quarter to a half of the centre's distance to the outline. The same seed and count
give the same files, byte for byte.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import shapely
import typer

from jaxmatch.cli import run_typer
from jaxmatch.files import write_text_atomic

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)

HOLE_POINTS = 32
"""Points of a round hole's polygon."""


def star_part(rng: np.random.Generator, with_hole: bool) -> dict:
    """One part as ``{"boundary": [[x, y], ...] (n, 2), "holes": [...]}`` (counter-clockwise,
    coordinates rounded to 9 decimals; the units are arbitrary)."""
    n = int(rng.integers(5, 15))
    gaps = rng.uniform(1.0 / 6.0, 1.0, size=n)
    angles = 2 * np.pi * np.cumsum(gaps) / gaps.sum() + rng.uniform(0, 2 * np.pi)
    radii = rng.uniform(0.45, 1.0, size=n) * rng.uniform(1.0, 10.0)
    centre = rng.uniform(-20, 20, size=2)
    boundary = np.round(centre + np.c_[radii * np.cos(angles), radii * np.sin(angles)], 9)
    doc = {"boundary": boundary.tolist()}
    if with_hole:
        clearance = shapely.Polygon(boundary).exterior.distance(shapely.Point(centre))
        r = clearance * rng.uniform(0.25, 0.5)
        t = 2 * np.pi * np.arange(HOLE_POINTS) / HOLE_POINTS
        doc["holes"] = [np.round(centre + r * np.c_[np.cos(t), np.sin(t)], 9).tolist()]
    return doc


def parts(count: int = 300, seed: int = 38) -> list[dict]:
    """``count`` parts from one generator seeded with ``seed``; every third has a round hole."""
    rng = np.random.default_rng(seed)
    return [star_part(rng, i % 3 == 0) for i in range(count)]


@app.command()
def main(out: Path = typer.Option(..., help="Folder to write part-NNN.json to."),
         count: int = typer.Option(300, min=1, help="Number of parts."),
         seed: int = typer.Option(38, help="Seed of the random generator.")) -> None:
    out.mkdir(parents=True, exist_ok=True)
    docs = parts(count, seed)
    for i, doc in enumerate(docs):
        write_text_atomic(out / f"part-{i:03d}.json", json.dumps(doc) + "\n")
    print(f"wrote {count} parts to {out} ({sum('holes' in d for d in docs)} with a round hole)")


if __name__ == "__main__":
    run_typer(app)
