"""The mesh catalogue: generation (see :mod:`jaxmatch.catalogue.closing`) and storage.

File format (version :data:`FORMAT_VERSION`): one ``.npz`` (zip of numpy arrays, read
lazily array by array), written atomically. Member ``meta`` holds UTF-8 JSON:
``{"format": "jaxmatch-catalogue", "format_version": 1, "internal": [k...],
"lengths": [n...], "checksums": {member: sha256}}``. Per boundary length n (a *bucket*):

* ``n<n>.ids``      (N,) str: stable ids ``k<K>-<hex>`` (canonical form hash)
* ``n<n>.k``        (N,) int16: internal vertices
* ``n<n>.valences`` (N, n) int8: boundary valences along the ccw loop
* ``n<n>.boundary`` (N, n) int16: the ccw boundary loop (vertex ids)
* ``n<n>.offsets``  (N+1,) int32 and ``n<n>.quads`` (sum F, 4) int16: ccw quads per mesh
* ``n<n>.aut``      (N,) int16: automorphisms (rotations and reflections)
* ``n<n>.chiral``   (N,) bool: mirror image differs up to rotation (counts twice up to rotation)

Meshes are stored canonically relabelled (boundary vertices 0..n-1 in loop order, starting at
the canonical start), so their valence sequences are canonical too.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, NamedTuple

import numpy as np

from jaxmatch.cache import Cache
from jaxmatch.catalogue.canon import mesh_id, relabel
from jaxmatch.errors import InputError
from jaxmatch.files import atomic_path
from jaxmatch.catalogue.mesh import QuadMesh, boundary_valences, triples, validate, valences

FORMAT = "jaxmatch-catalogue"
FORMAT_VERSION = 1
DEFAULT_MAX_INTERNAL = 5
LARGE_K = 7
"""Largest k that ``jaxmatch catalogue build`` accepts without ``--allow-large``."""
_ARRAYS = ("ids", "k", "valences", "boundary", "offsets", "quads", "aut", "chiral")
MAX_MEMBER_BYTES = 2**29
"""Largest accepted uncompressed catalogue member (the k <= 5 catalogue's largest is 0.5 MB)."""
MAX_META_BYTES = 2**22
_REBUILD = "rebuild it with 'jaxmatch catalogue build'"


class Bucket(NamedTuple):
    """All meshes of one boundary length n.

    ids: (N,) str; k: (N,) int; valences: (N, n) int8 ccw boundary valences;
    aut: (N,) automorphism counts; chiral: (N,) bool.
    """

    n: int
    ids: np.ndarray
    k: np.ndarray
    valences: np.ndarray
    aut: np.ndarray
    chiral: np.ndarray


@dataclass(frozen=True)
class Entry:
    """One generated mesh with its canonical data."""

    id: str
    k: int
    mesh: QuadMesh
    aut: int
    chiral: bool


def parse_range(text: str) -> list[int]:
    """``"3"`` -> [3]; ``"0..4"`` -> [0, 1, 2, 3, 4]. Raises InputError."""
    t = str(text).strip()
    try:
        if ".." in t:
            lo, hi = t.split("..", 1)
            a, b = int(lo), int(hi)
        else:
            a = b = int(t)
    except ValueError:
        raise InputError(f"expected K or K1..K2 with integers, got {text!r}", "--internal") from None
    if a < 0 or b < a:
        raise InputError(f"empty or negative range {text!r}", "--internal")
    return list(range(a, b + 1))


def generate(max_internal: int, progress: Callable | None = None, workers: int = 1) -> list[Entry]:
    """All catalogue meshes with k = 0 .. max_internal, canonical, sorted by (k, n, id).

    workers: processes used to expand each level (see :func:`jaxmatch.catalogue.closing.close_all`).
    """
    from jaxmatch.catalogue.closing import close_all

    found = close_all(max_internal, progress=progress, workers=workers)
    entries = []
    for k, disks in found.items():
        for d in disks.values():
            entries.append(entry_from_quads(d.quads, d.boundary, d.vals, k))
    entries.sort(key=lambda e: (e.k, e.mesh.n_boundary, e.id))
    return entries


def entry_from_quads(quads, boundary, vals, k: int) -> Entry:
    """Canonicalise one disk mesh into a catalogue :class:`Entry`."""
    from jaxmatch.catalogue.canon_fast import canonical_key  # numba: loaded only when building

    c = canonical_key(quads, boundary, vals)
    q, b = relabel(quads, boundary, c.start)
    return Entry(id=mesh_id(c.key, k), k=k, mesh=QuadMesh(quads=q, boundary=b), aut=c.aut, chiral=c.chiral)


def _sha(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a).tobytes() + str(a.dtype).encode() + str(a.shape).encode()).hexdigest()


def save(entries: list[Entry], path: str | os.PathLike) -> None:
    """Write a catalogue file atomically (temp file + rename)."""
    arrays: dict[str, np.ndarray] = {}
    by_n: dict[int, list[Entry]] = {}
    for e in entries:
        by_n.setdefault(e.mesh.n_boundary, []).append(e)
    for n, es in sorted(by_n.items()):
        nq = np.array([e.mesh.n_quads for e in es])
        arrays[f"n{n}.ids"] = np.array([e.id for e in es])
        arrays[f"n{n}.k"] = np.array([e.k for e in es], dtype=np.int16)
        arrays[f"n{n}.valences"] = np.stack([boundary_valences(e.mesh) for e in es]).astype(np.int8)
        arrays[f"n{n}.boundary"] = np.stack([e.mesh.boundary for e in es]).astype(np.int16)
        arrays[f"n{n}.offsets"] = np.concatenate([[0], np.cumsum(nq)]).astype(np.int32)
        arrays[f"n{n}.quads"] = np.concatenate([e.mesh.quads for e in es]).astype(np.int16)
        arrays[f"n{n}.aut"] = np.array([e.aut for e in es], dtype=np.int16)
        arrays[f"n{n}.chiral"] = np.array([e.chiral for e in es], dtype=bool)
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "internal": sorted({e.k for e in entries}),
        "lengths": sorted(by_n),
        "checksums": {name: _sha(a) for name, a in arrays.items()},
    }
    arrays["meta"] = np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)


@dataclass
class Catalogue:
    """A catalogue file opened for reading; buckets are loaded on demand and verified.

    Use :func:`load`. ``internal``: the k values present; ``lengths``: boundary lengths.
    """

    path: Path
    meta: dict
    _npz: object = field(repr=False)
    _cache: dict = field(default_factory=dict, repr=False)
    cache: Cache = field(default_factory=Cache, repr=False)
    """What is kept between calls for this catalogue's meshes (:mod:`jaxmatch.cache`)."""

    def reopen(self) -> None:
        """Open the file again for this process: a process forked from the one that opened it
        must not read through the shared file offset (:func:`jaxmatch.parallel.ordered_map`'s
        workers call this). Buckets already read stay."""
        self._npz = np.load(self.path, allow_pickle=False)

    @property
    def internal(self) -> list[int]:
        return list(self.meta["internal"])

    @property
    def lengths(self) -> list[int]:
        return list(self.meta["lengths"])

    @property
    def format_version(self) -> int:
        return int(self.meta["format_version"])

    def _array(self, name: str) -> np.ndarray:
        if name in self._cache:
            return self._cache[name]
        try:
            a = self._npz[name]
        except Exception as err:  # zip CRC errors, truncated members
            raise InputError(f"catalogue member {name} is unreadable ({type(err).__name__}); rebuild it", str(self.path)) from None
        if _sha(a) != self.meta["checksums"].get(name):
            raise InputError(f"checksum mismatch in {name}: the file is corrupted; {_REBUILD}", str(self.path))
        self._cache[name] = a
        return a

    def _bad(self, n: int, problem: str) -> InputError:
        return InputError(f"catalogue bucket n{n} is inconsistent ({problem}); {_REBUILD}", str(self.path))

    def _checked(self, n: int) -> dict:
        """The arrays of bucket ``n``, verified against each other (types, shapes, ranges)."""
        key = ("bucket", n)
        if key in self._cache:
            return self._cache[key]
        a = {name: self._array(f"n{n}.{name}") for name in _ARRAYS}
        kinds = {"ids": "U", "k": "iu", "valences": "iu", "boundary": "iu", "offsets": "iu", "quads": "iu", "aut": "iu", "chiral": "b"}
        for name, kind in kinds.items():
            if a[name].dtype.kind not in kind:
                raise self._bad(n, f"{name} has dtype {a[name].dtype}")
        N = a["ids"].shape[0] if a["ids"].ndim == 1 else -1
        shapes = {"ids": (N,), "k": (N,), "valences": (N, n), "boundary": (N, n), "offsets": (N + 1,), "aut": (N,), "chiral": (N,)}
        for name, shape in shapes.items():
            if a[name].shape != shape:
                raise self._bad(n, f"{name} has shape {a[name].shape}, expected {shape}")
        q, off = a["quads"], a["offsets"].astype(np.int64)
        if q.ndim != 2 or q.shape[1] != 4:
            raise self._bad(n, f"quads has shape {q.shape}, expected (F, 4)")
        if off[0] != 0 or np.any(np.diff(off) < 1) or off[-1] != q.shape[0]:
            raise self._bad(n, "offsets do not partition the quads")
        if N and (a["valences"].min() < 2 or a["valences"].max() > 5):
            raise self._bad(n, "boundary valences outside 2..5")
        if N and (a["k"].min() < 0 or a["aut"].min() < 1):
            raise self._bad(n, "negative internal vertex count or automorphism count")
        if q.size and q.min() < 0:
            raise self._bad(n, "negative vertex index")
        self._cache[key] = a
        return a

    def bucket(self, n: int, internal: list[int] | None = None) -> Bucket:
        """The meshes of boundary length n (optionally only those with k in ``internal``)."""
        if n not in self.lengths:
            raise InputError(f"no bucket of boundary length {n}", str(self.path))
        a = self._checked(n)
        ids, k, vals, aut, chiral = a["ids"], a["k"], a["valences"], a["aut"], a["chiral"]
        sel = np.ones(len(ids), bool) if internal is None else np.isin(k, internal)
        return Bucket(n, ids[sel], k[sel].astype(np.int32), vals[sel], aut[sel], chiral[sel])

    def buckets(self, internal: list[int] | None = None) -> Iterator[Bucket]:
        """Buckets in increasing boundary length; empty ones skipped."""
        for n in self.lengths:
            b = self.bucket(n, internal)
            if len(b.ids):
                yield b

    def mesh(self, mesh_id: str) -> QuadMesh:
        """The stored mesh with this id (verified on first use, then kept; its arrays are
        read-only). Raises InputError if absent."""
        key = ("mesh", mesh_id)
        if key not in self._cache:
            self._cache[key] = self._load_mesh(mesh_id)
        return self._cache[key]

    def _load_mesh(self, mesh_id: str) -> QuadMesh:
        for n in self.lengths:
            a = self._checked(n)
            hit = np.flatnonzero(a["ids"] == mesh_id)
            if hit.size:
                i = int(hit[0])
                off = a["offsets"]
                quads = a["quads"][off[i] : off[i + 1]].astype(np.int32)
                boundary = a["boundary"][i].astype(np.int32)
                m = QuadMesh(quads=quads, boundary=boundary)
                problems = validate(m)
                if not problems and not np.array_equal(boundary_valences(m), a["valences"][i]):
                    problems = ["stored boundary valences differ from the quads"]
                if not problems and m.n_internal != int(a["k"][i]):
                    problems = ["stored internal vertex count differs from the quads"]
                if problems:
                    raise InputError(f"mesh {mesh_id} is not a valid catalogue mesh ({problems[0]}); {_REBUILD}", str(self.path))
                quads.setflags(write=False)
                boundary.setflags(write=False)
                return m
        raise InputError(f"no mesh with id {mesh_id!r}", str(self.path))

    def counts(self) -> dict:
        """``{"per_k": {k: {"meshes", "up_to_rotation"}}, "per_boundary_length": {n: count}}``."""
        per_k: dict[str, dict[str, int]] = {}
        per_n: dict[str, int] = {}
        for b in self.buckets():
            per_n[str(b.n)] = int(len(b.ids))
            for k in np.unique(b.k):
                m = b.k == k
                d = per_k.setdefault(str(int(k)), {"meshes": 0, "up_to_rotation": 0})
                d["meshes"] += int(m.sum())
                d["up_to_rotation"] += int(m.sum() + b.chiral[m].sum())
        per_k = dict(sorted(per_k.items(), key=lambda kv: int(kv[0])))
        return {"format_version": self.format_version, "per_k": per_k, "per_boundary_length": per_n}


def _sizes_of(meta: dict) -> str:
    """``"K1..K2"`` for the sizes a catalogue's metadata lists (``0..DEFAULT_MAX_INTERNAL`` when
    it lists none readable), for rebuild advice."""
    ks = meta.get("internal")
    if isinstance(ks, list) and ks and all(isinstance(k, int) and not isinstance(k, bool) and 0 <= k <= 99 for k in ks):
        return f"{min(ks)}..{max(ks)}" if min(ks) != max(ks) else str(ks[0])
    return f"0..{DEFAULT_MAX_INTERNAL}"


def load(path: str | os.PathLike) -> Catalogue:
    """Open a catalogue file; refuse corrupted, truncated, foreign or old-version files."""
    p = Path(path)
    if not p.exists():
        raise InputError("no such catalogue file", str(p))
    if not p.is_file():
        raise InputError("not a catalogue file (a folder or a device)", str(p))
    try:
        npz = np.load(p, allow_pickle=False)
        if not hasattr(npz, "files"):
            raise ValueError("not an npz archive")
        for info in npz.zip.infolist():  # refuse zip bombs before decompressing anything
            limit = MAX_META_BYTES if info.filename == "meta.npy" else MAX_MEMBER_BYTES
            if info.file_size > limit:
                raise InputError(f"catalogue member {info.filename} is {info.file_size} bytes uncompressed, more than the "
                                 f"limit {limit}; not a jaxmatch catalogue", str(p))
        meta = json.loads(bytes(npz["meta"]).decode())
    except InputError:
        raise
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"not a jaxmatch catalogue ({type(err).__name__}); build one with 'jaxmatch catalogue build'", str(p)) from None
    except Exception as err:  # anything else a damaged zip can raise
        raise InputError(f"unreadable catalogue ({type(err).__name__})", str(p)) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError("not a jaxmatch catalogue (wrong format tag)", str(p))
    version = meta.get("format_version")
    if isinstance(version, bool) or version != FORMAT_VERSION:
        raise InputError(
            f"catalogue format version {meta.get('format_version')} is not the supported {FORMAT_VERSION}; "
            f"rebuild it with 'jaxmatch catalogue build --internal {_sizes_of(meta)} --out {p}'", str(p))
    for key in ("internal", "lengths", "checksums"):
        if key not in meta:
            raise InputError(f"catalogue metadata lacks {key!r}", str(p))

    def int_list(v):
        return isinstance(v, list) and all(isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= 10_000 for x in v)

    if not int_list(meta["internal"]) or not int_list(meta["lengths"]) or len(set(meta["lengths"])) != len(meta["lengths"]):
        raise InputError(f"catalogue metadata is malformed ('internal' and 'lengths' must be lists of small integers); {_REBUILD}", str(p))
    if not isinstance(meta["checksums"], dict) or not all(isinstance(v, str) for v in meta["checksums"].values()):
        raise InputError(f"catalogue metadata is malformed ('checksums' must map members to hashes); {_REBUILD}", str(p))
    missing = [f"n{n}.{a}" for n in meta["lengths"] for a in _ARRAYS if f"n{n}.{a}" not in npz.files]
    if missing:
        raise InputError(f"catalogue is missing {missing[0]} (truncated?)", str(p))
    return Catalogue(path=p, meta=meta, _npz=npz)


def default_path() -> Path:
    """The catalogue shipped with the package (k = 0 .. DEFAULT_MAX_INTERNAL)."""
    return Path(__file__).resolve().parents[1] / "data" / f"catalogue-k0-{DEFAULT_MAX_INTERNAL}.npz"


def default_catalogue() -> Catalogue:
    """The shipped default catalogue; built and cached there on first use if missing."""
    p = default_path()
    if not p.exists():
        save(generate(DEFAULT_MAX_INTERNAL), p)
    return load(p)


def build(internal: list[int], out: str | os.PathLike, progress: Callable | None = None, workers: int = 1) -> dict:
    """Generate meshes for the k in ``internal`` and save them to ``out``. Returns timing info."""
    t0 = time.perf_counter()
    entries = [e for e in generate(max(internal), progress=progress, workers=workers) if e.k in internal]
    t1 = time.perf_counter()
    save(entries, out)
    return {"meshes": len(entries), "generate_s": t1 - t0, "save_s": time.perf_counter() - t1}


def export(cat: Catalogue, mesh_id: str) -> dict:
    """``{"id", "internal_vertices", "quads", "boundary", "triples"}`` for one mesh."""
    m = cat.mesh(mesh_id)
    val = valences(m.quads, m.n_vertices)
    return {
        "id": mesh_id,
        "internal_vertices": int(m.n_internal),
        "quads": m.quads.tolist(),
        "boundary": m.boundary.tolist(),
        "triples": triples(val[m.boundary]).tolist(),
    }
