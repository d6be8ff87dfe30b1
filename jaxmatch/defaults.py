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

DEFAULT_DIVISIONS = 32
"""``jaxmatch mesh`` without ``--size``: the target edge length is the outer perimeter / this."""

DEFAULT_BUDGET_S = 60.0
"""``jaxmatch mesh``: after this many seconds no further candidate is tried once one valid mesh
exists (``--budget``; the Python API has no budget unless given ``budget_s``)."""

DEFAULT_BAND = 0.1
"""The quality band of ``jaxmatch mesh`` (``--band``): a mesh whose utility is within this
fraction of the ranked mesh's and that places with min scaled Jacobian >= 0.3 is placed
instead of one that does not (:func:`jaxmatch.placement.choose.choose_mesh`; 0: off)."""


from dataclasses import dataclass


@dataclass(frozen=True)
class Search:
    """How much of the candidate search :func:`jaxmatch.mesh` runs (``search=``, ``--search``):
    the search itself is the same, these only stop it earlier.

    name: ``"best"`` (the default: every candidate that could win is meshed, so the mesh is the
        one the choice rule picks among all of them) or ``"fast"``.
    layouts: at most this many layouts are meshed (the most promising first) once one of them
        is valid and reaches :attr:`Quality.good_sj` (with a size field: and follows it; else the
        ring partition and the transitions would run after it); None: every layout that could win.
    leave_out: the strategies of the plan not run, by class name
        (:mod:`jaxmatch.meshing.strategies`: ``"Conforming"``, ``"Larger"``, ``"LeanCurves"``, ...).
    enough: after the layouts, stop at a best mesh that is valid, conforms to the size and
        reaches :attr:`Quality.high_sj` (no ring partition, no leaner curves, no bends).
    box: the layouts' count programs are first solved with every count bounded
        (:func:`jaxmatch.placement.milp.count_box`): an optimum all the same, found faster, but of
        equally good counts not always the one found without.
    """

    name: str = "best"
    layouts: int | None = None
    leave_out: tuple = ()
    enough: bool = False
    box: bool = False


SEARCHES = {"best": Search(), "fast": Search("fast", layouts=1, leave_out=("Conforming", "Larger"), enough=True, box=True)}
"""The searches by name (``--search``). ``"fast"``: what it gives up, measured on 300 random
parts and the 50 benchmark cases, is in docs/perf.md ("The fast search")."""


@dataclass(frozen=True)
class Quality:
    """The meshing quality policy: every floor and band, defined once.

    min_sj: quality floor of ``mesh --template`` (``--min-quality``; smallest acceptable min
        scaled Jacobian, in ``[-1, 1]``).
    good_sj: a placed or refined mesh "of good quality" reaches this min scaled Jacobian; below it
        templates are passed over (refinement, layouts) and the quality band looks further.
    max_edge_ratio: largest acceptable longest/shortest edge of a quad (``--max-edge-ratio``).
    band: the utility band of ``mesh --template`` (``--band``, a fraction of the utility).
    high_sj: the choice rule's quality band: a mesh reaching this min scaled Jacobian is preferred
        to one that does not before irregular vertices are counted.
    area_tol: a mesh keeps the region's area when ``|mesh area / region area - 1| <= area_tol``.
    coarse_side: a boundary stretch of ``n`` edges and length ``L`` is coarser than the size ``h``
        when even one edge more would leave its edges longer than this many ``h``,
        ``L / (n + 1) > coarse_side * h`` (one edge of rounding); with ``long_edge``, what size
        conformity rules out (a stretch finer than ``h`` is allowed: a small feature is meshed
        finer, not cut off).
    size_tol: a side fits the size ``h`` when its edge count ``n`` and length ``L`` satisfy
        ``|n - L / h| <= max(1, size_tol * L / h)`` (one edge of rounding, or this fraction): the
        choice rule's size fit, after the quality rule.
    long_edge: inside the region too, an edge longer than this many ``h`` breaks size conformity
        (a strip of quads across a region much wider than ``h``).
    sj_step: min scaled Jacobians within one step of this size count as equal (the choice rule's
        quality rule, and the template size's band of ``mesh --template``): a mesh with fewer
        irregular vertices, patches or quads is not given up for a few hundredths of quality.
    short_edge: with a size field, an edge shorter than the field at its midpoint over this
        breaks size conformity too (a graded mesh refined where the field does not ask for it;
        more lenient than ``long_edge``: too fine costs quads, too coarse misses the refinement).
    size_band: ``(lo, hi)``: an edge is "at the size" when its length is within ``[lo h, hi h]``
        (the field at its midpoint with a field).
    band_share: a mesh "meets the size band" when at least this share of its edges is at the size
        (``size_band``): the choice rule's size band, after the size fit; the ring partition and
        the lean curves are tried for a best mesh that nearly meets it (``band_near``). A yes or
        no: between meshes that both miss it (a region with features smaller than ``h`` is meshed
        finer there), it does not decide.
    band_near: the ring partition and the lean curves are tried for a best mesh that misses the
        size band only when at least this share of its edges is at the size (a near miss; further
        off, the region's features smaller than ``h`` make the short edges).
    lean_cost: a mesh whose curves take the curved sides' share of the area budget alone (tried
        when the best mesh nearly meets the size band: :class:`jaxmatch.meshing.strategies.LeanCurves`)
        is kept only when it meets the size band and its min scaled Jacobian is at most this
        below the best mesh's: coarser curves for the band, not for a worse mesh.
    transition_gain: a patch off the size band may take a larger template (a transition: opposite
        sides with different counts) where the integer program's size objective drops by at
        least this many edges per internal vertex the template has more
        (:func:`jaxmatch.placement.solve.mesh_layout`, ``transitions``).
    transition_cost: a mesh of transition templates (:class:`jaxmatch.meshing.strategies.Transitions`,
        tried when the best mesh misses the size band or the field) is kept only when its min
        scaled Jacobian is at most this below the best mesh's.
    uniform_transitions: whether a mesh to one size (no field) tries the transitions too (a mesh
        to a size field always does). Off: on 80 random parts at perimeter / 32
        (``scripts/make_bulk_parts.py --count 80 --seed 38``, in-process) they doubled the CPU
        time (31.3 s against 15.8 s) for 3 meshes nearer the size band; on, the 8-pointed star
        part at P/40 has 94 % of its edges in the band instead of 50 %.
    search: how much of the candidate search runs (:class:`Search`; default the whole of it).
    field: the size field the mesh follows (a bound :class:`jaxmatch.field.SizeField` or
        :class:`~jaxmatch.field.CallableSize`: ``(n, 2)`` points to ``(n,)`` sizes), or None: one size
        ``h`` everywhere. With a field, side counts are its integrals, side vertices are spaced by it
        and size conformity is judged against it (the pipeline sets it from ``mesh(size=...)``).
    """

    min_sj: float = 0.2
    good_sj: float = 0.3
    high_sj: float = 0.6
    max_edge_ratio: float = 8.0
    band: float = DEFAULT_BAND
    area_tol: float = 0.01
    coarse_side: float = 1.5
    size_tol: float = 0.25
    long_edge: float = 2.0
    sj_step: float = 0.1
    short_edge: float = 3.0
    size_band: tuple = (0.5, 1.5)
    band_share: float = 0.8
    band_near: float = 0.5
    lean_cost: float = 0.02
    transition_gain: float = 0.5
    transition_cost: float = 0.02
    uniform_transitions: bool = False
    search: Search = Search()
    field: object = None


QUALITY = Quality()
"""The default policy (:class:`Quality`)."""
