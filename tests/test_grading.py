"""The relaxation of a graded mesh towards its size field (:mod:`jaxmatch.meshing.grading`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from jaxmatch.defaults import QUALITY
from jaxmatch.field import Field, Near
from jaxmatch.meshing.grading import follow_field
from jaxmatch.meshing.pipeline import mesh
from jaxmatch.shape import make_shape

SQUARE = make_shape([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])


@pytest.fixture(scope="module")
def graded():
    f = Field(0.2, (Near("point", (1.0, 1.0), 0.04, 0.6),)).bind(SQUARE)
    m = mesh(SQUARE, size=0.1)  # a uniform mesh, then judged against the field
    return replace(m, field=f), f


def test_relaxing_moves_no_outline_vertex_and_keeps_the_quality(graded):
    m, _ = graded
    out = follow_field(m, QUALITY)
    on_loops = np.concatenate([np.asarray(loop) for loop in m._loops])
    assert np.array_equal(out.xy[on_loops], m.xy[on_loops]) and np.array_equal(out.quads, m.quads)
    assert out.inverted == 0 and out.min_scaled_jacobian >= min(m.min_scaled_jacobian, QUALITY.high_sj) - 1e-12
    assert out.field_share > m.field_share  # edges near the point shorten, the others lengthen


def test_without_a_field_the_mesh_is_returned_as_is(graded):
    m, _ = graded
    plain = replace(m, field=None)
    assert follow_field(plain) is plain


def test_the_graded_pipeline_ends_relaxed(graded):
    _, f = graded
    m = mesh(SQUARE, size=Field(0.2, (Near("point", (1.0, 1.0), 0.04, 0.6),)))
    assert m.valid and m.field_share >= 0.9 and m.min_scaled_jacobian >= 0.6


def test_after_its_first_step_the_relaxation_asks_the_field_at_the_inner_vertices_only(graded):
    m, f = graded
    asked = []

    def counting(points):
        asked.append(len(points))
        return f(points)

    out = follow_field(replace(m, field=counting), QUALITY)
    inner = m.xy.shape[0] - len(np.unique(np.concatenate([np.asarray(loop) for loop in m._loops])))
    n_edges = m._edges.shape[0]  # (the share of edges in the band, before and after, at the end)
    assert asked[0] == m.xy.shape[0] and asked[-2:] == [n_edges, n_edges]
    assert len(asked) > 4 and set(asked[1:-2]) == {inner}
    assert np.array_equal(out.xy, follow_field(m, QUALITY).xy)  # the same relaxation as with the bound field
