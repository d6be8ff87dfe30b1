"""The side-count program without HiGHS where it falls apart into strips
(:func:`jaxmatch.placement.milp.strip_counts`).

Specification:

* on grids of rectangles (each patch side one layout side, one chord along it) every answer
  ``strip_counts`` gives is HiGHS's answer to the same program, and the one optimum of a brute
  force search over the strips' counts;
* so also where T-junctions tie strips together (rectangles cut across again and again) and
  where several chords run along one side (three quads around a vertex);
* it gives no answer (None: HiGHS solves the program) where a side crosses several chords, on a
  tie, and on requested counts that contradict each other;
* meshes are the same with it and without it.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import jaxmatch
from jaxmatch.placement import milp, solve
from jaxmatch.placement.layout import layout_sides, make_layout
from jaxmatch.placement.milp import CHORD_WEIGHT, LayoutInfeasible, count_cost, solve_counts, strip_counts

EX = Path(__file__).resolve().parent.parent / "examples"
QUAD = np.array([[1, 0], [0, 1], [1, 0], [0, 1]])  # a quad template: opposite sides cross one chord
TRI = np.array([[1, 0, 1], [1, 1, 0], [0, 1, 1]])  # three quads around a vertex: two chords a side


def grid(widths, heights):
    """A grid of rectangles, columns ``widths`` wide and rows ``heights`` high: ``(layout, sides)``."""
    xs, ys = np.concatenate([[0.0], np.cumsum(widths)]), np.concatenate([[0.0], np.cumsum(heights)])
    nx = len(xs)
    pid = lambda i, j: j * nx + i  # noqa: E731
    pts = [[float(x), float(y)] for y in ys for x in xs]
    patches = [[pid(i, j), pid(i + 1, j), pid(i + 1, j + 1), pid(i, j + 1)]
               for j in range(len(heights)) for i in range(len(widths))]
    lay = make_layout(pts, patches, corners=list(range(len(pts))))
    return lay, layout_sides(lay)


def chord_targets(sides, size):
    """Each quad's chord targets as :func:`solve_counts` makes them from its widths: the mean
    length of the two sides it crosses over the size, at least 1."""
    tau = []
    for ps in sides.patch_sides:
        s = [int(np.asarray(x).ravel()[0]) for x in ps]
        L = sides.lengths
        tau.append(np.maximum(np.array([(L[s[0]] + L[s[2]]) / 2, (L[s[1]] + L[s[3]]) / 2]) / size, 1.0))
    return tau


def highs(*args, **kw):
    """:func:`solve_counts` with every program sent to HiGHS."""
    old, milp.STRIPS = milp.STRIPS, False
    try:
        return solve_counts(*args, **kw)
    finally:
        milp.STRIPS = old


def brute(sides, n_patches, counts, size, floors, top=12):
    """``(cost, counts per side)`` of every assignment of 1..``top`` edges to the strips (the sets
    of sides one count runs through: a quad's opposite sides), best first (numpy)."""
    comp = list(range(len(sides.chains)))

    def root(x):
        while comp[x] != x:
            x = comp[x]
        return x

    pairs = []
    for ps in sides.patch_sides[:n_patches]:
        s = [int(np.asarray(x).ravel()[0]) for x in ps]
        for a, b in ((s[0], s[2]), (s[1], s[3])):
            comp[max(root(a), root(b))] = min(root(a), root(b))
            pairs.append((a, b))
    roots = sorted({root(s) for s in range(len(comp))})
    vals = np.array(list(itertools.product(range(1, top + 1), repeat=len(roots))))  # (N, strips)
    n = vals[:, [roots.index(root(s)) for s in range(len(comp))]]  # (N, S)
    free = [s for s in range(len(comp)) if s not in counts]  # (a requested count stands for its side's floor)
    ok = np.all(n[:, free] >= floors[free], axis=1)
    for s, c in counts.items():
        ok &= n[:, s] == c
    L = sides.lengths
    cost = np.abs(n[:, free] - L[free] / size).sum(axis=1)
    for a, b in pairs:
        cost = cost + CHORD_WEIGHT * np.abs(n[:, a] - max((L[a] + L[b]) / 2 / size, 1.0))
    order = np.lexsort((np.arange(ok.sum()), cost[ok]))
    return [(float(cost[ok][i]), tuple(n[ok][i].tolist())) for i in order[:2]]


@settings(max_examples=60)
@given(widths=st.lists(st.sampled_from([0.5, 1.0, 1.25, 2.0, 3.0]), min_size=1, max_size=3),
       heights=st.lists(st.sampled_from([0.5, 1.0, 1.75, 2.5]), min_size=1, max_size=2),
       size=st.sampled_from([0.45, 0.7, 1.0, 1.3]), data=st.data())
def test_strips_are_highs_answer_and_the_brute_force_optimum(widths, heights, size, data):
    lay, sd = grid(widths, heights)
    S = len(sd.chains)
    mats = [QUAD] * lay.n_patches
    counts = data.draw(st.dictionaries(st.integers(0, S - 1), st.integers(1, 6), max_size=2))
    floors = np.array(data.draw(st.lists(st.integers(1, 3), min_size=S, max_size=S)))
    widths_ = [np.array(t) * size for t in chord_targets(sd, size)]
    tau = np.concatenate(chord_targets(sd, size))
    targets = {s: float(sd.lengths[s]) / size for s in range(S) if s not in counts}
    got = strip_counts(sd, mats, counts, targets, tau, floors)
    try:
        ref = highs(sd, mats, counts=counts, size=size, widths=widths_, floors=floors)
    except LayoutInfeasible:
        assert got is None  # contradictory requests: HiGHS's program explains
        return
    best = brute(sd, lay.n_patches, counts, size, floors)
    if got is None:  # no answer only on a tie (or near one) of the best two
        assert len(best) > 1 and best[1][0] - best[0][0] <= milp.STRIP_MARGIN * max(1.0, best[0][0]) + 1e-9
        return
    mults, n = got
    assert n.tolist() == ref[1].tolist() and all(a.tolist() == b.tolist() for a, b in zip(mults, ref[0]))
    assert tuple(n.tolist()) == best[0][1] and (len(best) == 1 or best[1][0] > best[0][0])
    for p, (A, m) in enumerate(zip(mats, mults)):  # shared sides: one count
        assert np.array_equal(A @ m, [n[np.asarray(parts).ravel()].sum() for parts in sd.patch_sides[p]])


def guillotine(cuts):
    """A rectangle cut again and again: ``cuts`` are ``(piece, vertical, fraction)``, each cutting
    that piece (by index, modulo the pieces so far) across at that fraction of its width or
    height, so that later cuts end on earlier ones (T-junctions). Returns ``(layout, sides)``."""
    rects = [(0.0, 0.0, 3.0, 2.0)]
    for k, vertical, f in cuts:
        x0, y0, x1, y1 = rects.pop(k % len(rects))
        if vertical:
            xm = x0 + f * (x1 - x0)
            rects += [(x0, y0, xm, y1), (xm, y0, x1, y1)]
        else:
            ym = y0 + f * (y1 - y0)
            rects += [(x0, y0, x1, ym), (x0, ym, x1, y1)]
    pts = sorted({(x, y) for r in rects for x, y in ((r[0], r[1]), (r[2], r[1]), (r[2], r[3]), (r[0], r[3]))})
    P = np.array(pts)
    patches = []
    for x0, y0, x1, y1 in rects:  # every point on the rectangle's outline, counter-clockwise from (x0, y0)
        def along(x, y):
            if y == y0 and x0 <= x < x1:
                return x - x0
            if x == x1 and y0 <= y < y1:
                return (x1 - x0) + (y - y0)
            if y == y1 and x0 < x <= x1:
                return (x1 - x0) + (y1 - y0) + (x1 - x)
            if x == x0 and y0 < y <= y1:
                return 2 * (x1 - x0) + (y1 - y0) + (y1 - y)
            return None
        on = [(along(x, y), i) for i, (x, y) in enumerate(pts) if along(x, y) is not None]
        patches.append([i for _, i in sorted(on)])
    lay = make_layout(P.tolist(), patches, corners=list(range(len(pts))))
    return lay, layout_sides(lay)


@settings(max_examples=60)
@given(cuts=st.lists(st.tuples(st.integers(0, 5), st.booleans(), st.sampled_from([0.25, 0.4, 0.5, 0.6])),
                     min_size=1, max_size=5),
       size=st.sampled_from([0.35, 0.5, 0.7, 1.0]), data=st.data())
def test_t_junctions_strips_are_highs_answer(cuts, size, data):
    """Rectangles cut across again and again (T-junctions, requested counts, floors): every
    answer strip_counts gives is HiGHS's to the same program."""
    lay, sd = guillotine(cuts)
    S = len(sd.chains)
    mats = [QUAD] * lay.n_patches
    counts = data.draw(st.dictionaries(st.integers(0, S - 1), st.integers(1, 6), max_size=1))
    floors = np.array(data.draw(st.lists(st.integers(1, 2), min_size=S, max_size=S)))
    L = sd.lengths
    tau = []
    for ps in sd.patch_sides:
        side = [float(L[np.asarray(x).ravel()].sum()) for x in ps]
        tau.append(np.maximum(np.array([(side[0] + side[2]) / 2, (side[1] + side[3]) / 2]) / size, 1.0))
    targets = {s: float(L[s]) / size for s in range(S) if s not in counts}
    got = strip_counts(sd, mats, counts, targets, np.concatenate(tau), floors)
    try:
        ref = highs(sd, mats, counts=counts, size=size, widths=[t * size for t in tau], floors=floors)
    except LayoutInfeasible:
        assert got is None
        return
    if got is not None:
        assert got[1].tolist() == ref[1].tolist() and all(a.tolist() == b.tolist() for a, b in zip(got[0], ref[0]))


def test_t_junction_answered_and_no_answer_where_the_program_does_not_fall_apart_into_strips():
    # a 2 x 1 block below two squares: the block's top side is two layout sides (a T-junction)
    lay = make_layout([[0, 0], [2, 0], [2, 1], [0.7, 1], [0, 1], [0.7, 2], [0, 2], [2, 2]],
                      [[0, 1, 2, 3, 4], [4, 3, 5, 6], [3, 2, 7, 5]])
    sd = layout_sides(lay)
    targets = {s: float(sd.lengths[s]) / 0.3 for s in range(len(sd.chains))}
    mults, n = strip_counts(sd, [QUAD] * 3, {}, targets, np.ones(6))
    ref = highs(sd, [QUAD] * 3, size=0.3)
    assert n.tolist() == ref[1].tolist() == [6, 3, 4, 2, 3, 3, 2, 3, 3, 4]
    assert n[2] + n[3] == n[0] == mults[0][0]  # the block's top: the two squares' bottoms together
    block = np.array([[1, 0], [0, 1], [1, 1], [0, 1]])  # two chords along the block's top, two layout sides
    assert strip_counts(sd, [block, QUAD, QUAD], {}, targets, np.ones(6)) is None
    lay, sd = grid([1.0], [1.0])
    assert strip_counts(sd, [QUAD], {}, {s: 2.5 for s in range(4)}, np.full(2, 2.5)) is None  # 2 or 3: a tie
    assert strip_counts(sd, [QUAD], {0: 3, 2: 4}, {1: 2.0, 3: 2.0}, np.full(2, 2.0)) is None  # both ends of a strip
    mults, n = strip_counts(sd, [QUAD], {0: 3}, {1: 2.2, 2: 2.9, 3: 2.2}, np.array([3.0, 2.2]))
    assert n.tolist() == [3, 2, 3, 2] and [m.tolist() for m in mults] == [[3, 2]]


@pytest.mark.parametrize("name", ["tshape.json", "square.json", "labels/shapes/ushape.json", "labels/shapes/trapezoid.json",
                                  "triangle.json", "hexagon.json"])
@pytest.mark.parametrize("div", [16, 32])
def test_meshes_are_the_same_without_highs_on_strips(monkeypatch, name, div):
    """A mesh whose programs strip_counts answers is the mesh HiGHS's answers give."""
    seen = []
    real = milp.strip_counts

    def spy(*a, **k):
        seen.append(real(*a, **k))
        return seen[-1]

    monkeypatch.setattr(milp, "strip_counts", spy)
    cat = jaxmatch.load_catalogue()
    shp = jaxmatch.load_shape(EX / name)
    cat.cache.forget_shapes()
    a = jaxmatch.mesh(shp, divisions=div)
    assert any(s is not None for s in seen) or name in ("triangle.json", "hexagon.json")  # (symmetric: ties)
    monkeypatch.setattr(milp, "STRIPS", False)
    cat.cache.forget_shapes()
    b = jaxmatch.mesh(shp, divisions=div)
    assert a.chosen == b.chosen and np.array_equal(a.quads, b.quads) and np.array_equal(a.xy, b.xy)


@settings(max_examples=60)
@given(lengths=st.lists(st.sampled_from([0.5, 1.0, 1.4, 2.0, 3.1]), min_size=3, max_size=3),
       size=st.sampled_from([0.2, 0.35, 0.5, 0.8]), req=st.one_of(st.none(), st.tuples(st.integers(0, 2), st.integers(2, 9))),
       floors=st.lists(st.integers(1, 4), min_size=3, max_size=3))
def test_sums_of_chords_are_highs_answer(lengths, size, req, floors):
    """A three-sided template (three quads around a vertex: each side two chords, a sum) with
    requested counts and floors: every answer strip_counts gives is HiGHS's."""
    tri = layout_sides(make_layout([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]]))
    sd = tri._replace(lengths=np.array(lengths))
    counts = dict([req]) if req else {}
    targets = {s: lengths[s] / size for s in range(3) if s not in counts}
    tau = np.maximum(np.array([lengths[0] + lengths[1], lengths[1] + lengths[2], lengths[0] + lengths[2]]) / 4 / size, 1.0)
    fl = np.array(floors)
    got = strip_counts(sd, [TRI], counts, targets, tau, fl)
    try:
        ref = highs(sd, [TRI], counts=counts, size=size, widths=[tau * size], floors=fl)
    except LayoutInfeasible:
        assert got is None
        return
    if got is not None:
        assert got[1].tolist() == ref[1].tolist() and got[0][0].tolist() == ref[0][0].tolist()


def _mesh_a_few(field: bool = False) -> None:
    """lshape, tshape and letter-A at P/24 (shapes forgotten first: their programs solved again),
    and with ``field`` the graded strip (a size field's template choice)."""
    from jaxmatch.field import load_field

    jaxmatch.load_catalogue().cache.forget_shapes()
    for name in ("lshape.json", "tshape.json", "holes/letter-A.json"):
        jaxmatch.mesh(jaxmatch.load_shape(EX / name), divisions=24)
    if field:
        jaxmatch.mesh(jaxmatch.load_shape(EX / "graded" / "strip.json"), size=load_field(EX / "graded" / "strip.field.json"))


def test_the_model_passed_as_arrays_solves_as_the_model_passed_as_an_lp(monkeypatch, recorded):
    """Every integer program of a few meshes (side counts, feasibility checks, and a size field's
    template choice with its own HiGHS options), passed to HiGHS as numpy arrays in one call, gives
    the status and the solution bit for bit that the same program passed as a ``HighsLp`` gives."""
    real = milp._highs
    progs = recorded(milp, "_highs", lambda: _mesh_a_few(field=True))
    assert len(progs) >= 10 and any(k.get("options") for _, k in progs)  # (the template choice's)
    assert any(not np.any(a[4]) for a, _ in progs)  # (a linear relaxation: the choice screens)
    got = {}
    for arrays in (True, False):
        monkeypatch.setattr(milp, "PASS_ARRAYS", arrays)
        got[arrays] = [real(*a, **k) for a, k in progs]
    for (st_a, x_a, _), (st_l, x_l, _) in zip(got[True], got[False]):
        assert st_a == st_l and (x_a is None) == (x_l is None)
        if x_a is not None:
            assert x_a.tobytes() == x_l.tobytes()


def _dense_side_rows(sides, matrices, equal=()):
    """The rows of _side_rows written out one entry at a time from their definition (dense)."""
    offs = np.cumsum([0] + [np.shape(A)[1] for A in matrices])
    M, S = int(offs[-1]), len(sides.chains)
    rows = []
    for p, A in enumerate(matrices):
        for i, ids in enumerate(sides.patch_sides[p]):
            r = np.zeros(M + S)
            r[offs[p]:offs[p + 1]] = np.asarray(A, np.float64)[i]
            r[M + np.unique(np.asarray(ids, np.int64))] = -1.0
            rows.append(r)
    for a, b in equal:
        r = np.zeros(M + S)
        r[M + np.unique(np.asarray(a, np.int64))] += 1.0
        r[M + np.unique(np.asarray(b, np.int64))] -= 1.0
        rows.append(r)
    return np.array(rows).reshape(len(rows), M + S)


def test_the_side_rows_of_real_layouts_are_their_definition(recorded):
    """The patch sides' rows of every program of a few meshes (many patches, T-junctions, sides
    listed twice) and of a periodic pair: each entry once, the dense matrix of the definition."""
    real = milp._side_rows
    calls = recorded(milp, "_side_rows", _mesh_a_few)
    lay, sd = grid([1.0, 2.0], [1.0, 0.5])
    calls.append(((sd, [QUAD] * 4), {"equal": [([0, 1], [2]), ([3], [3, 4])]}))
    assert len(calls) >= 5 and max(len(a[1]) for a, _ in calls) >= 8
    for a, k in calls:
        row, col, val, n0 = real(*a, **k)
        dense = _dense_side_rows(*a, **k)
        assert n0 == dense.shape[0] and len(set(zip(row.tolist(), col.tolist()))) == row.size and np.all(val != 0)
        got = np.zeros_like(dense)
        got[row, col] = val
        np.testing.assert_array_equal(got, dense)


def _meets_the_rows(sides, matrices, mults, n, counts) -> bool:
    """Every patch side's chords sum to the counts of the layout sides along it, requested counts
    met, every count and multiplicity at least 1 (the program's constraints, from their definition)."""
    for p, A in enumerate(matrices):
        for i, ids in enumerate(sides.patch_sides[p][:np.shape(A)[0]]):
            if int(np.asarray(A)[i] @ mults[p]) != int(np.sum(n[np.unique(np.asarray(ids, np.int64))])):
                return False
    return all(n[s] == c for s, c in counts.items()) and min(n) >= 1 and all(min(m) >= 1 for m in mults if len(m))


def test_the_boxed_program_gives_an_optimum_of_the_whole_program(monkeypatch, recorded):
    """Every count program of a few meshes (uniform and a size field's), solved by HiGHS with every
    count bounded by ``count_box`` (the fast search's ``box``), meets the program's rows and costs
    what the unbounded program's optimum costs (one optimum of the same program; among equally
    good counts possibly another). The box holds the unbounded answer whenever that costs at most
    its limit."""
    monkeypatch.setattr(milp, "STRIPS", False)  # (every program to HiGHS)
    calls = recorded(solve, "solve_counts", lambda: _mesh_a_few(field=True))  # (the layouts' programs)
    assert len(calls) >= 10 and any(k.get("side_targets") is not None for _, k in calls)
    bounded = 0
    for a, k in calls:
        k = {key: v for key, v in k.items() if key != "box"}
        try:
            free = milp.solve_counts(*a, **k)
        except LayoutInfeasible:
            with pytest.raises(LayoutInfeasible):
                milp.solve_counts(*a, **k, box=True)
            continue
        boxed = milp.solve_counts(*a, **k, box=True)
        sides, matrices = a[0], a[1]
        assert _meets_the_rows(sides, matrices, *boxed, k.get("counts") or {})
        size = k.get("size") or float(sum(sides.lengths[s] for s in k["counts"]) / sum(k["counts"].values()))
        cost = [count_cost(sides, *r, size=size, widths=k.get("widths"), counts=k.get("counts"),
                           side_targets=k.get("side_targets"), chord_targets=k.get("chord_targets"),
                           chord_weight=k.get("chord_weight", CHORD_WEIGHT)) for r in (free, boxed)]
        assert cost[1] == pytest.approx(cost[0], rel=2e-4, abs=1e-6)
        S = len(sides.chains)
        counts = k.get("counts") or {}
        targets = {s: float(k["side_targets"][s]) if k.get("side_targets") is not None else float(sides.lengths[s]) / size
                   for s in range(S) if s not in counts}
        off = milp._chord_offsets(matrices)
        lb = np.ones(int(off[-1]) + S)
        ub = np.full(lb.size, np.inf)
        for s, v in counts.items():
            lb[off[-1] + s] = ub[off[-1] + s] = v
        box = milp.count_box(milp._side_rows(sides, matrices, k.get("equal", ())), int(off[-1]), S, targets, lb, ub)
        if box is not None and cost[0] <= box[1]:
            x = np.concatenate([*free[0], free[1]]).astype(np.float64)
            assert np.all(x <= box[0][:x.size]), "the box cuts off an optimum within its limit"
            bounded += 1
    assert bounded >= 10


@pytest.mark.parametrize("above, boxed", [(0, True), (10**9, False)])
def test_programs_larger_than_box_above_are_boxed_in_every_search(monkeypatch, recorded, above, boxed):
    """``BOX_ABOVE``: a program of more columns is boxed without being asked (``box=False``); a
    smaller one only when asked."""
    monkeypatch.setattr(milp, "STRIPS", False)
    monkeypatch.setattr(milp, "BOX_ABOVE", above)
    lay, sd = grid([1.0, 2.0], [1.0, 0.5])
    calls = recorded(milp, "count_box", lambda: solve_counts(sd, [QUAD] * 4, size=0.25))
    assert bool(calls) == boxed
