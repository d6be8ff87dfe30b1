"""The one solve: a :class:`~jaxmatch.placement.layout.Layout` meshed into one conforming quad mesh.

:func:`mesh_layout` gives every patch its candidate templates
(:func:`jaxmatch.placement.templates.first_group_templates`, fewest internal vertices first: a
coarse template refined is better shaped than a fine one); ONE integer program
(:func:`~jaxmatch.placement.milp.solve_counts`, HiGHS) chooses the chord multiplicities of all
patches at once: each patch's side counts are its ``side_matrix @ multiplicities``, a shared side
has one count, requested counts are met exactly, and without them the counts are closest to
``side length / size``. Each patch is refined
(:func:`jaxmatch.placement.refine.refine_and_place`), patch sides made of several sides are
fitted to them (:func:`~jaxmatch.placement.layout.fit_sides`), and the patches are merged
(:func:`~jaxmatch.placement.layout.merge_patches`). A patch whose refinement folds (or has a
scaled Jacobian below ``quality.good_sj``) is given its next template and the program is solved
again; the best round is kept (fewest inverted quads, then the highest minimum scaled Jacobian of
the worst patch). The side counts' floors keep the area
(:func:`~jaxmatch.placement.floors.curve_floors`; ``lean_curves``: the area budget shared by the
curved sides alone, tried by :class:`jaxmatch.meshing.strategies.LeanCurves`). A patch that
is a translate of an earlier one takes that patch's templates and
refinement, moved. With ``transitions`` (:class:`jaxmatch.meshing.strategies.Transitions`), the
patches off the size band are offered larger templates too (transition patterns: opposite sides
with different counts) and one integer program with a binary per patch and template
(:func:`~jaxmatch.placement.milp.solve_choice`) chooses them with the multiplicities.

Everything made is kept in the catalogue's cache (:mod:`jaxmatch.cache`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Mapping, NamedTuple, Sequence

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.cache import Cache
from jaxmatch.cache import key as cache_key
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.errors import InputError, UnmatchableError
from jaxmatch.field import kept_on_field, line_integral
from jaxmatch.placement.embed import sj_inverted, smooth_in_frame, smooth_near
from jaxmatch.placement.floors import curve_floors
from jaxmatch.placement.layout import (Layout, LayoutMesh, Sides, _boundary_loops, fit_sides,
                                       layout_sides, merge_patches, parse_counts, patch_shapes, region_area)
from jaxmatch.placement.milp import LayoutInfeasible, count_cost, counts_feasible, solve_choice, solve_counts
from jaxmatch.placement.refine import SMOOTH_ALWAYS, SMOOTH_ITERS_LARGE, refine_and_place, side_points, side_polylines
from jaxmatch.placement.templates import first_group_templates, lazy_patch_templates
from jaxmatch.shape import Shape

if TYPE_CHECKING:  # pragma: no cover
    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice

__all__ = ["ALL_SIZES", "ROUNDS", "TEMPLATES_PER_PATCH", "TEMPLATE_SIZES", "TRANSITION_CHORDS", "TRANSITION_OFFERS",
           "TRANSITION_PATCHES", "TRANSITION_TEMPLATES", "layout_key", "layout_sides_kept", "lean_floors_help",
           "mesh_layout", "off_size_patches", "patch_shapes_kept"]

TEMPLATE_SIZES = ((0, 1), (2, 3))
"""Groups of internal-vertex counts tried for a patch's templates, in this order: the first
group with a template that keeps the patch's corners gives the candidates (coarse templates
refine into better-shaped meshes, and each size costs placements)."""

ALL_SIZES = ((0, 1), (2, 3), (4, 5), (6, 7))
"""The groups used for a shape meshed as one patch (it may need large templates)."""

TEMPLATES_PER_PATCH = 3
"""How many candidate templates of each size a patch keeps (tried in order when a refinement
folds)."""

ROUNDS = 8
"""Largest number of (integer program, refine) rounds :func:`mesh_layout` runs."""


def _has(templates, j: int) -> bool:
    """Whether a patch has a ``j``-th candidate template (placing no more than that one)."""
    try:
        templates[j]
    except IndexError:
        return False
    return True


def _chord_targets(t, f) -> np.ndarray:
    """``t.chord_targets(f)`` of template ``t`` under size field ``f``
    (:meth:`~jaxmatch.placement.templates.PatchTemplate.chord_targets`), worked out once per
    placement and field (:func:`~jaxmatch.field.kept_on_field`: the rounds of each layout and the
    transition rounds ask again for the same templates); a copy."""
    return kept_on_field(f, "chord targets", (t.placement, t.edge_list, t.edge_chord),
                         lambda: t.chord_targets(f)).copy()


def _round_key(refined_mesh) -> tuple:
    """``(inverted quads, -min scaled Jacobian to 3 decimals)`` of a refined patch, from its own
    figures (which :func:`_fitted` keeps up to date when its sides move)."""
    return (int(refined_mesh.inverted), -round(float(refined_mesh.scaled_jacobian.min()), 3))


def _fitted(refined_mesh, xy: np.ndarray):
    """``refined_mesh`` at positions ``xy (V, 2)`` (e.g. from :func:`fit_sides`), its scaled
    Jacobians and inverted count measured there (the other figures are the refinement's)."""
    sj, inv = sj_inverted(xy, refined_mesh.quads)
    return refined_mesh._replace(xy=xy, scaled_jacobian=sj, inverted=int(inv.sum()))


def mesh_layout(layout: Layout, catalogue: Catalogue, lattice: Lattice, *, size: float | None = None,
                counts: Mapping[int, int] | None = None, templates_per_patch: int = TEMPLATES_PER_PATCH,
                sizes=TEMPLATE_SIZES, smooth_cuts: bool = False, progress=None,
                first_templates: Sequence[int] | None = None, quality: Quality = QUALITY,
                periodic: Sequence = (), lean_curves: bool = False, transitions: bool = False) -> LayoutMesh:
    """Mesh every patch of ``layout`` and merge them into one conforming :class:`LayoutMesh`.

    size: target edge length (user units) for sides without a requested count; counts:
    ``{side id: edges}`` requested (added to ``layout.requested``, which they override).
    sizes: groups of template sizes (internal vertices) tried per patch, see :data:`TEMPLATE_SIZES`.
    quality: the policy (:class:`~jaxmatch.defaults.Quality`): a refined patch below
    ``quality.good_sj`` (or with inverted quads) gets its next template in the next round;
    ``quality.area_tol`` bounds a curved side's chords.
    periodic: pairs of polylines ``(pa (k, 2), pb (j, 2))`` (user units) on the outer boundary:
    the layout sides along ``pa`` get as many edges in total as those along ``pb`` (one equality
    of the integer program, :func:`_equal_sides`).
    first_templates: per patch, the index of the candidate template to start from (default 0,
    the best-ranked; a patch with fewer candidates raises IndexError).
    smooth_cuts: after merging, untangle/smooth all vertices except the outer boundary
    (:func:`jaxmatch.placement.embed.smooth`; for decompositions, whose inner sides are not
    the user's): it never lowers the minimum scaled Jacobian.
    lean_curves: the area budget of the curved sides' chords shared by the curved boundary sides
    alone, not by the whole boundary (:func:`~jaxmatch.placement.floors.curve_floors`): curves
    nearer the size where the outline also has straight sides.
    transitions: after the rounds, the patches whose sides or chords are off the size band
    (:func:`off_size_patches`) are offered larger templates too (transition patterns: opposite
    sides may then get different counts) and ONE integer program chooses each patch's template
    with the multiplicities (:func:`~jaxmatch.placement.milp.solve_choice`, a larger template at
    ``quality.transition_gain`` edges of the size objective per internal vertex more); kept when
    its refinement neither folds nor falls below ``quality.good_sj``
    (:func:`_transition_rounds`).

    What is made is kept in the catalogue's cache (:mod:`jaxmatch.cache`: the meshed layout, its
    sides, patch shapes, integer programs, templates and refined patches): the same layout meshed
    again with the same options is not solved again.

    Raises :class:`InputError` when a patch has no template that keeps its corners, and
    :class:`LayoutInfeasible` when the requested counts cannot be met.
    """
    return _mesh_layout_cached(layout, catalogue, lattice, size=size, counts=counts,
                               templates_per_patch=templates_per_patch, sizes=sizes, smooth_cuts=smooth_cuts,
                               progress=progress, first_templates=first_templates, quality=quality,
                               periodic=tuple(periodic), lean_curves=bool(lean_curves),
                               transitions=bool(transitions))


def _equal_sides(layout: Layout, sides: Sides, periodic) -> tuple:
    """``((side ids along pa, side ids along pb), ...)``: the boundary sides of ``layout`` whose
    points all lie on each polyline of ``periodic`` (within ``1e-9`` of the layout's extent;
    shapely distances). Raises :class:`InputError` when a polyline has no side along it."""
    if not periodic:
        return ()
    import shapely

    tol = 1e-9 * float(np.ptp(layout.points, axis=0).max())
    outer = np.flatnonzero(sides.outer)
    out = []
    for pair in periodic:
        ids = []
        for poly in pair:
            line = shapely.LineString(np.asarray(poly, np.float64))
            on = [int(s) for s in outer
                  if float(np.max(shapely.distance(line, shapely.points(layout.points[sides.chains[s]])))) <= tol]
            if not on:
                raise InputError("a periodic side is no side of the layout", where=layout.source)
            ids.append(tuple(on))
        out.append(tuple(ids))
    return tuple(out)


FEASIBILITY_TRIES = 40
"""Integer programs :func:`_advance_for_feasibility` solves at most, looking for the one patch
whose template change makes a layout's program feasible: past it the layout is given up
(:class:`LayoutInfeasible`). Each try is a whole program; a ring partition of a 20-tooth gear
(138 patches) took 219 of them, 7.6 of its 8.6 s, for a mesh that did not win."""


def _advance_for_feasibility(sides, cands, choice, want, size, source, equal=(), f=None, side_targets=None) -> bool:
    """Switch one patch to another template so that the program becomes feasible; True when
    one was found (``choice`` is changed in place) within :data:`FEASIBILITY_TRIES` programs.
    Each try asks whether the program's constraints have a solution
    (:func:`~jaxmatch.placement.milp.counts_feasible`; ``size``, ``f`` and ``side_targets`` only
    price a solution, they decide none)."""
    tries = 0
    for p in range(len(cands)):
        j = -1
        while _has(cands[p], j + 1):  # (each candidate placed when reached: len() would place them all)
            j += 1
            if j == choice[p]:
                continue
            tries += 1
            if tries > FEASIBILITY_TRIES:
                return False
            trial = list(choice)
            trial[p] = j
            if not counts_feasible(sides, [cands[q][trial[q]].side_matrix() for q in range(len(cands))], counts=want,
                                   equal=equal):  # (the program's constraints alone: its targets only price it)
                continue
            choice[p] = j
            return True
    return False



def layout_key(layout: Layout) -> tuple:
    """The cache key of ``layout`` (every field, ``source`` too: the messages name it)."""
    return cache_key(layout)


def layout_sides_kept(layout: Layout, catalogue: Catalogue, lkey: tuple | None = None) -> Sides:
    """:func:`~jaxmatch.placement.layout.layout_sides`, kept in the catalogue's cache (store ``sides``)."""
    return catalogue.cache.get("sides", layout_key(layout) if lkey is None else lkey, lambda: layout_sides(layout),
                               keep_errors=(InputError, LayoutInfeasible))


def lean_floors_help(layout: Layout, catalogue: Catalogue, size: float, quality: Quality = QUALITY) -> bool:
    """Whether meshing ``layout`` with ``lean_curves`` (:func:`mesh_layout`) can bring a side
    nearer the size: some boundary side's floor from the whole boundary's share of the area
    budget (:func:`~jaxmatch.placement.floors.curve_floors`) makes its edges shorter than
    ``quality.size_band[0] * size`` and the curved sides' share alone lets them be that long.
    (Where it cannot, the lean solve gives a mesh no nearer the size band.)"""
    sides = layout_sides_kept(layout, catalogue)
    region = region_area(layout)
    fine = curve_floors(layout, sides, quality.area_tol, region)
    short = sides.lengths / fine < quality.size_band[0] * float(size)
    if not np.any(short & (fine > 1)):
        return False
    lean = curve_floors(layout, sides, quality.area_tol, region, lean=True, size=size)
    return bool(np.any(short & (sides.lengths / lean >= quality.size_band[0] * float(size))))


def patch_shapes_kept(layout: Layout, catalogue: Catalogue, lkey: tuple | None = None) -> list[Shape]:
    """:func:`~jaxmatch.placement.layout.patch_shapes`, kept in the catalogue's cache (store ``shapes``)."""
    return catalogue.cache.get("shapes", layout_key(layout) if lkey is None else lkey, lambda: patch_shapes(layout),
                               keep_errors=(InputError, LayoutInfeasible))


def _solve_counts_cached(layout: Layout, sides: Sides, matrices, want, size, widths, floors, cache: Cache,
                         lkey: tuple, equal: tuple = (), side_targets=None, chord_targets=None, box: bool = False):
    """:func:`solve_counts` of ``layout`` (whose ``sides`` these are, ``lkey`` its
    :func:`layout_key`; ``box`` as there), from ``cache`` (store ``solves``) when the same program
    was solved before; fresh copies of the arrays either way."""
    k = (lkey,) + cache_key(matrices, {int(a): int(b) for a, b in want.items()}, None if size is None else float(size),
                            widths, floors) + ((equal,) if equal else ())
    if side_targets is not None:  # a size field's targets (uniform sizes: the key as it was)
        k = k + cache_key(side_targets, chord_targets)
    if box:
        k = k + cache_key("box")
    mults, n = cache.get("solves", k, lambda: solve_counts(sides, matrices, counts=want, size=size, widths=widths,
                                                          source=layout.source, floors=floors, equal=equal,
                                                          side_targets=side_targets, chord_targets=chord_targets,
                                                          box=box),
                         keep_errors=(InputError, LayoutInfeasible))
    return [np.array(m) for m in mults], np.array(n)


CUT_RINGS = 6
"""Above :data:`jaxmatch.placement.refine.SMOOTH_ALWAYS` quads, the whole-mesh smoothing of a
decomposition moves only the vertices within this many rings of quads of an inner side (the
cuts): the patches come smoothed already, and smoothing every vertex was ~80% of the time of a
25,000-quad L-shape."""


def _smooth_cuts(xy: np.ndarray, quads: np.ndarray, fixed: np.ndarray, sides: Sides, side_ids) -> np.ndarray:
    """The merged mesh smoothed with the outer loops ``fixed``
    (:func:`jaxmatch.placement.embed.smooth_in_frame`): every other vertex up to
    :data:`~jaxmatch.placement.refine.SMOOTH_ALWAYS` quads; above, with
    :data:`~jaxmatch.placement.refine.SMOOTH_ITERS_LARGE` iterations, only the vertices within
    :data:`CUT_RINGS` rings of the inner sides (the quads around them smoothed as a submesh
    whose other vertices stay)."""
    if quads.shape[0] <= SMOOTH_ALWAYS:
        return smooth_in_frame(xy, quads, fixed)
    inner = [np.asarray(side_ids[s], np.int64) for s in range(len(side_ids)) if sides.users[s, 1] >= 0]
    if not inner:
        return xy
    return smooth_near(xy, quads, np.concatenate(inner), fixed, rings=CUT_RINGS, frame=xy[fixed],
                       iters=SMOOTH_ITERS_LARGE)


def _mesh_layout_cached(layout: Layout, catalogue, lattice, *, size, counts, templates_per_patch, sizes, smooth_cuts,
                        progress, first_templates, quality, periodic=(), lean_curves=False,
                        transitions=False) -> LayoutMesh:
    """:func:`_mesh_layout` from the catalogue's cache (store ``layouts``) when the same layout was
    meshed with the same options (the answer names the given layout; its arrays are copies)."""
    lkey = layout_key(layout)
    k = (lkey,) + cache_key(lattice, None if size is None else float(size),
                            None if counts is None else {int(a): int(b) for a, b in dict(counts).items()},
                            int(templates_per_patch), sizes, bool(smooth_cuts), first_templates, quality) \
        + ((cache_key(*[np.asarray(x, np.float64) for pair in periodic for x in pair]),) if periodic else ()) \
        + (("lean",) if lean_curves else ()) + (("transitions",) if transitions else ())
    cache = catalogue.cache
    done = cache.lookup("layouts", k)  # (an error kept for these options is raised again)
    if done is not None:
        if progress:
            for p in range(layout.n_patches):
                progress(p + 1, layout.n_patches)
        return _copied(done, layout)
    lm = cache.get("layouts", k, lambda: _mesh_layout(layout, catalogue, lattice, size=size, counts=counts,
                                                      templates_per_patch=templates_per_patch, sizes=sizes,
                                                      smooth_cuts=smooth_cuts, progress=progress,
                                                      first_templates=first_templates, quality=quality, lkey=lkey,
                                                      periodic=periodic, lean_curves=lean_curves,
                                                      transitions=transitions),
                   quads=lambda m: m.quads.shape[0], keep_errors=(LayoutInfeasible, InputError))
    return _copied(lm, layout)


def _copied(lm: LayoutMesh, layout: Layout) -> LayoutMesh:
    """``lm`` for ``layout``, its arrays copied (a caller may write to them)."""
    def cp(v):
        if isinstance(v, np.ndarray):
            return v.copy()
        if isinstance(v, tuple):
            return tuple(cp(x) for x in v)
        if isinstance(v, list):
            return [cp(x) for x in v]
        return v

    out = {f.name: cp(getattr(lm, f.name)) for f in dataclasses.fields(lm) if f.name not in ("layout", "sides")}
    return dataclasses.replace(lm, layout=layout, **out)


def _mesh_layout(layout: Layout, catalogue: Catalogue, lattice: Lattice, *, size, counts, templates_per_patch, sizes,
                 smooth_cuts, progress, first_templates, quality: Quality, lkey: tuple, periodic=(),
                 lean_curves: bool = False, transitions: bool = False) -> LayoutMesh:
    """The work of :func:`mesh_layout` (see there; ``lkey``: :func:`layout_key` of ``layout``)."""
    cache = catalogue.cache
    sides = layout_sides_kept(layout, catalogue, lkey)
    want = {s: c for s, c in parse_counts(dict(layout.requested), sides, layout.source).items()}
    want.update(counts or {})
    equal = _equal_sides(layout, sides, periodic)
    shapes = patch_shapes_kept(layout, catalogue, lkey)
    f = quality.field
    moved = _translates(layout) if f is None else [Translate(p, np.zeros(2), 0) for p in range(len(shapes))]
    # (a size field is not the same on a translate: every patch its own)
    side_targets = None if f is None or size is None else \
        np.array([line_integral(f, layout.points[c])[-1] for c in sides.chains])
    cands = []
    for p, shp in enumerate(shapes):
        if moved[p].of != p:  # a translate of an earlier patch: its templates, turned
            cands.append(_Turned(cands[moved[p].of], moved[p].turn, shp))
            if progress:
                progress(p + 1, len(shapes))
            continue
        t = first_group_templates(shp, catalogue, lattice, templates_per_patch, sizes)
        if not t:
            ks = sorted({k for g in sizes for k in g if k in catalogue.internal})
            raise InputError(f"patch {p}: no catalogue template with {ks[0]}..{ks[-1]} internal vertices keeps its "
                             f"{shp.n_corners} corners without folding (split the patch)", where=layout.source)
        cands.append(t)
        if progress:
            progress(p + 1, len(shapes))
    region = region_area(layout)
    choice0 = [0] * len(shapes) if first_templates is None else [int(j) for j in first_templates]
    for p, j in enumerate(choice0):
        if not (j >= 0 and _has(cands[p], j)):
            raise IndexError(f"patch {p} has {len(cands[p])} candidate templates, not {j + 1}")
    made: dict = {}
    floors = curve_floors(layout, sides, quality.area_tol, region, lean=lean_curves,
                          size=size) if size is not None else None
    best = _rounds(layout, sides, shapes, cands, moved, list(choice0), want, size, floors, equal, side_targets, f, made,
                   quality, lkey, cache)
    if transitions and size is not None:
        best = _transition_rounds(layout, sides, shapes, cands, moved, best, want, size, floors, equal, side_targets,
                                  f, quality, catalogue, lattice)
    return _merged(layout, sides, best, smooth_cuts, region)


def _merged(layout: Layout, sides: Sides, best: tuple, smooth_cuts: bool, region: float) -> LayoutMesh:
    """The :class:`LayoutMesh` of a best round of :func:`_rounds`: its patches merged, the cuts
    smoothed when ``smooth_cuts``."""
    _, tmpl, mults, n, refined = best
    xy, quads, patch, side_ids, gap = merge_patches(layout, sides, refined, n)
    loops = _boundary_loops(layout, sides, side_ids, xy)
    outer, holes = loops[0], tuple(loops[1:])
    if smooth_cuts:
        xy = _smooth_cuts(xy, quads, np.concatenate(loops), sides, side_ids)
    return LayoutMesh(layout=layout, sides=sides, xy=xy, quads=quads, patch=patch, side_vertices=side_ids,
                      counts=n, outer=outer, holes=holes, templates=tuple(t.mesh_id for t in tmpl),
                      multiplicities=tuple(mults), shared_gap=gap, region_area=float(region))


def _rounds(layout: Layout, sides: Sides, shapes, cands, moved, choice: list, want, size, floors, equal, side_targets, f,
            made: dict, quality: Quality, lkey: tuple, cache: Cache):
    """The rounds of :func:`_mesh_layout` with these side ``floors``: solve, refine, give each
    patch that folds (or is below ``quality.good_sj``) its next template, at most :data:`ROUNDS`
    times. Returns the best round ``(key, templates, multiplicities, counts, refined patches)``;
    ``made``: refinements kept across calls. Raises :class:`LayoutInfeasible` when no round is
    feasible."""
    best = None
    for _ in range(ROUNDS):
        tmpl = [cands[p][choice[p]] for p in range(len(shapes))]
        try:
            mults, n = _solve_counts_cached(layout, sides, [t.side_matrix() for t in tmpl], want, size,
                                            [t.chord_widths() for t in tmpl], floors, cache, lkey, equal, side_targets,
                                            None if side_targets is None else [_chord_targets(t, f) for t in tmpl],
                                            quality.search.box)
        except LayoutInfeasible:
            if not _advance_for_feasibility(sides, cands, choice, want, size, layout.source, equal,
                                            None if side_targets is None else f, side_targets):
                raise
            continue
        refined = []
        for p, (t, m) in enumerate(zip(tmpl, mults)):
            q = moved[p].of
            key = (q, choice[p], tuple(m.tolist()))
            if key not in made:
                made[key] = refine_and_place(cands[q][choice[p]] if q != p else t, m, quality=quality, cache=cache)
            rm = made[key]
            if q != p:
                rm = _translated(rm, moved[p], shapes[p], t)
            if any(len(parts) > 1 for parts in sides.patch_sides[p]):  # neighbours meet along a side
                rm = _fitted(rm, fit_sides(layout, sides, p, rm, n, quality=quality, cache=cache))
            refined.append(rm)
        keys = [_round_key(r) for r in refined]
        total = (sum(k[0] for k in keys), max(k[1] for k in keys))  # inverted quads, then the worst patch
        if best is None or total < best[0]:
            best = (total, list(tmpl), mults, n, refined)
        bad = [p for p, k in enumerate(keys) if (k[0] > 0 or -k[1] < quality.good_sj) and _has(cands[p], choice[p] + 1)]
        if not bad:
            break
        for p in bad:
            choice[p] += 1
    if best is None:  # pragma: no cover - the loop solved at least once or raised
        raise LayoutInfeasible("no round of the layout's solve was feasible", where=layout.source)
    return best


TRANSITION_TEMPLATES = 6
"""How many templates of each size of the next size group (:data:`ALL_SIZES`) a patch off the
size is offered by :func:`_transition_rounds`, besides its own candidates (ranked by the
lattice, not by their chords: with 3, the trapezoid of tests/test_solve.py was offered no
template whose parallel sides take different counts, with 6 it is)."""


TRANSITION_OFFERS = 6
"""Most templates a patch off the size is offered that reach side counts its own cannot, its own
included (:func:`_offered`): each binary choice widens the program. The 8-pointed star's ring
partition at P/40 (13 patches): with 3 or 4 the template that brings its points to the size is
not among them, with 6 it is."""

TRANSITION_PATCHES = 16
"""Most patches (a translate's with its original) :func:`_transition_rounds` offers other
templates: those whose sides are furthest off their targets (the program's binaries, and its
time, grow with them; the 8-pointed star's ring partition needs its 13 patches)."""

TRANSITION_SCREEN = True
"""Whether :func:`_transition_rounds`' programs are screened by their linear relaxation first
(:func:`~jaxmatch.placement.milp.solve_choice`, ``screen``): ``jaxmatch.mesh`` in a fresh
process took 9.0 s with all alternatives and 3.3 s screened on the letter B (holes) at P/80,
4.7 s and 1.9 s on the slotted link at P/40 (neither keeps a transition either way); the
8-pointed star at P/40 and the graded rectangle take their transitions either way (the star's:
53 quads, 94 % of edges at the size unscreened, 52 quads and 94 % screened)."""

TRANSITION_CHORDS = 2
"""Most templates a patch off the size is offered besides those (:func:`_offered`) that reach no
new side counts but have more chords than its own: rows inside it at a size field's sizes (the
graded rectangle's ring partition takes two such in its core)."""


TRANSITION_NODES = 500
"""Most branch-and-bound nodes HiGHS may spend on one program of :func:`_transition_rounds` (a
limit of work, so the answer does not depend on the machine's load; past it, the best solution
found: the program starts from every patch's own template and multiplicities, so it is never
worse than the round it would replace)."""

TRANSITION_CHORD_WEIGHT = 1.0
"""Weight of the chords' deviations ``|m_c - width_c / size|`` in the program of
:func:`_transition_rounds` (against 1 for the sides'): a template's inner chords make edges
as its sides do, and a transition that brings its sides to the size by squeezing its chords
is no nearer the size band."""

TRANSITION_ROUNDS = 3
"""Largest number of programs :func:`_transition_rounds` solves (each after banning the
templates whose refinement folded or fell below the floor)."""

TRANSITION_TIE = 1e-3
"""Penalty of taking another template than a patch's own at no size gain (ties stay)."""


def off_size_patches(sides: Sides, templates, mults, n: np.ndarray, size: float, quality: Quality = QUALITY, *,
                     side_targets: np.ndarray | None = None, chord_targets=None, floors: np.ndarray | None = None,
                     want: Mapping[int, int] | None = None) -> list[int]:
    """The patches of a solved layout that a template with other chords could bring nearer the
    size: one of its layout sides (not requested, not held at its floor) whose edges, ``target_s
    / n_s`` sizes long (``target_s = length_s / size``, or a size field's integral), lie outside
    ``quality.size_band``; or one of its chords whose edges across, ``tau_c / m_c`` sizes
    (``tau_c = width_c / size`` of :meth:`PatchTemplate.chord_widths`, or the field's
    ``chord_targets``), do (shorter only where ``m_c > 1``).

    templates: per patch the template used; mults: its ``(c_p,)`` multiplicities; n: ``(S,)``
    edges per side. Returns the patch indices, ascending."""
    lo, hi = quality.size_band
    want = dict(want or {})
    tgt = np.asarray(side_targets, np.float64) if side_targets is not None else np.asarray(sides.lengths) / float(size)
    n = np.asarray(n, np.float64)
    ratio = tgt / np.maximum(n, 1.0)
    held = np.zeros(len(n), bool) if floors is None else (n <= np.maximum(np.asarray(floors), 1)) & (ratio < lo)
    off_side = ((ratio < lo) | (ratio > hi)) & ~held
    off_side[list(want)] = False
    out = []
    for p, (t, m) in enumerate(zip(templates, mults)):
        if any(off_side[np.asarray(x, np.int64)].any() for x in sides.patch_sides[p]):
            out.append(p)
            continue
        tau = np.asarray(chord_targets[p] if chord_targets is not None else t.chord_widths() / float(size), np.float64)
        r = tau / np.maximum(np.asarray(m, np.float64), 1.0)
        if np.any(((r < lo) & (np.asarray(m) > 1)) | (r > hi)):
            out.append(p)
    return out


def _internal(t) -> int:
    """Internal vertices of template ``t`` (a :class:`~jaxmatch.placement.templates.PatchTemplate`)."""
    return int(t.match.internal_vertices)


def _same_template(a, b) -> bool:
    """Whether two templates of one patch are the same catalogue mesh fitted the same way."""
    return a.mesh_id == b.mesh_id and int(a.match.rotation) == int(b.match.rotation) and \
        bool(a.match.reflected) == bool(b.match.reflected) and np.array_equal(a.match.alignment, b.match.alignment)


def _offered(shape: Shape, base, own, catalogue, lattice) -> list:
    """The templates offered to a patch off the size (``base`` first, its template now): of up
    to :data:`TRANSITION_TEMPLATES` of each size of the :data:`ALL_SIZES` group after ``base``'s
    and then its own candidates ``own``, one per form of side matrix (:func:`_chord_form`):
    those that reach side counts ``base`` cannot (:func:`_new_counts`; with ``base``,
    :data:`TRANSITION_OFFERS` at most), then those with more chords than ``base``
    (:data:`TRANSITION_CHORDS` at most)."""
    out = [base]
    k = _internal(base)
    at = next((i for i, g in enumerate(ALL_SIZES) if k in g), len(ALL_SIZES))
    nxt = ALL_SIZES[at + 1] if at + 1 < len(ALL_SIZES) else None
    groups = []
    if nxt is not None:
        ks = [x for x in nxt if x in catalogue.internal]
        if ks:
            groups.append(lazy_patch_templates(shape, catalogue, lattice, limit=TRANSITION_TEMPLATES, internal=ks))
    groups.append(own)
    seen = {_chord_form(base.side_matrix())}
    more = []  # templates reaching no new side counts but with more chords inside (a size field's rows)
    nb = base.side_matrix().shape[1]
    for g in groups:
        for t in _each(g):  # (placed one by one: no more than the offers need)
            if len(out) >= TRANSITION_OFFERS and len(more) >= TRANSITION_CHORDS:
                return out + more
            A = t.side_matrix()
            if _chord_form(A) in seen:
                continue
            seen.add(_chord_form(A))
            if _new_counts(base.side_matrix(), A):
                if len(out) < TRANSITION_OFFERS:
                    out.append(t)
            elif A.shape[1] > nb and len(more) < TRANSITION_CHORDS:
                more.append(t)
    return out + more


def _each(templates):
    """The templates of a sequence one by one (a :class:`~jaxmatch.placement.templates.LazyTemplates`
    places each when asked for), none when its walk finds no match."""
    j = 0
    while True:
        try:
            t = templates[j]
        except (IndexError, InputError, UnmatchableError):
            return
        yield t
        j += 1


def _chord_form(A: np.ndarray) -> tuple:
    """Side matrix ``A (n, c)`` up to the order of its chords: templates with the same form
    reach the same side counts."""
    return tuple(sorted(map(tuple, np.asarray(A, np.int64).T.tolist())))


def _new_counts(base: np.ndarray, A: np.ndarray) -> bool:
    """Whether side matrix ``A`` can reach side counts that ``base`` cannot: ``base``'s counts obey
    the equalities ``y @ counts = 0`` of its left null space (a grid: opposite sides equal);
    ``A`` is new when one of them does not hold for its columns. A ``base`` without equalities
    (a 3-sided template) takes every other form (they may reach fewer edges on a side)."""
    base = np.asarray(base, np.float64)
    _, sv, vt = np.linalg.svd(base.T)
    rank = int(np.count_nonzero(sv > 1e-9))
    Y = vt[rank:]
    if Y.shape[0] == 0:
        return True
    return bool(np.abs(Y @ np.asarray(A, np.float64)).max() > 1e-9)


def _transition_rounds(layout: Layout, sides: Sides, shapes, cands, moved, best: tuple, want, size, floors, equal,
                       side_targets, f, quality: Quality, catalogue, lattice) -> tuple:
    """The best round of :func:`_rounds` with templates chosen for size: the patches off the size
    (:func:`off_size_patches`; a translate's with its original) are offered their other
    candidates and larger templates (:func:`_offered`), and ONE integer program
    (:func:`~jaxmatch.placement.milp.solve_choice`) chooses every patch's template and
    multiplicities, a larger template costing ``quality.transition_gain`` per internal vertex
    more than the patch's template now. The refined patches that fold or fall below
    ``quality.good_sj`` lose that template and the program is solved again (at most
    :data:`TRANSITION_ROUNDS` times). Returns the new round ``(key, templates, multiplicities, counts, refined
    patches)`` when its size objective is lower than ``best``'s and no patch folds or falls
    below ``quality.good_sj``; else ``best``."""
    cache = catalogue.cache
    _, tmpl, mults, n, _ = best
    ct = None if side_targets is None else [_chord_targets(t, f) for t in tmpl]
    flagged = off_size_patches(sides, tmpl, mults, n, size, quality, side_targets=side_targets, chord_targets=ct,
                               floors=floors, want=want)
    tgt = np.asarray(side_targets, np.float64) if side_targets is not None else sides.lengths / float(size)
    off = {}  # original patch -> how far its sides are off their targets (edges), over its translates
    for p in flagged:
        ids = np.unique(np.concatenate([np.asarray(x, np.int64).ravel() for x in sides.patch_sides[p]]))
        off[moved[p].of] = off.get(moved[p].of, 0.0) + float(np.sum(np.abs(np.asarray(n)[ids] - tgt[ids])))
    originals = sorted(sorted(off, key=lambda q: (-off[q], q))[:TRANSITION_PATCHES])
    if not originals:
        return best
    plain = count_cost(sides, mults, n, size=size, widths=[t.chord_widths() for t in tmpl], counts=want,
                       side_targets=side_targets, chord_targets=ct, chord_weight=TRANSITION_CHORD_WEIGHT)
    offered = {}  # original patch -> its templates offered (unturned)
    for q in originals:
        offered[q] = _offered(shapes[q], tmpl[q], cands[q], catalogue, lattice)
    alts, origs = [], []  # per patch: templates as this patch sees them, and the originals to refine
    for p in range(len(shapes)):
        q = moved[p].of
        if q not in offered:
            alts.append([tmpl[p]])
            origs.append([next(t for t in _each(cands[q]) if _same_template(t, tmpl[p]))] if q != p else [tmpl[p]])
            continue
        origs.append(offered[q])
        alts.append(offered[q] if q == p else list(_Turned(offered[q], moved[p].turn, shapes[p])))
    top = max([float(np.max(m)) for m in mults] + [float(np.max(sides.lengths)) / float(size)]
              + ([float(np.max(side_targets))] if side_targets is not None else []))
    bound = 3 * int(math.ceil(top)) + 4
    most = np.maximum.reduce([np.asarray(n, np.float64), np.ceil(tgt / quality.size_band[0]) + 1,
                              np.ones(len(n)) if floors is None else np.asarray(floors, np.float64)])
    for s_, c_ in want.items():
        most[s_] = max(most[s_], c_)
    banned = [set() for _ in alts]
    for _ in range(TRANSITION_ROUNDS):
        keep = [[j for j in range(len(a)) if j not in banned[p]] for p, a in enumerate(alts)]
        pick = [[alts[p][j] for j in keep[p]] for p in range(len(alts))]
        pen = [[0.0 if j == 0 else quality.transition_gain * max(_internal(alts[p][j]) - _internal(alts[p][0]), 0)
                + TRANSITION_TIE for j in keep[p]] for p in range(len(alts))]
        try:
            ch = solve_choice(sides, [[t.side_matrix() for t in a] for a in pick], penalties=pen, size=size,
                              widths=[[t.chord_widths() for t in a] for a in pick], floors=floors, counts=want,
                              equal=equal, side_targets=side_targets,
                              chord_targets=None if f is None else [[_chord_targets(t, f) for t in a] for a in pick],
                              chord_weight=TRANSITION_CHORD_WEIGHT, bound=bound, most=most,
                              start=(mults, n), max_nodes=TRANSITION_NODES, screen=TRANSITION_SCREEN,
                              source=layout.source)
        except LayoutInfeasible:
            return best
        chosen = [keep[p][j] for p, j in enumerate(ch.choice)]
        if not any(chosen) or not ch.size_cost < plain:
            return best
        refined, new_tmpl = [], []
        for p, j in enumerate(chosen):
            q, m = moved[p].of, ch.multiplicities[p]
            t = alts[p][j]
            rm = refine_and_place(origs[p][j], m, quality=quality, cache=cache)
            if q != p:
                rm = _translated(rm, moved[p], shapes[p], t)
            if any(len(parts) > 1 for parts in sides.patch_sides[p]):
                rm = _fitted(rm, fit_sides(layout, sides, p, rm, ch.counts, quality=quality, cache=cache))
            refined.append(rm)
            new_tmpl.append(t)
        keys = [_round_key(r) for r in refined]
        bad = [p for p, k in enumerate(keys) if k[0] > 0 or -k[1] < quality.good_sj]
        if not bad:
            total = (0, max(k[1] for k in keys))
            return (total, new_tmpl, ch.multiplicities, ch.counts, refined)
        if any(chosen[p] == 0 for p in bad):
            return best  # a patch kept its template and still folds at the new counts
        for p in bad:
            banned[p].add(chosen[p])
    return best


TRANSLATE_TOL = 1e-12
"""Patches whose points, relative to their lowest-leftmost point, agree to this fraction of the
layout's extent are translates of each other (:func:`_translates`)."""


class Translate(NamedTuple):
    """Patch ``of`` (an earlier patch) moved by ``shift (2,) float64`` is this patch, its loop
    listed from another corner: this patch's side ``i`` is that patch's side ``i + turn`` (mod
    its number of sides)."""

    of: int
    shift: np.ndarray
    turn: int


def _translates(layout: Layout) -> list[Translate]:
    """Per patch, the first patch of which it is a translate (itself, ``turn`` 0, when none):
    the same corners and the same points relative to the lowest-leftmost one, up to
    :data:`TRANSLATE_TOL` of the layout's extent, whichever corner each loop starts from. Such a
    patch has the same templates, its sides turned (:class:`_Turned`), and its refinement at the
    same multiplicities is that patch's moved (:func:`_translated`)."""
    unit = TRANSLATE_TOL * max(float(np.max(np.ptp(layout.points, axis=0))), np.finfo(float).tiny)
    first: dict = {}
    out = []
    for p, (loop, pc) in enumerate(zip(layout.patches, layout.patch_corner)):
        rel = np.rint((layout.points[loop] - layout.points[loop].min(axis=0)) / unit).astype(np.int64)
        low = int(np.lexsort((rel[:, 1], rel[:, 0]))[0])  # lowest x, then lowest y (exact on the grid)
        key = (roll(rel, -low).tobytes(), roll(np.asarray(pc), -low).tobytes())
        q, qlow = first.setdefault(key, (p, low))
        n = len(loop)
        offset = (qlow - low) % n  # point i of this loop is point i + offset of patch q's
        qloop, qpc = layout.patches[q], np.asarray(layout.patch_corner[q])
        turn = int(np.count_nonzero(qpc[:offset]))  # this patch's corner 0 (loop point 0) is q's corner `turn`
        out.append(Translate(q, layout.points[loop[0]] - layout.points[qloop[offset]], turn))
    return out


def _turned_sides(items: tuple, turn: int) -> tuple:
    """Per-side ``items`` of a patch as seen from a translate whose side ``i`` is side ``i + turn``."""
    return tuple(items[turn:]) + tuple(items[:turn])


class _Turned(Sequence):
    """The templates of a patch (a sequence of :class:`~jaxmatch.placement.templates.PatchTemplate`,
    placed as asked for) as templates of its translate ``shape`` whose side ``i`` is its side
    ``i + turn``: the per-side fields turned, ``shape`` replaced (the placement stays the
    original's: only its edge lengths, which a translation keeps, are read)."""

    def __init__(self, templates, turn: int, shape: Shape):
        self._templates, self._turn, self._shape = templates, int(turn), shape

    def __getitem__(self, j):
        if isinstance(j, slice):
            return [self._one(t) for t in self._templates[j]]
        return self._one(self._templates[j])

    def _one(self, t):
        return t._replace(shape=self._shape, side_chords=_turned_sides(t.side_chords, self._turn),
                          side_path=_turned_sides(t.side_path, self._turn))

    def __len__(self) -> int:
        return len(self._templates)

    def __bool__(self) -> bool:
        return bool(self._templates)


def _translated(rm, tr: Translate, shape: Shape, template):
    """Refined patch ``rm`` (of patch ``tr.of``) moved onto its translate ``shape`` (refined from
    ``template``, the turned one): the boundary vertices exactly where the refinement of
    ``shape`` puts them (:func:`jaxmatch.placement.refine.side_points` on its sides, so shared
    sides stay bit-identical), the others moved by ``tr.shift``; the sides turned; its quality
    figures are the original's."""
    xy = rm.xy + tr.shift
    side_vertices = _turned_sides(rm.side_vertices, tr.turn)
    counts = np.asarray(_turned_sides(tuple(rm.counts.tolist()), tr.turn), np.int64)
    for sv, poly, c in zip(side_vertices, side_polylines(shape), counts.tolist()):
        xy[sv] = side_points(poly, int(c))
    return rm._replace(xy=xy, side_vertices=side_vertices, counts=counts, template=template)
