"""The candidates as strategy objects (:mod:`jaxmatch.meshing.strategies`): each kind one object,
run once per request in one plan, chosen once; the policy reaches every level."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import jaxmatch
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.field import Field
from jaxmatch.meshing import strategies as S
from jaxmatch.meshing.result import Candidate
from jaxmatch.placement import refine, solve
from jaxmatch.placement.decompose import STRATEGIES, decompose, same_cuts, single_patch

EX = Path(__file__).resolve().parent.parent / "examples"


def test_layout_strategies_are_the_named_ones():
    sts = S.layout_strategies(("single",) + STRATEGIES)
    assert [s.name for s in sts] == ["single", *STRATEGIES]
    assert isinstance(sts[0], S.Single) and sts[0].single and sts[0].sizes == solve.ALL_SIZES
    assert all(isinstance(s, S.Split) and not s.single and s.sizes == solve.TEMPLATE_SIZES for s in sts[1:])


@pytest.mark.parametrize("name", STRATEGIES)
def test_a_split_cuts_as_decompose(name):
    shp = jaxmatch.load_shape(EX / "tshape.json")
    split = S.Split(name)
    assert split.kind(shp) == same_cuts(shp, name)
    a, b = split.layout(shp, 1.0), decompose(shp, name, check=False)
    assert np.array_equal(a.points, b.points) and all(np.array_equal(p, q) for p, q in zip(a.patches, b.patches))
    one = S.Single().layout(shp, 1.0)
    assert one.n_patches == 1 and np.array_equal(one.points, single_patch(shp).points)


class _Fixed:
    """A strategy that always runs and gives the candidates it was made with."""

    def __init__(self, *cands, when=lambda best: True):
        self.cands, self.when = cands, when

    def wanted(self, best, tried, req):
        return self.when(best)

    def candidates(self, req, tried):
        return list(self.cands)


def test_run_tries_a_strategy_only_when_its_condition_holds_and_inserts_after_single(cat):
    m = jaxmatch.mesh(EX / "square.json", divisions=8, catalogue=cat)
    req = S.Request(None, cat, None, 1.0, np.zeros((0, 2)), QUALITY, None, 0.0, None)
    first = _Fixed(Candidate("single", m), Candidate("recursive", None, "no cuts"))
    never = _Fixed(Candidate("never", m), when=lambda best: False)

    class Late(S.Larger):  # after the single candidate, when the best is below the floor
        def wanted(self, best, tried, req):
            return best is not None

        def candidates(self, req, tried):
            return [Candidate("single late", m)]

    tried = S.run((first, never, Late(), _Fixed(Candidate("end", m))), req)
    assert [c.name for c in tried] == ["single", "single late", "recursive", "end"]
    assert S.run((_Fixed(Candidate("a", None, "x")), _Fixed(Candidate("b", m))), req) == [Candidate("a", None, "x")]


def test_the_policy_reaches_the_solve_and_the_refinement(cat, monkeypatch):
    """``jaxmatch.mesh(..., quality=q)``: every layout solve and every refinement gets ``q``
    (not a module copy of the defaults), and a stricter floor changes the patch rounds."""
    seen = []
    real_solve, real_refine = solve._mesh_layout, refine._refine_and_place

    def spy_solve(*a, quality, **k):
        seen.append(("solve", quality))
        return real_solve(*a, quality=quality, **k)

    def spy_refine(*a, quality, **k):
        seen.append(("refine", quality))
        return real_refine(*a, quality=quality, **k)

    monkeypatch.setattr(solve, "_mesh_layout", spy_solve)
    monkeypatch.setattr(refine, "_refine_and_place", spy_refine)
    strict = Quality(good_sj=0.95)
    cat.cache.clear()
    jaxmatch.mesh(EX / "tshape.json", divisions=16, catalogue=cat, quality=strict)
    assert {k for k, _ in seen} == {"solve", "refine"}
    assert all(q is strict for _, q in seen)
    cat.cache.clear()
    seen.clear()
    jaxmatch.mesh(EX / "tshape.json", divisions=16, catalogue=cat)
    assert seen and all(q == QUALITY for _, q in seen)
    cat.cache.clear()


class _OffSize:
    """A best mesh whose sides are off the size (what :class:`S.Conforming` asks of it)."""

    def sides_off_size(self, tol):
        return 1


@pytest.mark.parametrize("graded", [False, True])
def test_conforming_templates_are_tried_for_a_uniform_size_only(graded):
    """With a size field the integer program already aims at the field's integrals: the exact
    counts of :class:`S.Conforming` are not asked (a uniform size still asks them)."""
    q = QUALITY if not graded else Quality(field=Field(1.0).bind(jaxmatch.make_shape([[0, 0], [1, 0], [1, 1], [0, 1]])))
    req = S.Request(None, None, None, 1.0, np.zeros((0, 2)), q, None, 0.0, None)
    best = _OffSize()
    assert S.Conforming().wanted(best, [Candidate("single", best)], req) is (not graded)


@pytest.mark.parametrize("single_best", [True, False])
def test_graded_larger_templates_are_tried_while_the_single_patch_is_the_best_mesh(single_best):
    """With a size field the larger templates are the single patch's transitions: tried when the
    single candidate is the best mesh so far and misses the field, not where a partition already
    beats it; below the quality floor they are tried as for one size."""
    f = Field(0.2, (jaxmatch.Near("point", (1.0, 1.0), 0.04, 0.6),))
    sq = jaxmatch.make_shape([[0, 0], [2, 0], [2, 2], [0, 2]])
    single = jaxmatch.mesh(sq, size=f, strategies=["single"])
    rings = jaxmatch.mesh(sq, size=f, strategies=["rings"])
    q = Quality(field=single.field)
    assert single.size_conformity(q) > 0 and rings.size_conformity(q) < single.size_conformity(q)
    req = S.Request(None, None, None, 1.0, np.zeros((0, 2)), q, None, 0.0, None)
    tried = [Candidate("single", single), Candidate("rings", rings)]
    best = single if single_best else rings
    assert S.Larger().wanted(best, tried, req) is single_best
    floor = Quality(field=single.field, good_sj=1.01)  # every mesh below the floor: tried either way
    assert S.Larger().wanted(best, tried, S.Request(None, None, None, 1.0, np.zeros((0, 2)), floor, None, 0.0, None))
