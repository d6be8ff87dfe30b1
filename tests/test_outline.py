"""A region as read, before make_shape (jaxmatch.io.outline): repeated points merged with one
warning, dense outlines simplified with one warning saying how many points were kept (corners
kept, the region valid), the limit kept for what cannot be simplified, and the formats a file's
name selects.

Independent checks: corners of the traced outline are known (they are where it was traced
from); areas by shapely on the points as written; the mesh's area by the shoelace formula.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import shapely

import jaxmatch
from jaxmatch.errors import EXIT_BAD_INPUT, InputError, InputWarning
from jaxmatch.io.outline import MAX_SIMPLIFY, Outline, tidy
from jaxmatch.io.readers import detect_format, parse_shape
from jaxmatch.quality import quad_areas
from jaxmatch.shape import MAX_POINTS, make_shape

ROOT = Path(__file__).resolve().parents[1]
L_CORNERS = np.array([[0, 0], [100, 0], [100, 40], [40, 40], [40, 100], [0, 100]], float)


def said(call):
    """(result, the InputWarnings' texts) of ``call()``."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", InputWarning)
        out = call()
    return out, [str(w.message) for w in caught if issubclass(w.category, InputWarning)]


def traced(n: int, noise: float, seed: int = 0) -> np.ndarray:
    """``n`` points along the L's outline, evenly by arc length, each moved by up to ``noise``
    across it (a traced outline's jitter; none at the corners, which are traced points)."""
    ring = np.vstack([L_CORNERS, L_CORNERS[:1]])
    seg = np.hypot(*np.diff(ring, axis=0).T)
    t = np.linspace(0, seg.sum(), n, endpoint=False)
    t = np.union1d(t, np.concatenate([[0], np.cumsum(seg)[:-1]]))[:n]
    k = np.searchsorted(np.cumsum(seg), t, side="right")
    u = (t - np.concatenate([[0], np.cumsum(seg)[:-1]])[k]) / seg[k]
    d = (ring[k + 1] - ring[k]) / seg[k, None]
    pts = ring[k] + (u * seg[k])[:, None] * d
    jitter = np.random.default_rng(seed).uniform(-noise, noise, len(t)) * (u > 0)
    return pts + jitter[:, None] * np.c_[-d[:, 1], d[:, 0]]


# ---------------------------------------------------------------------------------------------
# repeated points


@pytest.mark.parametrize("boundary, merged", [
    ([[0, 0], [1, 0], [1, 0], [1, 1], [0, 1]], 1),  # exactly repeated
    ([[0, 0], [1, 0], [1, 1e-10], [1, 1], [0, 1], [0, 1]], 2),  # closer than 1e-9 of the size, and a repeat
    ([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0], [0, 0]], 1),  # the closing point twice
])
def test_repeated_points_are_merged_with_one_warning(boundary, merged):
    shape, notes = said(lambda: parse_shape(json.dumps({"boundary": boundary}).encode(), "r.json"))
    assert shape.n_points == 4 and shape.n_corners == 4
    assert notes == [f"r.json: merged {merged} repeated point{'s' if merged > 1 else ''} (equal to the one before or "
                     "closer than 1e-09 of the part's size)"]


def test_corners_follow_the_merged_points_and_near_points_keep_their_error():
    doc = {"boundary": [[0, 0], [2, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], "corners": [0, 2, 3, 4, 5, 6]}
    shape, _ = said(lambda: parse_shape(json.dumps(doc).encode(), "c.json"))
    np.testing.assert_array_equal(shape.given_points[shape.corners], make_shape(np.delete(doc["boundary"], 2, axis=0)).given_points[
        make_shape(np.delete(doc["boundary"], 2, axis=0)).corners])
    with pytest.raises(InputError, match="repeated consecutive points 1 and 2"):  # the Python API stays strict
        make_shape(doc["boundary"])
    with pytest.raises(InputError, match="crosses or touches itself"):  # 1e-7 apart: a fold, not a repeat
        parse_shape(json.dumps({"boundary": [[0, 0], [1, 0], [1 - 1e-7, 0], [1, 1], [0, 1]]}).encode(), "f.json")


# ---------------------------------------------------------------------------------------------
# dense outlines


def test_a_100000_point_traced_outline_meshes_with_the_note(tmp_path):
    pts = traced(100_000, noise=1e-4)
    path = tmp_path / "traced.csv"
    path.write_text("x,y\n" + "\n".join(f"{x!r},{y!r}" for x, y in pts.tolist()))
    shape, notes = said(lambda: jaxmatch.load_shape(path))
    assert len(notes) == 1
    kept = int(re.fullmatch(rf"{re.escape(str(path))}: outline of 100000 points simplified: (\d+) kept \(each point "
                            r"left out within \S+ of it, \S+ of the part's size\)", notes[0]).group(1))
    assert kept == shape.n_points <= MAX_POINTS
    tol = float(re.search(r"within (\S+) of it", notes[0]).group(1))
    assert tol <= MAX_SIMPLIFY * 100
    assert shapely.LineString(np.vstack([shape.given_points, shape.given_points[:1]])).hausdorff_distance(
        shapely.LineString(np.vstack([pts, pts[:1]]))) <= tol * 1.01
    for c in L_CORNERS:  # every corner kept
        assert np.min(np.hypot(*(shape.given_points - c).T)) == 0.0
    m = jaxmatch.mesh(shape, size=5.0)
    assert float(quad_areas(m.xy, m.quads).sum()) == pytest.approx(shapely.Polygon(pts).area, rel=0.01)
    assert all(np.min(np.hypot(*(m.xy - c).T)) <= 1e-9 * 100 for c in L_CORNERS)  # a vertex at each corner


def test_a_region_with_holes_stays_valid_when_simplified():
    a = np.linspace(0, 2 * np.pi, 30_000, endpoint=False)
    outer = np.c_[50 + 50 * np.cos(a), 50 + 50 * np.sin(a)]
    hole = np.c_[50 + 49.9 * np.cos(a[::3]), 50 + 49.9 * np.sin(a[::3])]  # 0.1 inside: simplifying must not cross
    out, notes = said(lambda: tidy(Outline(outer, None, (hole,)), "w.json"))
    assert len(notes) == 1 and "outline of 40000 points simplified" in notes[0]
    poly = shapely.Polygon(out.points, list(out.holes))
    assert poly.is_valid and len(out.points) <= MAX_POINTS and len(out.holes) == 1


def test_an_outline_that_cannot_be_simplified_keeps_the_limit():
    a = np.linspace(0, 2 * np.pi, 12_000, endpoint=False)
    r = np.where(np.arange(12_000) % 2 == 0, 1.0, 0.5)  # a star of 6,000 spikes: every point a corner
    with pytest.raises(InputError, match=r"s\.json: a loop has 12000 points, more than the maximum 10000, and still 1\d{4} "
                                         r"simplified within 0\.00128 of the part's size"):
        parse_shape(json.dumps({"boundary": np.c_[r * np.cos(a), r * np.sin(a)].tolist()}).encode(), "s.json")


# ---------------------------------------------------------------------------------------------
# formats by name


@pytest.mark.parametrize("name, head, fmt", [
    ("a.stp", b"", "step"), ("a.STEP", b"", "step"), ("a.igs", b"", "iges"), ("a.iges", b"", "iges"), ("a.brep", b"", "brep"),
    ("a.xyz", b"", "text"), ("a.xy", b"", "text"), ("part", b"ISO-10303-21;\nHEADER;", "step"),
    ("a.weird", b"<svg/>", "svg"), ("a.weird", b'{"boundary": []}', "json"),
])
def test_formats_by_name_then_content(name, head, fmt):
    assert detect_format(name, head) == fmt


@pytest.mark.parametrize("name, head", [
    ("part.sldprt", bytes(range(256))),  # binary
    ("part.points", b"0 0\n1 0\n0 1\n"),  # rows, but not of a text suffix
    ("part", b"\x00\x01\x02garbage"),
])
def test_unknown_formats_are_named(name, head):
    with pytest.raises(InputError) as info:
        detect_format(name, head)
    suffix = Path(name).suffix
    assert str(info.value).startswith(f"{name}: unsupported format {repr(suffix) if suffix else '(a binary file'}")
    assert "supported: .json, .geojson, .txt, .csv, .tsv, .xy, .xyz, .dat, .svg, .dxf, .step, .stp, .iges, .igs, .brep" \
        in str(info.value)


def test_cli_names_an_unsupported_file_in_one_line(tmp_path):
    part = tmp_path / "part.sldprt"
    part.write_bytes(bytes(range(256)) * 4)
    run = subprocess.run([sys.executable, "-m", "jaxmatch", "mesh", str(part)], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == EXIT_BAD_INPUT
    assert run.stderr.strip().startswith(f"error: {part}: unsupported format '.sldprt'; supported: .json,")
    assert len(run.stderr.strip().splitlines()) == 1
