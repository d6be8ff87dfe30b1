"""Regions with holes (issue 20): read from every format that carries them, checked with one-line
errors, cut into simply connected patches and meshed as one conforming mesh.

Specification (measured independently of the code: plain numpy on the mesh's points and quads,
shapely only for the input region's area):

* every hole is a boundary loop of the mesh, every hole corner a vertex, boundary vertices on
  the rings, area within 1 %, no fold;
* an annulus and a square frame get a structured mesh: 0 irregular internal vertices;
* bad regions (a hole outside, holes overlapping or touching each other or the outer loop, a
  self-crossing hole, a hole of zero area) are one-line errors, exit 2 from the command line.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import jaxmatch
from jaxmatch.defaults import QUALITY
from jaxmatch.errors import EXIT_BAD_INPUT, InputError
from jaxmatch.io.readers import parse_shape

ROOT = Path(__file__).resolve().parent.parent
HOLES = ROOT / "examples" / "holes"
SQUARE = [[0, 0], [4, 0], [4, 4], [0, 4]]


def circle(cx, cy, r, n=48):
    t = 2 * np.pi * np.arange(n) / n
    return np.c_[cx + r * np.cos(t), cy + r * np.sin(t)].tolist()


def loops_of(quads: np.ndarray) -> list[list[int]]:
    d = np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2)
    key = np.sort(d, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    nxt = {int(a): int(b) for a, b in d[cnt[inv.ravel()] == 1]}
    loops, seen = [], set()
    for s in nxt:
        if s not in seen:
            loop, v = [], s
            while v not in seen:
                seen.add(v)
                loop.append(v)
                v = nxt[v]
            loops.append(loop)
    return loops


def dist_to_ring(p: np.ndarray, ring: np.ndarray) -> np.ndarray:
    a, b = ring, np.roll(ring, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("kmj,mj->km", p[:, None] - a[None], ab) / np.sum(ab * ab, axis=1), 0, 1)
    return np.min(np.linalg.norm(p[:, None] - (a[None] + t[..., None] * ab[None]), axis=2), axis=1)


def check_region_mesh(shape, m) -> None:
    import shapely

    q = m.quads
    p = m.xy[q]
    a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
    assert np.all(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0] > 0)  # no fold
    loops = loops_of(q)
    assert len(loops) == 1 + len(shape.holes)
    outer, holes = shape.input_points, [np.asarray(h) for h in shape.holes]
    ext = float(np.ptp(outer, axis=0).max())
    for loop in loops:
        d = np.min([dist_to_ring(m.xy[loop], r) for r in [outer, *holes]], axis=0)
        assert d.max() <= 1e-9 * ext
    for ring, corners in [(outer, shape.corners), *zip(holes, shape.hole_corners)]:
        for c in ring[np.asarray(corners, np.int64)]:
            assert np.min(np.linalg.norm(m.xy - c, axis=1)) <= 1e-9 * ext
    area = 0.5 * np.sum(p[..., 0] * np.roll(p[..., 1], -1, 1) - np.roll(p[..., 0], -1, 1) * p[..., 1])
    assert area / shapely.Polygon(outer, holes=holes).area == pytest.approx(1.0, abs=0.01)


def irregular_plain(m) -> int:
    e = np.unique(np.sort(np.stack([m.quads, np.roll(m.quads, -1, axis=1)], -1).reshape(-1, 2), axis=1), axis=0)
    val = np.bincount(e.ravel(), minlength=len(m.xy))
    bnd = np.zeros(len(m.xy), bool)
    for loop in loops_of(m.quads):
        bnd[loop] = True
    return int(np.sum(~bnd & (val != 4) & (val > 0)))


# ---------------------------------------------------------------------------------------------
# reading and checking


def test_json_geojson_and_api_carry_holes():
    hole = [[1, 1], [2, 1], [2, 2], [1, 2]]
    a = parse_shape(json.dumps({"boundary": SQUARE, "holes": [hole]}).encode(), "r.json")
    b = parse_shape(json.dumps({"type": "Polygon", "coordinates": [SQUARE + [SQUARE[0]], hole[::-1] + [hole[-1]]]}).encode(),
                    "r.geojson")
    c = jaxmatch.make_shape(SQUARE, holes=[hole[::-1]])  # either orientation
    for s in (a, b, c):
        assert len(s.holes) == 1 and len(s.hole_corners[0]) == 4
        ring = s.holes[0]
        area = 0.5 * np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1])
        assert area == pytest.approx(-1.0)  # stored clockwise: the region on the left
    assert {tuple(p) for p in a.holes[0]} == {tuple(p) for p in b.holes[0]} == {tuple(p) for p in c.holes[0]}


@pytest.mark.parametrize("hole, words", [
    ([[5, 5], [6, 5], [6, 6]], "hole 1 lies outside"),
    ([[0, 1], [1, 1], [1, 2]], "hole 1 touches the outer boundary"),
    ([[3, 3], [5, 3], [5, 5], [3, 5]], "hole 1 crosses or touches the outer boundary"),
    ([[1, 1], [2, 2], [2, 1], [1, 2]], "hole 1: hole crosses or touches itself"),
    ([[1, 1], [2, 1], [3, 1]], "hole 1: hole has zero area"),
])
def test_bad_holes_are_one_line_errors(hole, words):
    with pytest.raises(InputError, match=words) as e:
        jaxmatch.make_shape(SQUARE, holes=[hole], source="r.json")
    assert "\n" not in str(e.value) and str(e.value).startswith("r.json: ")


@pytest.mark.parametrize("second, words", [
    ([[1.5, 1.5], [3, 1.5], [3, 3]], "holes 1 and 2 overlap"),
    ([[2, 2], [3, 2], [3, 3]], "holes 1 and 2 touch"),
])
def test_holes_overlapping_or_touching(second, words):
    with pytest.raises(InputError, match=words):
        jaxmatch.make_shape(SQUARE, holes=[[[1, 1], [2, 1], [2, 2], [1, 2]], second])


def test_cli_bad_hole_exit_2(cli, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"boundary": SQUARE, "holes": [[[5, 5], [6, 5], [6, 6]]]}))
    out = tmp_path / "o.msh"
    code, _, err = cli("mesh", bad, "--size", "0.5", "--out", out)
    assert code == EXIT_BAD_INPUT and len(err.strip().splitlines()) == 1 and "hole 1 lies outside" in err
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# meshing


@pytest.mark.parametrize("region", [
    {"boundary": SQUARE, "holes": [[[1, 1], [3, 1], [3, 3], [1, 3]]]},      # square frame
    {"boundary": circle(0, 0, 2, 96), "holes": [circle(0, 0, 1)]},        # washer
])
def test_frame_and_annulus_are_structured(cat, region):
    shp = jaxmatch.make_shape(region["boundary"], holes=region["holes"])
    per = float(np.sum(np.linalg.norm(np.roll(shp.input_points, -1, 0) - shp.input_points, axis=1)))
    for div in (40, 80):
        m = jaxmatch.mesh(shp, size=per / div, catalogue=cat)
        check_region_mesh(shp, m)
        assert irregular_plain(m) == 0


@pytest.mark.parametrize("name", ["frame", "window"])
def test_cuts_that_split_right_angles_are_not_meshed_after_a_grid(cat, name):
    """The continuations of a frame or a window make grids (min scaled Jacobian 1); the
    bisectors (and the window's radial cuts) split right-angled corners, so their min scaled
    Jacobian is at most sin 45 degrees whatever their mesh: tried after a grid at the size, they
    are not meshed, and the choice is the one meshing every strategy gives."""
    from jaxmatch.meshing.choose import choose
    from jaxmatch.meshing.pipeline import strategy_names

    shp = jaxmatch.load_shape(HOLES / f"{name}.json")
    m = jaxmatch.mesh(shp, divisions=16, catalogue=cat)
    notes = {c.name: c.note for c in m.tried}
    assert m.chosen == "continuations" and m.min_scaled_jacobian == pytest.approx(1.0)
    assert m.coarse_stretches(QUALITY.coarse_side) + m.long_edges(QUALITY.long_edge) == 0  # at the size: nothing can beat it
    assert "at most 0.71 cannot beat continuations" in notes["bisectors"]
    alone = []
    for n in strategy_names():
        one = jaxmatch.mesh(shp, divisions=16, catalogue=cat, strategies=[n]) if n in ("continuations", "bisectors") else None
        if one is not None:
            alone.append(next(c for c in one.tried if c.name == n))
            if n == "bisectors":
                assert alone[-1].mesh.min_scaled_jacobian <= np.sin(np.pi / 4) + 1e-9
    assert choose(alone).chosen == m.chosen


@pytest.mark.parametrize("name", ["plate-bolt", "window", "triangle-hole", "letter-O"])
def test_example_regions_mesh_validly(cat, name):
    shp = jaxmatch.load_shape(HOLES / f"{name}.json")
    per = float(np.sum(np.linalg.norm(np.roll(shp.input_points, -1, 0) - shp.input_points, axis=1)))
    m = jaxmatch.mesh(shp, size=per / 40, catalogue=cat)
    check_region_mesh(shp, m)
    assert m.min_scaled_jacobian >= 0.3


@pytest.mark.slow
@pytest.mark.parametrize("name", ["plate-two-holes", "gasket", "bracket", "nut", "letter-A", "letter-B"])
def test_more_example_regions(cat, name):
    shp = jaxmatch.load_shape(HOLES / f"{name}.json")
    per = float(np.sum(np.linalg.norm(np.roll(shp.input_points, -1, 0) - shp.input_points, axis=1)))
    for div in (40, 80):
        check_region_mesh(shp, jaxmatch.mesh(shp, size=per / div, catalogue=cat))


def test_msh_groups_name_every_hole(cat, tmp_path):
    import meshio

    m = jaxmatch.mesh(HOLES / "window.json", size=0.25, catalogue=cat)
    path = jaxmatch.write_mesh(tmp_path / "w.msh", m)
    back = meshio.read(path)
    assert {"boundary", "hole 1", "hole 2"} <= set(back.field_data)
    tags = np.concatenate([t for c, t in zip(back.cells, back.cell_data["gmsh:physical"]) if c.type == "line"])
    loops = sorted(len(lp) for lp in loops_of(m.quads))
    for name in ("hole 1", "hole 2"):
        n = int(np.sum(tags == back.field_data[name][0]))
        assert n == len(m.line_sets[name]) and n in loops  # a hole's group is one whole boundary loop


def test_same_mesh_however_the_rings_are_written(cat):
    hole = circle(2, 2, 0.7)
    a = jaxmatch.mesh(jaxmatch.make_shape(SQUARE, holes=[hole]), size=0.4, catalogue=cat)
    b = jaxmatch.mesh(jaxmatch.make_shape(SQUARE[::-1], holes=[np.roll(hole[::-1], 7, axis=0)]), size=0.4, catalogue=cat)
    assert a.quads.shape == b.quads.shape
    assert np.allclose(np.unique(np.round(a.xy, 9), axis=0), np.unique(np.round(b.xy, 9), axis=0), atol=1e-7)
