"""Pictures: files are written atomically with valid PNG/SVG content; the drawing shows what
it should (legend entries, quality in the title, inverted quads in red)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from jaxmatch.placement.embed import arc_lengths, place
from jaxmatch.errors import InputError
from jaxmatch.catalogue.mesh import boundary_valences, from_quads
from jaxmatch.io.plot import Panel, draw_many, draw_match, new_figure, quality_line, save_figure
from jaxmatch.meshing.build import from_placement

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def grid(nx, ny):
    vid = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    q = [[vid[j, i], vid[j, i + 1], vid[j + 1, i + 1], vid[j + 1, i]] for j in range(ny) for i in range(nx)]
    return from_quads(q)


def star(k):
    return from_quads([[0, 1 + i, 1 + k + i, 1 + (i + 1) % k] for i in range(k)])


def l_outline():
    corners = np.array([(0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2)], float)
    pts = np.concatenate([corners[i] + (corners[(i + 1) % 6] - corners[i]) * np.linspace(0, 1, 7)[:-1, None] for i in range(6)])
    codes = np.zeros(len(pts), int)
    codes[[0, 6, 12, 24, 30]] = 1
    codes[18] = 2
    return pts, codes


def l_match(**kw):
    """A 3x3 grid in an L (concave corner on a valence-3 vertex); Tutte alone folds it."""
    pts, codes = l_outline()
    t = arc_lengths(pts)[:-1]
    pl = place(pts, t, np.array([0, 2, 4, 6, 8, 10, 12, 18, 21, 24, 30, 33]), grid(3, 3), 0, False, **kw)
    return Panel(pts, pts, codes, from_placement(None, pl), "L, 3x3 grid")


def star_match(k=5, reflected=False):
    ang = np.pi / 2 + 2 * np.pi * np.arange(k) / k
    c = np.c_[np.cos(ang), np.sin(ang)]
    pts = np.concatenate([c[i] + (c[(i + 1) % k] - c[i]) * np.linspace(0, 1, 5)[:-1, None] for i in range(k)])
    codes = np.where(np.arange(len(pts)) % 4 == 0, 1, 0)
    t = arc_lengths(pts)[:-1]
    mesh = star(k)
    s = boundary_valences(mesh)[::-1] if reflected else boundary_valences(mesh)
    rot = int(np.flatnonzero(s == 2)[0])  # a corner (valence 2) first in matched order
    pl = place(pts, t, 2 * np.arange(2 * k), mesh, rot, reflected)
    assert pl.inverted == 0
    return Panel(pts, pts, codes, from_placement(None, pl), f"valence-{k} star")


@pytest.fixture(scope="module")
def panels():
    bad = l_match(smooth_iters=0)
    assert bad.mesh.inverted > 0
    good = l_match()
    assert good.mesh.inverted == 0
    return {"good": good, "bad": bad, "star": star_match()}


def draw_one(panel) -> tuple[Figure, object]:
    fig, (ax,) = new_figure(1)
    draw_match(ax, panel.points, panel.positions, panel.codes, panel.mesh, title=panel.title)
    return fig, ax


def legend_labels(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def test_png_is_written(tmp_path, panels):
    fig, _ = draw_one(panels["good"])
    path = tmp_path / "out" / "match.png"  # parent folder is created
    assert save_figure(fig, path) == path
    data = path.read_bytes()
    assert data.startswith(PNG_MAGIC) and len(data) > 5000
    assert [p.name for p in path.parent.iterdir()] == ["match.png"]


def test_svg_is_valid_xml(tmp_path, panels):
    fig, _ = draw_one(panels["star"])
    path = tmp_path / "match.svg"
    save_figure(fig, path)
    root = ET.fromstring(path.read_bytes())
    assert root.tag.endswith("svg")


def test_legend_and_title_show_valences_codes_and_quality(panels):
    fig, ax = draw_one(panels["star"])
    labels = legend_labels(ax)
    for want in ["s (straight)", "x (convex corner)", "boundary valence 2", "boundary valence 3", "internal valence 5"]:
        assert want in labels
    assert "inverted quad" not in labels
    title = ax.get_title()
    assert title.startswith("valence-5 star\n")
    assert quality_line(panels["star"].mesh) in title and "inverted 0" in title
    fig, ax = draw_one(panels["good"])
    assert "v (concave corner)" in legend_labels(ax)


def test_inverted_quads_are_filled_red(panels):
    m = panels["bad"].mesh
    fig, ax = draw_one(panels["bad"])
    assert "inverted quad" in legend_labels(ax)
    assert f"inverted {m.inverted}" in ax.get_title()
    polys = [c for c in ax.collections if isinstance(c, PolyCollection)]
    assert len(polys) == 1
    colours = polys[0].get_facecolors()
    assert colours.shape[0] == m.quads.shape[0]
    red = (colours[:, 0] > 0.8) & (colours[:, 1] < 0.3)
    assert red.sum() == m.inverted


def test_draw_many_accepts_panels_tuples_and_dicts(tmp_path, panels):
    s = panels["star"]
    items = [
        panels["good"],
        (s.points, s.positions, s.codes, s.mesh),
        dict(points=s.points, positions=s.positions, codes=s.codes, mesh=star_match(3, reflected=True).mesh, title="reflected"),
        panels["bad"],
        star_match(4),
    ]
    path = draw_many(items, tmp_path / "top.png", title="top 5")
    data = path.read_bytes()
    assert data.startswith(PNG_MAGIC)
    svg = draw_many(items[:2], tmp_path / "top.svg", ncols=1)
    assert ET.fromstring(svg.read_bytes()).tag.endswith("svg")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["top.png", "top.svg"]


def test_draw_many_needs_items(tmp_path):
    with pytest.raises(ValueError):
        draw_many([], tmp_path / "x.png")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["match.pdf", "match", "match.jpeg"])
def test_bad_suffix_is_input_error(tmp_path, panels, name):
    fig, _ = draw_one(panels["star"])
    with pytest.raises(InputError, match="unknown picture file format"):
        save_figure(fig, tmp_path / name)
    with pytest.raises(InputError, match="unknown picture file format"):
        draw_many([panels["star"]], tmp_path / name)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".png", ".svg"])
def test_failed_save_leaves_nothing(tmp_path, panels, monkeypatch, suffix):
    fig, _ = draw_one(panels["star"])
    path = tmp_path / f"match{suffix}"

    def boom(self, fname, *args, **kwargs):
        with open(fname, "wb") as fh:  # half-written
            fh.write(b"\x89PN")
        raise RuntimeError("renderer died")

    monkeypatch.setattr(Figure, "savefig", boom)
    with pytest.raises(RuntimeError, match="renderer died"):
        save_figure(fig, path)
    assert list(tmp_path.iterdir()) == []
    # an existing picture survives a failed overwrite
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        draw_many([panels["star"]], path)
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_panel_title_keeps_the_whole_mesh_id():
    """Regression: 15-character ids were cut to 14, so an id copied from a picture was not found."""
    from jaxmatch.report import panel_title
    from jaxmatch.scoring.rank import Match

    mesh_id = "k5-b2b65fa5f3b0"
    assert len(mesh_id) == 15
    title = panel_title(1, Match(mesh_id, 5, 12, 24.0, 0, True, np.arange(3), np.zeros((3, 3), int)))
    assert mesh_id in title.split()
    panel = star_match()
    fig, axes = new_figure(1)
    draw_match(axes[0], panel.points, panel.positions, panel.codes, panel.mesh, title)
    assert mesh_id in axes[0].get_title().split()
