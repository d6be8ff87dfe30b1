"""Assemblies and embedded points and curves (:mod:`jaxmatch.meshing.assembly`): each mesh is
written by ``jaxmatch mesh`` and read back with meshio, and checked with shapely and numpy only:
all quads, each region's cells cover its area, free edges only on the union's outline, every
boundary edge of a region's cells on the outline or shared with exactly one other region (no
hanging node), an interface group per shared boundary covering it with the same node ids from
both sides, every region corner a vertex, embedded points vertices and curves covered by edges.
"""

from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path

import meshio
import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxmatch
from jaxmatch.errors import EXIT_BAD_INPUT, InputError
from jaxmatch.meshing.assembly import _layout_of
from jaxmatch.meshing.region import canonical, load_region
from jaxmatch.model import Embedded, Model
from jaxmatch.placement.rings import ring_layout

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]


def _circle(cx, cy, r, n=32):
    return [[cx + r * math.cos(2 * math.pi * k / n), cy + r * math.sin(2 * math.pi * k / n)] for k in range(n)]


LUG = {"regions": [{"name": "block", "boundary": [[0, 0], [4, 0], [4, 1], [0, 1]]},
                   {"name": "lug", "boundary": [[1.5, 1], [2.5, 1], [2.5, 1.6], [1.5, 1.6]]}]}
TWO_L = {"regions": [{"name": "a", "boundary": [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]},
                     {"name": "b", "boundary": [[2, 0], [3, 0], [3, 2], [1, 2], [1, 1], [2, 1]]}]}
TWO = {"regions": [{"name": "left", "boundary": SQUARE},
                   {"name": "right", "boundary": [[1, 0], [3, 0], [3, 1], [1, 1]]}]}

CASES = {  # name: (document or example file, size)
    "two rectangles": (TWO, 0.25),
    "inclusion": (EXAMPLES / "assemblies" / "inclusion.json", 0.15),
    "laminate": (EXAMPLES / "assemblies" / "laminate.json", 0.1),
    "lug on a side": (LUG, 0.1),
    "two L shapes": (TWO_L, 0.2),
    "crack and point": (EXAMPLES / "assemblies" / "crack.json", 0.1),
    "a point one side lacks": ({"regions": [{"name": "a", "boundary": SQUARE},  # (1, 0.4): inserted into a's side
                                            {"name": "b", "boundary": [[1, 0], [2, 0], [2, 1], [1, 1], [1, 0.4]]}]}, 0.2),
    "holed plate, block, edge crack": ({"regions": [
        {"name": "plate", "boundary": [[0, 0], [2, 0], [2, 1], [0, 1]],
         "holes": [[[0.4, 0.3], [0.8, 0.3], [0.8, 0.7], [0.4, 0.7]]], "embedded": {"curves": [[[2, 0.5], [1.4, 0.5]]]}},
        {"name": "block", "boundary": [[2, 0], [3, 0], [3, 1], [2, 1]]}]}, 0.1),
    "DXF layers: lug": (("dxf", LUG), 0.1),
    "SVG ids: two L shapes": (("svg", TWO_L), 0.2),
}


def _file(tmp_path: Path, doc, name="model.json") -> Path:
    """``doc`` written as JSON (a Path: as it is; ``("dxf", doc)``: each region a closed polyline on
    its own layer; ``("svg", doc)``: each region a polygon element with its name as id)."""
    if isinstance(doc, Path):
        return doc
    if isinstance(doc, tuple) and doc[0] == "dxf":
        import ezdxf

        dxf = ezdxf.new()
        for r in doc[1]["regions"]:
            dxf.modelspace().add_lwpolyline(r["boundary"], close=True, dxfattribs={"layer": r["name"]})
        path = tmp_path / "model.dxf"
        dxf.saveas(path)
        return path
    if isinstance(doc, tuple) and doc[0] == "svg":
        shapes = "".join(f'<polygon id="{r["name"]}" points="{" ".join(f"{x},{y}" for x, y in r["boundary"])}"/>'
                         for r in doc[1]["regions"])
        path = tmp_path / "model.svg"
        path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 10">{shapes}</svg>')
        return path
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _regions(doc) -> dict[str, shapely.Polygon]:
    """The regions of an assembly document (or JSON file) as shapely polygons (read here, not by
    jaxmatch; SVG coordinates are read as they are written)."""
    doc = doc[1] if isinstance(doc, tuple) else json.loads(doc.read_text()) if isinstance(doc, Path) else doc
    items = doc["regions"] if "regions" in doc else [dict(doc, name="region")]
    return {r["name"]: shapely.Polygon(r["boundary"], holes=r.get("holes", [])) for r in items}


def _read(path: Path):
    """``(points (V, 2), quads (Q, 4), region name per quad, line groups, vertex groups)`` of a .msh."""
    m = meshio.read(path)
    names = {int(tag): name for name, (tag, dim) in m.field_data.items()}
    quads, region, lines, verts = [], [], {}, {}
    for block, tags in zip(m.cells, m.cell_data["gmsh:physical"]):
        if block.type == "quad":
            quads.append(block.data)
            region += [names[int(t)] for t in tags]
        elif block.type == "line":
            for t in np.unique(tags):
                lines[names[int(t)]] = block.data[tags == t]
        elif block.type == "vertex":
            for t in np.unique(tags):
                verts[names[int(t)]] = block.data[tags == t].ravel()
        else:
            raise AssertionError(f"unexpected cell type {block.type}")
    return m.points[:, :2], np.concatenate(quads), np.array(region), lines, verts


def _edges(quads: np.ndarray) -> np.ndarray:
    e = np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2)
    return np.sort(e, axis=1)


def _once(edges: np.ndarray) -> set:
    keys, counts = np.unique(edges, axis=0, return_counts=True)
    return {tuple(k) for k in keys[counts == 1].tolist()}


def _scaled_jacobian(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Min over the 4 corners of the cross product of the unit edges (numpy, written here)."""
    p = xy[quads]
    a = np.roll(p, -1, axis=1) - p
    b = np.roll(p, 1, axis=1) - p
    a /= np.linalg.norm(a, axis=2, keepdims=True)
    b /= np.linalg.norm(b, axis=2, keepdims=True)
    return (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]).min(axis=1)


def _length(xy, edges) -> float:
    return float(np.linalg.norm(xy[edges[:, 0]] - xy[edges[:, 1]], axis=1).sum())


@pytest.mark.parametrize("case", list(CASES))
def test_assembly_is_one_conforming_mesh(cli, tmp_path, case):
    doc, size = CASES[case]
    src = _file(tmp_path, doc)
    out = tmp_path / "a.msh"
    code, stdout, err = cli("mesh", src, "--size", size, "--out", out)
    assert code == 0, err
    _check_conforming(out, _regions(doc), size)


def _check_conforming(out: Path, polys: dict, size: float) -> None:
    """The checks of the module docstring on the mesh file ``out`` of the regions ``polys``."""
    xy, quads, region, lines, _ = _read(out)
    assert set(region) == set(polys)
    sj = _scaled_jacobian(xy, quads)
    area = 0.5 * np.abs(np.sum(xy[quads, 0] * np.roll(xy[quads, 1], -1, axis=1)
                               - np.roll(xy[quads, 0], -1, axis=1) * xy[quads, 1], axis=1))
    union = shapely.union_all(list(polys.values()))
    tol = 1e-9 * max(union.bounds[2] - union.bounds[0], union.bounds[3] - union.bounds[1])
    # each region: its cells' area, quality, corners as vertices
    for name, poly in polys.items():
        mine = region == name
        assert abs(area[mine].sum() - poly.area) <= 0.01 * poly.area, name
        assert sj[mine].min() >= 0.3, (name, sj[mine].min())
        for c in np.asarray(poly.exterior.coords):
            assert np.min(np.linalg.norm(xy - c, axis=1)) < 1e-9 or not _is_corner(poly, c), (name, c)
    # free edges: on the union's outline, as long as it
    free = np.array(sorted(_once(_edges(quads))))
    mids = shapely.points(0.5 * (xy[free[:, 0]] + xy[free[:, 1]]))
    assert np.all(shapely.distance(union.boundary, mids) <= 1e-3 * size)
    assert abs(_length(xy, free) - union.boundary.length) <= 0.01 * union.boundary.length
    # no hanging node: each boundary edge of a region's cells is free, or on exactly one other region's
    own = {name: _once(_edges(quads[region == name])) for name in polys}
    outline = {tuple(e) for e in free.tolist()}
    for name, edges in own.items():
        for e in edges:
            others = [o for o in polys if o != name and e in own[o]]
            assert (e in outline) != (len(others) == 1), (name, e, others)
    # an interface group per shared boundary: same node ids from both sides, the shared length
    for a in polys:
        for b in polys:
            if a < b:
                shared = polys[a].boundary.intersection(polys[b].boundary).length
                key = f"{a}|{b}"
                if shared <= tol:
                    assert key not in lines
                    continue
                e = np.sort(lines[key], axis=1)
                assert {tuple(x) for x in e.tolist()} <= own[a] & own[b]
                assert abs(_length(xy, e) - shared) <= 0.01 * shared


def _is_corner(poly, c) -> bool:
    """``c`` turns the outline by more than 30 degrees (a corner jaxmatch must keep)."""
    ring = np.asarray(poly.exterior.coords)[:-1]
    i = int(np.argmin(np.linalg.norm(ring - c, axis=1)))
    a, b = ring[i] - ring[i - 1], ring[(i + 1) % len(ring)] - ring[i]
    return abs(math.degrees(math.atan2(a[0] * b[1] - a[1] * b[0], a @ b))) > 30


def test_embedded_point_is_a_vertex_and_curve_is_covered_by_edges(cli, tmp_path):
    src = EXAMPLES / "assemblies" / "crack.json"
    doc = json.loads(src.read_text())
    out = tmp_path / "c.msh"
    code, _, err = cli("mesh", src, "--size", 0.1, "--out", out)
    assert code == 0, err
    xy, quads, _, lines, verts = _read(out)
    (p,) = doc["embedded"]["points"]
    (v,) = verts["point 1"]
    assert np.linalg.norm(xy[v] - p) < 1e-9
    curve = shapely.LineString(doc["embedded"]["curves"][0])
    e = lines["curve 1"]
    assert np.all(shapely.distance(curve, shapely.points(xy[e.ravel()])) < 1e-9)
    assert abs(_length(xy, e) - curve.length) < 1e-9
    for end in curve.coords:  # the crack's tips are vertices
        assert np.min(np.linalg.norm(xy - end, axis=1)) < 1e-9
    assert set(map(tuple, np.sort(e, axis=1).tolist())) <= {tuple(x) for x in _edges(quads).tolist()}
    assert _scaled_jacobian(xy, quads).min() >= 0.3


@settings(max_examples=12, deadline=None)
@given(x0=st.floats(0.05, 3.0), width=st.floats(0.3, 1.0), height=st.floats(0.2, 1.0),
       cut=st.floats(0.2, 0.8))
def test_a_lug_anywhere_on_a_split_block_is_conforming(x0, width, height, cut):
    """A lug whose corners fall anywhere on the top of a block made of two regions side by side
    (T-junctions on both of them, and the lug across their interface or not): conforming."""
    x1 = min(x0 + width, 3.95)
    regions = {"left": [[0, 0], [4 * cut, 0], [4 * cut, 1], [0, 1]], "right": [[4 * cut, 0], [4, 0], [4, 1], [4 * cut, 1]],
               "lug": [[x0, 1], [x1, 1], [x1, 1 + height], [x0, 1 + height]]}
    if any(abs(4 * cut - x) < 0.05 for x in (x0, x1)):  # (a lug corner within 1/20 of the interface: slivers)
        return
    m = jaxmatch.mesh(regions=[{"name": k, "boundary": v} for k, v in regions.items()], size=0.1)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "m.msh"
        jaxmatch.write_mesh(out, m)
        _check_conforming(out, {k: shapely.Polygon(v) for k, v in regions.items()}, 0.1)


@pytest.mark.parametrize("doc, what", [
    ({"regions": [{"name": "a", "boundary": SQUARE}, {"name": "b", "boundary": [[0.5, 0], [2, 0], [2, 1], [0.5, 1]]}]},
     "regions 'a' and 'b' overlap"),
    ({"regions": [{"name": "a", "boundary": SQUARE}, {"name": "a", "boundary": [[1, 0], [2, 0], [2, 1], [1, 1]]}]},
     "two regions are named 'a'"),
    ({"boundary": SQUARE, "embedded": {"points": [[2, 2]]}}, "embedded point 1 (2, 2) lies outside"),
    ({"boundary": SQUARE, "embedded": {"curves": [[[0.5, 0.5], [1.5, 0.5]]]}}, "embedded curve 1 leaves the regions"),
    ({"regions": [{"name": "a", "boundary": SQUARE}], "colour": 1}, "unknown key 'colour'"),
    ({"regions": [{"name": "a", "boundary": SQUARE}, {"name": "b", "boundary": [[2, 0], [3, 0], [3, 1], [2, 1]]}]},
     "region 'b' does not meet region 'a'"),
])
def test_bad_models_are_one_line_errors(cli, tmp_path, doc, what):
    code, stdout, err = cli("mesh", _file(tmp_path, doc), "--size", 0.25, "--out", tmp_path / "x.msh")
    assert code == EXIT_BAD_INPUT
    assert what in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "x.msh").exists()


def test_python_api_regions_and_loaded_model(tmp_path):
    m = jaxmatch.mesh(regions=TWO["regions"], size=0.25)
    assert m.regions == ("left", "right") and m.chosen == "assembly"
    assert set(m.cell_sets) == {"left", "right"}
    assert abs(np.sum(m.patch == 1) - 2 * np.sum(m.patch == 0)) == 0  # a 1 x 1 and a 2 x 1 rectangle at one size
    model = load_region(_file(tmp_path, TWO))
    assert isinstance(model, Model)
    again = jaxmatch.mesh(model, size=0.25)
    assert np.array_equal(again.quads, m.quads) and "left|right" in again.line_sets
    with pytest.raises(InputError, match="an assembly is meshed at a size"):
        jaxmatch.mesh(model, sides=[4, 4, 4, 4])
    regions = [jaxmatch.Region(r["name"], jaxmatch.make_shape(r["boundary"])) for r in TWO["regions"]]
    assert np.array_equal(jaxmatch.mesh(regions=regions, size=0.25).quads, m.quads)


def test_points_on_the_outline_and_on_an_interface_are_vertices_on_them():
    """A point on a side moves a vertex along that side: the side stays straight and covered."""
    doc = dict(TWO, embedded={"points": [[3, 0.37], [1, 0.61], [2.3, 0]]})
    m = jaxmatch.mesh(jaxmatch.make_model([jaxmatch.Region(r["name"], jaxmatch.make_shape(r["boundary"]))
                                           for r in doc["regions"]], Embedded(np.array(doc["embedded"]["points"]))),
                      size=0.25)
    for k, p in enumerate(doc["embedded"]["points"], start=1):
        (v,) = m.point_sets[f"point {k}"]
        assert np.linalg.norm(m.xy[v] - p) < 1e-9
    for name, line in (("right side 1-2", [[3, 0], [3, 1]]), ("left|right", [[1, 0], [1, 1]]),
                       ("right side 0-1", [[1, 0], [3, 0]])):
        e = m.line_sets[name]
        assert np.all(shapely.distance(shapely.LineString(line), shapely.points(m.xy[e.ravel()])) < 1e-9)
        assert abs(_length(m.xy, e) - shapely.LineString(line).length) < 1e-9
    assert m.valid and m.min_scaled_jacobian >= 0.3


def test_geojson_feature_collection_and_dxf_layers_are_assemblies(tmp_path):
    feats = [{"type": "Feature", "properties": {"name": r["name"]},
              "geometry": {"type": "Polygon", "coordinates": [r["boundary"] + [r["boundary"][0]]]}}
             for r in TWO_L["regions"]]
    feats.append({"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [0.5, 0.5]}})
    gj = tmp_path / "two.geojson"
    gj.write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    model = load_region(gj)
    assert isinstance(model, Model) and model.names == ("a", "b") and model.embedded.points.tolist() == [[0.5, 0.5]]
    ezdxf = pytest.importorskip("ezdxf")
    doc = ezdxf.new()
    for r in LUG["regions"]:
        doc.modelspace().add_lwpolyline(r["boundary"], close=True, dxfattribs={"layer": r["name"]})
    dxf = tmp_path / "lug.dxf"
    doc.saveas(dxf)
    model = load_region(dxf)
    assert isinstance(model, Model) and model.names == ("block", "lug")
    m = jaxmatch.mesh(model, size=0.1)
    assert "block|lug" in m.line_sets and m.valid


def test_svg_shapes_with_ids_are_an_assembly(tmp_path):
    svg = tmp_path / "two.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 3 1">'
                   '<rect id="left" x="0" y="0" width="1" height="1"/>'
                   '<rect id="right" x="1" y="0" width="2" height="1"/></svg>')
    model = load_region(svg)
    assert isinstance(model, Model) and model.names == ("left", "right")
    m = jaxmatch.mesh(model, size=0.25)
    assert "left|right" in m.line_sets and m.valid


@pytest.mark.parametrize("doc", [TWO_L, LUG], ids=["two L shapes", "lug on a side"])
def test_region_side_groups_cover_the_input_sides(tmp_path, doc):
    """``NAME side i-j``: the region's cells' edges along its side from point i to i + 1 (every
    point of these polygons a corner), on the outline or on an interface."""
    m = jaxmatch.mesh(load_region(_file(tmp_path, doc)), size=0.1)
    for r in doc["regions"]:
        pts = np.asarray(r["boundary"], float)
        for i in range(len(pts)):
            j = (i + 1) % len(pts)
            side = shapely.LineString([pts[i], pts[j]])
            e = m.line_sets[f"{r['name']} side {i}-{j}"]
            assert np.all(shapely.distance(side, shapely.points(m.xy[e.ravel()])) < 1e-9)
            assert abs(_length(m.xy, e) - side.length) < 1e-9 * side.length
            key = f"{r['name']} side {i}-{j}"  # side_counts (--json, summary.jsonl) keyed as the groups
            assert m.side_counts[key] == len(e) and abs(m.side_lengths[key] - side.length) < 1e-9 * side.length
    assert set(m.side_counts) == {k for k in m.line_sets if " side " in k and not k.startswith("hole ")}


@pytest.mark.slow
def test_motor_section(cli, tmp_path):
    """Rotor, air gap, stator and 6 coils (72-gons and arcs): one mesh, 8 interfaces."""
    out = tmp_path / "motor.msh"
    code, _, err = cli("mesh", EXAMPLES / "assemblies" / "motor.json", "--size", 0.1, "--out", out)
    assert code == 0, err
    xy, quads, region, lines, _ = _read(out)
    assert len(set(region)) == 9 and sum("|" in k for k in lines) == 8
    assert _scaled_jacobian(xy, quads).min() >= 0.3


def test_abaqus_file_has_region_element_sets_and_point_node_sets(cli, tmp_path):
    out = tmp_path / "c.inp"
    code, _, err = cli("mesh", EXAMPLES / "assemblies" / "crack.json", "--size", 0.1, "--out", out)
    assert code == 0, err
    m = meshio.read(out)
    (p,) = json.loads((EXAMPLES / "assemblies" / "crack.json").read_text())["embedded"]["points"]
    (v,) = m.point_sets["point_1"]
    assert np.linalg.norm(m.points[v, :2] - p) < 1e-9
    assert sum(len(c) for c in m.cell_sets["region"]) == len(m.cells[0].data)


@pytest.mark.parametrize("suffix", ["", " +lean curves", " +transitions", " +lean curves +transitions"])
def test_a_region_meshed_with_the_solves_options_gives_its_layout_again(suffix):
    """A region whose chosen mesh carries a solve option in its name (lean curves, transitions)
    is the same layout for the assembly's one solve (the options are that solve's)."""
    shape = load_region(EXAMPLES / "holes" / "plate-bolt.json")
    lay, single = _layout_of(shape, "rings" + suffix, 0.2, 30.0)
    want = ring_layout(canonical(shape, 0.2, 30.0), 0.2)
    assert not single and np.array_equal(lay.points, want.points)
    assert all(np.array_equal(a, b) for a, b in zip(lay.patches, want.patches))
