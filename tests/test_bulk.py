"""Bulk scoring (jaxmatch.scoring.bulk) and the fast exact kernel of jaxmatch.scoring.exact.

Everything is compared with the plain exhaustive scorer (score_bucket on every mesh) or the
Python references. The multi-device checks run in a subprocess with 4 simulated CPU devices
(``XLA_FLAGS`` must be set before JAX is imported, and this process has imported it already).
"""

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.scoring import bulk
from jaxmatch.kernels import reference
from jaxmatch.catalogue.store import Bucket, default_catalogue
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.scoring.exact import (
    DPKind,
    NEG,
    dp_kind,
    dp_table,
    final_values,
    orientation_slabs,
    orientation_weights,
    reduce_orientations,
    score_bucket,
)
from jaxmatch.kernels.model import make_weights
from jaxmatch.io.readers import load_shape
from jaxmatch.shape import annotate

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ["circle.json", "lshape.json", "tshape.json", "hexagon.json"]


def random_table(seed: int, forbidden: float, scale: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = (rng.integers(-5, 6, (3, 4, 4, 4)) * scale).astype(np.float32)
    t[rng.random(t.shape) < forbidden] = -np.inf
    return t


SKIPS = [(0, 0, 0), (0, -3, -5), (-2, -20, -math.inf), (1, -math.inf, -math.inf), (-1000, 0, 2)]
"""Skip weight vectors the bulk paths are checked with (free, costly corners, must-match, extremes)."""


def random_model(seed: int, forbidden: float, scale: float = 1.0, skip=None):
    """A scoring model: random_table plus skip weights (drawn from SKIPS unless given)."""
    rng = np.random.default_rng(seed + 1)
    sk = SKIPS[int(rng.integers(len(SKIPS)))] if skip is None else skip
    return make_weights(random_table(seed, forbidden, scale), np.asarray(sk, np.float64))


def same(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(a, b))


@pytest.fixture(scope="module")
def small_parts():
    """The default catalogue's meshes with k <= 3 (112 meshes, n = 4..12), grouped."""
    return bulk.prepare(default_catalogue().buckets([0, 1, 2, 3]))


@pytest.fixture(scope="module")
def fine():
    return load_lattice("fine").table()


# --------------------------------------------------------------------------- the fast kernel


@pytest.mark.parametrize("n", [1, 3, 6])
def test_orientation_slabs_are_orientation_weights(n):
    vals = np.random.default_rng(n).integers(2, 6, (3, n))
    table = random_table(n, 0.2)
    kind = dp_kind(table, n)
    slabs = np.asarray(orientation_slabs(vals, dp_table(table, kind)))  # (4, n, 2n * B), orientation-major
    ref = np.asarray(orientation_weights(vals, np.asarray(dp_table(table, DPKind(np.float32, NEG)))[:3].reshape(3, 4, 4, 4)))
    ref = np.where(ref > NEG / 2, ref, kind.neg)
    got = slabs[:3].reshape(3, n, 2 * n, 3).transpose(0, 1, 3, 2)  # -> (3, n, B, 2n)
    np.testing.assert_array_equal(got, ref.astype(got.dtype))
    assert np.all(slabs[3] == kind.neg)


def test_dp_kind_picks_the_narrowest_exact_type():
    assert dp_kind(load_lattice("fine").table(), 34).dtype == np.int16
    assert dp_kind(random_table(0, 0.3, scale=1000.0), 10).dtype == np.int32
    assert dp_kind(random_table(0, 0.3, scale=0.5), 10).dtype == np.float32
    assert dp_kind(np.full((3, 4, 4, 4), -np.inf), 5).dtype == np.int16


def test_dp_kinds_reads_the_model_once_for_every_length():
    """``dp_kinds`` gives each length the type of the rule ``n * max|W'|`` against ``2**13`` and
    ``2**29`` (integer weights; float32 otherwise): with weights up to 1000 the int16 range ends
    at n = 8 and int32 goes on."""
    from jaxmatch.scoring.exact import dp_kinds

    table = np.where(np.arange(192).reshape(3, 4, 4, 4) % 2, 1000.0, -np.inf)
    kinds = dp_kinds(table, [1, 8, 9, 100])
    assert [kinds[n].dtype for n in (1, 8, 9, 100)] == [np.int16, np.int16, np.int32, np.int32]
    assert dp_kinds(random_table(0, 0.3, scale=0.5), [3, 10])[10].dtype == np.float32
    assert all(dp_kind(table, n) == k for n, k in kinds.items())


def test_exact_values_takes_the_callers_problem(fine):
    """A problem built once per number type (what top_k does for its parts) gives the values that
    exact_values builds for itself; one for another boundary length is refused."""
    from jaxmatch.scoring.exact import dp_problem, exact_values

    codes = annotate(load_shape(ROOT / "examples" / "lshape.json"), 24).codes
    vals = np.random.default_rng(1).integers(2, 6, size=(9, 6)).astype(np.int32)
    prob = dp_problem([codes], fine, 8)._replace(n=6)
    np.testing.assert_array_equal(exact_values([codes], vals, fine, problem=prob), exact_values([codes], vals, fine))
    np.testing.assert_array_equal(final_values(codes, vals, fine, problem=prob), final_values(codes, vals, fine))
    with pytest.raises(ValueError, match="boundary length 8"):
        exact_values([codes], vals, fine, problem=dp_problem([codes], fine, 8))


@given(st.integers(0, 2**32 - 1), st.sampled_from([1.0, 1000.0, 0.5]), st.sampled_from([0.0, 0.3, 0.9]))
@settings(max_examples=20)
def test_every_number_type_gives_the_reference_utilities(seed, scale, forbidden):
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(1, 12)), int(rng.integers(1, 7))
    codes, vals = rng.integers(0, 3, m), rng.integers(2, 6, (3, n))
    model = random_model(seed, forbidden, scale)
    res = score_bucket(codes, vals, model)
    expect = np.array([reference.dp_reference(codes, v, model.table_inf(), model.skip_inf()) for v in vals], np.float32)
    np.testing.assert_array_equal(res.utility, expect)


def test_threads_and_chunking_do_not_change_results(fine):
    rng = np.random.default_rng(3)
    codes, vals = rng.integers(0, 3, 40), rng.integers(2, 6, (100, 14))
    base = final_values(codes, vals, fine, threads=1)
    np.testing.assert_array_equal(final_values(codes, vals, fine, threads=3, batch=16), base)
    np.testing.assert_array_equal(final_values(codes, vals, fine, plan=(2, 3), m_pad=64), base)


# --------------------------------------------------------------------------- distinct sequences


@given(st.one_of(st.integers(1, 9), st.sampled_from([30, 31, 32, 37])), st.integers(1, 40), st.integers(0, 2**32 - 1))
def test_group_sequences_maps_every_orientation(n, count, seed):
    rng = np.random.default_rng(seed)
    base = rng.integers(2, 6, (max(count // 4, 1), n))
    # rotations / reflections of a few sequences, so groups really share
    vals = []
    for _ in range(count):
        v = base[rng.integers(len(base))]
        v = v[::-1] if rng.random() < 0.5 else v
        vals.append(np.roll(v, int(rng.integers(n))))
    vals = np.array(vals)
    g = bulk.group_sequences(vals)
    o_mesh, o_rep = bulk._orientations(vals.astype(np.int32)), bulk._orientations(g.seqs)
    np.testing.assert_array_equal(o_mesh, o_rep[g.index[:, None], g.orient])
    assert len(g.seqs) <= len(base)
    # representatives are distinct up to rotation and reflection
    keys = {min(tuple(r) for r in bulk._orientations(s[None])[0]) for s in g.seqs}
    assert len(keys) == len(g.seqs)
    # each representative is its group's lexicographically smallest orientation, in sorted order
    # (the int64-key path for n <= 31 and the row-wise path above it give the same arrays)
    assert [tuple(s) for s in g.seqs] == sorted(keys)


def test_fan_out_gives_score_bucket_results_including_orientation_ties(fine):
    # symmetric sequences tie between orientations: the mesh's own smallest index must win
    vals = np.array([[2, 3, 3, 2, 3, 3], [3, 3, 2, 3, 3, 2], [3, 2, 3, 3, 2, 3], [2, 3, 2, 3, 2, 3], [3, 2, 3, 2, 3, 2]])
    for codes in ([1, 0, 0, 1, 0, 0, 1, 0], [0] * 12, [1, 2, 0, 1, 0, 2, 1, 0, 0]):
        assert same(bulk.score_distinct(codes, vals, fine), score_bucket(codes, vals, fine))


@given(st.integers(0, 2**32 - 1))
@settings(max_examples=25)
def test_score_distinct_equals_score_bucket(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 8))
    base = rng.integers(2, 6, (4, n))
    vals = np.array([np.roll(base[i % 4][:: (-1) ** i], i) for i in range(12)])
    codes = rng.integers(0, 3, int(rng.integers(n, 16)))
    model = random_model(seed, float(rng.choice([0.0, 0.4, 0.9])))
    assert same(bulk.score_distinct(codes, vals, model), score_bucket(codes, vals, model))


# --------------------------------------------------------------------------- bounds


@given(st.integers(0, 2**32 - 1), st.sampled_from([0.0, 0.3, 0.8]))
@settings(max_examples=60)
def test_upper_bound_is_above_the_exact_utility(seed, forbidden):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 7))
    seqs = rng.integers(2, 6, (5, n))
    codes = rng.integers(0, 3, int(rng.integers(1, 11)))
    model = random_model(seed, forbidden)
    table, skip = model.table_inf(), model.skip_inf()
    ub = bulk.upper_bounds(seqs, codes, model)
    finite = np.where(np.isfinite(table), table, NEG)
    for s, b in zip(seqs, ub):
        exact = reference.dp_reference(codes, s, table, skip)
        if n > len(codes):
            assert b == -math.inf
        elif exact > -math.inf:
            assert b >= exact
        elif not model.has_skip:  # unmatchable: the bound only promises >= the NEG-substituted optimum
            assert b >= reference.dp_reference(codes, s, finite, skip) - 1e-3
        if b <= NEG / 2:
            assert exact == -math.inf


# --------------------------------------------------------------------------- pruned top K


def exhaustive_rows(codes, parts, table, top, per_size):
    """The ranking of pipeline.rank from score_bucket on every mesh: best ``top`` (per k) + ties."""
    rows = []
    for p in parts:
        res = score_bucket(codes, p.valences, table)
        for i in np.flatnonzero(~res.unmatchable):
            rows.append((float(res.utility[i]), int(p.k[i]), p.n, str(p.ids[i]), int(res.rotation[i]), bool(res.reflected[i])))
    return [r[:6] for r in bulk._select(rows, top, per_size)]


@pytest.mark.parametrize("shape, skip", [("lshape.json", (0, -10, -10)), ("tshape.json", (0, -math.inf, -math.inf))])
def test_pruned_top_k_equals_exhaustive_with_corner_skip_weights(shape, skip, small_parts):
    """Skip penalties on corners: the bound (shifted frame + offset) must stay an upper bound."""
    model = make_weights(load_lattice("fine").table(), np.asarray(skip, np.float64))
    codes = annotate(load_shape(ROOT / "examples" / shape), 24).codes
    expect = exhaustive_rows(codes, small_parts, model, 3, True)
    got = bulk.top_k(codes, small_parts, model, top=3, per_size=True, round_size=4)
    assert [r[:6] for r in got.rows] == expect and got.pruned > 0


@pytest.mark.parametrize("shape", EXAMPLES)
@pytest.mark.parametrize("per_size", [False, True])
@pytest.mark.parametrize("m", [12, 24])
def test_pruned_top_k_equals_exhaustive_on_examples(shape, per_size, m, small_parts, fine):
    codes = annotate(load_shape(ROOT / "examples" / shape), m).codes
    expect = exhaustive_rows(codes, small_parts, fine, 3, per_size)
    for prune in (True, False):
        got = bulk.top_k(codes, small_parts, fine, top=3, per_size=per_size, prune=prune, round_size=4)
        assert [r[:6] for r in got.rows] == expect
        assert got.total == 112 and got.scored + got.pruned <= got.total
        if not prune:
            assert got.pruned == 0


@given(seed=st.integers(0, 2**32 - 1), top=st.integers(1, 6), per_size=st.booleans(), forbidden=st.sampled_from([0.0, 0.3, 0.7]))
@settings(max_examples=40)
def test_pruned_top_k_equals_exhaustive_random(seed, top, per_size, forbidden, small_parts):
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, 3, int(rng.integers(8, 17)))  # one padded length: one compilation
    model = random_model(seed, forbidden)
    got = bulk.top_k(codes, small_parts, model, top=top, per_size=per_size, round_size=int(rng.integers(1, 20)))
    assert [r[:6] for r in got.rows] == exhaustive_rows(codes, small_parts, model, top, per_size)
    assert got.scored + got.pruned + got.unmatchable >= got.total


@given(seed=st.integers(0, 2**32 - 1), top=st.integers(1, 6), per_size=st.booleans(), forbidden=st.sampled_from([0.0, 0.3, 0.7]))
@settings(max_examples=25)
def test_top_k_of_one_round_equals_exhaustive(seed, top, per_size, forbidden, small_parts):
    """With no more sequences than one round scores, top_k scores them all without bounds: the
    same rows as the exhaustive ranking, unmatchable sequences (forbidden types) included."""
    rng = np.random.default_rng(seed)
    codes = rng.integers(0, 3, int(rng.integers(8, 17)))
    model = random_model(seed, forbidden)
    got = bulk.top_k(codes, small_parts, model, top=top, per_size=per_size, round_size=10**6)
    assert [r[:6] for r in got.rows] == exhaustive_rows(codes, small_parts, model, top, per_size)
    assert got.pruned == 0 and got.scored + got.unmatchable >= got.total


def test_pruning_skips_most_of_the_catalogue(small_parts, fine):
    codes = annotate(load_shape(ROOT / "examples" / "lshape.json"), 24).codes
    got = bulk.top_k(codes, small_parts, fine, top=1, round_size=4)
    assert got.pruned > got.total // 2


def test_top_k_accepts_buckets_and_streams_them(fine):
    cat = default_catalogue()
    seen = []

    def buckets():
        for b in cat.buckets([0, 1, 2]):
            seen.append(b.n)
            yield b

    codes = annotate(load_shape(ROOT / "examples" / "square.json"), 16).codes
    got = bulk.top_k(codes, buckets(), fine, top=2)
    assert seen == sorted(seen) and got.total == 16
    assert [r[:6] for r in got.rows] == exhaustive_rows(codes, bulk.prepare(cat.buckets([0, 1, 2])), fine, 2, False)


def test_top_k_with_unmatchable_parts(fine):
    # a bucket longer than the shape: unmatchable by length, never scored
    parts = bulk.prepare([Bucket(4, np.array(["a", "b"]), np.array([0, 1]), np.array([[2, 2, 2, 2], [2, 3, 3, 2]], np.int8),
                                 np.ones(2), np.zeros(2, bool)),
                          Bucket(6, np.array(["c"]), np.array([1]), np.array([[2, 2, 3, 2, 2, 3]], np.int8), np.ones(1), np.zeros(1, bool))])
    got = bulk.top_k([1, 0, 1, 0, 1], parts, fine, top=5)
    assert got.unmatchable >= 1 and all(r[2] == 4 for r in got.rows)
    assert [r[:6] for r in got.rows] == exhaustive_rows([1, 0, 1, 0, 1], parts, fine, 5, False)


# --------------------------------------------------------------------------- output, devices


def test_write_jsonl_is_atomic(tmp_path):
    out = tmp_path / "r.jsonl"
    bulk.write_jsonl(out, [{"a": 1}, {"b": [1, 2]}])
    assert [json.loads(x) for x in out.read_text().splitlines()] == [{"a": 1}, {"b": [1, 2]}]

    def broken():
        yield {"c": 3}
        raise RuntimeError("disk on fire")

    with pytest.raises(RuntimeError):
        bulk.write_jsonl(out, broken())
    assert [json.loads(x) for x in out.read_text().splitlines()] == [{"a": 1}, {"b": [1, 2]}]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.jsonl"]


def test_configure_host_devices_after_jax_import_only_checks():
    import jax

    bulk.configure_host_devices(len(jax.devices()))
    with pytest.raises(RuntimeError, match="before importing jax"):
        bulk.configure_host_devices(len(jax.devices()) + 1000)
    with pytest.raises(ValueError):
        bulk.configure_host_devices(0)


@pytest.mark.parametrize("skip", [None, (0, -4, -math.inf)])
def test_one_device_mesh_runs_the_sharded_code(fine, skip):
    rng = np.random.default_rng(5)
    codes, vals = rng.integers(0, 3, 20), rng.integers(2, 6, (30, 8))
    if skip is not None:
        fine = make_weights(fine, np.asarray(skip, np.float64))
    assert same(bulk.score_sharded(codes, vals, fine, devices=1), score_bucket(codes, vals, fine))
    many = bulk.score_many([codes, codes[:9]], vals, fine, devices=1)
    assert same(many[0], score_bucket(codes, vals, fine)) and same(many[1], score_bucket(codes[:9], vals, fine))


SHARDED = textwrap.dedent("""
    from jaxmatch.scoring import bulk
    bulk.configure_host_devices(4)
    import jax, numpy as np
    assert len(jax.devices()) == 4, jax.devices()
    from jaxmatch.catalogue.store import default_catalogue
    from jaxmatch.scoring.lattice import load_lattice
    from jaxmatch.scoring.exact import score_bucket
    from jaxmatch.io.readers import load_shape
    from jaxmatch.shape import annotate
    from jaxmatch.kernels.model import make_weights
    table = make_weights(load_lattice("fine").table(), [0, -7, float("-inf")])  # skip weights, must-match corners
    cat = default_catalogue()
    rng = np.random.default_rng(0)
    shapes = [annotate(load_shape("examples/lshape.json"), 24).codes, annotate(load_shape("examples/circle.json"), 20).codes,
              rng.integers(0, 3, 17)]  # all padded to 32 points: one compilation per n
    same = lambda a, b: all(np.array_equal(x, y) for x, y in zip(a, b))
    for b in [cat.bucket(6), cat.bucket(10, [3])]:  # 11 and 53 meshes: uneven over 4 devices
        ref = [score_bucket(c, b.valences, table) for c in shapes]
        assert same(bulk.score_sharded(shapes[0], b.valences, table, devices=4), ref[0]), b.n
        assert same(bulk.score_sharded(shapes[1], b.valences, table, devices=4, batch=8), ref[1]), b.n
        for r, x in zip(ref, bulk.score_many(shapes, b.valences, table, devices=4)):
            assert same(r, x), b.n
    assert same(bulk.score_sharded(shapes[0], b.valences, table, devices=2), ref[0])
    parts = bulk.prepare(b for b in cat.buckets([0, 1, 2]) if b.n <= 10)
    one = bulk.top_k_many(shapes, parts, table, top=3, per_size=True)
    four = bulk.top_k_many(shapes, parts, table, top=3, per_size=True, devices=4)
    pruned4 = [bulk.top_k(c, parts, table, top=3, per_size=True, devices=4) for c in shapes]
    for a, b, c in zip(one, four, pruned4):
        assert [r[:6] for r in a.rows] == [r[:6] for r in b.rows] == [r[:6] for r in c.rows]
    print("SHARDED-OK")
""")


def test_sharded_results_equal_single_device_on_4_simulated_devices():
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run([sys.executable, "-c", SHARDED], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "SHARDED-OK" in proc.stdout


# --------------------------------------------------------------------------- reuse of one prepared catalogue


@pytest.mark.parametrize("m", [6, 10, 24])
@pytest.mark.parametrize("skip", [None, [0.0, -2.0, -np.inf]])
def test_part_bounds_equal_per_part_upper_bounds(m, skip, small_parts):
    from jaxmatch.kernels.model import make_weights

    weights = make_weights(random_table(m, 0.2), skip)
    codes = np.random.default_rng(m).integers(0, 3, m)  # m = 6, 10: some parts are longer than the shape
    got = bulk.part_bounds(small_parts, codes, weights)
    for p, b in zip(small_parts, got):
        np.testing.assert_array_equal(b, bulk.upper_bounds(p.groups.seqs, codes, weights, hist=p.hist))


def test_prepared_is_computed_once_per_catalogue_and_selection():
    cat = default_catalogue()
    first = bulk.prepared(cat, [0, 1, 2])
    assert bulk.prepared(cat, [2, 1, 0]) is first  # same selection, any order
    assert bulk.prepared(cat, [0, 1]) is not first
    assert [p.n for p in first] == [b.n for b in cat.buckets([0, 1, 2])]
    for p, b in zip(first, cat.buckets([0, 1, 2])):
        np.testing.assert_array_equal(p.ids, b.ids)
