"""STEP, IGES and BREP faces (jaxmatch.io.cad): a plate with fillets and holes written by gmsh's
OpenCASCADE kernel is read back with every loop, its curves sampled on the true curves and its
mesh's area within 1 % of the analytic area; solids, curved faces and several faces are refused
in one line; gmsh is optional.

Independent checks: the files are written by gmsh from known geometry (a rounded rectangle, a
circle and an ellipse cut out); the read points are compared with the analytic fillet circles and
hole curves, the areas with the analytic area, the meshes' boundary loops found from the quads.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
import shapely

import jaxmatch
from jaxmatch.errors import InputError
from jaxmatch.io import cad
from jaxmatch.io.outline import CURVE_TOLERANCE, MAX_CURVE_TURN
from jaxmatch.io.readers import load_shape
from jaxmatch.meshing.result import boundary_loops
from jaxmatch.quality import quad_areas

gmsh = pytest.importorskip("gmsh")

W, H, R = 100.0, 60.0, 10.0  # the plate and its fillets' radius
HOLE = (30.0, 30.0, 8.0)  # a round hole: centre, radius
ELLIPSE = (70.0, 30.0, 12.0, 6.0)  # an elliptic hole: centre, semi-axes
AREA = W * H - (4 - math.pi) * R * R - math.pi * HOLE[2] ** 2 - math.pi * ELLIPSE[2] * ELLIPSE[3]


def write_with_gmsh(path, build) -> None:
    """``build(occ)`` in a fresh gmsh model, written to ``path`` (its suffix picks the format);
    in a subprocess, as a user's CAD program would, so that this process's gmsh is untouched."""
    code = f"""
import gmsh
gmsh.initialize(readConfigFiles=False, interruptible=False)
gmsh.option.setNumber("General.Terminal", 0)
occ = gmsh.model.occ
{build}
occ.synchronize()
gmsh.write({str(path)!r})
gmsh.finalize()
"""
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


PLATE = f"""
plate = occ.addRectangle(0, 0, 0, {W}, {H}, roundedRadius={R})
holes = [occ.addDisk({HOLE[0]}, {HOLE[1]}, 0, {HOLE[2]}, {HOLE[2]}), occ.addDisk(*{ELLIPSE[:2]}, 0, *{ELLIPSE[2:]})]
occ.cut([(2, plate)], [(2, h) for h in holes])
"""


@pytest.fixture(scope="module")
def plates(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cad")
    paths = {}
    for suffix in (".step", ".igs", ".brep"):
        paths[suffix] = folder / f"plate{suffix}"
        write_with_gmsh(paths[suffix], PLATE)
    return paths


@pytest.mark.parametrize("suffix", [".step", ".igs", ".brep"])
def test_a_plate_with_fillets_and_holes(plates, suffix, capfd):
    shape = load_shape(plates[suffix])
    assert capfd.readouterr().out == ""  # OpenCASCADE's statistics do not reach standard output
    assert len(shape.holes) == 2 and shape.n_corners == 0  # the fillets join the sides smoothly
    xy, size = shape.given_points, max(W, H)
    for cx, cy in [(R, R), (W - R, R), (W - R, H - R), (R, H - R)]:  # the fillets: on their circles, finely sampled
        near = (np.abs(xy[:, 0] - cx) < R) & (np.abs(xy[:, 1] - cy) < R) & (np.hypot(xy[:, 0] - cx, xy[:, 1] - cy) > R / 2)
        assert near.sum() >= 90 / MAX_CURVE_TURN - 1
        assert np.abs(np.hypot(xy[near, 0] - cx, xy[near, 1] - cy) - R).max() <= 1e-9 * size
    round_, oval = sorted(shape.holes, key=lambda h: h[:, 0].mean())
    assert np.abs(np.hypot(round_[:, 0] - HOLE[0], round_[:, 1] - HOLE[1]) - HOLE[2]).max() <= 1e-9 * size
    ex, ey = (oval[:, 0] - ELLIPSE[0]) / ELLIPSE[2], (oval[:, 1] - ELLIPSE[1]) / ELLIPSE[3]
    assert np.abs(np.hypot(ex, ey) - 1).max() <= 1e-6  # (IGES writes the ellipse as a B-spline)
    assert shapely.Polygon(xy, list(shape.holes)).area == pytest.approx(AREA, rel=1e-3)
    m = jaxmatch.mesh(shape, size=5.0)
    assert float(quad_areas(m.xy, m.quads).sum()) == pytest.approx(AREA, rel=0.01)
    loops = boundary_loops(m.quads)
    assert len(loops) == 3
    on_round = [np.abs(np.hypot(*(m.xy[lp] - HOLE[:2]).T) - HOLE[2]).max() <= CURVE_TOLERANCE * size for lp in loops]
    on_oval = [np.abs(np.hypot((m.xy[lp, 0] - ELLIPSE[0]) / ELLIPSE[2], (m.xy[lp, 1] - ELLIPSE[1]) / ELLIPSE[3]) - 1).max()
               <= 2 * CURVE_TOLERANCE * size / ELLIPSE[3] for lp in loops]
    assert sum(on_round) == 1 and sum(on_oval) == 1  # each hole a boundary loop of the mesh


def test_a_face_in_another_plane_is_read_in_its_own_frame(tmp_path):
    path = tmp_path / "tilted.step"
    write_with_gmsh(path, PLATE + "occ.rotate(occ.getEntities(2), 0, 0, 0, 1, 1, 0, 0.7)\nocc.translate(occ.getEntities(2), 0, 0, 5)")
    shape = load_shape(path)
    assert len(shape.holes) == 2
    assert shapely.Polygon(shape.given_points, list(shape.holes)).area == pytest.approx(AREA, rel=1e-3)


@pytest.mark.parametrize("build, pattern", [
    ("occ.addBox(0, 0, 0, 10, 10, 2)", r"a 3D solid \(1 volume\)"),
    ("occ.addRectangle(0, 0, 0, 10, 10)\nocc.addRectangle(20, 0, 0, 10, 10)", r"2 faces .*choose a face with FILE#N \(faces: 1, 2\)"),
    ("c = occ.addCylinder(0, 0, 0, 0, 0, 10, 3)\nocc.remove([(3, c)])", r"3 faces"),
])
def test_refusals(tmp_path, build, pattern):
    path = tmp_path / "part.step"
    write_with_gmsh(path, build)
    with pytest.raises(InputError, match=pattern) as info:
        load_shape(path)
    assert str(info.value).startswith(f"{path}: ")


def test_a_face_is_chosen_by_number_and_a_curved_one_refused(tmp_path):
    path = tmp_path / "two.step"
    write_with_gmsh(path, "occ.addRectangle(0, 0, 0, 10, 10)\nocc.addRectangle(20, 0, 0, 10, 5)")
    assert load_shape(f"{path}#2").given_points[:, 0].min() == pytest.approx(20)
    with pytest.raises(InputError, match=r"no face '7' \(faces: 1, 2\)"):
        load_shape(f"{path}#7")
    tube = tmp_path / "tube.step"
    write_with_gmsh(tube, "c = occ.addCylinder(0, 0, 0, 0, 0, 10, 3)\nocc.remove([(3, c)])")
    with pytest.raises(InputError, match=r"face 1 is not planar \(a Cylinder"):
        load_shape(f"{tube}#1")
    assert load_shape(f"{tube}#2").n_corners == 0  # an end disk is planar


def test_unreadable_file_and_missing_gmsh(tmp_path, monkeypatch):
    bad = tmp_path / "bad.step"
    bad.write_text("ISO-10303-21;\nnonsense\n")
    with pytest.raises(InputError, match=r"bad\.step: not a readable STEP file"):
        load_shape(bad)

    class NoGmsh:
        def __getattr__(self, name):
            raise ModuleNotFoundError("No module named 'gmsh'")

    monkeypatch.setattr(cad, "later", NoGmsh())
    with pytest.raises(InputError, match=r"reading STEP files needs gmsh: pip install 'jaxmatch\[cad\]'"):
        load_shape(bad)


def test_a_caller_s_gmsh_session_is_left_as_it_was(plates):
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("mine")
        gmsh.model.occ.addRectangle(0, 0, 0, 1, 1)
        gmsh.model.occ.synchronize()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert len(load_shape(plates[".step"]).holes) == 2
        assert gmsh.isInitialized() and gmsh.model.getCurrent() == "mine"
        assert gmsh.model.getEntities(2) == [(2, 1)]
    finally:
        gmsh.finalize()
