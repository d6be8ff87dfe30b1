"""An assembly (a :class:`~jaxmatch.model.Model`: named regions, embedded points and curves)
meshed as one conforming quad mesh.

1. **Pieces.** Each region is cut along the embedded curves inside it, each curve extended
   straight from an end inside the region to the region's boundary (shapely's polygonize); the
   pieces of one region keep its name. Every piece's loops get the points of the other pieces
   that lie on them (a corner of one region on another's side becomes a point of both; it is
   no corner of the other, which runs straight there).
2. **Each piece's strategy.** Each piece is meshed on its own by the pipeline
   (:func:`jaxmatch.meshing.pipeline.mesh`: every candidate, the one choice rule) and the layout
   of the candidate that won is made again (the single patch, a decomposition, the ring
   partition or the disk's O-grid).
3. **One solve.** The pieces' layouts are merged into one layout (coincident points one point;
   a point of one layout on a patch side of another inserted there: a T-junction, where the
   patches along the side change) and meshed by the one solve
   (:func:`jaxmatch.placement.solve.mesh_layout`): ONE integer program for every side count of
   every patch of every region, so an interface side has one count and one set of vertices for
   both its regions; the merge gives each side's vertices one id (no hanging node;
   :func:`~jaxmatch.placement.layout.check_layout` refuses a layout that would have one).
4. **Smoothing and embedded points.** The merged mesh is smoothed with the outline, the holes,
   every interface and every embedded curve kept; then each embedded point (and each curve end
   inside a region) becomes a vertex: the nearest vertex free to move there (on the same side,
   for a point on a side) is moved onto it and the mesh smoothed again around it.

The result is the one :class:`~jaxmatch.meshing.result.QuadMesh`: ``patch`` is the region of each
quad and ``regions`` their names (each region a cell group named after it), line groups
``boundary``, ``hole h`` (holes of the union), ``NAME1|NAME2`` (names sorted) per interface,
``NAME side i-j`` per side of each region (from its corner ``i`` to ``i + 1``, numbered in the
file's order; on the outline or an interface) and ``curve k`` per embedded curve, and vertex groups ``point k`` per embedded point.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple, Sequence

import numpy as np

from jaxmatch.defaults import DEFAULT_DIVISIONS, DEFAULT_LATTICE, QUALITY, Quality
from jaxmatch.errors import InputError, InputWarning
from jaxmatch.geometry import turning_angles
from jaxmatch.inputs import _lattice, load_catalogue
from jaxmatch.meshing.build import from_layout
from jaxmatch.meshing.region import canonical, corner_points, default_size
from jaxmatch.meshing.result import Candidate, QuadMesh
from jaxmatch.meshing.strategies import DISK, FINER, LEAN, SINGLE, TRANSITIONS, layout_strategies
from jaxmatch.model import TOUCH_TOL, Model, region_polygon
from jaxmatch.placement.decompose import disk_layout, single_patch
from jaxmatch.placement.embed import smooth_in_frame
from jaxmatch.placement.layout import Layout, check_layout
from jaxmatch.placement.solve import ALL_SIZES, TEMPLATE_SIZES, mesh_layout
from jaxmatch.quality import quad_areas, sj_inverted
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, Shape, make_shape

__all__ = ["Piece", "mesh_model", "pieces", "region_quality"]

SNAP_TOL = 1e-8
"""Relative (to the model's extent) distance within which points are the same point or lie on a
line (:data:`jaxmatch.model.TOUCH_TOL` times 10: points the readers computed from the same input
numbers differ by round-off only)."""


class Piece(NamedTuple):
    """A part of a region: ``region`` its index in the model, ``shape`` its loops (user
    coordinates), ``cut``: made by cutting or inserting points (else the region's own shape)."""

    region: int
    shape: Shape
    cut: bool


# ---------------------------------------------------------------------------------------------
# 1. pieces


def _extended(curve: np.ndarray, poly, tol: float) -> np.ndarray:
    """``curve (k, 2)`` with each end inside ``poly`` extended straight (along its end segment)
    to the first point of ``poly``'s boundary."""
    import shapely

    out = [np.asarray(curve, np.float64)]
    boundary = poly.boundary
    far = 4.0 * max(poly.bounds[2] - poly.bounds[0], poly.bounds[3] - poly.bounds[1])
    for first in (True, False):
        c = out[0] if first else out[-1]
        end, prev = (c[0], c[1]) if first else (c[-1], c[-2])
        if boundary.distance(shapely.Point(end)) <= tol:
            continue
        d = (end - prev) / np.linalg.norm(end - prev)
        hits = shapely.get_coordinates(boundary.intersection(shapely.LineString([end, end + far * d])))
        dist = np.linalg.norm(hits - end, axis=1) if len(hits) else np.zeros(0)
        if not np.any(dist > tol):  # pragma: no cover - a point inside a polygon sees its boundary
            raise InputError("an embedded curve's end cannot be extended to the region's boundary")
        hit = hits[int(np.argmin(np.where(dist > tol, dist, np.inf)))]
        if first:
            out.insert(0, hit[None])
        else:
            out.append(hit[None])
    return np.concatenate(out)


def _region_pieces(poly, lines: list, tol: float) -> list:
    """``poly`` cut along ``lines`` (shapely LineStrings from boundary to boundary): the faces."""
    import shapely
    from shapely.ops import polygonize

    if not lines:
        return [poly]
    noded = shapely.union_all([poly.boundary] + lines)
    faces = list(polygonize(shapely.get_parts(noded)))
    inside = [f for f in faces if poly.buffer(tol).contains(f.representative_point()) and f.area > tol * tol]
    return inside


def _on_rings(p: np.ndarray, rings: Sequence[np.ndarray], tol: float) -> bool:
    import shapely

    pt = shapely.Point(p)
    return any(shapely.LinearRing(r).distance(pt) <= tol for r in rings)


def _with_points(ring: np.ndarray, tree, allpts: np.ndarray, tol: float) -> np.ndarray:
    """``ring (k, 2)`` with every point of ``allpts`` that lies on one of its segments (within
    ``tol``, not at its ends) inserted in order along it."""
    import shapely

    out = []
    k = ring.shape[0]
    for i in range(k):
        a, b = ring[i], ring[(i + 1) % k]
        out.append(a)
        near = tree.query(shapely.LineString([a, b]), predicate="dwithin", distance=tol)
        if not len(near):
            continue
        q = allpts[near]
        ab = b - a
        t = (q - a) @ ab / float(ab @ ab)
        keep = (np.linalg.norm(q - a, axis=1) > tol) & (np.linalg.norm(q - b, axis=1) > tol) & (t > 0) & (t < 1)
        for j in np.argsort(t[keep]):
            out.append(q[keep][j])
    out = np.array(out)
    keep = np.ones(len(out), bool)  # (the same point found twice)
    keep[1:] = np.linalg.norm(np.diff(out, axis=0), axis=1) > tol
    return out[keep]


def _piece_corners(ring: np.ndarray, region: Shape, own: np.ndarray, cuts: list, tol: float, angle: float) -> list[int]:
    """The corners of a piece's loop ``ring (k, 2)``: the region's own corners ``own (C, 2)``,
    and points off the region's loops or on a cut where the loop turns by more than ``angle``
    degrees (points of other regions inserted on a straight side are none)."""
    import shapely

    turn = np.degrees(np.abs(turning_angles(ring)))
    rings = [region.given_points] + [np.asarray(h) for h in region.holes]
    out = []
    for i, p in enumerate(ring):
        if own.size and np.min(np.linalg.norm(own - p, axis=1)) <= tol:
            out.append(i)
        elif turn[i] > angle and (not _on_rings(p, rings, tol)
                                  or any(c.distance(shapely.Point(p)) <= tol for c in cuts)):
            out.append(i)
    return out


def pieces(model: Model, corner_angle: float = DEFAULT_CORNER_ANGLE) -> tuple[list[Piece], list[np.ndarray], float]:
    """The model's pieces (step 1 of the module docstring), the embedded curves as extended to
    their regions' boundaries ``(k, 2)`` each, and the tolerance used (user units)."""
    import shapely

    polys = [region_polygon(r.shape) for r in model.regions]
    b = np.array([p.bounds for p in polys])
    extent = float(max(b[:, 2].max() - b[:, 0].min(), b[:, 3].max() - b[:, 1].min()))
    tol = SNAP_TOL * extent
    extended, by_region = [], {}
    for k, c in enumerate(model.embedded.curves):
        line = shapely.LineString(c)
        r = next(i for i, p in enumerate(polys) if line.difference(p.buffer(10 * TOUCH_TOL * extent)).length
                 <= 10 * TOUCH_TOL * extent)
        ext = _extended(c, polys[r], tol)
        extended.append(ext)
        by_region.setdefault(r, []).append(shapely.LineString(ext))
    faces = []
    for r, poly in enumerate(polys):
        cuts = by_region.get(r, [])
        for f in _region_pieces(poly, cuts, tol):
            faces.append((r, f, cuts))
    allpts = np.concatenate([shapely.get_coordinates(f.boundary) for _, f, _ in faces])
    tree = shapely.STRtree(shapely.points(allpts))
    out = []
    for r, f, cuts in faces:
        reg = model.regions[r].shape
        outer = np.asarray(f.exterior.coords)[:-1]
        holes = [np.asarray(h.coords)[:-1] for h in f.interiors]
        new_outer = _with_points(outer, tree, allpts, tol)
        new_holes = [_with_points(h, tree, allpts, tol) for h in holes]
        if not cuts and len(new_outer) == len(outer) and all(len(a) == len(h) for a, h in zip(new_holes, holes)):
            out.append(Piece(r, reg, False))
            continue
        own = np.concatenate([reg.given_points[reg.corners]]
                             + [np.asarray(h)[c] for h, c in zip(reg.holes, reg.hole_corners)]).reshape(-1, 2)
        name = model.regions[r].name
        corners = _piece_corners(new_outer, reg, own, cuts, tol, corner_angle)
        hole_corners = [_piece_corners(h, reg, own, cuts, tol, corner_angle) for h in new_holes]
        shape = make_shape(new_outer, corners, corner_angle=corner_angle, source=f"{model.source}#{name}",
                           holes=new_holes or None, hole_corners=hole_corners or None)
        out.append(Piece(r, shape, True))
    return out, extended, tol


def _connected(model: Model) -> None:
    """InputError unless the regions' union is one region (regions meet along sides)."""
    import shapely

    polys = [region_polygon(r.shape) for r in model.regions]
    union = shapely.union_all(polys)
    if union.geom_type == "Polygon":
        return
    first = union.geoms[0]
    apart = [r.name for r, p in zip(model.regions, polys) if not first.covers(p.representative_point())]
    inside = [r.name for r, p in zip(model.regions, polys) if first.covers(p.representative_point())]
    raise InputError(f"region {apart[0]!r} does not meet region {inside[0]!r} or the others along a side: the "
                     "regions of an assembly form one connected region (mesh separate parts one by one)",
                     where=model.source)


# ---------------------------------------------------------------------------------------------
# 2. each piece's layout


def _layout_of(shape: Shape, chosen: str, h: float, corner_angle: float) -> tuple[Layout, bool]:
    """The layout of the candidate ``chosen`` of ``shape`` at size ``h`` (made again as the
    pipeline made it), and whether it is a single patch (every template size group). The
    solve's options a name carries (`` +lean curves``, `` +transitions``) are the assembly
    solve's to choose, not the layout's."""
    for option in (TRANSITIONS, LEAN):
        chosen = chosen[: -len(option)] if chosen.endswith(option) else chosen
    bends = chosen.endswith(FINER)
    base = chosen[: -len(FINER)] if bends else chosen
    region = canonical(shape, h, corner_angle, held_angle=corner_angle if bends else None)
    if base == DISK or (region.n_corners < 2 and not region.holes):
        return disk_layout(region), False
    if base.split(" ")[0] == SINGLE:
        return single_patch(region), True
    return layout_strategies([base])[0].layout(region, h), False


# ---------------------------------------------------------------------------------------------
# 3. one layout


def _merge(layouts: Sequence[Layout], tol: float, source: str, regions: Sequence[int] | None = None
           ) -> tuple[Layout, np.ndarray]:
    """One :class:`Layout` of every patch of ``layouts`` (points within ``tol`` one point; every
    point inserted in the patch sides it lies on) and ``(patches,) int64`` the layout each patch
    came from; ``regions``: the region of each layout (the merged layout's ``regions``)."""
    import shapely

    pts = np.concatenate([lay.points for lay in layouts])
    offsets = np.cumsum([0] + [lay.points.shape[0] for lay in layouts])
    geoms = shapely.points(pts)
    i, j = shapely.STRtree(geoms).query(geoms, predicate="dwithin", distance=tol)
    parent = np.arange(len(pts))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for a, b in zip(i.tolist(), j.tolist()):
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    root = np.array([find(a) for a in range(len(pts))])
    uniq, gid = np.unique(root, return_inverse=True)
    points = pts[uniq]
    tree = shapely.STRtree(shapely.points(points))
    loops, pcs, owner = [], [], []
    for li, lay in enumerate(layouts):
        for loop, pc in zip(lay.patches, lay.patch_corner):
            g = gid[loop + offsets[li]]
            new, newpc = [], []
            for k in range(len(g)):
                a, b = int(g[k]), int(g[(k + 1) % len(g)])
                new.append(a)
                newpc.append(bool(pc[k]))
                near = tree.query(shapely.LineString([points[a], points[b]]), predicate="dwithin", distance=tol)
                near = [n for n in near.tolist() if n != a and n != b]
                if near:
                    ab = points[b] - points[a]
                    t = (points[near] - points[a]) @ ab / float(ab @ ab)
                    for n in np.asarray(near)[np.argsort(t)][(np.sort(t) > 0) & (np.sort(t) < 1)].tolist():
                        new.append(n)
                        newpc.append(False)
            if len(set(new)) < len(new):
                raise InputError("two points of a patch coincide after merging the regions' layouts (regions closer "
                                 "than the tolerance without sharing their points)", where=source)
            loops.append(np.array(new, np.int64))
            pcs.append(np.array(newpc, bool))
            owner.append(li)
    corner = np.zeros(len(points), bool)
    for loop, pc in zip(loops, pcs):
        corner[loop[pc]] = True
    merged = Layout(points=points, patches=tuple(loops), corner=corner, patch_corner=tuple(pcs), requested={},
                    source=source, regions=None if regions is None else np.asarray(regions)[np.asarray(owner)])
    try:
        check_layout(merged)
    except InputError as e:
        raise InputError(f"the regions do not fit together point for point: {e.problem} (regions that share a "
                         "boundary need its points on both, or each one's points on the other's segments; regions "
                         "must touch along sides, not at a point only)", where=source) from None
    return merged, np.asarray(owner, np.int64)


# ---------------------------------------------------------------------------------------------
# 4. smoothing, embedded points


def _smoothed(xy: np.ndarray, quads: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """``xy`` smoothed with ``fixed`` kept, when that raises the min scaled Jacobian and folds
    nothing (else ``xy``)."""
    if fixed.size == xy.shape[0]:
        return xy
    new = smooth_in_frame(xy, quads, fixed)
    sj0, inv0 = sj_inverted(xy, quads)
    sj1, inv1 = sj_inverted(new, quads)
    return new if (int(inv1.sum()), -float(sj1.min())) <= (int(inv0.sum()), -float(sj0.min())) else xy


SNAP_TRIES = 8
"""Vertices tried for an embedded point (the nearest that may move there): the one whose quads
are best shaped once it is there is moved."""


def _best_move(xy: np.ndarray, quads: np.ndarray, p: np.ndarray, cands: Sequence[int]) -> int:
    """The vertex of ``cands`` (the nearest first) whose quads have the highest min scaled
    Jacobian once it is moved to ``p`` (ties: the nearer)."""
    best, key = int(cands[0]), None
    for v in cands:
        around = quads[np.any(quads == v, axis=1)]
        old = xy[v].copy()
        xy[v] = p
        sj, _ = sj_inverted(xy, around)
        xy[v] = old
        k = round(float(sj.min()), 6) if len(around) else -1.0
        if key is None or k > key:
            best, key = int(v), k
    return best


SLIDE_ROUNDS = 4
"""Rounds of :func:`_slid`: interface vertices slid along their sides, then the rest smoothed."""


def _slid(xy: np.ndarray, quads: np.ndarray, fixed: np.ndarray, sides: Sequence[tuple[np.ndarray, np.ndarray]],
          rounds: int = SLIDE_ROUNDS, pinned: np.ndarray = np.zeros(0, np.int64)) -> np.ndarray:
    """``xy`` with the vertices inside each interface side slid along it: each toward the mean
    of its neighbours, projected onto the side's polyline and kept between its two neighbours on
    the side (the side's end nodes stay), then every vertex not ``fixed`` smoothed; after each of
    ``rounds`` rounds the mesh is kept when its min scaled Jacobian rose and nothing folds.
    Layouts chosen region by region put their nodes at different places on the two sides of a
    thin region (an air gap): sliding takes out the shear that leaves between them.

    sides: ``(vertex ids (k,), polyline (p, 2))`` per side, ids in the polyline's direction;
    pinned: vertex ids that stay where they are (an embedded curve's ends)."""
    import shapely

    if not sides:
        return xy
    e = np.unique(np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1), axis=0)
    deg = np.bincount(e.ravel(), minlength=len(xy)).astype(np.float64)
    lines = [(ids, shapely.LineString(poly)) for ids, poly in sides if len(ids) > 2]
    sj, inv = sj_inverted(xy, quads)
    best, key = xy, (int(inv.sum()), -float(sj.min()))
    cur = xy.copy()
    for _ in range(rounds):
        total = np.zeros_like(cur)
        np.add.at(total, e[:, 0], cur[e[:, 1]])
        np.add.at(total, e[:, 1], cur[e[:, 0]])
        mean = total / np.maximum(deg, 1)[:, None]
        for ids, line in lines:
            t = np.asarray(line.project(shapely.points(cur[ids])))
            want = np.asarray(line.project(shapely.points(mean[ids[1:-1]])))
            lo, hi = t[:-2], t[2:]
            gap = 0.2 * (hi - lo)
            t_new = np.clip(want, lo + gap, hi - gap)
            keep = np.isin(ids[1:-1], pinned)
            t_new[keep] = t[1:-1][keep]
            cur[ids[1:-1]] = shapely.get_coordinates(line.interpolate(t_new))
        cur = smooth_in_frame(cur, quads, fixed)
        sj, inv = sj_inverted(cur, quads)
        k = (int(inv.sum()), -float(sj.min()))
        if k < key:
            best, key = cur.copy(), k
    return best


def _snap(xy: np.ndarray, quads: np.ndarray, p: np.ndarray, chains: Sequence[np.ndarray], fixed: np.ndarray,
          tol: float, taken: set) -> int:
    """Make point ``p`` a vertex: an existing vertex within ``tol``, else a movable vertex of the
    side chain ``p`` lies on (its interior vertices), else a vertex not ``fixed``: of the
    :data:`SNAP_TRIES` nearest, the one whose quads are best shaped there (:func:`_best_move`) is
    moved onto ``p`` (``xy`` changed in place). Returns its id."""
    d = np.linalg.norm(xy - p, axis=1)
    if d.min() <= tol:
        return int(np.argmin(d))
    for ch in chains:
        seg_a, seg_b = xy[ch[:-1]], xy[ch[1:]]
        ab = seg_b - seg_a
        t = np.clip(np.einsum("ij,ij->i", p - seg_a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
        dist = np.linalg.norm(seg_a + t[:, None] * ab - p, axis=1)
        s = int(np.argmin(dist))
        if dist[s] <= tol:
            inner = [v for v in ch[1:-1].tolist() if v not in taken]
            if not inner:
                raise InputError(f"embedded point ({p[0]:g}, {p[1]:g}): no vertex of its side is free to move onto it "
                                 "(try a smaller --size)")
            v = _best_move(xy, quads, p, sorted(inner, key=lambda v: d[v])[:3])
            xy[v] = p
            return v
    free = np.ones(len(xy), bool)
    free[fixed] = False
    free[list(taken)] = False
    if not free.any():  # pragma: no cover - a mesh with no interior vertex and a point inside
        raise InputError(f"embedded point ({p[0]:g}, {p[1]:g}): no interior vertex to move onto it (try a smaller --size)")
    ids = np.flatnonzero(free)
    v = _best_move(xy, quads, p, ids[np.argsort(d[ids])[:SNAP_TRIES]].tolist())
    xy[v] = p
    return v


def _on_curve(xy: np.ndarray, edges: np.ndarray, curve: np.ndarray, tol: float) -> np.ndarray:
    """The rows of ``edges (E, 2)`` whose ends and midpoint lie on the polyline ``curve``."""
    import shapely

    line = shapely.LineString(curve)
    ends = shapely.distance(line, shapely.points(xy[edges[:, 0]])) <= tol
    ends &= shapely.distance(line, shapely.points(xy[edges[:, 1]])) <= tol
    mid = shapely.distance(line, shapely.points(0.5 * (xy[edges[:, 0]] + xy[edges[:, 1]]))) <= max(tol, 1e-3 * line.length)
    return edges[ends & mid]


def _region_sides(model: Model, xy: np.ndarray, quads: np.ndarray, region: np.ndarray, tol: float) -> dict:
    """``"NAME side i-j"`` -> ``(E, 2)`` the edges of region NAME's cells along its side from its
    corner ``i`` to ``j = i + 1`` (corners numbered in the file's order,
    :attr:`~jaxmatch.shape.Shape.side_frame`), on the outline or on an interface."""
    out = {}
    for r, reg in enumerate(model.regions):
        shape = reg.shape
        n = shape.n_corners
        if n < 2:
            continue
        e = np.stack([quads[region == r], np.roll(quads[region == r], -1, axis=1)], axis=-1).reshape(-1, 2)
        key, first, count = np.unique(np.sort(e, axis=1), axis=0, return_index=True, return_counts=True)
        edges = e[first[count == 1]]
        ring, c = shape.given_points, np.asarray(shape.corners, np.int64)
        for i, (k, _) in enumerate(shape.side_frame):
            a, b = int(c[k]), int(c[(k + 1) % n])
            poly = ring[np.arange(a, a + (b - a) % len(ring) + 1) % len(ring)]
            out[f"{reg.name} side {i}-{(i + 1) % n}"] = _on_curve(xy, edges, poly, tol)
    return out


def region_quality(mesh: QuadMesh) -> dict[str, dict]:
    """Per region of an assembly's mesh: ``{"quads", "min_scaled_jacobian", "area"}``."""
    sj = mesh.scaled_jacobian
    areas = quad_areas(mesh.xy, mesh.quads)
    return {name: {"quads": int((mesh.patch == r).sum()), "min_scaled_jacobian": float(sj[mesh.patch == r].min()),
                   "area": float(areas[mesh.patch == r].sum())}
            for r, name in enumerate(mesh.regions)}


def mesh_model(model: Model, mesh_one, *, size: float | None = None, divisions: int | None = None, catalogue=None,
               lattice=DEFAULT_LATTICE, quality: Quality = QUALITY, corner_angle: float = DEFAULT_CORNER_ANGLE,
               strategies: Sequence[str] | None = None, budget_s: float | None = None, progress=None) -> QuadMesh:
    """Mesh ``model`` as one conforming quad mesh (see the module docstring).

    mesh_one: the pipeline's front door (:func:`jaxmatch.meshing.pipeline.mesh`, which calls
    this function with itself: this module does not import the pipeline that dispatches to it),
    called once per piece to choose its strategy.
    size: target edge length (user units; default the union's outline / ``divisions``, itself
    default :data:`~jaxmatch.defaults.DEFAULT_DIVISIONS`). The other options are those of
    :func:`jaxmatch.meshing.pipeline.mesh`, used for every piece.

    Returns a :class:`QuadMesh` (``chosen="assembly"``; ``detail``: per region its pieces'
    strategies; ``tried``: per region a :class:`Candidate` named ``"region NAME (strategies)"``
    whose mesh is that region's cells, for its figures). Raises :class:`InputError` naming the model's file for a model that cannot be
    meshed.
    """
    if size is not None and divisions is not None:
        raise InputError("give divisions or a size, not both")
    h = float(size) if size is not None else default_size(model, int(divisions or DEFAULT_DIVISIONS))
    if not (h > 0 and math.isfinite(h)):
        raise InputError(f"element size must be a positive number, got {size!r}")
    cat, lat = load_catalogue(catalogue), _lattice(lattice)
    _connected(model)
    parts, _, tol = pieces(model, corner_angle)
    layouts, singles, chosen = [], [], []
    for n, piece in enumerate(parts):
        m = mesh_one(piece.shape, size=h, catalogue=cat, lattice=lat, quality=quality, corner_angle=corner_angle,
                     strategies=strategies, budget_s=budget_s)
        try:
            lay, single = _layout_of(piece.shape, m.chosen, h, corner_angle)
        except InputError as e:
            raise InputError(f"region {model.regions[piece.region].name!r}: its {m.chosen} mesh is no layout "
                             f"({e.problem})", where=model.source) from None
        layouts.append(lay)
        singles.append(single)
        chosen.append(m.chosen)
        if progress is not None:
            progress(n + 1, len(parts) + 1, model.regions[piece.region].name)
    merged, piece_of = _merge(layouts, tol, model.source, [p.region for p in parts])
    region_of_patch = np.array([parts[p].region for p in piece_of], np.int64)
    lm = mesh_layout(merged, cat, lat, size=h, sizes=ALL_SIZES if any(singles) else TEMPLATE_SIZES, quality=quality)
    interfaces, curve_sides = _kinds(model, lm.sides, region_of_patch, piece_of)
    xy, point_ids = _placed(model, lm, merged, [s for ss in interfaces.values() for s in ss], curve_sides, tol)
    quads = np.asarray(lm.quads, np.int64)
    region_of_quad = region_of_patch[np.asarray(lm.patch, np.int64)]
    base = from_layout(lm, size=h, corners=np.zeros((0, 2)))
    line_sets = {k: v for k, v in base.line_sets.items() if k == "boundary" or k.startswith("hole ")}
    for key in sorted(interfaces):
        line_sets[key] = np.concatenate([_chain_edges(lm.side_vertices[s]) for s in interfaces[key]])
    line_sets.update(_region_sides(model, xy, quads, region_of_quad, tol))
    line_sets.update(_curve_groups(model, xy, quads, tol))
    corners = np.concatenate([corner_points(canonical(p.shape, h, corner_angle)) for p in parts]
                             + [np.asarray(model.embedded.points).reshape(-1, 2)])
    detail = {r.name: [c for p, c in zip(parts, chosen) if model.regions[p.region] is r] for r in model.regions}
    sides = {k: np.asarray(v, np.int64).reshape(-1, 2) for k, v in line_sets.items() if " side " in k and not k.startswith("hole ")}
    out = QuadMesh(xy=xy, quads=quads, patch=region_of_quad, line_sets=line_sets,
                   region_area=float(lm.region_area), corners=corners, size=h,
                   side_lengths={k: float(np.linalg.norm(xy[e[:, 1]] - xy[e[:, 0]], axis=1).sum()) for k, e in sides.items()},
                   side_counts={k: int(len(e)) for k, e in sides.items()},  # keyed as the groups, "NAME side i-j"
                   templates=tuple(lm.templates), detail=detail, regions=model.names,
                   point_sets={f"point {k + 1}": np.array([v], np.int64) for k, v in enumerate(point_ids)})
    rule = "; ".join(f"{name}: {', '.join(c)}" for name, c in detail.items())
    per_region = []
    for r, reg in enumerate(model.regions):  # each region's cells as a mesh of their own: its figures
        mine = region_of_quad == r
        patches = np.unique(np.asarray(lm.patch, np.int64)[mine], return_inverse=True)[1].reshape(-1)
        sub = QuadMesh(xy=xy, quads=quads[mine], patch=patches.astype(np.int64), line_sets={},
                       region_area=float(region_polygon(reg.shape).area), corners=corner_points(reg.shape), size=h)
        per_region.append(Candidate(f"region {reg.name} ({', '.join(detail[reg.name])})", sub))
    return out.with_choice("assembly", rule, None, per_region)


def _chain_edges(ids) -> np.ndarray:
    """``(k - 1, 2) int64`` the edges of a side's vertex chain ``(k,)``."""
    ids = np.asarray(ids, np.int64)
    return np.stack([ids[:-1], ids[1:]], axis=1)


def _kinds(model: Model, sides, region_of_patch: np.ndarray, piece_of: np.ndarray) -> tuple[dict, list[int]]:
    """The merged layout's inner sides by kind: ``({"NAME1|NAME2": [side ids]}, [side ids of the
    embedded curves' cuts])`` (the other inner sides are a region's own cuts)."""
    interfaces, curve_sides = {}, []
    for s in range(len(sides.chains)):
        u0, u1 = sides.users[s]
        if u1 < 0:
            continue
        r0, r1 = region_of_patch[u0], region_of_patch[u1]
        if r0 != r1:
            key = "|".join(sorted((model.regions[r0].name, model.regions[r1].name)))
            interfaces.setdefault(key, []).append(s)
        elif piece_of[u0] != piece_of[u1]:  # an embedded curve's cut (or its extension to the boundary)
            curve_sides.append(s)
    return interfaces, curve_sides


def _placed(model: Model, lm, merged: Layout, interface_sides: list[int], curve_sides: list[int],
            tol: float) -> tuple[np.ndarray, list[int]]:
    """Step 4 of the module docstring: the merged mesh's ``xy (V, 2)`` smoothed, interface
    vertices slid, embedded curves' ends and points made vertices; and the vertex of each
    embedded point."""
    import shapely

    sides, quads = lm.sides, np.asarray(lm.quads, np.int64)
    xy = np.array(lm.xy, np.float64)
    chains = [np.asarray(lm.side_vertices[s], np.int64) for s in range(len(sides.chains))]
    loops = [np.asarray(lm.outer, np.int64)] + [np.asarray(hl, np.int64) for hl in lm.holes]
    kept = np.unique(np.concatenate(loops + [chains[s] for s in interface_sides]))
    taken: set = set()
    for c in model.embedded.curves:  # a curve's ends: vertices, slid along their cuts while these are straight
        for p in (c[0], c[-1]):
            taken.add(_snap(xy, quads, p, [chains[s] for s in curve_sides], kept, tol, taken))
    ends = np.array(sorted(taken), np.int64)
    on_curves = np.zeros(len(xy), bool)  # the cuts' vertices on the curves stay; their extensions' are free
    if curve_sides:
        cut = np.unique(np.concatenate([chains[s] for s in curve_sides]))
        near = shapely.distance(shapely.MultiLineString(list(model.embedded.curves)), shapely.points(xy[cut]))
        on_curves[cut[near <= tol]] = True
    fixed = np.unique(np.concatenate([kept, np.flatnonzero(on_curves), ends]))
    xy = _smoothed(xy, quads, fixed)
    xy = _slid(xy, quads, fixed, [(chains[s], merged.points[sides.chains[s]]) for s in interface_sides + curve_sides],
               pinned=ends)
    point_ids = []
    for p in model.embedded.points:
        v = _snap(xy, quads, np.asarray(p, np.float64), chains, fixed, tol, taken)
        taken.add(v)
        point_ids.append(v)
    if point_ids:
        xy = _smoothed(xy, quads, np.unique(np.concatenate([fixed, np.array(sorted(taken), np.int64)])))
        _, inverted = sj_inverted(xy, quads)
        for k, v in enumerate(point_ids):
            if np.any(inverted & np.any(quads == v, axis=1)):
                x, y = model.embedded.points[k]
                warnings.warn(InputWarning(f"embedded point {k + 1} ({x:g}, {y:g}): the quads around its vertex fold at "
                                           "this size (it is too near a corner or another point); try a smaller size",
                                           model.source), stacklevel=3)
    return xy, point_ids


def _curve_groups(model: Model, xy: np.ndarray, quads: np.ndarray, tol: float) -> dict:
    """``"curve k"`` -> ``(E, 2)`` the mesh edges on embedded curve ``k`` (a warning when they
    cover less or more than its length, 1 %)."""
    all_edges = np.unique(np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1), axis=0)
    out = {}
    for k, c in enumerate(model.embedded.curves):
        e = _on_curve(xy, all_edges, c, tol)
        out[f"curve {k + 1}"] = e
        length = float(np.sum(np.linalg.norm(np.diff(c, axis=0), axis=1)))
        covered = float(np.sum(np.linalg.norm(xy[e[:, 0]] - xy[e[:, 1]], axis=1)))
        if abs(covered - length) > 0.01 * length:  # (a curve that bends between its mesh vertices)
            warnings.warn(InputWarning(f"embedded curve {k + 1} is covered by mesh edges over {covered:.4g} of its "
                                       f"length {length:.4g}", model.source), stacklevel=3)
    return out
