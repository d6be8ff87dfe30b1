"""Write a placed quad mesh to a file (meshio formats and a small JSON format).

The format comes from the file suffix (case-insensitive):

=========  ==============================================  ==========================
suffix     format                                          keeps ``scaled_jacobian``
=========  ==============================================  ==========================
``.vtk``   legacy VTK, binary (meshio)                     yes (cell data)
``.vtu``   VTK XML unstructured grid (meshio)              yes (cell data)
``.obj``   Wavefront OBJ (meshio)                          no
``.msh``   Gmsh 2.2, binary (meshio)                       yes (``$ElementData``)
``.json``  ``{"points": [[x, y], ...], "quads": [[a, b, c, d], ...],
           "scaled_jacobian": [...]}`` (written here)      yes
=========  ==============================================  ==========================

Points are the placement's ``xy`` in the user's coordinates; meshio formats get them padded
to 3D with ``z = 0``. Quads are 0-based vertex indices, counter-clockwise (OBJ and Gmsh files
store them 1-based, as their formats require; meshio converts back). Gmsh is written binary
because meshio 5.3 writes ASCII ``$ElementData`` values that it cannot read back under
numpy 2; every element gets physical and geometrical tag 1.

Every file is written atomically (:mod:`jaxmatch.files`): a failed write leaves no file and
no temporary behind, and keeps any previous file at ``path`` intact.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from jaxmatch.placement.embed import Placement
from jaxmatch.errors import InputError
from jaxmatch.files import atomic_open, atomic_path

__all__ = ["MESH_FORMATS", "mesh_format", "read_json_mesh", "write_mesh"]

MESH_FORMATS: dict[str, str] = {
    ".vtk": "vtk",
    ".vtu": "vtu",
    ".obj": "obj",
    ".msh": "gmsh22",
    ".json": "json",
}
"""File suffix -> format name (meshio's name, or ``"json"``)."""


def mesh_format(path: str | os.PathLike) -> str:
    """The format name for ``path``'s suffix; :class:`InputError` when it is not supported."""
    suffix = Path(path).suffix.lower()
    try:
        return MESH_FORMATS[suffix]
    except KeyError:
        known = ", ".join(MESH_FORMATS)
        raise InputError(f"unknown mesh file format {suffix or '(no suffix)'!r}; use one of {known}", where=str(path)) from None


def _points3d(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, dtype=np.float64)
    return np.column_stack([xy, np.zeros(xy.shape[0])])


def _meshio_mesh(placement: Placement, fmt: str):
    import meshio  # imported lazily: only mesh output needs it

    quads = np.asarray(placement.mesh.quads, dtype=np.int64)
    cell_data: dict[str, list[np.ndarray]] = {}
    if fmt != "obj":
        cell_data["scaled_jacobian"] = [np.asarray(placement.scaled_jacobian, dtype=np.float64)]
    if fmt == "gmsh22":
        ones = np.ones(quads.shape[0], dtype=np.int32)
        cell_data["gmsh:physical"] = [ones]
        cell_data["gmsh:geometrical"] = [ones.copy()]
    return meshio.Mesh(_points3d(placement.xy), [("quad", quads)], cell_data=cell_data)


def _json_text(placement: Placement) -> str:
    data = {
        "points": np.asarray(placement.xy, dtype=np.float64).tolist(),
        "quads": np.asarray(placement.mesh.quads, dtype=np.int64).tolist(),
        "scaled_jacobian": np.asarray(placement.scaled_jacobian, dtype=np.float64).tolist(),
    }
    return json.dumps(data, allow_nan=False) + "\n"


def write_mesh(path: str | os.PathLike, placement: Placement) -> Path:
    """Write ``placement`` (points, quads, per-quad scaled Jacobian) to ``path`` atomically.

    The format comes from the suffix (see the module docstring). Raises :class:`InputError`
    for an unknown suffix, before anything is written. Returns the path written.
    """
    fmt = mesh_format(path)
    final = Path(path)
    if fmt == "json":
        text = _json_text(placement)
        with atomic_open(final, "w") as fh:
            fh.write(text)
        return final
    import meshio

    mesh = _meshio_mesh(placement, fmt)
    kwargs = {"binary": True} if fmt in ("vtk", "gmsh22") else {}
    with atomic_path(final) as tmp:
        meshio.write(tmp, mesh, file_format=fmt, **kwargs)
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
