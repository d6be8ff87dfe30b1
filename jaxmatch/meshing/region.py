"""The region a request meshes: read from a file (a shape or a layout), its default size, and
its loops written one canonical way with corners judged at the mesh size (step 1 of the
pipeline, :mod:`jaxmatch.meshing.pipeline`)."""

from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.defaults import DEFAULT_DIVISIONS
from jaxmatch.geometry import cumulative_length
from jaxmatch.files import read_limited
from jaxmatch.errors import InputError
from jaxmatch.io.assembly import read_model, several_regions
from jaxmatch.io.readers import detect_format, load_shape, split_element
from jaxmatch.model import Model, region_polygon
from jaxmatch.placement.decompose import _corner_points
from jaxmatch.placement.layout import MAX_BYTES, layout_sides, parse_layout
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, Shape, make_shape, scale_corners
from jaxmatch.sides import LoopNumbers

__all__ = ["DEDUPE", "canonical", "corner_points", "default_size", "load_region"]


def default_size(region, divisions: int = DEFAULT_DIVISIONS) -> float:
    """Perimeter of the region's outer boundary / ``divisions`` (user units); of a
    :class:`~jaxmatch.model.Model`, the outline of the union of its regions."""
    if isinstance(region, Model):
        import shapely

        union = shapely.union_all([region_polygon(r.shape) for r in region.regions])
        return float(shapely.get_exterior_ring(union).length if union.geom_type == "Polygon"
                     else sum(g.exterior.length for g in union.geoms)) / divisions
    if isinstance(region, Shape):
        pts = region.user_points
    else:  # a Layout: its outer sides

        sides = layout_sides(region)
        return float(np.sum(sides.lengths[sides.outer])) / divisions
    return float(cumulative_length(pts)[-1]) / divisions


def load_region(path: str | os.PathLike, *, corner_angle: float = DEFAULT_CORNER_ANGLE):
    """A shape, a layout or an assembly from a file: a JSON object with ``"patches"`` is a layout
    (:func:`jaxmatch.placement.layout.parse_layout`), one with ``"regions"`` or ``"embedded"``
    (or a GeoJSON, SVG or DXF file of several regions) an assembly
    (:func:`jaxmatch.io.assembly.read_model`), anything else a shape of any format jaxmatch
    reads (``file#element`` chooses an element). Raises :class:`InputError` naming the file."""

    p = Path(path)
    if p.suffix.lower() == ".json" and p.is_file():

        raw = read_limited(p, MAX_BYTES, "shape file")
        try:
            doc = json.loads(raw.decode("utf-8-sig"))
        except (ValueError, UnicodeDecodeError):
            doc = None
        if isinstance(doc, dict) and "patches" in doc:
            return parse_layout(raw, str(path))
        if isinstance(doc, dict) and ("regions" in doc or "embedded" in doc):
            return read_model(raw, str(path), "json", corner_angle)
    file, element = split_element(path)
    if element is None and p.suffix.lower() == ".geojson" and p.is_file():
        model = read_model(read_limited(p, MAX_BYTES, "shape file"), str(path), "geojson", corner_angle)
        if model is not None:
            return model
    try:
        return load_shape(path, corner_angle=corner_angle)
    except InputError as err:  # an SVG or DXF file of several regions: an assembly
        if element is not None or not several_regions(err) or not Path(file).is_file():
            raise
        data = read_limited(file, MAX_BYTES, "shape file")
        model = read_model(data, str(path), detect_format(str(file), data), corner_angle)
        if model is None:
            raise
        return model


def corner_points(shape: Shape) -> np.ndarray:
    """``(C, 2)`` every corner of the region (outer loop and holes), user coordinates."""

    return _corner_points(shape)


DEDUPE = 1e-8
"""Points of a loop closer than this fraction of its extent to the previous one are merged
before meshing (a corner among them stays, at the first point): layouts need distinct points."""


def _dedupe(ring: np.ndarray, corners: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ring (P, 2)`` without points within ``tol`` of the previous kept point, ``corners``
    (indices) mapped onto the kept points, and the kept points' indices into ``ring``."""
    step = np.hypot(*(roll(ring, -1) - ring).T)  # to the next point, the last to the first
    if np.all(step > tol):  # (the common case: nothing to merge, no loop over the points)
        return ring, np.asarray(corners, np.int64), np.arange(len(ring))
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
        return ring, np.asarray(corners, np.int64), np.arange(len(ring))
    return ring[keep], np.unique(owner[np.asarray(corners, np.int64)]), np.asarray(keep, np.int64)


def canonical(shape: Shape, size: float | None = None, corner_angle: float = DEFAULT_CORNER_ANGLE,
              held_angle: float | None = None) -> Shape:
    """The same shape with its loops written one way: the outer loop counter-clockwise and each
    hole clockwise from its lexicographically smallest point (x, then y), holes in the order of
    those points, points closer than :data:`DEDUPE` of the extent merged. Corners detected from
    angles are judged again at ``size`` when it is given
    (:func:`jaxmatch.shape.scale_corners`: wiggles shorter than about ``size`` are no corners);
    explicit corners are kept. Meshing the canonical shape makes the mesh
    independent of where the user's loop starts and which way it runs."""

    def first(ring: np.ndarray) -> int:
        return int(np.lexsort((ring[:, 1], ring[:, 0]))[0])


    rejudge = size is not None and not shape.explicit_corners

    def corners_of(ring: np.ndarray, given) -> np.ndarray:
        if not rejudge:
            return np.asarray(given, np.int64)
        return scale_corners(ring, size, corner_angle, held_angle=held_angle)

    pts = shape.given_points
    tol = DEDUPE * float(np.ptp(pts, axis=0).max())
    numbering = shape.numbering or (LoopNumbers(np.arange(len(pts)), None, shape.input_clockwise, 0),)
    holes, hole_corners, passed = [], [], []  # passed: per loop, the file's numbers of the points handed on
    holes_kept = True  # every hole keeps its points (a checked hole listed from another point)
    order = sorted(range(len(shape.holes)), key=lambda k: tuple(shape.holes[k][first(shape.holes[k])]))
    for i in order:
        ring, hc = shape.holes[i], shape.hole_corners[i]
        nb = numbering[i + 1] if i + 1 < len(numbering) else LoopNumbers(np.arange(len(ring)), None, True, i + 1)
        n_before = len(ring)
        ring, hc, keep = _dedupe(ring, corners_of(ring, hc), tol)
        holes_kept = holes_kept and len(ring) == n_before
        k = first(ring)
        holes.append(roll(ring, -k))
        hole_corners.append(sorted(int(c) for c in (hc - k) % len(ring)))
        passed.append(nb._replace(numbers=roll(np.asarray(nb.numbers)[keep], -k)))
    pts2, outer, keep = _dedupe(pts, corners_of(pts, shape.corners), tol)
    start = first(pts2)
    if start == 0 and shape.corner_order is None and not holes and len(pts2) == len(pts) \
            and np.array_equal(outer, shape.corners):
        return shape
    same_points = len(pts2) == len(pts)  # the checked loop from another point: simple, distinct points
    pts = pts2
    passed.insert(0, numbering[0]._replace(numbers=roll(np.asarray(numbering[0].numbers)[keep], -start)))
    corners = sorted(int(c) for c in (outer - start) % len(pts))
    region = make_shape(roll(pts, -start), corners=corners, source=shape.source, holes=holes or None,
                        hole_corners=hole_corners or None, checked=same_points,
                        holes_checked=holes_kept and same_points)  # (their place against the same outer loop)
    # the region's loops index the points handed on; the file's numbers are those points' numbers
    carried = tuple(p._replace(numbers=np.asarray(p.numbers)[np.asarray(r.numbers)])
                    for p, r in zip(passed, region.numbering))
    return replace(region, numbering=carried, tags=shape.tags, periodic=shape.periodic)
