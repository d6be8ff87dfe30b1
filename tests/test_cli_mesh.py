"""``jaxmatch mesh`` and ``jaxmatch score --png/--svg``: exit codes, files, JSON fields.

Most runs call :func:`jaxmatch.cli.main` in-process (exit codes come from main()); one runs
``python -m jaxmatch.cli`` in a subprocess to check the real exit status.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

from jaxmatch.catalogue import store as cm
from jaxmatch.cli import main
from jaxmatch.errors import EXIT_BAD_INPUT, EXIT_INVERTED
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.io.meshfile import read_json_mesh
from jaxmatch.api import rank
from jaxmatch.placement.choose import acceptable, place_top
from jaxmatch.io.readers import load_shape

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="session")
def small_cat(tmp_path_factory):
    p = tmp_path_factory.mktemp("clicat") / "c.npz"
    cm.save(cm.generate(3), p)
    return p


U_SHAPE = EXAMPLES / "labels" / "shapes" / "ushape.json"
Z_SHAPE = EXAMPLES / "labels" / "shapes" / "zshape.json"


@pytest.fixture(scope="session")
def folded(small_cat):
    """(rank of a mesh that is not a good mesh of the U shape at k = 1..3, rank and id of the
    next one that is) under the small catalogue and the CLI's default ranking."""
    shp = load_shape(U_SHAPE)
    lat = load_lattice("fine")
    r = rank(shp, cm.load(small_cat), lat, top=12, internal=[1, 2, 3], tie_break="geometry")
    pls = place_top(shp, r, cm.load(small_cat), lattice=lat)
    ok = [acceptable(p) for p in pls]
    bad = ok.index(False) + 1
    want = next(i for i in range(bad, len(ok)) if ok[i]) + 1
    return bad, want, r.results[want - 1].mesh_id




def test_mesh_writes_vtk_and_pictures_json(cli, small_cat, tmp_path):
    out, png, svg = tmp_path / "m.vtk", tmp_path / "m.png", tmp_path / "m.svg"
    code, stdout, err = cli("mesh", EXAMPLES / "square.json", "--template", "--catalogue", small_cat, "--out", out, "--png", png, "--svg", svg, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    for key in ("mesh_id", "utility", "rotation", "reflected", "min_scaled_jacobian", "mean_scaled_jacobian", "inverted", "out"):
        assert key in d
    assert d["inverted"] == 0 and d["valid"] and d["rank"] == 1 and d["next_valid"] is None
    assert d["out"] == str(out) and d["png"] == str(png) and d["svg"] == str(svg)
    assert 0 < d["min_scaled_jacobian"] <= d["mean_scaled_jacobian"] <= 1
    m = meshio.read(out)
    quads = m.cells_dict["quad"]
    assert quads.shape == (d["quads"], 4)
    sj = m.cell_data_dict["scaled_jacobian"]["quad"]
    assert sj.min() == pytest.approx(d["min_scaled_jacobian"]) and sj.mean() == pytest.approx(d["mean_scaled_jacobian"])
    assert np.allclose(m.points[:, 2], 0) and m.points[:, :2].min() >= -1e-9  # the square's user coordinates
    assert png.read_bytes().startswith(PNG_MAGIC)
    assert ET.fromstring(svg.read_bytes()).tag.endswith("svg")
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == ["m.png", "m.svg", "m.vtk"]  # no temporaries


@pytest.mark.parametrize("suffix", [".msh", ".obj", ".json", ".vtu"])
def test_mesh_formats_read_back(cli, small_cat, tmp_path, suffix):
    out = tmp_path / f"m{suffix}"
    code, stdout, err = cli("mesh", EXAMPLES / "lshape.json", "--template", "--catalogue", small_cat, "--require-valid", "--out", out, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["valid"] and d["missed_corners"] == [] and abs(d["area_ratio"] - 1) <= 1e-9
    if suffix == ".json":
        pts, quads, sj = read_json_mesh(out)
    else:
        m = meshio.read(out)
        pts, quads = m.points[:, :2], m.cells_dict["quad"]
        sj = m.cell_data_dict["scaled_jacobian"]["quad"] if suffix == ".vtu" else None  # .msh with groups: none
    assert quads.shape == (d["quads"], 4)
    if sj is not None:
        assert sj.min() == pytest.approx(d["min_scaled_jacobian"])
    # every quad counter-clockwise (positive area) in the file's coordinates
    p = pts[quads]
    q = np.roll(p, -1, axis=1)
    assert np.all(0.5 * np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0], axis=1) > 0)


def test_mesh_text_output_and_picture_only(cli, small_cat, tmp_path):
    png = tmp_path / "only.png"
    code, stdout, err = cli("mesh", EXAMPLES / "triangle.json", "--template", "--catalogue", small_cat, "--png", png)
    assert code == 0, err
    assert "scaled Jacobian: min" in stdout and "mean" in stdout and "inverted quads: 0" in stdout
    assert f"wrote {png}" in stdout
    assert [p.name for p in tmp_path.iterdir() if p.is_file()] == ["only.png"]


def test_mesh_not_good_names_the_next_good_one(cli, small_cat, tmp_path, folded):
    bad, want, want_id = folded
    code, stdout, err = cli("mesh", U_SHAPE, "--template", "--catalogue", small_cat, "--internal", "1..3", "--rank", bad, "--json", "--band", "0")
    d = json.loads(stdout)
    assert not d["good"] and d["rank"] == bad
    assert code == (0 if d["valid"] else EXIT_INVERTED)
    assert d["next_valid"]["rank"] == want and d["next_valid"]["mesh_id"] == want_id
    assert f"#{want} {want_id}" in err


def test_mesh_require_valid_walks_down(cli, small_cat, tmp_path, folded):
    bad, want, want_id = folded
    code, stdout, err = cli("mesh", U_SHAPE, "--template", "--catalogue", small_cat, "--internal", "1..3", "--rank", bad, "--require-valid", "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["rank"] == want and d["requested_rank"] == bad and d["mesh_id"] == want_id and d["inverted"] == 0
    assert d["good"] and d["valid"] and d["min_scaled_jacobian"] >= d["min_quality"]


def test_mesh_folded_exit_3_still_writes(cli, small_cat, tmp_path):
    """The Z shape with one internal vertex: none of its 3 meshes embeds without a fold or a
    degenerate quad."""
    out = tmp_path / "f.json"
    code, stdout, err = cli("mesh", Z_SHAPE, "--template", "--catalogue", small_cat, "--internal", "1", "--out", out)
    assert code == EXIT_INVERTED
    assert "FOLDED" in err or "MISSED CORNERS" in err  # warnings and advice go to stderr
    assert "no mesh ranked #1..#3" in err and out.exists() and read_json_mesh(out)[1].shape[0] > 0
    code, stdout, err = cli("mesh", Z_SHAPE, "--template", "--catalogue", small_cat, "--internal", "1", "--json")
    assert code == EXIT_INVERTED
    d = json.loads(stdout)
    assert (d["inverted"] > 0 or d["missed_corners"]) and not d["valid"] and not d["good"] and d["next_valid"] is None
    assert len(d["missed_corners"]) == d["corners"] - d["corners_kept"]


@pytest.mark.parametrize(
    "extra",
    [
        ["--out", "{d}/m.stl"],
        ["--out", "{d}/m"],
        ["--out", "{d}/m.vtk", "--png", "{d}/m.jpg"],
        ["--out", "{d}/m.vtk", "--svg", "{d}/m.png"],
        ["--out", "{d}/m.vtk", "--tie-break", "size"],
        ["--out", "{d}/m.vtk", "--rank", "999"],
        ["--out", "{d}/m.vtk", "--min-quality", "1.5"],
        ["--out", "{d}/m.vtk", "--max-edge-ratio", "0.5"],
    ],
)
def test_mesh_bad_options_exit_2_one_line_nothing_written(cli, small_cat, tmp_path, extra):
    d = tmp_path / "o"
    d.mkdir()
    args = [a.format(d=d) for a in extra]
    code, stdout, err = cli("mesh", EXAMPLES / "square.json", "--template", "--catalogue", small_cat, *args)
    assert code == EXIT_BAD_INPUT
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in err
    assert list(d.iterdir()) == []


def test_score_png_svg_top_k(cli, small_cat, tmp_path):
    png, svg = tmp_path / "top.png", tmp_path / "top.svg"
    code, stdout, err = cli("score", EXAMPLES / "lshape.json", "--catalogue", small_cat, "--top", "3", "--png", png, "--svg", svg, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["tie_break"] == "geometry" and len(d["results"]) == 3
    data = png.read_bytes()
    assert data.startswith(PNG_MAGIC)
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert width > 2 * height  # three panels side by side
    assert ET.fromstring(svg.read_bytes()).tag.endswith("svg")
    code, _, err = cli("score", EXAMPLES / "lshape.json", "--catalogue", small_cat, "--png", tmp_path / "x.gif")
    assert code == EXIT_BAD_INPUT and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.gif").exists()


def test_score_tie_break_id_keeps_utilities(cli, small_cat):
    runs = {}
    for tb in ("id", "geometry"):
        code, stdout, err = cli("score", EXAMPLES / "square.json", "--catalogue", small_cat, "--top", "6", "--tie-break", tb, "--json")
        assert code == 0, err
        runs[tb] = json.loads(stdout)["results"]
    assert [r["utility"] for r in runs["id"]] == [r["utility"] for r in runs["geometry"]]


def test_real_process_exit_3(small_cat, tmp_path):
    out = tmp_path / "p.vtk"
    r = subprocess.run([sys.executable, "-m", "jaxmatch.cli", "mesh", str(Z_SHAPE), "--template", "--catalogue", str(small_cat),
                        "--internal", "1", "--out", str(out)], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == EXIT_INVERTED, r.stderr
    assert ("MISSED CORNERS" in r.stderr or "FOLDED" in r.stderr) and out.exists()  # warnings go to stderr
    assert "FOLDED" not in r.stdout and "MISSED CORNERS" not in r.stdout
    assert meshio.read(out).cells_dict["quad"].shape[1] == 4


def test_mesh_chooses_the_size_and_says_which_rule_decided(cli, small_cat):
    code, stdout, err = cli("mesh", EXAMPLES / "square.json", "--template", "--catalogue", small_cat, "--json")
    assert code == 0, err
    d = json.loads(stdout)
    sc = d["size_choice"]
    assert sc["rule"] in sc["rules"] and sc["k"] == d["internal_vertices"] == sc["candidates"][0]["k"]
    assert sorted(c["k"] for c in sc["candidates"]) == [0, 1, 2, 3]
    assert f"size k={sc['k']} chosen by rule '{sc['rule']}'" in err
    assert d["corners_kept"] == d["corners"] == 4 and d["missed_corners"] == [] and d["max_edge_ratio"] >= 1
    code, stdout, err = cli("mesh", EXAMPLES / "square.json", "--template", "--catalogue", small_cat, "--internal", "2", "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["size_choice"] is None and d["internal_vertices"] == 2
    code, stdout, err = cli("mesh", EXAMPLES / "square.json", "--template", "--catalogue", small_cat)
    assert code == 0 and "chosen by rule" in stdout and "corners kept: 4 of 4" in stdout and "max edge ratio" in stdout


STAIRS = EXAMPLES / "labels" / "shapes" / "stairs.json"


def test_mesh_quality_band_is_reported_and_can_be_turned_off(cli, small_cat):
    code, stdout, err = cli("mesh", STAIRS, "--template", "--catalogue", small_cat, "--internal", "3", "--json")
    assert code == 0, err
    d = json.loads(stdout)
    assert d["passed_over"]["rank"] == 1 and d["rank"] > 1 and d["min_scaled_jacobian"] >= 0.3 > d["passed_over"]["min_scaled_jacobian"]
    assert d["utility"] >= 0.9 * d["passed_over"]["utility"] and "quality band" in err
    code, stdout, err = cli("mesh", STAIRS, "--template", "--catalogue", small_cat, "--internal", "3", "--json", "--band", "0")
    d0 = json.loads(stdout)
    assert code == 0 and d0["rank"] == 1 and d0["passed_over"] is None and d0["mesh_id"] == d["passed_over"]["mesh_id"]


@pytest.mark.parametrize("value", ["-0.1", "1.5"])
def test_mesh_band_out_of_range_is_a_clear_error(cli, small_cat, value):
    code, stdout, err = cli("mesh", STAIRS, "--template", "--catalogue", small_cat, "--internal", "3", "--band", value)
    assert code == EXIT_BAD_INPUT and "--band" in err and "Traceback" not in err


MESH_IMPORTS = """
unwanted = {"jax", "jaxlib", "numba", "matplotlib", "optax", "starlette", "uvicorn", "svgelements", "ezdxf",
            "rich.progress", "rich.table", "jaxmatch.tuning", "jaxmatch.label", "jaxmatch.scoring.soft",
            "jaxmatch.kernels.dp_xla", "jaxmatch.io.plot", "jaxmatch.catalogue.canon_fast", "scipy"}
print(sorted(m for m in sys.modules if m in unwanted or m.split(".")[0] == "scipy"))
"""


def test_mesh_command_loads_only_what_it_uses(tmp_path, cli_then):
    """Start-up (docs/perf.md, "Start-up"): a piped ``jaxmatch mesh SHAPE --size H --out FILE`` imports no
    JAX, numba, matplotlib, labelling, tuning or progress-bar code, and no scipy at all for a small mesh
    (the integer programs go to HiGHS through highspy, the harmonic extensions of its patches are
    dense compiled solves, chords a union-find; no timing asserted)."""
    env = {k: v for k, v in os.environ.items() if k != "JAXMATCH_PROGRESS"}
    out = tmp_path / "l.msh"
    r = subprocess.run([sys.executable, "-c", cli_then(MESH_IMPORTS), "mesh", str(EXAMPLES / "lshape.json"), "--size", "0.5",
                        "--out", str(out)], capture_output=True, text=True, cwd=ROOT, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.rstrip().splitlines()[-1] == "[]", r.stdout
    assert out.exists()


def test_annotate_loads_no_solver(cli_then):
    """``jaxmatch annotate`` places nothing: scipy's sparse and optimize packages stay unloaded."""
    code = cli_then(MESH_IMPORTS.replace('unwanted = {', 'unwanted = {"meshio", ')
            .replace('"rich.table", ', ''))  # annotate prints tables
    r = subprocess.run([sys.executable, "-c", code, "annotate", str(EXAMPLES / "lshape.json")],
                       capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.rstrip().splitlines()[-1] == "[]", r.stdout


@pytest.mark.parametrize("args, where", [(["--search", "fastest"], "--search"),
                                         (["--search", "fast", "--template"], "--search")])
def test_mesh_search_refused_is_one_line(cli, args, where):
    code, stdout, err = cli("mesh", STAIRS, *args)
    assert code == EXIT_BAD_INPUT and where in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_mesh_search_fast_meshes_and_says_what_it_skipped(cli, tmp_path):
    """``--search fast``: a valid mesh, and the layouts left out are named with the reason."""
    code, stdout, err = cli("mesh", STAIRS, "--divisions", "32", "--search", "fast", "--json")
    d = json.loads(stdout)
    assert code == 0 and d["inverted"] == 0 and d["missed_corners"] == 0
    skipped = [c["name"] for c in d["candidates"] if c["note"].startswith("not tried: the fast search meshes at most 1 layout")]
    assert skipped and d["chosen"] not in skipped
    code, stdout, err = cli("mesh", STAIRS, "--divisions", "32", "--search", "best", "--json")
    assert code == 0 and not any(c["note"].startswith("not tried") for c in json.loads(stdout)["candidates"])
