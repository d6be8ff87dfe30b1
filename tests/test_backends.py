"""The numba backend of the exact host (jaxmatch.kernels.backends), its C kernel for problems of one
thread and its numpy kernel for small problems, against the XLA backend and the plain-Python DP,
with and without skip weights (must-match types included)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.kernels import reference
from jaxmatch.errors import InputError
from jaxmatch.kernels.backends import NumbaBackend, c_kernel, c_values, default_backend, numba_values, numpy_values
from jaxmatch.scoring.exact import CPUBackend, dp_problem, exact_values, score_bucket
from jaxmatch.kernels.model import make_weights


def random_model(seed: int, forbidden: float, skip: str):
    """Integer weights in -5..5 (a fraction ``forbidden`` of them -inf) and skip weights:
    ``"zero"``, ``"neg"`` (integers in -3..0) or ``"must"`` (some -inf)."""
    rng = np.random.default_rng(seed)
    t = rng.integers(-5, 6, (3, 4, 4, 4)).astype(np.float32)
    t[rng.random(t.shape) < forbidden] = -np.inf
    s = np.zeros(3, np.float32)
    if skip != "zero":
        s = rng.integers(-3, 1, 3).astype(np.float32)
    if skip == "must":
        s[rng.integers(0, 3)] = -np.inf
    return t, s


@st.composite
def problems(draw, max_n=12, max_m=30, max_meshes=300):
    n = draw(st.integers(1, max_n))
    shapes = [np.array(draw(st.lists(st.integers(0, 2), min_size=1, max_size=max_m)), np.int32)
              for _ in range(draw(st.integers(1, 3)))]
    big_n = draw(st.integers(1, max_meshes))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    vals = rng.integers(2, 6, (big_n, n)).astype(np.int32)
    table, skip = random_model(draw(st.integers(0, 2**32 - 1)), draw(st.sampled_from([0.0, 0.2, 0.6])),
                               draw(st.sampled_from(["zero", "neg", "must"])))
    lanes = draw(st.sampled_from([1, 7, 32, 128]))
    return shapes, vals, make_weights(table, skip), lanes


@settings(max_examples=40, deadline=None)
@given(problems())
def test_numba_backend_equals_the_xla_backend(case):
    shapes, vals, weights, lanes = case
    ours = exact_values(shapes, vals, weights, backend=NumbaBackend(lanes=lanes))
    theirs = exact_values(shapes, vals, weights, backend=CPUBackend())
    np.testing.assert_array_equal(ours, theirs)  # -inf included


@settings(max_examples=40, deadline=None)
@given(problems(), st.sampled_from([None, np.int32, np.float32]))
def test_numpy_kernel_equals_the_xla_backend(case, wider):
    """The numpy kernel (small problems before numba is loaded), in every DP number type."""
    from jaxmatch.scoring import exact

    shapes, vals, weights, _ = case
    big_n, n = vals.shape
    kind = None if wider is None else exact.DPKind(wider, exact.NEG32 if wider is np.int32 else exact.NEG)
    prob = dp_problem(shapes, weights, n, kind=kind)
    theirs = CPUBackend().run(prob, vals.reshape(1, 1, big_n, n))
    ours = numpy_values(prob.codes, prob.lengths, vals, prob.tab, prob.gate, prob.strict)
    assert ours.dtype == theirs.dtype
    valid = theirs > prob.kind.neg / 2
    np.testing.assert_array_equal(ours > prob.kind.neg / 2, valid)
    np.testing.assert_array_equal(ours[valid], theirs[valid])


needs_c = pytest.mark.skipif(c_kernel() is None, reason="the C kernel (jaxmatch.kernels._dp) is not built")


@needs_c
@settings(max_examples=60, deadline=None)
@given(problems(), st.booleans())
def test_c_kernel_is_the_numba_kernel_bit_for_bit(case, strict):
    """c_values against numba_values on the same padded problem: every value equal, the invalid
    ones' sentinels too (the same steps in the same int16 arithmetic), strict or not, whatever
    the chunk of meshes (lanes 1, 7, 32, 128 against numba's 256)."""
    shapes, vals, weights, lanes = case
    prob = dp_problem(shapes, weights, vals.shape[1])
    if prob.tab.dtype != np.int16:
        return
    ours = c_values(prob.codes, prob.lengths, vals, prob.tab, prob.gate, strict, lanes)
    theirs = numba_values(prob.codes, prob.lengths, vals, prob.tab, prob.gate, strict, 256)
    assert ours.dtype == theirs.dtype == np.int16 and ours.shape == theirs.shape
    np.testing.assert_array_equal(ours, theirs)


@needs_c
def test_c_kernel_takes_int16_only():
    tab = np.zeros((4, 64), np.int32)
    with pytest.raises(ValueError, match="int16"):
        c_values(np.zeros((1, 3), np.int32), [3], np.full((2, 4), 4), tab, np.zeros(4, np.int32))


def budget_case(monkeypatch, seed: int, skip: str):
    """A small problem (one 30-point shape, 40 meshes of 8 vertices), its XLA values, and the
    list every kernel call of the numba backend is recorded in ("c", "numpy", "numba"), in a
    process where neither the budget nor the numba kernel has been used yet."""
    from jaxmatch.kernels import backends

    rng = np.random.default_rng(seed)
    shapes, vals = [rng.integers(0, 3, 30)], rng.integers(2, 6, (40, 8))
    w = make_weights(*random_model(seed, 0.2, skip))
    ref = exact_values(shapes, vals, w, backend=CPUBackend())
    ran = []
    for name, kernel in (("c", c_values), ("numpy", numpy_values), ("numba", numba_values)):
        monkeypatch.setattr(backends, f"{name}_values", lambda *a, name=name, kernel=kernel: ran.append(name) or kernel(*a))
    monkeypatch.setattr(backends, "_NUMPY_SPENT", [0])
    monkeypatch.setattr(backends, "_NUMBA_LOADED", [False])
    return shapes, vals, w, ref, ran


@needs_c
def test_small_problems_run_in_c_within_the_budget(monkeypatch):
    """With the C library built, the light kernel of the budget is C (not numpy): the same
    budget, numba after it; the values are XLA's."""
    shapes, vals, w, ref, ran = budget_case(monkeypatch, 4, "neg")
    be = NumbaBackend(numpy_cells=2 * 2 * 8 * 8 * 30 * 40)  # two problems of 2n * n * m * meshes (40, unpadded)
    for _ in range(3):
        np.testing.assert_array_equal(exact_values(shapes, vals, w, backend=be), ref)
    assert ran == ["c", "c", "numba"]


@needs_c
@pytest.mark.parametrize("meshes", [1, 3, 40, 70])
def test_int16_kernels_get_the_meshes_unpadded(monkeypatch, meshes):
    """exact_values hands the numba backend's int16 kernels the meshes as they are (no padding
    to a block: 3 meshes are not scored as 64), with the values of the padded XLA kernel."""
    from jaxmatch.kernels import backends

    rng = np.random.default_rng(meshes)
    shapes, vals = [rng.integers(0, 3, 30)], rng.integers(2, 6, (meshes, 10))
    w = make_weights(*random_model(meshes, 0.2, "neg"))
    seen = []
    monkeypatch.setattr(backends, "c_values", lambda *a: seen.append(np.shape(a[2])) or c_values(*a))
    monkeypatch.setattr(backends, "_NUMPY_SPENT", [0])
    monkeypatch.setattr(backends, "_NUMBA_LOADED", [False])  # (the light kernel: not after numba ran)
    got = exact_values(shapes, vals, w, backend=NumbaBackend(numpy_cells=1 << 40))
    assert seen == [(meshes, 10)]
    np.testing.assert_array_equal(got, exact_values(shapes, vals, w, backend=CPUBackend()))


def test_numba_backend_runs_small_problems_in_numpy_within_its_budget(monkeypatch):
    """Without the C library: small problems in numpy until the budget is spent, then numba."""
    from jaxmatch.kernels import backends

    monkeypatch.setattr(backends, "_C_DP", [None, True])  # as if not built
    shapes, vals, w, ref, ran = budget_case(monkeypatch, 3, "must")
    exact_values(shapes, vals, w, backend=NumbaBackend(numpy_cells=1 << 40))
    cells = backends._NUMPY_SPENT[0]  # 2n * n * m * meshes (the 40 given: no padding meshes)
    assert ran == ["numpy"] and cells == 2 * 8 * 8 * 30 * 40
    be = NumbaBackend(numpy_cells=3 * cells)
    for _ in range(3):  # two more within the budget, then numba
        np.testing.assert_array_equal(exact_values(shapes, vals, w, backend=be), ref)
    assert ran == ["numpy", "numpy", "numpy", "numba"] and backends._NUMPY_SPENT == [3 * cells]
    np.testing.assert_array_equal(exact_values(shapes, vals, w, backend=NumbaBackend(numpy_cells=1 << 40)), ref)
    assert ran[-1] == "numba"  # the numba kernel is loaded now: numba from here on
    assert default_backend().numpy_cells == backends.NUMPY_CELLS and NumbaBackend().numpy_cells == 0


@pytest.mark.parametrize("skip", ["zero", "neg", "must"])
@pytest.mark.parametrize("seed", range(3))
def test_numba_backend_equals_the_plain_dp(seed, skip):
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, 3, 21)
    vals = rng.integers(2, 6, (9, 7))
    table, sk = random_model(seed, 0.2, skip)
    res = score_bucket(codes, vals, make_weights(table, sk), backend=NumbaBackend(lanes=4))
    expect = [reference.dp_reference(codes, v, table, sk) for v in vals]
    np.testing.assert_array_equal(res.utility, np.array(expect, np.float32))
    assert np.array_equal(res.unmatchable, [e == -math.inf for e in expect])


def test_band_edges_longest_boundary_equal_to_points():
    """n = m: the band is one cell wide (every point takes a vertex), and n = m + 1 is unmatchable."""
    table, sk = random_model(5, 0.0, "neg")
    w = make_weights(table, sk)
    codes = np.array([1, 0, 2, 0, 1, 1], np.int32)
    for n in (len(codes), len(codes) + 1):
        vals = np.random.default_rng(n).integers(2, 6, (20, n)).astype(np.int32)
        np.testing.assert_array_equal(exact_values([codes], vals, w, backend=NumbaBackend()),
                                      exact_values([codes], vals, w, backend=CPUBackend()))


def test_numba_values_rejects_wider_types_and_backend_falls_back():
    table = np.full((3, 4, 4, 4), 1000.0, np.float32)  # n * 1000 >= 2**13: int32 DP
    w = make_weights(table)
    prob = dp_problem([np.zeros(12, np.int32)], w, 10)
    assert np.dtype(prob.kind.dtype) == np.int32
    with pytest.raises(ValueError, match="int16"):
        numba_values(prob.codes, prob.lengths, np.full((3, 10), 3, np.int32), prob.tab, prob.gate)
    vals = np.random.default_rng(0).integers(2, 6, (5, 10))
    np.testing.assert_array_equal(exact_values([np.zeros(12, np.int32)], vals, w, backend=NumbaBackend()),
                                  exact_values([np.zeros(12, np.int32)], vals, w, backend=CPUBackend()))


@pytest.mark.parametrize("value, kind", [("numba", NumbaBackend), ("xla", CPUBackend), ("auto", NumbaBackend), ("", NumbaBackend)])
def test_default_backend_follows_the_environment(monkeypatch, value, kind):
    monkeypatch.setenv("JAXMATCH_BACKEND", value)
    assert isinstance(default_backend(), kind)  # tests run JAX on the CPU: auto = numba


def test_default_backend_rejects_unknown_names(monkeypatch):
    monkeypatch.setenv("JAXMATCH_BACKEND", "cuda")
    with pytest.raises(InputError, match="JAXMATCH_BACKEND: must be one of auto, numba, xla"):
        default_backend()


@pytest.mark.parametrize("skip", ["zero", "must"])
def test_parallel_and_serial_kernels_agree(monkeypatch, skip):
    from jaxmatch.kernels import backends

    rng = np.random.default_rng(11)
    shapes = [rng.integers(0, 3, 40), rng.integers(0, 3, 17)]
    vals = rng.integers(2, 6, (700, 9))
    table, sk = random_model(11, 0.2, skip)
    w = make_weights(table, sk)
    monkeypatch.setattr(backends, "PARALLEL_CELLS", 0)
    par = exact_values(shapes, vals, w, backend=NumbaBackend(lanes=64))
    monkeypatch.setattr(backends, "PARALLEL_CELLS", 1 << 62)
    ser = exact_values(shapes, vals, w, backend=NumbaBackend(lanes=64))
    np.testing.assert_array_equal(par, ser)
    np.testing.assert_array_equal(par, exact_values(shapes, vals, w, backend=CPUBackend()))
