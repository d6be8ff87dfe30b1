"""scripts/corner_placements.py: the exhaustive search that says whether *any* catalogue mesh of a
size can be placed with every corner kept, no fold and min scaled Jacobian >= 0.3 (the evidence
behind the placement table's "no mesh can" rows)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"


@pytest.fixture(scope="module")
def search():
    spec = importlib.util.spec_from_file_location("corner_placements", ROOT / "scripts" / "corner_placements.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.search


def test_a_square_takes_the_single_quad_perfectly(search):
    r = search(EXAMPLES / "square.json", 0)
    assert r["meshes"] == 1 and r["passes"] and r["best_fold_free"]["min_sj"] == pytest.approx(1.0)
    assert r["placements"] == 2 * 4 * 2  # 4 rotations x 2 mirror images, each plain and sliding


def test_no_single_quad_fits_a_triangle(search):
    """Three corners on four vertices: the fourth sits on a side (a 180 degree corner)."""
    r = search(EXAMPLES / "triangle.json", 0)
    assert r["placements"] > 0 and not r["passes"]
    assert r["best_fold_free"] is None or r["best_fold_free"]["min_sj"] < 1e-6


@pytest.mark.slow
def test_no_mesh_with_one_internal_vertex_fits_the_u_without_folding(search):
    r = search(EXAMPLES / "labels" / "shapes" / "ushape.json", 1)
    assert r["meshes"] >= 1 and r["placements"] > 1000 and r["best_fold_free"] is None and not r["passes"]


@pytest.mark.slow
def test_the_stairs_at_one_internal_vertex_can_pass(search):
    """Which is why the quality band's last resort (other orientations) exists."""
    r = search(EXAMPLES / "labels" / "shapes" / "stairs.json", 1)
    assert r["passes"] and r["best_fold_free"]["min_sj"] >= 0.3
