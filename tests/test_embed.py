"""Placement of a matched mesh in a shape: orientation, boundary, Tutte + untangling +
smoothing, quality measures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.placement.embed import (
    Placement,
    arc_lengths,
    boundary_paths,
    oriented_boundary,
    place,
    point_at,
    polygon_area,
    smooth,
    to_user,
    tutte,
)
from jaxmatch.quality import (edge_ratios, inverted_mask, placement_measures, quad_areas, quality, quality_inverted,
                              sj_inverted)
from jaxmatch.catalogue.mesh import boundary_valences, from_quads, validate, valences

# ---------------------------------------------------------------------------------------------
# hand-built meshes and shapes


def grid(nx: int, ny: int):
    """nx x ny grid of unit squares: (QuadMesh, lattice positions (V, 2))."""
    vid = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    q = [[vid[j, i], vid[j, i + 1], vid[j + 1, i + 1], vid[j + 1, i]] for j in range(ny) for i in range(nx)]
    xy = np.array([[i, j] for j in range(ny + 1) for i in range(nx + 1)], float)
    return from_quads(q), xy


def star(k: int):
    """One internal vertex (0) of valence k; spokes 1..k (valence 3), corners k+1..2k (valence 2)."""
    return from_quads([[0, 1 + i, 1 + k + i, 1 + (i + 1) % k] for i in range(k)])


def subdivide(mesh):
    """Split every quad 2x2 (edge midpoints and face centres become new vertices)."""
    nv = mesh.n_vertices
    mids: dict[tuple[int, int], int] = {}

    def mid(a, b):
        key = (min(a, b), max(a, b))
        if key not in mids:
            mids[key] = nv + len(mids)
        return mids[key]

    out = []
    for quad in mesh.quads.tolist():
        out.append((quad, [mid(quad[i], quad[(i + 1) % 4]) for i in range(4)]))
    base = nv + len(mids)
    quads = []
    for f, (quad, m) in enumerate(out):
        c = base + f
        a, b, cc, d = quad
        quads += [[a, m[0], c, m[3]], [m[0], b, m[1], c], [c, m[1], cc, m[2]], [m[3], c, m[2], d]]
    return from_quads(quads)


def l_mesh():
    """An L of three unit squares, each split 2x2: 5 internal vertices, concave corner (1, 1)
    on a boundary vertex of valence 4. Returns (mesh, lattice positions)."""
    cells = [(a, b) for b in range(4) for a in range(4) if not (a >= 2 and b >= 2)]
    ids: dict[tuple[int, int], int] = {}

    def vid(i, j):
        return ids.setdefault((i, j), len(ids))

    quads = [[vid(a, b), vid(a + 1, b), vid(a + 1, b + 1), vid(a, b + 1)] for a, b in cells]
    xy = np.array(sorted(ids, key=ids.get), float) * 0.5
    return from_quads(quads), xy


def half_disk_mesh():
    """4 quads covering a half disk: centre rectangle a b c d, arc vertices e (45 deg) and
    f (135 deg); diameter ends p (-1, 0) and q (1, 0) have valence 2."""
    p, a, b, q, e, c, d, f = range(8)
    return from_quads([[a, b, c, d], [b, q, e, c], [d, c, e, f], [p, a, d, f]])


def seg(a, b, k):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a + (b - a) * np.linspace(0, 1, k + 1)[:, None]


def arc(r, th0, th1, k):
    th = np.linspace(th0, th1, k + 1)
    return np.c_[r * np.cos(th), r * np.sin(th)]


def loop_of(sides):
    """Closed polyline from sides (each includes both ends; consecutive sides share ends)."""
    return np.concatenate([np.asarray(s, float)[:-1] for s in sides])


def annotated(points, idx):
    """(t, positions) of the polyline vertices ``idx`` (annotated points on polyline vertices)."""
    cum = arc_lengths(points)
    idx = np.asarray(idx)
    return cum[idx], points[idx]


def polygon_loop(corners, per_side):
    """Polygon with ``per_side`` segments per side; returns (points, corner indices)."""
    c = np.asarray(corners, float)
    k = len(c)
    pts = loop_of([seg(c[i], c[(i + 1) % k], per_side) for i in range(k)])
    return pts, np.arange(k) * per_side


# each case: a function returning place()'s arguments (points, t, alignment, mesh, rotation, reflected)
def case_quad():
    mesh, _ = grid(1, 1)
    pts, corners = polygon_loop([(0, 0), (2, 0), (2, 2), (0, 2)], 4)
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, corners, mesh, 0, False


def case_grid3():
    mesh, _ = grid(3, 3)
    pts, _ = polygon_loop([(0, 0), (3, 0), (3, 3), (0, 3)], 3)
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, np.arange(12), mesh, 0, False


def case_star(k):
    def make():
        mesh = star(k)
        ang = np.pi / 2 + 2 * np.pi * np.arange(k) / k
        pts, _ = polygon_loop(np.c_[np.cos(ang), np.sin(ang)], 4)
        t, _ = annotated(pts, np.arange(len(pts)))
        rot = int(np.flatnonzero(boundary_valences(mesh) == 2)[0])  # a corner first
        return pts, t, 2 * np.arange(2 * k), mesh, rot, False

    return make


def case_l_lattice():
    mesh, xy = l_mesh()
    pts = xy[mesh.boundary]
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, np.arange(len(pts)), mesh, 0, False


def _warp_thin(u):
    return np.where(u <= 1, 0.5 * u, 0.5 + 2.5 * (u - 1))


def case_l_thin():
    """The L mesh in an L with thin arms: Tutte folds a quad at the concave corner."""
    mesh, xy = l_mesh()
    b = xy[mesh.boundary]
    pts = np.c_[_warp_thin(b[:, 0]), _warp_thin(b[:, 1])]
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, np.arange(len(pts)), mesh, 0, False


def case_l_grid():
    """A 3x3 grid in an L: the concave corner lands on a valence-3 vertex (Tutte folds)."""
    mesh, _ = grid(3, 3)
    pts, _ = polygon_loop([(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)], 6)
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, np.array([0, 2, 4, 6, 8, 10, 12, 18, 21, 24, 30, 33]), mesh, 0, False


def case_quarter_annulus():
    mesh, _ = grid(3, 3)
    pts = loop_of([seg((1, 0), (2, 0), 3), arc(2, 0, np.pi / 2, 42), seg((0, 2), (0, 1), 3), arc(1, np.pi / 2, 0, 42)])
    idx = np.r_[0:3, 3:45:14, 45:48, 48:90:14]
    t, _ = annotated(pts, idx)
    return pts, t, np.arange(12), mesh, 0, False


def case_d_shape():
    """A half disk: a diameter of 6 segments and a curved side of 90 segments, annotated at
    every fifth arc point; the mesh (half-disk mesh split 2x2) uses every third annotated arc
    point, so its boundary edges skip annotated points and polyline vertices."""
    mesh = subdivide(half_disk_mesh())
    pts = loop_of([seg((-1, 0), (1, 0), 6), arc(1, 0, np.pi, 90)])
    idx = np.r_[0:6, 6:96:5]  # 6 diameter points + 18 arc points
    t, _ = annotated(pts, idx)
    rot = int(np.flatnonzero(mesh.boundary == 0)[0])  # start at p = (-1, 0)
    al = np.r_[0:6, 6:24:3]  # arc vertices at 0, 30, ..., 150 degrees
    return pts, t, al, mesh, rot, False


def case_c_shape():
    """A 6x2 grid bent into a C (annulus sector of 300 degrees): strongly non-convex."""
    mesh, xy = grid(6, 2)
    th = np.radians(300) * xy[:, 0] / 6
    r = 1 + 0.5 * xy[:, 1] / 2
    lattice = np.c_[r * np.cos(th), -r * np.sin(th)]
    pts = lattice[mesh.boundary]
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, np.arange(len(pts)), mesh, 0, False


CASES = {
    "quad": case_quad,
    "grid3": case_grid3,
    "star3": case_star(3),
    "star4": case_star(4),
    "star5": case_star(5),
    "l_lattice": case_l_lattice,
    "l_thin": case_l_thin,
    "l_grid": case_l_grid,
    "quarter_annulus": case_quarter_annulus,
    "d_shape": case_d_shape,
    "c_shape": case_c_shape,
}

# lower bounds for the minimum scaled Jacobian (measured values are printed by -s)
MIN_SJ = {
    "quad": 1.0 - 1e-12,
    "grid3": 1.0 - 1e-12,
    "star3": 0.86,
    "star4": 1.0 - 1e-12,
    "star5": 0.95,
    "l_lattice": 1.0 - 1e-12,
    "l_thin": 0.8,
    "l_grid": 0.45,
    "quarter_annulus": 0.9,
    "d_shape": 0.85,
    "c_shape": 0.85,
}


def run_case(name, **kw) -> tuple[Placement, tuple]:
    args = CASES[name]()
    return place(*args, **kw), args


# ---------------------------------------------------------------------------------------------
# test meshes are what they claim


def test_hand_meshes_are_valid():
    for mesh in [grid(1, 1)[0], grid(3, 3)[0], star(3), star(4), star(5), l_mesh()[0], half_disk_mesh(), subdivide(half_disk_mesh())]:
        assert validate(mesh, invariant_i=False) == []
    mesh, xy = l_mesh()
    assert validate(mesh) == []
    assert mesh.n_internal == 5
    concave = int(np.flatnonzero((xy == [1.0, 1.0]).all(axis=1))[0])
    assert concave in mesh.boundary.tolist() and valences(mesh.quads)[concave] == 4


# ---------------------------------------------------------------------------------------------
# placements


@pytest.mark.parametrize("name", sorted(CASES))
def test_no_inverted_quads_and_quality(name):
    pl, (pts, t, al, mesh, rot, refl) = run_case(name)
    assert pl.inverted == 0, name
    assert np.all(quad_areas(pl.xy, pl.mesh.quads) > 0)
    assert pl.min_scaled_jacobian >= MIN_SJ[name], (name, pl.min_scaled_jacobian)
    print(f"{name}: min SJ {pl.min_scaled_jacobian:.3f} mean {pl.mean_scaled_jacobian:.3f} area {pl.mesh_area:.4f}/{pl.region_area:.4f}")
    assert pl.xy.shape == (mesh.n_vertices, 2) and np.all(np.isfinite(pl.xy))
    assert pl.scaled_jacobian.shape == pl.min_angle.shape == pl.max_angle.shape == (mesh.n_quads,)
    assert np.all(pl.max_angle < 180) and np.all(pl.min_angle > 0)


@pytest.mark.parametrize("name", sorted(CASES))
def test_boundary_vertices_sit_on_aligned_points(name):
    pl, (pts, t, al, mesh, rot, refl) = run_case(name)
    loop = pl.mesh.boundary
    expected = pts[np.searchsorted(arc_lengths(pts), t[al])]  # annotated points are polyline vertices
    np.testing.assert_array_equal(pl.xy[loop], expected)
    np.testing.assert_array_equal(pl.alignment, al)


@pytest.mark.parametrize("name", ["l_thin", "l_grid", "c_shape"])
def test_untangling_is_needed_and_works(name):
    """Plain Tutte (smooth_iters=0) folds on these non-convex shapes; the full placement not."""
    raw, _ = run_case(name, smooth_iters=0)
    assert raw.inverted > 0
    pl, _ = run_case(name)
    assert pl.inverted == 0


def test_perfect_grid_has_unit_scaled_jacobian():
    pl, _ = run_case("grid3")
    np.testing.assert_allclose(pl.scaled_jacobian, 1.0, atol=1e-12)
    np.testing.assert_allclose(pl.min_angle, 90.0, atol=1e-9)
    np.testing.assert_allclose(pl.max_angle, 90.0, atol=1e-9)
    _, lattice = grid(3, 3)
    np.testing.assert_allclose(pl.xy, lattice, atol=1e-12)
    assert pl.irregular.size == 0


def test_irregular_vertices_and_areas():
    for k in (3, 5):
        pl, _ = run_case(f"star{k}")
        assert pl.irregular.tolist() == [0]
    pl, _ = run_case("l_lattice")
    assert pl.irregular.size == 0
    assert pl.mesh_area == pytest.approx(pl.region_area) == pytest.approx(3.0)
    pl, _ = run_case("quarter_annulus")  # chords cut the outer arc, add at the inner one
    assert pl.region_area == pytest.approx(0.75 * math.pi, rel=2e-3)
    assert 0.9 < pl.area_ratio < 1.0


def test_smooth_iters_zero_is_tutte():
    pts, t, al, mesh, rot, refl = case_l_fat()
    pl = place(pts, t, al, mesh, rot, refl, smooth_iters=0)
    b = pl.xy[pl.mesh.boundary]
    c = b.mean(axis=0)
    s = np.sqrt(np.mean(np.sum((b - c) ** 2, axis=1)))
    x0 = to_user(tutte(pl.mesh.quads, mesh.n_vertices, pl.mesh.boundary, (b - c) / s), s, c)
    np.testing.assert_allclose(pl.xy, x0, atol=1e-12)


def case_l_fat():
    mesh, xy = l_mesh()
    b = xy[mesh.boundary]
    f = lambda u: np.where(u <= 1, 2.5 * u, 2.5 + 0.5 * (u - 1))  # noqa: E731
    pts = np.c_[f(b[:, 0]), f(b[:, 1])]
    t, _ = annotated(pts, np.arange(len(pts)))
    return pts, t, np.arange(len(pts)), mesh, 0, False


def test_smoothing_improves_worst_quad_without_folding():
    args = case_l_fat()
    raw = place(*args, smooth_iters=0)
    pl = place(*args)
    assert raw.inverted == pl.inverted == 0
    assert pl.min_scaled_jacobian > raw.min_scaled_jacobian + 0.05


def test_positions_argument_is_used_exactly():
    pts, t, al, mesh, rot, refl = case_quarter_annulus()
    pos = point_at(pts, t) + 1e-3  # deliberately off the polyline
    pl = place(pts, t, al, mesh, rot, refl, positions=pos)
    np.testing.assert_array_equal(pl.xy[pl.mesh.boundary], pos[al])
    for j, path in enumerate(pl.boundary_paths):
        np.testing.assert_array_equal(path[0], pos[al[j]])
        np.testing.assert_array_equal(path[-1], pos[al[(j + 1) % len(al)]])


# ---------------------------------------------------------------------------------------------
# orientation and reflection


def test_oriented_boundary_rotation_and_reflection():
    mesh, _ = l_mesh()
    s = mesh.boundary
    for rot in (0, 3, len(s) - 1):
        om, loop = oriented_boundary(mesh, rot, False)
        assert loop[0] == s[rot]
        np.testing.assert_array_equal(loop, np.roll(s, -rot))
        np.testing.assert_array_equal(om.quads, mesh.quads)
        np.testing.assert_array_equal(om.boundary, loop)
        om, loop = oriented_boundary(mesh, rot, True)
        np.testing.assert_array_equal(loop, np.roll(s[::-1], -rot))
        np.testing.assert_array_equal(om.quads, mesh.quads[:, ::-1])
        assert validate(om) == []  # mirrored quads are ccw around the reversed loop


@pytest.mark.parametrize("rot", [0, 5])
def test_reflected_placement_is_the_mirror_image(rot):
    """An L mesh mirrored (x -> -x) into a mirrored L: positions are the mirrored lattice and
    every quad stays ccw."""
    mesh, xy = l_mesh()
    mirrored = xy * [-1.0, 1.0] + [5.0, 0.0]
    loop = np.roll(mesh.boundary[::-1], -rot)
    pts = mirrored[loop]  # ccw in the plane (mirror reverses orientation)
    assert polygon_area(pts) > 0
    t, _ = annotated(pts, np.arange(len(pts)))
    pl = place(pts, t, np.arange(len(pts)), mesh, rot, True)
    assert pl.inverted == 0
    assert np.all(quad_areas(pl.xy, pl.mesh.quads) > 0)
    np.testing.assert_allclose(pl.xy, mirrored, atol=1e-12)
    np.testing.assert_array_equal(pl.mesh.boundary, loop)


def mirror_case(pts, t, al, mesh, rot, refl):
    """The same match into the mirror image (x -> -x) of the shape: the mirrored outline is
    made ccw again by reversing it (keeping point 0 first), so the mesh is matched reflected."""
    P, m = len(pts), len(t)
    per = arc_lengths(pts)[-1]
    q = (pts * [-1.0, 1.0])[np.mod(-np.arange(P), P)]
    t_new = np.mod(per - t, per)
    order = np.argsort(t_new)
    new_index = np.empty(m, int)
    new_index[order] = np.arange(m)
    al_new = new_index[al]  # input index of loop[j] in the mirrored input
    _, loop = oriented_boundary(mesh, rot, refl)
    s = mesh.boundary if refl else mesh.boundary[::-1]
    first = loop[int(np.argmin(al_new))]
    rot_new = int(np.flatnonzero(s == first)[0])
    _, loop_new = oriented_boundary(mesh, rot_new, not refl)
    np.testing.assert_array_equal(loop_new, loop[np.argsort(al_new)])  # the construction is right
    return q, t_new[order], np.sort(al_new), mesh, rot_new, not refl


@pytest.mark.parametrize("name", ["star3", "l_thin", "l_grid", "d_shape", "c_shape"])
def test_reflected_placements_stay_ccw_and_mirror(name):
    """The same mesh matched reflected into the mirror image of the shape: all quads ccw, and
    the placement is the mirror image of the unreflected one."""
    args = CASES[name]()
    margs = mirror_case(*args)
    assert margs[5] is True and polygon_area(margs[0]) > 0
    pl = place(*args)
    pm = place(*margs)
    assert pm.inverted == 0
    assert np.all(quad_areas(pm.xy, pm.mesh.quads) > 0)
    np.testing.assert_allclose(pm.xy, pl.xy * [-1.0, 1.0], atol=1e-6)
    np.testing.assert_allclose(np.sort(pm.scaled_jacobian), np.sort(pl.scaled_jacobian), atol=1e-6)


# ---------------------------------------------------------------------------------------------
# invariance (hypothesis)


@settings(max_examples=25, deadline=None)
@given(
    name=st.sampled_from(["l_thin", "l_grid", "star5", "quarter_annulus"]),
    scale=st.floats(1e-2, 1e3),
    dx=st.floats(-1e3, 1e3),
    dy=st.floats(-1e3, 1e3),
)
def test_translation_and_scaling_move_the_placement_alike(name, scale, dx, dy):
    pts, t, al, mesh, rot, refl = CASES[name]()
    base = place(pts, t, al, mesh, rot, refl)
    moved = place(pts * scale + [dx, dy], t * scale, al, mesh, rot, refl)
    tol = 1e-7 * scale * (1 + abs(dx) / scale + abs(dy) / scale)
    np.testing.assert_allclose(moved.xy, base.xy * scale + [dx, dy], atol=tol)
    np.testing.assert_allclose(moved.scaled_jacobian, base.scaled_jacobian, atol=1e-6)
    assert moved.inverted == base.inverted


@settings(max_examples=40, deadline=None)
@given(
    theta=st.floats(0, 2 * math.pi),
    scale=st.floats(1e-3, 1e3),
    shift=st.integers(0, 3),
    seed=st.integers(0, 2**31 - 1),
)
def test_quality_is_invariant_under_similarity_and_relabelling(theta, scale, shift, seed):
    rng = np.random.default_rng(seed)
    xy = rng.normal(size=(4, 2))
    quads = np.array([[0, 1, 2, 3]])
    rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    moved = xy @ rot.T * scale + [3.0, -7.0]
    a = np.array(quality(xy, quads))
    b = np.array(quality(moved, np.roll(quads, shift, axis=1)))
    np.testing.assert_allclose(a, b, atol=1e-8)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amp=st.floats(0.0, 0.25))
def test_smooth_never_makes_things_worse(seed, amp):
    """From any valid perturbed grid: no new inversions, min scaled Jacobian not lower."""
    mesh, xy = grid(4, 3)
    rng = np.random.default_rng(seed)
    internal = np.setdiff1d(np.arange(mesh.n_vertices), mesh.boundary)
    start = xy.copy()
    start[internal] += rng.uniform(-amp, amp, size=(internal.size, 2))
    out = smooth(start, mesh.quads, mesh.boundary)
    np.testing.assert_array_equal(out[mesh.boundary], xy[mesh.boundary])
    assert inverted_mask(out, mesh.quads).sum() <= inverted_mask(start, mesh.quads).sum()
    if not inverted_mask(start, mesh.quads).any():
        assert quality(out, mesh.quads)[0].min() >= quality(start, mesh.quads)[0].min() - 1e-12


# ---------------------------------------------------------------------------------------------
# quality against hand-computed values

S3 = math.sqrt(3) / 2
ATAN3 = math.degrees(math.atan2(1, 3))  # 18.43 deg
COS06 = math.degrees(math.acos(-0.6))  # 126.87 deg
TRAP = math.degrees(math.atan2(2, 1))  # 63.43 deg


@pytest.mark.parametrize(
    "xy, sj, amin, amax",
    [
        ([(0, 0), (1, 0), (1, 1), (0, 1)], 1.0, 90.0, 90.0),  # unit square
        ([(0, 0), (3, 0), (3, 1), (0, 1)], 1.0, 90.0, 90.0),  # rectangle
        ([(0, 0), (1, 0), (1.5, S3), (0.5, S3)], S3, 60.0, 120.0),  # 60-degree rhombus
        ([(0, 0), (2, 0), (1.5, 1), (0.5, 1)], 1 / math.sqrt(1.25), TRAP, 180 - TRAP),  # trapezoid
        ([(0, 0), (2, 0), (0.5, 0.5), (0, 2)], -0.8, ATAN3, 360 - COS06),  # dart: reflex at (0.5, 0.5)
        ([(0, 0), (0, 1), (1, 1), (1, 0)], -1.0, 270.0, 270.0),  # clockwise square
        ([(0, 0), (1, 0), (1, 0), (0, 1)], 0.0, 0.0, 90.0),  # zero-length edge: those corners read 0
    ],
    ids=["square", "rectangle", "rhombus", "trapezoid", "dart", "clockwise", "degenerate"],
)
def test_quality_hand_values(xy, sj, amin, amax):
    s, lo, hi = quality(np.array(xy, float), np.array([[0, 1, 2, 3]]))
    assert s[0] == pytest.approx(sj, abs=1e-12)
    assert lo[0] == pytest.approx(amin, abs=1e-9)
    assert hi[0] == pytest.approx(amax, abs=1e-9)


def test_inverted_mask_and_vectorised_quality():
    xy = np.array([(0, 0), (1, 0), (1, 1), (0, 1), (2, 0), (2, 1), (0.5, 0.5)], float)
    quads = np.array([[0, 1, 2, 3], [1, 4, 5, 2], [0, 1, 6, 3], [0, 3, 2, 1]])
    # [0,1,6,3]: the corner at 6 is straight -> cross 0 -> counts as inverted
    np.testing.assert_array_equal(inverted_mask(xy, quads), [False, False, True, True])
    sj, lo, hi = quality(xy, quads)
    assert sj.shape == (4,)
    np.testing.assert_allclose(sj[:2], 1.0)
    assert sj[2] == pytest.approx(0.0) and sj[3] == pytest.approx(-1.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sj_inverted_is_quality_and_inverted_mask(seed):
    """The one-pass measure gives exactly the plain paths' arrays (random, partly folded quads)."""
    rng = np.random.default_rng(seed)
    xy = rng.normal(size=(40, 2))
    quads = rng.integers(0, 40, size=(60, 4))
    sj, inv = sj_inverted(xy, quads)
    np.testing.assert_array_equal(sj, quality(xy, quads)[0])
    np.testing.assert_array_equal(inv, inverted_mask(xy, quads))
    assert sj_inverted(xy, np.zeros((0, 4), np.int64))[0].shape == (0,)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_quality_inverted_is_the_corner_by_corner_measures(seed):
    """The placement's four measures from one set of corner vectors: the one-pass scaled
    Jacobian, the plain inverted mask, and angles computed corner by corner in Python (random,
    partly folded quads)."""
    rng = np.random.default_rng(seed)
    xy = rng.normal(size=(40, 2))
    quads = rng.integers(0, 40, size=(60, 4))
    quads = np.array([rng.choice(40, 4, replace=False) for _ in range(60)])  # four distinct vertices each
    sj, lo, hi, inv = quality_inverted(xy, quads)
    np.testing.assert_array_equal(sj, sj_inverted(xy, quads)[0])
    np.testing.assert_array_equal(inv, inverted_mask(xy, quads))
    for f, q in enumerate(quads.tolist()):
        angles = []
        for c in range(4):
            (x0, y0), (x1, y1), (x3, y3) = xy[q[c]], xy[q[(c + 1) % 4]], xy[q[(c + 3) % 4]]
            ux, uy, vx, vy = x1 - x0, y1 - y0, x3 - x0, y3 - y0  # to the next and the previous vertex
            a = math.degrees(math.atan2(ux * vy - uy * vx, ux * vx + uy * vy)) % 360.0  # ccw from one to the other
            angles.append(a)
        assert lo[f] == pytest.approx(min(angles), abs=1e-9) and hi[f] == pytest.approx(max(angles), abs=1e-9)
    assert [a.shape for a in quality_inverted(xy, np.zeros((0, 4), np.int64))] == [(0,)] * 4


# ---------------------------------------------------------------------------------------------
# polyline helpers


def test_point_at_returns_polyline_vertices_exactly_and_wraps():
    pts = loop_of([arc(1, 0, np.pi, 7), seg((-1, 0), (1, 0), 3)])
    cum = arc_lengths(pts)
    np.testing.assert_array_equal(point_at(pts, cum[:-1]), pts)
    np.testing.assert_array_equal(point_at(pts, cum[-1]), pts[0])  # perimeter wraps to start
    mid = point_at(pts, 0.5 * (cum[1] + cum[2]))
    np.testing.assert_allclose(mid, 0.5 * (pts[1] + pts[2]))


def test_boundary_paths_cover_the_whole_outline():
    pts, t, al, mesh, rot, refl = case_d_shape()
    paths = boundary_paths(pts, t[al])
    assert len(paths) == len(al)
    joined = np.concatenate([p[:-1] for p in paths])
    # every polyline vertex appears once, in order, starting at the first aligned point
    start = int(np.searchsorted(arc_lengths(pts), t[al[0]]))
    np.testing.assert_array_equal(joined, np.roll(pts, -start, axis=0))
    for j, p in enumerate(paths):
        np.testing.assert_array_equal(p[-1], paths[(j + 1) % len(paths)][0])
    # the placed boundary polygon is inscribed in the outline
    assert polygon_area(np.concatenate([p[:-1] for p in paths])) == pytest.approx(polygon_area(pts))


def test_boundary_path_between_points_off_the_vertices():
    pts = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], float)
    (p0, p1) = boundary_paths(pts, np.array([0.5, 2.5]))
    np.testing.assert_allclose(p0, [(0.5, 0), (1, 0), (1, 1), (0.5, 1)])
    np.testing.assert_allclose(p1, [(0.5, 1), (0, 1), (0, 0), (0.5, 0)])


@pytest.mark.parametrize(
    "al, msg",
    [([0, 1, 2], "entries"), ([0, 2, 1, 3], "increasing"), ([0, 1, 2, 99], r"\[0, ")],
)
def test_bad_alignment_raises(al, msg):
    pts, t, _, mesh, rot, refl = case_quad()
    with pytest.raises(ValueError, match=msg):
        place(pts, t, np.array(al), mesh, rot, refl)


# ---------------------------------------------------------------------------------------------
# sliding boundary vertices and edge ratios


def test_slide_gradient_matches_finite_differences():
    """The chain rule through the softmax gap parametrisation (embed._Params.pull) against
    central differences of the energy."""
    from jaxmatch.placement.embed import Slide, _Params, _objective

    mesh, lattice = grid(3, 2)
    xy = lattice + np.random.default_rng(3).normal(0, 0.05, lattice.shape)
    b = mesh.boundary
    bottom = [v for v in b if lattice[v, 1] == 0 and 0 < lattice[v, 0] < 3]
    bottom = sorted(bottom, key=lambda v: lattice[v, 0])
    xy[bottom] = lattice[bottom]
    slides = (Slide(np.array([0.0, 0.0]), np.array([3.0, 0.0]), np.array(bottom)),)
    free = np.setdiff1d(np.arange(mesh.n_vertices), b)
    params = _Params(xy, free, slides)
    x = params.start(xy) + np.random.default_rng(4).normal(0, 0.1, params.start(xy).shape)
    f, g = _objective(x, params, mesh.quads, 1e-3, 2.0)
    h = 1e-6
    num = np.array([(_objective(x + h * e, params, mesh.quads, 1e-3, 2.0)[0] - _objective(x - h * e, params, mesh.quads, 1e-3, 2.0)[0]) / (2 * h)
                    for e in np.eye(x.size)])
    np.testing.assert_allclose(g, num, rtol=1e-4, atol=1e-7)


def test_sliding_vertices_stay_on_their_side_in_order_and_keep_the_area():
    """A 3x1 strip of quads in a 3x1 rectangle with the two middle bottom vertices crowded
    to one end: sliding spreads them back, they stay on the bottom side in order, and the
    covered area stays the rectangle's."""
    mesh, lattice = grid(3, 1)
    loop = mesh.boundary
    pts = lattice[loop]
    bxy = pts.copy()
    j1, j2 = [int(np.flatnonzero((pts == p).all(axis=1))[0]) for p in ([1.0, 0.0], [2.0, 0.0])]
    ja, jb = [int(np.flatnonzero((pts == p).all(axis=1))[0]) for p in ([0.0, 0.0], [3.0, 0.0])]
    bxy[j1], bxy[j2] = [2.6, 0.0], [2.8, 0.0]
    t = arc_lengths(pts)[:-1]
    al = np.arange(len(loop))
    fixed = place(pts, t, al, mesh, boundary_xy=bxy)
    slid = place(pts, t, al, mesh, boundary_xy=bxy, slide_groups=((ja, jb, [j1, j2]),))
    assert slid.slid and not fixed.slid
    assert slid.min_scaled_jacobian > fixed.min_scaled_jacobian + 0.1
    y = slid.xy[loop[[j1, j2]]]
    assert np.all(y[:, 1] == 0.0) and 0 < y[0, 0] < y[1, 0] < 3
    assert slid.mesh_area == pytest.approx(3.0, abs=1e-12) and slid.inverted == 0


@pytest.mark.parametrize("w, ratio", [(1.0, 1.0), (12.9, 12.9), (0.25, 4.0)])
def test_edge_ratios_of_rectangles(w, ratio):
    xy = np.array([[0, 0], [w, 0], [w, 1], [0, 1]], float)
    np.testing.assert_allclose(edge_ratios(xy, np.array([[0, 1, 2, 3]])), [ratio])
    assert edge_ratios(np.array([[0, 0], [1, 0], [1, 0], [0, 1]], float), np.array([[0, 1, 2, 3]]))[0] == np.inf


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 12), P=st.integers(3, 40))
def test_boundary_paths_are_the_sub_polylines(seed, n, P):
    """All pieces at once give exactly what cutting one piece at a time does."""
    from jaxmatch.geometry import sub_polyline

    rng = np.random.default_rng(seed)
    ang = np.sort(rng.uniform(0, 2 * np.pi, P))
    pts = np.c_[np.cos(ang), np.sin(ang)] * rng.uniform(0.5, 1.5, (P, 1))
    cum = arc_lengths(pts)
    t = np.sort(rng.uniform(0, cum[-1], n))
    if n > 2:
        t[1] = cum[int(rng.integers(0, P))]  # a piece starting exactly at a polyline vertex
        t = np.sort(t)
    got = boundary_paths(pts, t)
    for j in range(n):
        a, b = t[j], t[(j + 1) % n]
        want = sub_polyline(pts, a, b if b > a else b + cum[-1], cum)
        np.testing.assert_array_equal(got[j], want)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 12), P=st.integers(3, 40), at_vertices=st.booleans())
def test_exact_paths_are_the_boundary_paths_with_given_ends(seed, n, P, at_vertices):
    """:func:`exact_paths` (every path gathered at once, ends never computed) gives bit for bit
    the pieces of :func:`boundary_paths` with their ends replaced by the vertex positions, also
    for parameters on polyline vertices (which a piece must not repeat) and one-vertex loops."""
    from jaxmatch.placement.embed import exact_paths

    rng = np.random.default_rng(seed)
    ang = np.sort(rng.uniform(0, 2 * np.pi, P))
    pts = np.c_[np.cos(ang), np.sin(ang)] * rng.uniform(0.5, 1.5, (P, 1))
    cum = arc_lengths(pts)
    t = np.unique(rng.choice(cum[:-1], min(n, P), replace=False) if at_vertices else rng.uniform(0, cum[-1], n))
    bxy = rng.normal(size=(t.shape[0], 2))
    want = [p.copy() for p in boundary_paths(pts, t, cum)]
    for j, p in enumerate(want):
        p[0], p[-1] = bxy[j], bxy[(j + 1) % len(want)]
    for cum_given in (cum, None):
        got = exact_paths(pts, t, bxy, cum_given)
        assert len(got) == len(want)
        for g, w in zip(got, want):
            assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), F=st.integers(0, 30), degenerate=st.booleans())
def test_placement_measures_are_quality_and_edge_ratios(seed, F, degenerate):
    """:func:`placement_measures` (one set of edge lengths for the scaled Jacobian and the edge
    ratios) gives bit for bit :func:`quality_inverted` and :func:`edge_ratios`, also for folded
    quads and quads with a repeated vertex (zero-length edges: ratio inf, scaled Jacobian 0)."""
    rng = np.random.default_rng(seed)
    xy = rng.normal(size=(12, 2)) * rng.uniform(1e-3, 1e3)
    quads = rng.integers(0, 12 if not degenerate else 5, size=(F, 4))
    got = placement_measures(xy, quads)
    want = (*quality_inverted(xy, quads), edge_ratios(xy, quads))
    assert len(got) == 5
    for g, w in zip(got, want):
        assert g.dtype == w.dtype and g.shape == w.shape and g.tobytes() == w.tobytes()


def test_sj_inverted_refuses_vertex_ids_out_of_range():
    """A quad naming a vertex that does not exist is an IndexError (numpy's), not a read past the array."""
    xy = np.zeros((4, 2))
    with pytest.raises(IndexError):
        sj_inverted(xy, np.array([[0, 1, 2, 4]]))
