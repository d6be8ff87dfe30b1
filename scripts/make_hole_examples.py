#!/usr/bin/env python3
"""Write the regions with holes of ``examples/holes/`` (jaxmatch JSON with ``"holes"``).

    .venv/bin/python scripts/make_hole_examples.py [--out examples/holes]

Plates with bolt holes, a washer, frames, a gasket, a bracket, a hexagon nut and letters of
matplotlib's DejaVu Sans font (``matplotlib.textpath.TextPath``; the outer loop is the ring of
largest area, the others are its holes). Round holes are polygons of 48 points (no corners).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from jaxmatch.cli import run_typer

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def circle(cx: float, cy: float, r: float, n: int = 48) -> list[list[float]]:
    t = 2 * np.pi * np.arange(n) / n
    return np.round(np.c_[cx + r * np.cos(t), cy + r * np.sin(t)], 9).tolist()


def rect(x0: float, y0: float, x1: float, y1: float) -> list[list[float]]:
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def letter(ch: str, size: float = 10.0) -> dict:
    """The glyph ``ch`` as ``{"boundary", "holes"}``: TextPath's polygons, curves sampled by
    matplotlib, the largest ring the outer loop."""
    import shapely
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), ch, size=size, prop=FontProperties(family="DejaVu Sans"))
    rings = [np.asarray(p[:-1], float) for p in path.to_polygons(closed_only=True) if len(p) > 3]
    rings.sort(key=lambda r: -abs(shapely.Polygon(r).area))
    outer, holes = rings[0], rings[1:]
    return {"boundary": np.round(outer, 9).tolist(), "holes": [np.round(h, 9).tolist() for h in holes]}


def regions() -> dict[str, dict]:
    hexagon = [[np.cos(a), np.sin(a)] for a in np.pi / 3 * np.arange(6)]
    return {
        "plate-bolt": {"boundary": rect(0, 0, 4, 4), "holes": [circle(2, 2, 0.7)]},
        "washer": {"boundary": circle(0, 0, 2, 96), "holes": [circle(0, 0, 1)]},
        "frame": {"boundary": rect(0, 0, 4, 4), "holes": [rect(1, 1, 3, 3)]},
        "window": {"boundary": rect(0, 0, 5, 3), "holes": [rect(0.5, 0.5, 2.25, 2.5), rect(2.75, 0.5, 4.5, 2.5)]},
        "plate-two-holes": {"boundary": rect(0, 0, 6, 3), "holes": [circle(1.5, 1.5, 0.6), circle(4.5, 1.5, 0.6)]},
        "gasket": {"boundary": rect(0, 0, 6, 4), "holes": [circle(1, 1, 0.4), circle(5, 1, 0.4), circle(5, 3, 0.4),
                                                           circle(1, 3, 0.4), circle(3, 2, 0.8)]},
        "bracket": {"boundary": [[0, 0], [4, 0], [4, 1.5], [1.5, 1.5], [1.5, 4], [0, 4]],
                    "holes": [circle(0.75, 3.0, 0.4), circle(3.0, 0.75, 0.4)]},
        "nut": {"boundary": np.round(np.array(hexagon) * 2, 9).tolist(), "holes": [circle(0, 0, 1)]},
        "triangle-hole": {"boundary": [[0, 0], [6, 0], [3, 5]], "holes": [[[2, 1], [3, 2.6], [4, 1]]]},
        "letter-O": letter("O"),
        "letter-A": letter("A"),
        "letter-B": letter("B"),
    }


@app.command()
def main(out: Path = typer.Option(Path("examples/holes"), help="Folder to write the regions to.")) -> None:
    from jaxmatch.files import write_text_atomic

    out.mkdir(parents=True, exist_ok=True)
    for name, doc in regions().items():
        write_text_atomic(out / f"{name}.json", json.dumps(doc) + "\n")
        print(f"wrote {out / f'{name}.json'}: {len(doc['holes'])} hole(s)")


if __name__ == "__main__":
    run_typer(app)
