"""Multi-patch layouts: several patches of one planar region, each meshed by a refined catalogue
template (:mod:`jaxmatch.placement.refine`), merged into one conforming quad mesh.

Layout file (JSON)::

    {"points": [[x, y], ...],                 # shared points, user coordinates
     "patches": [[i, j, k, ...], ...],        # each patch a loop of point indices (either orientation)
     "corners": [i, ...],                     # optional: the points that are patch corners (default: all)
     "sides": {"i-j": count, ...}}            # optional: edges wanted on a side

A point listed in ``corners`` is a corner of each patch that turns there; a point on a
straight run of a patch (e.g. where two neighbours meet along its side: a T-junction) is not.
A *side* is a chain of points between two *nodes* (points that are a corner of some patch, or
where the patches along the boundary change); it is named by its end points ``"i-j"`` (either
order; when two sides have the same ends, by the whole chain ``"i-k-j"``), and is shared by the
patches that run along it. A patch side (between two consecutive corners of the patch) is one
side, or several where neighbours meet along it.
Rules checked by :func:`make_layout` (each failure is one :class:`InputError` line): indices in
range, no point listed twice in a patch, no two points at the same place, simple patches of
non-zero area, no segment used by three patches or twice in the same direction, no overlapping
patches, one connected region without holes (gaps), and every segment used by only one patch on
the outer boundary of the union (patches meeting without sharing their points there would leave
hanging nodes).

Meshing a layout is :func:`jaxmatch.placement.solve.mesh_layout`; this module has the parts it
uses: the sides (:func:`layout_sides`), the patch shapes, the fitting of patch sides made of
several layout sides (:func:`fit_sides`) and the merge into one conforming mesh
(:func:`merge_patches`: the vertices of a side get one global id each, so shared sides carry
identical vertices and there is no hanging node).

All lengths are in the user's units.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Mapping, NamedTuple, Sequence

import numpy as np

from jaxmatch.cache import Cache
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.errors import InputError
from jaxmatch.files import read_limited
from jaxmatch.arrays import roll
from jaxmatch.placement.milp import CHORD_WEIGHT, LayoutInfeasible, solve_counts  # noqa: F401 (public here)
from jaxmatch.placement.refine import (SMOOTH_ITERS_GRADED, SMOOTH_LOCAL, bad_quads, harmonic_displacement, side_points,
                                       smooth_near_bad)
from jaxmatch.placement.embed import polygon_area, smooth_in_frame, tutte
from jaxmatch.catalogue.mesh import boundary_edges, valences  # noqa: F401 (boundary_edges public here)
from jaxmatch.quality import inverted_mask, quad_areas, quality, sj_inverted
from jaxmatch.shape import Shape, make_shape

__all__ = [
    "Layout",
    "LayoutInfeasible",
    "LayoutMesh",
    "Sides",
    "CHORD_WEIGHT",
    "boundary_edges",
    "check_layout",
    "fit_sides",
    "layout_sides",
    "load_counts",
    "load_layout",
    "make_layout",
    "merge_patches",
    "parse_layout",
    "patch_shapes",
    "parse_counts",
    "solve_counts",
]

MAX_BYTES = 16 * 2**20
"""Largest accepted layout or sides file (bytes)."""

MAX_POINTS = 100_000
"""Largest accepted number of layout points."""

_TOL = 1e-9  # relative (to the layout's extent) tolerance for coincident points and areas
_KEYS = ("points", "patches", "corners", "sides")


# ---------------------------------------------------------------------------------------------
# data


@dataclass(frozen=True, eq=False)
class Layout:
    """A validated layout (see the module docstring).

    points: ``(P, 2) float64`` user coordinates.
    patches: patch ``p`` is ``(k_p,) int64`` point ids, a counter-clockwise loop that starts at
        its first corner.
    corner: ``(P,) bool``, the point may be a patch corner (the file's ``corners``; default all).
    patch_corner: patch ``p``: ``(k_p,) bool`` along its loop, the point is a corner of the
        patch: a ``corner`` point where the patch's outline turns (a point on a straight run of
        a patch, e.g. where two neighbours meet along its side, is not its corner).
    requested: ``{side name: edge count}`` as given in the file (names checked).
    source: where the layout came from (used in messages).
    regions: ``(patches,) int64`` the region of each patch of an assembly
        (:mod:`jaxmatch.meshing.assembly`): a side between two regions keeps both regions' areas
        like a boundary side keeps the region's (:func:`curve_floors`); None: one region.
    """

    points: np.ndarray
    patches: tuple[np.ndarray, ...]
    corner: np.ndarray
    patch_corner: tuple[np.ndarray, ...]
    requested: Mapping[str, int]
    source: str = "<layout>"
    regions: np.ndarray | None = None

    @property
    def n_patches(self) -> int:
        return len(self.patches)


class Sides(NamedTuple):
    """The sides of a layout: chains of points between *nodes* (points that are a corner of a
    patch containing them, or where the patches along the boundary change). A patch side
    (between two consecutive corners of the patch) is one or more layout sides: more than one
    where neighbours meet along it (a T-junction).

    chains: side ``s`` is ``(k_s,) int64`` point ids from one node to the next, in the
        direction of the first patch (lowest index) that runs along it.
    names: side names (``"i-j"``, or the whole chain when two sides have the same ends).
    patch_sides: patch ``p``, its side ``i`` (from its corner ``i`` to ``i + 1``): ``(k,) int64``
        the layout sides along it, in the patch's direction.
    patch_reversed: the same shape, ``bool``: the patch runs that side against its direction.
    users: ``(S, 2) int64`` the patches along each side (``-1``: none; one patch = outer side).
    lengths: ``(S,) float64`` side lengths (user units).
    """

    chains: tuple[np.ndarray, ...]
    names: tuple[str, ...]
    patch_sides: tuple[tuple[np.ndarray, ...], ...]
    patch_reversed: tuple[tuple[np.ndarray, ...], ...]
    users: np.ndarray
    lengths: np.ndarray

    @property
    def outer(self) -> np.ndarray:
        """``(S,) bool``: the side is on the outer boundary (one patch uses it)."""
        return self.users[:, 1] < 0


@dataclass(frozen=True, eq=False)
class LayoutMesh:
    """A layout meshed into one conforming quad mesh.

    xy: ``(V, 2) float64`` user coordinates; quads: ``(Q, 4) int64`` ccw; patch: ``(Q,) int64``
    the patch of each quad; side_vertices: side ``s``: ``(counts[s] + 1,) int64`` vertex ids
    along the side's direction; counts: ``(S,) int64`` edges per side; outer: ``(B,) int64``
    outer boundary loop (ccw); holes: each hole's boundary loop (cw); templates: catalogue id per patch; multiplicities: per patch
    ``(n_chords,) int64``; shared_gap: largest distance between the two patches' own positions
    of a shared side vertex before merging (0.0 when bit-identical); region_area: area of the
    union of the patches.
    """

    layout: Layout
    sides: Sides
    xy: np.ndarray
    quads: np.ndarray
    patch: np.ndarray
    side_vertices: tuple[np.ndarray, ...]
    counts: np.ndarray
    outer: np.ndarray
    templates: tuple[str, ...]
    multiplicities: tuple[np.ndarray, ...]
    shared_gap: float
    region_area: float
    holes: tuple[np.ndarray, ...] = ()

    @property
    def scaled_jacobian(self) -> np.ndarray:
        """``(Q,) float64`` Verdict scaled Jacobian per quad."""
        return quality(self.xy, self.quads)[0]

    @property
    def min_scaled_jacobian(self) -> float:
        return float(self.scaled_jacobian.min())

    @property
    def mean_scaled_jacobian(self) -> float:
        return float(self.scaled_jacobian.mean())

    @property
    def inverted(self) -> int:
        return int(inverted_mask(self.xy, self.quads).sum())

    @property
    def irregular(self) -> np.ndarray:
        """Internal vertices (not on the outer loop) whose valence is not 4."""
        val = valences(self.quads, self.xy.shape[0])
        internal = np.ones(self.xy.shape[0], bool)
        internal[self.outer] = False
        for loop in self.holes:
            internal[loop] = False
        return np.flatnonzero(internal & (val != 4))

    @property
    def area_ratio(self) -> float:
        """Sum of the quads' signed areas / area of the region."""
        return float(quad_areas(self.xy, self.quads).sum() / self.region_area)

    def summary(self) -> dict:
        """JSON-ready figures: quads, vertices, patches, quality, counts per side."""
        return {
            "quads": int(self.quads.shape[0]), "vertices": int(self.xy.shape[0]), "patches": self.layout.n_patches,
            "min_scaled_jacobian": self.min_scaled_jacobian, "mean_scaled_jacobian": self.mean_scaled_jacobian,
            "inverted": self.inverted, "irregular": int(self.irregular.size), "area_ratio": self.area_ratio,
            "shared_gap": self.shared_gap,
            "counts": {n: int(c) for n, c in zip(self.sides.names, self.counts)},
            "templates": list(self.templates),
        }


# ---------------------------------------------------------------------------------------------
# reading and validation


def load_layout(path) -> Layout:
    """Read a layout JSON file; see :func:`parse_layout`."""
    return parse_layout(read_limited(path, MAX_BYTES, "layout file"), str(path))


def parse_layout(data, source: str = "<layout>") -> Layout:
    """Parse layout JSON (bytes or text) into a validated :class:`Layout` (see
    :func:`make_layout`). Raises :class:`InputError` naming ``source``."""
    doc = _json(data, source)
    if not isinstance(doc, dict):
        raise InputError('top level must be a JSON object {"points": ..., "patches": ...}', where=source)
    unknown = [k for k in doc if k not in _KEYS]
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} (allowed: {', '.join(_KEYS)})", where=source)
    for key in ("points", "patches"):
        if key not in doc:
            raise InputError(f"missing key {key!r}", where=source)
    return make_layout(doc["points"], doc["patches"], doc.get("corners"), doc.get("sides"), source=source)


def _json(data, source: str):
    try:
        text = data if isinstance(data, str) else bytes(data).decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise InputError(f"not UTF-8 text (byte {err.start})", where=source) from None

    def no_constants(name):
        raise ValueError(f"{name} is not a finite number")

    try:
        return json.loads(text, parse_constant=no_constants)
    except json.JSONDecodeError as err:
        raise InputError(f"not valid JSON: {err.msg} (line {err.lineno}, column {err.colno})", where=source) from None
    except (ValueError, RecursionError) as err:
        raise InputError(f"not valid JSON ({err})", where=source) from None


def _int(value, what: str, source: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{what} must be an integer point index, got {value!r:.40}", where=source)
    return int(value)


def make_layout(points, patches, corners=None, sides=None, *, source: str = "<layout>", check: bool = True) -> Layout:
    """Validate a layout (see the module docstring for the rules) and normalise it: patches
    counter-clockwise, each starting at its first corner.

    points: ``(P, 2)`` numbers; patches: lists of point indices; corners: point indices (None:
    every point is a corner); sides: ``{name: count}`` (None: none requested).
    Raises :class:`InputError` (``where=source``) with one line naming the patch, point or side.
    check: False leaves the geometric checks (coincident points, simple patches, segments, cover:
    :func:`check_layout`) to the caller, for layouts made by code that may be dropped unmeshed
    (the pipeline's decompositions: a skipped layout is not checked).
    """
    try:
        pts = np.array(points, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError('"points" must be a list of [x, y] number pairs', where=source) from None
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 3:
        raise InputError(f'"points" must be at least 3 [x, y] pairs, got an array of shape {pts.shape}', where=source)
    if pts.shape[0] > MAX_POINTS:
        raise InputError(f"{pts.shape[0]} points, more than the maximum {MAX_POINTS}", where=source)
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise InputError(f"point {int(np.flatnonzero(bad)[0])} is not finite", where=source)
    P = pts.shape[0]
    extent = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    if not extent > 0:
        raise InputError("all points are at the same place", where=source)
    tol = _TOL * extent
    if check:
        _check_coincident(pts, tol, source)

    if not isinstance(patches, list) or not patches:
        raise InputError('"patches" must be a non-empty list of point-index loops', where=source)
    if corners is None:
        corner = np.ones(P, bool)
    else:
        if not isinstance(corners, list):
            raise InputError('"corners" must be a list of point indices', where=source)
        corner = np.zeros(P, bool)
        if all(type(c) is int and 0 <= c < P for c in corners):  # (the common case, without a call per entry)
            corner[corners] = True
        else:
            for j, c in enumerate(corners):
                c = _int(c, f"corners[{j}]", source)
                if not 0 <= c < P:
                    raise InputError(f"corners[{j}] = {c} is out of range (there are {P} points)", where=source)
                corner[c] = True

    loops: list[np.ndarray] = []
    pcorners: list[np.ndarray] = []
    polys = []
    for p, loop in enumerate(patches):
        if not isinstance(loop, list) or len(loop) < 3:
            raise InputError(f"patch {p} must be a list of at least 3 point indices", where=source)
        if all(type(v) is int for v in loop):  # (the common case, without a call per entry)
            ids, vals = np.array(loop, dtype=np.int64), loop
        else:
            ids = np.array([_int(v, f"patch {p} entry {i}", source) for i, v in enumerate(loop)], dtype=np.int64)
            vals = ids.tolist()
        if min(vals) < 0 or max(vals) >= P:
            out = ids[(ids < 0) | (ids >= P)]
            raise InputError(f"patch {p}: point index {int(out[0])} is out of range (there are {P} points)", where=source)
        if len(set(vals)) < len(vals):
            uniq, cnt = np.unique(ids, return_counts=True)
            raise InputError(f"patch {p} lists point {int(uniq[cnt > 1][0])} twice", where=source)
        xy = pts[ids]
        area = polygon_area(xy)
        if not abs(area) > tol * extent:
            raise InputError(f"patch {p} has zero area", where=source)
        if check:
            polys.append(_simple_patch(pts, ids, p, source))
        if area < 0:
            ids, xy = ids[::-1], xy[::-1]
        pc = corner[ids] & ~_straight(xy)
        cpos = np.flatnonzero(pc)
        if cpos.size < 2:
            raise InputError(f"patch {p} has {cpos.size} corner(s); a patch needs at least 2", where=source)
        loops.append(roll(ids, -int(cpos[0])))
        pcorners.append(roll(pc, -int(cpos[0])))

    if check:
        _check_segments(loops, source)
        _check_cover(pts, loops, polys, tol, source)
    layout = Layout(points=pts, patches=tuple(loops), corner=corner, patch_corner=tuple(pcorners), requested={},
                    source=source)
    if sides is None:
        return layout
    sd = layout_sides(layout)
    requested = parse_counts(sides, sd, source)
    return Layout(points=pts, patches=tuple(loops), corner=corner, patch_corner=tuple(pcorners),
                  requested={sd.names[s]: c for s, c in requested.items()}, source=source)


def check_layout(layout: Layout) -> None:
    """The geometric checks :func:`make_layout` leaves out with ``check=False`` (the same
    :class:`InputError` lines): no two points at the same place, simple patches, no segment used
    by three patches or twice in the same direction, no overlap, one region, no hanging node."""
    pts, source = layout.points, layout.source
    tol = _TOL * float(np.max(pts.max(axis=0) - pts.min(axis=0)))
    _check_coincident(pts, tol, source)
    polys = [_simple_patch(pts, loop, p, source) for p, loop in enumerate(layout.patches)]
    _check_segments(list(layout.patches), source)
    _check_cover(pts, list(layout.patches), polys, tol, source)


def _simple_patch(pts: np.ndarray, ids: np.ndarray, p: int, source: str):
    """Patch ``p`` (points ``ids``) as a shapely Polygon; InputError when it crosses or touches
    itself."""
    import shapely

    poly = shapely.Polygon(pts[ids])
    if not poly.is_valid:
        raise InputError(f"patch {p} crosses or touches itself ({shapely.is_valid_reason(poly)})", where=source)
    return poly


def _straight(loop_xy: np.ndarray) -> np.ndarray:
    """``(k,) bool``: the closed loop goes straight on at the point (turn below 1e-9 rad)."""
    e_in = loop_xy - roll(loop_xy, 1)
    e_out = roll(e_in, -1)  # (point i + 1's incoming edge: the same differences)
    cross = e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]
    dot = np.sum(e_in * e_out, axis=1)
    return (np.abs(np.arctan2(cross, dot)) <= 1e-9)


def _check_coincident(pts: np.ndarray, tol: float, source: str) -> None:
    """InputError naming the first pair ``i < j`` of points ``(P, 2)`` within ``tol`` of each other
    (shapely's STRtree, ``dwithin``: distance <= tol; not scipy's cKDTree: scipy.spatial's import
    costs the meshing command ~0.1 s, docs/perf.md "Start-up")."""
    import shapely

    geoms = shapely.points(pts)
    i, j = shapely.STRtree(geoms).query(geoms, predicate="dwithin", distance=tol)
    keep = i < j
    if keep.any():
        i, j = min(zip(i[keep].tolist(), j[keep].tolist()))
        raise InputError(f"points {i} and {j} are at the same place", where=source)


def _segments(loop: np.ndarray) -> list[tuple[int, int]]:
    """The ``k`` directed segments ``(a, b)`` of a closed loop ``(k,)`` of point ids, as Python ints."""
    ids = np.asarray(loop).tolist()
    return list(zip(ids, ids[1:] + ids[:1]))


def _check_segments(loops: Sequence[np.ndarray], source: str) -> None:
    """No segment used by three patches, or twice in the same direction."""
    users: dict[tuple[int, int], list[tuple[int, bool]]] = {}
    for p, loop in enumerate(loops):
        for a, b in _segments(loop):
            users.setdefault((min(a, b), max(a, b)), []).append((p, a < b))
    for (a, b), us in users.items():
        if len(us) > 2:
            raise InputError(f"side {a}-{b} is used by {len(us)} patches ({', '.join(str(u[0]) for u in us)}); "
                             "a side belongs to at most 2 patches", where=source)
        if len(us) == 2 and us[0][1] == us[1][1]:
            raise InputError(f"patches {us[0][0]} and {us[1][0]} overlap (both lie on the same side of segment {a}-{b})",
                             where=source)


def _check_cover(pts, loops, polys, tol: float, source: str):
    """Patches do not overlap, form one connected region (holes allowed: a frame of patches
    around a window), and every segment used by one patch lies on the region's boundary (its
    outer ring or a hole's). Returns the union (a shapely Polygon)."""
    import shapely

    tree = shapely.STRtree(polys)
    left, right = tree.query(polys, predicate="intersects")
    for i, j in zip(left.tolist(), right.tolist()):
        if i < j:
            inter = polys[i].intersection(polys[j]).area
            if inter > tol * max(math.sqrt(min(polys[i].area, polys[j].area)), tol):
                raise InputError(f"patches {i} and {j} overlap (common area {inter:.3g})", where=source)
    union = shapely.union_all(polys)
    if union.geom_type != "Polygon":
        raise InputError("the patches do not form one connected region (some patch touches the others only at a point, "
                         "or not at all)", where=source)
    count: dict[tuple[int, int], int] = {}
    owner: dict[tuple[int, int], int] = {}
    for p, loop in enumerate(loops):
        for a, b in _segments(loop):
            key = (min(a, b), max(a, b))
            count[key] = count.get(key, 0) + 1
            owner[key] = p
    ring = union.boundary  # the outer ring and the holes' rings
    lone = [ab for ab, c in count.items() if c == 1]
    if lone:
        ab = np.asarray(lone, np.int64)
        far = np.flatnonzero(shapely.distance(ring, shapely.points(0.5 * (pts[ab[:, 0]] + pts[ab[:, 1]]))) > 10 * tol)
        if far.size:
            a, b = lone[int(far[0])]
            raise InputError(f"segment {a}-{b} of patch {owner[(a, b)]} lies inside the region but no other patch uses it "
                             "(patches meet there without sharing their points: a hanging node, or a gap)", where=source)
    return union


def layout_sides(layout: Layout) -> Sides:
    """The sides of ``layout`` (see :class:`Sides`)."""
    pts = layout.points
    users: dict[tuple[int, int], list[int]] = {}
    keys = []  # per patch, its segments' undirected keys
    for p, loop in enumerate(layout.patches):
        ks = [(a, b) if a < b else (b, a) for a, b in _segments(loop)]
        keys.append(ks)
        for k in ks:
            users.setdefault(k, []).append(p)
    node = np.zeros(pts.shape[0], bool)
    for loop, pc, ks in zip(layout.patches, layout.patch_corner, keys):
        node[loop[pc]] = True
        seg = [users[k] for k in ks]
        change = [i for i in range(len(seg)) if seg[i - 1] != seg[i]]  # users differ before/after point i
        node[loop[change]] = True
    chains: list[list[int]] = []  # (Python lists here, arrays in the answer)
    owner: list[list[int]] = []
    by_first: dict[tuple[int, int], int] = {}  # first directed segment of a chain -> side id
    patch_sides, patch_rev = [], []
    is_node = node.tolist()
    for p, (loop, pc) in enumerate(zip(layout.patches, layout.patch_corner)):
        lp = loop.tolist()
        k = len(lp)
        nodes = [i for i, v in enumerate(lp) if is_node[v]]  # starts with 0: the loop starts at a corner
        corners = set(np.flatnonzero(pc).tolist())
        ids, rev = [], []
        cur_ids, cur_rev = [], []
        for j, start in enumerate(nodes):
            stop = nodes[j + 1] if j + 1 < len(nodes) else k
            chain = lp[start:stop + 1] if stop < k else lp[start:] + lp[:1]
            back = (chain[-1], chain[-2])  # the other patch's first segment, if it ran it before
            if back in by_first and chains[by_first[back]] == chain[::-1]:
                sid = by_first[back]
                owner[sid].append(p)
                cur_ids.append(sid)
                cur_rev.append(True)
            else:
                sid = len(chains)
                chains.append(chain)
                owner.append([p])
                by_first[(chain[0], chain[1])] = sid
                cur_ids.append(sid)
                cur_rev.append(False)
            if stop % k in corners:
                ids.append(np.asarray(cur_ids, np.int64))
                rev.append(np.asarray(cur_rev, bool))
                cur_ids, cur_rev = [], []
        patch_sides.append(tuple(ids))
        patch_rev.append(tuple(rev))
    ends_count: dict[tuple[int, int], int] = {}
    for c in chains:
        key = (min(c[0], c[-1]), max(c[0], c[-1]))
        ends_count[key] = ends_count.get(key, 0) + 1
    names = tuple(f"{c[0]}-{c[-1]}" if ends_count[(min(c[0], c[-1]), max(c[0], c[-1]))] == 1 else _chain_name(c)
                  for c in chains)
    u = np.full((len(chains), 2), -1, np.int64)
    for sid, us in enumerate(owner):
        if len(us) > 2:  # cannot happen after _check_segments
            raise InputError(f"side {names[sid]} is used by {len(us)} patches", where=layout.source)
        u[sid, : len(us)] = us
    seg = np.linalg.norm(np.diff(pts[[v for c in chains for v in c]], axis=0), axis=1)  # the chains' segments, end to end
    ends = np.cumsum([len(c) for c in chains]).tolist()
    lengths = np.array([float(seg[a:b - 1].sum()) for a, b in zip([0] + ends[:-1], ends)])
    return Sides(tuple(np.array(c, np.int64) for c in chains), names, tuple(patch_sides), tuple(patch_rev), u, lengths)


def _chain_name(chain) -> str:
    return "-".join(str(int(v)) for v in chain)


def parse_counts(counts, sides: Sides, source: str) -> dict[int, int]:
    """``{name: count}`` (names ``"i-j"`` in either order, or whole chains) as
    ``{side id: count}``. Raises :class:`InputError` for unknown sides or counts < 1."""
    if not isinstance(counts, dict):
        raise InputError('"sides" must be an object {"i-j": count, ...}', where=source)
    if not counts:
        return {}
    lookup: dict[tuple[int, ...], int] = {}
    for s, (c, name) in enumerate(zip(sides.chains, sides.names)):
        for key in (tuple(int(v) for v in name.split("-")), tuple(int(v) for v in c)):
            lookup[key] = s
            lookup[key[::-1]] = s
    out: dict[int, int] = {}
    for name, value in counts.items():
        try:
            key = tuple(int(v) for v in str(name).split("-"))
        except ValueError:
            key = ()
        if len(key) < 2 or key not in lookup:
            raise InputError(f"side {str(name)[:40]!r} is not a side of the layout (sides are named 'i-j' by their "
                             "corner points)", where=source)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise InputError(f"side {name}: the edge count must be a positive integer, got {value!r:.40}", where=source)
        s = lookup[key]
        if s in out and out[s] != value:
            raise InputError(f"side {name} is given twice with different counts", where=source)
        out[s] = int(value)
    return out


def load_counts(path, sides: Sides) -> dict[int, int]:
    """Read a sides file ``{"i-j": count, ...}`` (JSON) as ``{side id: count}``."""
    src = str(path)
    return parse_counts(_json(read_limited(path, MAX_BYTES, "sides file"), src), sides, src)


# ---------------------------------------------------------------------------------------------
# patches as shapes


def patch_shapes(layout: Layout) -> list[Shape]:
    """One :class:`Shape` per patch, with the patch's corners (:attr:`Layout.patch_corner`) as
    explicit corners in loop order, so that the shape's side ``i`` is the patch's side ``i``
    (:attr:`Sides.patch_sides`). The layout is taken as checked (:func:`make_layout`,
    :func:`check_layout`): its patches are simple loops of distinct points."""
    out = []
    for p, (loop, pc) in enumerate(zip(layout.patches, layout.patch_corner)):
        out.append(make_shape(layout.points[loop], corners=np.flatnonzero(pc).tolist(), source=f"{layout.source} patch {p}",
                              checked=True))
    return out


# ---------------------------------------------------------------------------------------------
# the integer program


def region_area(layout: Layout) -> float:
    """Area of the region the patches of ``layout`` cover (their union; user units squared). The
    patches' polygons are made in one call (the rings ``shapely.Polygon`` makes of each, a quarter
    of the time on a layout of 2-8 patches)."""
    import shapely

    loops = layout.patches
    rings = shapely.linearrings(layout.points[np.concatenate(loops)],
                                indices=np.repeat(np.arange(len(loops)), [len(lp) for lp in loops]))
    return float(shapely.union_all(shapely.polygons(rings)).area)


# ---------------------------------------------------------------------------------------------
# merging


def merge_patches(layout: Layout, sides: Sides, refined: Sequence, counts: np.ndarray):
    """Merge refined patches into one mesh with one vertex per side position.

    refined: per patch a :class:`jaxmatch.placement.refine.RefinedMesh` (``xy``, ``quads``,
    ``side_vertices`` from the patch's corner ``i`` to ``i + 1``). Returns ``(xy (V, 2)
    float64, quads (Q, 4) int64, patch (Q,) int64, side_vertices per layout side, shared_gap
    float)``. Every layout side's vertices get global ids once (its end points are layout
    points), so a shared side is one set of vertices; a patch side made of several layout sides
    is cut into them by their counts. Positions come from the first patch along the side, and
    ``shared_gap`` is the largest distance to the other patch's own position of the same vertex
    (use :func:`fit_sides` first so that the patches agree). Raises ValueError when a patch's
    side counts disagree with ``counts`` (a bug, not bad input).
    """
    S = len(sides.chains)
    ends = [(int(c[0]), int(c[-1])) for c in sides.chains]
    node_pts = np.array(sorted({v for e in ends for v in e}), np.int64)
    nid = np.full(layout.points.shape[0], -1, np.int64)
    nid[node_pts] = np.arange(node_pts.size)
    cl = [int(c) for c in np.asarray(counts).tolist()]
    # every side's ids in one array (its end nodes, then its inner vertices numbered side after side), cut into sides
    stop = np.cumsum(np.asarray(cl, np.int64) + 1)
    start = stop - (np.asarray(cl, np.int64) + 1)
    flat = np.empty(int(stop[-1]) if S else 0, np.int64)
    inner = np.ones(flat.size, bool)
    inner[start], inner[stop - 1] = False, False
    nxt = node_pts.size + int(np.count_nonzero(inner))
    flat[inner] = np.arange(node_pts.size, nxt)
    flat[start] = nid[[e[0] for e in ends]]
    flat[stop - 1] = nid[[e[1] for e in ends]]
    side_ids = [flat[a:b] for a, b in zip(start.tolist(), stop.tolist())]
    # every patch at once: patch p's vertex v is v + start[p] of the patches' vertices end to end
    rxy = [np.asarray(rm.xy, dtype=np.float64) for rm in refined]
    start = np.cumsum([0] + [x.shape[0] for x in rxy]).tolist()
    svs, gs, qs = [], [], []
    for p, rm in enumerate(refined):
        for i, (parts, revs) in enumerate(zip(sides.patch_sides[p], sides.patch_reversed[p])):
            sv = rm.side_vertices[i]
            parts, revs = parts.tolist(), revs.tolist()
            want = sum(cl[s] for s in parts)
            if len(sv) != want + 1:
                raise ValueError(f"patch {p} side {i} has {len(sv) - 1} edges, the program chose {want}")
            ids = [side_ids[s][::-1] if r else side_ids[s] for s, r in zip(parts, revs)]
            svs.append(np.asarray(sv, np.int64) + start[p])
            gs.append(ids[0] if len(ids) == 1 else np.concatenate([x[:-1] for x in ids] + [ids[-1][-1:]]))
        qs.append(np.asarray(rm.quads, dtype=np.int64) + start[p])
    sv, g = np.concatenate(svs), np.concatenate(gs)
    local = np.full(start[-1], -1, np.int64)
    local[sv] = g
    wrong = np.flatnonzero(local[sv] != g)
    if wrong.size:
        p = int(np.searchsorted(start, sv[wrong[0]], side="right")) - 1
        raise ValueError(f"patch {p}: a vertex is on two sides at different places")
    pos = np.concatenate(rxy)
    _, first = np.unique(g, return_index=True)  # each side vertex placed by the first patch along it
    xy_side = np.full((nxt, 2), np.nan)
    xy_side[g[first]] = pos[sv[first]]
    d = xy_side[g] - pos[sv]  # (0 for the first patch's own)
    gap = math.sqrt(float(np.max(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]))) if d.size else 0.0
    inner = np.flatnonzero(local < 0)  # patch by patch, each in its vertex order
    local[inner] = nxt + np.arange(inner.size)
    xy = np.concatenate([xy_side, pos[inner]])
    xy[nid[node_pts]] = layout.points[node_pts]  # nodes: exactly the layout's coordinates
    quads = local[np.concatenate(qs)]
    patch = np.repeat(np.arange(len(qs), dtype=np.int64), [x.shape[0] for x in qs])
    return xy, quads, patch, tuple(side_ids), gap


def fit_sides(layout: Layout, sides: Sides, p: int, refined, counts: np.ndarray, *, smooth_iters: int = 200,
              quality: Quality = QUALITY, cache: Cache | None = None) -> np.ndarray:
    """Positions ``(V, 2)`` of patch ``p``'s refined mesh with every side vertex where the
    layout side it belongs to puts it: ``counts[s]`` edges evenly spaced by arc length on each
    layout side (:func:`jaxmatch.placement.refine.side_points`, the formula the refinement uses,
    so a patch side made of one layout side does not move). Where a patch side is made of
    several layout sides (neighbours meet along it), its vertices move so that one lands on
    each node; then the interior follows (harmonic extension of the boundary displacement, one
    sparse solve) and is untangled and smoothed (:func:`jaxmatch.placement.embed.smooth`,
    never lowering the minimum scaled Jacobian from there). Above
    :data:`~jaxmatch.placement.refine.SMOOTH_LOCAL` quads, as a refinement of that size: the
    solve of the refinement (:func:`~jaxmatch.placement.refine.harmonic_displacement`: the same
    system, its factorisation kept), and only the vertices within
    :data:`~jaxmatch.placement.refine.BAD_RINGS` rings of the quads that fold or fall below
    ``quality.good_sj`` smoothed, with
    :data:`~jaxmatch.placement.refine.SMOOTH_ITERS_LARGE` iterations (none when there are none).

    Returns ``(V, 2) float64`` user coordinates."""
    xy = np.array(refined.xy, dtype=np.float64)
    moved = False
    bverts = []
    for i, (parts, revs) in enumerate(zip(sides.patch_sides[p], sides.patch_reversed[p])):
        sv = np.asarray(refined.side_vertices[i], dtype=np.int64)
        bverts.append(sv)
        if len(parts) == 1:
            continue
        pos = []
        for s, r in zip(parts, revs):
            q = side_points(layout.points[sides.chains[s]], int(counts[s]), quality.field)
            pos.append((q[::-1] if r else q)[:-1])
        last = sides.chains[parts[-1]][0 if revs[-1] else -1]  # the end corner of the patch side
        new = np.concatenate(pos + [layout.points[last][None]])
        moved |= not np.array_equal(new, xy[sv])
        xy[sv] = new
    if not moved:
        return xy
    b = np.unique(np.concatenate(bverts))
    quads = np.asarray(refined.quads, dtype=np.int64)
    target = xy[b].copy()
    large = quads.shape[0] > SMOOTH_LOCAL
    if large:
        disp = harmonic_displacement(quads, xy.shape[0], b, target - np.asarray(refined.xy)[b], cache=cache)
    else:
        disp = tutte(quads, xy.shape[0], b, target - np.asarray(refined.xy)[b])
    xy = np.asarray(refined.xy) + disp
    xy[b] = target
    if not large:
        iters = smooth_iters if quality.field is None else min(smooth_iters, SMOOTH_ITERS_GRADED)
        return smooth_in_frame(xy, quads, b, frame=target, iters=iters)
    bad = bad_quads(*sj_inverted(xy, quads), quality.good_sj)
    return smooth_near_bad(xy, quads, bad, b, frame=target) if bad.any() else xy


def _boundary_loops(layout: Layout, sides: Sides, side_ids, xy: np.ndarray) -> list[np.ndarray]:
    """Vertex ids of every boundary loop (in the patches' direction: the outer loop ccw, holes
    cw), from the sides one patch uses; the outer loop (largest signed area) first, then the holes
    by signed area (ties to 1e-9 of the largest in the order found: by their smallest vertex id)."""
    nxt: dict[int, np.ndarray] = {}
    for p in range(layout.n_patches):
        for s, rev in zip(np.concatenate(sides.patch_sides[p]), np.concatenate(sides.patch_reversed[p])):
            if sides.users[s, 1] < 0:
                ids = side_ids[s][::-1] if rev else side_ids[s]
                nxt[int(ids[0])] = ids
    loops, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        out, v = [], start
        while v not in seen:
            seen.add(v)
            ids = nxt[v]
            out.append(ids[:-1])
            seen.update(ids[1:-1].tolist())
            v = int(ids[-1])
        loops.append(np.concatenate(out))
    if len(loops) > 1:  # (loops of the same area up to round-off, e.g. two equal holes, in the order found)
        area = np.array([polygon_area(xy[lp]) for lp in loops])
        key = np.round(area / np.abs(area).max(), 9)
        loops = [loops[i] for i in sorted(range(len(loops)), key=lambda i: (-key[i], i))]
    return loops
