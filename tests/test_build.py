"""Each strategy's mesh object as a QuadMesh (:mod:`jaxmatch.meshing.build`)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from jaxmatch.meshing.build import _path_edges


@given(st.lists(st.integers(0, 10**6), min_size=0, max_size=12), st.sampled_from([np.int64, np.int32]))
def test_a_paths_edges_are_its_consecutive_pairs(ids, dtype):
    """``_path_edges`` is ``np.stack([ids[:-1], ids[1:]], axis=1)``: the same pairs, shape and dtype."""
    a = np.asarray(ids, dtype)
    got, want = _path_edges(a), np.stack([a[:-1], a[1:]], axis=1)
    assert got.dtype == want.dtype and got.shape == want.shape
    np.testing.assert_array_equal(got, want)
