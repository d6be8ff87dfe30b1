"""Bulk meshing runs: ``jaxmatch mesh REGION... --out-dir DIR`` (one mesh file per region and
``DIR/summary.jsonl``).

One run: every region is read and checked in this process first (bad input stops the run before
any work unless ``skip_bad``); then the regions are meshed, each by
:func:`jaxmatch.meshing.pipeline.mesh` with the same options, by one of three runners:

* **local workers** (:func:`_local_results`): ``jobs`` processes forked from this one after it
  has opened the catalogue, read the lattice, meshed a unit square and (50 regions or more)
  loaded numba's single-thread scoring kernel (so each worker starts in milliseconds with
  everything loaded, nothing imported again per region; one BLAS thread each); each worker is sent
  chunks of region numbers, meshes them in order, writes each mesh file and answers one record
  per region. A worker still busy with one region ``grace`` seconds past the region budget is
  killed and replaced (a worker that dies is replaced too); its region gets a record, the
  others of its chunk go to the next free worker.
* **in this process** (:func:`_inline_results`) where workers cannot be forked (no ``fork``, or
  JAX already loaded: its threads are not fork-safe).
* **Dask** (:func:`_dask_results`): each region is a task of a running Dask scheduler, the
  input file's bytes sent with it; a worker process opens the catalogue and lattice once, and
  the task returns the record and the mesh file's bytes, written here.

Every region gets one record (:data:`RECORD_FIELDS`), appended to the summary the moment it
arrives (one ``write`` of a whole line, after the mesh file is in place), so a run killed at
any moment loses only the regions being meshed; at the end the summary is rewritten (atomically)
in the order of the regions given, one record each. ``resume``: a region whose record in the
existing summary has the same input hash (SHA-256 of the file's bytes) and options hash
(:func:`options_hash`), status ``"meshed"``, and whose mesh file exists, is not meshed again.

Per-region budget: a region still being meshed after ``region_budget`` seconds is stopped (an
exception raised in the meshing thread: :func:`deadline`) and gets ``{"status": "timed out"}``;
the run goes on.
"""

from __future__ import annotations

import contextlib
import ctypes
import dataclasses
import hashlib
import itertools
import json
import math
import multiprocessing
import os
import signal
import sys
import tempfile
import threading
import time
from collections import deque
from multiprocessing.connection import wait as wait_any
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
import threadpoolctl

from jaxmatch import __version__, report
from jaxmatch.catalogue.store import default_path
from jaxmatch.errors import InputError
from jaxmatch.files import atomic_open, atomic_path
from jaxmatch.io.meshfile import MESH_FORMATS, mesh_format, write_mesh
from jaxmatch.io.output import MeshOutput
from jaxmatch.kernels import backends
from jaxmatch.lazy import Later
from jaxmatch.parallel import available_cpus, can_fork

__all__ = ["DEFAULT_GRACE_S", "Job", "RECORD_FIELDS", "RegionTimedOut", "RunResult", "deadline", "mesh_job",
           "options_hash", "plan", "read_summary", "run"]

later = Later(
    pipeline="jaxmatch.meshing.pipeline",  # the meshing stack: loaded by the run (not by --help)
    region="jaxmatch.meshing.region",  # reading a region (a Dask worker reads the bytes sent)
    inputs="jaxmatch.inputs",  # a Dask worker opens the catalogue and lattice once
)

DEFAULT_GRACE_S = 5.0
"""Seconds past the region budget after which a local worker that has not answered (stuck in
compiled code, where the budget's exception cannot be raised) is killed and replaced."""

RECORD_FIELDS: dict[str, str] = {
    "shape": "the region as given on the command line (a path, or FILE#ID)",
    "status": '"meshed", "failed" (see error) or "timed out" (past the region budget; no mesh file)',
    "error": "failed records only: the one-line reason (bad input, or no mesh meets the request)",
    "chosen": "the candidate kept: single, continuations, bisectors, recursive, radial, fillets, rings (or a refinement of one)",
    "rule": "the step of the choice rule that decided between the chosen candidate and the runner-up",
    "runner_up": "the second-best candidate (null: none other was meshed)",
    "quads": "quads in the mesh",
    "vertices": "vertices in the mesh",
    "patches": "patches (catalogue templates) the region was split into",
    "min_scaled_jacobian": "smallest scaled Jacobian of a quad (1: a rectangle; <= 0: inverted)",
    "mean_scaled_jacobian": "mean scaled Jacobian over the quads",
    "inverted": "quads with a corner of zero or negative area (0 in a valid mesh)",
    "corners": "corners of the region (outer loop and holes)",
    "missed_corners": "corners with no mesh vertex on them (0 in a valid mesh)",
    "area_ratio": "sum of the quads' areas / the region's area (1 within round-off for a polygon)",
    "irregular": "internal vertices whose valence is not 4",
    "irregular_bound": "Euler's lower bound on irregular internal vertices for the mesh's boundary valences",
    "max_edge_ratio": "largest longest/shortest edge ratio of a quad",
    "mean_edge_length": "mean length of the mesh's edges (the region's units)",
    "size": "the target edge length h (the region's units; --size, or perimeter / --divisions; with --size-field "
            "the outline's length over the field's integral of 1 / size along it)",
    "size_deviation": "largest abs(n / (L / h) - 1) over the sides: n the side's edges, L its length. A side far "
                      "shorter than h still gets one edge, so a 0.0006 h side gives about 1660; the choice rule's "
                      "size test allows max(1, 25 %) of L / h edges off, so such a side passes",
    "field_share": "share of the edges whose length / the size at their midpoint lies in [0.5, 1.6]: the size "
                   "field's value there with --size-field, else h; null without a size (--template)",
    "side_counts": 'edges per side, keyed "i-j" as the mesh file\'s "side i-j" groups (from the input\'s corner i to the '
                   'next, j: point numbers, or positions in "corners") and "hole h side i-j" as its hole sides; an assembly\'s as its groups, "NAME side i-j"',
    "templates": "the catalogue mesh id of each patch's template",
    "warnings": "what is poor about the mesh, each with what to try (empty for a good mesh): min scaled Jacobian "
                "below the quality floor, irregular vertices beyond twice Euler's bound, edges far longer than h",
    "candidates": "every candidate tried: name, note (why it was skipped or how it was meshed) and, when meshed, "
                  "patches, quads, min/mean scaled Jacobian, inverted, irregular and sides_off_size (sides whose "
                  "edge count is off L / h by more than max(1, 25 %))",
    "seconds": "wall time spent on the region in its worker (reading excluded; meshing, and for failed or "
               "timed-out records the time until it stopped)",
    "region_budget": "timed-out records only: the budget (seconds) the region went past",
    "out": "meshed records only: the mesh file written",
    "input_hash": "SHA-256 of the region's input file (what --resume compares)",
    "options_hash": "SHA-256 of the options a mesh depends on (size, divisions, strategies, budget, corner angle, "
                    "format, catalogue and lattice contents, jaxmatch version; what --resume compares)",
}
"""Every field of a ``summary.jsonl`` record, with what it holds (``docs/reference.md`` shows
this table; ``tests/test_batch.py`` checks both name every field a record has)."""


class RegionTimedOut(BaseException):
    """Raised in the meshing thread when a region goes past its budget (a BaseException, so that
    no ``except Exception`` on the way turns it into a failed candidate)."""


@dataclasses.dataclass(frozen=True)
class Job:
    """One region of a run: ``index`` in the order given, ``shape`` as given, ``target`` its
    mesh file, ``input_hash`` the SHA-256 of its file, ``error`` the reading error (with
    ``skip_bad``; None when it was read)."""

    index: int
    shape: str
    target: str
    input_hash: str
    error: str | None = None


@dataclasses.dataclass(frozen=True)
class RunResult:
    """What a run did: ``records`` in the order of the regions (one each), ``reused`` regions
    skipped by ``resume``, ``seconds`` of the whole run."""

    records: tuple[dict, ...]
    reused: int
    seconds: float

    def count(self, status: str) -> int:
        return sum(1 for r in self.records if r.get("status") == status)

    @property
    def folded(self) -> int:
        """Meshed regions whose mesh folds or misses a corner."""
        return sum(1 for r in self.records if r.get("status") == "meshed" and (r["inverted"] or r["missed_corners"]))


# ---------------------------------------------------------------------------------------------
# the budget of one region


@contextlib.contextmanager
def deadline(seconds: float | None) -> Iterator[None]:
    """Raise :class:`RegionTimedOut` in this thread once ``seconds`` have passed inside the block
    (None or inf: no limit). The main thread uses ``SIGALRM``; another thread (a Dask task) gets
    the exception from a timer thread (``PyThreadState_SetAsyncExc``). Python code is stopped at
    its next step; compiled code only when it returns."""
    if seconds is None or not math.isfinite(seconds):
        yield
        return
    if threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer"):
        def alarm(signum, frame):
            raise RegionTimedOut()

        previous = signal.signal(signal.SIGALRM, alarm)
        signal.setitimer(signal.ITIMER_REAL, max(float(seconds), 1e-6))
        try:
            yield
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)
        return
    tid, lock, state = threading.get_ident(), threading.Lock(), {"done": False, "fired": False}

    def fire():
        with lock:
            if not state["done"]:
                state["fired"] = True
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(tid), ctypes.py_object(RegionTimedOut))

    timer = threading.Timer(float(seconds), fire)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        with lock:
            state["done"] = True
            if state["fired"]:  # not raised yet (the block ended first): withdraw it, raise it here
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(tid), None)
        if state["fired"]:
            raise RegionTimedOut()


# ---------------------------------------------------------------------------------------------
# jobs, options, the summary


def _file_of(shape: str) -> str:
    return shape.split("#", 1)[0]


def _hash_file(path: str) -> str:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return ""
    return h.hexdigest()


def plan(regions: Sequence[str | os.PathLike], out_dir: Path, suffix: str, read: Callable[[str], object],
         skip_bad: bool) -> tuple[list[Job], list[object]]:
    """Every region read (``read(shape)``, raising :class:`InputError`) and named: the jobs and
    the regions read (an error text in place of a region that could not be read, with
    ``skip_bad``; else the error is raised). Mesh files are named after the region's file
    (``FILE#ID``: ``FILE-ID``), ``-2``, ``-3``, ... where names repeat."""
    jobs, loaded, names = [], [], set()
    for i, p in enumerate(map(str, regions)):
        stem = Path(_file_of(p)).stem + ("-" + p.split("#", 1)[1] if "#" in p else "")
        name, k = stem, 1
        while name in names:
            k += 1
            name = f"{stem}-{k}"
        names.add(name)
        try:
            region, error = read(p), None
        except InputError as e:
            if not skip_bad:
                raise
            region, error = str(e), str(e)
        jobs.append(Job(i, p, str(out_dir / f"{name}{suffix}"), _hash_file(_file_of(p)), error))
        loaded.append(region)
    return jobs, loaded


def _catalogue_id(cat) -> str:
    path = Path(getattr(cat, "path", "") or "")
    return "shipped" if path and path.resolve() == default_path().resolve() else _hash_file(str(path))


def options_hash(options: dict, writing: MeshOutput, corner_angle: float) -> str:
    """SHA-256 of everything a region's mesh depends on besides its file: ``options`` (the
    :func:`~jaxmatch.meshing.pipeline.mesh` keywords: size, divisions, strategies, budget,
    catalogue, lattice, and automatic sizing and the search where not the default), how the mesh file is written (``writing``: format, MSH version, element
    type, order, extrusion), the corner angle and jaxmatch's version (the shipped catalogue by
    name, another by its file's contents; the lattice by its weights)."""
    doc = {"size": options.get("size"), "divisions": options.get("divisions"), "strategies": options.get("strategies"),
           "budget_s": options.get("budget_s"), "writing": dataclasses.asdict(writing), "corner_angle": float(corner_angle),
           "catalogue": _catalogue_id(options.get("catalogue")), "lattice": repr(options.get("lattice")),
           "version": __version__}
    for key, default in (("auto_size", False), ("search", None)):  # (only when given: the hashes of other runs as they were)
        if options.get(key, default) not in (default, "best"):
            doc[key] = options[key]
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def read_summary(path: Path) -> tuple[dict[str, dict], int]:
    """The last record of each shape in a summary file, and the number of lines that were not a
    record (a line cut short by a kill). A missing file: ``({}, 0)``."""
    out, bad = {}, 0
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return {}, 0
    except OSError as e:
        raise InputError(f"cannot read the summary to resume from: {e.strerror or e}", str(path)) from None
    for line in text.splitlines():
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except ValueError:
            bad += 1
            continue
        if isinstance(rec, dict) and isinstance(rec.get("shape"), str):
            out[rec["shape"]] = rec
        else:
            bad += 1
    return out, bad


def _reusable(rec: dict | None, job: Job, opts: str) -> bool:
    return (rec is not None and rec.get("status") == "meshed" and rec.get("input_hash") == job.input_hash
            and rec.get("options_hash") == opts and rec.get("out") == job.target and Path(job.target).is_file())


class _Appender:
    """The summary file, each record appended with one ``write`` of the whole line."""

    def __init__(self, path: Path):
        self.fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o666)

    def add(self, rec: dict) -> None:
        data = (json.dumps(rec) + "\n").encode()
        while data:
            data = data[os.write(self.fd, data):]

    def close(self) -> None:
        os.close(self.fd)


def _write_summary(path: Path, records) -> None:
    with atomic_open(path, "w") as fh:
        for rec in records:
            fh.write(json.dumps(rec) + "\n")


# ---------------------------------------------------------------------------------------------
# one region


def _stamp(rec: dict, job: Job, opts: str) -> dict:
    rec["input_hash"], rec["options_hash"] = job.input_hash, opts
    return rec


def mesh_job(job: Job, region, options: dict, opts: str, region_budget: float | None,
             write: Callable[[str, object], str]) -> dict:
    """The record of one region (:data:`RECORD_FIELDS`): meshed with ``options`` within
    ``region_budget`` seconds, the mesh handed to ``write(target, mesh)`` (which returns the
    file written, recorded as ``out``); a region that could not be read (``region`` an error
    text) or meshed (:class:`InputError`) gets ``status: failed``, one past its budget
    ``status: timed out``."""
    if isinstance(region, str):
        return _stamp({"shape": job.shape, "status": "failed", "error": region, "seconds": 0.0}, job, opts)
    t0 = time.perf_counter()
    try:
        with deadline(region_budget):
            m = later.pipeline.mesh(region, **options)
    except RegionTimedOut:
        return _stamp({"shape": job.shape, "status": "timed out", "seconds": round(time.perf_counter() - t0, 4),
                       "region_budget": region_budget}, job, opts)
    except InputError as e:
        return _stamp({"shape": job.shape, "status": "failed", "error": str(e),
                       "seconds": round(time.perf_counter() - t0, 4)}, job, opts)
    seconds = time.perf_counter() - t0
    rec = report.mesh_record(job.shape, m, seconds)
    try:
        out = write(job.target, m)
    except InputError as e:  # the mesh file cannot be written (e.g. a format that cannot hold it)
        return _stamp({"shape": job.shape, "status": "failed", "error": f"{job.shape}: {e}",
                       "seconds": round(seconds, 4)}, job, opts)
    rec = {"shape": rec.pop("shape"), "status": "meshed", **rec, "out": out}
    return _stamp(rec, job, opts)


def _writer(writing: MeshOutput) -> Callable[[str, object], str]:
    """``write(target, mesh) -> path written``, as ``writing`` says (module level: workers
    inherit it, Dask pickles it by value of ``writing``)."""
    return lambda target, m: str(write_mesh(target, m, writing))


# ---------------------------------------------------------------------------------------------
# runners: each yields (index, record) as regions finish


PRELOAD_REGIONS = 50
"""Runs of at least this many regions load numba's kernel before forking (:func:`warm_kernels`);
fewer regions rarely spend the C kernel's budget in a worker, and loading it costs ~0.7 s."""


def warm_kernels(load: bool = True) -> None:
    """Before forking the workers: keep every process to the single-thread scoring kernel (one
    core per worker: the multi-thread kernel in each of two workers on two cores only fights
    for them) and (``load``) load numba's kernel here, where every worker would import numba
    and load it on its own once the C kernel's budget is spent (~0.5 s each, seconds on a
    loaded machine). The kernels are exact: the same values, the same meshes."""
    backends.serial_only()
    if not load or not backends._numba_available():
        return
    backends.numba_values(np.zeros((1, 4), np.int32), np.array([4]), np.full((1, 4), 3, np.int32),
                          np.zeros((4, 64), np.int16), np.zeros(4, np.int16))


def _inline_results(jobs, loaded, options, opts, region_budget, writing) -> Iterator[tuple[int, dict]]:
    for job in jobs:
        yield job.index, mesh_job(job, loaded[job.index], options, opts, region_budget, _writer(writing))


def _die_with_parent() -> None:
    """Linux: this process gets SIGKILL when its parent dies (a killed run leaves no workers)."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # pragma: no cover - not Linux: a worker ends at its next answer
        pass


def one_core() -> None:
    """This process's BLAS (OpenBLAS under numpy and scipy) on one thread: each worker has one
    core, and BLAS threads of two workers on two cores wait for each other (~5 % of the run's
    CPU time on 110 random parts)."""
    threadpoolctl.threadpool_limits(1)


def _worker_main(conn, jobs, loaded, options, opts, region_budget, writing, initializer) -> None:
    _die_with_parent()
    one_core()
    sys.stdout, sys.stderr = sys.__stdout__, sys.__stderr__  # not the progress display's proxies
    if initializer is not None:
        initializer()
    try:
        while True:
            chunk = conn.recv()
            if chunk is None:
                return
            for i in chunk:
                try:
                    rec = mesh_job(jobs[i], loaded[i], options, opts, region_budget, _writer(writing))
                except Exception as e:  # noqa: BLE001 - an internal error: the region's record says so
                    rec = _stamp({"shape": jobs[i].shape, "status": "failed",
                                  "error": f"{jobs[i].shape}: internal error: {type(e).__name__}: {e}"}, jobs[i], opts)
                conn.send((i, rec))
    except (EOFError, OSError, KeyboardInterrupt):
        return


class _Worker:
    def __init__(self, ctx, args):
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker_main, args=(child, *args), daemon=True)
        self.proc.start()
        child.close()
        self.queue: deque[int] = deque()
        self.since = time.monotonic()

    def send(self, chunk: list[int]) -> None:
        if not self.queue:
            self.since = time.monotonic()
        self.queue.extend(chunk)
        self.conn.send(chunk)

    def stop(self, kill: bool = False) -> None:
        if kill:
            self.proc.kill()
        else:
            try:
                self.conn.send(None)
            except OSError:
                pass
        self.proc.join(timeout=None if kill else 2.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def chunk_size(remaining: int, jobs: int) -> int:
    """Regions sent to a worker at once: up to 8, fewer towards the end so the workers finish
    together."""
    return max(1, min(8, remaining // (4 * max(jobs, 1))))


def _local_results(jobs, loaded, options, opts, region_budget, n_workers: int, initializer,
                   grace: float = DEFAULT_GRACE_S, writing: MeshOutput = MeshOutput()) -> Iterator[tuple[int, dict]]:
    todo = deque(j.index for j in jobs)
    by_index = {j.index: j for j in jobs}
    ctx = multiprocessing.get_context("fork")
    args = ({j.index: j for j in jobs}, loaded, options, opts, region_budget, writing, initializer)
    workers = [_Worker(ctx, args) for _ in range(min(n_workers, len(todo)))]
    limit = None if region_budget is None or not math.isfinite(region_budget) else region_budget + grace

    def feed(w: _Worker) -> None:
        if len(w.queue) <= 1 and todo:  # the next chunk is there before the last one is done
            n = chunk_size(len(todo), len(workers))
            w.send([todo.popleft() for _ in range(min(n, len(todo)))])

    def replace(w: _Worker, rec: dict) -> tuple[int, dict]:
        i = w.queue.popleft()
        todo.extendleft(reversed(w.queue))
        w.stop(kill=True)
        workers[workers.index(w)] = fresh = _Worker(ctx, args)
        feed(fresh)
        return i, _stamp({"shape": by_index[i].shape, **rec}, by_index[i], opts)

    try:
        for w in workers:
            feed(w)
        while any(w.queue for w in workers):
            busy = [w for w in workers if w.queue]
            timeout = None if limit is None else max(0.05, min(w.since + limit for w in busy) - time.monotonic())
            ready = wait_any([w.conn for w in busy], timeout)
            for w in busy:
                if w.conn in ready:
                    try:
                        i, rec = w.conn.recv()
                    except (EOFError, OSError):
                        code = w.proc.exitcode
                        yield replace(w, {"status": "failed", "error": f"{by_index[w.queue[0]].shape}: the worker "
                                                                       f"process died (exit status {code})"})
                        continue
                    w.queue.popleft()
                    w.since = time.monotonic()
                    feed(w)
                    yield i, rec
                elif limit is not None and time.monotonic() - w.since > limit:
                    yield replace(w, {"status": "timed out", "seconds": round(time.monotonic() - w.since, 4),
                                      "region_budget": region_budget})
    finally:
        for w in workers:
            w.stop(kill=bool(w.queue))


# ---------------------------------------------------------------------------------------------
# Dask


@dataclasses.dataclass(frozen=True)
class DaskSettings:
    """What a Dask task needs besides its region: the options (catalogue by path, None: the
    shipped one; the lattice itself), the mesh suffix, the corner angle and the budgets."""

    catalogue: str | None
    lattice: object
    size: float | None
    divisions: int | None
    strategies: tuple[str, ...] | None
    budget_s: float
    region_budget: float | None
    writing: MeshOutput
    suffix: str
    corner_angle: float
    options_hash: str


_OPENED: dict = {}
"""A Dask worker process's opened catalogues and lattices (each opened once per process)."""


def _opened(settings: DaskSettings) -> dict:
    k = (settings.catalogue, repr(settings.lattice))
    if k not in _OPENED:
        one_core()
        cat = later.inputs.load_catalogue(settings.catalogue)
        later.pipeline.warm_up(cat, settings.lattice)
        _OPENED[k] = cat
    return {"catalogue": _OPENED[k], "lattice": settings.lattice, "size": settings.size,
            "divisions": settings.divisions, "strategies": None if settings.strategies is None else list(settings.strategies),
            "budget_s": settings.budget_s}


def dask_task(job: Job, data: bytes, settings: DaskSettings) -> tuple[int, dict, bytes | None]:
    """One region on a Dask worker: its file's bytes (``data``) read as a file of the same name,
    meshed, the mesh file's bytes returned with the record (the client writes the file)."""
    options = _opened(settings)
    file_name = Path(_file_of(job.shape)).name
    with tempfile.TemporaryDirectory(prefix="jaxmatch-") as tmp:
        local = Path(tmp) / file_name
        with atomic_path(local) as part:
            part.write_bytes(data)
        fragment = "#" + job.shape.split("#", 1)[1] if "#" in job.shape else ""
        try:
            region = later.region.load_region(str(local) + fragment, corner_angle=settings.corner_angle)
        except InputError as e:
            region = str(e).replace(str(local), _file_of(job.shape))
        out: dict = {}

        def write(target: str, m) -> str:
            out["data"] = write_mesh(Path(tmp) / ("mesh" + settings.suffix), m, settings.writing).read_bytes()
            return target

        rec = mesh_job(job, region, options, settings.options_hash, settings.region_budget, write)
    return job.index, rec, out.get("data")


def _dask_client(address: str):
    try:
        distributed = __import__("distributed")
    except ImportError:
        raise InputError("needs Dask's 'distributed' package: pip install 'jaxmatch[dask]'", "--dask") from None
    try:
        return distributed, distributed.Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise InputError(f"cannot reach a Dask scheduler at {address!r}: {e}", "--dask") from None


def _dask_results(address: str, jobs, options, opts, region_budget, writing: MeshOutput, suffix: str,
                  corner_angle: float) -> Iterator[tuple[int, dict]]:
    distributed, client = _dask_client(address)
    cat = options.get("catalogue")
    shipped = _catalogue_id(cat) == "shipped"
    settings = DaskSettings(None if shipped else str(cat.path), options["lattice"], options.get("size"),
                            options.get("divisions"), None if options.get("strategies") is None else tuple(options["strategies"]),
                            options["budget_s"], region_budget, writing, suffix, corner_angle, opts)
    try:
        slots = max(4, 4 * sum(client.nthreads().values()))
        todo = deque(jobs)
        by_index = {j.index: j for j in jobs}
        if not todo:
            return

        def submit():
            job = todo.popleft()
            data = Path(_file_of(job.shape)).read_bytes()
            return client.submit(dask_task, job, data, settings, pure=False, key=f"jaxmatch-region-{job.index}-{os.getpid()}")

        pending = distributed.as_completed([submit() for _ in range(min(slots, len(todo)))], loop=client.loop)
        for fut in pending:
            try:
                i, rec, data = fut.result()
            except Exception as e:  # noqa: BLE001 - a worker lost, a task that raised: the region's record says so
                i = int(fut.key.rsplit("-", 2)[1])
                rec = _stamp({"shape": by_index[i].shape, "status": "failed",
                              "error": f"{by_index[i].shape}: the Dask task failed: {type(e).__name__}: {e}"}, by_index[i], opts)
                data = None
            if data is not None:
                with atomic_path(rec["out"]) as tmp:
                    tmp.write_bytes(data)
            if todo:
                pending.add(submit())
            yield i, rec
    finally:
        client.close()


# ---------------------------------------------------------------------------------------------
# the run


def _rate_text(done: int, total: int, started: float) -> str:
    """``"regions (7.9/s, ~12 s left)"``: the rate of this run's regions and the time left at it."""
    elapsed = time.monotonic() - started
    if done == 0 or elapsed <= 0:
        return "regions"
    rate = done / elapsed
    return f"regions ({rate:.1f}/s, ~{(total - done) / rate:.0f} s left)"


def run(regions: Sequence[str | os.PathLike], out_dir: Path, writing: MeshOutput, corner_angle: float, options: dict, *,
        jobs: int | None, skip_bad: bool, resume: bool = False, region_budget: float | None = None,
        dask: str | None = None, read: Callable[[str], object], progress=None,
        warm: Callable[[], None] | None = None, initializer: Callable[[], None] | None = None,
        say: Callable[[str], None] = lambda line: print(line, file=sys.stderr)) -> RunResult:
    """Mesh every region into ``out_dir`` (see the module's docstring): the records in the order
    of ``regions``.

    writing: how the mesh files are written (format: default msh). options: the keywords of
    :func:`~jaxmatch.meshing.pipeline.mesh` (catalogue and lattice opened). jobs: local worker
    processes (None: the CPUs). read: ``read(shape)`` a region or :class:`InputError`.
    progress: a display with rich's ``add_task``/``update`` (the CLI's), shown while meshing.
    warm: run in this process before the workers are forked. initializer: run in each worker.
    say: where the notes (regions reused, lines skipped) and the closing line go.
    Raises InputError (bad input, a failed region without ``skip_bad``: stops the run; the
    records so far stay in the summary for ``resume``)."""
    t_start = time.monotonic()
    name = mesh_format("x", writing.format or "msh")
    suffix = next(s for s, n in MESH_FORMATS.items() if n == name)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("is not a folder", str(out_dir))
    if region_budget is not None and not region_budget > 0:
        raise InputError(f"must be a positive number of seconds, got {region_budget:g}", "--region-budget")
    job_list, loaded = plan(regions, out_dir, suffix, read, skip_bad)
    opts = options_hash(options, writing, corner_angle)
    summary = out_dir / "summary.jsonl"
    out_dir.mkdir(parents=True, exist_ok=True)
    records: dict[int, dict] = {}
    if resume:
        old, torn = read_summary(summary)
        if torn:
            say(f"{summary}: {torn} line(s) that are not a record ignored (a run stopped while writing)")
        for job in job_list:
            if _reusable(old.get(job.shape), job, opts):
                records[job.index] = old[job.shape]
        say(f"--resume: {len(records)} of {len(job_list)} regions already meshed with these options, "
            f"{len(job_list) - len(records)} to mesh")
    _write_summary(summary, [records[i] for i in sorted(records)])
    todo = [j for j in job_list if j.index not in records]
    unread = [j for j in todo if j.error is not None]  # --skip-bad: their records need no worker
    readable = [j for j in todo if j.error is None]
    workers = available_cpus() if jobs is None else int(jobs)
    if dask is not None and readable:
        meshed = _dask_results(dask, readable, options, opts, region_budget, writing, suffix, corner_angle)
    elif readable and can_fork():
        if warm is not None:
            warm()
        warm_kernels(load=len(readable) >= PRELOAD_REGIONS)
        meshed = _local_results(readable, loaded, options, opts, region_budget, workers, initializer, writing=writing)
    else:
        meshed = _inline_results(readable, loaded, options, opts, region_budget, writing)
    results = itertools.chain(_inline_results(unread, loaded, options, opts, region_budget, writing), meshed)
    appender = _Appender(summary)
    display = progress if progress is not None else contextlib.nullcontext()
    started, done = time.monotonic(), 0
    try:
        with display as prog:
            task = prog.add_task("regions", total=len(job_list), completed=len(records)) if prog is not None else None
            for i, rec in results:
                if rec["status"] == "failed" and not skip_bad:
                    err = rec["error"]
                    raise InputError(err.split(": ", 1)[-1] if err.startswith(rec["shape"]) else err, rec["shape"])
                appender.add(rec)
                records[i] = rec
                done += 1
                if prog is not None:
                    prog.update(task, completed=len(records), description=_rate_text(done, len(todo), started))
    finally:
        appender.close()
        close = getattr(meshed, "close", None)
        if close is not None:
            close()
    ordered = tuple(records[j.index] for j in job_list)
    _write_summary(summary, ordered)
    result = RunResult(ordered, len(job_list) - len(todo), time.monotonic() - t_start)
    failed, timed_out = result.count("failed"), result.count("timed out")
    warned = sum(1 for r in ordered if r.get("warnings"))
    rate = f"; {done / (time.monotonic() - started):.1f} regions/s" if done and time.monotonic() > started else ""
    notes = "".join([f", {len(job_list) - len(todo)} kept from the summary (--resume)" if resume else "",
                     f", {failed} failed (records with \"error\")" if failed else "",
                     f", {timed_out} timed out (records with \"status\": \"timed out\")" if timed_out else "",
                     f", {warned} with warnings (records' \"warnings\": a poor mesh)" if warned else ""])
    say(f"wrote {summary}: {len(ordered)} regions, {result.count('meshed')} meshed{notes}{rate}")
    return result
