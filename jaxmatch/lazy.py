"""Modules imported on first use, declared once at the top of the module that uses them.

A command's start-up loads only what it runs (``jaxmatch mesh`` loads no JAX, matplotlib,
labelling page or progress bars; ``jaxmatch --help`` no meshing): a module that needs a heavy or
large module for one path names it in one :class:`Later` at its top, with the reason, instead of
importing it inside the functions that use it::

    later = Later(plot="jaxmatch.io.plot")  # matplotlib: only with --png/--svg
    ...
    later.plot.draw_quadmesh(path, mesh)

The dependency stays visible where the module's other imports are.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["Later", "served_from"]


class Later:
    """Named modules, each imported on first attribute access (then kept on this object).

    modules: ``name="package.module"`` pairs; ``later.name`` is the module."""

    def __init__(self, **modules: str):
        self._modules = dict(modules)

    def __getattr__(self, name: str) -> ModuleType:
        modules = self.__dict__.get("_modules", {})
        if name not in modules:
            raise AttributeError(f"no lazy module {name!r} (declared: {', '.join(modules)})")
        module = importlib.import_module(modules[name])
        setattr(self, name, module)
        return module

    def __repr__(self) -> str:
        return f"Later({', '.join(f'{k}={v!r}' for k, v in self._modules.items())})"


def served_from(module: str, names, namespace: dict):
    """A module's ``__getattr__`` that serves ``names`` from ``module``, imported on the first
    access of one of them and then kept in ``namespace`` (the serving module's ``globals()``)::

        __getattr__ = served_from("jaxmatch.kernels.dp_xla", XLA_NAMES, globals())  # imports JAX
    """
    names = frozenset(names)
    owner = namespace.get("__name__", "?")

    def __getattr__(name: str):
        if name in names:
            value = getattr(importlib.import_module(module), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {owner!r} has no attribute {name!r}")

    return __getattr__
