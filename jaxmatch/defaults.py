"""The defaults shared by ``jaxmatch score``, ``score-many``, ``mesh``, ``annotate`` and the
Python API (:mod:`jaxmatch.api`): one place for each (a light module, no JAX import).

The corner angle lives with the shapes: :data:`jaxmatch.shape.DEFAULT_CORNER_ANGLE`. The
default number of annotated points is :func:`jaxmatch.shape.default_points` (twice the longest
boundary of the sizes scored); the default catalogue is the shipped one
(:func:`jaxmatch.catalogue.store.default_catalogue`, k = 0..5).
"""

TIE_BREAKS = ("id", "geometry")
"""Orders among equal utilities (see :func:`jaxmatch.scoring.rank.rank`)."""

DEFAULT_LATTICE = "fine"
"""Lattice used when none is named (``--lattice``)."""

DEFAULT_TOP = 5
"""How many ranked meshes are returned (``--top``)."""

DEFAULT_TIE_BREAK = "geometry"
"""Ties in utility are ordered by the quality of the placed meshes (``--tie-break``)."""

DEFAULT_PRUNE = True
"""Pruned top-K search (``--exhaustive`` turns it off; the ranking is the same)."""

DEFAULT_BAND = 0.1
"""The quality band of ``jaxmatch mesh`` (``--band``): a mesh whose utility is within this
fraction of the ranked mesh's and that places with min scaled Jacobian >= 0.3 is placed
instead of one that does not (:func:`jaxmatch.placement.choose.choose_mesh`; 0: off)."""
