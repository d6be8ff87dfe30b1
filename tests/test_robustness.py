"""Numerical robustness: what the ranking does and does not depend on, and clear messages when
nothing matches.

Exactly what is invariant (all of it tested below):

* **Translation and uniform scaling** (scale ``1e-6 .. 1e6``, translations up to 1000 shape
  sizes): coordinates are mapped to the unit box first, so the annotation (codes, ``t``, unit
  positions) is the same up to round-off (``1e-9``), the codes exactly, and hence the whole
  ranking is identical: ids, utilities, rotations, reflections and alignments.
* **Listing the loop from another point, or in the other orientation** (same loop): the shape
  is made counter-clockwise and rotated to its first *listed* corner, so the annotation starts
  at another corner: it is the same sequence of codes and positions shifted cyclically (ties
  in spreading ``s`` points over sides are broken from the lowest corner, not the first). The
  LCS tries every rotation of the mesh, and a cyclic matching can always be read from the
  shape point with the smallest index, so utilities, and with them the ids in ranked order,
  are identical. Rotation, reflection and alignment are one optimal matching each; they need
  not be the *same* optimal matching (ties between matchings are broken by index), so the
  test moves each matching through the index shift and checks that it is optimal for the
  other listing too.
* **A loop without corners** starts at its lowest point whatever the listing, so its
  annotation (all ``s``, evenly spaced) and its whole ranking are identical.

Catalogue: ``jaxmatch.catalogue.store.generate(3)`` (112 meshes, boundary lengths 4..22).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from jaxmatch.catalogue import store as cm
from jaxmatch.errors import InputError, UnmatchableError
from jaxmatch.scoring.lattice import ALL_TRIPLES, Lattice, Level, load_lattice, save_lattice
from jaxmatch.api import rank
from jaxmatch.scoring.exact import utility_of
from jaxmatch.shape import annotate, make_shape

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
N = settings.default.max_examples


def few(fraction: float) -> settings:
    return settings(max_examples=max(6, int(N * fraction)), deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    path = tmp_path_factory.mktemp("cat") / "c3.npz"
    cm.save(cm.generate(3), path)
    cat = cm.load(path)
    vals = {str(i): v for b in cat.buckets() for i, v in zip(b.ids, b.valences)}
    return path, cat, load_lattice("fine"), vals


# ---------------------------------------------------------------------------------------------
# polygons: small, integer coordinates (exact in every listing), many ties


@st.composite
def polygons(draw):
    """(points, corners): a star-shaped or an orthogonal 'histogram' polygon with integer
    coordinates, some sides split by collinear points, optionally explicit corners."""
    if draw(st.booleans()):
        k = draw(st.integers(3, 8))
        steps = sorted(draw(st.lists(st.integers(0, 23), min_size=k, max_size=k, unique=True)))
        radii = draw(st.lists(st.integers(2, 8), min_size=k, max_size=k))
        pts = [[round(2 * r * math.cos(s * math.pi / 12)), round(2 * r * math.sin(s * math.pi / 12))] for s, r in zip(steps, radii)]
    else:
        k = draw(st.integers(1, 4))
        widths = draw(st.lists(st.integers(1, 3), min_size=k, max_size=k))
        heights = draw(st.lists(st.integers(1, 4), min_size=k, max_size=k))
        xs = np.concatenate([[0], np.cumsum(widths)])
        pts = [[0, 0], [int(xs[-1]), 0]]
        for i in reversed(range(k)):
            pts += [[int(xs[i + 1]), heights[i]], [int(xs[i]), heights[i]]]
        pts = [p for i, p in enumerate(pts) if p != pts[i - 1]] if len(pts) > 1 else pts
        pts = [[2 * x, 2 * y] for x, y in pts]
    out = []
    for i, p in enumerate(pts):
        out.append(p)
        if draw(st.integers(0, 3)) == 0:  # a collinear point in the middle of the side
            q = pts[(i + 1) % len(pts)]
            if (p[0] + q[0]) % 2 == 0 and (p[1] + q[1]) % 2 == 0:
                out.append([(p[0] + q[0]) // 2, (p[1] + q[1]) // 2])
    corners = None
    if draw(st.integers(0, 3)) == 0:
        corners = sorted(draw(st.lists(st.integers(0, len(out) - 1), min_size=1, max_size=len(out), unique=True)))
    try:
        make_shape(out, corners)
    except InputError:
        assume(False)
    return np.array(out, float), corners


def relisted(pts, corners, start: int, reverse: bool):
    """The same loop listed from ``pts[start]``, optionally in the other orientation."""
    n = len(pts)
    order = [(start + i) % n for i in range(n)]
    if reverse:
        order = order[::-1]
    new = [order.index(c) for c in corners] if corners is not None else None
    return pts[order], new


def cyclic_shift(a, b, m) -> int:
    """The shift ``s`` with ``b.codes == roll(a.codes, -s)`` and the same user positions."""
    for s in range(m):
        if np.array_equal(np.roll(a.codes, -s), b.codes) and np.allclose(np.roll(a.user, -s, axis=0), b.user, atol=1e-9):
            return s
    raise AssertionError(f"not a cyclic shift: {a.symbols} vs {b.symbols}")


class Ann:
    def __init__(self, shape, m):
        self.ann = annotate(shape, m)
        self.codes, self.symbols = self.ann.codes, self.ann.symbols
        self.user = shape.to_user(self.ann.positions)


def transform(pts, log_scale, shift):
    scale = 10.0**log_scale
    size = np.ptp(pts, axis=0).max()
    return pts * scale + np.asarray(shift) * size * scale


# ---------------------------------------------------------------------------------------------
# translation and scaling


@few(1.0)
@given(poly=polygons(), log_scale=st.floats(-6, 6), shift=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)),
       extra=st.integers(0, 30))
def test_annotation_invariant_under_translation_and_scale(poly, log_scale, shift, extra):
    pts, corners = poly
    a = make_shape(pts, corners)
    b = make_shape(transform(pts, log_scale, shift), corners)
    assert b.n_corners == a.n_corners
    np.testing.assert_array_equal(b.corners, a.corners)
    np.testing.assert_array_equal(b.convex, a.convex)
    np.testing.assert_allclose(b.points, a.points, atol=1e-9)
    m = max(a.n_corners, 1) + extra
    x, y = annotate(a, m), annotate(b, m)
    np.testing.assert_array_equal(y.codes, x.codes)
    np.testing.assert_allclose(y.t, x.t, atol=1e-9)
    np.testing.assert_allclose(y.positions, x.positions, atol=1e-9)


def ranking(shape, small, points=None):
    _, cat, lat, _ = small
    r = rank(shape, cat, lat, top=10_000, points=points, tie_break="id")
    return r, [(m.mesh_id, m.utility, m.rotation, m.reflected, tuple(m.alignment.tolist())) for m in r.results]


@few(0.2)
@given(poly=polygons(), log_scale=st.floats(-6, 6), shift=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)))
def test_ranking_identical_under_translation_and_scale(small, poly, log_scale, shift):
    pts, corners = poly
    _, want = ranking(make_shape(pts, corners), small)
    _, got = ranking(make_shape(transform(pts, log_scale, shift), corners), small)
    assert got == want


@pytest.mark.parametrize("log_scale", [-6, -3, 0, 3, 6])
def test_examples_identical_at_every_scale(small, log_scale):
    for name in ("lshape.json", "tshape.json", "curved.json"):
        import json

        doc = json.loads((EXAMPLES / name).read_text())
        pts = np.array(doc["boundary"], float)
        base = make_shape(pts, doc.get("corners"))
        moved = make_shape(transform(pts, log_scale, (123.0, -45.0)), doc.get("corners"))
        assert annotate(moved, 30).symbols == annotate(base, 30).symbols


# ---------------------------------------------------------------------------------------------
# listing start and orientation


@few(1.0)
@given(poly=polygons(), data=st.data())
def test_annotation_is_shifted_cyclically_by_relisting(poly, data):
    pts, corners = poly
    start = data.draw(st.integers(0, len(pts) - 1))
    reverse = data.draw(st.booleans())
    a = make_shape(pts, corners)
    b = make_shape(*relisted(pts, corners, start, reverse))
    assert b.n_corners == a.n_corners and sorted(b.convex.tolist()) == sorted(a.convex.tolist())
    m = max(a.n_corners, 1) + data.draw(st.integers(0, 30))
    x, y = Ann(a, m), Ann(b, m)
    s = cyclic_shift(x, y, m)
    if a.n_corners == 0:  # smooth loops start at their lowest point: no shift at all
        assert s == 0


def transported(match, vals, shift, m):
    """``match`` (for the listing B) as a matching of listing A, where B's point i is A's point
    ``(i + shift) % m``: (rotation, reflected, alignment) in A's indices."""
    n = len(vals)
    idx = (np.asarray(match.alignment) + shift) % m
    j0 = int(np.argmin(idx))
    return (match.rotation + j0) % n, match.reflected, np.roll(idx, -j0)


@few(0.2)
@given(poly=polygons(), data=st.data())
def test_ranking_invariant_under_relisting(small, poly, data):
    pts, corners = poly
    start = data.draw(st.integers(0, len(pts) - 1))
    reverse = data.draw(st.booleans())
    a = make_shape(pts, corners)
    b = make_shape(*relisted(pts, corners, start, reverse))
    points = data.draw(st.sampled_from([None, max(a.n_corners, 4) + data.draw(st.integers(0, 6))]))
    try:
        ra, want = ranking(a, small, points)
    except UnmatchableError:
        with pytest.raises(UnmatchableError):
            ranking(b, small, points)
        return
    rb, got = ranking(b, small, points)
    assert [g[:2] for g in got] == [w[:2] for w in want]  # ids and utilities, in order
    m = len(ra.annotation.codes)
    x, y = Ann(a, m), Ann(b, m)
    s = cyclic_shift(x, y, m)
    _, _, _, vals = small
    table = small[2]  # the lattice: utility_of includes its skip weights
    for mb in rb.results:  # every matching of B, moved to A, is optimal there too
        rot, refl, align = transported(mb, vals[mb.mesh_id], s, m)
        assert np.all(np.diff(align) > 0)
        assert utility_of(ra.annotation.codes, vals[mb.mesh_id], table, rot, refl, align) == mb.utility
    if a.n_corners == 0:
        assert got == want


def test_smooth_loop_is_identical_from_any_start(small):
    import json

    pts = np.array(json.loads((EXAMPLES / "circle.json").read_text())["boundary"], float)
    _, want = ranking(make_shape(pts), small)
    for start in (1, 7, 13):
        for reverse in (False, True):
            shape = make_shape(relisted(pts, None, start, reverse)[0])
            np.testing.assert_allclose(shape.user_points[0], [0, -1], atol=1e-6)
            _, got = ranking(shape, small)
            assert got == want


# ---------------------------------------------------------------------------------------------
# straight runs: round-off must not make corners or flip their convexity


@few(0.5)
@given(log_scale=st.floats(-6, 6), shift=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)), k=st.integers(2, 7))
def test_explicit_corners_on_straight_runs_are_convex_at_any_scale(log_scale, shift, k):
    """A parallelogram with k points on its slanted bottom side, all of them explicit corners."""
    bottom = [[3 * i / k, i / k] for i in range(k)]
    pts = np.array(bottom + [[3, 1], [3, 3], [0, 2]])
    corners = list(range(len(pts)))
    shape = make_shape(transform(pts, log_scale, shift), corners)
    assert shape.convex.all()
    assert annotate(shape, len(pts) + 4).symbols.count("v") == 0


@few(0.5)
@given(log_scale=st.floats(-6, 6), shift=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)), k=st.integers(2, 7))
def test_corner_angle_zero_never_takes_straight_points(log_scale, shift, k):
    pts = np.array([[3 * i / k, i / k] for i in range(k)] + [[3, 1], [3, 3], [1.5, 2.5], [0, 2]])
    shape = make_shape(transform(pts, log_scale, shift), corner_angle=0.0)
    assert shape.n_corners == 4


# ---------------------------------------------------------------------------------------------
# nothing matches: say why and which option to change


def x_forbidding_lattice(path) -> Path:
    """The fine lattice, except that a convex corner 'x' accepts no triple that occurs."""
    fine = load_lattice("fine")
    keep = fine.weeded[1][0]  # the only level: a triple no catalogue mesh has
    forbidden = tuple(t for t in ALL_TRIPLES if t not in fine.weeded[1])
    weeded = tuple(t for t in fine.weeded[1] if t != keep)
    lat = Lattice(name="no-x", levels=(fine.levels[0], (Level(0, (keep,)),), fine.levels[2]),
                  weeded=(fine.weeded[0], weeded, fine.weeded[2]), forbidden=(fine.forbidden[0], forbidden, fine.forbidden[2]))
    save_lattice(lat, path)
    assert load_lattice(path).table()[1].max() == 0
    return path


def test_unmatchable_too_few_points(small):
    _, cat, lat, _ = small
    shape = make_shape([[0, 0], [1, 0], [1, 1], [0, 1]])
    with pytest.raises(UnmatchableError) as exc:
        rank(shape, cat, lat, internal=[3], points=5, tie_break="id")
    msg = str(exc.value)
    assert "more boundary vertices (6+)" in msg and "(5)" in msg and "at least 22 points" in msg and "\n" not in msg
    assert "--" not in msg and exc.value.cause == "points" and exc.value.points == 22  # the CLI adds the option


def test_unmatchable_all_corners_forbidden(small, tmp_path):
    _, cat, _, _ = small
    lat = load_lattice(x_forbidding_lattice(tmp_path / "no-x.toml"))
    shape = make_shape([[0, 0], [1, 0], [1, 1], [0, 1]])
    with pytest.raises(UnmatchableError) as exc:  # the single quad must put a vertex on every corner
        rank(shape, cat, lat, internal=[0], points=4, tie_break="id")
    msg = str(exc.value)
    assert "forbidden" in msg and "4 convex" in msg and "'no-x'" in msg
    assert "points" in msg and "mesh sizes" in msg and "lattice" in msg and "\n" not in msg
    assert "--" not in msg and exc.value.cause == "forbidden"  # the CLI adds the options
    # with enough straight points the corners can be skipped: it matches
    assert rank(shape, cat, lat, internal=[0], tie_break="id").results


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "jaxmatch.cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT,
                          timeout=300, env={**os.environ, "JAX_PLATFORMS": "cpu"})


@pytest.mark.parametrize("case", ["too few points", "corners forbidden"])
def test_cli_unmatchable_exit_4_with_reason(small, tmp_path, case):
    path = small[0]
    if case == "too few points":
        r = run_cli("score", EXAMPLES / "square.json", "--catalogue", path, "--internal", "3", "--points", "5")
        needles = ["more boundary vertices", "raise --points"]
    else:
        lat = x_forbidding_lattice(tmp_path / "格子 no-x.toml")
        r = run_cli("score", EXAMPLES / "square.json", "--catalogue", path, "--internal", "0", "--points", "4", "--lattice", lat)
        needles = ["forbidden", "lattice 'no-x'", "--points", "--internal"]
    assert r.returncode == 4, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert lines[0].startswith("no match: ")
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
