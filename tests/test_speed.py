"""Caches of the meshing path (issue 22): cached answers equal freshly computed ones.

No timings here: speed is measured by ``scripts/bench.py --mesh`` (docs/perf.md)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxmatch.errors import UnmatchableError
from jaxmatch.io.readers import load_shape
from jaxmatch.placement import solve as S
from jaxmatch.placement import templates as T
from jaxmatch.scoring.lattice import load_lattice

ROOT = Path(__file__).resolve().parent.parent


def _same_templates(a, b) -> None:
    assert [t.mesh_id for t in a] == [t.mesh_id for t in b]
    for s, t in zip(a, b):
        assert s.rank == t.rank and s.n_chords == t.n_chords
        assert (s.match.rotation, s.match.reflected) == (t.match.rotation, t.match.reflected)
        np.testing.assert_array_equal(s.placement.xy, t.placement.xy)
        for x, y in zip(s.side_chords, t.side_chords):
            np.testing.assert_array_equal(x, y)


def test_cached_templates_equal_fresh_ones_and_carry_the_callers_shape(cat):
    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "tshape.json")
    cat.cache.clear()
    fresh = T.patch_templates(shp, cat, lat, limit=3, internal=[0, 1, 2])
    other = dataclasses.replace(load_shape(ROOT / "examples" / "tshape.json"), source="elsewhere")
    again = T.patch_templates(other, cat, load_lattice("fine"), limit=3, internal=[2, 1, 0])
    _same_templates(fresh, again)
    assert all(t.shape is other for t in again)
    cat.cache.clear()
    _same_templates(fresh, T.patch_templates(shp, cat, lat, limit=3, internal=[0, 1, 2]))


def test_a_different_request_is_not_answered_from_the_cache(cat):
    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "lshape.json")
    few = T.patch_templates(shp, cat, lat, limit=1, internal=[0, 1])
    more = T.patch_templates(shp, cat, lat, limit=4, internal=[0, 1])
    assert len(more) >= len(few)
    assert T.patch_templates(shp, cat, lat, limit=1, internal=[0, 1])[0].mesh_id == few[0].mesh_id


def test_unmatchable_is_raised_again_from_the_cache(cat, monkeypatch):
    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "square.json")
    cat.cache.clear()
    calls = []

    def boom(*a, **k):
        calls.append(1)
        raise UnmatchableError("none")

    monkeypatch.setattr(T, "_iter_templates", boom)
    for _ in range(2):
        with pytest.raises(UnmatchableError):
            T.patch_templates(shp, cat, lat, limit=2)
    assert len(calls) == 1
    cat.cache.clear()


def _same_mesh(a, b) -> None:
    np.testing.assert_array_equal(a.xy, b.xy)
    np.testing.assert_array_equal(a.quads, b.quads)
    assert a.templates == b.templates
    np.testing.assert_array_equal(a.counts, b.counts)


@pytest.mark.parametrize("name,size", [("house.json", 0.6), ("t-junction.json", 0.4)])
def test_mesh_layout_from_its_caches_equals_a_fresh_one(cat, name, size):
    from jaxmatch.placement import layout as L

    lat = load_lattice("fine")
    lay = L.load_layout(ROOT / "examples" / "layouts" / name)
    cat.cache.clear()
    cat.cache.clear()
    fresh = S.mesh_layout(lay, cat, lat, size=size)
    again = S.mesh_layout(L.load_layout(ROOT / "examples" / "layouts" / name), cat, lat, size=size)
    _same_mesh(fresh, again)
    other = S.mesh_layout(lay, cat, lat, size=size * 0.7)  # another program, same templates
    cat.cache.clear()
    _same_mesh(other, S.mesh_layout(lay, cat, lat, size=size * 0.7))


def test_jaxmatch_mesh_twice_gives_the_same_mesh(cat):
    import jaxmatch

    shp = load_shape(ROOT / "examples" / "tshape.json")
    cat.cache.clear()
    cat.cache.clear()
    a = jaxmatch.mesh(shp, size=0.1, catalogue=cat)
    b = jaxmatch.mesh(shp, size=0.1, catalogue=cat)
    assert a.chosen == b.chosen
    np.testing.assert_array_equal(a.xy, b.xy)
    np.testing.assert_array_equal(a.quads, b.quads)


def test_a_lattice_is_parsed_once_per_content():
    assert load_lattice("fine") is load_lattice("fine")


def test_a_large_decomposition_is_smoothed_near_its_cuts_only(cat):
    from jaxmatch.placement import layout as L
    from jaxmatch.quality import inverted_mask, quality
    from jaxmatch.placement.refine import SMOOTH_ALWAYS

    lat = load_lattice("fine")
    lay = L.load_layout(ROOT / "examples" / "layouts" / "two-blocks.json")
    ext = float(np.ptp(lay.points, axis=0).max())
    plain = S.mesh_layout(lay, cat, lat, size=ext / 70)
    smoothed = S.mesh_layout(lay, cat, lat, size=ext / 70, smooth_cuts=True)
    assert smoothed.quads.shape[0] > SMOOTH_ALWAYS
    np.testing.assert_array_equal(plain.quads, smoothed.quads)
    assert not inverted_mask(smoothed.xy, smoothed.quads).any()
    assert quality(smoothed.xy, smoothed.quads)[0].min() >= quality(plain.xy, plain.quads)[0].min() - 1e-9
    moved = np.any(plain.xy != smoothed.xy, axis=1)
    assert moved.sum() < 0.5 * plain.xy.shape[0]  # the band around the cut, not every vertex


def test_the_refined_meshes_kept_stay_within_their_quad_budget(cat, monkeypatch):
    from jaxmatch.placement import layout as L

    from jaxmatch.cache import Cache, CacheSizes

    monkeypatch.setattr(cat, "cache", Cache(CacheSizes(total_quads=300)))
    lat = load_lattice("fine")
    lay = L.load_layout(ROOT / "examples" / "layouts" / "house.json")
    for size in (0.6, 0.5, 0.4, 0.3, 0.25):
        S.mesh_layout(lay, cat, lat, size=size)
        assert 0 < cat.cache.quads("refined") <= 300


def test_a_meshed_layout_from_the_cache_is_a_copy_for_the_callers_layout(cat):
    from jaxmatch.placement import layout as L

    lat = load_lattice("fine")
    cat.cache.clear()
    lay = L.load_layout(ROOT / "examples" / "layouts" / "house.json")
    a = S.mesh_layout(lay, cat, lat, size=0.5)
    a.xy[:] = 0.0  # a caller writing to its answer does not change the next one
    other = L.load_layout(ROOT / "examples" / "layouts" / "house.json")  # another object, the same layout
    seen = []
    b = S.mesh_layout(other, cat, lat, size=0.5, progress=lambda i, n: seen.append((i, n)))
    assert b.layout is other and np.ptp(b.xy) > 0
    assert seen == [(p + 1, lay.n_patches) for p in range(lay.n_patches)]
    cat.cache.clear()
    cat.cache.clear()
    _same_mesh(b, S.mesh_layout(other, cat, lat, size=0.5))


def _same_matches(a, b) -> None:
    assert [(m.mesh_id, m.rotation, m.reflected, m.utility) for m in a] == \
        [(m.mesh_id, m.rotation, m.reflected, m.utility) for m in b]
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x.alignment, y.alignment)


@pytest.mark.parametrize("internal", [[0], [1], [2, 3]])
def test_kept_rankings_equal_fresh_ones_for_shapes_of_the_same_point_types(cat, internal):
    """Two rectangles of one aspect ratio (annotated alike) share a ranking; a third of another
    aspect ratio does not; each answer equals a ranking computed with the memo cleared."""
    from jaxmatch.scoring.rank import rank
    from jaxmatch.shape import make_shape

    lat = load_lattice("fine")
    a = make_shape([[0, 0], [3, 0], [3, 1], [0, 1]])
    b = make_shape([[5, 5], [11, 5], [11, 7], [5, 7]])  # a scaled and moved
    c = make_shape([[0, 0], [1, 0], [1, 1], [0, 1]])
    kw = dict(internal=internal, top=9, per_size=True, prune=True)
    fresh = {}
    for name, shp in (("a", a), ("b", b), ("c", c)):
        cat.cache.clear("rankings")
        fresh[name] = rank(shp, cat, lat, **kw)
    cat.cache.clear("rankings")
    kept = {name: rank(shp, cat, lat, **kw) for name, shp in (("a", a), ("b", b), ("c", c))}
    assert np.array_equal(kept["a"].annotation.codes, kept["b"].annotation.codes)
    assert not np.array_equal(kept["a"].annotation.codes, kept["c"].annotation.codes)
    assert cat.cache.size("rankings") == 2  # a and b share one ranking
    for name in fresh:
        _same_matches(fresh[name].results, kept[name].results)
        np.testing.assert_array_equal(kept[name].annotation.positions, fresh[name].annotation.positions)
    cat.cache.clear("rankings")


def test_lazy_templates_are_placed_once_and_as_far_as_asked(cat):
    """A patch's templates are made as they are asked for, shared by every caller of the cache,
    in the order of the plain walk (fewest internal vertices first); threads may share them."""
    from concurrent.futures import ThreadPoolExecutor

    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "tshape.json")
    cat.cache.clear()
    lazy = T.lazy_patch_templates(shp, cat, lat, limit=2, internal=[0, 1, 2])
    first = lazy[0]
    walk = lazy._walk
    assert len(walk.made) == 1  # only the first one placed
    with ThreadPoolExecutor(4) as pool:
        lens = list(pool.map(lambda _: len(T.lazy_patch_templates(shp, cat, lat, limit=2, internal=[0, 1, 2])), range(8)))
    assert len(set(lens)) == 1 and lens[0] >= 1
    plain = list(T._iter_by_size(shp, cat, lat, limit=2, internal=[0, 1, 2]))
    _same_templates(plain, lazy[:])
    assert lazy[0] is not first and lazy[0].mesh_id == first.mesh_id  # handed out with the caller's shape
    ks = [t.match.internal_vertices for t in lazy[:]]
    assert ks == sorted(ks)
    cat.cache.clear()


@pytest.mark.parametrize("internal", [[0, 1], [2, 3], None])
def test_lazy_rankings_equal_eager_ones(cat, internal):
    """rank(lazy=True) aligns a match when first asked for; every match, and the template scan's
    reordering, equal the eager ranking's."""
    from jaxmatch.scoring.rank import LazyMatches, rank

    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "lshape.json")
    kw = dict(internal=internal, top=6, per_size=True, prune=True)
    cat.cache.clear("rankings")
    eager = rank(shp, cat, lat, **kw).results
    lazy = rank(shp, cat, lat, lazy=True, **kw).results
    assert isinstance(lazy, LazyMatches) and len(lazy) == len(eager) and not lazy._made
    _same_matches(eager, [lazy[i] for i in range(len(lazy))])
    _same_matches(eager[-2:], lazy[-2:])
    merged = lazy.reordered(lambda r: (-r[0], r[1], r[3]))
    _same_matches(sorted(eager, key=lambda m: (-m.utility, m.internal_vertices, m.mesh_id)), merged[:])
    with pytest.raises(IndexError):
        lazy[len(lazy)]
    cat.cache.clear("rankings")


def _dense_program(sides, matrices, equal, targets, tau_m):
    """The integer program's rows built one dense row at a time (the plain path): ``(A, lo)``."""
    from jaxmatch.placement.milp import _chord_row

    nc = [int(np.asarray(A).shape[1]) for A in matrices]
    off = np.concatenate([[0], np.cumsum(nc)]).astype(int)
    M, S, T = int(off[-1]), len(sides.chains), len(targets)
    nv = M + S + T + M
    rows, lo = [], []

    def row(bound):
        r = np.zeros(nv)
        rows.append(r)
        lo.append(bound)
        return r

    for p, A in enumerate(matrices):
        for i, parts in enumerate(sides.patch_sides[p]):
            r = row(0.0)
            r[off[p]:off[p + 1]] = np.asarray(A, np.float64)[i]
            r[M + parts] = -1.0
    for ids_a, ids_b in equal:
        r = row(0.0)
        r[M + np.asarray(ids_a, np.int64)] += 1.0
        r[M + np.asarray(ids_b, np.int64)] -= 1.0
    items = [(M + s, M + S + j, tau) for j, (s, tau) in enumerate(targets.items())]
    items += [(c, M + S + T + c, float(tau_m[c])) for c in range(M)]
    for x, d, tau in items:
        for sign in (1.0, -1.0):
            r = row(-sign * tau)
            r[x], r[d] = -sign, 1.0
        chord = _chord_row(tau)
        if chord is not None:
            r = row(chord[1])
            r[x], r[d] = -chord[0], 1.0
    return np.array(rows), np.array(lo)


@pytest.mark.parametrize("seed", range(6))
def test_the_sparse_integer_program_is_the_dense_one(seed, monkeypatch):
    """solve_counts builds its rows as SparseRows: the same matrix and bounds as the rows built
    one at a time, and HiGHS reads the same columns from it as from the dense matrix (zeros,
    -0.0 included, left out; a side listed twice, sides on both sides of an equal pair)."""
    from jaxmatch.placement import milp

    rng = np.random.default_rng(seed)
    n = 4 + 2 * int(rng.integers(0, 3))
    lengths = rng.choice([0.5, 1.0, 1.25, 2.0, 2.5, 3.7], size=n) * rng.integers(1, 4)  # whole, half (slope 0), other
    sides = milp.one_patch_sides(lengths)
    c = int(rng.integers(2, 5))
    A = rng.integers(0, 3, size=(n, c)).astype(np.int64)  # zeros in it
    sides = sides._replace(patch_sides=(tuple(np.array([i, i]) if i == 0 else np.array([i]) for i in range(n)),))
    equal = [([0, 1], [1, 2])] if seed % 2 else []
    widths = [rng.choice([0.5, 1.0, 1.5, 2.25], size=c)]
    seen = []
    monkeypatch.setattr(milp, "STRIPS", False)  # (the program goes to HiGHS even where strip_counts would answer)
    monkeypatch.setattr(milp, "run_milp", lambda *a, **k: seen.append(a))  # no solve: the program only
    with pytest.raises(milp.LayoutInfeasible):  # (None from run_milp reads as infeasible)
        milp.solve_counts(sides, [A], size=1.0, widths=widths, equal=equal, counts={1: 2})
    cost, sparse, lo, hi, integ, lb, ub = seen[0]
    targets = {s: float(lengths[s]) for s in range(n) if s != 1}
    dense, dlo = _dense_program(sides, [A], equal, targets, np.maximum(widths[0], 1.0))
    np.testing.assert_array_equal(np.asarray(sparse), dense)
    np.testing.assert_array_equal(lo, dlo)
    assert np.array_equal(np.signbit(lo), np.signbit(dlo))
    assert len(set(zip(sparse.row.tolist(), sparse.col.tolist()))) == sparse.row.size  # each entry once
    for a, b in zip(milp._columns(sparse), milp._columns(dense)):
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)


def _plain_part(p, ignore):
    """cache.key's part, one isinstance test after the other (the plain path)."""
    import dataclasses as dc

    if p is None or isinstance(p, (str, bool, int, float)):
        return p
    if isinstance(p, np.ndarray):
        a = np.ascontiguousarray(p)
        return a.dtype.str, a.shape, a.tobytes()
    if isinstance(p, np.generic):
        return p.item()
    if isinstance(p, (tuple, list)):
        return tuple(_plain_part(x, ignore) for x in p)
    if isinstance(p, dict):
        return tuple(sorted((k, _plain_part(v, ignore)) for k, v in p.items()))
    if dc.is_dataclass(p) and not isinstance(p, type):
        params, fields = type(p).__dataclass_params__, type(p).__dataclass_fields__
        if params.frozen and params.eq and not any(n in fields for n in ignore):
            try:
                hash(p)
                return p
            except TypeError:
                pass
        return (type(p).__name__,) + tuple(_plain_part(getattr(p, f.name), ignore) for f in dc.fields(p)
                                           if f.name not in ignore)
    return p


def test_the_key_builder_gives_the_plain_paths_keys(cat):
    """cache.key dispatches the common types by exact type first: the same keys as testing each
    kind in turn, for shapes, layouts, a lattice, templates, numpy scalars, dicts and views."""
    from jaxmatch.cache import key
    from jaxmatch.placement.decompose import decompose

    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "tshape.json")
    lay = decompose(shp, "continuations")
    tmpl = T.patch_templates(load_shape(ROOT / "examples" / "lshape.json"), cat, lat, limit=1, internal=[0, 1])[0]
    parts = [("walk", True, shp, lat, 3, (0, 1)), (lay,), (lat,), (tmpl.match, tmpl.placement.xy, tmpl.side_chords),
             (np.float64(0.5), np.int64(3), np.bool_(True), {"b": np.arange(3)[::2], "a": [1.5, None]}),
             (np.arange(12.0).reshape(3, 4).T, [shp.numbering, shp.holes], dataclasses.replace(shp, source="x"))]
    for ps in parts:
        for ignore in ((), ("source",)):
            got, want = key(*ps, ignore=ignore), tuple(_plain_part(p, ignore) for p in ps)
            assert got == want
            assert [type(x) for x in got] == [type(x) for x in want]


def test_a_side_walk_of_a_refined_topology_is_the_edge_by_edge_one(cat):
    """The refined vertices of each template side, found for all its template edges at once, are
    those of the walk edge by edge (template vertex, then the edge's inner points)."""
    from jaxmatch.placement import refine as R

    lat = load_lattice("fine")
    shp = load_shape(ROOT / "examples" / "tshape.json")
    for t in T.patch_templates(shp, cat, lat, limit=2, internal=[0, 1, 2, 3]):
        tq = np.asarray(t.placement.mesh.quads, np.int64)
        for m in (np.ones(t.n_chords, np.int64), np.arange(1, t.n_chords + 1) % 4 + 1):
            nv, quads, along, W, VV = R._refine_topology(tq, t.edge_list, t.edge_chord, t.quad_chords, m)
            V0 = int(tq.max()) + 1
            ekey = t.edge_list[:, 0] * V0 + t.edge_list[:, 1]
            got = R._make_refined_topology(tq, t, m)[4]
            for path, sv in zip(t.side_path, got):
                ids = []
                for a, b in zip(path[:-1].tolist(), path[1:].tolist()):
                    me = int(m[t.edge_chord[int(np.searchsorted(ekey, min(a, b) * V0 + max(a, b)))]])
                    ids += along(np.int64(a), np.int64(b), np.arange(me), me).tolist()
                np.testing.assert_array_equal(sv, ids + [int(path[-1])])
                assert sv.dtype == np.int64


def test_a_reused_highs_object_solves_as_a_fresh_one(cat, monkeypatch, recorded):
    """Every integer program of a few meshes, solved by the thread's one HiGHS object (its model
    cleared each time), in order and in reverse, gives the status and solution of a new object."""
    import threading

    import jaxmatch
    from jaxmatch.placement import milp

    def run():
        cat.cache.clear()
        for name in ("lshape.json", "tshape.json", "holes/letter-A.json"):
            jaxmatch.mesh(load_shape(ROOT / "examples" / name), catalogue=cat, divisions=24)

    real = milp._highs
    progs = recorded(milp, "_highs", run)
    assert len(progs) >= 5
    reused = [real(*a, **k) for a, k in progs] + [real(*a, **k) for a, k in reversed(progs)][::-1]
    fresh = []
    for a, k in progs:
        monkeypatch.setattr(milp, "_SOLVER", threading.local())  # a new object for this program
        fresh.append(real(*a, **k))
    for i, (st, x, _) in enumerate(reused):
        f = fresh[i % len(progs)]
        assert st == f[0] and (x is None) == (f[1] is None)
        if x is not None:
            np.testing.assert_array_equal(x, f[1])


def test_the_choice_rules_counts_kept_on_a_mesh_equal_fresh_ones(cat):
    """A mesh's size conformity, size fit, irregular vertices and Euler bound, asked again (kept
    on the mesh) or for another quality, equal those of a fresh copy of it."""
    import jaxmatch
    from jaxmatch.defaults import QUALITY
    from jaxmatch.meshing.choose import mesh_key

    m = jaxmatch.mesh(load_shape(ROOT / "examples" / "tshape.json"), catalogue=cat, size=0.3)
    strict = dataclasses.replace(QUALITY, long_edge=1.01, coarse_side=1.01, size_tol=0.01)
    keys = [mesh_key(m, 0, q) for q in (QUALITY, strict, QUALITY)]
    fresh = dataclasses.replace(m)  # the same mesh, nothing computed yet
    assert keys[0] == keys[2] == mesh_key(fresh, 0, QUALITY)
    assert keys[1] == mesh_key(dataclasses.replace(m), 0, strict)
    assert (m.size_conformity(strict), m.size_fit(strict)) == (fresh.size_conformity(strict), fresh.size_fit(strict))
    np.testing.assert_array_equal(m.irregular, fresh.irregular)
    assert m.irregular_bound == fresh.irregular_bound
    m.irregular[:] = -1  # a copy: the kept array stays
    np.testing.assert_array_equal(m.irregular, fresh.irregular)


@settings(max_examples=40, deadline=None)
@given(st.integers(3, 300), st.floats(0.3, 6.0), st.floats(1e-6, 0.5), st.booleans(), st.integers(0, 2**31 - 1))
def test_the_fewest_chord_pieces_from_batches_are_those_of_the_search_one_count_at_a_time(k, span, share, backwards,
                                                                                          seed):
    """``curve_floors``' search for the fewest pieces of a curved side gives the same count when
    the counts it may ask for are measured in batches as when each is measured alone, and a
    batch's errors are each count's own, bit for bit."""
    from jaxmatch.placement import floors as L

    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0.0, span, k))
    r = 2.0 + 0.1 * rng.standard_normal(k)
    arc = np.stack([1.0 + r * np.cos(t), -3.0 + r * np.sin(t)], axis=1)
    arc = arc[::-1].copy() if backwards else arc
    budget = share * L.chord_area_error(arc, 1)
    counts = rng.permutation(np.arange(1, 4 * k + 1))[:40]
    batch = L.chord_area_errors(arc, counts)
    assert batch.tolist() == [L.chord_area_error(arc, int(n)) for n in counts]
    fast = L._fewest_pieces(arc, budget)
    old = L.CURVE_BATCH
    try:
        L.CURVE_BATCH = 0
        assert L._fewest_pieces(arc, budget) == fast
    finally:
        L.CURVE_BATCH = old


@pytest.mark.parametrize("change", [dict(area_tol=-1.0), dict(good_sj=1.01), dict(high_sj=1.01), dict(sj_step=0.3),
                                    dict(coarse_side=0.5), dict(long_edge=0.5), dict(size_band=(0.99, 1.01)),
                                    dict(band_share=1.01)])
def test_a_kept_mesh_key_is_kept_per_threshold_it_reads(cat, change):
    """mesh_key's kept key (all but the order tried, kept on the mesh) is kept per threshold of
    the quality it reads: asked for a quality that differs in one of them (each changing the
    key of this mesh), it equals the key of a fresh copy of the mesh; the order tried is its
    last element whatever was kept."""
    import jaxmatch
    from jaxmatch.defaults import QUALITY
    from jaxmatch.meshing.choose import mesh_key

    m = jaxmatch.mesh(load_shape(ROOT / "examples" / "tshape.json"), catalogue=cat, size=0.3)
    other = dataclasses.replace(QUALITY, **change)
    kept = [mesh_key(m, 0, QUALITY), mesh_key(m, 3, other)]
    assert kept[1] == mesh_key(dataclasses.replace(m), 3, other)
    assert kept[1][:-1] != kept[0][:-1]  # (the threshold decides a rule here)
    assert kept[0] == mesh_key(dataclasses.replace(m), 0, QUALITY) == mesh_key(m, 7, QUALITY)[:-1] + (0,)
    assert mesh_key(m, 7, QUALITY)[-1] == 7
