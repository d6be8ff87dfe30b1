"""The command line: outputs, JSON shapes, exit codes, one-line errors."""

from __future__ import annotations

import json
import os
import re
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


def test_check_outputs():
    """Output suffixes are refused before any work, naming the option."""
    from jaxmatch.cli import check_outputs
    from jaxmatch.errors import InputError

    check_outputs("a.vtk", "a.png", "a.svg")
    check_outputs(None, None, None)
    for kw, opt in (({"out": "a.stl"}, "--out"), ({"png": "a.svg"}, "--png"), ({"svg": "a.png"}, "--svg"),
                    ({"out": "noext"}, "--out")):
        with pytest.raises(InputError) as e:
            check_outputs(**kw)
        assert opt in str(e.value)


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
    single = json.loads(run("score", shapes[1], "--catalogue", small_cat, "--internal", "2", "--top", "2", "--json").stdout)
    assert lines[1] == dict(single, shape=str(shapes[1]))  # same defaults (tie-break included): the same record
    assert "3 shapes, 3 scored" in r.stderr


def test_score_many_jobs_give_the_same_records_in_input_order(small_cat, tmp_path):
    """Worker processes (--jobs 2, the geometric tie-break placing meshes in each) write exactly
    what one process writes, in the input order."""
    shapes = [EXAMPLES / n for n in ("square.json", "lshape.json", "triangle.json", "tshape.json", "hexagon.json")]
    outs = []
    for jobs in ("1", "2"):
        out = tmp_path / f"r{jobs}.jsonl"
        r = run("score-many", *shapes, "--catalogue", small_cat, "--top", "3", "--out", out, "--jobs", jobs)
        assert r.returncode == 0, r.stderr
        outs.append(out.read_text())
    assert outs[0] == outs[1]
    assert [json.loads(x)["shape"] for x in outs[1].splitlines()] == [str(s) for s in shapes]


def test_score_many_bad_shape_writes_nothing(small_cat, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    out = tmp_path / "r.jsonl"
    r = run("score-many", EXAMPLES / "square.json", bad, "--catalogue", small_cat, "--out", out)
    assert r.returncode == 2 and str(bad) in r.stderr and not out.exists()


def test_score_many_skip_bad_records_errors_and_goes_on(small_cat, tmp_path):
    bad, crossing = tmp_path / "bad.json", tmp_path / "cross.txt"
    bad.write_text("{")
    crossing.write_text("0 0\n1 1\n1 0\n0 1\n")
    out = tmp_path / "r.jsonl"
    shapes = [EXAMPLES / "square.json", bad, EXAMPLES / "lshape.csv", crossing]
    r = run("score-many", *shapes, "--catalogue", small_cat, "--internal", "2", "--top", "1", "--out", out, "--skip-bad")
    assert r.returncode == 0, r.stderr
    recs = [json.loads(x) for x in out.read_text().splitlines()]
    assert [d["shape"] for d in recs] == [str(s) for s in shapes]
    assert "results" in recs[0] and "results" in recs[2]
    assert str(bad) in recs[1]["error"] and "JSON" in recs[1]["error"]
    assert "crosses" in recs[3]["error"]
    assert r.stderr.strip().splitlines()[-1] == f"wrote {out}: 4 shapes, 2 scored, 2 failed (records with \"error\")"


def test_one_answer_annotate_uses_the_points_score_uses():
    """Regression: annotate showed 68 points where 'score --internal 4' scores 56."""
    a = json.loads(run("annotate", EXAMPLES / "lshape.json", "--internal", "4", "--json").stdout)
    s = json.loads(run("score", EXAMPLES / "lshape.json", "--internal", "4", "--top", "1", "--json").stdout)
    assert len(a["points"]) == s["points"] == 56 and a["sequence"] == s["sequence"]


@pytest.mark.parametrize("args, option, fragment", [
    (["score", "examples/square.json", "--corner-angle", "200"], "--corner-angle", "[0, 180)"),
    (["annotate", "examples/square.json", "--corner-angle", "-1"], "--corner-angle", "[0, 180)"),
    (["score", "examples/square.json", "--internal", "9"], "--internal", "it has k = 0..5"),
    (["annotate", "examples/square.json", "--internal", "7"], "--internal", "it has k = 0..5"),
    (["score", "examples/square.json", "--tie-break", "best"], "--tie-break", "geometry"),
])
def test_option_errors_name_the_option_once(args, option, fragment):
    r = run(*args)
    assert r.returncode == 2
    line = r.stderr.strip()
    assert line.startswith(f"error: {option}: ") and fragment in line and "\n" not in line
    assert line.count("corner angle") == 0 and line.count(option) == 1


def test_version_and_python_m():
    for cmd in ([sys.executable, "-m", "jaxmatch", "--version"], [sys.executable, "-m", "jaxmatch.cli", "--version"]):
        r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=120)
        assert r.returncode == 0 and r.stdout.strip() == "jaxmatch 0.1.0"


HELP = [[], ["score"], ["score-many"], ["mesh"], ["annotate"], ["lattice", "show"], ["catalogue", "build"],
        ["catalogue", "info"], ["catalogue", "export"]]


@pytest.mark.parametrize("cmd", HELP, ids=lambda c: " ".join(c) or "jaxmatch")
def test_help_is_conventional(cmd):
    """Flags show no '<bool>' (they take no value), arguments show as NAME, not '{name}' or
    '<list[Path]>'; every option and argument has a help text."""
    r = subprocess.run([sys.executable, "-m", "jaxmatch", *cmd, "--help"], capture_output=True, text=True, cwd=ROOT,
                       timeout=120, env={**os.environ, "COLUMNS": "200"})
    assert r.returncode == 0, r.stderr
    text = r.stdout
    usage = next(ln for ln in text.splitlines() if "Usage:" in ln)
    assert "Usage: jaxmatch" in usage and "{" not in usage and "<" not in usage, usage
    for bad in ("<bool>", "<list[", "<path>", "<str>"):
        assert bad not in text, (bad, text)
    rows = [ln for ln in text.splitlines() if re.match(r"^│\s+(\*\s+)?(--[a-z-]+|[A-Z|.]+)\s", ln)]
    assert rows and all(len(re.split(r"\s{2,}", ln.strip("│ ").strip())) >= 2 for ln in rows), text


def test_json_flag_takes_no_value():
    r = run("score", EXAMPLES / "square.json", "--json", "true")
    assert r.returncode == 2 and "unexpected extra argument" in r.stderr


def test_extra_json_keys_warn_on_stderr_only(tmp_path, small_cat):
    f = tmp_path / "named.json"
    f.write_text(json.dumps({"boundary": [[0, 0], [1, 0], [1, 1], [0, 1]], "name": "plate", "units": "mm"}))
    r = run("score", f, "--catalogue", small_cat, "--internal", "1", "--top", "1", "--json")
    assert r.returncode == 0, r.stderr
    json.loads(r.stdout)
    assert r.stderr.strip() == f"warning: {f}: ignored keys 'name', 'units' (known keys: boundary, corners, holes, hole_corners, tags, periodic)"


def test_heartbeat_lines_when_not_a_terminal():
    import io

    from jaxmatch.cli import Heartbeat

    buf = io.StringIO()
    with Heartbeat(interval=0.0, stream=buf) as hb:
        task = hb.add_task("scoring meshes", total=None)
        hb.update(task, completed=10, total=40)
        hb.advance(task, 5)
    lines = buf.getvalue().splitlines()
    assert lines[0].startswith("scoring meshes: 10/40 (") and lines[1].startswith("scoring meshes: 15/40 (")
    quiet = io.StringIO()
    hb = Heartbeat(interval=3600.0, stream=quiet)
    hb.update(hb.add_task("x", total=3), completed=1)
    assert quiet.getvalue() == ""


def test_piped_run_says_it_is_alive(small_cat):
    env = {**os.environ, "JAXMATCH_PROGRESS": ""}
    r = subprocess.run([sys.executable, "-c", "import jaxmatch.cli as c; c.HEARTBEAT_S = 0.0; c.main()", "score",
                        str(EXAMPLES / "square.json"), "--catalogue", str(small_cat), "--top", "1"],
                       capture_output=True, text=True, cwd=ROOT, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    assert re.search(r"^scoring meshes: \d+/\d+ \(\d+ s\)$", r.stderr, re.M), r.stderr


NO_JAX = """
loaded = sorted(m for m in sys.modules if m == "jax" or m.startswith(("jax.", "jaxlib")))
assert not loaded, loaded[:5]
print("no jax")
"""


@pytest.mark.parametrize("env", [{"JAXMATCH_BACKEND": "numba"}, {"JAXMATCH_BACKEND": "auto", "JAX_PLATFORMS": "cpu"}])
def test_score_on_the_numba_backend_never_imports_jax(small_cat, tmp_path, env, cli_then):
    """The default CPU path (numba kernel, numpy backtrack, compile-cache settings) runs without JAX."""
    env = {**os.environ, "JAXMATCH_CACHE": str(tmp_path / "cache"), **env}
    r = subprocess.run([sys.executable, "-c", cli_then(NO_JAX), "score", str(EXAMPLES / "lshape.json"), "--catalogue", str(small_cat),
                        "--tie-break", "id", "--json"], capture_output=True, text=True, cwd=ROOT, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.rstrip().endswith("no jax") and json.loads(r.stdout.rstrip()[: -len("no jax")])["results"]


def test_make_labels_refuses_bad_variants_and_empty_output(tmp_path):
    script = ROOT / "scripts" / "make_labels.py"
    out = tmp_path / "l.jsonl"
    r = subprocess.run([sys.executable, script, "synthetic", "--variants", "-1", "--out", out], capture_output=True, text=True,
                       cwd=ROOT, timeout=300)
    assert r.returncode == 2 and "--variants" in r.stderr and not out.exists()
    r = subprocess.run([sys.executable, script, "synthetic", "--internal", "9", "--out", out], capture_output=True, text=True,
                       cwd=ROOT, timeout=300)
    assert r.returncode == 2 and "9 internal vertices" in r.stderr and not out.exists()


def test_commands_share_their_defaults():
    """score, score-many, mesh and annotate take their defaults from jaxmatch.defaults (as the API does)."""
    import typer

    from jaxmatch import defaults
    from jaxmatch.api import rank
    from jaxmatch.cli import app
    from jaxmatch.shape import DEFAULT_CORNER_ANGLE

    want = {"lattice": defaults.DEFAULT_LATTICE, "tie_break": defaults.DEFAULT_TIE_BREAK, "top": defaults.DEFAULT_TOP,
            "corner_angle": DEFAULT_CORNER_ANGLE, "points": None, "internal": None, "catalogue": None}
    commands = typer.main.get_command(app).commands
    for name in ("score", "score-many", "mesh", "annotate"):
        got = {p.name: p.default for p in commands[name].params if p.name in want}
        assert got == {k: v for k, v in want.items() if k in got}, name
        assert {"corner_angle", "internal", "catalogue", "points"} <= set(got), name
    api = rank.__kwdefaults__
    assert (api["top"], api["tie_break"], api["prune"]) == (defaults.DEFAULT_TOP, defaults.DEFAULT_TIE_BREAK, True)


def test_score_bad_shape_with_the_geometric_tie_break_exits_cleanly(tmp_path):
    """A shape with two points, default options: one clear line naming the file, exit 2."""
    bad = tmp_path / "bad.json"
    bad.write_text('{"boundary": [[0, 0], [1, 1]]}')
    r = run("score", bad)
    assert r.returncode == 2 and str(bad) in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_score_many_unmatchable_in_a_worker(small_cat, tmp_path, jobs):
    """An unmatchable shape (5 points, meshes of 6 or more boundary vertices) stops the run with
    exit 4 and one line naming the first one (nothing written), or with --skip-bad becomes an
    error record in its place, whichever process scored it."""
    shapes = [EXAMPLES / "square.json", EXAMPLES / "triangle.json", EXAMPLES / "circle.json"]
    out = tmp_path / "r.jsonl"
    args = ["score-many", *shapes, "--catalogue", small_cat, "--internal", "3", "--points", "5", "--out", out, "--jobs", jobs]
    r = run(*args)
    assert r.returncode == 4 and str(EXAMPLES / "square.json") in r.stderr and not out.exists()
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    r = run(*args, "--skip-bad")
    assert r.returncode == 0, r.stderr
    recs = [json.loads(x) for x in out.read_text().splitlines()]
    assert [d["shape"] for d in recs] == [str(s) for s in shapes]
    assert all("no match" in d["error"] for d in recs)
