"""Solver files (jaxmatch.io.solverfiles, jaxmatch.io.elements): every format is read back by meshio
and, where installable, by the format's own reader (gmsh for .msh, netCDF4 for Exodus), with the
area and the groups as written; second-order nodes lie on the outline's curve and every element
has a positive Jacobian (computed by gmsh); extruded meshes have layers x quads hexahedra and
the region's area x thickness as volume (gmsh's Jacobians); bad options are one-line errors.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
import shapely

import jaxmatch
from jaxmatch.errors import InputError, InputWarning
from jaxmatch.io.meshfile import write_mesh
from jaxmatch.io.solverfiles import abaqus_name

meshio = pytest.importorskip("meshio")
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
REGIONS = {"lshape": (EXAMPLES / "lshape.json", 0.25), "plate-bolt": (EXAMPLES / "holes" / "plate-bolt.json", 0.4)}


@pytest.fixture(scope="module", params=sorted(REGIONS))
def region(request):
    path, size = REGIONS[request.param]
    return path, jaxmatch.mesh(path, size=size)


def polygon(path: Path) -> shapely.Polygon:
    """The region straight from its JSON file (independent of jaxmatch's readers)."""
    d = json.loads(path.read_text())
    return shapely.Polygon(d["boundary"], d.get("holes", []))


def quad_area(points, quads) -> float:
    p = points[quads][..., :2]
    q = np.roll(p, -1, axis=1)
    return float(0.5 * np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]))


def write(path, m, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        write_mesh(path, m, **kw)
    return [str(w.message) for w in caught if issubclass(w.category, InputWarning)]


def _abaqus_reader():
    import meshio.abaqus._abaqus as abq

    abq.abaqus_to_meshio_type.update({"CPE4": "quad", "CAX4": "quad", "CPS8": "quad8", "CPE8": "quad8", "CAX8": "quad8"})


@pytest.mark.parametrize("suffix", [".msh", ".inp", ".xdmf", ".bdf", ".e", ".vtu", ".mesh"])
def test_every_format_reads_back_with_area_and_groups(tmp_path, region, suffix):
    src, m = region
    if suffix in (".xdmf", ".e"):
        pytest.importorskip("h5py" if suffix == ".xdmf" else "netCDF4")
    _abaqus_reader()
    out = tmp_path / f"m{suffix}"
    notes = write(out, m)
    back = meshio.read(out)
    quads = np.concatenate([c.data for c in back.cells if c.type == "quad"])
    assert quads.shape[0] == m.quads.shape[0]
    assert quad_area(back.points, quads) == pytest.approx(polygon(src).area * m.area_ratio, rel=1e-9)
    assert quad_area(back.points, quads) == pytest.approx(polygon(src).area, rel=0.01)
    groups = dict(m.line_sets)
    if suffix == ".msh":
        for name, edges in groups.items():
            tag = back.field_data[name][0]
            n = sum(int(np.sum(t == tag)) for c, t in zip(back.cells, back.cell_data["gmsh:physical"]) if c.type == "line")
            assert n == len(edges)
    elif suffix == ".inp":
        for name, edges in groups.items():
            assert set(back.point_sets[abaqus_name(name)]) == set(np.unique(edges).tolist())
        assert sum(len(back.cell_sets[abaqus_name(f"patch {p}")][0]) for p in range(m.n_patches)) == len(m.quads)
    elif suffix == ".bdf":
        assert "were left out" in notes[0] and "boundary" in notes[0]
    elif suffix == ".e":
        assert len(back.cells) == m.n_patches  # one block per patch
        assert {k: len(v) for k, v in back.point_sets.items()} == {k: len(np.unique(v)) for k, v in groups.items()}
    elif suffix in (".xdmf", ".mesh"):
        facet = meshio.read(tmp_path / "m_facets.xdmf") if suffix == ".xdmf" else back
        marks = facet.cell_data["group" if suffix == ".xdmf" else "medit:ref"][-1]
        facets = [c for c in facet.cells if c.type == "line"][0].data
        names = list(groups)
        holders = {}  # facet -> the groups holding it
        for j, name in enumerate(names):
            for e in np.asarray(groups[name]).tolist():
                holders.setdefault(tuple(sorted(e)), []).append(j)
        assert len(facets) == len(holders)  # every facet once
        for f, mk in zip(facets.tolist(), marks.tolist()):
            js = holders[tuple(sorted(f))]
            assert mk == 1 + min(js, key=lambda j: (len(groups[names[j]]), j))  # the smallest group's marker
    elif suffix == ".vtu":
        assert np.sum(back.cell_data["line_group"][1] == 0) == len(groups["boundary"])


def test_msh_41_is_read_by_gmsh_with_every_group(tmp_path, region):
    gmsh = pytest.importorskip("gmsh")
    _, m = region
    for binary in (True, False):
        out = tmp_path / f"m{binary}.msh"
        write(out, m, binary=binary)
        assert out.read_bytes().startswith(b"$MeshFormat\n4.1 " + (b"1" if binary else b"0"))
        gmsh.initialize(interruptible=False)
        try:
            gmsh.option.setNumber("General.Verbosity", 0)
            gmsh.open(str(out))
            named = {gmsh.model.getPhysicalName(d, t): (d, t) for d, t in gmsh.model.getPhysicalGroups()}
            assert set(named) == set(m.line_sets) | {f"patch {p}" for p in range(m.n_patches)}
            for name, edges in m.line_sets.items():
                d, t = named[name]
                n = sum(len(tags) for e in gmsh.model.getEntitiesForPhysicalGroup(d, t)
                        for tags in gmsh.model.mesh.getElements(d, e)[1])
                assert (d, n) == (1, len(edges))
        finally:
            gmsh.finalize()


def test_msh_22_is_still_there(tmp_path, region):
    _, m = region
    write(tmp_path / "a.msh", m, msh_version="2.2")
    assert (tmp_path / "a.msh").read_bytes().startswith(b"$MeshFormat\n2.2 1")
    write(tmp_path / "b.msh", m, msh_version="2.2", binary=False)
    assert (tmp_path / "b.msh").read_bytes().startswith(b"$MeshFormat\n2.2 0")


@pytest.mark.parametrize("divisions,version", [(4, "2.2"), (8, "4.1")])
def test_a_mesh_of_a_few_quads_is_written_by_default_as_msh_22_with_a_note(tmp_path, divisions, version):
    """MSH 4.1 classifies every group on a node of its own; a mesh with more groups than nodes
    (one quad of a square: 4 nodes, a region, the boundary and four sides) is written as MSH 2.2,
    said in one note, and reads back with every quad."""
    m = jaxmatch.mesh(EXAMPLES / "square.json", divisions=divisions)
    notes = write(tmp_path / "a.msh", m)
    back = meshio.read(tmp_path / "a.msh")
    assert sum(len(c.data) for c in back.cells if c.type == "quad") == len(m.quads)
    assert (tmp_path / "a.msh").read_bytes().startswith(b"$MeshFormat\n" + version.encode())
    assert any("written as MSH 2.2" in n for n in notes) == (version == "2.2")


def test_exodus_side_sets_are_the_groups_edges(tmp_path, region):
    netCDF4 = pytest.importorskip("netCDF4")
    _, m = region
    write(tmp_path / "m.exo", m)
    with netCDF4.Dataset(tmp_path / "m.exo") as nc:
        names = [b"".join(r).decode().rstrip("\x00") for r in nc.variables["ss_names"][:].data]
        blocks = [nc.variables[f"connect{k + 1}"][:] - 1 for k in range(len(nc.dimensions["num_el_blk"]))]
        elems = np.concatenate(blocks)
        assert names == list(m.line_sets)
        for k, name in enumerate(names, 1):
            e, s = nc.variables[f"elem_ss{k}"][:] - 1, nc.variables[f"side_ss{k}"][:] - 1
            sides = {tuple(sorted((int(elems[i][j]), int(elems[i][(j + 1) % 4])))) for i, j in zip(e, s)}
            assert sides == {tuple(sorted(x)) for x in np.asarray(m.line_sets[name]).tolist()}


# ---------------------------------------------------------------------------------------------
# second order, extrusion (gmsh computes the Jacobians)


def gmsh_jacobians(path: Path, dim: int):
    """``(determinants (E, G), weights (G,))`` of every element of dimension ``dim`` (gmsh)."""
    gmsh = pytest.importorskip("gmsh")
    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Verbosity", 0)
        gmsh.open(str(path))
        dets, w = [], None
        for etype in gmsh.model.mesh.getElementTypes(dim):
            local, weights = gmsh.model.mesh.getIntegrationPoints(etype, "Gauss6")
            det = gmsh.model.mesh.getJacobians(etype, local)[1]
            dets.append(det.reshape(-1, len(weights)))
            w = np.asarray(weights)
        return np.concatenate(dets), w
    finally:
        gmsh.finalize()


CURVES = {"lshape.json": None, "circle.json": ((0.0, 0.0), 1.0), "plate-bolt.json": ((2.0, 2.0), 0.7)}


@pytest.mark.parametrize("serendipity", [False, True])
@pytest.mark.parametrize("name", sorted(CURVES))
def test_order_2_nodes_on_the_outline_and_positive_jacobians(tmp_path, name, serendipity):
    src = next(EXAMPLES.rglob(name))
    m = jaxmatch.mesh(src, divisions=16)
    write(tmp_path / "m.vtu", m, order=2, serendipity=serendipity)
    back = meshio.read(tmp_path / "m.vtu")
    cells = back.cells_dict["quad8" if serendipity else "quad9"]
    p = back.points[:, :2]
    names = list(m.line_sets)
    outline = np.isin(back.cell_data_dict["line_group"]["line3"], [j for j, n in enumerate(names)
                                                                   if n == "boundary" or n.startswith("hole")])
    lines = back.cells_dict["line3"][outline]  # the outline's edges: ends, middle
    poly = polygon(src)
    length = np.linalg.norm(p[lines[:, 0]] - p[lines[:, 1]], axis=1)
    mid = p[lines[:, 2]]
    on_hole = np.zeros(len(lines), bool)
    if CURVES[name] is not None:  # the round part: distance to the circle through the file's points
        (cx, cy), r = CURVES[name]
        dist_c = np.abs(np.hypot(mid[:, 0] - cx, mid[:, 1] - cy) - r)
        on_hole = np.abs(np.hypot(*(p[lines[:, 0]] - [cx, cy]).T) - r) < 1e-6
        assert np.all(dist_c[on_hole] <= 0.01 * length[on_hole])
        assert on_hole.any()
    dist = shapely.distance(shapely.points(mid[~on_hole]), poly.boundary)
    assert np.all(dist <= 0.01 * length[~on_hole] + 1e-12)
    write(tmp_path / "m.msh", m, order=2, serendipity=serendipity)
    det, w = gmsh_jacobians(tmp_path / "m.msh", 2)
    assert det.shape[0] == len(cells) and det.min() > 0
    true_area = {"lshape.json": 3.0, "circle.json": np.pi, "plate-bolt.json": 16.0 - np.pi * 0.49}[name]
    assert float((det * w).sum()) == pytest.approx(true_area, rel=1e-3)  # the curve's area, not the polygon's


@pytest.mark.parametrize("order", [1, 2])
def test_extrude_10_by_4_layers(tmp_path, region, order):
    src, m = region
    out = tmp_path / "m.msh"
    write(out, m, extrude=10.0, layers=4, order=order)
    back = meshio.read(out)
    kind = "hexahedron" if order == 1 else "hexahedron27"
    assert sum(len(c.data) for c in back.cells if c.type == kind) == 4 * len(m.quads)
    det, w = gmsh_jacobians(out, 3)
    assert det.min() > 0
    if order == 1:
        area = quad_area(np.asarray(m.xy), np.asarray(m.quads))
    else:  # curved sides: the area of the second-order quads themselves
        write(tmp_path / "flat.msh", m, order=2)
        d2, w2 = gmsh_jacobians(tmp_path / "flat.msh", 2)
        area = float((d2 * w2).sum())
    assert float((det * w).sum()) == pytest.approx(area * 10.0, rel=1e-6)
    expect = {"bottom", "top", *m.line_sets, *(f"patch {p}" for p in range(m.n_patches))}
    assert set(back.field_data) == expect
    assert {n: int(v[1]) for n, v in back.field_data.items() if n.startswith("patch")} == {
        f"patch {p}": 3 for p in range(m.n_patches)}
    assert back.field_data["top"][1] == 2


def test_grading_makes_the_top_layer_r_times_the_bottom(tmp_path, region):
    _, m = region
    write(tmp_path / "g.vtu", m, extrude=2.0, layers=3, grading=4.0)
    z = np.unique(np.round(meshio.read(tmp_path / "g.vtu").points[:, 2], 12))
    assert len(z) == 4 and z[0] == 0 and z[-1] == pytest.approx(2.0)
    assert (z[3] - z[2]) / (z[1] - z[0]) == pytest.approx(4.0)


@pytest.mark.parametrize("suffix, kw, where", [
    (".inp", {"order": 2}, "--order"), (".inp", {"element_type": "XYZ"}, "--element-type"),
    (".inp", {"extrude": 1.0, "element_type": "CPS4"}, "--element-type"), (".mesh", {"order": 2}, "--order"),
    (".msh", {"msh_version": "3"}, "--msh-version"), (".msh", {"layers": 3}, "--layers"),
    (".msh", {"extrude": -1.0}, "--extrude"), (".obj", {"order": 2}, "--order"),
    (".vtu", {"element_type": "CPS4"}, "--element-type"), (".msh", {"serendipity": True}, "--serendipity"),
])
def test_bad_options_are_one_line_errors_and_write_nothing(tmp_path, region, suffix, kw, where):
    _, m = region
    with pytest.raises(InputError) as err:
        write_mesh(tmp_path / f"m{suffix}", m, **kw)
    assert err.value.where == where and "\n" not in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_cli_writes_by_format_and_notes_what_is_left_out(tmp_path):
    import subprocess
    import sys

    from matplotlib.image import imread

    def run(*args):
        return subprocess.run([sys.executable, "-m", "jaxmatch", "mesh", str(EXAMPLES / "lshape.json"), *map(str, args)],
                              capture_output=True, text=True, cwd=EXAMPLES.parent)

    out = tmp_path / "l.txt"
    r = run("--size", "0.5", "--out", out, "--format", "bdf", "--png", tmp_path / "l.png", "--color", "quality",
            "--histogram", "--png-size", "640,480")
    assert r.returncode == 0, r.stderr
    assert out.read_text().startswith("$ Nastran")
    assert [line for line in r.stderr.splitlines() if "were left out" in line][0].startswith("warning: ")
    assert imread(tmp_path / "l.png").shape[:2] == (480, 640)
    r = run("--out", tmp_path / "x.inp", "--order", "3")
    assert r.returncode == 2 and r.stderr.strip().splitlines() == ["error: --order: expected 1 or 2, got 3"]
    assert not (tmp_path / "x.inp").exists()
