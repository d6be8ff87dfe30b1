"""Corner keeping of rank-1 meshes (jaxmatch.tuning.corners), the measure used to choose lattices."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from jaxmatch.catalogue.store import default_catalogue
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.io.readers import load_shape
from jaxmatch.tuning.corners import corner_fit, corner_report, must_keep_corners

ROOT = Path(__file__).resolve().parents[1]


def test_must_keep_corners_only_changes_corner_skip_weights():
    lat = replace(load_lattice("fine"), skip=(1, -3, -4))
    m = must_keep_corners(lat)
    assert m.skip[0] == 1 and all(math.isinf(x) and x < 0 for x in m.skip[1:])
    assert m.levels == lat.levels and m.forbidden == lat.forbidden


@pytest.mark.parametrize("shape", ["lshape.json", "tshape.json"])
def test_corner_fit_counts_corners_in_the_alignment(shape):
    cat = default_catalogue()
    shp = load_shape(ROOT / "examples" / shape)
    free = corner_fit(shape, shp, cat, replace(load_lattice("fine"), skip=(0, 0, 0)), 3)
    must = corner_fit(shape, shp, cat, must_keep_corners(load_lattice("fine")), 3)
    assert free.corners == must.corners > 0
    assert must.possible and must.kept == must.corners  # -inf corner skips: the top keeps them all
    assert free.possible and 0 <= free.kept <= free.corners


def test_corner_report_summary_matches_its_rows():
    cat = default_catalogue()
    shapes = [(n, load_shape(ROOT / "examples" / f"{n}.json")) for n in ("lshape", "square", "circle")]
    rep = corner_report(shapes, cat, load_lattice("fine"), [1, 2])
    rows = rep["rows"]
    assert all(r["corners"] > 0 for r in rows) and "circle" not in {r["shape"] for r in rows}  # no corners: not counted
    assert rep["cases"] == len(rows) == 4
    assert rep["corners"] == sum(r["corners"] for r in rows)
    assert rep["top_keeps_all"] == sum(r["possible"] and r["kept"] == r["corners"] for r in rows)
    assert len(rep["missed"]) == rep["possible"] - rep["top_keeps_all"]
