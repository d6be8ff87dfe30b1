"""Specification of jaxmatch.placement.reach: whether a count vector is a nonnegative integer
sum of columns, as enumeration and the box search on the whole matrix say."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.placement.reach import FEASIBLE_STATES, box_search, reachable


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 4).flatmap(lambda S: st.tuples(
    st.lists(st.lists(st.integers(0, 2), min_size=S, max_size=S), min_size=1, max_size=4),
    st.lists(st.integers(-1, 7), min_size=S, max_size=S))))
def test_reachable_equals_enumeration(case):
    """``reachable(A, t)``: some integer ``x >= 0`` has ``A @ x == t``, as enumerating every
    multiplicity vector in the box says."""
    cols, t = case
    A = np.array(cols, np.int64).T  # (S, C)
    box = range(max(max(t), 0) + 1)  # a nonzero column used more often overshoots t
    want = any(np.array_equal(A @ np.array(x), t) for x in itertools.product(box, repeat=A.shape[1]))
    assert reachable(A, np.array(t)) == want


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 9).flatmap(lambda S: st.tuples(
    st.lists(st.one_of(st.tuples(st.integers(0, S - 1), st.integers(0, S - 1)).map(lambda ij: ("chord",) + ij),
                       st.lists(st.integers(0, 3), min_size=S, max_size=S).map(lambda c: ("any", c))),
             min_size=0, max_size=12),
    st.lists(st.integers(-1, 4 if S <= 6 else 2), min_size=S, max_size=S))))  # (boxes within FEASIBLE_STATES)
def test_reachable_equals_box_search(case):
    """``reachable``'s forced moves keep the answer of the box search on the whole matrix
    (``box_search``): columns as a template's chords (two boundary edges: sides i and j, or
    both on one side) and any columns, more sides than enumeration reaches."""
    cols, t = case
    S = len(t)
    A = np.zeros((S, len(cols)), np.int64)
    for j, c in enumerate(cols):
        if c[0] == "chord":
            A[c[1], j] += 1
            A[c[2], j] += 1
        else:
            A[:, j] = c[1]
    want = box_search(A.T.tolist(), list(t))
    assert want is not None
    assert reachable(A, np.array(t)) == want


def test_box_search_says_none_beyond_its_states():
    """Beyond :data:`FEASIBLE_STATES` marked vectors the box search gives no answer (None: the
    caller's integer program answers), and the forced moves still answer what they settle."""
    goal = [9] * 6  # 10 ** 6 vectors
    assert 10 ** 6 > FEASIBLE_STATES
    assert box_search([[1, 1, 0, 0, 0, 0]], goal) is None
    cols = np.eye(6, dtype=np.int64)  # every side reached by its own column only
    assert reachable(cols, np.array(goal)) is True
    assert reachable(np.eye(6, dtype=np.int64) * 2, np.array(goal)) is False  # 9 is no multiple of 2
