"""The Python entry points that combine the pipeline's stages (scoring, then placement).

:func:`rank` is :func:`jaxmatch.scoring.rank.rank` with the tie-break named by a string
(``"id"`` or ``"geometry"``, as the CLI's ``--tie-break``); ``"geometry"`` places tied meshes
(:func:`jaxmatch.placement.choose.geometry_tie_breaker`).
"""

from __future__ import annotations

from jaxmatch.catalogue.store import Catalogue
from jaxmatch.placement.choose import choose_mesh, geometry_tie_breaker
from jaxmatch.scoring.lattice import Lattice
from jaxmatch.scoring.rank import Ranking
from jaxmatch.scoring.rank import rank as _rank
from jaxmatch.shape import Shape

__all__ = ["TIE_BREAKS", "choose_mesh", "rank"]

TIE_BREAKS = ("id", "geometry")
"""Orders among equal utilities (see :func:`jaxmatch.scoring.rank.rank`)."""


def rank(shape: Shape, catalogue: Catalogue, lattice: Lattice, *, tie_break: str = "id", **options) -> Ranking:
    """:func:`jaxmatch.scoring.rank.rank` with ``tie_break`` one of :data:`TIE_BREAKS`
    (``"geometry"``: ties ordered by the quality of the placed meshes). Other keyword
    arguments as there. Raises ValueError for an unknown ``tie_break``."""
    if tie_break not in TIE_BREAKS:
        raise ValueError(f"tie_break must be one of {TIE_BREAKS}, got {tie_break!r}")
    tb = geometry_tie_breaker(catalogue, lattice) if tie_break == "geometry" else "id"
    return _rank(shape, catalogue, lattice, tie_break=tb, **options)
