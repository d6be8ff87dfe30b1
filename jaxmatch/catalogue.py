"""The mesh catalogue: generation (see :mod:`jaxmatch.closing`) and storage.

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

from .canon import mesh_id, relabel
from .canon_fast import canonical_key
from .errors import InputError
from .files import atomic_path
from .mesh import QuadMesh, boundary_valences, triples, valences

FORMAT = "jaxmatch-catalogue"
FORMAT_VERSION = 1
DEFAULT_MAX_INTERNAL = 5
_ARRAYS = ("ids", "k", "valences", "boundary", "offsets", "quads", "aut", "chiral")


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

    workers: processes used to expand each level (see :func:`jaxmatch.closing.close_all`).
    """
    from .closing import close_all

    found = close_all(max_internal, progress=progress, workers=workers)
    entries = []
    for k, disks in found.items():
        for d in disks.values():
            entries.append(entry_from_quads(d.quads, d.boundary, d.vals, k))
    entries.sort(key=lambda e: (e.k, e.mesh.n_boundary, e.id))
    return entries


def entry_from_quads(quads, boundary, vals, k: int) -> Entry:
    """Canonicalise one disk mesh into a catalogue :class:`Entry`."""
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
            raise InputError(f"checksum mismatch in {name}: the file is corrupted; rebuild it with 'jaxmatch catalogue build'", str(self.path))
        self._cache[name] = a
        return a

    def bucket(self, n: int, internal: list[int] | None = None) -> Bucket:
        """The meshes of boundary length n (optionally only those with k in ``internal``)."""
        ids, k = self._array(f"n{n}.ids"), self._array(f"n{n}.k")
        vals, aut, chiral = self._array(f"n{n}.valences"), self._array(f"n{n}.aut"), self._array(f"n{n}.chiral")
        sel = np.ones(len(ids), bool) if internal is None else np.isin(k, internal)
        return Bucket(n, ids[sel], k[sel].astype(np.int32), vals[sel], aut[sel], chiral[sel])

    def buckets(self, internal: list[int] | None = None) -> Iterator[Bucket]:
        """Buckets in increasing boundary length; empty ones skipped."""
        for n in self.lengths:
            b = self.bucket(n, internal)
            if len(b.ids):
                yield b

    def mesh(self, mesh_id: str) -> QuadMesh:
        """The stored mesh with this id. Raises InputError if absent."""
        for n in self.lengths:
            ids = self._array(f"n{n}.ids")
            hit = np.flatnonzero(ids == mesh_id)
            if hit.size:
                i = int(hit[0])
                off = self._array(f"n{n}.offsets")
                quads = self._array(f"n{n}.quads")[off[i] : off[i + 1]].astype(np.int32)
                boundary = self._array(f"n{n}.boundary")[i].astype(np.int32)
                return QuadMesh(quads=quads, boundary=boundary)
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


def load(path: str | os.PathLike) -> Catalogue:
    """Open a catalogue file; refuse corrupted, truncated, foreign or old-version files."""
    p = Path(path)
    if not p.is_file():
        raise InputError("no such catalogue file", str(p))
    try:
        npz = np.load(p, allow_pickle=False)
        if not hasattr(npz, "files"):
            raise ValueError("not an npz archive")
        meta = json.loads(bytes(npz["meta"]).decode())
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"not a jaxmatch catalogue ({type(err).__name__}); build one with 'jaxmatch catalogue build'", str(p)) from None
    except Exception as err:  # anything else a damaged zip can raise
        raise InputError(f"unreadable catalogue ({type(err).__name__})", str(p)) from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise InputError("not a jaxmatch catalogue (wrong format tag)", str(p))
    if meta.get("format_version") != FORMAT_VERSION:
        raise InputError(
            f"catalogue format version {meta.get('format_version')} is not the supported {FORMAT_VERSION}; "
            "rebuild it with 'jaxmatch catalogue build --internal 0..5 --out PATH'", str(p))
    for key in ("internal", "lengths", "checksums"):
        if key not in meta:
            raise InputError(f"catalogue metadata lacks {key!r}", str(p))
    missing = [f"n{n}.{a}" for n in meta["lengths"] for a in _ARRAYS if f"n{n}.{a}" not in npz.files]
    if missing:
        raise InputError(f"catalogue is missing {missing[0]} (truncated?)", str(p))
    return Catalogue(path=p, meta=meta, _npz=npz)


def default_path() -> Path:
    """The catalogue shipped with the package (k = 0 .. DEFAULT_MAX_INTERNAL)."""
    return Path(__file__).parent / "data" / f"catalogue-k0-{DEFAULT_MAX_INTERNAL}.npz"


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
