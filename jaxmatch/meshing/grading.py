"""Moving a mesh's inner vertices towards the size field (the last step of a graded mesh).

The smoother of the solve (:func:`jaxmatch.placement.embed.smooth`) minimises the quads' corner
condition numbers: it is blind to size, so it keeps the grading the side counts and the side
vertices give only where the topology forces it. :func:`follow_field` then treats every edge as
a spring whose rest length is the field at its midpoint and relaxes the inner vertices (the
outline's vertices, spaced by the field already, stay), a step at a time, each vertex's step
taken only where no quad around it falls below the quality it must keep; the relaxed mesh is
kept when more of its edges are within the field's band (:attr:`QuadMesh.field_share`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from jaxmatch.catalogue.mesh import edges as mesh_edges
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.meshing.result import QuadMesh
from jaxmatch.quality import sj_inverted

__all__ = ["FOLLOW_ITERS", "FOLLOW_STEP", "REVERTS", "SETTLED", "follow_field"]

FOLLOW_ITERS = 60
"""Relaxation steps of :func:`follow_field`."""

SETTLED = 1e-3
"""The relaxation stops when no vertex moves by more than this fraction of the field there."""

REVERTS = 8
"""Rounds of putting back the vertices of quads a step took below their floor."""

FOLLOW_STEP = 0.3
"""Fraction of the mean spring force a vertex moves by in one step."""


def _quad_floor(sj0: np.ndarray, quality: Quality) -> np.ndarray:
    """Per quad, the scaled Jacobian it must keep: its own, or the mesh's worst if higher than the
    quality band (``Quality.high_sj``), else the band, whichever is lower: the mesh's min scaled
    Jacobian never drops, nor does a quad fall out of the quality band."""
    return np.minimum(sj0, max(float(sj0.min()), quality.high_sj))


def follow_field(m: QuadMesh, quality: Quality = QUALITY, iters: int = FOLLOW_ITERS, step: float = FOLLOW_STEP) -> QuadMesh:
    """``m`` with its inner vertices relaxed towards edges as long as the field along them
    (``m.field``, the mean of its values at the edge's ends; ``m`` itself without one). Each step
    moves every inner vertex by ``step`` times the mean over its edges of ``(L - f) / L * (other
    end - it)``, until none moves by more than :data:`SETTLED` of the field there; a vertex whose
    move would fold a quad around it or take one below its floor (:func:`_quad_floor`: the
    quality band is kept where it was reached) stays. The outline's vertices do not move, so
    corners, sides and area along them are kept. Returns a new :class:`QuadMesh` (its choice
    fields kept)."""
    if m.field is None or not m.quads.size:
        return m
    xy = np.array(m.xy, np.float64)
    quads = np.asarray(m.quads, np.int64)
    e = mesh_edges(quads)
    boundary = np.zeros(xy.shape[0], bool)
    for loop in m._loops:
        boundary[np.asarray(loop, np.int64)] = True
    free = ~boundary
    if not free.any():
        return m
    sj0, _ = sj_inverted(xy, quads)
    floor = _quad_floor(sj0, quality)
    deg = np.bincount(e.ravel(), minlength=xy.shape[0]).astype(np.float64)
    fv = np.asarray(m.field(xy), np.float64)  # at the vertices: an edge's rest length is its ends' mean
    for it in range(int(iters)):
        a, b = xy[e[:, 0]], xy[e[:, 1]]
        d = b - a
        L = np.linalg.norm(d, axis=1)
        if it:  # (only the inner vertices move: the field is evaluated again there only)
            fv[free] = np.asarray(m.field(xy[free]), np.float64)
        t = 0.5 * (fv[e[:, 0]] + fv[e[:, 1]])
        pull = ((L - t) / np.maximum(L, 1e-300))[:, None] * d  # moves a towards b when too long
        force = np.zeros_like(xy)
        np.add.at(force, e[:, 0], pull)
        np.add.at(force, e[:, 1], -pull)
        move = np.where(free[:, None], step * force / np.maximum(deg, 1.0)[:, None], 0.0)
        if not np.any(np.linalg.norm(move, axis=1) > SETTLED * fv):
            break
        trial = xy + move
        for _ in range(REVERTS):  # the vertices of a quad below its floor stay where they were
            sj, inv = sj_inverted(trial, quads)
            bad_q = (sj < floor) | inv
            if not bad_q.any():
                break
            trial[quads[bad_q].ravel()] = xy[quads[bad_q].ravel()]
        else:
            break  # (the reverts keep undoing each other: no step taken)
        xy = trial
    out = replace(m, xy=xy)
    return out if out.field_share >= m.field_share else m
