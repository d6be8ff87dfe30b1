"""Soft relaxation (jaxmatch.scoring.soft): log-partition value, convergence, finite exact gradients."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from jaxmatch.kernels import reference
from jaxmatch.scoring import exact as score
from jaxmatch.scoring import soft
from jaxmatch.scoring.exact import NEG, score_bucket
from jaxmatch.kernels.model import make_weights
from jaxmatch.scoring.soft import pad_shapes, soft_utility, soft_utility_batch, table_parts

S, X, V = 0, 1, 2
N_MESHES = 3  # fixed batch: one compilation per (n, padded m)



def _model(free, mask):
    """The Weights whose free values are ``free`` and forbidden entries ``mask``."""
    return make_weights(np.where(np.asarray(mask), -np.inf, np.asarray(free, np.float32)))


def su(codes, vals, free, mask, gamma, **kw):
    """soft_utility with the match table ``free`` (traced or not), skip weights 0."""
    return soft_utility(codes, vals, _model(np.zeros((3, 4, 4, 4)), mask), gamma, table=free, **kw)


def sub(codes, valid, vals, free, mask, gamma, **kw):
    return soft_utility_batch(codes, valid, vals, _model(np.zeros((3, 4, 4, 4)), mask), gamma, table=free, **kw)


def random_table(seed: int, forbidden: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = rng.integers(-5, 6, (3, 4, 4, 4)).astype(np.float32)
    t[rng.random(t.shape) < forbidden] = -np.inf
    return t


def random_case(seed, m, n, forbidden=0.3, n_meshes=N_MESHES):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 3, m), rng.integers(2, 6, (n_meshes, n)), random_table(seed, forbidden)


def n_paths(m, n):
    """Orientations times alignments."""
    return 2 * n * math.comb(m, n)


def test_soft_uses_the_exact_scorers_dp():
    assert soft.dp_scan is score.dp_scan


@given(
    st.integers(1, 5).flatmap(
        lambda n: st.tuples(
            st.lists(st.integers(0, 2), min_size=1, max_size=9),
            st.lists(st.lists(st.integers(2, 5), min_size=n, max_size=n), min_size=N_MESHES, max_size=N_MESHES),
        )
    ),
    st.integers(0, 2**32 - 1),
    st.sampled_from([0.0, 0.3, 0.7]),
    st.sampled_from([0.25, 1.0]),
)
def test_soft_is_the_log_partition_function(shape_meshes, seed, forbidden, gamma):
    codes, vals = shape_meshes
    table = random_table(seed, forbidden)
    free, mask = table_parts(table)
    got = np.asarray(su(codes, np.array(vals), free, mask, gamma))
    for k, v in enumerate(vals):
        expect = reference.brute_force_soft(codes, v, table, gamma)
        if expect == -math.inf:
            assert got[k] <= NEG / 2
        else:
            assert got[k] == pytest.approx(expect, rel=1e-5, abs=1e-4)


@pytest.mark.parametrize("gamma", [1e-1, 1e-2, 1e-3])
def test_converges_to_exact_within_log_paths_bound(gamma):
    m, n = 12, 6
    codes, vals, table = random_case(0, m, n, forbidden=0.3, n_meshes=8)
    exact = score_bucket(codes, vals, table)
    free, mask = table_parts(table)
    got = np.asarray(su(codes, vals, free, mask, gamma))
    ok = ~exact.unmatchable
    assert ok.sum() >= 4
    tol = 1e-5 * np.abs(exact.utility[ok]) + 1e-5
    assert np.all(got[ok] >= exact.utility[ok] - tol)  # soft >= max
    assert np.all(got[ok] <= exact.utility[ok] + gamma * math.log(n_paths(m, n)) + tol)
    assert np.all(got[exact.unmatchable] <= NEG / 2)


def test_soft_approaches_exact_monotonically():
    codes, vals, table = random_case(1, 10, 5, forbidden=0.0)
    free, mask = table_parts(table)
    exact = score_bucket(codes, vals, table).utility
    gaps = [np.asarray(su(codes, vals, free, mask, g)) - exact for g in (1.0, 0.3, 0.1, 0.03)]
    for a, b in zip(gaps, gaps[1:]):
        assert np.all(b <= a + 1e-5)
    assert np.all(gaps[-1] >= -1e-5)


def _grad(codes, vals, free, mask, gamma):
    return jax.grad(lambda t: su(codes, vals, t, mask, gamma).sum())(jnp.asarray(free))


@pytest.mark.parametrize("gamma", [1.0, 1e-2, 1e-3])
def test_gradients_finite_with_forbidden_rows_and_unmatchable_meshes(gamma):
    table = random_table(2, 0.3)
    table[V] = -np.inf  # concave points match nothing
    table[S, 3, 3, 3] = -np.inf
    codes = [S, X, V, S, S, X, V, S, X, S]
    vals = np.array([[3, 3, 2, 4, 2], [5, 5, 5, 5, 5], [2, 3, 4, 5, 3]])
    free, mask = table_parts(table)
    value = np.asarray(su(codes, vals, free, mask, gamma))
    assert np.isfinite(value).all()
    g = np.asarray(_grad(codes, vals, free, mask, gamma))
    assert np.isfinite(g).all()
    assert np.all(g[mask] == 0.0)  # forbidden entries: no gradient
    assert np.all(g[V] == 0.0)
    # an all-forbidden table: everything unmatchable, still finite
    none_free = np.ones((3, 4, 4, 4), bool)
    g0 = np.asarray(_grad(codes, vals, free, none_free, gamma))
    assert np.isfinite(g0).all() and np.all(g0 == 0.0)
    assert np.all(np.asarray(su(codes, vals, free, none_free, gamma)) <= NEG / 2)


def test_forbidden_entries_are_fixed():
    codes, vals, table = random_case(3, 9, 5, forbidden=0.4)
    free, mask = table_parts(table)
    other = np.where(mask, 1e6, free).astype(np.float32)  # values under the mask are ignored
    np.testing.assert_array_equal(
        np.asarray(su(codes, vals, free, mask, 0.5)), np.asarray(su(codes, vals, other, mask, 0.5))
    )


def test_gradient_is_expected_usage_summing_to_n():
    m, n = 9, 5
    codes, vals, table = random_case(4, m, n, forbidden=0.2)
    free, mask = table_parts(table)
    exact = score_bucket(codes, vals, table)
    for k in np.flatnonzero(~exact.unmatchable):
        g = _grad(codes, vals[k : k + 1], free, mask, 0.5)
        assert float(g.sum()) == pytest.approx(n, rel=1e-5)
        assert float(g.min()) >= 0.0


@pytest.mark.parametrize("gamma", [1.0, 1e-3])
def test_gradient_of_unmatchable_meshes_stays_bounded(gamma):
    # values of the size of NEG round in float32; the gradient must not blow up there
    rng = np.random.default_rng(11)
    m, n = 40, 12
    codes = rng.integers(0, 3, m)
    vals = rng.integers(2, 6, (16, n))
    table = random_table(11, 0.3)
    exact = score_bucket(codes, vals, table)
    assert exact.unmatchable.any()
    free, mask = table_parts(table)
    for k in np.flatnonzero(exact.unmatchable):
        g = np.asarray(_grad(codes, vals[k : k + 1], free, mask, gamma))
        assert np.isfinite(g).all() and g.min() >= 0.0 and g.sum() <= n * (1 + 1e-5)


def test_small_gamma_gradient_counts_the_unique_best_path():
    for seed in range(100):
        codes, vals, table = random_case(seed, 8, 4, forbidden=0.3, n_meshes=1)
        us = sorted((u for u, *_ in reference.all_utilities(codes, vals[0], table)), reverse=True)
        if us[0] > -math.inf and us[0] > us[1]:
            break
    best, r, refl, alignment = reference.brute_force(codes, vals[0], table)
    counts = np.zeros((3, 4, 4, 4))
    seq = score.oriented_sequence(vals[0], r, refl)
    for (u, v, w), i in zip(reference.triples(list(seq)), alignment):
        counts[codes[i], u - 2, v - 2, w - 2] += 1
    free, mask = table_parts(table)
    g = np.asarray(_grad(codes, vals, free, mask, 1e-2))
    np.testing.assert_allclose(g, counts, atol=1e-4)


def test_gradient_matches_finite_differences_float64():
    codes, vals, table = random_case(5, 8, 4, forbidden=0.3)
    free, mask = table_parts(table)
    gamma = 0.5
    with jax.enable_x64(True):
        t0 = jnp.asarray(free, jnp.float64)

        def f(t):
            return su(codes, vals, t, mask, gamma).sum()

        assert f(t0).dtype == jnp.float64
        g = np.asarray(jax.grad(f)(t0))
        used = np.argwhere(np.abs(g) > 1e-3)
        rng = np.random.default_rng(0)
        picks = [tuple(p) for p in used[rng.choice(len(used), size=min(12, len(used)), replace=False)]]
        picks.append(tuple(np.argwhere(mask)[0]))  # a forbidden entry: zero both ways
        eps = 1e-5
        for p in picks:
            e = np.zeros((3, 4, 4, 4))
            e[p] = eps
            fd = (float(f(t0 + e)) - float(f(t0 - e))) / (2 * eps)
            assert g[p] == pytest.approx(fd, rel=1e-6, abs=1e-8)
        # and w.r.t. gamma (entropy terms of the smoothed maxima)
        h = lambda gm: su(codes, vals, t0, mask, gm).sum()  # noqa: E731
        dg = float(jax.grad(h)(jnp.float64(gamma)))
        fd = (float(h(gamma + eps)) - float(h(gamma - eps))) / (2 * eps)
        assert dg == pytest.approx(fd, rel=1e-6)


def test_padding_does_not_change_soft_values():
    codes, vals, table = random_case(6, 11, 5)
    free, mask = table_parts(table)
    a = np.asarray(su(codes, vals, free, mask, 0.3))
    b = np.asarray(su(codes, vals, free, mask, 0.3, m_pad=32))
    np.testing.assert_array_equal(a, b)


def test_batch_over_shapes_matches_single_shapes():
    rng = np.random.default_rng(8)
    shapes = [rng.integers(0, 3, k) for k in (5, 9, 20)]
    vals = rng.integers(2, 6, (N_MESHES, 6))
    free, mask = table_parts(random_table(8, 0.2))
    codes, valid = pad_shapes(shapes)
    assert codes.shape == (3, 32) and valid.sum(axis=1).tolist() == [5, 9, 20]
    got = np.asarray(sub(codes, valid, vals, free, mask, 0.2))
    assert got.shape == (3, N_MESHES)
    assert np.all(got[0] <= NEG / 2)  # n = 6 > m = 5
    for s, shape in enumerate(shapes[1:], start=1):
        np.testing.assert_allclose(got[s], np.asarray(su(shape, vals, free, mask, 0.2, m_pad=32)), rtol=1e-6)
    g = jax.grad(lambda t: sub(codes, valid, vals, t, mask, 1e-3).sum())(jnp.asarray(free))
    assert np.isfinite(np.asarray(g)).all()


def test_soft_utility_is_jittable_with_traced_inputs():
    codes, vals, table = random_case(9, 7, 4)
    free, mask = table_parts(table)
    f = jax.jit(lambda c, v, t: su(c, v, t, mask, 0.1))
    np.testing.assert_allclose(
        np.asarray(f(jnp.asarray(codes), jnp.asarray(vals), jnp.asarray(free))),
        np.asarray(su(codes, vals, free, mask, 0.1)),
        rtol=1e-6,
    )


def test_table_parts():
    table = random_table(10, 0.5)
    free, mask = table_parts(table)
    assert free.dtype == np.float32 and np.isfinite(free).all()
    np.testing.assert_array_equal(mask, np.isinf(table))
    np.testing.assert_array_equal(free[~mask], table[~mask])


# --------------------------------------------------------------------------- skip weights


@pytest.mark.parametrize("skip", [(0.0, -2.0, -5.0), (1.0, -math.inf, -3.0), (-math.inf, 0.0, 0.0)])
@pytest.mark.parametrize("gamma", [0.5, 2.0])
def test_soft_with_skip_weights_is_the_log_partition_function(skip, gamma):
    rng = np.random.default_rng(11)
    codes, vals = rng.integers(0, 3, 7), rng.integers(2, 6, (3, 4))
    table = random_table(4, 0.2)
    model = make_weights(table, np.asarray(skip))
    got = np.asarray(soft_utility(codes, vals, model, gamma))
    for k, v in enumerate(vals):
        want = reference.brute_force_soft(codes, v, table, gamma, skip=np.asarray(skip))
        if want == -math.inf:
            assert got[k] <= NEG / 2
        else:
            assert got[k] == pytest.approx(want, rel=1e-5, abs=1e-4)


def test_skip_gradient_is_the_expected_number_of_skipped_points():
    """d soft / d skip[c] = expected count of skipped type-c points; -inf skip weights get none."""
    rng = np.random.default_rng(12)
    codes, vals = rng.integers(0, 3, 9), rng.integers(2, 6, (1, 5))
    table = random_table(5, 0.0)
    model = make_weights(table, [0.0, -1.0, -math.inf])
    gamma = 0.7
    g = np.asarray(jax.grad(lambda s: soft_utility(codes, vals, model, gamma, skip=s).sum())(jnp.asarray(model.skip)))
    assert g[2] == 0.0  # fixed at -inf: no gradient
    # expectation under the Gibbs distribution, by enumeration
    us = [(u, a) for u, _, _, a in reference.all_utilities(codes, vals[0], table, model.skip_inf()) if u > -math.inf]
    top = max(u for u, _ in us)
    p = np.array([math.exp((u - top) / gamma) for u, _ in us])
    p /= p.sum()
    for c in (0, 1):
        skipped = np.array([sum(1 for i in range(len(codes)) if i not in a and codes[i] == c) for _, a in us])
        assert g[c] == pytest.approx(float(p @ skipped), rel=1e-4, abs=1e-5)


def test_zero_skip_weights_give_the_same_soft_values():
    rng = np.random.default_rng(13)
    codes, vals = rng.integers(0, 3, 10), rng.integers(2, 6, (4, 5))
    table = random_table(6, 0.3)
    free, mask = table_parts(table)
    np.testing.assert_array_equal(np.asarray(su(codes, vals, free, mask, 0.4)),
                                  np.asarray(soft_utility(codes, vals, make_weights(table, np.zeros(3)), 0.4)))
