"""The relaxation of a graded mesh towards its size field (:mod:`jaxmatch.meshing.grading`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from jaxmatch.defaults import QUALITY
from jaxmatch.field import Field, Near
from jaxmatch.meshing.grading import follow_field, laplacian_solve
from jaxmatch.meshing.pipeline import mesh
from jaxmatch.shape import make_shape

SQUARE = make_shape([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
QUAD = make_shape([[0.0, 0.0], [2.0, 0.0], [2.3, 2.0], [0.2, 1.8]])


@pytest.fixture(scope="module")
def graded():
    # a uniform mesh, then judged against the field (not a square: a perfect grid's quads must all
    # keep a scaled Jacobian of 1, which no move of its inner vertices does)
    f = Field(0.2, (Near("point", (1.1, 1.0), 0.04, 0.6),)).bind(QUAD)
    m = mesh(QUAD, size=0.1)
    return replace(m, field=f), f


def test_relaxing_moves_no_outline_vertex_and_keeps_the_quality(graded):
    m, _ = graded
    out = follow_field(m, QUALITY)
    on_loops = np.concatenate([np.asarray(loop) for loop in m._loops])
    assert np.array_equal(out.xy[on_loops], m.xy[on_loops]) and np.array_equal(out.quads, m.quads)
    assert out.inverted == 0 and out.min_scaled_jacobian >= min(m.min_scaled_jacobian, QUALITY.high_sj) - 1e-12
    assert out.field_share > m.field_share + 0.1  # edges near the point shorten, the others lengthen


def test_a_perfect_grid_keeps_its_quads_square():
    f = Field(0.2, (Near("point", (1.0, 1.0), 0.04, 0.6),)).bind(SQUARE)
    m = replace(mesh(SQUARE, size=0.1), field=f)
    out = follow_field(m, QUALITY)
    assert out.min_scaled_jacobian == pytest.approx(1.0) and out.field_share >= m.field_share


@pytest.mark.parametrize("n", [1, 7, 60])
def test_laplacian_solve_is_the_dense_solve(n):
    rng = np.random.default_rng(n)
    ea, eb = np.triu_indices(n, 1)
    keep = rng.random(ea.size) < 0.3
    ea, eb = ea[keep], eb[keep]
    degree = np.bincount(np.concatenate([ea, eb]), minlength=n) + rng.integers(1, 3, n)  # + edges to fixed vertices
    A = np.diag(degree.astype(float))
    A[ea, eb] = A[eb, ea] = -1.0
    rhs = rng.normal(size=(n, 2))
    got = laplacian_solve(degree.astype(float), ea, eb, rhs, np.zeros((n, 2)), tol=1e-12)
    np.testing.assert_allclose(got, np.linalg.solve(A, rhs), rtol=1e-9, atol=1e-9)


def test_without_a_field_the_mesh_is_returned_as_is(graded):
    m, _ = graded
    plain = replace(m, field=None)
    assert follow_field(plain) is plain


def test_the_graded_pipeline_ends_relaxed(graded):
    _, f = graded
    m = mesh(SQUARE, size=Field(0.2, (Near("point", (1.0, 1.0), 0.04, 0.6),)))
    assert m.valid and m.field_share >= 0.9 and m.min_scaled_jacobian >= 0.6


def test_after_its_first_step_the_relaxation_asks_the_field_at_the_inner_vertices_only(graded):
    m, f = graded
    asked = []

    def counting(points):
        asked.append(len(points))
        return f(points)

    out = follow_field(replace(m, field=counting), QUALITY)
    inner = m.xy.shape[0] - len(np.unique(np.concatenate([np.asarray(loop) for loop in m._loops])))
    n_edges = m._edges.shape[0]  # (the shares of edges in the band, at the start and after each step)
    # the vertices, the start's shares, the first step's; then per step the inner vertices and its shares
    assert asked[:3] == [m.xy.shape[0], n_edges, n_edges] and len(asked) > 4 and len(asked) % 2 == 1
    assert set(asked[3::2]) == {inner} and set(asked[4::2]) == {n_edges}
    assert np.array_equal(out.xy, follow_field(m, QUALITY).xy)  # the same relaxation as with the bound field


@pytest.mark.parametrize("graded_size", [False, True])
def test_with_a_field_the_patches_are_smoothed_with_fewer_iterations(monkeypatch, graded_size):
    import jaxmatch.placement.layout as layout
    import jaxmatch.placement.refine as refine
    import jaxmatch.placement.solve as solve
    from jaxmatch.inputs import load_catalogue

    seen = {"patches": [], "cuts": []}
    for mod, what in ((refine, "patches"), (layout, "patches"), (solve, "cuts")):
        real = mod.smooth_in_frame
        monkeypatch.setattr(mod, "smooth_in_frame", lambda *a, _real=real, _w=what, **k: (
            seen[_w].append(k.get("iters", refine.SMOOTH_ITERS)), _real(*a, **k))[1])
    load_catalogue().cache.forget_shapes()  # (a first call: nothing refined before)
    L = make_shape([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])
    mesh(L, size=Field(0.2, (Near("point", (1.0, 1.0), 0.05, 0.8),)) if graded_size else 0.1)
    want = refine.SMOOTH_ITERS_GRADED if graded_size else refine.SMOOTH_ITERS
    assert seen["patches"] and set(seen["patches"]) == {want}
    assert seen["cuts"] and set(seen["cuts"]) == {refine.SMOOTH_ITERS}  # the merged mesh's cuts: as for one size


def test_a_mesh_with_every_edge_in_the_band_is_returned_as_is():
    m = mesh(SQUARE, size=0.1)  # a grid of 0.1 edges against a field of 0.1 everywhere
    m = replace(m, field=Field(0.1).bind(SQUARE))
    assert m.field_share == 1.0 and follow_field(m, QUALITY) is m


@pytest.mark.parametrize("case, perfect", [("square", True), ("plate-hole", False), ("rectangle", False)])
def test_the_relaxation_stops_once_every_edge_is_in_the_band(monkeypatch, case, perfect):
    """The keys (share + refined share) of the start and of each step: the steps stop at the
    first one with both shares 1 (the square of ``examples/graded``: after 2), else run until
    settled or all :data:`FOLLOW_ITERS` are taken; the mesh of the best key is returned."""
    import jaxmatch
    import jaxmatch.meshing.grading as G
    from jaxmatch.field import load_field

    folder = Path(__file__).resolve().parent.parent / "examples" / "graded"
    shp, f = jaxmatch.load_shape(folder / f"{case}.json"), load_field(folder / f"{case}.field.json")
    keys, shares, real = [], [], G._shares

    def recorded(*a):
        r = real(*a)
        keys.append(r[0] + r[1])
        shares.append(r[0])
        return r

    monkeypatch.setattr(G, "_shares", recorded)
    out = mesh(shp, size=f)
    assert 2 <= len(keys) <= G.FOLLOW_ITERS + 1 and max(keys[:-1]) < G.PERFECT
    assert (keys[-1] == G.PERFECT) is perfect
    if perfect:
        assert len(keys) < G.FOLLOW_ITERS + 1
    assert out.field_share == pytest.approx(shares[int(np.argmax(np.array(keys) + 1e-12 * np.arange(len(keys))))])
