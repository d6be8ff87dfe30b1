"""The one meshing pipeline: request -> strategies -> one solve each -> one choice rule -> one
result type.

:func:`mesh` is the front door (``jaxmatch.mesh``; ``jaxmatch mesh`` calls it):

* a **layout** (a :class:`~jaxmatch.placement.layout.Layout` or a layout JSON file) is meshed as
  that layout;
* a **shape** with a target edge length ``size`` (default: perimeter / :data:`DEFAULT_DIVISIONS`)
  is meshed as one template (``"single"``) and as each decomposition of
  :data:`~jaxmatch.placement.decompose.STRATEGIES`; every candidate is meshed by the same solve
  (:func:`~jaxmatch.placement.layout.mesh_layout`: templates per patch, one integer program for
  every side count, refinement, placement, merging, smoothing) and the best is kept by the one
  rule of :mod:`jaxmatch.meshing.choose`;
* a shape with ``sides`` (edges per side) is meshed as one template meeting them exactly;
* ``template=True`` gives the paper's answer: the best-ranked catalogue mesh placed as is
  (:func:`jaxmatch.placement.choose.choose_mesh`).

Every case returns a :class:`~jaxmatch.meshing.result.QuadMesh`.
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from jaxmatch.defaults import DEFAULT_DIVISIONS, DEFAULT_LATTICE, QUALITY, Quality
from jaxmatch.errors import InputError, SolverError
from jaxmatch.meshing.build import from_layout, from_placement, from_refined
from jaxmatch.meshing.choose import choose
from jaxmatch.meshing.result import Candidate, QuadMesh
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, Shape

__all__ = ["SINGLE", "default_size", "load_region", "mesh", "strategy_names"]

SINGLE = "single"
"""Name of the one-template candidate."""


def strategy_names() -> tuple[str, ...]:
    """Every candidate strategy, in the order tried: ``"single"``, then the decompositions."""
    from jaxmatch.placement.decompose import STRATEGIES

    return (SINGLE,) + tuple(STRATEGIES)


def default_size(region) -> float:
    """Perimeter of the region's outer boundary / :data:`DEFAULT_DIVISIONS` (user units)."""
    if isinstance(region, Shape):
        pts = region.user_points
    else:  # a Layout: its outer sides
        from jaxmatch.placement.layout import layout_sides

        sides = layout_sides(region)
        return float(np.sum(sides.lengths[sides.outer])) / DEFAULT_DIVISIONS
    return float(np.sum(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1))) / DEFAULT_DIVISIONS


def load_region(path: str | os.PathLike, *, corner_angle: float = DEFAULT_CORNER_ANGLE):
    """A shape or a layout from a file: a JSON object with ``"patches"`` is a layout
    (:func:`jaxmatch.placement.layout.parse_layout`), anything else a shape of any format
    jaxmatch reads (``file#element`` chooses an element). Raises :class:`InputError` naming the
    file."""
    from jaxmatch.io.readers import load_shape

    p = Path(path)
    if p.suffix.lower() == ".json" and p.is_file():
        from jaxmatch.files import read_limited
        from jaxmatch.placement.layout import MAX_BYTES, parse_layout

        raw = read_limited(p, MAX_BYTES, "shape file")
        try:
            doc = json.loads(raw.decode("utf-8-sig"))
        except (ValueError, UnicodeDecodeError):
            doc = None
        if isinstance(doc, dict) and "patches" in doc:
            return parse_layout(raw, str(path))
    return load_shape(path, corner_angle=corner_angle)


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
    from jaxmatch.placement.layout import layout_sides
    from jaxmatch.placement.refine import _side_frame

    sides = layout_sides(layout)
    ends = {(int(c[0]), int(c[-1])): s for s, c in enumerate(sides.chains)}
    c = shape.corners
    out = []
    for j, _ in _side_frame(shape):
        a, b = int(c[j]), int(c[(j + 1) % len(c)])
        s = ends.get((a, b), ends.get((b, a)))
        if s is None:  # pragma: no cover - single_patch keeps every corner as a node
            raise ValueError(f"side {a}-{b} is not a layout side")
        out.append(s)
    return out


def mesh(region, *, size: float | None = None, sides: Sequence[int] | None = None,
         counts: Mapping[int, int] | None = None, template: bool = False,
         catalogue=None, lattice=DEFAULT_LATTICE, strategies: Sequence[str] | None = None,
         quality: Quality = QUALITY, corner_angle: float = DEFAULT_CORNER_ANGLE, budget_s: float | None = None,
         progress: Callable[[int, int, str], None] | None = None, template_cache: dict | None = None,
         **template_options) -> QuadMesh:
    """Mesh a region: the one front door.

    Args:
      region: a :class:`~jaxmatch.shape.Shape`, a :class:`~jaxmatch.placement.layout.Layout`,
        or a path (a shape file of any format, or a layout JSON file).
      size: target edge length (user units); default perimeter / :data:`DEFAULT_DIVISIONS`.
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
      budget_s: stop trying further candidates after this many seconds once one valid mesh exists.
      progress: ``progress(done, total, name)`` after each candidate.
      template_cache: dict shared between calls on the same shape (templates per patch).

    Returns:
      a :class:`~jaxmatch.meshing.result.QuadMesh`; ``chosen``, ``rule``, ``runner_up`` and
      ``tried`` say how it was chosen.

    Raises:
      InputError: a bad request (unreadable file, bad size, counts no template meets: the
        message names the nearest feasible counts), or no candidate could be meshed.
    """
    from jaxmatch.inputs import _lattice, load_catalogue
    from jaxmatch.placement.layout import Layout

    if isinstance(region, (str, os.PathLike)):
        region = load_region(region, corner_angle=corner_angle)
    if sides is not None and size is not None:
        raise InputError("give either sides or size, not both")
    if size is not None:
        size = _check_size(size)
    cat, lat = load_catalogue(catalogue), _lattice(lattice)
    if isinstance(region, Layout):
        if template:
            raise InputError("a layout is meshed patch by patch; the single template (template=True) is for shapes")
        return _mesh_layout_file(region, cat, lat, size, sides, counts)
    if counts:
        raise InputError("edge counts per named side are for layouts; give sides (one count per side) for a shape")
    if not isinstance(region, Shape):
        raise TypeError(f"region must be a Shape, a Layout or a path, got {type(region).__name__}")
    if template:
        if size is not None or sides is not None:
            raise InputError("the single template is placed as is; it takes no size or sides")
        return _mesh_template(region, cat, lat, template_options)
    if template_options:
        raise TypeError(f"unexpected options without template=True: {', '.join(sorted(template_options))}")
    if sides is not None:
        return _mesh_sides(region, cat, lat, sides)
    h = size if size is not None else default_size(region)
    return _mesh_size(region, cat, lat, h, strategies, quality, budget_s, progress, template_cache, corner_angle)


def _mesh_layout_file(layout, cat, lat, size, sides, counts) -> QuadMesh:
    from jaxmatch.placement.layout import mesh_layout

    if sides is not None:
        raise InputError("a layout takes edge counts per side in its file (\"sides\") or as counts=; not sides")
    h = size if size is not None or layout.requested or counts else default_size(layout)
    lm = mesh_layout(layout, cat, lat, size=h, counts=counts)
    return from_layout(lm, size=h).with_choice("layout", "", None, ())


def _mesh_template(shape, cat, lat, options) -> QuadMesh:
    from jaxmatch.inputs import check_sizes
    from jaxmatch.placement.choose import choose_mesh

    opts = dict(options)
    if "internal" in opts:
        opts["internal"] = check_sizes(cat, opts["internal"])
    choice = choose_mesh(shape, cat, lat, **opts)
    m = from_placement(shape, choice.placement, choice.match.mesh_id)
    return m.with_choice("template", "", None, (Candidate("template", m),))


def _mesh_sides(shape, cat, lat, sides) -> QuadMesh:
    from jaxmatch.placement.decompose import single_patch
    from jaxmatch.placement.layout import LayoutInfeasible, layout_sides, mesh_layout
    from jaxmatch.placement.refine import InfeasibleRequest, _check_counts, refine_mesh

    n_sides = max(shape.n_corners, 1)
    counts = _check_counts(sides, n_sides, shape.source)
    if shape.n_corners < 2:
        choice = refine_mesh(shape, cat, lat, sides=counts.tolist())
        m = from_refined(shape, choice.mesh)
    else:
        lay = single_patch(shape)
        ids = _side_ids(shape, lay)
        try:
            lm = mesh_layout(lay, cat, lat, counts={s: int(c) for s, c in zip(ids, counts)},
                             sizes=_all_sizes())
        except LayoutInfeasible as e:
            names = layout_sides(lay).names
            near = ("; nearest feasible counts " + ",".join(str(e.nearest.get(names[s], "?")) for s in ids)) if e.nearest else ""
            odd = (f"their total {int(counts.sum())} is odd (every quad mesh has an even number of boundary edges); "
                   if counts.sum() % 2 else "")
            raise InfeasibleRequest(f"edge counts {','.join(map(str, counts.tolist()))} cannot be met: {odd}"
                                    f"{e.problem}{near}", shape.source) from None
        m = from_layout(lm, corners=_corners(shape))
    return m.with_choice(SINGLE, "", None, (Candidate(SINGLE, m),))


def _all_sizes():
    from jaxmatch.placement.layout import ALL_SIZES

    return ALL_SIZES


def _corners(shape: Shape) -> np.ndarray:
    """``(C, 2)`` every corner of the region (outer loop and holes), user coordinates."""
    from jaxmatch.placement.decompose import _corner_points

    return _corner_points(shape)


def _mesh_size(shape, cat, lat, h, strategies, quality, budget_s, progress, template_cache, corner_angle) -> QuadMesh:
    from jaxmatch.placement.decompose import single_patch

    names = tuple(strategies) if strategies is not None else strategy_names()
    unknown = [n for n in names if n not in strategy_names()]
    if unknown:
        raise InputError(f"unknown strategy {unknown[0]!r} (expected {', '.join(strategy_names())})")
    region = canonical(shape, h, corner_angle)
    if region.n_corners < 2 and not region.holes:
        return _mesh_smooth(region, cat, lat, h, quality, template_cache)
    corners = _corners(region)
    cache = template_cache if template_cache is not None else {}
    t0 = time.perf_counter()
    tried = _try_strategies(region, names, cat, lat, h, corners, cache, budget_s, t0, progress)
    if not any(c.mesh is not None for c in tried):
        raise InputError("no candidate could be meshed: " + "; ".join(f"{c.name}: {c.note}" for c in tried),
                         where=region.source)
    best = choose(tried, quality)
    single = next((c.mesh for c in tried if c.name == SINGLE and c.mesh is not None), None)
    if single is not None and not best.min_scaled_jacobian >= quality.good_sj:  # below the floor: larger templates
        more = _larger_templates(single_patch(region), cat, lat, h, corners, single, cache)
        if more:
            tried = tried[:1] + more + tried[1:]
            best = choose(tried, quality)
    if single is not None and best.sides_off_size(quality.size_tol):  # no candidate follows the size yet
        more = _conforming_templates(region, cat, lat, h, single, quality)
        if more:
            tried = tried[:1] + more + tried[1:]
            best = choose(tried, quality)
    if not best.valid and not shape.explicit_corners:  # every candidate folds: the bends become corners too
        finer = canonical(shape, h, corner_angle, held_angle=corner_angle)
        if not np.array_equal(finer.corners, region.corners):
            more = _try_strategies(finer, names, cat, lat, h, _corners(finer), cache, budget_s, t0, progress,
                                   suffix=FINER)
            if any(c.mesh is not None for c in more):
                best = choose(tried + more, quality)
    return best


FINER = " +bends"
"""Suffix of the candidates meshed with the bends of a curved outline as corners too (when every
other candidate folds; :data:`jaxmatch.shape.HELD_ANGLE`)."""


def _try_strategies(shape: Shape, names, cat, lat, h: float, corners: np.ndarray, cache: dict, budget_s, t0: float,
                    progress, suffix: str = "") -> list[Candidate]:
    """Each strategy of ``names`` meshed (one :class:`Candidate` each, with its mesh or the reason
    it has none): the same solve for every one (:func:`~jaxmatch.placement.layout.mesh_layout`).
    A strategy whose cuts or solve fail for any reason is skipped with that reason."""
    from jaxmatch.placement.decompose import _same, decompose, single_patch
    from jaxmatch.placement.layout import ALL_SIZES, TEMPLATE_SIZES, mesh_layout

    tried: list[Candidate] = []
    seen = []
    for i, name in enumerate(names):
        label = name + suffix
        if budget_s is not None and time.perf_counter() - t0 > budget_s and any(
                c.mesh is not None and c.mesh.valid for c in tried):
            tried.append(Candidate(label, None, f"not tried: time budget of {budget_s:g} s spent"))
            continue
        try:
            lay = single_patch(shape) if name == SINGLE else decompose(shape, name)
            if any(_same(lay, other) for other in seen):
                tried.append(Candidate(label, None, "same patches as an earlier candidate"))
                continue
            seen.append(lay)
            lm = mesh_layout(lay, cat, lat, size=h, smooth_cuts=lay.n_patches > 1,
                             sizes=ALL_SIZES if name == SINGLE else TEMPLATE_SIZES, template_cache=cache)
        except InputError as e:
            tried.append(Candidate(label, None, e.problem))
        except SolverError as e:  # not a verdict on the request: the other candidates go on
            tried.append(Candidate(label, None, f"solver error: {e}"))
        except (ValueError, ArithmeticError, IndexError) as e:  # degenerate cuts (near-duplicate points, slivers)
            tried.append(Candidate(label, None, f"skipped: {type(e).__name__}: {e}"))
        else:
            tried.append(Candidate(label, from_layout(lm, size=h, corners=corners)))
        if progress is not None:
            progress(i + 1, len(names), label)
    return tried


def _larger_templates(lay, cat, lat, h, corners, first: QuadMesh, cache) -> list[Candidate]:
    """Single-patch candidates from the larger template sizes: the best template of each size
    group of :data:`~jaxmatch.placement.layout.ALL_SIZES` after the first (the single candidate
    takes the first group that has one), named ``"single <template id>"``."""
    from jaxmatch.placement.layout import ALL_SIZES, mesh_layout

    out, seen = [], {first.templates}
    for group in ALL_SIZES[1:]:
        try:
            lm = mesh_layout(lay, cat, lat, size=h, sizes=(group,), template_cache=cache)
        except (InputError, SolverError, IndexError):
            continue
        m = from_layout(lm, size=h, corners=corners)
        if m.templates not in seen:
            seen.add(m.templates)
            out.append(Candidate(f"{SINGLE} {m.templates[0]}", m))
    return out


DISK = "disk"
"""Name of the central-block candidate of a region with fewer than two corners."""


def _mesh_smooth(shape: Shape, cat, lat, h: float, quality: Quality, cache) -> QuadMesh:
    """A region with fewer than two corners (a disk, an ellipse, a teardrop): one template
    refined to the size (``"single"``), and a central block with four patches around it
    (``"disk"``, :func:`jaxmatch.placement.decompose.disk_layout`); the better by the rule."""
    from jaxmatch.placement.decompose import disk_layout
    from jaxmatch.placement.layout import mesh_layout
    from jaxmatch.placement.refine import refine_mesh

    corners = _corners(shape)
    tried = []
    try:
        tried.append(Candidate(SINGLE, from_refined(shape, refine_mesh(shape, cat, lat, size=h).mesh, size=h)))
    except (InputError, SolverError) as e:
        tried.append(Candidate(SINGLE, None, str(getattr(e, "problem", e))))
    try:
        lm = mesh_layout(disk_layout(shape), cat, lat, size=h, smooth_cuts=True, template_cache=cache)
        tried.append(Candidate(DISK, from_layout(lm, size=h, corners=corners)))
    except (InputError, SolverError) as e:
        tried.append(Candidate(DISK, None, str(getattr(e, "problem", e))))
    if not any(c.mesh is not None for c in tried):
        raise InputError("no candidate could be meshed: " + "; ".join(f"{c.name}: {c.note}" for c in tried),
                         where=shape.source)
    return choose(tried, quality)


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


def _conforming_templates(shape: Shape, cat, lat, h, first: QuadMesh, quality: Quality) -> list[Candidate]:
    """A single-template candidate whose side counts follow ``h``: the nearest even counts
    (:func:`_target_counts`), each met exactly by the best template of the catalogue that can
    (:func:`jaxmatch.placement.refine.refine_mesh`), named ``"single <template id>"``."""
    from jaxmatch.errors import UnmatchableError
    from jaxmatch.placement.refine import DEFAULT_LIMIT, InfeasibleRequest, patch_templates, refine_mesh, side_lengths

    try:
        templates = patch_templates(shape, cat, lat, limit=DEFAULT_LIMIT)
    except UnmatchableError:
        return []
    out, seen = [], {first.templates}
    for counts in _target_counts(side_lengths(shape), h, CONFORMING_TRIES):
        try:
            choice = refine_mesh(shape, cat, lat, sides=counts.tolist(), templates=templates)
        except (InfeasibleRequest, SolverError):
            continue
        m = from_refined(shape, choice.mesh, size=h)
        if m.templates not in seen and not m.sides_off_size(quality.size_tol):
            seen.add(m.templates)
            out.append(Candidate(f"{SINGLE} {m.templates[0]}", m))
    return out


DEDUPE = 1e-8
"""Points of a loop closer than this fraction of its extent to the previous one are merged
before meshing (a corner among them stays, at the first point): layouts need distinct points."""


def _dedupe(ring: np.ndarray, corners: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """``ring (P, 2)`` without points within ``tol`` of the previous kept point, and ``corners``
    (indices) mapped onto the kept points."""
    keep = [0]
    owner = np.zeros(len(ring), np.int64)
    for i in range(1, len(ring)):
        if np.linalg.norm(ring[i] - ring[keep[-1]]) > tol:
            keep.append(i)
        owner[i] = len(keep) - 1
    if len(keep) > 1 and np.linalg.norm(ring[keep[-1]] - ring[0]) <= tol:  # the last one wraps onto the first
        owner[owner == len(keep) - 1] = 0
        keep.pop()
    if len(keep) == len(ring):
        return ring, np.asarray(corners, np.int64)
    return ring[keep], np.unique(owner[np.asarray(corners, np.int64)])


def canonical(shape: Shape, size: float | None = None, corner_angle: float = DEFAULT_CORNER_ANGLE,
              held_angle: float | None = None) -> Shape:
    """The same shape with its loops written one way: the outer loop counter-clockwise and each
    hole clockwise from its lexicographically smallest point (x, then y), holes in the order of
    those points, points closer than :data:`DEDUPE` of the extent merged. Corners detected from
    angles are judged again at ``size`` when it is given
    (:func:`jaxmatch.shape.scale_corners`: wiggles shorter than about ``size`` are no corners);
    explicit corners are kept. Meshing the canonical shape makes the mesh
    independent of where the user's loop starts and which way it runs."""
    from jaxmatch.placement.decompose import _xy
    from jaxmatch.shape import make_shape

    def first(ring: np.ndarray) -> int:
        return int(np.lexsort((ring[:, 1], ring[:, 0]))[0])

    from jaxmatch.shape import scale_corners

    rejudge = size is not None and not shape.explicit_corners

    def corners_of(ring: np.ndarray, given) -> np.ndarray:
        if not rejudge:
            return np.asarray(given, np.int64)
        return scale_corners(ring, size, corner_angle, held_angle=held_angle)

    pts = _xy(shape)
    tol = DEDUPE * float(np.ptp(pts, axis=0).max())
    holes, hole_corners = [], []
    for ring, hc in sorted(zip(shape.holes, shape.hole_corners), key=lambda rc: tuple(rc[0][first(rc[0])])):
        ring, hc = _dedupe(ring, corners_of(ring, hc), tol)
        k = first(ring)
        holes.append(np.roll(ring, -k, axis=0))
        hole_corners.append(sorted(int(c) for c in (hc - k) % len(ring)))
    pts2, outer = _dedupe(pts, corners_of(pts, shape.corners), tol)
    start = first(pts2)
    if start == 0 and shape.corner_order is None and not holes and len(pts2) == len(pts) \
            and np.array_equal(outer, shape.corners):
        return shape
    pts = pts2
    corners = sorted(int(c) for c in (outer - start) % len(pts))
    return make_shape(np.roll(pts, -start, axis=0), corners=corners, source=shape.source, holes=holes or None,
                      hole_corners=hole_corners or None)
