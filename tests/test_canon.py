"""Canonical keys: the compiled implementation equals the plain one, and keys are invariants."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from jaxmatch.catalogue.canon import canonical, mesh_id
from jaxmatch.catalogue.canon_fast import canonical_key
from jaxmatch.catalogue.closing import close_all


@pytest.fixture(scope="module")
def disks():
    found = close_all(3)
    return [d for level in found.values() for d in level.values()]


def test_fast_equals_plain_on_every_mesh_up_to_k3(disks):
    for d in disks:
        assert canonical_key(d.quads, d.boundary, d.vals) == canonical(d.quads, d.boundary, d.vals)


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_fast_equals_plain_with_marks_and_relabelling(disks, data):
    d = data.draw(st.sampled_from(disks))
    nv = len(d.vals)
    perm = np.asarray(data.draw(st.permutations(range(nv))))
    vals = np.asarray(d.vals)
    mark = data.draw(st.sampled_from(list(d.boundary)))
    marked = vals.copy()
    marked[mark] += 10
    q = perm[np.asarray(d.quads)]
    b = np.roll(perm[np.asarray(d.boundary)], data.draw(st.integers(0, len(d.boundary) - 1)))
    v = np.empty(nv, int)
    v[perm] = marked
    fast = canonical_key(q, b, v)
    plain = canonical(q.tolist(), b.tolist(), v.tolist())
    assert fast == plain
    # relabelling and rotating the loop does not change the key
    assert fast.key == canonical(d.quads, d.boundary, marked.tolist()).key


def test_marking_a_vertex_changes_the_key_unless_symmetric(disks):
    star4 = next(d for d in disks if d.interior == 1 and len(d.quads) == 4)
    keys = set()
    for p in star4.boundary:
        vals = list(star4.vals)
        vals[p] += 10
        keys.add(canonical_key(star4.quads, star4.boundary, vals).key)
    assert len(keys) == 2  # the 8 boundary vertices of the valence-4 star fall in 2 orbits


def test_ids_distinguish_all_meshes(disks):
    ids = [mesh_id(canonical_key(d.quads, d.boundary, d.vals).key, d.interior) for d in disks]
    assert len(ids) == len(set(ids))
