"""Fuzzing every reader: shapes, lattices, catalogues (and label files when they exist).

Contract, for any input of bounded size: the reader returns a correct result, or raises
:class:`jaxmatch.errors.InputError` whose message is one line that names the file; never
another exception, never a hang. A few cases go end to end through the CLI: exit status 2 and
exactly one line on stderr, no traceback.

The inputs: random bytes, truncations and byte edits of valid files, wrong JSON/TOML types,
NaN/inf, huge and tiny coordinates, duplicate and collinear points, self-intersections,
oversized and endless files (``/dev/zero``), zip-bomb members, hand-built catalogues whose
checksums are right but whose arrays are not, unicode paths. Example counts follow the
hypothesis profile (``tests/conftest.py``): a quarter to a half of its ``max_examples``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from jaxmatch.catalogue import store as cm
from jaxmatch.errors import InputError, InputWarning
from jaxmatch.scoring.lattice import MAX_BYTES as LATTICE_MAX_BYTES
from jaxmatch.scoring.lattice import load_lattice, parse_lattice
from jaxmatch.shape import MAX_BYTES as SHAPE_MAX_BYTES
from jaxmatch.io.readers import load_shape, parse_shape
from jaxmatch.shape import MAX_POINTS, annotate, make_shape

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
LATTICES = ROOT / "lattices"
SHAPE_FILES = sorted(p for p in EXAMPLES.iterdir() if p.is_file())
ELEMENT = {"bracket.svg": "outline"}  # examples with several elements: the one to read
FINE = (LATTICES / "fine.toml").read_bytes()
COARSE = (LATTICES / "coarse.toml").read_bytes()

N = settings.default.max_examples


def few(fraction: float) -> settings:
    return settings(max_examples=max(8, int(N * fraction)), deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.data_too_large])


def check_error(err: InputError, where: str) -> None:
    msg = str(err)
    assert where in msg, msg
    assert "\n" not in msg and "\r" not in msg, msg
    assert "Traceback" not in msg


def result_or_error(fn, *args, where: str, **kwargs):
    """``fn(*args)``, or the InputError it raised (checked); anything else fails the test."""
    try:
        return fn(*args, **kwargs)
    except InputError as err:
        check_error(err, where)
        return err


@st.composite
def edited(draw, data: bytes, max_edits: int = 4) -> bytes:
    """``data`` with a few random byte edits: flip, insert, delete a range, duplicate a range."""
    b = bytearray(data)
    for _ in range(draw(st.integers(1, max_edits))):
        op = draw(st.sampled_from(["flip", "insert", "delete", "duplicate", "truncate"]))
        i = draw(st.integers(0, max(len(b) - 1, 0)))
        if op == "flip" and b:
            b[i] ^= draw(st.integers(1, 255))
        elif op == "insert":
            b[i:i] = draw(st.binary(min_size=1, max_size=8))
        elif op == "delete":
            del b[i : i + draw(st.integers(1, 16))]
        elif op == "duplicate":
            j = i + draw(st.integers(1, 32))
            b[j:j] = b[i:j]
        elif op == "truncate":
            del b[i:]
    return bytes(b)


def run_cli(*args, timeout=120):
    return subprocess.run([sys.executable, "-m", "jaxmatch.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=ROOT, timeout=timeout, env={**os.environ, "JAX_PLATFORMS": "cpu"})


def assert_one_line_exit_2(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# =============================================================================================
# shapes


@pytest.mark.filterwarnings("ignore::jaxmatch.errors.InputWarning")  # random keys are warned, tested elsewhere
@pytest.mark.parametrize("path", SHAPE_FILES, ids=lambda p: p.name)
def test_shape_truncated_at_any_byte(path):
    """Every prefix of every example: a valid (smaller) shape or a one-line InputError."""
    data = path.read_bytes()
    src = f"dir/{path.name}"
    element = ELEMENT.get(path.name)
    full = parse_shape(data, src, element=element)
    for cut in range(len(data)):
        got = result_or_error(parse_shape, data[:cut], src, where=src, element=element)
        if not isinstance(got, InputError) and path.suffix == ".json":
            # a JSON prefix parses only when nothing but trailing whitespace was cut
            assert data[cut:].strip() == b"" and np.array_equal(got.points, full.points)


@pytest.mark.filterwarnings("ignore::jaxmatch.errors.InputWarning")  # random keys are warned, tested elsewhere
@few(0.5)
@given(data=st.data())
def test_shape_byte_edits(data):
    path = data.draw(st.sampled_from(SHAPE_FILES))
    blob = data.draw(edited(path.read_bytes()))
    src = f"dir/{path.name}"
    got = result_or_error(parse_shape, blob, src, where=src, element=ELEMENT.get(path.name))
    if not isinstance(got, InputError):
        assert got.points.min() == 0 and got.points.max() == 1 and np.isfinite(got.points).all()


weird_values = st.one_of(
    st.none(), st.booleans(), st.text(max_size=4), st.integers(-(10**30), 10**30), st.just(10**400),
    st.floats(allow_nan=True, allow_infinity=True), st.just([]), st.just({}), st.just([[0, 0]]),
    st.just([0, 0, 0]), st.just({"x": 0, "y": 0}), st.just("0 0"), st.just([[[1]]]),
)


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, prefix + (i,))


def _replace(doc, path, value):
    if not path:
        return value
    doc = json.loads(json.dumps(doc))
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return doc


@pytest.mark.filterwarnings("ignore::jaxmatch.errors.InputWarning")  # random keys are warned, tested elsewhere
@few(0.5)
@given(data=st.data())
def test_shape_json_wrong_types_anywhere(data):
    """Replace any node of a valid shape document by a value of another type."""
    path = data.draw(st.sampled_from([p for p in SHAPE_FILES if p.suffix == ".json"]))
    doc = json.loads(path.read_text())
    if "corners" not in doc and data.draw(st.booleans()):
        doc["corners"] = [0, 1, 2]
    where = data.draw(st.sampled_from(list(_paths(doc))))
    new = _replace(doc, where, data.draw(weird_values))
    blob = json.dumps(new, allow_nan=True).encode()
    result_or_error(parse_shape, blob, "w.json", where="w.json")


@pytest.mark.parametrize("token", ["nan", "NaN", "-nan", "inf", "-inf", "+inf", "Infinity", "-Infinity", "1e309", "-1e999",
                                   "0x10", "1_000", "١", "1,5", "", "--1", "1e", "e5"])
def test_shape_text_non_numbers_and_non_finite(token):
    data = f"0 0\n1 0\n{token} 1\n0 1\n".encode()
    err = result_or_error(parse_shape, data, "t.txt", where="t.txt")
    if token in ("1_000", "١"):  # Python's float() accepts these: a valid (if odd) number
        return
    assert isinstance(err, InputError)


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e400", "-1e400", "1" + "0" * 400, "1" + "0" * 5000])
@pytest.mark.parametrize("place", ["x", "y", "corner"])
def test_shape_json_non_finite(literal, place):
    if place == "corner":
        text = '{"boundary": [[0, 0], [1, 0], [1, 1]], "corners": [%s]}' % literal
    elif place == "x":
        text = '{"boundary": [[0, 0], [1, 0], [%s, 1]]}' % literal
    else:
        text = '{"boundary": [[0, 0], [1, 0], [1, %s]]}' % literal
    assert isinstance(result_or_error(parse_shape, text.encode(), "n.json", where="n.json"), InputError)


L_SHAPE = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)


@few(0.5)
@given(exponent=st.integers(-330, 330), shift=st.sampled_from([0.0, 1.0, -7.5]), which=st.sampled_from(["L", "square"]))
def test_shape_huge_and_tiny_coordinates(exponent, shift, which):
    """Scaled by 10**e: same corners and annotation while areas (squares) are normal floats
    (|e| <= 140); beyond that a one-line error (too large, too small, overflow) or, still, the
    same annotation."""
    base = L_SHAPE if which == "L" else SQUARE
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        pts = (base + shift) * np.power(10.0, exponent)
    doc = {"boundary": pts.tolist()}
    blob = json.dumps(doc).encode()  # inf -> Infinity: rejected like any non-finite number
    got = result_or_error(parse_shape, blob, "s.json", where="s.json")
    want = annotate(make_shape(base), 20)
    if -140 <= exponent <= 140:
        assert not isinstance(got, InputError), got
    if not isinstance(got, InputError):
        assert annotate(got, 20).symbols == want.symbols
        np.testing.assert_allclose(annotate(got, 20).t, want.t, atol=1e-9)


convex_polygon = st.lists(st.integers(0, 359), min_size=3, max_size=12, unique=True).map(
    lambda deg: np.array([[1000 * math.cos(math.radians(d)), 1000 * math.sin(math.radians(d))] for d in sorted(deg)]))


@few(0.5)
@given(pts=convex_polygon, data=st.data())
def test_shape_duplicate_points_are_refused(pts, data):
    """A copy of a vertex anywhere in the loop: repeated (next to it) or touching (elsewhere);
    except where the copy makes the last point equal the first: a closed ring (accepted, same
    points)."""
    i = data.draw(st.integers(0, len(pts) - 1))
    j = data.draw(st.integers(0, len(pts)))
    loop = np.insert(pts, j, pts[i], axis=0)
    err = result_or_error(make_shape, loop, source="d.json", where="d.json")
    if (i, j) in ((0, len(pts)), (len(pts) - 1, 0)):  # last point = first: a closed ring
        assert not isinstance(err, InputError), err
        assert {tuple(np.round(p, 6)) for p in err.user_points} == {tuple(np.round(p, 6)) for p in pts}
        return
    assert isinstance(err, InputError)
    assert any(w in str(err) for w in ("repeated", "repeats the first", "crosses or touches")), err


@few(0.5)
@given(pts=convex_polygon, data=st.data())
def test_shape_self_intersections_are_refused(pts, data):
    """Points in convex position form a simple loop only in (either) hull order."""
    assume(len(pts) >= 4)
    i, j = data.draw(st.lists(st.integers(0, len(pts) - 1), min_size=2, max_size=2, unique=True))
    order = list(range(len(pts)))
    order[i], order[j] = order[j], order[i]
    n = len(order)
    hull = [[(s + d * k) % n for k in range(n)] for s in range(n) for d in (1, -1)]
    got = result_or_error(make_shape, pts[order], source="x.json", where="x.json")
    if order in hull:
        assert not isinstance(got, InputError)
    else:
        assert isinstance(got, InputError) and "crosses" in str(got)


@few(0.5)
@given(pts=convex_polygon, data=st.data())
def test_shape_points_added_on_sides_are_straight(pts, data):
    """Collinear points inserted on the sides change neither the corners nor the annotation."""
    base = make_shape(pts)
    loop = []
    for k in range(len(pts)):
        a, b = pts[k], pts[(k + 1) % len(pts)]
        loop.append(a)
        for f in sorted(data.draw(st.lists(st.sampled_from([0.125, 0.25, 0.5, 0.75]), max_size=3, unique=True))):
            loop.append(a + f * (b - a))
    shape = make_shape(np.array(loop))
    assert shape.n_corners == base.n_corners
    np.testing.assert_allclose(shape.user_points[shape.corners], base.user_points[base.corners], atol=1e-9)
    m = data.draw(st.integers(base.n_corners, 3 * base.n_corners + 5))
    a, b = annotate(base, m), annotate(shape, m)
    assert a.symbols == b.symbols
    np.testing.assert_allclose(shape.to_user(b.positions), base.to_user(a.positions), atol=1e-6)


@few(0.25)
@given(t=st.lists(st.floats(-100, 100, allow_nan=False), min_size=3, max_size=20), slope=st.floats(-10, 10))
def test_shape_all_collinear_has_zero_area(t, slope):
    pts = [[x, slope * x + 1] for x in t]
    err = result_or_error(make_shape, pts, source="c.json", where="c.json")
    assert isinstance(err, InputError)


def _smooth(n):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 1 + 0.3 * np.sin(7 * a)
    return np.c_[r * np.cos(a), r * np.sin(a)]


def test_shape_with_10000_points_loads_in_seconds(tmp_path):
    pts = _smooth(MAX_POINTS)
    as_json = tmp_path / "big.json"
    as_json.write_text(json.dumps({"boundary": pts.tolist()}))
    as_text = tmp_path / "big.txt"
    as_text.write_text("\n".join(f"{float(x)!r} {float(y)!r}" for x, y in pts))
    for path in (as_json, as_text):
        t0 = time.perf_counter()
        shape = load_shape(path)
        assert time.perf_counter() - t0 < 5.0
        assert shape.n_points == MAX_POINTS
    too_many = tmp_path / "more.json"
    too_many.write_text(json.dumps({"boundary": _smooth(MAX_POINTS + 1).tolist()}))
    t0 = time.perf_counter()
    with pytest.warns(InputWarning, match="outline of 10001 points simplified"):  # over the limit: simplified, said
        assert load_shape(too_many).n_points <= MAX_POINTS
    assert time.perf_counter() - t0 < 2.0


def test_worst_case_10000_point_shape_is_bounded():
    """Every segment's bounding box overlaps every other (10,000 thin spikes meeting in the
    middle): the crossing test's worst case, still a few seconds."""
    a = np.linspace(0, 2 * np.pi, MAX_POINTS, endpoint=False)
    r = np.where(np.arange(MAX_POINTS) % 2 == 0, 1.0, 1e-3)
    t0 = time.perf_counter()
    shape = make_shape(np.c_[r * np.cos(a), r * np.sin(a)])
    assert time.perf_counter() - t0 < 30.0
    assert shape.n_corners == MAX_POINTS


@pytest.mark.parametrize("kind", ["oversized", "comments", "whitespace json", "long number json", "long number text", "deep json"])
def test_shape_large_files_are_bounded(tmp_path, kind):
    path = tmp_path / ("f.txt" if "text" in kind or kind == "comments" else "f.json")
    size = SHAPE_MAX_BYTES - 1000
    if kind == "oversized":
        path.write_bytes(b"0 0\n" * (SHAPE_MAX_BYTES // 4 + 1))
    elif kind == "comments":
        path.write_bytes(b"# nothing here\n" * (size // 15))
    elif kind == "whitespace json":
        path.write_bytes(b" " * size + b'{"boundary": [[0, 0], [1, 0], [0, 1]]}')
    elif kind == "long number json":
        path.write_bytes(b'{"boundary": [[0, 0], [1, 0], [0, 1' + b"1" * size + b"]]}")
    elif kind == "long number text":
        path.write_bytes(b"0 0\n1 0\n0 1" + b"1" * size + b"\n")
    else:
        path.write_bytes(b'{"boundary": ' + b"[" * (size // 2) + b"]" * (size // 2) + b"}")
    t0 = time.perf_counter()
    got = result_or_error(load_shape, path, where=str(path))
    assert time.perf_counter() - t0 < 10.0
    if kind == "whitespace json":
        assert got.n_points == 3
    else:
        assert isinstance(got, InputError)


@pytest.mark.parametrize("m", [-1, 0, 3, 100_001, 10**12])
def test_annotation_point_counts_are_bounded(m):
    """``--points`` below the corner count or absurdly large: a one-line error, at once."""
    shape = make_shape(L_SHAPE, source="l.json")
    t0 = time.perf_counter()
    with pytest.raises(InputError) as exc:
        annotate(shape, m)
    check_error(exc.value, "l.json")
    assert time.perf_counter() - t0 < 1.0


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
def test_endless_inputs_are_bounded():
    for fn in (load_shape, load_lattice, cm.load):
        t0 = time.perf_counter()
        with pytest.raises(InputError) as exc:
            fn("/dev/zero")
        check_error(exc.value, "/dev/zero")
        assert time.perf_counter() - t0 < 5.0


def test_unicode_paths(tmp_path):
    good = tmp_path / "形状 ü.json"
    good.write_bytes((EXAMPLES / "lshape.json").read_bytes())
    assert load_shape(good).n_corners == 6
    bad = tmp_path / "ünïcødé 形状.txt"
    bad.write_text("0 0\n1 zero\n1 1\n", encoding="utf-8")
    with pytest.raises(InputError) as exc:
        load_shape(bad)
    check_error(exc.value, f"{bad}:2")
    lat = tmp_path / "格子 é.toml"
    lat.write_bytes(FINE.replace(b'name = "fine"', 'name = "格子"'.encode()))
    assert load_lattice(lat).name == "格子"
    lat.write_bytes(FINE.replace(b"weight = 8", b"weight = 8.5", 1))
    with pytest.raises(InputError) as exc:
        load_lattice(lat)
    check_error(exc.value, str(lat))
    cat = tmp_path / "目録 ü.npz"
    cat.write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(InputError) as exc:
        cm.load(cat)
    check_error(exc.value, str(cat))


@pytest.mark.parametrize("reader", [load_shape, load_lattice, cm.load], ids=["shape", "lattice", "catalogue"])
def test_missing_files_and_folders(tmp_path, reader):
    for path in (tmp_path / "missing.json", tmp_path / "missing.toml", tmp_path):
        with pytest.raises(InputError) as exc:
            reader(path)
        check_error(exc.value, str(path))


# =============================================================================================
# lattices


@pytest.mark.parametrize("blob,name", [(FINE, "fine.toml"), (COARSE, "coarse.toml")])
def test_lattice_truncated(blob, name):
    """Every line-boundary prefix and ~150 byte prefixes of the built-in lattices."""
    src = f"dir/{name}"
    lines = blob.splitlines(keepends=True)
    cuts = {sum(len(x) for x in lines[:i]) for i in range(len(lines))} | set(range(0, len(blob), max(1, len(blob) // 150)))
    for cut in sorted(cuts):
        got = result_or_error(parse_lattice, blob[:cut], src, where=src)
        if not isinstance(got, InputError):  # only the comment-only tail may be cut
            assert got == parse_lattice(blob, src)


@few(0.5)
@given(data=st.data())
def test_lattice_byte_edits(data):
    blob = data.draw(edited(data.draw(st.sampled_from([FINE, COARSE]))))
    result_or_error(parse_lattice, blob, "e.toml", where="e.toml")


@pytest.mark.parametrize("value", ["8.5", "nan", "inf", "-inf", '"8"', "true", "1979-05-27", "07:32:00", "[8]", "{a = 8}",
                                   "99999999999999999999999", "-9223372036854775809", "0x7fffffffffffffff", "1e3"])
def test_lattice_weight_of_wrong_type(value):
    text = FINE.decode().replace("weight = 8", f"weight = {value}", 1)
    err = result_or_error(parse_lattice, text, "w.toml", where="w.toml:")
    assert isinstance(err, InputError)


@pytest.mark.parametrize("triple", ['"2-2"', '"2-2-2 "', '"２-２-２"', "222", '["2-2-2"]', '"6-6-6"', '"3-3-3-3"', '""', "true"])
def test_lattice_bad_triples(triple):
    text = FINE.decode().replace('triples = ["3-2-3"]', f"triples = [{triple}]", 1)
    assert text != FINE.decode()
    err = result_or_error(parse_lattice, text, "t.toml", where="t.toml:")
    assert isinstance(err, InputError)


@pytest.mark.parametrize("name", ['"a\\u001b[31mred"', '"two\\nlines"', '"tab\\there"', '"   "', '""', "3", "[]"])
def test_lattice_names_are_printable_one_liners(name):
    """The name is printed in tables and messages: no control characters (terminal escapes)."""
    text = FINE.decode().replace('name = "fine"', f"name = {name}", 1)
    err = result_or_error(parse_lattice, text, "n.toml", where="n.toml:")
    assert isinstance(err, InputError) and "name" in str(err)


@pytest.mark.parametrize("kind", ["oversized", "deep array", "deep table", "many keys", "nul bytes", "bom"])
def test_lattice_odd_files(tmp_path, kind):
    path = tmp_path / "odd.toml"
    if kind == "oversized":
        path.write_bytes(b"#" * (LATTICE_MAX_BYTES + 1))
    elif kind == "deep array":
        path.write_bytes(b"a = " + b"[" * 100_000 + b"]" * 100_000)
    elif kind == "deep table":
        path.write_bytes(b"a = " + b"{b = " * 10_000 + b"1" + b"}" * 10_000)
    elif kind == "many keys":
        path.write_bytes(b"".join(b"k%d = %d\n" % (i, i) for i in range(50_000)))
    elif kind == "nul bytes":
        path.write_bytes(FINE.replace(b"weight = 8", b"weight = \x008", 1))
    else:
        path.write_bytes(b"\xef\xbb\xbf" + FINE)
    t0 = time.perf_counter()
    err = result_or_error(load_lattice, path, where=str(path))
    assert time.perf_counter() - t0 < 10.0
    assert isinstance(err, InputError)


# =============================================================================================
# catalogues


class Saved(tuple):
    def __repr__(self):  # hypothesis prints the arguments of failing examples
        return f"<catalogue {self[0]}>"


@pytest.fixture(scope="module")
def cat2(tmp_path_factory):
    """A small catalogue file (k <= 2, 16 meshes), its bytes, arrays and metadata."""
    path = tmp_path_factory.mktemp("cat") / "c2.npz"
    cm.save(cm.generate(2), path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(arrays.pop("meta").tobytes())
    return Saved((path, path.read_bytes(), arrays, meta))


def read_everything(path):
    """Open a catalogue and touch every member: counts, each bucket, two meshes per bucket."""
    cat = cm.load(path)
    cat.counts()
    out = {}
    for b in cat.buckets():
        out[b.n] = b
        for mid in {str(b.ids[0]), str(b.ids[-1])}:
            cm.export(cat, mid)
    return out


def write_npz(path, arrays, meta, checksums=True):
    arrays = dict(arrays)
    meta = dict(meta)
    if checksums:
        meta["checksums"] = {k: cm._sha(v) for k, v in arrays.items()}
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    np.savez(path, **arrays)
    return path


@few(0.5)
@given(blob=st.binary(max_size=2000))
def test_catalogue_random_bytes(tmp_path_factory, blob):
    path = tmp_path_factory.mktemp("r") / "r.npz"
    path.write_bytes(blob)
    with pytest.raises(InputError) as exc:
        read_everything(path)
    check_error(exc.value, str(path))


def test_catalogue_truncated_anywhere(cat2, tmp_path):
    _, blob, _, _ = cat2
    path = tmp_path / "t.npz"
    for cut in sorted(set(range(0, len(blob), max(1, len(blob) // 60))) | {len(blob) - 1, len(blob) - 22}):
        path.write_bytes(blob[:cut])
        with pytest.raises(InputError) as exc:
            read_everything(path)
        check_error(exc.value, str(path))


@few(0.5)
@given(data=st.data())
def test_catalogue_byte_edits(cat2, tmp_path_factory, data):
    """Damage anywhere: refused, or (damage in zip metadata that does not matter) the same data."""
    path0, blob, _, _ = cat2
    damaged = data.draw(edited(blob, max_edits=2))
    path = tmp_path_factory.mktemp("e") / "e.npz"
    path.write_bytes(damaged)
    got = result_or_error(read_everything, path, where=str(path))
    if not isinstance(got, InputError):
        want = read_everything(path0)
        assert got.keys() == want.keys()
        for n in want:
            for field in ("ids", "k", "valences", "aut", "chiral"):
                np.testing.assert_array_equal(getattr(got[n], field), getattr(want[n], field))


meta_values = st.one_of(st.none(), st.booleans(), st.integers(-5, 10**6), st.floats(allow_nan=False), st.text(max_size=4),
                        st.lists(st.one_of(st.integers(-3, 30), st.text(max_size=2), st.booleans()), max_size=4),
                        st.dictionaries(st.text(max_size=8), st.one_of(st.integers(), st.text(max_size=4)), max_size=3))


@few(0.5)
@given(key=st.sampled_from(["format", "format_version", "internal", "lengths", "checksums", "extra"]),
       value=meta_values, delete=st.booleans())
def test_catalogue_metadata_fuzz(cat2, tmp_path_factory, key, value, delete):
    _, _, arrays, meta = cat2
    meta = dict(meta)
    if delete:
        meta.pop(key, None)
    else:
        meta[key] = value
    path = write_npz(tmp_path_factory.mktemp("m") / "m.npz", arrays, meta, checksums=False)
    got = result_or_error(read_everything, path, where=str(path))
    if not isinstance(got, InputError):  # only harmless changes load: the buckets listed are there
        assert key == "extra" or (key in ("internal", "lengths") and not delete)
        assert set(got) <= set(meta["lengths"])


def _swap_quad(a, n):
    q = a[f"n{n}.quads"].copy()
    q[0, [1, 2]] = q[0, [2, 1]]
    return {f"n{n}.quads": q}


def _other_valences(a, n):
    v = a[f"n{n}.valences"].copy()
    v[0] = np.roll(v[0], 1) if len(set(v[0].tolist())) > 1 else v[0]
    return {f"n{n}.valences": v}


TAMPER = {
    "valence 7": lambda a, n: {f"n{n}.valences": np.where(a[f"n{n}.valences"] == 3, 7, a[f"n{n}.valences"]).astype(np.int8)},
    "float valences": lambda a, n: {f"n{n}.valences": a[f"n{n}.valences"].astype(float)},
    "ids as ints": lambda a, n: {f"n{n}.ids": np.arange(len(a[f"n{n}.ids"]))},
    "ids 2-d": lambda a, n: {f"n{n}.ids": a[f"n{n}.ids"][:, None]},
    "short k": lambda a, n: {f"n{n}.k": a[f"n{n}.k"][:-1]},
    "long chiral": lambda a, n: {f"n{n}.chiral": np.r_[a[f"n{n}.chiral"], True]},
    "valences wrong width": lambda a, n: {f"n{n}.valences": a[f"n{n}.valences"][:, :-1]},
    "offsets backwards": lambda a, n: {f"n{n}.offsets": a[f"n{n}.offsets"][::-1].copy()},
    "offsets past the quads": lambda a, n: {f"n{n}.offsets": a[f"n{n}.offsets"] + 1},
    "quads with 3 corners": lambda a, n: {f"n{n}.quads": a[f"n{n}.quads"][:, :3]},
    "negative vertex": lambda a, n: {f"n{n}.quads": -a[f"n{n}.quads"]},
    "huge vertex": lambda a, n: {f"n{n}.quads": a[f"n{n}.quads"] + 30000},
    "quad turned over": _swap_quad,
    "valences of another mesh": _other_valences,
    "negative k": lambda a, n: {f"n{n}.k": -a[f"n{n}.k"] - 1},
    "wrong k": lambda a, n: {f"n{n}.k": a[f"n{n}.k"] + 1},
    "zero automorphisms": lambda a, n: {f"n{n}.aut": 0 * a[f"n{n}.aut"]},
    "object array": lambda a, n: {f"n{n}.aut": a[f"n{n}.aut"].astype(object)},
    "empty bucket": lambda a, n: {f"n{n}.{x}": a[f"n{n}.{x}"][:0] for x in ("ids", "k", "valences", "boundary", "aut", "chiral")},
}


@pytest.mark.parametrize("tamper", list(TAMPER), ids=list(TAMPER))
@pytest.mark.parametrize("n", [6, 8])
def test_catalogue_hand_built_with_right_checksums(cat2, tmp_path, tamper, n):
    """Checksums only catch accidents: arrays that disagree with each other are refused too."""
    _, _, arrays, meta = cat2
    a = dict(arrays)
    a.update(TAMPER[tamper](a, n))
    path = write_npz(tmp_path / "h.npz", a, meta)
    with pytest.raises(InputError) as exc:
        read_everything(path)
    check_error(exc.value, str(path))
    assert "rebuild" in str(exc.value) or "not a jaxmatch catalogue" in str(exc.value) or "unreadable" in str(exc.value)


def test_catalogue_member_too_large_is_refused_before_decompressing(cat2, tmp_path, monkeypatch):
    _, _, arrays, meta = cat2
    a = dict(arrays)
    a["n4.quads"] = np.zeros((2**18, 4), np.int16)  # 2 MiB of zeros: compresses to a few kB
    path = tmp_path / "bomb.npz"
    meta2 = dict(meta, checksums={k: cm._sha(v) for k, v in a.items()})
    a["meta"] = np.frombuffer(json.dumps(meta2).encode(), np.uint8)
    np.savez_compressed(path, **a)
    assert path.stat().st_size < 100_000
    monkeypatch.setattr(cm, "MAX_MEMBER_BYTES", 2**20)
    t0 = time.perf_counter()
    with pytest.raises(InputError, match="uncompressed") as exc:
        cm.load(path)
    check_error(exc.value, str(path))
    assert time.perf_counter() - t0 < 1.0


def test_catalogue_member_claiming_a_huge_array(cat2, tmp_path):
    """An .npy header announcing 10**12 elements over a few bytes of data."""
    path0, _, _, _ = cat2
    path = tmp_path / "liar.npz"
    with zipfile.ZipFile(path0) as src, zipfile.ZipFile(path, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "n4.quads.npy":
                header = "{'descr': '<i2', 'fortran_order': False, 'shape': (1000000000000, 4), }"
                header = header + " " * (63 - len(header) % 64) + "\n"
                data = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode() + b"\0" * 64
            dst.writestr(info.filename, data)
    t0 = time.perf_counter()
    with pytest.raises(InputError) as exc:
        read_everything(path)
    check_error(exc.value, str(path))
    assert time.perf_counter() - t0 < 5.0


def test_catalogue_zip_with_many_members(cat2, tmp_path):
    path0, _, _, _ = cat2
    path = tmp_path / "many.npz"
    with zipfile.ZipFile(path0) as src, zipfile.ZipFile(path, "w") as dst:
        for info in src.infolist():
            dst.writestr(info.filename, src.read(info))
        for i in range(20_000):
            dst.writestr(f"junk{i}.npy", b"")
    t0 = time.perf_counter()
    result_or_error(read_everything, path, where=str(path))
    assert time.perf_counter() - t0 < 10.0


# =============================================================================================
# label files (the tuner's; only when the module exists)


def test_label_files_random_lines(tmp_path):
    labels = pytest.importorskip("jaxmatch.tuning.labels")
    cat = cm.load(cm.default_path()) if cm.default_path().exists() else None
    if cat is None or not hasattr(labels, "load_labels"):
        pytest.skip("no default catalogue or no load_labels")
    good = {"shape": {"boundary": SQUARE.tolist()}, "preferred": str(next(cat.buckets([1])).ids[0])}
    rng = np.random.default_rng(0)
    lines = [json.dumps(good), "", "# comment", "{", "[]", '{"shape": 3, "preferred": "k1-x"}',
             json.dumps({**good, "rotation": -1}), json.dumps({**good, "rotation": 10**30}),
             json.dumps({**good, "reflected": "yes"}), json.dumps({**good, "extra": 1}),
             json.dumps({**good, "shape": "no/such/file.json"}), json.dumps({**good, "shape": {"boundary": [[0, 0], [1, 1]]}}),
             json.dumps({**good, "preferred": "k9-000000000000"}), '{"shape": NaN, "preferred": Infinity}',
             "\x00\x01", "ü" * 10]
    path = tmp_path / "标签 ü.jsonl"
    for trial in range(40):
        pick = [lines[i] for i in rng.integers(0, len(lines), rng.integers(1, 6))]
        blob = "\n".join(pick).encode()
        if trial % 5 == 0:
            blob = blob[: rng.integers(0, len(blob) + 1)]
        path.write_bytes(blob)
        for skip_bad in (False, True):
            result_or_error(labels.load_labels, path, cat, where=str(path), skip_bad=skip_bad)


# =============================================================================================
# end to end: exit 2, one line, no traceback


def test_cli_bad_shape_at_unicode_path(tmp_path):
    bad = tmp_path / "形状 ü.json"
    bad.write_bytes((EXAMPLES / "lshape.json").read_bytes()[:40])
    line = assert_one_line_exit_2(run_cli("annotate", bad), str(bad), "JSON")
    assert line.startswith("error: ")
    crossing = tmp_path / "交差 é.txt"
    crossing.write_text("0 0\n1 1\n1 0\n0 1\n", encoding="utf-8")
    assert_one_line_exit_2(run_cli("annotate", crossing), str(crossing), "crosses")


def test_cli_bad_lattice_and_endless_lattice(tmp_path):
    lat = tmp_path / "格子.toml"
    lat.write_bytes(FINE[: len(FINE) // 2])
    assert_one_line_exit_2(run_cli("lattice", "show", lat), f"{lat}:")
    if Path("/dev/zero").exists():
        assert_one_line_exit_2(run_cli("lattice", "show", "/dev/zero", timeout=60), "/dev/zero", "larger than")


def test_cli_damaged_and_old_catalogues(cat2, tmp_path):
    _, blob, arrays, meta = cat2
    damaged = tmp_path / "目録 damaged.npz"
    b = bytearray(blob)
    b[len(b) // 3] ^= 0xFF
    damaged.write_bytes(bytes(b))
    assert_one_line_exit_2(run_cli("catalogue", "info", damaged), str(damaged))
    old = write_npz(tmp_path / "old.npz", arrays, dict(meta, format_version=0))
    line = assert_one_line_exit_2(run_cli("catalogue", "info", old), str(old), "format version 0")
    assert f"rebuild it with 'jaxmatch catalogue build --internal 0..2 --out {old}'" in line  # the file's own sizes
    inconsistent = write_npz(tmp_path / "hand.npz", {**arrays, "n6.k": arrays["n6.k"][:-1]}, meta)
    assert_one_line_exit_2(run_cli("catalogue", "export", inconsistent, "--id", str(arrays["n6.ids"][0])),
                           str(inconsistent), "inconsistent")
