"""The main job: rank catalogue meshes for a shape (shape -> annotation -> scores -> top K).

Everything the ``jaxmatch score`` command prints comes from :func:`rank`.
"""

from __future__ import annotations

import copy
from itertools import groupby, islice
from collections.abc import Sequence
from typing import Callable, Iterator, NamedTuple

import numpy as np

from jaxmatch.cache import key as cache_key
from jaxmatch.catalogue.store import Catalogue
from jaxmatch.errors import UnmatchableError
from jaxmatch.scoring.lattice import Lattice
from jaxmatch.catalogue.mesh import triples
from jaxmatch.scoring.exact import align, oriented_sequence, score_bucket, utility_parts
from jaxmatch.kernels.model import Weights, weights_of
from jaxmatch.scoring.bulk import prepared, top_k
from jaxmatch.shape import Annotation, Shape, annotate, default_points


class Match(NamedTuple):
    """One ranked mesh.

    alignment: (n,) int32 input index per mesh boundary vertex, in matched order
    (after rotation and reflection; strictly increasing). triples: (n, 3) in that order.
    match_utility / skip_utility: the utility split into the matched pairs' weights and the
    skipped points' skip weights (``utility = match_utility + skip_utility``).
    """

    mesh_id: str
    internal_vertices: int
    boundary_length: int
    utility: float
    rotation: int
    reflected: bool
    alignment: np.ndarray
    triples: np.ndarray
    match_utility: float = float("nan")
    skip_utility: float = 0.0

    def as_json(self) -> dict:
        return {
            "mesh_id": self.mesh_id,
            "internal_vertices": int(self.internal_vertices),
            "boundary_length": int(self.boundary_length),
            "utility": float(self.utility),
            "match_utility": float(self.match_utility),
            "skip_utility": float(self.skip_utility),
            "rotation": int(self.rotation),
            "reflected": bool(self.reflected),
            "alignment": [int(i) for i in self.alignment],
            "triples": [[int(x) for x in t] for t in self.triples],
        }


class Ranking(NamedTuple):
    """Result of :func:`rank`: the annotation used, the top matches (best first) and counts.

    placements: with ``tie_break="geometry"``, the meshes placed to break ties
    (mesh id -> :class:`~jaxmatch.placement.embed.Placement`, user coordinates); None otherwise.
    following: the matches after ``results`` in the same order, produced lazily (a one-shot
    iterator; with ``tie_break="geometry"`` it places tied meshes as it goes, into
    ``placements``, within the same cap); None with ``per_size``.
    pruned: meshes skipped by the pruned search (``rank(prune=True)``): they cannot enter the top.
    """

    annotation: Annotation
    results: list[Match]
    scored: int
    unmatchable: int
    placements: dict | None = None
    following: Iterator[Match] | None = None
    pruned: int = 0


class LazyMatches(Sequence):
    """Ranked matches, each made (aligned, its utility parts) when first asked for.

    rows: ``(utility, k, n, mesh_id, rotation, reflected, valences)`` in rank order; make: row ->
    :class:`Match`. :meth:`reordered` gives a view in another order sharing the matches made."""

    def __init__(self, rows: Sequence[tuple], make: Callable[[tuple], Match]):
        self.rows = list(rows)
        self._make = make
        self._made: dict[int, Match] = {}
        self._order: list[int] | None = None

    def reordered(self, key: Callable[[tuple], object]) -> "LazyMatches":
        """The same matches ordered by ``key(row)`` (a stable sort of this view)."""
        view = copy.copy(self)
        view._order = sorted(self._indices(), key=lambda j: key(self.rows[j]))
        return view

    def _indices(self) -> list[int]:
        return list(range(len(self.rows))) if self._order is None else self._order

    def __len__(self) -> int:
        return len(self.rows)

    def head(self, i: int) -> tuple[str, int, int, bool]:
        """``(mesh_id, internal_vertices, rotation, reflected)`` of the ``i``-th match (``i >= 0``),
        without making it (a scan skips most matches on these alone)."""
        r = self.rows[i if self._order is None else self._order[i]]
        return r[3], r[1], r[4], r[5]

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        i = range(len(self.rows))[i]  # negative indices; IndexError past the end
        j = i if self._order is None else self._order[i]
        m = self._made.get(j)
        if m is None:
            m = self._made[j] = self._make(self.rows[j])
        return m


TIE_CAP = 64
"""Default largest number of meshes placed to break ties in one ranking."""

TieBreaker = Callable[[Shape, Annotation, Sequence[Match], int, dict], list[Match]]
"""``(shape, annotation, tied matches, cap, placements cache) -> re-ordered matches``: re-orders
runs of equal utility (:func:`jaxmatch.placement.choose.geometry_tie_breaker` places them and
orders them by quality); it may place at most ``cap`` meshes and fills the cache."""


def selected_lengths(catalogue: Catalogue, internal: list[int] | None) -> list[int]:
    """Boundary lengths that hold at least one mesh with k in ``internal``."""
    return [b.n for b in catalogue.buckets(internal)]


def rank(
    shape: Shape,
    catalogue: Catalogue,
    lattice: Lattice | Weights,
    *,
    internal: list[int] | None = None,
    top: int = 5,
    points: int | None = None,
    per_size: bool = False,
    progress: Callable[[int, int], None] | None = None,
    tie_break: str | TieBreaker = "id",
    tie_cap: int | None = None,
    prune: bool = False,
    devices: int | None = None,
    lazy: bool = False,
) -> Ranking:
    """Score every selected catalogue mesh against ``shape`` and return the best ``top``.

    lattice: the scoring model (a :class:`Lattice` or its compiled
    :class:`jaxmatch.kernels.model.Weights`), compiled once for the whole ranking.
    internal: k values to consider (None: all sizes compete; raw utilities then favour larger
    meshes, which match more points). per_size: return the best ``top`` of *each* k.
    points: number m of annotated shape points (default :func:`default_points` for the
    longest selected boundary). progress(done, total): meshes scored so far.

    tie_break: order among equal utilities.

    * ``"id"`` (default): fewer internal vertices, then shorter boundary, then id.
    * a :data:`TieBreaker` such as :func:`jaxmatch.placement.choose.geometry_tie_breaker`
      (``"geometry"`` in :func:`jaxmatch.api.rank` and the CLI; beyond the paper; meshes with the same boundary sequence always tie, and
      integer weights make many more ties): every mesh whose utility equals that of a returned
      mesh is placed in the shape (:func:`jaxmatch.placement.choose.place_match`, about 0.02-0.15 s
      each) and ties are ordered by higher min scaled Jacobian, then fewer irregular internal
      vertices, then id (:func:`jaxmatch.placement.choose.rerank_ties`). Only ties are re-ordered,
      utilities keep their order. At most ``tie_cap`` meshes (default
      :data:`TIE_CAP` = 64) are placed per call, in "id" order; tied meshes
      past the cap follow the placed ones of their utility in "id" order. Meshes alone at
      their utility are not placed. The placements are returned in ``Ranking.placements``.

    prune: find the top meshes with :func:`jaxmatch.scoring.bulk.top_k`: each distinct boundary sequence is
    scored once, in decreasing order of a cheap upper bound, and sequences that cannot enter the
    top are skipped (same results as exhaustive scoring, tested; ``Ranking.pruned`` counts the
    skipped meshes and ``following`` then only holds the remaining tied rows). lazy (with
    ``per_size`` and ties by id): ``results`` is a :class:`LazyMatches`, each match aligned when
    first asked for (a template scan uses a few of them). devices: shard the
    scoring over that many JAX devices (:func:`jaxmatch.scoring.bulk.configure_host_devices` makes CPU
    devices; it must run before JAX is imported); implies the bulk path.

    Raises UnmatchableError when no selected mesh has a finite matching; ValueError for an
    unknown ``tie_break``.
    """
    if not (tie_break == "id" or callable(tie_break)):
        raise ValueError(f"tie_break must be 'id' or a tie breaker function, got {tie_break!r}")
    bulk_path = prune or (devices is not None and devices > 1)
    if bulk_path:  # the catalogue grouped once (bulk.prepared), not re-read for every shape

        parts = prepared(catalogue, internal)
        lengths = [p.n for p in parts]
    else:
        lengths = selected_lengths(catalogue, internal)
    if not lengths:
        raise _unmatchable(f"the catalogue has no mesh with {internal_text(internal)}", "internal")
    m = points if points is not None else default_points(shape, max(lengths))
    ann = annotate(shape, m)
    memo = (per_size and bulk_path and tie_break == "id" and progress is None
            and not (devices is not None and devices > 1))
    if memo:
        key = cache_key(ann.codes, None if internal is None else tuple(internal), lattice, int(top), bool(prune),
                        bool(lazy))
        hit = catalogue.cache.lookup("rankings", key)
        if hit is not None:
            return Ranking(ann, hit[0] if lazy else list(hit[0]), *hit[1:])
    weights = weights_of(lattice)
    buckets = [] if bulk_path else list(catalogue.buckets(internal))
    total = sum(len(p.ids) for p in parts) if bulk_path else sum(len(b.ids) for b in buckets)
    rows = []  # (utility, k, n, id, rotation, reflected, vals)
    done = unmatchable = pruned = 0
    if bulk_path:
        tk = top_k(ann.codes, parts, weights, top=top, per_size=per_size, prune=prune,
                   devices=devices if devices is not None and devices > 1 else None, progress=progress)
        rows, unmatchable, pruned = list(tk.rows), tk.unmatchable, tk.pruned
    for b in buckets:
        res = score_bucket(ann.codes, b.valences, weights)
        ok = ~res.unmatchable
        unmatchable += int((~ok).sum())
        for i in np.flatnonzero(ok):
            rows.append((float(res.utility[i]), int(b.k[i]), b.n, str(b.ids[i]), int(res.rotation[i]), bool(res.reflected[i]), b.valences[i]))
        done += len(b.ids)
        if progress is not None:
            progress(done, total)
    if not rows:
        raise unmatchable_error(ann, lengths, weights)
    rows.sort(key=lambda r: (-r[0], r[1], r[2], r[3]))

    def to_match(r) -> Match:
        util, k, n, mid, rot, refl, vals = r
        alignment = align(ann.codes, vals, weights, rot, refl)
        parts = utility_parts(ann.codes, vals, weights, rot, refl, alignment)
        return Match(mid, k, n, util, rot, refl, alignment, triples(oriented_sequence(vals, rot, refl)),
                     parts.match, parts.skip)

    placements = {} if callable(tie_break) else None
    budget = [TIE_CAP if tie_cap is None else max(int(tie_cap), 0)]

    def ordered(sel) -> Iterator[Match]:
        """Matches of the sorted rows ``sel`` in final order, one utility run at a time."""
        for _, grp in groupby(sel, key=lambda r: r[0]):
            grp = list(grp)
            if placements is None or len(grp) < 2 or budget[0] <= 0:
                yield from (to_match(r) for r in grp)
                continue
            head = [to_match(r) for r in grp[: budget[0]]]
            placed = tie_break(shape, ann, head, budget[0], placements)
            budget[0] -= len(head)
            yield from placed
            yield from (to_match(r) for r in grp[len(head):])

    if per_size:
        if lazy and placements is None:
            chosen = []
            for k in sorted({r[1] for r in rows}):
                chosen.extend([r for r in rows if r[1] == k][:top])  # what ordered() yields with ties by id
            results = LazyMatches(chosen, to_match)
        else:
            results = []
            for k in sorted({r[1] for r in rows}):
                results.extend(islice(ordered([r for r in rows if r[1] == k]), top))
        if memo:  # with ties broken by id the matches depend on nothing else (the template scan's calls)
            catalogue.cache.put("rankings", key, (results if isinstance(results, LazyMatches) else tuple(results),
                                                  total, unmatchable, placements, None, pruned))
        return Ranking(ann, results, total, unmatchable, placements, None, pruned)
    it = ordered(rows)
    results = list(islice(it, top))
    return Ranking(ann, results, total, unmatchable, placements, it, pruned)


def ranking_json(shape: str, ranking: Ranking, lattice_name: str, tie_break: str) -> dict:
    """The JSON record of ``jaxmatch score --json`` (and each line of ``score-many``)."""
    return {
        "shape": shape, "sequence": ranking.annotation.symbols, "lattice": lattice_name,
        "points": len(ranking.annotation.codes), "scored": ranking.scored, "unmatchable": ranking.unmatchable,
        "pruned": ranking.pruned, "tie_break": tie_break, "results": [r.as_json() for r in ranking.results],
    }


def internal_text(internal: list[int] | None) -> str:
    if internal is None:
        return "any number of internal vertices"
    if len(internal) == 1:
        return f"{internal[0]} internal vertices"
    return f"{internal[0]}..{internal[-1]} internal vertices"


UNMATCHABLE_CAUSES = ("internal", "points", "forbidden")
"""Values of ``UnmatchableError.cause``: which input would have to change (the CLI names the
option for each; core messages name only the concept)."""


def _unmatchable(message: str, cause: str, points: int | None = None) -> UnmatchableError:
    err = UnmatchableError(message)
    err.cause = cause  # type: ignore[attr-defined]
    err.points = points  # type: ignore[attr-defined]  # the number of points needed, for "points"
    return err


def unmatchable_reason(ann: Annotation, lengths: list[int], lattice) -> str:
    """One sentence: why no mesh matched, and what to change (concepts, no option names)."""
    return str(unmatchable_error(ann, lengths, lattice))


def unmatchable_error(ann: Annotation, lengths: list[int], lattice) -> UnmatchableError:
    """:class:`UnmatchableError` saying why no mesh matched, with ``cause`` (one of
    :data:`UNMATCHABLE_CAUSES`) and ``points`` (the number of points needed, or None) for the
    caller's hint."""
    w = weights_of(lattice)
    m = len(ann.codes)
    if min(lengths) > m:
        return _unmatchable(f"every selected mesh has more boundary vertices ({min(lengths)}+) than the shape has points ({m}); "
                            f"annotate the shape with at least {max(lengths)} points", "points", max(lengths))
    must = [f"{ann.symbols.count(k)} {name}" for k, name in zip("sxv", ("straight points", "convex corners", "concave corners"))
            if w.must["sxv".index(k)]]
    need = f"; the lattice requires a mesh vertex at each of its {' and '.join(must)}" if must else ""
    name = f" '{w.name}'" if w.name else ""
    return _unmatchable(f"every selected mesh needs a forbidden (-inf) pairing with the shape's {ann.symbols.count('x')} convex and "
                        f"{ann.symbols.count('v')} concave corners under lattice{name} (m={m}){need}; "
                        "try more annotated points, other mesh sizes, or a lattice with fewer forbidden entries", "forbidden")
