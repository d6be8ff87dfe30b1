"""A shape's mesh given the line groups of the input's numbering: ``side i-j`` (the outer loop's
side from the file's corner ``i`` to the next, ``j``), ``hole h`` and ``hole h side i-j`` (``h``
the file's hole number), the user's tags, and the periodic pairs' node groups.

Every strategy builds its mesh from the canonical region (:func:`jaxmatch.meshing.region.canonical`:
one loop direction, one start, patch cuts); :func:`name_groups` names the chosen mesh's groups once,
after the choice, from the numbering the shape carries from its reader
(:attr:`jaxmatch.shape.Shape.numbering`, :func:`jaxmatch.sides.named_sides`): the mesh vertex of
each corner of the region is found on the mesh's boundary loops, and a side's group is the run of
boundary edges between its two corners, in the loop's direction (the region on the left). Cuts
between patches are in no group (their numbering would be the strategy's, not the file's). Nodes
and quads are not touched.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.meshing.result import _KEPT, QuadMesh
from jaxmatch.placement.refine import harmonic_displacement
from jaxmatch.shape import Shape
from jaxmatch.sides import NamedSide, named_sides, resolve_side, side_lengths, side_polyline

__all__ = ["make_periodic", "name_groups", "periodic_mismatch", "periodic_nodes"]


def _loop_edges(loop: np.ndarray) -> np.ndarray:
    loop = np.asarray(loop, np.int64)
    return np.stack([loop, np.roll(loop, -1)], axis=1)


def _corner_vertices(mesh: QuadMesh, ring: np.ndarray, corners, loops) -> tuple[int, np.ndarray]:
    """The mesh boundary loop of a region loop and where its corners are on it: ``(loop id,
    (c,) positions along that loop)``; the loop is the one nearest the ring's first corner (its
    first point without corners), each corner the nearest vertex of that loop."""
    anchors = ring[np.asarray(corners, np.int64)] if len(corners) else ring[:1]
    best = min(range(len(loops)), key=lambda i: float(np.min(np.linalg.norm(mesh.xy[loops[i]] - anchors[0], axis=1))))
    lxy = mesh.xy[loops[best]]
    pos = np.argmin(np.linalg.norm(lxy[None, :, :] - anchors[:, None, :], axis=2), axis=1).astype(np.int64)  # (c,)
    return best, (pos if len(corners) else np.zeros(0, np.int64))


def _run(loop: np.ndarray, a: int, b: int) -> np.ndarray:
    """``(E, 2)`` the loop's edges from position ``a`` to position ``b`` (the whole loop when equal)."""
    n = len(loop)
    k = (b - a) % n or n
    run = np.concatenate([loop[a:], loop[:a + 1]])[:k + 1] if a + k >= n else loop[a:a + k + 1]  # positions a..a+k
    out = np.empty((k, 2), np.int64)
    out[:, 0], out[:, 1] = run[:-1], run[1:]
    return out


def _side_runs(mesh: QuadMesh, region: Shape):
    """``(loops, rings kept, corner positions per ring, named sides, {side name: (E, 2) edges}``):
    the mesh's boundary loops and each named side's run of boundary edges on them."""
    loops = [np.asarray(lp, np.int64) for lp in mesh._loops]
    rings = [region.given_points] + [np.asarray(h, np.float64) for h in region.holes]
    corner_lists = [region.corners] + list(region.hole_corners)
    if len(loops) < len(rings):  # a mesh of the outer loop only (a placed template ignores holes)
        rings, corner_lists = rings[:1], corner_lists[:1]
    where = [_corner_vertices(mesh, r, c, loops) for r, c in zip(rings, corner_lists)]
    sides = [s for s in named_sides(region) if s.loop < len(rings)]
    edges_of: dict[str, np.ndarray] = {}
    orders = [{c: k for k, c in enumerate(sorted(int(c) for c in cs))} for cs in corner_lists]  # corner -> its place
    for side in sides:
        lid, pos = where[side.loop]
        order = orders[side.loop]
        edges_of[side.name] = _run(loops[lid], int(pos[order[side.start]]), int(pos[order[side.stop]]))
    return loops, rings, where, sides, edges_of


def name_groups(mesh: QuadMesh, region: Shape) -> QuadMesh:
    """``mesh`` (of ``region``, any strategy) with its line groups in the input's numbering:
    ``boundary``; ``side i-j`` per outer side; per hole ``hole h`` and ``hole h side i-j``; each tag
    of ``region`` as a group of its sides' edges; per periodic pair ``k`` (1-based) the node
    groups ``periodic k a`` / ``periodic k b`` in matching order (:attr:`QuadMesh.point_sets`).
    ``side_counts`` / ``side_lengths`` are keyed by the same names (``"i-j"`` for outer sides,
    ``"hole h side i-j"``). Raises :class:`InputError` when a tag names a side the region has
    no longer at the mesh size (detected corners are judged again at the size)."""
    loops, rings, where, sides, edges_of = _side_runs(mesh, region)
    sets: dict[str, np.ndarray] = {"boundary": np.asarray(mesh.line_sets["boundary"], np.int64)}
    counts, lengths = {}, {}
    for side, length in zip(sides, side_lengths(region, sides)):
        key = side.name[len("side "):] if side.loop == 0 else side.name
        counts[key] = int(len(edges_of[side.name]))
        lengths[key] = length
        if side.loop == 0:
            sets[side.name] = edges_of[side.name]
    hole_sets: dict[int, dict[str, np.ndarray]] = {}
    for k in range(len(rings) - 1):
        h = region.numbering[k + 1].hole if k + 1 < len(region.numbering) else k + 1
        lid, pos = where[k + 1]
        group = {f"hole {h}": _loop_edges(np.roll(loops[lid], -(int(pos[0]) if len(pos) else 0)))}
        group.update({s.name: edges_of[s.name] for s in sides if s.loop == k + 1})
        hole_sets[h] = group
    for h in sorted(hole_sets):
        sets.update(hole_sets[h])
    for tag, members in region.tags:
        parts = []
        for mem in members:
            try:
                hit, _ = resolve_side(region, mem, sides)
            except InputError as err:
                raise InputError(f"tag {tag!r}: {err.problem}; at this size the corners are judged again: give them "
                                 "explicitly (\"corners\") to keep the file's sides", where=region.source) from None
            whole = mem.startswith("hole ") and " side " not in mem
            if whole and mem not in sets:  # (a placed template covers the outer loop only)
                raise InputError(f"tag {tag!r}: the mesh has no {mem}", where=region.source)
            parts += [sets[mem]] if whole else [edges_of[s.name] for s in hit]
        sets[tag] = np.concatenate(parts) if len(parts) > 1 else parts[0]
    out = replace(mesh, line_sets=sets, side_counts=counts, side_lengths=lengths,
                  point_sets=periodic_nodes(region, edges_of, sides))
    out.__dict__.update({k: mesh.__dict__[k] for k in _KEPT if k in mesh.__dict__})
    return out


def periodic_mismatch(mesh: QuadMesh, region: Shape) -> str:
    """Why ``mesh`` cannot be periodic (a pair whose sides got different edge counts), or ``""``."""
    if not region.periodic:
        return ""
    _, _, _, _, edges_of = _side_runs(mesh, region)
    for a, b, _ in region.periodic:
        if len(edges_of[a]) != len(edges_of[b]):
            return f"periodic {a} and {b} got {len(edges_of[a])} and {len(edges_of[b])} edges"
    return ""


def make_periodic(mesh: QuadMesh) -> QuadMesh:
    """``mesh`` (named: :func:`name_groups`) with each periodic pair's ``b`` nodes moved onto the
    translates of its ``a`` nodes (the translation of the pair's first nodes), the move carried
    into the interior harmonically with every boundary vertex fixed
    (:func:`jaxmatch.placement.refine.harmonic_displacement`): the outline does not change,
    ``b[i] = a[i] + t`` (the ends are the sides' corners, translates within round-off). A mesh
    without pairs is returned as it is."""
    pairs = sorted({name.rsplit(" ", 1)[0] for name in mesh.point_sets if name.startswith("periodic ")})
    if not pairs:
        return mesh
    xy = np.array(mesh.xy, np.float64)
    bverts = np.unique(np.concatenate([np.asarray(lp, np.int64) for lp in mesh._loops]))
    disp = np.zeros_like(xy)
    for p in pairs:
        a, b = mesh.point_sets[f"{p} a"], mesh.point_sets[f"{p} b"]
        t = xy[b[0]] - xy[a[0]]
        disp[b] = xy[a] + t - xy[b]
    moved = xy + harmonic_displacement(np.asarray(mesh.quads, np.int64), len(xy), bverts, disp[bverts])
    for p in pairs:  # the inner nodes exactly on the translates of a's (the end corners stay where they are)
        a, b = mesh.point_sets[f"{p} a"], mesh.point_sets[f"{p} b"]
        moved[b[1:-1]] = xy[a[1:-1]] + (xy[b[0]] - xy[a[0]])
    return replace(mesh, xy=moved)


def periodic_nodes(region: Shape, edges_of: dict[str, np.ndarray], sides: list[NamedSide]) -> dict[str, np.ndarray]:
    """Per periodic pair ``k`` of ``region`` (1-based): ``{"periodic k a": (n,) int64, "periodic k
    b": (n,) int64}`` the node ids of its two sides, ``b[i]`` the image of ``a[i]`` under the
    translation from side ``a`` to side ``b`` (``a`` from its corner ``i`` to ``j``)."""
    out: dict[str, np.ndarray] = {}
    by_name = {s.name: s for s in sides}
    for k, (a, b, rev) in enumerate(region.periodic, start=1):
        na = _nodes_in_name_order(region, by_name[a], edges_of[a])
        nb = _nodes_in_name_order(region, by_name[b], edges_of[b])
        out[f"periodic {k} a"] = na
        out[f"periodic {k} b"] = nb[::-1] if rev else nb
    return out


def _nodes_in_name_order(region: Shape, side: NamedSide, e: np.ndarray) -> np.ndarray:
    """The node ids along a side's edges ``e`` (loop direction), in its name's direction."""
    nodes = np.concatenate([e[:, 0], e[-1:, 1]]).astype(np.int64)
    poly = side_polyline(region, side)
    ring = region.given_points if side.loop == 0 else np.asarray(region.holes[side.loop - 1], np.float64)
    return nodes if np.array_equal(poly[0], ring[side.start]) else nodes[::-1]
