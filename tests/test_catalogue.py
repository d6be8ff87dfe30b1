"""The catalogue: complete, duplicate-free, valid, stable ids, robust storage."""

from __future__ import annotations

import json
import zipfile
from collections import Counter

import numpy as np
import pytest

from jaxmatch.catalogue import store as cm
from jaxmatch.catalogue.canon import canonical, mesh_id
from jaxmatch.errors import InputError
from jaxmatch.scoring.lattice import load_lattice
from jaxmatch.catalogue.mesh import boundary_valences, triples, validate, valences
from jaxmatch.catalogue.shelling import shell


@pytest.fixture(scope="module")
def entries3():
    return cm.generate(3)


@pytest.fixture(scope="module")
def default_cat():
    return cm.default_catalogue()


def ids_by_k(entries):
    out = {}
    for e in entries:
        out.setdefault(e.k, set()).add(e.id)
    return out


# ----------------------------------------------------------------------------- generation


def test_small_counts(entries3):
    assert {k: len(v) for k, v in ids_by_k(entries3).items()} == {0: 1, 1: 3, 2: 12, 3: 96}


def test_k0_is_the_single_quad(entries3):
    (e,) = [e for e in entries3 if e.k == 0]
    assert e.mesh.n_quads == 1 and e.mesh.n_boundary == 4


def test_k1_is_the_three_stars(entries3):
    stars = sorted(tuple(sorted(Counter(boundary_valences(e.mesh).tolist()).items())) for e in entries3 if e.k == 1)
    # star of valence d: d spoke ends (valence 3) and d diagonal corners (valence 2)
    assert stars == [((2, d), (3, d)) for d in (3, 4, 5)]


@pytest.mark.slow
def test_agrees_with_independent_shelling_enumerator(entries3):
    """Same sets of canonical ids for k <= 3 from two different enumerators."""
    oracle = shell(3)
    oracle_ids = {k: {mesh_id(key, k) for key in disks} for k, disks in oracle.items()}
    assert oracle_ids == ids_by_k(entries3)


def test_shelling_and_closing_agree_quickly_for_k2():
    oracle = shell(2)
    ours = ids_by_k(cm.generate(2))
    assert {k: {mesh_id(key, k) for key in d} for k, d in oracle.items()} == ours


def test_every_mesh_is_valid_and_in_the_class(entries3):
    for e in entries3:
        assert validate(e.mesh) == [], e.id
        val = valences(e.mesh.quads, e.mesh.n_vertices)
        assert val.max() <= 5
        assert e.mesh.n_internal == e.k
        inner = np.ones(e.mesh.n_vertices, bool)
        inner[e.mesh.boundary] = False
        assert (4 - val[inner]).sum() + (3 - val[~inner]).sum() == 4  # angle-sum identity
        if e.k >= 1:  # every quad holds an internal vertex
            assert all(inner[q].any() for q in e.mesh.quads)


def test_default_catalogue_k4_k5_meshes_are_valid(default_cat):
    rng = np.random.default_rng(0)
    for n in default_cat.lengths:
        b = default_cat.bucket(n, [4, 5])
        for i in rng.choice(len(b.ids), size=min(20, len(b.ids)), replace=False) if len(b.ids) else []:
            m = default_cat.mesh(str(b.ids[i]))
            assert validate(m) == [], b.ids[i]
            assert m.n_internal == b.k[i]
            np.testing.assert_array_equal(boundary_valences(m), b.valences[i])


def test_no_duplicates(default_cat):
    ids = np.concatenate([b.ids for b in default_cat.buckets()])
    assert len(ids) == len(set(ids.tolist()))


def test_ids_stable_across_builds_and_equal_to_the_shipped_catalogue(entries3, default_cat):
    again = cm.generate(3)
    assert [e.id for e in again] == [e.id for e in entries3]
    shipped = {str(i) for b in default_cat.buckets([0, 1, 2, 3]) for i in b.ids}
    assert shipped == {e.id for e in entries3}


def test_canonical_id_ignores_labelling_rotation_and_mirror(entries3):
    rng = np.random.default_rng(1)
    for e in entries3[::7]:
        q, b = e.mesh.quads, e.mesh.boundary
        perm = rng.permutation(e.mesh.n_vertices)
        q2 = perm[q]
        b2 = np.roll(perm[b], 3)
        val = valences(q2, e.mesh.n_vertices)
        assert mesh_id(canonical(q2.tolist(), b2.tolist(), val.tolist()).key, e.k) == e.id
        mq = q2[:, ::-1]  # mirror image
        mb = b2[::-1]
        assert mesh_id(canonical(mq.tolist(), mb.tolist(), val.tolist()).key, e.k) == e.id


def test_symmetry_counts(entries3):
    by_k = Counter()
    for e in entries3:
        assert e.aut >= 1
        by_k[e.k] += 2 if e.chiral else 1
    stars = [e for e in entries3 if e.k == 1]
    assert sorted(e.aut for e in stars) == [6, 8, 10]  # dihedral groups of the stars
    assert by_k[3] >= 96


def test_weeded_lattice_triples_never_occur(default_cat):
    lat = load_lattice("fine")
    seen = set()
    for b in default_cat.buckets(list(range(1, 6))):
        for row in triples_of(b.valences):
            seen.add(row)
    for kind_weeded in lat.weeded:
        assert not (set(kind_weeded) & seen)


def triples_of(vals):
    out = set()
    for v in vals:
        for t in triples(v).tolist():
            out.add("-".join(map(str, t)))
    return out


# ----------------------------------------------------------------------------- storage


@pytest.fixture()
def saved(tmp_path, entries3):
    p = tmp_path / "c.npz"
    cm.save(entries3, p)
    return p


def test_round_trip(saved, entries3):
    cat = cm.load(saved)
    assert cat.internal == [0, 1, 2, 3]
    for e in entries3[::5]:
        m = cat.mesh(e.id)
        np.testing.assert_array_equal(m.quads, e.mesh.quads)
        np.testing.assert_array_equal(m.boundary, e.mesh.boundary)


def test_buckets_group_by_boundary_length(saved):
    cat = cm.load(saved)
    for b in cat.buckets():
        assert b.valences.shape == (len(b.ids), b.n)
    assert sum(len(b.ids) for b in cat.buckets([3])) == 96


def test_info_json_shape(saved):
    c = cm.load(saved).counts()
    assert c["format_version"] == cm.FORMAT_VERSION
    assert c["per_k"]["3"]["meshes"] == 96
    assert c["per_k"]["3"]["up_to_rotation"] >= 96
    assert sum(c["per_boundary_length"].values()) == 112


def test_export(saved, entries3):
    e = entries3[10]
    d = cm.export(cm.load(saved), e.id)
    assert set(d) == {"id", "internal_vertices", "quads", "boundary", "triples"}
    assert d["internal_vertices"] == e.k and len(d["triples"]) == len(d["boundary"])


def test_unknown_id_is_an_input_error(saved):
    with pytest.raises(InputError, match="no mesh"):
        cm.load(saved).mesh("k9-000000000000")


@pytest.mark.parametrize("damage", ["truncate", "garbage", "text", "empty", "flip"])
def test_damaged_files_are_refused(saved, damage):
    data = saved.read_bytes()
    if damage == "truncate":
        saved.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        saved.write_bytes(np.random.default_rng(0).bytes(4096))
    elif damage == "text":
        saved.write_text("hello")
    elif damage == "empty":
        saved.write_bytes(b"")
    else:  # flip a byte inside the largest member's data
        with zipfile.ZipFile(saved) as z:
            info = max(z.infolist(), key=lambda i: i.compress_size)
        b = bytearray(data)
        pos = info.header_offset + 30 + len(info.filename) + info.compress_size // 2
        b[pos] ^= 0xFF
        saved.write_bytes(bytes(b))
    with pytest.raises(InputError) as exc:
        cat = cm.load(saved)
        for bucket in cat.buckets():
            cat.mesh(str(bucket.ids[0]))
    assert str(saved) in str(exc.value) and "\n" not in str(exc.value)


def test_foreign_npz_and_old_version_are_refused(tmp_path, saved):
    foreign = tmp_path / "f.npz"
    np.savez(foreign, a=np.arange(3))
    with pytest.raises(InputError, match="not a jaxmatch catalogue"):
        cm.load(foreign)
    with zipfile.ZipFile(saved) as z:
        members = {n: z.read(n) for n in z.namelist()}
    meta = json.loads(np.load(saved)["meta"].tobytes())
    meta["format_version"] = 0
    old = tmp_path / "old.npz"
    arrays = {k: np.load(saved)[k] for k in np.load(saved).files}
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    np.savez(old, **arrays)
    assert members
    with pytest.raises(InputError, match="rebuild"):
        cm.load(old)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such catalogue"):
        cm.load(tmp_path / "nope.npz")


def test_save_is_atomic(tmp_path, entries3, monkeypatch):
    p = tmp_path / "c.npz"
    cm.save(entries3, p)
    before = p.read_bytes()

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(RuntimeError):
        cm.save(entries3[:3], p)
    assert p.read_bytes() == before
    assert [f.name for f in tmp_path.iterdir()] == ["c.npz"]


@pytest.mark.parametrize("text,expected", [("3", [3]), ("0..4", [0, 1, 2, 3, 4]), (" 2..2 ", [2])])
def test_parse_range(text, expected):
    assert cm.parse_range(text) == expected


@pytest.mark.parametrize("text", ["", "a", "3..1", "-1", "1..x"])
def test_parse_range_rejects(text):
    with pytest.raises(InputError):
        cm.parse_range(text)
