"""One registry of the file formats jaxmatch reads and writes (after meshio's ``register_format``):
each format module registers its formats when imported; lookups by name or by file suffix.

Kinds: ``"shape"`` (read by :mod:`jaxmatch.io.readers`: ``reader(data, source, element) ->
Outline``), ``"mesh"`` (written by :mod:`jaxmatch.io.meshfile`; ``writer`` is the meshio format
name or ``"json"``), ``"picture"`` (written by :mod:`jaxmatch.io.plot`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, NamedTuple

from jaxmatch.errors import InputError

__all__ = ["Format", "find", "formats", "register_format", "suffixes"]


class Format(NamedTuple):
    """A registered format: ``name``, ``kind``, ``suffixes`` (lower case, with the dot),
    ``reader`` (or None) and ``writer`` (or None)."""

    name: str
    kind: str
    suffixes: tuple[str, ...]
    reader: Callable | None = None
    writer: Any = None


_FORMATS: dict[tuple[str, str], Format] = {}


def register_format(name: str, kind: str, suffixes, *, reader: Callable | None = None, writer: Any = None) -> Format:
    """Register (or replace) format ``name`` of ``kind`` for ``suffixes``; returns it."""
    fmt = Format(name, kind, tuple(s.lower() for s in suffixes), reader, writer)
    _FORMATS[(kind, name)] = fmt
    return fmt


def formats(kind: str) -> list[Format]:
    """The formats of ``kind``, in the order registered."""
    return [f for (k, _), f in _FORMATS.items() if k == kind]


def suffixes(kind: str) -> dict[str, str]:
    """``{suffix: format name}`` of ``kind``."""
    return {s: f.name for f in formats(kind) for s in f.suffixes}


def find(kind: str, *, name: str | None = None, path=None) -> Format:
    """The format of ``kind`` named ``name``, or the one for ``path``'s suffix. Raises
    :class:`InputError` (naming the path) when there is none."""
    if name is not None:
        try:
            return _FORMATS[(kind, name)]
        except KeyError:
            known = ", ".join(f.name for f in formats(kind))
            raise InputError(f"unknown {kind} format {name!r} (known: {known})") from None
    suffix = Path(str(path)).suffix.lower()
    for f in formats(kind):
        if suffix in f.suffixes:
            return f
    known = ", ".join(s for f in formats(kind) for s in f.suffixes)
    raise InputError(f"unknown {kind} file format {suffix or '(no suffix)'!r}; use one of {known}", where=str(path))
