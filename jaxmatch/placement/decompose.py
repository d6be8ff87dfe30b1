"""Split a concave shape into patches at its concave corners, and choose between meshing it with
one template and meshing its patches (:mod:`jaxmatch.placement.layout`).

Cuts (:func:`cut_segments`) start at every concave corner and run straight into the shape to
the first point where they meet its boundary again:

* ``"continuations"``: both sides at the corner, continued past it (a rectilinear shape becomes
  rectangles; every piece is convex, since each reflex angle is split in three);
* ``"bisectors"``: one cut along the bisector of the reflex angle (fewer, larger pieces);
* ``"fillets"``: the continuations, and from both ends of every fillet (a concave rounded stretch
  of the outer loop between straight sides, :func:`fillet_ends`) a cut along the outline's inward
  normal (an L with a filleted inner corner becomes its two legs and the corner block);
* ``"recursive"``: one concave corner at a time, along the shorter continuation of its sides to
  the boundary of the piece it is in, until no piece has a concave corner (fewest pieces; a cut
  may end on an earlier one, a T-junction, which the layout handles).

The outline and the cuts are noded and polygonized with shapely (:func:`decompose`); the pieces
become a :class:`~jaxmatch.placement.layout.Layout` whose corners are the shape's corners and
every point where three or more pieces' edges meet (cut ends and crossings), so that pieces
share their sides whole and the merged mesh is conforming. Every point of the outline is kept,
so the decomposition covers the shape exactly.

The meshing pipeline (:func:`jaxmatch.meshing.pipeline.mesh`) meshes the shape as one patch and
as each decomposition and keeps the best by its one choice rule (:mod:`jaxmatch.meshing.choose`).
"""

from __future__ import annotations

import math

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.arrays import roll
from jaxmatch.geometry import turning_angles
from jaxmatch.placement.layout import Layout, make_layout
from jaxmatch.shape import Shape


__all__ = ["STRATEGIES", "cut_segments", "decompose", "fillet_ends", "same_cuts", "single_patch"]

STRATEGIES = ("continuations", "bisectors", "recursive", "radial", "fillets")
"""The ways :func:`decompose` cuts at concave corners (and, for regions with holes, from the
holes: ``radial`` cuts each hole to the outer loop's convex corners and to its nearest hole)."""



def _rings(shape: Shape) -> list[np.ndarray]:
    """The region's boundary loops, user coordinates: the outer loop (ccw) then each hole (cw);
    the region lies on the left of every loop."""
    return [shape.given_points] + [np.asarray(h, np.float64) for h in shape.holes]


def _reflex_corners(shape: Shape) -> list[tuple[np.ndarray, int]]:
    """``(ring points, index)`` of every corner where the region's angle exceeds 180 degrees:
    the outer loop's concave corners and the holes' corners where the hole is convex."""
    out = [(shape.given_points, int(c)) for c, convex in zip(shape.corners.tolist(), shape.convex.tolist()) if not convex]
    for ring, corners in zip(shape.holes, shape.hole_corners):
        ring = np.asarray(ring, np.float64)
        e_in = ring - roll(ring, 1)
        e_out = roll(ring, -1) - ring
        cross = e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]
        out += [(ring, int(c)) for c in corners if cross[c] < 0]  # a right turn with the region on the left
    return out


FILLET_TURN = 45.0
"""Degrees: a fillet (:func:`fillet_ends`) turns the outline by at least this much."""

FILLET_TANGENT = 4.0
"""A fillet meets a straight side at each end: the outline's edges just before and after it are at
least this many times the fillet's longest edge."""


def fillet_ends(shape: Shape) -> list[tuple[int, int]]:
    """``(a, b)`` outer-loop point indices of the first and last point of every fillet: a run of
    consecutive points of ``shape.given_points`` that are no corners and turn right (concave, the
    loop being counter-clockwise), turning by :data:`FILLET_TURN` degrees or more in all, between
    edges :data:`FILLET_TANGENT` times longer than its own (straight sides, not a curved stretch
    that ends at a corner)."""
    pts = shape.given_points
    P = pts.shape[0]
    turn = np.degrees(turning_angles(pts))
    concave = turn < -1e-6
    concave[shape.corners] = False
    if concave.all() or not concave.any():
        return []
    seg = np.linalg.norm(roll(pts, -1) - pts, axis=1)  # seg[i]: from point i to i + 1
    out = []
    starts = [i for i in range(P) if concave[i] and not concave[i - 1]]
    for a in starts:
        b = a
        while concave[(b + 1) % P]:
            b += 1
        run = np.arange(a, b + 1) % P
        if b == a or turn[run].sum() > -FILLET_TURN:
            continue
        longest = float(seg[run[:-1]].max())
        if min(seg[(a - 1) % P], seg[b % P]) >= FILLET_TANGENT * longest:
            out.append((a % P, b % P))
    return out


def _fillet_rays(shape: Shape) -> list[tuple[np.ndarray, np.ndarray]]:
    """From both ends of every fillet (:func:`fillet_ends`), the inward normal of the straight
    side it meets there."""
    pts = shape.given_points
    P = pts.shape[0]
    out = []
    for a, b in fillet_ends(shape):
        for v, e in ((pts[a], pts[a] - pts[(a - 1) % P]), (pts[b], pts[(b + 1) % P] - pts[b])):
            n = np.array([-e[1], e[0]]) / np.linalg.norm(e)  # the left normal: into the region
            out.append((v, n))
    return out


def _axis_rays(ring: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Four cuts from a hole without corners: from its leftmost, rightmost, lowest and highest
    points, outwards along the axes (a round hole in a square becomes four patches)."""
    out = []
    for axis, sign in ((0, -1.0), (0, 1.0), (1, -1.0), (1, 1.0)):
        i = int(np.argmax(sign * ring[:, axis]))
        d = np.zeros(2)
        d[axis] = sign
        out.append((ring[i], d))
    return out


def _rays(shape: Shape, strategy: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """(start (2,), unit direction (2,)) of every cut, user coordinates."""
    if strategy not in ("continuations", "bisectors", "fillets"):
        raise ValueError(f"strategy must be 'continuations', 'bisectors' or 'fillets', got {strategy!r}")
    out = _fillet_rays(shape) if strategy == "fillets" else []
    for pts, c in _reflex_corners(shape):
        P = pts.shape[0]
        v, prev, nxt = pts[c], pts[(c - 1) % P], pts[(c + 1) % P]
        u1 = (prev - v) / np.linalg.norm(prev - v)
        u2 = (nxt - v) / np.linalg.norm(nxt - v)
        if strategy in ("continuations", "fillets"):
            dirs = [-u1, -u2]
        else:
            b = -(u1 + u2)
            dirs = [b / np.linalg.norm(b)] if np.linalg.norm(b) > 1e-12 else [np.array([u1[1], -u1[0]])]
        out += [(v, d) for d in dirs]
    for ring, corners in zip(shape.holes, shape.hole_corners):
        if len(corners) == 0:
            out += _axis_rays(np.asarray(ring, np.float64))
    return out


def _snap(rings: list[np.ndarray], end: np.ndarray, tol: float, inserts: list) -> np.ndarray:
    """``end`` on a boundary loop: moved onto a loop point within ``tol`` (the first loop's that
    has one), else recorded in ``inserts`` as ``(ring, segment index, fraction along it, point)``
    of the nearest segment (:func:`_snap_all` of one end)."""
    return _snap_all(rings, np.asarray(end, np.float64).reshape(1, 2), tol, inserts)[0]


def _snap_all(rings: list[np.ndarray], ends: np.ndarray, tol: float, inserts: list) -> list[np.ndarray]:
    """Each of ``ends (n, 2)`` on a boundary loop, in order (:func:`_snap`), the distances to
    every loop computed for all of them at once: a list of ``(2,)`` points, ``inserts`` appended
    to for the ends that no loop point is within ``tol`` of."""
    if not len(ends):
        return []
    snapped: list = [None] * len(ends)
    best = [None] * len(ends)
    for r, pts in enumerate(rings):
        near = np.linalg.norm(pts[None, :, :] - ends[:, None, :], axis=2)  # (n, P)
        j = np.argmin(near, axis=1)
        a, b = pts, roll(pts, -1)
        ab = b - a
        f = np.clip(np.sum((ends[:, None, :] - a) * ab, axis=2) / np.sum(ab * ab, axis=1), 0.0, 1.0)  # (n, P)
        d = np.linalg.norm(a + f[:, :, None] * ab - ends[:, None, :], axis=2)
        k = np.argmin(d, axis=1)
        for e in range(len(ends)):
            if snapped[e] is not None:
                continue
            if near[e, j[e]] <= tol:
                snapped[e] = pts[j[e]]
            elif best[e] is None or d[e, k[e]] < best[e][0]:
                best[e] = (float(d[e, k[e]]), r, int(k[e]), float(f[e, k[e]]))
    for e in range(len(ends)):
        if snapped[e] is None:
            _, r, k, f = best[e]
            inserts.append((r, k, f, ends[e]))
            snapped[e] = ends[e]
    return snapped


def _hits(shape: Shape, strategy: str) -> tuple[list[np.ndarray], list[tuple[int, int, float, np.ndarray]]]:
    """Cuts (``(2, 2)`` segments) and where they end on a boundary loop: ``(ring, segment index,
    fraction along it, point)`` for ends inside a loop segment (ends within ``1e-9`` of the
    extent of a loop point are moved onto that point)."""
    import shapely

    rings = _rings(shape)
    boundary = shapely.MultiLineString([np.vstack([r, r[:1]]) for r in rings])
    pts = rings[0]
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    tol = 1e-9 * extent
    far = 4.0 * extent
    cuts: list[np.ndarray] = []
    inserts: list[tuple[int, int, float, np.ndarray]] = []
    rays = _rays(shape, strategy)
    if not rays:
        return cuts, inserts
    starts = np.array([v for v, _ in rays])
    dirs = np.array([d for _, d in rays])
    hits = shapely.intersection(boundary, shapely.linestrings(np.stack([starts, starts + far * dirs], axis=1)))
    coords, which = shapely.get_coordinates(hits, return_index=True)  # every ray's crossings at once
    found = []  # (ray, its first crossing beyond tol)
    for r, (v, d) in enumerate(zip(starts, dirs)):
        c = coords[which == r]
        dist = (c - v) @ d
        ok = dist > tol
        if ok.any():
            found.append((r, c[ok][np.argmin(dist[ok])]))
    ends = _snap_all(rings, np.array([e for _, e in found]).reshape(-1, 2), tol, inserts)
    for (r, _), end in zip(found, ends):
        v = starts[r]
        seg = np.array([v, end])
        if not _close_to_any(seg, cuts, tol):  # (the same cut found twice, or from its other end)
            cuts.append(seg)
    return cuts, inserts


def _close_to_any(seg: np.ndarray, cuts: list[np.ndarray], tol: float) -> bool:
    """Whether the cut ``seg (2, 2)`` is ``np.allclose`` (``atol=tol``, its default ``rtol``
    1e-5) to one of ``cuts`` (each ``(2, 2)``) or to one reversed: all pairs at once, without
    ``np.allclose``'s per-call overhead."""
    if not cuts:
        return False
    C = np.asarray(cuts)
    return any(bool((np.abs(seg - other) <= tol + 1e-5 * np.abs(other)).all(axis=(1, 2)).any())
               for other in (C, C[:, ::-1]))


def _toward(ring: np.ndarray, corners: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The point of a hole ``ring`` that faces ``target``: the hole corner seen from the hole's
    centroid in the direction closest to ``target``'s, or, for a hole without corners, where
    the ray from the centroid towards ``target`` leaves the ring."""
    import shapely

    c = np.asarray(shapely.Polygon(ring).centroid.coords[0])
    d = target - c
    d = d / (np.linalg.norm(d) or 1.0)
    if len(corners):
        u = ring[corners] - c
        cos = (u @ d) / np.maximum(np.linalg.norm(u, axis=1), 1e-300)
        return ring[corners[int(np.argmax(cos))]]
    far = 4.0 * float(np.max(np.ptp(ring, axis=0)))
    hit = shapely.get_coordinates(shapely.LinearRing(ring).intersection(shapely.LineString([c, c + far * d])))
    if not len(hit):  # pragma: no cover - a centroid outside its (non-star) hole
        return ring[int(np.argmax((ring - c) @ d))]
    return hit[int(np.argmax((hit - c) @ d))]


def _radial_hits(shape: Shape) -> tuple[list[np.ndarray], list]:
    """The ``radial`` cuts: the concave corners' continuations (as ``continuations``), then
    from each hole to every convex corner of the outer loop for which that hole is the nearest
    one seen without crossing another loop, and between each hole and its nearest hole (along
    the line of their centroids) when the segment stays inside the region."""
    import shapely

    rings = _rings(shape)
    extent = float(np.max(np.ptp(rings[0], axis=0)))
    tol = 1e-9 * extent
    region = shapely.Polygon(rings[0], holes=rings[1:])
    cuts, inserts = [], []
    for v, d in [(v, d) for v, d in _rays_continuations(shape)]:
        end = _first_hit(rings, v, d, tol)
        if end is not None:
            cuts.append(np.array([v, _snap(rings, end, tol, inserts)]))
    holes = [np.asarray(h, np.float64) for h in shape.holes]

    def inside(a, b) -> bool:
        d = b - a
        n = float(np.linalg.norm(d))
        if n <= 10 * tol:
            return False
        shrink = 1e-7 * extent / n
        return bool(region.contains(shapely.LineString([a + shrink * d, b - shrink * d])))

    outer = rings[0]
    for c, convex in zip(shape.corners.tolist(), shape.convex.tolist()):
        if not convex:
            continue
        corner = outer[c]
        best = None
        for k, (ring, hc) in enumerate(zip(holes, shape.hole_corners)):
            p = _toward(ring, np.asarray(hc, np.int64), corner)
            dist = float(np.linalg.norm(corner - p))
            if inside(p, corner) and (best is None or dist < best[0]):
                best = (dist, p)
        if best is not None:
            cuts.append(np.array([_snap(rings, best[1], tol, inserts), corner]))
    cents = [np.asarray(shapely.Polygon(h).centroid.coords[0]) for h in holes]
    pairs = set()
    for k in range(len(holes)):
        others = [j for j in range(len(holes)) if j != k]
        if not others:
            break
        j = min(others, key=lambda j: float(np.linalg.norm(cents[j] - cents[k])))
        if (min(j, k), max(j, k)) in pairs:
            continue
        pairs.add((min(j, k), max(j, k)))
        a = _toward(holes[k], np.asarray(shape.hole_corners[k], np.int64), cents[j])
        b = _toward(holes[j], np.asarray(shape.hole_corners[j], np.int64), cents[k])
        if inside(a, b):
            cuts.append(np.array([_snap(rings, a, tol, inserts), _snap(rings, b, tol, inserts)]))
    return cuts, inserts


def _rays_continuations(shape: Shape) -> list[tuple[np.ndarray, np.ndarray]]:
    """The continuation rays of the outer loop's concave corners only."""
    pts = shape.given_points
    P = pts.shape[0]
    out = []
    for c, convex in zip(shape.corners.tolist(), shape.convex.tolist()):
        if convex:
            continue
        v, prev, nxt = pts[c], pts[(c - 1) % P], pts[(c + 1) % P]
        out += [(v, -(prev - v) / np.linalg.norm(prev - v)), (v, -(nxt - v) / np.linalg.norm(nxt - v))]
    return out


def _first_hit(rings: list[np.ndarray], v: np.ndarray, d: np.ndarray, tol: float) -> np.ndarray | None:
    """Where the ray from ``v`` along ``d`` first meets a boundary loop (beyond ``tol``), or None."""
    import shapely

    boundary = shapely.MultiLineString([np.vstack([r, r[:1]]) for r in rings])
    far = 4.0 * float(np.max(np.ptp(rings[0], axis=0)))
    coords = shapely.get_coordinates(boundary.intersection(shapely.LineString([v, v + far * d])))
    dist = (coords - v) @ d
    ok = dist > tol
    return coords[ok][np.argmin(dist[ok])] if ok.any() else None


def cut_segments(shape: Shape, strategy: str = "continuations") -> list[np.ndarray]:
    """The cuts of ``strategy`` as ``(2, 2) float64`` segments (user coordinates): from a concave
    corner to the first point beyond it where the ray meets the outline (an outline point when
    within ``1e-9`` of the shape's extent of one). Duplicates (the same cut from both of its
    ends) are dropped."""
    return _hits(shape, strategy)[0]


def single_patch(shape: Shape) -> Layout:
    """The shape as a layout of one patch (its corners as given). Raises :class:`InputError`
    for a shape with fewer than 2 corners (a layout patch needs 2; such a shape has no concave
    corner either: mesh it whole with :func:`jaxmatch.placement.refine.refine_mesh`)."""
    if shape.holes:
        raise InputError(f"a region with {len(shape.holes)} hole(s) is not one patch: it is cut into patches",
                         where=shape.source)
    if shape.n_corners < 2:
        raise InputError(f"the shape has {shape.n_corners} corner(s); a patch needs at least 2 (a shape without "
                         "concave corners is meshed whole by 'jaxmatch mesh --size')", where=shape.source)
    pts = shape.given_points  # (a Shape's loop: simple, of distinct points; make_layout's geometric checks would pass)
    return make_layout(pts.tolist(), [list(range(pts.shape[0]))], shape.corners.tolist(), source=shape.source,
                       check=False)


def _faces(rings: list[np.ndarray], cuts: list[np.ndarray], inserts: list, overshoot: list[bool], region=None) -> list:
    """The pieces (shapely Polygons) of the region bounded by ``rings`` (the outer loop, then the
    holes) cut by ``cuts``: cut ends listed in ``inserts`` (``(ring, segment, fraction, point)``)
    become loop points exactly; cuts flagged in ``overshoot`` (ending on an earlier cut) are
    extended by ``1e-7`` of the extent so that noding finds the crossing (the stub outside is a
    dangle that polygonize drops). A piece may keep a hole that no cut reaches."""
    import shapely

    pts = rings[0]
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    at: dict[tuple[int, int], list] = {}  # the inserts of each loop segment, in their order
    for i in inserts:
        at.setdefault((i[0], i[1]), []).append(i)
    lines = []
    for r, ring in enumerate(rings):  # each loop with the cut ends inserted (exact end points)
        if any(key[0] == r for key in at):
            ring_pts = []
            for k in range(ring.shape[0]):
                ring_pts.append(ring[k])
                if (r, k) in at:
                    ring_pts += [e for _, _, _, e in sorted(at[r, k], key=lambda i: i[2])]
            ring = np.array(ring_pts)
        lines.append(shapely.linestrings(np.vstack([ring, ring[:1]])))
    if cuts:
        ends = np.array(cuts, np.float64)  # (n, 2, 2)
        for j, over in enumerate(overshoot):
            if over:
                a, b = ends[j, 0], cuts[j][1]
                ends[j, 1] = b + 1e-7 * extent * (b - a) / np.linalg.norm(b - a)
        lines += list(shapely.linestrings(ends))
    noded = shapely.union_all(lines)
    if region is None:  # (the region as a shapely Polygon, when the caller has it)
        region = shapely.Polygon(rings[0], holes=rings[1:])
    faces = list(shapely.get_parts(shapely.polygonize(shapely.get_parts(noded))))
    inside = shapely.contains(region, shapely.point_on_surface(np.array(faces, dtype=object))) if faces else []
    return [f for f, ok in zip(faces, inside) if ok]


def _corner_points(shape: Shape) -> np.ndarray:
    """``(C, 2)`` the region's corners in user coordinates: the outer loop's, then the holes'."""
    parts = [shape.given_points[shape.corners]] + [np.asarray(h, np.float64)[c] for h, c in zip(shape.holes, shape.hole_corners)]
    return np.concatenate(parts) if parts else np.zeros((0, 2))


def _layout(shape: Shape, faces: list, name: str, check: bool = True) -> Layout:
    """A :class:`Layout` of the pieces: corners are the shape's corners and every point where
    three or more piece edges meet (``check``: as :func:`~jaxmatch.placement.layout.make_layout`'s)."""
    import shapely

    index: dict[tuple[float, float], int] = {}
    points: list[tuple[float, float]] = []
    loops: list[list[int]] = []
    edges: set[tuple[int, int]] = set()
    if faces and np.any(shapely.get_num_interior_rings(faces) > 0):
        raise InputError(f"a hole is not reached by any {name} cut (a piece would keep it)", where=shape.source)
    xy, which = shapely.get_coordinates(shapely.get_exterior_ring(faces), return_index=True) if faces else \
        (np.zeros((0, 2)), np.zeros(0, np.int64))
    ends = np.flatnonzero(np.diff(which)).tolist() + [len(which) - 1]  # each ring's closing point (its first again)
    xy = xy.tolist()
    start = 0
    for end in ends:
        loop = []
        for x, y in xy[start:end]:
            if (x, y) not in index:
                index[(x, y)] = len(points)
                points.append((x, y))
            loop.append(index[(x, y)])
        start = end + 1
        loops.append(loop)
        edges.update((a, b) if a < b else (b, a) for a, b in zip(loop, loop[1:] + loop[:1]))
    nbrs = [0] * len(points)
    for a, b in edges:
        nbrs[a] += 1
        nbrs[b] += 1
    shape_corners = {tuple(p) for p in _corner_points(shape).tolist()}
    corners = [i for i, p in enumerate(points) if p in shape_corners or nbrs[i] >= 3]
    return make_layout(points, loops, corners, source=f"{shape.source} ({name} cuts)", check=check)


def _recursive(shape: Shape, check: bool = True) -> Layout:
    """Cut one concave corner at a time, along the shorter continuation of its two sides to the
    boundary of the piece it is in (an earlier cut, or the outline), until no piece has a
    concave corner."""
    import shapely

    pts = shape.given_points
    ring = shapely.LinearRing(pts)
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    tol = 1e-9 * extent
    cuts: list[np.ndarray] = []
    inserts: list = []
    over: list[bool] = []
    faces = None  # the pieces of the cuts so far (None: not yet cut into them)
    region = shapely.Polygon(pts)
    for _ in range(int((~shape.convex).sum()) + 1):
        faces = _faces([pts], cuts, inserts, over, region)
        found = None
        for f in faces:
            f = shapely.orient_polygons(f) if hasattr(shapely, "orient_polygons") else shapely.geometry.polygon.orient(f)
            xy = np.asarray(f.exterior.coords)[:-1]
            e_in, e_out = xy - roll(xy, 1), roll(xy, -1) - xy
            turn = np.arctan2(e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0], np.sum(e_in * e_out, axis=1))
            reflex = np.flatnonzero(turn < -1e-9)
            if reflex.size:
                found = (f, xy, int(reflex[0]))
                break
        if found is None:
            break
        f, xy, i = found
        v = xy[i]
        best = None
        for d in (e_in[i] / np.linalg.norm(e_in[i]), -e_out[i] / np.linalg.norm(e_out[i])):
            hit = f.exterior.intersection(shapely.LineString([v, v + 4.0 * extent * d]))
            c = shapely.get_coordinates(hit)
            dist = (c - v) @ d
            ok = dist > tol
            if ok.any() and (best is None or dist[ok].min() < best[0]):
                best = (float(dist[ok].min()), c[ok][np.argmin(dist[ok])])
        if best is None:  # pragma: no cover - a reflex vertex always sees the boundary
            break
        end = best[1]
        near = np.linalg.norm(pts - end, axis=1)
        j = int(np.argmin(near))
        if near[j] <= tol:
            end, on_cut = pts[j], False
        elif ring.distance(shapely.Point(end)) <= tol:
            a, b = pts, roll(pts, -1)
            ab = b - a
            fr = np.clip(np.sum((end - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
            k = int(np.argmin(np.linalg.norm(a + fr[:, None] * ab - end, axis=1)))
            inserts.append((0, k, float(fr[k]), end))
            on_cut = False
        else:
            on_cut = True
        cuts.append(np.array([v, end]))
        over.append(on_cut)
        faces = None
    if faces is None:  # (the loop ran out with a cut made after its last pieces)
        faces = _faces([pts], cuts, inserts, over, region)
    return _layout(shape, faces, "recursive", check)


def same_cuts(shape: Shape, strategy: str) -> str | None:
    """The strategy whose cuts :func:`decompose` makes in ``shape`` for ``strategy`` (the same
    patches; only the layout's ``source`` names the strategy): ``"continuations"`` for
    ``"fillets"`` without a fillet; None (no cut, the shape whole, :func:`single_patch`) for
    every strategy when the shape has no hole, no concave corner and no fillet,
    ``"continuations"`` for ``"radial"`` without holes (its cuts are then the concave corners'
    continuations alone), else ``strategy``."""
    if strategy == "fillets" and not fillet_ends(shape):
        strategy = "continuations"
    if not shape.holes:
        if bool(np.all(shape.convex)) and strategy != "fillets":
            return None
        if strategy == "radial":
            return "continuations"
    return strategy


def decompose(shape: Shape, strategy: str = "continuations", *, check: bool = True) -> Layout:
    """Split ``shape`` into a :class:`Layout`: by the cuts of ``strategy`` (:func:`cut_segments`,
    all at once), or, for ``"recursive"``, one concave corner at a time along the shorter
    continuation of its sides to the piece's boundary (later cuts may end on earlier ones:
    T-junctions). A shape without concave corners gives one patch. Raises
    :class:`InputError` when the pieces do not make a valid layout (``check=False``: the
    geometric checks are left to :func:`~jaxmatch.placement.layout.check_layout`)."""
    if strategy == "recursive":
        if shape.holes:
            raise InputError("recursive cuts are for regions without holes", where=shape.source)
        if not (~shape.convex).any():
            return single_patch(shape)
        return _recursive(shape, check)
    cuts, inserts = _radial_hits(shape) if strategy == "radial" else _hits(shape, strategy)
    if not cuts:
        return single_patch(shape)
    return _layout(shape, _faces(_rings(shape), cuts, inserts, [False] * len(cuts)), strategy, check)


DISK_BLOCK = 0.5
"""The central block of :func:`disk_layout` reaches this fraction of the way from the centre
to the outline."""


def disk_layout(shape: Shape) -> Layout:
    """A region with fewer than two corners (a disk, an ellipse, a teardrop) as five patches: a
    central block and four patches between it and the outline (an O-grid), so that a quad mesh
    of it needs no irregular vertex but the block's corners' neighbours.

    The outline is split at four points, the directions from its centroid along its principal
    axes turned by 45 degrees (a single corner, if any, is one of them); the block's corners lie
    :data:`DISK_BLOCK` of the way from the centroid to those points. Split points that are not
    outline points are inserted exactly on the outline."""
    import shapely

    pts = shape.given_points
    poly = shapely.Polygon(pts)
    c = np.asarray(poly.centroid.coords[0])
    d = pts - c
    cov = d.T @ d
    _, vec = np.linalg.eigh(cov)
    major = vec[:, -1]
    base = math.atan2(major[1], major[0]) + math.pi / 4
    if shape.n_corners == 1:
        v = pts[shape.corners[0]] - c
        base = math.atan2(v[1], v[0])
    far = 4.0 * float(np.max(np.ptp(pts, axis=0)))
    ring = shapely.LinearRing(pts)
    ext = float(np.max(np.ptp(pts, axis=0)))
    tol = 1e-9 * ext
    inserts, splits = [], []
    for k in range(4):
        a = base + k * math.pi / 2
        u = np.array([math.cos(a), math.sin(a)])
        hit = shapely.get_coordinates(ring.intersection(shapely.LineString([c, c + far * u])))
        if not len(hit):
            raise InputError("the outline is not star-shaped around its centroid", where=shape.source)
        end = hit[int(np.argmax((hit - c) @ u))]
        if k == 0 and shape.n_corners == 1:
            end = pts[shape.corners[0]]
        splits.append(_snap([pts], end, tol, inserts))
    ring_pts = []
    for k in range(pts.shape[0]):
        ring_pts.append(pts[k])
        ring_pts += [e for _, kk, _, e in sorted((i for i in inserts if i[1] == k), key=lambda i: i[2])]
    ring_pts = np.array(ring_pts)
    idx = [int(np.argmin(np.linalg.norm(ring_pts - b, axis=1))) for b in splits]
    if len(set(idx)) < 4:
        raise InputError("the outline's split points coincide", where=shape.source)
    order = sorted(range(4), key=lambda k: (idx[k] - idx[0]) % len(ring_pts))
    idx = [idx[k] for k in order]
    block = [c + DISK_BLOCK * (ring_pts[i] - c) for i in idx]
    n = len(ring_pts)
    points = ring_pts.tolist() + [b.tolist() for b in block]
    q = list(range(n, n + 4))
    patches = [q]
    for k in range(4):
        i, j = idx[k], idx[(k + 1) % 4]
        arc = [(i + t) % n for t in range(((j - i) % n) + 1)]
        patches.append(arc + [q[(k + 1) % 4], q[k]])
    corners = idx + q + [int(np.argmin(np.linalg.norm(ring_pts - pts[c0], axis=1))) for c0 in shape.corners]
    return make_layout(points, patches, sorted(set(corners)), source=f"{shape.source} (disk)")


def _same(a: Layout, b: Layout) -> bool:
    if a.n_patches != b.n_patches or a.points.shape != b.points.shape:
        return False
    return bool(np.array_equal(a.points, b.points)) and all(np.array_equal(x, y) for x, y in zip(a.patches, b.patches))
