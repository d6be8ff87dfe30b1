"""Size fields (:mod:`jaxmatch.field`): the formula, its JSON form and errors, the integrals the
meshing reads, and graded meshes that follow it.

The field is checked against a plain per-point, per-segment Python loop (independent of the
module's vectorised distances, shapely's)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from unittest.mock import patch

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.defaults import QUALITY
from jaxmatch.errors import EXIT_BAD_INPUT, InputError
from jaxmatch.field import (CallableSize, Field, Near, SizeField, bind, field_share, graded_points,
                            line_integral, load_field, parse_field, segment_distance, segment_distances)
from jaxmatch.io.readers import load_shape
from jaxmatch.meshing.pipeline import mesh
from jaxmatch.shape import make_shape

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
PLATE = EXAMPLES / "holes" / "plate-bolt.json"
SQUARE = make_shape([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def _polyline(e: Near, shape) -> list[tuple[float, float]]:
    if e.kind == "point":
        return [e.entity]
    if e.kind == "curve":
        return list(e.entity)
    if e.kind == "hole":
        ring = [tuple(map(float, p)) for p in shape.holes[e.entity - 1]]
        return ring + ring[:1]
    i, j = map(int, e.entity.split("-"))
    pts = [tuple(map(float, p)) for p in shape.given_points]
    idx = list(range(i, j + 1)) if j > i else list(range(i, len(pts))) + list(range(0, j + 1))
    return [pts[k] for k in idx]


def _distance(x: float, y: float, line: list) -> float:
    """Distance from (x, y) to a polyline, segment by segment, in plain Python."""
    if len(line) == 1:
        return math.hypot(x - line[0][0], y - line[0][1])
    best = math.inf
    for (ax, ay), (bx, by) in zip(line, line[1:]):
        dx, dy = bx - ax, by - ay
        L2 = dx * dx + dy * dy
        t = 0.0 if L2 == 0 else min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / L2))
        best = min(best, math.hypot(x - ax - t * dx, y - ay - t * dy))
    return best


def reference(f: Field, shape, points: np.ndarray) -> np.ndarray:
    """The field's definition, one point and one segment at a time (plain Python)."""
    lines = [(e.size, e.distance, _polyline(e, shape)) for e in f.near]
    out = []
    for x, y in points.tolist():
        v = f.size
        for s, d, line in lines:
            v = min(v, s + (f.size - s) * min(1.0, _distance(x, y, line) / d))
        out.append(v)
    return np.array(out)


def test_every_kind_matches_the_per_point_reference():
    plate = load_shape(PLATE)
    f = Field(0.25, (Near("hole", 1, 0.05, 0.8), Near("point", (0.5, 3.5), 0.03, 0.4),
                     Near("side", "0-1", 0.1, 0.6), Near("curve", ((0.2, 0.2), (1.0, 1.5), (3.8, 0.5)), 0.07, 0.3)))
    pts = np.random.default_rng(0).uniform(-0.5, 4.5, (400, 2))
    np.testing.assert_allclose(f.bind(plate)(pts), reference(f, plate, pts), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("r", [0.0, 0.1, 0.25, 0.39, 0.4, 0.8, 3.0])
def test_a_point_entry_is_the_threshold_formula(r):
    s, H, d = 0.02, 0.1, 0.4
    f = Field(H, (Near("point", (0.5, 0.5), s, d),)).bind(SQUARE)
    want = s + (H - s) * min(1.0, r / d)  # gmsh's Threshold: SizeMin s, SizeMax H, DistMin 0, DistMax d
    assert f(np.array([[0.5 + r, 0.5]]))[0] == pytest.approx(want, rel=1e-12)


coords = st.floats(-2.0, 3.0, allow_nan=False).filter(lambda v: v == 0.0 or abs(v) >= 1e-100)
"""Coordinates of points and polylines: no magnitude between 0 and 1e-100, so that no segment is
shorter than ~1e-116 (shapely's distance to a segment whose squared length underflows to 0 is inf,
e.g. from (0, 0) to the segment (0, 0)-(0, 6.5e-255), where numpy's is 0: no geometry of a part)."""


@settings(max_examples=40, deadline=None)
@given(H=st.floats(0.05, 2.0), entries=st.lists(st.tuples(
    st.sampled_from(["point", "curve"]), st.lists(st.tuples(coords, coords), min_size=2, max_size=5),
    st.floats(0.01, 1.0), st.floats(0.01, 3.0)), min_size=1, max_size=3),
       pts=st.lists(st.tuples(coords, coords), min_size=1, max_size=20))
def test_property_field_is_the_reference_and_between_its_sizes(H, entries, pts):
    near = tuple(Near(k, p[0] if k == "point" else tuple(p), min(s, H), d) for k, p, s, d in entries)
    f = Field(H, near)
    x = np.array(pts, np.float64)
    got = f.bind(SQUARE)(x)
    np.testing.assert_allclose(got, reference(f, SQUARE, x), rtol=1e-9, atol=1e-12)
    assert np.all(got <= H) and np.all(got >= min(e.size for e in near) - 1e-15)


@settings(max_examples=40, deadline=None)
@given(lines=st.lists(st.lists(st.tuples(coords, coords), min_size=1, max_size=6), min_size=1, max_size=7),
       pts=st.lists(st.tuples(coords, coords), min_size=1, max_size=20), shapely_path=st.booleans())
def test_property_the_field_gives_shapelys_distances_bit_for_bit(lines, pts, shapely_path):
    # numpy's distances or shapely's (a field of few entries chooses per entry; one of many takes
    # numpy's on the pairs within reach or shapely's per entry): either way shapely's numbers
    x = np.array(pts, np.float64)
    near, want = [], np.full(len(pts), 1.0)
    for k, line in enumerate(lines):
        p = np.array(line + line[-1:] if len(line) == 1 else line, np.float64)
        seg = np.stack([p[:-1], p[1:]], axis=1)
        geom = shapely.Point(p[0]) if len(line) == 1 else shapely.MultiLineString(list(seg))
        np.testing.assert_array_equal(segment_distance(x, seg), shapely.distance(shapely.points(x), geom))
        s, d = 0.1 + 0.05 * k, 0.5 + 0.3 * k
        near.append(Near("point", line[0], s, d) if len(line) == 1 else Near("curve", tuple(line), s, d))
        want = np.minimum(want, s + (1.0 - s) * np.minimum(1.0, shapely.distance(shapely.points(x), geom) / d))
    f = Field(1.0, tuple(near)).bind(SQUARE)
    with patch("jaxmatch.field.NUMPY_POINTS", 10 ** 9 if shapely_path else 0), \
            patch("jaxmatch.field.NUMPY_SEGMENTS", 10 ** 9), \
            patch("jaxmatch.field.NUMPY_NS", (1e9, 1e9) if shapely_path else (0.0, 0.0)):
        np.testing.assert_array_equal(f(x), want)


@settings(max_examples=40, deadline=None)
@given(lines=st.lists(st.lists(st.tuples(coords, coords), min_size=1, max_size=12), min_size=1, max_size=8),
       pts=st.lists(st.tuples(coords, coords), min_size=1, max_size=30), d=st.floats(0.01, 3.0),
       shapely_path=st.booleans())
def test_property_distances_within_reach_only_give_every_pairs_sizes_bit_for_bit(lines, pts, d, shapely_path):
    # each entry's distances computed only for the points within its reach (its distance d from
    # its bounding box, rounding included; a field of few entries per entry, one of many per
    # (point, entry) pair or per entry, the points in blocks); the others take the entry's
    # largest size, as every pair's distances give them, bit for bit (points at the reach's edge too)
    near = tuple(Near("point", line[0], 0.1, d) if len(line) == 1 else Near("curve", tuple(line), 0.1 + 0.01 * k, d)
                 for k, line in enumerate(lines))
    edge = [(lo[0] - d, lo[1]) for lo in (np.min(np.array(line), axis=0) for line in lines)] + \
        [(hi[0], hi[1] + d * (1 + 1e-15)) for hi in (np.max(np.array(line), axis=0) for line in lines)]
    x = np.array(pts + edge, np.float64)
    f = Field(1.0, near).bind(SQUARE)
    segments, starts, s, dd = f._segments
    dist = np.minimum.reduceat(segment_distances(x, segments), starts, axis=1)  # every pair, numpy
    want = np.minimum(1.0, (s + (1.0 - s) * np.minimum(1.0, dist / dd)).min(axis=1))
    with patch("jaxmatch.field.PRUNE_POINTS", 0), patch("jaxmatch.field.NUMPY_POINTS", 10 ** 9 if shapely_path else 0), \
            patch("jaxmatch.field.NUMPY_SEGMENTS", 10 ** 9), patch("jaxmatch.field.PAIR_BLOCK", 7), \
            patch("jaxmatch.field.NUMPY_NS", (1e9, 1e9) if shapely_path else (0.0, 0.0)):
        got = f(x)
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("first", ["integral", "points"])
def test_integral_and_graded_points_along_one_polyline_ask_the_field_once_the_same_numbers(first):
    # line_integral and graded_points cut a polyline into the same pieces: the second along it (in
    # the same direction) takes the field at their starts from the first, its answers bit for bit
    # those of a field that had seen neither
    t = np.linspace(0.0, 2 * np.pi, 49)[:-1]
    ring = tuple((0.5 + 0.2 * math.cos(a), 0.5 + 0.2 * math.sin(a)) for a in t)
    field = Field(0.3, (Near("curve", ring + ring[:1], 0.03, 0.4), Near("point", (0.9, 0.1), 0.05, 0.3)))
    polys = [np.array([[0.0, 0.0], [0.4, 0.1], [1.0, 0.3]]), np.array([[1.0, 1.0], [0.0, 0.7]]),
             np.array([[0.2, 0.9], [0.3, 0.2], [0.8, 0.5], [0.95, 0.95]])]
    shared = field.bind(SQUARE)
    for poly in polys:
        for q in (poly, poly[::-1].copy()):
            calls = [lambda f: line_integral(f, q), lambda f: graded_points(f, q, 9)]
            for call in (calls if first == "integral" else calls[::-1]):
                np.testing.assert_array_equal(call(shared), call(field.bind(SQUARE)))


def test_line_integral_along_a_linear_ramp():
    # size grows from s at x = 0 to H at x = d along the x axis: integral of 1/size is d/(H-s) ln(H/s)
    s, H, d = 0.05, 0.5, 1.0
    f = Field(H, (Near("point", (0.0, 0.0), s, d),)).bind(SQUARE)
    got = line_integral(f, np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]))
    want1 = d / (H - s) * math.log(H / s)
    assert got[1] == pytest.approx(want1, rel=1e-3) and got[2] == pytest.approx(want1 + 1.0 / H, rel=1e-3)


def test_graded_points_equal_steps_and_same_points_either_way():
    f = Field(0.5, (Near("point", (0.0, 0.0), 0.05, 1.0),)).bind(SQUARE)
    poly = np.array([[0.0, 0.0], [0.7, 0.0], [1.5, 0.3]])
    p = graded_points(f, poly, 12)
    steps = np.diff(line_integral(f, p))
    assert np.ptp(steps) < 0.02 * steps.mean()
    np.testing.assert_array_equal(graded_points(f, poly[::-1], 12)[::-1], p)  # bit-identical both ways
    d = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert d[0] < d[-1] / 3  # fine at the point, coarse away


def test_a_bound_field_integrates_each_polyline_once(monkeypatch):
    # the candidates share sides: their integrals are kept on the bound field, the same numbers
    poly = np.array([[0.0, 0.0], [0.7, 0.0], [1.5, 0.3]])
    f = Field(0.5, (Near("point", (0.0, 0.0), 0.05, 1.0),))
    kept, fresh = f.bind(SQUARE), f.bind(SQUARE)
    a, b = graded_points(kept, poly, 12), line_integral(kept, poly)

    def no_more(self, points):
        raise AssertionError("the field evaluated again")

    monkeypatch.setattr(SizeField, "__call__", no_more)
    np.testing.assert_array_equal(graded_points(kept, poly[::-1], 12)[::-1], a)
    np.testing.assert_array_equal(line_integral(kept, poly), b)
    got = graded_points(kept, poly, 5)
    monkeypatch.undo()
    np.testing.assert_array_equal(got, graded_points(fresh, poly, 5))
    np.testing.assert_array_equal(b, line_integral(fresh, poly))


def test_json_form_and_file(tmp_path):
    obj = {"size": 0.3, "near": [{"hole": 1, "size": 0.05, "distance": 0.5}, {"point": [1, 2], "size": 0.1, "distance": 1},
                                 {"side": "1-2", "size": 0.1, "distance": 0.2},
                                 {"curve": [[0, 0], [1, 1]], "size": 0.2, "distance": 0.4}]}
    p = tmp_path / "f.json"
    p.write_text(json.dumps(obj))
    f = load_field(p)
    assert f == parse_field(obj) and [e.kind for e in f.near] == ["hole", "point", "side", "curve"]
    assert f.near[1].entity == (1.0, 2.0) and f.near[3].entity == ((0.0, 0.0), (1.0, 1.0))


@pytest.mark.parametrize("obj, words", [
    ({"size": -1}, "positive"),
    ({"size": 0.1, "near": [{"point": [0, 0], "size": -0.1, "distance": 1}]}, "positive"),
    ({"size": 0.1, "near": [{"point": [0, 0], "size": 0.2, "distance": 1}]}, "larger than"),
    ({"size": 0.1, "near": [{"point": [0, 0], "size": 0.05}]}, "distance"),
    ({"near": []}, "missing key"),
    ({"size": 0.1, "near": [{"pt": [0, 0], "size": 0.05, "distance": 1}]}, "exactly one of"),
    ({"size": 0.1, "near": [{"hole": 0, "size": 0.05, "distance": 1}]}, "hole number"),
    ({"size": 0.1, "near": [{"side": "a-b", "size": 0.05, "distance": 1}]}, "i-j"),
    ({"size": 0.1, "near": [{"curve": [[0, 0]], "size": 0.05, "distance": 1}]}, "two points"),
    ({"size": 0.1, "extra": 1}, "unknown key"),
    ([1, 2], "JSON object"),
])
def test_bad_fields_are_one_line_errors_naming_the_file(obj, words):
    with pytest.raises(InputError) as e:
        parse_field(obj, "f.json")
    assert words in str(e.value) and e.value.where == "f.json" and "\n" not in str(e.value)


@pytest.mark.parametrize("entry, words", [({"hole": 2}, "hole 2 does not exist"), ({"side": "0-2"}, "not a side"),
                                          ({"side": "0-7"}, "not a side")])
def test_unknown_hole_or_side_names_the_field_file(entry, words):
    f = parse_field({"size": 0.3, "near": [{**entry, "size": 0.1, "distance": 1}]}, "f.json")
    with pytest.raises(InputError) as e:
        f.bind(load_shape(PLATE))
    assert words in e.value.problem and e.value.where == "f.json"


def test_sides_are_named_by_the_files_points_either_way():
    plate = load_shape(PLATE)  # corners 0..3 of the file: side 1-2 is x = 4
    for name in ("1-2", "2-1"):
        f = Field(1.0, (Near("side", name, 0.1, 1.0),)).bind(plate)
        assert f(np.array([[4.0, 2.0]]))[0] == pytest.approx(0.1) and f(np.array([[0.0, 2.0]]))[0] == 1.0


@pytest.mark.parametrize("fn, words", [(lambda p: np.ones(len(p) + 1), "shape"), (lambda p: -np.ones(len(p)), "positive"),
                                       (lambda p: np.full(len(p), np.nan), "positive"), (lambda p: 1 / 0, "failed")])
def test_a_bad_callable_is_an_input_error(fn, words):
    with pytest.raises(InputError) as e:
        mesh(SQUARE, size=fn)
    assert words in str(e.value)


def test_a_callable_and_the_equivalent_field_give_the_same_mesh():
    f = Field(0.1, (Near("point", (0.0, 0.0), 0.02, 0.6),))
    fb = f.bind(SQUARE)
    a = mesh(SQUARE, size=f)
    b = mesh(SQUARE, size=lambda p: fb(p))
    assert np.array_equal(a.quads, b.quads) and np.allclose(a.xy, b.xy)
    assert isinstance(bind(lambda p: fb(p), SQUARE), CallableSize)


def test_graded_tries_the_ring_partition_before_the_larger_templates():
    # a square finer at its centre: the ring partition follows the field (no edge off it), so the
    # larger templates (tried when the best mesh so far misses the field) are not
    folder = EXAMPLES / "graded"
    m = mesh(load_shape(folder / "square.json"), size=load_field(folder / "square.field.json"))
    names = [c.name for c in m.tried if c.mesh is not None]
    assert m.chosen == "rings" and m.size_conformity(replace(QUALITY, field=m.field)) == 0
    assert names == ["single", "rings"]


@pytest.mark.parametrize("case, meshed, chosen", [
    # the ring partition beats the single patch: no larger template (its layout with templates
    # chosen for size follows the field better still)
    ("rectangle", ["single", "rings", "rings +transitions"], "rings +transitions"),
    ("strip", ["single", "single k2-abbdea1b1e36", "single k4-22d2f29ecc34", "rings"], "single k4-22d2f29ecc34"),
])
def test_graded_tries_the_larger_templates_while_the_single_patch_is_the_best_mesh(case, meshed, chosen):
    folder = EXAMPLES / "graded"
    m = mesh(load_shape(folder / f"{case}.json"), size=load_field(folder / f"{case}.field.json"))
    assert [c.name for c in m.tried if c.mesh is not None] == meshed and m.chosen == chosen


def _refined_share(m, f, H, s):
    e = m._edges
    mid = 0.5 * (m.xy[e[:, 0]] + m.xy[e[:, 1]])
    ratio = np.linalg.norm(m.xy[e[:, 0]] - m.xy[e[:, 1]], axis=1) / f(mid)
    ok = (ratio >= 0.5) & (ratio <= 1.6)
    return float(ok.mean()), float(ok[f(mid) < 0.5 * (s + H)].mean())


@pytest.mark.parametrize("region, spec", [
    (PLATE, {"size": 0.25, "near": [{"hole": 1, "size": 0.05, "distance": 0.8}]}),
    (EXAMPLES / "lshape.json", {"size": 0.15, "near": [{"point": [1, 1], "size": 0.03, "distance": 0.5}]}),
])
def test_graded_meshes_follow_the_field(region, spec):
    f = parse_field(spec)
    m = mesh(region, size=f)
    fb = f.bind(load_shape(region))
    share, refined = _refined_share(m, fb, f.size, f.near[0].size)
    assert m.valid and m.min_scaled_jacobian >= 0.6
    assert share >= 0.8 and refined >= 0.6
    assert m.field_share == pytest.approx(field_share(fb, m.xy, m._edges))
    uniform = mesh(region, size=f.size)  # the same H everywhere: far fewer quads, none at the fine size
    assert m.quads.shape[0] > 1.1 * uniform.quads.shape[0]
    assert _refined_share(uniform, fb, f.size, f.near[0].size)[1] < refined


def test_cli_size_field_writes_summary_and_picture(cli, tmp_path):
    field = tmp_path / "f.json"
    field.write_text(json.dumps({"size": 0.3, "near": [{"hole": 1, "size": 0.08, "distance": 0.8}]}))
    png = tmp_path / "p.png"
    code, out, err = cli("mesh", PLATE, "--size-field", field, "--json", "--png", png, "--color", "size")
    assert code == 0, err
    rec = json.loads(out)
    assert 0.8 <= rec["field_share"] <= 1.0 and png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("spec, extra, words", [
    ({"size": 0.3, "near": [{"hole": 4, "size": 0.08, "distance": 0.8}]}, [], "hole 4"),
    ({"size": -0.3}, [], "positive"),
    ({"size": 0.3, "near": [{"hole": 1, "size": 0.5, "distance": 0.8}]}, [], "larger than"),
    ({"size": 0.3}, ["--size", "0.2"], "--size-field"),
])
def test_cli_bad_size_field_exit_2_one_line_nothing_written(cli, tmp_path, spec, extra, words):
    field = tmp_path / "f.json"
    field.write_text(json.dumps(spec))
    out = tmp_path / "m.msh"
    code, _, err = cli("mesh", PLATE, "--size-field", field, "--out", out, *extra)
    lines = err.strip().splitlines()
    assert code == EXIT_BAD_INPUT and len(lines) == 1 and words in lines[0] and not out.exists()


@pytest.mark.parametrize("poly", [[[0.0, 0.0], [1.0, 0.0], [2.0, 0.3]], [[0.2, 0.9], [0.25, 0.1], [0.9, 0.6], [0.2, 0.9]]])
def test_line_integral_asks_the_field_once_a_point_and_sums_each_pieces_ends(poly):
    """Each piece's trapezoid from the field at its two ends (computed here at both ends of every
    piece, as written), while the field is asked at each piece's start and each segment's end
    only: the same numbers, bit for bit."""
    f = Field(0.5, (Near("point", (0.3, 0.2), 0.04, 0.6), Near("curve", ((0.0, 1.0), (1.0, 0.7)), 0.1, 0.4))).bind(SQUARE)
    p = np.array(poly)
    asked = []
    got = line_integral(CallableSize(lambda x: (asked.append(len(x)), f(x))[1], smallest=f.smallest), p)
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    k = np.clip(np.ceil(seg / (f.smallest / 4)), 1, 512).astype(int)
    assert asked == [int(k.sum()) + len(seg)]
    want = [0.0]
    for i in range(len(seg)):
        t = np.arange(k[i] + 1)
        a, d = p[i], p[i + 1] - p[i]
        ends = 1.0 / f(np.concatenate([a + (t[:-1] / k[i])[:, None] * d, a + (t[1:] / k[i])[:, None] * d]))
        want.append(want[-1] + np.sum(0.5 * (ends[:k[i]] + ends[k[i]:]) * seg[i] / k[i]))
    np.testing.assert_allclose(got, want, rtol=1e-12)
