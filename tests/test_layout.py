"""Multi-patch layouts (:mod:`jaxmatch.placement.layout`) and the ``jaxmatch layout`` command.

Specification:

* bad layouts are refused with one line naming the patch, point or side (and the CLI exits 2,
  writing nothing);
* ONE integer program chooses all multiplicities: shared sides get one count, requested counts
  are met exactly, and its optimum equals a brute-force search over small multiplicities;
* merged meshes are conforming, checked independently of the code: every edge lies in one or
  two quads, the edges of one quad lie exactly on the region's outer boundary and cover it, no
  quad is inverted, the quads' areas add up to the region's area;
* ``.msh`` files are read back by meshio and by gmsh itself: element types and counts, and the
  physical groups (one per patch, the outer boundary, every side).
"""

from __future__ import annotations

import itertools
import json
import math
import sys
from collections import Counter
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.errors import EXIT_BAD_INPUT, InputError
from jaxmatch.placement.floors import CURVE_SHARE, chord_area_error, curve_floors
from jaxmatch.placement.layout import (
    LayoutInfeasible,
    layout_sides,
    load_layout,
    make_layout,
    merge_patches,
    parse_layout,
    region_area,
    solve_counts,
)
from jaxmatch.io.meshfile import write_mesh
from jaxmatch.meshing.build import from_layout
from jaxmatch.meshing.pipeline import strategy_names
from jaxmatch.placement import solve as lay_solve
from jaxmatch.placement.refine import side_points
from jaxmatch.placement.solve import lean_floors_help, mesh_layout
from jaxmatch.scoring.lattice import load_lattice

ROOT = Path(__file__).resolve().parent.parent
LAYOUTS = ROOT / "examples" / "layouts"

SQUARE2 = [[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]]
TJ = {"points": [[0, 0], [2, 0], [2, 1], [0.7, 1], [0, 1], [0.7, 2], [0, 2], [2, 2]],
      "patches": [[0, 1, 2, 3, 4], [4, 3, 5, 6], [3, 2, 7, 5]]}


def sid_name(sides, name: str) -> str:
    """The name of side ``"a-b"`` as the layout spells it (either direction)."""
    rev = "-".join(name.split("-")[::-1])
    return next(n for n in sides.names if n in (name, rev))


@pytest.fixture(scope="module")
def lat():
    return load_lattice("fine")


# ---------------------------------------------------------------------------------------------
# independent checks


def edge_use(quads) -> Counter:
    """Undirected edge -> number of quads using it (plain Python)."""
    c: Counter = Counter()
    for q in np.asarray(quads).tolist():
        for a, b in zip(q, q[1:] + q[:1]):
            c[(min(a, b), max(a, b))] += 1
    return c


def dist_to_polyline(p, loop) -> float:
    """Distance from point ``p`` to the closed polyline ``loop (k, 2)``."""
    a = np.asarray(loop, float)
    b = np.roll(a, -1, axis=0)
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0, 1)
    return float(np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)))


def signed_areas(xy, quads) -> np.ndarray:
    p = np.asarray(xy)[np.asarray(quads)]
    q = np.roll(p, -1, axis=1)
    return 0.5 * np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0], axis=1)


def scaled_jacobians(xy, quads) -> np.ndarray:
    """Verdict scaled Jacobian, computed here (min over corners of sin of the corner angle)."""
    out = []
    for q in np.asarray(quads).tolist():
        vals = []
        for k in range(4):
            o, n, p = (np.asarray(xy[q[k]]), np.asarray(xy[q[(k + 1) % 4]]), np.asarray(xy[q[k - 1]]))
            e1, e2 = n - o, p - o
            vals.append((e1[0] * e2[1] - e1[1] * e2[0]) / (np.linalg.norm(e1) * np.linalg.norm(e2)))
        out.append(min(vals))
    return np.asarray(out)


def check_conforming(xy, quads, outline, tol=1e-9):
    """Every edge in 1 or 2 quads; the 1-quad edges lie on ``outline`` (closed (k, 2) loop) and
    their total length is its perimeter (so they cover it); every quad ccw; areas add up."""
    xy = np.asarray(xy)
    use = edge_use(quads)
    assert set(use.values()) <= {1, 2}, "an edge is in more than 2 quads"
    scale = float(np.max(np.ptp(outline, axis=0)))
    length = 0.0
    for (a, b), n in use.items():
        if n == 1:
            for p in (xy[a], xy[b], 0.5 * (xy[a] + xy[b])):
                assert dist_to_polyline(p, outline) <= tol * scale, f"boundary edge {a}-{b} is not on the outline"
            length += float(np.linalg.norm(xy[a] - xy[b]))
    perimeter = float(np.sum(np.linalg.norm(np.roll(outline, -1, axis=0) - outline, axis=1)))
    assert length == pytest.approx(perimeter, rel=1e-9)
    areas = signed_areas(xy, quads)
    assert np.all(areas > 0)
    o = np.asarray(outline, float)
    region = 0.5 * abs(np.sum(o[:, 0] * np.roll(o[:, 1], -1) - np.roll(o[:, 0], -1) * o[:, 1]))
    assert areas.sum() / region == pytest.approx(1.0, abs=1e-9)
    used = np.unique(np.asarray(quads))
    assert used.size == xy.shape[0], "unused vertices"


def outline_of(layout) -> np.ndarray:
    import shapely

    u = shapely.union_all([shapely.Polygon(layout.points[p]) for p in layout.patches])
    return np.asarray(u.exterior.coords)[:-1]


# ---------------------------------------------------------------------------------------------
# reading and validation

BAD = [
    ({"points": SQUARE2, "patches": [[0, 1, 9]]}, "out of range"),
    ({"points": SQUARE2, "patches": [[0, 1, 1, 4]]}, "twice"),
    ({"points": SQUARE2, "patches": [[0, 1, 4, 5], [0, 1, 4, 5]]}, "overlap"),
    ({"points": [[0, 0], [2, 0], [2, 2], [0, 2], [1, 1], [3, 1], [3, 3], [1, 3]], "patches": [[0, 1, 2, 3], [4, 5, 6, 7]]},
     "overlap"),
    ({"points": [[0, 0], [1, 0], [0.5, 1], [0.5, -1], [0.4, 0.5]], "patches": [[0, 1, 2], [1, 0, 3], [0, 1, 4]]},
     "used by 3 patches"),
    ({"points": [[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [3, 0], [3, 1], [2, 1]], "patches": [[0, 1, 2, 3], [4, 5, 6, 7]]},
     "connected"),
    ({"points": [[0, 0], [2, 0], [2, 1], [0, 1], [1, 1], [1, 2], [0, 2], [2, 2]], "patches": [[0, 1, 2, 3], [3, 4, 5, 6], [4, 2, 7, 5]]},
     "hanging node"),
    ({"points": [[0, 0], [1, 0], [1, 1], [0, 1], [1, 1e-13]], "patches": [[0, 4, 2, 3]]}, "same place"),
    ({"points": [[0, 0], [3, 0], [0, 1], [1, 2]], "patches": [[0, 1, 2, 3]]}, "crosses"),
    ({"points": [[0, 0], [1, 0], [2, 0]], "patches": [[0, 1, 2]]}, "zero area"),
    ({"points": SQUARE2, "patches": [[0, 1, 4, 5], [1, 2, 3, 4]], "sides": {"0-3": 2}}, "not a side"),
    ({"points": SQUARE2, "patches": [[0, 1, 4, 5], [1, 2, 3, 4]], "sides": {"0-1": 0}}, "positive integer"),
    ({"points": SQUARE2, "patches": [[0, 1, 4, 5]], "colour": 1}, "unknown key"),
    ({"points": SQUARE2}, "missing key"),
    ({"points": [[0, 0], [1, "a"]], "patches": [[0, 1]]}, "points"),
    ({"points": SQUARE2, "patches": [[0, 1, 4, 5]], "corners": [0, 99]}, "out of range"),
]


@pytest.mark.parametrize("doc,words", BAD, ids=[w for _, w in BAD])
def test_bad_layouts_get_one_line_errors(doc, words):
    with pytest.raises(InputError) as e:
        parse_layout(json.dumps(doc), "bad.json")
    msg = str(e.value)
    assert msg.startswith("bad.json: ") and "\n" not in msg
    assert words in msg


@pytest.mark.parametrize("doc,words", [b for b in BAD if "sides" not in b[0] and set(b[0]) == {"points", "patches"}],
                         ids=lambda x: x if isinstance(x, str) else "")
def test_checks_left_to_check_layout_give_the_same_line(doc, words):
    """``make_layout(..., check=False)`` (the pipeline's cuts, checked only when meshed) and then
    ``check_layout`` refuse a bad layout with the line ``make_layout`` gives."""
    from jaxmatch.placement.layout import check_layout

    with pytest.raises(InputError) as whole:
        make_layout(doc["points"], doc["patches"], source="bad.json")
    try:
        lay = make_layout(doc["points"], doc["patches"], source="bad.json", check=False)
    except InputError as e:  # a structural fault: found before the geometric checks either way
        assert str(e) == str(whole.value)
        return
    with pytest.raises(InputError) as later:
        check_layout(lay)
    assert str(later.value) == str(whole.value) and words in str(later.value)


def test_check_layout_accepts_what_make_layout_accepts():
    from jaxmatch.placement.layout import check_layout

    lay = make_layout(TJ["points"], TJ["patches"], check=False)
    check_layout(lay)
    full = make_layout(TJ["points"], TJ["patches"])
    assert all(np.array_equal(a, b) for a, b in zip(lay.patches, full.patches))
    assert all(np.array_equal(a, b) for a, b in zip(lay.patch_corner, full.patch_corner))


def test_not_json_names_file():
    with pytest.raises(InputError, match=r"^x\.json: not valid JSON"):
        parse_layout("{nope", "x.json")


def test_orientation_and_corners_are_normalised():
    # the second patch listed clockwise, starting at a non-corner point
    lay = make_layout(SQUARE2 + [[1, 0.5]], [[0, 1, 4, 5], [4, 3, 2, 1]], corners=[0, 1, 2, 3, 4, 5])
    for loop in lay.patches:
        p = lay.points[loop]
        area = 0.5 * np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
        assert area > 0 and lay.corner[loop[0]]
    sd = layout_sides(lay)
    assert len(sd.chains) == 7 and int((~sd.outer).sum()) == 1
    shared = int(np.flatnonzero(~sd.outer)[0])
    assert sd.names[shared] in ("1-4", "4-1") and sorted(sd.users[shared].tolist()) == [0, 1]


def test_t_junction_splits_a_patch_side():
    # a 2 x 1 block below two unit squares: point 3 is a corner of both squares and lies on the
    # block's top side, which is made of two sides
    lay = make_layout(TJ["points"], TJ["patches"])
    assert lay.patch_corner[0].sum() == 4  # (1, 1) is not a corner of the block
    sd = layout_sides(lay)
    top = [parts for parts in sd.patch_sides[0] if len(parts) > 1]
    assert len(top) == 1 and sorted(sd.names[s] for s in top[0]) == sorted([sid_name(sd, "2-3"), sid_name(sd, "3-4")])
    assert all(sd.users[s, 1] >= 0 for s in top[0])


def test_side_names_by_chain_when_ends_repeat():
    # a square with two corners: both sides run between points 0 and 2
    pts = [[0, 0], [1, 0], [1, 1], [0, 1]]
    sd = layout_sides(make_layout(pts, [[0, 1, 2, 3]], corners=[0, 2]))
    assert sd.names == ("0-1-2", "2-3-0")
    doc = {"points": pts, "patches": [[0, 1, 2, 3]], "corners": [0, 2], "sides": {"2-1-0": 4}}
    assert dict(parse_layout(json.dumps(doc), "s.json").requested) == {"0-1-2": 4}
    with pytest.raises(InputError, match="not a side"):
        parse_layout(json.dumps({**doc, "sides": {"0-2": 4}}), "s.json")


# ---------------------------------------------------------------------------------------------
# the integer program against brute force

QUAD = np.array([[1, 0], [0, 1], [1, 0], [0, 1]])  # one quad: opposite sides share a chord
TRI = np.array([[1, 0, 1], [1, 1, 0], [0, 1, 1]])  # three quads around a vertex


def strip(widths):
    """A row of rectangles of the given widths (height 1): (layout, sides)."""
    xs = np.concatenate([[0.0], np.cumsum(widths)])
    k = len(widths)
    pts = [[x, 0.0] for x in xs] + [[x, 1.0] for x in xs]
    patches = [[i, i + 1, k + 2 + i, k + 1 + i] for i in range(k)]
    lay = make_layout(pts, patches)
    return lay, layout_sides(lay)


def brute(sides, matrices, counts, size, bound=7):
    """Min objective of :func:`solve_counts` by enumerating every ``m`` in ``1..bound`` (numpy;
    widths None: chord targets 1), or None when no ``m`` meets the constraints."""
    nc = [A.shape[1] for A in matrices]
    m = np.array(list(itertools.product(range(1, bound + 1), repeat=sum(nc))))  # (N, M)
    parts = np.split(m, np.cumsum(nc)[:-1], axis=1)
    S = len(sides.chains)
    n = np.full((m.shape[0], S), -1)
    ok = np.ones(m.shape[0], bool)
    for p, (A, mp) in enumerate(zip(matrices, parts)):
        for i, (s,) in enumerate(sides.patch_sides[p]):
            v = mp @ A[i]
            ok &= (n[:, s] < 0) | (n[:, s] == v)
            n[:, s] = v
    for s, c in counts.items():
        ok &= n[:, s] == c
    if not ok.any():
        return None
    free = [s for s in range(S) if s not in counts]
    obj = np.abs(n[:, free] - sides.lengths[free] / size).sum(axis=1) + 0.01 * (m - 1).sum(axis=1)
    return float(obj[ok].min())


@settings(max_examples=25)
@given(widths=st.lists(st.sampled_from([0.5, 1.0, 1.5, 2.0]), min_size=1, max_size=3),
       size=st.sampled_from([0.5, 0.75, 1.0, 0.7, 0.45]), data=st.data())
def test_program_matches_brute_force(widths, size, data):
    lay, sd = strip(widths)
    mats = [QUAD] * lay.n_patches
    S = len(sd.chains)
    req = data.draw(st.dictionaries(st.integers(0, S - 1), st.integers(1, 5), max_size=2))
    want = brute(sd, mats, req, size)
    if want is None:
        with pytest.raises(LayoutInfeasible) as e:
            solve_counts(sd, mats, counts=req, size=size)
        assert "nearest feasible" in str(e.value) and e.value.nearest is not None
        return
    mults, n = solve_counts(sd, mats, counts=req, size=size)
    for p, (A, m) in enumerate(zip(mats, mults)):
        assert np.all(m >= 1)
        assert np.array_equal(A @ m, [n[parts].sum() for parts in sd.patch_sides[p]])  # shared sides: one count
    assert all(n[s] == c for s, c in req.items())
    got = sum(abs(n[s] - sd.lengths[s] / size) for s in range(S) if s not in req) + 0.01 * sum(float(np.sum(m - 1)) for m in mults)
    assert got == pytest.approx(want, abs=1e-6)


@given(tau=st.floats(0.0, 1000.0), x=st.integers(0, 1002), t=st.floats(0.0, 1.0))
def test_chord_row_is_the_absolute_value_at_integers_and_its_hull_between(tau, x, t):
    """The row the program adds per deviation (d >= slope * x + bound) never exceeds |x - tau| at
    an integer x, so the integer optimum is unchanged; between the integers around tau it is the
    chord of the two integer values, above |x - tau| (the tighter relaxation)."""
    from jaxmatch.placement.milp import _chord_row

    row = _chord_row(tau)
    if row is None:
        assert tau - np.floor(tau) <= 1e-12  # whole (up to round-off): the two lines suffice
        return
    slope, bound = row
    assert slope * x + bound <= abs(x - tau) + 1e-9
    lo = np.floor(tau)
    y = lo + t
    chord = (1 - t) * abs(lo - tau) + t * abs(lo + 1 - tau)
    assert slope * y + bound == pytest.approx(chord, abs=1e-9)
    assert slope * y + bound >= abs(y - tau) - 1e-9


def sid(sides, name: str) -> int:
    """Side id of ``"a-b"`` in either direction."""
    rev = "-".join(name.split("-")[::-1])
    return next(s for s, n in enumerate(sides.names) if n in (name, rev))


def test_program_couples_patches_through_shared_sides():
    # a square next to a 2-wide rectangle: the shared vertical side forces both heights equal
    lay, sd = strip([1.0, 2.0])
    left, right, top_right = sid(sd, "0-3"), sid(sd, "2-5"), sid(sd, "4-5")
    mults, n = solve_counts(sd, [QUAD, QUAD], counts={left: 3, top_right: 7})
    assert n[left] == 3 and n[top_right] == 7
    assert n[right] == 3 and n[sid(sd, "1-4")] == 3 and n[sid(sd, "1-2")] == 7
    with pytest.raises(LayoutInfeasible, match="asked, nearest feasible"):
        # the right edge is the same chord as the left one: 3 and 4 cannot both hold
        solve_counts(sd, [QUAD, QUAD], counts={left: 3, right: 4})


def test_program_triangle_parity():
    # a triangle patch: every side count is a sum of two chords, so the total is even
    lay = make_layout([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]])
    sd = layout_sides(lay)
    with pytest.raises(LayoutInfeasible) as e:
        solve_counts(sd, [TRI], counts={0: 2, 1: 2, 2: 3})
    assert sum(e.value.nearest.values()) % 2 == 0
    _, n = solve_counts(sd, [TRI], counts={0: 2, 1: 3, 2: 3})
    assert n.tolist() == [2, 3, 3]


# ---------------------------------------------------------------------------------------------
# merging (with structured grids standing in for refined templates)


class Grid(NamedTuple):
    xy: np.ndarray
    quads: np.ndarray
    side_vertices: tuple
    counts: np.ndarray


def grid_patch(corners, nx, ny) -> Grid:
    """Bilinear nx x ny grid in the quad ``corners (4, 2)`` (ccw), sides from corner i to i+1."""
    c = np.asarray(corners, float)
    u, v = np.meshgrid(np.arange(nx + 1) / nx, np.arange(ny + 1) / ny)
    u, v = u.ravel(), v.ravel()
    xy = ((1 - u) * (1 - v))[:, None] * c[0] + (u * (1 - v))[:, None] * c[1] + (u * v)[:, None] * c[2] + ((1 - u) * v)[:, None] * c[3]
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    sides = (idx[0, :], idx[:, -1], idx[-1, ::-1], idx[::-1, 0])
    # side points recomputed exactly as a straight side would be (bit-identical on both patches)
    return Grid(xy, quads, sides, np.array([nx, ny, nx, ny]))


def test_merge_grids_is_conforming():
    lay, sd = strip([1.0, 2.0])
    n = np.zeros(len(sd.chains), np.int64)
    nx, ny = (3, 5), 4
    patches = []
    for p, loop in enumerate(lay.patches):
        g = grid_patch(lay.points[loop], nx[p], ny)
        for i, (s,) in enumerate(sd.patch_sides[p]):
            n[s] = g.counts[i]
        patches.append(g)
    xy, quads, patch, side_ids, gap = merge_patches(lay, sd, patches, n)
    check_conforming(xy, quads, outline_of(lay))
    assert xy.shape[0] == (sum(nx) + 1) * (ny + 1)  # the shared side's vertices once
    assert quads.shape[0] == sum(nx) * ny and np.bincount(patch).tolist() == [nx[0] * ny, nx[1] * ny]
    assert gap < 1e-15


def test_merge_takes_the_first_patchs_side_vertices_and_measures_the_gap():
    """A shared side's vertices are the first patch's own positions; ``gap`` is the largest
    distance from the other patch's own position of one of them (here one moved by (3, 4) / 1000:
    5 / 1000), measured again here."""
    lay, sd = strip([1.0, 2.0])
    n = np.zeros(len(sd.chains), np.int64)
    patches = []
    for p, loop in enumerate(lay.patches):
        g = grid_patch(lay.points[loop], 2, 4)
        for i, (s,) in enumerate(sd.patch_sides[p]):
            n[s] = g.counts[i]
        patches.append(g)
    i = next(i for i, (s,) in enumerate(sd.patch_sides[1]) if sd.users[s, 1] >= 0)  # patch 1's side on the cut
    s = int(sd.patch_sides[1][i][0])
    moved_xy = patches[1].xy.copy()
    v = patches[1].side_vertices[i][2]  # an inner vertex of that side
    moved_xy[v] += [0.003, 0.004]
    xy, quads, patch, side_ids, gap = merge_patches(lay, sd, [patches[0], patches[1]._replace(xy=moved_xy)], n)
    k = next(k for k, (t,) in enumerate(sd.patch_sides[0]) if int(t) == s)
    mine = patches[0].xy[patches[0].side_vertices[k]]
    ids = side_ids[s] if not sd.patch_reversed[0][k][0] else side_ids[s][::-1]
    assert np.array_equal(xy[ids], mine)  # the first patch's positions, bit for bit
    own = moved_xy[patches[1].side_vertices[i]]
    ids1 = side_ids[s][::-1] if sd.patch_reversed[1][i][0] else side_ids[s]
    assert gap == pytest.approx(float(np.max(np.linalg.norm(xy[ids1] - own, axis=1))), abs=1e-15)
    assert gap == pytest.approx(0.005, abs=1e-12)
    check_conforming(xy, quads, outline_of(lay))


def test_merge_refuses_counts_that_disagree():
    lay, sd = strip([1.0, 1.0])
    patches = [grid_patch(lay.points[lay.patches[0]], 2, 2), grid_patch(lay.points[lay.patches[1]], 2, 3)]
    n = np.full(len(sd.chains), 2)
    with pytest.raises(ValueError, match="edges"):
        merge_patches(lay, sd, patches, n)


# ---------------------------------------------------------------------------------------------
# meshing with the catalogue


def test_two_blocks_mesh_conforming(cat, lat):
    lay = load_layout(LAYOUTS / "two-blocks.json")
    m = mesh_layout(lay, cat, lat, size=0.25)
    check_conforming(m.xy, m.quads, outline_of(lay))
    assert m.shared_gap == 0.0  # both patches put the shared side's vertices at the same points
    assert m.inverted == 0 and m.counts.tolist() == [4] * len(m.counts)
    sj = scaled_jacobians(m.xy, m.quads)
    assert sj.min() == pytest.approx(m.min_scaled_jacobian)
    # every side's vertices are evenly spaced on the side
    for ids in m.side_vertices:
        step = np.linalg.norm(np.diff(m.xy[ids], axis=0), axis=1)
        assert np.allclose(step, step[0])


def test_requested_counts_and_triangle_patch(cat, lat):
    lay = load_layout(LAYOUTS / "house.json")
    sd = layout_sides(lay)
    bottom = sid(sd, "0-1")
    m = mesh_layout(lay, cat, lat, size=0.3, counts={bottom: 6})
    check_conforming(m.xy, m.quads, outline_of(lay))
    assert m.counts[bottom] == 6 and m.inverted == 0
    # the quad patch's four sides with an odd total: no template can do it
    odd = {sid(sd, "0-1"): 2, sid(sd, "1-2"): 2, sid(sd, "2-4"): 2, sid(sd, "0-4"): 1}
    with pytest.raises(LayoutInfeasible, match="asked, nearest feasible") as e:
        mesh_layout(lay, cat, lat, counts=odd)
    assert sum(e.value.nearest.values()) % 2 == 0


def test_t_junction_mesh_is_conforming(cat, lat):
    lay = make_layout(TJ["points"], TJ["patches"])
    m = mesh_layout(lay, cat, lat, size=0.25)
    check_conforming(m.xy, m.quads, outline_of(lay))
    assert m.inverted == 0 and m.shared_gap == 0.0
    assert np.min(np.linalg.norm(m.xy - [0.7, 1.0], axis=1)) == 0.0  # the junction is a vertex
    assert m.min_scaled_jacobian >= 0.3
    # the block's top side carries the squares' bottom sides, evenly spaced on each
    for name in ("2-3", "3-4"):
        ids = m.side_vertices[m.sides.names.index(sid_name(m.sides, name))]
        step = np.linalg.norm(np.diff(m.xy[ids], axis=0), axis=1)
        assert np.allclose(step, step[0])


def test_t_junction_large_mesh_paths(cat, lat, monkeypatch):
    """fit_sides's path above SMOOTH_LOCAL quads (the solve's large ordering, smoothing only
    near the bad quads), forced on a small mesh with every quad "bad": the plain path's quads
    and boundary, conforming and valid."""
    from jaxmatch.defaults import Quality
    from jaxmatch.placement import layout as LM
    from jaxmatch.placement import refine as R

    def fresh(quality=Quality()):
        cat.cache.clear()
        lay = make_layout(TJ["points"], TJ["patches"])
        return lay, mesh_layout(lay, cat, lat, size=0.25, quality=quality)

    _, plain = fresh()
    monkeypatch.setattr(R, "SMOOTH_LOCAL", 0)
    monkeypatch.setattr(LM, "SMOOTH_LOCAL", 0)
    lay, fast = fresh(Quality(good_sj=2.0))
    np.testing.assert_array_equal(fast.quads, plain.quads)
    np.testing.assert_array_equal(fast.xy[plain.outer], plain.xy[plain.outer])
    check_conforming(fast.xy, fast.quads, outline_of(lay))
    assert fast.inverted == 0 and fast.shared_gap == 0.0
    assert fast.min_scaled_jacobian >= 0.3
    monkeypatch.undo()
    fresh()


def read_gmsh(path):
    """(physical groups {name: (dim, tag)}, {name: (element type names, element count)}) via gmsh."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(path))
        groups, elems = {}, {}
        for dim, tag in gmsh.model.getPhysicalGroups():
            name = gmsh.model.getPhysicalName(dim, tag)
            groups[name] = (dim, tag)
            types, count = set(), 0
            for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                ts, tags, _ = gmsh.model.mesh.getElements(dim, int(ent))
                for t, tg in zip(ts, tags):
                    types.add(gmsh.model.mesh.getElementProperties(int(t))[0])
                    count += len(tg)
            elems[name] = (types, count)
        nodes = gmsh.model.mesh.getNodes()[0].size
        return groups, elems, nodes
    finally:
        gmsh.finalize()


def check_msh(path, m):
    """The .msh file against the mesh: meshio and gmsh read the same groups and counts."""
    import meshio

    r = meshio.read(path)
    assert r.cells_dict["quad"].shape == m.quads.shape
    assert np.array_equal(r.cell_data_dict["gmsh:physical"]["quad"], m.patch + 1)  # physical group "patch p" is tag p + 1
    assert np.allclose(r.points[:, :2], m.xy)
    groups, elems, nodes = read_gmsh(path)
    assert nodes == m.xy.shape[0]
    P = m.layout.n_patches
    for p in range(P):
        assert groups[f"patch {p}"][0] == 2
        assert elems[f"patch {p}"] == ({"Quadrilateral 4"}, int(np.sum(m.patch == p)))
    assert groups["boundary"][0] == 1 and elems["boundary"] == ({"Line 2"}, int(m.outer.size))
    for name, c, outer in zip(m.sides.names, m.counts, m.sides.outer):  # a side between patches: "cut i-j"
        assert elems[f"{'side' if outer else 'cut'} {name}"] == ({"Line 2"}, int(c))
    assert len(groups) == P + 1 + len(m.sides.names)


def test_two_blocks_msh_read_back(cat, lat, tmp_path):
    lay = load_layout(LAYOUTS / "two-blocks.json")
    m = mesh_layout(lay, cat, lat, size=0.5)
    out = write_mesh(tmp_path / "t.msh", from_layout(m), msh_version="2.2")  # node order as in xy
    check_msh(out, m)


@pytest.mark.parametrize("suffix", [".vtu", ".json"])
def test_two_blocks_other_formats_keep_patch_and_lines(cat, lat, tmp_path, suffix):
    import meshio

    m = mesh_layout(load_layout(LAYOUTS / "two-blocks.json"), cat, lat, size=0.5)
    out = write_mesh(tmp_path / f"t{suffix}", from_layout(m))
    if suffix == ".json":
        d = json.loads(out.read_text())
        assert d["patch"] == m.patch.tolist() and d["quads"] == m.quads.tolist()
        assert len(d["groups"]["boundary"]) == m.outer.size and d["quad_groups"]["names"] == ["patch 0", "patch 1"]
        return
    r = meshio.read(out)
    assert np.array_equal(r.cells_dict["quad"], m.quads)
    assert np.array_equal(r.cell_data_dict["patch"]["quad"], m.patch)
    lines = r.cells_dict["line"]
    group = r.cell_data_dict["line_group"]["line"]
    assert np.sum(group == 0) == m.outer.size  # "boundary" is the first line group
    assert lines.shape[0] == m.outer.size + int(m.counts.sum())


def test_notched_plate_many_patches(cat, lat, tmp_path):
    """The >= 10-patch example: one conforming mesh that gmsh reads with its physical groups."""
    lay = load_layout(LAYOUTS / "notched-plate.json")
    assert lay.n_patches >= 10
    m = mesh_layout(lay, cat, lat, size=0.25)
    check_conforming(m.xy, m.quads, outline_of(lay))
    assert m.inverted == 0 and m.shared_gap == 0.0
    assert m.counts[sid(m.sides, "14-15")] == 4  # the file's requested count
    sj = scaled_jacobians(m.xy, m.quads)
    assert sj.min() >= 0.3
    check_msh(write_mesh(tmp_path / "plate.msh", from_layout(m), msh_version="2.2"), m)


# ---------------------------------------------------------------------------------------------
# the command




def test_cli_layout_msh_png_json(cli, tmp_path):
    out, png = tmp_path / "m.msh", tmp_path / "m.png"
    sides = tmp_path / "s.json"
    sides.write_text(json.dumps({"0-1": 2}))
    code, stdout, err = cli("mesh", LAYOUTS / "two-blocks.json", "--size", 0.5, "--sides-file", sides,
                            "--out", out, "--png", png, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["patches"] == 2 and d["inverted"] == 0 and d["side_counts"]["0-1"] == 2 and d["out"] == str(out)
    assert png.read_bytes().startswith(b"\x89PNG")
    import meshio

    r = meshio.read(out)
    assert r.cells_dict["quad"].shape[0] == d["quads"]
    assert {"boundary", "patch 0", "patch 1", "side 0-1", "cut 1-4"} <= set(r.field_data)
    assert "side 1-4" not in r.field_data  # the side between the patches is no side group


def test_cli_shape_one_strategy(cli, tmp_path):
    code, stdout, err = cli("mesh", ROOT / "examples" / "tshape.json", "--size", 0.5, "--strategy", "continuations")
    assert code == 0, err
    assert "chosen: continuations" in stdout and "4 patches" in stdout and "inverted quads: 0" in stdout


@pytest.mark.slow
def test_a_frame_of_patches_encloses_a_hole(cat, tmp_path):
    """Four patches around a window: a layout with a hole, meshed with the hole as a boundary loop."""
    import jaxmatch

    frame = {"points": [[0, 0], [3, 0], [3, 3], [0, 3], [1, 1], [2, 1], [2, 2], [1, 2]],
             "patches": [[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]}
    path = tmp_path / "frame.json"
    path.write_text(json.dumps(frame))
    m = jaxmatch.mesh(path, size=0.25, catalogue=cat)
    inner = sum(c for name, c in m.side_counts.items() if {int(i) for i in name.split("-")} <= {4, 5, 6, 7})
    assert m.inverted == 0 and "hole 1" in m.line_sets and len(m.line_sets["hole 1"]) == inner
    assert m.area_ratio == pytest.approx(1.0, abs=1e-12) and len(m.irregular) == 0


def test_cli_shape_is_decomposed(cli, tmp_path):
    code, stdout, err = cli("mesh", ROOT / "examples" / "lshape.json", "--size", 0.5, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    tried = set(strategy_names()) - {"rings"}  # (the ring partition: only when no candidate is at the size and of high quality)
    assert d["chosen"] in tried
    assert {c["name"] for c in d["candidates"]} == tried
    assert d["inverted"] == 0 and d["area_ratio"] == pytest.approx(1, abs=1e-9)


@pytest.mark.parametrize("args,words", [
    (["--size", "0.5"], "overlap"),
    (["--size", "-1"], "--size"),
    (["--size", "0.5", "--strategy", "zigzag"], "--strategy"),
])
def test_cli_bad_input_one_line_exit_2(cli, tmp_path, args, words):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"points": SQUARE2, "patches": [[0, 1, 4, 5], [0, 1, 4, 5]]} if words == "overlap"
                              else {"points": SQUARE2, "patches": [[0, 1, 4, 5], [1, 2, 3, 4]]}))
    out = tmp_path / "o.msh"
    code, stdout, err = cli("mesh", bad, *args, "--out", out)
    assert code == EXIT_BAD_INPUT
    lines = err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in err
    assert not out.exists()


def test_cli_shape_without_corners_is_meshed(cli):
    code, stdout, err = cli("mesh", ROOT / "examples" / "circle.json", "--size", 0.5, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["corners"] == 0 and d["inverted"] == 0 and d["min_scaled_jacobian"] >= 0.3


def test_cli_layout_without_size_uses_the_default(cli):
    code, stdout, err = cli("mesh", LAYOUTS / "two-blocks.json", "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["chosen"] == "layout" and d["size"] > 0 and d["inverted"] == 0


def test_cli_sides_file_errors(cli, tmp_path):
    sides = tmp_path / "s.json"
    sides.write_text(json.dumps({"0-9": 2}))
    code, _, err = cli("mesh", LAYOUTS / "two-blocks.json", "--sides-file", sides)
    assert code == EXIT_BAD_INPUT and str(sides) in err and "not a side" in err
    code, _, err = cli("mesh", ROOT / "examples" / "lshape.json", "--sides-file", sides)
    assert code == EXIT_BAD_INPUT and "--sides-file" in err


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(2, 30), tol=st.sampled_from([1e-9, 1e-3, 0.05, 0.3]))
def test_coincident_points_are_the_brute_force_pairs(seed, n, tol):
    """_check_coincident refuses a point set exactly when some pair is within tol (every pair
    measured), naming the first such pair i < j."""
    from jaxmatch.placement.layout import _check_coincident

    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 1, size=(n, 2))
    if rng.random() < 0.5:
        pts[rng.integers(0, n)] = pts[rng.integers(0, n)] + rng.uniform(-tol, tol, 2) * 0.5
    d = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    close = [(i, j) for i in range(n) for j in range(i + 1, n) if d[i, j] <= tol]
    if not close:
        _check_coincident(pts, tol, "<test>")
        return
    with pytest.raises(InputError, match=rf"points {close[0][0]} and {close[0][1]} are at the same place"):
        _check_coincident(pts, tol, "<test>")


# ---------------------------------------------------------------------------------------------
# the bound from a layout's nodes (node_sj_bound): what lets the pipeline skip a layout unmeshed


def _split_sj_plain(lo: float, hi: float, q0: int) -> float:
    """The best worst-quad scaled Jacobian at a vertex, searched: q from q0 to 40 quads, angles
    sampled densely in [lo, hi] (and the multiples of 90 degrees there), equal split."""
    angles = np.concatenate([np.linspace(lo, hi, 2001), [a for a in np.pi / 2 * np.arange(1, 200) if lo <= a <= hi]])
    best = -1.0
    for q in range(q0, 41):
        a = angles / q
        best = max(best, float(np.max(np.where((a > 0) & (a < np.pi), np.sin(a), 0.0))))
    return best


@settings(max_examples=200, deadline=None)
@given(lo=st.floats(0.05, 7.0), width=st.floats(0.0, 0.5), q0=st.integers(1, 8))
def test_split_sj_is_the_searched_best(lo, width, q0):
    from jaxmatch.placement.bounds import _split_sj

    assert _split_sj(lo, lo + width, q0) == pytest.approx(_split_sj_plain(lo, lo + width, q0), abs=2e-6)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n_a=st.integers(1, 6), n_b=st.integers(1, 6), t=st.floats(0.0, 1.0))
def test_outline_angle_holds_every_first_edge(seed, n_a, n_b, t):
    """A boundary edge from an outline point ends anywhere on the outline up to the next patch
    corner: the angle between such edges lies in the range ``_outline_angle`` gives."""
    from jaxmatch.placement.bounds import _outline_angle

    rng = np.random.default_rng(seed)
    # a corner at the origin, its sides bending gently: ahead along +x, back along a direction at 40-140 degrees
    turn = rng.uniform(np.radians(40), np.radians(140))
    ahead = np.cumsum(np.stack([np.cos(rng.uniform(-0.4, 0.4, n_a)), np.sin(rng.uniform(-0.4, 0.4, n_a))], 1), 0)
    dirs = turn + rng.uniform(-0.4, 0.4, n_b)
    behind = np.cumsum(np.stack([np.cos(dirs), np.sin(dirs)], 1), 0)
    pts = np.concatenate([[[0.0, 0.0]], ahead, behind])
    a_ids, b_ids = list(range(1, n_a + 1)), list(range(n_a + 1, n_a + n_b + 1))
    lo, hi = _outline_angle(pts, 0, a_ids, b_ids)
    ia, ib = rng.integers(0, n_a), rng.integers(0, n_b)
    pa = pts[a_ids[ia]] if ia == 0 else (1 - t) * pts[a_ids[ia - 1]] + t * pts[a_ids[ia]]
    pb = pts[b_ids[ib]] if ib == 0 else (1 - t) * pts[b_ids[ib - 1]] + t * pts[b_ids[ib]]
    angle = (np.arctan2(pb[1], pb[0]) - np.arctan2(pa[1], pa[0])) % (2 * np.pi)
    assert lo - 1e-12 <= angle <= hi + 1e-12
    if n_a == n_b == 1:
        assert lo == pytest.approx(hi) == pytest.approx(angle)


def test_node_sj_bound_of_plain_layouts():
    from jaxmatch.placement.bounds import node_sj_bound

    square = make_layout([[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 1, 2, 3]])
    assert node_sj_bound(square) == 1.0
    # the square cut along its diagonal: two patches split a right angle at both ends
    diagonal = make_layout([[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 1, 2], [0, 2, 3]])
    assert node_sj_bound(diagonal) == pytest.approx(np.sin(np.pi / 4), abs=1e-6)
    # five patches around a point inside a pentagon: some angle there is at most 72 degrees
    ring = [[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 11)[:-1]]
    pts = ring + [[0.0, 0.0]]
    fan = [[10, 2 * i, 2 * i + 1, (2 * i + 2) % 10] for i in range(5)]
    assert node_sj_bound(make_layout(pts, fan, corners=[10] + list(range(0, 10, 2)))) == pytest.approx(np.sin(np.radians(72)), abs=1e-6)
    # a T-junction on a straight side (three patches, 180 degrees): q = 2 reaches 90 degrees
    assert node_sj_bound(make_layout(TJ["points"], TJ["patches"])) == 1.0


BOUND_SHAPES = [ROOT / "examples" / n for n in ("lshape.json", "tshape.json", "plus.json", "hexagon.json",
                                                "triangle.json", "curved.json", "holes/plate-bolt.json",
                                                "holes/frame.json")] + \
    [ROOT / "examples" / "labels" / "shapes" / f"{n}.json" for n in ("ushape", "zshape", "stairs", "cross",
                                                                     "notched-rectangle", "chevron", "trapezoid",
                                                                     "quarter-disk", "arch")]


@pytest.mark.parametrize("path", BOUND_SHAPES, ids=lambda p: p.stem)
def test_node_sj_bound_holds_on_every_strategys_mesh(cat, lat, path):
    """Every strategy's layout of the example regions at two sizes, meshed as the pipeline meshes
    it: its min scaled Jacobian (measured on the mesh here) is at most ``node_sj_bound``, unless a
    quad is inverted."""
    import jaxmatch
    from jaxmatch.geometry import cumulative_length
    from jaxmatch.meshing.pipeline import strategy_names
    from jaxmatch.meshing.region import canonical
    from jaxmatch.placement.decompose import decompose, single_patch
    from jaxmatch.placement.bounds import node_sj_bound
    from jaxmatch.placement.solve import ALL_SIZES, TEMPLATE_SIZES
    from jaxmatch.shape import DEFAULT_CORNER_ANGLE

    shp0 = jaxmatch.load_shape(path)
    claims = 0
    for div in (16, 32):
        h = float(cumulative_length(shp0.input_points)[-1]) / div
        shp = canonical(shp0, h, DEFAULT_CORNER_ANGLE)
        for name in strategy_names():
            try:
                lay = single_patch(shp) if name == "single" else decompose(shp, name)
                lm = mesh_layout(lay, cat, lat, size=h, smooth_cuts=lay.n_patches > 1,
                                 sizes=ALL_SIZES if name == "single" else TEMPLATE_SIZES)
            except (InputError, ValueError, ArithmeticError, IndexError):
                continue
            bound = node_sj_bound(lay)
            p = lm.xy[lm.quads]
            a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
            sj = (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]) / (np.linalg.norm(a, axis=2) * np.linalg.norm(b, axis=2))
            assert sj.min() <= 0 or sj.min() <= bound + 1e-9, (name, div, sj.min(), bound)
            claims += bound < 1
    if path.stem in ("lshape", "ushape", "zshape", "hexagon", "trapezoid"):
        assert claims > 0  # the bound says something on these


def test_node_sj_bound_claims_nothing_where_the_outline_is_not_one_loop():
    """Layouts made without their checks (the pipeline's cuts before meshing) may be broken: two
    squares touching at a corner (the outline touches itself) get no claim, not an error."""
    from jaxmatch.placement.bounds import node_sj_bound

    lay = make_layout([[0, 0], [1, 0], [1, 1], [0, 1], [2, 1], [2, 2], [1, 2]], [[0, 1, 2, 3], [2, 4, 5, 6]], check=False)
    assert node_sj_bound(lay) == 1.0


# ---------------------------------------------------------------------------------------------
# translated patches share their templates and refinements


def _alone(monkeypatch, lay_mod):
    """Every patch its own (no patch taken for a translate of another)."""
    monkeypatch.setattr(lay_mod, "_translates",
                        lambda lay: [lay_mod.Translate(p, np.zeros(2), 0) for p in range(lay.n_patches)])


def _quad_set(xy, quads, digits=9) -> list:
    """The quads as corner coordinates (rounded), each from its smallest corner in its own
    order, sorted: the mesh whatever its vertex numbering."""
    out = []
    for q in np.asarray(quads).tolist():
        c = [tuple(np.round(xy[v], digits) + 0.0) for v in q]
        k = c.index(min(c))
        out.append(tuple(c[k:] + c[:k]))
    return sorted(out)


def _mesh_both(cat, lat, monkeypatch, layout, size):
    from jaxmatch.defaults import QUALITY

    lay_mod = lay_solve
    shared = mesh_layout(layout, cat, lat, size=size)
    with monkeypatch.context() as mp:
        _alone(mp, lay_mod)
        alone = lay_mod._mesh_layout(layout, cat, lat, size=size, counts=None,
                                     templates_per_patch=lay_mod.TEMPLATES_PER_PATCH, sizes=lay_mod.TEMPLATE_SIZES,
                                     smooth_cuts=True, progress=None, first_templates=None, quality=QUALITY,
                                     lkey=lay_mod.layout_key(layout))
    return shared, alone


@pytest.mark.parametrize("dx", [1.0, 0.37, 1e3 + 0.1])
def test_translated_patches_mesh_as_if_meshed_alone(cat, lat, monkeypatch, dx):
    """A row of three slanted quads, each a translate of the first: they are found as such, and
    the mesh is the one meshing every patch on its own gives (up to round-off), with shared
    sides bit-identical."""
    lay_mod = lay_solve

    pts = [[k * dx, 0.0] for k in range(4)] + [[k * dx + 0.2, 1.0] for k in range(4)]
    patches = [[k, k + 1, 5 + k, 4 + k] for k in range(3)]
    layout = make_layout(pts, patches)  # (k * dx + 0.2 - k * dx is 0.2 only up to round-off)
    moved = lay_mod._translates(layout)
    assert [t.of for t in moved] == [0, 0, 0] and np.allclose(moved[2].shift, [2 * dx, 0.0])
    shared, alone = _mesh_both(cat, lat, monkeypatch, layout, dx / 3)
    assert np.array_equal(shared.quads, alone.quads) and shared.counts.tolist() == alone.counts.tolist()
    assert np.allclose(shared.xy, alone.xy, atol=1e-12 * (1 + 3 * dx))
    assert shared.shared_gap == 0.0 and shared.inverted == 0
    check_conforming(shared.xy, shared.quads, outline_of(layout))


@pytest.mark.parametrize("start", [0, 1, 2, 3])
def test_translate_listed_from_another_corner(cat, lat, monkeypatch, start):
    """Two congruent rectangles side by side, the second's loop listed from another corner (so
    its sides are the first's turned), with a third patch across both to tie their counts: the
    second takes the first's templates and refinement turned, and the mesh is the one meshing
    each patch alone gives."""
    lay_mod = lay_solve

    pts = [[0, 0], [1.5, 0], [3, 0], [3, 1], [1.5, 1], [0, 1], [0, 2.25], [3, 2.25]]
    second = [1, 2, 3, 4]
    second = second[start:] + second[:start]
    layout = make_layout(pts, [[0, 1, 4, 5], second, [5, 4, 3, 7, 6]])  # (4: a T-junction on the third)
    moved = lay_mod._translates(layout)
    assert moved[1].of == 0 and np.allclose(moved[1].shift, [1.5, 0.0]) and moved[2].of == 2
    shared, alone = _mesh_both(cat, lat, monkeypatch, layout, 0.3)
    assert shared.counts.tolist() == alone.counts.tolist()  # (the vertices may be numbered otherwise)
    assert _quad_set(shared.xy, shared.quads) == _quad_set(alone.xy, alone.quads)
    assert shared.shared_gap == 0.0 and shared.inverted == 0
    check_conforming(shared.xy, shared.quads, outline_of(layout))


def test_translates_need_the_same_corners_and_offsets():
    lay_mod = lay_solve

    def of(lay):
        return [t.of for t in lay_mod._translates(lay)]

    pts = [[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]]
    assert of(make_layout(pts, [[0, 1, 4, 5], [1, 2, 3, 4]])) == [0, 0]
    assert of(make_layout(pts, [[0, 1, 4, 5], [4, 1, 2, 3]])) == [0, 0]  # listed from another corner
    bent = [[0, 0], [1, 0], [2, 0], [2, 1.5], [1, 1], [0, 1]]
    assert of(make_layout(bent, [[0, 1, 4, 5], [1, 2, 3, 4]])) == [0, 1]
    near = [[0, 0], [1, 0], [2, 0], [2, 1 + 1e-9], [1, 1], [0, 1]]
    assert of(make_layout(near, [[0, 1, 4, 5], [1, 2, 3, 4]])) == [0, 1]


def _even_points(poly: np.ndarray, n: int) -> np.ndarray:
    """``n + 1`` points evenly spaced by arc length along ``poly`` (numpy only)."""
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(poly, axis=0), axis=1))])
    t = np.linspace(0.0, cum[-1], n + 1)
    return np.stack([np.interp(t, cum, poly[:, 0]), np.interp(t, cum, poly[:, 1])], axis=1)


def _shoelace(p: np.ndarray) -> float:
    return 0.5 * abs(float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=60, unique=True), st.floats(0.2, 5.5),
       st.integers(1, 90), st.booleans())
def test_chord_area_error_is_the_area_between_a_convex_arc_and_its_chords(fracs, span, n, backwards):
    """On a convex arc every piece lies on one side of its chord, so the pieces' areas add up to
    the arc's polygon less the chords' polygon (both closed by the same end chord; shapely's
    areas), whichever way the arc runs; a straight polyline loses none."""
    import shapely

    t = span * np.array(sorted({0.0, 1.0, *fracs}))
    arc = np.stack([3.0 + 2.0 * np.cos(t), -1.0 + 2.0 * np.sin(t)], axis=1)
    arc = arc[::-1].copy() if backwards else arc
    chords = side_points(arc, n)
    want = (shapely.Polygon(arc).area - (shapely.Polygon(chords).area if n > 1 else 0.0)) if len(arc) > 2 else 0.0
    assert chord_area_error(arc, n) == pytest.approx(want, rel=1e-9, abs=1e-12)
    line = np.linspace([0.0, 1.0], [5.0, -2.0], len(arc))
    assert chord_area_error(line, n) == pytest.approx(0.0, abs=1e-12)


def _bulge(width: float):
    """A rectangle ``width`` x 10 whose top is a flat circular arc (58 points), its four corners
    the layout's: ``(points, layout)``."""
    t = np.linspace(0.0, math.pi, 61)[1:-1]
    r = width / 2
    arc = np.stack([r + r * np.cos(t), 10.0 + 0.6 * r * np.sin(t)], axis=1)  # from the right to the left
    pts = np.vstack([[[0.0, 0.0], [width, 0.0], [width, 10.0]], arc, [[0.0, 10.0]]])
    n = len(pts)
    return pts, make_layout(pts, [list(range(n))], corners=[0, 1, 2, n - 1])


@pytest.mark.parametrize("doc", [
    {"points": [[0, 0], [2, 0], [2, 1], [1, 1], [0, 1]], "patches": [[0, 1, 2, 3], [0, 3, 4]]},
    {"points": [[0, 0], [3, 0], [3, 3], [0, 3], [1, 1], [2, 1], [2, 2], [1, 2]],
     "patches": [[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]}])
def test_region_area_is_the_union_of_the_patch_polygons_bit_for_bit(doc):
    """The area of the union of the patches made one by one as ``shapely.Polygon`` (the plain
    path), exactly; and the sum of the patches' shoelace areas to round-off (a frame: its window
    left out)."""
    import shapely

    pts = np.asarray(doc["points"], np.float64) * 1.37 + 0.11
    lay = make_layout(pts, doc["patches"])
    plain = shapely.union_all([shapely.Polygon(pts[lp]) for lp in lay.patches]).area
    assert region_area(lay) == plain
    assert region_area(lay) == pytest.approx(sum(_shoelace(pts[lp]) for lp in lay.patches), rel=1e-12)


@pytest.mark.parametrize("width", [10.0, 40.0])
def test_lean_curve_floors_share_the_area_budget_among_the_curved_sides(width):
    """The straight sides get no floor; with ``lean`` they take no share of the budget either, so
    the arc's lean floor is below the one of the budget shared by the whole boundary, and its
    chords (evenly spaced, as the mesh places them) lose at most ``CURVE_SHARE * area_tol`` of the
    region's area, measured by the shoelace formula; one edge fewer loses more."""
    pts, lay = _bulge(width)
    sd = layout_sides(lay)
    region = region_area(lay)
    assert region == pytest.approx(_shoelace(pts))
    lean = curve_floors(lay, sd, 0.01, lean=True)
    fine = curve_floors(lay, sd, 0.01)
    curved = [s for s in range(len(sd.chains)) if len(sd.chains[s]) > 2]
    assert len(curved) == 1 and all(lean[s] == fine[s] == 1 for s in range(len(sd.chains)) if s not in curved)
    s = curved[0]
    assert 1 < lean[s] < fine[s]
    chain = lay.points[sd.chains[s]]
    for floor, share in ((lean[s], 1.0), (fine[s], float(sd.lengths[s] / sd.lengths.sum()))):
        budget = CURVE_SHARE * 0.01 * region * share
        lost = _shoelace(pts) - _shoelace(np.vstack([[[0.0, 0.0], [width, 0.0]], _even_points(chain, int(floor))]))
        assert 0 < lost <= budget * (1 + 1e-9)
        fewer = _shoelace(pts) - _shoelace(np.vstack([[[0.0, 0.0], [width, 0.0]], _even_points(chain, int(floor) - 1)]))
        assert fewer > budget  # the fewest edges that keep it


def test_lean_floors_help_only_where_a_curve_floor_is_below_the_size_band(cat):
    """The bulge 40 wide: its arc of length ``L`` has the floor ``fine`` from the whole
    boundary's share and the smaller ``lean`` from the curves' own. The lean solve can help at a
    size ``h`` where ``L / fine < 0.5 h <= L / lean`` (the floor puts the arc's edges below the
    size band and the lean floor lets them into it); not at a finer size (no floor below the
    band), nor at a coarser one (the lean floor is below it too), nor for a polygon without curves."""
    _, lay = _bulge(40.0)
    sd = layout_sides(lay)
    s = next(s for s in range(len(sd.chains)) if len(sd.chains[s]) > 2)
    fine = int(curve_floors(lay, sd, 0.01)[s])
    lean = int(curve_floors(lay, sd, 0.01, lean=True)[s])
    L = float(sd.lengths[s])
    assert lean < fine
    assert lean_floors_help(lay, cat, 2 * L / lean)
    assert lean_floors_help(lay, cat, L / lean + L / fine)
    assert not lean_floors_help(lay, cat, 2 * L / fine)
    assert not lean_floors_help(lay, cat, 2 * L / lean * 1.01)
    square = make_layout([[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [20.0, 10.0], [0.0, 10.0]], [[0, 1, 2, 3, 4]],
                         corners=[0, 1, 2, 4])
    assert not lean_floors_help(square, cat, 2 * L / lean)
