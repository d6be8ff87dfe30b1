"""The lean curve floors of ``jaxmatch/placement/layout.py`` (``curve_floors(..., lean=True)``,
``lean_curve_floors``, ``chord_piece_areas``): the curved sides' share of the area budget
allocated where it pays and by sign. Areas are measured here, independently of the package: the
region's with shapely, the chords' and the quads' with the shoelace formula (numpy)."""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.defaults import QUALITY
from jaxmatch.meshing.region import canonical, load_region
from jaxmatch.placement.floors import CURVE_SHARE, chord_area_error, chord_piece_areas, curve_floors, lean_curve_floors
from jaxmatch.placement.layout import layout_sides
from jaxmatch.placement.rings import ring_layout
from jaxmatch.placement.solve import mesh_layout
from jaxmatch.scoring.lattice import load_lattice

PARTS = Path(__file__).resolve().parent.parent / "examples" / "parts"
CURVED = ("slotted-link", "plate-3-holes", "keyhole")


def _signed(p: np.ndarray) -> float:
    """Signed shoelace area of the closed polygon ``p (k, 2)`` (counter-clockwise positive)."""
    return 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def _even(poly: np.ndarray, n: int) -> np.ndarray:
    """``n + 1`` points evenly spaced by arc length along ``poly (k, 2)`` (numpy interpolation)."""
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])
    t = np.linspace(0.0, cum[-1], n + 1)
    return np.stack([np.interp(t, cum, poly[:, 0]), np.interp(t, cum, poly[:, 1])], axis=1)


def _arc(r: float, a0: float, a1: float, k: int = 60, centre=(0.0, 0.0)) -> np.ndarray:
    """``(k, 2)`` points of the circle of radius ``r`` from angle ``a0`` to ``a1`` (radians)."""
    t = np.linspace(a0, a1, k)
    return np.stack([centre[0] + r * np.cos(t), centre[1] + r * np.sin(t)], axis=1)


@functools.lru_cache(maxsize=None)
def _part(name: str, fraction: int = 40):
    """``(layout, sides, h)``: the ring partition of the part ``name`` at h = outer perimeter / fraction."""
    truth = json.loads((PARTS / "truth" / f"{name}.json").read_text())
    h = truth["outer_perimeter"] / fraction
    lay = ring_layout(canonical(load_region(PARTS / f"{name}.json"), h), h)
    return lay, layout_sides(lay), h


@settings(max_examples=40, deadline=None)
@given(pts=st.lists(st.tuples(st.floats(-10, 10), st.floats(-10, 10)), min_size=3, max_size=25),
       n=st.integers(1, 30))
def test_the_pieces_signed_areas_add_up_to_the_area_between_polyline_and_chords(pts, n):
    """Their absolute values add up to ``chord_area_error``; their sum is the signed area of the
    polygon that runs along the polyline and back along its chords."""
    p = np.asarray(pts, np.float64)
    a = chord_piece_areas(p, n)
    assert a.shape == (n,)
    scale = 1.0 + float(np.abs(p).max()) ** 2 * len(p)
    assert np.sum(np.abs(a)) == pytest.approx(chord_area_error(p, n), abs=1e-9 * scale)
    ring = np.vstack([p, _even(p, n)[::-1][1:-1]])
    assert np.sum(a) == pytest.approx(_signed(ring), abs=1e-9 * scale)


@pytest.mark.parametrize("ccw", [True, False])
def test_a_convex_stretch_loses_area_and_a_concave_one_adds_it(ccw):
    """Along a counter-clockwise arc (the region on its left: the outline of a disk) every chord
    cuts area off: positive pieces; clockwise (a hole's side, the region on its left) every chord
    adds area: negative, of the circle's segment area ``r^2 (t - sin t) / 2`` each."""
    arc = _arc(5.0, 0.0, math.pi / 2, 400) if ccw else _arc(5.0, math.pi / 2, 0.0, 400)
    a = chord_piece_areas(arc, 3)
    t = math.pi / 6
    assert np.all(a > 0) if ccw else np.all(a < 0)
    assert np.abs(a) == pytest.approx(25.0 * (t - math.sin(t)) / 2, rel=1e-3)


def test_a_small_hole_keeps_its_size_count_and_the_budget_goes_to_the_long_arc():
    """A long convex arc (radius 100, a quarter) and a small hole (radius 2, four quarters) at
    size 10: the hole's chords add 4.6 units^2 at one edge a quarter, within the budget of 5 (the
    added area is a sign group of its own), so the hole keeps its size count (1); the long arc
    takes edges beyond its size count (16) until its lost area fits the budget, and one edge
    fewer would not fit it."""
    arc = _arc(100.0, 0.0, math.pi / 2, 400)
    hole = [_arc(2.0, math.pi / 2 * (4 - i), math.pi / 2 * (3 - i), 40, (50.0, 50.0)) for i in range(4)]
    budget, h = 5.0, 10.0
    n = lean_curve_floors([arc] + hole, budget, h)
    assert n[1:].tolist() == [1, 1, 1, 1]
    assert sum(chord_area_error(c, 1) for c in hole) <= budget
    assert n[0] > round(arc_length := 50 * math.pi / h) and arc_length > 15
    assert chord_area_error(arc, int(n[0])) <= budget < chord_area_error(arc, int(n[0]) - 1)
    assert (lean_curve_floors([arc] + hole, budget) >= 1).all()  # (without a size: from one edge)


@pytest.mark.parametrize("name", CURVED)
@settings(max_examples=15, deadline=None)
@given(extra=st.lists(st.integers(0, 4), min_size=64, max_size=64))
def test_chords_at_or_above_the_lean_floors_keep_the_region_area(name, extra):
    """The part's ring partition at P/40: each curved boundary side replaced by its chords at its
    lean floor or more edges; the patches' shoelace areas (shared sides cancel) add up to within
    ``CURVE_SHARE * area_tol`` of shapely's area of the region."""
    lay, sides, h = _part(name)
    floors = curve_floors(lay, sides, QUALITY.area_tol, lean=True, size=h)
    counts = floors + np.resize(np.asarray(extra), floors.shape)
    region = shapely.union_all([shapely.Polygon(lay.points[lp]) for lp in lay.patches]).area
    total = 0.0
    for ids, revs in zip(sides.patch_sides, sides.patch_reversed):
        loop = []
        for s, r in zip(np.concatenate(ids), np.concatenate(revs)):
            chain = lay.points[sides.chains[s]]
            pts = _even(chain, int(counts[s])) if sides.outer[s] and len(chain) > 2 else chain
            loop.append((pts[::-1] if r else pts)[:-1])
        total += _signed(np.vstack(loop))
    assert abs(total / region - 1.0) <= CURVE_SHARE * QUALITY.area_tol * (1 + 1e-9)


def test_the_slotted_link_uses_both_sign_groups():
    """At P/40 the slotted link's lean floors lose more area on its outline and add more on its
    holes than either alone could: the absolute errors add up to more than the budget, each sign
    group is within it, and the lean floors are at least the size counts."""
    lay, sides, h = _part("slotted-link")
    floors = curve_floors(lay, sides, QUALITY.area_tol, lean=True, size=h)
    region = shapely.union_all([shapely.Polygon(lay.points[lp]) for lp in lay.patches]).area
    budget = CURVE_SHARE * QUALITY.area_tol * region
    lost = added = absolute = 0.0
    for s in np.flatnonzero(sides.outer):
        chain = lay.points[sides.chains[s]]
        if len(chain) <= 2:
            continue
        a = chord_piece_areas(chain, int(floors[s]))
        lost, added, absolute = lost + a[a > 0].sum(), added - a[a < 0].sum(), absolute + chord_area_error(chain, int(floors[s]))
        assert floors[s] >= max(1, round(sides.lengths[s] / h))
    assert lost <= budget and added <= budget < absolute


@pytest.mark.parametrize("name", ["slotted-link", "plate-3-holes"])
def test_a_mesh_at_the_lean_floors_keeps_the_area(name, cat):
    """The ring partition meshed with the lean curves at P/40: the quads' shoelace areas add up
    to within ``area_tol`` of shapely's area of the region."""
    lay, _, h = _part(name)
    m = mesh_layout(lay, cat, load_lattice("fine"), size=h, lean_curves=True)
    xy, q = np.asarray(m.xy), np.asarray(m.quads)
    x, y = xy[q, 0], xy[q, 1]
    area = 0.5 * float(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y))
    region = shapely.union_all([shapely.Polygon(lay.points[lp]) for lp in lay.patches]).area
    assert abs(area / region - 1.0) <= QUALITY.area_tol
