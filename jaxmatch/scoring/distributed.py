"""Several processes (on one or several hosts) sharing a bulk run: ``jax.distributed``.

``jaxmatch score-many --coordinator HOST:PORT --num-processes P --process-id I`` started once per
process: every process joins the cluster (:func:`initialize`, ``jax.distributed.initialize``;
CPU processes exchange data through gloo collectives), ranks its share of the shapes
(:func:`share`: shapes ``I, I + P, I + 2P, ...``, each with the whole pipeline), and the
records are gathered in input order on every process (:func:`gather_records`,
``multihost_utils.process_allgather``); process 0 writes the output. The merged output equals
a single-process run (``tests/test_distributed.py``). How to start it on several hosts:
``docs/perf.md``.

JAX is imported inside the functions (nothing here runs at ``import jaxmatch``).
"""

from __future__ import annotations

import json
from typing import NamedTuple, Sequence

import numpy as np

from jaxmatch.errors import InputError

__all__ = ["Cluster", "make_cluster", "parse_address", "initialize", "share", "gather_records", "shutdown"]


class Cluster(NamedTuple):
    """Where this process sits: ``coordinator`` ``"host:port"`` (process 0 listens there),
    ``num_processes`` P >= 1, ``process_id`` in ``0 .. P - 1``."""

    coordinator: str
    num_processes: int
    process_id: int


def parse_address(text: str) -> str:
    """``"host:port"`` checked (port 1..65535); InputError otherwise."""
    host, sep, port = str(text).rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise InputError(f"expected HOST:PORT (port 1..65535), got {text!r}")
    return f"{host}:{int(port)}"


def make_cluster(coordinator: str, num_processes: int, process_id: int) -> Cluster:
    """A checked :class:`Cluster` (InputError naming the problem; no option names)."""
    p, i = int(num_processes), int(process_id)
    if p < 1:
        raise InputError(f"the number of processes must be at least 1, got {p}")
    if not 0 <= i < p:
        raise InputError(f"the process id must be in 0..{p - 1}, got {i}")
    return Cluster(parse_address(coordinator), p, i)


def initialize(cluster: Cluster, timeout_s: int = 120) -> None:
    """Join the cluster (``jax.distributed.initialize``) before any JAX computation; on CPU the
    processes' collectives go through gloo. Blocks until all ``num_processes`` have joined
    (or ``timeout_s``, then RuntimeError from JAX)."""
    if cluster.num_processes == 1:
        return  # one process: nothing to join (and no JAX to import)
    import jax

    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.distributed.initialize(coordinator_address=cluster.coordinator, num_processes=cluster.num_processes,
                               process_id=cluster.process_id, initialization_timeout=int(timeout_s))


def shutdown(cluster: Cluster) -> None:
    """Leave the cluster (waits for the other processes)."""
    if cluster.num_processes > 1:
        import jax

        jax.distributed.shutdown()


def share(count: int, cluster: Cluster) -> np.ndarray:
    """Indices of the items this process handles: ``process_id, process_id + P, ...`` of ``count``
    (round robin, so shapes of similar cost spread evenly)."""
    return np.arange(cluster.process_id, int(count), cluster.num_processes)


def gather_records(records: Sequence[dict], indices: Sequence[int], count: int, cluster: Cluster) -> list[dict]:
    """All ``count`` records in input order, on every process: each process passes its own
    ``records`` (JSON-serialisable dicts) and their input ``indices`` (:func:`share`).

    The records travel as UTF-8 JSON bytes through two ``process_allgather`` calls (lengths,
    then the bytes padded to the longest). ValueError if some index is missing or doubled."""
    if len(records) != len(indices):
        raise ValueError(f"{len(records)} records for {len(indices)} indices")
    payload = json.dumps([[int(i), r] for i, r in zip(indices, records)]).encode()
    if cluster.num_processes == 1:
        parts = [payload]
    else:
        from jax.experimental import multihost_utils

        lengths = np.asarray(multihost_utils.process_allgather(np.array([len(payload)], np.int64))).reshape(-1)
        buf = np.zeros(int(lengths.max()), np.uint8)
        buf[: len(payload)] = np.frombuffer(payload, np.uint8)
        allbuf = np.asarray(multihost_utils.process_allgather(buf)).reshape(len(lengths), -1)
        parts = [allbuf[p, : int(lengths[p])].tobytes() for p in range(len(lengths))]
    out: list = [None] * int(count)
    for part in parts:
        for i, rec in json.loads(part.decode()):
            if not 0 <= i < count or out[i] is not None:
                raise ValueError(f"record {i} is out of range or came twice")
            out[i] = rec
    missing = [i for i, r in enumerate(out) if r is None]
    if missing:
        raise ValueError(f"records missing for inputs {missing[:5]}")
    return out
