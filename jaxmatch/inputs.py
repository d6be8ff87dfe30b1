"""The catalogue, lattice and mesh sizes a call uses, resolved once from what the caller gave
(None for the shipped ones, a path, or the object itself), for :mod:`jaxmatch.api` and the
meshing pipeline alike (a light module: no JAX, no placement code)."""

from __future__ import annotations

import functools
import os
from typing import Iterable, Union

from jaxmatch.catalogue.store import Catalogue, default_catalogue, parse_range
from jaxmatch.catalogue.store import load as _load_catalogue
from jaxmatch.errors import InputError
from jaxmatch.scoring.lattice import Lattice, load_lattice

__all__ = ["Sizes", "check_sizes", "load_catalogue", "sizes_text"]


Sizes = Union[int, str, Iterable[int], None]
"""Mesh sizes (numbers of internal vertices): ``4``, ``"3..5"``, ``[3, 4]``, or None for all."""


def load_catalogue(path: str | os.PathLike | Catalogue | None = None) -> Catalogue:
    """A catalogue: ``None`` for the shipped one (k = 0..5), a path to a ``.npz`` built with
    ``jaxmatch catalogue build``, or a :class:`Catalogue` (returned as is)."""
    if isinstance(path, Catalogue):
        return path
    return _shipped_catalogue() if path is None else _load_catalogue(path)


@functools.lru_cache(maxsize=1)
def _shipped_catalogue() -> Catalogue:
    """The shipped catalogue, opened once per process (checksums and grouping took ~40 ms a call)."""
    return default_catalogue()


def _lattice(lattice: str | os.PathLike | Lattice) -> Lattice:
    """A lattice: a :class:`Lattice` as is, else :func:`jaxmatch.scoring.lattice.load_lattice`."""
    return lattice if isinstance(lattice, Lattice) else load_lattice(lattice)


def sizes_text(ks: Iterable[int]) -> str:
    """``[0, 1, 2, 5]`` -> ``"0..2, 5"``: numbers of internal vertices, runs collapsed."""
    ks = sorted(set(int(k) for k in ks))
    parts, i = [], 0
    while i < len(ks):
        j = i
        while j + 1 < len(ks) and ks[j + 1] == ks[j] + 1:
            j += 1
        parts.append(str(ks[i]) if i == j else f"{ks[i]}..{ks[j]}")
        i = j + 1
    return ", ".join(parts) or "none"


def check_sizes(catalogue: Catalogue, internal: Sizes) -> list[int] | None:
    """``internal`` as a sorted list of k (None: all sizes), each present in ``catalogue``.

    internal: an int ``K``, a string ``"K"`` or ``"K1..K2"``, a sequence of ints, or None.
    Raises :class:`InputError` (no ``where``: the caller names the argument) when a size is
    not in the catalogue, saying which sizes it has.
    """
    if internal is None:
        return None
    if isinstance(internal, str):
        try:
            ks = parse_range(internal)
        except InputError as e:
            raise InputError(e.problem) from None
    elif isinstance(internal, (int,)) and not isinstance(internal, bool):
        ks = [int(internal)]
    else:
        try:
            ks = sorted({int(k) for k in internal})
        except (TypeError, ValueError):
            raise InputError(f"sizes must be K, 'K1..K2' or a list of ints, got {internal!r}") from None
    have = set(catalogue.internal)
    missing = [k for k in ks if k not in have]
    if missing:
        raise InputError(f"the catalogue has no meshes with {sizes_text(missing)} internal vertices; "
                         f"it has k = {sizes_text(have)} (build more with 'jaxmatch catalogue build')")
    return ks
