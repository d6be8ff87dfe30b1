"""Automatic sizing (:mod:`jaxmatch.autosize`): the size field of a part's own features.

Specification (sizes checked against geometry computed here, independently):

* a part thinner than the size ``H`` asks for its thickness (one element across) along it;
* a curved stretch of radius ``r`` asks for ``r * 30 degrees``; a small hole for a ring of 8 edges;
* a part without such features keeps its uniform size: the same mesh as without ``auto_size``;
* meshed with ``auto_size``, a thin fin gets about square cells, and where it does not apply the
  request is a one-line error.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import jaxmatch
from jaxmatch.autosize import ARC_ANGLE, RING_EDGES, auto_field, feature_sizes
from jaxmatch.errors import EXIT_BAD_INPUT, InputError
from jaxmatch.shape import make_shape

ROOT = Path(__file__).resolve().parent.parent


def circle(cx, cy, r, n, cw=False):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    p = np.c_[cx + r * np.cos(t), cy + r * np.sin(t)]
    return p[::-1] if cw else p


@pytest.mark.parametrize("thick", [0.5, 1.0, 2.0])
def test_a_thin_strip_asks_for_its_thickness(thick):
    shp = make_shape([[0, 0], [20, 0], [20, thick], [0, thick]])
    H = 4.0
    feats = feature_sizes(shp, H)
    assert feats, "a strip thinner than H has a feature"
    assert min(s for _, s in feats) == pytest.approx(thick, rel=1e-6)
    for poly, s in feats:  # on the strip's long sides, where it is that thin
        assert np.all((np.abs(poly[:, 1]) < 1e-9) | (np.abs(poly[:, 1] - thick) < 1e-9))


def test_a_wide_square_has_no_feature_and_keeps_its_mesh():
    shp = make_shape([[0, 0], [1, 0], [1, 1], [0, 1]])
    assert feature_sizes(shp, 0.25) == [] and auto_field(shp, 0.25) is None
    a, b = jaxmatch.mesh(shp, size=0.25), jaxmatch.mesh(shp, size=0.25, auto_size=True)
    assert np.array_equal(a.xy, b.xy) and np.array_equal(a.quads, b.quads)


@pytest.mark.parametrize("r", [1.0, 2.5])
def test_a_curved_outline_asks_for_its_radius_times_the_arc_angle(r):
    shp = make_shape(circle(0, 0, r, 180))
    H = 10 * r
    s = min(s for _, s in feature_sizes(shp, H))
    assert s == pytest.approx(r * math.radians(ARC_ANGLE), rel=0.01)


def test_a_small_hole_asks_for_a_ring_of_edges():
    sq = [[-2, -2], [2, -2], [2, 2], [-2, 2]]
    hole = [[-0.2, -0.2], [-0.2, 0.2], [0.2, 0.2], [0.2, -0.2]]  # square: no curvature, perimeter 1.6
    shp = make_shape(sq, holes=[hole])
    H = 1.0
    feats = feature_sizes(shp, H)
    ring = [s for poly, s in feats if len(poly) == 5 and np.allclose(poly[0], poly[-1])]
    assert ring == [pytest.approx(1.6 / RING_EDGES)]


def test_a_fin_meshed_with_auto_size_gets_about_square_cells():
    """A plate with one fin 1 thick and 10 long at H = 4: without automatic sizing the fin is one
    element across of cells up to 4 long; with it, no edge of the fin's cells is longer than 2
    (twice its thickness)."""
    outline = [[0, 0], [12, 0], [12, 4], [6.5, 4], [6.5, 14], [5.5, 14], [5.5, 4], [0, 4]]
    shp = make_shape(outline)
    m = jaxmatch.mesh(shp, size=4.0, auto_size=True)
    assert m.valid and m.min_scaled_jacobian > 0.5
    fin = m.xy[m.quads].mean(axis=1)[:, 1] > 4.5  # quads in the fin
    e = m.xy[m.quads[fin]] - m.xy[np.roll(m.quads[fin], -1, axis=1)]
    assert fin.any() and np.linalg.norm(e, axis=2).max() <= 2.0 + 1e-9
    plain = jaxmatch.mesh(shp, size=4.0)
    pfin = plain.xy[plain.quads].mean(axis=1)[:, 1] > 4.5
    assert fin.sum() > pfin.sum()


def test_auto_size_adds_to_a_field_and_refuses_where_it_does_not_apply(tmp_path):
    shp = make_shape([[0, 0], [20, 0], [20, 1], [0, 1]])
    user = jaxmatch.Field(4.0, [jaxmatch.Near("point", [10, 0.5], 0.5, 2.0)])
    f = auto_field(shp, 4.0, user)
    assert f.near[0] == user.near[0] and len(f.near) > 1 and f.size == 4.0
    with pytest.raises(InputError, match="automatic sizing"):
        jaxmatch.mesh(shp, sides=[4, 2, 4, 2], auto_size=True)
    with pytest.raises(InputError, match="callable"):
        jaxmatch.mesh(shp, size=lambda p: np.full(len(p), 1.0), auto_size=True)
    src = tmp_path / "s.json"
    src.write_text(json.dumps({"boundary": [[0, 0], [20, 0], [20, 1], [0, 1]]}))
    p = subprocess.run([sys.executable, "-m", "jaxmatch", "mesh", str(src), "--template", "--auto-size"],
                       capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == EXIT_BAD_INPUT and "--auto-size" in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1
