"""Pictures of meshes: a placed template over the shape and its s/x/v annotation
(:func:`draw_match`, :func:`draw_in_shape`), and meshes of a region by patch (:func:`draw_meshes`,
:func:`draw_quadmesh`). Every mesh drawn is a :class:`~jaxmatch.meshing.result.QuadMesh` (the
type the writers take too; ``QuadMesh`` is only named here, this low layer imports no meshing).

Drawing uses :class:`matplotlib.figure.Figure` directly (Agg canvas, no pyplot, no display,
no global state). Colours follow the paper's figures in spirit: each boundary valence
(2, 3, 4, 5) has its own colour, so a good match shows low valences at the shape's convex
corners and high valences at its concave corners.
"""

from __future__ import annotations

import math
import os
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Iterable, Sequence

import numpy as np
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from jaxmatch.catalogue.mesh import edges, valences
from jaxmatch.errors import InputError
from jaxmatch.files import atomic_path
from jaxmatch.io import registry
from jaxmatch.quality import inverted_mask, quality

if TYPE_CHECKING:  # pragma: no cover - the type only (io stays below meshing)
    from jaxmatch.meshing.result import QuadMesh

__all__ = [
    "CODE_STYLE",
    "FIGURE_FORMATS",
    "Panel",
    "VALENCE_COLOURS",
    "draw_in_shape",
    "draw_many",
    "draw_match",
    "draw_mesh",
    "draw_meshes",
    "draw_quadmesh",
    "figure_format",
    "new_figure",
    "quality_line",
    "size_ratios",
    "save_figure",
]

VALENCE_COLOURS: dict[int, str] = {2: "#1f77b4", 3: "#2ca02c", 4: "#ff7f0e", 5: "#9467bd"}
"""Boundary vertex colour by valence (blue, green, orange, purple); others are grey."""

CODE_STYLE: dict[int, tuple[str, str, str]] = {
    0: ("s (straight)", "o", "#7f7f7f"),
    1: ("x (convex corner)", "X", "#000000"),
    2: ("v (concave corner)", "v", "#8c564b"),
}
"""Annotation code -> (legend label, marker, colour)."""

IRREGULAR_MARKERS: dict[int, str] = {3: "^", 5: "p"}
"""Internal vertex valence -> marker (triangle for 3, pentagon for 5; others a diamond)."""

for _name in ("png", "svg"):
    registry.register_format(_name, "picture", ("." + _name,), writer=_name)
FIGURE_FORMATS: dict[str, str] = registry.suffixes("picture")
"""Picture suffix -> matplotlib format."""

INVERTED_COLOUR = "#d62728"
QUAD_COLOUR = "#dbe9f6"
EDGE_COLOUR = "#1b2a41"
OUTLINE_COLOUR = "#b0b0b0"


@dataclass(frozen=True, eq=False)
class Panel:
    """One match to draw: shape outline ``points (P, 2)``, annotated ``positions (m, 2)`` and
    ``codes (m,)``, the placed template as a :class:`~jaxmatch.meshing.result.QuadMesh`
    (``line_sets["boundary"]`` its boundary loop), and a title."""

    points: np.ndarray
    positions: np.ndarray
    codes: np.ndarray
    mesh: "QuadMesh"
    title: str = ""


def quality_line(mesh: "QuadMesh") -> str:
    """``"min SJ 0.873, mean SJ 0.973, inverted 0"``."""
    return f"min SJ {mesh.min_scaled_jacobian:.3f}, mean SJ {mesh.mean_scaled_jacobian:.3f}, inverted {mesh.inverted}"


def draw_match(
    ax,
    points: np.ndarray,
    annotation_positions: np.ndarray,
    codes: np.ndarray,
    mesh: "QuadMesh",
    title: str | None = None,
    *,
    legend: bool = True,
) -> None:
    """Draw one match on the matplotlib axes ``ax``.

    points: (P, 2) shape outline (closed ccw loop); annotation_positions: (m, 2) and
    codes: (m,) ints (0 s, 1 x, 2 v); mesh: the placed template (same coordinates; its
    ``line_sets["boundary"]`` the boundary loop, edge ``j`` from vertex ``j``).
    Draws the outline, the quads (inverted ones filled red), the mesh edges, the annotated
    points (marker per code), boundary vertices coloured by valence and irregular internal
    vertices (valence 3 triangle, 5 pentagon); the title gets a second line with the quality
    (min / mean scaled Jacobian, inverted count).
    """
    pts = np.asarray(points, dtype=np.float64)
    xy = np.asarray(mesh.xy, dtype=np.float64)
    quads = np.asarray(mesh.quads)
    loop = np.asarray(mesh.line_sets["boundary"])[:, 0]
    val = valences(quads, xy.shape[0])

    # quads: light fill, inverted ones red
    bad = inverted_mask(xy, quads)
    faces = xy[quads]
    ax.add_collection(
        PolyCollection(
            faces,
            facecolors=np.where(bad[:, None], np.array([[0.84, 0.15, 0.16, 0.75]]), np.array([[0.86, 0.91, 0.96, 1.0]])),
            edgecolors="none",
            zorder=1,
        )
    )
    # shape outline
    closed = np.vstack([pts, pts[:1]])
    ax.plot(closed[:, 0], closed[:, 1], color=OUTLINE_COLOUR, lw=3.0, zorder=2, solid_joinstyle="round")
    # mesh edges
    e = edges(quads)
    ax.add_collection(LineCollection(xy[e], colors=EDGE_COLOUR, linewidths=1.0, zorder=3))

    handles = []
    # annotated shape points
    pos = np.asarray(annotation_positions, dtype=np.float64).reshape(-1, 2)
    cds = np.asarray(codes).reshape(-1)
    for code, (label, marker, colour) in CODE_STYLE.items():
        sel = cds == code
        if sel.any():
            ax.scatter(pos[sel, 0], pos[sel, 1], marker=marker, s=22 if code == 0 else 60, c=colour, zorder=4, linewidths=0)
            handles.append(Line2D([], [], ls="", marker=marker, color=colour, label=label))
    # boundary vertices by valence
    bval = val[loop]
    for v in sorted(set(bval.tolist())):
        colour = VALENCE_COLOURS.get(v, "#7f7f7f")
        sel = loop[bval == v]
        ax.scatter(xy[sel, 0], xy[sel, 1], s=70, facecolors="none", edgecolors=colour, linewidths=2.2, zorder=5)
        handles.append(Line2D([], [], ls="", marker="o", mfc="none", mec=colour, mew=2.2, label=f"boundary valence {v}"))
    # irregular internal vertices
    irr = np.asarray(mesh.irregular, dtype=np.int64)
    for v in sorted(set(val[irr].tolist())):
        marker = IRREGULAR_MARKERS.get(v, "D")
        colour = VALENCE_COLOURS.get(v, "#7f7f7f")
        sel = irr[val[irr] == v]
        ax.scatter(xy[sel, 0], xy[sel, 1], marker=marker, s=90, c=colour, edgecolors="k", linewidths=0.8, zorder=6)
        handles.append(Line2D([], [], ls="", marker=marker, color=colour, mec="k", label=f"internal valence {v}"))
    if bad.any():
        handles.append(Line2D([], [], ls="", marker="s", ms=10, color=INVERTED_COLOUR, alpha=0.75, label="inverted quad"))

    both = np.vstack([pts, xy])
    lo, hi = both.min(axis=0), both.max(axis=0)
    pad = 0.06 * float(max(hi - lo)) or 1.0
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)
    head = f"{title}\n" if title else ""
    ax.set_title(head + quality_line(mesh), fontsize=10)
    if legend:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.01), ncol=3, fontsize=7, frameon=False, handletextpad=0.2, columnspacing=0.8)


def new_figure(n_panels: int = 1, ncols: int | None = None, panel_size: float = 4.2) -> tuple[Figure, list]:
    """A figure with ``n_panels`` axes in a grid (at most 4 columns unless ``ncols``).
    Returns ``(figure, axes)``; unused grid cells are hidden."""
    n = max(int(n_panels), 1)
    cols = int(ncols) if ncols else min(n, 4)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(panel_size * cols, (panel_size + 0.9) * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False).ravel().tolist()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def figure_format(path: str | os.PathLike) -> str:
    """The picture format for ``path``'s suffix; :class:`InputError` when not .png/.svg."""
    return registry.find("picture", path=path).name


def save_figure(fig: Figure, path: str | os.PathLike, *, dpi: int = 120) -> Path:
    """Write ``fig`` to ``path`` atomically; format from the suffix (.png or .svg).

    Raises :class:`InputError` for another suffix (nothing written). A failing write leaves
    no file (and no temporary) and keeps a previous file at ``path``. Returns the path.
    """
    fmt = figure_format(path)
    final = Path(path)
    with atomic_path(final) as tmp:
        fig.savefig(tmp, format=fmt, dpi=dpi)
    return final


def _panel(item) -> Panel:
    if isinstance(item, Panel):
        return item
    if isinstance(item, dict):
        return Panel(**item)
    return Panel(*item)


def draw_many(items: Iterable[Panel | Sequence | dict], path: str | os.PathLike, *, ncols: int | None = None, title: str | None = None) -> Path:
    """Draw several matches side by side (one panel each, e.g. the top K) and save to ``path``.

    items: :class:`Panel` objects, or tuples ``(points, positions, codes, mesh[, title])``,
    or dicts with those keys. Returns the path written (atomically, see :func:`save_figure`).
    """
    figure_format(path)  # fail early on a bad suffix
    panels = [_panel(it) for it in items]
    if not panels:
        raise ValueError("draw_many needs at least one match to draw")
    fig, axes = new_figure(len(panels), ncols)
    for ax, p in zip(axes, panels):
        draw_match(ax, p.points, p.positions, p.codes, p.mesh, title=p.title or None)
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


def draw_in_shape(path: str | os.PathLike, shape, annotation, items: Sequence[tuple[str, "QuadMesh"]], *,
                  title: str | None = None, ncols: int | None = None) -> Path:
    """Draw placed templates side by side (one panel per ``(panel title, QuadMesh)``) over the
    shape's outline and annotated s/x/v points, in user coordinates, and save to ``path``
    (.png or .svg, atomically; :func:`draw_many`). shape: the :class:`~jaxmatch.shape.Shape`;
    annotation: its :class:`~jaxmatch.shape.Annotation` (unit-box positions, codes). Each panel
    shows boundary vertices coloured by valence, irregular internal vertices, inverted quads in
    red and the quality (min / mean scaled Jacobian, inverted count) in its title."""
    outline = shape.user_points
    pos = shape.to_user(annotation.positions)
    return draw_many([Panel(outline, pos, annotation.codes, m, t) for t, m in items], path, ncols=ncols, title=title)


# ---------------------------------------------------------------------------------------------
# meshes of a region (the meshing pipeline's QuadMesh, layouts)

PATCH_PALETTE = np.array([[0.80, 0.88, 0.97], [0.98, 0.88, 0.75], [0.83, 0.94, 0.82], [0.94, 0.84, 0.94],
                          [0.98, 0.96, 0.76], [0.85, 0.93, 0.93]])
"""Pale fill colours of the patches (RGB in [0, 1]), repeated."""


def mesh_quality_line(xy: np.ndarray, quads: np.ndarray) -> str:
    """``"240 quads, SJ min 0.812 mean 0.951, 0 inverted"``."""
    sj = quality(xy, quads)[0]
    return (f"{quads.shape[0]} quads, SJ min {sj.min():.3f} mean {sj.mean():.3f}, "
            f"{int(inverted_mask(xy, quads).sum())} inverted")


def _boundary_mask(quads: np.ndarray, n: int) -> np.ndarray:
    e = np.stack([quads, np.roll(quads, -1, axis=1)], -1).reshape(-1, 2)
    uniq, cnt = np.unique(np.sort(e, axis=1), axis=0, return_counts=True)
    on_b = np.zeros(n, bool)
    on_b[uniq[cnt == 1].ravel()] = True
    return on_b


def _mark_and_frame(ax, xy: np.ndarray, irregular: np.ndarray, corners, y_down: bool) -> None:
    """Irregular internal vertices (indices into ``xy (V, 2)``) as red dots and the corners
    ``(C, 2)`` as black squares; equal axes fitted to the data, y down for SVG input, no ticks or
    frame."""
    if irregular.size:
        ax.plot(xy[irregular, 0], xy[irregular, 1], "o", ms=2.5, color="tab:red", zorder=3)
    if corners is not None and len(corners):
        c = np.asarray(corners, np.float64)
        ax.plot(c[:, 0], c[:, 1], "s", ms=2.5, color="k", zorder=3)
    ax.set_aspect("equal")
    ax.autoscale_view()
    if y_down:
        ax.invert_yaxis()
    ax.set_xticks([])
    ax.set_yticks([])
    for spine in ax.spines.values():
        spine.set_visible(False)


def draw_meshes(path: str | os.PathLike, panels: Sequence[tuple], *, title: str | None = None,
                ncols: int | None = None, y_down: bool = False) -> Path:
    """Draw quad meshes side by side and save to ``path`` (.png or .svg, atomically).

    panels: ``(panel title, xy (V, 2), quads (Q, 4), patch (Q,) int or None, lines)``, optionally
    followed by ``corners (C, 2)``: ``lines`` a list of ``(k, 2)`` polylines drawn a little
    thicker (e.g. the sides between patches) or None. Edges are thin lines, quads filled pale by
    patch, inverted quads red; markers only where they mean something: corners (small black
    squares) and irregular internal vertices (small red dots). Aspect ratio kept. y_down: the
    input's y axis points down (SVG), so the picture is flipped to show it as drawn.
    """
    figure_format(path)
    fig, axes = new_figure(len(panels), ncols)
    for ax, panel in zip(axes, panels):
        head, xy, quads, patch, lines = panel[:5]
        corners = panel[5] if len(panel) > 5 else None
        xy = np.asarray(xy, np.float64)
        quads = np.asarray(quads, np.int64)
        face = PATCH_PALETTE[np.asarray(patch) % len(PATCH_PALETTE)] if patch is not None \
            else np.tile(PATCH_PALETTE[0], (quads.shape[0], 1))
        face = np.where(inverted_mask(xy, quads)[:, None], np.array([0.95, 0.3, 0.3]), face)
        ax.add_collection(PolyCollection(xy[quads], facecolors=face, edgecolors="0.3", linewidths=0.35))
        if lines:
            ax.add_collection(LineCollection([np.asarray(line) for line in lines], colors="0.1", linewidths=0.9))
        irr = np.flatnonzero(~_boundary_mask(quads, xy.shape[0]) & (valences(quads, xy.shape[0]) != 4)
                             & np.isin(np.arange(xy.shape[0]), quads))
        _mark_and_frame(ax, xy, irr, corners, y_down)
        ax.set_title(f"{head}\n{mesh_quality_line(xy, quads)}, {irr.size} irregular", fontsize=9)
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


def draw_quadmesh(path: str | os.PathLike, mesh, *, title: str = "", y_down: bool = False,
                  size: tuple[int, int] | None = None, dpi: int | None = None, color: str = "patch",
                  histogram: bool = False) -> Path:
    """Draw one :class:`jaxmatch.meshing.result.QuadMesh` to ``path`` (.png or .svg): its quads
    (pale by patch, or by scaled Jacobian with a colour bar with ``color="quality"``), the
    patches' shared sides a little thicker, its corners (black squares), irregular vertices
    (red dots), inverted quads red; ``histogram`` adds the scaled Jacobians' histogram below.

    size: ``(W, H)`` pixels of the picture, or None: the drawing fitted to the region's aspect
    (4.2 to 9 inches wide); dpi: dots per inch (default 120). The title is wrapped to the
    picture's width, never clipped. y_down: the input's y axis points down (SVG input).
    """
    figure_format(path)
    dpi = int(dpi or 120)
    xy = np.asarray(mesh.xy, np.float64)
    quads = np.asarray(mesh.quads, np.int64)
    sj = np.asarray(mesh.scaled_jacobian, np.float64)
    span = np.ptp(xy, axis=0) if xy.size else np.ones(2)
    aspect = float(span[0] / span[1]) if span[1] > 0 else 1.0
    bar = 0.9 if color in ("quality", "size") else 0.0
    if size is None:
        width = float(np.clip(4.2 * np.sqrt(aspect), 4.2, 9.0)) + bar
        drawing_h = float(np.clip((width - bar) / aspect, 1.0, 9.0))
        fig = Figure(figsize=(width, drawing_h + 1.0 + (1.8 if histogram else 0.0)), dpi=dpi, layout="constrained")
    else:
        fig = Figure(figsize=(size[0] / dpi, size[1] / dpi), dpi=dpi, layout="constrained")
    if histogram:
        ax, hax = fig.subplots(2, 1, height_ratios=[4, 1.3])
    else:
        ax, hax = fig.subplots(1, 1), None
    lines = []
    if mesh.n_patches > 1:
        for name, e in mesh.line_sets.items():
            if name.startswith("side "):
                lines.extend(xy[np.asarray(e)])
    bad = inverted_mask(xy, quads)
    if color == "quality":
        pc = PolyCollection(xy[quads], array=sj, cmap="viridis", edgecolors="0.3", linewidths=0.35)
        pc.set_clim(min(0.0, float(sj.min()) if sj.size else 0.0), 1.0)
        ax.add_collection(pc)
        fig.colorbar(pc, ax=ax, label="scaled Jacobian", shrink=0.9)
    elif color == "size":
        ratio = size_ratios(mesh)
        pc = PolyCollection(xy[quads], array=np.log2(ratio), cmap="coolwarm", edgecolors="0.3", linewidths=0.35)
        pc.set_clim(-1.5, 1.5)
        ax.add_collection(pc)
        cb = fig.colorbar(pc, ax=ax, label="edge length / size", shrink=0.9, ticks=np.log2([0.35, 0.5, 1.0, 1.6, 2.8]))
        cb.ax.set_yticklabels(["0.35", "0.5", "1", "1.6", "2.8"])
    else:
        face = PATCH_PALETTE[np.asarray(mesh.patch) % len(PATCH_PALETTE)]
        face = np.where(bad[:, None], np.array([0.95, 0.3, 0.3]), face)
        ax.add_collection(PolyCollection(xy[quads], facecolors=face, edgecolors="0.3", linewidths=0.35))
    if lines:
        ax.add_collection(LineCollection(lines, colors="0.1", linewidths=0.9))
    irr = np.asarray(mesh.irregular, np.int64)
    _mark_and_frame(ax, xy, irr, mesh.corners, y_down)
    head = f"{title}: {mesh.chosen}" if title else (mesh.chosen or "mesh")
    if mesh.n_patches > 1:
        head += f" ({mesh.n_patches} patches)"
    text = f"{head}. {mesh_quality_line(xy, quads)}, {irr.size} irregular"
    per_line = max(int(fig.get_figwidth() * 72 / (9 * 0.55)), 12)  # characters of 9 pt that fit the width
    fig.suptitle(textwrap.fill(text, per_line), fontsize=9)
    if hax is not None:
        hax.hist(sj, bins=np.linspace(min(0.0, float(sj.min()) if sj.size else 0.0), 1.0, 21), color="#4c72b0")
        hax.set_xlabel("scaled Jacobian", fontsize=8)
        hax.set_ylabel("quads", fontsize=8)
        hax.tick_params(labelsize=7)
    return save_figure(fig, path, dpi=dpi)


def size_ratios(mesh) -> np.ndarray:
    """``(Q,) float64`` per quad, the mean of its four edge lengths / the size at its centre (the
    mesh's size field, or its one size): what ``--color size`` draws. Raises
    :class:`InputError` for a mesh made without a size (``--template``)."""
    xy = np.asarray(mesh.xy, np.float64)
    p = xy[np.asarray(mesh.quads, np.int64)]
    mean_edge = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2).mean(axis=1)
    if mesh.field is not None:
        return mean_edge / np.asarray(mesh.field(p.mean(axis=1)), np.float64)
    if not mesh.size:
        raise InputError("colour by size needs a mesh made to a size (--size, --size-field), not --template", "--color")
    return mean_edge / float(mesh.size)


draw_mesh = draw_quadmesh
"""The Python API's name (``jaxmatch.draw_mesh``)."""
