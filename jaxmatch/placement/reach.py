"""Whether a count vector is a sum of columns: ``A @ x == target`` for some integer ``x >= 0``.

A template's side counts are ``A @ mult`` (``A`` its side matrix, one column per chord, each
with two boundary edges; :mod:`jaxmatch.placement.refine`): whether ``counts - A @ 1`` is
such a sum tells whether some multiplicities ``>= 1`` meet ``counts`` exactly
(:func:`jaxmatch.placement.refine.feasible`). Plain Python and numpy; imports nothing of the
package.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["FEASIBLE_STATES", "box_search", "reachable", "reachable_cols"]

FEASIBLE_STATES = 100_000
"""Largest number of count vectors :func:`box_search` marks (every vector below the target);
beyond it the caller's integer program answers
(:func:`jaxmatch.placement.refine.feasible`)."""


def reachable(A: np.ndarray, target: np.ndarray) -> bool | None:
    """Whether ``A @ x == target`` for some integer ``x >= 0`` (``A``: ``(S, C)`` nonnegative
    integers, ``target``: ``(S,)``); None when the box search it ends with
    (:func:`box_search`) would mark more than :data:`FEASIBLE_STATES` vectors.

    First the forced moves, in plain Python (a template's columns are its chords, each with two
    boundary edges: most sides meet one or two chords, and most answers are no): a side whose
    target is 0 rules out every column that touches it; a side that only one column touches
    fixes that column's multiplicity (target over entry: no answer unless it divides, nor when
    it overshoots another side); a side with a target that no column touches has no answer.
    What is left when none applies goes to :func:`box_search` (every answer the same as
    the box search on the whole of ``A``: each move keeps exactly the solutions)."""
    return reachable_cols(np.asarray(A, np.int64).T.tolist(), [int(v) for v in np.asarray(target).tolist()])


def reachable_cols(cols: list, t: list) -> bool | None:
    """:func:`reachable` of the columns ``cols`` (lists of nonnegative ints, each as long as
    ``t``) and the target ``t`` (a list of ints)."""
    if min(t, default=0) < 0:
        return False
    cols = [c for c in cols if any(c)]
    moved = True
    while moved:
        moved = False
        for i, g in enumerate(t):
            cov = [c for c in cols if c[i]]
            if g == 0:
                if cov:
                    cols = [c for c in cols if not c[i]]
                    moved = True
            elif not cov:
                return False
            elif len(cov) == 1:
                a = cov[0]
                x, r = divmod(g, a[i])
                if r:
                    return False
                t = [v - x * s for v, s in zip(t, a)]
                if min(t) < 0:
                    return False
                cols = [c for c in cols if c is not a]
                moved = True
            if moved:
                break
    live = [i for i, g in enumerate(t) if g]  # (every side left with target 0 has no column: moved above)
    if not live:
        return True
    return box_search([[c[i] for i in live] for c in cols], [t[i] for i in live])


def box_search(cols: list, goal: list) -> bool | None:
    """:func:`reachable` by marking every vector ``<= goal`` that sums of ``cols`` (lists of
    nonnegative ints, each as long as ``goal``) reach, one column at a time: the marks shifted by
    ``a``, ``2a``, ``4a``, ... (each a slice of the ``goal + 1`` box) close them under adding any
    number of copies of column ``a``; None when there are more than :data:`FEASIBLE_STATES` such
    vectors."""
    if min(goal, default=0) < 0:
        return False
    dims = tuple(g + 1 for g in goal)
    if math.prod(dims) > FEASIBLE_STATES:
        return None
    reach = np.zeros(dims, bool)
    reach[(0,) * len(dims)] = True
    goal = tuple(goal)
    for a in cols:  # Python ints: a few steps of tiny boxes
        step = a
        while any(step) and all(s <= g for s, g in zip(step, goal)):
            dst = tuple(slice(s, None) for s in step)
            src = tuple(slice(0, d - s) for d, s in zip(dims, step))
            reach[dst] |= reach[src]
            step = [2 * s for s in step]
        if reach[goal]:  # marks are only ever added
            return True
    return bool(reach[goal])
