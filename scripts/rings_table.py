"""Regular polygons meshed with and without the ring partition (``"rings"``), measured from the
mesh's points and quads: quads, min scaled Jacobian, longest edge / h, share of edges within
[0.5h, 1.5h]. Usage: python scripts/rings_table.py [--sides 6,8,12,16] [--divisions 40,80]"""

from __future__ import annotations

import argparse
import math

import numpy as np

import jaxmatch
from jaxmatch.meshing.pipeline import strategy_names
from jaxmatch.shape import make_shape


def edges_over_h(xy: np.ndarray, quads: np.ndarray, h: float) -> np.ndarray:
    e = np.concatenate([quads[:, [0, 1]], quads[:, [1, 2]], quads[:, [2, 3]], quads[:, [3, 0]]])
    e = np.unique(np.sort(e, axis=1), axis=0)
    return np.linalg.norm(xy[e[:, 0]] - xy[e[:, 1]], axis=1) / h


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sides", default="6,8,12,16")
    ap.add_argument("--divisions", default="40,80")
    a = ap.parse_args()
    without = tuple(n for n in strategy_names() if n != "rings")
    print("| polygon | P/h | strategies | chosen | quads | min SJ | longest / h | in [0.5h, 1.5h] |")
    print("|---|---:|---|---|---:|---:|---:|---:|")
    for n in map(int, a.sides.split(",")):
        t = 2 * math.pi * np.arange(n) / n
        pts = np.stack([10 * np.cos(t), 10 * np.sin(t)], axis=1)
        per = float(np.sum(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1)))
        for div in map(int, a.divisions.split(",")):
            h = per / div
            for label, names in (("all", None), ("without rings", without)):
                m = jaxmatch.mesh(make_shape(pts), size=h, strategies=names)
                ln = edges_over_h(m.xy, m.quads, h)
                print(f"| {n}-gon | {div} | {label} | {m.chosen} | {len(m.quads)} | {m.min_scaled_jacobian:.3f} | "
                      f"{ln.max():.2f} | {np.mean((ln >= 0.5) & (ln <= 1.5)):.2f} |")


if __name__ == "__main__":
    main()
