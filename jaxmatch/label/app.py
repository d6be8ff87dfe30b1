"""The labelling web app of ``jaxmatch label`` (Starlette; served by uvicorn on loopback).

The page (``static/index.html``, plain HTML/JS/SVG) shows one shape at a time with the top K
meshes of the catalogue placed in it; the designer clicks the preferred one and it is appended
to the labels file (:class:`jaxmatch.label.store.LabelStore`).

HTTP API (JSON in and out; errors are 4xx ``{"error": "<one line>"}``, never a traceback):

``GET /api/state``
    ``{"total", "labelled", "labels", "out", "top", "internal", "shapes": [{"id", "name", "mark"}]}``;
    ``mark`` is a mesh id, ``"none"`` or null (not labelled yet).
``GET /api/shapes/{id}``
    The shape and its candidates: ``outline (P, 2)`` user coordinates, ``points``: the s/x/v
    annotation ``[{"x", "y", "code": "s"|"x"|"v"}]``, ``candidates``: one per ranked mesh
    ``{"rank", "mesh_id", "k", "utility", "min_scaled_jacobian", "inverted", "rotation",
    "reflected", "xy" (V, 2), "quads" (F, 4), "boundary" (n,) vertex indices, "valence" (V,)}``
    (placed in the shape's units; with ``size`` the template refined to edges of about that
    length), and ``mark``.
``POST /api/shapes/{id}/choose``
    ``{"mesh_id": ID}`` (one of the candidates shown for that shape, else 400) or
    ``{"none": true}``; the line is fsynced before the answer ``{"ok": true, "record", "labelled"}``.
``POST /api/shapes``
    A drawn shape ``{"boundary": [[x, y], ...], "corners": [i, ...]}`` (corners optional);
    checked as a shape file; answers ``{"id"}``.
``POST /api/upload?name=FILE``
    A dropped shape file: the request body is its bytes (any format jaxmatch reads; ``name``
    only picks the format by suffix and names the shape in messages, it is never opened).
``POST /api/tune``
    Tunes the lattice on the file's labels and writes it to the configured output
    (:func:`jaxmatch.label.store.tune_labels`); answers its summary and ``toml`` (the text).
"""

from __future__ import annotations

import json
import math
import os
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path, PurePath

import numpy as np
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from jaxmatch import api
from jaxmatch.catalogue.mesh import valences
from jaxmatch.errors import InputError, InputWarning, UnmatchableError
from jaxmatch.io.readers import SUFFIXES, detect_format, parse_shape, split_element
from jaxmatch.label.store import LabelStore, shape_key, tune_labels
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, check_corner_angle

__all__ = ["Item", "LabelSession", "STATIC_DIR", "create_app"]

STATIC_DIR = Path(__file__).with_name("static")
MAX_BODY = 8 * 2**20
"""Largest request body (bytes): a dropped shape file or a drawn shape."""
MAX_DRAWN_POINTS = 10_000
CODE_LETTERS = "sxv"


class BadRequest(Exception):
    """A request the app refuses: ``status`` (4xx) and a one-line ``message``."""

    def __init__(self, message: str, status: int = 400):
        super().__init__(" ".join(str(message).split()))
        self.status = status


@dataclass(eq=False)
class Item:
    """One shape of the session: ``spec`` is what its label lines hold as ``"shape"`` (a path
    relative to the labels folder, or an inline object); ``candidates`` the JSON shown (cached)."""

    name: str
    shape: object
    spec: object
    candidates: dict | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)

    @property
    def key(self) -> str:
        return shape_key(self.spec)


class LabelSession:
    """The state of one ``jaxmatch label`` run.

    shapes: shape file paths (``FILE#ID`` allowed), checked here (InputError on a bad one);
    labels: the labels file (its folder must exist; created on the first choice); internal:
    mesh sizes (``2``, ``"2..3"``, None: all sizes compete); top: candidates per shape (1..9);
    size: target edge length (shape units) to refine the shown meshes to, or None; out: where
    the tune action writes the tuned lattice (default ``<labels>.tuned.toml``); lattice,
    catalogue, corner_angle: as for ``jaxmatch score``; epochs: tuning passes.
    """

    def __init__(self, shapes=(), labels="labels.jsonl", *, internal=None, top: int = 5, size: float | None = None,
                 out=None, lattice: str = "fine", catalogue=None, corner_angle: float | None = None, epochs: int = 10):
        if not 1 <= int(top) <= 9:
            raise InputError(f"must be 1..9 (keys 1..9 choose), got {top}", where="--top")
        if size is not None and not (size > 0 and math.isfinite(size)):
            raise InputError(f"must be a positive length, got {size!r}", where="--size")
        self.labels = Path(labels)
        if self.labels.is_dir():
            raise InputError("is a folder, expected a .jsonl file", where=str(self.labels))
        if not self.labels.parent.is_dir():
            raise InputError("its folder does not exist", where=str(self.labels))
        self.out = Path(out) if out is not None else self.labels.with_suffix(".tuned.toml")
        self.top, self.size, self.epochs = int(top), size, int(epochs)
        self.lattice_name = str(lattice)
        self.catalogue = api.load_catalogue(catalogue)
        try:
            self.internal = api.check_sizes(self.catalogue, internal)
        except InputError as e:
            raise InputError(e.problem, where="--internal") from None
        self.lattice = api.load_lattice(lattice)
        self.corner_angle = check_corner_angle(DEFAULT_CORNER_ANGLE if corner_angle is None else corner_angle)
        self.store = LabelStore(self.labels)
        self.items: list[Item] = []
        self._lock = threading.Lock()
        self._compute = threading.Lock()  # one ranking at a time (JAX, and a 2-core machine)
        self._tuning = threading.Lock()
        seen = set()
        for path in shapes:
            item = self._file_item(str(path))
            if item.key not in seen:
                seen.add(item.key)
                self.items.append(item)
        for _, rec, _kind in self.store.records():  # shapes labelled before, not given now
            key = shape_key(rec["shape"])
            if key in seen:
                continue
            seen.add(key)
            try:
                self.items.append(self._record_item(rec["shape"]))
            except InputError as e:
                warnings.warn(InputWarning(f"shape not shown: {e.problem}", where=str(self.labels)))

    # -- shapes -------------------------------------------------------------------------------

    def _load(self, path: str):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InputWarning)
            return api.load_shape(path, corner_angle=self.corner_angle)

    def _file_item(self, path: str) -> Item:
        """A shape given on the command line: its label lines name it relative to the labels folder."""
        shape = self._load(path)
        file, element = split_element(path)
        rel = os.path.relpath(os.path.abspath(file), os.path.abspath(self.labels.parent))
        spec = Path(rel).as_posix() + (f"#{element}" if element else "")
        return Item(PurePath(file).name + (f"#{element}" if element else ""), shape, spec)

    def _record_item(self, spec) -> Item:
        """A shape found in the labels file (a path there is relative to the file's folder)."""
        if isinstance(spec, str):
            path = Path(spec)
            full = path if path.is_absolute() else self.labels.parent / path
            return Item(PurePath(spec).name, self._load(str(full)), spec)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InputWarning)
            shape = parse_shape(json.dumps(spec), "labelled shape", fmt="json", corner_angle=self.corner_angle)
        return Item(f"drawn shape {len(self.items) + 1}", shape, spec)

    def _inline(self, shape, name: str) -> int:
        """Add a shape given by the page (drawn or dropped); its label lines hold it inline.
        Returns its id (an existing one when the same shape is there already)."""
        pts = shape.given_points
        spec = {"boundary": [[float(x), float(y)] for x, y in np.asarray(pts, np.float64).tolist()]}
        if shape.n_corners:
            spec["corners"] = [int(c) for c in np.asarray(shape.corners).tolist()]
        item = Item(name, shape, spec)
        with self._lock:
            for i, other in enumerate(self.items):
                if other.key == item.key:
                    return i
            self.items.append(item)
            return len(self.items) - 1

    def add_drawn(self, doc) -> int:
        """A drawn shape ``{"boundary": [[x, y], ...], "corners": [...]}``: the JSON shape file
        checks apply (InputError with their message)."""
        if not isinstance(doc, dict) or not isinstance(doc.get("boundary"), list):
            raise BadRequest('expected {"boundary": [[x, y], ...], "corners": [i, ...]}')
        if len(doc["boundary"]) > MAX_DRAWN_POINTS:
            raise BadRequest(f"a drawn shape has at most {MAX_DRAWN_POINTS} points")
        body = {k: doc[k] for k in ("boundary", "corners") if k in doc and doc[k] is not None}
        if body.get("corners") == []:
            del body["corners"]
        shape = parse_shape(json.dumps(body), "drawn shape", fmt="json", corner_angle=self.corner_angle)
        return self._inline(shape, f"drawn shape {len(self.items) + 1}")

    def add_upload(self, data: bytes, name: str) -> int:
        """A dropped shape file's bytes; ``name`` (a file name, never opened) picks the format by
        its suffix, else the content does."""
        base = PurePath(str(name).replace("\\", "/")).name.replace("#", "_")[:120] or "dropped shape"
        suffix = PurePath(base).suffix.lower()
        fmt = detect_format("upload" + (suffix if suffix in SUFFIXES else ""), data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", InputWarning)
            shape = parse_shape(data, base, fmt=fmt, corner_angle=self.corner_angle)
        return self._inline(shape, base)

    # -- state, candidates, choices -----------------------------------------------------------

    def item(self, i) -> Item:
        try:
            i = int(i)
        except (TypeError, ValueError):
            raise BadRequest(f"unknown shape {i!r}", 404) from None
        if not 0 <= i < len(self.items):
            raise BadRequest(f"unknown shape {i} (there are {len(self.items)})", 404)
        return self.items[i]

    @staticmethod
    def _mark_text(mark) -> str | None:
        if mark is None:
            return None
        return mark.preferred if mark.preferred is not None else "none"

    def state(self) -> dict:
        """Progress and the list of shapes with their marks (from the labels file)."""
        marks = self.store.marks()
        shapes = [{"id": i, "name": it.name, "mark": self._mark_text(marks.get(it.key))} for i, it in enumerate(self.items)]
        return {"total": len(shapes), "labelled": sum(s["mark"] is not None for s in shapes), "shapes": shapes,
                "labels": str(self.labels), "out": str(self.out), "top": self.top,
                "internal": None if self.internal is None else self.internal, "size": self.size}

    def candidates(self, i) -> dict:
        """The shape ``i`` and its top meshes placed in it (see the module docstring); cached."""
        item = self.item(i)
        with item.lock:
            if item.candidates is None:
                with self._compute:
                    item.candidates = self._compute_candidates(item)
        out = dict(item.candidates)
        out["id"] = int(i)
        out["mark"] = self._mark_text(self.store.marks().get(item.key))
        return out

    def _compute_candidates(self, item: Item) -> dict:
        shape = item.shape
        ranking = api.rank(shape, self.catalogue, self.lattice, internal=self.internal, top=self.top)
        ann = ranking.annotation
        pos = shape.to_user(ann.positions)
        cands = []
        for r, match in enumerate(ranking.results, start=1):
            pl = api.place(shape, ranking, which=r, catalogue=self.catalogue, lattice=self.lattice)
            note = ""
            if self.size is not None:
                pl, note = self._refined(shape, ann, match, r, pl)
            xy = np.asarray(pl.xy, np.float64)
            quads = np.asarray(pl.mesh.quads, np.int64)
            cands.append({
                "rank": r, "mesh_id": match.mesh_id, "k": int(match.internal_vertices),
                "utility": float(match.utility), "rotation": int(match.rotation), "reflected": bool(match.reflected),
                "min_scaled_jacobian": float(pl.min_scaled_jacobian), "inverted": int(pl.inverted),
                "xy": np.round(xy, 9).tolist(), "quads": quads.tolist(),
                "boundary": np.asarray(pl.mesh.boundary, np.int64).tolist(),
                "valence": valences(quads, xy.shape[0]).astype(int).tolist(), "note": note,
            })
        return {"name": item.name, "spec": item.spec, "outline": np.round(shape.user_points, 9).tolist(),
                "points": [{"x": float(x), "y": float(y), "code": CODE_LETTERS[int(c)]} for (x, y), c in zip(pos.tolist(), ann.codes.tolist())],
                "candidates": cands}

    def _refined(self, shape, ann, match, r, pl):
        """The placement ``pl`` refined to edges of about ``self.size`` (what ``jaxmatch mesh
        --size`` does, for this template; the template stays the label), or ``pl`` with a note
        when this template cannot be refined (a corner without a mesh vertex, a fold)."""
        try:
            from jaxmatch.placement.choose import place_match
            from jaxmatch.placement.refine import refine_and_place, solve_multiplicities
            from jaxmatch.placement.templates import fit_template

            template = fit_template(shape, ann, match, self.catalogue, r)
            if template is None:
                return pl, "not refined: a corner has no mesh vertex"
            placed = place_match(shape, ann, self.catalogue, match)  # the ranked orientation, as refine_mesh places it
            if placed.inverted:
                return pl, "not refined: the template folds"
            template = template._replace(placement=placed)
            refined = refine_and_place(template, solve_multiplicities(template, size=self.size), cache=self.catalogue.cache)
            return refined.as_placement(), ""
        except InputError as e:
            return pl, f"not refined: {e.problem}"
        except Exception as e:  # noqa: BLE001 - the unrefined template is still worth showing
            return pl, f"not refined: {type(e).__name__}"

    def choose(self, i, body) -> dict:
        """Record the choice for shape ``i``: ``{"mesh_id": ID}`` or ``{"none": true}``."""
        item = self.item(i)
        if not isinstance(body, dict):
            raise BadRequest('expected {"mesh_id": "k3-..."} or {"none": true}')
        shown = item.candidates
        if shown is None:
            raise BadRequest("no candidates were shown for this shape yet", 409)
        ids = [c["mesh_id"] for c in shown["candidates"]]
        if body.get("none") is True:
            rec = self.store.add_none(item.spec, ids)
        else:
            mid = body.get("mesh_id")
            if not isinstance(mid, str):
                raise BadRequest('"mesh_id" must be a catalogue id string')
            match = next((c for c in shown["candidates"] if c["mesh_id"] == mid), None)
            if match is None:
                raise BadRequest(f"mesh {mid[:40]!r} is not one of the candidates shown for this shape ({', '.join(ids)})")
            rec = self.store.add_label(item.spec, mid, match["rotation"], match["reflected"])
        state = self.state()
        return {"ok": True, "record": rec, "labelled": state["labelled"], "total": state["total"]}

    def tune(self) -> dict:
        """Tune on the labels file, write :attr:`out`; the summary plus ``toml`` (the text)."""
        if not self._tuning.acquire(blocking=False):
            raise BadRequest("a tuning run is already going on", 409)
        try:
            with self._compute:
                summary = tune_labels(self.labels, self.out, lattice=self.lattice_name, catalogue=self.catalogue,
                                      epochs=self.epochs)
        finally:
            self._tuning.release()
        summary["toml"] = self.out.read_text(encoding="utf-8")
        return summary


# ---------------------------------------------------------------------------------------------
# the Starlette app


def _error(message: str, status: int) -> JSONResponse:
    return JSONResponse({"error": " ".join(str(message).split())}, status_code=status)


async def _body(request: Request, limit: int = MAX_BODY) -> bytes:
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limit:
        raise BadRequest(f"request body larger than {limit} bytes", 413)
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise BadRequest(f"request body larger than {limit} bytes", 413)
        chunks.append(chunk)
    return b"".join(chunks)


async def _json(request: Request):
    data = await _body(request)
    try:
        return json.loads(data.decode("utf-8"), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    except (UnicodeDecodeError, ValueError, RecursionError):
        raise BadRequest("the request body is not valid JSON") from None


def create_app(session: LabelSession) -> Starlette:
    """The web app for ``session``: the page at ``/``, its files at ``/static``, the API."""
    from starlette.concurrency import run_in_threadpool

    def guarded(fn):
        async def endpoint(request: Request):
            try:
                return await fn(request)
            except BadRequest as e:
                return _error(str(e), e.status)
            except InputError as e:
                return _error(str(e), 400)
            except UnmatchableError as e:
                return _error(f"no catalogue mesh can be matched to this shape: {e}", 422)
            except HTTPException:
                raise
            except Exception as e:  # never a traceback to the page
                if os.environ.get("JAXMATCH_DEBUG"):
                    raise
                return _error(f"internal error: {type(e).__name__}: {e}", 500)
        return endpoint

    async def index(request: Request):
        return FileResponse(STATIC_DIR / "index.html", headers={"Cache-Control": "no-store"})

    async def state(request: Request):
        return JSONResponse(await run_in_threadpool(session.state))

    async def shape(request: Request):
        return JSONResponse(await run_in_threadpool(session.candidates, request.path_params["sid"]))

    async def choose(request: Request):
        body = await _json(request)
        return JSONResponse(await run_in_threadpool(session.choose, request.path_params["sid"], body))

    async def drawn(request: Request):
        body = await _json(request)
        return JSONResponse({"id": await run_in_threadpool(session.add_drawn, body)})

    async def upload(request: Request):
        data = await _body(request)
        if not data:
            raise BadRequest("the dropped file is empty")
        name = request.query_params.get("name", "dropped shape")
        return JSONResponse({"id": await run_in_threadpool(session.add_upload, data, name)})

    async def tune(request: Request):
        return JSONResponse(await run_in_threadpool(session.tune))

    async def not_found(request: Request, exc: HTTPException):
        return _error(exc.detail or "not found", exc.status_code)

    routes = [
        Route("/", guarded(index)),
        Route("/api/state", guarded(state)),
        Route("/api/shapes/{sid:int}", guarded(shape)),
        Route("/api/shapes/{sid:int}/choose", guarded(choose), methods=["POST"]),
        Route("/api/shapes", guarded(drawn), methods=["POST"]),
        Route("/api/upload", guarded(upload), methods=["POST"]),
        Route("/api/tune", guarded(tune), methods=["POST"]),
        Mount("/static", StaticFiles(directory=STATIC_DIR), name="static"),
    ]
    app = Starlette(routes=routes, exception_handlers={HTTPException: not_found})
    app.state.session = session
    return app


def serve(session: LabelSession, host: str = "127.0.0.1", port: int = 0, *, announce=print) -> None:
    """Serve the app until Ctrl-C. ``port`` 0 picks a free port; the address
    ``http://HOST:PORT/`` is announced (printed, flushed) once the socket listens."""
    import socket

    import uvicorn

    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
    except OSError as err:
        sock.close()
        raise InputError(f"cannot listen on {host}:{port}: {err.strerror or err}", where="--host/--port") from None
    sock.listen(128)
    real = sock.getsockname()[1]
    shown = f"[{host}]" if ":" in host else host
    config = uvicorn.Config(create_app(session), log_level="warning", access_log=False, lifespan="off")
    server = uvicorn.Server(config)
    announce(f"http://{shown}:{real}/")
    try:
        server.run(sockets=[sock])
    finally:
        sock.close()
