"""The candidates of the pipeline (step 2), each kind of candidate one strategy object, run once
per request by :func:`run` in the order of one plan (:func:`jaxmatch.meshing.pipeline.mesh` makes
it), and chosen once (:func:`jaxmatch.meshing.choose.choose`):

======================= ================================================================= ===========================
strategy                candidates                                                        when
======================= ================================================================= ===========================
:class:`Layouts`        the layout strategies together (:class:`Single`: the region as    always
                        one template; :class:`Split`: each decomposition), meshed by the
                        one solve most promising first, a layout that cannot win skipped
:class:`Larger`         the single patch with each larger template size group            below the quality floor;
                                                                                         graded: the single is the
                                                                                         best, off the field
:class:`Conforming`     single templates whose side counts follow the size                no candidate follows it
                                                                                         (no size field)
:class:`RingPartition`  a layer of patches along every loop and an O-grid core, or a box  an edge of every candidate
                        around every hole and a grid through the rest                     is longer than 2 h, none
                        (:class:`Rings`, ``"rings"``)                                     reaches the quality band,
                                                                                         or the best nearly meets the
                                                                                         size band
:class:`LeanCurves`     the best mesh's layout again, the curves' area budget shared by   the best nearly meets the
                        the curved sides alone (``" +lean curves"``), kept at the band    size band (curved sides)
:class:`Transitions`    the best mesh's layout again, templates chosen for size in the    the best misses the field,
                        one integer program (``" +transitions"``), kept nearer the band   or the size band (near
                                                                                         miss; one size only with
                                                                                         uniform_transitions)
:class:`Bends`          the layouts again with a curved outline's bends as corners        every candidate folds
:class:`Enough`         not a candidate: ends the plan (the fast search,                  the best is valid, conforms
                        :attr:`~jaxmatch.defaults.Search.enough`)                         and reaches the band
:class:`Smooth`         a region with fewer than two corners: a refined template and the  (its own plan)
                        central block (``"disk"``)
======================= ================================================================= ===========================

With a size field the plan is the layouts, the ring partition, the larger templates (so tried
only when the single candidate is still the best mesh and misses the field), the transitions,
the bends (``Conforming`` never applies).

Every strategy has ``wanted(best, tried, request)`` (its condition on the best mesh so far) and
``candidates(request, tried)``.
"""

from __future__ import annotations

import time
from typing import NamedTuple, Sequence

import numpy as np

from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.errors import InputError, SolverError, UnmatchableError
from jaxmatch.field import line_integral
from jaxmatch.meshing.build import from_layout, from_refined
from jaxmatch.meshing.choose import best_possible_key, cannot_win, mesh_key
from jaxmatch.meshing.region import corner_points
from jaxmatch.meshing.result import Candidate, QuadMesh
from jaxmatch.placement.bounds import node_sj_bound, single_sj_bound, template_sj_bound
from jaxmatch.placement.decompose import _same, decompose, disk_layout, same_cuts, single_patch
from jaxmatch.placement.layout import check_layout
from jaxmatch.placement.rings import ring_layout
from jaxmatch.placement.refine import DEFAULT_LIMIT, InfeasibleRequest, refine_mesh, side_lengths, side_polylines
from jaxmatch.placement.solve import ALL_SIZES, TEMPLATE_SIZES, lean_floors_help, mesh_layout
from jaxmatch.placement.templates import walk
from jaxmatch.shape import Shape
from jaxmatch.sides import periodic_lines

__all__ = ["CONFORMING_TRIES", "DISK", "Enough", "FINER", "LEAN", "RINGS", "SINGLE", "Bends", "Conforming", "Larger", "LayoutStrategy",
           "Layouts", "LeanCurves", "TRANSITIONS", "Transitions", "has_curves",
           "Request", "RingPartition", "Rings", "Single", "Smooth", "Split", "conforming_templates", "larger_templates", "layout_strategies", "run",
           "smooth_candidates", "try_layouts"]

SINGLE = "single"
"""Name of the one-template candidate."""

RINGS = "rings"
"""Name of the ring partition's candidate (:class:`Rings`)."""


FINER = " +bends"
"""Suffix of the candidates meshed with the bends of a curved outline as corners too (when every
other candidate folds; :data:`jaxmatch.shape.HELD_ANGLE`)."""


FAILED = (InputError, SolverError, ValueError, ArithmeticError, IndexError)
"""What skips one strategy, the others going on: a request its cuts or patches cannot meet, a
solver failure (not a verdict on the request), degenerate cuts or patches (near-duplicate
points, slivers)."""


def _why_not(e: Exception) -> str:
    """The note of a strategy skipped for ``e`` (one of :data:`FAILED`)."""
    if isinstance(e, InputError):
        return e.problem
    if isinstance(e, SolverError):
        return f"solver error: {e}"
    return f"skipped: {type(e).__name__}: {e}"


def try_layouts(shape: Shape, strategies: Sequence["LayoutStrategy"], cat, lat, h: float, corners: np.ndarray, budget_s,
                t0: float, progress, suffix: str = "", quality: Quality = QUALITY, lean_curves: bool = False,
                best: tuple | None = None, transitions: bool = False) -> list[Candidate]:
    """Each layout strategy of ``strategies`` (one :class:`Candidate` each, in their order, with its
    mesh or the reason it has none): every strategy's layout is cut first, then meshed by the same
    solve (:func:`~jaxmatch.placement.solve.mesh_layout`), the most promising first: by the best
    key its mesh could have (:func:`~jaxmatch.meshing.choose.best_possible_key`: the quality its
    bound allows, then fewest patches; the single patch of a region with a concave corner last).
    A layout that cannot beat the best mesh so far whatever its mesh
    (:func:`~jaxmatch.meshing.choose.cannot_win`: by its patch count and an upper bound on its min
    scaled Jacobian: :func:`~jaxmatch.placement.bounds.node_sj_bound` from the angles its nodes
    split, and for the single patch :func:`~jaxmatch.placement.bounds.single_sj_bound` from its
    template sizes and, with a size field, :func:`~jaxmatch.placement.bounds.template_sj_bound`
    from its candidate templates' corners and internal vertices) is not meshed, so the choice is
    the one meshing all of them would give. With a search that caps them (``quality.search.layouts``,
    :class:`~jaxmatch.defaults.Search`), no further layout is meshed once that many are and one
    is valid and reaches ``quality.good_sj`` (with a size field: and follows it). A strategy whose cuts or solve fail for any reason is
    skipped with that reason. ``lean_curves``:
    the solve's curve floors from the curved sides' share alone
    (:func:`~jaxmatch.placement.solve.mesh_layout`); ``transitions``: templates chosen for size
    in the solve (the same); ``best``: ``(key, name, valid)`` of the best
    mesh already made elsewhere (what a layout must beat to be meshed)."""
    names = [st.name for st in strategies]
    tried: list[Candidate | None] = [None] * len(names)
    layouts: list[tuple[int, object]] = []
    made: dict = {}  # layouts by the strategy that gives them (same_cuts): each cut once
    for i, (name, st) in enumerate(zip(names, strategies)):
        try:
            how = st.kind(shape)
            if how not in made:  # the first strategy of its kind names the layout (its messages' source)
                made[how] = st.layout(shape, h)
            lay = made[how]
        except FAILED as e:
            tried[i] = Candidate(name + suffix, None, _why_not(e))
            continue
        if any(_same(lay, other) for _, other in layouts):
            tried[i] = Candidate(name + suffix, None, "same patches as an earlier candidate")
            continue
        if lean_curves:
            try:
                helps = lean_floors_help(lay, cat, h, quality)
            except FAILED as e:
                tried[i] = Candidate(name + suffix, None, _why_not(e))
                continue
            if not helps:
                tried[i] = Candidate(name + suffix, None, "no side's curve floor below the size band to make coarser")
                continue
        layouts.append((i, lay))
    concave = bool(np.any(~np.asarray(shape.convex, bool)))
    late = {i for i, _ in layouts if strategies[i].single and concave}  # after the cuts: a grid they make may rule it out
    caps = {}
    for i, lay in layouts:
        try:
            caps[i] = node_sj_bound(lay)
        except FAILED:  # (a layout its checks refuse: the solve below says why)
            caps[i] = 1.0
    order = sorted(layouts, key=lambda il: (il[0] in late, best_possible_key(il[1].n_patches, il[0], caps[il[0]], quality)))
    most, meshed, floor_met = quality.search.layouts, 0, False  # (the fast search: Search.layouts)
    for done, (i, lay) in enumerate(order, start=1):
        label = names[i] + suffix
        sizes = strategies[i].sizes
        bound, why = caps[i], "a node splits its angle"
        if best is not None and strategies[i].single and not cannot_win(best[0], 1, i, bound, quality):
            try:  # (one patch: only a cap on its quality can rule it out)
                grid = single_sj_bound(lay, cat, lat, sizes=sizes)
            except FAILED:  # no templates: the solve below says why
                grid = 1.0
            if grid < bound:
                bound, why = grid, "no template of its sizes refines into a grid"
            if quality.field is not None and not transitions and not cannot_win(best[0], 1, i, bound, quality):
                try:  # (graded: its candidate templates' corners and internal vertices; transitions offer others)
                    tmpl = template_sj_bound(lay, cat, lat, sizes=sizes)
                except FAILED:
                    tmpl = 1.0
                if tmpl < bound:
                    bound, why = tmpl, "every template of its sizes splits a corner's angle or has an irregular vertex"
        if best is not None and cannot_win(best[0], lay.n_patches, i, bound, quality):
            tried[i] = Candidate(label, None, f"min scaled Jacobian at most {bound:.2f} cannot beat {best[1]}; {why}"
                                 if not cannot_win(best[0], lay.n_patches, i, 1.0, quality) else
                                 f"{lay.n_patches} patches cannot beat {best[1]}",
                                 best_possible_key(lay.n_patches, i, bound, quality))
        elif most is not None and meshed >= most and floor_met:
            tried[i] = Candidate(label, None, f"not tried: the {quality.search.name} search meshes at most {most} "
                                 f"layout{'s' if most > 1 else ''} once one reaches min scaled Jacobian {quality.good_sj:g}")
        elif budget_s is not None and time.perf_counter() - t0 > budget_s and best is not None and best[2]:
            tried[i] = Candidate(label, None, f"not tried: time budget of {budget_s:g} s spent")
        else:
            try:
                check_layout(lay)  # (the cuts' layouts are checked only when meshed)
                lm = mesh_layout(lay, cat, lat, size=h, smooth_cuts=lay.n_patches > 1, sizes=sizes, quality=quality,
                                 periodic=periodic_lines(shape), lean_curves=lean_curves, transitions=transitions)
            except FAILED as e:
                tried[i] = Candidate(label, None, _why_not(e))
            else:
                m = from_layout(lm, size=h, corners=corners, field=quality.field)
                tried[i] = Candidate(label, m)
                meshed += 1
                floor_met = floor_met or (m.valid and m.min_scaled_jacobian >= quality.good_sj and  # (graded: and follows
                                          (quality.field is None or m.size_conformity(quality) == 0))  # the field)
                key = mesh_key(m, i, quality)
                if best is None or key < best[0]:
                    best = (key, label, m.valid)
        if progress is not None:
            progress(done, len(layouts), label)
    return list(tried)


# ---------------------------------------------------------------------------------------------
# the strategies: each candidate kind one object, chosen once per request (:func:`plan`)


class LayoutStrategy:
    """A strategy that cuts the region into a layout (meshed by the one solve,
    :func:`~jaxmatch.placement.solve.mesh_layout`, in :func:`try_layouts`)."""

    name: str = ""
    single: bool = False  # the region as one patch (only a cap on its quality can rule it out)
    sizes: tuple = TEMPLATE_SIZES  # the template size groups its patches take

    def kind(self, shape: Shape):
        """What makes two strategies give the same layout (the layout is cut once)."""
        return self.name

    def layout(self, shape: Shape, h: float):
        """The layout of ``shape`` at element size ``h`` (user units)."""
        raise NotImplementedError


class Single(LayoutStrategy):
    """The region as one template (``"single"``; every template size group)."""

    name, single, sizes = SINGLE, True, ALL_SIZES

    def kind(self, shape: Shape):
        return None

    def layout(self, shape: Shape, h: float):
        return single_patch(shape)


class Split(LayoutStrategy):
    """A decomposition at the concave corners or around the holes
    (:func:`jaxmatch.placement.decompose.decompose`: ``"continuations"``, ``"bisectors"``,
    ``"recursive"``, ``"radial"``)."""

    def __init__(self, name: str):
        self.name = name

    def kind(self, shape: Shape):
        return same_cuts(shape, self.name)

    def layout(self, shape: Shape, h: float):
        return decompose(shape, self.name, check=False)


class Rings(LayoutStrategy):
    """A layer of patches one ring depth wide along every loop and an O-grid core
    (``"rings"``, :func:`jaxmatch.placement.rings.ring_layout`): the interior at the size
    whatever the region's corners."""

    name = RINGS

    def layout(self, shape: Shape, h: float):
        return ring_layout(shape, h)


class Request(NamedTuple):
    """What every strategy of one request sees: the region (corners judged at the size), the
    catalogue, lattice, size ``h``, the region's corners ``(C, 2)``, the policy, the time budget
    (seconds, from ``t0``) and the progress callback."""

    region: Shape
    cat: object
    lat: object
    h: float
    corners: np.ndarray
    quality: Quality
    budget_s: float | None
    t0: float
    progress: object


class Layouts:
    """The layout strategies tried together, most promising first, a layout that cannot beat the
    best mesh so far skipped (:func:`try_layouts`). Candidates go at the start."""

    def __init__(self, strategies: Sequence[LayoutStrategy]):
        self.strategies = tuple(strategies)

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        return True

    def candidates(self, req: Request, tried) -> list[Candidate]:
        return try_layouts(req.region, self.strategies, req.cat, req.lat, req.h, req.corners, req.budget_s, req.t0,
                           req.progress, quality=req.quality)


def _single(tried) -> QuadMesh | None:
    return next((c.mesh for c in tried if c.name == SINGLE and c.mesh is not None), None)


class Larger:
    """Below the quality floor, or, with a size field, the single candidate is the best mesh so
    far and its edges do not all conform to the field: the single patch with each larger
    template size group (:func:`larger_templates`), after the single candidate. (Graded, a
    larger template's irregular vertices are the single patch's transitions of size; where a
    partition already follows the field better than the single patch, they are not tried.)"""

    after_single = True

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        single = _single(tried)
        if single is None:
            return False
        if not best.min_scaled_jacobian >= req.quality.good_sj:
            return True
        return req.quality.field is not None and best is single and best.size_conformity(req.quality) > 0

    def candidates(self, req: Request, tried) -> list[Candidate]:
        return larger_templates(single_patch(req.region), req.cat, req.lat, req.h, req.corners, _single(tried),
                                req.quality, periodic_lines(req.region))


class Conforming:
    """No candidate follows the size yet: single templates whose side counts do
    (:func:`conforming_templates`), after the single candidate. Not with a size field: the
    integer program already takes the field's integrals as the side targets these templates are
    asked to meet exactly, and where one template cannot follow them (a side finer than the one
    facing it) the larger templates (:class:`Larger`) are its transitions; meeting such counts
    exactly takes a fan of irregular vertices (docs/graded.md: what it cost and never won)."""

    after_single = True

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        if req.quality.field is not None:
            return False
        return _single(tried) is not None and bool(best.sides_off_size(req.quality.size_tol))

    def candidates(self, req: Request, tried) -> list[Candidate]:
        return conforming_templates(req.region, req.cat, req.lat, req.h, _single(tried), req.quality)


class Bends:
    """Every candidate folds: the layout strategies again with the bends of a curved outline as
    corners too (``" +bends"``; the region re-judged with ``held_angle``), kept when one meshes.
    ``rejudge(held_angle)``: the region's corners re-judged (None when they are the same)."""

    def __init__(self, layouts: Layouts, rejudge):
        self.layouts, self.rejudge = layouts, rejudge

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        return not best.valid

    def candidates(self, req: Request, tried) -> list[Candidate]:
        finer = self.rejudge()
        if finer is None:
            return []
        more = try_layouts(finer, self.layouts.strategies, req.cat, req.lat, req.h, corner_points(finer), req.budget_s,
                           req.t0, req.progress, suffix=FINER, quality=req.quality)
        return more if any(c.mesh is not None for c in more) else []


class Smooth:
    """A region with fewer than two corners: one refined template and the central block
    (:func:`smooth_candidates`)."""

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        return True

    def candidates(self, req: Request, tried) -> list[Candidate]:
        return smooth_candidates(req.region, req.cat, req.lat, req.h, req.quality)


def layout_strategies(names: Sequence[str]) -> tuple[LayoutStrategy, ...]:
    """The layout strategy objects of ``names`` (``"single"`` and the decompositions)."""
    return tuple(Single() if n == SINGLE else Rings() if n == RINGS else Split(n) for n in names)


class RingPartition:
    """Every candidate has an edge longer than ``Quality.long_edge`` sizes, or none reaches the
    quality band (``Quality.high_sj``), or the best nearly meets the size band
    (:meth:`QuadMesh.near_size_band`): the ring partition (:class:`Rings`), meshed by the same solve, at the end; also
    when nothing else meshed (``when_none_meshed``). Sides off the size alone are
    :class:`Conforming`'s (docs/meshing.md, "The ring partition": what trying the rings for them
    too cost)."""

    when_none_meshed = True

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        q = req.quality
        return best is None or best.long_edges(q.long_edge) > 0 or not best.min_scaled_jacobian >= q.high_sj or \
            best.near_size_band(q)

    def candidates(self, req: Request, tried) -> list[Candidate]:
        return try_layouts(req.region, (Rings(),), req.cat, req.lat, req.h, req.corners, req.budget_s, req.t0,
                           req.progress, quality=req.quality)


LEAN = " +lean curves"
"""Suffix of the candidates meshed again with the curves' floors from the curved sides' share of
the area budget alone (:class:`LeanCurves`)."""


def has_curves(shape: Shape) -> bool:
    """Whether a loop of ``shape`` has a point that is not a corner (a curved or subdivided
    side: the only sides whose floors :class:`LeanCurves` changes)."""
    return shape.points.shape[0] > len(shape.corners) or \
        any(len(hole) > len(c) for hole, c in zip(shape.holes, shape.hole_corners))


class LeanCurves:
    """The best mesh so far nearly meets the size band (:meth:`QuadMesh.near_size_band`; one
    size, no field) and the region has curved sides: the best mesh's layout meshed again (``" +lean
    curves"``; one solve, none when the best mesh is not one of ``strategies``') with the area
    budget of the curves' chords shared by the curved sides alone (``lean_curves`` of
    :func:`~jaxmatch.placement.solve.mesh_layout`: where the whole boundary shares it, round
    holes among long straight sides are meshed finer than the size and their rings carry those
    short edges inside), only where that makes a side coarser that the whole boundary's share put below
    the size band (:func:`~jaxmatch.placement.solve.lean_floors_help`). The mesh is kept when it
    meets the size band and its min scaled Jacobian is at most ``Quality.lean_cost`` below the
    best's: coarser curves to reach the band, not for a worse mesh."""

    def __init__(self, strategies: Sequence[LayoutStrategy]):
        self.strategies = tuple(strategies)

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        return req.quality.field is None and best.near_size_band(req.quality) and has_curves(req.region)

    def candidates(self, req: Request, tried) -> list[Candidate]:
        q = req.quality
        key, i = _best_keyed(tried, q)
        best = tried[i].mesh
        own = [st for st in self.strategies if st.name == tried[i].name]  # the best mesh's own layout
        if not own:
            return []
        more = try_layouts(req.region, own, req.cat, req.lat, req.h, req.corners, req.budget_s, req.t0,
                           req.progress, suffix=LEAN, quality=q, lean_curves=True, best=(key, tried[i].name, best.valid))
        floor = best.min_scaled_jacobian - q.lean_cost
        return [c for c in more if c.mesh is not None and not c.mesh.misses_size_band(q)
                and c.mesh.min_scaled_jacobian >= floor]


TRANSITIONS = " +transitions"
"""Suffix of the candidates whose patches' templates were chosen for size (:class:`Transitions`)."""


class Transitions:
    """The best mesh so far misses the size band by a near miss (:meth:`QuadMesh.near_size_band`;
    one size, in the plan only with ``Quality.uniform_transitions``), or misses the size field (its size conformity or its size band): the best mesh's
    layout meshed again (``" +transitions"``; one solve, none when the best mesh is not one of
    ``strategies``', with lean curves when it had them) with templates chosen for size
    (``transitions`` of :func:`~jaxmatch.placement.solve.mesh_layout`: a patch whose sides or
    chords are off the size band may take a larger template, a transition pattern whose opposite
    sides get different counts, where the one integer program's size objective drops). The mesh
    is kept when its templates changed, more of its edges are within ``Quality.size_band`` than
    the best's and its min scaled Jacobian is at most ``Quality.transition_cost`` below the best's;
    then the one choice rule decides."""

    def __init__(self, strategies: Sequence[LayoutStrategy]):
        self.strategies = tuple(strategies)

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        q = req.quality
        if q.field is not None:
            return best.size_conformity(q) > 0 or best.misses_size_band(q)
        return best.near_size_band(q)

    def candidates(self, req: Request, tried) -> list[Candidate]:
        q = req.quality
        key, i = _best_keyed(tried, q)
        best = tried[i].mesh
        name = tried[i].name
        lean = name.endswith(LEAN)
        base = name[:-len(LEAN)] if lean else name
        own = [st for st in self.strategies if st.name == base]  # the best mesh's own layout
        if not own:
            return []
        more = try_layouts(req.region, own, req.cat, req.lat, req.h, req.corners, req.budget_s, req.t0, req.progress,
                           suffix=(LEAN if lean else "") + TRANSITIONS, quality=q, lean_curves=lean,
                           best=(key, name, best.valid), transitions=True)
        floor = best.min_scaled_jacobian - q.transition_cost
        share = best.band_share(q.size_band)
        return [c for c in more if c.mesh is not None and c.mesh.templates != best.templates
                and c.mesh.band_share(q.size_band) > share and c.mesh.min_scaled_jacobian >= floor]


def _best_keyed(tried, quality: Quality) -> tuple[tuple, int] | None:
    """``(key, index)`` of the candidate of ``tried`` with the smallest
    :func:`~jaxmatch.meshing.choose.mesh_key` (None when none has a mesh)."""
    keyed = [(mesh_key(c.mesh, i, quality), i) for i, c in enumerate(tried) if c.mesh is not None]
    return min(keyed) if keyed else None


def _best(tried, quality: Quality) -> QuadMesh | None:
    """The mesh of ``tried`` with the smallest :func:`~jaxmatch.meshing.choose.mesh_key`."""
    kept = _best_keyed(tried, quality)
    return tried[kept[1]].mesh if kept else None


class Enough:
    """Not a candidate: the end of the plan (:func:`run` stops here) when the search stops at a
    good enough mesh (:attr:`jaxmatch.defaults.Search.enough`) and the best mesh so far is valid,
    conforms to the size and reaches the quality band (``Quality.high_sj``)."""

    ends = True

    def wanted(self, best: QuadMesh | None, tried, req: Request) -> bool:
        q = req.quality
        return best is not None and best.valid and best.size_conformity(q) == 0 and best.min_scaled_jacobian >= q.high_sj

    def candidates(self, req: Request, tried) -> list[Candidate]:
        return []


def run(plan: Sequence, req: Request) -> list[Candidate]:
    """Every strategy of ``plan`` whose condition on the best mesh so far holds
    (``wanted(best, tried, req)``), in order; the candidates of a strategy marked
    ``after_single`` (:class:`Larger`, :class:`Conforming`) go right after the single candidate (single, conforming, larger, the
    decompositions, the bends), the others at the end; a strategy marked ``ends``
    (:class:`Enough`) whose condition holds ends the plan. Returns every candidate, for the one
    choice (:func:`~jaxmatch.meshing.choose.choose`)."""
    tried: list[Candidate] = []
    for st in plan:
        best = _best(tried, req.quality)
        if tried and best is None and not getattr(st, "when_none_meshed", False):
            continue  # nothing meshed: no condition on a best mesh can be judged
        if not st.wanted(best, tried, req):
            continue
        if getattr(st, "ends", False):
            break
        more = st.candidates(req, tried)
        if getattr(st, "after_single", False):
            at = next((i + 1 for i, c in enumerate(tried) if c.name == SINGLE), 1)
            tried = tried[:at] + list(more) + tried[at:]
        else:
            tried = tried + list(more)
    return tried


def larger_templates(lay, cat, lat, h, corners, first: QuadMesh, quality: Quality = QUALITY,
                     periodic=()) -> list[Candidate]:
    """Single-patch candidates from the larger template sizes: the best template of each size
    group of :data:`~jaxmatch.placement.solve.ALL_SIZES` after the first (the single candidate
    takes the first group that has one), named ``"single <template id>"``."""
    out, seen = [], {first.templates}
    for group in ALL_SIZES[1:]:
        try:
            lm = mesh_layout(lay, cat, lat, size=h, sizes=(group,), quality=quality, periodic=periodic)
        except (InputError, SolverError, IndexError):
            continue
        m = from_layout(lm, size=h, corners=corners, field=quality.field)
        if m.templates not in seen:
            seen.add(m.templates)
            out.append(Candidate(f"{SINGLE} {m.templates[0]}", m))
    return out


DISK = "disk"
"""Name of the central-block candidate of a region with fewer than two corners."""


def smooth_candidates(shape: Shape, cat, lat, h: float, quality: Quality) -> list[Candidate]:
    """A region with fewer than two corners (a disk, an ellipse, a teardrop): one template
    refined to the size (``"single"``), and a central block with four patches around it
    (``"disk"``, :func:`jaxmatch.placement.decompose.disk_layout`)."""
    corners = corner_points(shape)
    tried = []
    try:
        tried.append(Candidate(SINGLE, from_refined(shape, refine_mesh(shape, cat, lat, size=h, quality=quality).mesh,
                                                     size=h, field=quality.field)))
    except (InputError, SolverError) as e:
        tried.append(Candidate(SINGLE, None, str(getattr(e, "problem", e))))
    try:
        lm = mesh_layout(disk_layout(shape), cat, lat, size=h, smooth_cuts=True, quality=quality)
        tried.append(Candidate(DISK, from_layout(lm, size=h, corners=corners, field=quality.field)))
    except (InputError, SolverError) as e:
        tried.append(Candidate(DISK, None, str(getattr(e, "problem", e))))
    return tried


CONFORMING_TRIES = 3
"""When the single template's side counts cannot follow the size (its chords tie sides of
different lengths together, e.g. the two parallel sides of a trapezoid), the nearest even
count vectors to ``length / h`` (at most this many) are asked of every catalogue template."""


def _target_counts(lengths: np.ndarray, h: float, tries: int) -> list[np.ndarray]:
    """Edge counts per side nearest to ``lengths / h`` with an even total (a quad mesh has an
    even number of boundary edges), best first: ``(S,) int64`` each."""
    want = np.asarray(lengths, np.float64) / h
    base = np.maximum(np.rint(want), 1).astype(np.int64)
    if base.sum() % 2 == 0:
        return [base]
    moves = []
    for i in range(len(base)):
        for d in (-1, 1):
            if base[i] + d >= 1:
                moves.append((abs(base[i] + d - want[i]) - abs(base[i] - want[i]), i, d))
    out = []
    for _, i, d in sorted(moves)[:tries]:
        c = base.copy()
        c[i] += d
        out.append(c)
    return out


def conforming_templates(shape: Shape, cat, lat, h, first: QuadMesh, quality: Quality) -> list[Candidate]:
    """A single-template candidate whose side counts follow ``h``: the nearest even counts
    (:func:`_target_counts`), each met exactly by the best template of the catalogue that can
    (:func:`jaxmatch.placement.refine.refine_mesh`), named ``"single <template id>"``."""
    templates = walk(shape, cat, lat, limit=DEFAULT_LIMIT)  # placed as far as used (none: no count vector is met)
    out, seen = [], {first.templates}
    f = quality.field
    targets = side_lengths(shape) if f is None else np.array([line_integral(f, p)[-1] for p in side_polylines(shape)])
    for counts in _target_counts(targets, h if f is None else 1.0, CONFORMING_TRIES):
        try:
            choice = refine_mesh(shape, cat, lat, sides=counts.tolist(), templates=templates, explain=False,
                                 quality=quality)
        except (InfeasibleRequest, SolverError):
            continue
        except UnmatchableError:  # no catalogue mesh matches the shape: none matches it for other counts
            return out
        m = from_refined(shape, choice.mesh, size=h, field=quality.field)
        if m.templates not in seen and not m.sides_off_size(quality.size_tol):
            seen.add(m.templates)
            out.append(Candidate(f"{SINGLE} {m.templates[0]}", m))
    return out


