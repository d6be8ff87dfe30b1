"""Label files, the synthetic generator and the designer rule (jaxmatch.tuning.labels)."""

import json
from pathlib import Path

import numpy as np
import pytest

from jaxmatch.errors import InputError, InputWarning
from jaxmatch.tuning.labels import (
    boundary_key,
    corner_cycle,
    cyclic_edit_distance,
    design_ranking,
    dump_labels,
    ideal_turns,
    load_labels,
    parse_labels,
    synthetic_examples,
    turning_fits,
)
from jaxmatch.shape import make_shape

ROOT = Path(__file__).resolve().parents[1]
LABELS = ROOT / "examples" / "labels"
SQUARE = {"boundary": [[0, 0], [1, 0], [1, 1], [0, 1]]}


@pytest.fixture(scope="module")
def k3(index):
    return index.by_k[3][0]


def write(tmp_path, lines, name="labels.jsonl"):
    p = tmp_path / name
    p.write_text("".join((x if isinstance(x, str) else json.dumps(x)) + "\n" for x in lines))
    return p


# ------------------------------------------------------------------------------- parsing


def test_good_file_inline_and_path_shapes(tmp_path, index, k3):
    (tmp_path / "sq.json").write_text(json.dumps(SQUARE))
    p = write(tmp_path, [
        "# a comment line",
        "",
        {"shape": "sq.json", "preferred": k3},
        {"shape": {**SQUARE, "corners": [0, 1, 2, 3]}, "preferred": k3, "rotation": 1, "reflected": True, "note": "why"},
    ])
    got = load_labels(p, index)
    assert got.problems == []
    a, b = got.examples
    assert (a.preferred, a.k, a.rotation, a.reflected, a.where) == (k3, 3, None, None, f"{p}:3")
    assert (b.rotation, b.reflected, b.note, b.where) == (1, True, "why", f"{p}:4")
    assert a.shape.n_corners == 4 and b.shape.n_corners == 4


BAD = [
    ("{not json", "not valid JSON"),
    ("[1, 2]", "JSON object"),
    ({"shape": SQUARE}, 'missing key "preferred"'),
    ({"preferred": "K3"}, 'missing key "shape"'),
    ({"shape": SQUARE, "preferred": "k3-zz"}, "catalogue id"),
    ({"shape": SQUARE, "preferred": "k3-0123456789ab"}, "not in the catalogue"),
    ({"shape": SQUARE, "preferred": "K3", "colour": 1}, "unknown key"),
    ({"shape": SQUARE, "preferred": "K3", "rotation": -1}, '"rotation"'),
    ({"shape": SQUARE, "preferred": "K3", "rotation": 999}, '"rotation"'),
    ({"shape": SQUARE, "preferred": "K3", "rotation": True}, '"rotation"'),
    ({"shape": SQUARE, "preferred": "K3", "reflected": 1}, '"reflected"'),
    ({"shape": SQUARE, "preferred": "K3", "note": 3}, '"note"'),
    ({"shape": 7, "preferred": "K3"}, '"shape"'),
    ({"shape": "missing.json", "preferred": "K3"}, "shape missing.json"),
    ({"shape": {"boundary": [[0, 0], [1, 1], [1, 0], [0, 1]]}, "preferred": "K3"}, "crosses"),
    ({"shape": {"boundary": [[0, 0], [1, 0]]}, "preferred": "K3"}, "at least 3"),
    ('{"shape": {"boundary": [[0, 0], [1, 0], [0, NaN]]}, "preferred": "K3"}', "not"),
]


def _fill(item, k3):
    if isinstance(item, str):
        return item.replace("K3", k3)
    return json.loads(json.dumps(item).replace('"K3"', json.dumps(k3)))


@pytest.mark.parametrize("line,message", BAD)
def test_bad_line_is_reported_with_its_line_number(tmp_path, index, k3, line, message):
    good = {"shape": SQUARE, "preferred": k3}
    p = write(tmp_path, ["# header", good, _fill(line, k3), good])
    with pytest.raises(InputError) as err:
        load_labels(p, index)
    assert err.value.where == f"{p}:3"
    assert message in err.value.problem
    assert "\n" not in str(err.value)
    kept = load_labels(p, index, skip_bad=True)
    assert [e.where for e in kept.examples] == [f"{p}:2", f"{p}:4"]
    assert [e.where for e in kept.problems] == [f"{p}:3"]


def test_extra_key_in_an_embedded_shape_is_warned_not_refused(tmp_path, index, k3):
    """As in shape files (jaxmatch.io.readers): unknown shape keys are ignored with a warning."""
    p = write(tmp_path, [{"shape": dict(SQUARE, extra=1), "preferred": k3}])
    with pytest.warns(InputWarning, match="ignored key 'extra'"):
        assert len(load_labels(p, index).examples) == 1


def test_skip_bad_collects_every_bad_line_and_an_all_bad_file_fails(tmp_path, index, k3):
    p = write(tmp_path, ["{", {"shape": SQUARE, "preferred": k3}, "[]", "nope"])
    got = load_labels(p, index, skip_bad=True)
    assert [e.where for e in got.problems] == [f"{p}:1", f"{p}:3", f"{p}:4"]
    assert len(got.examples) == 1
    bad = write(tmp_path, ["{", "[]"], "bad.jsonl")
    with pytest.raises(InputError, match="no labelled examples"):
        load_labels(bad, index, skip_bad=True)
    with pytest.raises(InputError) as err:
        load_labels(tmp_path / "absent.jsonl", index)
    assert "cannot read" in err.value.problem


def test_dump_and_parse_round_trip(index, k3):
    text = dump_labels([{"shape": SQUARE, "preferred": k3, "note": "x"}])
    assert text.count("\n") == 1
    (ex,) = parse_labels(text, "mem", index).examples
    assert ex.preferred == k3 and ex.record["note"] == "x"


# ------------------------------------------------------------------------------- ideal outlines


def test_ideal_turns_close_the_outline(index):
    for k in (0, 1, 2, 3):
        for mid in index.by_k[k]:
            t = ideal_turns(index.vals[mid])
            assert t.sum() == pytest.approx(2 * np.pi)
    # a regular grid: corners turn 90 degrees, sides go straight
    np.testing.assert_allclose(np.degrees(ideal_turns([2, 3, 3, 3, 2, 3, 2, 3, 3, 3, 2, 3])), [90, 0, 0, 0, 90, 0] * 2, atol=1e-9)


def test_boundary_key_is_rotation_and_reflection_invariant():
    v = [2, 3, 4, 3, 2, 3, 3]
    assert boundary_key(v) == boundary_key(v[3:] + v[:3]) == boundary_key(v[::-1])
    assert boundary_key(v) != boundary_key([2, 3, 3, 4, 2, 3, 3])


# ------------------------------------------------------------------------------- synthetic


@pytest.mark.parametrize("k", [1, 2, 3])
def test_synthetic_shapes_are_valid_and_labelled_with_catalogue_meshes(cat, index, k):
    records, skipped = synthetic_examples(cat, k, variants=2, seed=7, index=index)
    assert skipped == []
    assert len(records) == 2 * len(index.by_k[k])
    for rec in records:
        shape = make_shape(rec["shape"]["boundary"], rec["shape"]["corners"])  # valid
        assert rec["preferred"] in index.where and index.where[rec["preferred"]][0] == k
        # corners: one per mesh vertex of valence other than 3, convex exactly for valence 2
        source = rec["note"].split("outline of ")[1].split(",")[0]
        vals = index.vals[source]
        assert shape.n_corners == int(np.sum(vals != 3))
        assert sorted(shape.convex.tolist()) == sorted((vals[vals != 3] == 2).tolist())
    parsed = parse_labels(dump_labels(records), "mem", index)  # the file format reads them back
    assert len(parsed.examples) == len(records) and not parsed.problems


def test_synthetic_is_deterministic_by_seed(cat, index):
    a, _ = synthetic_examples(cat, 2, variants=1, seed=3, index=index)
    b, _ = synthetic_examples(cat, 2, variants=1, seed=3, index=index)
    c, _ = synthetic_examples(cat, 2, variants=1, seed=4, index=index)
    assert dump_labels(a) == dump_labels(b)
    assert dump_labels(a) != dump_labels(c)


def test_synthetic_twins_are_labelled_with_the_smallest_id(cat, index):
    groups = {}
    for mid in index.by_k[4]:
        groups.setdefault(boundary_key(index.vals[mid]), []).append(mid)
    twins = [sorted(g) for g in groups.values() if len(g) > 1]
    assert twins, "k = 4 has meshes with the same boundary cycle"
    records, _ = synthetic_examples(cat, 4, variants=1, seed=0, index=index)
    labels = {r["note"].split("outline of ")[1].split(",")[0]: r["preferred"] for r in records}
    for g in twins:
        for mid in g:
            if mid in labels:
                assert labels[mid] == g[0]


# ------------------------------------------------------------------------------- designer rule


def test_cyclic_edit_distance():
    assert cyclic_edit_distance("xxxv", "vxxx") == 0  # rotation
    assert cyclic_edit_distance("xxvxv", "vxvxx"[::-1]) == 0  # mirror image
    assert cyclic_edit_distance("xxxx", "xxx") == 1
    assert cyclic_edit_distance("xxxx", "xxxv") == 2  # a swap is a deletion and an insertion
    assert cyclic_edit_distance("", "xx") == 2 and cyclic_edit_distance("xx", "") == 2
    assert corner_cycle([2, 3, 4, 3, 5, 2]) == "xvvx"


def test_designer_rule_picks_the_grid_for_a_2x1_rectangle(cat, index):
    shape = make_shape([[0, 0], [2, 0], [2, 1], [0, 1]])
    rows = design_ranking(shape, cat, 3, index=index)
    best = rows[0]
    assert boundary_key(index.vals[best.mesh_id]) == boundary_key([2, 3, 3, 3, 2, 3, 2, 3, 3, 3, 2, 3])  # the 4 x 2 grid
    assert best.corners == 0 and best.irregular == 0 and best.distance < 1e-6
    assert len(rows) == len(index.by_k[3])
    # the turning fit is invariant under a similarity transform of the shape
    moved = make_shape([[5, 5], [5 + 2 * np.cos(0.3), 5 + 2 * np.sin(0.3)], [5 + 2 * np.cos(0.3) - np.sin(0.3), 5 + 2 * np.sin(0.3) + np.cos(0.3)], [5 - np.sin(0.3), 5 + np.cos(0.3)]])
    d0 = [d for d, _, _ in turning_fits(shape, [index.vals[r.mesh_id] for r in rows[:5]])]
    d1 = [d for d, _, _ in turning_fits(moved, [index.vals[r.mesh_id] for r in rows[:5]])]
    np.testing.assert_allclose(d0, d1, atol=0.02)


def test_shipped_designer_labels_follow_the_rule(cat, index):
    got = load_labels(LABELS / "designer-k3.jsonl", index)
    assert not got.problems
    assert len(got.examples) >= 20
    assert all(e.k == 3 for e in got.examples)
    corners = {e.shape.n_corners > 0 for e in got.examples}
    concave = {bool((~e.shape.convex).any()) for e in got.examples}
    assert corners == {True, False} and concave == {True, False}  # convex, concave and smooth shapes
    for ex in got.examples:
        best = design_ranking(ex.shape, cat, 3, index=index)[0]
        assert (best.mesh_id, best.rotation, best.reflected) == (ex.preferred, ex.rotation, ex.reflected), ex.where


def test_shipped_synthetic_labels_load(index):
    got = load_labels(LABELS / "synthetic-k3.jsonl", index)
    assert not got.problems and len(got.examples) >= 150
    assert {e.k for e in got.examples} == {3}


def test_endless_label_file_is_refused_not_read_forever(tmp_path):
    """A device that never ends (like /dev/zero) is cut off at the size limit."""
    import os

    from jaxmatch.catalogue import store as cm
    from jaxmatch.tuning.labels import load_labels

    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    with pytest.raises(InputError, match="/dev/zero"):
        load_labels("/dev/zero", cm.default_catalogue())
