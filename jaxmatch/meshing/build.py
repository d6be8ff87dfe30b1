"""Each strategy's own mesh object turned into the one :class:`~jaxmatch.meshing.result.QuadMesh`.

``from_layout`` takes a :class:`~jaxmatch.placement.layout.LayoutMesh` (a single patch, a
decomposition or a layout file), ``from_placement`` a placed catalogue template
(:class:`~jaxmatch.placement.embed.Placement`, the paper's answer), ``from_refined`` a refined
template of a shape without two corners (:class:`~jaxmatch.placement.refine.RefinedMesh`).
"""

from __future__ import annotations

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.meshing.result import QuadMesh
from jaxmatch.placement.refine import side_lengths
from jaxmatch.shape import Shape

__all__ = ["from_layout", "from_placement", "from_refined"]


def _loop_edges(loop: np.ndarray) -> np.ndarray:
    loop = np.asarray(loop, np.int64)
    return np.stack([loop, roll(loop, -1)], axis=1)


def _path_edges(ids: np.ndarray) -> np.ndarray:
    """``(k - 1, 2)`` the edges of the vertex path ``ids (k,)``, in its dtype (what
    ``np.stack([ids[:-1], ids[1:]], axis=1)`` gives, without its general machinery: a layout
    mesh has a side list per side)."""
    out = np.empty((max(len(ids) - 1, 0), 2), ids.dtype)
    out[:, 0] = ids[:-1]
    out[:, 1] = ids[1:]
    return out


def _shape_corners(shape: Shape) -> np.ndarray:
    return shape.to_user(shape.points[shape.corners]) if shape.n_corners else np.zeros((0, 2))


def from_layout(lm, *, size: float | None = None, corners: np.ndarray | None = None, field=None) -> QuadMesh:
    """A :class:`~jaxmatch.placement.layout.LayoutMesh` as a :class:`QuadMesh`.

    corners: ``(C, 2)`` the region's corners (default: the layout points marked as corners on
    the outer boundary); field: the size field it follows (:attr:`QuadMesh.field`). Side lengths and counts are kept for the sides on the region's boundary
    (the sizes of cuts between patches are the pipeline's own choice, not the user's)."""
    lay = lm.layout
    if corners is None:
        outer_pts = np.unique(np.concatenate([lm.sides.chains[s] for s in np.flatnonzero(lm.sides.outer)]))
        corners = lay.points[outer_pts[lay.corner[outer_pts]]]
    line_sets = {"boundary": _loop_edges(lm.outer)}
    for h, loop in enumerate(getattr(lm, "holes", ()), start=1):
        line_sets[f"hole {h}"] = _loop_edges(loop)
    names, outer = lm.sides.names, lm.sides.outer
    for name, ids, o in zip(lm.sides.names, lm.side_vertices, outer):  # cuts between patches: "cut i-j"
        line_sets[f"{'side' if o else 'cut'} {name}"] = _path_edges(np.asarray(ids))
    return QuadMesh(xy=lm.xy, quads=np.asarray(lm.quads, np.int64), patch=np.asarray(lm.patch, np.int64),
                    line_sets=line_sets, region_area=float(lm.region_area), corners=np.asarray(corners, np.float64),
                    size=size, side_lengths={n: float(v) for n, v, o in zip(names, lm.sides.lengths, outer) if o},
                    side_counts={n: int(c) for n, c, o in zip(names, lm.counts, outer) if o}, templates=tuple(lm.templates),
                    field=field)


def from_placement(shape: Shape | None, pl, mesh_id: str = "", *, detail=None) -> QuadMesh:
    """A placed catalogue template (:class:`~jaxmatch.placement.embed.Placement`) of ``shape``
    (None: a placement without a shape, no corners); ``detail``: how it was chosen
    (:attr:`QuadMesh.detail`)."""
    quads = np.asarray(pl.mesh.quads, np.int64)
    return QuadMesh(xy=np.asarray(pl.xy, np.float64), quads=quads, patch=np.zeros(len(quads), np.int64),
                    line_sets={"boundary": _loop_edges(pl.mesh.boundary)}, region_area=float(pl.region_area),
                    corners=np.zeros((0, 2)) if shape is None else _shape_corners(shape),
                    templates=(mesh_id,) if mesh_id else (), detail=detail)


def from_refined(shape: Shape, rm, *, size: float | None = None, field=None) -> QuadMesh:
    """A refined template (:class:`~jaxmatch.placement.refine.RefinedMesh`) of ``shape``."""

    quads = np.asarray(rm.quads, np.int64)
    lengths = side_lengths(shape)
    names = [f"{i}" for i in range(len(lengths))]
    line_sets = {"boundary": _loop_edges(rm.boundary)}
    for name, ids in zip(names, rm.side_vertices):
        ids = np.asarray(ids, np.int64)
        line_sets[f"side {name}"] = np.stack([ids[:-1], ids[1:]], axis=1)
    return QuadMesh(xy=np.asarray(rm.xy, np.float64), quads=quads, patch=np.zeros(len(quads), np.int64),
                    line_sets=line_sets, region_area=float(rm.region_area), corners=_shape_corners(shape), size=size,
                    side_lengths=dict(zip(names, map(float, lengths))),
                    side_counts=dict(zip(names, map(int, rm.counts))), templates=(rm.template.mesh_id,), field=field)
