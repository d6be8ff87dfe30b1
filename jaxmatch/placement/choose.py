"""Placing ranked meshes in the user's shape: the glue between ranking and geometry.

:func:`rank <jaxmatch.scoring.rank.rank>` works on the combinatorics only; this module puts a
ranked mesh into the shape (:func:`jaxmatch.placement.embed.place` on the unit-box shape, then mapped to
the user's coordinates), re-orders tied utilities by the quality of the embedding
(:func:`rerank_ties`), walks down a ranking for the first mesh that embeds without folds
(:func:`first_valid`), and draws placed meshes (:func:`draw_placements`).

:func:`choose_mesh` is what ``jaxmatch mesh`` does; :func:`place_top` is what
``jaxmatch score --png`` does.

All placements returned here are in the user's coordinates (the shape file's unit of length).
Placements are deterministic (numpy only), so a ``placements`` cache (``mesh_id -> Placement``,
valid for one shape, annotation and catalogue) can be passed around to avoid placing a mesh
twice.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from itertools import groupby, islice
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Sequence

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.placement.embed import Placement, inverted_mask, place, quality
from jaxmatch.scoring.rank import TIE_CAP, Match, Ranking, TieBreaker
from jaxmatch.scoring.rank import rank as rank_meshes

if TYPE_CHECKING:  # pragma: no cover
    from jaxmatch.catalogue.store import Catalogue
    from jaxmatch.scoring.lattice import Lattice
    from jaxmatch.shape import Annotation, Shape

__all__ = [
    "DEFAULT_WALK",
    "MeshChoice",
    "TIE_CAP",
    "check_outputs",
    "choose_mesh",
    "draw_placements",
    "first_valid",
    "geometry_key",
    "geometry_tie_breaker",
    "place_match",
    "place_top",
    "rerank_ties",
]

DEFAULT_WALK = 50
"""Default number of ranked candidates :func:`first_valid` tries."""

SJ_DIGITS = 6
"""Minimum scaled Jacobians are compared rounded to this many decimals (so that round-off
cannot reorder two meshes of practically equal quality; the mesh id decides then)."""


# ---------------------------------------------------------------------------------------------
# spreading the boundary vertices

SPREAD_MAX_WORK = 40_000_000
"""Largest ``starts * m * m * n`` the exact :func:`spread_alignment` DP may cost; beyond it the
first vertex is only tried on the points nearest its given one (about 0.3 s of numpy)."""


def spread_alignment(t: np.ndarray, perimeter: float, codes: np.ndarray, alignment: np.ndarray) -> np.ndarray:
    """An alignment with the same utility as ``alignment`` whose vertices are spread evenly.

    t: (m,) increasing arc-length parameters of the annotated points in ``[0, perimeter)``;
    codes: (m,) point codes (s/x/v); alignment: (n,) strictly increasing indices (a match's).

    The utility of an alignment is the sum of ``weight[codes[i_j], triple_j]``, so every
    strictly increasing ``i'`` with ``codes[i'_j] == codes[alignment[j]]`` for all ``j`` has
    exactly the same utility, whatever the lattice. Among those, this returns the one that
    minimises the sum of squared arc-length gaps between cyclically consecutive vertices
    (the gap after the last vertex wraps around to the first), i.e. the most even spacing
    along the outline: the scorer's own alignment only maximises utility and often packs the
    vertices into a few neighbouring points. Exact dynamic programme over (first vertex,
    vertex, point), ``O(starts * n * m^2)``; the first vertex is tried on every point of its
    code (on the nearest ones only when that exceeds :data:`SPREAD_MAX_WORK`). Ties keep the
    smaller indices. Returns ``(n,) int64``; ``alignment`` itself when ``n < 2``.
    """
    tt = np.asarray(t, dtype=np.float64).ravel()
    c = np.asarray(codes).ravel()
    al = np.asarray(alignment, dtype=np.int64).ravel()
    n, m = al.shape[0], tt.shape[0]
    if n < 2:
        return al.copy()
    want = c[al]  # (n,) code of each vertex's point
    ok = c[None, :] == want[:, None]  # (n, m) allowed points per vertex
    starts = np.flatnonzero(ok[0])
    if starts.size * m * m * n > SPREAD_MAX_WORK:
        keep = max(SPREAD_MAX_WORK // (m * m * n), 1)
        starts = starts[np.argsort(np.abs(starts - al[0]), kind="stable")[:keep]]
        starts = np.union1d(starts, al[:1])
    S = starts.size
    inf = np.inf
    gap2 = (tt[:, None] - tt[None, :]) ** 2  # [i, i']
    gap2 = np.where(np.arange(m)[None, :] < np.arange(m)[:, None], gap2, inf)  # only i' < i
    D = np.full((S, m), inf)
    D[np.arange(S), starts] = 0.0
    back = np.zeros((n, S, m), dtype=np.int32)
    for j in range(1, n):
        tot = D[:, None, :] + gap2[None, :, :]  # (S, i, i')
        arg = np.argmin(tot, axis=2)
        D = np.take_along_axis(tot, arg[..., None], axis=2)[..., 0]
        D[:, ~ok[j]] = inf
        back[j] = arg
    closing = (perimeter - tt[None, :] + tt[starts][:, None]) ** 2
    total = D + closing
    flat = int(np.argmin(total))
    if not np.isfinite(total.flat[flat]):  # cannot happen: ``alignment`` itself is feasible
        return al.copy()
    s, i = divmod(flat, m)
    out = np.empty(n, np.int64)
    for j in range(n - 1, -1, -1):
        out[j] = i
        i = int(back[j, s, i])
    return out


def gap_cost(t: np.ndarray, perimeter: float, alignment: np.ndarray) -> float:
    """Sum of squared cyclic arc-length gaps between consecutive aligned points (what
    :func:`spread_alignment` minimises)."""
    ta = np.asarray(t, dtype=np.float64)[np.asarray(alignment, dtype=np.int64)]
    g = np.diff(np.concatenate([ta, [ta[0] + perimeter]]))
    return float(np.sum(g * g))


# ---------------------------------------------------------------------------------------------
# placing one match


def place_match(shape: Shape, annotation: Annotation, catalogue: Catalogue, match: Match, *,
                smooth_iters: int = 200, spread: bool = True, placements: dict | None = None) -> Placement:
    """Place the ranked ``match`` in ``shape``; the result is in the user's coordinates.

    annotation: the annotation the match was computed for (``ranking.annotation``).
    The mesh (``catalogue.mesh(match.mesh_id)``) is oriented by the match's rotation and
    reflection; its boundary vertices sit exactly on annotated points: those of
    ``match.alignment`` re-spread evenly along the outline at the same utility
    (:func:`spread_alignment`; ``spread=False``: ``match.alignment`` as it is; should the
    spread one fold, ``match.alignment`` is placed too and the one with fewer inverted quads,
    then higher min scaled Jacobian, is kept). The interior is embedded and smoothed
    (:func:`jaxmatch.placement.embed.place`). ``Placement.alignment`` holds the
    alignment used. Quality (scaled Jacobian, angles, inverted count) is recomputed on the user
    coordinates, so it agrees with what is drawn and written. ``placements``: optional cache
    keyed by mesh id (read and filled; only for one shape, annotation, catalogue and
    ``spread``/``smooth_iters`` setting).
    """
    if placements is not None and match.mesh_id in placements:
        return placements[match.mesh_id]
    mesh = catalogue.mesh(match.mesh_id)
    given = np.asarray(match.alignment, dtype=np.int64)
    al = spread_alignment(annotation.t, annotation.perimeter, annotation.codes, given) if spread else given

    def put(alignment):
        return place(shape.points, annotation.t, alignment, mesh, match.rotation, match.reflected,
                     positions=annotation.positions, smooth_iters=smooth_iters)

    pl = put(al)
    if pl.inverted and not np.array_equal(al, given):  # rare: then keep the better of the two
        other = put(given)
        if (other.inverted, -other.min_scaled_jacobian) < (pl.inverted, -pl.min_scaled_jacobian):
            pl = other
    user = to_user_placement(shape, pl)
    if placements is not None:
        placements[match.mesh_id] = user
    return user


def to_user_placement(shape: Shape, pl: Placement) -> Placement:
    """A unit-box placement mapped to user coordinates (``shape.to_user``), quality recomputed."""
    xy = shape.to_user(pl.xy)
    quads = pl.mesh.quads
    sj, amin, amax = quality(xy, quads)
    s2 = float(shape.scale) ** 2
    return dataclasses.replace(
        pl,
        xy=xy,
        scaled_jacobian=sj,
        min_angle=amin,
        max_angle=amax,
        inverted=int(inverted_mask(xy, quads).sum()),
        boundary_paths=tuple(shape.to_user(p) for p in pl.boundary_paths),
        region_area=pl.region_area * s2,
        mesh_area=pl.mesh_area * s2,
    )


# ---------------------------------------------------------------------------------------------
# ties


def geometry_key(placement: Placement, mesh_id: str) -> tuple:
    """Sort key among equal utilities: higher min scaled Jacobian (rounded to
    :data:`SJ_DIGITS` decimals; NaN counts as worst), then fewer irregular internal vertices,
    then the mesh id. A placement with inverted quads always sorts after one without (this
    only matters when both round to a min scaled Jacobian of 0: a degenerate, 180-degree
    corner whose sign is round-off)."""
    sj = placement.min_scaled_jacobian
    sj = -math.inf if math.isnan(sj) else round(sj, SJ_DIGITS)
    return (placement.inverted > 0, -sj, int(len(placement.irregular)), mesh_id)


def rerank_ties(shape: Shape, annotation: Annotation, catalogue: Catalogue, matches: Sequence[Match], *,
                cap: int = TIE_CAP, placements: dict | None = None, smooth_iters: int = 200) -> list[Match]:
    """Re-order meshes of equal utility by the quality of their embedding.

    matches: ranked best first (utilities non-increasing). Within each run of equal utility
    with more than one member, members are placed (:func:`place_match`) and ordered by
    :func:`geometry_key` (no inverted quads first, then higher min scaled Jacobian, then
    fewer irregular internal vertices, then id). At most ``cap`` meshes are placed in all, in the given order; tied meshes beyond
    the cap follow the placed ones of their run, in the given order. Utilities never change
    order. ``placements``: cache (mesh id -> placement), read and filled. Returns a new list.
    """
    budget = max(int(cap), 0)
    cache = {} if placements is None else placements
    out: list[Match] = []
    for _, grp in groupby(matches, key=lambda m: float(m.utility)):
        grp = list(grp)
        if len(grp) < 2 or budget <= 0:
            out.extend(grp)
            continue
        head, tail = grp[:budget], grp[budget:]
        budget -= len(head)
        keyed = [(geometry_key(place_match(shape, annotation, catalogue, m, smooth_iters=smooth_iters, placements=cache), m.mesh_id), i)
                 for i, m in enumerate(head)]
        out.extend(head[i] for _, i in sorted(keyed))
        out.extend(tail)
    return out


def geometry_tie_breaker(catalogue: Catalogue, *, smooth_iters: int = 200) -> TieBreaker:
    """The ``tie_break`` of :func:`jaxmatch.scoring.rank.rank` that orders equal utilities by
    :func:`rerank_ties` (placed quality) for meshes of ``catalogue``."""

    def reorder(shape: Shape, annotation: Annotation, matches: Sequence[Match], cap: int, placements: dict) -> list[Match]:
        return rerank_ties(shape, annotation, catalogue, matches, cap=cap, placements=placements, smooth_iters=smooth_iters)

    return reorder


# ---------------------------------------------------------------------------------------------
# walking down a ranking


def first_valid(shape: Shape, annotation: Annotation, catalogue: Catalogue, matches: Iterable[Match], *,
                limit: int = DEFAULT_WALK, placements: dict | None = None,
                smooth_iters: int = 200) -> tuple[int, Match, Placement] | None:
    """The first of (at most ``limit`` of) ``matches`` whose placement has no inverted quad.

    matches: candidates in ranking order (any iterable; consumed lazily). Returns
    ``(index into matches, match, placement)`` or None when none of the first ``limit``
    embeds without folds. ``placements``: cache, read and filled.
    """
    for i, m in enumerate(islice(matches, max(int(limit), 0))):
        pl = place_match(shape, annotation, catalogue, m, smooth_iters=smooth_iters, placements=placements)
        if pl.inverted == 0:
            return i, m, pl
    return None


@dataclass(frozen=True, eq=False)
class MeshChoice:
    """Result of :func:`choose_mesh`.

    ranking: the ranking used (its ``results`` hold the first ``requested_rank`` matches);
    rank / match / placement: the mesh placed (1-based rank; placement in user coordinates);
    requested_rank: the ``--rank`` asked for (``rank`` differs only with ``require_valid``);
    alternative: when ``placement`` has inverted quads, the next-ranked mesh that embeds
    without folds as ``(rank, match, placement)``, or None when none of the next ``walk``
    does (also None when ``placement`` is valid); searched: how many ranked meshes after
    the requested one were placed looking for a valid one (0 when none was needed).
    """

    ranking: Ranking
    rank: int
    match: Match
    placement: Placement
    requested_rank: int
    alternative: tuple[int, Match, Placement] | None = None
    searched: int = 0

    @property
    def valid(self) -> bool:
        return self.placement.inverted == 0


def choose_mesh(shape: Shape, catalogue: Catalogue, lattice: Lattice, *, rank: int = 1,
                internal: list[int] | None = None, points: int | None = None, tie_break: str = "geometry",
                tie_cap: int = TIE_CAP, require_valid: bool = False, walk: int = DEFAULT_WALK,
                progress: Callable[[int, int], None] | None = None) -> MeshChoice:
    """Rank the catalogue for ``shape``, take the ``rank``-th mesh (1-based) and place it.

    When that mesh folds (inverted quads): with ``require_valid`` the ranking is walked down
    (at most ``walk`` meshes from ``rank`` on, in ranking order) and the first mesh that embeds
    with zero inverted quads is placed instead (if there is none, the ``rank``-th is kept and
    ``alternative`` is None); otherwise the ``rank``-th is kept and the next ``walk`` meshes
    are searched for ``alternative``. Raises :class:`InputError` when fewer than ``rank``
    meshes match, :class:`UnmatchableError` when none does.
    """
    r = int(rank)
    if r < 1:
        raise InputError(f"rank must be at least 1, got {r}", "--rank")
    # top=0: score only; count the matchable meshes before aligning (or placing) any of them
    tb = geometry_tie_breaker(catalogue) if tie_break == "geometry" else tie_break
    ranking = rank_meshes(shape, catalogue, lattice, internal=internal, top=0, points=points,
                          tie_break=tb, tie_cap=tie_cap, progress=progress)
    count = ranking.scored - ranking.unmatchable
    if count < r:
        raise InputError(f"only {count} meshes match the shape, cannot take rank {r}", "--rank")
    ranking = ranking._replace(results=list(islice(ranking.following, r)))
    cache = ranking.placements if ranking.placements is not None else {}
    ann = ranking.annotation
    match = ranking.results[r - 1]
    pl = place_match(shape, ann, catalogue, match, placements=cache)
    if pl.inverted == 0:
        return MeshChoice(ranking, r, match, pl, r)
    following = ranking.following if ranking.following is not None else iter(())
    tried: list[Match] = []
    candidates = (tried.append(m) or m for m in following)
    found = first_valid(shape, ann, catalogue, candidates, limit=max(int(walk) - 1, 0), placements=cache)
    alt = None if found is None else (r + 1 + found[0], found[1], found[2])
    if require_valid and alt is not None:
        return MeshChoice(ranking, alt[0], alt[1], alt[2], r, None, len(tried))
    return MeshChoice(ranking, r, match, pl, r, alt, len(tried))


def place_top(shape: Shape, ranking: Ranking, catalogue: Catalogue, *, placements: dict | None = None) -> list[Placement]:
    """Placements (user coordinates) of every match in ``ranking.results``, in order; reuses
    ``ranking.placements`` (meshes already placed for tie-breaking)."""
    cache = placements if placements is not None else (ranking.placements if ranking.placements is not None else {})
    return [place_match(shape, ranking.annotation, catalogue, m, placements=cache) for m in ranking.results]


# ---------------------------------------------------------------------------------------------
# output


def check_outputs(out: str | os.PathLike | None = None, png: str | os.PathLike | None = None,
                  svg: str | os.PathLike | None = None) -> None:
    """Refuse unsupported output suffixes before any work is done (:class:`InputError`, where
    is the option): ``out`` a mesh file (.vtk .vtu .obj .msh .json), ``png`` a .png file,
    ``svg`` a .svg file."""
    from jaxmatch.io.meshfile import mesh_format

    if out is not None:
        try:
            mesh_format(out)
        except InputError as e:
            raise InputError(f"{e}", "--out") from None
    for opt, path, suffix in (("--png", png, ".png"), ("--svg", svg, ".svg")):
        if path is not None and Path(path).suffix.lower() != suffix:
            raise InputError(f"{path}: picture file must end in {suffix}", opt)


def draw_placements(path: str | os.PathLike, shape: Shape, annotation: Annotation,
                    items: Sequence[tuple[str, Placement]], *, title: str | None = None, ncols: int | None = None) -> Path:
    """Draw placed meshes side by side (one panel per ``(panel title, placement)``) over the
    shape's outline and annotated s/x/v points, in user coordinates, and save to ``path``
    (.png or .svg, atomically; see :func:`jaxmatch.io.plot.draw_many`). Each panel shows boundary
    vertices coloured by valence, irregular internal vertices, inverted quads in red and the
    quality (min / mean scaled Jacobian, inverted count) in its title."""
    from jaxmatch.io.plot import Panel, draw_many

    outline = shape.user_points
    pos = shape.to_user(annotation.positions)
    panels = [Panel(outline, pos, annotation.codes, pl, t) for t, pl in items]
    return draw_many(panels, path, ncols=ncols, title=title)


def panel_title(rank: int, match: Match) -> str:
    """``"#1 k5-b2b65fa5f3b0 (utility 24, rot 0)"``: title line for a picture panel (the full
    mesh id, so that it can be copied into ``catalogue export --id``)."""
    refl = ", reflected" if match.reflected else ""
    return f"#{rank} {match.mesh_id} (utility {match.utility:g}, rot {match.rotation}{refl})"
