"""Lattice tuning (jaxmatch.tuning.tune, scripts/tune_lattice.py): parametrisation, exact evaluation,
determinism, and a tiny end-to-end run."""

import json
import math
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from jaxmatch.tuning import tune
from jaxmatch.tuning.labels import dump_labels, parse_labels, synthetic_examples
from jaxmatch.scoring.lattice import NEG, level_structure, load_lattice, table_from_levels, with_level_weights
from jaxmatch.scoring.exact import score_bucket
from jaxmatch.shape import annotate, default_points

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "tune_lattice.py"
TINY = dict(epochs=2, temperature=1.0, learning_rate=0.1, batch_size=8, l2=1e-3)


@pytest.fixture(scope="module")
def tiny(cat, index):
    """12 synthetic examples of size k = 1 (3 candidate meshes): cheap to compile and train."""
    records, _ = synthetic_examples(cat, 1, variants=4, seed=1, index=index)
    return records


@pytest.fixture(scope="module")
def tiny_examples(tiny, index):
    return parse_labels(dump_labels(tiny), "tiny", index).examples


def lattices():
    return [load_lattice("fine"), load_lattice("coarse")]


# ------------------------------------------------------------------------------- parametrisation


@pytest.mark.parametrize("lat", lattices(), ids=["fine", "coarse"])
def test_params_round_trip_the_lattice_weights(lat):
    s = level_structure(lat)
    w = np.asarray(tune.params_to_weights(jnp.asarray(tune.init_params(s)), s))
    # equal neighbouring levels (the tuned built-ins have some) start MIN_GAP apart
    ties = sum(int(np.sum(np.diff(s.weights[s.types == t]) == 0)) for t in range(3))
    np.testing.assert_allclose(w, s.weights, atol=1e-4 + tune.MIN_GAP * ties)
    np.testing.assert_array_equal(np.rint(w), s.weights)


@given(st.integers(0, 2**32 - 1), st.floats(0.1, 30.0), st.sampled_from([1, 2, 3, 8, 50]))
def test_level_order_survives_any_parameters_and_rounding(seed, spread, scale):
    for lat in lattices():
        s = level_structure(lat)
        p = np.random.default_rng(seed).normal(0.0, spread, s.weights.shape).astype(np.float32)
        w = np.asarray(tune.params_to_weights(jnp.asarray(p), s), np.float64)
        for t in range(3):
            assert np.all(np.diff(w[s.types == t]) <= 0)  # (strictly < 0 unless softplus underflows)
        rounded = with_level_weights(lat, scale * w / max(1.0, np.abs(scale * w).max() / 1000))
        for levels, orig in zip(rounded.levels, lat.levels):
            ws = [lev.weight for lev in levels]
            assert ws == sorted(ws, reverse=True)
            assert [lev.triples for lev in levels] == [lev.triples for lev in orig]  # no level moved


def test_excluded_entries_stay_fixed_and_get_no_gradient():
    for lat in lattices():
        s = level_structure(lat)
        excluded = ~np.isfinite(lat.table())
        for w in (s.weights, s.weights * 3 - 7):
            t = np.asarray(table_from_levels(s, jnp.asarray(w)))
            assert np.all(t[excluded] == np.float32(NEG))
            assert np.all(t[~excluded] != np.float32(NEG))
        # no level weight reaches an excluded cell (and the soft scorer gives the cells
        # themselves zero gradient: tests/test_soft.py)
        jac = np.asarray(jax.jacobian(lambda w: table_from_levels(s, w))(jnp.asarray(s.weights)))
        assert np.all(jac[excluded] == 0) and np.all(jac[~excluded].sum(axis=-1) == 1)


# ------------------------------------------------------------------------------- exact evaluation


def test_exact_utilities_equal_score_bucket(index, tiny_examples):
    lat = load_lattice("coarse")
    cands = tune.candidates(index, 1)
    examples = tiny_examples[:5]
    got = tune.exact_utilities(tune.encode(examples, cands), cands, lat.table())
    for i, ex in enumerate(examples):
        codes = annotate(ex.shape, default_points(ex.shape, cands.max_n)).codes
        expect = np.concatenate([score_bucket(codes, v, lat.table()).utility for _, v in cands.buckets])
        np.testing.assert_array_equal(got[i], expect)


def test_rank_positions_tie_rules():
    util = np.array([[5.0, 7.0, 7.0, 3.0, 7.0, -np.inf]])
    twin = np.zeros((1, 6), bool)
    pos = np.array([2])
    pess, by_id = tune.rank_positions(util, pos, twin)
    assert (pess[0], by_id[0]) == (3, 2)  # ties at 7: both count pessimistically, only index 1 by id
    twin[0, 1] = True  # a twin is not a competitor
    pess, by_id = tune.rank_positions(util, pos, twin)
    assert (pess[0], by_id[0]) == (2, 1)
    pess, by_id = tune.rank_positions(util, np.array([5]), np.zeros((1, 6), bool))
    assert pess[0] == 6 and by_id[0] == 6  # unmatchable preferred: beaten by everything
    m = tune._metrics(np.array([1, 2, 6, 1]), np.array([1, 1, 5, 1]))
    assert m["top1"] == 0.5 and m["top5"] == 0.75 and m["top1_by_id"] == 0.75 and m["top5_by_id"] == 1.0


def test_split_is_deterministic_grouped_and_sized(tiny_examples):
    a = tune.split_examples(tiny_examples, 0.3, 4)
    assert a == tune.split_examples(tiny_examples, 0.3, 4)
    train, held = a
    assert sorted(train + held) == list(range(len(tiny_examples)))
    assert held and train
    assert not {tiny_examples[i].preferred for i in train} & {tiny_examples[i].preferred for i in held}
    assert tune.split_examples(tiny_examples, 0.0, 4) == (list(range(len(tiny_examples))), [])


def test_candidate_sample_is_deterministic_and_keeps_the_preferred(index):
    keep = [index.by_k[4][-1]]
    a = tune.candidates(index, 4, keep=keep, max_candidates=50, seed=2)
    b = tune.candidates(index, 4, keep=keep, max_candidates=50, seed=2)
    assert a.ids == b.ids and len(a.ids) == 50 and keep[0] in a.ids
    assert a.max_n == tune.candidates(index, 4).max_n
    assert sum(v.shape[0] for _, v in a.buckets) == 50


# ------------------------------------------------------------------------------- training


def test_tuning_is_deterministic_improves_the_loss_and_keeps_the_order(cat, tiny_examples):
    lat = load_lattice("fine")
    a_lat, a = tune.run_tuning(lat, tiny_examples, cat, heldout=0.25, seed=3, **TINY)
    b_lat, b = tune.run_tuning(lat, tiny_examples, cat, heldout=0.25, seed=3, **TINY)
    assert a_lat == b_lat
    for key in ("train", "heldout", "loss", "weights", "scale", "scales", "split"):
        assert a[key] == b[key]
    assert a["loss"][-1] < a["loss"][0]
    s = level_structure(lat)
    w = np.concatenate([a["weights"]["after_unrounded"][t] for t in "sxv"])
    for t in range(3):
        assert np.all(np.diff(w[s.types == t]) < 0)
    assert not np.allclose(w, s.weights)
    for levels in a_lat.levels:
        assert [lev.weight for lev in levels] == sorted((lev.weight for lev in levels), reverse=True)
    for split in ("train", "heldout"):
        for when in ("before", "after", "after_unrounded"):
            got = a[split][when]
            assert set(got) >= {"top1", "top5", "top1_by_id", "top5_by_id", "examples", "unmatchable"}
            assert 0 <= got["top1"] <= got["top1_by_id"] <= got["top5_by_id"] <= 1 and got["top1"] <= got["top5"] <= got["top5_by_id"]


def test_non_finite_gradients_fail_loudly(index, tiny_examples, monkeypatch):
    real = tune._value_and_grad

    def broken(params, *args, **kwargs):
        value, grads = real(params, *args, **kwargs)
        return value, grads.at[0].set(jnp.nan)

    monkeypatch.setattr(tune, "_value_and_grad", broken)
    with pytest.raises(FloatingPointError, match="non-finite"):
        tune.train(load_lattice("fine"), tiny_examples, index, seed=0, **TINY)


def _script(labels, out, report, *extra):
    args = [sys.executable, str(SCRIPT), "--labels", str(labels), "--lattice", "coarse", "--out", str(out),
            "--report", str(report), "--epochs", "2", "--seed", "1", "--heldout", "0.25", "--batch-size", "8", *extra]
    return subprocess.run(args, capture_output=True, text=True, cwd=ROOT)


def test_end_to_end_script_writes_a_loadable_lattice_and_a_report(tmp_path, tiny):
    labels = tmp_path / "tiny.jsonl"
    labels.write_text("# tiny set\n" + dump_labels(tiny) + "{broken\n")
    bad_line = f"{labels}:{len(tiny) + 2}"
    out, report = tmp_path / "tuned.toml", tmp_path / "report.json"
    bad = _script(labels, out, report)
    assert bad.returncode == 2 and bad_line in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1 and not out.exists()

    run = _script(labels, out, report, "--skip-bad")
    assert run.returncode == 0, run.stderr
    assert f"skipped: {bad_line}" in run.stderr
    tuned = load_lattice(out)
    base = load_lattice("coarse")
    assert tuned.name == "coarse-tuned"
    assert tuned.weeded == base.weeded and tuned.forbidden == base.forbidden
    assert [[lev.triples for lev in t] for t in tuned.levels] == [[lev.triples for lev in t] for t in base.levels]
    assert np.array_equal(np.isfinite(tuned.table()), np.isfinite(base.table()))  # -inf entries unchanged
    text = out.read_text()
    assert "tuned from lattice" in text
    assert (ROOT / "lattices" / "coarse.toml").read_text().splitlines()[0] in text  # design comments kept
    rep = json.loads(report.read_text())
    for split in ("train", "heldout"):
        for when in ("before", "after"):
            for key in ("top1", "top5"):
                assert 0.0 <= rep[split][when][key] <= 1.0
    assert rep["split"]["train"] + rep["split"]["heldout"] == len(tiny)
    assert rep["labels"]["skipped"] and rep["scale"] >= 1 and len(rep["loss"]) == 2

    # the jaxmatch command reads the tuned lattice
    score = subprocess.run([str(Path(sys.executable).parent / "jaxmatch"), "score", str(ROOT / "examples" / "square.json"),
                            "--lattice", str(out), "--internal", "1", "--top", "1", "--json"], capture_output=True, text=True, cwd=ROOT)
    assert score.returncode == 0, score.stderr


def test_finite_skip_weights_are_learned_and_minus_inf_stays(index, tiny_examples):
    from dataclasses import replace

    lat = replace(load_lattice("fine"), skip=(0, -3, -math.inf))
    res = tune.train(lat, tiny_examples, index, seed=0, **TINY)
    assert math.isinf(res.skip[2]) and res.skip[2] < 0  # -inf: fixed
    assert np.all(np.isfinite(res.skip[:2])) and not np.allclose(res.skip[:2], [0, -3])  # free: moved
    fixed = tune.train(lat, tiny_examples, index, seed=0, tune_skip=False, **TINY)
    assert fixed.skip[:2].tolist() == [0, -3] and math.isinf(fixed.skip[2])
    # rounding keeps -inf and scales the finite ones with the levels
    tuned, scale, _ = tune.choose_scale(lat, res.weights, tiny_examples[:4], index, scales=(2,), skip=res.skip)
    assert math.isinf(tuned.skip[2]) and tuned.skip[:2] == tuple(int(np.clip(np.rint(2 * x), -1000, 1000)) for x in res.skip[:2])
