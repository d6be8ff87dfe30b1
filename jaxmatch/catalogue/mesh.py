"""Quad mesh data, boundary annotation and validation.

A :class:`QuadMesh` is a combinatorial quad mesh of a closed disk:

* ``quads``: ``(F, 4) int32``, vertex indices ``0 .. V-1``, each quad listed
  counter-clockwise (all quads consistently oriented);
* ``boundary``: ``(n,) int32``, the boundary loop, counter-clockwise (interior on the left),
  starting at an arbitrary boundary vertex.

A vertex is *internal* when it is not on the boundary loop. The paper's catalogue class
adds: every valence <= 5, and invariant (I): every internal edge (an edge of two quads)
has at least one internal endpoint.

Boundary annotation (paper, section 4): boundary vertex ``b_i`` becomes the triple
``[u, v, w]`` = valences of (counter-clockwise neighbour ``b_{i+1}``, ``b_i``,
clockwise neighbour ``b_{i-1}``).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass

import numpy as np

QUAD_NEXT = np.array([1, 2, 3, 0])
"""The next corner of each quad corner: ``q[:, QUAD_NEXT]`` is ``np.roll(q, -1, axis=1)`` (same values, faster)."""

MAX_VALENCE = 5


@dataclass(frozen=True, eq=False)
class QuadMesh:
    """A quad mesh of a disk.

    quads: (F, 4) int32, counter-clockwise quads.
    boundary: (n,) int32, counter-clockwise boundary loop.
    """

    quads: np.ndarray
    boundary: np.ndarray

    @property
    def n_vertices(self) -> int:
        return int(self.quads.max()) + 1 if self.quads.size else 0

    @property
    def n_quads(self) -> int:
        return int(self.quads.shape[0])

    @property
    def n_boundary(self) -> int:
        return int(self.boundary.shape[0])

    @property
    def n_internal(self) -> int:
        return self.n_vertices - self.n_boundary


def edges(quads: np.ndarray) -> np.ndarray:
    """Undirected edges, ``(E, 2) int`` sorted pairs, each once."""
    q = np.asarray(quads)
    d = np.sort(np.stack([q, q[:, QUAD_NEXT]], axis=-1).reshape(-1, 2), axis=1)
    if d.size == 0 or d.dtype.kind not in "iu" or d.min() < 0:
        return np.unique(d, axis=0)
    # one int64 key per pair, a * base + b: its order is the pairs' lexicographic order, so this
    # is np.unique(d, axis=0), ~10x faster (placement calls it for every candidate)
    # (sorted, then the first of each run: np.unique's answer; numpy >= 2.3 hashes instead, ~10x slower here)
    base = int(d.max()) + 1
    key = np.sort(d[:, 0].astype(np.int64) * base + d[:, 1])
    key = key[np.concatenate([[True], key[1:] != key[:-1]])]
    return np.stack([key // base, key % base], axis=1).astype(d.dtype)


def boundary_edges(quads: np.ndarray) -> np.ndarray:
    """``(B, 2) int64`` directed edges used by exactly one quad, in the quads' order (ccw quads:
    the region's boundary runs counter-clockwise along them). One int64 key per undirected edge
    (as :func:`edges`), not ``np.unique(..., axis=0)``: the same edges, ~10x faster on large meshes."""
    q = np.asarray(quads, dtype=np.int64)
    d = np.stack([q, q[:, QUAD_NEXT]], axis=-1).reshape(-1, 2)
    if d.size == 0:
        return d
    base = int(d.max()) + 1
    key = np.minimum(d[:, 0], d[:, 1]) * base + np.maximum(d[:, 0], d[:, 1])
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    return d[cnt[inv] == 1]


def boundary_loops(quads: np.ndarray) -> list[np.ndarray]:
    """The boundary loops of a quad mesh (edges used by exactly one quad), each ``(B,) int64``
    in the quads' direction (ccw quads: the outer loop runs ccw, holes cw). Assumes each
    boundary vertex has one outgoing boundary edge (a manifold mesh)."""
    b = boundary_edges(quads)
    nxt = dict(zip(b[:, 0].tolist(), b[:, 1].tolist()))
    loops, seen = [], set()
    for start in b[:, 0].tolist():
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt.get(v, start)
        loops.append(np.asarray(loop, np.int64))
    return loops


def valences(quads: np.ndarray, n_vertices: int | None = None) -> np.ndarray:
    """Vertex valences (number of incident edges), ``(V,) int32``."""
    e = edges(quads)
    nv = n_vertices if n_vertices is not None else (int(np.max(quads)) + 1)
    return np.bincount(e.ravel(), minlength=nv).astype(np.int32)


def boundary_loop(quads: np.ndarray) -> np.ndarray:
    """The counter-clockwise boundary loop of a disk mesh with ccw quads, ``(n,) int32``.

    Starts at the smallest boundary vertex index. Raises ValueError when the boundary
    edges do not form exactly one simple loop.
    """
    q = np.asarray(quads)
    directed = Counter()
    for quad in q.tolist():
        for a, b in zip(quad, quad[1:] + quad[:1]):
            directed[(a, b)] += 1
    nxt: dict[int, int] = {}
    for (a, b), c in directed.items():
        if c > 1:
            raise ValueError(f"directed edge {a}->{b} used by {c} quads (orientation or manifold error)")
        if (b, a) not in directed:
            if a in nxt:
                raise ValueError(f"vertex {a} is on the boundary twice (pinched)")
            nxt[a] = b
    if not nxt:
        raise ValueError("no boundary (closed surface)")
    start = min(nxt)
    loop = [start]
    while True:
        v = nxt[loop[-1]]
        if v == start:
            break
        if len(loop) > len(nxt):
            raise ValueError("boundary edges do not close")
        loop.append(v)
    if len(loop) != len(nxt):
        raise ValueError("boundary has more than one loop")
    return np.asarray(loop, dtype=np.int32)


def from_quads(quads) -> QuadMesh:
    """Build a :class:`QuadMesh` from ccw quads, computing the boundary loop."""
    q = np.asarray(quads, dtype=np.int32).reshape(-1, 4)
    return QuadMesh(quads=q, boundary=boundary_loop(q))


def mesh_valences(mesh: QuadMesh) -> np.ndarray:
    """:func:`valences` of ``mesh`` ``(V,) int32``; kept on the mesh object (read-only) when its
    quads are read-only, as the catalogue's are, so placing one many times counts its edges once."""
    val = mesh.__dict__.get("_valences")
    if val is None:
        val = valences(mesh.quads, mesh.n_vertices)
        if mesh.quads.flags.writeable:  # only meshes that cannot change (catalogue meshes) keep it
            return val
        val.setflags(write=False)
        object.__setattr__(mesh, "_valences", val)
    return val


def boundary_valences(mesh: QuadMesh) -> np.ndarray:
    """Valences along the ccw boundary loop, ``(n,) int32``."""
    return mesh_valences(mesh)[mesh.boundary]


def triples(boundary_vals) -> np.ndarray:
    """Boundary triples ``[u, v, w]`` from a ccw valence sequence.

    boundary_vals: (n,) ints (ccw). Returns (n, 3) int32 where row i is
    ``[val[i+1], val[i], val[i-1]]`` (ccw neighbour, vertex, clockwise neighbour).
    """
    b = np.asarray(boundary_vals, dtype=np.int32).reshape(-1)
    out = np.empty((b.shape[0], 3), np.int32)  # np.stack of np.roll(b, -1), b, np.roll(b, 1), without np.roll
    if b.shape[0]:
        out[:-1, 0], out[-1, 0] = b[1:], b[0]
        out[:, 1] = b
        out[1:, 2], out[0, 2] = b[:-1], b[-1]
    return out


def validate(mesh: QuadMesh, max_valence: int = MAX_VALENCE, invariant_i: bool = True) -> list[str]:
    """All problems that keep ``mesh`` out of the catalogue class; ``[]`` when valid.

    Checks: quads have 4 distinct vertices; all vertices used; consistent orientation;
    every edge in 1 or 2 quads; two quads share at most one edge; one boundary loop equal
    to ``mesh.boundary`` up to rotation; every vertex a manifold disk/half-disk (its quad fan
    is one cycle, or one path for boundary vertices); Euler ``V - E + F = 1``; valences
    ``<= max_valence``; internal valence >= 3; invariant (I); and the angle-sum identity
    ``sum_internal(4 - val) + sum_boundary(3 - val) = 4``.
    """
    problems: list[str] = []
    q = np.asarray(mesh.quads)
    if q.ndim != 2 or q.shape[1] != 4 or q.shape[0] == 0:
        return ["quads must be a non-empty (F, 4) array"]
    nv = mesh.n_vertices
    if q.min() < 0:
        return ["negative vertex index"]
    for f, quad in enumerate(q.tolist()):
        if len(set(quad)) != 4:
            problems.append(f"quad {f} has repeated vertices {quad}")
    used = np.zeros(nv, bool)
    used[q.ravel()] = True
    if not used.all():
        problems.append(f"vertices {np.flatnonzero(~used).tolist()} are in no quad")
    if problems:
        return problems

    directed = Counter()
    undirected: dict[tuple[int, int], list[int]] = defaultdict(list)
    for f, quad in enumerate(q.tolist()):
        for a, b in zip(quad, quad[1:] + quad[:1]):
            directed[(a, b)] += 1
            undirected[(min(a, b), max(a, b))].append(f)
    for (a, b), c in directed.items():
        if c > 1:
            problems.append(f"directed edge {a}->{b} appears in {c} quads (inconsistent orientation)")
    for e, fs in undirected.items():
        if len(fs) > 2:
            problems.append(f"edge {e} is in {len(fs)} quads")
    pair_count = Counter()
    for e, fs in undirected.items():
        if len(fs) == 2:
            pair_count[tuple(sorted(fs))] += 1
    for fs, c in pair_count.items():
        if c > 1:
            problems.append(f"quads {fs} share {c} edges")
    if problems:
        return problems

    try:
        loop = boundary_loop(q)
    except ValueError as err:
        return [str(err)]
    b = np.asarray(mesh.boundary).tolist()
    if sorted(b) != sorted(loop.tolist()) or len(b) != len(loop):
        problems.append("stored boundary differs from the boundary of the quads")
    else:
        i = b.index(int(loop[0]))
        if b[i:] + b[:i] != loop.tolist():
            problems.append("stored boundary is not the ccw boundary loop")
    on_boundary = np.zeros(nv, bool)
    on_boundary[loop] = True

    # vertex fans: corners around each vertex must form one cycle (internal) or one path (boundary)
    succ: dict[int, dict[int, int]] = defaultdict(dict)  # at vertex v: prev-neighbour -> next-neighbour
    for quad in q.tolist():
        for i in range(4):
            v, nxt_v, prv_v = quad[i], quad[(i + 1) % 4], quad[(i - 1) % 4]
            succ[v][nxt_v] = prv_v  # ccw around v: from edge (v,nxt) to edge (v,prv)
    for v in range(nv):
        s = succ[v]
        n_corners = len(s)
        starts = set(s) - set(s.values())
        if on_boundary[v]:
            if len(starts) != 1:
                problems.append(f"boundary vertex {v} is not a single fan")
                continue
            cur, seen = next(iter(starts)), 0
            while cur in s:
                cur, seen = s[cur], seen + 1
            if seen != n_corners:
                problems.append(f"boundary vertex {v} fan is broken")
        else:
            if starts:
                problems.append(f"internal vertex {v} has an open fan")
                continue
            cur, seen = next(iter(s)), 0
            first = cur
            while True:
                cur, seen = s[cur], seen + 1
                if cur == first or seen > n_corners:
                    break
            if seen != n_corners:
                problems.append(f"internal vertex {v} fan is not one cycle")
    if problems:
        return problems

    n_edges = len(undirected)
    if nv - n_edges + len(q) != 1:
        problems.append(f"Euler characteristic V-E+F = {nv - n_edges + len(q)} != 1")
    val = valences(q, nv)
    if val.max() > max_valence:
        problems.append(f"valence {int(val.max())} > {max_valence} at vertex {int(val.argmax())}")
    internal = ~on_boundary
    if internal.any() and val[internal].min() < 3:
        problems.append("internal vertex of valence < 3")
    if invariant_i:
        for (a, bb), fs in undirected.items():
            if len(fs) == 2 and on_boundary[a] and on_boundary[bb]:
                problems.append(f"invariant (I) fails: internal edge {a}-{bb} has two boundary endpoints")
    angle = int((4 - val[internal]).sum() + (3 - val[on_boundary]).sum())
    if angle != 4:
        problems.append(f"angle-sum identity gives {angle} != 4")
    return problems
