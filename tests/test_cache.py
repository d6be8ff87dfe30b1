"""The one cache layer (:mod:`jaxmatch.cache`): least recently used stores under one size
policy, errors kept like values, meshes bounded by their quads, one key builder; and nothing
kept anywhere else (no module global, nothing written into another module's object)."""

from __future__ import annotations

import dataclasses
from collections import OrderedDict

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import jaxmatch
from jaxmatch.cache import Cache, CacheSizes, key


def _plain_lru(ops, size):
    """The reference: an OrderedDict used as an LRU of ``size`` entries; ``ops``: keys asked for.
    Returns the keys made (misses), in order, and the keys kept at the end."""
    kept, made = OrderedDict(), []
    for k in ops:
        if k in kept:
            kept.move_to_end(k)
            continue
        made.append(k)
        while len(kept) >= size:
            kept.popitem(last=False)
        kept[k] = k
    return made, list(kept)


@given(st.lists(st.integers(0, 6), max_size=60), st.integers(1, 5))
def test_a_store_is_a_least_recently_used_dict(ops, size):
    cache = Cache(CacheSizes(solves=size))
    made = []
    for k in ops:
        assert cache.get("solves", k, lambda k=k: made.append(k) or k * 10) == k * 10
    want_made, want_kept = _plain_lru(ops, size)
    assert made == want_made
    assert list(cache._stores.get("solves", {})) == want_kept


def test_an_error_is_kept_and_raised_again_only_when_asked_to():
    cache = Cache()
    calls = []

    def fail():
        calls.append(1)
        raise ValueError("no")

    for _ in range(2):
        with pytest.raises(ValueError):
            cache.get("sides", "a", fail, keep_errors=(ValueError,))
    assert len(calls) == 1
    for _ in range(2):
        with pytest.raises(KeyError):
            cache.get("sides", "b", lambda: {}["x"])
    assert cache.size("sides") == 1  # "b" was not kept


def test_meshes_are_bounded_by_their_quads():
    cache = Cache(CacheSizes(max_quads=10, total_quads=25))
    for i, q in enumerate([8, 8, 8, 11, 8]):
        assert cache.get("refined", i, lambda q=q: q, quads=lambda v: v) == q
    assert cache.lookup("refined", 3) is None  # larger than max_quads: returned, not kept
    assert 0 < cache.quads("refined") <= 25
    assert list(cache._stores["refined"]) == [1, 2, 4]  # the oldest dropped for the total


def test_clear_forgets_one_store_or_all():
    cache = Cache()
    cache.put("solves", 1, "a")
    cache.put("sides", 1, "b")
    cache.clear("solves")
    assert cache.lookup("solves", 1) is None and cache.lookup("sides", 1) == "b"
    cache.put("prepared", 1, "c")
    cache.forget_shapes()
    assert cache.size("sides") == 0 and cache.lookup("prepared", 1) == "c"  # the catalogue's own stay
    cache.clear()
    assert cache.size("prepared") == 0


@dataclasses.dataclass(frozen=True)
class _Thing:
    a: np.ndarray
    b: float
    source: str = "x"


@given(st.lists(st.floats(-5, 5, allow_nan=False), min_size=1, max_size=6), st.floats(-1, 1, allow_nan=False))
def test_the_key_builder_compares_values(xs, b):
    a = np.asarray(xs)
    assert key(_Thing(a, b)) == key(_Thing(a.copy(), b))
    assert key(_Thing(a, b, "y"), ignore=("source",)) == key(_Thing(a.copy(), b, "z"), ignore=("source",))
    assert key(_Thing(a, b, "y")) != key(_Thing(a, b, "z"))
    assert key(_Thing(a, b)) != key(_Thing(a + 1.0, b))
    assert key(a) != key(a.astype(np.float32))  # the dtype counts
    assert key(a.reshape(1, -1)) != key(a)  # and the shape
    assert hash(key(_Thing(a, b), [a, {"k": a}], None))


def _plain_array_key(a):
    """The reference key of an array: its contiguous copy's dtype, shape and bytes."""
    c = np.ascontiguousarray(a)
    return c.dtype.str, c.shape, c.tobytes()


@pytest.mark.parametrize("a", [
    np.arange(12.0).reshape(3, 4), np.arange(12.0).reshape(3, 4).T, np.arange(12.0).reshape(3, 4)[:, ::2],
    np.arange(6, dtype=np.int32)[::-1], np.array(2.5), np.zeros((0, 2)), np.asfortranarray(np.eye(3, dtype=np.int64))])
def test_an_array_keys_as_its_contiguous_copy(a):
    """Any layout (transposed, strided, reversed, Fortran order, 0-d) keys as the contiguous copy
    of the array, and equal values in another layout give the same key."""
    assert key(a) == (_plain_array_key(a),)
    assert key([a, (a,)]) == ((_plain_array_key(a), (_plain_array_key(a),)),)
    assert key(a) == key(np.array(a, order="C"))


def test_meshing_keeps_nothing_outside_the_catalogues_cache(cat):
    """After meshing, the catalogue and the shape hold only their own fields and their own
    computed properties (nothing written into them by another module), and the package keeps no
    module-level store (every kept thing is in ``cat.cache``)."""
    shape = jaxmatch.load_shape("examples/lshape.json")
    cat.cache.clear()
    jaxmatch.mesh(shape, divisions=16, catalogue=cat)
    fields = {f.name for f in dataclasses.fields(cat)}
    assert set(vars(cat)) <= fields
    own = {n for n, v in vars(type(shape)).items() if hasattr(v, "__set_name__")} | {f.name for f in dataclasses.fields(shape)}
    assert set(vars(shape)) <= own
    assert cat.cache.size("templates") and cat.cache.size("layouts") and cat.cache.size("rankings")
    for m in ("jaxmatch.placement.refine", "jaxmatch.placement.solve", "jaxmatch.placement.templates",
              "jaxmatch.placement.layout", "jaxmatch.scoring.rank"):
        mod = __import__(m, fromlist=["_"])
        stores = [n for n, v in vars(mod).items() if isinstance(v, dict) and not n.startswith("__")]
        assert stores == [], (m, stores)
