"""Fast enumeration of catalogue meshes by closing boundary vertices one at a time.

States are *star-covered disks*: disk quad meshes in which every quad contains an
interior vertex (for k >= 1 every catalogue mesh is one: a quad whose 4 vertices were on the
boundary would need its internal edges to have an internal endpoint, so all its edges would
be boundary edges and the mesh would be that single quad). Level j holds the star-covered
disks with j interior vertices, deduplicated by canonical form (:mod:`jaxmatch.catalogue.canon`).

Step: pick a boundary vertex p of a state and *close* it: attach quads that contain p, one
at a time, each along a boundary path that starts or ends at p (1, 2 or 3 edges, so vertices
of the new quad may be glued to the contiguous boundary), until one attachment has p inside
its path, which makes p interior. Every new quad contains p, so the result is star-covered
again; attachments along longer paths may close further boundary vertices at the same time
(they then become interior with their current valence). Intermediate states of a closing are
deduplicated with p marked.

Why it is complete (and how it is checked). Order the internal vertices of a catalogue mesh M
so that each shares a quad with an earlier one (possible: the "shares a quad" graph of
internal vertices is connected, because adjacent quads share an internal edge whose internal
endpoint lies in both). The unions of stars of the prefixes are exactly the states a closing
sequence visits, as long as each union is a disk: then closing the next vertex attaches its
missing quads contiguously. A union that is not a disk would need a pocket of M enclosed by
one star and reachable only through it (when the star's link touches the boundary of the
union away from the closed vertex, the vertices on the boundary arc between the two contacts
are internal and can be closed first, which shrinks the pocket; what remains are stars whose
link passes twice through one diagonal vertex that lies on the mesh boundary and encloses
internal vertices, which needs many internal vertices: a pinched star enclosing a filled
4-cycle already needs about 8). So this argument covers the catalogue sizes built here but is
not a proof for every k. The tests check it against :mod:`jaxmatch.catalogue.shelling`, which is complete
by the shellability of disks, as sets of canonical ids for k <= 3.
"""

from __future__ import annotations

import contextlib
import signal
from typing import Callable

from jaxmatch.catalogue.canon_fast import canonical_key as canonical
from jaxmatch.catalogue.shelling import Disk, attach, single_quad, is_catalogue_mesh


def _needs_lower_bound_excluding(d: Disk, p: int) -> int:
    """Lower bound on boundary vertices (other than p) that must become internal."""
    on_b = set(d.boundary) - {p}
    n = len(d.boundary)
    bedges = set()
    for j in range(n):
        a, c = d.boundary[j], d.boundary[(j + 1) % n]
        bedges.add((a, c) if a < c else (c, a))
    needs = [set(q) for q in d.quads if all(v in on_b for v in q)]
    needs += [{a, c} for a, c in d.edges if a in on_b and c in on_b and (a, c) not in bedges]
    needs.sort(key=len)
    used: set[int] = set()
    count = 0
    for s in needs:
        if not (s & used):
            used |= s
            count += 1
    return count


def _marked_key(d: Disk, p: int) -> tuple:
    vals = list(d.vals)
    vals[p] += 10  # mark the vertex being closed: it is then distinguishable in the canonical form
    return canonical(d.quads, d.boundary, vals).key


def close_vertex(d: Disk, p: int, max_internal: int) -> list[Disk]:
    """All star-covered disks obtained from ``d`` by closing boundary vertex ``p``."""
    results: list[Disk] = []
    frontier = {_marked_key(d, p): d}
    seen = set(frontier)
    while frontier:
        nxt: dict = {}
        for s in frontier.values():
            n = len(s.boundary)
            ip = s.boundary.index(p)
            # quads around p: at most MAX_VALENCE; valence of a boundary vertex = quads + 1
            for length in (1, 2, 3):
                for start in range(ip - length, ip + 1):
                    inside = start < ip < start + length
                    c = attach(s, start % n, length)
                    if c is None:
                        continue
                    if c.interior + (0 if inside else 1) > max_internal:
                        continue
                    if inside:
                        if c.interior + _needs_lower_bound_excluding(c, -1) <= max_internal:
                            results.append(c)
                        continue
                    if c.interior + 1 + _needs_lower_bound_excluding(c, p) > max_internal:
                        continue
                    key = _marked_key(c, p)
                    if key not in seen:
                        seen.add(key)
                        nxt[key] = c
        frontier = nxt
    return results


def _expand(states: list[Disk], max_internal: int) -> dict[tuple, Disk]:
    """Children of a chunk of states (every boundary vertex closed in every way), deduplicated."""
    out: dict[tuple, Disk] = {}
    for s in states:
        for p in s.boundary:
            for child in close_vertex(s, p, max_internal):
                key = canonical(child.quads, child.boundary, child.vals).key
                if key not in out:
                    out[key] = child
    return out


def close_all(max_internal: int, progress: Callable | None = None, workers: int = 1) -> dict[int, dict[tuple, Disk]]:
    """All catalogue meshes with k = 0 .. max_internal internal vertices.

    Returns {k: {canonical key: Disk}}. ``progress(k, n_states, n_found)`` is called when
    level k is done. ``workers > 1`` expands each level's states in that many processes.
    """
    found: dict[int, dict[tuple, Disk]] = {k: {} for k in range(max_internal + 1)}
    q = single_quad()
    found[0][canonical(q.quads, q.boundary, q.vals).key] = q
    if max_internal == 0:
        return found
    levels: dict[int, dict[tuple, Disk]] = {j: {} for j in range(1, max_internal + 1)}
    # level 1: closing a corner of the single quad gives the stars of valence 3, 4, 5
    for child in close_vertex(q, 0, max_internal):
        levels[child.interior].setdefault(canonical(child.quads, child.boundary, child.vals).key, child)
    pool = None
    if workers > 1:
        import concurrent.futures
        import multiprocessing

        pool = concurrent.futures.ProcessPoolExecutor(
            workers, mp_context=multiprocessing.get_context("spawn"), initializer=_ignore_sigint)
    try:
        for j in range(1, max_internal + 1):
            for key, s in levels[j].items():
                if is_catalogue_mesh(s):
                    found[j][key] = s
            if j < max_internal:
                states = list(levels[j].values())
                if pool is None or len(states) < 64:
                    parts = [_expand(states, max_internal)]
                else:
                    size = max(16, len(states) // (workers * 16))
                    chunks = [states[i : i + size] for i in range(0, len(states), size)]
                    with _sigint_ignored():  # workers spawned now inherit it: Ctrl-C is the parent's
                        parts = pool.map(_expand, chunks, [max_internal] * len(chunks))
                for part in parts:
                    for key, child in part.items():
                        levels[child.interior].setdefault(key, child)
            levels[j] = {}  # expanded: free the memory
            if progress is not None:
                progress(j, len(found[j]), len(found[j]))
    except BaseException:
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
            pool = None
        raise
    finally:
        if pool is not None:
            pool.shutdown()
    return found


@contextlib.contextmanager
def _sigint_ignored():
    """Ignore SIGINT while worker processes are started (they inherit the disposition)."""
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _ignore_sigint() -> None:
    """Workers leave Ctrl-C to the parent (which cancels them), so they print no tracebacks."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
