"""jaxmatch.placement.milp._capped_milp: a count program solved with its side counts capped first
has the optimum of the program without caps, whether the answer lies within the first caps, past
them (solved again with the caps its cost allows) or only past them (infeasible within them)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxmatch.placement import milp
from jaxmatch.placement.milp import COUNT_SLACK, COUNT_SLACK_PER_SIDE, SparseRows, run_milp


def _program(tau, rows, lower=None):
    """A count program as :func:`milp.solve_counts` builds one, small: integer counts ``n (S,)
    >= lower`` (default 1), deviations ``d_s >= |n_s - tau_s|`` at cost 1 each, and the coupling
    rows ``(coefficients (S,), lo, hi)`` on the counts. Returns the arguments of
    :func:`run_milp` and the count columns."""
    tau = np.asarray(tau, np.float64)
    S = tau.size
    r, c, v, lo, hi = [], [], [], [], []
    for k, (coef, a, b) in enumerate(rows):
        for j in np.flatnonzero(coef):
            r.append(k), c.append(int(j)), v.append(float(coef[j]))
        lo.append(a), hi.append(b)
    k = len(rows)
    for s in range(S):  # d - n >= -tau, d + n >= tau
        r += [k, k, k + 1, k + 1]
        c += [S + s, s, S + s, s]
        v += [1.0, -1.0, 1.0, 1.0]
        lo += [-tau[s], tau[s]]
        hi += [np.inf, np.inf]
        k += 2
    A = SparseRows((k, 2 * S), np.array(r), np.array(c), np.array(v))
    cost = np.concatenate([np.zeros(S), np.ones(S)])
    integrality = np.concatenate([np.ones(S), np.zeros(S)])
    lb = np.concatenate([np.ones(S) if lower is None else np.asarray(lower, np.float64), np.zeros(S)])
    ub = np.full(2 * S, np.inf)
    return (cost, A, np.array(lo), np.array(hi), integrality, lb, ub), np.arange(S), tau


def _both(args, cols, tau):
    calls = []
    real = milp.run_milp

    def counted(*a, **k):
        calls.append(np.asarray(a[6])[cols].copy())
        return real(*a, **k)

    milp.run_milp = counted
    try:
        capped = milp._capped_milp(*args, cols, tau)
    finally:
        milp.run_milp = real
    return capped, run_milp(*args), calls


def test_an_answer_within_the_caps_is_taken_from_one_capped_program():
    args, cols, tau = _program([3.4, 5.6, 3.4], [(np.array([1, 0, -1]), 0.0, 0.0)])  # sides 0 and 2 equal
    capped, plain, calls = _both(args, cols, tau)
    assert len(calls) == 1 and np.all(np.isfinite(calls[0]))
    assert np.array_equal(np.rint(capped[:3]), [3, 6, 3]) and np.array_equal(np.rint(plain[:3]), [3, 6, 3])


def test_an_optimum_past_the_first_caps_is_found_with_the_caps_its_cost_allows():
    # n1 = 2 n0: at n0 = 20 side 1 meets its target 40 (cost 19); the first cap of n0 is 1 + 8 + 3
    args, cols, tau = _program([1.0, 40.0], [(np.array([2, -1]), 0.0, 0.0)])
    assert np.floor(1.0 + COUNT_SLACK + COUNT_SLACK_PER_SIDE * 2) < 20
    capped, plain, calls = _both(args, cols, tau)
    assert len(calls) == 2 and calls[1][0] > calls[0][0]  # solved again, the caps raised
    assert np.array_equal(np.rint(capped[:2]), [20, 40]) and np.array_equal(np.rint(plain[:2]), [20, 40])


def test_a_program_feasible_only_past_the_caps_is_solved_without_them():
    args, cols, tau = _program([1.0, 1.0], [(np.array([1, -1]), 60.0, np.inf)])  # n0 >= n1 + 60
    capped, plain, calls = _both(args, cols, tau)
    assert len(calls) == 2 and np.all(np.isinf(calls[1]))
    assert np.array_equal(np.rint(capped[:2]), [61, 1]) and np.array_equal(np.rint(plain[:2]), [61, 1])


def test_an_infeasible_program_stays_infeasible():
    args, cols, tau = _program([2.5, 2.5], [(np.array([1, 1]), 3.0, 3.0), (np.array([1, -1]), 0.0, 0.0)])  # odd
    capped, plain, _ = _both(args, cols, tau)
    assert capped is None and plain is None


@pytest.mark.parametrize("seed", range(12))
def test_random_programs_have_the_same_optimum_capped_or_not(seed):
    rng = np.random.default_rng(seed)
    S = int(rng.integers(3, 7))
    tau = rng.uniform(0.5, 30.0, S)
    rows = []
    for _ in range(int(rng.integers(1, 4))):  # equalities among small multiples of the counts
        coef = rng.integers(-2, 3, S)
        if np.any(coef):
            rows.append((coef, 0.0, 0.0))
    lower = np.maximum(1, np.rint(rng.uniform(0, 1, S) * tau * rng.integers(0, 3)))  # some floors above target
    args, cols, tau = _program(tau, rows, lower)
    capped, plain, _ = _both(args, cols, tau)
    assert (capped is None) == (plain is None)
    if plain is not None:
        cost = args[0]
        assert cost @ capped == pytest.approx(cost @ plain, rel=1e-4, abs=1e-6)  # HiGHS's gap
        lo, hi = args[2], args[3]
        assert np.all(np.asarray(args[1]) @ capped >= lo - 1e-6) and np.all(np.asarray(args[1]) @ capped <= hi + 1e-6)


def _chord_matrix(rng, n_sides: int, n_chords: int) -> np.ndarray:
    """A side matrix as a template's: each chord's two ends on one side or two."""
    A = np.zeros((n_sides, n_chords), np.int64)
    for c in range(n_chords):
        a, b = rng.integers(0, n_sides, 2)
        A[a, c] += 1
        A[b, c] += 1
    for s in np.flatnonzero(A.sum(axis=1) == 0):  # every side gets an end
        A[s, rng.integers(0, n_chords)] += 1
    return A


@pytest.mark.parametrize("seed", range(16))
def test_counts_feasible_says_whether_solve_counts_answers(seed):
    rng = np.random.default_rng(100 + seed)
    S = int(rng.integers(3, 6))
    A = _chord_matrix(rng, S, int(rng.integers(2, 5)))
    counts = rng.integers(1, 6, S)
    sides = milp.one_patch_sides(counts.astype(np.float64))
    want = {int(s): int(counts[s]) for s in range(S) if rng.uniform() < 0.7}
    try:
        milp.solve_counts(sides, [A], counts=want, size=1.0)
        answered = True
    except milp.LayoutInfeasible:
        answered = False
    assert milp.counts_feasible(sides, [A], counts=want) is answered
