#!/usr/bin/env python3
"""Write the dense and noisy outlines of ``examples/dense/`` (jaxmatch JSON, corners detected).

    .venv/bin/python scripts/make_dense_examples.py [--out examples/dense]

A coastline-like loop (2,500 points: a radius with random harmonics and noise, seeded), a font
glyph's outer ring (DejaVu Sans "G", curves sampled densely by matplotlib), a circle and an
ellipse of 1,000 points, an L-shape with 1,000 points on its straight sides, a square whose
sides wiggle by 0.2 % (2,000 points) and the 20 x 1 parallelogram sheared by 3 (turns of 18
degrees at two corners).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import typer

from jaxmatch.cli import run_typer

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def coastline(n: int = 2500, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = 2 * np.pi * np.arange(n) / n
    r = np.ones(n)
    for k in range(2, 40):
        r += rng.normal(0, 0.25 / k ** 1.2) * np.cos(k * t + rng.uniform(0, 2 * np.pi))
    r += rng.normal(0, 0.002, n)
    return np.c_[r * np.cos(t), r * np.sin(t)] * 10


def glyph(ch: str = "G", size: float = 10.0) -> np.ndarray:
    import shapely
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), ch, size=size, prop=FontProperties(family="DejaVu Sans")).interpolated(24)
    rings = [np.asarray(p[:-1], float) for p in path.to_polygons(closed_only=True) if len(p) > 3]
    ring = max(rings, key=lambda r: abs(shapely.Polygon(r).area))
    keep = np.ones(len(ring), bool)
    keep[1:] = np.linalg.norm(np.diff(ring, axis=0), axis=1) > 1e-9
    return ring[keep]


def on_sides(corners: np.ndarray, n: int) -> np.ndarray:
    """``n`` points on the closed polygon ``corners``, its corners among them, evenly by length."""
    seg = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    per = seg.sum()
    out = []
    for i, (a, L) in enumerate(zip(corners, seg)):
        b = corners[(i + 1) % len(corners)]
        k = max(1, int(round(n * L / per)))
        out += [a + (b - a) * j / k for j in range(k)]
    return np.asarray(out)


def wiggly_square(n: int = 2000, amp: float = 0.002, seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pts = on_sides(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float), n)
    corner = np.any(np.all(np.isin(pts, [0.0, 1.0]), axis=1)[:, None], axis=1)
    normal = np.zeros_like(pts)
    normal[np.isclose(pts[:, 1], 0)] = [0, 1]
    normal[np.isclose(pts[:, 0], 1)] = [-1, 0]
    normal[np.isclose(pts[:, 1], 1)] = [0, -1]
    normal[np.isclose(pts[:, 0], 0)] = [1, 0]
    wiggle = amp * np.sin(np.arange(len(pts)) * 0.7) + rng.normal(0, amp / 4, len(pts))
    out = pts + normal * wiggle[:, None]
    out[corner] = pts[corner]
    return out * 10


def outlines() -> dict[str, np.ndarray]:
    t = 2 * np.pi * np.arange(1000) / 1000
    return {
        "coastline": coastline(),
        "glyph-G": glyph("G"),
        "circle-1000": np.c_[5 * np.cos(t), 5 * np.sin(t)],
        "ellipse-1000": np.c_[8 * np.cos(t), 3 * np.sin(t)],
        "lshape-1000": on_sides(np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]], float), 1000),
        "wiggly-square": wiggly_square(),
        "parallelogram": np.array([[0, 0], [20, 0], [23, 1], [3, 1]], float),
    }


@app.command()
def main(out: Path = typer.Option(Path("examples/dense"), help="Folder to write the outlines to.")) -> None:
    from jaxmatch.files import write_text_atomic

    out.mkdir(parents=True, exist_ok=True)
    for name, pts in outlines().items():
        write_text_atomic(out / f"{name}.json", json.dumps({"boundary": np.round(pts, 9).tolist()}) + "\n")
        print(f"wrote {out / f'{name}.json'}: {len(pts)} points")


if __name__ == "__main__":
    run_typer(app)
