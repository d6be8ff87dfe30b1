"""Lattices: the weight functions ``w_s, w_x, w_v : {2,3,4,5}^3 -> Z u {-inf}`` (paper, sec. 4).

A mesh boundary vertex is the triple ``"u-v-w"`` = valences of (ccw neighbour, vertex, cw
neighbour) (:func:`jaxmatch.catalogue.mesh.triples`). For each shape point type (``s`` straight, ``x``
convex, ``v`` concave) a lattice sorts the 64 triples into *levels* from best to worst, each
with an integer weight, plus two ``-inf`` groups:

* ``weeded``: triples that cannot occur on meshes of the catalogue class (disks, valences
  <= 5, invariant (I)); they weigh ``-inf`` so that the table is total, but never match;
* ``forbidden``: triples that must never be matched to this point type (``-inf``).

File format (TOML; ``lattices/fine.toml`` and ``lattices/coarse.toml`` are the built-ins)::

    name = "fine"                      # optional, defaults to the file stem
    description = "..."                # optional
    [x]                                # one table per type: s, x, v (all three required)
    weeded = ["2-2-3", ...]            # optional, default []
    forbidden = ["4-4-4", ...]         # optional, default []
    [[x.levels]]                       # levels, best first; at least one
    weight = 8                         # integer, |weight| <= MAX_WEIGHT
    triples = ["3-2-3"]                # non-empty list of "u-v-w", u, v, w in 2..5
    [skip]                             # optional: skip weight per point type (default 0)
    s = 0                              # integer, |weight| <= MAX_WEIGHT, or -inf
    x = -20                            # (-inf: every point of this type must get a mesh vertex)
    v = -inf

Rules: every one of the 64 triples is placed exactly once per type (in a level, ``weeded`` or
``forbidden``); a level must not weigh more than a level listed before it; no other keys.
Violations raise :class:`InputError` with ``where="path:LINE"`` (the offending line, found by
searching the file text; TOML syntax errors keep tomllib's line).

The skip weights enter the recurrence ``D[i][j] = max(D[i-1][j] + skip[code[i-1]],
D[i-1][j-1] + W[i-1, j-1])`` (:mod:`jaxmatch.scoring.exact`); a file without ``[skip]`` scores
as before (skipping is free, as in the paper).

Arrays: ``table()`` is ``(3, 4, 4, 4) float32`` indexed ``[type, u-2, v-2, w-2]`` with type
``0 = s, 1 = x, 2 = v`` (:data:`jaxmatch.shape.SYMBOLS`), ``-inf`` where weeded/forbidden;
:func:`finite_table` replaces ``-inf`` by :data:`NEG` for the scorer; ``weights()`` compiles the
lattice (table and skip weights) into the :class:`jaxmatch.kernels.model.Weights` every scorer takes.
"""

from __future__ import annotations

import functools
import importlib.resources
import itertools
import math
import re
import tomllib
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.files import read_limited, write_text_atomic
from jaxmatch.kernels.model import NEG, Weights, make_weights
from jaxmatch.shape import SYMBOLS

__all__ = [
    "ALL_TRIPLES",
    "BUILTIN_DIR",
    "Lattice",
    "Level",
    "LevelStructure",
    "MAX_WEIGHT",
    "NEG",
    "TYPES",
    "TYPE_NAMES",
    "builtin_names",
    "finite_table",
    "lattice_json",
    "lattice_text",
    "lattice_toml",
    "level_structure",
    "load_lattice",
    "parse_lattice",
    "parse_triple",
    "save_lattice",
    "table_from_levels",
    "triple_index",
    "with_level_weights",
]

MAX_BYTES = 2**20
"""Largest accepted lattice file (bytes); the built-ins are about 10 kB."""

MAX_WEIGHT = 1000
"""Largest accepted ``|weight|``: keeps ``m * |weight|`` far from ``|NEG|`` and exact in float32."""

TYPES = tuple(SYMBOLS)
"""Point types in table order: ``("s", "x", "v")``."""

TYPE_NAMES = {"s": "straight point", "x": "convex corner", "v": "concave corner"}

ALL_TRIPLES = tuple(f"{u}-{v}-{w}" for u, v, w in itertools.product(range(2, 6), repeat=3))
"""The 64 triples ``"u-v-w"`` in table order (``u`` slowest, ``w`` fastest)."""

BUILTIN_DIR = Path(__file__).resolve().parents[2] / "lattices"
"""Built-in lattices in a source checkout (installed packages use ``jaxmatch/data``)."""

_TRIPLE_RE = re.compile(r"^[2-5]-[2-5]-[2-5]$")
_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
_TOP_KEYS = ("name", "description", *TYPES, "skip")
_TYPE_KEYS = ("levels", "weeded", "forbidden")
_LEVEL_KEYS = ("weight", "triples")


class Level(NamedTuple):
    """One lattice level: an integer weight and its triples (``"u-v-w"`` strings)."""

    weight: int
    triples: tuple[str, ...]


@dataclass(frozen=True)
class Lattice:
    """Three weight functions (types ``s``, ``x``, ``v``, in that order).

    levels: per type, a tuple of :class:`Level`, best first (non-increasing weights).
    weeded: per type, triples that cannot occur in the catalogue class (weight ``-inf``).
    forbidden: per type, triples never matched to that point type (weight ``-inf``).
    skip: per type, the skip weight (an integer, or ``-inf``: the point must get a mesh vertex).
    """

    name: str
    levels: tuple[tuple[Level, ...], tuple[Level, ...], tuple[Level, ...]]
    weeded: tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]
    forbidden: tuple[tuple[str, ...], tuple[str, ...], tuple[str, ...]]
    description: str = ""
    skip: tuple[float, float, float] = (0, 0, 0)

    def weights(self) -> Weights:
        """The compiled scoring model (match table and skip weights) every scorer takes;
        compiled once per lattice object."""
        return self._compiled

    @cached_property
    def _compiled(self) -> Weights:
        t = np.full((3, 64), -np.inf, np.float32)
        for k, levels in enumerate(self.levels):
            for lev in levels:
                for tr in lev.triples:
                    t[k, triple_index(tr)] = lev.weight
        return make_weights(t, np.asarray(self.skip, np.float64), self.name)

    def table(self) -> np.ndarray:
        """``(3, 4, 4, 4) float32`` weights ``[type, u-2, v-2, w-2]``; ``-inf`` when excluded
        (a new array each call)."""
        return self._compiled.table_inf()

    def weight(self, kind: str, triple: str) -> float:
        """Weight of ``triple`` (``"u-v-w"``) for point type ``kind`` (``"s"``, ``"x"``, ``"v"``)."""
        return float(self.table()[TYPES.index(kind)].reshape(64)[triple_index(triple)])


def parse_triple(text: str) -> tuple[int, int, int]:
    """``"u-v-w"`` -> ``(u, v, w)``; ValueError unless each is in 2..5."""
    if not isinstance(text, str) or not _TRIPLE_RE.match(text):
        raise ValueError(f"not a triple 'u-v-w' with valences 2..5: {text!r}")
    u, v, w = (int(x) for x in text.split("-"))
    return u, v, w


def triple_index(text: str) -> int:
    """Flat index ``16 (u-2) + 4 (v-2) + (w-2)`` of a triple string."""
    u, v, w = parse_triple(text)
    return 16 * (u - 2) + 4 * (v - 2) + (w - 2)


def finite_table(lat: Lattice) -> np.ndarray:
    """``lat.table()`` with ``-inf`` replaced by :data:`NEG`, ``(3, 4, 4, 4) float32``."""
    t = lat.table()
    return np.where(np.isfinite(t), t, np.float32(NEG)).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# parametrisation for tuning


class LevelStructure(NamedTuple):
    """Level membership of a lattice, for rebuilding tables from level weights.

    masks: ``(L, 3, 4, 4, 4) bool``, level ``l``'s triples (all levels of all types, in
        order s, x, v and best first within a type).
    weights: ``(L,) float32``, the level weights.
    types: ``(L,) int32``, the type index (0 s, 1 x, 2 v) of each level.
    """

    masks: np.ndarray
    weights: np.ndarray
    types: np.ndarray


def level_structure(lat: Lattice) -> LevelStructure:
    """Membership masks, weights and types of all levels (see :class:`LevelStructure`).

    Cells in no level are exactly the weeded/forbidden ones; :func:`table_from_levels`
    rebuilds :func:`finite_table` from the weights.
    """
    masks, weights, types = [], [], []
    for k, levels in enumerate(lat.levels):
        for lev in levels:
            m = np.zeros((3, 64), bool)
            m[k, [triple_index(t) for t in lev.triples]] = True
            masks.append(m.reshape(3, 4, 4, 4))
            weights.append(lev.weight)
            types.append(k)
    return LevelStructure(
        masks=np.stack(masks) if masks else np.zeros((0, 3, 4, 4, 4), bool),
        weights=np.asarray(weights, np.float32),
        types=np.asarray(types, np.int32),
    )


def table_from_levels(structure: LevelStructure, weights):
    """``(3, 4, 4, 4)`` table with level weights ``weights (L,)``: excluded cells get NEG.

    Works with numpy or JAX arrays for ``weights`` (``weights @ masks``), so it can be
    differentiated by a tuner. Equals :func:`finite_table` for the lattice's own weights.
    """
    m = structure.masks.reshape(structure.masks.shape[0], -1).astype(np.float32)
    base = np.where(structure.masks.any(axis=0), 0.0, NEG).astype(np.float32).reshape(-1)
    return (weights @ m + base).reshape(3, 4, 4, 4)


def with_level_weights(lat: Lattice, weights, skip=None) -> Lattice:
    """A copy of ``lat`` with new level weights ``(L,)`` in :func:`level_structure` order (and,
    when given, new skip weights ``(3,)``: finite ones rounded and clipped like the levels,
    ``-inf`` ones of ``lat`` stay ``-inf``).

    Weights are rounded to integers and clipped to ``[-MAX_WEIGHT, MAX_WEIGHT]`` (the file
    format is integer-only, as in the paper). Levels are then stably re-sorted best first
    within each type, so the result is always a valid lattice file; call
    :func:`level_structure` again on the result if the order matters.
    """
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    n_levels = sum(len(levels) for levels in lat.levels)
    if w.shape[0] != n_levels:
        raise ValueError(f"expected {n_levels} level weights, got {w.shape[0]}")
    if not np.isfinite(w).all():
        raise ValueError("level weights must be finite")
    w = np.clip(np.rint(w), -MAX_WEIGHT, MAX_WEIGHT).astype(np.int64)
    out, i = [], 0
    for levels in lat.levels:
        new = [Level(int(w[i + j]), lev.triples) for j, lev in enumerate(levels)]
        i += len(levels)
        out.append(tuple(sorted(new, key=lambda lev: -lev.weight)))  # stable
    new_skip = lat.skip
    if skip is not None:
        sk = np.asarray(skip, dtype=np.float64).reshape(-1)
        if sk.shape != (3,):
            raise ValueError(f"expected 3 skip weights, got {sk.shape[0]}")
        new_skip = tuple(
            old if math.isinf(old) else int(np.clip(np.rint(x), -MAX_WEIGHT, MAX_WEIGHT)) if np.isfinite(x) else _bad_skip()
            for old, x in zip(lat.skip, sk))
    return replace(lat, levels=tuple(out), skip=new_skip)


def _bad_skip():
    raise ValueError("finite skip weights must stay finite")


# ---------------------------------------------------------------------------------------------
# reading


def builtin_names() -> list[str]:
    """Names of the built-in lattices (``fine``, ``coarse``, ...)."""
    names = {p.stem for p in BUILTIN_DIR.glob("*.toml")} if BUILTIN_DIR.is_dir() else set()
    try:
        data = importlib.resources.files("jaxmatch").joinpath("data")
        if data.is_dir():
            names |= {Path(p.name).stem for p in data.iterdir() if p.name.endswith(".toml")}
    except (ModuleNotFoundError, OSError):
        pass
    return sorted(names)


def _resolve(name_or_path) -> tuple[str, bytes]:
    """(source label, file bytes) for a built-in name or a path."""
    arg = str(name_or_path)
    path = Path(arg)
    is_name = bool(_NAME_RE.match(arg)) and path.suffix.lower() != ".toml" and not path.is_file()
    if is_name:
        local = BUILTIN_DIR / f"{arg}.toml"
        if local.is_file():
            path = local
        else:
            try:
                res = importlib.resources.files("jaxmatch").joinpath("data", f"{arg}.toml")
                if res.is_file():
                    return f"{arg}.toml", res.read_bytes()
            except (ModuleNotFoundError, OSError):
                pass
            known = ", ".join(builtin_names()) or "none found"
            raise InputError(f"no lattice file or built-in lattice of this name (built-ins: {known})", where=arg)
    return str(path), read_limited(path, MAX_BYTES, "lattice file")


def load_lattice(name_or_path) -> Lattice:
    """Load a lattice: a built-in name (``"fine"``, ``"coarse"``) or a TOML file path.

    Names resolve to ``<repo>/lattices/<name>.toml`` (source checkout), else to the package
    data ``jaxmatch/data/<name>.toml`` (installed). An existing file of that name, or any
    argument ending in ``.toml``, is read as a path.
    """
    source, data = _resolve(name_or_path)
    return _parse_cached(data, source)


@functools.lru_cache(maxsize=16)
def _parse_cached(data: bytes, source: str) -> Lattice:
    """:func:`parse_lattice` once per file content and source (a Lattice is immutable; parsing
    and validating took ~30 ms, on every meshing call that names its lattice)."""
    return parse_lattice(data, source)


def parse_lattice(data, source: str = "<lattice>") -> Lattice:
    """Parse and validate lattice TOML (bytes or str); :class:`InputError` on any problem."""
    if isinstance(data, str):
        text = data
    else:
        try:
            text = bytes(data).decode("utf-8")
        except UnicodeDecodeError as err:
            raise InputError(f"not UTF-8 text (byte {err.start})", where=source) from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        msg = str(err)
        found = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        if found:
            problem = msg.replace(found.group(0), f"(column {found.group(2)})").strip()
            raise InputError(f"TOML syntax error: {problem}", where=f"{source}:{found.group(1)}") from None
        raise InputError(f"TOML syntax error: {msg}", where=source) from None
    except RecursionError:
        raise InputError("TOML nesting too deep", where=source) from None
    return _validate(doc, _Locator(text, source), source)


class _Locator:
    """Finds the line of a key, triple or level weight in the raw text (best effort)."""

    _HEADER = re.compile(r"^\s*\[\[?\s*([^\]]*?)\s*\]\]?\s*$")

    def __init__(self, text: str, source: str):
        self.source = source
        self.code = [_strip_comment(line) for line in text.splitlines()]
        # owner: the top-level table each line belongs to ("" = top level)
        self.owner: list[str] = []
        self.levels: list[bool] = []  # line is a [[t.levels]] header
        cur = ""
        for line in self.code:
            m = self._HEADER.match(line)
            is_level = False
            if m:
                parts = [p.strip().strip("\"'") for p in m.group(1).split(".")]
                cur = parts[0]
                is_level = line.lstrip().startswith("[[") and parts[1:] == ["levels"]
            self.owner.append(cur)
            self.levels.append(is_level)

    def at(self, line: int | None) -> str:
        return f"{self.source}:{line if line else 1}"

    def _lines(self, table: str | None):
        return [i for i in range(len(self.code)) if table is None or self.owner[i] == table]

    def header(self, table: str) -> int | None:
        for i in self._lines(table):
            if self._HEADER.match(self.code[i]):
                return i + 1
        for i in self._lines(table):  # dotted keys at top level, e.g. x.levels = [...]
            if re.match(rf"^\s*{re.escape(table)}\s*[.=]", self.code[i]):
                return i + 1
        return None

    def key(self, table: str | None, key: str) -> int | None:
        pat = re.compile(rf"(^|[{{,.\s])[\"']?{re.escape(key)}[\"']?\s*=")
        hdr = re.compile(rf"^\s*\[\[?[^\]]*\b{re.escape(key)}\b")
        for i in self._lines(table):
            if pat.search(self.code[i]) or hdr.match(self.code[i]):
                return i + 1
        return None

    def value(self, table: str | None, value: str, occurrence: int = 1) -> int | None:
        found = 0
        needle = [f'"{value}"', f"'{value}'"]
        for i in self._lines(table):
            found += sum(self.code[i].count(n) for n in needle)
            if found >= occurrence:
                return i + 1
        return None

    def within(self, line: int | None, value) -> int | None:
        """Line of ``value`` in the array value that starts on ``line`` (else ``line``)."""
        if line is None:
            return None
        if isinstance(value, str):
            needles = [f'"{value}"', f"'{value}'"]
        elif isinstance(value, bool):
            needles = [str(value).lower()]
        else:
            needles = [str(value)]
        for i in range(line - 1, len(self.code)):
            if i > line - 1 and (self._HEADER.match(self.code[i]) or re.match(r"^\s*[\w\"'.-]+\s*=", self.code[i])):
                break
            if any(n in self.code[i] for n in needles):
                return i + 1
        return line

    def level(self, table: str, index: int, key: str = "weight") -> int | None:
        """Line of ``key`` in the ``index``-th level of ``table`` (else its header line)."""
        heads = [i for i in self._lines(table) if self.levels[i]]
        if index < len(heads):
            end = heads[index + 1] if index + 1 < len(heads) else len(self.code)
            for i in range(heads[index], end):
                if self.owner[i] == table and re.search(rf"(^|[{{,\s]){key}\s*=", self.code[i]):
                    return i + 1
            return heads[index] + 1
        hits = [i for i in self._lines(table) if re.search(rf"(^|[{{,\s])weight\s*=", self.code[i])]
        if index < len(hits):
            return hits[index] + 1
        return self.header(table)


def _strip_comment(line: str) -> str:
    """The part of a TOML line before a ``#`` that is not inside a string."""
    quote = None
    i = 0
    while i < len(line):
        ch = line[i]
        if quote:
            if ch == "\\" and quote == '"':
                i += 1
            elif ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:i]
        i += 1
    return line


def _short(value, limit: int = 40) -> str:
    r = repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def _validate(doc: dict, loc: _Locator, source: str) -> Lattice:
    for key in doc:
        if key not in _TOP_KEYS:
            raise InputError(f"unknown key {_short(key)} (allowed: {', '.join(_TOP_KEYS)})", where=loc.at(loc.key("", key) or loc.key(None, key)))
    name = doc.get("name", Path(source).stem)
    if not isinstance(name, str) or not name.strip() or not name.isprintable():
        raise InputError("name must be a non-empty one-line string of printable characters", where=loc.at(loc.key("", "name")))
    description = doc.get("description", "")
    if not isinstance(description, str):
        raise InputError("description must be a string", where=loc.at(loc.key("", "description")))
    levels_all, weeded_all, forbidden_all = [], [], []
    for kind in TYPES:
        if kind not in doc:
            raise InputError(f"missing table [{kind}] ({TYPE_NAMES[kind]})", where=loc.at(None))
        table = doc[kind]
        if not isinstance(table, dict):
            raise InputError(f"{kind} must be a table [{kind}]", where=loc.at(loc.key(None, kind)))
        for key in table:
            if key not in _TYPE_KEYS:
                raise InputError(f"[{kind}]: unknown key {_short(key)} (allowed: {', '.join(_TYPE_KEYS)})", where=loc.at(loc.key(kind, key) or loc.header(kind)))
        placed: dict[str, str] = {}

        def place(triple, what: str, line: int | None, kind=kind, placed=placed):
            if not isinstance(triple, str) or not _TRIPLE_RE.match(triple):
                line = loc.within(line, triple)
                raise InputError(f"[{kind}] {what}: {_short(triple)} is not a triple 'u-v-w' with valences 2..5", where=loc.at(line or loc.header(kind)))
            if triple in placed:
                raise InputError(f"[{kind}]: triple {triple} is placed twice ({placed[triple]} and {what})", where=loc.at(loc.value(kind, triple, 2) or loc.header(kind)))
            placed[triple] = what

        def triple_list(key: str, kind=kind, table=table) -> tuple[str, ...]:
            value = table.get(key, [])
            if not isinstance(value, list):
                raise InputError(f"[{kind}] {key} must be a list of triples 'u-v-w'", where=loc.at(loc.key(kind, key) or loc.header(kind)))
            for tr in value:
                place(tr, key, loc.key(kind, key))
            return tuple(value)

        levels = table.get("levels")
        if levels is None:
            raise InputError(f"[{kind}] has no levels ([[{kind}.levels]] with weight and triples)", where=loc.at(loc.header(kind)))
        if not isinstance(levels, list) or not levels or not all(isinstance(lv, dict) for lv in levels):
            raise InputError(f"[{kind}] levels must be a non-empty array of tables [[{kind}.levels]]", where=loc.at(loc.key(kind, "levels") or loc.header(kind)))
        parsed: list[Level] = []
        for i, lv in enumerate(levels):
            where = f"[{kind}] level {i + 1}"
            for key in lv:
                if key not in _LEVEL_KEYS:
                    raise InputError(f"{where}: unknown key {_short(key)} (allowed: weight, triples)", where=loc.at(loc.level(kind, i, re.escape(key))))
            if "weight" not in lv:
                raise InputError(f"{where}: missing weight", where=loc.at(loc.level(kind, i)))
            w = lv["weight"]
            if isinstance(w, bool) or not isinstance(w, int):
                raise InputError(f"{where}: weight must be an integer, got {_short(w)}", where=loc.at(loc.level(kind, i)))
            if abs(w) > MAX_WEIGHT:
                raise InputError(f"{where}: weight {w} is outside [-{MAX_WEIGHT}, {MAX_WEIGHT}]", where=loc.at(loc.level(kind, i)))
            if parsed and w > parsed[-1].weight:
                raise InputError(f"{where}: weight {w} is larger than the previous level's {parsed[-1].weight} (levels go best first)", where=loc.at(loc.level(kind, i)))
            triples = lv.get("triples")
            if not isinstance(triples, list) or not triples:
                raise InputError(f"{where}: triples must be a non-empty list of 'u-v-w'", where=loc.at(loc.level(kind, i, "triples")))
            for tr in triples:
                place(tr, f"level {i + 1}", loc.level(kind, i, "triples"))
            parsed.append(Level(int(w), tuple(triples)))
        weeded = triple_list("weeded")
        forbidden = triple_list("forbidden")
        missing = [t for t in ALL_TRIPLES if t not in placed]
        if missing:
            more = f" and {len(missing) - 8} more" if len(missing) > 8 else ""
            raise InputError(f"[{kind}]: triples not placed (put each in a level, weeded or forbidden): {' '.join(missing[:8])}{more}", where=loc.at(loc.header(kind)))
        levels_all.append(tuple(parsed))
        weeded_all.append(weeded)
        forbidden_all.append(forbidden)
    skip = _validate_skip(doc.get("skip", {}), loc)
    return Lattice(name=name, levels=tuple(levels_all), weeded=tuple(weeded_all), forbidden=tuple(forbidden_all),
                   description=description, skip=skip)


def _validate_skip(table, loc: _Locator) -> tuple:
    """The ``[skip]`` table: keys s, x, v (missing = 0), integers within MAX_WEIGHT or -inf."""
    if not isinstance(table, dict):
        raise InputError("skip must be a table [skip] with keys s, x, v", where=loc.at(loc.key(None, "skip")))
    out = []
    for key in table:
        if key not in TYPES:
            raise InputError(f"[skip]: unknown key {_short(key)} (allowed: s, x, v)", where=loc.at(loc.key("skip", key) or loc.header("skip")))
    for kind in TYPES:
        w = table.get(kind, 0)
        where = loc.at(loc.key("skip", kind) or loc.header("skip"))
        if isinstance(w, float) and math.isinf(w) and w < 0:
            out.append(-math.inf)
            continue
        if isinstance(w, bool) or not isinstance(w, int):
            raise InputError(f"[skip] {kind}: skip weight must be an integer or -inf, got {_short(w)}", where=where)
        if abs(w) > MAX_WEIGHT:
            raise InputError(f"[skip] {kind}: skip weight {w} is outside [-{MAX_WEIGHT}, {MAX_WEIGHT}]", where=where)
        out.append(int(w))
    return tuple(out)


def _skip_value(w) -> str:
    return "-inf" if math.isinf(w) else str(int(w))


# ---------------------------------------------------------------------------------------------
# writing and display


def _toml_str(text: str) -> str:
    """A TOML basic string for ``text`` (one line, escaped)."""
    out = ['"']
    for ch in text:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ch == "\n":
            out.append("\\n")
        elif ch == "\t":
            out.append("\\t")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _triple_array(triples, indent: str = "    ", per_line: int = 8) -> str:
    items = [f'"{t}"' for t in triples]
    if len(items) <= per_line:
        return "[" + ", ".join(items) + "]"
    rows = [indent + ", ".join(items[i : i + per_line]) + "," for i in range(0, len(items), per_line)]
    return "[\n" + "\n".join(rows) + "\n]"


def lattice_toml(lat: Lattice) -> str:
    """The TOML text of ``lat`` (the format :func:`parse_lattice` reads)."""
    lines = [
        f"# jaxmatch lattice {_toml_str(lat.name)}: weight functions w_s, w_x, w_v on boundary triples",
        "# \"u-v-w\" = valences of (ccw neighbour, vertex, cw neighbour). Levels go best first;",
        "# weeded (cannot occur in the catalogue class) and forbidden triples weigh -inf.",
        f"name = {_toml_str(lat.name)}",
    ]
    if lat.description:
        lines.append(f"description = {_toml_str(lat.description)}")
    lines += _skip_lines(lat)
    for k, kind in enumerate(TYPES):
        lines += ["", f"# {kind}: {TYPE_NAMES[kind]}", f"[{kind}]"]
        lines.append(f"weeded = {_triple_array(lat.weeded[k])}")
        lines.append(f"forbidden = {_triple_array(lat.forbidden[k])}")
        for lev in lat.levels[k]:
            lines += ["", f"[[{kind}.levels]]", f"weight = {int(lev.weight)}", f"triples = {_triple_array(lev.triples)}"]
    return "\n".join(lines) + "\n"


def _skip_lines(lat: Lattice) -> list[str]:
    """The ``[skip]`` table (with a blank line and a comment before it), or nothing when all are 0.
    It goes before the type tables, so a truncated file never loses it silently."""
    if not any(w != 0 for w in lat.skip):
        return []
    return ["", "# skip weights: what leaving a shape point of that type without a mesh vertex adds to the utility",
            "[skip]", *[f"{kind} = {_skip_value(w)}" for kind, w in zip(TYPES, lat.skip)]]


def _patched(lat: Lattice, template: str) -> str | None:
    """``template`` text with its name and level weights replaced by ``lat``'s, when its
    structure (levels' triples, weeded, forbidden) is the same; else None."""
    try:
        old = parse_lattice(template, "<template>")
    except InputError:
        return None
    same = all(
        [lev.triples for lev in old.levels[k]] == [lev.triples for lev in lat.levels[k]]
        and old.weeded[k] == lat.weeded[k]
        and old.forbidden[k] == lat.forbidden[k]
        for k in range(3)
    )
    if not same or old.description != lat.description:
        return None
    loc = _Locator(template, "<template>")
    lines = template.splitlines(keepends=True)
    for k, kind in enumerate(TYPES):
        for i, lev in enumerate(lat.levels[k]):
            n = loc.level(kind, i)
            if n is None:
                return None
            new, count = re.subn(r"(\bweight\s*=\s*)[+-]?\d+", rf"\g<1>{int(lev.weight)}", lines[n - 1], count=1)
            if count != 1:
                return None
            lines[n - 1] = new
    if tuple(old.skip) != tuple(lat.skip):
        for kind, w_old, w_new in zip(TYPES, old.skip, lat.skip):
            if w_old == w_new:
                continue
            n = loc.key("skip", kind)
            if n is None:
                if loc.header("skip") is not None:
                    return None
                continue  # no [skip] table: appended below
            new, count = re.subn(r"^(\s*%s\s*=\s*)(-inf|[+-]?\d+)" % kind, rf"\g<1>{_skip_value(w_new)}", lines[n - 1], count=1)
            if count != 1:
                return None
            lines[n - 1] = new
        if loc.header("skip") is None:  # after name / description, else before the first table
            at = loc.key("", "description") or loc.key("", "name")
            if at is None:
                at = next((i for i, code in enumerate(loc.code) if loc._HEADER.match(code)), len(lines))
            lines.insert(at, "\n".join(_skip_lines(lat)[1:]) + "\n\n")
    text = "".join(lines)
    n = loc.key("", "name")
    if old.name != lat.name:
        if n is None:
            return None
        lines[n - 1] = re.sub(r"^(\s*name\s*=\s*).*?(\s*(#.*)?)$", lambda m: m.group(1) + _toml_str(lat.name) + m.group(2), lines[n - 1].rstrip("\n")) + "\n"
        text = "".join(lines)
    try:
        if parse_lattice(text, "<patched>") != lat:
            return None
    except InputError:
        return None
    return text


def save_lattice(lat: Lattice, path, template=None) -> None:
    """Write ``lat`` as TOML to ``path`` atomically; the file round-trips through
    :func:`load_lattice`.

    template: optional lattice file path or TOML text (e.g. the file ``lat`` was tuned from).
    When it has the same levels/weeded/forbidden structure, it is copied with only its weights
    and name replaced, keeping all its comments; otherwise a fresh file with a short header is
    written.
    """
    text = None
    if template is not None:
        if isinstance(template, Path) or (isinstance(template, str) and "\n" not in template and Path(template).is_file()):
            template = Path(template).read_text(encoding="utf-8")
        text = _patched(lat, str(template))
    write_text_atomic(path, text if text is not None else lattice_toml(lat))


def lattice_json(lat: Lattice) -> dict:
    """``{"s": {"2-2-2": w or None, ...}, "x": {...}, "v": {...}, "skip": {"s": w, "x": w, "v": w
    or None}}``: all 64 triples per type in :data:`ALL_TRIPLES` order, integer weights, ``None``
    for ``-inf``; the skip weights likewise."""
    t = lat.table().reshape(3, 64)
    out = {
        kind: {tr: (int(t[k, i]) if np.isfinite(t[k, i]) else None) for i, tr in enumerate(ALL_TRIPLES)}
        for k, kind in enumerate(TYPES)
    }
    out["skip"] = {kind: (None if math.isinf(w) else int(w)) for kind, w in zip(TYPES, lat.skip)}
    return out


def lattice_text(lat: Lattice) -> str:
    """Human-readable table: per type, the levels (weight and triples), then -inf groups."""
    out = [f"lattice {lat.name}"]
    if lat.description:
        out.append(f"  {lat.description}")
    for k, kind in enumerate(TYPES):
        out.append(f"{kind}  ({TYPE_NAMES[kind]})")
        for lev in lat.levels[k]:
            out.append(f"  {lev.weight:>5}  {' '.join(lev.triples)}")
        if lat.forbidden[k]:
            out.append(f"  {'-inf':>5}  forbidden: {' '.join(lat.forbidden[k])}")
        if lat.weeded[k]:
            out.append(f"  {'-inf':>5}  weeded:    {' '.join(lat.weeded[k])}")
    out.append("skip  (weight of leaving a point without a mesh vertex; -inf: must get one)")
    out.append("  " + "  ".join(f"{kind} {_skip_value(w):>5}" for kind, w in zip(TYPES, lat.skip)))
    return "\n".join(out) + "\n"
