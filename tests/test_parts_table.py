"""scripts/part_measures.py, scripts/make_parts.py and scripts/parts_table.py: the engineering-parts
yardstick. The measures are checked on meshes made by hand (figures known exactly), the parts
against shapely and their stated exact areas, the table's pieces on one small part."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
import shapely

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


pm = _load("part_measures")
mp = _load("make_parts")
pt = _load("parts_table")

UNIT = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)


def grid(n: int, x0=0.0, y0=0.0, size=1.0) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid of quads on the square [x0, x0 + size] x [y0, y0 + size], anticlockwise."""
    t = np.linspace(0, size, n + 1)
    xy = np.array([[x0 + x, y0 + y] for y in t for x in t])
    q = [[j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i]
         for j in range(n) for i in range(n)]
    return xy, np.array(q)


def test_unit_square_2x2_grid_is_perfect():
    xy, q = grid(2)
    m = pm.measure(xy, {"quad": q}, [UNIT], UNIT, 1.0, 0.5)
    assert m["valid"], m["problem"]
    assert (m["quads"], m["folded"], m["loops"], m["corners_kept"], m["irregular"]) == (4, 0, 1, 4, 0)
    assert m["min_sj"] == pytest.approx(1.0) and m["mean_sj"] == pytest.approx(1.0)
    assert m["area_ratio"] == pytest.approx(1.0)
    assert m["longest"] == pytest.approx(1.0) and m["mean_edge"] == pytest.approx(1.0) and m["in_band"] == 1.0
    assert m["off_ring"] == pytest.approx(0.0, abs=1e-12)


def test_clockwise_mesh_is_not_folded_and_one_reversed_quad_is():
    xy, q = grid(2)
    cw = pm.measure(xy, {"quad": q[:, ::-1]}, [UNIT], UNIT, 1.0, 0.5)
    assert cw["valid"] and cw["folded"] == 0
    mixed = q.copy()
    mixed[0] = mixed[0][::-1]
    m = pm.measure(xy, {"quad": mixed}, [UNIT], UNIT, 1.0, 0.5)
    assert m["folded"] == 1 and not m["valid"] and "folded" in m["problem"]


def test_folded_quad_detected():
    xy, q = grid(2)
    xy = xy.copy()
    xy[4] = [1.3, 0.5]  # the centre pushed past the right side: two quads fold
    m = pm.measure(xy, {"quad": q}, [UNIT], UNIT, 1.0, 0.5)
    assert m["folded"] >= 1 and m["min_sj"] < 0 and not m["valid"]


def test_missing_corner_detected():
    # a 2x2 grid of a square whose input has a fifth corner at (0.25, 0) that is no mesh vertex
    xy, q = grid(2)
    ring = np.array([[0, 0], [0.25, 0.0], [1, 0], [1, 1], [0, 1]], float)
    corners = np.r_[UNIT, [[0.25, 0.0]]]
    m = pm.measure(xy, {"quad": q}, [ring], corners, 1.0, 0.5)
    assert (m["corners"], m["corners_kept"]) == (5, 4) and not m["valid"] and "1 corners missed" in m["problem"]


def test_hole_loop_counted():
    # a 3x3 grid of the square [0, 3]^2 without its middle quad: a square frame
    xy, q = grid(3, size=3.0)
    frame = np.delete(q, 4, axis=0)
    outer = UNIT * 3
    hole = UNIT + 1
    m = pm.measure(xy, {"quad": frame}, [outer, hole], np.r_[outer, hole], 8.0, 1.0)
    assert m["valid"], m["problem"]
    assert (m["loops"], m["rings"], m["loops_ok"], m["irregular"]) == (2, 2, True, 0)
    # the same mesh against the outer ring only: two loops, one ring
    bad = pm.measure(xy, {"quad": frame}, [outer], outer, 8.0, 1.0)
    assert not bad["loops_ok"] and not bad["valid"]
    # the full grid against the frame's rings: one loop for two rings, area off
    full = pm.measure(xy, {"quad": q}, [outer, hole], np.r_[outer, hole], 8.0, 1.0)
    assert not full["loops_ok"] and full["area_ratio"] == pytest.approx(9 / 8)


def test_triangles_area_and_off_ring_detected():
    xy, q = grid(2)
    tri = pm.measure(xy, {"quad": q[1:], "triangle": np.array([[0, 1, 4]])}, [UNIT], UNIT, 1.0, 0.5)
    assert not tri["all_quads"] and tri["other_cells"] == 1 and not tri["valid"]
    lines_only = pm.measure(xy, {"quad": q, "line": np.array([[0, 1]]), "vertex": np.array([[0]])}, [UNIT], UNIT, 1.0, 0.5)
    assert lines_only["valid"]  # a mesh file's boundary lines and points are no cells of the region
    shifted = xy.copy()
    shifted[1] = [0.5, -0.02]  # a boundary vertex 0.04 h off the ring, the area 1 % larger
    m = pm.measure(shifted, {"quad": q}, [UNIT], UNIT, 1.0, 0.5)
    assert m["off_ring"] == pytest.approx(0.04) and m["area_ratio"] == pytest.approx(1.01) and not m["valid"]


def test_irregular_vertex_and_edge_band():
    # a triangle cut into three quads at its centroid: one interior vertex of valence 3
    tri = np.array([[0, 0], [1, 0], [0, 1]], float)
    xy = np.r_[tri, [[0.5, 0], [0.5, 0.5], [0, 0.5], [1 / 3, 1 / 3]]]
    q = np.array([[0, 3, 6, 5], [3, 1, 4, 6], [5, 6, 4, 2]])
    m = pm.measure(xy, {"quad": q}, [tri], tri, 0.5, 0.5)
    assert m["valid"], m["problem"]
    assert (m["irregular"], m["vertices"], m["edges"]) == (1, 7, 9)
    assert m["min_sj"] == pytest.approx(min(pm.corner_jacobians(xy, q)[1].min(axis=1)))
    # the 2x2 grid's edges (0.5) at h = 0.25: all 2h, none in the band
    xy, q = grid(2)
    m = pm.measure(xy, {"quad": q}, [UNIT], UNIT, 1.0, 0.25)
    assert m["longest"] == pytest.approx(2.0) and m["in_band"] == 0.0 and m["valid"]


@pytest.mark.parametrize("part", mp.parts(), ids=lambda p: p.name)
def test_parts_are_valid_polygons_with_their_exact_area(part):
    poly = shapely.Polygon(part.outer.points, [h.points for h in part.holes])
    assert poly.is_valid
    assert poly.area == pytest.approx(part.area, rel=1e-3)  # dense sampling: within 0.1 % of the exact area
    for ring in part.rings:  # pieces cover the ring once, in order, ending where the next starts
        n = len(ring.points)
        covered = [i for _, s, e in ring.pieces for i in pt.piece_indices(s, e, n)[:-1]]
        assert sorted(covered) == list(range(n))
        assert all(ring.pieces[k][2] == ring.pieces[(k + 1) % len(ring.pieces)][1] for k in range(len(ring.pieces)))


EXPECTED_CORNERS = {"plate-3-holes": 4, "flange": 0, "l-bracket": 5, "clevis": 4, "gear": 84, "naca0012": 5,
                    "heat-sink": 28, "keyhole": 8, "12-gon": 0, "6-gon": 6, "star-8": 16, "channel": 4, "cam": 0,
                    "slotted-link": 0, "web-plate": 4}


def test_parts_catalogue_and_corners():
    parts = mp.parts()
    assert len(parts) >= 14 and [p.name for p in parts] == list(EXPECTED_CORNERS)
    for p in parts:
        doc, truth = mp.documents(p)
        assert len(truth["corners"]) == EXPECTED_CORNERS[p.name], p.name
        # a corner turns by more than 30 degrees; every other point by at most 30 (12-gon: exactly 30)
        for ring, info in zip(p.rings, truth["rings"]):
            t = mp.turns(ring.points)
            assert np.all(t[info["corners"]] > 30) and np.all(np.delete(t, info["corners"]) <= 30 + 1e-7)
    assert mp.turns(mp.regular(12).outer.points) == pytest.approx(np.full(12, 30.0))


def test_written_files_match_the_generator():
    # the files of examples/parts/ are the generator's (to round-off of another platform's sin/cos)
    for p in mp.parts():
        doc, truth = mp.documents(p)
        on_disk = json.loads((pt.PARTS / f"{p.name}.json").read_text())
        assert sorted(on_disk) == sorted(doc), p.name
        for a, b in zip(pt.rings_of(on_disk), pt.rings_of(doc)):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
        told = json.loads((pt.PARTS / "truth" / f"{p.name}.json").read_text())
        assert told["rings"] == truth["rings"] and told["name"] == p.name, p.name
        assert told["area"] == pytest.approx(truth["area"], rel=1e-12)
        assert told["outer_perimeter"] == pytest.approx(truth["outer_perimeter"], rel=1e-12)
        np.testing.assert_allclose(np.reshape(told["corners"], (-1, 2)), np.reshape(truth["corners"], (-1, 2)), atol=1e-9)


def test_criteria_count_cases():
    ok = {"valid": True, "min_sj": 0.8, "longest": 1.2, "in_band": 0.9}
    rows = [{"part": "a", "fraction": 40, "h": 1.0, "jaxmatch": dict(ok), "gmsh": dict(ok)},
            {"part": "b", "fraction": 40, "h": 1.0, "jaxmatch": {**ok, "min_sj": 0.5, "longest": 2.5, "in_band": 0.6},
             "gmsh": dict(ok)},
            {"part": "c", "fraction": 40, "h": 1.0, "jaxmatch": {"error": "timeout after 120 s", "valid": False},
             "gmsh": {**ok, "valid": False}}]
    crit = {c[0][:12]: c[1:4] for c in pt.criteria(rows)}
    assert crit["every jaxmat"] == (2, 3, False)
    assert crit["min SJ >= gm"] == (1, 2, False)
    assert crit["mean of min "][2] is False  # (0.8 + 0.5) / 2 < 0.8
    assert crit["no edge long"] == (1, 3, False)
    assert crit["where gmsh h"] == (1, 3, False)
    assert pt.band_misses(rows) == ["b P/40 (60%, gmsh 90%)", "c P/40 (0%, gmsh 90%)"]


def test_one_small_part_through_both_meshers(tmp_path):
    pytest.importorskip("gmsh")
    row, meshes = pt.mesh_case("6-gon", 20, tmp_path, timeout=120)
    for method in pt.METHODS:
        rec = row[method]
        assert "error" not in rec, rec
        assert rec["all_quads"] and rec["folded"] == 0 and rec["corners_kept"] == 6
        assert abs(rec["area_ratio"] - 1) < 0.01 and rec["seconds"] > 0
        assert meshes[method][1].shape == (rec["quads"], 4)
    assert "6-gon | 20 |" in pt.table([row])


def test_page_and_explicit_corners(tmp_path):
    ok = {"valid": True, "min_sj": 0.8, "longest": 1.2, "in_band": 0.9, "quads": 10, "mean_sj": 0.9, "irregular": 0,
          "corners": 4, "corners_kept": 4, "seconds": 0.5}
    rows = [{"part": "a", "fraction": 40, "h": 1.0, "jaxmatch": dict(ok), "gmsh": {**ok, "seconds": 0.25}}]
    text = pt.page(rows, ["a.png"], "scripts/parts_table.py --parts a")
    assert "| a | 40 | 1 | 10 / 10 | 0.800 / 0.800 |" in text and "![a.png](parts/a.png)" in text
    assert "jaxmatch / gmsh median 2.0x" in text and "| 1 of 1 | yes |" in text
    assert "| jaxmatch 0.800, gmsh 0.800 over 1 cases | yes |" in text
    doc, truth = pt.load_part("keyhole")
    given = json.loads(pt.with_corners(doc, truth, tmp_path).read_text())
    rings = pt.rings_of(given)
    pts = [rings[0][given["corners"]]] + [r[c] for r, c in zip(rings[1:], given["hole_corners"])]
    assert np.concatenate(pts).tolist() == truth["corners"]
