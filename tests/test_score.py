"""Exact scorer (jaxmatch.scoring.exact) against the plain-Python references."""

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from jaxmatch.catalogue import mesh
from jaxmatch.kernels import reference
from jaxmatch.errors import UnmatchableError
from jaxmatch.scoring.exact import (
    NEG,
    ScoreResult,
    align,
    bucket_length,
    dp_kind,
    finite_table,
    orientation_triples,
    oriented_sequence,
    score_bucket,
    utility_of,
    utility_parts,
)
from jaxmatch.kernels.model import make_weights, weights_of

S, X, V = 0, 1, 2


def random_table(seed: int, forbidden: float) -> np.ndarray:
    """Integer weights in -5..5, a fraction ``forbidden`` of them -inf."""
    rng = np.random.default_rng(seed)
    t = rng.integers(-5, 6, (3, 4, 4, 4)).astype(np.float32)
    t[rng.random(t.shape) < forbidden] = -np.inf
    return t


@st.composite
def cases(draw, max_n=6, max_m=9, max_meshes=4):
    """(codes, vals (N, n), table) with small n, m so brute force is cheap."""
    m = draw(st.integers(1, max_m))
    n = draw(st.integers(1, max_n))
    codes = np.array(draw(st.lists(st.integers(0, 2), min_size=m, max_size=m)), np.int32)
    n_meshes = draw(st.integers(1, max_meshes))
    vals = np.array(
        draw(st.lists(st.lists(st.integers(2, 5), min_size=n, max_size=n), min_size=n_meshes, max_size=n_meshes)),
        np.int32,
    )
    table = random_table(draw(st.integers(0, 2**32 - 1)), draw(st.sampled_from([0.0, 0.2, 0.5, 0.8, 1.0])))
    return codes, vals, table


# --------------------------------------------------------------------------- conventions


def test_oriented_sequence_convention():
    vals = [2, 3, 4, 5]
    assert oriented_sequence(vals, 0, False).tolist() == [2, 3, 4, 5]
    assert oriented_sequence(vals, 1, False).tolist() == [3, 4, 5, 2]  # s_r[0] = s[r]
    assert oriented_sequence(vals, 0, True).tolist() == [5, 4, 3, 2]
    assert oriented_sequence(vals, 1, True).tolist() == [4, 3, 2, 5]


@pytest.mark.parametrize("n", [1, 2, 3, 5, 8])
def test_orientation_triples_are_mesh_triples_of_oriented_sequences(n):
    vals = np.random.default_rng(n).integers(2, 6, (3, n))
    t = np.asarray(orientation_triples(vals))
    assert t.shape == (3, 2 * n, n, 3)
    for b in range(3):
        for o in range(2 * n):
            expect = mesh.triples(oriented_sequence(vals[b], o % n, o >= n))
            np.testing.assert_array_equal(t[b, o], expect)


def test_reflection_swaps_ccw_and_cw_neighbours():
    t = np.asarray(orientation_triples([[2, 3, 4, 5]]))[0]
    np.testing.assert_array_equal(t[4][:, [2, 1, 0]], mesh.triples([2, 3, 4, 5])[::-1])


def test_finite_table_replaces_minus_inf_by_neg():
    t = random_table(0, 0.5)
    f = np.asarray(finite_table(t))
    assert f.dtype == np.float32 and np.isfinite(f).all()
    np.testing.assert_array_equal(f[np.isinf(t)], NEG)
    np.testing.assert_array_equal(f[np.isfinite(t)], t[np.isfinite(t)])


@pytest.mark.parametrize("m, expected", [(1, 16), (16, 16), (17, 32), (64, 64), (128, 128), (129, 192)])
def test_bucket_length(m, expected):
    assert bucket_length(m) == expected


# --------------------------------------------------------------------------- against brute force


@given(cases())
def test_score_bucket_equals_brute_force(case):
    codes, vals, table = case
    res = score_bucket(codes, vals, table)
    assert isinstance(res, ScoreResult)
    assert res.utility.dtype == np.float32 and res.rotation.dtype == np.int32 and res.reflected.dtype == bool
    for k, v in enumerate(vals):
        best, rot, refl, _ = reference.brute_force(codes, v, table)
        assert res.utility[k] == best  # integers in float32: exact
        assert res.unmatchable[k] == (best == -math.inf)
        if best == -math.inf:
            assert res.rotation[k] == -1 and not res.reflected[k]
            continue
        # ties: smallest rotation, non-reflected first -- the enumeration order of brute_force
        assert (res.rotation[k], bool(res.reflected[k])) == (rot, refl)
        a = align(codes, v, table, int(res.rotation[k]), bool(res.reflected[k]))
        assert a.shape == (len(v),) and a.dtype == np.int32
        assert np.all(np.diff(a) > 0) and a[0] >= 0 and a[-1] < len(codes)
        assert utility_of(codes, v, table, res.rotation[k], res.reflected[k], a) == res.utility[k]


@pytest.mark.parametrize("seed", range(4))
def test_score_bucket_equals_dp_reference_on_larger_cases(seed):
    rng = np.random.default_rng(seed)
    m, n = 30, 10
    codes = rng.integers(0, 3, m)
    vals = rng.integers(2, 6, (6, n))
    table = random_table(seed, 0.3)
    res = score_bucket(codes, vals, table)
    expect = [reference.dp_reference(codes, v, table) for v in vals]
    np.testing.assert_array_equal(res.utility, np.array(expect, np.float32))


def test_align_any_orientation_achieves_its_dp_value():
    rng = np.random.default_rng(7)
    codes = rng.integers(0, 3, 9)
    table = random_table(7, 0.0)
    v = rng.integers(2, 6, 5)
    by_orientation = {}
    for u, r, refl, _ in reference.all_utilities(codes, v, table):
        by_orientation[(r, refl)] = max(u, by_orientation.get((r, refl), -math.inf))
    for (r, refl), best in by_orientation.items():
        a = align(codes, v, table, r, refl)
        assert utility_of(codes, v, table, r, refl, a) == best


@given(st.integers(1, 40), st.integers(1, 14), st.sampled_from(["zero", "neg", "must"]), st.integers(0, 2**32 - 1))
def test_dp_rows_are_the_rows_of_dp_scan(m, n, skip, seed):
    """align's numpy rows (dp_rows) equal the JAX recurrence dp_scan (keep_rows) bit for bit."""
    import jax.numpy as jnp

    from jaxmatch.scoring.exact import dp_rows, dp_scan
    from jaxmatch.kernels.model import skip_frame

    rng = np.random.default_rng(seed)
    codes, seq = rng.integers(0, 3, m), rng.integers(2, 6, n)
    sk = np.zeros(3) if skip == "zero" else rng.integers(-3, 1, 3).astype(np.float64)
    if skip == "must":
        sk[rng.integers(0, 3)] = -np.inf
    w = make_weights(random_table(seed, 0.3), sk)
    fr = skip_frame(w)
    t = np.stack([np.roll(seq, -1), seq, np.roll(seq, 1)], axis=-1) - 2
    wc = fr.table.astype(np.float32).reshape(3, 64)[:, t[:, 0] * 16 + t[:, 1] * 4 + t[:, 2]]
    gate = np.where(fr.gate, NEG, 0.0).astype(np.float32)
    _, rows = dp_scan(jnp.asarray(wc), jnp.asarray(codes), jnp.ones(m, bool), jnp.maximum, gate=jnp.asarray(gate), keep_rows=True)
    np.testing.assert_array_equal(dp_rows(codes, seq, w), np.asarray(rows))


@pytest.mark.skipif(__import__("jaxmatch.kernels.backends", fromlist=["c_kernel"]).c_kernel() is None,
                    reason="the C kernel (jaxmatch.kernels._dp) is not built")
@given(st.integers(1, 40), st.integers(1, 14), st.sampled_from(["zero", "neg", "must"]), st.integers(0, 2**32 - 1),
       st.integers(0, 13), st.booleans(), st.booleans())
def test_align_in_c_is_align_in_numpy(m, n, skip, seed, rotation, reflected, strided):
    """align's C rows and backtrack give numpy's alignment (ties included: integer weights make
    many) or both find none; strided codes (a view) too."""
    from jaxmatch.kernels import backends

    rng = np.random.default_rng(seed)
    codes, vals = rng.integers(0, 3, 2 * m), rng.integers(2, 6, n)
    codes = codes[::2] if strided else codes[:m]
    sk = np.zeros(3) if skip == "zero" else rng.integers(-3, 1, 3).astype(np.float64)
    if skip == "must":
        sk[rng.integers(0, 3)] = -np.inf
    w = make_weights(random_table(seed, 0.3), sk)
    r = rotation % n

    def run():
        try:
            return align(codes, vals, w, r, reflected)
        except UnmatchableError as e:
            return str(e)

    in_c = run()
    saved = backends._C_DP[:]
    backends._C_DP[:] = [None, True]  # as if not built: numpy
    try:
        in_numpy = run()
    finally:
        backends._C_DP[:] = saved
    if isinstance(in_numpy, str):
        assert in_c == in_numpy
    else:
        assert in_c.dtype == in_numpy.dtype == np.int32
        np.testing.assert_array_equal(in_c, in_numpy)


# --------------------------------------------------------------------------- unmatchable, padding


def test_mixed_batch_reports_unmatchable_and_never_ranks_them():
    # convex points only match valence-2 vertices; straight points anything but 2
    table = np.full((3, 4, 4, 4), -np.inf, np.float32)
    table[X, :, 0, :] = 3.0
    table[S, :, 1:, :] = 1.0
    codes = [X, S, S, X, S, S, X, S, S, X, S, S]  # a square: 4 corners, 2 straights per side
    vals = np.array(
        [
            [2, 3, 3, 2, 3, 3, 2, 3, 3, 2, 3, 3],  # the 3x3 grid: perfect fit
            [2, 3, 3, 2, 3, 3, 2, 3, 3, 3, 3, 3],  # 3 corners for 4 convex points, n == m: no skipping
            [3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3, 3],  # no valence 2: convex points cannot be matched
            [2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2],  # only valence 2: straights cannot be matched
        ],
        np.int32,
    )
    res = score_bucket(codes, vals, table)
    expect = [reference.brute_force(codes, v, table)[0] for v in vals]
    np.testing.assert_array_equal(res.utility, np.array(expect, np.float32))
    assert res.utility[0] == 4 * 3 + 8 * 1
    assert res.unmatchable.tolist() == [False, True, True, True]
    assert np.isneginf(res.utility[1:]).all() and (res.rotation[1:] == -1).all()


def test_longer_mesh_than_shape_is_unmatchable():
    table = np.zeros((3, 4, 4, 4), np.float32)
    res = score_bucket([S, S, S], [[2, 2, 2, 2], [3, 3, 3, 3]], table)
    assert res.unmatchable.all() and np.isneginf(res.utility).all()
    with pytest.raises(UnmatchableError):
        align([S, S, S], [2, 2, 2, 2], table, 0, False)


def test_all_forbidden_table():
    table = np.full((3, 4, 4, 4), -np.inf, np.float32)
    res = score_bucket([S, X, V, S, X], [[2, 3, 4], [5, 5, 5]], table)
    assert res.unmatchable.all() and np.isneginf(res.utility).all()
    with pytest.raises(UnmatchableError):
        align([S, X, V, S, X], [2, 3, 4], table, 0, False)


def test_padding_does_not_change_results():
    rng = np.random.default_rng(3)
    codes = rng.integers(0, 3, 13)
    vals = rng.integers(2, 6, (21, 6))
    table = random_table(3, 0.4)
    base = score_bucket(codes, vals, table)
    assert base.unmatchable.any() and not base.unmatchable.all()  # a mixed batch
    for m_pad in (16, 48):
        for batch in (8, 256):
            res = score_bucket(codes, vals, table, m_pad=m_pad, batch=batch)
            for a, b in zip(res, base):
                np.testing.assert_array_equal(a, b)
    one_by_one = [score_bucket(codes, v[None], table) for v in vals]
    np.testing.assert_array_equal(np.concatenate([r.utility for r in one_by_one]), base.utility)
    with pytest.raises(ValueError):
        score_bucket(codes, vals, table, m_pad=8)


def test_ties_prefer_smallest_rotation_then_unreflected():
    res = score_bucket([S] * 8, [[2, 3, 4, 5, 3]], np.zeros((3, 4, 4, 4), np.float32))
    assert (res.utility[0], res.rotation[0], res.reflected[0]) == (0.0, 0, False)


def test_reflection_can_win():
    vals = [2, 2, 3, 5]
    reflected_triples = mesh.triples(vals[::-1])
    table = np.full((3, 4, 4, 4), -np.inf, np.float32)
    for u, v, w in reflected_triples:
        table[:, u - 2, v - 2, w - 2] = 1.0
    assert not any(np.isfinite(table[0, u - 2, v - 2, w - 2]) for u, v, w in mesh.triples(vals))
    res = score_bucket([S, S, S, S], [vals], table)
    assert (res.utility[0], res.rotation[0], res.reflected[0]) == (4.0, 0, True)
    a = align([S, S, S, S], vals, table, 0, True)
    assert a.tolist() == [0, 1, 2, 3]


def test_empty_bucket():
    res = score_bucket([S, S], np.zeros((0, 4), np.int32), np.zeros((3, 4, 4, 4), np.float32))
    assert all(a.shape == (0,) for a in res)


@pytest.mark.parametrize(
    "codes, vals",
    [([S, 3], [[2, 2, 2]]), ([S, -1], [[2, 2, 2]]), ([S, S], [[1, 2, 2]]), ([S, S], [[2, 6, 2]])],
)
def test_bad_input_raises(codes, vals):
    with pytest.raises(ValueError):
        score_bucket(codes, vals, np.zeros((3, 4, 4, 4), np.float32))


def test_utility_of_rejects_bad_alignments():
    table = np.zeros((3, 4, 4, 4), np.float32)
    for bad in ([0, 0, 1], [0, 1], [1, 2, 5], [-1, 0, 1]):
        with pytest.raises(ValueError):
            utility_of([S] * 5, [2, 3, 4], table, 0, False, bad)


# --------------------------------------------------------------------------- skip weights

SKIP_CHOICES = [0.0, -1.0, -3.0, -7.0, 2.0, -math.inf]


@st.composite
def skip_cases(draw, max_n=5, max_m=8, max_meshes=3):
    """(codes, vals, table, skip): small cases with a skip weight per type (ints or -inf)."""
    codes, vals, table = draw(cases(max_n=max_n, max_m=max_m, max_meshes=max_meshes))
    skip = np.array([draw(st.sampled_from(SKIP_CHOICES)) for _ in range(3)], np.float32)
    return codes, vals, table, skip


@given(skip_cases())
def test_skip_weights_equal_brute_force(case):
    """D[i][j] = max(D[i-1][j] + skip[code], D[i-1][j-1] + W): best utility, winning orientation,
    and an alignment whose utility (matched + skipped) is that utility, as the brute force says."""
    codes, vals, table, skip = case
    model = make_weights(table, skip)
    res = score_bucket(codes, vals, model)
    for k, v in enumerate(vals):
        best, rot, refl, _ = reference.brute_force(codes, v, table, skip)
        assert res.utility[k] == best
        assert res.unmatchable[k] == (best == -math.inf)
        if best == -math.inf:
            continue
        assert (res.rotation[k], bool(res.reflected[k])) == (rot, refl)
        a = align(codes, v, model, int(res.rotation[k]), bool(res.reflected[k]))
        parts = utility_parts(codes, v, model, res.rotation[k], res.reflected[k], a)
        assert parts.total == utility_of(codes, v, model, res.rotation[k], res.reflected[k], a) == res.utility[k]
        skipped = np.setdiff1d(np.arange(len(codes)), a)
        assert parts.skip == float(np.sum(skip[np.asarray(codes)[skipped]])) and parts.match + parts.skip == parts.total
        must = np.flatnonzero(np.isneginf(skip))
        assert not np.isin(np.asarray(codes)[skipped], must).any()  # a -inf type is never skipped


@given(cases())
def test_zero_skip_weights_are_the_papers_free_skipping(case):
    codes, vals, table = case
    res = score_bucket(codes, vals, make_weights(table, np.zeros(3)))
    expect = [reference.brute_force(codes, v, table)[0] for v in vals]  # no skip argument at all
    np.testing.assert_array_equal(res.utility, np.array(expect, np.float32))
    assert not make_weights(table, np.zeros(3)).has_skip


@pytest.mark.parametrize("scale, dtype", [(1.0, np.int16), (1000.0, np.int32), (0.5, np.float32)])
@pytest.mark.parametrize("skip", [(0, -4, -9), (-1000, -1000, 0), (3, -math.inf, -2), (-math.inf, -math.inf, -math.inf)])
def test_every_number_type_with_skip_weights_equals_the_dp_reference(scale, dtype, skip):
    """int16 / int32 / float32 kernels, with large negative and -inf skip weights (sentinel arithmetic)."""
    rng = np.random.default_rng(int(scale * 10) + len(str(skip)))
    codes, vals = rng.integers(0, 3, 23), rng.integers(2, 6, (9, 7))
    table = (rng.integers(-5, 6, (3, 4, 4, 4)) * scale).astype(np.float32)
    table[rng.random(table.shape) < 0.2] = -np.inf
    model = make_weights(table, np.asarray(skip, np.float64) * (scale if abs(scale) < 10 else 1))
    if skip != (-1000, -1000, 0) or scale == 1.0:
        assert dp_kind(model, 7).dtype == dtype
    expect = np.array([reference.dp_reference(codes, v, table, model.skip_inf()) for v in vals], np.float32)
    np.testing.assert_array_equal(score_bucket(codes, vals, model).utility, expect)


def test_int16_range_holds_with_large_skip_weights():
    """|W - skip| * n must fit: the kernel widens to int32 when it would not."""
    table = np.ones((3, 4, 4, 4), np.float32)
    assert dp_kind(make_weights(table, [-1000, 0, 0]), 8).dtype == np.int16  # 8 * 1001 < 2**13
    assert dp_kind(make_weights(table, [-1000, 0, 0]), 9).dtype == np.int32
    codes = [0] * 40
    vals = np.full((2, 9), 3)
    res = score_bucket(codes, vals, make_weights(table, [-1000, 0, 0]))
    np.testing.assert_array_equal(res.utility, np.float32(9 - 31 * 1000))


def test_must_match_points_make_too_short_meshes_unmatchable():
    table = np.zeros((3, 4, 4, 4), np.float32)
    model = make_weights(table, [0, -math.inf, 0])
    codes = [X, S, S, X, S, S, X, S, S, X, S, S]
    assert score_bucket(codes, [[3, 3, 3]], model).unmatchable.tolist() == [True]  # 4 convex points need 4 vertices
    assert score_bucket(codes, [[3, 3, 3, 3, 3]], model).unmatchable.tolist() == [False]
    with pytest.raises(UnmatchableError):
        align(codes, [3, 3, 3], model, 0, False)
    a = align(codes, [3, 3, 3, 3, 3], model, 0, False)
    assert set(np.flatnonzero(np.asarray(codes) == X)) <= set(a.tolist())


def test_a_skip_penalty_keeps_the_concave_corner():
    """Free skipping lets a mesh drop a concave corner for a better straight match; a penalty on
    skipping v (or -inf) makes the alignment take it."""
    table = np.full((3, 4, 4, 4), -np.inf, np.float32)
    table[S] = 1.0
    table[X, :, 0, :] = 2.0  # valence 2 on convex corners
    table[V, :, 2, :] = -1.0  # valence 4 on the concave corner, worth less than a straight match
    codes = [X, S, X, S, V, S, X, S, X, S]  # an L-like sequence
    vals = [[2, 3, 2, 3, 4, 3, 2, 2]]  # two points fewer than the shape
    free = score_bucket(codes, vals, table)
    al = align(codes, vals[0], table, int(free.rotation[0]), bool(free.reflected[0]))
    assert free.utility[0] == 11 and 4 not in al.tolist()  # free skipping drops the concave corner
    for skip in ([0, -20, -20], [0, -math.inf, -math.inf]):
        model = make_weights(table, skip)
        res = score_bucket(codes, vals, model)
        al = align(codes, vals[0], model, int(res.rotation[0]), bool(res.reflected[0]))
        assert res.utility[0] == 10 and {0, 2, 4, 6, 8} <= set(al.tolist())  # every corner has a mesh vertex


def test_weights_of_accepts_tables_lattices_and_weights():
    from jaxmatch.scoring.lattice import load_lattice

    t = random_table(1, 0.3)
    w = weights_of(t)
    assert weights_of(w) is w and w.skip.tolist() == [0, 0, 0] and not w.must.any()
    np.testing.assert_array_equal(w.table_inf(), t)
    lat = load_lattice("fine")
    lw = weights_of(lat)
    np.testing.assert_array_equal(lw.table_inf(), lat.table())
    assert lw.skip_inf().tolist() == [float(x) for x in lat.skip]
    with pytest.raises(ValueError):
        weights_of(lat, skip=[0, 0, 0])
    with pytest.raises(ValueError):
        make_weights(t, [0, 0])
    assert not w.table.flags.writeable  # frozen


@pytest.mark.parametrize("skip", [(0, 0, 0), (0, -15, -15), (0, -math.inf, -math.inf)])
def test_ranked_matches_carry_the_skip_contribution(skip):
    """rank(): utility = match_utility + skip_utility, utility_of reproduces it from the alignment,
    and the JSON record carries both parts."""
    from dataclasses import replace

    from jaxmatch.catalogue.store import default_catalogue
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.scoring.rank import rank
    from jaxmatch.io.readers import load_shape

    lat = replace(load_lattice("fine"), skip=skip)
    shape = load_shape(Path(__file__).resolve().parents[1] / "examples" / "lshape.json")
    r = rank(shape, default_catalogue(), lat, internal=[2], top=3, tie_break="id", prune=True)
    vals = {b_id: v for b in default_catalogue().buckets([2]) for b_id, v in zip(b.ids, b.valences)}
    corners = np.flatnonzero(np.asarray(r.annotation.codes) != 0)
    for m in r.results:
        assert m.match_utility + m.skip_utility == m.utility
        assert utility_of(r.annotation.codes, vals[m.mesh_id], lat, m.rotation, m.reflected, m.alignment) == m.utility
        skipped = np.setdiff1d(np.arange(len(r.annotation.codes)), m.alignment)
        assert m.skip_utility == sum(0 if math.isinf(skip[c]) else skip[c] for c in np.asarray(r.annotation.codes)[skipped])
        d = m.as_json()
        assert d["match_utility"] == m.match_utility and d["skip_utility"] == m.skip_utility
        if math.isinf(skip[2]):
            assert np.isin(corners, m.alignment).all()


class _NumpyBackend:
    """A second backend for the exact host, plain numpy (the seam's contract: raw shifted-frame
    values ``(S, meshes, 2n)`` in the problem's number type, mesh-major)."""

    mesh_lanes = 1

    def __init__(self):
        self.calls = 0

    def run(self, problem, vals):
        self.calls += vals.shape[0]
        tab, gate, neg = problem.tab.astype(np.int64), problem.gate.astype(np.int64), problem.kind.neg
        meshes = vals.reshape(-1, problem.n)
        out = np.empty((problem.codes.shape[0], meshes.shape[0], 2 * problem.n), np.int64)
        for s, codes in enumerate(problem.codes):
            for b, v in enumerate(meshes):
                for o in range(2 * problem.n):
                    seq = oriented_sequence(v, o % problem.n, o >= problem.n)
                    t = mesh.triples(seq) - 2
                    w = tab[:, t[:, 0] * 16 + t[:, 1] * 4 + t[:, 2]]  # (4, n)
                    d, z = np.full(problem.n, neg, np.int64), 0
                    for c in codes:
                        shifted = np.concatenate([[z], d[:-1]]) + w[c]
                        d, z = np.maximum(np.minimum(d, gate[c]), shifted), min(z, gate[c])
                    out[s, b, o] = d[-1]
        return out.astype(problem.kind.dtype)


@pytest.mark.parametrize("skip", [(0, 0, 0), (0, -6, -math.inf)])
def test_a_second_backend_plugs_into_the_exact_host(skip):
    from jaxmatch.scoring.exact import exact_values

    rng = np.random.default_rng(21)
    model = make_weights(random_table(21, 0.2), np.asarray(skip, np.float64))
    shapes = [rng.integers(0, 3, 11), rng.integers(0, 3, 7)]
    vals = rng.integers(2, 6, (5, 4))
    be = _NumpyBackend()
    got = exact_values(shapes, vals, model, backend=be)
    assert be.calls >= 1 and got.shape == (2, 5, 8)
    np.testing.assert_array_equal(got, exact_values(shapes, vals, model))
    for s, codes in enumerate(shapes):
        expect = [reference.dp_reference(codes, v, model.table_inf(), model.skip_inf()) for v in vals]
        np.testing.assert_array_equal(got[s].max(axis=1), np.array(expect, np.float32))


def test_lazy_matches_head_without_making_the_match():
    """``LazyMatches.head(i)`` names the i-th match (in a reordered view too) as the made match
    does, and makes nothing."""
    from jaxmatch.scoring.rank import LazyMatches, Match

    made = []

    def make(row):
        made.append(row)
        return Match(row[3], row[1], row[2], row[0], row[4], row[5], np.arange(row[2]), np.zeros((row[2], 3)), 0.0, 0.0)

    rows = [(3.0, 1, 6, "b", 2, True, None), (5.0, 0, 4, "a", 0, False, None), (4.0, 2, 8, "c", 5, False, None)]
    lm = LazyMatches(rows, make).reordered(lambda r: -r[0])
    heads = [lm.head(i) for i in range(len(lm))]
    assert not made and heads == [("a", 0, 0, False), ("c", 2, 5, False), ("b", 1, 2, True)]
    assert heads == [(m.mesh_id, m.internal_vertices, m.rotation, m.reflected) for m in lm]


@given(st.lists(st.integers(2, 5), min_size=1, max_size=24), st.integers(-50, 50), st.booleans())
def test_oriented_sequence_and_triples_are_the_rolls(vals, rotation, reflected):
    """``oriented_sequence`` is ``np.roll(vals[::-1] if reflected else vals, -rotation)`` and
    ``triples`` stacks its rolls ``[next, self, previous]`` (both without ``np.roll``)."""
    from jaxmatch.catalogue.mesh import triples
    from jaxmatch.scoring.exact import oriented_sequence

    v = np.asarray(vals, np.int32)
    seq = oriented_sequence(v, rotation, reflected)
    assert seq.tolist() == np.roll(v[::-1] if reflected else v, -rotation).tolist()
    t = triples(seq)
    assert t.dtype == np.int32 and t.tolist() == np.stack([np.roll(seq, -1), seq, np.roll(seq, 1)], axis=-1).tolist()
