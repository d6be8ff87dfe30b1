"""DXF drawings as CAD programs export them (jaxmatch.io.dxf): lines, arcs, circles, splines,
bulged polylines and inserted blocks chained into loops and nested into a region with holes;
every piece's points on its true curve; every entity left out counted; one-line errors naming
the entity's handle and layer.

Independent checks: the drawings are written by ezdxf from known geometry; sampled points are
compared with the analytic circles (distance to the centre) and with the spline evaluated by
scipy from the entity's own knots; areas with the analytic area (or shapely's area of the
scipy-evaluated spline); meshes through jaxmatch.mesh, their area by the shoelace formula and
their boundary loops from the quads.
"""

from __future__ import annotations

import io
import math
import re
import warnings

import ezdxf
import numpy as np
import pytest
import shapely
from scipy.interpolate import BSpline

import jaxmatch
from jaxmatch.errors import InputError, InputWarning
from jaxmatch.io.outline import CURVE_TOLERANCE, MAX_CURVE_TURN
from jaxmatch.io.readers import parse_shape
from jaxmatch.meshing.result import boundary_loops
from jaxmatch.quality import quad_areas


def write(doc) -> bytes:
    s = io.StringIO()
    doc.write(s)
    return s.getvalue().encode()


def read(data: bytes, name: str = "part.dxf", element=None):
    """(shape, the warnings' texts)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputWarning)
        shape = parse_shape(data, name, element=element)
    return shape, [str(w.message) for w in caught if issubclass(w.category, InputWarning)]


def on_circle(points: np.ndarray, centre, r: float, size: float) -> np.ndarray:
    """The points within ``CURVE_TOLERANCE`` of the circle's ring (a mask); those must be on it."""
    d = np.hypot(points[:, 0] - centre[0], points[:, 1] - centre[1])
    return np.abs(d - r) <= CURVE_TOLERANCE * size


def check_mesh(shape, size: float, true_area: float, hole_curves) -> None:
    """Mesh ``shape`` at ``size``: its area within 1 % of ``true_area``, one boundary loop for the
    outside and one per hole, each hole's loop on its curve (``hole_curves``: distance functions)."""
    m = jaxmatch.mesh(shape, size=size)
    area = float(quad_areas(m.xy, m.quads).sum())
    assert area == pytest.approx(true_area, rel=0.01)
    loops = boundary_loops(m.quads)
    assert len(loops) == 1 + len(shape.holes)
    ext = float(np.ptp(shape.given_points, axis=0).max())
    for dist in hole_curves:  # each hole: one mesh loop whose every vertex lies on the hole's curve
        assert sum(bool(np.all(dist(m.xy[loop]) <= 2 * CURVE_TOLERANCE * ext)) for loop in loops) == 1


def circle_dist(cx, cy, r):
    return lambda p: np.abs(np.hypot(p[:, 0] - cx, p[:, 1] - cy) - r)


# ---------------------------------------------------------------------------------------------
# the drawings of the issue


def rounded_plate(m, layer="0", dx=0.0, dy=0.0):
    """100 x 60 with the top corners rounded (r = 10) by ARCs, drawn as a CAD program would: in
    no order, some lines backwards, and a CIRCLE hole r = 12 at (50, 30)."""
    a = {"layer": layer}
    m.add_line((dx + 100, dy + 50), (dx + 100, dy + 0), dxfattribs=a)  # backwards
    m.add_arc((dx + 10, dy + 50), 10, 90, 180, dxfattribs=a)
    m.add_line((dx + 0, dy + 0), (dx + 100, dy + 0), dxfattribs=a)
    m.add_line((dx + 90, dy + 60), (dx + 10, dy + 60), dxfattribs=a)
    m.add_circle((dx + 50, dy + 30), 12, dxfattribs=a)
    m.add_arc((dx + 90, dy + 50), 10, 0, 90, dxfattribs=a)
    m.add_line((dx + 0, dy + 50), (dx + 0, dy + 0), dxfattribs=a)


PLATE_AREA = 100 * 60 - 2 * (100 - 25 * math.pi) - math.pi * 144


def test_lines_arcs_and_a_circle_hole():
    doc = ezdxf.new("R2010")
    m = doc.modelspace()
    rounded_plate(m)
    m.add_text("PLATE 1")
    m.add_text("t = 3")
    m.add_point((200, 200))
    shape, said = read(write(doc))
    assert said == ["part.dxf: 3 entities ignored: TEXT x2, POINT x1"]
    assert len(shape.holes) == 1 and shape.n_corners == 2  # the bottom corners; the arcs join the lines smoothly
    xy = shape.given_points
    for centre in [(10, 50), (90, 50)]:
        near = np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) < 10.5
        assert near.sum() >= 90 / MAX_CURVE_TURN  # sampled at most MAX_CURVE_TURN degrees apart
        np.testing.assert_allclose(np.hypot(*(xy[near] - centre).T), 10, rtol=1e-12)  # on the arc
    hole = shape.holes[0]
    np.testing.assert_allclose(np.hypot(hole[:, 0] - 50, hole[:, 1] - 30), 12, rtol=1e-12)
    assert len(hole) >= 360 / MAX_CURVE_TURN
    assert shapely.Polygon(xy, [hole]).area == pytest.approx(PLATE_AREA, rel=1e-3)
    check_mesh(shape, 6.0, PLATE_AREA, [circle_dist(50, 30, 12)])


def test_bulged_polyline_with_circle_holes():
    doc = ezdxf.new("R2010")
    m = doc.modelspace()
    # a stadium: 80 x 40 with half circles (bulge 1) at both ends, and two round holes
    m.add_lwpolyline([(0, 0, 0), (80, 0, 1), (80, 40, 0), (0, 40, 1)], format="xyb", close=True)
    m.add_circle((20, 20), 8)
    m.add_circle((60, 20), 8)
    shape, said = read(write(doc))
    assert said == [] and len(shape.holes) == 2
    xy = shape.given_points
    right = xy[:, 0] > 80 + 1e-9
    np.testing.assert_allclose(np.hypot(xy[right, 0] - 80, xy[right, 1] - 20), 20, rtol=1e-12)
    area = 80 * 40 + math.pi * 400 - 2 * math.pi * 64
    check_mesh(shape, 5.0, area, [circle_dist(20, 20, 8), circle_dist(60, 20, 8)])


def test_a_spline_side_is_sampled_on_the_spline():
    doc = ezdxf.new("R2010")
    m = doc.modelspace()
    top = [(100, 40), (70, 70), (30, 20), (0, 40)]
    spline = m.add_open_spline(top, degree=3)
    m.add_line((0, 40), (0, 0))
    m.add_line((0, 0), (100, 0))
    m.add_line((100, 0), (100, 40))
    shape, _ = read(write(doc))
    curve = BSpline(np.asarray(spline.knots), np.asarray(top, float), 3)  # the spline, evaluated by scipy
    fine = curve(np.linspace(0, 1, 20001))
    xy = shape.given_points
    upper = xy[xy[:, 1] > 40 + 1e-9]
    assert len(upper) > 20
    gap = shapely.LineString(fine).distance(shapely.points(upper))
    assert gap.max() <= 1e-4  # on the curve (the fine polyline's own chords are ~1e-6 off it)
    true_area = shapely.Polygon(np.vstack([[[0, 0], [100, 0]], fine])).area
    assert shape.n_corners == 4
    check_mesh(shape, 6.0, true_area, [])


def test_a_block_insert_is_placed_and_two_are_two_regions():
    doc = ezdxf.new("R2010")
    block = doc.blocks.new("PLATE")
    rounded_plate(block)
    m = doc.modelspace()
    first = m.add_blockref("PLATE", (500, 200), dxfattribs={"xscale": 2, "yscale": 2, "rotation": 30, "layer": "A"})
    shape, _ = read(write(doc))
    assert len(shape.holes) == 1
    assert shapely.Polygon(shape.given_points, list(shape.holes)).area == pytest.approx(4 * PLATE_AREA, rel=1e-3)
    c = np.array([500, 200]) + 2 * np.array([[math.cos(math.radians(30)), -math.sin(math.radians(30))],
                                               [math.sin(math.radians(30)), math.cos(math.radians(30))]]) @ [50, 30]
    np.testing.assert_allclose(np.hypot(*(shape.holes[0] - c).T), 24, rtol=1e-9)  # the hole, moved, turned, scaled
    check_mesh(shape, 12.0, 4 * PLATE_AREA, [circle_dist(c[0], c[1], 24)])
    second = m.add_blockref("PLATE", (0, 0), dxfattribs={"layer": "B"})
    data = write(doc)
    with pytest.raises(InputError, match=r"2 regions \(outer loops: .*block 'PLATE' \(INSERT \w+, layer A\).*FILE#LAYER"):
        read(data)
    assert read(data, element="B")[0].given_points.max() <= 100
    assert read(data, element=first.dxf.handle)[0].given_points[:, 0].min() > 300
    assert read(data, element=second.dxf.handle)[0].given_points.max() <= 100


def test_ends_within_the_tolerance_meet():
    doc = ezdxf.new("R2010")
    m = doc.modelspace()
    off = 1e-8 * 100  # well inside CHAIN_TOLERANCE (1e-6) of the size
    m.add_line((0, 0), (100, 0))
    m.add_line((100 + off, -off), (100, 50))
    m.add_line((100, 50), (0, 50 + off))
    m.add_line((0, 50), (0, 0))
    shape, _ = read(write(doc))
    assert shape.n_points == 4 and shape.n_corners == 4


def _doc(build):
    doc = ezdxf.new("R2010")
    build(doc.modelspace())
    return write(doc)


def _square(m, x0=0, y0=0, s=10, layer="0"):
    for a, b in [((x0, y0), (x0 + s, y0)), ((x0 + s, y0), (x0 + s, y0 + s)), ((x0 + s, y0 + s), (x0, y0 + s)),
                 ((x0, y0 + s), (x0, y0))]:
        m.add_line(a, b, dxfattribs={"layer": layer})


@pytest.mark.parametrize("build, pattern", [
    (lambda m: [m.add_line((0, 0), (10, 0), dxfattribs={"layer": "CUT"}), m.add_line((10, 0), (10, 10)),
                m.add_line((10, 10), (0, 0.5))],
     r"LINE \w+ \(layer (CUT|0)\) ends at \((0, 0|0, 0\.5)\) where no other entity meets it \(an open outline; "
     r"the nearest other end is 0\.5 away\)"),
    (lambda m: [_square(m), m.add_line((10, 10), (0, 0))], r"meet at \((0, 0|10, 10)\): the outline branches there"),
    (lambda m: [m.add_circle((0, 0), 5), m.add_circle((6, 0), 5, dxfattribs={"layer": "H"})],
     r"CIRCLE \w+ \(layer 0\) and CIRCLE \w+ \(layer H\) cross or touch"),
    (lambda m: [_square(m), _square(m, 20, 0, layer="RIGHT")], r"2 regions .*choose it with FILE#LAYER"),
    (lambda m: [m.add_lwpolyline([(0, 0), (10, 10), (10, 0), (0, 10)], close=True), m.add_circle((50, 50), 1)],
     r"LWPOLYLINE \w+ \(layer 0\) crosses itself at \(5, 5\)"),
    (lambda m: [_square(m), m.add_line((20, 0, 0), (20, 5, 3))], r"LINE \w+ \(layer 0\) is not in the plane"),
    (lambda m: [m.add_text("x")], r"no LINE, ARC, .* \(only TEXT\)"),
])
def test_refusals_name_the_entity(build, pattern):
    with pytest.raises(InputError) as info:
        read(_doc(build), "bad.dxf")
    msg = str(info.value)
    assert msg.startswith("bad.dxf: ") and "\n" not in msg
    assert re.search(pattern, msg), msg


def test_a_layer_is_chosen_by_name():
    data = _doc(lambda m: [_square(m, layer="LEFT"), _square(m, 20, 0, s=5, layer="RIGHT"), m.add_circle((5, 5), 2,
                                                                                                        dxfattribs={"layer": "LEFT"})])
    left = read(data, element="LEFT")[0]
    assert len(left.holes) == 1 and left.given_points.max() == 10
    right = read(data, element="RIGHT")[0]
    assert right.holes == () and right.given_points[:, 0].min() == 20
    with pytest.raises(InputError, match=r"no layer or entity handle 'NONE' \(layers: LEFT, RIGHT\)"):
        read(data, element="NONE")


def test_closed_polylines_alone_are_read_as_before():
    """A drawing of closed polylines only keeps its sampling (200 points per loop perimeter), so
    the examples' meshes do not change; the pieces' way samples by the drawing's size."""
    poly = [(0, 0, 0), (10, 0, 1), (10, 10, 0), (0, 10, 0)]
    alone = read(_doc(lambda m: m.add_lwpolyline(poly, format="xyb", close=True)))[0]
    with_line = read(_doc(lambda m: [m.add_lwpolyline(poly, format="xyb", close=True), m.add_line((20, 0), (20, 0))]))[0]
    for shape in (alone, with_line):
        top = shape.given_points[shape.given_points[:, 0] > 10 + 1e-9]
        np.testing.assert_allclose(np.hypot(top[:, 0] - 10, top[:, 1] - 5), 5, rtol=1e-12)
    assert alone.n_points != with_line.n_points
    assert read(_doc(lambda m: [m.add_lwpolyline(poly, format="xyb", close=True), m.add_line((20, 0), (20, 0))]))[1] == [
        "part.dxf: 1 entity ignored: LINE (zero length) x1"]
