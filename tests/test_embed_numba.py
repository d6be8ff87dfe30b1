"""The compiled smoothers (the C library, kernels/_placement.c through kernels/placement.py, and
its numba fallback, kernels/_numba_smooth.py) are the numpy reference in embed.py, step for
step: same energy and gradient, same parametrisation of sliding vertices, same L-BFGS iterates,
hence the same smoothed placements (up to round-off)."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.kernels import _numba_smooth
from jaxmatch.kernels import placement as kernels
from jaxmatch.placement.embed import LBFGS_FTOL, LBFGS_GTOL, LBFGS_MEMORY, Slide, _energy, _lbfgs, _objective, _Params
from jaxmatch.placement.embed import smooth
from jaxmatch.quality import inverted_mask, quality

from test_embed import grid, star

BACKENDS = [kernels, _numba_smooth] if kernels.BACKEND == "c" else [_numba_smooth]
"""The compiled versions this installation has (the C library when it was built, numba always)."""


def _strip_case(seed: int, amp: float):
    """A 4 x 3 grid with jittered internal vertices and its bottom side free to slide."""
    mesh, lattice = grid(4, 3)
    rng = np.random.default_rng(seed)
    xy = lattice.copy()
    internal = np.setdiff1d(np.arange(mesh.n_vertices), mesh.boundary)
    xy[internal] += rng.uniform(-amp, amp, size=(internal.size, 2))
    bottom = sorted((v for v in mesh.boundary if lattice[v, 1] == 0 and 0 < lattice[v, 0] < 4), key=lambda v: lattice[v, 0])
    xy[bottom, 0] += rng.uniform(-0.3, 0.3, len(bottom))
    xy[bottom] = xy[bottom][np.argsort(xy[bottom, 0])]
    slides = (Slide(np.array([0.0, 0.0]), np.array([4.0, 0.0]), np.array(bottom)),)
    return mesh, xy, internal, slides


@pytest.mark.parametrize("nb", BACKENDS, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amp=st.floats(0.0, 0.6), delta=st.sampled_from([1e-6, 1e-3, 0.1]),
       power=st.sampled_from([1.0, 2.0, 8.0, 16.0]))
def test_energy_and_gradient_equal_the_reference(nb, seed, amp, delta, power):
    """Including folded corners (amp up to 0.6 folds some quads): the regularised energy is
    finite there, and both versions agree."""
    mesh, xy, _, _ = _strip_case(seed, amp)
    f_ref, g_ref = _energy(xy, mesh.quads, delta, power)
    f, g = nb.energy(xy, np.asarray(mesh.quads, np.int64), delta, power)
    if np.isfinite(f_ref):
        assert f == pytest.approx(f_ref, rel=1e-12)
        np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-12 * np.abs(g_ref).max())
    else:
        assert not np.isfinite(f)


@pytest.mark.parametrize("nb", BACKENDS, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amp=st.floats(0.0, 0.3))
def test_objective_with_sliding_vertices_equals_the_reference(nb, seed, amp):
    mesh, xy, internal, slides = _strip_case(seed, amp)
    params = _Params(xy, internal, slides)
    x = params.start(xy) + np.random.default_rng(seed).normal(0, 0.1, params.start(xy).shape)
    f_ref, g_ref = _objective(x, params, mesh.quads, 1e-3, 4.0)
    f, g = nb.objective(x, params.base, internal.astype(np.int64), *params.flat, np.asarray(mesh.quads, np.int64), 1e-3, 4.0)
    assert f == pytest.approx(f_ref, rel=1e-12)
    np.testing.assert_allclose(g, g_ref, rtol=1e-9, atol=1e-12 * np.abs(g_ref).max())


@pytest.mark.parametrize("nb", BACKENDS, ids=lambda m: m.__name__.rsplit(".", 1)[-1])
@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("power", [1.0, 4.0, 16.0])
def test_lbfgs_iterates_match_the_reference(nb, seed, power):
    """A few iterations follow the same path (identical up to round-off), also past the point
    where the oldest of the LBFGS_MEMORY pairs is overwritten (20 iterations: the kept pairs'
    products, 1 / s.y and y.y, stay with their pair); the minimum found after many is the same
    to optimiser precision."""
    mesh, xy, internal, slides = _strip_case(seed, 0.25)
    params = _Params(xy, internal, slides)
    q = np.asarray(mesh.quads, np.int64)
    x0 = params.start(xy)
    for iters, tol in ((3, 1e-9), (2 * LBFGS_MEMORY + 4, 1e-9), (200, 1e-5)):
        ref = _lbfgs(lambda z: _objective(z, params, q, 1e-3, power), x0, iters)
        got = nb.lbfgs(x0, params.base, internal.astype(np.int64), *params.flat, q, 1e-3, power, iters,
                       LBFGS_MEMORY, LBFGS_FTOL, LBFGS_GTOL)
        np.testing.assert_allclose(params.positions(got), params.positions(ref), atol=tol)


@pytest.mark.parametrize("k", [3, 4, 5])
def test_untangling_a_folded_star_agrees_with_the_reference(k):
    """Start from a fold (the centre pushed outside): both optimisers untangle it, to the
    same quality."""
    mesh = star(k)
    ang = 2 * np.pi * np.arange(k) / k
    xy = np.zeros((mesh.n_vertices, 2))
    xy[1:k + 1] = np.c_[np.cos(ang), np.sin(ang)]
    mid = ang + np.pi / k
    xy[k + 1:] = 1.4 * np.c_[np.cos(mid), np.sin(mid)]
    xy[0] = [1.6, 0.1]
    boundary = np.arange(1, 2 * k + 1)
    assert inverted_mask(xy, mesh.quads).any()
    ref = smooth(xy, mesh.quads, boundary, reference=True)
    got = smooth(xy, mesh.quads, boundary)
    assert not inverted_mask(got, mesh.quads).any() and not inverted_mask(ref, mesh.quads).any()
    assert quality(got, mesh.quads)[0].min() == pytest.approx(quality(ref, mesh.quads)[0].min(), abs=1e-6)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amp=st.floats(0.0, 0.45), slide=st.booleans())
def test_compiled_smooth_equals_the_reference(seed, amp, slide):
    """The whole loop (untangling rounds, power continuation, best-so-far choice) gives the
    same positions as the numpy version, with and without sliding vertices, folded or not."""
    mesh, xy, internal, slides = _strip_case(seed, amp)
    fixed = mesh.boundary
    kw = dict(slides=slides) if slide else {}
    ref = smooth(xy, mesh.quads, fixed, reference=True, **kw)
    got = smooth(xy, mesh.quads, fixed, **kw)
    assert inverted_mask(got, mesh.quads).sum() == inverted_mask(ref, mesh.quads).sum()
    assert quality(got, mesh.quads)[0].min() == pytest.approx(quality(ref, mesh.quads)[0].min(), abs=1e-6)
    np.testing.assert_allclose(got, ref, atol=1e-5)


@pytest.mark.parametrize("k", [3, 5, 6])
@pytest.mark.parametrize("grid_shape", [(3, 2), (5, 4)])
def test_compiled_tutte_equals_the_reference(k, grid_shape):
    from jaxmatch.placement.embed import tutte

    for mesh in (star(k), grid(*grid_shape)[0]):
        n = len(mesh.boundary)
        ang = 2 * np.pi * np.arange(n) / n
        bxy = np.c_[np.cos(ang), 1.3 * np.sin(ang)]
        a = tutte(mesh.quads, mesh.n_vertices, mesh.boundary, bxy)
        b = tutte(mesh.quads, mesh.n_vertices, mesh.boundary, bxy, reference=True)
        np.testing.assert_allclose(a, b, atol=1e-12)


needs_c = pytest.mark.skipif(kernels.BACKEND != "c", reason="the C library is not built in this installation")


@needs_c
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amp=st.floats(0.0, 0.45), slide=st.booleans())
def test_c_and_numba_smoothing_loops_agree(seed, amp, slide):
    """The fallback gives the same placements as the library it stands in for."""
    mesh, xy, internal, slides = _strip_case(seed, amp)
    flat = kernels.flat_slides(slides if slide else ())
    args = (xy, np.asarray(mesh.quads, np.int64), internal.astype(np.int64), *flat, 200,
            np.array([2.0, 4.0, 8.0, 16.0]), 12, LBFGS_MEMORY, LBFGS_FTOL, LBFGS_GTOL)
    np.testing.assert_allclose(kernels.smooth(*args), _numba_smooth.smooth(*args), atol=1e-6)


@needs_c
@pytest.mark.parametrize("k", [3, 5])
def test_c_and_numba_tutte_agree(k):
    mesh = star(k)
    n = len(mesh.boundary)
    bxy = np.c_[np.cos(2 * np.pi * np.arange(n) / n), np.sin(2 * np.pi * np.arange(n) / n)]
    a = kernels.tutte_dense(mesh.quads, mesh.n_vertices, mesh.boundary, bxy)
    b = _numba_smooth.tutte_dense(np.asarray(mesh.quads, np.int64), mesh.n_vertices, np.asarray(mesh.boundary, np.int64), bxy)
    np.testing.assert_allclose(a, b, atol=1e-12)


def _scalar_energy(xy, quads, delta, power):
    """The C energy's formula one corner at a time in Python floats (IEEE doubles; math.sqrt is
    correctly rounded, math.pow is the C library's pow), each sum in corner order: what the
    library's two corners per vector instruction must give to the bit. Returns (f, grad (V, 2))."""
    d2 = 4.0 * delta * delta
    sq = next((e for e in range(7) if power == math.ldexp(1.0, e)), -1)
    corners, kmax = [], -math.inf
    for v in quads.tolist():
        for c in range(4):
            p, nx, pv = v[c], v[(c + 1) % 4], v[(c + 3) % 4]
            e1x, e1y = xy[nx][0] - xy[p][0], xy[nx][1] - xy[p][1]
            e2x, e2y = xy[pv][0] - xy[p][0], xy[pv][1] - xy[p][1]
            a = e1x * e2y - e1y * e2x
            r = math.sqrt(a * a + d2)
            h = 0.5 * (a + r) if a >= 0 else d2 / (2.0 * (r - a))
            k = (e1x * e1x + e1y * e1y + e2x * e2x + e2y * e2y) / (2.0 * h)
            kmax = k if not k <= kmax else kmax
            corners.append((p, nx, pv, e1x, e1y, e2x, e2y, r, h, k))
    C = 4.0 * len(quads)
    acc = 0.0
    for *_, k in corners:
        t = k / kmax
        for _ in range(sq):
            t = t * t
        acc += t
    f = kmax * math.pow(acc / C, 1.0 / power)
    grad = [[0.0, 0.0] for _ in xy]
    for p, nx, pv, e1x, e1y, e2x, e2y, r, h, k in corners:
        x = t = k / f
        for _ in range(sq):
            t = t * t
        dk = t / x / C
        gN, ga = dk / (2.0 * h), -dk * k / r
        g1x, g1y = 2.0 * gN * e1x + ga * e2y, 2.0 * gN * e1y - ga * e2x
        g2x, g2y = 2.0 * gN * e2x - ga * e1y, 2.0 * gN * e2y + ga * e1x
        grad[p][0] -= g1x + g2x
        grad[p][1] -= g1y + g2y
        grad[nx][0] += g1x
        grad[nx][1] += g1y
        grad[pv][0] += g2x
        grad[pv][1] += g2y
    return f, np.array(grad)


@needs_c
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), amp=st.floats(0.0, 0.6), delta=st.sampled_from([1e-6, 1e-3, 0.1]),
       power=st.sampled_from([1.0, 2.0, 4.0, 8.0, 16.0]))
def test_c_energy_equals_its_scalar_formula_to_the_bit(seed, amp, delta, power):
    """The library computes a quad's corners two to a vector instruction: the same IEEE
    operations as the formula written corner by corner, so the same doubles, folded corners
    (amp up to 0.6) included."""
    mesh, xy, _, _ = _strip_case(seed, amp)
    q = np.asarray(mesh.quads, np.int64)
    f, g = kernels.energy(xy, q, delta, power)
    f_ref, g_ref = _scalar_energy(xy.tolist(), q, delta, power)
    assert f == f_ref
    np.testing.assert_array_equal(g, g_ref)


@pytest.mark.skipif(not (shutil.which("cc") or shutil.which("gcc")), reason="no C compiler: numba is the expected backend")
def test_the_c_library_was_built_where_a_compiler_exists():
    """The extension is optional (installs without a compiler fall back to numba); where one
    exists it must have been built, or the fast start-up silently disappears."""
    assert kernels.BACKEND == "c"


@pytest.mark.skipif(kernels.BACKEND != "c", reason="the C library is not built")
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 12), scale=st.sampled_from([1e-200, 1e-3, 1.0, 1e150]),
       special=st.sampled_from([None, "repeat", "nan", "inf"]))
def test_compiled_sj_inverted_equals_the_numpy_measure_to_the_bit(seed, n, scale, special):
    """kernels.sj_inverted (C) gives quality()'s scaled Jacobians and inverted_mask() bit for bit, on
    random (partly folded) quads, with zero-length edges (a repeated vertex), NaN and inf positions,
    and scales where |e1| |e2| underflows or overflows."""
    rng = np.random.default_rng(seed)
    xy = rng.normal(size=(n + 3, 2)) * scale
    quads = rng.integers(0, n + 3, size=(3 * n, 4))
    if special == "repeat":
        xy[1] = xy[0]
    elif special is not None:
        xy[rng.integers(0, n + 3)] = np.nan if special == "nan" else np.inf
    sj, inv = kernels.sj_inverted(xy, quads)
    with np.errstate(all="ignore"):
        ref_sj, ref_inv = quality(xy, quads)[0], inverted_mask(xy, quads)
    np.testing.assert_array_equal(sj, ref_sj)
    np.testing.assert_array_equal(inv, ref_inv)
