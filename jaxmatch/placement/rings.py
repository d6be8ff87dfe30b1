"""The ring partition (``"rings"``): a layer of patches one ring depth wide along every loop of
the region (the outline inside, each hole outside: an O-grid-like layer of quads at the size
around a round hole, along a fillet, a leading edge or a polygon's sides), and the core left
inside, an O-grid of its own (a central block and four patches) when it has no hole, cut to its
holes otherwise.

The core is the region opened and shrunk: eroded by ``depth + opening``, dilated by ``opening``
(round joins), so features narrower than about twice the opening (teeth, fins, the neck of a
keyhole) stay in the ring and the core's outline is smooth. A loop's corner is joined to its
nearest core point by a cut when it is concave, or convex and near the core (not the tip of a
protrusion); a loop with fewer than :data:`MIN_CUTS` cuts gets cuts from evenly spaced points
too. Every piece between the cuts becomes a patch of the one integer program, so each ring
patch is four-sided where a side of the region is (outline side, two cuts, core arc) and its
quads are at the size through the layer.
"""

from __future__ import annotations

import math

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.lazy import Later
from jaxmatch.placement.decompose import DISK_BLOCK, _faces, _layout, _radial_hits, _rings, _snap
from jaxmatch.placement.layout import Layout
from jaxmatch.shape import Shape, make_shape

__all__ = ["CUT_REACH", "MIN_CUTS", "OPENING", "RING_DEPTH", "hole_ring_layout", "ring_layout"]

_later = Later(shapely="shapely")

RING_DEPTH = 1.0
"""Width of the ring layer along every loop, in element sizes ``h``."""

OPENING = 0.5
"""Radius of the opening that smooths the core, in ring depths: thinner features stay in the ring."""

CUT_REACH = 2.0
"""A convex corner is cut to the core when the core is within this many ring depths of it (a
right angle's corner lies ``sqrt(2)`` depths away; the tip of a tooth or fin farther)."""

MIN_CUTS = 4
"""Fewest cuts per loop (a round hole has no corner: four evenly spaced cuts)."""

QUAD_SEGMENTS = 4
"""Segments per quarter circle of the core's rounded parts (shapely's ``quad_segs``)."""


def _turns(ring: np.ndarray) -> np.ndarray:
    """``(P,)`` signed turn at each point of a closed loop (left turns positive, radians)."""
    a = ring - np.roll(ring, 1, axis=0)
    b = np.roll(ring, -1, axis=0) - ring
    return np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.sum(a * b, axis=1))


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
        turn = _turns(ring)
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
        if made < MIN_CUTS:  # evenly spaced cuts from loop points
            per = np.cumsum(np.hypot(*(np.roll(ring, -1, axis=0) - ring).T))
            total = float(per[-1])
            start = float(per[corners[0] - 1]) if corners.size and corners[0] > 0 else 0.0
            for k in range(MIN_CUTS):
                s = (start + k * total / MIN_CUTS) % total
                i = int(np.searchsorted(per, s)) % len(ring)
                p = ring[(i + 1) % len(ring)]
                q = foot_of(p)
                if usable(p, q):
                    cuts.append(np.array([p, _snap(core_rings, q, tol, core_inserts)]))
                    feet.append(q)
                    made += 1
        if made < 2:
            raise InputError(f"loop {r}: fewer than two cuts reach the core", where=shape.source)
    for part in parts:  # each part of the core: cut to its holes, or an O-grid block
        mine = [f for f in feet if part.exterior.distance(shapely.Point(f)) <= 1e-7 * ext
                or any(r.distance(shapely.Point(f)) <= 1e-7 * ext for r in part.interiors)]
        if len(part.interiors):
            _hole_cuts(part, core_rings, mine, cuts, core_inserts, tol, d)
        else:
            _block_cuts(part, core_rings, mine, cuts, core_inserts, tol, shape.source)
    all_rings = rings + core_rings
    ins = inserts + [(len(rings) + r, k, f, e) for (r, k, f, e) in core_inserts]
    faces = _faces(all_rings, cuts, ins, [False] * len(cuts), region=region)
    return _layout(shape, faces, "rings", check=False)


def _block_cuts(core, core_rings, feet, cuts, core_inserts, tol, source) -> None:
    """The O-grid of a core without holes: a central block reaching :data:`DISK_BLOCK` of the way
    to four spokes' ends, the feet nearest the directions of the core's principal axes turned by
    45 degrees (appended to ``cuts``)."""
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
    ends = []
    for k in range(4):
        a = base + k * math.pi / 2
        ends.append(cand[int(np.argmin(np.abs((ang - a + math.pi) % (2 * math.pi) - math.pi)))])
    ends_arr = np.unique(np.array(ends), axis=0)
    if ends_arr.shape[0] < 4:
        raise InputError("the core's spokes coincide", where=source)
    ends_arr = ends_arr[np.argsort(np.arctan2(ends_arr[:, 1] - c0[1], ends_arr[:, 0] - c0[0]))]
    block = c0 + DISK_BLOCK * (ends_arr - c0)
    for k in range(4):
        cuts.append(np.array([block[k], block[(k + 1) % 4]]))
        cuts.append(np.array([block[k], _snap(core_rings, ends_arr[k], tol, core_inserts)]))


def _hole_cuts(core, core_rings, feet, cuts, core_inserts, tol, d) -> None:
    """A core with holes cut so that every piece is simply connected: from each of its holes, two
    cuts from the feet on that hole most nearly facing the other loops (at least 90 degrees apart
    around the hole), each along the line from the hole's centre through the foot to the first
    other loop it meets, ending on a foot there when one is within ``d`` (appended to ``cuts``)."""
    shapely = _later.shapely
    part_rings = [np.asarray(r.coords)[:-1] for r in [core.exterior, *core.interiors]]
    ext = float(np.max(np.ptp(part_rings[0], axis=0)))
    far = 4.0 * ext
    feet_arr = np.array(feet) if feet else np.zeros((0, 2))
    loops = [shapely.LinearRing(r) for r in part_rings]
    made = []
    for k in range(1, len(part_rings)):
        ring = part_rings[k]
        c = np.asarray(shapely.Polygon(ring).centroid.coords[0])
        on = feet_arr[[loops[k].distance(shapely.Point(f)) <= 1e-7 * ext for f in feet_arr]] if len(feet_arr) else feet_arr
        chosen = _leave(k, c, on, ring, loops, feet_arr, core, made + cuts, ext, far, d)
        if len(chosen) < 2:
            raise InputError(f"core hole {k}: fewer than two cuts leave it", where=None)
        for _, _, f, end in chosen:
            seg = np.array([_snap(core_rings, f, tol, core_inserts), _snap(core_rings, end, tol, core_inserts)])
            made.append(seg)
            cuts.append(seg)


def _leave(k, c, on, ring, loops, feet_arr, core, others, ext, far, d) -> list:
    """Two cuts out of core hole ``k`` (centre ``c``): from its feet ``on``, else from 16 of its
    points; ``(length, angle, start, end)`` each."""
    shapely = _later.shapely
    for starts in (on, ring[:: max(1, len(ring) // 16)]):
        options = []
        for f in starts:
            u = f - c
            n = float(np.linalg.norm(u))
            if n == 0:
                continue
            ray = shapely.LineString([f + 1e-7 * ext * u / n, f + far * u / n])
            best = None
            for j, lp in enumerate(loops):
                if j == k:
                    continue
                hit = ray.intersection(lp)
                if hit.is_empty:
                    continue
                pts = shapely.get_coordinates(hit)
                dist = np.linalg.norm(pts - f, axis=1)
                i = int(np.argmin(dist))
                if best is None or dist[i] < best[0]:
                    best = (float(dist[i]), pts[i])
            if best is None:
                continue
            end = best[1]
            if len(feet_arr):
                fd = np.linalg.norm(feet_arr - end, axis=1)
                if fd.min() <= d and not np.allclose(feet_arr[int(np.argmin(fd))], f):
                    end = feet_arr[int(np.argmin(fd))]
            seg = shapely.LineString([f, end])
            inner = seg.interpolate(1e-7 * ext).buffer(0) if seg.length == 0 else shapely.LineString(
                [f + 1e-7 * ext * (end - f) / seg.length, end - 1e-7 * ext * (end - f) / seg.length])
            if not core.contains(inner) or any(inner.intersects(shapely.LineString(m)) for m in others):
                continue
            options.append((best[0], math.atan2(u[1], u[0]), f, end))
            options.sort(key=lambda o: o[0])
            chosen = []
            for o in options:
                if all(abs((o[1] - c_[1] + math.pi) % (2 * math.pi) - math.pi) >= math.pi / 2 for c_ in chosen):
                    chosen.append(o)
                if len(chosen) == 2:
                    return chosen
    return []


def hole_ring_layout(shape: Shape, h: float, depth: float = RING_DEPTH) -> Layout:
    """A region with holes: a ring of patches one depth ``depth * h`` wide around every hole (an
    O-grid-like layer: cut at the hole's corners and at evenly spaced points, at least
    :data:`MIN_CUTS`), and the rest of the region cut to the rings by the ``"radial"`` cuts
    (:func:`jaxmatch.placement.decompose._radial_hits`) with the rings' feet as its holes'
    corners. Raises :class:`InputError` when a ring would leave the region or meet another."""
    shapely = _later.shapely
    d = depth * float(h)
    outer = shape.given_points
    region = shapely.Polygon(outer, holes=[np.asarray(x, np.float64) for x in shape.holes])
    boundary = shapely.LinearRing(outer)
    offsets, grown_all, ring_cuts, feet_idx = [], [], [], []
    for k, (hole, hc) in enumerate(zip(shape.holes, shape.hole_corners)):
        hole = np.asarray(hole, np.float64)
        grown = shapely.Polygon(hole).buffer(d, join_style="round", quad_segs=2 * QUAD_SEGMENTS)
        grown = grown.simplify(0.02 * float(h))
        if boundary.distance(grown) < 0.5 * d or any(grown.distance(o) < 0.5 * d for o in grown_all) \
                or not shapely.Polygon(outer).contains(grown):
            raise InputError(f"hole {k + 1}: no room for a ring {d:.4g} wide around it", where=shape.source)
        grown_all.append(grown)
        loop = np.asarray(grown.exterior.coords)[:-1]
        if shapely.LinearRing(loop).is_ccw:  # holes run clockwise
            loop = loop[::-1]
        starts = [int(c) for c in hc]
        if len(starts) < MIN_CUTS:  # evenly spaced hole points, from the first corner on
            per = np.concatenate([[0.0], np.cumsum(np.hypot(*(np.roll(hole, -1, axis=0) - hole).T))])
            first = starts[0] if starts else 0
            s0 = per[first]
            for j in range(MIN_CUTS):
                target = (s0 + j * per[-1] / MIN_CUTS) % per[-1]
                i = int(np.argmin(np.abs(per[:-1] - target)))
                if all(min(abs(i - q), len(hole) - abs(i - q)) > 1 for q in starts):
                    starts.append(i)
        starts = sorted(set(starts))
        feet = []
        for i in starts:
            j = int(np.argmin(np.linalg.norm(loop - hole[i], axis=1)))
            if j in feet:
                raise InputError(f"hole {k + 1}: two ring cuts meet at one point", where=shape.source)
            feet.append(j)
            ring_cuts.append(np.array([hole[i], loop[j]]))
        offsets.append(loop)
        feet_idx.append(feet)
    try:
        rest = make_shape(outer, corners=[int(c) for c in shape.corners], source=shape.source, holes=offsets,
                          hole_corners=feet_idx, checked=True)
    except InputError as e:
        raise InputError(f"the rings around the holes: {e.problem}", where=shape.source) from None
    cuts, inserts = _radial_hits(rest)
    n_holes = len(shape.holes)
    rings = _rings(shape) + [np.asarray(x, np.float64) for x in rest.holes]
    ins = [(0 if r == 0 else n_holes + r, k, f, e) for (r, k, f, e) in inserts]
    for (a, b) in ring_cuts:
        for seg in cuts:
            if shapely.LineString(seg).crosses(shapely.LineString([a, b])):
                raise InputError("a radial cut crosses a hole's ring", where=shape.source)
    faces = _faces(rings, ring_cuts + cuts, ins, [False] * (len(ring_cuts) + len(cuts)), region=region)
    return _layout(shape, faces, "rings", check=False)
