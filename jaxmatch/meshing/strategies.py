"""The candidates of the pipeline (step 2): each strategy's layout meshed by the one solve, and
the extra single-template candidates asked for when none of them is good enough (larger
templates below the quality floor, templates whose side counts follow the size, the central
block of a region without corners, the bends of a curved outline as corners)."""

from __future__ import annotations

import time

import numpy as np

from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.errors import InputError, SolverError
from jaxmatch.meshing.build import from_layout, from_refined
from jaxmatch.meshing.choose import best_possible_key, cannot_win, choose, mesh_key
from jaxmatch.meshing.region import corner_points
from jaxmatch.meshing.result import Candidate, QuadMesh
from jaxmatch.shape import Shape

__all__ = ["CONFORMING_TRIES", "DISK", "FINER", "SINGLE", "conforming_templates", "larger_templates", "mesh_smooth",
           "try_strategies"]

SINGLE = "single"
"""Name of the one-template candidate."""


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


def try_strategies(shape: Shape, names, cat, lat, h: float, corners: np.ndarray, cache: dict, budget_s, t0: float,
                    progress, suffix: str = "", quality: Quality = QUALITY) -> list[Candidate]:
    """Each strategy of ``names`` (one :class:`Candidate` each, in the order of ``names``, with its
    mesh or the reason it has none): every strategy's layout is cut first, then meshed by the same
    solve (:func:`~jaxmatch.placement.layout.mesh_layout`), the most promising first: by the best
    key its mesh could have (:func:`~jaxmatch.meshing.choose.best_possible_key`: the quality its
    bound allows, then fewest patches; the single patch of a region with a concave corner last).
    A layout that cannot beat the best mesh so far whatever its mesh
    (:func:`~jaxmatch.meshing.choose.cannot_win`: by its patch count and an upper bound on its min
    scaled Jacobian: :func:`~jaxmatch.placement.layout.node_sj_bound` from the angles its nodes
    split, and for the single patch :func:`~jaxmatch.placement.layout.single_sj_bound` from its
    template sizes) is not meshed, so the choice is the one meshing all of them would give. A
    strategy whose cuts or solve fail for any reason is skipped with that reason."""
    from jaxmatch.placement.decompose import _same, decompose, same_cuts, single_patch
    from jaxmatch.placement.layout import (ALL_SIZES, TEMPLATE_SIZES, check_layout, mesh_layout, node_sj_bound,
                                           single_sj_bound)

    tried: list[Candidate | None] = [None] * len(names)
    layouts: list[tuple[int, object]] = []
    made: dict = {}  # layouts by the strategy that gives them (same_cuts): each cut once
    for i, name in enumerate(names):
        try:
            how = None if name == SINGLE else same_cuts(shape, name)
            if how not in made:  # the first strategy of its kind names the layout (its messages' source)
                made[how] = single_patch(shape) if name == SINGLE else decompose(shape, name, check=False)
            lay = made[how]
        except FAILED as e:
            tried[i] = Candidate(name + suffix, None, _why_not(e))
            continue
        if any(_same(lay, other) for _, other in layouts):
            tried[i] = Candidate(name + suffix, None, "same patches as an earlier candidate")
            continue
        layouts.append((i, lay))
    best: tuple | None = None
    concave = bool(np.any(~np.asarray(shape.convex, bool)))
    late = {i for i, _ in layouts if names[i] == SINGLE and concave}  # after the cuts: a grid they make may rule it out
    caps = {}
    for i, lay in layouts:
        try:
            caps[i] = node_sj_bound(lay)
        except FAILED:  # (a layout its checks refuse: the solve below says why)
            caps[i] = 1.0
    order = sorted(layouts, key=lambda il: (il[0] in late, best_possible_key(il[1].n_patches, il[0], caps[il[0]], quality)))
    for done, (i, lay) in enumerate(order, start=1):
        label = names[i] + suffix
        sizes = ALL_SIZES if names[i] == SINGLE else TEMPLATE_SIZES
        bound, why = caps[i], "a node splits its angle"
        if best is not None and names[i] == SINGLE and not cannot_win(best[0], 1, i, bound, quality):
            try:  # (one patch: only a cap on its quality can rule it out)
                grid = single_sj_bound(lay, cat, lat, sizes=sizes, template_cache=cache)
            except FAILED:  # no templates: the solve below says why
                grid = 1.0
            if grid < bound:
                bound, why = grid, "no template of its sizes refines into a grid"
        if best is not None and cannot_win(best[0], lay.n_patches, i, bound, quality):
            tried[i] = Candidate(label, None, f"min scaled Jacobian at most {bound:.2f} cannot beat {best[1]}; {why}"
                                 if not cannot_win(best[0], lay.n_patches, i, 1.0, quality) else
                                 f"{lay.n_patches} patches cannot beat {best[1]}",
                                 best_possible_key(lay.n_patches, i, bound, quality))
        elif budget_s is not None and time.perf_counter() - t0 > budget_s and best is not None and best[2]:
            tried[i] = Candidate(label, None, f"not tried: time budget of {budget_s:g} s spent")
        else:
            try:
                check_layout(lay)  # (the cuts' layouts are checked only when meshed)
                lm = mesh_layout(lay, cat, lat, size=h, smooth_cuts=lay.n_patches > 1, sizes=sizes, template_cache=cache)
            except FAILED as e:
                tried[i] = Candidate(label, None, _why_not(e))
            else:
                m = from_layout(lm, size=h, corners=corners)
                tried[i] = Candidate(label, m)
                key = mesh_key(m, i, quality)
                if best is None or key < best[0]:
                    best = (key, label, m.valid)
        if progress is not None:
            progress(done, len(layouts), label)
    return list(tried)


def larger_templates(lay, cat, lat, h, corners, first: QuadMesh, cache) -> list[Candidate]:
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


def mesh_smooth(shape: Shape, cat, lat, h: float, quality: Quality, cache) -> QuadMesh:
    """A region with fewer than two corners (a disk, an ellipse, a teardrop): one template
    refined to the size (``"single"``), and a central block with four patches around it
    (``"disk"``, :func:`jaxmatch.placement.decompose.disk_layout`); the better by the rule."""
    from jaxmatch.placement.decompose import disk_layout
    from jaxmatch.placement.layout import mesh_layout
    from jaxmatch.placement.refine import refine_mesh

    corners = corner_points(shape)
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


def conforming_templates(shape: Shape, cat, lat, h, first: QuadMesh, quality: Quality) -> list[Candidate]:
    """A single-template candidate whose side counts follow ``h``: the nearest even counts
    (:func:`_target_counts`), each met exactly by the best template of the catalogue that can
    (:func:`jaxmatch.placement.refine.refine_mesh`), named ``"single <template id>"``."""
    from jaxmatch.errors import UnmatchableError
    from jaxmatch.placement.refine import (DEFAULT_LIMIT, InfeasibleRequest, lazy_patch_templates, refine_mesh,
                                           side_lengths)

    templates = lazy_patch_templates(shape, cat, lat, limit=DEFAULT_LIMIT, by_size=False)  # placed as far as used
    try:
        if not templates:
            return []
    except UnmatchableError:
        return []
    out, seen = [], {first.templates}
    for counts in _target_counts(side_lengths(shape), h, CONFORMING_TRIES):
        try:
            choice = refine_mesh(shape, cat, lat, sides=counts.tolist(), templates=templates, explain=False)
        except (InfeasibleRequest, SolverError):
            continue
        m = from_refined(shape, choice.mesh, size=h)
        if m.templates not in seen and not m.sides_off_size(quality.size_tol):
            seen.add(m.templates)
            out.append(Candidate(f"{SINGLE} {m.templates[0]}", m))
    return out


