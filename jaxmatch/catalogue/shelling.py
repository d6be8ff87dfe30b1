"""Enumeration of catalogue meshes by shelling: grow disks one quad at a time.

Why it is complete. Every quad mesh of a disk is *shellable* (every 2-ball is shellable:
its quads can be ordered Q_1..Q_F so that every prefix is a disk; equivalently a disk with
F >= 2 quads has a quad meeting the boundary in one path whose removal leaves a disk).
Each step of a shelling attaches one quad to the current disk along one boundary path of
1, 2 or 3 edges (4 would close a sphere). So a breadth-first search that, from every disk
with F quads, attaches a quad in every possible way reaches every disk with F + 1 quads.

Pruning keeps only predicates that hold for *every sub-disk* P of a catalogue mesh M with
at most K internal vertices, so every prefix of every shelling of M survives:

* valence_P(v) <= valence_M(v) <= 5, and interior vertices of P (interior in M too) have
  valence >= 3;
* interior vertices of P are internal in M: |Int(P)| <= K;
* every quad of M has an internal vertex (k >= 1) and every internal edge has an internal
  endpoint (invariant (I)). A quad of P with no interior vertex, or an internal edge of P with
  both endpoints on the boundary of P, needs one of its boundary vertices to be internal in
  M; so |Int(P)| + (a packing lower bound on the hitting set of those needs) <= K;
* F(P) <= F(M) <= sum of the valences of the internal vertices of M (every quad holds one)
  <= sum over Int(P) of their (final) valences + 5 (K - |Int(P)|).

Disks are deduplicated per level by their canonical form (:mod:`jaxmatch.catalogue.canon`), and
every catalogue mesh found is recorded once by its canonical key.
"""

from __future__ import annotations

from typing import Iterator, NamedTuple

from jaxmatch.catalogue.canon import canonical
from jaxmatch.catalogue.mesh import MAX_VALENCE


class Disk(NamedTuple):
    """A disk quad mesh under construction (immutable; tuples for hashing speed).

    quads: ccw vertex 4-tuples; boundary: ccw loop; vals: valence per vertex;
    edges: set of sorted vertex pairs; interior: number of interior vertices.
    """

    quads: tuple
    boundary: tuple
    vals: tuple
    edges: frozenset
    interior: int


def single_quad() -> Disk:
    return Disk(((0, 1, 2, 3),), (0, 1, 2, 3), (2, 2, 2, 2), frozenset({(0, 1), (1, 2), (2, 3), (0, 3)}), 0)


def _e(a: int, b: int) -> tuple[int, int]:
    return (a, b) if a < b else (b, a)


def attach(d: Disk, i: int, length: int) -> Disk | None:
    """Attach a quad outside boundary path b_i .. b_{i+length}; None when invalid.

    The new quad runs along the path backwards (it lies on the other side), so it stays ccw.
    """
    b, n = d.boundary, len(d.boundary)
    vals = list(d.vals)
    path = [b[(i + j) % n] for j in range(length + 1)]
    nv = len(vals)
    edges = set(d.edges)
    if length == 1:
        p0, p1 = path
        y, z = nv, nv + 1
        quad = (p1, p0, y, z)
        vals += [2, 2]
        vals[p0] += 1
        vals[p1] += 1
        new_edges = [(p0, y), (y, z), (z, p1)]
        new_boundary = [p0, y, z, p1]
        closed: list[int] = []
    elif length == 2:
        p0, p1, p2 = path
        y = nv
        quad = (p2, p1, p0, y)
        vals += [2]
        vals[p0] += 1
        vals[p2] += 1
        new_edges = [(p0, y), (y, p2)]
        new_boundary = [p0, y, p2]
        closed = [p1]
    else:
        if n < 6:
            return None
        p0, p1, p2, p3 = path
        if _e(p0, p3) in edges:
            return None
        quad = (p3, p2, p1, p0)
        vals[p0] += 1
        vals[p3] += 1
        new_edges = [(p0, p3)]
        new_boundary = [p0, p3]
        closed = [p1, p2]
    if vals[path[0]] > MAX_VALENCE or vals[path[-1]] > MAX_VALENCE:
        return None
    for c in closed:
        if vals[c] < 3:  # closing a valence-2 vertex: its one quad would share two edges with the new one
            return None
    for a, c in new_edges:
        edges.add(_e(a, c))
    rest = [b[(i + length + j) % n] for j in range(1, n - length)]
    boundary = tuple(new_boundary + rest)
    return Disk(d.quads + (quad,), boundary, tuple(vals), frozenset(edges), d.interior + len(closed))


def needs_lower_bound(d: Disk) -> int:
    """Lower bound on how many boundary vertices of ``d`` must become internal.

    Needs: quads without an interior vertex (4 boundary vertices) and internal edges with two
    boundary endpoints. A greedy packing of pairwise disjoint needs bounds the hitting set.
    """
    on_b = set(d.boundary)
    needs = []
    for q in d.quads:
        if all(v in on_b for v in q):
            needs.append(set(q))
    # internal edges with both endpoints on the boundary: edges not on the boundary loop
    n = len(d.boundary)
    bedges = {_e(d.boundary[j], d.boundary[(j + 1) % n]) for j in range(n)}
    for a, c in d.edges:
        if a in on_b and c in on_b and (a, c) not in bedges:
            needs.append({a, c})
    needs.sort(key=len)
    used: set[int] = set()
    count = 0
    for s in needs:
        if not (s & used):
            used |= s
            count += 1
    return count


def quad_bound(d: Disk, max_internal: int) -> int:
    """Upper bound on the quads of any catalogue mesh (k <= max_internal) containing ``d``."""
    on_b = set(d.boundary)
    inner = sum(v for i, v in enumerate(d.vals) if i not in on_b)
    return inner + 5 * (max_internal - d.interior)


def is_catalogue_mesh(d: Disk) -> bool:
    """The disk satisfies the catalogue class: (I), every quad has an interior vertex (k>=1)."""
    if d.interior == 0:
        return len(d.quads) == 1
    return needs_lower_bound(d) == 0


def shell(max_internal: int, progress=None) -> dict[int, dict[tuple, Disk]]:
    """All catalogue meshes with k = 0 .. max_internal internal vertices, by shelling.

    Returns {k: {canonical key: Disk}}. ``progress(level, n_states, n_found)`` is called per level.
    """
    found: dict[int, dict[tuple, Disk]] = {k: {} for k in range(max_internal + 1)}
    level = {canonical(single_quad().quads, single_quad().boundary, single_quad().vals).key: single_quad()}
    f = 1
    while level:
        for key, d in level.items():
            if d.interior <= max_internal and is_catalogue_mesh(d):
                found[d.interior][key] = d
        if f >= 5 * max_internal:
            break
        nxt: dict[tuple, Disk] = {}
        for d in level.values():
            for child in children(d):
                if child.interior + needs_lower_bound(child) > max_internal:
                    continue
                if len(child.quads) > quad_bound(child, max_internal):
                    continue
                key = canonical(child.quads, child.boundary, child.vals).key
                if key not in nxt:
                    nxt[key] = child
        f += 1
        level = nxt
        if progress is not None:
            progress(f, len(level), sum(len(v) for v in found.values()))
    return found


def children(d: Disk) -> Iterator[Disk]:
    """Every disk made by attaching one quad along a boundary path of 1, 2 or 3 edges."""
    n = len(d.boundary)
    for length in (1, 2, 3):
        for i in range(n):
            c = attach(d, i, length)
            if c is not None:
                yield c


def _star_covered_with(d: Disk, p: int) -> bool:
    """Every quad contains an interior vertex or the vertex ``p`` being closed."""
    on_b = set(d.boundary)
    return all(any((v not in on_b) or v == p for v in q) for q in d.quads)
