"""Bounds on a layout's mesh before it is meshed (:mod:`jaxmatch.placement.bounds`):
:func:`template_sj_bound`, the single patch's cap from its candidate templates' vertices. (The
node and grid bounds: tests/test_layout.py, tests/test_meshing.py.)

Independent checks: the bound is compared with the min scaled Jacobian measured here (numpy) on
the mesh the solve makes, and with angles worked out by hand."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import jaxmatch
from jaxmatch.field import Field, Near
from jaxmatch.geometry import cumulative_length
from jaxmatch.inputs import _lattice, load_catalogue
from jaxmatch.meshing.region import canonical
from jaxmatch.placement.bounds import template_sj_bound
from jaxmatch.placement.decompose import single_patch
from jaxmatch.placement.layout import make_layout
from jaxmatch.placement.solve import ALL_SIZES
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, make_shape

ROOT = Path(__file__).resolve().parent.parent
EX, LAB = ROOT / "examples", ROOT / "examples" / "labels" / "shapes"
SHAPES = [EX / "lshape.json", EX / "tshape.json", EX / "plus.json", LAB / "ushape.json", LAB / "zshape.json",
          LAB / "stairs.json", EX / "hexagon.json", EX / "square.json", EX / "graded" / "strip.json"]


def _min_sj(xy: np.ndarray, quads: np.ndarray) -> float:
    """The least over every quad corner of sin(angle) (cross / |e1| |e2|), numpy only."""
    p = xy[quads]
    a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return float((cross / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))).min())


def _single(shape, size):
    """The single candidate's mesh of ``shape`` at ``size`` (a number or a size field) and the
    bound of its layout, corners judged as the pipeline judges them."""
    cat = load_catalogue(None)
    m = jaxmatch.mesh(shape, size=size, catalogue=cat, strategies=["single"])
    single = next(c.mesh for c in m.tried if c.name == "single")  # (not a larger template tried after it)
    h = single.size
    lay = single_patch(canonical(shape, h, DEFAULT_CORNER_ANGLE))
    return single, template_sj_bound(lay, cat, _lattice("fine"), sizes=ALL_SIZES)


@pytest.mark.parametrize("path", SHAPES, ids=lambda p: p.stem)
@pytest.mark.parametrize("graded", [False, True], ids=["uniform", "graded"])
def test_the_single_patch_mesh_is_never_better_than_its_template_bound(path, graded):
    shp = jaxmatch.load_shape(path)
    per = float(cumulative_length(shp.input_points)[-1])
    lo = shp.input_points.min(axis=0)
    size = Field(per / 16, (Near("point", tuple(lo), per / 80, per / 4),)) if graded else per / 16
    m, bound = _single(shp, size)
    assert 0.0 <= bound <= 1.0
    assert m.inverted > 0 or _min_sj(m.xy, m.quads) <= bound + 1e-9


def test_an_l_whose_templates_meet_the_inner_corner_with_two_quads_is_capped_at_sin_135():
    shp = jaxmatch.load_shape(EX / "lshape.json")
    m, bound = _single(shp, 0.1)
    assert bound == pytest.approx(math.sin(math.radians(135)), abs=1e-5)
    assert _min_sj(m.xy, m.quads) <= bound + 1e-9


@pytest.mark.parametrize("corners, want", [(6, math.sin(math.radians(120))), (4, 1.0)])
def test_a_regular_polygon_is_capped_by_its_corner_angle(corners, want):
    """A convex polygon's corner quads: one quad at each corner of a template that keeps the
    corners, so a hexagon's is at most sin 120 degrees; a square's grid is not capped."""
    t = np.arange(corners) * 2 * np.pi / corners
    shp = make_shape(np.c_[np.cos(t), np.sin(t)])
    _, bound = _single(shp, 2 * np.sin(np.pi / corners) / 8)
    assert bound == pytest.approx(want, abs=1e-5)


def test_no_claim_for_several_patches():
    pts = [[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]]
    lay = make_layout(pts, [[0, 1, 4, 5], [1, 2, 3, 4]])
    assert template_sj_bound(lay, load_catalogue(None), _lattice("fine")) == 1.0


def _node_bound_numpy(layout) -> float:
    """node_sj_bound with the outline found by numpy's edge counting (np.unique of the undirected
    segments, np.bincount of the patches at each point): the reference of its plain-Python count."""
    from jaxmatch.placement import bounds as B

    pts, loops = layout.points, layout.patches
    n = pts.shape[0]
    flat = np.concatenate(loops)
    nxt = np.concatenate([np.roll(p, -1) for p in loops])
    uses = np.bincount(flat, minlength=n)
    und = np.minimum(flat, nxt) * n + np.maximum(flat, nxt)
    _, inv, cnt = np.unique(und, return_inverse=True, return_counts=True)
    a, b = flat[cnt[inv] == 1], nxt[cnt[inv] == 1]
    if np.unique(a).size < a.size or np.unique(b).size < b.size:
        return 1.0
    ahead, back = dict(zip(a.tolist(), b.tolist())), dict(zip(b.tolist(), a.tolist()))
    corner = np.zeros(n, bool)
    for p, pc in zip(loops, layout.patch_corner):
        corner[p[pc]] = True
    stop = set(np.flatnonzero(corner).tolist())
    bound = 1.0
    for v in sorted(stop):
        if v in ahead:
            after, before = B._walk(ahead, stop, v), B._walk(back, stop, v)
            if after is None or before is None:
                continue
            lo, hi = B._outline_angle(pts, v, after, before)
        else:
            lo = hi = 2 * math.pi
        bound = min(bound, B._split_sj(lo - B.NODE_ANGLE_TOL, hi + B.NODE_ANGLE_TOL, int(uses[v])))
    return bound


@pytest.mark.parametrize("path", SHAPES + [EX / "holes" / "frame.json", EX / "holes" / "letter-A.json",
                                           EX / "holes" / "bracket.json"], ids=lambda p: p.stem)
def test_the_node_bound_counts_the_outline_as_numpy_does(path):
    """node_sj_bound (its outline, corners and patches per point counted in plain Python) equals
    the bound from numpy's counts, on every decomposition of the examples, and is a bound: the
    mesh the solve makes of each layout is no better (numpy's own min scaled Jacobian)."""
    from jaxmatch.placement.bounds import node_sj_bound
    from jaxmatch.placement.decompose import STRATEGIES, decompose
    from jaxmatch.placement.solve import mesh_layout

    shp = canonical(jaxmatch.load_shape(path), None)
    tried = 0
    for strategy in STRATEGIES:
        try:
            lay = decompose(shp, strategy)
        except jaxmatch.InputError:
            continue
        bound = node_sj_bound(lay)
        assert bound == _node_bound_numpy(lay)
        try:
            lm = mesh_layout(lay, load_catalogue(None), _lattice("fine"), size=float(np.ptp(shp.given_points, axis=0).max()) / 8)
        except jaxmatch.InputError:  # (a layout the solve cannot mesh: no mesh to compare)
            continue
        assert _min_sj(lm.xy, np.asarray(lm.quads)) <= bound + 1e-9 or lm.inverted
        tried += 1
    assert tried >= 1


def test_an_outline_that_touches_itself_gets_no_node_claim():
    """Two squares meeting at one point: the outline passes that point twice, so no claim (1)."""
    from jaxmatch.placement.bounds import node_sj_bound

    lay = make_layout([[0, 0], [1, 0], [1, 1], [0, 1], [2, 1], [2, 2], [1, 2]], [[0, 1, 2, 3], [2, 4, 5, 6]],
                      check=False)
    assert node_sj_bound(lay) == _node_bound_numpy(lay) == 1.0
