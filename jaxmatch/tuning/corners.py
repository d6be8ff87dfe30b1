"""Does the top-ranked mesh keep the shape's corners? (A measure for choosing lattices.)

A corner (an ``x`` or ``v`` point of the annotation) is *kept* by a match when some mesh boundary
vertex is aligned to it (its index is in the alignment). For a shape and a size ``k`` (as
``jaxmatch score --internal k``: ``default_points`` for the longest size-k boundary), keeping
every corner is *possible* when some size-k mesh has an alignment that keeps them all and uses no
forbidden pairing of the lattice (checked by scoring with the lattice's corner skip weights set
to ``-inf``). :func:`corner_report` counts, over shapes and sizes, how often the rank-1 mesh keeps
every corner where that is possible, and how many corners the rank-1 meshes keep in all.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Iterable, NamedTuple

import numpy as np

from jaxmatch.errors import UnmatchableError
from jaxmatch.scoring.lattice import Lattice
from jaxmatch.scoring.rank import rank

__all__ = ["CornerFit", "corner_fit", "corner_report", "must_keep_corners"]


class CornerFit(NamedTuple):
    """One shape and size: ``corners`` (x/v points), ``kept`` (of them, by the rank-1 mesh),
    ``possible`` (some size-k mesh keeps all), ``mesh_id`` and ``utility`` of the rank-1 mesh
    (None / nan when nothing matches)."""

    shape: str
    k: int
    corners: int
    kept: int
    possible: bool
    mesh_id: str | None
    utility: float


def must_keep_corners(lattice: Lattice) -> Lattice:
    """``lattice`` with skip weight ``-inf`` for ``x`` and ``v`` (every corner must get a vertex)."""
    return replace(lattice, skip=(lattice.skip[0], -math.inf, -math.inf))


def corner_fit(name: str, shape, catalogue, lattice: Lattice, k: int) -> CornerFit:
    """:class:`CornerFit` of the rank-1 mesh of size ``k`` (pruned search, ties by id)."""
    try:
        r = rank(shape, catalogue, lattice, internal=[k], top=1, tie_break="id", prune=True)
    except UnmatchableError:
        return CornerFit(name, k, -1, 0, False, None, math.nan)
    codes = np.asarray(r.annotation.codes)
    corners = np.flatnonzero(codes != 0)
    best = r.results[0]
    kept = int(np.isin(corners, best.alignment).sum())
    if kept == len(corners):
        possible = True
    else:
        try:
            rank(shape, catalogue, must_keep_corners(lattice), internal=[k], top=1, tie_break="id", prune=True)
            possible = True
        except UnmatchableError:
            possible = False
    return CornerFit(name, k, int(len(corners)), kept, possible, best.mesh_id, float(best.utility))


def corner_report(shapes: Iterable[tuple[str, object]], catalogue, lattice: Lattice, ks: Iterable[int]) -> dict:
    """Rank-1 corner keeping over ``shapes`` (``(name, Shape)`` pairs with at least one corner)
    and sizes ``ks``: ``{"cases", "possible", "top_keeps_all", "corners", "corners_kept",
    "missed": [(shape, k, kept, corners)], "rows": [CornerFit as dict]}``; ``top_keeps_all``
    counts the possible cases whose rank-1 mesh keeps every corner."""
    rows = [corner_fit(name, shp, catalogue, lattice, int(k)) for name, shp in shapes for k in ks]
    rows = [r for r in rows if r.corners > 0]
    possible = [r for r in rows if r.possible]
    return {
        "lattice": lattice.name,
        "cases": len(rows),
        "possible": len(possible),
        "top_keeps_all": sum(r.kept == r.corners for r in possible),
        "corners": sum(r.corners for r in rows),
        "corners_kept": sum(r.kept for r in rows),
        "missed": [(r.shape, r.k, r.kept, r.corners) for r in possible if r.kept < r.corners],
        "rows": [r._asdict() for r in rows],
    }
