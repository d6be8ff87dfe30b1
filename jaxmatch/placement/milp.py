"""The one integer program for side counts: :func:`solve_counts` gives every patch's chord
multiplicities and every side's edge count at once (a layout of many patches, or one template:
:func:`one_patch_sides`), and :func:`run_milp` runs it, telling solver failures from infeasible
requests in one place."""

from __future__ import annotations

import math
import threading
from typing import Mapping, NamedTuple, Sequence

import numpy as np

from jaxmatch.errors import InputError, SolverError

__all__ = ["BOX_ABOVE", "BOX_SLACK", "CHORD_WEIGHT", "Choice", "FEASIBILITY_JUMP", "LayoutInfeasible", "MILP_TIME_LIMIT", "OneSides", "PASS_ARRAYS", "SparseRows",
           "STRIPS", "STRIP_FREE", "STRIP_MARGIN", "STRIP_POINTS", "one_patch_sides", "count_cost", "counts_feasible", "run_milp",
           "count_box", "solve_choice", "solve_counts", "strip_counts"]


class LayoutInfeasible(InputError):
    """No choice of chord multiplicities meets the requested side counts.

    nearest: ``{side name: count}`` the closest feasible counts for the requested sides
    (least total absolute difference), or None when even those do not exist.
    """

    def __init__(self, problem: str, where: str | None = None, nearest: dict[str, int] | None = None):
        super().__init__(problem, where)
        self.nearest = nearest


class OneSides(NamedTuple):
    """The sides of one patch in the form :func:`solve_counts` reads (the fields of
    :class:`jaxmatch.placement.layout.Sides` it uses): side ``i`` is the patch's side ``i``."""

    chains: tuple
    names: tuple
    patch_sides: tuple
    lengths: np.ndarray


def one_patch_sides(lengths, names=None) -> OneSides:
    """One patch with ``len(lengths)`` sides of these lengths (user units), as a layout of one
    patch for :func:`solve_counts`."""
    n = len(lengths)
    return OneSides(chains=tuple(range(n)), names=tuple(names or (str(i) for i in range(n))),
                    patch_sides=(tuple(np.array([i], np.int64) for i in range(n)),),
                    lengths=np.asarray(lengths, np.float64))


CHORD_WEIGHT = 0.01
"""Weight of the secondary objective of :func:`solve_counts` (multiplicities close to
``chord width / size``, so that strips without boundary sides, and wide strips, are split to
about the size too) against the primary one (edges per side close to ``length / size``)."""


def solve_counts(sides, matrices: Sequence[np.ndarray], *, counts: Mapping[int, int] | None = None,
                 size: float | None = None, widths: Sequence[np.ndarray] | None = None,
                 source: str = "<layout>", floors: np.ndarray | None = None,
                 chord_weight: float = CHORD_WEIGHT, equal: Sequence = (), side_targets: np.ndarray | None = None,
                 chord_targets: Sequence[np.ndarray] | None = None, box: bool = False) -> tuple[list[np.ndarray], np.ndarray]:
    """Chord multiplicities of every patch from ONE integer program (``scipy.optimize.milp``).

    matrices: per patch ``(n_p, c_p) int64`` side matrix (edges of chord ``c`` on the patch's
    side ``i``); counts: ``{side id: count}`` required exactly; size: target edge length (user
    units; default: the requested sides' total length over their total count); widths: per
    patch ``(c_p,)`` chord widths (user units, :meth:`PatchTemplate.chord_widths`); floors:
    ``(S,)`` the fewest edges of each side not requested (:func:`curve_floors`); equal: pairs
    ``(side ids A, side ids B)`` whose total counts must be equal (periodic sides: a side of
    the input may be several layout sides where cuts end on it); side_targets, chord_targets: a
    size field's targets instead of ``length_s / size`` (``(S,)``, the integral of 1 / size along
    each side) and ``width_c / size`` (per patch ``(c_p,)``); box: first solve with every count
    bounded by :func:`count_box` (an optimum all the same, HiGHS much faster on large programs,
    but of equally good counts possibly another one than without).

    Variables: ``m_p >= 1`` integer per patch and chord, ``n_s >= 1`` integer per side.
    Constraints: ``A_p[i] @ m_p = sum of n_s over the layout sides along patch side i`` for
    every patch side (so a shared side has one count in both patches, a side along which two
    neighbours meet is split between them, and each patch's total is even), ``n_s = counts[s]``
    when requested, ``sum n_A = sum n_B`` for each pair of ``equal``. Objective: ``sum_s |n_s - length_s / size|`` over the sides not requested, plus
    :data:`CHORD_WEIGHT` ``* sum_c |m_c - max(width_c / size, 1)|``; each ``|x - tau|`` is a
    continuous variable bounded below by the two lines of the absolute value and by its chord
    between the integers around ``tau`` (:func:`_chord_row`: a tight relaxation, the same
    integer optimum).

    Returns ``(multiplicities per patch ((c_p,) int64), counts per side ((S,) int64))``.
    Raises :class:`LayoutInfeasible` (naming the requested sides and the nearest feasible
    counts) when the requested counts cannot be met; :class:`InputError` for a bad size or when
    neither a size nor counts are given.
    """
    counts = dict(counts or {})
    S = len(sides.chains)
    off = _chord_offsets(matrices)
    M = int(off[-1])
    if size is None:
        if not counts:
            raise InputError("give an element size or edge counts for some sides", where=source)
        size = float(sum(sides.lengths[s] for s in counts) / sum(counts.values()))
    h = float(size)
    if not (h > 0 and math.isfinite(h)):
        raise InputError(f"element size must be a positive number, got {size!r}", where=source)
    if float(np.sum(sides.lengths)) / h > 1_000_000:
        raise InputError(f"element size {h:g} gives more than 1000000 side edges", where=source)
    if chord_targets is not None:
        tau_m = np.concatenate([np.maximum(np.asarray(w, np.float64), 1.0) for w in chord_targets]) if M else np.ones(0)
    elif widths is not None:
        tau_m = np.concatenate([np.maximum(np.asarray(w, np.float64) / h, 1.0) for w in widths])
    else:
        tau_m = np.ones(M)

    rows: list = []  # (the patch sides' rows, made when a program is solved: strip_counts answers most without)

    def program(fixed: Mapping[int, int], targets: Mapping[int, float]):
        """Variables: m (M), n (S), t (T side deviations), u (M chord deviations). The rows, in
        order: one per patch side (``A_p[i] @ m_p - sum n = 0``), one per pair of ``equal``, and
        per side target then per chord the rows of :func:`_deviation_rows`; built as a
        :class:`SparseRows` (the gear's programs have thousands of rows of thousands of
        variables, each with two or three entries)."""
        if not rows:
            rows.append(_side_rows(sides, matrices, equal))
        row0, col0, val0, n0 = rows[0]
        T = len(targets)
        nv = M + S + T + M
        tau = np.concatenate([np.fromiter(targets.values(), np.float64, T), tau_m])
        x = np.concatenate([M + np.fromiter(targets.keys(), np.int64, T), np.arange(M)])
        d = M + S + np.arange(T + M)
        r, c, v, dlo = _deviation_rows(x, d, tau, n0)
        A = SparseRows((n0 + dlo.size, nv), np.concatenate([row0, r]), np.concatenate([col0, c]), np.concatenate([val0, v]))
        lo = np.concatenate([np.zeros(n0), dlo])
        hi = np.concatenate([np.zeros(n0), np.full(dlo.size, np.inf)])
        cost = np.concatenate([np.zeros(M + S), np.ones(T), np.full(M, chord_weight)])
        lb = np.concatenate([np.ones(M), np.ones(S) if floors is None else np.maximum(floors, 1), np.zeros(T + M)])
        ub = np.full(nv, np.inf)
        for s, v in fixed.items():
            lb[M + s] = ub[M + s] = float(v)
        integrality = np.concatenate([np.ones(M + S), np.zeros(T + M)])
        x = None
        top = count_box(rows[0], M, S, targets, lb, ub) if box or nv > BOX_ABOVE else None
        if top is not None:  # (an answer within the box's cost limit is an optimum of the whole program)
            x = run_milp(cost, A, lo, hi, integrality, lb, top[0])
            if x is not None and not float(cost @ x) <= top[1]:
                x = None
        if x is None:
            x = run_milp(cost, A, lo, hi, integrality, lb, ub)
        if x is None:
            return None
        x = np.rint(x).astype(np.int64)
        return [x[off[p]:off[p + 1]] for p in range(len(matrices))], x[M:M + S]

    if side_targets is not None:
        targets = {s: float(side_targets[s]) for s in range(S) if s not in counts}
    else:
        targets = {s: float(sides.lengths[s]) / h for s in range(S) if s not in counts}
    sol = None if equal or not STRIPS else strip_counts(sides, matrices, counts, targets, tau_m, floors, chord_weight)
    if sol is not None:
        return sol
    sol = program(counts, targets)
    if sol is not None:
        return sol
    names = sides.names
    near = program({}, {**targets, **{s: float(v) for s, v in counts.items()}}) if counts else None
    if near is None:  # the templates' chords tie shared sides together in contradictory ways
        raise LayoutInfeasible("no chord multiplicities give shared sides equal counts", where=source)
    nearest = {names[s]: int(near[1][s]) for s in counts}
    wrong = [s for s in counts if near[1][s] != counts[s]] or list(counts)
    detail = ", ".join(f"side {names[s]}: {counts[s]} asked, nearest feasible {nearest[names[s]]}" for s in wrong)
    raise LayoutInfeasible(f"the requested edge counts cannot be met together ({detail}; every patch needs an even "
                           "number of boundary edges, and both ends of a strip of quads get the same count)",
                           where=source, nearest=nearest)


BOX_ABOVE = 1000
"""A program of more columns than this is boxed (:func:`count_box`) whatever ``box`` says: on the
graded plate with a hole at a third of its sizes (programs of ~8,000 columns) HiGHS took 1.26 s
for one unboxed and 0.09 s boxed. No program of the benchmark's 50 cases, the graded examples
or 60 random parts at perimeter / 32 has more than 484 columns (their meshes are the unboxed ones)."""

BOX_SLACK = (3.0, 10.0)
"""``(a, b)``: the box of :func:`count_box` holds every solution of :func:`solve_counts`' program
costing at most ``a * T + b`` (``T`` sides with a target)."""


def count_box(rows, M: int, S: int, targets: Mapping[int, float], lb: np.ndarray,
              ub: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``(upper bounds (n,), cost limit)``: finite upper bounds on the counts and multiplicities of
    :func:`solve_counts`' program (its columns: ``M`` multiplicities, ``S`` side counts, then the
    deviations; ``rows`` its patch sides' rows, :func:`_side_rows`; ``lb``, ``ub`` its bounds)
    that every solution costing at most the limit meets: a side more than the limit off its
    target costs more, and a chord has at most as many edges as the sides along a patch side it
    crosses. None where a side without a target has no upper bound. HiGHS fixes columns by their
    reduced costs over up to 1,024 values each when a column has no upper bound: the box spares
    most of that."""
    row, col, val, n0 = rows
    limit = BOX_SLACK[0] * len(targets) + BOX_SLACK[1]
    top = np.array(ub, np.float64)
    t = M + np.fromiter(targets.keys(), np.int64, len(targets))
    top[t] = np.maximum(np.floor(np.fromiter(targets.values(), np.float64, len(targets)) + limit), lb[t])
    most = top[M:M + S]
    if not np.all(np.isfinite(most)):
        return None
    side = (col >= M) & (val < 0)  # (a patch side's layout sides; the rows of equal pairs have no chords)
    cap = np.zeros(n0)
    np.add.at(cap, row[side], most[col[side] - M])
    chord = col < M
    np.minimum.at(top, col[chord], np.floor(cap[row[chord]] / val[chord]))
    return top, limit


STRIPS = True
"""Whether :func:`solve_counts` first tries :func:`strip_counts` (no HiGHS run where the program
falls apart into strips with one best answer: a HiGHS run costs ~1 ms of CPU time, however small
the program); off, every program goes to HiGHS."""

STRIP_MARGIN = 2e-4
""":func:`strip_counts` answers only when every other integer solution costs more than the best
one by this share of its cost (at least this much): HiGHS stops once its solution is within
``mip_rel_gap`` (``1e-4``) of the optimum, relative to its cost (``mip_abs_gap``: ``1e-6``), so
with twice that margin its answer is that one solution too."""

STRIP_FREE = 6
"""Most strips :func:`strip_counts` enumerates together (those that no tie defines); with more,
HiGHS solves the program."""

STRIP_POINTS = 20_000
"""Most combinations of counts :func:`strip_counts` enumerates for the strips that T-junctions
tie together, and most counts it tabulates for one strip (past it, HiGHS solves the program)."""


def strip_counts(sides, matrices: Sequence[np.ndarray], counts: Mapping[int, int], targets: Mapping[int, float],
                 tau_m: np.ndarray, floors: np.ndarray | None = None,
                 chord_weight: float = CHORD_WEIGHT) -> tuple[list[np.ndarray], np.ndarray] | None:
    """:func:`solve_counts`' program solved without HiGHS where it falls apart into strips, or None.

    A patch side that is one layout side and crosses one chord once gives ``m_c = n_s``: the chords
    and sides joined so (a strip of quads) take one count ``x``, whose cost ``g(x) = sum |x -
    target_s| + chord_weight * sum |x - tau_c|`` is convex. The other rows tie strips together: a
    patch side made of several layout sides (a T-junction) ``x_chord = sum of x_side``, a layout
    side along which several chords run (a template with internal vertices) ``x_side = sum of
    edges * x_chord``; a patch side that is both gives None. A strip with a requested count takes
    it. Strips that nothing ties are solved alone: the best integer of their cost (from the lower
    bound: 1, a side's floor), the next integers on either side telling how much worse the second
    best is. The tied ones (at most :data:`STRIP_FREE` not defined by a tie) are enumerated
    together within ``g(x) <= min g + slack`` of every strip (:func:`_tied_strips`: a solution
    outside costs more than the sum of the minima plus the slack). The answer is given only when
    the whole program has that one optimum by more than :data:`STRIP_MARGIN`, so it is HiGHS's;
    else None (ties, requests that contradict each other or a floor, too many strips: HiGHS
    solves it).

    sides: a layout's sides (:class:`~jaxmatch.placement.layout.Sides` or :class:`OneSides`);
    matrices: per patch ``(n_p, c_p)`` side matrix; counts: ``{side: count}`` requested;
    targets: ``{side: length / size}`` of the other sides; tau_m: ``(M,)`` every chord's target
    (patch by patch); floors: ``(S,)`` the fewest edges per side (None: 1). Returns
    ``(multiplicities per patch ((c_p,) int64), counts per side ((S,) int64))`` as
    :func:`solve_counts`, or None."""
    S = len(sides.chains)
    off = _chord_offsets(matrices)
    M = int(off[-1])
    parent = list(range(M + S))  # chords 0..M-1, then sides

    def root(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    junctions = []  # (chord, [side nodes]): a patch side of several layout sides
    sums = []  # (side, [(chord, edges)]): a layout side along which several chords run
    offs = off.tolist()
    for p, A in enumerate(matrices):  # (Python lists: a few entries per patch side)
        A = np.asarray(A)
        ps = sides.patch_sides[p]
        if A.shape[0] < len(ps):
            return None
        rows = A[:len(ps)].tolist()
        for i in range(len(ps)):
            row = rows[i]
            nz = [c for c, v in enumerate(row) if v]
            ids = sorted(set(np.asarray(ps[i], np.int64).ravel().tolist()))
            if len(nz) < 1 or len(ids) < 1:
                return None
            if len(nz) > 1 or row[nz[0]] != 1:  # several chords (or one twice) along one layout side
                if len(ids) > 1:
                    return None
                sums.append((M + ids[0], [(offs[p] + c, int(row[c])) for c in nz]))
                continue
            if len(ids) > 1:
                junctions.append((offs[p] + nz[0], [M + x for x in ids]))
                continue
            a, b = root(offs[p] + nz[0]), root(M + ids[0])
            if a != b:
                parent[max(a, b)] = min(a, b)
    low = np.ones(M + S)
    if floors is not None:
        low[M:] = np.maximum(np.asarray(floors, np.float64), 1.0)
    tau = np.concatenate([np.asarray(tau_m, np.float64), np.zeros(S)])
    weight = np.concatenate([np.full(M, float(chord_weight)), np.zeros(S)])
    for s, t in targets.items():
        tau[M + s], weight[M + s] = float(t), 1.0
    comps: dict[int, list[int]] = {}
    for x in range(M + S):
        comps.setdefault(root(x), []).append(x)
    strips = list(comps.values())
    of = {r: g for g, r in enumerate(comps)}
    ties = [(of[root(c)], np.bincount([of[root(x)] for x in xs], minlength=len(strips))) for c, xs in junctions]
    ties += [(of[root(s_)], np.bincount([of[root(c)] for c, _ in cs], weights=[e for _, e in cs], minlength=len(strips)))
             for s_, cs in sums]
    tied = {g for g0, coef in ties for g in [g0] + np.flatnonzero(coef).tolist()}
    if len(tied - {g0 for g0, _ in ties}) > STRIP_FREE:
        return None  # (too many to enumerate)
    value = np.zeros(len(strips), np.int64)
    total, margin = 0.0, math.inf
    tables, fixed_at = {}, {}  # strip -> (first count, (k,) cost of it and the next k - 1); requested counts
    lows, taus = low.tolist(), tau.tolist()
    for g, members in enumerate(strips):
        idx = np.asarray(members, np.int64)
        w, t = weight[idx], tau[idx]
        fixed = {int(counts[x - M]) for x in members if x >= M and (x - M) in counts}
        if fixed:  # (a requested count stands for its side's floor, as in the program)
            free = [x for x in members if not (x >= M and (x - M) in counts)]
            if len(fixed) > 1 or (free and min(fixed) < max(lows[x] for x in free)):
                return None  # contradictory, or below another side's floor: HiGHS's program says so
            fixed_at[g] = value[g] = fixed.pop()
            total += float(np.sum(w * np.abs(value[g] - t)))
            continue
        slope = float(np.sum(w))  # of the cost past the largest target
        if not slope > 0:
            return None
        x0 = int(max(lows[x] for x in members))
        k = max(int(math.ceil(max(taus[x] for x in members))) - x0, 0) + 3 + min(int(math.ceil(STRIP_SLACKS[-1] / slope)), 256)
        if k > STRIP_POINTS:
            return None
        cost = np.sum(w[None, :] * np.abs(np.arange(x0, x0 + k, dtype=np.float64)[:, None] - t[None, :]), axis=1)
        tables[g] = (x0, cost)
        if g in tied:
            continue
        i = int(np.argmin(cost))
        nxt = cost[i + 1] if i == 0 else min(cost[i - 1], cost[i + 1])  # convex: the second best is a neighbour
        margin = min(margin, float(nxt - cost[i]))
        total += float(cost[i])
        value[g] = x0 + i
    if ties:
        joint = _tied_strips(ties, tied, tables, fixed_at)
        if joint is None:
            return None
        vals, g_star, second = joint
        for g, v in vals.items():
            value[g] = v
        total += g_star
        margin = min(margin, second - g_star)
    if not margin > STRIP_MARGIN * max(1.0, total):
        return None
    vals = value.tolist()
    x = np.array([vals[of[root(i)]] for i in range(M + S)], np.int64)
    return [x[off[p]:off[p + 1]].copy() for p in range(len(matrices))], x[M:].copy()


STRIP_SLACKS = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
"""The slacks :func:`_tied_strips` tries in turn (cost above each strip's best; one that cannot
hold the best solution an earlier one found is passed over)."""


def _tied_strips(ties, tied, tables, fixed_at):
    """The strips of :func:`strip_counts` that rows tie together, enumerated: ``({strip: count},
    best cost, second best cost or a bound below it)`` (the cost of the strips without a request),
    or None (no solution within :data:`STRIP_SLACKS` and :data:`STRIP_POINTS` combinations, or ties
    that do not resolve strip by strip).

    ties: ``(strip g0, (strips,) coefficients)``: ``x_g0 = coefficients @ x`` (a strip in a sum is
    at most the sum's span less the others' least); tables: per strip
    without a request ``(first count, costs (k,))``; fixed_at: requested strips' counts."""
    order = sorted(tied)
    lhs = {g0 for g0, _ in ties}
    if any(coef[g0] for g0, coef in ties):
        return None  # a strip made of itself and more: no count of at least 1
    best = {g: float(tables[g][1].min()) for g in order if g not in fixed_at}
    base = sum(best.values())
    terms = [[(h, int(coef[h])) for h in np.flatnonzero(coef).tolist()] for _, coef in ties]  # (strip, coefficient)
    need = 0.0  # (the slack the best solution found so far would need)
    for slack in STRIP_SLACKS:
        if slack < need:
            continue
        span = {}
        for g in order:
            if g in fixed_at:
                span[g] = (fixed_at[g], fixed_at[g])
                continue
            x0, cost = tables[g]
            inside = np.flatnonzero(cost <= best[g] + slack)  # (one run: the cost is convex)
            span[g] = (x0 + int(inside[0]), x0 + int(inside[-1]))  # (to the table's end: a sum bounds it below)
        for _ in range(len(ties)):  # a strip in a sum is at most the sum less the others' least
            for (g0, _), parts in zip(ties, terms):
                least = sum(c * span[h][0] for h, c in parts)
                for g, c in parts:
                    top = (span[g0][1] - least + c * span[g][0]) // c
                    span[g] = (span[g][0], min(span[g][1], top))
        if any(g not in fixed_at and span[g][1] >= tables[g][0] + tables[g][1].size - 1 for g in order):
            return None  # (a span the table does not hold)
        if any(a > b for a, b in span.values()):
            continue
        free = [g for g in order if g not in lhs]
        n = 1
        for g in free:
            n *= span[g][1] - span[g][0] + 1
        if n > STRIP_POINTS:
            return None
        x = {}  # each free strip's count at every combination, in np.meshgrid's "ij" order
        if free:
            grid = np.indices([span[g][1] - span[g][0] + 1 for g in free]).reshape(len(free), -1)
            x = {g: span[g][0] + grid[d] for d, g in enumerate(free)}
        ok = np.ones(n, bool)
        pending = list(range(len(ties)))
        while pending:  # each strip a tie defines, once its parts are known; the other ties checked
            step = [j for j in pending if all(g in x for g, _ in terms[j])]
            if not step:
                return None
            for j in step:
                g0 = ties[j][0]
                v = sum(c * x[g] for g, c in terms[j])
                if g0 in x:
                    ok &= x[g0] == v
                else:
                    ok &= (v >= span[g0][0]) & (v <= span[g0][1])
                    x[g0] = v
            pending = [j for j in pending if j not in step]
        if not ok.any():
            continue
        F = np.zeros(n)
        for g in order:
            if g not in fixed_at:
                x0, cost = tables[g]
                F = F + cost[np.minimum(np.maximum(x[g] - x0, 0), cost.size - 1)]  # (np.clip's values)
        F = np.where(ok, F, np.inf)
        i = int(np.argmin(F))
        outside = base + slack  # every solution outside the spans costs more than this
        if F[i] > outside:
            need = float(F[i]) - base  # (within that slack of their best, its strips are in the spans)
            continue
        g_star = float(F[i])
        F[i] = np.inf
        return {g: int(x[g][i]) for g in order}, g_star, min(float(F.min()), outside)
    return None


class Choice(NamedTuple):
    """The answer of :func:`solve_choice`: ``choice`` per patch the index of its chosen
    alternative; ``multiplicities`` per patch ``(c_p,) int64`` the chosen template's;
    ``counts`` ``(S,) int64`` edges per side; ``size_cost`` the size part of the objective,
    ``sum_s |n_s - target_s| + chord_weight * sum_c |m_c - tau_c|`` (penalties left out)."""

    choice: tuple
    multiplicities: list
    counts: np.ndarray
    size_cost: float


CHOICE_OPTIONS = {"mip_pool_soft_limit": 10}
"""HiGHS options of :func:`solve_choice`'s programs: a smaller cut pool (default 10000). Its
root node's cut rounds were most of its time: the three programs of the slotted link's ring
partition at P/40 took 9.1 s with the default and 3.8 s with this, the same optima."""


SCREEN_TOL = 1e-6
"""An alternative the linear relaxation gives no more than this share is left out of
:func:`solve_choice`'s program when it screens."""


def solve_choice(sides, alternatives: Sequence[Sequence[np.ndarray]], *, penalties: Sequence[Sequence[float]],
                 size: float, widths: Sequence[Sequence[np.ndarray]] | None = None, floors: np.ndarray | None = None,
                 counts: Mapping[int, int] | None = None, equal: Sequence = (), side_targets: np.ndarray | None = None,
                 chord_targets: Sequence[Sequence[np.ndarray]] | None = None, chord_weight: float = CHORD_WEIGHT,
                 bound: int | None = None, most: np.ndarray | None = None, time_limit: float | None = None,
                 start: tuple | None = None, max_nodes: int | None = None, screen: bool = False,
                 source: str = "<layout>") -> Choice:
    """The program of :func:`solve_counts` with a choice of template per patch: patch ``p`` takes
    one of its ``alternatives[p]`` (``(n_p, c_pj) int64`` side matrices), a binary variable
    ``z_pj`` per alternative (``sum_j z_pj = 1``), its multiplicities ``z_pj <= m_pjc <=
    bound * z_pj`` (so the side rows ``sum_j A_pj[i] @ m_pj = sum n_s`` read the chosen
    template's alone) and its chord deviations ``|m_pjc - tau_pjc z_pj|``. Objective: the size
    objective of :func:`solve_counts` plus ``penalties[p][j] * z_pj`` (what taking alternative
    ``j`` costs: e.g. its irregular vertices), so an alternative is taken only where it brings
    the sides nearer their targets by more than its penalty.

    widths / chord_targets: per patch, per alternative, as :func:`solve_counts` takes them for
    one template; bound: the largest multiplicity (default: three times the largest side target
    or floor, plus 4); most: ``(S,)`` the most edges each side may take (None: no limit), which
    also bounds each chord by the sides it has edges on (a tighter relaxation); time_limit:
    seconds for HiGHS (:func:`run_milp`; default :data:`MILP_TIME_LIMIT`); start: ``(multiplicities per patch, counts (S,))`` of every
    patch's first alternative, a feasible answer HiGHS starts from (a limit of time or nodes
    then answers no worse); max_nodes: the most branch-and-bound nodes (:func:`run_milp`);
    screen: first solve the linear relaxation and keep, besides each patch's first alternative,
    only those it gives a share above :data:`SCREEN_TOL` (fewer binaries: a heuristic, the
    optimum of the smaller program). A patch with one alternative is :func:`solve_counts`'
    patch. HiGHS runs with :data:`CHOICE_OPTIONS`. Returns a :class:`Choice`; raises
    :class:`LayoutInfeasible` when no choice meets the requested counts, :class:`InputError`
    for a bad size."""
    counts = dict(counts or {})
    h = float(size)
    if not (h > 0 and math.isfinite(h)):
        raise InputError(f"element size must be a positive number, got {size!r}", where=source)
    S = len(sides.chains)
    if side_targets is not None:
        targets = {s: float(side_targets[s]) for s in range(S) if s not in counts}
    else:
        targets = {s: float(sides.lengths[s]) / h for s in range(S) if s not in counts}
    blocks = [(p, j) for p in range(len(alternatives)) for j in range(len(alternatives[p]))]
    nc = [int(np.asarray(alternatives[p][j]).shape[1]) for p, j in blocks]
    off = np.concatenate([[0], np.cumsum(nc)]).astype(int)
    M, Z = int(off[-1]), len(blocks)
    tau_parts = []
    for b, (p, j) in enumerate(blocks):
        if chord_targets is not None:
            tau_parts.append(np.maximum(np.asarray(chord_targets[p][j], np.float64), 1.0))
        elif widths is not None:
            tau_parts.append(np.maximum(np.asarray(widths[p][j], np.float64) / h, 1.0))
        else:
            tau_parts.append(np.ones(nc[b]))
    tau_m = np.concatenate(tau_parts) if tau_parts else np.zeros(0)
    top = max([1.0] + list(targets.values()) + ([float(np.max(floors))] if floors is not None and len(floors) else [])
              + [float(v) for v in counts.values()])
    U = float(bound if bound is not None else 3 * math.ceil(top) + 4)
    T = len(targets)
    zc, nc0, tc, uc = M, M + Z, M + Z + S, M + Z + S + T  # first column of z, n, t, u
    ubm = np.full(M, U)  # each chord's largest multiplicity: U, or the fewest edges a side it lies on may take
    if most is not None:
        most = np.asarray(most, np.float64)
        for b, (p, j) in enumerate(blocks):
            A = np.asarray(alternatives[p][j], np.float64)
            for i, ids in enumerate(sides.patch_sides[p][:A.shape[0]]):
                cap = float(np.sum(most[np.unique(np.asarray(ids, np.int64).ravel())]))
                hit = np.flatnonzero(A[i])
                if hit.size:
                    seg = ubm[off[b]:off[b + 1]]
                    seg[hit] = np.minimum(seg[hit], np.floor(cap / A[i, hit]))
    nv = uc + M
    rr, cc, vv, lo, hi = [], [], [], [], []
    k = 0

    def row(cols, vals, low, high):
        nonlocal k
        rr.append(np.full(len(cols), k, np.int64))
        cc.append(np.asarray(cols, np.int64))
        vv.append(np.asarray(vals, np.float64))
        lo.append(low)
        hi.append(high)
        k += 1

    first = {}
    for b, (p, j) in enumerate(blocks):
        first.setdefault(p, b)
    for p, alts in enumerate(alternatives):
        ps = sides.patch_sides[p]
        b0 = first[p]
        for i in range(len(ps)):
            cols, vals = [], []
            for j in range(len(alts)):
                A = np.asarray(alts[j], np.float64)
                nzc = np.flatnonzero(A[i])
                cols += (off[b0 + j] + nzc).tolist()
                vals += A[i, nzc].tolist()
            for s in np.unique(np.asarray(ps[i], np.int64).ravel()):
                cols.append(nc0 + int(s))
                vals.append(-1.0)
            row(cols, vals, 0.0, 0.0)
        row([zc + b0 + j for j in range(len(alts))], [1.0] * len(alts), 1.0, 1.0)
    for b in range(Z):  # z <= m <= U z
        for c in range(off[b], off[b + 1]):
            row([c, zc + b], [1.0, -1.0], 0.0, np.inf)
            row([c, zc + b], [1.0, -float(ubm[c])], -np.inf, 0.0)
    for ids_a, ids_b in equal:
        a = np.unique(np.asarray(ids_a, np.int64))
        b_ = np.unique(np.asarray(ids_b, np.int64))
        cols = np.union1d(a, b_)
        vals = np.isin(cols, a).astype(np.float64) - np.isin(cols, b_)
        row((nc0 + cols[vals != 0]).tolist(), vals[vals != 0].tolist(), 0.0, 0.0)
    # side deviations: the rows of solve_counts
    ts = np.fromiter(targets.keys(), np.int64, T)
    tv = np.fromiter(targets.values(), np.float64, T)
    r, c, v, dlo = _deviation_rows(nc0 + ts, tc + np.arange(T), tv, k)
    rr.append(r)
    cc.append(c)
    vv.append(v)
    lo += dlo.tolist()
    hi += [np.inf] * dlo.size
    k += dlo.size
    # chord deviations, scaled by their patch's z: u >= |m - tau z| (and the chord of |x - tau| times z)
    zb = np.repeat(np.arange(Z), nc)
    for m in range(M):
        t_, u, z = float(tau_m[m]), uc + m, zc + int(zb[m])
        row([u, m, z], [1.0, -1.0, t_], 0.0, np.inf)
        row([u, m, z], [1.0, 1.0, -t_], 0.0, np.inf)
        ch = _chord_row(t_)
        if ch is not None:
            slope, bnd = ch
            row([u, m, z], [1.0, -slope, -bnd], 0.0, np.inf)
    A = SparseRows((k, nv), *_merged_entries(np.concatenate(rr), np.concatenate(cc), np.concatenate(vv)))
    pen = np.concatenate([[float(x) for x in penalties[p]] for p in range(len(alternatives))])
    cost = np.concatenate([np.zeros(M), pen, np.zeros(S), np.ones(T), np.full(M, chord_weight)])
    lb = np.concatenate([np.zeros(M + Z), np.ones(S) if floors is None else np.maximum(floors, 1), np.zeros(T + M)])
    ub = np.concatenate([ubm, np.ones(Z), np.full(S, np.inf) if most is None else most, np.full(T + M, np.inf)])
    for s, val in counts.items():
        lb[nc0 + s] = ub[nc0 + s] = float(val)
    integrality = np.concatenate([np.ones(M + Z + S), np.zeros(T + M)])
    x0 = None
    if start is not None:
        x0 = np.zeros(nv)
        for p, m in enumerate(start[0]):
            b = first[p]
            x0[off[b]:off[b + 1]] = m
            x0[zc + b] = 1.0
        x0[nc0:nc0 + S] = start[1]
        x0[tc:tc + T] = np.abs(np.asarray(start[1], np.float64)[ts] - tv)
        x0[uc:uc + M] = np.abs(x0[:M] - tau_m * x0[zc + zb])
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if screen and Z > len(alternatives):
        relaxed = run_milp(cost, A, lo, hi, np.zeros_like(integrality), lb, ub)
        if relaxed is None:
            raise LayoutInfeasible("no choice of templates and multiplicities meets the requested counts", where=source)
        z = relaxed[zc:zc + Z]
        kept = [[j for j in range(len(alts)) if j == 0 or z[first[p] + j] > SCREEN_TOL]
                for p, alts in enumerate(alternatives)]
        if any(len(k) < len(a) for k, a in zip(kept, alternatives)):
            sub = solve_choice(sides, [[alternatives[p][j] for j in k] for p, k in enumerate(kept)],
                               penalties=[[penalties[p][j] for j in k] for p, k in enumerate(kept)], size=size,
                               widths=None if widths is None else [[widths[p][j] for j in k] for p, k in enumerate(kept)],
                               floors=floors, counts=counts, equal=equal, side_targets=side_targets,
                               chord_targets=None if chord_targets is None else
                               [[chord_targets[p][j] for j in k] for p, k in enumerate(kept)],
                               chord_weight=chord_weight, bound=bound, most=most, time_limit=time_limit, start=start,
                               max_nodes=max_nodes, source=source)
            return sub._replace(choice=tuple(kept[p][j] for p, j in enumerate(sub.choice)))
    x = run_milp(cost, A, lo, hi, integrality, lb, ub,
                 time_limit=MILP_TIME_LIMIT if time_limit is None else time_limit, start=x0, max_nodes=max_nodes,
                 options=CHOICE_OPTIONS)
    if x is None:
        raise LayoutInfeasible("no choice of templates and multiplicities meets the requested counts", where=source)
    xi = np.rint(x[:M + Z + S]).astype(np.int64)
    choice, mults = [], []
    for p, alts in enumerate(alternatives):
        j = next(j for j in range(len(alts)) if xi[zc + first[p] + j] == 1)
        choice.append(j)
        mults.append(xi[off[first[p] + j]:off[first[p] + j + 1]].copy())
    n = xi[nc0:nc0 + S].copy()
    chosen = np.concatenate([np.arange(off[first[p] + j], off[first[p] + j + 1]) for p, j in enumerate(choice)]) \
        if M else np.zeros(0, np.int64)
    size_cost = float(np.sum(np.abs(n[ts] - tv)) + chord_weight * np.sum(np.abs(xi[chosen] - tau_m[chosen])))
    return Choice(tuple(choice), mults, n, size_cost)


def _chord_offsets(matrices: Sequence[np.ndarray]) -> np.ndarray:
    """``(P + 1,) int``: where each patch's chords start among the program's chord columns (patch
    after patch; the last entry is their number ``M``), from the ``(n_p, c_p)`` side matrices."""
    off = [0]
    for A in matrices:  # (a few patches: Python ints)
        off.append(off[-1] + int(np.shape(A)[1]))
    return np.array(off, dtype=int)


def _side_rows(sides, matrices: Sequence[np.ndarray], equal: Sequence = ()):
    """The equality rows of :func:`solve_counts`' program over its columns ``m`` (every patch's
    chords, patch after patch) then ``n`` (one per side): one row per patch side, ``A_p[i] @ m_p -
    sum of n_s over the layout sides along it = 0``, then one per pair of ``equal``. Returns
    ``(row, col, val, number of rows)`` (entries as :class:`SparseRows`)."""
    offs = _chord_offsets(matrices).tolist()
    M = offs[-1]
    er, ec, ev = [], [], []  # the patch sides' entries (Python lists: a few per patch side)
    k = 0
    for p, A in enumerate(matrices):
        ps = sides.patch_sides[p]
        for i, line in enumerate(np.asarray(A)[:len(ps)].tolist()):
            for j, v in enumerate(line):
                if v:  # a chord's edges on the side
                    er.append(k)
                    ec.append(offs[p] + j)
                    ev.append(float(v))
            for s in sorted(set(np.asarray(ps[i], np.int64).ravel().tolist())):  # a side listed twice: one entry
                er.append(k)
                ec.append(M + s)
                ev.append(-1.0)
            k += 1
    rr, cc, vv = [np.array(er, np.int64)], [np.array(ec, np.int64)], [np.array(ev, np.float64)]  # then the pairs of `equal`
    for ids_a, ids_b in equal:  # periodic sides: one count
        a = np.unique(np.asarray(ids_a, np.int64))
        b = np.unique(np.asarray(ids_b, np.int64))
        cols = np.union1d(a, b)
        vals = np.isin(cols, a).astype(np.float64) - np.isin(cols, b)
        rr.append(np.full(int(np.count_nonzero(vals)), k))
        cc.append(M + cols[vals != 0])
        vv.append(vals[vals != 0])
        k += 1
    n0 = k
    row0 = np.concatenate(rr).astype(np.int64) if rr else np.zeros(0, np.int64)
    col0 = np.concatenate(cc).astype(np.int64) if cc else np.zeros(0, np.int64)
    val0 = np.concatenate(vv).astype(np.float64) if vv else np.zeros(0)
    return row0, col0, val0, n0


def counts_feasible(sides, matrices: Sequence[np.ndarray], *, counts: Mapping[int, int] | None = None,
                    equal: Sequence = (), floors: np.ndarray | None = None) -> bool:
    """Whether :func:`solve_counts` of these ``sides``, side ``matrices``, requested ``counts``,
    ``equal`` pairs and ``floors`` has an answer (else it raises :class:`LayoutInfeasible`): its
    constraints alone, one HiGHS run without an objective (the targets only price a solution)."""
    S = len(sides.chains)
    M = int(_chord_offsets(matrices)[-1])
    row, col, val, n0 = _side_rows(sides, matrices, equal)
    lb = np.concatenate([np.ones(M), np.ones(S) if floors is None else np.maximum(floors, 1)])
    ub = np.full(M + S, np.inf)
    for s, v in dict(counts or {}).items():
        lb[M + s] = ub[M + s] = float(v)
    return run_milp(np.zeros(M + S), SparseRows((n0, M + S), row, col, val), np.zeros(n0), np.zeros(n0),
                    np.ones(M + S), lb, ub) is not None


def count_cost(sides, mults: Sequence[np.ndarray], n: np.ndarray, *, size: float, widths=None, counts=None,
               side_targets=None, chord_targets=None, chord_weight: float = CHORD_WEIGHT) -> float:
    """The size objective of :func:`solve_counts` at its answer ``(mults, n)``: ``sum_s |n_s -
    target_s|`` over the sides not in ``counts`` plus ``chord_weight * sum_c |m_c - tau_c|``
    (targets and ``tau`` as :func:`solve_counts` makes them; widths, chord_targets per patch)."""
    counts = dict(counts or {})
    h = float(size)
    S = len(sides.chains)
    free = np.array([s for s in range(S) if s not in counts], np.int64)
    tgt = (np.asarray(side_targets, np.float64) if side_targets is not None else np.asarray(sides.lengths) / h)
    cost = float(np.sum(np.abs(np.asarray(n)[free] - tgt[free]))) if free.size else 0.0
    for p, m in enumerate(mults):
        if chord_targets is not None:
            tau = np.maximum(np.asarray(chord_targets[p], np.float64), 1.0)
        elif widths is not None:
            tau = np.maximum(np.asarray(widths[p], np.float64) / h, 1.0)
        else:
            tau = np.ones(len(m))
        cost += chord_weight * float(np.sum(np.abs(np.asarray(m) - tau)))
    return cost


def _merged_entries(row: np.ndarray, col: np.ndarray, val: np.ndarray):
    """The entries ``(row, col, val)`` with repeated ``(row, col)`` pairs summed and zeros
    dropped (what :class:`SparseRows` requires)."""
    key = row * (int(col.max(initial=0)) + 1) + col
    uk, inv = np.unique(key, return_inverse=True)
    v = np.bincount(inv, weights=val, minlength=uk.size)
    width = int(col.max(initial=0)) + 1
    r, c = uk // width, uk % width
    keep = v != 0
    return r[keep].astype(np.int64), c[keep].astype(np.int64), v[keep]


class SparseRows(NamedTuple):
    """A constraint matrix by its nonzero entries (what :func:`run_milp` takes instead of a dense
    ``(m, n)`` array): entry ``k`` is ``val[k]`` at row ``row[k]``, column ``col[k]``, each
    ``(row, col)`` at most once, no zero values. ``np.asarray`` of it is the dense matrix."""

    shape: tuple
    row: np.ndarray
    col: np.ndarray
    val: np.ndarray

    def __array__(self, dtype=None, copy=None):
        a = np.zeros(self.shape, np.float64)
        a[self.row, self.col] = self.val
        return a if dtype is None else a.astype(dtype)


def _deviation_rows(x: np.ndarray, d: np.ndarray, tau: np.ndarray, first: int):
    """The rows making each variable ``d[i]`` at least ``|x_i - tau[i]|`` for the integer
    variable ``x[i]``, item after item from row ``first``: ``d - x >= -tau`` and ``d + x >= tau``
    (the two lines of the absolute value), then, unless ``tau[i]`` is whole, the chord through
    its values at the integers on either side of ``tau`` (:func:`_chord_row`: ``d - slope * x >=
    bound``, its ``x`` entry left out where the slope is 0).

    x, d: ``(K,) int64`` columns; tau: ``(K,) float64``. Returns ``(row, col, val, lower)``: the
    entries (``row``, ``col``, ``val``, as :class:`SparseRows`) and each row's lower bound (its
    upper one is infinite)."""
    K = tau.size
    fl = np.floor(tau)
    f = tau - fl
    slope = 1.0 - 2.0 * f
    bound = f - slope * fl
    chord = f > 1e-12
    n_rows = 2 + chord.astype(np.int64)
    start = first + np.concatenate([[0], np.cumsum(n_rows)[:-1]]).astype(np.int64)
    ci = np.flatnonzero(chord)
    lower = np.empty(int(n_rows.sum()))
    lower[start - first] = -tau
    lower[start - first + 1] = tau
    lower[start[ci] - first + 2] = bound[ci]
    cx = ci[slope[ci] != 0]  # -0.0 is no entry
    row = np.concatenate([start, start, start + 1, start + 1, start[ci] + 2, start[cx] + 2])
    col = np.concatenate([x, d, x, d, d[ci], x[cx]])
    val = np.concatenate([np.full(K, -1.0), np.ones(K), np.ones(K), np.ones(K), np.ones(ci.size), -slope[cx]])
    return row, col, val, lower


def _chord_row(tau: float) -> tuple[float, float] | None:
    """The chord of ``|x - tau|`` between the integers ``floor(tau)`` and ``floor(tau) + 1``,
    as ``(slope, bound)`` of the row ``d - slope * x >= bound``; None for a whole ``tau``.

    At every integer ``x`` the chord lies on or below ``|x - tau|`` (the function is convex and
    the chord joins two of its integer points), so adding the row changes no integer solution's
    cost. Without it the relaxation sets ``x = tau`` at no cost, and HiGHS branched on every
    side: on the letter A's largest program, 190 ms against 6 ms with the chords (docs/perf.md,
    "Integer programs"). With it the relaxation's cost of ``x`` is that of the nearest integers."""
    lo = math.floor(tau)
    f = tau - lo
    if f <= 1e-12:
        return None
    slope = 1.0 - 2.0 * f
    return slope, f - slope * lo


MILP_TIME_LIMIT = 30.0
"""Seconds HiGHS may spend on one integer program; past it the best solution found is used."""

FEASIBILITY_JUMP = False
"""Whether HiGHS runs its feasibility-jump heuristic. With the chord rows (:func:`_chord_row`)
the relaxation is tight and the heuristic only costs time: the 386 programs of the meshing,
holes and dense tables took 3.18 s with it and 2.23 s without, faster without in every size
band (``scripts/milp_options.py``; docs/perf.md, "Integer programs")."""


def run_milp(cost, A, lo, hi, integrality, lb, ub, *, time_limit: float = MILP_TIME_LIMIT, start=None,
             max_nodes: int | None = None, options: Mapping | None = None):
    """Solve one integer program with HiGHS: minimise ``cost @ x`` subject to ``lo <= A @ x <= hi``,
    ``lb <= x <= ub``, ``x[j]`` integer where ``integrality[j]`` is 1.

    cost, integrality, lb, ub: ``(n,)``; A: ``(m, n)`` dense or a :class:`SparseRows`; lo, hi: ``(m,)`` (``+-inf`` allowed).
    Returns ``x (n,) float64`` (the best solution found: optimal, or the incumbent at the time
    limit), or None when the program is infeasible. start: ``(n,)`` a feasible solution HiGHS
    starts from (through ``highspy`` only), so that a time limit returns one at least as good;
    max_nodes: the most branch-and-bound nodes (a limit of work, not of time: the same answer on
    a loaded machine), past which the best solution found is used; options: further HiGHS
    options for this program (``highspy`` only; each program starts from the defaults). A solver failure (status 3 or 4, or a time
    limit without a solution) is retried once without presolve, then raised as
    :class:`jaxmatch.errors.SolverError`, never reported as infeasible. The solver:
    :func:`_highs` (status numbers as :func:`scipy.optimize.milp`'s)."""

    args = [a if isinstance(a, SparseRows) else np.asarray(a, np.float64) for a in (cost, A, lo, hi, integrality, lb, ub)]
    status, x, message = 4, None, ""
    for presolve in (True, False):
        more = {k: v for k, v in (("x0", start), ("max_nodes", max_nodes), ("options", options)) if v is not None}
        status, x, message = _highs(*args, presolve=presolve, time_limit=float(time_limit), **more)
        if status in (0, 1) and x is not None:
            return x
        if status == 2:
            return None
    raise SolverError(f"the integer program failed (HiGHS status {status}: {message})", status)


_SOLVER = threading.local()
"""Each thread's HiGHS solver object (:func:`_highs`): made once, its model cleared before the
next program, which HiGHS then solves as a new object would (the same solutions: every program
of the example regions at P/16 and P/32, tests/test_speed.py); making one cost ~0.08 ms of a
small program's ~0.9 ms."""


def _highs(cost, A, lo, hi, integrality, lb, ub, *, presolve: bool, time_limit: float, x0=None,
           max_nodes: int | None = None, options: Mapping | None = None):
    """``(status, x or None, message)`` of one HiGHS run, status as :func:`scipy.optimize.milp`'s (0
    optimal, 1 time or iteration limit, 2 infeasible, 3 unbounded, 4 other).

    Through the ``highspy`` package when it is installed (the model passed as
    :func:`scipy.optimize.milp` passes it; ``pyproject.toml`` pins the release of the HiGHS that
    scipy bundles, so both give the same solutions bit for bit with the feasibility jump on,
    tested; without it (:data:`FEASIBILITY_JUMP`, which scipy cannot ask for) the same optimum,
    a tie possibly broken otherwise), which spares the command the import of ``scipy.optimize``
    (~0.3 s with the ``scipy.spatial`` and ``scipy.special`` it loads; docs/perf.md,
    "Start-up"); else :func:`scipy.optimize.milp`."""
    try:
        import highspy
    except ImportError:
        from scipy.optimize import Bounds, LinearConstraint, milp

        opts = {"time_limit": time_limit, "presolve": presolve}
        if max_nodes is not None:
            opts["node_limit"] = int(max_nodes)
        res = milp(cost, constraints=LinearConstraint(np.asarray(A, np.float64), lo, hi), integrality=integrality, bounds=Bounds(lb, ub),
                   options=opts)
        return res.status, res.x, res.message
    m, n = A.shape
    start, index, value = _columns(A)
    h = getattr(_SOLVER, "highs", None)
    if h is None:  # one solver object per thread, its model cleared for each program
        h = _SOLVER.highs = highspy.Highs()
    else:
        h.clearModel()
        h.resetOptions()  # (a program's own options go with it)
    h.setOptionValue("log_to_console", False)  # as scipy sets it
    for name, setting in (options or {}).items():
        h.setOptionValue(name, setting)
    h.setOptionValue("time_limit", float(time_limit))
    h.setOptionValue("presolve", "on" if presolve else "off")
    h.setOptionValue("mip_heuristic_run_feasibility_jump", bool(FEASIBILITY_JUMP))
    h.setOptionValue("mip_max_nodes", int(max_nodes) if max_nodes is not None else highspy.kHighsIInf)
    S = highspy.HighsModelStatus
    if _pass_model(h, highspy, n, m, start, index, value, cost, lb, ub, lo, hi, integrality) == highspy.HighsStatus.kError:
        return 2, None, "the model could not be loaded"  # as scipy: kModelError
    if x0 is not None:  # a feasible start: the answer past the time limit is no worse
        sol = highspy.HighsSolution()
        sol.col_value = np.asarray(x0, np.float64).tolist()
        sol.value_valid = True
        h.setSolution(sol)
    h.run()
    st = h.getModelStatus()
    status = {S.kOptimal: 0, S.kTimeLimit: 1, S.kIterationLimit: 1, S.kSolutionLimit: 1, S.kInfeasible: 2,
              S.kModelError: 2, S.kUnbounded: 3}.get(st, 4)
    limit = st in (S.kTimeLimit, S.kIterationLimit, S.kSolutionLimit)
    if st != S.kOptimal and not (limit and h.getInfo().objective_function_value != highspy.kHighsInf):
        return status, None, h.modelStatusToString(st)
    return status, np.array(h.getSolution().col_value), h.modelStatusToString(st)



PASS_ARRAYS = True
"""Whether :func:`_highs` passes the model to HiGHS as numpy arrays in one call (``Highs.passModel``
of the sizes and arrays, :func:`_pass_model`) rather than through a ``HighsLp`` object filled field
by field (its integrality a Python list of ``HighsVarType``): the same model, so the same solutions
bit for bit (tests/test_milp.py), about half of the Python time of passing it."""


def _pass_model(h, highspy, n: int, m: int, start, index, value, cost, lb, ub, lo, hi, integrality):
    """Load one program into the HiGHS object ``h`` (``n`` columns, ``m`` rows; ``start``, ``index``,
    ``value`` its compressed columns, :func:`_columns`; the rest as :func:`run_milp` takes them) and
    return ``h.passModel``'s status: minimise, no offset, column-wise."""
    if PASS_ARRAYS:
        return h.passModel(n, m, int(index.size), int(highspy.MatrixFormat.kColwise), int(highspy.ObjSense.kMinimize),
                           0.0, np.asarray(cost, np.float64), np.asarray(lb, np.float64), np.asarray(ub, np.float64),
                           np.asarray(lo, np.float64), np.asarray(hi, np.float64), start, index, value,
                           np.asarray(integrality).astype(np.int32))
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = n, m
    lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = n, m
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_, lp.a_matrix_.index_, lp.a_matrix_.value_ = start, index, value
    lp.col_cost_, lp.col_lower_, lp.col_upper_ = cost, lb, ub
    lp.row_lower_, lp.row_upper_ = lo, hi
    ints = np.asarray(integrality).astype(int).tolist()
    kinds = {i: highspy.HighsVarType(i) for i in set(ints)}
    lp.integrality_ = [kinds[i] for i in ints]
    return h.passModel(lp)


def _columns(A) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(start (n + 1,) int32, index (nnz,) int32, value (nnz,) float64)``: the nonzero entries of
    ``A`` (dense ``(m, n)`` or :class:`SparseRows`) column by column, rows ascending in each
    column (compressed sparse columns, as HiGHS reads them); the same arrays for a
    :class:`SparseRows` as for its dense matrix."""
    if isinstance(A, SparseRows):
        keep = A.val != 0
        row, col, val = A.row[keep], A.col[keep], A.val[keep]
        order = np.lexsort((row, col))
        counts = np.bincount(col, minlength=A.shape[1])
        return (np.concatenate([[0], np.cumsum(counts)]).astype(np.int32), row[order].astype(np.int32),
                val[order].astype(np.float64))
    nz = A.T != 0  # column-wise (CSC), rows ascending in each column
    return (np.concatenate([[0], np.cumsum(nz.sum(axis=1))]).astype(np.int32), np.nonzero(nz)[1].astype(np.int32),
            A.T[nz])
