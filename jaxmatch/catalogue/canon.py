"""Canonical forms of disk quad meshes (up to rotation and reflection).

A disk quad mesh is determined by a traversal that starts at a boundary dart: the
directed boundary edge ``b_i -> b_{i+1}`` of the ccw boundary loop, in either the ccw
orientation or the mirrored (cw) one. From a start, quads are visited breadth first
across shared edges; each visited quad is entered at a known edge, its 4 corners are
read from there in the orientation's order, and vertices are numbered in order of first
appearance. The resulting integer sequence (the *code*) reconstructs the mesh, so two
meshes are isomorphic by an orientation-preserving map iff their minimum ccw codes are
equal, and isomorphic by any map iff their minimum codes over both orientations are.

Automorphisms of a disk mesh map the boundary loop to itself, so boundary starts suffice.
Only starts whose cyclic boundary valence sequence is lexicographically minimal are
traversed (the sequence is an isomorphism invariant that comes first in the key).

Stable ids: ``k<K>-<12 hex digits of sha1(canonical code)>``: the same mesh gets the same
id on every build and machine.
"""

from __future__ import annotations

import hashlib
from collections import deque
from typing import NamedTuple, Sequence

import numpy as np


class Canonical(NamedTuple):
    """key: hashable canonical key (tuple of ints); aut: number of automorphisms
    (rotations and reflections); aut_rot: number of orientation-preserving ones;
    chiral: True when the mirror image is not orientation-preservingly isomorphic
    (so the mesh counts twice up to rotation only); start: (i, mirrored) of one minimal start."""

    key: tuple
    aut: int
    aut_rot: int
    chiral: bool
    start: tuple


def _min_rotations(seq: Sequence[int]) -> tuple[tuple, list[int]]:
    """Lexicographically smallest rotation of ``seq`` and all start indices that achieve it."""
    n = len(seq)
    doubled = tuple(seq) + tuple(seq)
    rots = [doubled[i : i + n] for i in range(n)]
    best = min(rots)
    return best, [i for i in range(n) if rots[i] == best]


def _traverse(quads: list[tuple], nbr: dict, start_quad: int, start_corner: int) -> tuple:
    """BFS code from quad ``start_quad`` entered at corner ``start_corner`` (ccw reading).

    nbr[(q, c)] = (q2, c2): quad q's edge from corner c to corner c+1 is shared with quad
    q2's edge from corner c2 to c2+1 (traversed the other way).
    """
    label: dict[int, int] = {}
    code: list[int] = []
    seen = {start_quad}
    queue = deque([(start_quad, start_corner)])
    while queue:
        q, c = queue.popleft()
        quad = quads[q]
        for j in range(4):
            v = quad[(c + j) % 4]
            if v not in label:
                label[v] = len(label)
            code.append(label[v])
        for j in range(4):
            other = nbr.get((q, (c + j) % 4))
            if other is not None and other[0] not in seen:
                seen.add(other[0])
                # enter q2 at the corner where the shared edge starts when read from q2
                queue.append((other[0], (other[1] + 1) % 4))
    return tuple(code)


def edge_neighbours(quads: Sequence[Sequence[int]]) -> dict:
    """Map (quad, corner) -> (quad2, corner2) for each shared edge (see :func:`_traverse`)."""
    owner: dict[tuple[int, int], tuple[int, int]] = {}
    for q, quad in enumerate(quads):
        for c in range(4):
            owner[(quad[c], quad[(c + 1) % 4])] = (q, c)
    nbr = {}
    for (a, b), qc in owner.items():
        other = owner.get((b, a))
        if other is not None:
            nbr[qc] = other
    return nbr


def _min_code(quads: list[tuple], boundary: Sequence[int], bvals: Sequence[int]) -> tuple[tuple, int, int]:
    """(key, first minimal start, number of minimal starts) over ccw boundary starts."""
    n = len(boundary)
    owner = {}
    for q, quad in enumerate(quads):
        for c in range(4):
            owner[(quad[c], quad[(c + 1) % 4])] = (q, c)
    nbr = edge_neighbours(quads)
    best_seq, starts = _min_rotations(bvals)
    codes = []
    for i in starts:
        q, c = owner[(boundary[i], boundary[(i + 1) % n])]
        codes.append((_traverse(quads, nbr, q, c), i))
    best = min(codes)
    return (best_seq, best[0]), best[1], sum(1 for cd, _ in codes if cd == best[0])


def mirror(quads: Sequence[Sequence[int]], boundary: Sequence[int]) -> tuple[list[tuple], list[int]]:
    """The mirror image: every quad reversed, boundary loop reversed (both ccw again)."""
    return [tuple(reversed(q)) for q in quads], list(reversed(list(boundary)))


def canonical(quads: Sequence[Sequence[int]], boundary: Sequence[int], vals: Sequence[int]) -> Canonical:
    """Canonical form of a disk mesh.

    quads: F ccw quads (vertex tuples); boundary: (n,) ccw loop; vals: valence per vertex.
    ``start = (i, mirrored)``: the minimal code starts at boundary index i of the loop
    (of the mirrored loop ``boundary[::-1]`` when mirrored).
    """
    quads = [tuple(q) for q in quads]
    boundary = list(boundary)
    key_ccw, i_ccw, aut_rot = _min_code(quads, boundary, [vals[b] for b in boundary])
    mq, mb = mirror(quads, boundary)
    key_cw, i_cw, _ = _min_code(mq, mb, [vals[b] for b in mb])
    chiral = key_ccw != key_cw
    if key_ccw <= key_cw:
        key, start = key_ccw, (i_ccw, False)
    else:
        key, start = key_cw, (i_cw, True)
    return Canonical(key=key, aut=aut_rot * (1 if chiral else 2), aut_rot=aut_rot, chiral=chiral, start=start)


def mesh_id(key: tuple, k: int) -> str:
    """Stable id from a canonical key: ``k<K>-<12 hex>``."""
    text = ";".join(",".join(map(str, part)) for part in key)
    return f"k{k}-" + hashlib.sha1(text.encode()).hexdigest()[:12]


def relabel(quads: Sequence[Sequence[int]], boundary: Sequence[int], start: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Canonically relabelled quads and boundary: the stored mesh of a catalogue entry.

    The mesh is mirrored if ``start`` says so (quads reversed), the boundary starts at the
    canonical start, and vertices are numbered boundary first (in loop order), then internal
    vertices in order of first appearance in the quads. Returns (quads (F,4) int32 ccw,
    boundary (n,) int32 = arange(n)).
    """
    i0, mirrored = start
    n = len(boundary)
    qs = [tuple(q) for q in quads]
    b = list(boundary)
    if mirrored:
        qs, b = mirror(qs, b)
    b = [b[(i0 + j) % n] for j in range(n)]
    label = {v: j for j, v in enumerate(b)}
    # deterministic quad order: BFS from the start quad
    owner = {}
    for q, quad in enumerate(qs):
        for c in range(4):
            owner[(quad[c], quad[(c + 1) % 4])] = (q, c)
    nbr = edge_neighbours(qs)
    q0, c0 = owner[(b[0], b[1])]
    order, seen, queue = [], {q0}, deque([(q0, c0)])
    while queue:
        q, c = queue.popleft()
        order.append((q, c))
        for j in range(4):
            other = nbr.get((q, (c + j) % 4))
            if other is not None and other[0] not in seen:
                seen.add(other[0])
                queue.append((other[0], (other[1] + 1) % 4))
    out = []
    for q, c in order:
        quad = [qs[q][(c + j) % 4] for j in range(4)]
        for v in quad:
            if v not in label:
                label[v] = len(label)
        out.append([label[v] for v in quad])
    return np.asarray(out, dtype=np.int32), np.arange(n, dtype=np.int32)
