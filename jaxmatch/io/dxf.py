"""DXF drawings as CAD programs export them, read with `ezdxf` into one region (an
:class:`~jaxmatch.io.outline.Outline`).

Two ways, chosen by what the model space holds:

* **closed polylines only** (``LWPOLYLINE`` / 2D ``POLYLINE`` with the closed flag or ending
  where they start, none in a block): each polyline a loop, bulges sampled at equal angles on
  the arc (:data:`~jaxmatch.io.outline.SVG_SAMPLES` points per loop perimeter, at least
  :data:`~jaxmatch.io.outline.MIN_CURVE_SAMPLES` per arc); one of them holds the others
  (holes), or ``FILE#HANDLE`` / ``FILE#LAYER`` chooses one;
* **a drawing of pieces** (anything else: ``LINE``, ``ARC``, ``CIRCLE``, ``ELLIPSE``,
  ``SPLINE``, open or closed polylines with bulges, in the model space or in blocks inserted
  there, ``INSERT`` transforms applied): every piece sampled on its true curve (ezdxf's
  ``flattening``: chords within :data:`~jaxmatch.io.outline.CURVE_TOLERANCE` of the drawing's
  size, turning at most :data:`~jaxmatch.io.outline.MAX_CURVE_TURN` degrees), chained end to end
  into closed loops (:func:`~jaxmatch.io.outline.chain`, ends within
  :data:`~jaxmatch.io.outline.CHAIN_TOLERANCE` of the size), nested into outer rings and holes
  (:func:`~jaxmatch.io.outline.regions`). ``FILE#LAYER`` reads the pieces of one layer only;
  ``FILE#HANDLE`` the region whose loops hold that entity (an ``INSERT``'s handle for the
  pieces of its block). Several regions without a choice: an error listing them.

Every other entity (``TEXT``, ``DIMENSION``, ``HATCH``, ``POINT``, 3D polylines, ...) is counted
in one warning. Errors name the entity by type, handle and layer.
"""

from __future__ import annotations

import io
import math

import ezdxf
import ezdxf.bbox
import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.io.outline import (CHAIN_TOLERANCE, CURVE_TOLERANCE, MAX_CURVE_TURN, MAX_READ_POINTS, MERGE_TOLERANCE, MIN_CURVE_SAMPLES,
                                 SVG_SAMPLES, Outline, Piece, as_text, chain, nested, regions, warn_ignored)
from jaxmatch.io.outline import short as _short

__all__ = ["CURVES", "read_dxf"]

CURVES = ("LINE", "ARC", "CIRCLE", "ELLIPSE", "SPLINE", "LWPOLYLINE", "POLYLINE")
"""The entity types a region is made of (``POLYLINE``: the 2D ones)."""


def read_dxf(data, source: str, element: str | None) -> Outline:
    """The region a DXF file draws (see the module docstring); :class:`InputError` naming the
    file (and the entity) for any problem."""
    text = as_text(data, source)
    try:
        doc = ezdxf.read(io.StringIO(text))
        found = [(e, e, "") for e in doc.modelspace()]
    except Exception as err:  # DXFStructureError and whatever a damaged file raises
        raise InputError(f"not a readable DXF file ({type(err).__name__}: {_short(str(err), 60)})", where=source) from None
    flat, ignored = [], []
    try:
        for e, origin, block in found:
            _explode(e, origin, block, flat, ignored, 0)
    except Exception as err:  # a damaged block reference
        raise InputError(f"a block of the DXF cannot be inserted ({type(err).__name__}: {_short(str(err), 60)})",
                         where=source) from None
    if flat and all(e is origin and e.dxftype() in ("LWPOLYLINE", "POLYLINE") and _closed(e) for e, origin, _ in flat):
        outline = _read_polylines([e for e, _, _ in flat], source, element)
    elif not flat:
        raise InputError(f"no {', '.join(CURVES[:-1])} or 2D POLYLINE in the model space or its blocks"
                         + (f" (only {', '.join(sorted(set(ignored)))})" if ignored else ""), where=source)
    else:
        outline = _read_pieces(flat, source, element, ignored)
    warn_ignored(ignored, source)
    return outline


def _explode(e, origin, block: str, flat: list, ignored: list, depth: int) -> None:
    """Sort ``e`` into ``flat`` (``(entity, origin, block name)``, the pieces of a region; an
    inserted block's entities with the ``INSERT`` they came from) or ``ignored`` (type names)."""
    kind = e.dxftype()
    if kind == "INSERT" and depth < 16:
        name = e.dxf.name
        for v in e.virtual_entities():
            _explode(v, origin, name, flat, ignored, depth + 1)
    elif kind in CURVES and (kind != "POLYLINE" or e.is_2d_polyline):
        flat.append((e, origin, block))
    else:
        ignored.append("3D POLYLINE" if kind == "POLYLINE" else kind)


def _closed(e) -> bool:
    try:
        pts = [tuple(p)[:2] for p in (e.get_points("xy") if e.dxftype() == "LWPOLYLINE" else
                                       (v.dxf.location for v in e.vertices))]
    except Exception:
        return False
    closed = bool(e.closed) if e.dxftype() == "LWPOLYLINE" else bool(e.is_closed)
    return len(pts) >= 2 and (closed or pts[0] == pts[-1])


def _name(e, origin, block: str) -> str:
    if block:
        return f"{e.dxftype()} of block {block!r} (INSERT {origin.dxf.handle}, layer {origin.dxf.layer})"
    return f"{e.dxftype()} {e.dxf.handle} (layer {e.dxf.layer})"


# ---------------------------------------------------------------------------------------------
# a drawing of pieces


def _read_pieces(flat: list, source: str, element: str | None, ignored: list) -> Outline:
    if element is not None:
        layer = [t for t in flat if t[1].dxf.layer == element or t[0].dxf.layer == element]
        handles = {t[1].dxf.handle for t in flat}
        if layer:
            flat = layer
        elif element not in handles:
            layers = sorted({t[0].dxf.layer for t in flat})
            raise InputError(f"no layer or entity handle {element!r} (layers: {', '.join(layers[:10])})", where=source)
    try:
        box = ezdxf.bbox.extents([t[0] for t in flat], fast=True)
        size = float(max(box.size.x, box.size.y)) if box.has_data else 0.0
    except Exception:
        size = 0.0
    if not (math.isfinite(size) and size > 0):
        raise InputError("the drawing has zero or non-finite size", where=source)
    pieces, z = [], []
    for e, origin, block in flat:
        name = _name(e, origin, block)
        try:
            p3 = _sample(e, CURVE_TOLERANCE * size)
        except Exception as err:
            raise InputError(f"{name} cannot be read ({type(err).__name__}: {_short(str(err), 60)})", where=source) from None
        if p3.shape[0] > MAX_READ_POINTS or not np.isfinite(p3).all():
            raise InputError(f"{name} has a number that is not finite or too many points", where=source)
        if p3.shape[0] < 2 or np.max(np.linalg.norm(p3[:, :2] - p3[0, :2], axis=1)) <= CHAIN_TOLERANCE * size:
            ignored.append(f"{e.dxftype()} (zero length)")  # a LINE from a point to itself: joins nothing
            continue
        z.append((float(p3[:, 2].min()), float(p3[:, 2].max()), name))
        pieces.append(Piece(_dedupe(p3[:, :2], MERGE_TOLERANCE * size), name, origin.dxf.handle, origin.dxf.layer))
    if not pieces:
        raise InputError("every piece of the drawing has zero length", where=source)
    low = min(lo for lo, _, _ in z)
    for lo, hi, name in z:
        if hi - low > CHAIN_TOLERANCE * size or lo - low > CHAIN_TOLERANCE * size:
            raise InputError(f"{name} is not in the plane of the others (z from {lo:.6g} to {hi:.6g}, the lowest is "
                             f"{low:.6g}): jaxmatch reads planar drawings", where=source)
    found = regions(chain(pieces, CHAIN_TOLERANCE * size, source), pieces, source)
    if element is not None and not any(t[1].dxf.layer == element or t[0].dxf.layer == element for t in flat):
        found = [r for r in found if any(pieces[i].handle == element for ring in (r[0], *r[1]) for i in ring.pieces)]
    if len(found) > 1:
        names = "; ".join(_ring_name(r[0], pieces) for r in found[:6])
        raise InputError(f"the drawing has {len(found)} regions (outer loops: {names}); jaxmatch meshes one: choose it "
                         "with FILE#LAYER or FILE#HANDLE (any entity of it)", where=source)
    outer, holes = found[0]
    return Outline(outer.points, None, tuple(h.points for h in holes))


def _ring_name(ring, pieces) -> str:
    first = pieces[ring.pieces[0]]
    more = f" and {len(ring.pieces) - 1} more" if len(ring.pieces) > 1 else ""
    return f"{first.name}{more}"


def _dedupe(p: np.ndarray, tol: float) -> np.ndarray:
    """``p (k, 2)`` without the points within ``tol`` of the one kept before (a polyline's
    zero-length segments), its ends kept."""
    step = np.hypot(*np.diff(p, axis=0).T)
    if np.all(step > tol):
        return p
    keep = [0]
    for i in range(1, p.shape[0]):
        if np.hypot(*(p[i] - p[keep[-1]])) > tol:
            keep.append(i)
    if keep[-1] != p.shape[0] - 1:
        keep[-1 if len(keep) > 1 else len(keep):] = [p.shape[0] - 1]
    return p[keep]


def _sample(e, tol: float) -> np.ndarray:
    """``(k, 3)`` points along the DXF entity ``e`` in world coordinates, on its true curve (ezdxf's
    ``flattening``), chords within ``tol`` of it and turning at most :data:`MAX_CURVE_TURN`
    degrees; a polyline's parts (lines and bulge arcs, ezdxf's ``virtual_entities``) in order."""
    kind = e.dxftype()
    if kind == "LINE":
        return np.array([tuple(e.dxf.start), tuple(e.dxf.end)], np.float64)
    if kind in ("ARC", "CIRCLE"):
        r = abs(float(e.dxf.radius))
        sagitta = min(tol, r * (1.0 - math.cos(math.radians(MAX_CURVE_TURN) / 2.0)))
        return np.array([tuple(v) for v in e.flattening(sagitta)], np.float64)
    if kind in ("ELLIPSE", "SPLINE"):
        return np.array([tuple(v) for v in e.flattening(tol, segments=int(math.ceil(360.0 / MAX_CURVE_TURN)))], np.float64)
    parts = [_sample(v, tol) for v in e.virtual_entities()]  # LWPOLYLINE / 2D POLYLINE: lines and arcs
    if not parts:
        return np.zeros((0, 3))
    out = [parts[0]]
    if len(parts) > 1:  # the first part drawn backwards (an arc of negative bulge): its start meets the next part
        ends = parts[1][[0, -1]]
        if np.linalg.norm(ends - parts[0][0], axis=1).min() < np.linalg.norm(ends - parts[0][-1], axis=1).min():
            out[0] = parts[0][::-1]
    for p in parts[1:]:  # each from where the one before ends (its own first point, the same to round-off, left out)
        end = out[-1][-1]
        out.append((p if np.linalg.norm(p[0] - end) <= np.linalg.norm(p[-1] - end) else p[::-1])[1:])
    return np.vstack(out)


# ---------------------------------------------------------------------------------------------
# closed polylines only


def _read_polylines(lines: list, source: str, element: str | None) -> Outline:
    found = lines
    if element is not None:
        lines = [e for e in lines if element in (e.dxf.handle, e.dxf.layer)]
        if not lines:
            names = sorted({f"{e.dxf.handle} (layer {e.dxf.layer})" for e in found})
            raise InputError(f"no 2D polyline with handle or layer {element!r} (polylines: {', '.join(names[:10]) or 'none'})",
                             where=source)
        if len(lines) > 1:
            raise InputError(f"{len(lines)} polylines on layer {element!r}; choose one by handle: "
                             f"{', '.join(e.dxf.handle for e in lines[:10])}", where=source)
    if len(lines) > 1:  # several: one region only when one polyline holds all the others
        try:
            return nested([_dxf_loop(e, source) for e in lines], "evenodd", source, strict=True)
        except InputError:
            raise InputError(f"the DXF has {len(lines)} polylines that are not one region with holes; choose one with "
                             f"FILE#HANDLE or FILE#LAYER: {', '.join(f'{e.dxf.handle} (layer {e.dxf.layer})' for e in lines[:10])}",
                             where=source) from None
    return Outline(_dxf_loop(lines[0], source))


def _dxf_loop(e, source: str) -> np.ndarray:
    """The closed loop of one DXF polyline, arcs sampled."""
    try:
        if e.dxftype() == "LWPOLYLINE":
            xyb = np.array([(x, y, b) for x, y, b in e.get_points("xyb")], dtype=np.float64).reshape(-1, 3)
            closed = bool(e.closed)
        else:
            xyb = np.array([(v.dxf.location.x, v.dxf.location.y, v.dxf.bulge) for v in e.vertices], dtype=np.float64).reshape(-1, 3)
            closed = bool(e.is_closed)
    except Exception as err:
        raise InputError(f"DXF polyline {e.dxf.handle} cannot be read ({type(err).__name__}: {_short(str(err), 60)})",
                         where=source) from None
    if xyb.shape[0] > MAX_READ_POINTS + 1:
        raise InputError(f"DXF polyline {e.dxf.handle} has {xyb.shape[0]} points, more than the {MAX_READ_POINTS} read", where=source)
    if not np.isfinite(xyb).all():
        raise InputError(f"DXF polyline {e.dxf.handle} has a number that is not finite", where=source)
    if xyb.shape[0] and not closed and not np.array_equal(xyb[0, :2], xyb[-1, :2]):
        raise InputError(f"DXF polyline {e.dxf.handle} is open (set its closed flag, or end it at its first point)", where=source)
    if xyb.shape[0] > 1 and np.array_equal(xyb[0, :2], xyb[-1, :2]):
        xyb = xyb[:-1]
    pts = _flatten_bulges(xyb)
    if pts.shape[0] > MAX_READ_POINTS:
        raise InputError(f"DXF polyline {e.dxf.handle} has {pts.shape[0]} points after flattening arcs, "
                         f"more than the {MAX_READ_POINTS} read", where=source)
    return pts


def _flatten_bulges(xyb: np.ndarray) -> np.ndarray:
    """Vertices of a closed polyline ``xyb (P, 3)`` (x, y, bulge of the segment to the next
    vertex) with every arc segment sampled at equal angles: the same spacing as SVG curves
    (:data:`SVG_SAMPLES` per perimeter, at least :data:`MIN_CURVE_SAMPLES` per arc). A bulge
    ``b`` is ``tan(sweep / 4)``, positive counter-clockwise."""
    p, bulge = xyb[:, :2], xyb[:, 2]
    q = np.roll(p, -1, axis=0)
    chord = np.linalg.norm(q - p, axis=1)
    sweep = 4.0 * np.arctan(bulge)
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(bulge != 0, chord / (2.0 * np.abs(np.sin(sweep / 2.0))), 0.0)
    length = np.where(bulge != 0, radius * np.abs(sweep), chord)
    total = float(length.sum())
    spacing = total / SVG_SAMPLES if math.isfinite(total) and total > 0 else 1.0
    out = []
    for i in range(p.shape[0]):
        out.append(p[i])
        if bulge[i] == 0 or chord[i] == 0 or not math.isfinite(radius[i]):
            continue
        k = max(MIN_CURVE_SAMPLES, math.ceil(length[i] / spacing))
        mid, d = (p[i] + q[i]) / 2.0, (q[i] - p[i]) / chord[i]
        normal = np.array([-d[1], d[0]])  # left of the chord
        # the centre is on the left of the chord for a ccw arc of less than a half turn
        h = radius[i] * np.cos(sweep[i] / 2.0) * np.sign(sweep[i])
        centre = mid + normal * h
        a0 = math.atan2(p[i][1] - centre[1], p[i][0] - centre[0])
        a = a0 + sweep[i] * np.arange(1, k) / k
        out.extend(centre + radius[i] * np.c_[np.cos(a), np.sin(a)])
    return np.array(out, dtype=np.float64).reshape(-1, 2)
