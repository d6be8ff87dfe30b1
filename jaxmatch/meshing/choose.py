"""The one choice rule: which of several meshes of the same region is better.

:func:`mesh_key` orders candidates (smaller is better) by the rules of :data:`RULES`, in order:

1. no fold: no inverted quad;
2. corners kept: every corner of the region is a mesh vertex;
3. area kept: ``|mesh area / region area - 1| <= Quality.area_tol``;
4. quality floor: min scaled Jacobian ``>= Quality.good_sj``;
5. size conformity: no boundary stretch between corners meshed coarser than the size (edges
   longer than ``Quality.coarse_side * h`` even with one edge more; the outline as the
   user sees it, not the pieces between the patches' cut ends) and no edge longer than
   ``Quality.long_edge * h`` (with a target size). For one size, a yes or no: between two meshes
   that both miss it, quality decides and the counts go to the size fit. A stretch finer than
   ``h`` is not ruled out here: a feature smaller than the size is meshed finer, not cut off.
   With a size field, ``h`` is the field at each edge's midpoint (a stretch's ``length / h`` its
   integral of ``1 / size``), an edge shorter than the field over ``Quality.short_edge`` misses
   it too, and the misses are counted: following the field is what was asked
   (:meth:`QuadMesh.size_conformity`);
6. quality band: min scaled Jacobian ``>= Quality.high_sj``;
7. quality: higher min scaled Jacobian, in steps of ``Quality.sj_step``;
8. size fit: fewer stretches whose edge count is off ``length / h`` by more than
   ``max(1, Quality.size_tol * length / h)`` either way, plus edges longer than
   ``Quality.long_edge * h`` (and, with a size field, the short ones: :meth:`QuadMesh.size_fit`);
9. size band: at least ``Quality.band_share`` of the edges within ``Quality.size_band`` sizes
   (:meth:`QuadMesh.misses_size_band`: the interior too; a yes or no: where every candidate
   misses it, a feature smaller than the size meshed finer, it does not decide);
10. irregular vertices: fewer irregular internal vertices beyond Euler's lower bound for the
   boundary valences used (:func:`jaxmatch.meshing.result.irregular_bound`; none below it counts
   as 0: a valence-6 vertex can make up for two);
11. fewer patches;
12. higher mean scaled Jacobian (2 decimals);
13. the order tried (single template first).

:func:`choose` names the first rule on which the winner beats the runner-up;
:func:`cannot_win` tells, before a candidate is meshed, that it cannot beat a given key (from its
patch count, and an upper bound on its min scaled Jacobian when one is known).

:func:`mesh_key` is the one rule for whole meshes of a region; :func:`best_possible_key` is the
same key for a mesh not made yet. The other orders in the package answer other questions, on
other objects, and say so here so that none of them is mistaken for a second choice rule:

=========================================== ==================================================
key                                         why it is not :func:`mesh_key`
=========================================== ==================================================
``placement.solve._round_key``              one refined *patch* inside a layout's round loop
                                            (inverted quads, then min scaled Jacobian to 3
                                            decimals): which round of one solve to keep, before
                                            the patches are merged into a mesh
``placement.embed._key``                    two *positions* of the same quads during smoothing
                                            (never make the worst quad worse); no corners, area
                                            or size to judge: they are the same
``placement.choose.placement_key``          placements of one catalogue *template* in the shape
                                            (the paper's answer, no size): missed corners, then
                                            quality, then coordinates for a deterministic tie
``placement.choose.geometry_key``           ties of *utility* in the paper's ranking (the
                                            selector, not the mesher): placed quality, then id
``placement.choose.size_key``               the template *size* (internal vertices) of
                                            ``mesh --template``: bands of min scaled Jacobian and
                                            area, then fewer quads (no target size to conform to)
=========================================== ==================================================
"""

from __future__ import annotations

import math
from typing import Sequence

from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.meshing.result import Candidate, QuadMesh

__all__ = ["RULES", "best_possible_key", "cannot_win", "choose", "mesh_key"]

RULES = ("no fold", "corners kept", "area kept", "quality floor", "size conformity", "quality band", "min scaled Jacobian",
         "size fit", "size band", "irregular vertices", "fewer patches", "mean scaled Jacobian", "order tried")
"""The rules of :func:`mesh_key`, in order (the last one: the earlier candidate)."""

def _thresholds(quality: Quality) -> tuple:
    """The numbers of ``quality`` that :func:`mesh_key` reads (what its kept keys are kept by)."""
    return ("mesh_key", quality.area_tol, quality.good_sj, quality.high_sj, quality.sj_step, quality.coarse_side,
            quality.long_edge, quality.short_edge, quality.size_tol, tuple(quality.size_band), quality.band_share)


def mesh_key(m: QuadMesh, order: int = 0, quality: Quality = QUALITY) -> tuple:
    """The sort key of :data:`RULES` for mesh ``m`` (``order``: its place among the candidates).
    All but ``order`` is computed once per mesh and thresholds of ``quality`` (kept in the mesh's
    ``_memo``, as its counts are): a call reads every candidate's key, several times."""
    memo = m._memo
    k = _thresholds(quality)
    if k not in memo:
        memo[k] = _rules_key(m, quality)
    return memo[k] + (order,)


def _rules_key(m: QuadMesh, quality: Quality) -> tuple:
    """:func:`mesh_key` without its last element (the order tried), computed."""
    sj, mean = m.min_scaled_jacobian, m.mean_scaled_jacobian  # of the (Q,) array the mesh keeps
    area = m.area_ratio
    return (
        m.inverted > 0,
        m.missed_corners.shape[0] > 0,
        not (abs(area - 1.0) <= quality.area_tol),
        not (sj >= quality.good_sj),
        m.size_conformity(quality),
        not (sj >= quality.high_sj),
        -math.floor(sj / quality.sj_step + 1e-9) if math.isfinite(sj) else math.inf,
        m.size_fit(quality),
        m.misses_size_band(quality),
        max(int(m.irregular.size) - m.irregular_bound, 0),
        m.n_patches,
        -round(mean, 2),
    )


def best_possible_key(n_patches: int, order: int, max_sj: float = 1.0, quality: Quality = QUALITY) -> tuple:
    """The smallest :func:`mesh_key` any mesh of ``n_patches`` patches tried at ``order`` whose
    min scaled Jacobian is at most ``max_sj`` can have: no fold, every corner, the area, every
    side at the size, min scaled Jacobian ``max_sj``, the size band met, no irregular vertex
    beyond the bound, mean 1."""
    return (False, False, False, not (max_sj >= quality.good_sj), 0, not (max_sj >= quality.high_sj),
            -math.floor(max_sj / quality.sj_step + 1e-9), 0, False, 0, int(n_patches), -1.0, int(order))


def cannot_win(best_key: tuple, n_patches: int, order: int, max_sj: float = 1.0, quality: Quality = QUALITY) -> bool:
    """Whether a candidate of ``n_patches`` patches tried at ``order``, whose min scaled Jacobian
    cannot exceed ``max_sj``, loses to a mesh of key ``best_key`` whatever its mesh (so it need
    not be meshed): ``best_key`` is smaller than :func:`best_possible_key`."""
    return best_key < best_possible_key(n_patches, order, max_sj, quality)


def choose(candidates: Sequence[Candidate], quality: Quality = QUALITY) -> QuadMesh:
    """The best mesh of ``candidates`` by :func:`mesh_key`, labelled with the rule that decided
    (the first rule on which it beats the runner-up), the runner-up's name and every candidate.
    A candidate not meshed because it could not win takes part with its ``bound`` (the best key
    its mesh could have had, its place among ``candidates`` taken as the order tried, as for the
    meshed ones: candidates inserted after the single template keep the others' order): as the
    runner-up, the winner beats it on that rule at the latest. Raises ValueError when no
    candidate has a mesh."""
    scored = [(mesh_key(c.mesh, i, quality), c) for i, c in enumerate(candidates) if c.mesh is not None]
    if not scored:
        raise ValueError("no candidate has a mesh")
    scored += [(tuple(c.bound[:-1]) + (i,), c) for i, c in enumerate(candidates) if c.mesh is None and c.bound is not None]
    scored.sort(key=lambda t: t[0])
    best_key, best = scored[0]
    if best.mesh is None:  # pragma: no cover - a bound is above a key meshed before it
        raise ValueError(f"candidate {best.name} was skipped but could have won")
    if len(scored) == 1:
        return best.mesh.with_choice(best.name, "", None, candidates)
    second_key, second = scored[1]
    rule = next(RULES[i] for i, (a, b) in enumerate(zip(best_key, second_key)) if a != b)
    return best.mesh.with_choice(best.name, rule, second.name, candidates)
