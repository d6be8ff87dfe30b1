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
            ids = np.array(loop, dtype=np.int64)
        else:
            ids = np.array([_int(v, f"patch {p} entry {i}", source) for i, v in enumerate(loop)], dtype=np.int64)
        out = ids[(ids < 0) | (ids >= P)]
        if out.size:
            raise InputError(f"patch {p}: point index {int(out[0])} is out of range (there are {P} points)", where=source)
        if len(set(ids.tolist())) < ids.size:
            uniq, cnt = np.unique(ids, return_counts=True)
            raise InputError(f"patch {p} lists point {int(uniq[cnt > 1][0])} twice", where=source)
        area = polygon_area(pts[ids])
        if not abs(area) > tol * extent:
            raise InputError(f"patch {p} has zero area", where=source)
        if check:
            polys.append(_simple_patch(pts, ids, p, source))
        if area < 0:
            ids = ids[::-1]
        pc = corner[ids] & ~_straight(pts[ids])
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
    e_out = roll(loop_xy, -1) - loop_xy
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


def _segments(loop: np.ndarray) -> np.ndarray:
    """``(k, 2) int64`` directed segments of a closed loop."""
    return np.stack([loop, roll(loop, -1)], axis=1)


def _check_segments(loops: Sequence[np.ndarray], source: str) -> None:
    """No segment used by three patches, or twice in the same direction."""
    users: dict[tuple[int, int], list[tuple[int, bool]]] = {}
    for p, loop in enumerate(loops):
        for a, b in _segments(loop).tolist():
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
        for a, b in _segments(loop).tolist():
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
    for p, loop in enumerate(layout.patches):
        for a, b in _segments(loop).tolist():
            users.setdefault((min(a, b), max(a, b)), []).append(p)
    node = np.zeros(pts.shape[0], bool)
    for loop, pc in zip(layout.patches, layout.patch_corner):
        node[loop[pc]] = True
        seg = [tuple(users[(min(a, b), max(a, b))]) for a, b in _segments(loop).tolist()]
        change = np.array([seg[i - 1] != seg[i] for i in range(len(seg))])  # users differ before/after point i
        node[loop[change]] = True
    chains: list[np.ndarray] = []
    owner: list[list[int]] = []
    by_first: dict[tuple[int, int], int] = {}  # first directed segment of a chain -> side id
    patch_sides, patch_rev = [], []
    for p, (loop, pc) in enumerate(zip(layout.patches, layout.patch_corner)):
        k = loop.size
        nodes = np.flatnonzero(node[loop])  # starts with 0: the loop starts at a corner
        corners = set(np.flatnonzero(pc).tolist())
        ids, rev = [], []
        cur_ids, cur_rev = [], []
        for j, start in enumerate(nodes.tolist()):
            stop = nodes[j + 1] if j + 1 < nodes.size else k
            chain = loop[np.arange(start, stop + 1) % k]
            back = (int(chain[-1]), int(chain[-2]))  # the other patch's first segment, if it ran it before
            if back in by_first and np.array_equal(chains[by_first[back]], chain[::-1]):
                sid = by_first[back]
                owner[sid].append(p)
                cur_ids.append(sid)
                cur_rev.append(True)
            else:
                sid = len(chains)
                chains.append(chain)
                owner.append([p])
                by_first[(int(chain[0]), int(chain[1]))] = sid
                cur_ids.append(sid)
                cur_rev.append(False)
            if int(stop) % k in corners:
                ids.append(np.asarray(cur_ids, np.int64))
                rev.append(np.asarray(cur_rev, bool))
                cur_ids, cur_rev = [], []
        patch_sides.append(tuple(ids))
        patch_rev.append(tuple(rev))
    ends_count: dict[tuple[int, int], int] = {}
    for c in chains:
        key = (min(int(c[0]), int(c[-1])), max(int(c[0]), int(c[-1])))
        ends_count[key] = ends_count.get(key, 0) + 1
    names = tuple(
        f"{int(c[0])}-{int(c[-1])}" if ends_count[(min(int(c[0]), int(c[-1])), max(int(c[0]), int(c[-1])))] == 1
        else _chain_name(c) for c in chains)
    u = np.full((len(chains), 2), -1, np.int64)
    for sid, us in enumerate(owner):
        if len(us) > 2:  # cannot happen after _check_segments
            raise InputError(f"side {names[sid]} is used by {len(us)} patches", where=layout.source)
        u[sid, : len(us)] = us
    seg = np.linalg.norm(np.diff(pts[np.concatenate(chains)], axis=0), axis=1)  # the chains' segments, end to end
    ends = np.cumsum([len(c) for c in chains])
    lengths = np.array([float(seg[a:b - 1].sum()) for a, b in zip(np.concatenate([[0], ends[:-1]]), ends)])
    return Sides(tuple(chains), names, tuple(patch_sides), tuple(patch_rev), u, lengths)


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


def chord_area_error(polyline: np.ndarray, n: int) -> float:
    """Area between ``polyline (k, 2)`` and the chords through its ``n + 1`` points evenly spaced
    by arc length (:func:`jaxmatch.placement.refine.side_points`, where the mesh puts its
    vertices): the sum over the ``n`` pieces of the absolute area each piece encloses with its
    chord (user units squared; 0 for a straight side). :func:`chord_area_errors` of one count."""
    return float(chord_area_errors(polyline, [n])[0])


def chord_area_errors(polyline: np.ndarray, counts) -> np.ndarray:
    """:func:`chord_area_error` of ``polyline (k, 2)`` for each piece count of ``counts (c,)``:
    ``(c,) float64`` (user units squared), every count's pieces at once.

    Each piece's ring (its first chord point, the polyline's points strictly inside it, its last
    chord point) is laid end to end in one array and its shoelace terms summed per ring
    (``np.add.reduceat``; a piece with no point inside is its chord: 0 exactly); a count's
    absolute areas are added piece by piece, in order. The chord points are those of
    :func:`~jaxmatch.placement.refine.side_points` and the pieces' ends those of
    ``np.linspace(0, length, n + 1)``, computed by the same operations (the same doubles,
    tested), so a count's error does not depend on the other counts asked with it."""
    p = np.asarray(polyline, np.float64)
    ns = np.asarray(counts, np.int64).reshape(-1)
    k = p.shape[0]
    if k <= 2 or not ns.size:
        return np.zeros(ns.shape[0])
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    flip = (not np.array_equal(p[0], p[-1])) and tuple(p[-1]) < tuple(p[0])  # (as side_points)
    f, fseg = (p[::-1], seg[::-1]) if flip else (p, seg)
    fcum = np.concatenate([[0.0], np.cumsum(fseg)]) if flip else cum
    per = ns + 1  # each count's chord points
    first = np.concatenate([[0], np.cumsum(per)[:-1]])
    of = np.repeat(first, per)
    j = np.arange(int(per.sum())) - of  # the point's place among its count's
    big_n = np.repeat(ns, per)
    t = j / big_n * fcum[-1]  # side_points: np.arange(N + 1) / N * length
    idx = np.clip(np.searchsorted(fcum, t, side="right") - 1, 0, k - 2)
    w = np.where(fseg[idx] > 0, (t - fcum[idx]) / np.where(fseg[idx] > 0, fseg[idx], 1.0), 0.0)
    q = f[idx] + w[:, None] * (f[idx + 1] - f[idx])
    q[first], q[first + ns] = f[0], f[-1]
    if flip:
        q = q[of + big_n - j]
    ends = j * (cum[-1] / big_n) + 0.0  # np.linspace(0, cum[-1], n + 1)
    ends[first + ns] = cum[-1]
    piece = np.flatnonzero(j < big_n)  # piece i of a count runs from its point i to i + 1
    cut = np.searchsorted(cum, ends[piece], side="right")  # vertices strictly after the piece start
    m = np.searchsorted(cum, ends[piece + 1], side="left") - cut  # and strictly before its end
    size = np.maximum(m, 0) + 2
    starts = np.concatenate([[0], np.cumsum(size)[:-1]])
    at = np.arange(int(size.sum())) - np.repeat(starts, size)  # place within its ring
    ring = p[np.clip(np.repeat(cut - 1, size) + at, 0, k - 1)]
    last = starts + size - 1
    ring[starts], ring[last] = q[piece], q[piece + 1]
    nxt = np.arange(1, ring.shape[0] + 1)
    nxt[last] = starts  # each ring closes on its first point
    x, y = ring[:, 0], ring[:, 1]
    area = np.abs(0.5 * np.add.reduceat(x * y[nxt] - x[nxt] * y, starts))
    table = np.zeros((ns.shape[0], int(ns.max())))  # one row a count, its pieces in order
    table[np.repeat(np.arange(ns.shape[0]), ns), j[piece]] = area
    return np.cumsum(table, axis=1)[:, -1]  # added in order, as one at a time


CURVE_SHARE = 0.8
"""The part of the area tolerance (``Quality.area_tol``) that the chords of curved sides may
use, shared among the curved boundary sides by length (:func:`curve_floors`)."""

CURVE_ZERO = 1e-9
"""A boundary side whose single chord leaves less than this fraction of the region's area is
straight (:func:`curve_floors`: no share of the area budget)."""


def region_area(layout: Layout) -> float:
    """Area of the region the patches of ``layout`` cover (their union; user units squared)."""
    import shapely

    return float(shapely.union_all([shapely.Polygon(layout.points[lp]) for lp in layout.patches]).area)


def _region_shares(layout: Layout, sides: Sides) -> np.ndarray:
    """``(S,) float64`` per side on a region's boundary (the outline, or between two regions of
    an assembly): the smallest over its regions of area / boundary length; inf for the others."""
    reg = np.asarray(layout.regions, np.int64)
    n = int(reg.max()) + 1
    area = np.zeros(n)
    for p, loop in enumerate(layout.patches):
        area[reg[p]] += abs(polygon_area(layout.points[loop]))
    users = sides.users
    r0 = reg[users[:, 0]]
    r1 = np.where(users[:, 1] >= 0, reg[np.maximum(users[:, 1], 0)], -1)
    on = r0 != r1
    length = np.zeros(n)
    np.add.at(length, r0[on], sides.lengths[on])
    inner = on & (r1 >= 0)
    np.add.at(length, r1[inner], sides.lengths[inner])
    share = np.full(len(users), np.inf)
    share[on] = area[r0[on]] / length[r0[on]]
    share[inner] = np.minimum(share[inner], area[r1[inner]] / length[r1[inner]])
    return share


def curve_floors(layout: Layout, sides: Sides, area_tol: float, region: float | None = None, *,
                 lean: bool = False, size: float | None = None) -> np.ndarray:
    """``(S,) int64`` the fewest edges each side may have so that its chords keep the region's
    area: a boundary side whose points do not lie on one line gets at least the edges that keep
    the area between it and its chords within its share of :data:`CURVE_SHARE` ``* area_tol`` of
    the region's area: its length over the whole boundary's; every other side 1. With ``lean``
    the curved boundary sides share the budget alone (a straight side loses no area and takes
    none: coarser curves, nearer the size, where the outline also has straight sides), allocated
    where it pays and by sign (:func:`lean_curve_floors`; ``size``: the target edge length, the
    curved sides' starting counts). ``region``: :func:`region_area` of ``layout`` when the caller
    has it. An assembly's layout (``layout.regions``): a side between two regions is kept like a
    boundary side of each, its budget the smaller of the two regions' shares (``lean`` does not
    apply)."""
    floors = np.ones(len(sides.chains), np.int64)
    own = _region_shares(layout, sides) if layout.regions is not None else None
    bound = np.flatnonzero(sides.outer if own is None else ~np.isinf(own))
    if not bound.size:
        return floors
    known = {int(s): _first_errors(layout.points[sides.chains[s]]) for s in bound}  # (one chord, the doubling counts)
    err1 = {s: errs[1] for s, errs in known.items()}
    if region is None and own is None:
        region = region_area(layout)
    curved = [s for s in bound if err1[int(s)] > CURVE_ZERO * region] if lean and own is None else bound
    if lean and own is None:
        chains = [layout.points[sides.chains[s]] for s in curved]
        floors[curved] = lean_curve_floors(chains, CURVE_SHARE * area_tol * region, size)
        return floors
    total = float(np.sum(sides.lengths[curved])) if len(curved) else 1.0
    for s in bound:
        poly = layout.points[sides.chains[s]]
        if poly.shape[0] <= 2:
            continue
        if own is not None:
            budget = CURVE_SHARE * area_tol * float(own[s]) * float(sides.lengths[s])
        else:
            budget = CURVE_SHARE * area_tol * region * float(sides.lengths[s]) / total
        if err1[int(s)] <= budget:
            continue
        floors[s] = _fewest_pieces(poly, budget, known[int(s)])
    return floors


def chord_piece_areas(polyline: np.ndarray, n: int) -> np.ndarray:
    """``(n,) float64`` the signed area each of the ``n`` pieces of ``polyline (k, 2)`` encloses
    with its chord, the pieces' ends evenly spaced by arc length as in :func:`chord_area_error`
    (whose error is the sum of their absolute values; user units squared). The sign is the
    shoelace's of the ring (the piece's first chord point, the polyline's points strictly inside
    it, its last chord point): positive where the polyline runs to the right of its chord. Along
    a boundary side of a counter-clockwise patch loop (the region on its left): positive, the
    area the chord cuts off the region (a convex stretch); negative, the area it adds (a concave
    stretch, a hole's side)."""
    p0 = np.asarray(polyline, np.float64)
    k, n = p0.shape[0], int(n)
    if k <= 2:
        return np.zeros(n)
    centre = 0.5 * (p0.min(axis=0) + p0.max(axis=0))  # (cross products of small coordinates)
    p = p0 - centre
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p0, axis=0), axis=1))])
    q = side_points(p0, n) - centre
    t = np.linspace(0.0, cum[-1], n + 1)
    a = np.searchsorted(cum, t[:-1], side="right")  # each piece's points inside: p[a:b]
    b = np.searchsorted(cum, t[1:], side="left")

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    pre = np.concatenate([[0.0], np.cumsum(cross(p[:-1], p[1:]))])  # pre[j]: the polyline's terms before point j
    ai, bi = np.minimum(a, k - 1), np.clip(b - 1, 0, k - 1)
    ring = cross(q[:-1], p[ai]) + (pre[np.maximum(bi, ai)] - pre[ai]) + cross(p[bi], q[1:]) + cross(q[1:], q[:-1])
    return np.where(b > a, 0.5 * ring, 0.0)


def lean_curve_floors(chains: Sequence[np.ndarray], budget: float, size: float | None = None) -> np.ndarray:
    """``(C,) int64`` the floors of the curved boundary sides ``chains[i] (k_i, 2)`` (user units,
    each run along a counter-clockwise patch loop: the region on its left): edge counts that keep
    the region's area within ``budget`` (user units squared), the budget allocated where it pays.

    Signs: a piece's chord cuts area off the region where the side is convex there and adds area
    where it is concave (:func:`chord_piece_areas`), and the area check is signed
    (``|mesh area / region - 1| <= area_tol``). If the pieces that lose area lose at most
    ``budget`` in all and those that add area add at most ``budget``, the net change is at most
    ``budget``: each sign group has the whole budget (a side with pieces of both signs counts in
    both).

    Allocation by marginal gain: every side starts at its size count (``round(length / size)``,
    at least 1; 1 without ``size``) and, while a sign group's total exceeds ``budget``, the side
    whose next edge lowers the exceeding groups' totals most per unit of size deviation gets it
    (the deviation of ``n`` edges of length ``L / n``: ``n * log(L / (n size))^2``; without
    ``size``, per edge). Greedy: the least deviation (the fewest edges) for one sign group when
    each side's error is convex and decreasing in its count, as a circular arc's is (~ 1 / n^2).
    A small hole or slot end keeps about its size count (its error is small) and the budget goes
    to the long arcs, where an edge more stays near the size. A side stops at ``4 * k_i`` edges.
    The floors keep their meaning as long as a side's errors fall as edges are added (at or
    above its floor, whatever count is chosen)."""
    C = len(chains)
    if not C:
        return np.zeros(0, np.int64)
    lengths = np.array([float(np.linalg.norm(np.diff(c, axis=0), axis=1).sum()) for c in chains])
    n = np.ones(C, np.int64) if size is None else np.maximum(1, np.rint(lengths / float(size))).astype(np.int64)
    cap = np.array([4 * c.shape[0] for c in chains], np.int64)
    n = np.minimum(n, cap)

    def groups(i: int, m: int) -> np.ndarray:  # (2,) area lost, area added
        a = chord_piece_areas(chains[i], m)
        return np.array([a[a > 0].sum(), -a[a < 0].sum()])

    now = np.array([groups(i, int(n[i])) for i in range(C)])  # (C, 2)
    nxt = np.array([groups(i, int(n[i]) + 1) for i in range(C)])
    total = now.sum(axis=0)
    x = None if size is None else np.maximum(lengths / float(size), 1e-12)  # (the size counts, unrounded)

    def cost(m: np.ndarray) -> np.ndarray:  # edges, or their squared log distance to the size
        return m.astype(np.float64) if x is None else m * np.log(m / x) ** 2

    while np.any(total > budget):
        over = (total > budget).astype(np.float64)
        gain = np.where(n < cap, (now - nxt) @ over / np.maximum(cost(n + 1) - cost(n), 1e-12), -np.inf)
        i = int(np.argmax(gain))
        if not np.isfinite(gain[i]):
            break
        n[i] += 1
        total += nxt[i] - now[i]
        now[i], nxt[i] = nxt[i], groups(i, int(n[i]) + 1)
    return n


CURVE_BATCH = 2048
"""Pieces measured together (:func:`chord_area_errors`) in the search for a curved side's fewest
pieces (:func:`_fewest_pieces`): the doubling counts up to this many pieces in all, then every
count between the last two if they are at most this many."""


CURVE_POINTS = 64
"""A side of at most this many points is measured at the doubling counts of
:func:`_fewest_pieces` together with its one chord (:func:`_first_errors`), before it is known to
need them: a short side's extra counts cost less than another call; a long, straight side (a
densely traced outline) is measured at one piece only."""


def _doubling(k: int) -> list[int]:
    """The counts :func:`_fewest_pieces` doubles through on a side of ``k`` points (2, 4, ... up
    to the first at least ``4 k``) that fit in :data:`CURVE_BATCH` pieces in all."""
    steps = [2]
    while steps[-1] < 4 * k:
        steps.append(steps[-1] * 2)
    return [n for n, total in zip(steps, np.cumsum(steps)) if total <= CURVE_BATCH]


def _first_errors(poly: np.ndarray) -> dict[int, float]:
    """``{count: error}`` (:func:`chord_area_error`) of the side ``poly (k, 2)`` at one piece and,
    up to :data:`CURVE_POINTS` points, at the counts of :func:`_doubling`, in one
    :func:`chord_area_errors` call; ``{1: 0.0}`` for a two-point side."""
    if poly.shape[0] <= 2:
        return {1: 0.0}
    counts = [1] + (_doubling(poly.shape[0]) if poly.shape[0] <= CURVE_POINTS else [])
    return dict(zip(counts, chord_area_errors(poly, counts).tolist()))


def _fewest_pieces(poly: np.ndarray, budget: float, known: dict[int, float] | None = None) -> int:
    """The pieces that :func:`curve_floors` gives the curved side ``poly (k, 2)`` for ``budget``
    (user units squared), whose one chord exceeds it: counts doubled from 2 until the error
    (:func:`chord_area_error`) keeps the budget or the count reaches ``4 k``, then halved back to
    the fewest that keep it (the error falls as pieces are added). The counts it may ask for are
    measured in two batches (:data:`CURVE_BATCH`; ``known``: :func:`_first_errors` of ``poly``,
    the first of them, when the caller has it): each costs about as much as one count alone, and
    a count's error is the same however it is asked for (the same floors, tested)."""
    most = poly.shape[0] * 4
    known = dict(_first_errors(poly) if known is None else known)

    def ask(counts) -> None:
        new = [n for n in counts if n not in known]
        if new:
            known.update(zip(new, chord_area_errors(poly, new).tolist()))

    ask(_doubling(poly.shape[0]))
    lo, hi = 1, 2
    while True:
        ask([hi])
        if not (known[hi] > budget and hi < most):
            break
        lo, hi = hi, hi * 2
    between = range(lo + 1, hi)
    if sum(between) <= CURVE_BATCH:
        ask(between)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        ask([mid])
        lo, hi = (lo, mid) if known[mid] <= budget else (mid, hi)
    return hi


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
    node_pts = np.unique(np.concatenate([c[[0, -1]] for c in sides.chains]))
    nid = np.full(layout.points.shape[0], -1, np.int64)
    nid[node_pts] = np.arange(node_pts.size)
    nxt = node_pts.size
    side_ids = []
    for s in range(S):
        n = int(counts[s])
        ids = np.empty(n + 1, np.int64)
        ids[0], ids[-1] = nid[sides.chains[s][0]], nid[sides.chains[s][-1]]
        ids[1:-1] = np.arange(nxt, nxt + n - 1)
        nxt += n - 1
        side_ids.append(ids)
    xy_side = np.full((nxt, 2), np.nan)
    gap = 0.0
    xy_parts, quad_parts, patch_parts = [], [], []
    cl = [int(c) for c in np.asarray(counts).tolist()]
    for p, rm in enumerate(refined):
        rxy = np.asarray(rm.xy, dtype=np.float64)
        local = np.full(rxy.shape[0], -1, np.int64)
        for i, (parts, revs) in enumerate(zip(sides.patch_sides[p], sides.patch_reversed[p])):
            sv = np.asarray(rm.side_vertices[i], dtype=np.int64)
            parts, revs = parts.tolist(), revs.tolist()
            want = sum(cl[s] for s in parts)
            if sv.size != want + 1:
                raise ValueError(f"patch {p} side {i} has {sv.size - 1} edges, the program chose {want}")
            ids = [side_ids[s][::-1] if r else side_ids[s] for s, r in zip(parts, revs)]
            g = ids[0] if len(ids) == 1 else np.concatenate([x[:-1] for x in ids] + [ids[-1][-1:]])
            old = local[sv]
            if np.any((old >= 0) & (old != g)):
                raise ValueError(f"patch {p}: a vertex is on two sides at different places")
            local[sv] = g
            pos = rxy[sv]
            have = ~np.isnan(xy_side[g, 0])
            if have.any():
                d = xy_side[g[have]] - pos[have]
                gap = max(gap, math.sqrt(float(np.max(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]))))
            xy_side[g[~have]] = pos[~have]
        inner = np.flatnonzero(local < 0)
        local[inner] = nxt + np.arange(inner.size)
        nxt += inner.size
        xy_parts.append(rxy[inner])
        quad_parts.append(local[np.asarray(rm.quads, dtype=np.int64)])
        patch_parts.append(np.full(len(rm.quads), p, np.int64))
    xy = np.concatenate([xy_side] + xy_parts)
    xy[nid[node_pts]] = layout.points[node_pts]  # nodes: exactly the layout's coordinates
    return xy, np.concatenate(quad_parts), np.concatenate(patch_parts), tuple(side_ids), gap


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
            seen.update(int(i) for i in ids[1:-1])
            v = int(ids[-1])
        loops.append(np.concatenate(out))
    if len(loops) > 1:  # (loops of the same area up to round-off, e.g. two equal holes, in the order found)
        area = np.array([polygon_area(xy[lp]) for lp in loops])
        key = np.round(area / np.abs(area).max(), 9)
        loops = [loops[i] for i in sorted(range(len(loops)), key=lambda i: (-key[i], i))]
    return loops
