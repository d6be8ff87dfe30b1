"""Groups named after the input (jaxmatch.meshing.groups): every ``side i-j`` of a written mesh lies
on, and covers, the input file's side from its corner i to corner j (read back with meshio, the
side taken from the file's own JSON with shapely), for every strategy, either loop direction and
any start point; tags are line groups of their sides in every format with groups; periodic sides
get equal counts and nodes that are translates (read back by meshio and by gmsh's $Periodic)."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import jaxmatch
from jaxmatch.errors import InputError

meshio = pytest.importorskip("meshio")
ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


# ---------------------------------------------------------------------------------------------
# the independent check: the file's sides, the .msh's groups


def file_loops(doc: dict) -> list[tuple[str, np.ndarray, list[int]]]:
    """``(name prefix, points (P, 2), corner point numbers in the file's corner order)`` of each
    loop of a JSON shape, straight from the file (every point a corner unless ``corners`` says)."""
    def ring(pts):
        p = np.asarray(pts, float)
        return p[:-1] if len(p) > 3 and np.array_equal(p[0], p[-1]) else p

    out = []
    outer = ring(doc["boundary"])
    out.append(("side", outer, list(doc.get("corners", range(len(outer))))))
    for h, hole in enumerate(doc.get("holes", []), start=1):
        hp = ring(hole)
        hc = (doc.get("hole_corners") or [None] * len(doc["holes"]))[h - 1]
        out.append((f"hole {h} side", hp, list(range(len(hp))) if hc is None else list(hc)))
    return out


def expected_sides(doc: dict) -> dict[str, np.ndarray]:
    """``{group name: the side's polyline (k, 2) from corner i to j in the file's order}``; the
    names use point numbers, or positions in ``corners`` where the file lists them."""
    out = {}
    for prefix, pts, corners in file_loops(doc):
        listed = prefix == "side" and "corners" in doc
        n = len(corners)
        for k in range(n):
            a, b = corners[k], corners[(k + 1) % n]
            i, j = (k, (k + 1) % n) if listed else (a, b)
            for step in (1, -1):  # the stretch from a to b holding no other corner (a list may run backwards)
                idx = [a]
                while idx[-1] != b:
                    idx.append((idx[-1] + step) % len(pts))
                if n <= 2 or not set(idx[1:-1]) & set(corners):
                    break
            out[f"{prefix} {i}-{j}"] = pts[idx]
    return out


def msh_line_groups(path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``(points (V, 2), {physical name: (E, 2) edges})`` of the line elements of a .msh file (meshio)."""
    r = meshio.read(path)
    name = {int(v[0]): k for k, v in r.field_data.items() if int(v[1]) == 1}
    groups: dict[str, list] = {}
    for block, tags in zip(r.cells, r.cell_data["gmsh:physical"]):
        if block.type == "line":
            for t in np.unique(tags):
                groups.setdefault(name[int(t)], []).append(block.data[tags == t])
    return r.points[:, :2], {k: np.concatenate(v) for k, v in groups.items()}


def check_side(xy: np.ndarray, edges: np.ndarray, poly: np.ndarray, extent: float) -> None:
    """The edges lie on the polyline and cover it: one path from its first point to its last,
    every vertex on it, and (straight stretches) every edge on it, lengths summing to its length."""
    tol = 1e-6 * extent
    line = shapely.LineString(poly)
    verts, deg = np.unique(edges, return_counts=True)
    assert np.max(shapely.distance(line, shapely.points(xy[verts]))) < tol
    ends = verts[deg == 1]
    assert len(ends) == 2 and np.all(deg <= 2), "the group is one path"
    assert {tuple(np.round(xy[e], 9)) for e in ends} == {tuple(np.round(poly[0], 9)), tuple(np.round(poly[-1], 9))}
    length = float(np.linalg.norm(xy[edges[:, 0]] - xy[edges[:, 1]], axis=1).sum())
    straight = shapely.LineString([poly[0], poly[-1]]).hausdorff_distance(line) < tol
    if straight:
        mids = 0.5 * (xy[edges[:, 0]] + xy[edges[:, 1]])
        assert np.max(shapely.distance(line, shapely.points(mids))) < tol
        assert length == pytest.approx(line.length, rel=1e-6)
    else:  # chords of a curve: shorter than it, within 1 %
        assert line.length * 0.99 < length <= line.length * (1 + 1e-9)


def check_file(path: Path, doc: dict, m) -> dict[str, np.ndarray]:
    """Write ``m`` as .msh, read it back, check every side group against the file; the groups."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        jaxmatch.write_mesh(path, m)
    xy, groups = msh_line_groups(path)
    want = expected_sides(doc)
    extent = float(np.ptp(np.asarray(doc["boundary"], float), axis=0).max())
    got = {k for k in groups if k.startswith("side ") or " side " in k}
    assert got == set(want), (sorted(got), sorted(want))
    for name, poly in want.items():
        check_side(xy, groups[name], poly, extent)
    outer = [k for k in want if k.startswith("side ")]
    assert sum(len(groups[k]) for k in outer) == len(groups["boundary"])  # the sides partition the boundary
    assert len({tuple(sorted(e)) for k in outer for e in groups[k].tolist()}) == len(groups["boundary"])
    return groups


HEXAGON = json.loads((EXAMPLES / "hexagon.json").read_text())["boundary"]
CASES = {
    "lshape": json.loads((EXAMPLES / "lshape.json").read_text()),
    "hexagon-rotated-reversed": {"boundary": (HEXAGON[2:] + HEXAGON[:2])[::-1]},
    "lshape-clockwise-from-3": {"boundary": [[1, 1], [2, 1], [2, 0], [0, 0], [0, 2], [1, 2]]},
    "triangle-hole": json.loads((EXAMPLES / "holes" / "triangle-hole.json").read_text()),
    "curved-corners": json.loads((EXAMPLES / "curved.json").read_text()),
    "square-corners-listed-backwards": {"boundary": [[0, 0], [1, 0], [2, 0], [2, 1], [0, 1]], "corners": [4, 3, 2, 0]},
}
SIZES = {"curved-corners": 0.25, "triangle-hole": 0.5}


@pytest.mark.parametrize("case", sorted(CASES))
def test_side_groups_lie_on_and_cover_the_files_sides(case, tmp_path):
    doc = CASES[case]
    src = tmp_path / f"{case}.json"
    src.write_text(json.dumps(doc))
    m = jaxmatch.mesh(src, size=SIZES.get(case, 0.25))
    groups = check_file(tmp_path / "m.msh", doc, m)
    assert m.side_counts == {k.removeprefix("side "): len(v) for k, v in groups.items()
                             if k.startswith("side ") or " side " in k}
    for name, poly in expected_sides(doc).items():  # the lengths the size test reads: the file's sides'
        assert m.side_lengths[name.removeprefix("side ")] == pytest.approx(shapely.LineString(poly).length, rel=1e-12)


STRATEGIES = ("single", "continuations", "bisectors", "recursive", "rings")


@pytest.mark.parametrize("strategy", STRATEGIES)
@pytest.mark.parametrize("case", ["lshape", "lshape-clockwise-from-3", "triangle-hole"])
def test_the_same_names_for_every_strategy(case, strategy, tmp_path):
    doc = CASES[case]
    src = tmp_path / f"{case}.json"
    src.write_text(json.dumps(doc))
    try:
        m = jaxmatch.mesh(src, size=SIZES.get(case, 0.25), strategies=[strategy])
    except InputError as e:  # (a strategy that makes no mesh of this region)
        pytest.skip(f"{strategy}: {e}")
    assert m.chosen.split()[0] == strategy
    check_file(tmp_path / "m.msh", doc, m)


def test_template_and_fixed_counts_get_the_names_too(tmp_path):
    doc = CASES["lshape-clockwise-from-3"]
    src = tmp_path / "l.json"
    src.write_text(json.dumps(doc))
    check_file(tmp_path / "t.msh", doc, jaxmatch.mesh(src, template=True, internal=4))
    m = jaxmatch.mesh(src, sides=[2, 3, 4, 4, 3, 2])  # side i from corner i to i + 1: 0-1, 1-2, ..., 5-0
    check_file(tmp_path / "s.msh", doc, m)
    assert m.side_counts == {"0-1": 2, "1-2": 3, "2-3": 4, "3-4": 4, "4-5": 3, "5-0": 2}


@settings(max_examples=8)
@given(n=st.integers(4, 7), seed=st.integers(0, 2**16), start=st.integers(0, 6), reverse=st.booleans())
def test_random_polygons_any_start_and_direction(n, seed, start, reverse, tmp_path_factory):
    rng = np.random.default_rng(seed)
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    ang = ang[np.diff(np.concatenate([ang, [ang[0] + 2 * np.pi]])) > 0.4] if n > 4 else np.linspace(0, 2 * np.pi, 5)[:4] + 0.3
    assume(len(ang) >= 3)  # (angles closer than 0.4 dropped: a polygon needs 3 points)
    r = rng.uniform(0.6, 1.0, len(ang))
    pts = np.round(np.column_stack([r * np.cos(ang), r * np.sin(ang)]), 6).tolist()
    xy = np.asarray(pts)
    a, b = np.roll(xy, 1, axis=0) - xy, np.roll(xy, -1, axis=0) - xy
    inner = np.degrees(np.arccos(np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1), -1, 1)))
    assume(inner.min() > 10)  # (not a sliver: three nearly collinear points given as corners have corners of ~0.1 degree,
    # which no quad keeps, and the mesher says so in one line; this test is about the groups' names)
    pts = pts[start % len(pts):] + pts[:start % len(pts)]
    doc = {"boundary": pts[::-1] if reverse else pts}
    tmp = tmp_path_factory.mktemp("poly")
    src = tmp / "p.json"
    src.write_text(json.dumps(doc))
    shape = jaxmatch.load_shape(src)
    if shape.n_corners != len(pts):  # (a vertex turning less than the corner angle: not a corner)
        doc["corners"] = [int(i) for i in range(len(pts))]
        src.write_text(json.dumps(doc))
    m = jaxmatch.mesh(src, divisions=12)
    check_file(tmp / "m.msh", doc, m)


# ---------------------------------------------------------------------------------------------
# tags


TAGGED = {"boundary": [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]],
          "holes": [[[0.3, 0.3], [0.6, 0.3], [0.6, 0.6], [0.3, 0.6]]],
          "tags": {"inlet": ["5-0"], "wall": ["0-1", "2-1"], "hole": ["hole 1"], "lip": ["hole 1 side 0-1"]}}


def test_tags_are_line_groups_of_their_sides(tmp_path):
    src = tmp_path / "t.json"
    src.write_text(json.dumps(TAGGED))
    m = jaxmatch.mesh(src, size=0.1)
    groups = check_file(tmp_path / "m.msh", TAGGED, m)

    def edges(*names):
        return {tuple(sorted(e)) for n in names for e in groups[n].tolist()}

    assert edges("inlet") == edges("side 5-0")
    assert edges("wall") == edges("side 0-1", "side 1-2")
    assert edges("hole") == edges("hole 1") == edges(*[k for k in groups if k.startswith("hole 1 side")])
    assert edges("lip") == edges("hole 1 side 0-1")
    xy, _ = msh_line_groups(tmp_path / "m.msh")
    assert np.allclose(xy[np.unique(groups["inlet"])][:, 0], 0.0)  # side 5-0 is x = 0


def test_tags_in_every_format_with_groups(tmp_path):
    src = tmp_path / "t.json"
    src.write_text(json.dumps(TAGGED))
    m = jaxmatch.mesh(src, size=0.25)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for suf in ("inp", "exo", "xdmf", "vtu", "json"):
            jaxmatch.write_mesh(tmp_path / f"m.{suf}", m)
    inp = meshio.read(tmp_path / "m.inp")
    assert {"inlet", "wall", "hole", "lip"} <= set(inp.point_sets)
    assert set(inp.point_sets["inlet"].tolist()) == set(np.unique(m.line_sets["side 5-0"]).tolist())
    exo = meshio.read(tmp_path / "m.exo")
    assert set(np.asarray(exo.point_sets["wall"]).tolist()) == set(np.unique(np.concatenate(
        [m.line_sets["side 0-1"], m.line_sets["side 1-2"]])).tolist())
    assert "inlet=" in " ".join(str(w.message) for w in caught)  # XDMF: the facet markers' table names it
    groups = json.loads((tmp_path / "m.json").read_text())["groups"]
    assert sorted(map(sorted, groups["lip"])) == sorted(map(sorted, m.line_sets["hole 1 side 0-1"].tolist()))


def test_a_tag_of_a_round_hole(tmp_path):
    doc = json.loads((EXAMPLES / "holes" / "plate-bolt.json").read_text())
    doc["tags"] = {"bolt": ["hole 1"]}
    src = tmp_path / "p.json"
    src.write_text(json.dumps(doc))
    m = jaxmatch.mesh(src, size=0.4)
    hole = shapely.LinearRing(doc["holes"][0])
    assert len(m.line_sets["bolt"]) == len(m.line_sets["hole 1"]) > 8
    assert np.max(shapely.distance(hole, shapely.points(m.xy[np.unique(m.line_sets["bolt"])]))) < 1e-9


def test_geojson_properties_tags(tmp_path):
    src = tmp_path / "g.geojson"
    src.write_text(json.dumps({"type": "Feature", "properties": {"tags": {"bottom": ["0-1"]}},
                               "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [2, 0], [2, 1], [0, 1], [0, 0]]]}}))
    m = jaxmatch.mesh(src, size=0.5)
    assert np.allclose(m.xy[np.unique(m.line_sets["bottom"])][:, 1], 0.0) and len(m.line_sets["bottom"]) == 4


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "jaxmatch.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


@pytest.mark.parametrize("extra, words", [
    ({"tags": {"inlet": ["0-2"]}}, ["tag 'inlet'", "'0-2' is not a side"]),
    ({"tags": {"side 9": ["0-1"]}}, ["tag 'side 9'", "clashes"]),
    ({"tags": {"wall": ["hole 3"]}}, ["tag 'wall'", "not a hole"]),
    ({"periodic": [["0-1", "1-2"]]}, ["periodic pair 1", "not translates"]),
    ({"periodic": [["0-1", "0-1"]]}, ["periodic pair 1"]),
])
def test_bad_tags_and_pairs_are_one_line_errors(extra, words, tmp_path):
    src = tmp_path / "bad.json"
    src.write_text(json.dumps({"boundary": [[0, 0], [2, 0], [2, 1], [0, 1]], **extra}))
    out = tmp_path / "m.msh"
    r = run_cli("mesh", src, "--size", 0.5, "--out", out)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and str(src) in r.stderr, r.stderr
    assert all(w in r.stderr for w in words), r.stderr
    assert not out.exists()


def test_make_shape_takes_tags_and_names_unknown_sides():
    s = jaxmatch.make_shape([[0, 0], [1, 0], [1, 1], [0, 1]], tags={"top": ["2-3"]})
    assert s.tags == (("top", ("side 2-3",)),)
    with pytest.raises(InputError, match="tag 'top': '2-4' is not a side"):
        jaxmatch.make_shape([[0, 0], [1, 0], [1, 1], [0, 1]], tags={"top": ["2-4"]})


# ---------------------------------------------------------------------------------------------
# periodic sides

SKEW = {"boundary": [[0, 0], [2, 0.5], [2, 1.5], [1, 2.2], [0, 1]], "periodic": [["1-2", "0-4"]]}


def test_periodic_sides_equal_counts_and_translated_nodes(tmp_path):
    src = tmp_path / "p.json"
    src.write_text(json.dumps(SKEW))
    free = jaxmatch.mesh(dict_shape := jaxmatch.make_shape(SKEW["boundary"]), size=0.18)
    assert free.side_counts["1-2"] != free.side_counts["4-0"]  # the pair is not equal by chance
    m = jaxmatch.mesh(src, size=0.18)
    assert dict_shape.n_corners == 5 and m.side_counts["1-2"] == m.side_counts["4-0"]
    a, b = m.point_sets["periodic 1 a"], m.point_sets["periodic 1 b"]
    assert np.allclose(m.xy[b] - m.xy[a], [-2.0, -0.5], atol=1e-9, rtol=0)
    assert np.allclose(m.xy[a][:, 0], 2.0) and m.inverted == 0 and m.min_scaled_jacobian > 0.3
    check_file(tmp_path / "m.msh", SKEW, m)

    r = meshio.read(tmp_path / "m.msh")  # $Periodic: (slave, master) node pairs, the affine map
    ((dim, (slave, master), affine, pairs),) = r.gmsh_periodic
    assert dim == 1 and np.allclose(np.reshape(affine, (4, 4))[:2, 3], [-2.0, -0.5])
    # (meshio lists MSH 4.1 nodes entity by entity; the pairs are the file's node tags - 1, our ids)
    assert np.allclose(m.xy[pairs[:, 0]] - m.xy[pairs[:, 1]], [-2.0, -0.5], atol=1e-9)
    assert len(pairs) == m.side_counts["1-2"] + 1

    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(tmp_path / "m.msh"))
        tag_master, nodes, nodes_master, aff = gmsh.model.mesh.getPeriodicNodes(1, int(slave))
        assert tag_master == master and len(nodes) == len(pairs)
        coord = {}
        tags, xyz, _ = gmsh.model.mesh.getNodes()
        coord = dict(zip(tags.tolist(), xyz.reshape(-1, 3)[:, :2]))
        moved = np.array([coord[n] - coord[k] for n, k in zip(nodes, nodes_master)])
        assert np.allclose(moved, [-2.0, -0.5], atol=1e-9) and np.allclose(np.reshape(aff, (4, 4))[:2, 3], [-2, -0.5])
    finally:
        gmsh.finalize()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for suf in ("inp", "exo"):
            jaxmatch.write_mesh(tmp_path / f"m.{suf}", m)
    for suf, key in (("inp", "periodic_1_{}"), ("exo", "periodic 1 {}")):
        ps = meshio.read(tmp_path / f"m.{suf}").point_sets
        pa, pb = np.asarray(ps[key.format("a")]), np.asarray(ps[key.format("b")])
        assert np.allclose(m.xy[pb] - m.xy[pa], [-2.0, -0.5], atol=1e-9)  # node groups in matching order


def test_periodic_sides_of_a_concave_region_for_several_strategies(tmp_path):
    """An L-shape whose end faces (3,0)-(3,1) and (2,1)-(2,2) are translates by (-1, 1); its
    bottom and top (lengths 3 and 2) are not, and are refused."""
    doc = {"boundary": [[0, 0], [3, 0], [3, 1], [2, 1], [2, 2], [0, 2]], "periodic": [["0-1", "5-4"]]}
    src = tmp_path / "l.json"
    src.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="not translates"):
        jaxmatch.load_shape(src)
    doc["periodic"] = [["1-2", "3-4"]]
    src.write_text(json.dumps(doc))
    for strategy in ("continuations", "recursive", "single"):
        m = jaxmatch.mesh(src, size=0.2, strategies=[strategy])
        assert m.side_counts["1-2"] == m.side_counts["3-4"]
        a, b = m.point_sets["periodic 1 a"], m.point_sets["periodic 1 b"]
        assert np.allclose(m.xy[b] - m.xy[a], [-1.0, 1.0], atol=1e-9, rtol=0) and m.inverted == 0


def test_corners_out_of_boundary_order_name_sides_by_point_numbers(tmp_path):
    src = tmp_path / "s.json"
    src.write_text(json.dumps({"boundary": [[0, 0], [1, 0], [2, 0], [2, 1], [0, 1]], "corners": [0, 3, 2, 4]}))
    with pytest.warns(jaxmatch.InputWarning, match="not listed in boundary order: the output's side groups are named by "
                                                   "point numbers"):
        shape = jaxmatch.load_shape(src)
    m = jaxmatch.mesh(shape, size=0.5)
    assert sorted(k for k in m.line_sets if k.startswith("side ")) == ["side 0-2", "side 2-3", "side 3-4", "side 4-0"]


@given(st.integers(1, 12), st.data())
def test_a_sides_run_is_the_loops_edges_from_a_to_b(n, data):
    """``_run(loop, a, b)``: the loop's edges from position ``a`` to ``b`` going forward (the
    whole loop when they are equal), as indexing the loop by ``(a + range(k + 1)) % n`` gives."""
    from jaxmatch.meshing.groups import _run

    loop = np.asarray(data.draw(st.permutations(list(range(100, 100 + n)))), np.int64)
    a, b = data.draw(st.integers(0, n - 1)), data.draw(st.integers(0, n - 1))
    k = (b - a) % n or n
    idx = (a + np.arange(k + 1)) % n
    want = np.stack([loop[idx[:-1]], loop[idx[1:]]], axis=1)
    got = _run(loop, a, b)
    assert got.dtype == np.int64
    np.testing.assert_array_equal(got, want)


def _wavy(n: int, clockwise: bool = False) -> list[list[float]]:
    """A square whose bottom side is traced with ``n`` uneven points (long sides: numpy sums them pairwise)."""
    bottom = [[10.0 * (k / n) ** 1.3, 0.37 * np.sin(k)] for k in range(n)]
    pts = bottom + [[10.0, 0.0], [10.0, 7.0], [0.0, 7.0]]
    return pts[::-1] if clockwise else pts


@pytest.mark.parametrize("doc", [
    {"boundary": _wavy(30)},
    {"boundary": _wavy(30, clockwise=True)},
    {"boundary": _wavy(12), "corners": [0, 12, 13, 14]},
    {"boundary": _wavy(12), "corners": [14, 13, 12, 0]},  # listed backwards: names run against the loop
    {"boundary": _wavy(20), "holes": [[[2, 2], [2, 4], [3, 4.5], [4, 4], [4, 2]]], "hole_corners": [[4, 3, 1, 0]]},
])
def test_side_lengths_are_the_side_polylines_lengths_bit_for_bit(doc):
    from jaxmatch.sides import named_sides, side_lengths, side_polyline

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        shape = jaxmatch.parse_shape(json.dumps(doc).encode(), "s.json")
    sides = named_sides(shape)
    assert len(sides) >= 4
    plain = [float(np.linalg.norm(np.diff(side_polyline(shape, s), axis=0), axis=1).sum()) for s in sides]
    assert side_lengths(shape, sides) == plain
    assert sum(plain) == pytest.approx(
        shapely.Polygon(shape.given_points, [h for h in shape.holes]).length, rel=1e-12)
