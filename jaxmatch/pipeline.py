"""The main job: rank catalogue meshes for a shape (shape -> annotation -> scores -> top K).

Everything the ``jaxmatch score`` command prints comes from :func:`rank`.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from .catalogue import Catalogue
from .errors import UnmatchableError
from .lattice import Lattice
from .mesh import triples
from .score import align, oriented_sequence, score_bucket
from .shape import Annotation, Shape, annotate, default_points


class Match(NamedTuple):
    """One ranked mesh.

    alignment: (n,) int32 input index per mesh boundary vertex, in matched order
    (after rotation and reflection; strictly increasing). triples: (n, 3) in that order.
    """

    mesh_id: str
    internal_vertices: int
    boundary_length: int
    utility: float
    rotation: int
    reflected: bool
    alignment: np.ndarray
    triples: np.ndarray

    def as_json(self) -> dict:
        return {
            "mesh_id": self.mesh_id,
            "internal_vertices": int(self.internal_vertices),
            "boundary_length": int(self.boundary_length),
            "utility": float(self.utility),
            "rotation": int(self.rotation),
            "reflected": bool(self.reflected),
            "alignment": [int(i) for i in self.alignment],
            "triples": [[int(x) for x in t] for t in self.triples],
        }


class Ranking(NamedTuple):
    """Result of :func:`rank`: the annotation used, the top matches (best first) and counts."""

    annotation: Annotation
    results: list[Match]
    scored: int
    unmatchable: int


def selected_lengths(catalogue: Catalogue, internal: list[int] | None) -> list[int]:
    """Boundary lengths that hold at least one mesh with k in ``internal``."""
    return [b.n for b in catalogue.buckets(internal)]


def rank(
    shape: Shape,
    catalogue: Catalogue,
    lattice: Lattice,
    *,
    internal: list[int] | None = None,
    top: int = 5,
    points: int | None = None,
    per_size: bool = False,
    progress: Callable[[int, int], None] | None = None,
) -> Ranking:
    """Score every selected catalogue mesh against ``shape`` and return the best ``top``.

    internal: k values to consider (None: all sizes compete; raw utilities then favour larger
    meshes, which match more points). per_size: return the best ``top`` of *each* k.
    points: number m of annotated shape points (default :func:`default_points` for the
    longest selected boundary). progress(done, total): meshes scored so far.
    Ties are broken by (fewer internal vertices, shorter boundary, id) for determinism.
    Raises UnmatchableError when no selected mesh has a finite matching.
    """
    lengths = selected_lengths(catalogue, internal)
    if not lengths:
        raise UnmatchableError(f"the catalogue has no mesh with {internal_text(internal)}")
    m = points if points is not None else default_points(shape, max(lengths))
    ann = annotate(shape, m)
    table = lattice.table()
    buckets = list(catalogue.buckets(internal))
    total = sum(len(b.ids) for b in buckets)
    rows = []  # (utility, k, n, id, rotation, reflected, vals)
    done = unmatchable = 0
    for b in buckets:
        res = score_bucket(ann.codes, b.valences, table)
        ok = ~res.unmatchable
        unmatchable += int((~ok).sum())
        for i in np.flatnonzero(ok):
            rows.append((float(res.utility[i]), int(b.k[i]), b.n, str(b.ids[i]), int(res.rotation[i]), bool(res.reflected[i]), b.valences[i]))
        done += len(b.ids)
        if progress is not None:
            progress(done, total)
    if not rows:
        raise UnmatchableError(unmatchable_reason(ann, lengths, lattice))
    rows.sort(key=lambda r: (-r[0], r[1], r[2], r[3]))
    if per_size:
        chosen, count = [], {}
        for r in rows:
            if count.get(r[1], 0) < top:
                count[r[1]] = count.get(r[1], 0) + 1
                chosen.append(r)
        chosen.sort(key=lambda r: (r[1], -r[0], r[2], r[3]))
    else:
        chosen = rows[:top]
    results = []
    for util, k, n, mid, rot, refl, vals in chosen:
        alignment = align(ann.codes, vals, table, rot, refl)
        results.append(Match(mid, k, n, util, rot, refl, alignment, triples(oriented_sequence(vals, rot, refl))))
    return Ranking(ann, results, total, unmatchable)


def internal_text(internal: list[int] | None) -> str:
    if internal is None:
        return "any number of internal vertices"
    if len(internal) == 1:
        return f"{internal[0]} internal vertices"
    return f"{internal[0]}..{internal[-1]} internal vertices"


def unmatchable_reason(ann: Annotation, lengths: list[int], lattice: Lattice) -> str:
    """One sentence: why no mesh matched, and which option to change."""
    m = len(ann.codes)
    if min(lengths) > m:
        return (f"every selected mesh has more boundary vertices ({min(lengths)}+) than the shape has points ({m}); "
                f"raise --points to at least {max(lengths)}")
    return (f"every selected mesh needs a forbidden (-inf) pairing with the shape's {ann.symbols.count('x')} convex and "
            f"{ann.symbols.count('v')} concave corners under lattice '{lattice.name}' (m={m}); "
            "try more --points, other --internal sizes, or a lattice with fewer forbidden triples")
