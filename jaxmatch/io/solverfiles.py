"""Solver files of a :class:`~jaxmatch.io.elements.SolverMesh` through meshio: Gmsh MSH 4.1 / 2.2
(binary or ASCII), Abaqus ``.inp``, XDMF (``.xdmf`` + ``.h5``), Nastran ``.bdf``, Exodus II
``.e``/``.exo``, Medit ``.mesh``, and VTK for second-order and extruded meshes.

Each writer returns the notes of what the format could not hold (one line each; the caller
joins them into one warning). How each format stores the groups:

========  ==========================================================================================
format    groups
========  ==========================================================================================
msh       every region and group a named physical group (regions of the cells' dimension, groups
          one below); MSH 4.1 gets one entity per group (each with at least one of its nodes);
          periodic pairs in ``$Periodic`` (side ``b``'s entity slave of side ``a``'s, the
          translation as the affine map, the node pairs)
inp       every region and group an element set (``*ELSET``) and a node set (``*NSET``); every
          group also a ``*SURFACE`` (its elements' faces ``S1``..); names with ``_`` for other
          characters (``side 4-3`` -> ``side_4_3``); node groups (``periodic k a`` / ``b``) as
          ``*NSET, UNSORTED`` in their order
xdmf      ``NAME.xdmf`` the cells with cell tags ``patch`` (patch ``p`` -> ``p + 1``),
          ``NAME_facets.xdmf`` the facets with tags ``group`` (group ``j`` -> ``j + 1``): what
          dolfinx's ``read_meshtags`` reads; one tag per facet (the smallest group holding it)
e/exo     one element block per region (``eb_names``), every group a node set and a side set
          (``ss_names``, sides numbered as Exodus does); node groups (``periodic k a`` / ``b``) node
          sets in their order
mesh      references: cells ``p + 1``, facets as in XDMF (Medit stores no names)
bdf       regions as property ids (``PID = p + 1``); the groups are left out (no named sets)
vtu/vtk   cells and facets, cell data ``patch``, ``line_group``/``face_group`` (the group's index)
========  ==========================================================================================
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from pathlib import Path

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.files import atomic_folder, atomic_path
from jaxmatch.io.elements import SolverMesh

__all__ = ["ABAQUS_TYPES", "abaqus_name", "facet_partition", "write_solver_file"]

ABAQUS_TYPES = {"CPS4": "CPS8", "CPE4": "CPE8", "CAX4": "CAX8", "S4R": "S8R", "C3D8": None, "C3D8R": None, "C3D8I": None}
"""Abaqus element types of ``--element-type`` -> their 8-node (serendipity) type (None: 3D)."""
PLANE_TYPES = ("CPS4", "CPE4", "CAX4", "S4R")


def _meshio():
    import meshio  # imported lazily: only mesh output needs it

    return meshio


def _need(module: str, fmt: str, where: str):
    try:
        return __import__(module)
    except ImportError:
        raise InputError(f"writing {fmt} needs the Python package {module} (pip install 'jaxmatch[solver]')",
                         where) from None


def _points(sm: SolverMesh, dim: int) -> np.ndarray:
    p = np.asarray(sm.points, np.float64)
    return np.column_stack([p, np.zeros(p.shape[0])]) if p.shape[1] < dim else p[:, :dim]


def _region_order(sm: SolverMesh) -> np.ndarray:
    """The cells region by region (the QuadMesh's order where its patches are contiguous)."""
    return np.argsort(sm.region, kind="stable")


def abaqus_name(name: str) -> str:
    """An Abaqus set name: ``"side 4-3"`` -> ``"side_4_3"``."""
    return re.sub(r"[^A-Za-z0-9_]", "_", name)


def facet_partition(sm: SolverMesh) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``(facets (F, kf), markers (F,) group index + 1, groups with no facet of their own)``:
    every facet of any group once, tagged with the smallest group holding it."""
    names = list(sm.groups)
    seen, facets, marks = {}, [], []
    for j in sorted(range(len(names)), key=lambda j: (len(sm.groups[names[j]]), j)):
        for f in np.asarray(sm.groups[names[j]]).tolist():
            key = tuple(sorted(f))
            if key not in seen:
                seen[key] = len(facets)
                facets.append(f)
                marks.append(j + 1)
    used = set(marks)
    lost = [n for j, n in enumerate(names) if (j + 1) not in used and len(sm.groups[n])]
    kf = sm.groups[names[0]].shape[1] if names else 2
    return np.asarray(facets, np.int64).reshape(-1, kf), np.asarray(marks, np.int64), lost


def _marker_note(fmt: str, sm: SolverMesh, lost: list[str]) -> str:
    table = ", ".join(f"{n}={j + 1}" for j, n in enumerate(sm.groups))
    cells = ("'patch p' = p + 1" if all(n == f"patch {p}" for p, n in enumerate(sm.region_names))
             else ", ".join(f"{n}={r + 1}" for r, n in enumerate(sm.region_names)))
    note = f"{fmt} stores no group names: cell markers {cells}; facet markers {table}"
    if lost:
        note += f"; one marker per facet, so {', '.join(lost)} has none of its own (the union of others)"
    return note


# ---------------------------------------------------------------------------------------------
# Gmsh


def _gmsh_blocks(sm: SolverMesh):
    cells, tags, field, dims = [], [], {}, []
    order = _region_order(sm)
    for r, name in enumerate(sm.region_names):
        sel = order[sm.region[order] == r]
        if sel.size:
            cells.append((sm.cell_type, sm.cells[sel]))
            tags.append(np.full(sel.size, r + 1, np.int32))
            field[name] = np.array([r + 1, sm.dim])
            dims.append((sm.dim, r + 1))
    first = len(sm.region_names) + 1
    for j, (name, f) in enumerate(sm.groups.items()):
        if len(f):
            cells.append((sm.facet_type, np.asarray(f, np.int64)))
            tags.append(np.full(len(f), first + j, np.int32))
            field[name] = np.array([first + j, sm.dim - 1])
            dims.append((sm.dim - 1, first + j))
    first += len(sm.groups)
    points = {name: ids for name, ids in sm.node_groups.items() if not name.startswith("periodic ")}  # ($Periodic)
    for j, (name, ids) in enumerate(points.items()):
        cells.append(("vertex", np.asarray(ids, np.int64).reshape(-1, 1)))
        tags.append(np.full(len(ids), first + j, np.int32))
        field[name] = np.array([first + j, 0])
        dims.append((0, first + j))
    return cells, tags, field, dims


def _match(sets: list[list[int]]) -> list[int] | None:
    """One distinct member of each set (an augmenting-path bipartite matching; sets are the
    element blocks' nodes, few), or None when there is none."""
    owner: dict[int, int] = {}

    def place(b: int, seen: set) -> bool:
        for v in sets[b]:
            if v not in seen:
                seen.add(v)
                if v not in owner or place(owner[v], seen):
                    owner[v] = b
                    return True
        return False

    for b in range(len(sets)):
        if not place(b, set()):
            return None
    chosen = [0] * len(sets)
    for v, b in owner.items():
        chosen[b] = v
    return chosen


def _node_entities(n_points: int, cells, dims) -> np.ndarray | None:
    """``(N, 2)`` (dim, tag) of the entity each node is classified on: every entity gets one of
    its own nodes (a bipartite matching), the other nodes the first cell block holding them; None
    when there are more groups than nodes to give them (a mesh of a few quads)."""
    sets = [np.unique(c).tolist() for _, c in cells]
    # a node of few blocks first: the matching then rarely needs to re-route
    count = np.bincount(np.concatenate([np.asarray(s, np.int64) for s in sets]), minlength=n_points)
    match = _match([sorted(s, key=lambda v: count[v]) for s in sets])
    owner = np.zeros(n_points, np.int64)
    for b in range(len(cells) - 1, -1, -1):  # the first block holding a node wins
        owner[np.asarray(sets[b], np.int64)] = b
    if match is None:  # (meshio's MSH 4.1 lists only the entities that own a node)
        return None
    owner[np.asarray(match, np.int64)] = np.arange(len(cells))
    return np.asarray(dims, np.int64)[owner]


def _gmsh_periodic(sm: SolverMesh) -> list:
    """meshio's ``gmsh_periodic`` of ``sm.periodic``: per pair ``[1, (tag of b, tag of a), the 4 x 4
    affine map a -> b (row-major), (n, 2) node pairs (b, a)]``; a group's entity tag is its
    physical tag (:func:`_gmsh_blocks`)."""
    first = len(sm.region_names) + 1
    tag = {name: first + j for j, name in enumerate(sm.groups)}
    out = []
    for ga, gb, a, b, t in sm.periodic:
        affine = np.eye(4)
        affine[:2, 3] = t
        out.append([1, (tag[gb], tag[ga]), affine.ravel(), np.column_stack([b, a]).astype(np.int64)])
    return out


def write_gmsh(path: Path, sm: SolverMesh, version: str, binary: bool) -> list[str]:
    """MSH ``version`` (``"4.1"`` or ``"2.2"``) with every region and group a physical group."""
    meshio = _meshio()
    cells, tags, field, dims = _gmsh_blocks(sm)
    pts = _points(sm, 3)
    data = {"gmsh:physical": tags, "gmsh:geometrical": [t.copy() for t in tags]}
    notes = []
    point_data = {}
    if version == "4.1":
        owners = _node_entities(pts.shape[0], cells, dims)
        if owners is None:
            version = "2.2"
            notes.append(f"msh: written as MSH 2.2: {len(cells)} groups and only {pts.shape[0]} nodes, and MSH 4.1 "
                         "classifies every group on a node of its own")
        else:
            first = len(sm.region_names) + 1
            tag = {name: first + j for j, name in enumerate(sm.groups)}
            for ga, gb, a, b, _ in sm.periodic:  # a periodic side's inner nodes on its own curve, as gmsh classifies them
                owners[np.asarray(a[1:-1], np.int64)] = (sm.dim - 1, tag[ga])
                owners[np.asarray(b[1:-1], np.int64)] = (sm.dim - 1, tag[gb])
            point_data = {"gmsh:dim_tags": owners}
    mesh = meshio.Mesh(pts, cells, point_data=point_data, cell_data=data, field_data=field,
                       gmsh_periodic=_gmsh_periodic(sm) or None)
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="gmsh" if version == "4.1" else "gmsh22", binary=binary)
    return notes + (["msh: no scaled_jacobian cell data (meshio 5.3 cannot read $ElementData back beside several "
                     "element blocks)"] if "scaled_jacobian" in sm.cell_data else [])


# ---------------------------------------------------------------------------------------------
# VTK (second order, extruded)


def write_vtk(path: Path, sm: SolverMesh, fmt: str) -> list[str]:
    meshio = _meshio()
    facets = [np.asarray(f, np.int64) for f in sm.groups.values() if len(f)]
    gid = [np.full(len(f), j, np.int64) for j, f in enumerate(sm.groups.values()) if len(f)]
    cells = [(sm.cell_type, sm.cells)]
    data = {k: [np.asarray(v)] for k, v in sm.cell_data.items()}
    if facets:
        every = np.concatenate(facets)
        cells.append((sm.facet_type, every))
        for k, v in sm.cell_data.items():
            v = np.asarray(v)
            data[k].append(np.full(every.shape[0], np.nan if v.dtype.kind == "f" else -1, dtype=v.dtype))
        data["line_group" if sm.dim == 2 else "face_group"] = [np.full(len(sm.cells), -1, np.int64), np.concatenate(gid)]
    mesh = meshio.Mesh(_points(sm, 3), cells, cell_data=data)
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format=fmt, **({"binary": True} if fmt == "vtk" else {}))
    return []


# ---------------------------------------------------------------------------------------------
# Abaqus


def abaqus_type(sm: SolverMesh, element_type: str | None) -> str:
    """The Abaqus element type written for ``sm`` (``element_type`` as given, or the default)."""
    et = (element_type or ("C3D8" if sm.dim == 3 else "CPS4")).upper()
    if et not in ABAQUS_TYPES:
        raise InputError(f"expected one of {', '.join(ABAQUS_TYPES)}, got {element_type!r}", "--element-type")
    if sm.dim == 3:
        if et in PLANE_TYPES:
            raise InputError(f"{et} is a plane or shell element; hexahedra are C3D8, C3D8R or C3D8I", "--element-type")
        if sm.order == 2:
            raise InputError("Abaqus .inp takes first-order hexahedra here (C3D27's node order is not checked); write "
                             "hex27 to .msh, .vtu or .vtk", "--order")
        return et
    if et not in PLANE_TYPES:
        raise InputError(f"{et} is a brick element; use it with --extrude", "--element-type")
    if sm.cell_type == "quad9":
        raise InputError(f"Abaqus has no 9-node {et[:3]} element: add --serendipity ({ABAQUS_TYPES[et]})", "--order")
    if et == "CAX4" and float(np.min(sm.points[:, 0])) < -1e-12:
        raise InputError(f"CAX elements need x >= 0 (x is the radius); the mesh reaches x = {np.min(sm.points[:, 0]):g}",
                         "--element-type")
    return ABAQUS_TYPES[et] if sm.order == 2 else et


ABAQUS_SIDES_3D = {0: 3, 1: 4, 2: 5, 3: 6, 4: 1, 5: 2}
"""Local side (module :mod:`jaxmatch.io.elements`) -> Abaqus face ``S`` number of a C3D8."""


def write_abaqus(path: Path, sm: SolverMesh, element_type: str | None) -> list[str]:
    meshio = _meshio()
    et = abaqus_type(sm, element_type)
    dim = 3 if (sm.dim == 3 or et.startswith("S")) else 2
    cell_sets, point_sets = {}, {}
    for r, name in enumerate(sm.region_names):
        sel = np.flatnonzero(sm.region == r)
        cell_sets[abaqus_name(name)] = [sel]
        point_sets[abaqus_name(name)] = np.unique(sm.cells[sel])
    surfaces = []
    for name, f in sm.groups.items():
        if not len(f):
            continue
        own = np.asarray(sm.owners[name])
        key = abaqus_name(name)
        cell_sets[key] = [np.unique(own[:, 0])]
        point_sets[key] = np.unique(f)
        lines = [f"*SURFACE, TYPE=ELEMENT, NAME={key}"]
        for side in np.unique(own[:, 1]).tolist():
            s = ABAQUS_SIDES_3D[side] if sm.dim == 3 else side + 1
            ids = (own[own[:, 1] == side, 0] + 1).tolist()
            surfaces.append(f"*ELSET, ELSET=_{key}_S{s}, INTERNAL\n" +
                            ",\n".join(",".join(map(str, ids[i:i + 8])) for i in range(0, len(ids), 8)))
            lines.append(f"_{key}_S{s}, S{s}")
        surfaces.append("\n".join(lines))
    for name, ids in sm.node_groups.items():  # in their order (Abaqus sorts a set unless it is UNSORTED)
        ids = (np.asarray(ids, np.int64) + 1).tolist()
        surfaces.append(f"*NSET, NSET={abaqus_name(name)}, UNSORTED\n" +
                        ",\n".join(",".join(map(str, ids[i:i + 8])) for i in range(0, len(ids), 8)))
    mesh = meshio.Mesh(_points(sm, dim), [(sm.cell_type, sm.cells)], cell_sets=cell_sets, point_sets=point_sets)
    mesh.cells[0].type = et  # written as given (translate_cell_names=False); meshio's Mesh knows its own names only
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="abaqus", translate_cell_names=False)
        with open(tmp, "a", encoding="utf-8") as fh:
            fh.write("".join(s + "\n" for s in surfaces))
    return ["inp: no cell data (scaled_jacobian, patch: the patches are element sets)"]


# ---------------------------------------------------------------------------------------------
# XDMF, Exodus, Medit, Nastran


def write_xdmf(path: Path, sm: SolverMesh) -> list[str]:
    meshio = _meshio()
    _need("h5py", "XDMF", str(path))
    if sm.cell_type == "hexahedron27":
        raise InputError("XDMF takes hexahedra of order 1 here (Hexahedron_27's node order is not checked)", "--order")
    facets, marks, lost = facet_partition(sm)
    pts = _points(sm, sm.dim)
    facet_path = path.with_name(path.stem + "_facets.xdmf")

    finals = [path.with_suffix(".h5"), path]
    if len(facets):
        finals = [facet_path.with_suffix(".h5"), facet_path] + finals
    with atomic_folder(finals) as folder:
        cells = meshio.Mesh(pts, [(sm.cell_type, sm.cells)], cell_data={"patch": [sm.region.astype(np.int32) + 1]})
        meshio.write(folder / path.name, cells, file_format="xdmf")
        if len(facets):
            fm = meshio.Mesh(pts, [(sm.facet_type, facets)], cell_data={"group": [marks.astype(np.int32)]})
            meshio.write(folder / facet_path.name, fm, file_format="xdmf")
    return [_marker_note("xdmf", sm, lost) + f" (in {facet_path.name})"]


EXODUS_SIDES_3D = {0: 1, 1: 2, 2: 3, 3: 4, 4: 5, 5: 6}
"""Local side -> Exodus side number of a HEX8 (the quad's sides, bottom, top)."""


def write_exodus(path: Path, sm: SolverMesh) -> list[str]:
    meshio = _meshio()
    netCDF4 = _need("netCDF4", "Exodus II", str(path))
    if sm.cell_type == "hexahedron27":
        raise InputError("Exodus takes hexahedra of order 1 here (HEX27's node order is not checked)", "--order")
    order = _region_order(sm)
    element_id = np.empty(len(order), np.int64)
    element_id[order] = np.arange(1, len(order) + 1)
    blocks = [(sm.cell_type, sm.cells[order[sm.region[order] == r]]) for r in range(len(sm.region_names))]
    keep = [i for i, b in enumerate(blocks) if len(b[1])]
    point_sets = {name: np.unique(f).astype(np.int64) for name, f in sm.groups.items() if len(f)}
    point_sets.update({name: np.asarray(ids, np.int64) for name, ids in sm.node_groups.items()})  # in their order
    mesh = meshio.Mesh(_points(sm, sm.dim), [blocks[i] for i in keep], point_sets=point_sets)
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="exodus")
        with netCDF4.Dataset(tmp, "a") as nc:
            _exodus_names(nc, "eb_names", "num_el_blk", [sm.region_names[i] for i in keep])
            sets = [(n, np.asarray(sm.owners[n])) for n, f in sm.groups.items() if len(f)]
            if sets:
                nc.createDimension("num_side_sets", len(sets))
                nc.createVariable("ss_status", "i4", ("num_side_sets",))[:] = 1
                nc.createVariable("ss_prop1", "i4", ("num_side_sets",))[:] = np.arange(1, len(sets) + 1)
                nc.variables["ss_prop1"].setncattr("name", "ID")
                _exodus_names(nc, "ss_names", "num_side_sets", [n for n, _ in sets])
                for k, (_, own) in enumerate(sets, 1):
                    nc.createDimension(f"num_side_ss{k}", len(own))
                    nc.createVariable(f"elem_ss{k}", "i4", (f"num_side_ss{k}",))[:] = element_id[own[:, 0]]
                    side = [EXODUS_SIDES_3D[s] for s in own[:, 1].tolist()] if sm.dim == 3 else own[:, 1] + 1
                    nc.createVariable(f"side_ss{k}", "i4", (f"num_side_ss{k}",))[:] = np.asarray(side)
    return ["exodus: no cell data (scaled_jacobian; the patches are element blocks)"]


def _exodus_names(nc, var: str, dim: str, names) -> None:
    v = nc.createVariable(var, "S1", (dim, "len_string"))
    v.set_auto_mask(False)
    arr = np.zeros((len(names), len(nc.dimensions["len_string"])), "S1")
    for i, n in enumerate(names):
        b = n.encode()[: arr.shape[1] - 1]
        arr[i, : len(b)] = np.frombuffer(b, "S1")
    v[:] = arr


def write_medit(path: Path, sm: SolverMesh) -> list[str]:
    meshio = _meshio()
    if sm.order != 1:
        raise InputError("Medit files hold first-order elements only (meshio)", "--order")
    facets, marks, lost = facet_partition(sm)
    cells = [(sm.cell_type, sm.cells)]
    refs = [sm.region.astype(np.int64) + 1]
    if len(facets):
        cells.append((sm.facet_type, facets))
        refs.append(marks)
    mesh = meshio.Mesh(_points(sm, sm.dim), cells, cell_data={"medit:ref": refs})
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="medit")
    return [_marker_note("mesh", sm, lost)]


def write_nastran(path: Path, sm: SolverMesh) -> list[str]:
    meshio = _meshio()
    if sm.cell_type in ("quad9", "hexahedron27"):
        raise InputError("Nastran .bdf: second order as CQUAD8 only: add --serendipity (and no --extrude)", "--order")
    mesh = meshio.Mesh(_points(sm, 3), [(sm.cell_type, sm.cells)], cell_data={"nastran:ref": [sm.region + 1]})
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="nastran")
    left = [n for n, f in sm.groups.items() if len(f)]
    return [f"bdf: patches as property ids (PID = patch + 1); no named sets in bulk data, so the groups "
            f"{', '.join(left)} were left out"] if left else []


def write_solver_file(path: Path, sm: SolverMesh, fmt: str, *, msh_version: str = "4.1", binary: bool = True,
                      element_type: str | None = None) -> list[str]:
    """Write ``sm`` to ``path`` in format ``fmt`` (a registered mesh format's name); the notes."""
    periodic = [n for n in sm.node_groups if n.startswith("periodic ")]
    lost = [] if fmt in ("abaqus", "exodus") or not sm.node_groups else \
        (["msh: the periodic pairs are in $Periodic (no node groups)"] if periodic else []) if fmt == "gmsh" else \
        [f"{fmt}: no node groups ({', '.join(sm.node_groups)} left out; msh, inp and exo hold them)"]
    if fmt == "gmsh":
        return write_gmsh(path, sm, msh_version, binary) + lost
    if fmt in ("vtu", "vtk"):
        return write_vtk(path, sm, fmt) + lost
    writers = {"abaqus": lambda: write_abaqus(path, sm, element_type), "xdmf": lambda: write_xdmf(path, sm),
               "exodus": lambda: write_exodus(path, sm), "medit": lambda: write_medit(path, sm),
               "nastran": lambda: write_nastran(path, sm)}
    if fmt not in writers:
        raise InputError(f"{fmt} files hold first-order quads only (no --order 2, no --extrude)", str(path))
    return writers[fmt]() + lost
