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

@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.floats(-10, 10), min_size=2, max_size=2), min_size=0, max_size=6),
       st.lists(st.integers(0, 11), min_size=0, max_size=4), st.sampled_from([1e-9, 1e-3, 0.5]),
       st.integers(1, 3))
def test_snapping_ends_together_is_snapping_them_one_by_one(free, on_points, tol, n_rings):
    """``_snap_all`` (the ends of every ray at once) gives ``_snap``'s points and inserts, in
    order: ends near a loop point (on the first loop that has one) moved onto it, the others
    recorded on their nearest loop segment."""
    from jaxmatch.placement.decompose import _snap, _snap_all

    t = np.linspace(0, 2 * np.pi, 5)[:-1]
    base = np.c_[9 * np.cos(t), 9 * np.sin(t)]
    rings = [base, base + 1e-10, base.copy()][:n_rings]  # (4, 2) each: ties between loops too, the first wins
    points = np.concatenate(rings)
    ends = np.array(free + [points[i % len(points)] + 1e-10 for i in on_points], np.float64).reshape(-1, 2)
    one, together = [], []
    want = [_snap(rings, e, tol, one) for e in ends]
    got = _snap_all(rings, ends, tol, together)
    assert len(got) == len(want) and all(np.array_equal(g, w) for g, w in zip(got, want))
    assert len(together) == len(one)
    for a, b in zip(together, one):
        assert a[:3] == b[:3] and np.array_equal(a[3], b[3])


def filleted_l(r: float, step_deg: float, angle_deg: float = 0.0) -> np.ndarray:
    """An L of legs 20 thick (80 x 60) whose inner corner at (20, 20) is rounded to radius ``r``
    (sampled every ``step_deg`` degrees), counter-clockwise, turned by ``angle_deg``."""
    t = np.radians(np.linspace(-90.0, -180.0, int(round(90 / step_deg)) + 1))
    arc = np.c_[20 + r + r * np.cos(t), 20 + r + r * np.sin(t)]
    pts = np.vstack([[[0, 0], [80, 0], [80, 20]], arc, [[20, 60], [0, 60]]])
    a = np.radians(angle_deg)
    return pts @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])


@pytest.mark.parametrize("r, step, angle", [(10, 3, 0), (5, 10, 30), (15, 1.5, -120)])
def test_a_fillet_gives_the_legs_and_the_corner_block(r, step, angle):
    """``fillets``: the tangent points of a filleted inner corner are its ends; a cut from each,
    along the inward normal of the straight side it meets, splits the L into its two legs and a
    corner block holding the fillet (checked with plain numpy: areas, cut directions)."""
    from jaxmatch.placement.decompose import fillet_ends
    from jaxmatch.shape import make_shape

    pts = filleted_l(r, step, angle)
    shp = make_shape(pts)
    assert bool(np.all(shp.convex))  # a fillet is no corner: no concave corner to cut at
    ends = fillet_ends(shp)
    assert len(ends) == 1
    got = shp.given_points[list(ends[0])]
    rot = filleted_l(r, 90.0, angle)[[3, 4]]  # the two tangent points, (20 + r, 20) and (20, 20 + r)
    assert np.allclose(got, rot, atol=1e-9)
    lay = decompose(shp, "fillets")
    assert lay.n_patches == 3
    assert sum(area(lay.points[loop]) for loop in lay.patches) == pytest.approx(abs(area(pts)), rel=1e-12)
    for a, b in cut_segments(shp, "fillets"):
        d = (b - a) / np.linalg.norm(b - a)
        ex = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
        assert min(abs(d @ ex), abs(abs(d @ ex) - 1)) < 1e-9  # along one leg's axis or across it
        assert np.linalg.norm(b - a) == pytest.approx(20.0, rel=1e-9)  # across a leg, 20 thick
    assert same_cuts(shp, "fillets") == "fillets" and same_cuts(shp, "continuations") is None


@pytest.mark.parametrize("path", [LAB / "quarter-annulus.json", EX / "hexagon.json", LAB / "notched-rectangle.json"])
def test_no_fillet_where_a_curve_ends_at_a_corner_or_nothing_is_rounded(path):
    """A concave arc that ends at corners (a quarter annulus's inner side) is no fillet, nor is a
    polygon's concave corner: ``fillets`` then makes the continuations' patches."""
    from jaxmatch.placement.decompose import fillet_ends

    shp = load_shape(path)
    assert fillet_ends(shp) == []
    assert same_cuts(shp, "fillets") == same_cuts(shp, "continuations")


def test_the_l_bracket_meshes_as_its_blocks(cat):
    """The pipeline tries ``fillets``; on the L-bracket part (fillet r 10 at the inner corner, a
    hole r 6 in the horizontal leg) at h = outer perimeter / 80 it beats every other candidate on
    quality: the legs and the corner block, no fan from the fillet, no edge longer than 2h."""
    import jaxmatch

    m = jaxmatch.mesh(EX / "parts" / "l-bracket.json", size=275.70616898472394 / 80, catalogue=cat)
    assert m.chosen == "fillets" and m.valid and m.long_edges(2.0) == 0
    others = [c.mesh.min_scaled_jacobian for c in m.tried if c.mesh is not None and c.name != "fillets"]
    assert m.min_scaled_jacobian >= 0.8 and all(s < m.min_scaled_jacobian for s in others)
