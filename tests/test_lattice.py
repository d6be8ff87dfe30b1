"""Lattices (weight functions w_s, w_x, w_v): a specification by example (jaxmatch.scoring.lattice)."""

import itertools
import re
from pathlib import Path

import math

import numpy as np
import pytest
import tomli_w
from hypothesis import given
from hypothesis import strategies as st

from jaxmatch.catalogue import mesh
from jaxmatch.errors import InputError
from jaxmatch.scoring.lattice import (
    ALL_TRIPLES,
    BUILTIN_DIR,
    MAX_WEIGHT,
    NEG,
    TYPES,
    Lattice,
    builtin_names,
    finite_table,
    lattice_json,
    lattice_text,
    lattice_toml,
    level_structure,
    load_lattice,
    parse_lattice,
    parse_triple,
    save_lattice,
    table_from_levels,
    triple_index,
    with_level_weights,
)
from jaxmatch.shape import SYMBOLS

NAMES = ["fine", "coarse"]
WEEDED = {"2-2-3", "2-2-4", "2-2-5", "3-2-2", "4-2-2", "5-2-2"}
FINE_TEXT = (BUILTIN_DIR / "fine.toml").read_text(encoding="utf-8")


@pytest.fixture(params=NAMES)
def lat(request) -> Lattice:
    return load_lattice(request.param)


def weights(lat: Lattice, kind: str) -> dict:
    return lattice_json(lat)[kind]


def centre(triple: str) -> int:
    return parse_triple(triple)[1]


# ---------------------------------------------------------------------------------------------
# the shipped lattices


def test_builtins_are_listed():
    assert set(NAMES) <= set(builtin_names())


def test_types_follow_shape_codes():
    assert "".join(TYPES) == SYMBOLS


def test_every_triple_placed_once_per_type(lat):
    for k in range(3):
        placed = [t for lev in lat.levels[k] for t in lev.triples] + list(lat.weeded[k]) + list(lat.forbidden[k])
        assert sorted(placed) == sorted(ALL_TRIPLES)


def test_levels_best_first(lat):
    for levels in lat.levels:
        w = [lev.weight for lev in levels]
        assert w == sorted(w, reverse=True)


@pytest.mark.parametrize("kind, best", [("s", "3-3-3"), ("x", "3-2-3"), ("v", "3-4-3")])
def test_ideal_triple_is_the_best(lat, kind, best):
    w = weights(lat, kind)
    assert w[best] == max(v for v in w.values() if v is not None)
    # a tie only with 2-2-2 on a convex corner: it occurs on the single quad alone (k = 0)
    assert set(t for t, v in w.items() if v == w[best]) <= {best, "2-2-2"}


def test_matched_corners_outweigh_straight_points(lat):
    best = {kind: max(w for w in weights(lat, kind).values() if w is not None) for kind in TYPES}
    assert best["x"] > best["s"] and best["v"] > best["s"]


def test_shipped_lattices_make_skipping_a_corner_costly(lat):
    """Straight points are skipped at (almost) no cost, corners only at a cost of several times
    any single weight difference: a mesh keeps every corner when some mesh of its size can
    (measured: scripts/compare_lattices.py; the shipped TOML files say how the values were chosen)."""
    w = lat.weights()
    finite = w.table[~w.forbidden]
    span = float(finite.max() - finite.min())
    assert abs(float(w.skip[0])) <= 1 and not w.must[0]
    for k in (1, 2):
        assert w.must[k] or -float(w.skip[k]) > 3 * span


def test_convex_corner_never_takes_valence_4_or_5(lat):
    assert all(w is None for t, w in weights(lat, "x").items() if centre(t) >= 4)


def test_concave_corner_never_takes_valence_2(lat):
    assert all(w is None for t, w in weights(lat, "v").items() if centre(t) == 2)


def test_straight_point_takes_any_occurring_triple(lat):
    assert {t for t, w in weights(lat, "s").items() if w is None} == WEEDED


def test_convex_valence_2_at_least_as_good_as_valence_3(lat):
    w = weights(lat, "x")
    two = [v for t, v in w.items() if centre(t) == 2 and v is not None]
    three = [v for t, v in w.items() if centre(t) == 3]
    assert min(two) >= max(three)


def test_weeded_is_the_adjacent_valence_2_set(lat):
    for k in range(3):
        assert set(lat.weeded[k]) == WEEDED
        assert "2-2-2" not in lat.weeded[k]


def test_coarse_has_fewer_levels_than_fine():
    fine, coarse = load_lattice("fine"), load_lattice("coarse")
    for k in range(3):
        assert len(coarse.levels[k]) < len(fine.levels[k])
        assert len(coarse.levels[k]) <= 5


# The weeding argument, checked on small catalogue-class meshes.


def grid(a: int, b: int) -> mesh.QuadMesh:
    idx = np.arange((a + 1) * (b + 1)).reshape(b + 1, a + 1)
    quads = [[idx[j, i], idx[j, i + 1], idx[j + 1, i + 1], idx[j + 1, i]] for j in range(b) for i in range(a)]
    return mesh.from_quads(quads)


CATALOGUE_SAMPLES = {
    "single quad": mesh.from_quads([[0, 1, 2, 3]]),
    "three quads around a valence-3 vertex": mesh.from_quads([[0, 1, 4, 2], [0, 2, 5, 3], [0, 3, 6, 1]]),
    "pillow": mesh.from_quads([[4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]),
    **{f"grid {a}x{b}": grid(a, b) for a, b in [(2, 2), (2, 3), (3, 3), (2, 4), (4, 4)]},
}


@pytest.mark.parametrize("name", CATALOGUE_SAMPLES)
def test_weeded_triples_do_not_occur_in_catalogue_meshes(name):
    m = CATALOGUE_SAMPLES[name]
    assert mesh.validate(m) == []
    seen = {"-".join(map(str, t)) for t in mesh.triples(mesh.boundary_valences(m)).tolist()}
    assert not seen & WEEDED
    for lat_name in NAMES:  # every occurring triple can be matched to a straight point
        lat = load_lattice(lat_name)
        assert all(lat.weight("s", t) > -np.inf for t in seen)


def test_single_quad_is_all_2_2_2():
    seen = mesh.triples(mesh.boundary_valences(CATALOGUE_SAMPLES["single quad"])).tolist()
    assert seen == [[2, 2, 2]] * 4


# ---------------------------------------------------------------------------------------------
# arrays


def test_table_layout(lat):
    t = lat.table()
    assert t.shape == (3, 4, 4, 4) and t.dtype == np.float32
    for k, kind in enumerate(TYPES):
        for tr, w in weights(lat, kind).items():
            u, v, w_ = parse_triple(tr)
            assert t[k, u - 2, v - 2, w_ - 2] == (-np.inf if w is None else w)
            assert t[k].reshape(64)[triple_index(tr)] == t[k, u - 2, v - 2, w_ - 2]


def test_finite_table(lat):
    f = finite_table(lat)
    assert f.dtype == np.float32 and np.isfinite(f).all()
    t = lat.table()
    np.testing.assert_array_equal(f[np.isfinite(t)], t[np.isfinite(t)])
    assert (f[~np.isfinite(t)] == np.float32(NEG)).all()


def test_level_structure_partitions_the_table(lat):
    s = level_structure(lat)
    n = sum(len(levels) for levels in lat.levels)
    assert s.masks.shape == (n, 3, 4, 4, 4) and s.weights.shape == (n,) and s.types.shape == (n,)
    assert (s.masks.sum(axis=0) <= 1).all()
    np.testing.assert_array_equal(s.masks.any(axis=0), np.isfinite(lat.table()))
    for l in range(n):  # a level lives in one type
        assert s.masks[l].reshape(3, -1).any(axis=1).tolist() == [k == s.types[l] for k in range(3)]
    np.testing.assert_array_equal(table_from_levels(s, s.weights), finite_table(lat))


def test_table_from_levels_accepts_jax_weights(lat):
    jnp = pytest.importorskip("jax.numpy")
    s = level_structure(lat)
    got = table_from_levels(s, jnp.asarray(s.weights))
    np.testing.assert_array_equal(np.asarray(got), finite_table(lat))


def test_with_level_weights_rounds_and_keeps_order(lat):
    s = level_structure(lat)
    new = with_level_weights(lat, s.weights * 2 + 0.4)
    assert level_structure(new).weights.tolist() == (s.weights * 2).tolist()
    shuffled = with_level_weights(lat, -s.weights)  # reverses every order: levels are re-sorted
    for levels in shuffled.levels:
        w = [lev.weight for lev in levels]
        assert w == sorted(w, reverse=True)
    assert parse_lattice(lattice_toml(shuffled)) == shuffled
    with pytest.raises(ValueError):
        with_level_weights(lat, s.weights[:-1])


def test_with_level_weights_clips(lat):
    n = level_structure(lat).weights.shape[0]
    new = with_level_weights(lat, np.full(n, 1e6))
    assert {lev.weight for levels in new.levels for lev in levels} == {MAX_WEIGHT}


def test_lattice_json(lat):
    doc = lattice_json(lat)
    assert list(doc) == ["s", "x", "v", "skip"]
    for kind in TYPES:
        assert list(doc[kind]) == list(ALL_TRIPLES)
        assert all(v is None or isinstance(v, int) for v in doc[kind].values())
    assert list(doc["skip"]) == list(TYPES)
    assert [None if v is None else float(v) for v in doc["skip"].values()] == [None if math.isinf(w) else w for w in lat.skip]


def test_lattice_text_lists_every_level(lat):
    text = lattice_text(lat)
    assert lat.name in text
    for levels in lat.levels:
        for lev in levels:
            assert " ".join(lev.triples) in text


# ---------------------------------------------------------------------------------------------
# round trips


def test_save_load_round_trip(lat, tmp_path):
    path = tmp_path / "out.toml"
    save_lattice(lat, path)
    assert load_lattice(path) == lat
    assert load_lattice(str(path)) == lat


def test_save_with_template_keeps_comments(tmp_path):
    lat = load_lattice("fine")
    tuned = with_level_weights(lat, level_structure(lat).weights + 1)
    path = tmp_path / "tuned.toml"
    save_lattice(tuned, path, template=BUILTIN_DIR / "fine.toml")
    text = path.read_text()
    assert "# Weeded (same for all types)" in text
    assert load_lattice(path) == tuned


def test_save_with_mismatched_template_writes_fresh_file(tmp_path):
    lat = load_lattice("coarse")
    path = tmp_path / "c.toml"
    save_lattice(lat, path, template=BUILTIN_DIR / "fine.toml")
    assert load_lattice(path) == lat


@given(data=st.data())
def test_round_trip_of_tuned_lattices(data):
    lat = load_lattice(data.draw(st.sampled_from(NAMES)))
    n = level_structure(lat).weights.shape[0]
    w = data.draw(st.lists(st.floats(-50, 50), min_size=n, max_size=n))
    tuned = with_level_weights(lat, w)
    assert parse_lattice(lattice_toml(tuned), "t.toml") == tuned


def test_name_defaults_to_file_stem(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(re.sub(r'(?m)^name = .*$', "", FINE_TEXT))
    assert load_lattice(path).name == "mine"


def test_unknown_name():
    with pytest.raises(InputError, match="built-in"):
        load_lattice("no-such-lattice")


def test_missing_path(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        load_lattice(tmp_path / "nope.toml")


# ---------------------------------------------------------------------------------------------
# bad files: InputError naming path:LINE of the offending line


def line_of(text: str, fragment: str) -> int:
    for i, line in enumerate(text.splitlines(), start=1):
        if fragment in line:
            return i
    raise AssertionError(fragment)


# (description, old, new, fragment of the expected line in the new text, fragment of message)
MUTATIONS = [
    ("repeated triple", 'triples = ["2-2-2"]', 'triples = ["2-2-2", "3-2-3"]', 'triples = ["2-2-2", "3-2-3"]', "twice"),
    ("missing triple", '"5-2-5", "2-3-2"', '"2-3-2"', "[x]", "5-2-5"),
    ("float weight", "weight = 5\n", "weight = 5.5\n", "weight = 5.5", "integer"),
    ("string weight", "weight = 5\n", 'weight = "5"\n', 'weight = "5"', "integer"),
    ("bool weight", "weight = 5\n", "weight = true\n", "weight = true", "integer"),
    ("huge weight", "weight = 5\n", "weight = 5000\n", "weight = 5000", "outside"),
    ("levels out of order", "weight = 1\n", "weight = 7\n", "weight = 7", "larger"),
    ("bad triple", '"5-5-5"]', '"5-5-6"]', '"5-5-6"', "5-5-6"),
    ("non-string triple", '"5-5-5"]', "555]", "555]", "555"),
    ("unknown type key", "[x]\n", "[x]\ncolour = 1\n", "colour = 1", "unknown key"),
    ("unknown top key", 'name = "fine"\n', 'name = "fine"\nauthor = "me"\n', 'author = "me"', "unknown key"),
    ("unknown table", 'name = "fine"\n', 'name = "fine"\n[z]\n', "[z]", "unknown key"),
    ("unknown level key", "weight = 5\n", "weight = 5\nwieght = 3\n", "wieght = 3", "unknown key"),
    ("empty triples", 'triples = ["2-2-2"]', "triples = []", "triples = []", "non-empty"),
    ("triples not a list", 'triples = ["2-2-2"]', 'triples = "2-2-2"', 'triples = "2-2-2"', "non-empty"),
    ("weeded not a list", 'weeded = ["2-2-3", "2-2-4", "2-2-5", "3-2-2", "4-2-2", "5-2-2"]\nforbidden = []', 'weeded = 3\nforbidden = []', "weeded = 3", "list"),
    ("missing weight", "weight = 5\n", "", "[[x.levels]]", "missing weight"),
    ("syntax error", 'triples = ["2-2-2"]', 'triples = ["2-2-2"', 'triples = ["2-2-2"', "syntax"),
    ("name not a string", 'name = "fine"', "name = 3", "name = 3", "name"),
]


@pytest.mark.parametrize("what, old, new, at, fragment", MUTATIONS, ids=[m[0] for m in MUTATIONS])
def test_bad_lattice_names_the_line(what, old, new, at, fragment, tmp_path):
    assert old in FINE_TEXT
    text = FINE_TEXT.replace(old, new, 1)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_lattice(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert fragment.lower() in msg.lower()
    if what == "missing weight":  # reported at the level header before the removed line
        before = FINE_TEXT[: FINE_TEXT.index(old)].splitlines()
        line = max(i for i, l in enumerate(before, 1) if l.strip().startswith("[["))
        assert msg.startswith(f"{path}:{line}: ")
    elif what == "syntax error":
        assert re.match(rf"{re.escape(str(path))}:\d+: ", msg)
    else:
        assert msg.startswith(f"{path}:{line_of(text, at)}: "), msg


def test_missing_type_table():
    text = FINE_TEXT[: FINE_TEXT.index("# ---", FINE_TEXT.index("[[x.levels]]"))]
    with pytest.raises(InputError, match=r"^t\.toml:1: missing table \[v\]"):
        parse_lattice(text, "t.toml")


def test_not_utf8():
    with pytest.raises(InputError, match="UTF-8"):
        parse_lattice(b"name = \xff", "t.toml")


@given(data=st.binary(max_size=200))
def test_random_bytes_never_crash(data):
    try:
        parse_lattice(data, "r.toml")
    except InputError as err:
        assert str(err).startswith("r.toml")


keys = st.sampled_from(["name", "s", "x", "v", "levels", "weeded", "forbidden", "weight", "triples", "z"])
toml_values = st.recursive(
    st.integers(-2000, 2000) | st.floats(allow_nan=False) | st.booleans() | st.sampled_from(ALL_TRIPLES[:5] + ("9-9-9", "")),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(keys, inner, max_size=4),
    max_leaves=25,
)


@given(doc=st.dictionaries(keys, toml_values, max_size=5))
def test_random_toml_documents_never_crash(doc):
    try:
        text = tomli_w.dumps(doc)
    except (TypeError, ValueError):
        return
    try:
        parse_lattice(text, "r.toml")
    except InputError as err:
        assert str(err).startswith("r.toml")


@given(data=st.data())
def test_random_line_edits_never_crash(data):
    lines = FINE_TEXT.splitlines()
    i = data.draw(st.integers(0, len(lines) - 1))
    j = data.draw(st.integers(0, len(lines) - 1))
    op = data.draw(st.sampled_from(["delete", "duplicate", "swap"]))
    if op == "delete":
        del lines[i]
    elif op == "duplicate":
        lines.insert(j, lines[i])
    else:
        lines[i], lines[j] = lines[j], lines[i]
    try:
        parse_lattice("\n".join(lines), "e.toml")
    except InputError as err:
        assert re.match(r"e\.toml(:\d+)?: ", str(err))


def test_triple_helpers():
    assert len(ALL_TRIPLES) == 64 and len(set(ALL_TRIPLES)) == 64
    assert [triple_index(t) for t in ALL_TRIPLES] == list(range(64))
    assert parse_triple("3-2-4") == (3, 2, 4)
    for bad in ["3-2", "1-2-3", "3-2-6", "a-b-c", 3]:
        with pytest.raises(ValueError):
            parse_triple(bad)
    assert list(itertools.product(range(2, 6), repeat=3))[triple_index("4-5-2")] == (4, 5, 2)


# ---------------------------------------------------------------------------------------------
# skip weights ([skip])

NO_SKIP_TEXT = re.sub(r"(?ms)^\[skip\].*?(?=^\[|\Z)", "", FINE_TEXT)
"""fine.toml without its [skip] table (if any)."""
SKIP_TEXT = NO_SKIP_TEXT.rstrip("\n") + "\n\n[skip]\ns = 0\nx = -5\nv = -inf\n"


def test_skip_table_is_optional_and_defaults_to_zero():
    lat = parse_lattice(NO_SKIP_TEXT, "f.toml")
    assert lat.skip == (0, 0, 0)
    assert not lat.weights().has_skip and lat.weights().skip.tolist() == [0, 0, 0]


def test_skip_table_integers_and_minus_inf():
    lat = parse_lattice(SKIP_TEXT, "f.toml")
    assert lat.skip[:2] == (0, -5) and math.isinf(lat.skip[2]) and lat.skip[2] < 0
    w = lat.weights()
    assert w.skip[:2].tolist() == [0, -5] and w.must.tolist() == [False, False, True] and w.skip[2] == np.float32(NEG)
    assert lattice_json(lat)["skip"] == {"s": 0, "x": -5, "v": None}
    assert "skip" in lattice_text(lat) and "-inf" in lattice_text(lat).split("skip", 1)[1]
    partial = parse_lattice(NO_SKIP_TEXT + "\n[skip]\nv = -3\n", "f.toml")
    assert partial.skip == (0, 0, -3)  # missing types: 0


SKIP_MUTATIONS = [
    ("float skip", "x = -5", "x = -1.5", "integer or -inf"),
    ("string skip", "x = -5", 'x = "-5"', "integer or -inf"),
    ("plus inf skip", "x = -5", "x = inf", "integer or -inf"),
    ("nan skip", "x = -5", "x = nan", "integer or -inf"),
    ("huge skip", "x = -5", "x = -5000", "outside"),
    ("unknown skip key", "x = -5", "x = -5\nw = 1", "unknown key"),
]


@pytest.mark.parametrize("what, old, new, fragment", SKIP_MUTATIONS, ids=[m[0] for m in SKIP_MUTATIONS])
def test_bad_skip_table_names_the_line(what, old, new, fragment, tmp_path):
    text = SKIP_TEXT.replace(old, new, 1)
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_lattice(path)
    msg = str(info.value)
    assert "\n" not in msg and fragment in msg
    assert msg.startswith(f"{path}:{line_of(text, new.splitlines()[-1])}: "), msg


def test_skip_not_a_table(tmp_path):
    with pytest.raises(InputError, match="skip must be a table"):
        parse_lattice('skip = 3\n' + NO_SKIP_TEXT, "f.toml")


@pytest.mark.parametrize("skip", [(0, -5, -math.inf), (2, 0, 0), (-math.inf, -math.inf, -math.inf), (0, 0, 0)])
def test_skip_round_trips_through_files_and_templates(skip, tmp_path):
    from dataclasses import replace

    lat = replace(load_lattice("fine"), skip=skip)
    assert parse_lattice(lattice_toml(lat), "t.toml") == lat
    for template in (SKIP_TEXT, NO_SKIP_TEXT):  # with and without a [skip] table of its own
        path = tmp_path / "t.toml"
        save_lattice(lat, path, template=template)
        text = path.read_text()
        assert load_lattice(path) == lat
        assert "# Weeded (same for all types)" in text  # the template's comments are kept


def test_with_level_weights_rounds_skip_and_keeps_minus_inf():
    from dataclasses import replace

    lat = replace(load_lattice("fine"), skip=(0, -5, -math.inf))
    w = level_structure(lat).weights
    new = with_level_weights(lat, w, [0.4, -7.6, 3.0])
    assert new.skip[:2] == (0, -8) and math.isinf(new.skip[2])
    assert with_level_weights(lat, w).skip == lat.skip
    with pytest.raises(ValueError):
        with_level_weights(lat, w, [0, 0])
