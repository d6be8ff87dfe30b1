"""The one meshing pipeline: request -> strategies -> one solve each -> one choice rule -> one
result type.

:func:`mesh` is the front door (``jaxmatch.mesh``; ``jaxmatch mesh`` calls it):

The steps live in their own modules: the region (:mod:`.region`: reading, default size, the
canonical loops, corners at the size), the candidates (:mod:`.strategies`), the choice
(:mod:`.choose`), the result (:mod:`.result`, built by :mod:`.build`).

* a **layout** (a :class:`~jaxmatch.placement.layout.Layout` or a layout JSON file) is meshed as
  that layout;
* a **shape** with a target edge length ``size`` (default: perimeter / :data:`DEFAULT_DIVISIONS`)
  is meshed as one template (``"single"``) and as each decomposition of
  :data:`~jaxmatch.placement.decompose.STRATEGIES`; every candidate is meshed by the same solve
  (:func:`~jaxmatch.placement.solve.mesh_layout`: templates per patch, one integer program for
  every side count, refinement, placement, merging, smoothing); then, when the best so far needs
  them, larger templates, templates that follow the size, the curves meshed coarser (nearer the
  size) and the bends as corners: one plan of
  strategy objects (:mod:`.strategies`), run once, and the best kept by the one rule of
  :mod:`jaxmatch.meshing.choose`, applied once;
* a shape with ``sides`` (edges per side) is meshed as one template meeting them exactly;
* ``template=True`` gives the paper's answer: the best-ranked catalogue mesh placed as is
  (:func:`jaxmatch.placement.choose.choose_mesh`).

Every case returns a :class:`~jaxmatch.meshing.result.QuadMesh`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import replace
from typing import Callable, Mapping, Sequence

import numpy as np

from jaxmatch.autosize import auto_field
from jaxmatch.defaults import DEFAULT_LATTICE, QUALITY, SEARCHES, Quality, Search
from jaxmatch.errors import InputError
from jaxmatch.field import CallableSize, Field, SizeField, bind, outline_size
from jaxmatch.meshing.build import from_layout, from_placement, from_refined
from jaxmatch.meshing.choose import choose
from jaxmatch.meshing.groups import make_periodic, name_groups, periodic_mismatch
from jaxmatch.meshing.grading import follow_field
from jaxmatch.meshing.region import canonical, corner_points, default_size, load_region
from jaxmatch.meshing.result import Candidate, QuadMesh
from jaxmatch.meshing.strategies import (RINGS, SINGLE, Bends, Conforming, Enough, Larger, Layouts, LeanCurves, Request, RingPartition,
                                         Rings, Smooth, Transitions, layout_strategies, run)
from jaxmatch.inputs import _lattice, check_sizes, load_catalogue
from jaxmatch.lazy import Later
from jaxmatch.model import Model, Region, make_model
from jaxmatch.placement.choose import choose_mesh
from jaxmatch.placement.decompose import STRATEGIES, single_patch
from jaxmatch.placement.layout import Layout, LayoutInfeasible, layout_sides
from jaxmatch.placement.refine import InfeasibleRequest, _check_counts, refine_mesh
from jaxmatch.placement.solve import ALL_SIZES, mesh_layout
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, Shape, make_shape

later = Later(assembly="jaxmatch.meshing.assembly", models="jaxmatch.io.assembly")  # only for assemblies

__all__ = ["SINGLE", "canonical", "default_size", "load_region", "mesh", "strategy_names", "warm_up"]


def strategy_names() -> tuple[str, ...]:
    """Every candidate strategy, in the order tried: ``"single"``, the decompositions, then the
    ring partition (``"rings"``)."""
    return (SINGLE,) + tuple(STRATEGIES) + (RINGS,)


def _is_field(size) -> bool:
    """Whether ``size`` is a size field (a :class:`~jaxmatch.field.Field`, a bound one, or a
    callable) rather than a number."""
    return isinstance(size, (Field, SizeField, CallableSize)) or (callable(size) and not isinstance(size, (int, float)))


def _check_size(size) -> float:
    try:
        h = float(size)
    except (TypeError, ValueError):
        h = math.nan
    if not (h > 0 and math.isfinite(h)):
        raise InputError(f"element size must be a positive number, got {size!r}")
    return h


def _side_ids(shape: Shape, layout) -> list[int]:
    """Layout side id of each user side ``i`` of ``shape`` (corner ``i`` to ``i + 1`` in the
    file's order) in :func:`~jaxmatch.placement.decompose.single_patch`'s layout."""
    sides = layout_sides(layout)
    ends = {(int(c[0]), int(c[-1])): s for s, c in enumerate(sides.chains)}
    c = shape.corners
    out = []
    for j, _ in shape.side_frame:
        a, b = int(c[j]), int(c[(j + 1) % len(c)])
        s = ends.get((a, b), ends.get((b, a)))
        if s is None:  # pragma: no cover - single_patch keeps every corner as a node
            raise ValueError(f"side {a}-{b} is not a layout side")
        out.append(s)
    return out


def mesh(region=None, *, regions=None, size: float | None = None, divisions: int | None = None, sides: Sequence[int] | None = None,
         counts: Mapping[int, int] | None = None, template: bool = False,
         catalogue=None, lattice=DEFAULT_LATTICE, strategies: Sequence[str] | None = None,
         quality: Quality = QUALITY, corner_angle: float = DEFAULT_CORNER_ANGLE, budget_s: float | None = None,
         progress: Callable[[int, int, str], None] | None = None, auto_size: bool = False,
         search: str | Search | None = None, **template_options) -> QuadMesh:
    """Mesh a region: the one front door.

    Args:
      region: a :class:`~jaxmatch.shape.Shape`, a :class:`~jaxmatch.placement.layout.Layout`,
        a :class:`~jaxmatch.model.Model` (an assembly), or a path (a shape file of any format, a
        layout JSON file, an assembly file).
      regions: instead of ``region``: an assembly's regions, each a :class:`~jaxmatch.model.Region`
        or a dict ``{"name": ..., "boundary": ..., "holes": ..., "embedded": ...}`` (the JSON
        file's entries); meshed as one conforming mesh (:mod:`jaxmatch.meshing.assembly`).
      size: target edge length (user units); default perimeter / :data:`DEFAULT_DIVISIONS`. Or a
        size field (shapes only): a :class:`jaxmatch.field.Field` (``Field(H, near=[Near(...)])``,
        the JSON form of ``--size-field``) or a callable mapping ``(n, 2)`` points to ``(n,)``
        positive sizes; the mesh follows it (side counts from the integral of 1 / size, side
        vertices spaced by it, size conformity judged against it: ``Quality.field``).
      divisions: instead of ``size``: edge length = the region's perimeter / ``divisions``
        (a whole number >= 1; each region of a batch gets its own size).
      auto_size: add the size field of the part's own features (thin parts, curvature, small
        holes: :mod:`jaxmatch.autosize`) to the size or :class:`~jaxmatch.field.Field` (shapes
        meshed to a size only).
      sides: edges per user side (side ``i`` from corner ``i`` to ``i + 1``, file order), met
        exactly by one template; excludes ``size``.
      counts: layouts only: ``{side id: edges}`` (ids of
        :func:`~jaxmatch.placement.layout.layout_sides`; added to the file's ``"sides"``).
      template: the paper's answer instead: the best-ranked catalogue mesh placed as is
        (``template_options``: ``internal``, ``rank``, ``points``, ``tie_break``,
        ``require_valid``, ``min_quality``, ``max_edge_ratio``, ``band``, ``walk``).
      catalogue, lattice: None / a path / the object (default: shipped catalogue, ``"fine"``).
      strategies: candidate names (default all of :func:`strategy_names`).
      quality: the policy (:class:`jaxmatch.defaults.Quality`).
      search: how much of the candidate search runs: ``"best"`` (every candidate that could win),
        ``"fast"`` (stops earlier, at some cost in quality: docs/perf.md) or a
        :class:`~jaxmatch.defaults.Search`; default ``quality.search`` (the best).
      budget_s: stop trying further candidates after this many seconds once one valid mesh exists.
      progress: ``progress(done, total, name)`` after each candidate.

    Returns:
      a :class:`~jaxmatch.meshing.result.QuadMesh`; ``chosen``, ``rule``, ``runner_up`` and
      ``tried`` say how it was chosen.

    Raises:
      InputError: a bad request (unreadable file, bad size, counts no template meets: the
        message names the nearest feasible counts), or no candidate could be meshed.
    """
    if search is not None:
        quality = replace(quality, search=_search(search))
    if regions is not None:
        if region is not None:
            raise InputError("give region or regions, not both")
        region = (make_model(regions) if all(isinstance(r, Region) for r in regions)
                  else later.models.model_from_json({"regions": list(regions)}, "<regions>", corner_angle))
    if isinstance(region, (str, os.PathLike)):
        region = load_region(region, corner_angle=corner_angle)
    if isinstance(region, Model):
        if sides is not None or counts or template or template_options or auto_size:
            raise InputError("an assembly is meshed at a size (size= or divisions=); sides, counts, template and "
                             "automatic sizing are for one region")
        return later.assembly.mesh_model(region, mesh, size=size, divisions=divisions, catalogue=catalogue, lattice=lattice,
                                         quality=quality, corner_angle=corner_angle, strategies=strategies,
                                         budget_s=budget_s, progress=progress)
    if sides is not None and size is not None:
        raise InputError("give either sides or size, not both")
    if auto_size:
        size, divisions = _auto_size(region, size, divisions, sides, template)
    if size is not None and _is_field(size):
        if not isinstance(region, Shape) or template or divisions is not None:
            raise InputError("a size field is for a shape meshed to a size (not a layout, --template or --divisions)")
        f = bind(size, region, "size field" if isinstance(size, Field) else "size")
        quality = replace(quality, field=f)
        size = outline_size(f, region)
    if divisions is not None:
        if size is not None or sides is not None:
            raise InputError("give divisions or a size or sides, not two of them")
        size = _divisions_size(region, divisions)
    if size is not None:
        size = _check_size(size)
    cat, lat = load_catalogue(catalogue), _lattice(lattice)
    if isinstance(region, Layout):
        if template:
            raise InputError("a layout is meshed patch by patch; the single template (template=True) is for shapes")
        return _mesh_layout_file(region, cat, lat, size, sides, counts, quality)
    if counts:
        raise InputError("edge counts per named side are for layouts; give sides (one count per side) for a shape")
    if not isinstance(region, Shape):
        raise TypeError(f"region must be a Shape, a Layout or a path, got {type(region).__name__}")
    if template:
        if size is not None or sides is not None:
            raise InputError("the single template is placed as is; it takes no size or sides")
        return _mesh_template(region, cat, lat, template_options, progress, quality)
    if template_options:
        raise TypeError(f"unexpected options without template=True: {', '.join(sorted(template_options))}")
    if sides is not None:
        return _mesh_sides(region, cat, lat, sides, quality)
    h = size if size is not None else default_size(region)
    return _mesh_size(region, cat, lat, h, strategies, quality, budget_s, progress, corner_angle)


def _search(search) -> Search:
    """The :class:`~jaxmatch.defaults.Search` named (:data:`~jaxmatch.defaults.SEARCHES`) or given.
    Raises :class:`InputError` for an unknown name."""
    if not isinstance(search, Search):
        if search not in SEARCHES:
            raise InputError(f"expected one of {', '.join(SEARCHES)}, got {search!r}", "search")
        search = SEARCHES[search]
    unknown = [n for n in search.leave_out if n not in PLAN_STRATEGIES]
    if unknown:  # (a name of no plan strategy would leave nothing out, silently)
        raise InputError(f"leave_out names no strategy of the plan: {', '.join(unknown)} (expected among "
                         f"{', '.join(sorted(PLAN_STRATEGIES))})", "search")
    return search


PLAN_STRATEGIES = frozenset(cls.__name__ for cls in (Larger, Conforming, RingPartition, LeanCurves, Transitions, Bends))
"""The strategies a search may leave out of the plan (:attr:`jaxmatch.defaults.Search.leave_out`)."""


def _divisions_size(region, divisions) -> float | None:
    """The size of ``divisions`` edges along ``region``'s perimeter (None for neither a shape
    nor a layout). Raises :class:`InputError` for divisions that are no whole number >= 1."""
    if isinstance(divisions, bool) or not isinstance(divisions, (int, np.integer)) or divisions < 1:
        raise InputError(f"divisions must be a whole number >= 1, got {divisions!r}")
    return default_size(region, int(divisions)) if isinstance(region, (Shape, Layout)) else None


def _auto_size(region, size, divisions, sides, template) -> tuple:
    """``(size, divisions)`` with automatic sizing (:func:`jaxmatch.autosize.auto_field`) added:
    the field of the part's features, on top of the user's size or :class:`~jaxmatch.field.Field`
    (divisions become the size they give); the size unchanged when the part has no feature
    smaller than it. Raises :class:`InputError` where automatic sizing does not apply."""
    if not isinstance(region, Shape) or template or sides is not None:
        raise InputError("automatic sizing (auto_size, --auto-size) is for a shape meshed to a size (not a layout, "
                         "--template or --sides)")
    user = size if isinstance(size, Field) else None
    if size is not None and user is None and _is_field(size):
        raise InputError("automatic sizing adds to a size or a Field, not to a callable size")
    if divisions is not None:
        if size is not None:
            raise InputError("give divisions or a size or sides, not two of them")
        H = _divisions_size(region, divisions)
    else:
        H = user.size if user is not None else _check_size(size) if size is not None else default_size(region)
    field = auto_field(region, H, user)
    return (H if field is None else field), None


def warm_up(catalogue=None, lattice=DEFAULT_LATTICE) -> None:
    """Load what a process's first :func:`mesh` call loads (the catalogue's groupings, the
    compiled kernels, the solvers' modules) by meshing a unit square at 4 edges a side: about a
    tenth of a second, where a first real region can take three times that. For a parent that
    forks workers (``jaxmatch mesh`` of many regions): they inherit it all."""
    mesh(make_shape([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]), divisions=16, catalogue=catalogue,
         lattice=lattice)


def _mesh_layout_file(layout, cat, lat, size, sides, counts, quality) -> QuadMesh:
    if sides is not None:
        raise InputError("a layout takes edge counts per side in its file (\"sides\") or as counts=; not sides")
    h = size if size is not None or layout.requested or counts else default_size(layout)
    lm = mesh_layout(layout, cat, lat, size=h, counts=counts, quality=quality)
    return from_layout(lm, size=h).with_choice("layout", "", None, ())


def _mesh_template(shape, cat, lat, options, progress, quality) -> QuadMesh:
    opts = dict(options)
    if "internal" in opts:
        opts["internal"] = check_sizes(cat, opts["internal"])
    scored = None if progress is None else (lambda done, total: progress(done, total, "template"))
    choice = choose_mesh(shape, cat, lat, progress=scored, quality=quality, **opts)
    m = from_placement(shape, choice.placement, choice.match.mesh_id, detail=choice)
    return _named(m.with_choice("template", "", None, (Candidate("template", m),)), shape)


def _mesh_sides(shape, cat, lat, sides, quality) -> QuadMesh:
    n_sides = max(shape.n_corners, 1)
    counts = _check_counts(sides, n_sides, shape.source)
    if shape.n_corners < 2:
        choice = refine_mesh(shape, cat, lat, sides=counts.tolist(), quality=quality)
        m = from_refined(shape, choice.mesh)
    else:
        lay = single_patch(shape)
        ids = _side_ids(shape, lay)
        try:
            lm = mesh_layout(lay, cat, lat, counts={s: int(c) for s, c in zip(ids, counts)}, quality=quality,
                             sizes=ALL_SIZES)
        except LayoutInfeasible as e:
            names = layout_sides(lay).names
            near = ("; nearest feasible counts " + ",".join(str(e.nearest.get(names[s], "?")) for s in ids)) if e.nearest else ""
            odd = (f"their total {int(counts.sum())} is odd (every quad mesh has an even number of boundary edges); "
                   if counts.sum() % 2 else "")
            raise InfeasibleRequest(f"edge counts {','.join(map(str, counts.tolist()))} cannot be met: {odd}"
                                    f"{e.problem}{near}", shape.source) from None
        m = from_layout(lm, corners=corner_points(shape))
    return _named(m.with_choice(SINGLE, "", None, (Candidate(SINGLE, m),)), shape)


def _mesh_size(shape, cat, lat, h, strategies, quality, budget_s, progress, corner_angle) -> QuadMesh:
    names = tuple(strategies) if strategies is not None else strategy_names()
    unknown = [n for n in names if n not in strategy_names()]
    if unknown:
        raise InputError(f"unknown strategy {unknown[0]!r} (expected {', '.join(strategy_names())})")
    region = canonical(shape, h, corner_angle)
    req = Request(region, cat, lat, h, corner_points(region), quality, budget_s, time.perf_counter(), progress)
    rings = (RingPartition(),) if RINGS in names else ()
    if region.n_corners < 2 and not region.holes:
        plan = (Smooth(),) + rings
    else:
        layouts = Layouts(layout_strategies([n for n in names if n != RINGS]))

        def rejudge():  # the bends of a curved outline as corners too (detected corners only)
            if shape.explicit_corners:
                return None
            finer = canonical(shape, h, corner_angle, held_angle=corner_angle)
            return None if np.array_equal(finer.corners, region.corners) else finer

        search = quality.search
        enough = (Enough(),) if search.enough else ()
        if quality.field is None:
            lean = LeanCurves(layouts.strategies + ((Rings(),) if rings else ()))
            trans = (Transitions(lean.strategies),) if quality.uniform_transitions else ()
            plan = (layouts,) + enough + (Larger(), Conforming()) + rings + (lean,) + trans + (Bends(layouts, rejudge),)
        else:  # graded: the ring partition before the larger templates, tried only if it too misses the field
            trans = Transitions(layouts.strategies + ((Rings(),) if rings else ()))
            plan = (layouts,) + enough + rings + (trans, Larger(), Bends(layouts, rejudge))
        plan = tuple(st for st in plan if type(st).__name__ not in search.leave_out)
    tried = run(plan, req)
    if region.periodic:  # a candidate whose periodic sides got different counts (no equal-count program) is out
        tried = [c if c.mesh is None or not periodic_mismatch(c.mesh, region) else
                 Candidate(c.name, None, periodic_mismatch(c.mesh, region)) for c in tried]
    if not any(c.mesh is not None for c in tried):
        raise InputError("no candidate could be meshed: " + "; ".join(f"{c.name}: {c.note}" for c in tried),
                         where=region.source)
    best = choose(tried, quality)
    return _named(best if quality.field is None else follow_field(best, quality), region)


def _named(m: QuadMesh, region: Shape) -> QuadMesh:
    """``m`` with the groups of the input's numbering (:func:`jaxmatch.meshing.groups.name_groups`)
    and its periodic sides made translates (:func:`~jaxmatch.meshing.groups.make_periodic`).
    Raises :class:`InputError` when a periodic pair's sides got different edge counts."""
    why = periodic_mismatch(m, region)
    if why:
        raise InputError(f"{why}: periodic sides need equal counts (give equal --sides)", where=region.source)
    return make_periodic(name_groups(m, region))
