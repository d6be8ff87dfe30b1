"""Shape input and annotation: a specification by example (jaxmatch.shape)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.errors import InputError, InputWarning
from jaxmatch.io.readers import load_shape, parse_shape
from jaxmatch.shape import (
    MAX_POINTS,
    S,
    SYMBOLS,
    V,
    X,
    annotate,
    cumulative_length,
    default_points,
    interior_angles,
    largest_remainder,
    make_shape,
    point_at,
    signed_area,
)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]
L_SHAPE = [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]
TRIANGLE = [[0, 0], [2, 0], [1, math.sqrt(3)]]
HEXAGON = [[math.cos(k * math.pi / 3), math.sin(k * math.pi / 3)] for k in range(6)]


def js(doc) -> bytes:
    return json.dumps(doc).encode()


def corner_points(shape):
    """User coordinates of the corners, as a set of rounded tuples."""
    return {tuple(np.round(p, 9)) for p in shape.user_points[shape.corners]}


# ---------------------------------------------------------------------------------------------
# examples and corner detection


@pytest.mark.parametrize(
    "name, n_convex, n_concave",
    [
        ("square.json", 4, 0),
        ("lshape.json", 5, 1),
        ("lshape.txt", 5, 1),
        ("triangle.json", 3, 0),
        ("hexagon.json", 6, 0),
        ("tshape.json", 6, 2),
        ("curved.json", 4, 0),
        ("dshape.json", 2, 0),
        ("circle.json", 0, 0),
        ("lshape.csv", 5, 1),
        ("plate.geojson", 5, 0),
        ("bracket.svg#outline", 3, 0),  # the notch is a smooth S-curve (a cubic): no concave corner
        ("slot.dxf", 2, 0),
    ],
)
def test_examples_load_with_expected_corners(name, n_convex, n_concave):
    shape = load_shape(f"{EXAMPLES / name}")
    assert int(shape.convex.sum()) == n_convex
    assert int((~shape.convex).sum()) == n_concave
    assert signed_area(shape.points) > 0
    assert shape.points.min() >= 0 and shape.points.max() <= 1 + 1e-12


def test_text_and_json_l_shapes_agree():
    a, b = load_shape(EXAMPLES / "lshape.json"), load_shape(EXAMPLES / "lshape.txt")
    np.testing.assert_allclose(a.points, b.points)
    np.testing.assert_array_equal(a.corners, b.corners)
    np.testing.assert_array_equal(a.convex, b.convex)


@pytest.mark.parametrize(
    "points, convex",
    [
        (SQUARE, [True] * 4),
        (L_SHAPE, [True, True, True, False, True, True]),
        (TRIANGLE, [True] * 3),
        (HEXAGON, [True] * 6),
    ],
)
def test_corner_detection(points, convex):
    shape = make_shape(points)
    np.testing.assert_array_equal(shape.corners, np.arange(len(points)))
    np.testing.assert_array_equal(shape.convex, convex)


def test_points_on_straight_sides_are_not_corners():
    square_with_midpoints = [[0, 0], [0.5, 0], [1, 0], [1, 0.5], [1, 1], [0.5, 1], [0, 1], [0, 0.5]]
    shape = make_shape(square_with_midpoints)
    assert corner_points(shape) == {(0, 0), (1, 0), (1, 1), (0, 1)}


@pytest.mark.parametrize("threshold, n_corners", [(30, 8), (44, 8), (46, 0), (10, 8)])
def test_corner_threshold(threshold, n_corners):
    octagon = [[math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)] for k in range(8)]  # turns 45 deg
    assert make_shape(octagon, corner_angle=threshold).n_corners == n_corners


def test_explicit_corners_override_angles():
    shape = make_shape(SQUARE, corners=[0, 2])
    assert corner_points(shape) == {(0, 0), (1, 1)}
    assert shape.convex.all()
    assert make_shape(SQUARE, corners=[]).n_corners == 0


def test_interior_angles_and_area():
    np.testing.assert_allclose(interior_angles(SQUARE), [90] * 4)
    np.testing.assert_allclose(interior_angles(L_SHAPE), [90, 90, 90, 270, 90, 90])
    assert signed_area(SQUARE) == pytest.approx(1.0)
    assert signed_area(SQUARE[::-1]) == pytest.approx(-1.0)


# ---------------------------------------------------------------------------------------------
# normalisation


def test_clockwise_is_normalised_and_corners_remapped():
    cw = L_SHAPE[::-1]  # clockwise, the concave corner (1, 1) is input index 2
    shape = make_shape(cw, corners=[0, 1, 2, 3, 4, 5])
    assert signed_area(shape.points) > 0
    concave = shape.user_points[shape.corners[~shape.convex]]
    np.testing.assert_allclose(concave, [[1, 1]])
    ccw = make_shape(L_SHAPE)
    a, b = annotate(shape, 20).symbols, annotate(ccw, 20).symbols
    assert a in b + b  # the same cyclic sequence, started at another corner


def test_clockwise_explicit_corner_subset():
    cw = [[0, 0], [0, 1], [1, 1], [1, 0]]
    shape = make_shape(cw, corners=[1, 3])
    assert corner_points(shape) == {(0, 1), (1, 0)}


def test_unit_box_and_user_transform():
    pts = np.array(L_SHAPE, float) * 7.5 + [100, -3]
    shape = make_shape(pts)
    assert shape.scale == pytest.approx(15.0)
    np.testing.assert_allclose(shape.offset, [100, -3])
    assert shape.points.min() == 0 and shape.points.max() == 1
    # same loop in user coordinates (rotated so that the first corner comes first)
    assert {tuple(np.round(p, 9)) for p in shape.user_points} == {tuple(np.round(p, 9)) for p in pts}


def test_first_corner_is_first_point():
    # point 0 is a straight point: the loop is rotated so points[0] is the first corner
    pts = [[0.5, 0], [1, 0], [1, 1], [0, 1], [0, 0]]
    shape = make_shape(pts)
    assert shape.corners[0] == 0
    np.testing.assert_allclose(shape.user_points[0], [1, 0])


# ---------------------------------------------------------------------------------------------
# bad input


BAD = [
    (b"\xff\xfe\x00garbage", "x.json", "UTF-8"),
    (b"{not json", "x.json", "JSON"),
    (b"[]", "x.json", "object"),
    (js({"boundary": [[0, 0], [1, 0]]}), "x.json", "at least 3"),
    (js({"corners": [0]}), "x.json", "missing"),
    (js({"boundary": {"a": 1}}), "x.json", "list"),
    (js({"boundary": [[0, 0], [1, 0], [1]]}), "x.json", "pair"),
    (js({"boundary": [[0, 0], [1, 0], [[1], 1]]}), "x.json", "non-number"),
    (js({"boundary": [[0, 0], [1, 0], ["1", 1]]}), "x.json", "non-number"),
    (js({"boundary": [[0, 0], [1, 0], [True, 1]]}), "x.json", "non-number"),
    (b'{"boundary": [[0, 0], [1, 0], [NaN, 1]]}', "x.json", "finite"),
    (b'{"boundary": [[0, 0], [1, 0], [Infinity, 1]]}', "x.json", "finite"),
    (b'{"boundary": [[0, 0], [1, 0], [1e999, 1]]}', "x.json", "finite"),
    (js({"boundary": [[0, 0], [1, 0], [10**400, 1]]}), "x.json", "finite"),
    (b'{"boundary": [[0,0],[1,0],[1,1]], "boundary": [[0,0],[1,0],[1,1]]}', "x.json", "duplicate"),
    (js({"boundary": [[0, 0], [1, 0], [0, 0]]}), "x.json", "at least 3"),  # a closed ring of 2 points
    (js({"boundary": [[0, 0], [1, 0], [2, 0]]}), "x.json", "zero area"),
    (js({"boundary": [[0, 0], [1, 1], [1, 0], [0, 1]]}), "x.json", "crosses"),
    (js({"boundary": [[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]]}), "x.json", "crosses"),  # touches
    (js({"boundary": [[0, 0], [2, 0], [1, 0], [1, 1]]}), "x.json", "crosses"),  # folds back
    (js({"boundary": [[-1e308, 0], [1e308, 0], [0, 1]]}), "x.json", "too large"),
    (js({"boundary": [[1e308, 1e308], [1.5e308, 1e308], [1.5e308, 1.5e308]]}), "x.json", "too large"),  # areas overflow
    (js({"boundary": [[0, 0], [1e-200, 0], [0, 1e-200]]}), "x.json", "too small"),  # areas vanish
    (js({"boundary": SQUARE, "corners": [0, 4]}), "x.json", "out of range"),
    (js({"boundary": SQUARE, "corners": [0, -1]}), "x.json", "out of range"),
    (js({"boundary": SQUARE, "corners": [1, 1]}), "x.json", "twice"),
    (js({"boundary": SQUARE, "corners": [1.0]}), "x.json", "integer"),
    (js({"boundary": SQUARE, "corners": [True]}), "x.json", "integer"),
    (js({"boundary": SQUARE, "corners": 2}), "x.json", "list"),
    (b"[" * 100000, "x.json", "JSON"),
    (b"0 0\n1 0\n", "x.txt", "at least 3"),
    (b"0 0\n1 zero\n1 1\n", "x.txt", "not a number"),
    (b"0 0\n1 0 3\n1 1\n", "x.txt", "two numbers"),
    (b"0 0\n1 nan\n1 1\n", "x.txt", "finite"),
    (b"# only a comment\n\n", "x.txt", "no points"),
]


@pytest.mark.parametrize("data, name, fragment", BAD)
def test_bad_input_is_one_line_input_error(data, name, fragment):
    with pytest.raises(InputError) as info:
        parse_shape(data, f"some/dir/{name}")
    msg = str(info.value)
    assert "some/dir/" + name in msg
    assert fragment.lower() in msg.lower()
    assert "\n" not in msg


def test_text_errors_name_the_line():
    with pytest.raises(InputError, match=r"s\.txt:3: "):
        parse_shape(b"0 0\n# comment\n1 x\n", "s.txt")


def test_too_many_points():
    pts = [[math.cos(a), math.sin(a)] for a in np.linspace(0, 6, MAX_POINTS + 1)]
    with pytest.raises(InputError, match="maximum"):  # explicit corners: not simplified (tests/test_outline.py)
        parse_shape(js({"boundary": pts, "corners": [0]}), "big.json")
    with pytest.raises(InputError, match="maximum"):
        make_shape(pts)


def test_unreadable_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_shape(tmp_path / "missing.json")
    with pytest.raises(InputError, match="cannot read"):
        load_shape(tmp_path)  # a directory


@pytest.mark.parametrize("angle", [200, -1, 180, float("nan"), "wide"])
def test_bad_corner_angle_is_said_once(angle):
    with pytest.raises(InputError) as info:
        make_shape(SQUARE, corner_angle=angle)
    assert str(info.value).count("corner angle") == 1 and info.value.where is None


# ---------------------------------------------------------------------------------------------
# closed rings, extra keys


@pytest.mark.parametrize("loop", [SQUARE, L_SHAPE, TRIANGLE, HEXAGON])
def test_closed_ring_equals_open_loop(loop):
    """A ring whose last point repeats the first (GeoJSON, SVG) is the same shape."""
    open_ = make_shape(loop)
    closed = make_shape(list(loop) + [loop[0]])
    np.testing.assert_array_equal(closed.points, open_.points)
    np.testing.assert_array_equal(closed.corners, open_.corners)
    assert annotate(closed, 20).symbols == annotate(open_, 20).symbols


def test_closed_ring_corner_on_the_repeated_point_means_the_first():
    closed = make_shape(SQUARE + [SQUARE[0]], corners=[1, 2, 3, 4])
    assert corner_points(closed) == corner_points(make_shape(SQUARE))


def test_extra_json_keys_warn_once_naming_them():
    doc = {"boundary": SQUARE, "name": "plate", "units": "mm"}
    with pytest.warns(InputWarning) as record:
        shape = parse_shape(js(doc), "p.json")
    assert len(record) == 1
    msg = str(record[0].message)
    assert msg.startswith("p.json: ") and "'name'" in msg and "'units'" in msg and "boundary, corners" in msg
    assert shape.n_corners == 4


@pytest.mark.filterwarnings("ignore::jaxmatch.errors.InputWarning")  # random keys are warned, tested elsewhere
@pytest.mark.parametrize("name", ["r.json", "r.txt", "r.shape"])
@given(data=st.binary(max_size=300))
def test_random_bytes_never_crash(name, data):
    try:
        parse_shape(data, name)
    except InputError as err:
        assert name in str(err) and "\n" not in str(err)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
    lambda inner: st.lists(inner, max_size=6) | st.dictionaries(st.sampled_from(["boundary", "corners", "x"]), inner, max_size=3),
    max_leaves=30,
)


@pytest.mark.filterwarnings("ignore::jaxmatch.errors.InputWarning")  # random keys are warned, tested elsewhere
@given(doc=json_values)
def test_random_json_never_crashes(doc):
    try:
        parse_shape(json.dumps(doc).encode(), "r.json")
    except InputError as err:
        assert "r.json" in str(err)


@given(
    pts=st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)), min_size=0, max_size=9),
    corners=st.none() | st.lists(st.integers(-2, 10), max_size=5),
)
def test_random_polygons_either_load_or_input_error(pts, corners):
    doc = {"boundary": [list(p) for p in pts]}
    if corners is not None:
        doc["corners"] = corners
    try:
        shape = parse_shape(js(doc), "p.json")
    except InputError as err:
        assert "p.json" in str(err)
        return
    assert signed_area(shape.points) > 0
    annotate(shape, default_points(shape, 8))


# ---------------------------------------------------------------------------------------------
# annotation


def test_square_annotation():
    a = annotate(make_shape(SQUARE), 12)
    assert a.symbols == "xssxssxssxss"
    np.testing.assert_array_equal(a.codes, [X, S, S] * 4)
    np.testing.assert_array_equal(a.side, np.repeat(np.arange(4), 3))
    np.testing.assert_allclose(a.t, np.arange(12) / 3)
    assert a.perimeter == pytest.approx(4.0)
    np.testing.assert_allclose(a.positions[:3], [[0, 0], [1 / 3, 0], [2 / 3, 0]])


def test_symbols_match_codes():
    a = annotate(make_shape(L_SHAPE), 17)
    assert a.symbols == "".join(SYMBOLS[c] for c in a.codes)
    assert a.symbols.count("v") == 1 and a.symbols.count("x") == 5


def test_s_points_proportional_to_side_length():
    # 3 x 1 rectangle: sides 3, 1, 3, 1 -> 8 s points split 3, 1, 3, 1
    a = annotate(make_shape([[0, 0], [3, 0], [3, 1], [0, 1]]), 12)
    assert a.symbols == "xsssxsxsssxs"
    assert np.bincount(a.side).tolist() == [4, 2, 4, 2]


@pytest.mark.parametrize("m", [6, 7, 11, 20, 33])
def test_annotation_invariants(m):
    shape = make_shape(L_SHAPE)
    a = annotate(shape, m)
    assert len(a.symbols) == m == a.codes.shape[0] == a.t.shape[0] == a.positions.shape[0]
    assert a.t[0] == 0 and np.all(np.diff(a.t) > 0) and a.t[-1] < a.perimeter
    np.testing.assert_allclose(a.positions, point_at(shape.points, a.t))
    corners = np.flatnonzero(a.codes != S)
    np.testing.assert_array_equal(a.side[corners], np.arange(shape.n_corners))
    # s points evenly spaced strictly inside their side
    for j in range(shape.n_corners):
        tj = a.t[a.side == j]
        end = a.t[corners[j + 1]] if j + 1 < shape.n_corners else a.perimeter
        gaps = np.diff(np.concatenate([tj, [end]]))
        np.testing.assert_allclose(gaps, gaps[0])


def test_corner_positions_exact_in_user_coordinates():
    pts = np.array(L_SHAPE, float) * 3 + 1
    shape = make_shape(pts)
    a = annotate(shape, 12)
    got = shape.to_user(a.positions[a.codes != S])
    assert {tuple(np.round(p, 9)) for p in got} == {tuple(p) for p in pts.tolist()}


def test_no_corners_all_straight_evenly_spaced():
    circle = [[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 40, endpoint=False)]
    shape = make_shape(circle)
    assert shape.n_corners == 0
    a = annotate(shape, 10)
    assert a.symbols == "s" * 10
    np.testing.assert_allclose(np.diff(a.t), a.perimeter / 10)


def test_m_equal_to_corner_count_and_too_small():
    shape = make_shape(L_SHAPE)
    assert annotate(shape, 6).symbols == "xxxvxx"
    with pytest.raises(InputError, match="corners"):
        annotate(shape, 5)
    with pytest.raises(InputError):
        annotate(make_shape(SQUARE, corners=[]), 0)


@given(
    scale=st.floats(1e-3, 1e4),
    dx=st.floats(-1e3, 1e3),
    dy=st.floats(-1e3, 1e3),
    m=st.integers(8, 40),
    which=st.sampled_from([SQUARE, L_SHAPE, TRIANGLE, HEXAGON]),
)
def test_symbols_invariant_under_translation_and_scale(scale, dx, dy, m, which):
    base = annotate(make_shape(which), m)
    moved = annotate(make_shape(np.array(which, float) * scale + [dx, dy]), m)
    assert moved.symbols == base.symbols
    np.testing.assert_allclose(moved.t, base.t, atol=1e-9)


@given(weights=st.lists(st.floats(0.01, 100), min_size=1, max_size=10), total=st.integers(0, 200))
def test_largest_remainder_sums_and_is_near_quota(weights, total):
    counts = largest_remainder(weights, total)
    assert counts.sum() == total
    quota = total * np.array(weights) / np.sum(weights)
    assert np.all(np.abs(counts - quota) < 1 + 1e-9)


@pytest.mark.parametrize("n", [0, 1, 4, 12, 30])
@pytest.mark.parametrize("name", ["square.json", "tshape.json", "circle.json"])
def test_default_points(n, name):
    shape = load_shape(EXAMPLES / name)
    m = default_points(shape, n)
    assert m >= n and m >= shape.n_corners and m >= 1 and m - shape.n_corners >= n
    annotate(shape, m)


def test_cumulative_length_and_point_at():
    cum = cumulative_length(SQUARE)
    np.testing.assert_allclose(cum, [0, 1, 2, 3, 4])
    np.testing.assert_allclose(point_at(SQUARE, [0.5, 4.25, -0.5]), [[0.5, 0], [0.25, 0], [0, 0.5]])


@pytest.mark.parametrize("n", [12, 11, 7])
@pytest.mark.parametrize("fractions", [(0.125,), (0.25, 0.5), (0.125, 0.25, 0.75)])
def test_points_added_on_sides_change_no_corner_of_a_near_regular_polygon(n, fractions):
    """A regular 12-gon turns exactly 30 degrees (the default corner angle) at every vertex:
    subdividing its sides must not move round-off across the threshold (regression: 4 vs 5
    corners)."""
    deg = sorted({round(k * 360 / n) % 360 for k in range(n)})
    pts = np.array([[1000 * math.cos(math.radians(d)), 1000 * math.sin(math.radians(d))] for d in deg])
    loop = []
    for k in range(len(pts)):
        a, b = pts[k], pts[(k + 1) % len(pts)]
        loop.append(a)
        loop.extend(a + f * (b - a) for f in fractions)
    base, fine = make_shape(pts), make_shape(np.array(loop))
    assert fine.n_corners == base.n_corners
    assert corner_points(fine) == corner_points(base)


@pytest.mark.parametrize("points", [[[0, 0], [4, 0], [4, 3], [0, 3]], [[10, 10], [10, 13], [14, 13], [14, 10]],
                                    [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]])
def test_given_points_and_user_area(points):
    """``given_points`` are the input coordinates (reordered ccw from the first corner), and
    ``user_area`` is the area they enclose (shapely, independently of the shoelace code)."""
    import shapely

    s = make_shape(points)
    assert sorted(map(tuple, s.given_points.tolist())) == sorted(map(tuple, np.asarray(points, float).tolist()))
    assert s.user_area == pytest.approx(shapely.Polygon(points).area, rel=1e-12)


def _scale_corners_plain(p: np.ndarray, h: float, corner_angle: float, held_angle) -> np.ndarray:
    """scale_corners' rule written plainly: each window's points searched on their own, every
    turn over the window tested against the points kept so far by their distance along the loop."""
    from jaxmatch import shape as S
    from jaxmatch.arrays import roll
    from jaxmatch.geometry import cumulative_length, point_at

    cum = cumulative_length(p)
    per = float(cum[-1])
    w = min(S.CORNER_WINDOW * float(h), per / 8)
    s = cum[:-1]

    def turn_over(win: float) -> np.ndarray:
        a, b = p - point_at(p, s - win, cum), point_at(p, s + win, cum) - p
        return np.degrees(np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.sum(a * b, axis=1))))

    wide = turn_over(w)
    local = np.degrees(np.abs(S.corner_turns(p)))
    bent = np.flatnonzero(local > 0)
    if bent.size:
        k = np.searchsorted(bent, np.arange(p.shape[0]))
        prev_b = bent[(k - 1) % bent.size]
        next_b = bent[np.searchsorted(bent, np.arange(p.shape[0]), side="right") % bent.size]
        run_in, run_out = (s - s[prev_b]) % per, (s[next_b] - s) % per
    else:
        run_in = run_out = np.full(p.shape[0], per)
    tie = S._ANGLE_TIE
    keep = [int(i) for i in np.flatnonzero((wide > corner_angle + tie) & (local > corner_angle + tie)
                                           & (np.minimum(run_in, run_out) >= S.SHARP_RUN * w))]
    bend = max(corner_angle, S.HELD_ANGLE) if held_angle is None else held_angle
    rest = np.flatnonzero((wide > bend + tie) & (local > 0) & (turn_over(w / 4) >= S.CONCENTRATION * wide))

    def near(i, others):
        d = np.abs(s[others] - s[i])
        return np.minimum(d, per - d) < w

    for i in rest[np.argsort(-wide[rest], kind="stable")]:
        if keep and np.any(near(i, np.asarray(keep))):
            continue
        peer = rest[near(i, rest) & (wide[rest] >= wide[i] - S.PEAK_BAND)]
        keep.append(int(peer[np.argmax(local[peer])]))
    e_in = np.linalg.norm(p - roll(p, 1), axis=1)
    e_out = roll(e_in, -1)
    straight = np.flatnonzero((np.minimum(e_in, e_out) >= S.STRAIGHT_RUN * h) & (local > S.MIN_STRAIGHT_TURN))
    drawn = np.flatnonzero((np.maximum(e_in, e_out) >= S.TRACED * h) & (local > corner_angle + tie))
    return np.unique(np.concatenate([np.asarray(keep, np.int64), straight.astype(np.int64), drawn.astype(np.int64)]))


def _rounded_rectangle(w: float, h: float, r: float, step: float) -> np.ndarray:
    """A w x h rectangle whose corners are rounded to radius r, sampled every ``step`` degrees."""
    out = []
    for cx, cy, a0 in ((w - r, r, -90), (w - r, h - r, 0), (r, h - r, 90), (r, r, 180)):
        a = np.radians(np.arange(a0, a0 + 90 + 1e-9, step))
        out.append(np.c_[cx + r * np.cos(a), cy + r * np.sin(a)])
    return np.vstack(out)


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**16), st.sampled_from(["polygon", "noisy", "rounded"]), st.floats(0.0, 0.4),
       st.sampled_from([4, 8, 16, 40, 200]), st.sampled_from([30.0, 45.0]), st.sampled_from([None, 20.0]))
def test_corners_at_a_size_follow_the_plain_rule(seed, kind, noise, divisions, corner_angle, held_angle):
    """scale_corners (its four windows searched at once, a point already kept not measured
    against the others) keeps the corners of the rule written plainly: on polygons, noisy
    curves and rounded rectangles (rounded corners, whose turn over a quarter window decides)."""
    from jaxmatch.shape import scale_corners

    rng = np.random.default_rng(seed)
    if kind == "rounded":
        p = _rounded_rectangle(4.0, 2.0 + 2 * noise, rng.uniform(0.05, 0.9), rng.choice([2.0, 5.0, 15.0]))
    else:
        n = int(rng.integers(3, 12 if kind == "polygon" else 120))
        t = np.sort(rng.uniform(0, 2 * np.pi, n))
        if len(np.unique(t)) < n:
            return
        r = 1.0 + (noise if kind == "noisy" else 0.3) * rng.standard_normal(n) / (1 if kind == "polygon" else 8)
        p = np.c_[np.abs(r) * np.cos(t), np.abs(r) * np.sin(t)] + 0.05
    h = float(np.sum(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1))) / divisions
    np.testing.assert_array_equal(scale_corners(p, h, corner_angle, held_angle=held_angle),
                                  _scale_corners_plain(p, h, corner_angle, held_angle))


@pytest.mark.parametrize("name", ["frame", "triangle-hole", "letter-A", "gasket", "bracket"])
def test_checked_holes_make_the_shape_their_tests_make(name):
    """make_shape with ``holes_checked`` (valid holes, e.g. a shape's own listed from another
    point: canonical) gives the shape of the full tests, field for field."""
    import dataclasses

    from jaxmatch.meshing.region import canonical

    path = Path(__file__).resolve().parent.parent / "examples" / "holes" / f"{name}.json"
    shp = canonical(load_shape(path), None)
    args = dict(corners=shp.corners.tolist(), source=shp.source, holes=list(shp.holes),
                hole_corners=[list(c) for c in shp.hole_corners])
    plain = make_shape(shp.given_points, **args)
    fast = make_shape(shp.given_points, **args, checked=True, holes_checked=True)
    for f in dataclasses.fields(plain):
        assert _same_value(getattr(plain, f.name), getattr(fast, f.name)), f.name


def _same_value(a, b) -> bool:
    """Equal values, arrays bit for bit (dtype and shape too), through tuples, lists and dicts."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same_value(a[k], b[k]) for k in a)
    return a == b


def _shape_fields(s):
    """Every field of a shape, arrays as lists (for equality)."""
    import dataclasses

    def plain(v):
        if isinstance(v, np.ndarray):
            return (v.dtype.str, v.tolist())
        if isinstance(v, tuple):
            return tuple(plain(x) for x in v)
        return v
    return {f.name: plain(getattr(s, f.name)) for f in dataclasses.fields(s)}


@given(st.integers(3, 9), st.randoms(use_true_random=False), st.booleans(), st.booleans())
def test_explicit_corners_warn_exactly_when_not_in_boundary_order(n, rnd, clockwise, closed):
    """The warning fires exactly when the listed corners are not a cyclic run of the loop's
    order, one way or the other (spelled out here from the input alone); a list of plain ints
    gives the same shape as the same indices as numpy integers."""
    import warnings

    pts = [[math.cos(2 * math.pi * k / n), math.sin(2 * math.pi * k / n)] for k in range(n)]
    if clockwise:
        pts = pts[::-1]
    if closed:
        pts = pts + [pts[0]]
    listed = rnd.sample(range(n), rnd.randint(1, n))
    if rnd.random() < 0.5:
        listed.sort()
    ring = sorted(listed)  # the corners in the loop's own order
    rotations = [ring[i:] + ring[:i] for i in range(len(ring))]
    in_order = len(listed) < 3 or listed in rotations or listed[::-1] in rotations
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        plain = make_shape(pts, corners=listed)
    assert any("not listed in boundary order" in str(w.message) for w in seen) == (not in_order)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        numpy_ints = make_shape(pts, corners=[np.int64(c) for c in listed])
    assert _shape_fields(plain) == _shape_fields(numpy_ints)


@pytest.mark.parametrize("corners, words", [([0, 4], "corners\\[1\\] = 4 is out of range"), ([1, 1], "listed twice"),
                                            ([0, True], "must be an integer"), ([0, -1], "out of range"),
                                            ([0, 2.0], "must be an integer")])
def test_bad_corner_lists_are_refused_by_their_entry(corners, words):
    with pytest.raises(InputError, match=words):
        make_shape(SQUARE, corners=corners, source="c.json")


@pytest.mark.parametrize("points, words", [
    ([[0, 0], [1, 0], [float("nan"), 1]], "boundary point 2 is not finite"),
    ([[0, 0], [float("inf"), 0], [1, 1]], "boundary point 1 is not finite"),
    ([[-2e150, 0], [1, 0], [1, 1]], "coordinates are too large \\(2e\\+150;"),
    ([[0, 0], [1, 3e150], [-1, 3e150]], "coordinates are too large \\(3e\\+150;")])
def test_non_finite_or_huge_coordinates_are_named(points, words):
    """The first non-finite point by its index; the largest coordinate in absolute value, from
    either end of either column."""
    with pytest.raises(InputError, match=words):
        make_shape(points, source="c.json")
