"""The meshing pipeline (:mod:`jaxmatch.meshing`): one front door, one result type, one choice rule.

Specification (geometry checked with plain numpy from the mesh's points and quads and the input
file, independently of the code under test):

* ``jaxmatch.mesh(shape, size=h)`` meshes the shape as one template and as each decomposition
  and keeps the best by one rule; the result names the candidate, the rule that decided and the
  runner-up, and lists every candidate tried; a layout that cannot beat the best so far is not
  meshed, and the answer is the one meshing every strategy alone would give;
* every corner is a vertex, no quad folds, the area is kept, min scaled Jacobian >= 0.3, on the
  concave example shapes at two sizes;
* squares and rectangles whose sides are multiples of h give the plain grid;
* every side's edge count follows the size (within ``max(1, size_tol * L / h)``);
* the same mesh however the loop is written (start point, direction);
* every result type writes to a file; a solver failure is not reported as infeasibility.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxmatch
from jaxmatch.defaults import QUALITY
from jaxmatch.errors import EXIT_BAD_INPUT, InputError, SolverError
from jaxmatch.meshing.choose import RULES, best_possible_key, cannot_win, choose, mesh_key
from jaxmatch.meshing.pipeline import strategy_names
from jaxmatch.meshing.result import Candidate, QuadMesh, irregular_bound
from jaxmatch.meshing import strategies as strat
from jaxmatch.placement.decompose import STRATEGIES

ROOT = Path(__file__).resolve().parent.parent
EX, LAB = ROOT / "examples", ROOT / "examples" / "labels" / "shapes"
CONCAVE = {"L": EX / "lshape.json", "T": EX / "tshape.json", "U": LAB / "ushape.json", "plus": EX / "plus.json",
           "Z": LAB / "zshape.json", "stairs": LAB / "stairs.json", "cross": LAB / "cross.json",
           "notched-rectangle": LAB / "notched-rectangle.json"}


def signed_area(p) -> float:
    p = np.asarray(p, float)
    return 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def sj_plain(xy, quads) -> np.ndarray:
    """Verdict scaled Jacobian per quad, written out here."""
    p = xy[np.asarray(quads)]
    a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return (cross / (np.linalg.norm(a, axis=2) * np.linalg.norm(b, axis=2))).min(axis=1)


def valence_plain(quads, n) -> tuple[np.ndarray, np.ndarray]:
    """(valence per vertex, on a boundary edge) from the quads alone."""
    e = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2), axis=1)
    uniq, cnt = np.unique(e, axis=0, return_counts=True)
    on_b = np.zeros(n, bool)
    on_b[uniq[cnt == 1].ravel()] = True
    return np.bincount(uniq.ravel(), minlength=n), on_b


def check_mesh(shape, m: QuadMesh) -> None:
    """A mesh of the shape, measured independently."""
    sj = sj_plain(m.xy, m.quads)
    assert sj.min() >= 0.3
    quad_area = sum(signed_area(m.xy[q]) for q in m.quads)
    assert quad_area / abs(signed_area(shape.input_points)) == pytest.approx(1.0, abs=1e-9)
    for c in shape.input_points[shape.corners]:
        assert np.min(np.linalg.norm(m.xy - c, axis=1)) <= 1e-12
    assert m.chosen.split()[0] in strategy_names()  # "single <template id>": another single template
    assert min(mesh_key(c.mesh, i) for i, c in enumerate(m.tried) if c.mesh is not None) == \
        mesh_key(m, [c.name for c in m.tried].index(m.chosen))


def test_strategy_names_are_the_single_template_then_every_decomposition_then_the_rings():
    assert strategy_names() == ("single",) + tuple(STRATEGIES) + ("rings",)


def test_l_shape_names_the_rule_and_the_runner_up(cat):
    shp = jaxmatch.load_shape(CONCAVE["L"])
    m = jaxmatch.mesh(shp, size=0.25, catalogue=cat)
    check_mesh(shp, m)
    assert [c.name for c in m.tried] == [n for n in strategy_names() if n != "rings"]  # (rings: only when wanted)
    # the recursive cut meshes the L as two grids (min scaled Jacobian 1); the bisectors split a
    # right-angled corner between two patches (some quad's angle there at most 45 degrees), the
    # continuations' three patches cannot beat two perfect ones, and no template of the single
    # patch's sizes refines into a grid (its min scaled Jacobian is at most 0.96): none of them is
    # meshed, and the runner-up is the one whose best possible mesh comes closest
    assert m.chosen == "recursive" and m.n_patches == 2 and m.min_scaled_jacobian == pytest.approx(1.0)
    assert [c.name for c in m.tried if c.mesh is not None] == ["recursive"]
    assert m.rule == "fewer patches" and m.runner_up == "continuations"
    notes = {c.name: c.note for c in m.tried}
    assert "3 patches cannot beat recursive" in notes["continuations"]
    assert "at most 0.71 cannot beat recursive" in notes["bisectors"] and "splits its angle" in notes["bisectors"]
    assert "cannot beat recursive" in notes["single"] and "grid" in notes["single"]
    bisectors = jaxmatch.mesh(shp, size=0.25, catalogue=cat, strategies=["bisectors"])
    assert bisectors.min_scaled_jacobian <= np.sin(np.pi / 4) + 1e-9  # the claim, on its mesh


@pytest.mark.parametrize("name,div", [("L", 16), ("T", 32), ("U", 16), ("plus", 32), ("stairs", 16),
                                      ("notched-rectangle", 32)])
def test_candidates_not_meshed_could_not_have_won(cat, name, div):
    """The pipeline meshes fewest patches first and skips a layout that cannot beat the best so
    far; meshing every strategy alone and choosing among all of them gives the same answer."""
    from jaxmatch.geometry import cumulative_length

    shp = jaxmatch.load_shape(CONCAVE[name])
    h = float(cumulative_length(shp.input_points)[-1]) / div
    m = jaxmatch.mesh(shp, size=h, catalogue=cat)
    alone = []
    for n in [n for n in strategy_names() if n != "rings" or n in {c.name for c in m.tried}]:  # rings: only when wanted
        one = jaxmatch.mesh(shp, size=h, catalogue=cat, strategies=[n])
        alone.append(next(c for c in one.tried if c.name == n))
    every = choose(alone)
    assert m.chosen == every.chosen
    assert mesh_key(m)[:-1] == mesh_key(every)[:-1]


@pytest.mark.parametrize("path", list(CONCAVE.values()) + [EX / "square.json", EX / "hexagon.json"], ids=lambda p: p.stem)
@pytest.mark.parametrize("div", [16, 32])
def test_single_sj_bound_holds(cat, path, div):
    """Where ``single_sj_bound`` claims less than 1, the single patch meshed alone has a min
    scaled Jacobian at most that (measured on its mesh), so skipping it loses nothing."""
    from jaxmatch.geometry import cumulative_length
    from jaxmatch.inputs import _lattice
    from jaxmatch.meshing.region import canonical
    from jaxmatch.placement.decompose import single_patch
    from jaxmatch.placement.bounds import single_sj_bound
    from jaxmatch.placement.solve import ALL_SIZES
    from jaxmatch.shape import DEFAULT_CORNER_ANGLE

    shp = jaxmatch.load_shape(path)
    h = float(cumulative_length(shp.input_points)[-1]) / div
    bound = single_sj_bound(single_patch(canonical(shp, h, DEFAULT_CORNER_ANGLE)), cat, _lattice("fine"), sizes=ALL_SIZES)
    one = jaxmatch.mesh(shp, size=h, catalogue=cat, strategies=["single"])
    m = next(c.mesh for c in one.tried if c.name == "single")  # not a larger template tried after it
    assert m.inverted > 0 or m.min_scaled_jacobian <= bound


@pytest.mark.parametrize("ks", [(0, 1), (2, 3), (4, 5)])
@pytest.mark.parametrize("corners", [(1, 1, 1, 1), (1, 1, 1, 1, 3, 1), (1, 1, 3, 1, 1, 3, 1, 1), (1, 1, 1, 1, 3, 3, 1, 1),
                                     (1, 3, 1, 1, 3, 1, 1, 3, 1, 1, 3, 1)])
def test_grid_templates_exist_against_a_scan(cat, ks, corners):
    """``grid_templates_exist`` agrees with a plain scan of every catalogue mesh of those sizes:
    all internal valences 4, and the boundary valences read from some vertex, either way round,
    are ``1 + corners[i]`` at the corners in order with only 3s between them."""
    from jaxmatch.catalogue.mesh import valences
    from jaxmatch.placement.bounds import grid_templates_exist

    want = [1 + q for q in corners]
    expect = False
    for b in cat.buckets(list(ks)):
        for mesh_id in b.ids.tolist():
            mesh = cat.mesh(mesh_id)
            val = valences(np.asarray(mesh.quads, np.int64), mesh.n_vertices)
            on = np.zeros(mesh.n_vertices, bool)
            on[np.asarray(mesh.boundary)] = True
            seq = val[np.asarray(mesh.boundary)].tolist()
            if not np.all(val[~on] == 4) or any(x not in (2, 3, 4) for x in seq):
                continue
            kept = [x for x in seq if x != 3]
            rolls = [kept[r:] + kept[:r] for r in range(len(kept))] or [[]]
            if any(r == want or r[::-1] == want for r in rolls):
                expect = True
    assert grid_templates_exist(cat, ks, corners) == expect


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CONCAVE))
def test_concave_shapes_at_two_sizes(cat, name):
    shp = jaxmatch.load_shape(CONCAVE[name])
    for size in (0.25, 0.125):
        check_mesh(shp, jaxmatch.mesh(shp, size=size, catalogue=cat))
    assert cat.cache.size("templates")  # the second size reused the templates


def test_tshape_at_a_quarter_meshes(cat):
    """Once a solver failure of HiGHS (status 4), reported as "no multiplicities found"."""
    shp = jaxmatch.load_shape(EX / "tshape.json")
    check_mesh(shp, jaxmatch.mesh(shp, size=0.25, catalogue=cat))


@pytest.mark.parametrize("w,h,size", [(10, 10, 1.0), (3, 1, 0.25), (4, 2, 0.5), (5, 3, 1.0)])
def test_rectangles_with_sides_multiple_of_h_give_the_plain_grid(cat, w, h, size):
    shp = jaxmatch.make_shape([[0, 0], [w, 0], [w, h], [0, h]])
    m = jaxmatch.mesh(shp, size=size, catalogue=cat)
    nx, ny = round(w / size), round(h / size)
    assert m.quads.shape[0] == nx * ny
    val, on_b = valence_plain(m.quads, len(m.xy))
    assert np.all(val[~on_b] == 4)
    assert sj_plain(m.xy, m.quads).min() == pytest.approx(1.0)


@pytest.mark.parametrize("path", [LAB / "trapezoid.json", EX / "hexagon.json", EX / "triangle.json", LAB / "pentagon.json"])
@pytest.mark.parametrize("div", [16, 32])
def test_every_side_follows_the_size(cat, path, div):
    shp = jaxmatch.load_shape(path)
    per = float(np.sum(np.linalg.norm(np.roll(shp.input_points, -1, 0) - shp.input_points, axis=1)))
    # the side counts of the templates and cuts (the ring partition may trade a side off by a
    # fraction of an edge for no edge longer than 2h: tests/test_rings.py)
    m = jaxmatch.mesh(shp, size=per / div, catalogue=cat, strategies=[n for n in strategy_names() if n != "rings"])
    assert m.sides_off_size(QUALITY.size_tol) == []
    # independently: count the boundary edges between consecutive corners along the loop
    loop = m.line_sets["boundary"][:, 0]
    at = sorted(int(np.flatnonzero(np.linalg.norm(m.xy[loop] - c, axis=1) < 1e-9)[0]) for c in shp.input_points[shp.corners])
    h = per / div
    for a, b in zip(at, at[1:] + [at[0] + len(loop)]):
        n = b - a
        L = float(np.linalg.norm(m.xy[loop[b % len(loop)]] - m.xy[loop[a]]))  # straight sides
        assert abs(n - L / h) <= max(1, QUALITY.size_tol * L / h), (n, L / h)


@pytest.mark.parametrize("path", [EX / "lshape.json", EX / "hexagon.json", LAB / "notched-rectangle.json"])
def test_the_same_mesh_however_the_loop_is_written(cat, path):
    data = json.loads(Path(path).read_text())
    pts = np.asarray(data["boundary"], float)
    base = jaxmatch.mesh(jaxmatch.make_shape(pts), size=0.25, catalogue=cat)
    for variant in (np.roll(pts, 2, axis=0), pts[::-1], np.roll(pts[::-1], 3, axis=0)):
        m = jaxmatch.mesh(jaxmatch.make_shape(variant), size=0.25, catalogue=cat)
        assert m.chosen == base.chosen and m.quads.shape == base.quads.shape
        a = np.unique(np.round(m.xy, 9), axis=0)
        b = np.unique(np.round(base.xy, 9), axis=0)
        assert a.shape == b.shape and np.allclose(a, b, atol=1e-7)


def grid_mesh(nx, ny, fold: bool = False, patches: int = 1) -> QuadMesh:
    vid = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    quads = np.array([[vid[j, i], vid[j, i + 1], vid[j + 1, i + 1], vid[j + 1, i]] for j in range(ny) for i in range(nx)])
    xy = np.array([[i, j] for j in range(ny + 1) for i in range(nx + 1)], float)
    if fold:
        xy[vid[1, 1]] = [2.5, 2.5]
    corners = xy[[vid[0, 0], vid[0, nx], vid[ny, nx], vid[ny, 0]]]
    patch = (np.arange(len(quads)) * patches // len(quads)).astype(np.int64)
    return QuadMesh(xy=xy, quads=quads, patch=patch, line_sets={}, region_area=float(nx * ny), corners=corners)


@pytest.mark.parametrize("fold", [False, True])
def test_kept_measures_are_the_plain_ones(fold):
    """QuadMesh computes its measures once (also across with_choice); they are the plain
    functions' values, and the arrays it hands out are copies."""
    from jaxmatch.catalogue.mesh import edges, valences
    from jaxmatch.meshing.result import boundary_loops
    from jaxmatch.quality import inverted_mask, quality

    m = grid_mesh(4, 3, fold=fold, patches=2)
    for mm in (m, m.with_choice("x", "", None, ()), m.with_choice("y", "", None, ())):
        sj = quality(m.xy, m.quads)[0]
        np.testing.assert_array_equal(mm.scaled_jacobian, sj)
        assert mm.min_scaled_jacobian == float(sj.min()) and mm.mean_scaled_jacobian == float(sj.mean())
        assert mm.inverted == int(inverted_mask(m.xy, m.quads).sum())
        assert mm.irregular_bound == irregular_bound(m.quads, m.xy.shape[0])
        e = edges(m.quads)
        assert mm.mean_edge_length == float(np.linalg.norm(m.xy[e[:, 0]] - m.xy[e[:, 1]], axis=1).mean())
        val = valences(m.quads, m.xy.shape[0])
        internal = np.ones(m.xy.shape[0], bool)
        for loop in boundary_loops(m.quads):
            internal[loop] = False
        np.testing.assert_array_equal(mm.irregular, np.flatnonzero(internal & (val != 4) & (val > 0)))
        assert mm.missed_corners.shape == (0, 2)
    m.scaled_jacobian[:] = 5.0
    assert m.min_scaled_jacobian <= 1.0


def test_a_poor_mesh_says_so_and_a_good_one_does_not():
    """Never a silent bad mesh: below the quality floor, too many irregular vertices or edges
    longer than the policy allows, each named with what to do; a plain grid has no warning."""
    from dataclasses import replace
    from jaxmatch.defaults import Quality
    good = grid_mesh(3, 3)
    assert good.warnings() == [] and good.summary()["warnings"] == []
    bent = grid_mesh(3, 3)
    xy = bent.xy.copy()
    xy[5] = [1.9, 1.9]  # vertex (1, 1) pushed towards (2, 2): its quads are poor
    poor = replace(bent, xy=xy)
    assert not poor.min_scaled_jacobian >= 0.3
    (w,) = poor.warnings()
    assert w.startswith("poor mesh: min scaled Jacobian") and "smaller --size" in w
    assert poor.warnings(Quality(good_sj=-1.0)) == []  # the floor is the policy's, passed down
    sized = replace(good, size=0.4)  # every edge 1 = 2.5 x the size
    (w,) = sized.warnings()
    assert w.startswith("24 edges longer than 2 x the size")


def test_irregular_bound_is_eulers():
    assert irregular_bound(grid_mesh(3, 2).quads, 12) == 0
    # one quad: four valence-2 corners, sum of (3 - valence) = 4 = 4 * (1 - 0 holes)
    assert irregular_bound(np.array([[0, 1, 2, 3]]), 4) == 0
    # a triangle split into three quads around a valence-3 centre: bound 1
    tri = np.array([[0, 3, 6, 5], [3, 1, 4, 6], [5, 6, 4, 2]])
    assert irregular_bound(tri, 7) == 1


def test_the_rule_order():
    good, folded, two = grid_mesh(3, 3), grid_mesh(3, 3, fold=True), grid_mesh(3, 3, patches=2)
    assert folded.inverted > 0
    picked = choose([Candidate("a", folded), Candidate("b", good)])
    assert picked.chosen == "b" and picked.rule == "no fold" and picked.runner_up == "a"
    picked = choose([Candidate("a", two), Candidate("b", good), Candidate("c", None, "failed")])
    assert picked.chosen == "b" and picked.rule == "fewer patches" and len(picked.tried) == 3
    picked = choose([Candidate("a", good), Candidate("b", grid_mesh(3, 3))])
    assert picked.chosen == "a" and picked.rule == "order tried"
    assert RULES[0] == "no fold" and RULES[-1] == "order tried"
    with pytest.raises(ValueError):
        choose([Candidate("a", None, "failed")])


@pytest.mark.parametrize("n, size, coarse", [
    (4, 1.0, 0),    # at the size
    (4, 4.0, 0),    # 4 edges where the size asks for 1: finer, never ruled out
    (4, 0.7, 0),    # mean edge 1.43 h: within the band
    (4, 0.5, 4),    # 4 edges for 8 h on each side: every side coarse
    (1, 0.55, 0),   # 1 edge for 1.8 h: coarser than 1.5 h, but within one edge of rounding
    (2, 0.6, 0),    # 2 edges for 3.3 h: 1.67 h each, 1.1 h with one more
    (2, 0.4, 4),    # 2 edges for 5 h: 2.5 h each, 1.67 h with one more
])
def test_a_side_is_coarse_only_past_the_band_and_one_edge_of_rounding(n, size, coarse):
    """Size conformity rules out sides meshed coarser than ``coarse_side * h`` even with one edge
    more (one edge of rounding), not finer ones: a feature smaller than the size is meshed finer."""
    import dataclasses

    m = dataclasses.replace(grid_mesh(n, n), size=size)
    assert m.coarse_stretches(QUALITY.coarse_side) == coarse
    assert coarse == 4 * int(n / (n + 1) > QUALITY.coarse_side * size)  # independently: each side is n unit edges


def test_quality_comes_before_the_size_fit():
    """Between two meshes at or finer than the size, the higher quality wins, whatever the
    fit of their side counts (rule "min scaled Jacobian" before "size fit")."""
    import dataclasses

    fine = dataclasses.replace(grid_mesh(4, 4), size=2.0)  # a 4 x 4 square, 4 edges per side where 2 are asked
    two = grid_mesh(2, 2)
    xy = 2 * two.xy + np.c_[0.8 * two.xy[:, 1], np.zeros(len(two.xy))]  # 2 edges per side, sheared: lower quality
    sheared = dataclasses.replace(two, xy=xy, corners=xy[[0, 2, 8, 6]], region_area=16.0, size=2.0)
    assert fine.stretches_off_size(QUALITY.size_tol) > 0 and sheared.stretches_off_size(QUALITY.size_tol) == 0
    picked = choose([Candidate("at size", sheared), Candidate("finer", fine)])
    assert picked.chosen == "finer" and picked.rule == "min scaled Jacobian"


def test_size_conformity_is_a_yes_or_no():
    """Two meshes that both have an edge longer than 2h: the count of such edges does not decide
    before quality (rule "min scaled Jacobian"); a mesh without any beats both (rule "size
    conformity")."""
    import dataclasses

    coarse_good = dataclasses.replace(grid_mesh(2, 2), size=0.4)  # every edge 2.5 h: 12 long edges
    two = grid_mesh(2, 2)
    xy = two.xy + np.c_[0.4 * two.xy[:, 1], np.zeros(len(two.xy))]
    coarse_poor = dataclasses.replace(two, xy=xy, corners=xy[[0, 2, 8, 6]], size=0.52)  # sheared, 6 long edges
    assert 0 < coarse_poor.long_edges(QUALITY.long_edge) < coarse_good.long_edges(QUALITY.long_edge)
    picked = choose([Candidate("fewer long, poorer", coarse_poor), Candidate("more long, better", coarse_good)])
    assert picked.chosen == "more long, better" and picked.rule == "min scaled Jacobian"
    at_size = dataclasses.replace(coarse_poor, size=1.0)
    picked = choose([Candidate("long", coarse_good), Candidate("at size", at_size)])
    assert picked.chosen == "at size" and picked.rule == "size conformity"


def _strip(height: float) -> QuadMesh:
    """A 4 x 1 row of quads ``height`` tall at the size 1: the long sides at the size, the short
    sides one edge of ``height`` (``height / h`` within one edge of rounding: the size fit holds)."""
    import dataclasses

    m = grid_mesh(4, 1)
    xy = m.xy * [1.0, height]
    return dataclasses.replace(m, xy=xy, corners=xy[[0, 4, 9, 5]], region_area=4.0 * height, size=1.0)


def test_the_size_band_decides_after_the_size_fit_and_only_as_a_yes_or_no():
    """Rectangles of the same quality whose sides all fit the size: a row of unit quads (every
    edge h) beats the same row 1.8 tall (its 5 edges across at 1.8 h: 8 of 13 edges within
    [0.5 h, 1.5 h], below 80 %) on the size band; two meshes that both miss it are not told apart
    by it. The ring partition is wanted for a best mesh that nearly meets it (at least
    ``Quality.band_near`` of its edges at the size), not for one far off it (a 4 x 4 grid of unit
    quads at the size 2.5: every edge 0.4 h)."""
    import dataclasses
    from types import SimpleNamespace

    at_size, tall, taller = _strip(1.0), _strip(1.8), _strip(1.9)
    for m in (at_size, tall, taller):
        assert not m.size_conformity(QUALITY) and m.size_fit(QUALITY) == 0 and m.min_scaled_jacobian == 1.0
    assert at_size.band_share(QUALITY.size_band) == 1.0 and tall.band_share(QUALITY.size_band) == pytest.approx(8 / 13)
    picked = choose([Candidate("tall", tall), Candidate("at size", at_size)])
    assert picked.chosen == "at size" and picked.rule == "size band"
    picked = choose([Candidate("taller", taller), Candidate("tall", tall)])
    assert picked.rule != "size band"
    assert not tall.misses_size_band(dataclasses.replace(QUALITY, band_share=0.6))
    far = dataclasses.replace(grid_mesh(4, 4), size=2.5)
    assert far.band_share(QUALITY.size_band) == 0.0 and far.misses_size_band(QUALITY)
    assert tall.near_size_band(QUALITY) and not far.near_size_band(QUALITY) and not at_size.near_size_band(QUALITY)
    req = SimpleNamespace(quality=QUALITY)
    assert strat.RingPartition().wanted(tall, [], req)
    assert not strat.RingPartition().wanted(far, [], req) and not strat.RingPartition().wanted(at_size, [], req)


def test_lean_curves_are_tried_off_the_size_band_and_kept_only_at_it(monkeypatch):
    """:class:`LeanCurves` is wanted when the best mesh nearly meets the size band and the region
    has curved sides (not for a polygon whose vertices are all corners, not far off the band,
    not with a size field); of its meshes it keeps those that meet the band with a min scaled
    Jacobian at most ``Quality.lean_cost`` below the best's (the layouts themselves come from
    ``try_layouts``, replaced here by ready meshes); only the best mesh's own layout is meshed
    again, none when it is not one of the strategy's."""
    import dataclasses
    from types import SimpleNamespace

    from jaxmatch.shape import make_shape

    fine = dataclasses.replace(grid_mesh(4, 4), size=2.5)  # far off the band (every edge 0.4 h), min SJ 1
    half = _strip(1.8)  # the best so far: a near miss, min SJ 1
    at_size = _strip(1.0)
    two = grid_mesh(4, 4)
    xy = two.xy + np.c_[0.3 * two.xy[:, 1], np.zeros(len(two.xy))]  # sheared: at the size, min SJ 0.96
    sheared = dataclasses.replace(two, xy=xy, corners=xy[[0, 4, 24, 20]], size=1.0)
    assert not sheared.misses_size_band(QUALITY) and sheared.min_scaled_jacobian < 1 - QUALITY.lean_cost
    square = make_shape([[0, 0], [4, 0], [4, 4], [0, 4]])
    disk = make_shape([[2 + 2 * np.cos(t), 2 + 2 * np.sin(t)] for t in np.linspace(0, 2 * np.pi, 40, endpoint=False)])
    assert not strat.has_curves(square) and strat.has_curves(disk)
    lean = strat.LeanCurves((strat.Rings(),))
    tried = [Candidate("rings", half)]
    assert lean.wanted(half, tried, SimpleNamespace(quality=QUALITY, region=disk))
    assert not lean.wanted(half, tried, SimpleNamespace(quality=QUALITY, region=square))
    assert not lean.wanted(at_size, tried, SimpleNamespace(quality=QUALITY, region=disk))
    assert not lean.wanted(fine, tried, SimpleNamespace(quality=QUALITY, region=disk))
    assert not lean.wanted(half, tried, SimpleNamespace(quality=dataclasses.replace(QUALITY, field=lambda p: p[:, 0]),
                                                        region=disk))
    made = [Candidate("a" + strat.LEAN, at_size), Candidate("b" + strat.LEAN, sheared),
            Candidate("c" + strat.LEAN, fine), Candidate("d" + strat.LEAN, None, "cannot beat")]
    seen = {}

    def fake(region, strategies, *args, **kw):
        seen.update(kw, strategies=strategies)
        return made

    monkeypatch.setattr(strat, "try_layouts", fake)
    req = SimpleNamespace(quality=QUALITY, region=disk, cat=None, lat=None, h=1.0, corners=np.zeros((0, 2)),
                          budget_s=None, t0=0.0, progress=None)
    kept = lean.candidates(req, tried)
    assert [c.name for c in kept] == ["a" + strat.LEAN]
    assert seen["lean_curves"] and seen["best"][1] == "rings" and [s.name for s in seen["strategies"]] == ["rings"]
    assert strat.LeanCurves((strat.Split("continuations"),)).candidates(req, tried) == []
    req.quality = dataclasses.replace(QUALITY, lean_cost=0.1)  # a larger cost allowed: the sheared one too
    assert [c.name for c in lean.candidates(req, tried)] == ["a" + strat.LEAN, "b" + strat.LEAN]


def test_size_conformity_counts_the_misses_of_a_size_field_only():
    """For one size, size conformity is a yes or no; with a size field (the same size
    everywhere here) it counts the misses: long edges, coarse stretches."""
    import dataclasses

    uniform = dataclasses.replace(grid_mesh(4, 4), size=0.4)  # every edge 2.5 h
    graded = dataclasses.replace(uniform, field=lambda p: np.full(len(p), 0.4))
    assert uniform.long_edges(QUALITY.long_edge) == 40 and uniform.size_conformity(QUALITY) == 1
    assert graded.size_conformity(QUALITY) == graded.long_edges(QUALITY.long_edge) + graded.coarse_stretches(
        QUALITY.coarse_side) + graded.short_edges(QUALITY.short_edge) == 44


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 4), st.integers(1, 4), st.booleans(), st.integers(1, 4), st.integers(0, 6),
       st.sampled_from([None, 0.5, 1.0, 3.0]))
def test_no_mesh_beats_the_best_possible_key(nx, ny, fold, patches, order, size):
    """The skip rule's bound: no mesh of that many patches, tried at that place, has a smaller
    key; and a candidate is skipped only when the best so far is smaller than that bound."""
    import dataclasses

    m = grid_mesh(max(nx, 2) if fold else nx, max(ny, 2) if fold else ny, fold=fold, patches=patches)
    if size is not None:
        m = dataclasses.replace(m, size=size)
    bound = best_possible_key(m.n_patches, order)
    assert mesh_key(m, order) >= bound
    assert not cannot_win(mesh_key(m, order), m.n_patches, order)  # never skips a mesh as good as itself
    assert cannot_win(bound, m.n_patches + 1, order)  # more patches: a perfect mesh beats it
    assert cannot_win(bound, m.n_patches, order + 1)  # tried later: the earlier wins a tie


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.integers(1, 3)), min_size=1, max_size=5))
def test_choose_takes_the_smallest_key(specs):
    cands = [Candidate(f"c{i}", grid_mesh(2, 2, fold=f, patches=p)) for i, (f, p) in enumerate(specs)]
    picked = choose(cands)
    keys = [mesh_key(c.mesh, i) for i, c in enumerate(cands)]
    assert picked.chosen == cands[keys.index(min(keys))].name


@pytest.mark.parametrize("inserted", [0, 1, 3])
def test_a_skipped_candidate_never_wins_and_keeps_its_place(inserted):
    """A candidate skipped because it could not win (``Candidate.bound``: its best possible key,
    tied with the winner's but for the order tried) stays behind the winner when the pipeline
    inserts more candidates after the single template (the order is their place in the list)."""
    perfect = grid_mesh(2, 2, fold=False, patches=1)
    order = 1
    best = Candidate("a", perfect)
    skipped = Candidate("b", None, "1 patches cannot beat a", best_possible_key(perfect.n_patches, order + 1))
    assert cannot_win(mesh_key(perfect, order), perfect.n_patches, order + 1)
    extra = [Candidate(f"single x{j}", grid_mesh(2, 2, fold=True, patches=1)) for j in range(inserted)]
    first = Candidate("single", grid_mesh(2, 2, fold=True, patches=1))
    picked = choose([first] + extra + [best, skipped])
    assert picked.chosen == "a" and picked.runner_up == "b" and picked.rule == "order tried"


def test_every_result_writes_with_groups(cat, tmp_path):
    """Every result is a QuadMesh by the time it is written (one output path)."""
    import meshio

    from jaxmatch.meshing.build import from_refined

    shp = jaxmatch.load_shape(EX / "lshape.json")
    lat = jaxmatch.load_lattice("fine")
    results = {
        "mesh": jaxmatch.mesh(shp, size=0.25, catalogue=cat),
        "template": jaxmatch.mesh(shp, template=True, catalogue=cat, internal=2),
        "refine": from_refined(shp, jaxmatch.refine_mesh(shp, cat, lat, size=0.25).mesh, size=0.25),
        "concave": jaxmatch.mesh_concave(shp, 0.25, cat),
        "layout": jaxmatch.mesh_layout(EX / "layouts" / "two-blocks.json", cat, size=0.5),
    }
    for name, res in results.items():
        path = jaxmatch.write_mesh(tmp_path / f"{name}.msh", res)
        back = meshio.read(path)
        assert "boundary" in back.field_data, name
        assert back.cells_dict["quad"].shape[0] > 0
    m = results["mesh"]
    back = meshio.read(tmp_path / "mesh.msh")
    assert {"boundary", "patch 0", "patch 1"} <= set(back.field_data)
    assert back.cells_dict["quad"].shape == m.quads.shape
    with pytest.raises(TypeError):
        jaxmatch.write_mesh(tmp_path / "x.msh", object())


def test_solver_failure_is_not_infeasible(monkeypatch):
    from jaxmatch.placement import milp

    calls = []

    def fake(*a, presolve, time_limit, status=4):
        calls.append(presolve)
        return status, None, "stub"

    monkeypatch.setattr(milp, "_highs", fake)
    args = (np.ones(1), np.ones((1, 1)), np.ones(1), np.ones(1), np.ones(1), np.zeros(1), np.ones(1))
    with pytest.raises(SolverError) as e:
        milp.run_milp(*args)
    assert e.value.status == 4 and calls == [True, False]  # retried without presolve
    monkeypatch.setattr(milp, "_highs", lambda *a, **k: (2, None, "infeasible"))
    assert milp.run_milp(*args) is None  # infeasible


@pytest.mark.parametrize("jump", [None, True])
@pytest.mark.parametrize("name", ["lshape.json", "tshape.json", "hexagon.json", "curved.json"])
def test_highs_directly_is_scipy_milp_to_the_bit(cat, monkeypatch, name, jump):
    """The integer programs of a mesh solved through highspy give scipy.optimize.milp's optimum
    and the same status for an infeasible one; without the feasibility jump (the default,
    FEASIBILITY_JUMP, which scipy cannot turn off) a solution meeting every constraint, a tie
    possibly broken otherwise; with it scipy's solutions bit for bit (the same HiGHS release)."""
    pytest.importorskip("highspy")
    import scipy.optimize

    from jaxmatch.placement import layout, milp, refine

    if jump is not None:
        monkeypatch.setattr(milp, "FEASIBILITY_JUMP", jump)
    monkeypatch.setattr(milp, "STRIPS", False)  # every program to HiGHS (milp.strip_counts answers some)

    programs = []
    real = milp.run_milp

    def spy(*args, **kw):
        programs.append(args)
        return real(*args, **kw)

    monkeypatch.setattr(milp, "run_milp", spy)
    cat.cache.clear()
    shp = jaxmatch.load_shape(EX / name)
    jaxmatch.mesh(shp, catalogue=cat, divisions=24)
    assert programs
    cost, A, lo, hi, integ, lb, ub = (np.asarray(a, np.float64).copy() for a in programs[0])
    j = int(np.flatnonzero(integ)[0])
    lb[j], ub[j] = 1.25, 1.75  # no integer between: infeasible
    programs.append((cost, A, lo, hi, integ, lb, ub))
    statuses = []
    for prog in programs:
        cost, A, lo, hi, integ, lb, ub = (np.asarray(a, np.float64) for a in prog)
        st, x, _ = milp._highs(cost, A, lo, hi, integ, lb, ub, presolve=True, time_limit=30.0)
        ref = scipy.optimize.milp(cost, constraints=scipy.optimize.LinearConstraint(A, lo, hi), integrality=integ,
                                  bounds=scipy.optimize.Bounds(lb, ub), options={"time_limit": 30.0, "presolve": True})
        assert st == ref.status
        statuses.append(st)
        if ref.x is None:
            assert x is None
        elif milp.FEASIBILITY_JUMP:
            np.testing.assert_array_equal(x, ref.x)
        else:  # the same optimum; a tie may be broken otherwise
            assert cost @ x == pytest.approx(cost @ ref.x, rel=1e-9, abs=1e-9)
            ii = integ == 1
            assert np.all(np.abs(x[ii] - np.rint(x[ii])) < 1e-6)
            assert np.all(A @ x >= lo - 1e-6) and np.all(A @ x <= hi + 1e-6)  # HiGHS's tolerances
            assert np.all(x >= lb - 1e-9) and np.all(x <= ub + 1e-9)
    assert statuses[-1] == 2 and 0 in statuses


def test_highs_without_highspy_is_scipy_milp(monkeypatch):
    """Without the highspy package the integer program goes to scipy.optimize.milp, with the same answer."""
    pytest.importorskip("highspy")
    from jaxmatch.placement import milp

    # min x + y subject to x + 2 y >= 3.5, x and y integers in [0, 10]: x + y = 2 at (0, 2)
    args = [np.array(v, np.float64) for v in ([1.0, 1.0], [[1.0, 2.0]], [3.5], [np.inf], [1, 1], [0, 0], [10, 10])]
    with_highspy = milp._highs(*args, presolve=True, time_limit=30.0)
    monkeypatch.setitem(sys.modules, "highspy", None)  # import highspy -> ImportError
    without = milp._highs(*args, presolve=True, time_limit=30.0)
    assert with_highspy[0] == without[0] == 0
    np.testing.assert_array_equal(with_highspy[1], without[1])
    assert with_highspy[1] @ [1.0, 1.0] == 2.0


def test_bad_requests(cat):
    shp = jaxmatch.load_shape(EX / "square.json")
    for kwargs in ({"size": 0}, {"size": -1.0}, {"size": float("nan")}, {"size": 1, "sides": [1, 1, 1, 1]},
                   {"template": True, "size": 1}, {"strategies": ["zigzag"]}):
        with pytest.raises(InputError):
            jaxmatch.mesh(shp, catalogue=cat, **kwargs)


@pytest.mark.parametrize("path", [EX / "lshape.json", EX / "hexagon.json"])
def test_divisions_give_the_perimeter_over_that_many(cat, path):
    from jaxmatch.geometry import cumulative_length

    shp = jaxmatch.load_shape(path)
    perimeter = float(cumulative_length(shp.input_points)[-1])
    by_divisions = jaxmatch.mesh(shp, divisions=16, catalogue=cat)
    by_size = jaxmatch.mesh(shp, size=perimeter / 16, catalogue=cat)
    assert by_divisions.size == pytest.approx(perimeter / 16)
    np.testing.assert_array_equal(by_divisions.quads, by_size.quads)
    np.testing.assert_allclose(by_divisions.xy, by_size.xy)


@pytest.mark.parametrize("kw", [dict(divisions=0), dict(divisions=2.5), dict(divisions=True),
                                dict(divisions=8, size=0.5), dict(divisions=8, sides=[2, 2, 2, 2, 2, 2])])
def test_bad_divisions(cat, kw):
    with pytest.raises(InputError, match="divisions"):
        jaxmatch.mesh(EX / "lshape.json", catalogue=cat, **kw)


def test_default_size_is_a_fraction_of_the_perimeter(cat):
    m = jaxmatch.mesh(EX / "square.json", catalogue=cat)
    assert m.size == pytest.approx(4.0 / 32) and m.quads.shape[0] == 64


# ---------------------------------------------------------------------------------------------
# the command


def test_cli_mesh_reports_the_choice(cli, tmp_path):
    out, png = tmp_path / "l.msh", tmp_path / "l.png"
    code, stdout, err = cli("mesh", EX / "lshape.json", "--size", "0.25", "--out", out, "--png", png)
    assert code == 0, err
    assert "chosen: recursive (rule that decided: fewer patches; runner-up continuations, not meshed: at its best)" in stdout
    assert "bisectors: not meshed (min scaled Jacobian at most 0.71 cannot beat recursive; a node splits" in stdout
    assert "continuations: not meshed (3 patches cannot beat recursive)" in stdout
    assert "single: not meshed (min scaled Jacobian at most 0.96 cannot beat recursive; no template of its sizes" in stdout
    assert out.exists() and png.read_bytes().startswith(b"\x89PNG")


def test_cli_mesh_without_size_prints_the_default(cli):
    code, stdout, err = cli("mesh", EX / "square.json")
    assert code == 0, err
    assert "(default: perimeter / 32)" in stdout and "64 quads" in stdout


def test_cli_divisions_give_each_region_its_own_size(cli, tmp_path):
    code, stdout, err = cli("mesh", EX / "lshape.json", "--divisions", "16")
    assert code == 0, err
    assert "size 0.5:" in stdout  # the L's perimeter is 8
    code, _, err = cli("mesh", EX / "square.json", EX / "lshape.json", "--divisions", "16", "--out-dir", tmp_path / "d")
    assert code == 0, err
    recs = [json.loads(line) for line in (tmp_path / "d" / "summary.jsonl").read_text().splitlines()]
    assert [r["quads"] for r in recs] == [16, 12]  # the square (perimeter 4) at 0.25, the L at 0.5
    for other in (["--size", "0.5"], ["--sides", "2,2,2,2,2,2"]):
        code, _, err = cli("mesh", EX / "lshape.json", "--divisions", "16", *other)
        assert code == EXIT_BAD_INPUT and "--divisions" in err and len(err.strip().splitlines()) == 1


def test_cli_template_options_need_template(cli):
    code, _, err = cli("mesh", EX / "square.json", "--rank", "2")
    assert code == EXIT_BAD_INPUT and "--rank" in err and "--template" in err
    code, stdout, err = cli("mesh", EX / "square.json", "--template", "--internal", "1", "--json")
    assert code == 0, err
    assert json.loads(stdout)["internal_vertices"] == 1


@pytest.mark.slow
def test_cli_many_regions_with_one_bad(cli, tmp_path):
    """50 regions, one bad: 49 meshes and one error record with --skip-bad, exit 0."""
    rng = np.random.default_rng(7)
    paths = []
    for i in range(50):
        p = tmp_path / f"r{i:02d}.json"
        if i == 17:
            p.write_text('{"boundary": [[0, 0], [1, 0]]}')  # two points: not a region
        else:
            w, h = rng.integers(1, 4, size=2)
            p.write_text(json.dumps({"boundary": [[0, 0], [int(w), 0], [int(w), int(h)], [0, int(h)]]}))
        paths.append(p)
    out = tmp_path / "out"
    code, _, err = cli("mesh", *paths, "--size", "0.5", "--out-dir", out, "--skip-bad", "--jobs", "2")
    assert code == 0, err
    recs = [json.loads(line) for line in (out / "summary.jsonl").read_text().splitlines()]
    assert len(recs) == 50 and [r["shape"] for r in recs] == [str(p) for p in paths]
    bad = [r for r in recs if "error" in r]
    assert len(bad) == 1 and bad[0]["shape"] == str(paths[17])
    assert len(list(out.glob("*.msh"))) == 49
    assert all(r["inverted"] == 0 and r["min_scaled_jacobian"] == pytest.approx(1.0) for r in recs if "error" not in r)
    # without --skip-bad the bad region stops the run before any work: one line, exit 2
    out2 = tmp_path / "out2"
    code, _, err = cli("mesh", *paths[15:20], "--size", "0.5", "--out-dir", out2)
    assert code == EXIT_BAD_INPUT and str(paths[17]) in err and len(err.strip().splitlines()) == 1
    assert not out2.exists()


def test_time_budget_keeps_the_best_valid_mesh_so_far(cat):
    m = jaxmatch.mesh(CONCAVE["Z"], divisions=16, catalogue=cat, budget_s=1e-9)
    notes = {c.name: c.note for c in m.tried}
    meshed = [c.name for c in m.tried if c.mesh is not None]
    # the first candidate tried (the cuts of fewest patches, the one whose nodes allow the best
    # quality first; the single patch of a concave region comes last) is kept; the single patch
    # could still have won (one patch, and a grid template of its sizes exists) but is skipped for
    # time; the others could not have won
    assert meshed == [m.chosen] == ["recursive"] and m.valid
    assert "time budget" in notes["single"]
    assert all("cannot beat" in notes[n] for n in ("continuations", "bisectors"))


def test_pipeline_warm_up_meshes_with_the_defaults_and_with_given_models():
    """jaxmatch mesh of many regions warms its parent with pipeline.warm_up (which must not fail
    silently there): with its defaults and with a catalogue and lattice passed."""
    import jaxmatch
    from jaxmatch.meshing.pipeline import warm_up
    from jaxmatch.scoring.lattice import load_lattice

    warm_up()
    warm_up(jaxmatch.load_catalogue(), load_lattice("coarse"))


def _dedupe_plain(ring, corners, tol):
    """Points within ``tol`` of the previous kept one merged (the last onto the first), corners
    moved onto the point that absorbed them: a plain loop."""
    keep, owner = [0], [0]
    for i in range(1, len(ring)):
        if np.hypot(*(ring[i] - ring[keep[-1]])) > tol:
            keep.append(i)
        owner.append(len(keep) - 1)
    if len(keep) > 1 and np.hypot(*(ring[keep[-1]] - ring[0])) <= tol:
        owner = [0 if o == len(keep) - 1 else o for o in owner]
        keep.pop()
    return ring[keep], sorted({owner[c] for c in corners})


@settings(max_examples=60, deadline=None)
@given(n=st.integers(3, 12), dup=st.lists(st.integers(0, 11), max_size=4), seed=st.integers(0, 10**6))
def test_dedupe_merges_near_points_as_a_plain_loop(n, dup, seed):
    """``canonical``'s merge of near points: the same points and corners as a plain loop, with
    nothing to merge (its shortcut) and with points a hair from the previous one."""
    from jaxmatch.meshing.region import _dedupe

    rng = np.random.default_rng(seed)
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    for d in sorted({d % n for d in dup if d % n}, reverse=True):  # a copy a hair after point d - 1
        ring = np.insert(ring, d, ring[d - 1] + 1e-12, axis=0)
    corners = sorted(set(rng.integers(0, len(ring), 3).tolist()))
    got_ring, got_corners, kept = _dedupe(ring, np.array(corners), 1e-9)
    assert np.array_equal(ring[kept], got_ring)  # the kept points' indices (the file's numbering goes with them)
    want_ring, want_corners = _dedupe_plain(ring, corners, 1e-9)
    assert np.array_equal(got_ring, want_ring) and list(got_corners) == want_corners
