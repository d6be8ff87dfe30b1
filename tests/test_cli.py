"""The command line: outputs, JSON shapes, exit codes, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from jaxmatch.catalogue import store as cm

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


def run(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "jaxmatch.cli", *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300)


@pytest.fixture(scope="module")
def small_cat(tmp_path_factory):
    p = tmp_path_factory.mktemp("cat") / "c3.npz"
    cm.save(cm.generate(3), p)
    return p


def test_score_json(small_cat):
    r = run("score", EXAMPLES / "lshape.json", "--catalogue", small_cat, "--internal", "2..3", "--top", "3", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert set(d) >= {"shape", "sequence", "lattice", "results"}
    assert set(d["sequence"]) <= set("sxv") and d["sequence"].count("v") == 1
    assert len(d["results"]) == 3
    utils = [x["utility"] for x in d["results"]]
    assert utils == sorted(utils, reverse=True)
    for res in d["results"]:
        assert res["internal_vertices"] in (2, 3)
        a = res["alignment"]
        assert len(a) == res["boundary_length"] == len(res["triples"])
        assert all(x < y for x, y in zip(a, a[1:]))


def test_score_table_and_per_size(small_cat):
    r = run("score", EXAMPLES / "square.json", "--catalogue", small_cat, "--per-size", "--top", "1")
    assert r.returncode == 0, r.stderr
    assert "best per size" in r.stdout
    for k in ("k0-", "k1-", "k2-", "k3-"):
        assert k in r.stdout


def test_annotate_json():
    r = run("annotate", EXAMPLES / "triangle.json", "--points", "12", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["sequence"].count("x") == 3 and len(d["points"]) == 12


def test_lattice_show_json():
    r = run("lattice", "show", "fine", "--json")
    d = json.loads(r.stdout)
    assert set(d) == {"s", "x", "v", "skip"} and all(len(d[k]) == 64 for k in "sxv") and set(d["skip"]) == {"s", "x", "v"}
    assert d["x"]["3-4-3"] is None  # convex corner on valence 4: -inf


def test_catalogue_build_info_export(tmp_path):
    out = tmp_path / "c.npz"
    r = run("catalogue", "build", "--internal", "0..2", "--out", out)
    assert r.returncode == 0, r.stderr
    info = json.loads(run("catalogue", "info", out, "--json").stdout)
    assert info["per_k"]["2"] == {"meshes": 12, "up_to_rotation": 12}
    assert info["format_version"] == cm.FORMAT_VERSION
    one = cm.load(out).bucket(6).ids[0]
    d = json.loads(run("catalogue", "export", out, "--id", one, "--format", "json").stdout)
    assert d["id"] == one and d["internal_vertices"] == 1


@pytest.mark.parametrize(
    "content,needle",
    [
        ("{not json", "JSON"),
        ('{"boundary": [[0, 0], [1, 0]]}', "3 points"),
        ('{"boundary": [[0, 0], [1, 0], [1, 1], [0, 1]], "corners": [7]}', "corner"),
        ('{"boundary": [[0, 0], [1, 1], [1, 0], [0, 1]]}', "crosses"),
        ('{"boundary": [[0, 0], [1, 0], [2, 0]]}', "area"),
        ('{"points": []}', "key"),
    ],
)
def test_bad_shape_one_line_exit_2(tmp_path, small_cat, content, needle):
    f = tmp_path / "bad shape.json"
    f.write_text(content)
    r = run("score", f, "--catalogue", small_cat)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(f) in lines[0] and "Traceback" not in r.stderr
    assert needle.lower() in lines[0].lower()


@pytest.mark.parametrize(
    "args",
    [
        ["score", "examples/square.json", "--catalogue", "nope.npz"],
        ["score", "examples/square.json", "--internal", "x..y"],
        ["score", "examples/square.json", "--lattice", "nope.toml"],
        ["catalogue", "info", "README.md"],
        ["catalogue", "export", "README.md", "--id", "x"],
    ],
)
def test_bad_options_one_line_exit_2(args):
    r = run(*args)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_unmatchable_exit_4(small_cat):
    r = run("score", EXAMPLES / "square.json", "--catalogue", small_cat, "--internal", "3", "--points", "5")
    assert r.returncode == 4
    assert "--points" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_build_refuses_huge_k_without_allow_large(tmp_path):
    r = run("catalogue", "build", "--internal", "0..50", "--out", tmp_path / "c.npz")
    assert r.returncode == 2 and "--allow-large" in r.stderr
    assert not (tmp_path / "c.npz").exists()


def test_pruned_default_equals_exhaustive_and_sharded(small_cat):
    """The default pruned search, --exhaustive and --devices 4 give the same ranking."""
    args = ["score", EXAMPLES / "lshape.json", "--catalogue", small_cat, "--internal", "3", "--top", "5", "--json", "--tie-break", "id"]
    pruned = json.loads(run(*args).stdout)
    full = json.loads(run(*args, "--exhaustive").stdout)
    sharded = json.loads(run(*args, "--devices", "4").stdout)
    assert full["pruned"] == 0 and pruned["pruned"] > 0
    assert pruned["results"] == full["results"] == sharded["results"]


def test_score_many_writes_one_line_per_shape(small_cat, tmp_path):
    out = tmp_path / "r.jsonl"
    shapes = [EXAMPLES / "square.json", EXAMPLES / "lshape.json", EXAMPLES / "triangle.json"]
    r = run("score-many", *shapes, "--catalogue", small_cat, "--internal", "2", "--top", "2", "--out", out)
    assert r.returncode == 0, r.stderr
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert [d["shape"] for d in lines] == [str(s) for s in shapes]
    single = json.loads(run("score", shapes[1], "--catalogue", small_cat, "--internal", "2", "--top", "2", "--json",
                            "--tie-break", "id").stdout)
    assert lines[1]["results"] == single["results"]


def test_score_many_bad_shape_writes_nothing(small_cat, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    out = tmp_path / "r.jsonl"
    r = run("score-many", EXAMPLES / "square.json", bad, "--catalogue", small_cat, "--out", out)
    assert r.returncode == 2 and str(bad) in r.stderr and not out.exists()
