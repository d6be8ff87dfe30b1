"""The Python API: the functions ``import jaxmatch`` gives, combining the pipeline's stages.

A session (the README's "Python API" section runs this, as a test)::

    import jaxmatch

    shape = jaxmatch.load_shape("examples/lshape.json")         # or make_shape([[x, y], ...])
    ranking = jaxmatch.rank(shape, internal=4, top=3)           # default catalogue and lattice
    best = ranking.results[0]                                   # a Match: mesh_id, utility, ...
    placement = jaxmatch.place(shape, ranking)                  # the #1 mesh, user coordinates
    m = jaxmatch.mesh(shape, size=0.25)                         # the meshing pipeline: a QuadMesh
    jaxmatch.write_mesh("lshape.vtk", m)                        # .vtk .vtu .obj .msh .json
    t = jaxmatch.mesh(shape, template=True, internal=4)         # the paper's answer, as a QuadMesh

Defaults are those of the ``jaxmatch`` command (``score``, ``score-many`` and ``mesh``), all
from :mod:`jaxmatch.defaults`: the shipped catalogue (k = 0..5), lattice ``"fine"``, top 5,
ties broken by ``"geometry"`` (quality of the placed meshes), the pruned top-K search
(same ranking as exhaustive scoring), ``m`` = twice the longest boundary scored, corner angle
:data:`jaxmatch.shape.DEFAULT_CORNER_ANGLE`.

Errors: bad input raises :class:`jaxmatch.errors.InputError` (one line naming the file or
the argument); a shape no selected mesh can match raises
:class:`jaxmatch.errors.UnmatchableError`.
"""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Callable

from jaxmatch.catalogue.store import Catalogue
from jaxmatch.defaults import DEFAULT_BAND, DEFAULT_LATTICE, DEFAULT_PRUNE, DEFAULT_TIE_BREAK, DEFAULT_TOP, TIE_BREAKS
from jaxmatch.inputs import Sizes, _lattice, check_sizes, load_catalogue, sizes_text  # noqa: F401 (public here)
from jaxmatch.errors import InputError
from jaxmatch.io.readers import load_shape, parse_shape
from jaxmatch.lazy import Later
from jaxmatch.scoring.lattice import Lattice, load_lattice
from jaxmatch.scoring.rank import Match, Ranking
from jaxmatch.scoring.rank import rank as _rank
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, Annotation, Shape, annotate, default_points, make_shape

if TYPE_CHECKING:  # at run time served by __getattr__ below
    from jaxmatch.io.meshfile import write_mesh
    from jaxmatch.meshing.pipeline import mesh
    from jaxmatch.placement.choose import MeshChoice
    from jaxmatch.placement.embed import Placement

__all__ = [
    "DEFAULT_CORNER_ANGLE",
    "DEFAULT_LATTICE",
    "DEFAULT_PRUNE",
    "DEFAULT_TIE_BREAK",
    "DEFAULT_TOP",
    "TIE_BREAKS",
    "annotate_shape",
    "check_sizes",
    "choose_mesh",
    "load_catalogue",
    "load_lattice",
    "load_shape",
    "make_shape",
    "mesh",
    "mesh_concave",
    "mesh_layout",
    "parse_shape",
    "place",
    "rank",
    "refine_mesh",
    "sizes_text",
    "write_mesh",
]

later = Later(choose="jaxmatch.placement.choose", refine="jaxmatch.placement.refine", pipeline="jaxmatch.meshing.pipeline")
"""The placement and meshing modules (and scipy), loaded only when a mesh is placed or made:
ranking with ``tie_break="id"``, and every command that imports this module (the command line),
do not pay for them."""

_LAZY = {"write_mesh": "jaxmatch.io.meshfile", "mesh": "jaxmatch.meshing.pipeline", "Placement": "jaxmatch.placement.embed", "MeshChoice": "jaxmatch.placement.choose"}
"""Names served on first access (for the same reason as :data:`later`)."""


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def rank(shape: Shape, catalogue: str | os.PathLike | Catalogue | None = None, lattice: str | os.PathLike | Lattice = DEFAULT_LATTICE,
         *, internal: Sizes = None, top: int = DEFAULT_TOP, points: int | None = None, per_size: bool = False,
         tie_break: str = DEFAULT_TIE_BREAK, prune: bool = DEFAULT_PRUNE, devices: int | None = None,
         progress: Callable[[int, int], None] | None = None, tie_cap: int | None = None) -> Ranking:
    """Rank catalogue meshes for ``shape`` (best first): :func:`jaxmatch.scoring.rank.rank`
    with the command line's defaults.

    catalogue: None (the shipped one), a path or a :class:`Catalogue`. lattice: ``"fine"``,
    ``"coarse"``, a TOML path or a :class:`Lattice`. internal: mesh sizes (``4``, ``"3..5"``,
    ``[3, 4]``; None: all sizes compete). top: how many matches in ``Ranking.results``.
    points: annotated shape points ``m`` (default twice the longest boundary scored).
    per_size: the best ``top`` of each size. tie_break: one of :data:`TIE_BREAKS`
    (``"geometry"``: equal utilities ordered by the quality of the placed meshes; ``"id"``:
    the paper's combinatorial order). prune: pruned top-K search (same results as
    ``prune=False``, faster). devices: shard the scoring over that many JAX devices.
    progress(done, total): called as meshes are scored.

    Returns a :class:`~jaxmatch.scoring.rank.Ranking`: ``annotation`` (the s/x/v sequence
    used), ``results`` (a list of :class:`~jaxmatch.scoring.rank.Match`: ``mesh_id``,
    ``internal_vertices``, ``boundary_length``, ``utility``, ``rotation``, ``reflected``,
    ``alignment (n,)``, ``triples (n, 3)``), counts ``scored``/``unmatchable``/``pruned``.
    Raises ValueError for an unknown ``tie_break``; :class:`InputError` for sizes the
    catalogue does not have.
    """
    if tie_break not in TIE_BREAKS:
        raise ValueError(f"tie_break must be one of {TIE_BREAKS}, got {tie_break!r}")
    cat = load_catalogue(catalogue)
    ks = check_sizes(cat, internal)
    lat = _lattice(lattice)
    tb = "id"
    if tie_break == "geometry":
        tb = later.choose.geometry_tie_breaker(cat, lat)
    return _rank(shape, cat, lat, internal=ks, top=top, points=points, per_size=per_size, tie_break=tb,
                 prune=prune, devices=devices, progress=progress, tie_cap=tie_cap)


def place(shape: Shape, ranking: Ranking, which: int | Match = 1,
          catalogue: str | os.PathLike | Catalogue | None = None,
          lattice: str | os.PathLike | Lattice = DEFAULT_LATTICE) -> Placement:
    """Place a ranked mesh in ``shape`` (user coordinates).

    which: the rank (1-based, within ``ranking.results``) or a :class:`Match` of ``ranking``.
    catalogue, lattice: the ones ``ranking`` was computed with (default: the shipped catalogue
    and lattice); the lattice lets placement try every orientation of equal utility, so the
    result does not depend on how the shape's loop is written.
    Returns a :class:`~jaxmatch.placement.embed.Placement`: ``xy (V, 2)`` vertex positions,
    ``mesh.quads (F, 4)``, ``scaled_jacobian (F,)``, ``min_scaled_jacobian``, ``inverted``
    (count of inverted quads), ``area_ratio``, ...; to write it, mesh with ``mesh(shape,
    template=True, ...)`` (a :class:`~jaxmatch.meshing.result.QuadMesh`, what :func:`write_mesh`
    takes) or convert it with :func:`jaxmatch.meshing.build.from_placement`.
    """
    if isinstance(which, Match):
        match = which
    else:
        r = int(which)
        if not 1 <= r <= len(ranking.results):
            raise InputError(f"rank {r} is not in the ranking (it holds {len(ranking.results)} results; raise top)")
        match = ranking.results[r - 1]
    cache = ranking.placements if ranking.placements is not None else None
    return later.choose.place_match(shape, ranking.annotation, load_catalogue(catalogue), match, placements=cache,
                                    lattice=_lattice(lattice))


def choose_mesh(shape: Shape, catalogue: str | os.PathLike | Catalogue | None = None,
                lattice: str | os.PathLike | Lattice = DEFAULT_LATTICE, *, rank: int = 1, internal: Sizes = None,
                points: int | None = None, tie_break: str = DEFAULT_TIE_BREAK, require_valid: bool = False,
                band: float = DEFAULT_BAND, progress: Callable[[int, int], None] | None = None) -> MeshChoice:
    """Rank, take the ``rank``-th mesh and place it (what ``jaxmatch mesh`` does):
    :func:`jaxmatch.placement.choose.choose_mesh` with the command line's defaults.

    require_valid: walk down the ranking to the first mesh that embeds without inverted
    quads. band: the quality band (a mesh within this fraction of the requested mesh's
    utility that places with min scaled Jacobian >= 0.3 is placed instead of one that does
    not; 0: off). Returns a :class:`~jaxmatch.placement.choose.MeshChoice` (``match``,
    ``placement``, ``rank``, ``valid``, ``alternative``, ``passed_over``).
    """
    if tie_break not in TIE_BREAKS:
        raise ValueError(f"tie_break must be one of {TIE_BREAKS}, got {tie_break!r}")
    cat = load_catalogue(catalogue)
    ks = check_sizes(cat, internal)
    return later.choose.choose_mesh(shape, cat, _lattice(lattice), rank=rank, internal=ks, points=points,
                                    tie_break=tie_break, require_valid=require_valid, band=band, progress=progress)


def annotate_shape(shape: Shape, catalogue: str | os.PathLike | Catalogue | None = None, *, internal: Sizes = None,
                   points: int | None = None) -> Annotation:
    """The s/x/v annotation :func:`rank` would score for these options: ``points`` annotated
    points, by default twice the longest boundary among the selected catalogue sizes."""
    cat = load_catalogue(catalogue)
    ks = check_sizes(cat, internal)
    if points is None:
        lengths = [b.n for b in cat.buckets(ks)]
        points = default_points(shape, max(lengths) if lengths else 0)
    return annotate(shape, points)


def refine_mesh(shape: Shape, catalogue: str | os.PathLike | Catalogue | None = None,
                lattice: str | os.PathLike | Lattice = DEFAULT_LATTICE, *, sides=None, size: float | None = None,
                internal: Sizes = None):
    """A mesh of ``shape`` with the requested edges per side (``sides``: one count per side, side
    i from corner i to corner i+1 in the file's order) or edges of about ``size`` (shape units):
    what ``jaxmatch mesh --sides/--size`` does (:func:`jaxmatch.placement.refine.refine_mesh`).

    Returns a :class:`~jaxmatch.placement.refine.RefineChoice`: ``mesh`` (a
    :class:`~jaxmatch.placement.refine.RefinedMesh`: ``xy (V, 2)``, ``quads (Q, 4)``,
    ``side_vertices``, ``counts (n_sides,)``, quality), ``template``, ``passed_over``, ``note``.
    Raises :class:`~jaxmatch.placement.refine.InfeasibleRequest` (an :class:`InputError`) naming
    the sides and the nearest feasible counts when no template can meet ``sides``.
    """
    cat = load_catalogue(catalogue)
    ks = check_sizes(cat, internal)
    return later.refine.refine_mesh(shape, cat, _lattice(lattice), sides=sides, size=size, internal=ks)


def mesh_layout(layout, catalogue: str | os.PathLike | Catalogue | None = None,
                lattice: str | os.PathLike | Lattice = DEFAULT_LATTICE, *, size: float | None = None, counts=None):
    """A multi-patch layout (a path or a :class:`~jaxmatch.placement.layout.Layout`) as one
    conforming mesh: a thin wrapper of :func:`jaxmatch.mesh` (``counts``: ``{side id: edges}``).
    Returns a :class:`~jaxmatch.meshing.result.QuadMesh`."""
    return later.pipeline.mesh(layout, size=size, counts=counts, catalogue=catalogue, lattice=lattice)


def mesh_concave(shape: Shape, size: float, catalogue: str | os.PathLike | Catalogue | None = None,
                 lattice: str | os.PathLike | Lattice = DEFAULT_LATTICE):
    """``shape`` meshed with edges of about ``size``, the best of one template and every
    decomposition: a thin wrapper of :func:`jaxmatch.mesh`. Returns a
    :class:`~jaxmatch.meshing.result.QuadMesh` (``chosen`` names the candidate)."""
    return later.pipeline.mesh(shape, size=size, catalogue=catalogue, lattice=lattice)
