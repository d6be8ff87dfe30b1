"""Bounds on what a layout's mesh can be, known before it is meshed: the pipeline skips a layout
that cannot beat the best mesh so far (:func:`jaxmatch.meshing.choose.cannot_win`).

:func:`node_sj_bound` from the angles its nodes split; :func:`single_sj_bound` for a single patch,
from its template sizes (:func:`grid_templates_exist`); :func:`template_sj_bound` for a single
patch, from the quads its candidate templates put at each corner and internal vertex.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from jaxmatch.catalogue.mesh import mesh_valences
from jaxmatch.geometry import signed_area, turning_angles
from jaxmatch.placement.layout import Layout
from jaxmatch.placement.solve import TEMPLATE_SIZES, TEMPLATES_PER_PATCH, patch_shapes_kept
from jaxmatch.placement.templates import first_group_templates

if TYPE_CHECKING:  # pragma: no cover
    from jaxmatch.catalogue.store import Catalogue

__all__ = ["NO_GRID_SJ", "grid_templates_exist", "node_sj_bound", "single_sj_bound", "template_sj_bound"]


def grid_templates_exist(catalogue: Catalogue, ks: Sequence[int], corners: Sequence[int]) -> bool:
    """Whether a catalogue mesh with ``k`` in ``ks`` internal vertices could mesh, refined, a region
    with straight sides whose corners, in ccw order, are right angles (``corners``: ``1`` for 90
    degrees, ``3`` for 270) as a grid of rectangles: every internal vertex of valence 4, and
    along its boundary (either way round, from any vertex) valence ``1 + corners[i]`` at the
    corners in that order and 3 at every vertex between them. Kept per catalogue."""
    want = [1 + int(q) for q in corners]
    key = ("grid templates", tuple(sorted(int(k) for k in ks)), tuple(want))
    cache = getattr(catalogue, "_cache", None)
    if isinstance(cache, dict) and key in cache:
        return cache[key]
    n2, n4 = want.count(2), want.count(4)
    turns = {tuple(want[r:] + want[:r]) for r in range(len(want))}
    turns |= {t[::-1] for t in turns}
    found = False
    for b in catalogue.buckets(list(key[1])):
        v = np.asarray(b.valences)
        fit = ((v == 2).sum(axis=1) == n2) & ((v == 4).sum(axis=1) == n4) & ((v == 3).sum(axis=1) == b.n - n2 - n4)
        for row in np.flatnonzero(fit).tolist():
            if tuple(int(x) for x in v[row] if x != 3) not in turns:
                continue
            mesh = catalogue.mesh(str(b.ids[row]))
            inner = np.ones(mesh.n_vertices, bool)
            inner[np.asarray(mesh.boundary)] = False
            if np.all(mesh_valences(mesh)[inner] == 4):
                found = True
                break
        if found:
            break
    if isinstance(cache, dict):
        cache[key] = found
    return found


NO_GRID_SJ = 0.96
"""An upper bound on the min scaled Jacobian of a mesh of straight-sided right-angled corners
that is no grid of rectangles: around an internal vertex of valence 3 or 5 some quad's angle is
at most 120 or 72 degrees (scaled Jacobian at most sin 72 = 0.951); at a corner of 90 or 270
degrees or a side point whose quads are too many or too few, some angle is at most 112.5 or at
least 135 degrees (at most 0.924); with a margin for corners up to 1e-3 rad off."""

def single_sj_bound(layout: Layout, catalogue: Catalogue, lattice, *, templates_per_patch: int = TEMPLATES_PER_PATCH,
                    sizes=TEMPLATE_SIZES) -> float:
    """An upper bound on the min scaled Jacobian of :func:`mesh_layout` of a one-patch ``layout``
    with these options (a mesh that does not fold; one that folds loses on that first), from its
    template sizes alone: 1 unless the region has straight sides and right-angled corners and no
    catalogue mesh of the template group that :func:`mesh_layout` would use (found as it finds
    it, the templates kept in the catalogue's cache) can be refined into a grid of rectangles
    with the region's corners in their order (:func:`grid_templates_exist`, :data:`NO_GRID_SJ`;
    when none of any size of ``sizes`` can, the group is not looked for). A corner off every
    multiple of 90 degrees gives 1 here: :func:`node_sj_bound` caps that closer. Refinement keeps
    a template vertex's valence and makes every new vertex regular, so the refined mesh is a grid
    only if its template is one. Without templates (the layout cannot be meshed): 1."""
    if layout.n_patches != 1:
        return 1.0
    shp = patch_shapes_kept(layout, catalogue)[0]
    turn = turning_angles(shp.points)
    is_corner = np.zeros(shp.n_points, bool)
    is_corner[shp.corners] = True
    if np.any(np.abs(turn[~is_corner]) > 1e-9):  # a side that bends: no claim
        return 1.0
    angle = math.pi - turn[shp.corners]  # interior angles (the loop runs ccw)
    quarters = np.rint(angle / (math.pi / 2))
    if np.any(np.abs(angle - quarters * (math.pi / 2)) > 1e-3) or np.any((quarters != 1) & (quarters != 3)):
        return 1.0  # not right angles (node_sj_bound's cap), or a corner of 0 or 180 degrees
    corners = quarters.astype(int).tolist()
    if not grid_templates_exist(catalogue, [k for g in sizes for k in g if k in catalogue.internal], corners):
        return NO_GRID_SJ  # none of any size: which group mesh_layout takes does not matter
    t = first_group_templates(shp, catalogue, lattice, templates_per_patch, sizes)
    if not t:
        return 1.0
    k0 = t[0].match.internal_vertices
    ks = [k for k in next(g for g in sizes if k0 in g) if k in catalogue.internal]
    if grid_templates_exist(catalogue, ks, corners):
        return 1.0
    return NO_GRID_SJ


def template_sj_bound(layout: Layout, catalogue: Catalogue, lattice, *, templates_per_patch: int = TEMPLATES_PER_PATCH,
                      sizes=TEMPLATE_SIZES) -> float:
    """An upper bound on the min scaled Jacobian of :func:`mesh_layout` of a one-patch ``layout``
    with these options (a mesh that does not fold; one that folds loses on that first), from the
    candidate templates it takes one of (:func:`first_group_templates`, found as it finds them:
    every one is placed, kept in the catalogue's cache). Refinement keeps the number of quads at
    every template vertex, so around a corner of angle ``a`` met by ``q`` quads some quad's angle
    is at least ``a / q`` and one at most, and its scaled Jacobian at most ``sin(a / q)`` (1 where
    ``q`` right angles fit ``a``; ``a`` within the outline's angle range there, as in
    :func:`node_sj_bound`), and around an internal vertex of valence ``d``, ``sin(2 pi / d)``. A
    template's bound is the least over its vertices; the layout's, the largest over its
    templates. E.g. an L-shape whose templates all meet the 270-degree corner with two quads:
    sin 135 degrees. 1 for several patches, no templates, or corners it cannot match up."""
    if layout.n_patches != 1:
        return 1.0
    shp = patch_shapes_kept(layout, catalogue)[0]
    if shp.holes or signed_area(shp.points) <= 0:
        return 1.0
    t = first_group_templates(shp, catalogue, lattice, templates_per_patch, sizes)
    if not t:
        return 1.0
    pts, corners = np.asarray(shp.points, np.float64), np.asarray(shp.corners, np.int64)
    n, c = pts.shape[0], corners.shape[0]
    angles = []  # each corner's angle range (radians), the corners in the templates' side order
    for i in range(c):
        v, after, before = int(corners[i]), int(corners[(i + 1) % c]), int(corners[i - 1])
        ahead = [(v + j) % n for j in range(1, (after - v) % n + 1 if c > 1 else n)]
        behind = [(v - j) % n for j in range(1, (v - before) % n + 1 if c > 1 else n)]
        lo, hi = _outline_angle(pts, v, ahead, behind)
        angles.append((lo - NODE_ANGLE_TOL, hi + NODE_ANGLE_TOL))
    user = np.asarray(shp.user_points, np.float64)[corners]
    tol = 1e-9 * max(float(np.ptp(user, axis=0).max()), 1.0)
    bound = 0.0
    for tmpl in t:
        if len(tmpl.side_path) != c:
            return 1.0
        xy = np.asarray(tmpl.placement.xy, np.float64)
        at = np.array([int(sp[0]) for sp in tmpl.side_path], np.int64)
        if np.abs(xy[at] - user).max() > tol:  # (corner i of the sides is not the shape's corner i)
            return 1.0
        quads = np.asarray(tmpl.placement.mesh.quads, np.int64)
        uses = np.bincount(quads.ravel(), minlength=xy.shape[0])
        inner = np.ones(xy.shape[0], bool)
        inner[np.concatenate([np.asarray(sp, np.int64) for sp in tmpl.side_path])] = False
        caps = [_exact_split_sj(lo, hi, int(uses[v])) for (lo, hi), v in zip(angles, at.tolist())]
        valences = np.unique(uses[inner & (uses > 0)]).tolist()
        caps += [_exact_split_sj(2 * math.pi, 2 * math.pi, int(d)) for d in valences]
        bound = max(bound, min(caps))
        if bound >= 1.0:
            return 1.0
    return bound


def _exact_split_sj(lo: float, hi: float, q: int) -> float:
    """The largest scaled Jacobian the worst of exactly ``q`` convex quads at a vertex can have
    when their angles there add up to an angle in ``[lo, hi]``: 1 where ``q`` right angles fit,
    else ``sin(angle / q)`` at the nearer end, 0 when ``angle / q >= pi``."""
    if q < 1:
        return 1.0
    if lo / q <= math.pi / 2 <= hi / q:
        return 1.0
    return max(math.sin(a) if 0.0 < a < math.pi else 0.0 for a in (lo / q, hi / q))


NODE_ANGLE_TOL = 1e-6
"""Slack (radians) on the angle at a node, for boundary vertices placed on the outline's
segments up to rounding (:func:`node_sj_bound`)."""


def node_sj_bound(layout: Layout) -> float:
    """An upper bound on the min scaled Jacobian of any mesh of ``layout`` that does not fold (one
    that folds loses on that first), from its patch corners alone: a patch corner is a mesh
    vertex, every patch that contains it has a quad there, and the ``q`` quads at a vertex split
    its angle (2 pi inside; between the first boundary edges on the outline) into ``q`` angles,
    one of them at least 1 / q-th of it apart from 90 degrees, so some quad's scaled Jacobian there
    is at most ``max(sin(angle / q))`` over ``q`` >= the patches at the vertex
    (:func:`_split_sj`). A boundary edge from a patch corner ends on the outline before the next
    patch corner: the angle lies between the extreme directions to the outline's points up to it
    (:func:`_outline_angle`). E.g. a cut from a right-angled corner (two patches there): sin 45
    degrees; five patches meeting inside: sin 72 degrees. 1 when no corner limits it.

    (With no quad inverted and the boundary running once round the outline, the mesh covers the
    region once, so the angles of a vertex's quads add up to its angle.)"""
    pts = layout.points
    segs = []  # every patch's segments (ccw), in order
    uses: dict[int, int] = {}  # patches at each point
    corner = set()
    for p, pc in zip(layout.patches, layout.patch_corner):
        ids = p.tolist()
        segs += zip(ids, ids[1:] + ids[:1])
        for v in ids:
            uses[v] = uses.get(v, 0) + 1
        corner.update(p[pc].tolist())
    count: dict[tuple[int, int], int] = {}
    for s in segs:
        k = (s[0], s[1]) if s[0] < s[1] else (s[1], s[0])
        count[k] = count.get(k, 0) + 1
    once = [(x, y) for x, y in segs if count[(x, y) if x < y else (y, x)] == 1]  # outline segments (ccw)
    ahead = dict(once)
    back = {y: x for x, y in once}
    if len(ahead) < len(once) or len(back) < len(once):  # the outline touches itself: no claim
        return 1.0
    bound = 1.0
    for v in sorted(corner):
        if v in ahead:
            after, before = _walk(ahead, corner, v), _walk(back, corner, v)
            if after is None or before is None:  # not a closed outline (a layout that fails its checks)
                continue
            lo, hi = _outline_angle(pts, v, after, before)
        else:  # inside the region
            lo = hi = 2 * math.pi
        bound = min(bound, _split_sj(lo - NODE_ANGLE_TOL, hi + NODE_ANGLE_TOL, uses[v]))
    return bound


def _walk(step: dict, stop: set, v: int) -> list[int] | None:
    """The outline points after ``v`` by ``step`` (a point -> the next), up to and including the
    first in ``stop`` (or ``v`` again); None when the outline breaks off first."""
    out = [step.get(v)]
    while out[-1] is not None and out[-1] not in stop and out[-1] != v and len(out) <= len(step):
        out.append(step.get(out[-1]))
    return out if out[-1] is not None and len(out) <= len(step) else None


def _outline_angle(pts: np.ndarray, v: int, ahead: list[int], behind: list[int]) -> tuple[float, float]:
    """The range ``(lo, hi)`` (radians) of the region's angle at outline point ``v``: from the
    direction to a point of the outline ``ahead`` (in order) counter-clockwise to the direction to
    a point of the outline ``behind`` (going back), each direction within the extreme directions
    to the chain's points (unwrapped along the chain: the segments between them are seen from
    ``v`` under less than pi)."""
    x, y = float(pts[v, 0]), float(pts[v, 1])

    def spread(chain):
        if len(chain) == 1:
            u, w = float(pts[chain[0], 0]) - x, float(pts[chain[0], 1]) - y
            t = math.atan2(w, u)
            return t, 0.0, 0.0
        d = pts[chain] - pts[v]
        t = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
        return float(t[0]), float(t.min() - t[0]), float(t.max() - t[0])

    a0, a_lo, a_hi = spread(ahead)
    b0, b_lo, b_hi = spread(behind)
    base = (b0 - a0) % (2 * math.pi)
    return base + b_lo - a_hi, base + b_hi - a_lo


def _split_sj(lo: float, hi: float, q0: int) -> float:
    """The largest scaled Jacobian the worst of ``q`` >= ``q0`` convex quads at a vertex can have
    when their angles there add up to an angle in ``[lo, hi]``: ``sin(angle / q)``, 0 (no convex
    quad) when ``angle / q >= pi``."""
    best = -1.0
    q = max(q0, 1)
    while True:
        if lo / q <= math.pi / 2 <= hi / q:
            return 1.0
        for a in (lo / q, hi / q):
            best = max(best, math.sin(a) if 0.0 < a < math.pi else 0.0)
        if hi / q < math.pi / 2:  # smaller angles only from here on
            return best
        q += 1
