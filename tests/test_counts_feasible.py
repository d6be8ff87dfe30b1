"""jaxmatch.placement.milp.counts_feasible: whether a count program has a solution, from its
constraints alone, is whether :func:`jaxmatch.placement.milp.solve_counts` answers it."""

from __future__ import annotations

import numpy as np
import pytest

from jaxmatch.placement import milp


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
