"""The one mesh result type: :class:`QuadMesh`, whatever made it (a placed template, a refined
template, a decomposition, a layout file), like meshio's one ``Mesh`` for every format.

Quality figures are computed from ``xy`` and ``quads`` alone (Verdict scaled Jacobian, signed
areas, valences), so two meshes made by different strategies are judged by the same measures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Mapping, NamedTuple

import numpy as np

from jaxmatch.arrays import roll
from jaxmatch.catalogue.mesh import boundary_loops, edges, valences
from jaxmatch.defaults import QUALITY, Quality
from jaxmatch.field import SHARE_BAND
from jaxmatch.geometry import signed_area
from jaxmatch.quality import edge_ratios, quad_areas, sj_inverted

__all__ = ["Candidate", "QuadMesh", "boundary_loops", "irregular_bound"]

_KEPT = ("_sj_inverted", "_edges", "_edge_lengths", "_valences", "_loops", "_missed", "_area", "_stretches",
         "_region_parts", "_edge_targets", "_irregular", "irregular_bound", "_memo")
"""The :class:`QuadMesh` measures computed once per mesh (``cached_property`` names)."""


class Candidate(NamedTuple):
    """One candidate the pipeline tried: ``name`` (``"single"``, a decomposition strategy,
    ``"template"``, ``"layout"``), its ``mesh`` (a :class:`QuadMesh`) or None, and ``note``:
    why it has no mesh (empty when it has one). ``bound``: for one not meshed because it could
    not win, the smallest :func:`~jaxmatch.meshing.choose.mesh_key` its mesh could have had."""

    name: str
    mesh: "QuadMesh | None"
    note: str = ""
    bound: tuple | None = None


def irregular_bound(quads: np.ndarray, n_vertices: int) -> int:
    """Fewest irregular internal vertices any quad mesh with these boundary valences can have.

    Euler's formula for a quad mesh of a region with ``H`` holes: ``sum over internal vertices
    (4 - valence) + sum over boundary vertices (3 - valence) = 4 (1 - H)``. With internal
    valences 3..5 each irregular vertex contributes +-1, so at least
    ``|4 (1 - H) - sum_boundary (3 - valence)|`` of them are needed.
    """
    quads = np.asarray(quads, dtype=np.int64)
    return _irregular_bound(valences(quads, n_vertices), boundary_loops(quads))


def _irregular_bound(val: np.ndarray, loops: list[np.ndarray]) -> int:
    """:func:`irregular_bound` from the valences ``(V,)`` and the boundary loops."""
    bverts = np.concatenate(loops) if loops else np.zeros(0, np.int64)
    total = 4 * (1 - (len(loops) - 1)) - int(np.sum(3 - val[bverts]))
    return abs(total)


@dataclass(frozen=True, eq=False)
class QuadMesh:
    """A quad mesh of a planar region, with where it came from and how it was chosen.

    xy: ``(V, 2) float64`` user coordinates; quads: ``(Q, 4) int64`` counter-clockwise.
    patch: ``(Q,) int64`` the patch of each quad (all 0 for one template).
    line_sets: name -> ``(E, 2) int64`` edges: ``"boundary"`` (the outer loop), ``"side i-j"``
        (the side from the input's corner ``i`` to ``j``: :mod:`jaxmatch.meshing.groups`; a
        layout file's side between its points ``i`` and ``j``), ``"hole h"``, ``"hole h side
        i-j"``, ``"cut k"`` (between patches), the user's tags.
    region_area: area of the region (user units squared); corners: ``(C, 2) float64`` the
        region's corners, each of which must be a mesh vertex.
    size: the target edge length (user units) or None; side_lengths / side_counts: name ->
        length of a side on the region's boundary and its number of mesh edges (``"i-j"``).
    point_sets: name -> ``(N,) int64`` node ids (the periodic pairs' ``"periodic k a"`` /
        ``"periodic k b"``, in matching order).
    field: the size field the mesh was made to follow (``Quality.field``: ``(n, 2)`` points to
        ``(n,)`` sizes) or None; with one, the size measures (:meth:`stretches_off_size`,
        :meth:`sides_off_size`, :meth:`long_edges`, :attr:`field_share`) read the local size at
        each edge's midpoint instead of ``size``.
    chosen: the candidate that won (``"single"``, a decomposition, ``"template"``, ``"layout"``);
    rule: the rule of :mod:`jaxmatch.meshing.choose` that decided (empty with one candidate);
    runner_up: the best other candidate's name or None; tried: every :class:`Candidate`;
    templates: catalogue ids of the templates used, per patch; detail: the strategy's own record
    of its choice where it has one (``template=True``: the
    :class:`~jaxmatch.placement.choose.MeshChoice`, with the ranking, rank, utility and quality
    band that the command line reports; an assembly: per region its pieces' strategies), else None.
    regions: an assembly's region names: ``patch`` is then the region of each quad (each region a
    cell group of its name; empty: the groups are ``"patch p"``); point_sets: name -> ``(k,)
    int64`` vertex ids (an assembly's ``"point k"``, its embedded points).

    The measures of ``xy`` and ``quads`` (scaled Jacobians, edges, valences, boundary loops,
    missed corners) are computed once per mesh and kept (:data:`_KEPT`): the choice rule reads
    them for every candidate, twice; ``xy`` and ``quads`` are not to be written to.
    """

    xy: np.ndarray
    quads: np.ndarray
    patch: np.ndarray
    line_sets: Mapping[str, np.ndarray]
    region_area: float
    corners: np.ndarray
    size: float | None = None
    side_lengths: Mapping[str, float] = field(default_factory=dict)
    side_counts: Mapping[str, int] = field(default_factory=dict)
    templates: tuple[str, ...] = ()
    point_sets: Mapping[str, np.ndarray] = field(default_factory=dict)
    chosen: str = ""
    rule: str = ""
    runner_up: str | None = None
    tried: tuple[Candidate, ...] = ()
    detail: object = None
    regions: tuple[str, ...] = ()
    point_sets: Mapping[str, np.ndarray] = field(default_factory=dict)
    field: object = None

    def with_choice(self, chosen: str, rule: str, runner_up: str | None, tried) -> "QuadMesh":
        """This mesh, labelled with how it was chosen (the measures kept so far kept with it)."""
        out = replace(self, chosen=chosen, rule=rule, runner_up=runner_up, tried=tuple(tried))
        out.__dict__.update({k: self.__dict__[k] for k in _KEPT if k in self.__dict__})
        return out

    # -- measures kept once computed (cached_property: written to the instance's __dict__) ------

    @cached_property
    def _sj_inverted(self) -> tuple[np.ndarray, int]:
        """``((Q,) float64`` scaled Jacobian per quad, inverted quads``)``, one pass over the corners."""
        sj, inv = sj_inverted(self.xy, self.quads)
        return sj, int(inv.sum())

    @cached_property
    def _edges(self) -> np.ndarray:
        """``(E, 2) int64`` undirected edges (:func:`~jaxmatch.catalogue.mesh.edges`)."""
        return edges(np.asarray(self.quads, np.int64))

    @cached_property
    def _edge_lengths(self) -> np.ndarray:
        """``(E,) float64`` length of each edge of :attr:`_edges` (user units)."""
        e = self._edges
        return np.linalg.norm(self.xy[e[:, 0]] - self.xy[e[:, 1]], axis=1)

    @cached_property
    def _edge_targets(self) -> np.ndarray:
        """``(E,) float64`` the size each edge of :attr:`_edges` is measured against: the field at
        its midpoint, or ``size`` everywhere (NaN without either)."""
        e = self._edges
        if self.field is None:
            return np.full(e.shape[0], self.size if self.size else math.nan)
        return np.asarray(self.field(0.5 * (self.xy[e[:, 0]] + self.xy[e[:, 1]])), np.float64)

    def _wanted(self, edges_: np.ndarray) -> float:
        """Edges of the field wanted along ``edges_ (k, 2)``: the sum of length / field at the
        midpoint."""
        a, b = self.xy[edges_[:, 0]], self.xy[edges_[:, 1]]
        return float(np.sum(np.linalg.norm(b - a, axis=1) / self.field(0.5 * (a + b))))

    @property
    def field_share(self) -> float | None:
        """Share of the edges whose length / the size at its midpoint (the field, or ``size``)
        lies in :data:`jaxmatch.field.SHARE_BAND` (None without a size)."""
        if self.field is None and not self.size:
            return None
        return self.band_share(SHARE_BAND)

    def band_share(self, band: tuple[float, float]) -> float:
        """Share of the edges whose length / the size at its midpoint (the field, or ``size``)
        lies in ``band = (lo, hi)`` (NaN without a size or without edges)."""
        if not self._edges.size:
            return math.nan
        r = self._edge_lengths / self._edge_targets
        return float(np.mean((r >= band[0]) & (r <= band[1])))

    def misses_size_band(self, quality) -> bool:
        """Whether fewer than ``quality.band_share`` of the edges are within ``quality.size_band``
        sizes (the choice rule's size band; False without a size: nothing to miss)."""
        if self.field is None and not self.size:
            return False
        return not (self.band_share(quality.size_band) >= quality.band_share)

    def near_size_band(self, quality) -> bool:
        """Whether the mesh misses the size band (:meth:`misses_size_band`) by a near miss: at
        least ``quality.band_near`` of its edges within ``quality.size_band`` sizes (further
        off, features of the region smaller than the size make the short edges, which no other
        partition of it avoids)."""
        return self.misses_size_band(quality) and self.band_share(quality.size_band) >= quality.band_near

    @cached_property
    def _valences(self) -> np.ndarray:
        """``(V,) int32`` vertex valences (:func:`~jaxmatch.catalogue.mesh.valences`, from :attr:`_edges`)."""
        return np.bincount(self._edges.ravel(), minlength=self.xy.shape[0]).astype(np.int32)

    @cached_property
    def _area(self) -> float:
        """Sum of the quads' signed areas (user units squared)."""
        return float(quad_areas(self.xy, self.quads).sum())

    @cached_property
    def _loops(self) -> list[np.ndarray]:
        """The boundary loops (:func:`boundary_loops`)."""
        return boundary_loops(self.quads)

    @cached_property
    def _missed(self) -> np.ndarray:
        """``(c, 2)`` :attr:`missed_corners`."""
        if not self.corners.size:
            return np.zeros((0, 2))
        ext = float(np.ptp(self.xy, axis=0).max()) or 1.0
        d = np.min(np.linalg.norm(self.corners[:, None, :] - self.xy[None, :, :], axis=2), axis=1)
        return self.corners[d > 1e-9 * ext]

    @cached_property
    def _stretches(self) -> np.ndarray:
        """``(S, 3)`` edges, length (user units; with a field: the integral of 1 / field, edges
        wanted) and outer (1: on the outer loop, 0: a hole's) of
        every boundary stretch between consecutive corners of a boundary loop (a loop without a
        corner: the whole loop), from ``xy``, the quads and the region's corners alone (not from
        how the mesh was made)."""
        out = []
        ext = float(np.ptp(self.xy, axis=0).max()) if self.xy.size else 1.0
        for loop in self._loops:
            pts = self.xy[loop]
            seg = np.linalg.norm(roll(pts, -1) - pts, axis=1)
            outer = float(signed_area(pts) > 0)
            at = np.zeros(0, np.int64)
            if self.corners.size:
                d = np.min(np.linalg.norm(pts[:, None, :] - self.corners[None, :, :], axis=2), axis=1)
                at = np.flatnonzero(d <= 1e-9 * ext)
            if at.size == 0:
                out.append((len(loop), float(seg.sum()), outer))
                continue
            if self.field is not None:  # the field's integral, edge by edge, in place of the length
                seg = seg / self.field(0.5 * (pts + roll(pts, -1)))
            csum = [0.0] + np.cumsum(seg).tolist()  # (Python floats: the same sums, a corner at a time)
            at = at.tolist()
            for a, b in zip(at, at[1:] + at[:1]):
                n = (b - a) % len(loop) or len(loop)
                length = csum[b] - csum[a] if b > a else csum[-1] - csum[a] + csum[b]
                out.append((n, length, outer))
        return np.asarray(out, np.float64).reshape(-1, 3)

    def stretches_off_size(self, tol: float) -> int:
        """Boundary stretches between corners (:attr:`_stretches`) whose edge count ``n`` is off
        ``L / h`` by more than ``max(1, tol * L / h)`` (0 without a size): what the user sees of
        the size along the outline, whatever cuts the mesh's patches end on it."""
        if not (self.size or self.field is not None) or not self._stretches.size:
            return 0
        n, want = self._stretches[:, 0], self._stretches[:, 1] / (1.0 if self.field is not None else self.size)
        return int(np.sum(np.abs(n - want) > np.maximum(1.0, tol * want) + 1e-9))

    def coarse_stretches(self, factor: float) -> int:
        """Boundary stretches between corners (:attr:`_stretches`) of ``n`` edges and length ``L``
        whose edges would be longer than ``factor * h`` even with one edge more,
        ``L / (n + 1) > factor * h`` (0 without a size): sides meshed coarser than the size asked,
        beyond one edge of rounding. With a size field, ``L / h`` is the stretch's integral of
        ``1 / size``."""
        if not (self.size or self.field is not None) or not self._stretches.size:
            return 0
        n, want = self._stretches[:, 0], self._stretches[:, 1] / (1.0 if self.field is not None else self.size)
        return int(np.sum(want > factor * (n + 1) + 1e-9))

    # -- sets and data, as meshio names them ---------------------------------------------------

    @property
    def n_patches(self) -> int:
        return int(self.patch.max()) + 1 if self.patch.size else 0

    @property
    def cell_sets(self) -> dict[str, np.ndarray]:
        """``"patch p"`` (an assembly: each region's name) -> ``(Q_p,) int64`` quad indices."""
        if self.regions:
            return {name: np.flatnonzero(self.patch == r) for r, name in enumerate(self.regions)}
        return {f"patch {p}": np.flatnonzero(self.patch == p) for p in range(self.n_patches)}

    @property
    def cell_data(self) -> dict[str, np.ndarray]:
        """``patch (Q,) int64`` and ``scaled_jacobian (Q,) float64``."""
        return {"patch": self.patch, "scaled_jacobian": self.scaled_jacobian}

    # -- quality, from xy and quads only -------------------------------------------------------

    @property
    def scaled_jacobian(self) -> np.ndarray:
        """``(Q,) float64`` Verdict scaled Jacobian per quad, in ``[-1, 1]`` (a copy)."""
        return self._sj_inverted[0].copy()

    @property
    def min_scaled_jacobian(self) -> float:
        sj = self._sj_inverted[0]
        return float(sj.min()) if sj.size else math.nan

    @property
    def mean_scaled_jacobian(self) -> float:
        sj = self._sj_inverted[0]
        return float(sj.mean()) if sj.size else math.nan

    @property
    def inverted(self) -> int:
        """Quads with a corner of signed area <= 0."""
        return self._sj_inverted[1]

    @property
    def max_edge_ratio(self) -> float:
        r = edge_ratios(self.xy, self.quads)
        return float(r.max()) if r.size else math.nan

    @property
    def area_ratio(self) -> float:
        """Sum of the quads' signed areas / area of the region."""
        return float(self._area / self.region_area) if self.region_area else math.nan

    @property
    def irregular(self) -> np.ndarray:
        """``(I,) int64`` internal vertices (on no boundary loop) whose valence is not 4 (an
        assembly: on no region's boundary, interfaces included); a copy."""
        return self._irregular.copy()

    @cached_property
    def _irregular(self) -> np.ndarray:
        """:attr:`irregular`, computed once."""
        val = self._valences
        internal = np.ones(self.xy.shape[0], bool)
        for loop in self._loops + [lp for _, _, loops in self._region_parts for lp in loops]:
            internal[loop] = False
        return np.flatnonzero(internal & (val != 4) & (val > 0))

    @cached_property
    def irregular_bound(self) -> int:
        """Euler's lower bound on irregular internal vertices for these boundary valences (an
        assembly: the sum of its regions' bounds, each region's cells on their own)."""
        if self.regions:
            return sum(_irregular_bound(val, loops) for _, val, loops in self._region_parts)
        return _irregular_bound(self._valences, self._loops)

    @cached_property
    def _memo(self) -> dict:
        """The choice rule's counts for a quality's thresholds (:meth:`size_conformity`,
        :meth:`size_fit`), each computed once: the rule reads them for every candidate, several
        times a call."""
        return {}

    @cached_property
    def _region_parts(self) -> list[tuple[int, np.ndarray, list[np.ndarray]]]:
        """An assembly's regions: ``(region, valences (V,) of its cells, its cells' boundary loops)``."""
        out = []
        for r in range(len(self.regions)):
            q = np.asarray(self.quads, np.int64)[self.patch == r]
            out.append((r, valences(q, self.xy.shape[0]), boundary_loops(q)))
        return out

    @property
    def missed_corners(self) -> np.ndarray:
        """``(c, 2)`` corners of the region with no mesh vertex within 1e-9 of the region's extent."""
        return self._missed.copy()

    @property
    def size_deviation(self) -> float:
        """Largest ``|n / (L / h) - 1|`` over the sides (0 without a size)."""
        if not (self.size or self.field is not None) or not self.side_counts:
            return 0.0
        if self.field is not None:
            return max(abs(self.side_counts[s] / max(self._side_wanted(s), 1e-300) - 1.0) for s in self.side_counts)
        return max(abs(self.side_counts[s] / (self.side_lengths[s] / self.size) - 1.0) for s in self.side_counts)

    def sides_off_size(self, tol: float) -> list[str]:
        """Sides whose edge count ``n`` is off ``L / h`` by more than ``max(1, tol * L / h)``."""
        if not (self.size or self.field is not None):
            return []
        out = []
        for s, n in self.side_counts.items():
            want = self._side_wanted(s) if self.field is not None else self.side_lengths[s] / self.size
            if abs(n - want) > max(1.0, tol * want) + 1e-9:  # round-off: L / h = 0.99999... is one edge
                out.append(s)
        return out

    def long_edges(self, factor: float) -> int:
        """Edges longer than ``factor * size`` (the field at the edge's midpoint with a field; 0
        without a size)."""
        if self.field is not None:
            return int(np.sum(self._edge_lengths > factor * self._edge_targets))
        if not self.size:
            return 0
        return int(np.sum(self._edge_lengths > factor * self.size))

    def short_edges(self, factor: float) -> int:
        """With a size field: edges shorter than the field at their midpoint over ``factor`` (a
        graded mesh refined where the field does not ask for it); 0 without a field."""
        if self.field is None:
            return 0
        return int(np.sum(self._edge_lengths * factor < self._edge_targets))

    def size_conformity(self, quality: Quality = QUALITY) -> int:
        """The choice rule's size conformity (0: the size is met everywhere): the boundary
        stretches coarser than the size (:meth:`coarse_stretches`), edges longer than
        ``quality.long_edge`` sizes and, with a size field, shorter than the field over
        ``quality.short_edge`` (:meth:`short_edges`). For one size ``h`` a yes or no (0 or 1):
        between two meshes that both miss it somewhere, quality decides. With a size field their
        count: following the field is what was asked, so the mesh that misses it least wins."""
        k = ("size_conformity", quality.coarse_side, quality.long_edge, quality.short_edge)
        memo = self._memo
        if k not in memo:
            misses = (self.coarse_stretches(quality.coarse_side) + self.long_edges(quality.long_edge)
                      + self.short_edges(quality.short_edge))
            memo[k] = misses if self.field is not None else int(misses > 0)
        return memo[k]

    def size_fit(self, quality: Quality = QUALITY) -> int:
        """The choice rule's size fit count: boundary stretches off the size either way
        (:meth:`stretches_off_size`), edges longer than ``quality.long_edge`` sizes and, with a
        size field, shorter than the field over ``quality.short_edge``."""
        k = ("size_fit", quality.size_tol, quality.long_edge, quality.short_edge)
        memo = self._memo
        if k not in memo:
            memo[k] = (self.stretches_off_size(quality.size_tol) + self.long_edges(quality.long_edge)
                       + self.short_edges(quality.short_edge))
        return memo[k]

    def _side_wanted(self, name: str) -> float:
        """Edges the field wants along side ``name`` (its ``"side NAME"`` edges as meshed)."""
        e = self.line_sets.get(f"side {name}")
        return self._wanted(np.asarray(e, np.int64)) if e is not None and len(e) else 0.0

    @property
    def mean_edge_length(self) -> float:
        """Mean length of the mesh's edges, each counted once (user units)."""
        return float(self._edge_lengths.mean()) if self._edges.size else math.nan

    @property
    def valid(self) -> bool:
        """A mesh of the region: no inverted quad and every corner a vertex."""
        return self.inverted == 0 and self._missed.shape[0] == 0

    def warnings(self, quality: Quality = QUALITY) -> list[str]:
        """What is poor about this mesh, each with what the user can do (empty for a good mesh):
        min scaled Jacobian below the quality floor ``quality.good_sj`` (naming where the worst
        quad is), more irregular internal vertices than twice Euler's bound (at least 2), edges
        longer than ``quality.long_edge * size``. ``mesh`` prints them on stderr and
        ``summary.jsonl`` records them (``warnings``)."""
        out = []
        sj = self._sj_inverted[0]
        if sj.size and not sj.min() >= quality.good_sj:
            at = self.xy[self.quads[int(np.argmin(sj))]].mean(axis=0)
            out.append(f"poor mesh: min scaled Jacobian {sj.min():.3f} is below the quality floor {quality.good_sj:g} "
                       f"(worst quad at ({at[0]:.4g}, {at[1]:.4g})); try a smaller --size, or give the corners "
                       "explicitly (\"corners\" in the JSON file)")
        bound = self.irregular_bound
        if self.irregular.size > 2 * max(bound, 1):
            out.append(f"{self.irregular.size} irregular internal vertices, more than twice Euler's bound {bound}; "
                       "try a smaller --size, or give the corners explicitly")
        long = self.long_edges(quality.long_edge)
        if long and self.field is not None:
            r = self._edge_lengths / self._edge_targets
            out.append(f"{long} edges longer than {quality.long_edge:g} x the size field at their midpoints (longest "
                       f"{r.max():.2f} x); the region's patches are wider than its templates can fill there")
        elif long:
            out.append(f"{long} edges longer than {quality.long_edge:g} x the size {self.size:.4g} (longest "
                       f"{self._edge_lengths.max() / self.size:.2f} x); the region's patches are wider than its "
                       "templates can fill at this size")
        return out

    def summary(self, quality: Quality = QUALITY) -> dict:
        """JSON-ready figures (``warnings``: :meth:`warnings` under ``quality``)."""
        return {
            "chosen": self.chosen, "rule": self.rule, "runner_up": self.runner_up,
            "quads": int(self.quads.shape[0]), "vertices": int(self.xy.shape[0]), "patches": self.n_patches,
            "min_scaled_jacobian": self.min_scaled_jacobian, "mean_scaled_jacobian": self.mean_scaled_jacobian,
            "inverted": self.inverted, "corners": int(self.corners.shape[0]),
            "missed_corners": int(self.missed_corners.shape[0]), "area_ratio": self.area_ratio,
            "irregular": int(self.irregular.size), "irregular_bound": self.irregular_bound,
            "max_edge_ratio": self.max_edge_ratio, "mean_edge_length": self.mean_edge_length,
            "size": self.size, "size_deviation": self.size_deviation, "field_share": self.field_share,
            "side_counts": {k: int(v) for k, v in self.side_counts.items()}, "templates": list(self.templates),
            "warnings": self.warnings(quality),
        }
