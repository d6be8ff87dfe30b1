"""Array helpers (:mod:`jaxmatch.arrays`): each equals the numpy function it stands for."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.arrays import roll


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 9), cols=st.sampled_from([None, 1, 2, 4]), shift=st.integers(-20, 20), axis=st.sampled_from([0, 1, -1]))
def test_roll_is_numpys(n, cols, shift, axis):
    a = np.arange(n * (cols or 1), dtype=np.float64).reshape((n,) if cols is None else (n, cols))
    if a.ndim == 1 and axis != 0:
        axis = 0
    out = roll(a, shift, axis=axis)
    assert out.dtype == a.dtype and np.array_equal(out, np.roll(a, shift, axis=axis))
    assert out is not a and not np.shares_memory(out, a)
