"""One machine's cores for bulk work: an ordered map over a process pool (standard library).

Shapes are independent, and most of the work per shape is Python and small numpy/numba calls
(placing the meshes that break ties), which one process runs on one core. :func:`ordered_map`
runs a function over many items in ``jobs`` processes started by ``fork`` *after* the caller
has loaded what the function needs (catalogue, lattice, compiled kernels), so workers start
in milliseconds and share those pages copy-on-write. Across machines, use ``score-many
--coordinator`` (``jax.distributed``); this module is only the local level.

Falls back to a plain loop (same results, same order) when ``jobs <= 1``, when there are fewer
than two items, where ``fork`` is unavailable (Windows, macOS default), or when JAX has been
imported (its runtime threads are not fork-safe).
"""

from __future__ import annotations

import multiprocessing
import os
import sys
from typing import Any, Callable, Iterator, Sequence

__all__ = ["available_cpus", "can_fork", "ordered_map"]

_FN: Callable[[Any], Any] | None = None
_ITEMS: Sequence[Any] = ()


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # pragma: no cover - not Linux
        return max(os.cpu_count() or 1, 1)


def can_fork() -> bool:
    """Whether :func:`ordered_map` can use worker processes here."""
    return "fork" in multiprocessing.get_all_start_methods() and "jax" not in sys.modules and sys.platform == "linux"


def _call(i: int):
    return _FN(_ITEMS[i])


def ordered_map(fn: Callable[[Any], Any], items: Sequence[Any], jobs: int = 1,
                initializer: Callable[[], None] | None = None, warm_first: bool = False,
                warm: Callable[[], Any] | None = None) -> Iterator[Any]:
    """``fn(item)`` for every item, yielded in the order of ``items``.

    fn: any callable (a closure is fine: workers inherit it by ``fork``, nothing is pickled
    but the results); its results must be picklable. jobs: worker processes (at most
    ``len(items)``); an exception in ``fn`` is raised here, at its item, as in a plain loop.
    initializer: run once in each worker (e.g. :func:`jaxmatch.kernels.backends.serial_only`).
    warm_first: run the first item in this process before starting the workers, so that what
    it loads and compiles (prepared catalogue, compiled kernels) is inherited, not redone in
    every worker. warm: instead, run ``warm()`` in this process before starting the workers
    (a cheaper call that loads the same), every item going to the workers.
    """
    global _FN, _ITEMS
    n = len(items)
    workers_to_come = bool(n) and min(int(jobs), n) > 1 and can_fork()
    if warm is not None and workers_to_come:
        warm()
    elif warm_first and workers_to_come:
        yield fn(items[0])
        items = items[1:]
        n -= 1
    jobs = min(int(jobs), n)
    if jobs <= 1 or not can_fork():
        for it in items:
            yield fn(it)
        return
    _FN, _ITEMS = fn, items
    try:
        with multiprocessing.get_context("fork").Pool(jobs, initializer=initializer) as pool:
            yield from pool.imap(_call, range(n), chunksize=1)
    finally:
        _FN, _ITEMS = None, ()
