"""The ring partition (``"rings"``), two layouts that put quads at the size through a region
whatever its corners:

* :func:`ring_layout`, a region without holes: a layer of patches one ring depth wide along the
  outline (along a polygon's sides, a fillet, a gear's teeth), and the core left inside meshed
  as an O-grid (a central block and four patches). The core is the region opened and shrunk:
  eroded by ``depth + opening``, dilated by ``opening`` (round joins), so features narrower than
  about twice the opening (teeth, fins, the neck of a keyhole) stay in the layer and the core's
  outline is smooth. A corner is joined to its nearest core point by a cut when it is concave,
  or convex and near the core (not the tip of a protrusion); a loop with fewer than
  :data:`MIN_CUTS` cuts gets cuts from its points nearest the corners of its smallest enclosing
  rectangle too (a rounded rectangle's fillets, an ellipse's diagonals). Each layer patch is
  four-sided where a side of the region is (outline side, two cuts, core arc).
* :func:`hole_ring_layout`, a region with holes: an O-grid box around every hole and a grid of
  the boxes' side continuations through the rest (block-structured, as a plate with bolt holes is
  meshed by hand).

Every piece becomes a patch of the one integer program.
"""

from __future__ import annotations

import math

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.geometry import turning_angles
from jaxmatch.lazy import Later
from jaxmatch.placement.decompose import DISK_BLOCK, _faces, _hits, _layout, _rings, _snap
from jaxmatch.placement.layout import Layout, check_layout
from jaxmatch.shape import Shape, make_shape

__all__ = ["BOX_ROOM", "BOX_SHARE", "BOX_SNAP", "CUT_REACH", "MIN_CUTS", "OPENING", "RING_DEPTH", "hole_ring_layout", "ring_layout"]

_later = Later(shapely="shapely")

RING_DEPTH = 1.0
"""Width of the ring layer along every loop, in element sizes ``h``."""

OPENING = 0.5
"""Radius of the opening that smooths the core, in ring depths: thinner features stay in the ring."""

CUT_REACH = 2.0
"""A convex corner is cut to the core when the core is within this many ring depths of it (a
right angle's corner lies ``sqrt(2)`` depths away; the tip of a tooth or fin farther)."""

MIN_CUTS = 4
"""Fewest cuts from the outline to the core (a disk has no corner: four)."""

BOX_ROOM = 0.45
"""The box around a hole leaves it at most this fraction of the way to the outer loop."""

BOX_SHARE = 0.225
"""The box around a hole leaves it at most this fraction of the way to the nearest other hole
(whose box takes as much from the other side)."""

BOX_SNAP = 0.75
"""Sides of two boxes closer than this many ``h`` along an axis are moved to one line (no thin
strip of quads between them, no extra cut through the boxes' ring patches)."""

QUAD_SEGMENTS = 4
"""Segments per quarter circle of the core's rounded parts (shapely's ``quad_segs``)."""


def _loop_corners(shape: Shape) -> list[np.ndarray]:
    """Corner indices of each loop (outer, then holes)."""
    return [np.asarray(shape.corners, np.int64)] + [np.asarray(c, np.int64) for c in shape.hole_corners]


def ring_layout(shape: Shape, h: float, depth: float = RING_DEPTH) -> Layout:
    """The ring partition of ``shape`` at element size ``h`` (user units): see the module
    docstring. Raises :class:`InputError` when the region has no core at this depth (thinner
    than two ring depths everywhere) or the cuts do not make a valid layout."""
    if shape.holes:
        return hole_ring_layout(shape, h, depth)
    shapely = _later.shapely
    rings = _rings(shape)
    region = shapely.Polygon(rings[0], holes=rings[1:])
    ext = float(np.max(np.ptp(rings[0], axis=0)))
    tol = 1e-9 * ext
    d = depth * float(h)
    r_open = OPENING * d
    core = region.buffer(-(d + r_open), join_style="round", quad_segs=QUAD_SEGMENTS)
    core = core.buffer(r_open, join_style="round", quad_segs=QUAD_SEGMENTS)
    core = core.simplify(0.02 * float(h)).buffer(0)
    parts = [p for p in shapely.get_parts(core) if p.area > (2 * d) ** 2]
    if not parts:
        raise InputError(f"no core inside a ring {d:.4g} deep (the region is thinner)", where=shape.source)
    core_rings = [np.asarray(r.coords)[:-1] for p in parts for r in [p.exterior, *p.interiors]]
    core_line = shapely.MultiLineString([np.vstack([r, r[:1]]) for r in core_rings])
    cuts, inserts = [], []
    core_inserts: list = []
    feet: list[np.ndarray] = []

    def foot_of(p: np.ndarray) -> np.ndarray:
        return np.asarray(shapely.shortest_line(core_line, shapely.Point(p)).coords[0])

    def usable(p: np.ndarray, q: np.ndarray) -> bool:
        seg = shapely.LineString([p, q])
        if seg.length <= 10 * tol:
            return False
        u = (q - p) / seg.length
        inner = shapely.LineString([p + 1e-7 * ext * u, q - 1e-7 * ext * u])
        if not region.contains(inner) or inner.crosses(core_line):
            return False
        return not any(inner.intersects(shapely.LineString(c)) for c in cuts) and \
            all(float(np.linalg.norm(q - f)) > 0.2 * d for f in feet)

    for r, (ring, corners) in enumerate(zip(rings, _loop_corners(shape))):
        turn = turning_angles(ring)
        made = 0
        order = sorted(corners.tolist(), key=lambda c: (turn[c] >= 0, -abs(turn[c])))  # concave first, then sharpest
        for c in order:
            p = ring[c]
            q = foot_of(p)
            dist = float(np.linalg.norm(q - p))
            if turn[c] >= 0 and dist > CUT_REACH * d:  # a protrusion's tip: its patch keeps it
                continue
            if usable(p, q):
                cuts.append(np.array([p, _snap(core_rings, q, tol, core_inserts)]))
                feet.append(q)
                made += 1
        if made < MIN_CUTS:  # cuts from the loop's points nearest the corners of its smallest enclosing rectangle
            box = np.asarray(shapely.Polygon(ring).minimum_rotated_rectangle.exterior.coords)[:-1]
            for b in box:
                p = ring[int(np.argmin(np.linalg.norm(ring - b, axis=1)))]
                q = foot_of(p)
                if usable(p, q):
                    cuts.append(np.array([p, _snap(core_rings, q, tol, core_inserts)]))
                    feet.append(q)
                    made += 1
        if made < 2:
            raise InputError(f"loop {r}: fewer than two cuts reach the core", where=shape.source)
    for part in parts:  # each part of the core an O-grid block (a region without holes: a core without holes)
        mine = [f for f in feet if part.exterior.distance(shapely.Point(f)) <= 1e-7 * ext]
        _block_cuts(part, core_rings, mine, cuts, core_inserts, tol, shape.source)
    all_rings = rings + core_rings
    ins = inserts + [(len(rings) + r, k, f, e) for (r, k, f, e) in core_inserts]
    faces = _faces(all_rings, cuts, ins, [False] * len(cuts), region=region)
    return _layout(shape, faces, "rings", check=False)


def _block_cuts(core, core_rings, feet, cuts, core_inserts, tol, source) -> None:
    """The O-grid of a core without holes: a central block reaching :data:`DISK_BLOCK` of the way
    to four spokes' ends (appended to ``cuts``): the foot nearest the direction of the core's
    principal axis turned by 45 degrees, and three more feet around, so that opposite patches of
    the block meet as many ring patches (the block ties their counts)."""
    shapely = _later.shapely
    ring_pts = np.asarray(core.exterior.coords)[:-1]
    c0 = np.asarray(core.centroid.coords[0])
    if not core.contains(shapely.Point(c0)):
        raise InputError("the core is not star-shaped around its centroid", where=source)
    dd = ring_pts - c0
    _, vec = np.linalg.eigh(dd.T @ dd)
    base = math.atan2(vec[1, -1], vec[0, -1]) + math.pi / 4
    cand = np.array(feet) if len(feet) >= 4 else ring_pts
    ang = np.arctan2(cand[:, 1] - c0[1], cand[:, 0] - c0[0])
    cand = cand[np.argsort(ang)]  # around the centre: the ring patches' order
    ang = np.sort(ang)
    j0 = int(np.argmin(np.abs((ang - base + math.pi) % (2 * math.pi) - math.pi)))
    n = cand.shape[0]  # four spokes: opposite patches of the block meet as many ring patches (a, b, a, b)
    a = n // 4
    b = (n - 2 * a) // 2
    ends = [cand[(j0 + o) % n] for o in (0, a, a + b, 2 * a + b)]
    ends_arr = np.unique(np.array(ends), axis=0)
    if ends_arr.shape[0] < 4:
        raise InputError("the core's spokes coincide", where=source)
    ends_arr = ends_arr[np.argsort(np.arctan2(ends_arr[:, 1] - c0[1], ends_arr[:, 0] - c0[0]))]
    block = c0 + DISK_BLOCK * (ends_arr - c0)
    for k in range(4):
        cuts.append(np.array([block[k], block[(k + 1) % 4]]))
        cuts.append(np.array([block[k], _snap(core_rings, ends_arr[k], tol, core_inserts)]))


def hole_ring_layout(shape: Shape, h: float, depth: float = RING_DEPTH) -> Layout:
    """A region with holes, block-structured: every hole in a square box (sides along the outer
    loop's smallest enclosing rectangle, ``depth * h`` or less clear of the hole, at most
    :data:`BOX_ROOM` of the way to the nearest other loop) joined to the hole by four cuts from
    the box's corners (an O-grid around the hole), and the rest of the region cut by the
    continuations of the boxes' sides and of the outer loop's concave corners
    (:func:`jaxmatch.placement.decompose._hits`: a grid through the part). Raises
    :class:`InputError` when a box would leave the region or meet another."""
    shapely = _later.shapely
    d = depth * float(h)
    outer = shape.given_points
    holes = [np.asarray(x, np.float64) for x in shape.holes]
    region = shapely.Polygon(outer, holes=holes)
    frame = np.asarray(shapely.Polygon(outer).minimum_rotated_rectangle.exterior.coords)[:2]
    u = (frame[1] - frame[0]) / np.linalg.norm(frame[1] - frame[0])
    v = np.array([-u[1], u[0]])
    boundary = shapely.LinearRing(outer)
    frame2 = np.stack([u, v], axis=1)
    ext = []  # per hole: (lo, hi) of its box and (lo, hi) of the hole, along u and v
    for k, hole in enumerate(holes):
        to_outer = boundary.distance(shapely.Polygon(hole))
        to_holes = min((shapely.Polygon(hole).distance(shapely.Polygon(o)) for j, o in enumerate(holes) if j != k),
                       default=math.inf)
        gap = min(d, BOX_ROOM * to_outer, BOX_SHARE * to_holes)
        if gap <= 0:
            raise InputError(f"hole {k + 1}: no room for a box around it", where=shape.source)
        w = hole @ frame2
        ext.append((w.min(axis=0) - gap, w.max(axis=0) + gap, w.min(axis=0), w.max(axis=0), gap))
    failed: InputError | None = None
    for snap in (float(h), 0.0):  # boxes' nearly aligned sides snapped to one line, else as they are
        boxes_xy = _aligned_boxes(ext, snap, outer, frame2, shapely)
        if boxes_xy is None:
            continue
        for nearest in (True, False):  # cuts to the hole's point nearest each box corner, else in its direction
            try:
                lay = _boxed_layout(shape, region, outer, holes, boxes_xy, nearest)
                check_layout(lay)
            except InputError as e:
                failed = e
                continue
            return lay
    raise failed or InputError("no room for a box around every hole", where=shape.source)


def _boxed_layout(shape: Shape, region, outer: np.ndarray, holes: list, boxes_xy: list, nearest: bool) -> Layout:
    """The layout of :func:`hole_ring_layout` for these boxes (corners ``(4, 2)`` each): four cuts
    from each box's corners to its hole (:func:`_toward_corner`), the continuations of the boxes'
    sides and of the outline's concave corners."""
    shapely = _later.shapely
    boxes = [shapely.Polygon(b) for b in boxes_xy]
    box_loops = [np.asarray(b.exterior.coords)[:-1][::-1] if b.exterior.is_ccw else np.asarray(b.exterior.coords)[:-1]
                 for b in boxes]
    try:
        rest = make_shape(outer, corners=[int(c) for c in shape.corners], source=shape.source, holes=box_loops,
                          hole_corners=[[0, 1, 2, 3]] * len(box_loops), checked=True)
    except InputError as e:
        raise InputError(f"the boxes around the holes: {e.problem}", where=shape.source) from None
    cuts, inserts = _hits(rest, "continuations")
    n_holes = len(holes)
    rings = _rings(shape) + [np.asarray(x, np.float64) for x in rest.holes]
    ins = [(0 if r == 0 else n_holes + r, k, f, e) for (r, k, f, e) in inserts]
    ring_cuts = [np.array([hole[_toward_corner(hole, q, nearest)], q]) for hole, corners in zip(holes, boxes_xy)
                 for q in corners]
    faces = _faces(rings, ring_cuts + cuts, ins, [False] * (len(ring_cuts) + len(cuts)), region=region)
    return _layout(shape, faces, "rings", check=False)


def _aligned_boxes(ext, snap: float, outer, frame2, shapely):
    """The boxes' corners ``(4, 2)`` each (user coordinates) from their extents along the frame's
    axes ``ext`` (:func:`hole_ring_layout`), sides closer than :data:`BOX_SNAP` ``* snap`` along an axis moved
    to one value, their mean as near as every box keeps a fifth of its gap to its hole (no thin
    strip of quads between two boxes' nearly aligned sides), or None when a box then leaves the
    region or meets another."""
    lo = np.array([e[0] for e in ext], np.float64)
    hi = np.array([e[1] for e in ext], np.float64)
    if snap > 0:
        for axis in (0, 1):
            vals = np.concatenate([lo[:, axis], hi[:, axis]])
            order = np.argsort(vals)
            groups, cur = [], [order[0]]
            for i in order[1:]:
                if vals[i] - vals[cur[-1]] < BOX_SNAP * snap:
                    cur.append(i)
                else:
                    groups.append(cur)
                    cur = [i]
            groups.append(cur)
            n = len(ext)
            for g in groups:  # one value for the group where every box keeps a fifth of its gap to its hole
                g = np.asarray(g)
                box = g % n
                if len(set(box.tolist())) < len(g) or (np.any(g < n) and np.any(g >= n)):
                    continue  # (both sides of one narrow box; two boxes facing each other: they would touch)
                ub = [ext[k][2][axis] - 0.2 * ext[k][4] for k, i in zip(box, g) if i < n]  # lo sides: at most
                lb = [ext[k][3][axis] + 0.2 * ext[k][4] for k, i in zip(box, g) if i >= n]  # hi sides: at least
                top, bottom = min(ub, default=np.inf), max(lb, default=-np.inf)
                if bottom <= top:
                    vals[g] = float(np.clip(vals[g].mean(), bottom, top))
            lo[:, axis], hi[:, axis] = vals[:n], vals[n:]
    region = shapely.Polygon(outer)
    out, polys = [], []
    for k, (blo, bhi, hlo, hhi, gap) in enumerate(ext):
        if np.any(lo[k] > hlo - 0.2 * gap) or np.any(hi[k] < hhi + 0.2 * gap):
            return None
        corners = np.array([[lo[k, 0], lo[k, 1]], [hi[k, 0], lo[k, 1]], [hi[k, 0], hi[k, 1]], [lo[k, 0], hi[k, 1]]]) @ frame2.T
        box = shapely.Polygon(corners)
        if not region.contains(box) or any(box.intersects(p) for p in polys):
            return None
        polys.append(box)
        out.append(corners)
    return out


def _toward_corner(hole: np.ndarray, q: np.ndarray, nearest: bool) -> int:
    """Index of the point of ``hole (H, 2)`` a cut from the box corner ``q`` ends on: the nearest
    one (a thin hole's ends, an airfoil's leading and trailing edges), or the one in the corner's
    direction from the hole's centroid (a round hole's point at 45 degrees either way)."""
    if nearest:
        return int(np.argmin(np.linalg.norm(hole - q, axis=1)))
    c = hole.mean(axis=0)
    ang = np.arctan2(hole[:, 1] - c[1], hole[:, 0] - c[0]) - math.atan2(q[1] - c[1], q[0] - c[0])
    return int(np.argmin(np.abs((ang + math.pi) % (2 * math.pi) - math.pi)))
