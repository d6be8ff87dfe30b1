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

Meshing (:func:`mesh_layout`): every patch gets candidate templates
(:func:`jaxmatch.placement.refine.patch_templates`, fewest internal vertices first: a coarse
template refined is better shaped than a fine one); ONE integer program
(:func:`solve_counts`, ``scipy.optimize.milp``/HiGHS) chooses the chord multiplicities of all
patches at once: each patch's side counts are its ``side_matrix @ multiplicities``, a shared
side has one count, requested counts are met exactly, and without them the counts are closest
to ``side length / size``. Each patch is refined (:func:`jaxmatch.placement.refine.refine_and_place`),
patch sides made of several sides are fitted to them (:func:`fit_sides`), and the patches are
merged (:func:`merge_patches`): the vertices of a side get one global id
each, so shared sides carry identical vertices and there is no hanging node. A patch whose
refinement folds (or has a scaled Jacobian below :data:`MIN_SJ`) is given its next template and
the program is solved again; the best round is kept (fewest inverted quads, then the highest
minimum scaled Jacobian of the worst patch).

All lengths are in the user's units.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Mapping, NamedTuple, Sequence

import numpy as np

from jaxmatch.defaults import QUALITY
from jaxmatch.errors import InputError
from jaxmatch.files import read_limited
from jaxmatch.arrays import roll
from jaxmatch.placement.refine import _array_key
from jaxmatch.placement.milp import CHORD_WEIGHT, LayoutInfeasible, solve_counts  # noqa: F401 (public here)
from jaxmatch.placement.embed import polygon_area, smooth_in_frame, smooth_near
from jaxmatch.catalogue.mesh import boundary_edges, valences  # noqa: F401 (boundary_edges public here)
from jaxmatch.quality import inverted_mask, quad_areas, quality, sj_inverted
from jaxmatch.shape import Shape, make_shape

if TYPE_CHECKING:  # pragma: no cover
    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice

__all__ = [
    "Layout",
    "LayoutInfeasible",
    "LayoutMesh",
    "Sides",
    "TEMPLATE_SIZES",
    "CHORD_WEIGHT",
    "boundary_edges",
    "check_layout",
    "fit_sides",
    "layout_sides",
    "load_counts",
    "load_layout",
    "make_layout",
    "merge_patches",
    "mesh_layout",
    "parse_layout",
    "patch_shapes",
    "parse_counts",
    "solve_counts",
]

MAX_BYTES = 16 * 2**20
"""Largest accepted layout or sides file (bytes)."""

MAX_POINTS = 100_000
"""Largest accepted number of layout points."""

TEMPLATE_SIZES = ((0, 1), (2, 3))
"""Groups of internal-vertex counts tried for a patch's templates, in this order: the first
group with a template that keeps the patch's corners gives the candidates (coarse templates
refine into better-shaped meshes, and each size costs placements)."""

ALL_SIZES = ((0, 1), (2, 3), (4, 5), (6, 7))
"""The groups used for a shape meshed as one patch (it may need large templates)."""

TEMPLATES_PER_PATCH = 3
"""How many candidate templates of each size a patch keeps (tried in order when a refinement
folds)."""

ROUNDS = 8
"""Largest number of (integer program, refine) rounds :func:`mesh_layout` runs."""

MIN_SJ = QUALITY.good_sj
"""A refined patch whose minimum scaled Jacobian is below this (or that has inverted quads)
gets its next template in the next round of :func:`mesh_layout` (the best round is kept)."""

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
    """

    points: np.ndarray
    patches: tuple[np.ndarray, ...]
    corner: np.ndarray
    patch_corner: tuple[np.ndarray, ...]
    requested: Mapping[str, int]
    source: str = "<layout>"

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
    (shapely's STRtree, ``dwithin``: distance <= tol; not scipy's cKDTree, whose import costs the
    meshing command ~0.3 s, docs/perf.md "Third pass")."""
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
    chord (user units squared; 0 for a straight side)."""
    from jaxmatch.placement.refine import side_points

    p = np.asarray(polyline, np.float64)
    if p.shape[0] <= 2:
        return 0.0
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    q = side_points(p, n)
    t = np.linspace(0.0, cum[-1], n + 1)
    cut = np.searchsorted(cum, t, side="right")  # vertices strictly after each piece start
    total = 0.0
    for i in range(n):
        inner = p[cut[i]:np.searchsorted(cum, t[i + 1], side="left")]
        if not len(inner):
            continue
        ring = np.vstack([q[i], inner, q[i + 1]])
        x, y = ring[:, 0], ring[:, 1]
        total += abs(0.5 * float(np.sum(x * roll(y, -1) - roll(x, -1) * y)))
    return total


CURVE_SHARE = 0.8
"""The part of the area tolerance (``Quality.area_tol``) that the chords of curved sides may
use, shared among the boundary sides by length (:func:`curve_floors`)."""


def region_area(layout: Layout) -> float:
    """Area of the region the patches of ``layout`` cover (their union; user units squared)."""
    import shapely

    return float(shapely.union_all([shapely.Polygon(layout.points[lp]) for lp in layout.patches]).area)


def curve_floors(layout: Layout, sides: Sides, area_tol: float, region: float | None = None) -> np.ndarray:
    """``(S,) int64`` the fewest edges each side may have so that its chords keep the region's
    area: a boundary side whose points do not lie on one line gets at least the edges that keep
    the area between it and its chords within its share (its length over the boundary's) of
    :data:`CURVE_SHARE` ``* area_tol`` of the region's area; every other side 1. ``region``:
    :func:`region_area` of ``layout`` when the caller has it."""
    floors = np.ones(len(sides.chains), np.int64)
    bound = np.flatnonzero(sides.outer)
    if not bound.size:
        return floors
    total = float(np.sum(sides.lengths[bound]))
    for s in bound:
        poly = layout.points[sides.chains[s]]
        if poly.shape[0] <= 2:
            continue
        if region is None:
            region = region_area(layout)
        budget = CURVE_SHARE * area_tol * region * float(sides.lengths[s]) / total
        if chord_area_error(poly, 1) <= budget:
            continue
        lo, hi = 1, 2
        while chord_area_error(poly, hi) > budget and hi < poly.shape[0] * 4:
            lo, hi = hi, hi * 2
        while hi - lo > 1:  # the error falls as pieces are added: the fewest that keep the budget
            mid = (lo + hi) // 2
            lo, hi = (lo, mid) if chord_area_error(poly, mid) <= budget else (mid, hi)
        floors[s] = hi
    return floors


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


def fit_sides(layout: Layout, sides: Sides, p: int, refined, counts: np.ndarray, *, smooth_iters: int = 200) -> np.ndarray:
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
    :data:`~jaxmatch.placement.refine.SJ_FLOOR` smoothed, with
    :data:`~jaxmatch.placement.refine.SMOOTH_ITERS_LARGE` iterations (none when there are none).

    Returns ``(V, 2) float64`` user coordinates."""
    from jaxmatch.placement.embed import tutte
    from jaxmatch.placement.refine import SMOOTH_LOCAL, bad_quads, harmonic_displacement, side_points, smooth_near_bad

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
            q = side_points(layout.points[sides.chains[s]], int(counts[s]))
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
        disp = harmonic_displacement(quads, xy.shape[0], b, target - np.asarray(refined.xy)[b])
    else:
        disp = tutte(quads, xy.shape[0], b, target - np.asarray(refined.xy)[b])
    xy = np.asarray(refined.xy) + disp
    xy[b] = target
    if not large:
        return smooth_in_frame(xy, quads, b, frame=target, iters=smooth_iters)
    bad = bad_quads(*sj_inverted(xy, quads))
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


# ---------------------------------------------------------------------------------------------
# meshing


def _templates(shape: Shape, catalogue, lattice, limit: int, sizes=TEMPLATE_SIZES):
    """Candidate templates for one patch: those of the first group of ``sizes`` that has one
    (at most ``limit`` per size), fewest internal vertices first, then in their ranked order;
    a :class:`~jaxmatch.placement.refine.LazyTemplates` (a template is placed when it is first
    used: most patches use their first one). Empty when no group has one."""
    from jaxmatch.placement.refine import lazy_patch_templates

    for group in sizes:
        ks = [k for k in group if k in catalogue.internal]
        if not ks:
            continue
        found = lazy_patch_templates(shape, catalogue, lattice, limit=limit, internal=ks)
        if found:
            return found
    return []


def _patch_templates(layout: Layout, p: int, shp: Shape, catalogue, lattice, templates_per_patch: int, sizes,
                     template_cache: dict | None):
    """:func:`_templates` of patch ``p`` (its shape ``shp``), from ``template_cache`` when there
    (keyed by the patch's points, corners, ``sizes`` and ``templates_per_patch``), put there
    otherwise."""
    key = (layout.points[layout.patches[p]].tobytes(), layout.corner[layout.patches[p]].tobytes(), sizes,
           templates_per_patch)
    if template_cache is not None and key in template_cache:
        return template_cache[key]
    t = _templates(shp, catalogue, lattice, templates_per_patch, sizes)
    if template_cache is not None:
        template_cache[key] = t
    return t


def grid_templates_exist(catalogue: Catalogue, ks: Sequence[int], corners: Sequence[int]) -> bool:
    """Whether a catalogue mesh with ``k`` in ``ks`` internal vertices could mesh, refined, a region
    with straight sides whose corners, in ccw order, are right angles (``corners``: ``1`` for 90
    degrees, ``3`` for 270) as a grid of rectangles: every internal vertex of valence 4, and
    along its boundary (either way round, from any vertex) valence ``1 + corners[i]`` at the
    corners in that order and 3 at every vertex between them. Kept per catalogue."""
    from jaxmatch.catalogue.mesh import mesh_valences

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
                    sizes=TEMPLATE_SIZES, template_cache: dict | None = None) -> float:
    """An upper bound on the min scaled Jacobian of :func:`mesh_layout` of a one-patch ``layout``
    with these options (a mesh that does not fold; one that folds loses on that first), from its
    template sizes alone: 1 unless the region has straight sides and right-angled corners and no
    catalogue mesh of the template group that :func:`mesh_layout` would use (found as it finds
    it, the templates kept in ``template_cache`` for it) can be refined into a grid of rectangles
    with the region's corners in their order (:func:`grid_templates_exist`, :data:`NO_GRID_SJ`;
    when none of any size of ``sizes`` can, the group is not looked for). A corner off every
    multiple of 90 degrees gives 1 here: :func:`node_sj_bound` caps that closer. Refinement keeps
    a template vertex's valence and makes every new vertex regular, so the refined mesh is a grid
    only if its template is one. Without templates (the layout cannot be meshed): 1."""
    from jaxmatch.geometry import turning_angles

    if layout.n_patches != 1:
        return 1.0
    shp = _lru_get(_SHAPES, _layout_key(layout), lambda: patch_shapes(layout))[0]
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
    t = _patch_templates(layout, 0, shp, catalogue, lattice, templates_per_patch, sizes, template_cache)
    if not t:
        return 1.0
    k0 = t[0].match.internal_vertices
    ks = [k for k in next(g for g in sizes if k0 in g) if k in catalogue.internal]
    if grid_templates_exist(catalogue, ks, corners):
        return 1.0
    return NO_GRID_SJ


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
    n = pts.shape[0]
    loops = layout.patches
    flat = np.concatenate(loops)
    nxt = np.concatenate([roll(p, -1) for p in loops])
    uses = np.bincount(flat, minlength=n)
    und = np.minimum(flat, nxt) * n + np.maximum(flat, nxt)
    _, inv, cnt = np.unique(und, return_inverse=True, return_counts=True)
    once = cnt[inv] == 1  # outline segments, each in its patch's (ccw) direction
    a, b = flat[once], nxt[once]
    if np.unique(a).size < a.size or np.unique(b).size < b.size:  # the outline touches itself: no claim
        return 1.0
    ahead = dict(zip(a.tolist(), b.tolist()))
    back = dict(zip(b.tolist(), a.tolist()))
    corner = np.zeros(n, bool)
    for p, pc in zip(loops, layout.patch_corner):
        corner[p[pc]] = True
    bound = 1.0
    for v in np.flatnonzero(corner).tolist():
        if v in ahead:
            after, before = _walk(ahead, corner, v), _walk(back, corner, v)
            if after is None or before is None:  # not a closed outline (a layout that fails its checks)
                continue
            lo, hi = _outline_angle(pts, v, after, before)
        else:  # inside the region
            lo = hi = 2 * math.pi
        bound = min(bound, _split_sj(lo - NODE_ANGLE_TOL, hi + NODE_ANGLE_TOL, int(uses[v])))
    return bound


def _walk(step: dict, stop: np.ndarray, v: int) -> list[int] | None:
    """The outline points after ``v`` by ``step`` (a point -> the next), up to and including the
    first where ``stop`` is true (or ``v`` again); None when the outline breaks off first."""
    out = [step.get(v)]
    while out[-1] is not None and not stop[out[-1]] and out[-1] != v and len(out) <= len(step):
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


TRANSLATE_TOL = 1e-12
"""Patches whose points, relative to their lowest-leftmost point, agree to this fraction of the
layout's extent are translates of each other (:func:`_translates`)."""


class Translate(NamedTuple):
    """Patch ``of`` (an earlier patch) moved by ``shift (2,) float64`` is this patch, its loop
    listed from another corner: this patch's side ``i`` is that patch's side ``i + turn`` (mod
    its number of sides)."""

    of: int
    shift: np.ndarray
    turn: int


def _translates(layout: Layout) -> list[Translate]:
    """Per patch, the first patch of which it is a translate (itself, ``turn`` 0, when none):
    the same corners and the same points relative to the lowest-leftmost one, up to
    :data:`TRANSLATE_TOL` of the layout's extent, whichever corner each loop starts from. Such a
    patch has the same templates, its sides turned (:class:`_Turned`), and its refinement at the
    same multiplicities is that patch's moved (:func:`_translated`)."""
    unit = TRANSLATE_TOL * max(float(np.max(np.ptp(layout.points, axis=0))), np.finfo(float).tiny)
    first: dict = {}
    out = []
    for p, (loop, pc) in enumerate(zip(layout.patches, layout.patch_corner)):
        rel = np.rint((layout.points[loop] - layout.points[loop].min(axis=0)) / unit).astype(np.int64)
        low = int(np.lexsort((rel[:, 1], rel[:, 0]))[0])  # lowest x, then lowest y (exact on the grid)
        key = (roll(rel, -low).tobytes(), roll(np.asarray(pc), -low).tobytes())
        q, qlow = first.setdefault(key, (p, low))
        n = len(loop)
        offset = (qlow - low) % n  # point i of this loop is point i + offset of patch q's
        qloop, qpc = layout.patches[q], np.asarray(layout.patch_corner[q])
        turn = int(np.count_nonzero(qpc[:offset]))  # this patch's corner 0 (loop point 0) is q's corner `turn`
        out.append(Translate(q, layout.points[loop[0]] - layout.points[qloop[offset]], turn))
    return out


def _turned_sides(items: tuple, turn: int) -> tuple:
    """Per-side ``items`` of a patch as seen from a translate whose side ``i`` is side ``i + turn``."""
    return tuple(items[turn:]) + tuple(items[:turn])


class _Turned(Sequence):
    """The templates of a patch (a sequence of :class:`~jaxmatch.placement.refine.PatchTemplate`,
    placed as asked for) as templates of its translate ``shape`` whose side ``i`` is its side
    ``i + turn``: the per-side fields turned, ``shape`` replaced (the placement stays the
    original's: only its edge lengths, which a translation keeps, are read)."""

    def __init__(self, templates, turn: int, shape: Shape):
        self._templates, self._turn, self._shape = templates, int(turn), shape

    def __getitem__(self, j):
        if isinstance(j, slice):
            return [self._one(t) for t in self._templates[j]]
        return self._one(self._templates[j])

    def _one(self, t):
        return t._replace(shape=self._shape, side_chords=_turned_sides(t.side_chords, self._turn),
                          side_path=_turned_sides(t.side_path, self._turn))

    def __len__(self) -> int:
        return len(self._templates)

    def __bool__(self) -> bool:
        return bool(self._templates)


def _translated(rm, tr: Translate, shape: Shape, template):
    """Refined patch ``rm`` (of patch ``tr.of``) moved onto its translate ``shape`` (refined from
    ``template``, the turned one): the boundary vertices exactly where the refinement of
    ``shape`` puts them (:func:`jaxmatch.placement.refine.side_points` on its sides, so shared
    sides stay bit-identical), the others moved by ``tr.shift``; the sides turned; its quality
    figures are the original's."""
    from jaxmatch.placement.refine import side_points, side_polylines

    xy = rm.xy + tr.shift
    side_vertices = _turned_sides(rm.side_vertices, tr.turn)
    counts = np.asarray(_turned_sides(tuple(rm.counts.tolist()), tr.turn), np.int64)
    for sv, poly, c in zip(side_vertices, side_polylines(shape), counts.tolist()):
        xy[sv] = side_points(poly, int(c))
    return rm._replace(xy=xy, side_vertices=side_vertices, counts=counts, template=template)


def _has(templates, j: int) -> bool:
    """Whether a patch has a ``j``-th candidate template (placing no more than that one)."""
    try:
        templates[j]
    except IndexError:
        return False
    return True


def _key(refined_mesh) -> tuple:
    """``(inverted quads, -min scaled Jacobian to 3 decimals)`` of a refined patch, from its own
    figures (which :func:`_fitted` keeps up to date when its sides move)."""
    return (int(refined_mesh.inverted), -round(float(refined_mesh.scaled_jacobian.min()), 3))


def _fitted(refined_mesh, xy: np.ndarray):
    """``refined_mesh`` at positions ``xy (V, 2)`` (e.g. from :func:`fit_sides`), its scaled
    Jacobians and inverted count measured there (the other figures are the refinement's)."""
    sj, inv = sj_inverted(xy, refined_mesh.quads)
    return refined_mesh._replace(xy=xy, scaled_jacobian=sj, inverted=int(inv.sum()))


def mesh_layout(layout: Layout, catalogue: Catalogue, lattice: Lattice, *, size: float | None = None,
                counts: Mapping[int, int] | None = None, templates_per_patch: int = TEMPLATES_PER_PATCH,
                sizes=TEMPLATE_SIZES, smooth_cuts: bool = False, template_cache: dict | None = None,
                progress=None, first_templates: Sequence[int] | None = None) -> LayoutMesh:
    """Mesh every patch of ``layout`` and merge them into one conforming :class:`LayoutMesh`.

    size: target edge length (user units) for sides without a requested count; counts:
    ``{side id: edges}`` requested (added to ``layout.requested``, which they override).
    sizes: groups of template sizes (internal vertices) tried per patch, see :data:`TEMPLATE_SIZES`.
    template_cache: optional dict, read and filled, of each patch's candidate templates (keyed by
    the patch's points, corners, ``sizes`` and ``templates_per_patch``; valid for one catalogue
    and lattice), so that meshing the same layout at another size does not rank again.
    first_templates: per patch, the index of the candidate template to start from (default 0,
    the best-ranked; a patch with fewer candidates raises IndexError).
    smooth_cuts: after merging, untangle/smooth all vertices except the outer boundary
    (:func:`jaxmatch.placement.embed.smooth`; for decompositions, whose inner sides are not
    the user's): it never lowers the minimum scaled Jacobian.

    The answer is kept per catalogue (:func:`_mesh_layout_cached`): the same layout meshed again
    with the same options is not solved again.

    Raises :class:`InputError` when a patch has no template that keeps its corners, and
    :class:`LayoutInfeasible` when the requested counts cannot be met.
    """
    return _mesh_layout_cached(layout, catalogue, lattice, size=size, counts=counts,
                               templates_per_patch=templates_per_patch, sizes=sizes, smooth_cuts=smooth_cuts,
                               template_cache=template_cache, progress=progress, first_templates=first_templates)


def _advance_for_feasibility(sides, cands, choice, want, size, source) -> bool:
    """Switch one patch to another template so that the program becomes feasible; True when
    one was found (``choice`` is changed in place)."""
    for p in range(len(cands)):
        for j in range(len(cands[p])):
            if j == choice[p]:
                continue
            trial = list(choice)
            trial[p] = j
            try:
                solve_counts(sides, [cands[q][trial[q]].side_matrix() for q in range(len(cands))], counts=want,
                             size=size, widths=[cands[q][trial[q]].chord_widths() for q in range(len(cands))],
                             source=source)
            except LayoutInfeasible:
                continue
            choice[p] = j
            return True
    return False


# ---------------------------------------------------------------------------------------------
# caches of the meshing path (issue 22): pure functions of their inputs, kept between calls


SOLVE_CACHE_SIZE = 1024
"""Integer programs (:func:`solve_counts`), sides and patch shapes kept between
:func:`mesh_layout` calls, each (least recently used dropped; refined patches are kept by
:func:`jaxmatch.placement.refine.refine_and_place`): the pipeline meshes the
same patches with the same templates again for its size groups, for ``+bends`` and on every call
at the same size (a slider, a batch of the same part)."""

_SOLVES: dict = {}
_SIDES: dict = {}
_SHAPES: dict = {}


def clear_caches() -> None:
    """Forget the programs, refined patches, sides and patch shapes kept between calls (for
    timings of a first call)."""
    for c in (_SOLVES, _SIDES, _SHAPES):
        c.clear()


def _lru_get(cache: dict, key, make):
    """``cache[key]``, made by ``make()`` when missing (an exception it raises is kept and raised
    again); the least recently used entry dropped beyond :data:`SOLVE_CACHE_SIZE`."""
    hit = cache.pop(key, None)
    if hit is None:
        try:
            hit = (True, make())
        except (InputError, LayoutInfeasible) as e:
            hit = (False, e)
        while len(cache) >= SOLVE_CACHE_SIZE:
            cache.pop(next(iter(cache)))
    cache[key] = hit
    ok, value = hit
    if not ok:
        raise value
    return value


def _layout_key(layout: Layout) -> tuple:
    return (_array_key(layout.points), tuple(_array_key(p) for p in layout.patches), _array_key(layout.corner),
            tuple(_array_key(p) for p in layout.patch_corner), tuple(sorted(dict(layout.requested).items())), layout.source)


def _solve_counts_cached(layout: Layout, sides: Sides, matrices, want, size, widths, floors):
    """:func:`solve_counts` of ``layout`` (whose ``sides`` these are), from the cache when the
    same program was solved before; fresh copies of the arrays either way."""
    key = (_layout_key(layout), tuple(_array_key(A) for A in matrices), tuple(sorted((int(k), int(v)) for k, v in want.items())),
           None if size is None else float(size), tuple(_array_key(w) for w in widths), _array_key(floors))
    mults, n = _lru_get(_SOLVES, key, lambda: solve_counts(sides, matrices, counts=want, size=size, widths=widths,
                                                           source=layout.source, floors=floors))
    return [np.array(m) for m in mults], np.array(n)


def _refine_cached(template, mult):
    """:func:`jaxmatch.placement.refine.refine_and_place` (which keeps its refined meshes
    between calls)."""
    from jaxmatch.placement.refine import refine_and_place

    return refine_and_place(template, mult)


CUT_RINGS = 6
"""Above :data:`jaxmatch.placement.refine.SMOOTH_ALWAYS` quads, the whole-mesh smoothing of a
decomposition moves only the vertices within this many rings of quads of an inner side (the
cuts): the patches come smoothed already, and smoothing every vertex was ~80% of the time of a
25,000-quad L-shape."""


def _smooth_cuts(xy: np.ndarray, quads: np.ndarray, fixed: np.ndarray, sides: Sides, side_ids) -> np.ndarray:
    """The merged mesh smoothed with the outer loops ``fixed``
    (:func:`jaxmatch.placement.embed.smooth_in_frame`): every other vertex up to
    :data:`~jaxmatch.placement.refine.SMOOTH_ALWAYS` quads; above, with
    :data:`~jaxmatch.placement.refine.SMOOTH_ITERS_LARGE` iterations, only the vertices within
    :data:`CUT_RINGS` rings of the inner sides (the quads around them smoothed as a submesh
    whose other vertices stay)."""
    from jaxmatch.placement.refine import SMOOTH_ALWAYS, SMOOTH_ITERS_LARGE

    if quads.shape[0] <= SMOOTH_ALWAYS:
        return smooth_in_frame(xy, quads, fixed)
    inner = [np.asarray(side_ids[s], np.int64) for s in range(len(side_ids)) if sides.users[s, 1] >= 0]
    if not inner:
        return xy
    return smooth_near(xy, quads, np.concatenate(inner), fixed, rings=CUT_RINGS, frame=xy[fixed],
                       iters=SMOOTH_ITERS_LARGE)


MESH_CACHE_SIZE = 256
"""Meshed layouts kept per catalogue between :func:`mesh_layout` calls (least recently used
dropped; only meshes of at most :data:`jaxmatch.placement.refine.REFINED_CACHE_QUADS` quads)."""


def _mesh_layout_cached(layout: Layout, catalogue, lattice, *, size, counts, templates_per_patch, sizes, smooth_cuts,
                        template_cache, progress, first_templates) -> LayoutMesh:
    """:func:`_mesh_layout` from the catalogue's cache when the same layout was meshed with the
    same options (the answer names the given layout; its arrays are copies)."""
    from jaxmatch.placement.refine import REFINED_CACHE_QUADS

    key = (_layout_key(layout), lattice, None if size is None else float(size),
           None if counts is None else tuple(sorted((int(a), int(b)) for a, b in dict(counts).items())),
           int(templates_per_patch), tuple(tuple(int(k) for k in g) for g in sizes), bool(smooth_cuts),
           None if first_templates is None else tuple(int(j) for j in first_templates))
    cache = catalogue.__dict__.setdefault("_mesh_layout_cache", {})
    hit = cache.pop(key, None)
    if hit is None:
        try:
            lm = _mesh_layout(layout, catalogue, lattice, size=size, counts=counts,
                              templates_per_patch=templates_per_patch, sizes=sizes, smooth_cuts=smooth_cuts,
                              template_cache=template_cache, progress=progress, first_templates=first_templates)
        except (LayoutInfeasible, InputError) as e:
            hit = (False, e)
        else:
            if lm.quads.shape[0] > REFINED_CACHE_QUADS:
                return lm
            hit = (True, lm)
        while len(cache) >= MESH_CACHE_SIZE:
            cache.pop(next(iter(cache)))
        cache[key] = hit
        if hit[0]:
            return _copied(hit[1], layout)
        raise hit[1]
    cache[key] = hit
    if not hit[0]:
        raise hit[1]
    if progress:
        for p in range(layout.n_patches):
            progress(p + 1, layout.n_patches)
    return _copied(hit[1], layout)


def _copied(lm: LayoutMesh, layout: Layout) -> LayoutMesh:
    """``lm`` for ``layout``, its arrays copied (a caller may write to them)."""
    import dataclasses

    def cp(v):
        if isinstance(v, np.ndarray):
            return v.copy()
        if isinstance(v, tuple):
            return tuple(cp(x) for x in v)
        if isinstance(v, list):
            return [cp(x) for x in v]
        return v

    out = {f.name: cp(getattr(lm, f.name)) for f in dataclasses.fields(lm) if f.name not in ("layout", "sides")}
    return dataclasses.replace(lm, layout=layout, **out)


def _mesh_layout(layout: Layout, catalogue: Catalogue, lattice: Lattice, *, size, counts, templates_per_patch, sizes,
                 smooth_cuts, template_cache, progress, first_templates) -> LayoutMesh:
    """The work of :func:`mesh_layout` (see there)."""
    lkey = _layout_key(layout)
    sides = _lru_get(_SIDES, lkey, lambda: layout_sides(layout))
    want = {s: c for s, c in parse_counts(dict(layout.requested), sides, layout.source).items()}
    want.update(counts or {})
    shapes = _lru_get(_SHAPES, lkey, lambda: patch_shapes(layout))
    moved = _translates(layout)
    cands = []
    for p, shp in enumerate(shapes):
        if moved[p].of != p:  # a translate of an earlier patch: its templates, turned
            cands.append(_Turned(cands[moved[p].of], moved[p].turn, shp))
            if progress:
                progress(p + 1, len(shapes))
            continue
        t = _patch_templates(layout, p, shp, catalogue, lattice, templates_per_patch, sizes, template_cache)
        if not t:
            ks = sorted({k for g in sizes for k in g if k in catalogue.internal})
            raise InputError(f"patch {p}: no catalogue template with {ks[0]}..{ks[-1]} internal vertices keeps its "
                             f"{shp.n_corners} corners without folding (split the patch)", where=layout.source)
        cands.append(t)
        if progress:
            progress(p + 1, len(shapes))
    region = region_area(layout)
    floors = curve_floors(layout, sides, QUALITY.area_tol, region) if size is not None else None
    choice = [0] * len(shapes) if first_templates is None else [int(j) for j in first_templates]
    for p, j in enumerate(choice):
        if not (j >= 0 and _has(cands[p], j)):
            raise IndexError(f"patch {p} has {len(cands[p])} candidate templates, not {j + 1}")
    cache: dict = {}
    best = None
    for _ in range(ROUNDS):
        tmpl = [cands[p][choice[p]] for p in range(len(shapes))]
        try:
            mults, n = _solve_counts_cached(layout, sides, [t.side_matrix() for t in tmpl], want, size,
                                            [t.chord_widths() for t in tmpl], floors)
        except LayoutInfeasible:
            if not _advance_for_feasibility(sides, cands, choice, want, size, layout.source):
                raise
            continue
        refined = []
        for p, (t, m) in enumerate(zip(tmpl, mults)):
            q = moved[p].of
            key = (q, choice[p], tuple(m.tolist()))
            if key not in cache:
                cache[key] = _refine_cached(cands[q][choice[p]] if q != p else t, m)
            rm = cache[key]
            if q != p:
                rm = _translated(rm, moved[p], shapes[p], t)
            if any(len(parts) > 1 for parts in sides.patch_sides[p]):  # neighbours meet along a side
                rm = _fitted(rm, fit_sides(layout, sides, p, rm, n))
            refined.append(rm)
        keys = [_key(r) for r in refined]
        total = (sum(k[0] for k in keys), max(k[1] for k in keys))  # inverted quads, then the worst patch
        if best is None or total < best[0]:
            best = (total, list(tmpl), mults, n, refined)
        bad = [p for p, k in enumerate(keys) if (k[0] > 0 or -k[1] < MIN_SJ) and _has(cands[p], choice[p] + 1)]
        if not bad:
            break
        for p in bad:
            choice[p] += 1
    _, tmpl, mults, n, refined = best
    xy, quads, patch, side_ids, gap = merge_patches(layout, sides, refined, n)
    loops = _boundary_loops(layout, sides, side_ids, xy)
    outer, holes = loops[0], tuple(loops[1:])
    if smooth_cuts:
        xy = _smooth_cuts(xy, quads, np.concatenate(loops), sides, side_ids)
    return LayoutMesh(layout=layout, sides=sides, xy=xy, quads=quads, patch=patch, side_vertices=side_ids,
                      counts=n, outer=outer, holes=holes, templates=tuple(t.mesh_id for t in tmpl),
                      multiplicities=tuple(mults), shared_gap=gap, region_area=float(region))
