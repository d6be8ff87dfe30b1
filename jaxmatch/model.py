"""A model of several named regions and embedded points and curves: what an assembly file holds.

A :class:`Model` is regions that may share whole or partial sides (a corner of one lying on
another's side) and may fill one another's holes, but never overlap, and embedded points
(each to be a mesh vertex) and curves (each to be covered by mesh edges) inside them. It is
meshed as one conforming quad mesh by :mod:`jaxmatch.meshing.assembly`; the readers of its
files are in :mod:`jaxmatch.io.assembly`.

All coordinates are the user's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.shape import Shape

__all__ = ["Embedded", "Model", "Region", "make_model", "region_polygon"]

TOUCH_TOL = 1e-9
"""Relative (to the model's extent) distance within which points count as on a line or the
same, and the area (times the extent squared) below which two regions only touch."""


@dataclass(frozen=True, eq=False)
class Region:
    """One named region: ``shape`` its validated outline and holes (a
    :class:`~jaxmatch.shape.Shape`, user coordinates in ``given_points`` and ``holes``)."""

    name: str
    shape: Shape


@dataclass(frozen=True, eq=False)
class Embedded:
    """Points ``(P, 2) float64`` each to be a mesh vertex, and curves (each ``(k, 2) float64``,
    an open polyline of ``k >= 2`` points) each to be covered by mesh edges."""

    points: np.ndarray
    curves: tuple[np.ndarray, ...] = ()

    @property
    def empty(self) -> bool:
        return self.points.shape[0] == 0 and not self.curves


NO_EMBEDDED = Embedded(np.zeros((0, 2)))


@dataclass(frozen=True, eq=False)
class Model:
    """Regions (distinct names, no two overlapping) and what is embedded in them; ``source``
    names the file in messages."""

    regions: tuple[Region, ...]
    embedded: Embedded = NO_EMBEDDED
    source: str = "<model>"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.regions)

    @property
    def n_corners(self) -> int:  # (what the command line reads of a region)
        return sum(r.shape.n_corners for r in self.regions)


def region_polygon(shape: Shape):
    """``shape`` as a shapely Polygon (user coordinates, holes as interior rings)."""
    import shapely

    return shapely.Polygon(shape.given_points, holes=[np.asarray(h, np.float64) for h in shape.holes])


def _as_points(value, what: str, source: str) -> np.ndarray:
    try:
        pts = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{what} must be [x, y] number pairs", where=source) from None
    if pts.size == 0:
        return np.zeros((0, 2))
    if pts.ndim != 2 or pts.shape[1] != 2 or not np.isfinite(pts).all():
        raise InputError(f"{what} must be finite [x, y] number pairs", where=source)
    return pts


def parse_embedded(doc, source: str) -> Embedded:
    """``{"points": [[x, y], ...], "curves": [[[x, y], ...], ...]}`` (either key optional) as an
    :class:`Embedded`; one :class:`InputError` line for a bad entry."""
    if doc is None:
        return NO_EMBEDDED
    if not isinstance(doc, dict):
        raise InputError('"embedded" must be an object {"points": [[x, y], ...], "curves": [[[x, y], ...], ...]}',
                         where=source)
    unknown = [k for k in doc if k not in ("points", "curves")]
    if unknown:
        raise InputError(f'"embedded" has an unknown key {unknown[0]!r} (known: points, curves)', where=source)
    points = _as_points(doc.get("points", []), '"embedded" "points"', source)
    curves_doc = doc.get("curves", [])
    if not isinstance(curves_doc, list):
        raise InputError('"embedded" "curves" must be a list of polylines [[[x, y], ...], ...]', where=source)
    curves = []
    for k, c in enumerate(curves_doc):
        pts = _as_points(c, f'embedded curve {k + 1}', source)
        keep = np.ones(len(pts), bool)
        keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
        pts = pts[keep]
        if pts.shape[0] < 2:
            raise InputError(f"embedded curve {k + 1} needs at least 2 distinct points", where=source)
        curves.append(pts)
    return Embedded(points, tuple(curves))


def join_embedded(parts: Sequence[Embedded]) -> Embedded:
    """The points and curves of ``parts``, in order."""
    pts = [p.points for p in parts if p.points.shape[0]]
    return Embedded(np.concatenate(pts) if pts else np.zeros((0, 2)), tuple(c for p in parts for c in p.curves))


def make_model(regions: Sequence[Region], embedded: Embedded = NO_EMBEDDED, *, source: str = "<model>") -> Model:
    """Check and make a :class:`Model` (each failure one :class:`InputError` line naming
    ``source``): at least one region, distinct names, no two regions overlapping (shapely: a
    common area above :data:`TOUCH_TOL` of the extent squared), every embedded point and curve
    inside or on the regions, no curve crossing itself."""
    import shapely

    regions = tuple(regions)
    if not regions:
        raise InputError("no regions", where=source)
    seen: set[str] = set()
    for r in regions:
        if not isinstance(r.name, str) or not r.name.strip():
            raise InputError(f"region name {r.name!r} must be a non-empty string", where=source)
        if "|" in r.name:
            raise InputError(f"region name {r.name!r} contains '|' (interface groups are named NAME1|NAME2)",
                             where=source)
        if r.name in seen:
            raise InputError(f"two regions are named {r.name!r}; names must be distinct", where=source)
        seen.add(r.name)
    polys = [region_polygon(r.shape) for r in regions]
    bounds = np.array([p.bounds for p in polys])
    extent = float(max(bounds[:, 2].max() - bounds[:, 0].min(), bounds[:, 3].max() - bounds[:, 1].min()))
    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="intersects")
    for i, j in sorted(zip(left.tolist(), right.tolist())):
        if i < j:
            common = polys[i].intersection(polys[j]).area
            if common > TOUCH_TOL * extent * extent:
                raise InputError(f"regions {regions[i].name!r} and {regions[j].name!r} overlap (common area {common:.4g})",
                                 where=source)
    union = shapely.union_all(polys)
    tol = TOUCH_TOL * extent * 10
    near = union.buffer(tol)
    for k, (x, y) in enumerate(embedded.points.tolist()):
        if not near.covers(shapely.Point(x, y)):
            raise InputError(f"embedded point {k + 1} ({x:g}, {y:g}) lies outside the regions", where=source)
    for k, c in enumerate(embedded.curves):
        line = shapely.LineString(c)
        if not line.is_simple:
            raise InputError(f"embedded curve {k + 1} crosses itself", where=source)
        outside = line.difference(near).length
        if outside > tol:
            raise InputError(f"embedded curve {k + 1} leaves the regions ({outside:.4g} of its length "
                             f"{line.length:.4g} lies outside)", where=source)
        inside = [i for i, p in enumerate(polys) if line.difference(p.buffer(tol)).length <= tol]
        if not inside:
            raise InputError(f"embedded curve {k + 1} crosses from one region into another; give it as a "
                             "region boundary or as one curve per region", where=source)
    if not math.isfinite(extent) or extent <= 0:  # pragma: no cover - make_shape refuses empty regions
        raise InputError("the regions have no extent", where=source)
    return Model(regions, embedded, source)
