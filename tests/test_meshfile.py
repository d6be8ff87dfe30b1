"""Mesh file output: every format reads back (meshio / json) with the same points, quads and
scaled Jacobian; writes are atomic; unknown suffixes are an InputError."""

from __future__ import annotations

import json

import meshio
import numpy as np
import pytest

from jaxmatch.placement.embed import arc_lengths, place
from jaxmatch.errors import InputError
from jaxmatch.io.meshfile import MESH_FORMATS, mesh_format, read_json_mesh, write_mesh
from jaxmatch.catalogue.mesh import from_quads
from jaxmatch.meshing.build import from_placement


def grid(nx, ny):
    vid = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    q = [[vid[j, i], vid[j, i + 1], vid[j + 1, i + 1], vid[j + 1, i]] for j in range(ny) for i in range(nx)]
    xy = np.array([[i, j] for j in range(ny + 1) for i in range(nx + 1)], float)
    return from_quads(q), xy


@pytest.fixture(scope="module")
def placement():
    """A 4x3 grid bent into an arc (non-trivial coordinates and scaled Jacobians)."""
    mesh, xy = grid(4, 3)
    th = np.radians(120) * xy[:, 0] / 4
    r = 2.0 + xy[:, 1] / 3
    lattice = np.c_[r * np.cos(th), -r * np.sin(th)] * 1.7 + [10.3, -4.1]
    pts = lattice[mesh.boundary]
    t = arc_lengths(pts)[:-1]
    pl = place(pts, t, np.arange(len(pts)), mesh, 0, False)
    assert pl.inverted == 0 and pl.scaled_jacobian.min() < 0.999
    return pl


@pytest.fixture(scope="module")
def qmesh(placement):
    """The placement as the one mesh type the writers take (no shape: no corners)."""
    return from_placement(None, placement)


@pytest.mark.parametrize("suffix", [".vtk", ".vtu", ".msh", ".obj"])
def test_meshio_formats_round_trip(tmp_path, placement, qmesh, suffix):
    path = tmp_path / f"mesh{suffix}"
    assert write_mesh(path, qmesh) == path
    back = meshio.read(path)
    np.testing.assert_array_equal(back.points[:, 2], 0.0)
    types = [c.type for c in back.cells]
    assert types == (["quad"] if suffix == ".obj" else ["quad", "line"])  # the boundary loop as a line group
    # the same quads at the same places (MSH 4.1 lists nodes entity by entity: meshio reads them in that order)
    np.testing.assert_array_equal(back.points[back.cells[0].data][..., :2], placement.xy[placement.mesh.quads])
    if suffix != ".msh":
        np.testing.assert_array_equal(back.points[:, :2], placement.xy)
        np.testing.assert_array_equal(back.cells[0].data, placement.mesh.quads)
    if suffix in (".vtk", ".vtu"):  # OBJ keeps no cell data; MSH 2 with line groups none (module docstring)
        np.testing.assert_array_equal(np.ravel(back.cell_data["scaled_jacobian"][0]), placement.scaled_jacobian)
    if suffix != ".obj":
        lines = back.points[back.cells[1].data][..., :2]
        assert len(lines) == len(placement.mesh.boundary)
        key = lambda seg: tuple(sorted(map(tuple, np.round(seg, 12).tolist())))  # noqa: E731
        assert {key(s) for s in lines} == {key(placement.xy[list(e)]) for e in zip(
            placement.mesh.boundary, np.roll(placement.mesh.boundary, -1))}
    if suffix == ".msh":
        assert "boundary" in back.field_data
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary left


def test_json_round_trip(tmp_path, placement, qmesh):
    path = tmp_path / "mesh.json"
    write_mesh(path, qmesh)
    data = json.loads(path.read_text())
    assert set(data) == {"points", "quads", "scaled_jacobian", "patch", "quad_groups", "groups"}
    assert data["quad_groups"] == {"names": ["patch 0"], "group": [0] * len(placement.mesh.quads)}
    assert len(data["groups"]["boundary"]) == len(placement.mesh.boundary)
    np.testing.assert_array_equal(np.array(data["points"]), placement.xy)
    np.testing.assert_array_equal(np.array(data["quads"]), placement.mesh.quads)
    np.testing.assert_array_equal(np.array(data["scaled_jacobian"]), placement.scaled_jacobian)
    pts, quads, sj = read_json_mesh(path)
    np.testing.assert_array_equal(pts, placement.xy)
    np.testing.assert_array_equal(quads, placement.mesh.quads)
    np.testing.assert_array_equal(sj, placement.scaled_jacobian)


def test_suffix_is_case_insensitive(tmp_path, placement, qmesh):
    path = tmp_path / "MESH.VTK"
    write_mesh(path, qmesh)
    assert meshio.read(path, file_format="vtk").points.shape == (placement.xy.shape[0], 3)
    assert mesh_format("a/b.Json") == "json"


@pytest.mark.parametrize("name", ["mesh.stl", "mesh", "mesh.txt"])
def test_unknown_suffix_is_input_error(tmp_path, placement, qmesh, name):
    with pytest.raises(InputError, match="unknown mesh file format") as err:
        write_mesh(tmp_path / name, qmesh)
    assert name in str(err.value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", sorted(MESH_FORMATS))
def test_failed_write_leaves_nothing_and_keeps_old_file(tmp_path, placement, qmesh, monkeypatch, suffix):
    path = tmp_path / f"mesh{suffix}"
    path.write_text("old")

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(meshio, "write", boom)
    monkeypatch.setattr(json, "dumps", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        write_mesh(path, qmesh)
    assert path.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_only_a_quadmesh_is_written(tmp_path, placement):
    """One output path: other results become a QuadMesh where they are made (meshing.build)."""
    for other in (placement, placement.mesh, object()):
        with pytest.raises(TypeError, match="takes a jaxmatch.QuadMesh"):
            write_mesh(tmp_path / "m.msh", other)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "text, msg",
    [("{", "not a jaxmatch JSON mesh"), ('{"points": [[0, 0]]}', "not a jaxmatch JSON mesh"),
     ('{"points": [[0, 0]], "quads": [[0, 1, 2, 3]], "scaled_jacobian": [1]}', "inconsistent")],
)
def test_read_json_mesh_rejects_bad_files(tmp_path, text, msg):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError, match=msg):
        read_json_mesh(path)
