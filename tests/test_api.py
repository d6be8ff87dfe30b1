"""The Python API (``import jaxmatch``): the README example runs, the exported names are
documented, and the API answers what the command line answers (same defaults)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxmatch
from jaxmatch import api
from jaxmatch.catalogue import store as cm
from jaxmatch.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def readme_example() -> str:
    text = (ROOT / "README.md").read_text()
    found = re.search(r"<!-- api-example -->\s*```python\n(.*?)```", text, re.S)
    assert found, "README lost its Python API example"
    return found.group(1)


def test_readme_python_example_runs(tmp_path, monkeypatch, capsys):
    shutil.copytree(EXAMPLES, tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    exec(compile(readme_example(), "README.md", "exec"), {})
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3
    assert lines[0] == "recursive fewer patches continuations"  # what the README's comment says
    assert lines[1].startswith("(48, 4) 1.0 0 0")
    assert lines[2].startswith("[('k4-")
    import meshio

    back = meshio.read(tmp_path / "lshape.msh")
    assert back.cells_dict["quad"].shape == (48, 4) and "boundary" in back.field_data


def test_exported_names_resolve_and_are_documented():
    assert jaxmatch.__version__
    for name in jaxmatch.__all__:
        obj = getattr(jaxmatch, name)
        if name != "__version__":
            assert (obj.__doc__ or "").strip(), name
    assert {"load_shape", "make_shape", "rank", "place", "choose_mesh", "write_mesh", "mesh", "QuadMesh"} <= set(dir(jaxmatch))
    with pytest.raises(AttributeError):
        jaxmatch.no_such_name  # noqa: B018


def test_import_is_light():
    """``import jaxmatch`` does not load JAX (the first call that scores does)."""
    code = "import sys, jaxmatch; print('jax' in sys.modules, jaxmatch.__version__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120).stdout.split()
    assert out == ["False", jaxmatch.__version__]


@pytest.fixture(scope="module")
def small_cat(tmp_path_factory):
    p = tmp_path_factory.mktemp("cat") / "c3.npz"
    cm.save(cm.generate(3), p)
    return p


def test_api_answers_what_score_answers(small_cat):
    """Same defaults: jaxmatch.rank and 'jaxmatch score --json' (no options beyond the inputs)."""
    shape = jaxmatch.load_shape(EXAMPLES / "tshape.json")
    got = jaxmatch.rank(shape, small_cat)
    r = subprocess.run([sys.executable, "-m", "jaxmatch", "score", str(EXAMPLES / "tshape.json"), "--catalogue", str(small_cat),
                        "--json"], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert r.returncode == 0, r.stderr
    cli = json.loads(r.stdout)
    assert cli["tie_break"] == api.DEFAULT_TIE_BREAK == "geometry" and cli["lattice"] == api.DEFAULT_LATTICE
    assert [m.as_json() for m in got.results] == cli["results"]
    assert len(got.results) == api.DEFAULT_TOP and got.pruned > 0  # the pruned search, as the CLI


@pytest.mark.parametrize("internal, want", [(2, [2]), ("1..2", [1, 2]), ([3, 1], [1, 3]), (None, None)])
def test_sizes_accepted_forms(small_cat, internal, want):
    assert api.check_sizes(cm.load(small_cat), internal) == want


def test_missing_size_names_the_sizes_the_catalogue_has(small_cat):
    with pytest.raises(InputError) as info:
        api.check_sizes(cm.load(small_cat), "2..5")
    msg = str(info.value)
    assert "4..5 internal vertices" in msg and "k = 0..3" in msg and info.value.where is None


def test_place_and_choose_mesh_agree(small_cat):
    shape = jaxmatch.load_shape(EXAMPLES / "lshape.json")
    ranking = jaxmatch.rank(shape, small_cat, internal=3, top=2)
    first = jaxmatch.place(shape, ranking, catalogue=small_cat)
    again = jaxmatch.place(shape, ranking, ranking.results[0], catalogue=small_cat)
    choice = jaxmatch.choose_mesh(shape, small_cat, internal=3)
    assert choice.match.mesh_id == ranking.results[0].mesh_id
    np.testing.assert_allclose(first.xy, choice.placement.xy)
    np.testing.assert_allclose(first.xy, again.xy)
    with pytest.raises(InputError, match="rank 3 is not in the ranking"):
        jaxmatch.place(shape, ranking, 3, catalogue=small_cat)


def test_choose_mesh_quality_band_through_the_api(small_cat):
    """The stairs at k = 3: by default the API, like ``jaxmatch mesh``, places a near-top mesh
    that reaches min scaled Jacobian 0.3 and says which one it passed over; band=0 places the
    ranked mesh."""
    shape = jaxmatch.load_shape(EXAMPLES / "labels" / "shapes" / "stairs.json")
    banded = jaxmatch.choose_mesh(shape, small_cat, internal=3)
    plain = jaxmatch.choose_mesh(shape, small_cat, internal=3, band=0)
    assert plain.passed_over is None and plain.placement.min_scaled_jacobian < 0.3
    assert banded.passed_over[1].mesh_id == plain.match.mesh_id and banded.placement.min_scaled_jacobian >= 0.3


def test_annotation_matches_the_ranking(small_cat):
    shape = jaxmatch.load_shape(EXAMPLES / "lshape.json")
    ann = jaxmatch.annotate_shape(shape, small_cat, internal=3)
    assert ann.symbols == jaxmatch.rank(shape, small_cat, internal=3, top=1).annotation.symbols


def test_huge_coordinates_place_with_finite_areas(small_cat):
    """Regression: coordinates near 1e308 ended in OverflowError; now the largest accepted
    coordinates (1e150) still give finite areas and quality, and larger ones a clear error."""
    pts = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    shape = jaxmatch.make_shape(pts * 4e149)
    pl = jaxmatch.place(shape, jaxmatch.rank(shape, small_cat, internal=2, top=1), catalogue=small_cat)
    assert np.isfinite([pl.region_area, pl.mesh_area, pl.min_scaled_jacobian]).all() and pl.area_ratio > 0
    with pytest.raises(InputError, match="too large"):
        jaxmatch.make_shape(pts * 1e300)


def test_refine_mesh_meets_the_requested_counts(small_cat):
    """``jaxmatch.refine_mesh`` gives exactly the edges asked for per side, and its boundary
    vertices lie on the shape's sides (distances computed here with shapely)."""
    from shapely.geometry import LineString, Point

    shape = jaxmatch.load_shape(EXAMPLES / "square.json")
    choice = jaxmatch.refine_mesh(shape, small_cat, sides=[4, 2, 4, 2])
    mesh = choice.mesh
    assert [len(v) - 1 for v in mesh.side_vertices] == [4, 2, 4, 2]
    outline = LineString(np.vstack([shape.user_points, shape.user_points[:1]]))
    far = max(outline.distance(Point(*mesh.xy[i])) for side in mesh.side_vertices for i in side)
    assert far <= 1e-9 * float(np.ptp(shape.user_points, axis=0).max())


def test_refine_mesh_refuses_an_odd_total(small_cat):
    shape = jaxmatch.load_shape(EXAMPLES / "square.json")
    with pytest.raises(InputError):
        jaxmatch.refine_mesh(shape, small_cat, sides=[3, 2, 2, 2])


def test_mesh_layout_is_one_conforming_mesh(small_cat):
    """Every edge of the merged two-block layout lies in one or two quads (no hanging node)."""
    lm = jaxmatch.mesh_layout(EXAMPLES / "layouts" / "two-blocks.json", small_cat, size=0.5)
    quads = np.asarray(lm.quads)
    e = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2), axis=1)
    _, uses = np.unique(e, axis=0, return_counts=True)
    assert set(uses.tolist()) <= {1, 2} and (uses == 2).any()
