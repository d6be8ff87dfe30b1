"""Outlines from real drawings (issue 21): dense, noisy and curved outlines, corners judged at the
scale of the mesh (:func:`jaxmatch.shape.scale_corners`), meshed validly.

Specification:

* at size ``h`` a corner is a turn that holds over a stretch of about ``h``: wiggles shorter than
  that are no corners, a polygon's vertices between straight runs stay corners, a small turn
  between two long straight sides is a corner, explicit corners always win;
* the corners do not depend on where the loop starts, on its units or on points added on a side;
* dense outlines mesh validly (no fold, area within 1 %, boundary vertices on the outline);
* a circle or an ellipse (no corners) is meshed, e.g. as a central block with four patches.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxmatch
from jaxmatch.shape import scale_corners

ROOT = Path(__file__).resolve().parent.parent
DENSE = ROOT / "examples" / "dense"
L_CORNERS = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]], float)


def dense_polygon(corners: np.ndarray, per_side: int) -> np.ndarray:
    out = []
    for i, a in enumerate(corners):
        b = corners[(i + 1) % len(corners)]
        out += [a + (b - a) * j / per_side for j in range(per_side)]
    return np.asarray(out)


def outline(name: str) -> np.ndarray:
    return np.asarray(json.loads((DENSE / f"{name}.json").read_text())["boundary"], float)


@pytest.mark.parametrize("h", [0.1, 0.4, 1.0])
def test_a_dense_polygon_keeps_exactly_its_corners(h):
    pts = dense_polygon(L_CORNERS, 50)
    found = scale_corners(pts, h)
    assert np.array_equal(pts[found], L_CORNERS)


@pytest.mark.parametrize("h", [0.5, 1.0, 2.0])
def test_wiggles_shorter_than_h_are_not_corners(h):
    pts = outline("wiggly-square")  # 10 x 10, sides wiggling by 0.02
    found = pts[scale_corners(pts, h)]
    assert len(found) == 4
    for c in [[0, 0], [10, 0], [10, 10], [0, 10]]:
        assert np.min(np.linalg.norm(found - c, axis=1)) < 0.1


def test_smooth_curves_have_no_corners():
    for name in ("circle-1000", "ellipse-1000"):
        pts = outline(name)
        per = float(np.sum(np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)))
        for div in (40, 80):
            assert scale_corners(pts, per / div).size == 0


def test_a_small_turn_between_long_straight_sides_is_a_corner():
    pg = np.array([[0, 0], [20, 0], [23, 1], [3, 1]], float)  # turns of 18 degrees at two vertices
    assert jaxmatch.make_shape(pg).n_corners == 2  # the 30-degree angle rule alone misses them
    assert scale_corners(pg, 0.5).tolist() == [0, 1, 2, 3]


@settings(max_examples=25, deadline=None)
@given(shift=st.integers(0, 299), scale=st.sampled_from([0.001, 1.0, 1000.0]), h=st.sampled_from([0.2, 0.5, 1.0]))
def test_corners_do_not_depend_on_start_units_or_added_points(shift, scale, h):
    pts = dense_polygon(L_CORNERS, 50)
    base = {tuple(p) for p in pts[scale_corners(pts, h)]}
    moved = np.roll(pts, shift, axis=0) * scale + 7.0
    got = {tuple(np.round((p - 7.0) / scale, 9)) for p in moved[scale_corners(moved, h * scale)]}
    assert got == {tuple(np.round(p, 9)) for p in base}
    coarse = dense_polygon(L_CORNERS, 7)
    assert {tuple(p) for p in coarse[scale_corners(coarse, h)]} == base


def test_explicit_corners_win(cat):
    pts = outline("circle-1000")
    shp = jaxmatch.make_shape(pts, corners=[0, 250, 500, 750])
    m = jaxmatch.mesh(shp, size=1.0, catalogue=cat)
    for c in pts[[0, 250, 500, 750]]:
        assert np.min(np.linalg.norm(m.xy - c, axis=1)) <= 1e-12


def check_on_outline(m, pts) -> None:
    a, b = pts, np.roll(pts, -1, axis=0)
    ab = b - a
    e = np.sort(np.stack([m.quads, np.roll(m.quads, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    uniq, cnt = np.unique(e, axis=0, return_counts=True)
    bv = np.unique(uniq[cnt == 1])
    p = m.xy[bv]
    t = np.clip(np.einsum("kmj,mj->km", p[:, None] - a[None], ab) / np.sum(ab * ab, axis=1), 0, 1)
    d = np.min(np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=2), axis=1)
    assert d.max() <= 1e-9 * float(np.ptp(pts, axis=0).max())


@pytest.mark.parametrize("name, div", [("wiggly-square", 40), ("ellipse-1000", 40), ("circle-1000", 80),
                                       ("lshape-1000", 40), ("parallelogram", 40)])
def test_dense_outlines_mesh_validly(cat, name, div):
    pts = outline(name)
    per = float(np.sum(np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)))
    m = jaxmatch.mesh(jaxmatch.make_shape(pts), size=per / div, catalogue=cat)
    assert m.inverted == 0 and m.min_scaled_jacobian >= 0.3
    assert m.area_ratio == pytest.approx(1.0, abs=0.01)
    check_on_outline(m, jaxmatch.make_shape(pts).input_points)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["coastline", "glyph-G"])
def test_traced_outlines_mesh_validly(cat, name):
    pts = outline(name)
    shp = jaxmatch.make_shape(pts)
    per = float(np.sum(np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)))
    m = jaxmatch.mesh(shp, size=per / 40, catalogue=cat)
    assert m.inverted == 0 and m.min_scaled_jacobian >= 0.3
    assert m.area_ratio == pytest.approx(1.0, abs=0.01)
    check_on_outline(m, shp.input_points)


def test_a_disk_is_a_central_block_with_four_patches(cat):
    m = jaxmatch.mesh(DENSE / "circle-1000.json", size=0.8, catalogue=cat)
    disk = next(c.mesh for c in m.tried if c.name == "disk")
    assert disk.n_patches == 5 and disk.inverted == 0 and len(disk.irregular) == 4


@pytest.mark.parametrize("dup", [1e-10, 1e-9])
def test_near_duplicate_points_and_tiny_edges_still_mesh(cat, dup):
    """(Points closer than 1e-11 of the extent are refused by the shape checks, one line.)"""
    pts = [[0, 0], [4, 0], [4, 2], [2, 2], [2 + dup, 2 + dup], [2, 4], [0, 4]]
    shp = jaxmatch.make_shape(pts)
    m = jaxmatch.mesh(shp, size=0.25, catalogue=cat)
    assert m.inverted == 0 and m.area_ratio == pytest.approx(1.0, abs=0.01)
    assert all(c.mesh is not None or c.note for c in m.tried)  # a failed candidate says why


def test_cli_annotate_shows_the_corners_at_a_size(cli):
    code, out, err = cli("annotate", DENSE / "wiggly-square.json", "--size", "1.0", "--json")
    assert code == 0, err
    assert "corners judged at size 1: 4" in err
    assert json.loads(out)["sequence"].count("x") == 4
