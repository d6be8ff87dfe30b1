"""Shape file formats (jaxmatch.io.readers): every format gives the shape the same loop gives
through make_shape; curves are sampled on the curve; errors are one line naming the file.

Independent checks: sampled SVG/DXF points are compared with the analytic curve (distance to
the circle centre), spacing by arc length with distances between consecutive samples, and the
loops written in each format with make_shape on the original coordinates.
"""

from __future__ import annotations

import io
import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.errors import InputError
from jaxmatch.io.readers import FORMATS, detect_format, load_shape, parse_shape, split_element
from jaxmatch.shape import make_shape

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
L_SHAPE = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]


def same_shape(a, b):
    np.testing.assert_allclose(a.user_points, b.user_points, atol=1e-9)
    np.testing.assert_array_equal(a.corners, b.corners)
    np.testing.assert_array_equal(a.convex, b.convex)


def svg(body: str, view: str = "0 0 100 100") -> bytes:
    return f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{view}">{body}</svg>'.encode()


def dxf(build) -> bytes:
    import ezdxf

    doc = ezdxf.new("R2010")
    build(doc.modelspace())
    s = io.StringIO()
    doc.write(s)
    return s.getvalue().encode()


# ---------------------------------------------------------------------------------------------
# examples: each new format gives the shape it draws


def test_example_csv_with_header_and_closed_ring_is_the_l_shape():
    same_shape(load_shape(EXAMPLES / "lshape.csv"), load_shape(EXAMPLES / "lshape.json"))


def test_example_geojson_plate():
    shape = load_shape(EXAMPLES / "plate.geojson")
    same_shape(shape, make_shape([[0, 0], [40, 0], [40, 10], [25, 25], [0, 25]]))


def test_example_svg_needs_its_element_and_reads_the_outline():
    with pytest.raises(InputError, match="2 shape elements.*outline, centre-line"):
        load_shape(EXAMPLES / "bracket.svg")
    shape = load_shape(f"{EXAMPLES / 'bracket.svg'}#outline")
    assert shape.n_corners == 3  # the arc and the end of the cubic join their neighbours smoothly
    xy = shape.user_points
    assert 100 - 0.01 < xy[:, 0].max() <= 100 and xy[:, 1].max() == pytest.approx(60)  # viewBox units, not px
    arc = xy[xy[:, 0] > 70 + 1e-9]
    np.testing.assert_allclose(np.hypot(arc[:, 0] - 70, arc[:, 1] - 30), 30, rtol=1e-9)  # on the circle
    assert load_shape(EXAMPLES / "bracket.svg", element="outline").n_points == shape.n_points


def test_example_dxf_slot_with_a_bulge():
    shape = load_shape(EXAMPLES / "slot.dxf")
    xy = shape.user_points
    arc = xy[xy[:, 0] > 30 + 1e-9]
    assert len(arc) >= 8
    np.testing.assert_allclose(np.hypot(arc[:, 0] - 30, arc[:, 1] - 5), 5, rtol=1e-9)
    assert shape.n_corners == 2  # (0, 0) and (0, 10); the half circle joins the straight sides smoothly


# ---------------------------------------------------------------------------------------------
# text, CSV, TSV


@pytest.mark.parametrize("text", [
    "x,y\n0,0\n2,0\n2,1\n1,1\n1,2\n0,2\n",
    "X;Y\n0;0\n2;0\n2;1\n1;1\n1;2\n0;2\n",
    "# exported\nid\tx\ty\tz\na\t0\t0\t5\nb\t2\t0\t5\nc\t2\t1\t5\nd\t1\t1\t5\ne\t1\t2\t5\nf\t0\t2\t5\n",
    '"y","x"\n0,0\n0,2\n1,2\n1,1\n2,1\n2,0\n',  # columns found by name: y first
    "u v\n0 0\n2 0\n2 1\n1 1\n1 2\n0 2\n0 0\n",  # two unnamed columns; closed ring
    "0 0\n2 0\n2 1\n1 1\n1 2\n0 2\n",
])
def test_text_with_or_without_header(text):
    same_shape(parse_shape(text.encode(), "s.csv"), make_shape(L_SHAPE))


@pytest.mark.parametrize("text, fragment, line", [
    ("a,b,c\n0,0,0\n", "names no columns 'x' and 'y'", 1),
    ("x,y\n0,0\n1,0,3\n", "2 columns as in the header", 3),
    ("x,y\n0,0\n1,zero\n", "not a number", 3),
    ("0 0\nx y\n", "not a number", 2),  # a header after data is not a header
])
def test_text_errors_name_the_line(text, fragment, line):
    with pytest.raises(InputError) as info:
        parse_shape(text.encode(), "t.tsv")
    assert str(info.value).startswith(f"t.tsv:{line}: ") and fragment in str(info.value)


# ---------------------------------------------------------------------------------------------
# GeoJSON


RING = [[0, 0], [4, 0], [4, 1], [2, 3], [0, 1], [0, 0]]


@pytest.mark.parametrize("doc", [
    {"type": "Polygon", "coordinates": [RING]},
    {"type": "Polygon", "coordinates": [[p + [7.5] for p in RING]]},  # 3D positions: z ignored
    {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [RING]}},
    {"type": "MultiPolygon", "coordinates": [[RING]]},
    {"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [0, 0]}},
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [RING]}}]},
])
def test_geojson_polygons(doc):
    got = parse_shape(json.dumps(doc).encode(), "g.geojson")
    same_shape(got, make_shape(RING[:-1]))
    same_shape(parse_shape(json.dumps(doc).encode(), "g.json"), got)  # detected by content too


@pytest.mark.parametrize("doc, fragment", [
    ({"type": "Polygon", "coordinates": [RING, [[11, 11], [12, 11], [12, 12], [11, 11]]]}, "hole 1 lies outside"),
    ({"type": "LineString", "coordinates": RING}, "'LineString' is not a polygon"),
    ({"type": "MultiPolygon", "coordinates": [[RING], [RING]]}, "2 polygons"),
    ({"type": "FeatureCollection", "features": []}, "0 polygon features"),
    ({"type": "Polygon", "coordinates": [[[0, 0], [1, "a"], [0, 1]]]}, "non-number"),
])
def test_geojson_refusals(doc, fragment):
    with pytest.raises(InputError, match=fragment) as info:
        parse_shape(json.dumps(doc).encode(), "g.geojson")
    assert str(info.value).startswith("g.geojson: ")


def test_geojson_feature_chosen_by_name_or_id(tmp_path):
    square = [[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "id": 7, "properties": {"name": "a"}, "geometry": {"type": "Polygon", "coordinates": [RING]}},
        {"type": "Feature", "properties": {"name": "b"}, "geometry": {"type": "Polygon", "coordinates": [square]}}]}
    f = tmp_path / "two.geojson"
    f.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="2 polygon features"):
        load_shape(f)
    assert load_shape(f"{f}#b").n_corners == 4
    assert load_shape(f"{f}#7").n_corners == load_shape(f"{f}#a").n_corners == 5
    with pytest.raises(InputError, match="no feature with id or name 'c' .*7, a, b"):
        load_shape(f"{f}#c")


# ---------------------------------------------------------------------------------------------
# SVG


def test_svg_polygon_rect_and_transforms():
    poly = parse_shape(svg('<polygon points="0,0 2,0 2,1 1,1 1,2 0,2"/>'), "p.svg")
    same_shape(poly, make_shape(L_SHAPE))
    rect = parse_shape(svg('<g transform="translate(10, 20) scale(2)"><rect x="1" y="1" width="3" height="2"/></g>'), "r.svg")
    assert rect.n_corners == 4
    np.testing.assert_allclose(rect.offset, [12, 22])
    assert rect.scale == pytest.approx(6)


def test_svg_circle_is_sampled_evenly_on_the_circle():
    shape = parse_shape(svg('<circle cx="50" cy="40" r="20"/>'), "c.svg")
    xy = shape.user_points
    np.testing.assert_allclose(np.hypot(xy[:, 0] - 50, xy[:, 1] - 40), 20, rtol=1e-9)
    step = np.linalg.norm(np.roll(xy, -1, axis=0) - xy, axis=1)
    assert step.max() / step.min() < 1.01  # equal arc-length steps (chords of equal arcs)
    assert shape.n_corners == 0 and 150 <= shape.n_points <= 260


def test_svg_cubic_sampled_by_arc_length():
    """A cubic with unevenly moving parameter: the samples are evenly spaced along the curve."""
    shape = parse_shape(svg('<path d="M 0 0 C 0 0 90 0 100 100 L 0 100 Z"/>'), "b.svg")
    xy = shape.user_points
    curve = xy[(xy[:, 1] < 100 - 1e-9)]
    curve = curve[np.argsort(curve[:, 1])]
    step = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    assert step.max() / step.min() < 1.05


@pytest.mark.parametrize("body, holes", [
    ('<path fill-rule="evenodd" d="M 0 0 H 10 V 10 H 0 Z M 2 2 H 4 V 4 H 2 Z"/>', 1),      # evenodd: a hole
    ('<path d="M 0 0 H 10 V 10 H 0 Z M 2 2 V 4 H 4 V 2 Z"/>', 1),                          # nonzero, the other way: a hole
    ('<path d="M 0 0 H 10 V 10 H 0 Z M 2 2 H 4 V 4 H 2 Z"/>', 0),                          # nonzero, the same way: filled
    ('<rect width="10" height="10"/><circle cx="5" cy="5" r="2"/>', 1),                     # nested elements
])
def test_svg_regions_with_holes(body, holes):
    shape = parse_shape(svg(body), "d.svg")
    assert len(shape.holes) == holes and shape.n_corners == 4


@pytest.mark.parametrize("body, fragment", [
    ('<path d="M 0 0 L 10 0 L 10 10"/>', "open"),
    ('<path fill-rule="evenodd" d="M 0 0 H 10 V 10 H 0 Z M 2 2 H 8 V 8 H 2 Z M 4 4 H 6 V 6 H 4 Z"/>', "island"),
    ('<path d="M 0 0 H 10 V 10 H 0 Z M 20 2 H 24 V 4 H 20 Z"/>', "not one region"),
    ('<text x="0" y="0">hi</text>', "no path or shape element"),
    ('<rect id="a" width="1" height="1"/><rect id="b" width="2" height="1"/>', "2 shape elements that are not one region "
     "with holes; choose one with FILE#ID; ids: a, b"),
])
def test_svg_refusals(body, fragment):
    with pytest.raises(InputError, match=fragment) as info:
        parse_shape(svg(body), "d.svg")
    assert str(info.value).startswith("d.svg: ") and "\n" not in str(info.value)


def test_svg_element_by_id():
    data = svg('<rect id="a" width="1" height="1"/><polygon id="b" points="0,0 2,0 2,1 1,1 1,2 0,2"/>')
    same_shape(parse_shape(data, "two.svg", element="b"), make_shape(L_SHAPE))
    with pytest.raises(InputError, match="no shape element with id 'c' \\(ids: a, b\\)"):
        parse_shape(data, "two.svg", element="c")


def test_broken_svg_is_one_line():
    with pytest.raises(InputError, match="not a readable SVG") as info:
        parse_shape(b"<svg><path d='M 0 0 L", "x.svg")
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------------------------
# DXF


def test_dxf_lwpolyline_and_polyline():
    a = parse_shape(dxf(lambda m: m.add_lwpolyline(L_SHAPE, close=True)), "a.dxf")
    same_shape(a, make_shape(L_SHAPE))
    b = parse_shape(dxf(lambda m: m.add_polyline2d(L_SHAPE, close=True)), "b.dxf")
    same_shape(b, make_shape(L_SHAPE))
    c = parse_shape(dxf(lambda m: m.add_lwpolyline(L_SHAPE + [L_SHAPE[0]])), "c.dxf")  # open but ends at its start
    same_shape(c, make_shape(L_SHAPE))


def test_dxf_bulge_is_flattened_onto_the_arc():
    # square 0..10 whose top side is a half circle bulging upwards (bulge 1 = 180 degrees)
    data = dxf(lambda m: m.add_lwpolyline([(0, 0, 0), (10, 0, 0), (10, 10, 1), (0, 10, 0)], format="xyb", close=True))
    xy = parse_shape(data, "arc.dxf").user_points
    top = xy[xy[:, 1] > 10 + 1e-9]
    assert len(top) >= 10
    np.testing.assert_allclose(np.hypot(top[:, 0] - 5, top[:, 1] - 10), 5, rtol=1e-9)
    assert (np.hypot(top[:, 0] - 5, top[:, 1] - 10) <= 5 * (1 + 1e-9)).all()


def test_dxf_nested_polylines_are_a_region_with_holes():
    def build(m):
        m.add_lwpolyline([(0, 0), (10, 0), (10, 6), (0, 6)], close=True)
        m.add_lwpolyline([(2, 2), (4, 2), (4, 4), (2, 4)], close=True)
        m.add_lwpolyline([(6, 2, 0), (8, 2, -1.0), (8, 4, 0), (6, 4, 0)], format="xyb", close=True)  # an arc

    shape = parse_shape(dxf(build), "plate.dxf")
    assert shape.n_corners == 4 and len(shape.holes) == 2
    arc = max(shape.holes, key=len)
    on_arc = arc[np.abs(arc[:, 0] - 6) > 1e-9]
    assert len(arc) > 10 and np.allclose(np.hypot(on_arc[:, 0] - 8, on_arc[:, 1] - 3)[1:-1], 1.0)  # sampled on the arc


def test_dxf_several_polylines_choose_by_handle_or_layer():
    def build(m):
        m.add_lwpolyline(L_SHAPE, close=True, dxfattribs={"layer": "outline"})
        m.add_lwpolyline([(0, 0), (1, 0), (1, 1), (0, 1)], close=True, dxfattribs={"layer": "hole"})

    data = dxf(build)
    with pytest.raises(InputError, match="2 polylines that are not one region with holes; choose one with FILE#HANDLE"):
        parse_shape(data, "two.dxf")  # the square touches the L's corner: not a hole
    same_shape(parse_shape(data, "two.dxf", element="outline"), make_shape(L_SHAPE))
    import ezdxf

    handle = [e.dxf.handle for e in ezdxf.read(io.StringIO(data.decode())).modelspace() if e.dxf.layer == "hole"][0]
    assert parse_shape(data, "two.dxf", element=handle).n_corners == 4


@pytest.mark.parametrize("data, fragment", [
    (b"0\nSECTION\n2\nENTITIES\n0\nENDSEC\n0\nEOF\n", "no LINE, ARC, CIRCLE, ELLIPSE, SPLINE, LWPOLYLINE or 2D POLYLINE"),
    (b"garbage\n", "not a readable DXF"),
])
def test_dxf_refusals(data, fragment):
    with pytest.raises(InputError, match=fragment):
        parse_shape(data, "bad.dxf")


def test_dxf_open_polyline_refused():
    with pytest.raises(InputError, match=r"open\.dxf: LWPOLYLINE \w+ \(layer 0\) ends at \(0, 0\) where no other entity meets it \(an open outline"):
        parse_shape(dxf(lambda m: m.add_lwpolyline(L_SHAPE)), "open.dxf")


# ---------------------------------------------------------------------------------------------
# detection, element syntax, one loop in every format


@pytest.mark.parametrize("name, head, fmt", [
    ("a.JSON", b"", "json"), ("a.geojson", b"", "geojson"), ("a.tsv", b"", "text"), ("a.svg", b"", "svg"), ("a.dxf", b"", "dxf"),
    ("a", b'{"boundary": []}', "json"), ("a", b'{"type": "Polygon"}', "geojson"), ("a", b"\xef\xbb\xbf <svg>", "svg"),
    ("a", b"  0\nSECTION\n", "dxf"), ("a", b"0 0\n1 0\n", "text"), ("a.svg#outline", b"", "svg"),
])
def test_detect_format(name, head, fmt):
    assert detect_format(name, head) == fmt and fmt in FORMATS


def test_split_element(tmp_path):
    assert split_element("a.svg#outline") == ("a.svg", "outline")
    assert split_element("a.svg") == ("a.svg", None)
    odd = tmp_path / "odd#name.txt"
    odd.write_text("0 0\n1 0\n0 1\n")
    assert split_element(str(odd)) == (str(odd), None)  # an existing file keeps its '#'
    assert load_shape(odd).n_corners == 3
    with pytest.raises(InputError, match="has one loop"):
        load_shape(f"{EXAMPLES / 'lshape.json'}#x")


def _as(fmt: str, pts: np.ndarray) -> tuple[bytes, str]:
    ring = np.concatenate([pts, pts[:1]]).tolist()
    if fmt == "json":
        return json.dumps({"boundary": pts.tolist(), "name": "p"}).encode(), "p.json"
    if fmt == "geojson":
        return json.dumps({"type": "Polygon", "coordinates": [ring]}).encode(), "p.geojson"
    if fmt == "text":
        return ("x\ty\n" + "\n".join(f"{float(x)!r}\t{float(y)!r}" for x, y in pts)).encode(), "p.tsv"
    if fmt == "svg":
        return svg(f'<polygon points="{" ".join(f"{float(x)!r},{float(y)!r}" for x, y in pts)}"/>'), "p.svg"
    return dxf(lambda m: m.add_lwpolyline(pts.tolist(), close=True)), "p.dxf"


@settings(max_examples=25, deadline=None)
@given(deg=st.lists(st.integers(0, 359), min_size=3, max_size=10, unique=True), fmt=st.sampled_from(FORMATS),
       scale=st.sampled_from([0.01, 1.0, 250.0]))
def test_every_format_gives_the_shape_of_its_points(deg, fmt, scale):
    pts = np.array([[scale * math.cos(math.radians(d)), scale * math.sin(math.radians(d))] for d in sorted(deg)])
    data, name = _as(fmt, pts)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the JSON sample has an extra key (warned; tested in test_shape)
        got = parse_shape(data, name)
    same_shape(got, make_shape(pts))
