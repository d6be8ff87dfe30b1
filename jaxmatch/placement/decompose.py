"""Split a concave shape into patches at its concave corners, and choose between meshing it with
one template and meshing its patches (:mod:`jaxmatch.placement.layout`).

Cuts (:func:`cut_segments`) start at every concave corner and run straight into the shape to
the first point where they meet its boundary again:

* ``"continuations"``: both sides at the corner, continued past it (a rectilinear shape becomes
  rectangles; every piece is convex, since each reflex angle is split in three);
* ``"bisectors"``: one cut along the bisector of the reflex angle (fewer, larger pieces);
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

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.placement.layout import Layout, make_layout
from jaxmatch.shape import Shape


__all__ = ["STRATEGIES", "cut_segments", "decompose", "single_patch"]

STRATEGIES = ("continuations", "bisectors", "recursive")
"""The ways :func:`decompose` cuts at concave corners."""



def _xy(shape: Shape) -> np.ndarray:
    """``(P, 2)`` the shape's points in user coordinates, exactly as given when known."""
    return shape.input_points if shape.input_points is not None else shape.user_points


def _rays(shape: Shape, strategy: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """(start (2,), unit direction (2,)) of every cut, user coordinates."""
    if strategy not in ("continuations", "bisectors"):
        raise ValueError(f"strategy must be 'continuations' or 'bisectors', got {strategy!r}")
    pts = _xy(shape)
    P = pts.shape[0]
    out = []
    for c, convex in zip(shape.corners.tolist(), shape.convex.tolist()):
        if convex:
            continue
        v, prev, nxt = pts[c], pts[(c - 1) % P], pts[(c + 1) % P]
        u1 = (prev - v) / np.linalg.norm(prev - v)
        u2 = (nxt - v) / np.linalg.norm(nxt - v)
        if strategy == "continuations":
            dirs = [-u1, -u2]
        else:
            b = -(u1 + u2)
            dirs = [b / np.linalg.norm(b)] if np.linalg.norm(b) > 1e-12 else [np.array([u1[1], -u1[0]])]
        out += [(v, d) for d in dirs]
    return out


def _hits(shape: Shape, strategy: str) -> tuple[list[np.ndarray], list[tuple[int, float, np.ndarray]]]:
    """Cuts (``(2, 2)`` segments) and where they end on the outline: ``(segment index, fraction
    along it, point)`` for ends inside an outline segment (ends within ``1e-9`` of the extent of
    an outline point are moved onto that point)."""
    import shapely

    pts = _xy(shape)
    ring = shapely.LinearRing(pts)
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    tol = 1e-9 * extent
    far = 4.0 * extent
    cuts: list[np.ndarray] = []
    inserts: list[tuple[int, float, np.ndarray]] = []
    for v, d in _rays(shape, strategy):
        hit = ring.intersection(shapely.LineString([v, v + far * d]))
        coords = shapely.get_coordinates(hit)
        dist = (coords - v) @ d
        ok = dist > tol
        if not ok.any():
            continue
        end = coords[ok][np.argmin(dist[ok])]
        near = np.linalg.norm(pts - end, axis=1)
        j = int(np.argmin(near))
        if near[j] <= tol:
            end = pts[j]
        else:  # inside an outline segment: the nearest one
            a, b = pts, np.roll(pts, -1, axis=0)
            ab = b - a
            f = np.clip(np.sum((end - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
            k = int(np.argmin(np.linalg.norm(a + f[:, None] * ab - end, axis=1)))
            inserts.append((k, float(f[k]), end))
        seg = np.array([v, end])
        if any(np.allclose(seg, c[::-1], atol=tol) or np.allclose(seg, c, atol=tol) for c in cuts):
            continue
        cuts.append(seg)
    return cuts, inserts


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
    if shape.n_corners < 2:
        raise InputError(f"the shape has {shape.n_corners} corner(s); a patch needs at least 2 (a shape without "
                         "concave corners is meshed whole by 'jaxmatch mesh --size')", where=shape.source)
    pts = _xy(shape)
    return make_layout(pts.tolist(), [list(range(pts.shape[0]))], shape.corners.tolist(), source=shape.source)


def _faces(pts: np.ndarray, cuts: list[np.ndarray], inserts: list, overshoot: list[bool]) -> list:
    """The pieces (shapely Polygons) of the outline ``pts`` cut by ``cuts``: cut ends listed in
    ``inserts`` become outline points exactly; cuts flagged in ``overshoot`` (ending on an
    earlier cut) are extended by ``1e-7`` of the extent so that noding finds the crossing (the
    stub outside is a dangle that polygonize drops)."""
    import shapely
    from shapely.ops import polygonize

    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    ring_pts = []
    for k in range(pts.shape[0]):  # the outline with the cut ends inserted (exact end points)
        ring_pts.append(pts[k])
        ring_pts += [e for _, _, e in sorted((i for i in inserts if i[0] == k), key=lambda i: i[1])]
    ring_pts = np.array(ring_pts)
    lines = [shapely.LineString(np.vstack([ring_pts, ring_pts[:1]]))]
    for (a, b), over in zip(cuts, overshoot):
        if over:
            b = b + 1e-7 * extent * (b - a) / np.linalg.norm(b - a)
        lines.append(shapely.LineString([a, b]))
    noded = shapely.union_all(lines)
    outline = shapely.Polygon(pts)
    return [f for f in polygonize(shapely.get_parts(noded)) if outline.contains(f.representative_point())]


def _layout(shape: Shape, faces: list, name: str) -> Layout:
    """A :class:`Layout` of the pieces: corners are the shape's corners and every point where
    three or more piece edges meet."""
    pts = _xy(shape)
    index: dict[tuple[float, float], int] = {}
    points: list[tuple[float, float]] = []
    loops: list[list[int]] = []
    edges: set[frozenset] = set()
    for f in faces:
        loop = []
        for x, y in np.asarray(f.exterior.coords)[:-1].tolist():
            if (x, y) not in index:
                index[(x, y)] = len(points)
                points.append((x, y))
            loop.append(index[(x, y)])
        loops.append(loop)
        edges.update(frozenset((a, b)) for a, b in zip(loop, loop[1:] + loop[:1]))
    nbrs = np.zeros(len(points), np.int64)
    for e in edges:
        for v in e:
            nbrs[v] += 1
    shape_corners = {tuple(p) for p in pts[shape.corners].tolist()}
    corners = [i for i, p in enumerate(points) if p in shape_corners or nbrs[i] >= 3]
    return make_layout([list(p) for p in points], loops, corners, source=f"{shape.source} ({name} cuts)")


def _recursive(shape: Shape) -> Layout:
    """Cut one concave corner at a time, along the shorter continuation of its two sides to the
    boundary of the piece it is in (an earlier cut, or the outline), until no piece has a
    concave corner."""
    import shapely

    pts = _xy(shape)
    ring = shapely.LinearRing(pts)
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    tol = 1e-9 * extent
    cuts: list[np.ndarray] = []
    inserts: list = []
    over: list[bool] = []
    for _ in range(int((~shape.convex).sum()) + 1):
        faces = _faces(pts, cuts, inserts, over)
        found = None
        for f in faces:
            f = shapely.orient_polygons(f) if hasattr(shapely, "orient_polygons") else shapely.geometry.polygon.orient(f)
            xy = np.asarray(f.exterior.coords)[:-1]
            e_in, e_out = xy - np.roll(xy, 1, axis=0), np.roll(xy, -1, axis=0) - xy
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
            a, b = pts, np.roll(pts, -1, axis=0)
            ab = b - a
            fr = np.clip(np.sum((end - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
            k = int(np.argmin(np.linalg.norm(a + fr[:, None] * ab - end, axis=1)))
            inserts.append((k, float(fr[k]), end))
            on_cut = False
        else:
            on_cut = True
        cuts.append(np.array([v, end]))
        over.append(on_cut)
    return _layout(shape, _faces(pts, cuts, inserts, over), "recursive")


def decompose(shape: Shape, strategy: str = "continuations") -> Layout:
    """Split ``shape`` into a :class:`Layout`: by the cuts of ``strategy`` (:func:`cut_segments`,
    all at once), or, for ``"recursive"``, one concave corner at a time along the shorter
    continuation of its sides to the piece's boundary (later cuts may end on earlier ones:
    T-junctions). A shape without concave corners gives one patch. Raises
    :class:`InputError` when the pieces do not make a valid layout."""
    if strategy == "recursive":
        if not (~shape.convex).any():
            return single_patch(shape)
        return _recursive(shape)
    pts = _xy(shape)
    cuts, inserts = _hits(shape, strategy)
    if not cuts:
        return single_patch(shape)
    return _layout(shape, _faces(pts, cuts, inserts, [False] * len(cuts)), strategy)


def _same(a: Layout, b: Layout) -> bool:
    if a.n_patches != b.n_patches or a.points.shape != b.points.shape:
        return False
    return bool(np.array_equal(a.points, b.points)) and all(np.array_equal(x, y) for x, y in zip(a.patches, b.patches))
