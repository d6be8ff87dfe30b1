"""Quality measures of a planar quad mesh, from its vertex positions and quads alone (numpy
only): signed areas, the Verdict scaled Jacobian, interior angles, inverted quads, edge ratios.

The one set of measures every result is judged by: :class:`jaxmatch.meshing.result.QuadMesh`,
the placement (:mod:`jaxmatch.placement.embed`), the layouts and refinements, the pictures
(:mod:`jaxmatch.io.plot`). It imports nothing of the package above :mod:`jaxmatch.catalogue.mesh`,
so any layer may use it.

Arrays: ``xy (V, 2) float64`` positions (any unit), ``quads (F, 4)`` vertex ids, counter-clockwise.
"""

from __future__ import annotations

import numpy as np

from jaxmatch.catalogue.mesh import QUAD_NEXT as _NEXT
from jaxmatch.lazy import Later

__all__ = ["corner_vectors", "edge_ratios", "inverted_mask", "placement_measures", "quad_areas", "quality",
           "quality_inverted", "sj_inverted"]

_later = Later(kernels="jaxmatch.kernels.placement")
"""The compiled kernels, on the first :func:`sj_inverted`: where the C library is absent they
are numba's (~0.5 s to load), which a process that only reads or writes meshes does not need."""


def quad_areas(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Signed (shoelace) areas of the quads, ``(F,)``; positive for ccw quads."""
    p = np.asarray(xy, dtype=np.float64)[np.asarray(quads)]
    q = p[:, _NEXT]
    return 0.5 * np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0], axis=1)


_PREV = np.array([3, 0, 1, 2])
_TINY = np.finfo(np.float64).tiny


def corner_vectors(xy: np.ndarray, quads: np.ndarray):
    """Corner edge vectors ``e1`` (to next vertex), ``e2`` (to previous), (F, 4, 2) each,
    and corner signed areas ``e1 x e2`` (F, 4)."""
    p = np.asarray(xy, dtype=np.float64)[np.asarray(quads)]
    e1 = p[:, _NEXT] - p  # = np.roll(p, -1, axis=1) - p, without roll's overhead (same values)
    e2 = p[:, _PREV] - p
    cross = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
    return e1, e2, cross


def quality(xy: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-quad shape quality.

    xy: (V, 2) positions; quads: (F, 4) vertex ids, ccw.
    Returns ``(scaled_jacobian, min_angle, max_angle)``, each ``(F,) float64``:

    * scaled Jacobian (Verdict): min over the four corners of ``(e1 x e2) / (|e1| |e2|)``,
      ``e1``/``e2`` the edges leaving the corner to the next/previous vertex; in ``[-1, 1]``,
      1 for a square (or any rectangle), 0 when an edge has zero length;
    * min/max interior angle in degrees: the ccw angle from ``e1`` to ``e2`` in ``[0, 360)``,
      so a reflex (non-convex) corner reads above 180 and an inverted quad has angles
      above 180; a corner with a zero-length edge reads 0.
    """
    return quality_inverted(xy, quads)[:3]


def quality_inverted(xy: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(scaled_jacobian, min_angle, max_angle, inverted)``: :func:`quality`'s three ``(F,)
    float64`` arrays and :func:`inverted_mask`'s ``(F,) bool``, the same values from one set of
    corner vectors (a placement needs all four). xy: (V, 2) positions; quads: (F, 4) vertex ids, ccw."""
    q = np.asarray(quads)
    if q.size == 0:
        z = np.zeros(0)
        return z, z.copy(), z.copy(), np.zeros(0, bool)
    e1, e2, cross = corner_vectors(xy, q)
    dot = np.sum(e1 * e2, axis=-1)
    ang = np.degrees(np.mod(np.arctan2(cross, dot), 2 * np.pi))
    return _scaled_jacobian(e1, e2, cross), ang.min(axis=1), ang.max(axis=1), (cross <= 0).any(axis=1)


def placement_measures(xy: np.ndarray, quads: np.ndarray):
    """``(scaled_jacobian, min_angle, max_angle, inverted, edge_ratio)``: :func:`quality_inverted`'s
    four arrays and :func:`edge_ratios`, the same values from one set of corner vectors and one
    set of edge lengths (a placement records all five; an edge's length is that of the edge
    leaving its first corner, ``e2`` of a corner being ``-e1`` of the previous one).
    xy: (V, 2) positions; quads: (F, 4) vertex ids, ccw."""
    q = np.asarray(quads)
    if q.size == 0:
        return (*quality_inverted(xy, q), np.zeros(0))
    e1, e2, cross = corner_vectors(xy, q)
    dot = np.add.reduce(e1 * e2, axis=-1)  # (np.sum's reduction)
    ang = np.degrees(np.mod(np.arctan2(cross, dot), 2 * np.pi))
    l1 = np.sqrt(np.add.reduce(e1 * e1, axis=-1))  # (F, 4) edge lengths (np.linalg.norm's operations)
    ln = l1 * l1[:, _PREV]
    sj = _scaled_jacobian(e1, e2, cross, ln)
    return sj, ang.min(axis=1), ang.max(axis=1), (cross <= 0).any(axis=1), _longest_over_shortest(l1)


def _scaled_jacobian(e1: np.ndarray, e2: np.ndarray, cross: np.ndarray, ln: np.ndarray | None = None) -> np.ndarray:
    """``(F,) float64`` scaled Jacobian from the corner vectors of :func:`corner_vectors` (the one
    formula of :func:`quality` and :func:`sj_inverted`); ``ln``: ``|e1| |e2|`` when the caller has it."""
    if ln is None:
        ln = np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1)
    ok = ln > _TINY
    sj_c = np.where(ok, cross / np.where(ok, ln, 1.0), 0.0)
    return np.minimum(np.maximum(sj_c.min(axis=1), -1.0), 1.0)  # (np.clip's values, without its overhead)


def sj_inverted(xy: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(scaled_jacobian (F,) float64, inverted (F,) bool)``: :func:`quality`'s first array and
    :func:`inverted_mask`, the same values from one pass over the corners (no angles), for
    callers that need both of a large mesh.

    xy: (V, 2) positions; quads: (F, 4) vertex ids, ccw."""
    q = np.asarray(quads)
    if q.size == 0:
        return np.zeros(0), np.zeros(0, bool)
    kernels = _later.kernels
    if kernels.BACKEND == "c" and q.ndim == 2 and q.shape[1] == 4 and q.min() >= 0 and q.max() < len(xy) \
            and np.ndim(xy) == 2 and np.shape(xy)[1] == 2:  # the same operations in C, one pass
        return kernels.sj_inverted(xy, q)  # (100,000 quads: ~40 ms in numpy); numpy's errors for bad ids below
    e1, e2, cross = corner_vectors(xy, q)
    return _scaled_jacobian(e1, e2, cross), (cross <= 0).any(axis=1)


def inverted_mask(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """``(F,) bool``: quads with any corner of signed area ``e1 x e2 <= 0``."""
    q = np.asarray(quads)
    if q.size == 0:
        return np.zeros(0, bool)
    return (corner_vectors(xy, q)[2] <= 0).any(axis=1)


def edge_ratios(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """``(F,) float64``: longest over shortest of each quad's four edges (1 for a square or
    rhombus; ``inf`` when an edge has zero length). Scale-free; a min scaled Jacobian near 1
    says nothing about it (a 1 x 13 rectangle has scaled Jacobian 1 and edge ratio 13)."""
    q = np.asarray(quads)
    if q.size == 0:
        return np.zeros(0)
    p = np.asarray(xy, dtype=np.float64)[q]
    return _longest_over_shortest(np.linalg.norm(p[:, _NEXT] - p, axis=-1))


def _longest_over_shortest(lengths: np.ndarray) -> np.ndarray:
    """``(F,) float64`` each row's longest over shortest of ``lengths (F, 4)`` (``inf`` when one is 0)."""
    lo, hi = lengths.min(axis=1), lengths.max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lo > 0, hi / np.where(lo > 0, lo, 1.0), np.inf)
