#!/usr/bin/env python3
"""Write the engineering parts of ``examples/parts/`` (jaxmatch JSON) and their exact truth
(``examples/parts/truth/NAME.json``), the yardstick of ``scripts/parts_table.py``.

    .venv/bin/python scripts/make_parts.py [--out examples/parts]

Each part is built from exact geometry, piece by piece: straight sides (``line``: their end
points only) and curved stretches (``curve``: round holes, fillets, arcs, an airfoil, a cam,
sampled densely, at most 3 degrees of arc or of the curve's parameter per interval). The input
file holds ``boundary`` and ``holes`` only (no explicit ``corners``: the part as a user draws it);
the truth file holds what the measures need:

* ``area``: the region's exact area, from closed forms (circles, circular segments, fillets,
  the NACA 0012 thickness integral, the cam's Fourier coefficients), not from the polygon;
* ``outer_perimeter``: the perimeter of the boundary polygon of the input file (h = it / 40 ...);
* ``rings``: per ring (0 the boundary, then the holes in file order) its ``pieces``
  ``[kind, start, end]`` (point indices into that ring; a piece runs from ``start`` to ``end``
  forward, wrapping; ``end == start`` is a closed curve without corners) and its
  ``corners`` (point indices);
* ``corners``: the corner points ``[x, y]`` of all rings: every point where the outline turns
  by more than 30 degrees (:data:`CORNER_ANGLE`; measured on the polygon, a turn within 1e-7
  degrees of 30 is not a corner: a regular 12-gon turns by exactly 30 and has none).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import typer

from jaxmatch.cli import run_typer

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "examples" / "parts"
CORNER_ANGLE = 30.0
"""A point is a corner when the outline turns there by more than this many degrees."""
STEP = math.radians(3.0)
"""Largest sampling step of a curved stretch (radians of arc or of the curve's parameter)."""

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


@dataclass(frozen=True)
class Ring:
    """One closed ring: ``points (P, 2)`` (not repeated at the end), ``pieces`` as
    ``(kind, start, end)`` with kind ``"line"`` or ``"curve"``."""

    points: np.ndarray
    pieces: tuple


@dataclass(frozen=True)
class Part:
    """A part: ``outer`` ring, ``holes`` rings, exact ``area`` (user units squared), a one-line
    ``description``."""

    name: str
    description: str
    outer: Ring
    holes: tuple
    area: float

    @property
    def rings(self) -> tuple:
        return (self.outer, *self.holes)


class RingBuilder:
    """Build a ring piece by piece from a start point: :meth:`line` to a point, :meth:`curve`
    through sample points ending at a point; :meth:`close` joins the last point to the first."""

    def __init__(self, start):
        self.pts = [np.asarray(start, float)]
        self.kinds = []  # kind of the piece starting at each junction point
        self.starts = []

    def line(self, p):
        self.starts.append(len(self.pts) - 1)
        self.kinds.append("line")
        self.pts.append(np.asarray(p, float))
        return self

    def curve(self, samples):
        """``samples (k, 2)``: the curve's points after the current one, its end point last."""
        self.starts.append(len(self.pts) - 1)
        self.kinds.append("curve")
        self.pts.extend(np.asarray(samples, float))
        return self

    def close(self) -> Ring:
        """The ring: the last point must equal the first (the closing piece ends there)."""
        pts = np.asarray(self.pts)
        assert np.allclose(pts[-1], pts[0], atol=1e-9), (pts[-1], pts[0])
        pts = pts[:-1]
        n = len(pts)
        pieces = tuple((k, s % n, self.starts[(i + 1) % len(self.starts)] % n) for i, (k, s)
                       in enumerate(zip(self.kinds, self.starts)))
        return Ring(pts, pieces)


def arc(cx, cy, r, a0, a1, *, include_start=False) -> np.ndarray:
    """Points of the arc of centre ``(cx, cy)``, radius ``r`` from angle ``a0`` to ``a1``
    (radians, either direction), at most :data:`STEP` apart; the end point last, the start point
    only with ``include_start``."""
    n = max(2, math.ceil(abs(a1 - a0) / STEP))
    t = np.linspace(a0, a1, n + 1)
    t = t if include_start else t[1:]
    return np.c_[cx + r * np.cos(t), cy + r * np.sin(t)]


def circle_ring(cx, cy, r) -> Ring:
    """A round hole (or disk) without corners: one closed curve, anticlockwise from angle 0."""
    pts = arc(cx, cy, r, 0.0, 2 * math.pi, include_start=True)[:-1]
    return Ring(pts, (("curve", 0, 0),))


def polygon_ring(points) -> Ring:
    """A straight-sided ring: every point the end of a line."""
    pts = np.asarray(points, float)
    n = len(pts)
    return Ring(pts, tuple(("line", i, (i + 1) % n) for i in range(n)))


def shoelace(points) -> float:
    """Signed area of a polygon ``(P, 2)`` (anticlockwise positive)."""
    x, y = np.asarray(points, float).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def disk_strip(r: float, a: float) -> float:
    """Area of the part of the half disk ``y >= 0`` of radius ``r`` with ``|x| <= a``
    (``a <= r``): ``a sqrt(r^2 - a^2) + r^2 asin(a / r)``."""
    return a * math.sqrt(r * r - a * a) + r * r * math.asin(a / r)


def turns(points: np.ndarray) -> np.ndarray:
    """Turning angle at each point of a closed polygon, degrees in ``[0, 180]``."""
    d_in = points - np.roll(points, 1, axis=0)
    d_out = np.roll(points, -1, axis=0) - points
    cross = d_in[:, 0] * d_out[:, 1] - d_in[:, 1] * d_out[:, 0]
    dot = np.sum(d_in * d_out, axis=1)
    return np.degrees(np.abs(np.arctan2(cross, dot)))


def corner_indices(ring: Ring) -> list[int]:
    """Points of ``ring`` turning by more than :data:`CORNER_ANGLE` (+ 1e-7) degrees."""
    return [int(i) for i in np.flatnonzero(turns(ring.points) > CORNER_ANGLE + 1e-7)]


# ---------------------------------------------------------------------------------------------
# the parts


def plate() -> Part:
    holes = ((22.0, 30.0, 10.0), (55.0, 20.0, 6.0), (78.0, 40.0, 8.0))
    return Part("plate-3-holes", "plate 100 x 60 with three round holes (r 10, 6, 8)",
                polygon_ring([[0, 0], [100, 0], [100, 60], [0, 60]]),
                tuple(circle_ring(*c) for c in holes), 6000.0 - math.pi * sum(r * r for *_, r in holes))


def flange() -> Part:
    bolts = tuple(circle_ring(35 * math.cos(a), 35 * math.sin(a), 4.0) for a in np.arange(6) * math.pi / 3)
    return Part("flange", "flange: disk r 50, bore r 15, six bolt holes r 4 on a 35 bolt circle",
                circle_ring(0, 0, 50.0), (circle_ring(0, 0, 15.0), *bolts), math.pi * (2500 - 225 - 6 * 16))


def l_bracket() -> Part:
    b = RingBuilder([0, 0]).line([80, 0]).line([80, 20]).line([30, 20])
    b.curve(arc(30, 30, 10, -math.pi / 2, -math.pi)).line([20, 60]).line([0, 60]).line([0, 0])
    return Part("l-bracket", "L-bracket 80 x 60, legs 20 thick, inner corner filleted r 10, a hole r 6",
                b.close(), (circle_ring(55, 10, 6.0),), 80 * 20 + 20 * 40 + (100 - 25 * math.pi) - 36 * math.pi)


def clevis() -> Part:
    b = RingBuilder([10, 0]).line([70, 0]).curve(arc(70, 10, 10, -math.pi / 2, 0)).line([80, 50]).line([55, 50])
    b.line([55, 26]).curve(arc(49, 26, 6, 0, -math.pi / 2)).line([31, 20])
    b.curve(arc(31, 26, 6, -math.pi / 2, -math.pi)).line([25, 50]).line([0, 50]).line([0, 10])
    b.curve(arc(10, 10, 10, math.pi, 1.5 * math.pi))
    area = 80 * 50 - 30 * 30 - 2 * (100 - 25 * math.pi) + 2 * (36 - 9 * math.pi) - 2 * 25 * math.pi
    return Part("clevis", "U-bracket 80 x 50, slot 30 x 30, outer fillets r 10, slot fillets r 6, two holes r 5",
                b.close(), (circle_ring(12.5, 35, 5.0), circle_ring(67.5, 35, 5.0)), area)


def gear() -> Part:
    teeth, r_root, r_tip = 20, 40.0, 48.0
    pitch = 2 * math.pi / teeth
    pts = []
    for k in range(teeth):
        a = k * pitch
        pts += [[r_root * math.cos(a - 0.27 * pitch), r_root * math.sin(a - 0.27 * pitch)],
                [r_tip * math.cos(a - 0.13 * pitch), r_tip * math.sin(a - 0.13 * pitch)],
                [r_tip * math.cos(a + 0.13 * pitch), r_tip * math.sin(a + 0.13 * pitch)],
                [r_root * math.cos(a + 0.27 * pitch), r_root * math.sin(a + 0.27 * pitch)]]
    r, w, top = 12.0, 2.5, 15.0  # bore radius, keyway half width, keyway top (y)
    yc = math.sqrt(r * r - w * w)
    a0 = math.atan2(yc, w)
    b = RingBuilder([w, yc]).line([w, top]).line([-w, top]).line([-w, yc])
    b.curve(arc(0, 0, r, math.pi - a0, 2 * math.pi + a0))
    bore = r * r * math.pi + 2 * w * top - disk_strip(r, w)
    return Part("gear", "20-tooth gear (trapezoid teeth, 80 tooth corners), bore r 12 with a 5 x 3 keyway",
                polygon_ring(pts), (b.close(),), shoelace(pts) - bore)


def naca() -> Part:
    c = 100.0
    beta = np.linspace(0.0, math.pi, 101)
    x = 0.5 * (1 - np.cos(beta))  # 0 (leading edge) .. 1 (trailing edge)
    yt = 0.6 * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)
    upper = np.c_[c * x, c * yt][::-1]  # trailing edge -> leading edge
    lower = np.c_[c * x, -c * yt][1:]   # leading edge (excluded) -> trailing edge
    lower[-1] = upper[0]
    foil = RingBuilder(upper[0]).curve(np.r_[upper[1:], lower]).close()
    integral = 0.2969 * 2 / 3 - 0.1260 / 2 - 0.3516 / 3 + 0.2843 / 4 - 0.1036 / 5
    return Part("naca0012", "NACA 0012 (chord 100, closed trailing edge) as a hole in a 200 x 100 far-field box",
                polygon_ring([[-50, -50], [150, -50], [150, 50], [-50, 50]]), (foil,),
                200 * 100 - 2 * 0.6 * integral * c * c)


def heat_sink() -> Part:
    pts = [[0, 0], [60, 0], [60, 10]]
    for k in reversed(range(6)):
        x0 = 3.5 + 10 * k
        pts += [[x0 + 3, 10], [x0 + 3, 40], [x0, 40], [x0, 10]]
    pts.append([0, 10])
    return Part("heat-sink", "heat sink: base 60 x 10, six fins 3 wide x 30 tall",
                polygon_ring(pts), (), 600.0 + 6 * 90.0)


def keyhole() -> Part:
    r, w, bottom, cx, cy = 10.0, 4.0, 20.0, 30.0, 50.0
    yc = math.sqrt(r * r - w * w)
    a0 = math.atan2(-yc, w)  # the junction on the right side of the slot
    b = RingBuilder([cx + w, cy - yc]).curve(arc(cx, cy, r, a0, math.pi - a0))
    b.line([cx - w, bottom]).line([cx + w, bottom]).line([cx + w, cy - yc])
    hole = math.pi * r * r + 2 * w * (cy - bottom) - disk_strip(r, w)
    return Part("keyhole", "plate 60 x 80 with a keyhole: circle r 10 and a slot 8 wide down to y 20",
                polygon_ring([[0, 0], [60, 0], [60, 80], [0, 80]]), (b.close(),), 4800.0 - hole)


def regular(n: int) -> Part:
    pts = [[50 * math.cos(2 * math.pi * k / n), 50 * math.sin(2 * math.pi * k / n)] for k in range(n)]
    return Part(f"{n}-gon", f"regular {n}-gon, circumradius 50", polygon_ring(pts), (), shoelace(pts))


def star() -> Part:
    pts = [[(50 if k % 2 == 0 else 25) * math.cos(math.pi * k / 8), (50 if k % 2 == 0 else 25) * math.sin(math.pi * k / 8)]
           for k in range(16)]
    return Part("star-8", "8-pointed star, radii 50 and 25", polygon_ring(pts), (), shoelace(pts))


def channel() -> Part:
    b = RingBuilder([40, 0]).line([60, 0]).curve(arc(0, 0, 60, 0, math.pi / 2)).line([0, 40])
    b.curve(arc(0, 0, 40, math.pi / 2, 0))
    return Part("channel", "curved channel: annular sector, radii 40 and 60, 90 degrees",
                b.close(), (), 0.5 * (math.pi / 2) * (3600 - 1600))


def cam() -> Part:
    t = np.arange(0, 2 * math.pi, STEP)
    r = 30 + 10 * np.cos(t) + 2 * np.cos(2 * t)
    outer = Ring(np.c_[r * np.cos(t), r * np.sin(t)], (("curve", 0, 0),))
    return Part("cam", "cam r = 30 + 10 cos t + 2 cos 2t with a bore r 8",
                outer, (circle_ring(0, 0, 8.0),), math.pi * (900 + 50 + 2) - 64 * math.pi)


def slotted_link() -> Part:
    R = 15.0
    b = RingBuilder([0, -R]).line([80, -R]).curve(arc(80, 0, R, -math.pi / 2, math.pi / 2)).line([0, R])
    b.curve(arc(0, 0, R, math.pi / 2, 1.5 * math.pi))
    s = RingBuilder([35, -5]).line([65, -5]).curve(arc(65, 0, 5, -math.pi / 2, math.pi / 2)).line([35, 5])
    s.curve(arc(35, 0, 5, math.pi / 2, 1.5 * math.pi))
    area = 80 * 30 + math.pi * R * R - 36 * math.pi - (30 * 10 + 25 * math.pi)
    return Part("slotted-link", "link 110 x 30 with rounded ends, a round hole r 6 and a slot 40 x 10",
                b.close(), (circle_ring(0, 0, 6.0), s.close()), area)


def web_plate() -> Part:
    return Part("web-plate", "plate 80 x 40 with two holes r 12, 2 apart (a thin web)",
                polygon_ring([[0, 0], [80, 0], [80, 40], [0, 40]]),
                (circle_ring(27, 20, 12.0), circle_ring(53, 20, 12.0)), 3200.0 - 2 * 144 * math.pi)


PARTS = (plate, flange, l_bracket, clevis, gear, naca, heat_sink, keyhole, lambda: regular(12), lambda: regular(6),
         star, channel, cam, slotted_link, web_plate)
"""Builders of the parts, in table order."""


def parts() -> list[Part]:
    """Every part, in table order."""
    return [f() for f in PARTS]


def perimeter(points: np.ndarray) -> float:
    """Length of the closed polygon ``points (P, 2)``."""
    return float(np.sum(np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)))


def documents(part: Part) -> tuple[dict, dict]:
    """The input document (jaxmatch JSON) and the truth document of ``part``."""
    doc = {"boundary": part.outer.points.tolist(), "holes": [h.points.tolist() for h in part.holes]}
    if not part.holes:
        del doc["holes"]
    rings = [{"pieces": [list(p) for p in r.pieces], "corners": corner_indices(r)} for r in part.rings]
    corners = [r.points[i].tolist() for r, info in zip(part.rings, rings) for i in info["corners"]]
    truth = {"name": part.name, "description": part.description, "area": part.area,
             "outer_perimeter": perimeter(part.outer.points), "corner_angle": CORNER_ANGLE,
             "corners": corners, "rings": rings}
    return doc, truth


@app.command()
def main(out: Path = typer.Option(OUT, help="Folder to write the parts to (truth files in OUT/truth).")) -> None:
    from jaxmatch.files import write_text_atomic

    (out / "truth").mkdir(parents=True, exist_ok=True)
    for part in parts():
        doc, truth = documents(part)
        write_text_atomic(out / f"{part.name}.json", json.dumps(doc) + "\n")
        write_text_atomic(out / "truth" / f"{part.name}.json", json.dumps(truth, indent=1) + "\n")
        n = sum(len(r.points) for r in part.rings)
        print(f"wrote {out / part.name}.json: {len(part.holes)} hole(s), {n} points, "
              f"{len(truth['corners'])} corners, area {part.area:.4f}")


if __name__ == "__main__":
    run_typer(app)
