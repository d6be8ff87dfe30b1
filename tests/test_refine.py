"""Refinement of templates by chord multiplicities (``jaxmatch.placement.refine``, ``mesh --sides/--size``).

Specification checked here, each against an independent reference:

* chords equal those found by walking strips quad by quad (plain Python);
* the refined topology is a valid quad mesh of a disk with ``sum ma * mb`` quads and no new
  irregular vertex;
* the integer program says "feasible" exactly when brute-force enumeration of the
  multiplicities reaches the counts, and its solutions meet them exactly;
* requests: feasible ones are met exactly (counts per side, corners on input corners,
  boundary vertices on the input boundary, no fold); infeasible ones raise an error naming
  the sides and the nearest feasible counts;
* ``size``: mean edge length within 20 %, min scaled Jacobian >= 0.3, no inverted quad, boundary
  vertices on the input boundary (point-to-segment distances computed here);
* two squares sharing a side get bit-identical vertices on it.
"""

from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.catalogue.mesh import QuadMesh, edges, from_quads, valences, validate
from jaxmatch.errors import EXIT_BAD_INPUT, InputError
from jaxmatch.cache import Cache
from jaxmatch.defaults import Quality
from jaxmatch.placement import refine as R
from jaxmatch.placement import templates as T
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.io.readers import load_shape
from jaxmatch.shape import make_shape

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
LABELLED = EXAMPLES / "labels" / "shapes"
_TEMPLATES: dict = {}


@pytest.fixture(scope="module")
def lat():
    return load_lattice("fine")


@pytest.fixture(scope="module")
def templates(cat, lat):
    """``templates(path) -> (shape, [PatchTemplate])``, computed once per shape (limit 4 per size)."""

    def get(path):
        path = Path(path)
        if path not in _TEMPLATES:
            shp = load_shape(path)
            _TEMPLATES[path] = (shp, T.patch_templates(shp, cat, lat, limit=4))
        return _TEMPLATES[path]

    return get


# ---------------------------------------------------------------------------------------------
# independent references


def strips(quads) -> set[frozenset]:
    """Chords by walking: from an edge, through each quad holding it, to the opposite edge."""
    q = np.asarray(quads).tolist()
    holders: dict[tuple, list] = {}
    for f, quad in enumerate(q):
        for k in range(4):
            e = tuple(sorted((quad[k], quad[(k + 1) % 4])))
            holders.setdefault(e, []).append((f, k))
    seen, out = set(), set()
    for e0 in holders:
        if e0 in seen:
            continue
        chord, todo = set(), [e0]
        while todo:
            e = todo.pop()
            if e in chord:
                continue
            chord.add(e)
            for f, k in holders[e]:
                quad = q[f]
                todo.append(tuple(sorted((quad[(k + 2) % 4], quad[(k + 3) % 4]))))
        seen |= chord
        out.add(frozenset(chord))
    return out


def reachable(A: np.ndarray, cap: int) -> set[tuple]:
    """Every count vector ``A @ m`` with integer ``m >= 1`` and all counts <= cap (enumeration)."""
    n, C = A.shape
    states = {tuple([0] * n)}
    for c in range(C):
        col = A[:, c]
        if not col.any():
            continue
        nxt = set()
        for s in states:
            for k in range(1, cap + 1):
                v = tuple(int(a + k * b) for a, b in zip(s, col))
                if max(v) > cap:
                    break
                nxt.add(v)
        states = nxt
    return states


def boundary_distance(points_xy, loop_xy) -> np.ndarray:
    """Distance of each point ``(k, 2)`` to the closed polyline ``loop_xy (P, 2)``."""
    a = np.asarray(loop_xy, float)
    b = np.roll(a, -1, axis=0)
    p = np.asarray(points_xy, float)[:, None, :]
    d = b - a
    t = np.clip(np.sum((p - a) * d, axis=-1) / np.sum(d * d, axis=-1), 0.0, 1.0)
    return np.min(np.linalg.norm(p - (a + t[..., None] * d), axis=-1), axis=1)


def check_refined(rm: R.RefinedMesh, shape) -> None:
    """What every refined mesh must satisfy, measured independently of the code under test."""
    user = shape.input_points
    diam = float(np.ptp(user, axis=0).max())
    loop = from_quads(rm.quads).boundary  # the boundary as found from the quads
    assert sorted(loop.tolist()) == sorted(rm.boundary.tolist())
    assert boundary_distance(rm.xy[rm.boundary], user).max() <= 1e-9 * diam
    for i, sv in enumerate(rm.side_vertices):
        assert sv.shape[0] == rm.counts[i] + 1
    polys = R.side_polylines(shape)
    for sv, poly in zip(rm.side_vertices, polys):  # corners exactly on the input corners
        assert np.array_equal(rm.xy[sv[0]], poly[0]) and np.array_equal(rm.xy[sv[-1]], poly[-1])
    area = 0.5 * abs(np.sum(user[:, 0] * np.roll(user[:, 1], -1) - np.roll(user[:, 0], -1) * user[:, 1]))
    p = rm.xy[rm.quads]
    qa = 0.5 * np.sum(p[..., 0] * np.roll(p[..., 1], -1, axis=1) - np.roll(p[..., 0], -1, axis=1) * p[..., 1], axis=1)
    assert rm.area_ratio == pytest.approx(qa.sum() / area)
    assert validate(QuadMesh(rm.quads.astype(np.int32), rm.boundary.astype(np.int32)), invariant_i=False) == []


# ---------------------------------------------------------------------------------------------
# sides


@settings(max_examples=60)
@given(st.lists(st.floats(-1e3, 1e3, allow_nan=False, width=64), min_size=4, max_size=4), st.integers(1, 60))
def test_straight_side_points_do_not_depend_on_direction(xy, count):
    a, b = np.array(xy[:2]), np.array(xy[2:])
    if np.array_equal(a, b):
        return
    fwd = R.side_points(np.stack([a, b]), count)
    back = R.side_points(np.stack([b, a]), count)
    assert np.array_equal(fwd, back[::-1])  # bit-identical
    assert np.array_equal(fwd[0], a) and np.array_equal(fwd[-1], b)
    gaps = np.linalg.norm(np.diff(fwd, axis=0), axis=1)
    assert np.allclose(gaps, np.linalg.norm(b - a) / count, rtol=1e-9, atol=1e-9)


@settings(max_examples=40)
@given(st.integers(3, 8), st.integers(1, 40), st.integers(0, 2**31))
def test_curved_side_points_lie_on_the_polyline_evenly(k, count, seed):
    rng = np.random.default_rng(seed)
    poly = np.cumsum(rng.uniform(0.1, 1.0, (k, 2)) * [1, 1], axis=0)
    pts = R.side_points(poly, count)
    seg_a, seg_b = poly[:-1], poly[1:]
    d = seg_b - seg_a
    t = np.clip(np.sum((pts[:, None] - seg_a) * d, -1) / np.sum(d * d, -1), 0, 1)
    dist = np.linalg.norm(pts[:, None] - (seg_a + t[..., None] * d), axis=-1).min(axis=1)
    assert dist.max() <= 1e-12 * np.abs(poly).max()
    # arc-length parameter of each point: equal steps
    cum = np.concatenate([[0], np.cumsum(np.linalg.norm(d, axis=1))])
    j = np.argmin(np.linalg.norm(pts[:, None] - (seg_a + t[..., None] * d), axis=-1), axis=1)
    s = cum[j] + t[np.arange(len(j)), j] * np.linalg.norm(d[j], axis=1)
    assert np.allclose(np.diff(s), cum[-1] / count, rtol=1e-9, atol=1e-12)
    assert np.array_equal(pts[0], poly[0]) and np.array_equal(pts[-1], poly[-1])


@pytest.mark.parametrize("clockwise", [False, True])
@pytest.mark.parametrize("explicit", [None, [2, 3, 0, 1]])
def test_sides_follow_the_users_corners(clockwise, explicit):
    pts = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]
    if clockwise:
        pts = [pts[0], pts[3], pts[2], pts[1]]
    shp = make_shape(pts, explicit)
    order = explicit if explicit is not None else [0, 1, 2, 3]
    polys = R.side_polylines(shp)
    for i, poly in enumerate(polys):
        assert np.array_equal(poly[0], pts[order[i]]) and np.array_equal(poly[-1], pts[order[(i + 1) % 4]])
    assert np.allclose(R.side_lengths(shp), [np.linalg.norm(np.subtract(pts[order[(i + 1) % 4]], pts[order[i]]))
                                           for i in range(4)])


def test_corners_out_of_boundary_order_are_refused():
    shp = make_shape([[0, 0], [2, 0], [2, 1], [0, 1]], [0, 2, 1, 3], source="s.json")
    with pytest.raises(InputError, match="s.json: corners are not listed in boundary order"):
        R.side_polylines(shp)


# ---------------------------------------------------------------------------------------------
# chords and refinement topology


def _sample_meshes(cat, per_k=4):
    out = []
    for b in cat.buckets(None):
        for k, mid in zip(b.k.tolist(), b.ids.tolist()):
            if k <= 2 or len([1 for kk, _ in out if kk == k]) < per_k:
                out.append((k, str(mid)))
    return [mid for _, mid in out]


def test_chords_equal_walked_strips(cat):
    for mid in _sample_meshes(cat):
        mesh = cat.mesh(mid)
        loop = mesh.boundary.tolist()
        first = list(zip(loop, loop[1:] + loop[:1]))
        e, chord, qc, nc = T._chords(mesh.quads, mesh.boundary, first)
        mine = {frozenset(tuple(x) for x in e[chord == c].tolist()) for c in range(nc)}
        assert mine == strips(mesh.quads), mid
        # quad_chords: chord of edges 0/2 and 1/3
        q = np.asarray(mesh.quads)
        key = {tuple(x): c for x, c in zip(e.tolist(), chord.tolist())}
        for f, quad in enumerate(q.tolist()):
            for k in range(4):
                assert key[tuple(sorted((quad[k], quad[(k + 1) % 4])))] == qc[f, k % 2]
        # chords numbered by first boundary edge along the sides; every open chord has two ends
        bch = [key[tuple(sorted(x))] for x in first]
        assert [c for i, c in enumerate(bch) if c not in bch[:i]] == list(range(len(set(bch))))
        assert all(bch.count(c) == 2 for c in set(bch))


@given(st.integers(1, 40).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=80))))
def test_components_are_the_connected_components_of_a_plain_search(case):
    """The union-find of ``_chords`` against a breadth-first search written here: the same
    partition, each component named by its smallest node."""
    n, pairs = case
    a = np.array([p[0] for p in pairs], np.int64)
    b = np.array([p[1] for p in pairs], np.int64)
    nbr = {i: set() for i in range(n)}
    for x, y in pairs:
        nbr[x].add(y)
        nbr[y].add(x)
    want = [-1] * n
    for s in range(n):  # s is the smallest node of the component it finds first
        if want[s] < 0:
            want[s], todo = s, [s]
            while todo:
                for y in nbr[todo.pop()]:
                    if want[y] < 0:
                        want[y] = s
                        todo.append(y)
    got = T._components(n, a, b)
    assert got.dtype == np.int64 and got.tolist() == want


@settings(max_examples=30)
@given(st.data())
def test_refined_topology_is_a_disk_without_new_irregular_vertices(cat, data):
    ids = _sample_meshes(cat, per_k=3)
    mid = data.draw(st.sampled_from(ids))
    mesh = cat.mesh(mid)
    loop = mesh.boundary.tolist()
    e, chord, qc, nc = T._chords(mesh.quads, mesh.boundary, list(zip(loop, loop[1:] + loop[:1])))
    mult = np.array(data.draw(st.lists(st.integers(1, 4), min_size=nc, max_size=nc)), np.int64)
    nv, quads, along, W, VV = R._refine_topology(np.asarray(mesh.quads, np.int64), e, chord, qc, mult)
    assert quads.shape[0] == int(np.sum(mult[qc[:, 0]] * mult[qc[:, 1]]))
    assert quads.max() + 1 == nv
    fine = from_quads(quads)
    assert validate(fine, invariant_i=False) == []
    bnd_old = set(loop)
    assert fine.n_boundary == sum(int(mult[c]) for c in [chord[np.flatnonzero((e[:, 0] == min(a, b)) & (e[:, 1] == max(a, b)))[0]]
                                                         for a, b in zip(loop, loop[1:] + loop[:1])])
    val_old, val_new = valences(mesh.quads), valences(quads)
    internal_new = np.setdiff1d(np.arange(nv), fine.boundary)
    irregular_new = {int(v) for v in internal_new if val_new[v] != 4}
    irregular_old = {v for v in range(mesh.n_vertices) if v not in bnd_old and val_old[v] != 4}
    assert irregular_new == irregular_old
    assert np.allclose(W.sum(axis=1), 1.0)


@settings(max_examples=20, deadline=None)
@given(st.sampled_from(["square.json", "triangle.json", "hexagon.json"]), st.integers(0, 3), st.data())
def test_refined_side_vertices_step_each_template_edge(templates, name, j, data):
    """The refined vertices of every template side (all sides made at once) are, side by side,
    each template edge of its path stepped from its first end (``along``, edge by edge here),
    then the side's last template vertex; ``counts[i] + 1`` of them."""
    shp, ts = templates(EXAMPLES / name)
    t = ts[min(j, len(ts) - 1)]
    m = np.array(data.draw(st.lists(st.integers(1, 4), min_size=t.n_chords, max_size=t.n_chords)), np.int64)
    tq = np.asarray(t.placement.mesh.quads, np.int64)
    _, _, along, _, _ = R._refine_topology(tq, t.edge_list, t.edge_chord, t.quad_chords, m)
    *_, side_vertices = R._refined_topology(tq, t, m)
    assert len(side_vertices) == len(t.side_path)
    for path, sv, c in zip(t.side_path, side_vertices, t.side_matrix() @ m):
        want = []
        for a, b in zip(path[:-1], path[1:]):
            e = next(i for i, (u, w) in enumerate(t.edge_list.tolist()) if (u, w) == (min(a, b), max(a, b)))
            me = int(m[t.edge_chord[e]])
            want += [int(along(np.int64(a), np.int64(b), k, me)) for k in range(me)]
        want.append(int(path[-1]))
        assert sv.dtype == np.int64 and sv.tolist() == want and sv.size == c + 1


# ---------------------------------------------------------------------------------------------
# integer programs


@pytest.mark.parametrize("name", ["square.json", "triangle.json", "lshape.json", "plus.json"])
def test_side_matrix_counts_each_sides_edges_per_chord(templates, name):
    """``A[i, c]``: the number of side ``i``'s edges on chord ``c``, counted here edge by edge."""
    _, ts = templates(EXAMPLES / name)
    assert ts
    for t in ts:
        A = t.side_matrix()
        plain = np.zeros((len(t.side_chords), t.n_chords), np.int64)
        for i, ch in enumerate(t.side_chords):
            for c in np.asarray(ch).tolist():
                plain[i, c] += 1
        assert A.dtype == np.int64 and A.shape == plain.shape and np.array_equal(A, plain)
        assert A.sum() == sum(len(ch) for ch in t.side_chords)


@pytest.mark.parametrize("counted", [True, False])  # counted out, or the integer program
@pytest.mark.parametrize("name, cap", [("square.json", 4), ("triangle.json", 6)])
def test_milp_feasibility_equals_enumeration(templates, name, cap, counted, monkeypatch):
    if not counted:
        monkeypatch.setattr(R, "reachable_cols", lambda cols, t: None)
    shp, ts = templates(EXAMPLES / name)
    n = max(shp.n_corners, 1)
    for t in ts[:5]:
        A = t.side_matrix()
        reach = reachable(A, cap)
        for c in itertools.product(range(1, cap + 1), repeat=n):
            ok = R.feasible(t, c)
            assert ok == (c in reach), (t.mesh_id, c)
            if t is ts[0]:  # the nearest feasible counts are the counts themselves exactly when feasible
                assert np.array_equal(R.nearest_counts(t, c), c) == ok, (t.mesh_id, c)
            if ok:
                m = R.solve_multiplicities(t, counts=c)
                assert m.min() >= 1 and np.array_equal(A @ m, c)


def test_infeasible_request_names_sides_and_nearest(templates):
    shp, ts = templates(EXAMPLES / "square.json")
    t = next(t for t in ts if t.side_matrix().sum(axis=1).min() >= 2)
    low = t.side_matrix().sum(axis=1)
    with pytest.raises(R.InfeasibleRequest) as err:  # odd total
        R.solve_multiplicities(t, counts=[int(low[0]) + 1, *low[1:].tolist()])
    msg = str(err.value)
    assert "odd" in msg and "nearest feasible counts" in msg and msg.count("\n") == 0
    assert sum(err.value.nearest) % 2 == 0 and R.feasible(t, err.value.nearest)
    with pytest.raises(R.InfeasibleRequest) as err:  # too coarse
        R.solve_multiplicities(t, counts=[1, 1, 1, 1])
    assert f"side 0 needs at least {low[0]} edges" in str(err.value)
    near = np.array(err.value.nearest)
    assert R.feasible(t, near) and np.all(near >= low)
    with pytest.raises(InputError, match="expected one count per side"):
        R.solve_multiplicities(t, counts=[2, 2])


# ---------------------------------------------------------------------------------------------
# requests on the examples and labelled shapes

SIDES_SHAPES = [EXAMPLES / "triangle.json", EXAMPLES / "square.json", LABELLED / "pentagon.json",
                EXAMPLES / "hexagon.json", LABELLED / "lshape.json", LABELLED / "arch.json",
                LABELLED / "disk.json", LABELLED / "trapezoid.json"]


@pytest.mark.slow
@pytest.mark.parametrize("path", SIDES_SHAPES, ids=lambda p: p.name)
def test_sampled_side_requests_are_met_exactly_or_refused(templates, path):
    shp, ts = templates(path)
    n = max(shp.n_corners, 1)
    union = set().union(*(reachable(t.side_matrix(), 8) for t in ts))
    rng = np.random.default_rng(len(path.name))
    feas = sorted(union)
    picks = [feas[i] for i in rng.choice(len(feas), size=min(3, len(feas)), replace=False)]
    picks += [tuple(int(x) for x in rng.integers(1, 9, n)) for _ in range(3)]
    for c in picks:
        if c in union:
            ch = R.refine_mesh(shp, sides=list(c), templates=ts)
            assert tuple(ch.mesh.counts.tolist()) == c
            assert ch.mesh.inverted == 0
            check_refined(ch.mesh, shp)
            quiet = R.refine_mesh(shp, sides=list(c), templates=ts, explain=False)  # the same mesh, unexplained
            assert quiet.template.mesh_id == ch.template.mesh_id and np.array_equal(quiet.mesh.xy, ch.mesh.xy)
        else:
            with pytest.raises(R.InfeasibleRequest, match="nearest feasible counts") as err:
                R.refine_mesh(shp, sides=list(c), templates=ts)
            assert err.value.nearest in union
            with pytest.raises(R.InfeasibleRequest, match="cannot be met by any of the"):
                R.refine_mesh(shp, sides=list(c), templates=ts, explain=False)


SIZE_SHAPES = sorted(EXAMPLES.glob("*.json")) + [EXAMPLES / "lshape.txt"]


@pytest.mark.slow
@pytest.mark.parametrize("path", SIZE_SHAPES, ids=lambda p: p.name)
def test_size_requests_on_every_example(templates, path):
    shp, ts = templates(path)
    perimeter = float(R.side_lengths(shp).sum())
    for parts in (16, 32, 64):
        h = perimeter / parts
        ch = R.refine_mesh(shp, size=h, templates=ts)
        rm = ch.mesh
        e = edges(rm.quads)
        mean = float(np.linalg.norm(rm.xy[e[:, 0]] - rm.xy[e[:, 1]], axis=1).mean())
        assert abs(mean / h - 1) <= 0.2, (parts, mean / h)
        assert rm.inverted == 0 and rm.min_scaled_jacobian >= 0.3
        check_refined(rm, shp)


def test_two_squares_sharing_a_side_get_identical_vertices(cat, lat):
    left = make_shape([[0.1, 0.3], [0.7, 0.3], [0.7, 0.9], [0.1, 0.9]])
    right = make_shape([[0.7, 0.3], [1.3, 0.3], [1.3, 0.9], [0.7, 0.9]])
    a = R.refine_mesh(left, cat, lat, sides=[2, 5, 2, 5], limit=3).mesh
    b = R.refine_mesh(right, cat, lat, sides=[4, 5, 4, 5], limit=3).mesh
    shared_a = a.xy[a.side_vertices[1]]  # (0.7, 0.3) -> (0.7, 0.9)
    shared_b = b.xy[b.side_vertices[3]]  # (0.7, 0.9) -> (0.7, 0.3)
    assert np.array_equal(shared_a, shared_b[::-1])
    assert np.allclose(np.diff(shared_a[:, 1]), 0.6 / 5)


def test_clockwise_file_counts_follow_the_users_sides(cat, lat):
    pts = [[0.0, 0.0], [0.0, 1.0], [2.0, 1.0], [2.0, 0.0]]  # clockwise: sides 1, 2, 1, 2 long
    shp = make_shape(pts)
    rm = R.refine_mesh(shp, cat, lat, sides=[2, 4, 2, 4], limit=2).mesh
    assert rm.counts.tolist() == [2, 4, 2, 4]
    for i, sv in enumerate(rm.side_vertices):
        assert np.array_equal(rm.xy[sv[0]], pts[i]) and np.array_equal(rm.xy[sv[-1]], pts[(i + 1) % 4])
        assert np.allclose(np.linalg.norm(np.diff(rm.xy[sv], axis=0), axis=1), 0.5)
    check_refined(rm, shp)


def test_refine_and_place_counts_and_json(templates):
    shp, ts = templates(EXAMPLES / "square.json")
    t = ts[0]
    m = np.arange(1, t.n_chords + 1) % 3 + 1
    rm = R.refine_and_place(t, m)
    assert np.array_equal(rm.counts, t.side_matrix() @ m) and np.array_equal(rm.mult, m)
    check_refined(rm, shp)
    d = R.refined_json(R.RefineChoice(rm, t, []))
    assert d["sides"] == rm.counts.tolist() and d["quads"] == rm.n_quads
    assert [c["multiplicity"] for c in d["chords"]] == m.tolist()
    with pytest.raises(ValueError):
        R.refine_and_place(t, np.zeros(t.n_chords, np.int64))


# ---------------------------------------------------------------------------------------------
# command line




def test_cli_mesh_sides_json_and_errors(cli, tmp_path):
    out = tmp_path / "m.vtk"
    code, stdout, err = cli("mesh", EXAMPLES / "square.json", "--sides", "4,2,4,2", "--json", "--out", out)
    assert code == 0, err
    d = json.loads(stdout)
    assert d["sides"] == [4, 2, 4, 2] and d["inverted"] == 0 and out.exists()
    assert sorted(d["side_counts"].values()) == [2, 2, 4, 4] and d["quads"] == 8
    for args, words in ((["--sides", "1,2,1,1"], ["--sides", "odd", "nearest feasible counts"]),
                        (["--sides", "4,2"], ["--sides", "one count per side (4 sides)"]),
                        (["--sides", "4,x,4,2"], ["--sides", "comma-separated"]),
                        (["--size", "0"], ["--size", "positive"]),
                        (["--sides", "4,2,4,2", "--size", "1"], ["either --sides or --size"])):
        code, stdout, err = cli("mesh", EXAMPLES / "square.json", *args, "--out", tmp_path / "bad.vtk")
        assert code == EXIT_BAD_INPUT, args
        line = err.strip()
        assert "\n" not in line and "Traceback" not in line and all(w in line for w in words), line
        assert not (tmp_path / "bad.vtk").exists()


def test_cli_annotate_lists_sides(cli):
    code, stdout, _ = cli("annotate", EXAMPLES / "lshape.json", "--json")
    assert code == 0
    sides = json.loads(stdout)["sides"]
    assert [s["length"] for s in sides] == pytest.approx([2, 1, 1, 1, 1, 2])
    code, stdout, _ = cli("annotate", EXAMPLES / "lshape.json")
    assert "mesh --sides" in stdout


# ---------------------------------------------------------------------------------------------
# large meshes (issue 22): the fast paths against the plain ones, measured independently


def _grid(n: int):
    """An n x n grid of unit quads, ``(xy (V, 2), quads (Q, 4) int64 ccw, boundary ids)``."""
    ids = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([ids[:-1, :-1], ids[1:, :-1], ids[1:, 1:], ids[:-1, 1:]], -1).reshape(-1, 4)
    xy = np.stack(np.meshgrid(np.arange(n + 1.0), np.arange(n + 1.0), indexing="ij"), -1).reshape(-1, 2)
    return xy, quads, np.unique(np.concatenate([ids[0], ids[-1], ids[:, 0], ids[:, -1]]))


def _folded(xy, quads):
    """``(Q,) bool``: a corner whose two edges turn the wrong way (cross product <= 0)."""
    p = xy[quads]
    a, b = np.roll(p, -1, axis=1) - p, np.roll(p, 1, axis=1) - p
    return (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0] <= 0).any(axis=1)


def _signed_areas(xy, quads):
    p = xy[quads]
    return 0.5 * np.sum(p[..., 0] * np.roll(p[..., 1], -1, axis=1) - np.roll(p[..., 0], -1, axis=1) * p[..., 1], axis=1)


@pytest.mark.parametrize("seed", [0, 1])
def test_edges_and_boundary_edges_equal_the_unique_reference(seed):
    from jaxmatch.catalogue.mesh import boundary_edges

    _, quads, _ = _grid(7)
    quads = np.random.default_rng(seed).permutation(quads.max() + 1)[quads]  # any vertex numbering
    d = np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2)
    ref = np.unique(np.sort(d, axis=1), axis=0)
    assert np.array_equal(edges(quads), ref)
    _, inv, cnt = np.unique(np.sort(d, axis=1), axis=0, return_inverse=True, return_counts=True)
    assert np.array_equal(boundary_edges(quads), d[cnt[inv.ravel()] == 1])
    assert boundary_edges(np.zeros((0, 4), np.int64)).shape == (0, 2)


def test_smooth_near_unfolds_locally_and_keeps_the_rest():
    from jaxmatch.placement.embed import smooth_in_frame, smooth_near

    xy, quads, boundary = _grid(24)
    folded = xy.copy()
    v = 5 * 25 + 5  # an inner vertex pushed over its neighbour: folded quads around it
    folded[v] += [1.6, 0.3]
    inv = _folded(folded, quads)
    assert inv.any()
    out = smooth_near(folded, quads, quads[inv].ravel(), boundary, rings=3, frame=folded[boundary], iters=50)
    assert not _folded(out, quads).any()
    assert np.array_equal(out[boundary], folded[boundary])
    assert _signed_areas(out, quads).sum() == pytest.approx(24.0 * 24.0)  # the region is kept
    far = np.linalg.norm(xy - xy[v], axis=1) > 8  # beyond the rings (and their quads): untouched
    assert np.array_equal(out[far], folded[far])
    # rings that reach every vertex: the plain whole-mesh smoothing, to the last bit
    whole = smooth_near(folded, quads, quads[inv].ravel(), boundary, rings=60, frame=folded[boundary], iters=50)
    assert np.array_equal(whole, smooth_in_frame(folded, quads, boundary, frame=folded[boundary], iters=50))


@pytest.mark.parametrize("solver", ["qdldl", "superlu"])
def test_harmonic_solve_is_spsolve_and_keeps_one_factor(monkeypatch, solver):
    """The large meshes' solve (a kept LDL^T or SuperLU factor and Laplacian) against the plain
    spsolve on a small grid Laplacian; a second call on the same topology reuses them, another
    topology replaces them."""
    import scipy.sparse.linalg

    if solver == "qdldl":
        pytest.importorskip("qdldl")
    else:
        monkeypatch.setattr(R, "_large_solver", R._SuperLU)
    cache = Cache()
    rng = np.random.default_rng(0)

    def case(k):
        xy, quads, boundary = _grid(k)
        nv = xy.shape[0]
        free = np.setdiff1d(np.arange(nv), boundary)
        disp = np.zeros((nv, 2))
        disp[boundary] = rng.normal(size=(boundary.size, 2))
        L = R._laplacian(quads, nv)
        want = scipy.sparse.linalg.spsolve(L[free][:, free].tocsc(), -(L[free][:, boundary] @ disp[boundary]))
        return quads, nv, free, disp, want

    quads, nv, free, disp, want = case(12)
    x = R._harmonic_solve(quads, nv, free, disp, cache)
    assert x.shape == (free.size, 2)
    np.testing.assert_allclose(x, want, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(R._harmonic_solve(quads, nv, free, disp), x)  # no cache: the plain path
    assert cache.size("factors") == 1
    (k,) = cache._stores["factors"]
    kept = cache.lookup("factors", k)
    np.testing.assert_array_equal(R._harmonic_solve(quads, nv, free, disp, cache), x)
    assert cache.lookup("factors", k) is kept  # the same topology: the kept factor
    quads2, nv2, free2, disp2, want2 = case(10)
    np.testing.assert_allclose(R._harmonic_solve(quads2, nv2, free2, disp2, cache), want2, rtol=0, atol=1e-12)
    assert cache.size("factors") == cache.sizes.factors == 1 and cache.lookup("factors", k) is None


@pytest.mark.parametrize("k", [2, 5, 12, 17])
def test_harmonic_displacement_dense_path_is_the_sparse_one(monkeypatch, k):
    """Up to DENSE_TUTTE free vertices the extension is the dense compiled Tutte solve (no
    scipy.sparse): the sparse solve's values to round-off (DENSE_TUTTE forced to 0 for that)."""
    xy, quads, boundary = _grid(k)
    bdisp = np.random.default_rng(k).normal(size=(boundary.size, 2))
    dense = R.harmonic_displacement(quads, xy.shape[0], boundary, bdisp)
    assert (k - 1) ** 2 <= R.DENSE_TUTTE
    monkeypatch.setattr(R, "DENSE_TUTTE", 0)
    sparse = R.harmonic_displacement(quads, xy.shape[0], boundary, bdisp)
    np.testing.assert_array_equal(dense[boundary], bdisp)
    np.testing.assert_allclose(dense, sparse, rtol=0, atol=1e-12)


def test_harmonic_displacement_large_path_is_the_plain_one(monkeypatch):
    """Above SMOOTH_LOCAL quads (forced) the harmonic extension (kept factor, rhs from the whole
    Laplacian) equals the plain spsolve path to round-off."""
    xy, quads, boundary = _grid(9)
    bdisp = np.random.default_rng(1).normal(size=(boundary.size, 2))
    monkeypatch.setattr(R, "DENSE_TUTTE", 0)  # the sparse solve up to SMOOTH_LOCAL quads
    plain = R.harmonic_displacement(quads, xy.shape[0], boundary, bdisp)
    monkeypatch.setattr(R, "SMOOTH_LOCAL", 0)
    np.testing.assert_allclose(R.harmonic_displacement(quads, xy.shape[0], boundary, bdisp, cache=Cache()), plain,
                               rtol=0, atol=1e-12)


def test_large_mesh_paths_keep_the_refined_mesh_valid(templates, monkeypatch):
    """The paths above SMOOTH_ALWAYS / SMOOTH_LOCAL quads, forced on a small refinement: the
    solve's other ordering gives the same placement to round-off, the local smoothing a valid
    mesh of the shape (check_refined: boundary, corners, area)."""
    shp, ts = templates(EXAMPLES / "lshape.json")
    t = ts[0]
    m = np.full(t.n_chords, 4, np.int64)
    plain = R._refine_and_place(t, m)
    monkeypatch.setattr(R, "SMOOTH_ALWAYS", 0)
    monkeypatch.setattr(R, "SMOOTH_LOCAL", 0)
    every_bad = Quality(good_sj=2.0)  # every quad "bad": the local smoothing runs
    a = R._refine_and_place(t, m, quality=every_bad)
    monkeypatch.setattr(R, "LARGE_ORDERING", "COLAMD")
    b = R._refine_and_place(t, m, quality=every_bad)
    assert np.allclose(a.xy, b.xy, rtol=0, atol=1e-9)
    check_refined(a, shp)
    assert a.inverted == 0 and plain.inverted == 0


@pytest.mark.parametrize("smooth_iters, always, good_sj", [(None, R.SMOOTH_ALWAYS, 0.3), (0, R.SMOOTH_ALWAYS, 0.3),
                                                           (5, R.SMOOTH_ALWAYS, 0.3), (None, 0, 0.0), (None, 0, 2.0)])
def test_refined_figures_are_those_of_the_final_positions(templates, monkeypatch, smooth_iters, always, good_sj):
    """Whichever way a refinement is smoothed (always, never, only when a quad is bad: above
    SMOOTH_ALWAYS, forced here), its scaled Jacobians and inverted count are those of the positions
    it returns (measured again here), and its side counts the side matrix's."""
    shp, ts = templates(EXAMPLES / "lshape.json")
    t = ts[0]
    m = np.full(t.n_chords, 3, np.int64)
    monkeypatch.setattr(R, "SMOOTH_ALWAYS", always)
    rm = R._refine_and_place(t, m, smooth_iters=smooth_iters, quality=Quality(good_sj=good_sj))
    sj, inv = R.sj_inverted(rm.xy, rm.quads)
    assert np.array_equal(rm.scaled_jacobian, sj) and rm.inverted == int(inv.sum())
    assert rm.counts.dtype == np.int64 and np.array_equal(rm.counts, t.side_matrix() @ m)
    check_refined(rm, shp)


@pytest.mark.parametrize("path", [EXAMPLES / "plus.json", LABELLED / "stairs.json", LABELLED / "ushape.json",
                                  EXAMPLES / "lshape.json"])
def test_sizes_too_short_for_the_corners_are_not_ranked_and_change_nothing(cat, lat, monkeypatch, path):
    """_iter_by_size passes over a size whose longest boundary loop is shorter than the shape's
    corners without ranking it; the templates it makes (ids, orientations, ranks) are those of
    the walk that ranks every size."""
    shp = load_shape(path)
    ks = (0, 1, 2, 3)

    def walk():
        cat.cache.clear()
        return [(t.mesh_id, t.match.rotation, t.match.reflected, t.rank)
                for t in T._iter_by_size(shp, cat, lat, limit=R.DEFAULT_LIMIT, internal=ks)]

    ranked = []
    real = T._candidates
    monkeypatch.setattr(T, "_candidates", lambda *a, **k: ranked.append(k["internal"][0]) or real(*a, **k))
    fast = walk()
    short = [k for k in ks if T._longest_boundary(cat, k) < shp.n_corners]
    assert not set(short) & set(ranked)
    monkeypatch.setattr(T, "_longest_boundary", lambda c, k: 10**9)  # every size ranked
    ranked.clear()
    assert walk() == fast
    assert set(short) <= set(ranked)
    if shp.n_corners > 8:
        assert short  # the plus and the stairs: k = 0 and 1 are too short


def _refuse_some(t) -> str | None:
    """A check that refuses about two templates in three (a fixed pseudo-random choice)."""
    import zlib

    key = f"{t.mesh_id}:{t.match.rotation}:{t.match.reflected}".encode()
    return None if zlib.crc32(key) % 3 == 0 else "refused"


@pytest.mark.parametrize("limit", [1, 3, R.DEFAULT_LIMIT])
@pytest.mark.parametrize("path", [LABELLED / "trapezoid.json", LABELLED / "notched-rectangle.json",
                                  LABELLED / "quarter-disk.json", EXAMPLES / "plus.json"])
def test_checked_walk_is_the_filtered_walk_with_fewer_placements(cat, lat, monkeypatch, path, limit):
    """_iter_checked hands out exactly the templates of the whole walk (_iter_templates) that
    pass the check, in its order (ids, orientations, ranks, placements), whether the check is
    the counts' feasibility or refuses at random; it places no more candidates than the whole
    walk does, and far fewer when most are refused."""
    shp = load_shape(path)
    counts = np.maximum(np.rint(R.side_lengths(shp) / (float(R.side_lengths(shp).sum()) / 16)), 1).astype(np.int64)
    counts[0] += counts.sum() % 2
    feasible_counts = lambda t: None if R.feasible(t, counts) else "cannot meet the counts"  # noqa: E731
    placed = []
    real = T._try_candidate
    monkeypatch.setattr(T, "_try_candidate", lambda *a, **k: placed.append(1) or real(*a, **k))
    for check in (feasible_counts, _refuse_some):
        placed.clear()
        whole = list(T._iter_templates(shp, cat, lat, limit=limit))
        n_whole = len(placed)
        want = [t for t in whole if check(t) is None]
        placed.clear()
        passed: list = []
        got = list(T._iter_checked(shp, cat, lat, limit=limit, internal=None, check=check, memo=T._Memo(),
                                   passed=passed))
        assert [(t.mesh_id, t.match.rotation, t.match.reflected, t.rank) for t in got] == \
            [(t.mesh_id, t.match.rotation, t.match.reflected, t.rank) for t in want]
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a.placement.xy, b.placement.xy)
        refused = {(r, mid) for r, mid, _ in passed}
        assert {(t.rank, t.mesh_id) for t in whole if check(t) is not None} <= refused
        assert len(placed) <= n_whole
        if check is _refuse_some and len(whole) > 6:
            assert len(placed) < n_whole


def test_conforming_search_through_the_lazy_templates_is_the_plain_search(cat, lat):
    """refine_mesh given lazily placed templates (explain=False, as the pipeline's conforming
    search asks) takes the template, counts and mesh that the plain list of the same templates
    gives."""
    shp = load_shape(LABELLED / "trapezoid.json")
    h = float(R.side_lengths(shp).sum()) / 16
    counts = np.maximum(np.rint(R.side_lengths(shp) / h), 1).astype(np.int64)
    counts[0] += counts.sum() % 2
    cat.cache.clear()
    lazy = T.lazy_patch_templates(shp, cat, lat, limit=R.DEFAULT_LIMIT, by_size=False)
    a = R.refine_mesh(shp, cat, lat, sides=counts.tolist(), templates=lazy, explain=False)
    plain = T.patch_templates(shp, cat, lat, limit=R.DEFAULT_LIMIT)
    b = R.refine_mesh(shp, cat, lat, sides=counts.tolist(), templates=plain, explain=False)
    assert (a.template.mesh_id, a.template.rank) == (b.template.mesh_id, b.template.rank)
    np.testing.assert_array_equal(a.mesh.counts, b.mesh.counts)
    np.testing.assert_array_equal(a.mesh.xy, b.mesh.xy)
    cat.cache.clear()


@pytest.mark.parametrize("reflected", [False, True])
def test_kept_chord_topology_gives_the_chords_of_a_fresh_count(cat, reflected):
    """The chord topology kept on a catalogue mesh gives ``_chords`` the answer it computes
    from scratch, for every rotation and numbering order, and it cannot be written to."""
    from jaxmatch.placement.embed import oriented_boundary

    rng = np.random.default_rng(3)
    ids = [i for b in cat.buckets([0, 1, 2, 3]) for i in b.ids.tolist()]
    for mesh_id in rng.choice(ids, 12, replace=False).tolist():
        mesh = cat.mesh(mesh_id)
        for rotation in range(0, len(mesh.boundary), 3):
            om, loop = oriented_boundary(mesh, rotation, reflected)
            lp = np.asarray(loop, np.int64)
            first = [(int(a), int(b)) for a, b in zip(lp, np.roll(lp, -1))]
            first = [first[k] for k in rng.permutation(len(first))]
            fresh = T._chords(om.quads, lp, first)
            kept = T._chords(om.quads, lp, first, T._kept_topology(cat, mesh_id, reflected))
            for a, b in zip(fresh, kept):
                assert np.array_equal(a, b)
    topo = T._kept_topology(cat, ids[-1], reflected)
    with pytest.raises(ValueError):
        topo.edges[0, 0] = 0


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), share=st.floats(0.0, 1.0))
def test_chord_numbers_rank_the_first_meetings(cat, seed, share):
    """``_chord_numbers`` numbers the chords as ranking each one's first occurrence in the given
    edges followed by every edge does (``np.unique(..., return_index=True)``, written out
    here), for any subset and order of edges, also none or with repeats (closed chords and
    chords never met follow by their smallest edge)."""
    rng = np.random.default_rng(seed)
    ids = [i for b in cat.buckets([0, 1, 2, 3]) for i in b.ids.tolist()]
    topo = T._kept_topology(cat, str(rng.choice(ids)), bool(rng.integers(0, 2)))
    E = topo.edges.shape[0]
    first = rng.integers(0, E, size=int(share * E))
    order = np.concatenate([first, np.arange(E)])
    labels, at = np.unique(topo.label[order], return_index=True)
    want = np.empty(topo.n, np.int64)
    want[labels[np.argsort(at)]] = np.arange(labels.shape[0])
    got = T._chord_numbers(topo, first)
    assert got.dtype == np.int64 and got.tolist() == want[topo.label].tolist()


def test_a_size_whose_matches_a_scan_went_through_is_not_ranked_again(cat, lat, monkeypatch):
    """The Z's single patch: its k = 1 ranking holds fewer matches than the first scan asked
    for, and none of them is a template; the deeper scan would rank the same matches again
    (checked here), so the walk of sizes 0 and 1 ranks k = 1 once and ends without a template
    (the pipeline then walks sizes 2 and 3)."""
    from jaxmatch.meshing.region import canonical
    from jaxmatch.placement.decompose import single_patch
    from jaxmatch.placement.layout import patch_shapes
    from jaxmatch.shape import DEFAULT_CORNER_ANGLE

    shp = load_shape(EXAMPLES / "labels" / "shapes" / "zshape.json")
    patch = patch_shapes(single_patch(canonical(shp, 0.5, DEFAULT_CORNER_ANGLE)))[0]
    cat.cache.clear()
    first, deep = (T._candidates(patch, cat, lat, limit=s * 3, internal=[1])[1] for s in T.SCAN_PER_LIMIT)
    assert len(first) < T.SCAN_PER_LIMIT[0] * 3
    assert [first.head(i) for i in range(len(first))] == [deep.head(i) for i in range(len(deep))]
    asked = []
    real = T._candidates
    monkeypatch.setattr(T, "_candidates", lambda *a, **kw: asked.append((kw["limit"], tuple(kw["internal"]))) or real(*a, **kw))
    cat.cache.clear()
    assert list(T._iter_by_size(patch, cat, lat, limit=3, internal=[0, 1])) == []
    assert [k for _, (k,) in asked] == [1]


def _plain_fit(shape, annotation, match, cat):
    """:func:`T.fit_template`'s sides and chords the plain way: each corner's loop position
    from a dict, each side's path walked from one corner to the next (reversed when the user
    runs it backwards), chords numbered by a loop over the side edges then every edge."""
    from jaxmatch.placement.embed import oriented_boundary

    om, loop = oriented_boundary(cat.mesh(match.mesh_id), match.rotation, match.reflected)
    loop = [int(v) for v in loop]
    nb = len(loop)
    if shape.n_corners == 0:
        paths = [loop + loop[:1]]
    else:
        where = {int(a): j for j, a in enumerate(np.asarray(match.alignment).tolist())}
        side = np.asarray(annotation.side).tolist()
        corner_point = [side.index(j) for j in range(shape.n_corners)]
        if any(p not in where or int(annotation.codes[p]) == 0 for p in corner_point):
            return None
        pos = [where[p] for p in corner_point]
        paths = []
        for j, rev in shape.side_frame:
            a, b = pos[j], pos[(j + 1) % shape.n_corners]
            path = [loop[i % nb] for i in range(a, (b if b > a else b + nb) + 1)]
            paths.append(path[::-1] if rev else path)
    e = np.asarray(edges(np.asarray(om.quads)), np.int64)
    key = {tuple(x): i for i, x in enumerate(e.tolist())}
    label = T._chord_topology(np.asarray(om.quads)).label
    rename: dict = {}
    order = [key[tuple(sorted((p[k], p[k + 1])))] for p in paths for k in range(len(p) - 1)] + list(range(len(e)))
    for i in order:
        rename.setdefault(int(label[i]), len(rename))
    chord = [rename[int(c)] for c in label]
    side_chords = [[chord[key[tuple(sorted((p[k], p[k + 1])))]] for k in range(len(p) - 1)] for p in paths]
    return paths, side_chords, chord


@pytest.mark.parametrize("path", [EXAMPLES / "lshape.json", EXAMPLES / "triangle.json", EXAMPLES / "circle.json",
                                  LABELLED / "trapezoid.json", LABELLED / "stairs.json"], ids=lambda p: p.stem)
@pytest.mark.parametrize("clockwise", [False, True])
def test_fitted_template_is_the_plain_fit(cat, lat, path, clockwise):
    """:func:`T.fit_template` (loop positions, side paths and chord numbers in whole arrays)
    gives each ranked match of every size the sides, paths and chords of the plain walk above,
    for the file's outline and the same outline listed clockwise (the sides run backwards)."""
    from jaxmatch.scoring.rank import rank

    shp = load_shape(path)
    if clockwise:
        shp = make_shape(np.asarray(shp.points)[::-1])
    fitted = 0
    for k in sorted(cat.internal)[:4]:
        ranking = rank(shp, cat, lat, internal=[k], top=12, per_size=True, prune=True)
        for r, m in enumerate(ranking.results, 1):
            t = T.fit_template(shp, ranking.annotation, m, cat, r)
            plain = _plain_fit(shp, ranking.annotation, m, cat)
            assert (t is None) == (plain is None), (k, m.mesh_id)
            if t is None:
                continue
            fitted += 1
            paths, side_chords, chord = plain
            assert [p.tolist() for p in t.side_path] == paths
            assert all(p.dtype == np.int64 for p in t.side_path + t.side_chords)
            assert [c.tolist() for c in t.side_chords] == side_chords
            assert t.edge_chord.tolist() == chord and t.n_chords == max(chord) + 1
    assert fitted > 10
