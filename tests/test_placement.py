"""Placing ranked meshes (jaxmatch.placement.choose) and the geometry tie-break of rank()."""

from __future__ import annotations

import itertools
from itertools import islice
from pathlib import Path

import numpy as np
import pytest

from jaxmatch.catalogue import store as cm
from jaxmatch.placement.embed import inverted_mask, quality, quad_areas
from jaxmatch.errors import InputError
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.api import rank
from jaxmatch.placement.choose import (
    check_outputs,
    choose_mesh,
    draw_placements,
    first_valid,
    gap_cost,
    geometry_key,
    place_match,
    place_top,
    rerank_ties,
    spread_alignment,
)
from jaxmatch.scoring.exact import utility_of
from jaxmatch.shape import annotate, load_shape, make_shape

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="session")
def cat(tmp_path_factory):
    p = tmp_path_factory.mktemp("placement") / "c.npz"
    cm.save(cm.generate(3), p)
    return cm.load(p)


@pytest.fixture(scope="session")
def lat():
    return load_lattice("fine")


@pytest.fixture(scope="session")
def ranked(cat, lat):
    """(shape, ranking by id, ranking by geometry) per example, top 8."""
    out = {}
    for name in ("triangle", "lshape", "square"):
        shp = load_shape(EXAMPLES / f"{name}.json")
        out[name] = (shp, rank(shp, cat, lat, top=8), rank(shp, cat, lat, top=8, tie_break="geometry"))
    return out


# ---------------------------------------------------------------------------------------------
# spread_alignment


def brute_spread(t, per, codes, al):
    want = codes[al]
    best = None
    for comb in itertools.combinations(range(len(t)), len(al)):
        if np.all(codes[list(comb)] == want):
            c = gap_cost(t, per, comb)
            if best is None or c < best - 1e-12:
                best = c
    return best


def test_spread_alignment_spreads_packed_vertices_evenly():
    m, per = 12, 12.0
    t = np.arange(m, dtype=float)
    codes = np.zeros(m, int)
    out = spread_alignment(t, per, codes, np.array([0, 1, 2, 3]))
    assert np.all(np.diff(out) == 3)  # gaps 3, 3, 3 and 3 around
    assert gap_cost(t, per, out) == pytest.approx(36.0)


def test_spread_alignment_keeps_codes_and_matches_brute_force():
    rng = np.random.default_rng(7)
    for _ in range(40):
        m = int(rng.integers(4, 10))
        n = int(rng.integers(2, min(m, 5) + 1))
        t = np.sort(rng.uniform(0, 10, m))
        t -= t[0]
        per = t[-1] + rng.uniform(0.1, 3)
        codes = rng.choice(3, m, p=[0.6, 0.25, 0.15])
        al = np.sort(rng.choice(m, n, replace=False))
        out = spread_alignment(t, per, codes, al)
        assert out.shape == (n,) and np.all(np.diff(out) > 0)
        assert np.array_equal(codes[out], codes[al])  # same codes, hence the same utility
        assert gap_cost(t, per, out) <= gap_cost(t, per, al) + 1e-12
        assert gap_cost(t, per, out) == pytest.approx(brute_spread(t, per, codes, al))


def test_spread_alignment_single_vertex_unchanged():
    assert spread_alignment(np.arange(5.0), 5.0, np.zeros(5, int), np.array([3])).tolist() == [3]


# ---------------------------------------------------------------------------------------------
# place_match


def test_place_match_user_coordinates_and_same_utility(ranked, cat, lat):
    shp, r, _ = ranked["lshape"]
    ann = r.annotation
    for m in r.results[:3]:
        pl = place_match(shp, ann, cat, m)
        loop = pl.mesh.boundary
        # boundary vertices exactly on annotated points, in user coordinates
        assert np.allclose(pl.xy[loop], shp.to_user(ann.positions[pl.alignment]), atol=1e-12)
        lo, hi = shp.user_points.min(axis=0), shp.user_points.max(axis=0)
        assert np.all(pl.xy >= lo - 1e-9) and np.all(pl.xy <= hi + 1e-9)
        # quality is that of the user coordinates
        sj = quality(pl.xy, pl.mesh.quads)[0]
        assert np.array_equal(sj, pl.scaled_jacobian)
        assert pl.inverted == int(inverted_mask(pl.xy, pl.mesh.quads).sum())
        assert pl.mesh_area == pytest.approx(float(quad_areas(pl.xy, pl.mesh.quads).sum()))
        # the re-spread alignment keeps the ranked utility
        vals = cat.bucket(m.boundary_length).valences[list(cat.bucket(m.boundary_length).ids).index(m.mesh_id)]
        assert utility_of(ann.codes, vals, lat, m.rotation, m.reflected, pl.alignment) == m.utility  # skip weights included


def test_place_match_follows_translation_and_scaling(ranked, cat):
    shp, r, _ = ranked["square"]
    m = r.results[0]
    base = place_match(shp, r.annotation, cat, m)
    moved = make_shape(shp.user_points * 7.5 + np.array([100.0, -3.0]), shp.corners)
    pl = place_match(moved, annotate(moved, len(r.annotation.codes)), cat, m)
    assert np.allclose(pl.xy, base.xy * 7.5 + np.array([100.0, -3.0]), atol=1e-6)
    assert np.allclose(pl.scaled_jacobian, base.scaled_jacobian, atol=1e-9)
    assert pl.region_area == pytest.approx(base.region_area * 7.5**2)


def test_place_match_uses_cache(ranked, cat):
    shp, r, _ = ranked["triangle"]
    cache = {}
    a = place_match(shp, r.annotation, cat, r.results[0], placements=cache)
    assert cache == {r.results[0].mesh_id: a}
    assert place_match(shp, r.annotation, cat, r.results[0], placements=cache) is a


def test_spread_never_worse_than_given_alignment_on_examples(ranked, cat):
    for shp, r, _ in ranked.values():
        for m in r.results[:3]:
            spread = place_match(shp, r.annotation, cat, m)
            raw = place_match(shp, r.annotation, cat, m, spread=False)
            assert np.array_equal(raw.alignment, m.alignment)
            assert gap_cost(r.annotation.t, r.annotation.perimeter, spread.alignment) <= gap_cost(
                r.annotation.t, r.annotation.perimeter, m.alignment) + 1e-12


# ---------------------------------------------------------------------------------------------
# ties


def test_rank_default_is_id_order(ranked, cat, lat):
    shp, r_id, _ = ranked["triangle"]
    again = rank(shp, cat, lat, top=8, tie_break="id")
    assert [m.mesh_id for m in again.results] == [m.mesh_id for m in r_id.results]
    assert r_id.placements is None
    with pytest.raises(ValueError):
        rank(shp, cat, lat, top=3, tie_break="nope")


def test_geometry_tie_break_only_reorders_ties(ranked):
    for shp, r_id, r_geo in ranked.values():
        assert [m.utility for m in r_geo.results] == [m.utility for m in r_id.results]
        placed = r_geo.placements
        for u, grp in itertools.groupby(r_geo.results, key=lambda m: m.utility):
            grp = list(grp)
            if len(grp) > 1:
                keys = [geometry_key(placed[m.mesh_id], m.mesh_id) for m in grp]
                assert keys == sorted(keys)
        # only tied meshes were placed
        utils = [m.utility for m in r_geo.results]
        for m in r_geo.results:
            if utils.count(m.utility) > 1:
                assert m.mesh_id in placed


def test_geometry_ranking_is_prefix_consistent_and_following_continues(ranked, cat, lat):
    shp, _, r8 = ranked["lshape"]
    r3 = rank(shp, cat, lat, top=3, tie_break="geometry")
    assert [m.mesh_id for m in r3.results] == [m.mesh_id for m in r8.results[:3]]
    nxt = list(islice(r3.following, 5))
    assert [m.mesh_id for m in nxt] == [m.mesh_id for m in r8.results[3:8]]


def test_geometry_prefers_valid_higher_quality(ranked):
    """Among tied meshes, inverted ones never precede valid ones."""
    for shp, _, r_geo in ranked.values():
        for u, grp in itertools.groupby(r_geo.results, key=lambda m: m.utility):
            grp = [r_geo.placements.get(m.mesh_id) for m in grp]
            if len(grp) > 1:
                inv = [p.inverted > 0 for p in grp]
                assert inv == sorted(inv)


def test_rerank_ties_cap_and_singletons(ranked, cat):
    shp, r_id, _ = ranked["square"]
    ms = r_id.results
    cache = {}
    out = rerank_ties(shp, r_id.annotation, cat, ms, cap=0, placements=cache)
    assert out == list(ms) and cache == {}
    cache = {}
    out = rerank_ties(shp, r_id.annotation, cat, ms, cap=64, placements=cache)
    assert sorted(m.mesh_id for m in out) == sorted(m.mesh_id for m in ms)
    counts = {u: sum(1 for m in ms if m.utility == u) for u in {m.utility for m in ms}}
    assert set(cache) == {m.mesh_id for m in ms if counts[m.utility] > 1}  # singletons not placed
    cache2 = {}
    rerank_ties(shp, r_id.annotation, cat, ms, cap=1, placements=cache2)
    assert len(cache2) <= 1


def test_per_size_with_geometry(cat, lat):
    shp = load_shape(EXAMPLES / "square.json")
    r = rank(shp, cat, lat, top=2, per_size=True, tie_break="geometry")
    ks = [m.internal_vertices for m in r.results]
    assert ks == sorted(ks) and r.following is None
    for k in set(ks):
        assert ks.count(k) <= 2


# ---------------------------------------------------------------------------------------------
# walking for a valid mesh


def test_first_valid_skips_folded(ranked, cat, lat):
    shp = ranked["triangle"][0]
    r_id = rank(shp, cat, lat, top=16)  # deep enough to hold folded meshes too (the top 8 of fine all embed)
    ann = r_id.annotation
    cache = {}
    pls = [place_match(shp, ann, cat, m, placements=cache) for m in r_id.results]
    assert any(p.inverted for p in pls) and any(p.inverted == 0 for p in pls), "example needs both kinds"
    folded = [m for m, p in zip(r_id.results, pls) if p.inverted]
    good = [m for m, p in zip(r_id.results, pls) if p.inverted == 0]
    i, m, pl = first_valid(shp, ann, cat, folded + good, placements=cache)
    assert i == len(folded) and m is good[0] and pl.inverted == 0
    assert first_valid(shp, ann, cat, folded, placements=cache) is None
    assert first_valid(shp, ann, cat, folded + good, limit=len(folded), placements=cache) is None


def test_choose_mesh_reports_and_requires_valid(cat, lat):
    shp = load_shape(EXAMPLES / "triangle.json")
    ranking = rank(shp, cat, lat, top=12, tie_break="geometry")
    pls = place_top(shp, ranking, cat)
    bad = next(i for i, p in enumerate(pls) if p.inverted) + 1  # 1-based rank of a folded mesh
    want = next(i for i, p in enumerate(pls) if i + 1 > bad and p.inverted == 0) + 1

    c = choose_mesh(shp, cat, lat, rank=bad)
    assert not c.valid and c.rank == bad and c.match.mesh_id == ranking.results[bad - 1].mesh_id
    assert c.alternative is not None and c.alternative[0] == want
    assert c.alternative[1].mesh_id == ranking.results[want - 1].mesh_id and c.alternative[2].inverted == 0

    v = choose_mesh(shp, cat, lat, rank=bad, require_valid=True)
    assert v.valid and v.rank == want and v.requested_rank == bad and v.alternative is None

    top = choose_mesh(shp, cat, lat)
    assert top.rank == 1 and top.valid and top.searched == 0

    with pytest.raises(InputError, match="only 1 meshes"):
        choose_mesh(shp, cat, lat, rank=2, internal=[0])  # k = 0: the single quad


# ---------------------------------------------------------------------------------------------
# output helpers


def test_check_outputs():
    check_outputs("a.vtk", "a.png", "a.svg")
    check_outputs(None, None, None)
    for kw in ({"out": "a.stl"}, {"png": "a.svg"}, {"svg": "a.png"}, {"out": "noext"}):
        with pytest.raises(InputError):
            check_outputs(**kw)


def test_draw_placements_png(tmp_path, ranked, cat):
    shp, r, _ = ranked["lshape"]
    pls = place_top(shp, r, cat)[:2]
    path = draw_placements(tmp_path / "p.png", shp, r.annotation, [("a", pls[0]), ("b", pls[1])], title="two")
    assert path.read_bytes().startswith(PNG_MAGIC)
    assert [p.name for p in tmp_path.iterdir()] == ["p.png"]
