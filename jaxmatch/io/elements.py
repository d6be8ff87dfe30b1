"""The elements a solver file holds, made from a :class:`~jaxmatch.meshing.result.QuadMesh`:
first-order quads, second-order quads (``quad9``, or ``quad8`` serendipity) and hexahedra extruded
from either (``hexahedron``, ``hexahedron27``), with every group of the mesh carried along.

One type, :class:`SolverMesh`, is what every format writer of :mod:`jaxmatch.io.solverfiles`
reads: the cells of one type with the region (patch) of each, and named facet groups (lines in
2D, quads in 3D) with the cell and local side that owns each facet (for side sets and surfaces).

Node orders are meshio's (the VTK orders): ``quad8``/``quad9`` corners, then the mid-side nodes of
sides 0-1, 1-2, 2-3, 3-0, then (quad9) the centre; ``line3`` the two ends, then the middle;
``hexahedron`` the bottom quad then the top one; ``hexahedron27`` the 8 corners, the 12 edge
mid-points (bottom 4, top 4, vertical 4), the 6 face centres (-x, +x, -y, +y, -z, +z of the
reference cube) and the centre. Local sides: ``0..3`` the quad's sides ``i -> i+1``; for
hexahedra also ``4`` the bottom and ``5`` the top.

Second order: the mid-side node of an outline edge lies on the curve through the outline's
mesh vertices (a cubic through the edge's ends and their neighbours along the same stretch of
the outline, a stretch running from corner to corner; the chord's mid-point where the four
points are collinear); an interior edge's mid-side node is its mid-point; a quad9's centre is
the image of the reference centre under the serendipity map of its 8 nodes. An element whose
Jacobian determinant is not positive at every sample point keeps straight sides instead
(counted in :attr:`SolverMesh.notes`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping

import numpy as np

from jaxmatch.catalogue.mesh import boundary_loops
from jaxmatch.errors import InputError

if TYPE_CHECKING:  # pragma: no cover - the type only (io stays below meshing)
    from jaxmatch.meshing.result import QuadMesh

__all__ = ["SolverMesh", "jacobian_dets", "solver_mesh"]

FACET_TYPE = {"quad": "line", "quad8": "line3", "quad9": "line3", "hexahedron": "quad", "hexahedron27": "quad9"}
"""Cell type -> the type of its facets."""


@dataclass(frozen=True, eq=False)
class SolverMesh:
    """The elements written to a solver file.

    points: ``(N, dim) float64``; cell_type: meshio name (``quad``, ``quad8``, ``quad9``,
    ``hexahedron``, ``hexahedron27``); cells: ``(C, k) int64`` node ids; region: ``(C,) int64``
    the patch of each cell, named ``region_names[region]``; groups: facet group name ->
    ``(F, kf) int64`` facets of :attr:`facet_type`, each oriented outwards from its owner;
    owners: the same names -> ``(F, 2) int64`` (owning cell, local side); cell_data: name ->
    ``(C,)`` per cell; notes: what was changed or left out on the way (one line each);
    node_groups: name -> ``(N,) int64`` node ids in their order (an assembly's embedded points,
    ``"point k"``; the periodic pairs' ``periodic k a`` / ``periodic k b``); periodic: per pair
    ``(line group a, line group b, (n,) nodes a, (n,) nodes b, (2,) translation a -> b)`` (``.msh``:
    ``$Periodic``).
    """

    points: np.ndarray
    cell_type: str
    cells: np.ndarray
    region: np.ndarray
    region_names: tuple[str, ...]
    groups: Mapping[str, np.ndarray]
    owners: Mapping[str, np.ndarray]
    cell_data: Mapping[str, np.ndarray] = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    node_groups: Mapping[str, np.ndarray] = field(default_factory=dict)
    periodic: tuple = ()

    @property
    def dim(self) -> int:
        return 3 if self.cell_type.startswith("hexahedron") else 2

    @property
    def facet_type(self) -> str:
        return FACET_TYPE[self.cell_type]

    @property
    def order(self) -> int:
        return 1 if self.cell_type in ("quad", "hexahedron") else 2


# ---------------------------------------------------------------------------------------------
# first order: the QuadMesh as it is


def _sides(quads: np.ndarray) -> np.ndarray:
    """``(Q, 4, 2)`` the quads' sides ``i -> i+1``."""
    return np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1)


def _owners(quads: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``(E, 2)`` (quad, local side) of each undirected edge ``(E, 2)`` (the first quad that has it)."""
    s = _sides(quads).reshape(-1, 2)
    key = {}
    for i, (a, b) in enumerate(np.sort(s, axis=1).tolist()):
        key.setdefault((a, b), i)
    try:
        idx = np.array([key[(min(a, b), max(a, b))] for a, b in edges.tolist()], np.int64).reshape(-1)
    except KeyError as err:
        raise InputError(f"a line group's edge {err.args[0]} is no side of any quad") from None
    return np.stack([idx // 4, idx % 4], axis=1)


def first_order(mesh: "QuadMesh") -> SolverMesh:
    """The QuadMesh's quads, patches and line groups (each edge oriented as its quad's side)."""
    quads = np.asarray(mesh.quads, np.int64)
    patch = np.asarray(mesh.patch, np.int64)
    names = tuple(getattr(mesh, "regions", ())) or (tuple(f"patch {p}" for p in range(int(patch.max()) + 1))
                                                     if patch.size else ())
    groups, owners = {}, {}
    for name, e in mesh.line_sets.items():
        e = np.asarray(e, np.int64).reshape(-1, 2)
        own = _owners(quads, e)
        groups[name] = _sides(quads)[own[:, 0], own[:, 1]]
        owners[name] = own
    sj = np.asarray(mesh.scaled_jacobian, np.float64)
    xy = np.asarray(mesh.xy, np.float64)
    nodes = {k: np.asarray(v, np.int64) for k, v in getattr(mesh, "point_sets", {}).items()}
    return SolverMesh(xy, "quad", quads, patch, names, groups, owners, {"patch": patch, "scaled_jacobian": sj},
                      node_groups=nodes, periodic=_periodic_pairs(mesh.line_sets, nodes, xy))


def _periodic_pairs(line_sets, nodes, xy: np.ndarray) -> tuple:
    """:attr:`SolverMesh.periodic` from the node groups ``periodic k a`` / ``periodic k b`` and the
    side groups holding exactly their nodes."""
    out = []
    sides = {name: set(np.unique(np.asarray(e, np.int64)).tolist()) for name, e in line_sets.items()
             if name.startswith("side ") or (name.startswith("hole ") and " side " in name)}
    k = 1
    while f"periodic {k} a" in nodes:
        a, b = nodes[f"periodic {k} a"], nodes[f"periodic {k} b"]
        ga = next((n for n, v in sides.items() if v == set(a.tolist())), None)
        gb = next((n for n, v in sides.items() if v == set(b.tolist())), None)
        if ga is not None and gb is not None:
            out.append((ga, gb, a, b, xy[b[0]] - xy[a[0]]))
        k += 1
    return tuple(out)


# ---------------------------------------------------------------------------------------------
# second order


def _shape_derivatives(cell_type: str, r: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``(P, k, 2)`` d/dr, d/ds of the ``k`` shape functions of ``quad8``/``quad9`` at ``(r, s)``
    on the reference square ``[-1, 1]^2`` (node order of the module docstring)."""
    ref = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1], [0, -1], [1, 0], [0, 1], [-1, 0], [0, 0]], float)
    r, s = np.asarray(r, float)[:, None], np.asarray(s, float)[:, None]
    if cell_type == "quad9":
        def l1(x, xi):  # 1D quadratic Lagrange basis at nodes -1, 0, 1: value and derivative
            return (np.where(xi == -1, 0.5 * x * (x - 1), np.where(xi == 1, 0.5 * x * (x + 1), 1 - x * x)),
                    np.where(xi == -1, x - 0.5, np.where(xi == 1, x + 0.5, -2 * x)))
        lr, dlr = l1(r, ref[None, :, 0])
        ls, dls = l1(s, ref[None, :, 1])
        return np.stack([dlr * ls, lr * dls], axis=-1)
    ri, si = ref[None, :8, 0], ref[None, :8, 1]
    corner = (ri != 0) & (si != 0)
    dr_c = 0.25 * ri * (1 + s * si) * (2 * r * ri + s * si)
    ds_c = 0.25 * si * (1 + r * ri) * (r * ri + 2 * s * si)
    dr_m = np.where(ri == 0, -r * (1 + s * si), 0.5 * ri * (1 - s * s))
    ds_m = np.where(si == 0, -s * (1 + r * ri), 0.5 * si * (1 - r * r))
    return np.stack([np.where(corner, dr_c, dr_m), np.where(corner, ds_c, ds_m)], axis=-1)


def jacobian_dets(points: np.ndarray, cells: np.ndarray, cell_type: str, n: int = 5) -> np.ndarray:
    """``(C, n * n)`` Jacobian determinants of 2D ``quad8``/``quad9`` cells at an ``n x n`` grid of
    the reference square, its corners and sides included (``n >= 2``)."""
    t = np.linspace(-1.0, 1.0, n)
    r, s = (g.ravel() for g in np.meshgrid(t, t))
    d = _shape_derivatives(cell_type, r, s)  # (P, k, 2)
    x = np.asarray(points, float)[:, :2][np.asarray(cells)]  # (C, k, 2)
    J = np.einsum("pkd,ckx->cpxd", d, x)  # (C, P, 2 x, 2 d)
    return J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]


def _outline_midpoints(xy: np.ndarray, loops: list[np.ndarray], corner_ids: set) -> dict:
    """``{(a, b): point}`` the mid-side point of each outline edge on the curve through the
    outline's vertices (see the module docstring)."""
    out = {}
    for loop in loops:
        n = len(loop)
        for i in range(n):
            a, b = int(loop[i]), int(loop[(i + 1) % n])
            pa, pb = xy[a], xy[b]
            # neighbours along the same stretch: none across a corner
            prev = None if (a in corner_ids or n < 3) else xy[int(loop[i - 1])]
            nxt = None if (b in corner_ids or n < 3) else xy[int(loop[(i + 2) % n])]
            out[(a, b)] = _curve_mid(prev, pa, pb, nxt)
    return out


def _curve_mid(p, a, b, n) -> np.ndarray:
    """The mid-point (in chord length) of the interpolating cubic (or quadratic with one
    neighbour) through ``p, a, b, n`` between ``a`` and ``b``; the chord's mid-point when the
    points are collinear or there is no neighbour."""
    pts = [q for q in (p, a, b, n) if q is not None]
    mid = 0.5 * (a + b)
    if len(pts) < 3:
        return mid
    P = np.asarray(pts, float)
    chord = np.linalg.norm(b - a)
    u = (b - a) / chord
    off = np.abs((P - a) @ np.array([-u[1], u[0]]))
    if off.max() <= 1e-12 * chord:
        return mid
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    ia = 1 if p is not None else 0
    tm = 0.5 * (t[ia] + t[ia + 1])
    # Lagrange interpolation through the points at their chord-length parameters
    w = np.ones(len(t))
    for j in range(len(t)):
        for k in range(len(t)):
            if k != j:
                w[j] *= (tm - t[k]) / (t[j] - t[k])
    return w @ P


def second_order(mesh: "QuadMesh", *, serendipity: bool = False) -> SolverMesh:
    """The mesh with ``quad9`` cells (``quad8`` with ``serendipity``) and ``line3`` groups."""
    base = first_order(mesh)
    xy, quads = base.points, base.cells
    V, Q = xy.shape[0], quads.shape[0]
    sides = _sides(quads)  # (Q, 4, 2)
    uniq, inv = np.unique(np.sort(sides.reshape(-1, 2), axis=1), axis=0, return_inverse=True)
    side_edge = inv.reshape(Q, 4)
    straight = 0.5 * (xy[uniq[:, 0]] + xy[uniq[:, 1]])
    corner_ids = set()
    if np.asarray(mesh.corners).size:
        ext = float(np.ptp(xy, axis=0).max()) or 1.0
        c = np.asarray(mesh.corners, float).reshape(-1, 2)
        d = np.linalg.norm(c[:, None, :] - xy[None, :, :], axis=2)
        corner_ids = {int(i) for i in np.argmin(d, axis=1)[d.min(axis=1) <= 1e-9 * ext]}
    curved = straight.copy()
    index = {(int(a), int(b)): k for k, (a, b) in enumerate(uniq.tolist())}
    for (a, b), p in _outline_midpoints(xy, boundary_loops(quads), corner_ids).items():
        curved[index[(min(a, b), max(a, b))]] = p
    cell_type = "quad8" if serendipity else "quad9"

    def build(mids):
        pts = [xy, mids]
        cells = np.concatenate([quads, V + side_edge], axis=1)
        if not serendipity:
            centre = 0.5 * mids[side_edge].sum(axis=1) - 0.25 * xy[quads].sum(axis=1)
            pts.append(centre)
            cells = np.concatenate([cells, (V + len(mids) + np.arange(Q))[:, None]], axis=1)
        return np.concatenate(pts), cells

    points, cells = build(curved)
    bad = np.flatnonzero((jacobian_dets(points, cells, cell_type) <= 0).any(axis=1))
    notes = []
    if bad.size:  # those quads keep straight sides (the bilinear map of a valid quad has a positive Jacobian)
        fix = np.unique(side_edge[bad])
        curved[fix] = straight[fix]
        points, cells = build(curved)
        notes.append(f"--order 2: {bad.size} element(s) would have a non-positive Jacobian with mid-side nodes on the "
                     "curve; their sides were kept straight")
    groups = {k: np.concatenate([g, (V + side_edge[o[:, 0], o[:, 1]])[:, None]], axis=1)
              for (k, g), o in zip(base.groups.items(), base.owners.values())}
    return SolverMesh(points, cell_type, cells, base.region, base.region_names, groups, dict(base.owners),
                      dict(base.cell_data), tuple(notes))


# ---------------------------------------------------------------------------------------------
# extrusion


def layer_heights(dz: float, layers: int, grading: float = 1.0) -> np.ndarray:
    """``(layers + 1,)`` z of the layer boundaries from 0 to ``dz``; each layer ``grading **
    (1 / (layers - 1))`` times as thick as the one below (the top one ``grading`` times the bottom)."""
    if layers == 1 or grading == 1.0:
        return np.linspace(0.0, dz, layers + 1)
    q = grading ** (1.0 / (layers - 1))
    t = q ** np.arange(layers)
    return np.concatenate([[0.0], np.cumsum(t)]) / t.sum() * dz


def extrude(base: SolverMesh, dz: float, layers: int, grading: float = 1.0) -> SolverMesh:
    """``base`` (quad or quad9, 2D) swept along z over ``dz`` in ``layers`` layers: hexahedra
    (hexahedron27 from quad9); groups ``bottom``, ``top``, every line group as the faces it
    sweeps; regions as before (volume groups)."""
    if base.cell_type == "quad8":
        raise InputError("hexahedra from serendipity quads are not made (hex20); use --order 2 without --serendipity",
                         "--serendipity")
    order = base.order
    z = layer_heights(dz, layers, grading)
    if order == 2:  # the mid-level of every layer too
        z = np.sort(np.concatenate([z, 0.5 * (z[1:] + z[:-1])]))
    xy = base.points[:, :2]
    N = xy.shape[0]
    points = np.concatenate([np.column_stack([xy, np.full(N, zk)]) for zk in z])
    step = order  # node levels per layer
    q = base.cells
    C = q.shape[0]
    cells, region = [], []
    for k in range(layers):
        lo, mid, hi = k * step * N, (k * step + 1) * N, (k + 1) * step * N
        if order == 1:
            cells.append(np.concatenate([q + lo, q + hi], axis=1))
        else:
            c, m, ctr = q[:, :4], q[:, 4:8], q[:, 8:9]
            faces = np.stack([m[:, 3], m[:, 1], m[:, 0], m[:, 2]], axis=1) + mid  # -x, +x, -y, +y
            cells.append(np.concatenate([c + lo, c + hi, m + lo, m + hi, c + mid, faces, ctr + lo, ctr + hi,
                                         ctr + mid], axis=1))
        region.append(base.region)
    cells = np.concatenate(cells)
    region = np.concatenate(region)
    top = layers * step * N
    groups, owners = {}, {}
    if order == 1:
        groups["bottom"], groups["top"] = q[:, ::-1].copy(), q + top
    else:
        rev = q[:, [0, 3, 2, 1, 7, 6, 5, 4, 8]]  # the same quad9 seen from below
        groups["bottom"], groups["top"] = rev, q + top
    owners["bottom"] = np.stack([np.arange(C), np.full(C, 4)], axis=1)
    owners["top"] = np.stack([(layers - 1) * C + np.arange(C), np.full(C, 5)], axis=1)
    for name, lines in base.groups.items():
        own = base.owners[name]
        faces, fo = [], []
        for k in range(layers):
            lo, mid, hi = k * step * N, (k * step + 1) * N, (k + 1) * step * N
            a, b = lines[:, 0], lines[:, 1]
            if order == 1:
                faces.append(np.stack([a + lo, b + lo, b + hi, a + hi], axis=1))
            else:
                m = lines[:, 2]
                faces.append(np.stack([a + lo, b + lo, b + hi, a + hi, m + lo, b + mid, m + hi, a + mid, m + mid], axis=1))
            fo.append(np.stack([k * C + own[:, 0], own[:, 1]], axis=1))
        groups[name], owners[name] = np.concatenate(faces), np.concatenate(fo)
    cell_type = "hexahedron" if order == 1 else "hexahedron27"
    data = {"patch": region}
    notes = list(base.notes)
    notes.append("hexahedra: no scaled_jacobian cell data (the quads' values are not the hexahedra's)")
    return SolverMesh(points, cell_type, cells, region, base.region_names, groups, owners, data, tuple(notes))


def solver_mesh(mesh: "QuadMesh", *, order: int = 1, serendipity: bool = False, extrude_dz: float | None = None,
                layers: int = 1, grading: float = 1.0) -> SolverMesh:
    """The :class:`SolverMesh` of a QuadMesh: first or second ``order``, extruded over
    ``extrude_dz`` in ``layers`` layers (``grading``: the top layer's thickness over the bottom
    one's) when given."""
    base = second_order(mesh, serendipity=serendipity) if order == 2 else first_order(mesh)
    out = base if extrude_dz is None else extrude(base, extrude_dz, layers, grading)
    if getattr(mesh, "point_sets", None) and (order == 2 or extrude_dz is not None):
        out = dataclasses.replace(out, node_groups={}, periodic=(), notes=out.notes + (
            f"the node groups ({', '.join(mesh.point_sets)}) are written with first-order quads only: left out",))
    return out
