"""Write a :class:`~jaxmatch.meshing.result.QuadMesh` to a file (meshio formats and a small JSON format).

:func:`write_mesh` is the front door: first-order quads to the formats below are written here
(:func:`write_quads`); MSH 4.1 (the default for ``.msh``), the solver formats (``.inp``,
``.xdmf``, ``.bdf``, ``.e``/``.exo``, ``.mesh``), second order and extrusion go through
:mod:`jaxmatch.io.elements` and :mod:`jaxmatch.io.solverfiles` (docs/output.md).

The format comes from the file suffix (case-insensitive):

=========  ==============================================  ==========================
suffix     format                                          keeps ``scaled_jacobian``
=========  ==============================================  ==========================
``.vtk``   legacy VTK, binary (meshio)                     yes (cell data)
``.vtu``   VTK XML unstructured grid (meshio)              yes (cell data)
``.obj``   Wavefront OBJ (meshio)                          no
``.msh``   Gmsh 2.2, binary (meshio; :func:`write_mesh`    no (with line groups)
           writes MSH 4.1 by default, through
           :mod:`jaxmatch.io.solverfiles`)
``.json``  ``{"points": [[x, y], ...], "quads": [[a, b, c, d], ...],
           "scaled_jacobian": [...]}`` (written here)      yes
=========  ==============================================  ==========================

Points are the mesh's ``xy`` in the user's coordinates; meshio formats get them padded
to 3D with ``z = 0``. Quads are 0-based vertex indices, counter-clockwise (OBJ and Gmsh files
store them 1-based, as their formats require; meshio converts back). Gmsh is written binary
because meshio 5.3 writes ASCII ``$ElementData`` values that it cannot read back under
numpy 2; every element gets physical and geometrical tag 1.

Every mesh (:func:`write_mesh`) gets the cell data ``patch`` (the patch id of every quad) and
named groups: quad groups (each quad in one) and line groups (boundary edges, e.g. the outer
boundary and each input side; an edge may be in several). In ``.msh`` every group is a physical group with its name in ``$PhysicalNames``
(quads: dimension 2, group ``i`` has physical tag ``i + 1``; lines: dimension 1, 2-node line
elements); an element's geometrical tag equals its physical tag, and a line in several groups
is written once per group (MSH 2 gives an element one physical tag, and gmsh itself writes such
elements this way). A ``.msh`` file with line groups carries no ``$ElementData`` (cell data):
meshio 5.3.5 splits element data by the wrong lengths when reading a file with more than one
cell block and fails, so the quad groups (physical tags) carry e.g. the patch of each quad. ``.vtk``/``.vtu``
get the lines as a second cell block with cell data ``line_group`` (index into the names, in
the order given) and ``-1``/NaN for the quads' cell data; ``.json`` gets ``"groups": {name:
[[a, b], ...]}`` and ``"quad_groups"``; ``.obj`` keeps only the quads.

Every file is written atomically (:mod:`jaxmatch.files`): a failed write leaves no file and
no temporary behind, and keeps any previous file at ``path`` intact.
"""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, NamedTuple, Sequence

import numpy as np

from jaxmatch.errors import InputError, InputWarning
from jaxmatch.files import atomic_open, atomic_path
from jaxmatch.io import registry
from jaxmatch.io.elements import solver_mesh
from jaxmatch.io.output import MeshOutput
from jaxmatch.io.solverfiles import write_solver_file

if TYPE_CHECKING:  # pragma: no cover - the type only (io stays below meshing)
    from jaxmatch.meshing.result import QuadMesh

__all__ = ["LineGroup", "MESH_FORMATS", "QUADMESH_FIELDS", "mesh_format", "mesh_groups", "read_json_mesh", "write_mesh",
           "write_quads"]

for _name, _suffixes in (("vtk", (".vtk",)), ("vtu", (".vtu",)), ("obj", (".obj",)), ("gmsh", (".msh",)),
                         ("json", (".json",)), ("abaqus", (".inp",)), ("xdmf", (".xdmf",)), ("nastran", (".bdf", ".nas")),
                         ("exodus", (".e", ".exo")), ("medit", (".mesh",))):
    registry.register_format(_name, "mesh", _suffixes, writer=_name)

MESH_FORMATS: dict[str, str] = registry.suffixes("mesh")
"""File suffix -> format name (meshio's name, or ``"json"``), from :mod:`jaxmatch.io.registry`."""

LEGACY = ("vtk", "vtu", "obj", "gmsh", "json")
"""The formats :func:`write_quads` writes (first-order quads in the plane; ``.msh`` as MSH 2.2)."""


def mesh_format(path: str | os.PathLike, fmt: str | None = None) -> str:
    """The format name for ``path``'s suffix, or for ``fmt`` (a format's name or suffix, e.g.
    ``"inp"`` or ``"abaqus"``) when given; :class:`InputError` when it is not supported."""
    if fmt is None:
        return registry.find("mesh", path=path).name
    key = fmt.lower().lstrip(".")
    if key in {f.name for f in registry.formats("mesh")}:
        return key
    try:
        return registry.find("mesh", path=f"x.{key}").name
    except InputError:
        known = ", ".join(s[1:] for s in MESH_FORMATS)
        raise InputError(f"expected one of {known}, got {fmt!r}", "--format") from None


def _points3d(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64)
    return np.column_stack([xy, np.zeros(xy.shape[0])])


class LineGroup(NamedTuple):
    """A named set of mesh edges, written as line cells (e.g. a boundary side).

    name: the group's name (a ``.msh`` physical name); edges: ``(L, 2) int64`` vertex ids.
    """

    name: str
    edges: np.ndarray


def _meshio_mesh(xy, quads, cell_data, quad_groups, quad_group_names, line_groups, fmt: str):
    import meshio  # imported lazily: only mesh output needs it

    F = quads.shape[0]
    lines = [np.asarray(g.edges, dtype=np.int64).reshape(-1, 2) for g in line_groups]
    if fmt == "obj":
        return meshio.Mesh(_points3d(xy), [("quad", quads)])
    cells = [("quad", quads)]
    data: dict[str, list[np.ndarray]] = {k: [np.asarray(v)] for k, v in cell_data.items()}
    if fmt == "gmsh":
        qtag = (np.asarray(quad_groups, dtype=np.int32) + 1) if quad_groups is not None else np.ones(F, np.int32)
        tags = [qtag]
        field_data = {name: np.array([i + 1, 2]) for i, name in enumerate(quad_group_names)}
        first = max(len(quad_group_names), int(qtag.max()) if F else 0) + 1
        for j, (g, e) in enumerate(zip(line_groups, lines)):
            if e.shape[0] == 0:
                continue
            cells.append(("line", e))
            tags.append(np.full(e.shape[0], first + j, np.int32))
            field_data[g.name] = np.array([first + j, 1])
        if len(cells) > 1:  # meshio 5.3 cannot read $ElementData back once there are several cell blocks
            data = {}
        data["gmsh:physical"] = tags
        data["gmsh:geometrical"] = [t.copy() for t in tags]
        return meshio.Mesh(_points3d(xy), cells, cell_data=data, field_data=field_data)
    if lines:
        every = np.concatenate(lines) if lines else np.zeros((0, 2), np.int64)
        gid = np.concatenate([np.full(e.shape[0], j, np.int64) for j, e in enumerate(lines)])
        if every.shape[0]:
            cells.append(("line", every))
            for k, v in cell_data.items():
                fill = np.nan if np.asarray(v).dtype.kind == "f" else -1
                data[k].append(np.full(every.shape[0], fill, dtype=np.asarray(v).dtype))
            data["line_group"] = [np.full(F, -1, np.int64), gid]
    return meshio.Mesh(_points3d(xy), cells, cell_data=data)


def _json_text(xy, quads, cell_data, quad_groups, quad_group_names, line_groups, node_groups=None) -> str:
    data = {
        "points": np.asarray(xy, dtype=np.float64).tolist(),
        "quads": np.asarray(quads, dtype=np.int64).tolist(),
    }
    for k, v in cell_data.items():
        data[k] = np.asarray(v).tolist()
    if quad_groups is not None:
        data["quad_groups"] = {"names": list(quad_group_names), "group": np.asarray(quad_groups, dtype=np.int64).tolist()}
    if line_groups:
        data["groups"] = {g.name: np.asarray(g.edges, dtype=np.int64).reshape(-1, 2).tolist() for g in line_groups}
    if node_groups:
        data["node_groups"] = {k: np.asarray(v, np.int64).tolist() for k, v in node_groups.items()}
    return json.dumps(data, allow_nan=False) + "\n"


def write_quads(path: str | os.PathLike, xy: np.ndarray, quads: np.ndarray, *,
                cell_data: Mapping[str, np.ndarray] | None = None, quad_groups: np.ndarray | None = None,
                quad_group_names: Sequence[str] = (), line_groups: Sequence[LineGroup] = (),
                binary: bool = True, fmt: str | None = None, node_groups: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write a quad mesh with cell data and named groups to ``path`` atomically.

    xy: ``(V, 2) float64`` user coordinates; quads: ``(F, 4) int`` ccw vertex ids;
    cell_data: name -> ``(F,)`` array per quad (floats or ints); quad_groups: ``(F,) int``
    index into ``quad_group_names`` of each quad (``.msh``: physical group ``index + 1``;
    None: every quad in group 1, unnamed); line_groups: named edge sets (see the module
    docstring for how each format stores them); node_groups: name -> ``(N,) int`` node ids in
    their order (``.json`` only: ``"node_groups"``); binary: binary ``.msh`` (MSH 2.2, the version
    this writer writes) and ``.vtk``. Raises :class:`InputError` for an unknown suffix or a
    format this writer does not write (:func:`write_mesh` writes those), before anything is
    written. Returns the path written.
    """
    fmt = fmt or mesh_format(path)
    if fmt not in LEGACY:
        raise InputError(f"write_quads writes {', '.join(LEGACY)}; use write_mesh for {fmt}", str(path))
    final = Path(path)
    quads = np.asarray(quads, dtype=np.int64)
    cell_data = dict(cell_data or {})
    if fmt == "json":
        text = _json_text(xy, quads, cell_data, quad_groups, quad_group_names, line_groups, node_groups or {})
        with atomic_open(final, "w") as fh:
            fh.write(text)
        return final
    import meshio

    mesh = _meshio_mesh(xy, quads, cell_data, quad_groups, quad_group_names, line_groups, fmt)
    kwargs = {"binary": binary} if fmt in ("vtk", "gmsh") else {}
    with atomic_path(final) as tmp:
        meshio.write(tmp, mesh, file_format="gmsh22" if fmt == "gmsh" else fmt, **kwargs)
    return final


QUADMESH_FIELDS = ("xy", "quads", "patch", "line_sets", "scaled_jacobian")
"""What the writers read of a :class:`jaxmatch.meshing.result.QuadMesh`, the one mesh type they take
(named, not imported: this low layer imports nothing of the meshing pipeline above it)."""


def mesh_groups(mesh: "QuadMesh") -> tuple[np.ndarray, list[str], list[LineGroup]]:
    """``(quad groups (Q,) int64, their names, line groups)`` of a
    :class:`~jaxmatch.meshing.result.QuadMesh`: its ``patch`` (groups ``"patch p"``) and its
    ``line_sets`` (``"boundary"``, ``"side i-j"``, ``"hole h"``), in their order."""
    patch = np.asarray(mesh.patch, np.int64)
    names = list(getattr(mesh, "regions", ())) or ([f"patch {p}" for p in range(int(np.max(patch)) + 1)]
                                                    if patch.size else [])
    return patch, names, [LineGroup(k, np.asarray(v, np.int64)) for k, v in mesh.line_sets.items()]


def write_mesh(path: str | os.PathLike, mesh: "QuadMesh", output: MeshOutput | None = None, **options) -> Path:
    """Write a :class:`~jaxmatch.meshing.result.QuadMesh` (what :func:`jaxmatch.mesh` returns)
    to ``path`` atomically: points, cells, cell data (``scaled_jacobian``, ``patch``) and named
    groups (``"patch p"``, ``"boundary"``, ``"side i-j"``, ``"hole h"``; see :func:`mesh_groups`).

    output (or the same fields as keywords, :class:`~jaxmatch.io.output.MeshOutput`): ``format``
    (default: from the suffix), ``msh_version`` (``"4.1"`` default, ``"2.2"``), ``binary``,
    ``element_type`` (Abaqus), ``order`` (2: quad9, quad8 with ``serendipity``), ``extrude``,
    ``layers``, ``grading`` (hexahedra); see :mod:`jaxmatch.io.elements` and
    :mod:`jaxmatch.io.solverfiles`. What a format cannot hold is named in one
    :class:`~jaxmatch.errors.InputWarning`. ``.msh`` 2.2 of first-order quads is written as it
    always was (:func:`write_quads`), byte for byte.

    Other results become a QuadMesh where they are made (:mod:`jaxmatch.meshing.build`:
    ``from_placement``, ``from_layout``, ``from_refined``). Raises :class:`InputError` for an
    unknown suffix or an option the format cannot take, before anything is written; TypeError for
    anything but a QuadMesh. Returns the path written (XDMF: the ``.xdmf`` of the cells).
    """
    missing = [f for f in QUADMESH_FIELDS if not hasattr(mesh, f)]
    if missing:
        raise TypeError(f"write_mesh takes a jaxmatch.QuadMesh (jaxmatch.meshing.build makes one of other results), "
                        f"got {type(mesh).__name__} without {', '.join(missing)}")
    out = output if output is not None else MeshOutput(**options)
    fmt = mesh_format(path, out.format)
    final = Path(path)
    if out.element_type is not None and fmt != "abaqus":
        raise InputError(f"applies to Abaqus .inp files only, not {fmt}", "--element-type")
    nodes = dict(getattr(mesh, "point_sets", {}))
    if fmt in LEGACY and out.plain and (fmt != "gmsh" or (out.msh_version == "2.2" and not nodes)):
        patch, names, lines = mesh_groups(mesh)
        cell = {"scaled_jacobian": np.asarray(mesh.scaled_jacobian, dtype=np.float64), "patch": patch}
        if getattr(mesh, "point_sets", None):
            warnings.warn(InputWarning(f"the vertex groups ({', '.join(mesh.point_sets)}) are left out of {fmt} "
                                       "(msh 4.1, inp and exo hold them)", str(path)), stacklevel=2)
        if fmt == "obj" and lines:
            warnings.warn(InputWarning("obj holds the quads only: the groups and cell data were left out", str(path)),
                          stacklevel=2)
        write_quads(final, mesh.xy, mesh.quads, cell_data=cell, quad_groups=patch, quad_group_names=names,
                    line_groups=lines, binary=out.binary, fmt=fmt, node_groups=nodes)
        if nodes and fmt in ("vtk", "vtu", "obj"):
            warnings.warn(InputWarning(f"{fmt}: no node groups ({', '.join(nodes)} left out)", str(path)), stacklevel=2)
        return final
    if fmt in ("obj", "json"):
        raise InputError(f"{fmt} files hold first-order quads in the plane only (no --order 2, no --extrude)",
                         "--order" if out.order == 2 else "--extrude")
    sm = solver_mesh(mesh, order=out.order, serendipity=out.serendipity, extrude_dz=out.extrude, layers=out.layers,
                     grading=out.grading)
    notes = list(sm.notes) + write_solver_file(final, sm, fmt, msh_version=out.msh_version, binary=out.binary,
                                               element_type=out.element_type)
    if notes:
        warnings.warn(InputWarning("; ".join(notes), str(path)), stacklevel=2)
    return final


def read_json_mesh(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a file written by :func:`write_mesh` as ``.json``.

    Returns ``(points (V, 2) float64, quads (F, 4) int32, scaled_jacobian (F,) float64)``.
    Raises :class:`InputError` when the file is unreadable or malformed.
    """
    where = str(path)
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
        points = np.asarray(data["points"], dtype=np.float64).reshape(-1, 2)
        quads = np.asarray(data["quads"], dtype=np.int32).reshape(-1, 4)
        sj = np.asarray(data["scaled_jacobian"], dtype=np.float64).reshape(-1)
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise InputError(f"not a jaxmatch JSON mesh: {err}", where=where) from None
    if sj.shape[0] != quads.shape[0] or (quads.size and (quads.min() < 0 or quads.max() >= points.shape[0])):
        raise InputError("inconsistent JSON mesh (quad indices or scaled_jacobian length)", where=where)
    return points, quads, sj
