"""Decomposition of concave shapes (:mod:`jaxmatch.placement.decompose`); the choice between one
template and the pieces is specified in tests/test_meshing.py.

Specification (geometry checked with plain numpy, independently of shapely and of the code):

* the pieces cover the shape exactly: their areas add up to the shape's area, and every corner
  of the shape is a corner of the layout;
* ``continuations`` cuts leave only convex pieces; a rectilinear shape becomes axis-aligned
  rectangles;
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from jaxmatch.errors import InputError
from jaxmatch.placement.decompose import STRATEGIES, _same, cut_segments, decompose, same_cuts, single_patch
from jaxmatch.io.readers import load_shape

ROOT = Path(__file__).resolve().parent.parent
EX, LAB = ROOT / "examples", ROOT / "examples" / "labels" / "shapes"
SHAPES = {"L": EX / "lshape.json", "T": EX / "tshape.json", "U": LAB / "ushape.json", "plus": EX / "plus.json",
          "Z": LAB / "zshape.json", "stairs": LAB / "stairs.json", "cross": LAB / "cross.json",
          "notched-rectangle": LAB / "notched-rectangle.json"}
RECTILINEAR = [k for k in SHAPES if k != "notched-rectangle"]


def area(p) -> float:
    p = np.asarray(p, float)
    return 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def turns(p) -> np.ndarray:
    """Cross product of the two edges at every point of a loop (> 0: left turn)."""
    p = np.asarray(p, float)
    a, b = p - np.roll(p, 1, axis=0), np.roll(p, -1, axis=0) - p
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


@pytest.mark.parametrize("strategy", STRATEGIES)
@pytest.mark.parametrize("name", list(SHAPES))
def test_pieces_cover_the_shape(name, strategy):
    shp = load_shape(SHAPES[name])
    lay = decompose(shp, strategy)
    whole = abs(area(shp.input_points))
    parts = [area(lay.points[loop]) for loop in lay.patches]
    assert all(a > 0 for a in parts)
    assert sum(parts) == pytest.approx(whole, rel=1e-12)
    corners = {tuple(c) for c in shp.input_points[shp.corners].tolist()}
    have = {tuple(p) for p in lay.points[lay.corner].tolist()}
    assert corners <= have
    n_concave = int((~shp.convex).sum())
    assert lay.n_patches > 1 if n_concave else lay.n_patches == 1


@pytest.mark.parametrize("name", list(SHAPES))
@pytest.mark.parametrize("strategy", ["continuations", "recursive"])
def test_pieces_are_convex(name, strategy):
    shp = load_shape(SHAPES[name])
    lay = decompose(shp, strategy)
    scale = float(np.ptp(lay.points, axis=0).max())
    for loop, pc in zip(lay.patches, lay.patch_corner):
        assert np.all(turns(lay.points[loop]) >= -1e-12 * scale ** 2)
        if name in RECTILINEAR:
            c = lay.points[loop][pc]  # the patch's corners (not its T-junction points)
            assert c.shape[0] == 4
            assert len(np.unique(c[:, 0])) == 2 and len(np.unique(c[:, 1])) == 2  # an axis-aligned rectangle


def test_cuts_start_at_concave_corners_and_end_on_the_outline():
    shp = load_shape(LAB / "notched-rectangle.json")
    concave = shp.input_points[shp.corners[~shp.convex]]
    for strategy, per_corner in (("continuations", 2), ("bisectors", 1)):
        cuts = cut_segments(shp, strategy)
        assert len(cuts) == per_corner * len(concave)
        for a, b in cuts:
            assert any(np.array_equal(a, c) for c in concave)
            assert b[1] == pytest.approx(0.0, abs=1e-12)  # the notch's cuts reach the bottom side


def test_convex_shape_is_one_patch():
    shp = load_shape(EX / "hexagon.json")
    lay = decompose(shp)
    assert lay.n_patches == 1 and np.array_equal(lay.points, single_patch(shp).points)


@st.composite
def polyominoes(draw):
    """Outline ``(k, 2)`` of a random simply connected union of unit cells (grown from one cell)."""
    import shapely

    cells = {(0, 0)}
    for _ in range(draw(st.integers(1, 7))):
        x, y = draw(st.sampled_from(sorted(cells)))
        dx, dy = draw(st.sampled_from([(1, 0), (-1, 0), (0, 1), (0, -1)]))
        cells.add((x + dx, y + dy))
    u = shapely.union_all([shapely.box(x, y, x + 1, y + 1) for x, y in cells]).simplify(0)
    assume(u.geom_type == "Polygon" and not u.interiors)
    return np.asarray(u.exterior.coords)[:-1]


@settings(max_examples=40)
@given(outline=polyominoes(), strategy=st.sampled_from(["continuations", "recursive"]))
def test_random_rectilinear_shapes_become_rectangles(outline, strategy):
    from jaxmatch.shape import make_shape

    try:
        shp = make_shape(outline)
    except InputError:  # the outline touches itself at a point (cells meeting at a corner)
        assume(False)
    lay = decompose(shp, strategy)
    assert sum(area(lay.points[loop]) for loop in lay.patches) == pytest.approx(abs(area(outline)), rel=1e-12)
    for loop, pc in zip(lay.patches, lay.patch_corner):
        c = lay.points[loop][pc]
        assert c.shape[0] == 4 and len(np.unique(c[:, 0])) == 2 and len(np.unique(c[:, 1])) == 2


@pytest.mark.parametrize("path", sorted(EX.glob("*.json")) + sorted(LAB.glob("*.json")) + sorted((EX / "holes").glob("*.json")),
                         ids=lambda p: p.name)
def test_same_cuts_names_a_strategy_with_the_same_patches(path):
    """``same_cuts(shape, s)`` names a strategy (or None: the single patch) whose layout has the
    patches of ``s``'s layout, so the pipeline cuts each layout once."""
    shape = load_shape(path)
    for s in STRATEGIES:
        how = same_cuts(shape, s)
        try:
            lay = decompose(shape, s)
        except InputError:
            continue
        other = single_patch(shape) if how is None else decompose(shape, how)
        assert _same(lay, other), (path.name, s, how)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-10, 10), min_size=4, max_size=4),
       st.lists(st.lists(st.floats(-1e-4, 1e-4), min_size=4, max_size=4), min_size=0, max_size=3),
       st.floats(0, 1e-4), st.lists(st.booleans(), min_size=3, max_size=3))
def test_close_to_any_is_allclose_to_one_either_way(a, ds, tol, flips):
    """The cut dedup's ``_close_to_any`` answers as ``np.allclose(seg, cut, atol=tol)`` tried
    against every cut and every cut reversed."""
    from jaxmatch.placement.decompose import _close_to_any

    seg = np.array(a).reshape(2, 2)
    cuts = [(seg + np.array(d).reshape(2, 2))[::-1 if f else 1] for d, f in zip(ds, flips)]
    plain = any(np.allclose(seg, c, atol=tol) or np.allclose(seg, c[::-1], atol=tol) for c in cuts)
    assert _close_to_any(seg, cuts, tol) == plain