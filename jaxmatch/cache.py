"""The one cache layer: every result jaxmatch keeps between calls lives in a :class:`Cache`, in one
of its named stores, under a key made by :func:`key`.

A :class:`Cache` belongs to a catalogue (``Catalogue.cache``: what is kept is valid for that
catalogue's meshes) and is passed down to the code that fills it; nothing is kept anywhere
else, on module globals or on other modules' objects. ``cache.clear()`` forgets everything
(timings of a first call). Code that gets no cache (``cache=None``) computes afresh: the plain
path the tests compare the kept answers with.

Stores (:class:`CacheSizes` bounds each; least recently used dropped first):

============== ======================================================================== ==========
store          what                                                                      filled by
============== ======================================================================== ==========
rankings       rankings per size of an annotation (``"id"`` ties, pruned)                 scoring.rank
prepared       the catalogue's meshes of a selection of sizes, grouped for ranking        scoring.bulk
templates      a patch's template walk (templates placed as far as asked)                 placement.templates
chords         the chord topology of a catalogue mesh, as matched (mirrored or not)      placement.templates
layouts        meshed layouts (at most ``max_quads`` quads each)                           placement.solve
solves         the integer programs of a layout's side counts                             placement.solve
sides          a layout's sides                                                           placement.solve
shapes         a layout's patch shapes                                                    placement.solve
refined        refined, placed templates (``max_quads`` each, ``total_quads`` in all)     placement.refine
topology       refined topologies, a function of a template's combinatorics              placement.refine
factors        the factorised Laplacian of the last large refined topology               placement.refine
spread         a shape annotation's set-up of the alignment-spreading programme          placement.spread
============== ======================================================================== ==========

Values are shared, not copied: callers must not write to the arrays they get (the stores that
hand out arrays make them read-only or copy them, as their docstrings say).
"""

from __future__ import annotations

import dataclasses
import threading
from collections import OrderedDict
from typing import Any, Callable, TypeVar

import numpy as np

__all__ = ["CACHE_SIZES", "CATALOGUE_STORES", "Cache", "CacheSizes", "key"]

T = TypeVar("T")


@dataclasses.dataclass(frozen=True)
class CacheSizes:
    """The size policy of a :class:`Cache`: entries per store (None: unbounded), and for stores of
    meshes the largest mesh kept (``max_quads``, a large mesh is not asked twice) and the quads
    kept in all (``total_quads``, tens of MB)."""

    rankings: int = 4096
    prepared: int | None = None  # one per selection of sizes
    templates: int = 512
    chords: int | None = None  # one or two per catalogue mesh: bounded by the catalogue
    layouts: int = 256
    solves: int = 1024
    sides: int = 1024
    shapes: int = 1024
    refined: int = 512
    topology: int = 256
    factors: int = 1
    spread: int = 16
    max_quads: int = 20_000
    total_quads: int = 200_000


CACHE_SIZES = CacheSizes()
"""The default policy."""

CATALOGUE_STORES = ("prepared", "chords")
"""The stores that depend on the catalogue alone (its meshes grouped for ranking, their chord
topologies), not on any shape: what an opened catalogue keeps (:meth:`Cache.forget_shapes`
leaves them)."""


def key(*parts, ignore: tuple[str, ...] = ()) -> tuple:
    """The one key builder: ``parts`` as a hashable tuple that two parts compare equal in exactly
    when they hold the same values. Arrays become ``(dtype, shape, bytes)``; tuples and lists a
    tuple of their parts' keys; mappings their sorted items; a frozen dataclass hashable by value
    (a lattice) itself; other dataclass instances (a Shape, a Layout: arrays inside) their type and
    fields' keys, less the fields named in ``ignore`` (e.g. ``source``, which only messages use); numpy scalars Python numbers; everything else (str, int, float,
    bool, None, hashable objects such as a lattice) itself."""
    return tuple([_part(p, ignore) for p in parts])


_PLAIN = frozenset({type(None), str, bool, int, float})
"""Types a key part keeps as they are (exact types: the common case, tested first)."""

_DATACLASS_FIELDS: dict = {}
"""Per dataclass type: ``(frozen and eq, its field names)`` (what :func:`_part` reads of a type
every time; types only, never values)."""


def _part(p, ignore):
    t = type(p)
    if t in _PLAIN:
        return p
    if t is np.ndarray:  # (``tobytes`` is in C order whatever the layout; a 0-d array keys as 1-d, as it did)
        return p.dtype.str, (p.shape if p.ndim else (1,)), p.tobytes()
    if t is tuple or t is list:
        return tuple([_part(x, ignore) for x in p])
    return _other(p, ignore)


def _other(p, ignore):
    """:func:`_part` of what is not of a plain type, an array, a tuple or a list by exact type."""
    if p is None or isinstance(p, (str, bool, int, float)):
        return p
    if isinstance(p, np.ndarray):
        a = np.ascontiguousarray(p)
        return a.dtype.str, a.shape, a.tobytes()
    if isinstance(p, np.generic):
        return p.item()
    if isinstance(p, (tuple, list)):
        return tuple([_part(x, ignore) for x in p])
    if isinstance(p, dict):
        return tuple(sorted((k, _part(v, ignore)) for k, v in p.items()))
    t = type(p)
    info = _DATACLASS_FIELDS.get(t)
    if info is None and dataclasses.is_dataclass(p) and not isinstance(p, type):
        params = t.__dataclass_params__
        info = _DATACLASS_FIELDS[t] = (params.frozen and params.eq, tuple(f.name for f in dataclasses.fields(p)))
    if info is not None:
        by_value, names = info
        if by_value and not any(n in names for n in ignore):
            try:
                hash(p)  # hashable by value (a lattice: tuples inside)
                return p
            except TypeError:  # arrays inside: field by field
                pass
        return (t.__name__,) + tuple([_part(getattr(p, n), ignore) for n in names if n not in ignore])
    return p


class _Failed:
    """An error kept in place of a value (raised again on every hit)."""

    __slots__ = ("error",)

    def __init__(self, error: BaseException):
        self.error = error


class Cache:
    """Named least-recently-used stores under one size policy (:class:`CacheSizes`).

    Thread-safe for the store bookkeeping; ``make`` runs outside the lock (two threads may make
    the same value once each; the later one is kept)."""

    def __init__(self, sizes: CacheSizes = CACHE_SIZES):
        self.sizes = sizes
        self._stores: dict[str, OrderedDict] = {}
        self._quads: dict[str, int] = {}
        self._lock = threading.RLock()

    def get(self, store: str, k, make: Callable[[], T], *, quads: Callable[[T], int] | None = None,
            keep_errors: tuple[type[BaseException], ...] = ()) -> T:
        """``store[k]``, made by ``make()`` and kept when missing (the least recently used entries
        dropped beyond the store's size). ``quads(value)``: the value's size in quads, for the
        stores bounded by ``max_quads`` / ``total_quads`` (a larger value is returned, not kept).
        ``keep_errors``: errors of ``make`` kept like values and raised again on every hit."""
        with self._lock:
            s = self._stores.setdefault(store, OrderedDict())
            if k in s:
                s.move_to_end(k)
                hit = s[k][0]
                if isinstance(hit, _Failed):
                    raise hit.error
                return hit
        try:
            value = make()
        except keep_errors as e:
            self._put(store, k, _Failed(e), 0)
            raise
        q = 0 if quads is None else int(quads(value))
        if q <= self.sizes.max_quads or quads is None:
            self._put(store, k, value, q)
        return value

    def _put(self, store: str, k, value, q: int) -> None:
        limit = getattr(self.sizes, store, None)
        with self._lock:
            s = self._stores.setdefault(store, OrderedDict())
            old = s.pop(k, None)
            total = self._quads.get(store, 0) - (old[1] if old is not None else 0)
            while s and ((limit is not None and len(s) >= limit) or (q and total + q > self.sizes.total_quads)):
                total -= s.popitem(last=False)[1][1]
            if limit is None or limit > 0:
                s[k] = (value, q)
                total += q
            self._quads[store] = total

    def lookup(self, store: str, k, default: Any = None) -> Any:
        """``store[k]`` marked as just used, or ``default`` when missing (nothing is made)."""
        with self._lock:
            s = self._stores.get(store)
            if s is None or k not in s:
                return default
            s.move_to_end(k)
            hit = s[k][0]
        if isinstance(hit, _Failed):
            raise hit.error
        return hit

    def put(self, store: str, k, value, *, quads: int = 0) -> None:
        """Keep ``value`` as ``store[k]`` (not when ``quads`` exceeds ``max_quads``)."""
        if quads <= self.sizes.max_quads:
            self._put(store, k, value, int(quads))

    def size(self, store: str) -> int:
        """The number of entries ``store`` holds."""
        return len(self._stores.get(store, ()))

    def quads(self, store: str) -> int:
        """The quads of the meshes ``store`` holds, in all."""
        return self._quads.get(store, 0)

    def forget_shapes(self) -> None:
        """Forget everything made for shapes, keeping :data:`CATALOGUE_STORES`: the next call on
        any shape is a first call (for timings), the catalogue stays opened and grouped."""
        with self._lock:
            for name in [n for n in self._stores if n not in CATALOGUE_STORES]:
                self.clear(name)

    def clear(self, store: str | None = None) -> None:
        """Forget ``store`` (None: every store)."""
        with self._lock:
            for name in ([store] if store is not None else list(self._stores)):
                self._stores.pop(name, None)
                self._quads.pop(name, None)
