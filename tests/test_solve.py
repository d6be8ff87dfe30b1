"""The one solve with templates chosen for size (:mod:`jaxmatch.placement.solve`, ``transitions``;
:func:`jaxmatch.placement.milp.solve_choice`): a patch whose opposite sides want different
counts takes a transition template where that brings its sides to the size, and the mesh stays
valid (corners, area and scaled Jacobians measured here, independently)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from jaxmatch.defaults import QUALITY
from jaxmatch.field import Field, Near
from jaxmatch.inputs import load_catalogue, load_lattice
from jaxmatch.placement.decompose import single_patch
from jaxmatch.placement.layout import make_layout
from jaxmatch.placement.milp import count_cost, one_patch_sides, solve_choice, solve_counts
from jaxmatch.placement.solve import _chord_targets, mesh_layout, off_size_patches
from jaxmatch.placement.templates import first_group_templates
from jaxmatch.shape import make_shape

GRID = np.array([[1, 0], [0, 1], [1, 0], [0, 1]])
"""A 4-sided grid's side matrix: opposite sides share their chord (the same count)."""

THREE_TO_ONE = np.array([[1, 1, 1], [0, 0, 1], [0, 1, 0], [1, 0, 0]])
"""A transition's side matrix: side 0 takes the three chords, each other side one of them."""


@pytest.mark.parametrize("penalty, taken", [(0.5, 1), (3.0, 1), (5.0, 0)])
def test_the_program_takes_a_transition_only_for_more_than_its_penalty(penalty, taken):
    sides = one_patch_sides([6.0, 2.0, 2.0, 2.0])  # a trapezoid: 6 at the bottom, 2 at the top (size 1)
    ch = solve_choice(sides, [[GRID, THREE_TO_ONE]], penalties=[[0.0, penalty]], size=1.0)
    assert ch.choice == (taken,)
    # the grid's best: bottom = top, |n0 - 6| + |n2 - 2| = 4; the transition meets every target
    assert np.abs(ch.counts - sides.lengths).sum() == pytest.approx(4.0 if taken == 0 else 0.0)
    A = [GRID, THREE_TO_ONE][taken]
    assert np.array_equal(A @ ch.multiplicities[0], ch.counts)
    assert ch.size_cost == pytest.approx(count_cost(sides, ch.multiplicities, ch.counts, size=1.0))


def test_one_alternative_is_the_plain_program():
    sides = one_patch_sides([5.2, 2.9, 3.7, 2.1])
    mults, n = solve_counts(sides, [GRID], size=1.0)
    ch = solve_choice(sides, [[GRID]], penalties=[[0.0]], size=1.0)
    assert ch.choice == (0,) and np.array_equal(ch.counts, n) and np.array_equal(ch.multiplicities[0], mults[0])


def test_requested_counts_bind_the_choice():
    sides = one_patch_sides([6.0, 2.0, 2.0, 2.0])
    ch = solve_choice(sides, [[GRID, THREE_TO_ONE]], penalties=[[0.0, 0.5]], size=1.0, counts={0: 4, 2: 4})
    assert ch.counts[0] == 4 and ch.counts[2] == 4


def _scaled_jacobians(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Per quad, the smallest of its four corners' ``cross(e_next, e_prev) / (|e_next| |e_prev|)``."""
    p = xy[quads]
    nxt = np.roll(p, -1, axis=1) - p
    prv = np.roll(p, 1, axis=1) - p
    cross = nxt[..., 0] * prv[..., 1] - nxt[..., 1] * prv[..., 0]
    return (cross / (np.linalg.norm(nxt, axis=2) * np.linalg.norm(prv, axis=2))).min(axis=1)


TRAPEZOID = np.array([[0.0, 0.0], [8.0, 0.0], [5.0, 2.0], [3.0, 2.0]])


@pytest.fixture(scope="module")
def trapezoid_meshes():
    cat, lat = load_catalogue(), load_lattice("fine")
    lay = single_patch(make_shape(TRAPEZOID, corners=[0, 1, 2, 3]))
    return lay, mesh_layout(lay, cat, lat, size=1.0), mesh_layout(lay, cat, lat, size=1.0, transitions=True)


def test_a_trapezoid_takes_a_transition_template(trapezoid_meshes):
    lay, plain, trans = trapezoid_meshes
    # a grid carries the bottom's count to the top: 5 edges on each (edges of 1.6 and 0.4)
    assert plain.counts[0] == plain.counts[2]
    assert off_size_patches(plain.sides, [None], [np.ones(0)], plain.counts, 1.0) == [0]
    assert trans.templates != plain.templates
    lengths = plain.sides.lengths
    assert lengths[0] == pytest.approx(8.0) and lengths[2] == pytest.approx(2.0)
    assert (trans.counts[0], trans.counts[2]) == (8, 2)  # each side at the size
    assert np.abs(trans.counts - lengths).sum() < np.abs(plain.counts - lengths).sum()


def test_the_transition_mesh_keeps_corners_area_and_quality(trapezoid_meshes):
    lay, plain, trans = trapezoid_meshes
    xy, quads = trans.xy, trans.quads
    for c in TRAPEZOID:  # every corner a mesh vertex
        assert np.min(np.linalg.norm(xy - c, axis=1)) < 1e-12
    areas = shapely.area(shapely.polygons(xy[quads]))
    assert np.all(areas > 0)
    assert areas.sum() == pytest.approx(shapely.Polygon(TRAPEZOID).area, rel=1e-9)
    sj = _scaled_jacobians(xy, quads)
    assert sj.min() >= QUALITY.good_sj
    assert sj.min() == pytest.approx(float(trans.scaled_jacobian.min()), abs=1e-9)
    # no worse than the grid: the trapezoid's acute corners bound both
    assert sj.min() >= _scaled_jacobians(plain.xy, plain.quads).min() - 1e-9


def test_a_patch_at_the_size_is_not_changed():
    cat, lat = load_catalogue(), load_lattice("fine")
    lay = single_patch(make_shape(np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 2.0], [0.0, 2.0]]), corners=[0, 1, 2, 3]))
    plain = mesh_layout(lay, cat, lat, size=1.0)
    trans = mesh_layout(lay, cat, lat, size=1.0, transitions=True)
    assert trans.templates == plain.templates and np.array_equal(trans.counts, plain.counts)
    assert np.array_equal(trans.quads, plain.quads)


@pytest.mark.parametrize("lengths", [[6.0, 2.0, 2.0, 2.0], [4.0, 4.0, 4.0, 4.0], [2.0, 2.0, 6.0, 2.0]])
def test_screening_by_the_relaxation_keeps_the_optimum_of_a_small_program(lengths):
    """``screen``: the alternatives the linear relaxation leaves out are dropped before branching;
    on these programs the answer is the full program's."""
    sides = one_patch_sides(lengths)
    full = solve_choice(sides, [[GRID, THREE_TO_ONE]], penalties=[[0.0, 0.5]], size=1.0)
    screened = solve_choice(sides, [[GRID, THREE_TO_ONE]], penalties=[[0.0, 0.5]], size=1.0, screen=True)
    assert screened.choice == full.choice and np.array_equal(screened.counts, full.counts)
    assert screened.size_cost == pytest.approx(full.size_cost)


def test_a_start_and_a_node_limit_never_return_worse_than_the_start():
    """With the first alternatives' answer as the start, a program stopped after one node answers
    no worse than that start (its size cost at most the plain program's)."""
    sides = one_patch_sides([6.0, 2.0, 2.0, 2.0])
    mults, n = solve_counts(sides, [GRID], size=1.0)
    ch = solve_choice(sides, [[GRID, THREE_TO_ONE]], penalties=[[0.0, 0.5]], size=1.0, start=(mults, n), max_nodes=1)
    assert ch.size_cost <= count_cost(sides, mults, n, size=1.0) + 1e-9


def test_translated_patches_take_their_transitions_and_the_mesh_conforms():
    """Two trapezoids (8 at the bottom, 2 at the top) that are translates of each other, a
    triangle between them: both take a transition (the second as the first's templates, moved),
    and the merged mesh is conforming (every inner edge in two quads, the outline's edges in one),
    covers the region and keeps its corners."""
    cat, lat = load_catalogue(), load_lattice("fine")
    pts = np.array([[0.0, 0.0], [8.0, 0.0], [16.0, 0.0], [13.0, 2.0], [11.0, 2.0], [5.0, 2.0], [3.0, 2.0]])
    lay = make_layout(pts, [[0, 1, 5, 6], [1, 4, 5], [1, 2, 3, 4]])
    plain = mesh_layout(lay, cat, lat, size=1.0, smooth_cuts=True)
    trans = mesh_layout(lay, cat, lat, size=1.0, smooth_cuts=True, transitions=True)
    assert trans.templates[0] == trans.templates[2] != plain.templates[0]
    for p in (0, 2):  # each trapezoid's bottom and top at the size
        bottom, top = (int(sum(trans.counts[s] for s in trans.sides.patch_sides[p][i])) for i in (0, 2))
        assert (bottom, top) == (8, 2)
    q = trans.quads
    e = np.sort(np.concatenate([q[:, [0, 1]], q[:, [1, 2]], q[:, [2, 3]], q[:, [3, 0]]]), axis=1)
    uniq, uses = np.unique(e, axis=0, return_counts=True)
    assert set(uses.tolist()) <= {1, 2}
    outline = shapely.Polygon(pts[[0, 1, 2, 3, 4, 5, 6]]).exterior
    mids = 0.5 * (trans.xy[uniq[:, 0]] + trans.xy[uniq[:, 1]])
    on = shapely.distance(shapely.points(mids), outline) < 1e-9
    assert np.array_equal(uses == 1, on)
    areas = shapely.area(shapely.polygons(trans.xy[q]))
    assert np.all(areas > 0) and areas.sum() == pytest.approx(shapely.Polygon(pts).area, rel=1e-9)
    for c in pts[[0, 2, 3, 6]]:
        assert np.min(np.linalg.norm(trans.xy - c, axis=1)) < 1e-12
    assert _scaled_jacobians(trans.xy, q).min() >= QUALITY.good_sj


def test_chord_targets_are_the_templates_own_worked_out_once_per_field():
    # the rounds and the transition rounds ask again for a template's chord targets under a size
    # field: the field keeps the answer (a copy each time, bit for bit the template's own), and
    # another field, or the same template placed again, has its own
    cat, lat = load_catalogue(), load_lattice("fine")
    shape = make_shape(TRAPEZOID, corners=[0, 1, 2, 3])
    t = first_group_templates(shape, cat, lat, 3, ((0, 1), (2, 3)))[0]
    field = Field(1.0, (Near("point", (4.0, 0.0), 0.2, 3.0),))
    f, g = field.bind(shape), Field(1.0, (Near("point", (4.0, 2.0), 0.3, 3.0),)).bind(shape)
    calls = []
    real = type(t).chord_targets

    def counted(self, fld):
        calls.append(fld)
        return real(self, fld)

    type(t).chord_targets = counted
    try:
        first, again = _chord_targets(t, f), _chord_targets(t._replace(shape=shape), f)
        other = _chord_targets(t, g)
    finally:
        type(t).chord_targets = real
    assert calls == [f, g]
    np.testing.assert_array_equal(first, real(t, f))
    np.testing.assert_array_equal(again, first)
    np.testing.assert_array_equal(other, real(t, g))
    first[:] = -1.0  # a copy: the kept answer stays
    np.testing.assert_array_equal(_chord_targets(t, f), real(t, f))
