"""STEP, IGES and BREP files: one planar face read through gmsh's OpenCASCADE kernel (the `gmsh`
Python package, the optional extra ``jaxmatch[cad]``), as an :class:`~jaxmatch.io.outline.Outline`.

The face's edges are sampled on their true curves (gmsh evaluates them: points on the curve,
chords within :data:`~jaxmatch.io.outline.CURVE_TOLERANCE` of the face's size and turning at most
:data:`~jaxmatch.io.outline.MAX_CURVE_TURN` degrees, lines by their ends), chained into loops and
nested into the outer loop and its holes like a DXF drawing's pieces
(:func:`~jaxmatch.io.outline.chain`, :func:`~jaxmatch.io.outline.regions`); corners are where the
edges meet at an angle. Coordinates are the face's plane's: ``x, y`` for a face in a plane
``z = const``, else an orthonormal frame of its plane.

A file of several faces (an assembly, or a part's faces) needs ``FILE#N``, the face's number in
gmsh (the error lists them); a 3D solid or a face that is not planar is refused in one line.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.files import atomic_open
from jaxmatch.io.outline import CHAIN_TOLERANCE, CURVE_TOLERANCE, MAX_CURVE_TURN, Outline, Piece, chain, regions
from jaxmatch.io.outline import short as _short
from jaxmatch.lazy import Later

__all__ = ["KINDS", "read_cad"]

later = Later(gmsh="gmsh")  # the optional extra jaxmatch[cad]: only for these files

KINDS = {"step": ("STEP", ".step"), "iges": ("IGES", ".iges"), "brep": ("BREP", ".brep")}
"""Format name -> (how messages call it, the suffix gmsh reads it by)."""


def read_cad(data, source: str, element: str | None, kind: str) -> Outline:
    """The planar face of a STEP / IGES / BREP file (``kind``: a key of :data:`KINDS`) as an
    outline; ``element`` the face's number when the file has several. :class:`InputError`
    naming the file for anything else (gmsh missing, an unreadable file, a solid, a curved
    face, several faces and no choice)."""
    name, suffix = KINDS[kind]
    try:
        gmsh = later.gmsh
    except ImportError:
        raise InputError(f"reading {name} files needs gmsh: pip install 'jaxmatch[cad]'", where=source) from None
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    with tempfile.TemporaryDirectory() as tmp, _session(gmsh):
        path = os.path.join(tmp, "part" + suffix)
        with atomic_open(path, "wb") as f:  # (a name gmsh's reader can open)
            f.write(raw)
        try:
            with _quiet():
                gmsh.model.occ.importShapes(path)
                gmsh.model.occ.synchronize()
        except Exception as err:  # gmsh raises Exception with its last error
            raise InputError(f"not a readable {name} file ({_short(str(err), 80)})", where=source) from None
        face = _face(gmsh, source, element)
        return _outline(gmsh, face, source)


@contextlib.contextmanager
def _session(gmsh):
    """A gmsh model of its own, silent; gmsh initialised (and finalised after) only when the
    caller had not, else its model and terminal option given back."""
    own = not gmsh.isInitialized()
    if own:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    previous = None if own else gmsh.model.getCurrent()
    terminal = gmsh.option.getNumber("General.Terminal")
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add(f"jaxmatch-read-{os.getpid()}")
    try:
        yield
    finally:
        gmsh.model.remove()
        if own:
            gmsh.finalize()
        else:
            gmsh.option.setNumber("General.Terminal", terminal)
            gmsh.model.setCurrent(previous)


@contextlib.contextmanager
def _quiet():
    """Standard output closed at the descriptor (OpenCASCADE's readers print their statistics
    there, past gmsh's terminal option), so that a command's own output stays clean."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, 1)
            try:
                yield
            finally:
                os.dup2(saved, 1)
        finally:
            os.close(null)
    finally:
        os.close(saved)


def _face(gmsh, source: str, element: str | None) -> int:
    """The face to read: the only one, or the one ``element`` names."""
    volumes = gmsh.model.getEntities(3)
    if volumes:
        raise InputError(f"a 3D solid ({len(volumes)} volume{'s' if len(volumes) > 1 else ''}): jaxmatch meshes a planar "
                         "face; export the face (a surface) or a 2D drawing of it", where=source)
    faces = [t for _, t in gmsh.model.getEntities(2)]
    if not faces:
        curves = len(gmsh.model.getEntities(1))
        raise InputError(f"no face in the file ({curves} curves): jaxmatch meshes a planar face", where=source)
    if element is not None:
        if element not in [str(f) for f in faces]:
            raise InputError(f"no face {element!r} (faces: {', '.join(map(str, faces[:20]))})", where=source)
        return int(element)
    if len(faces) > 1:
        raise InputError(f"{len(faces)} faces (an assembly, or a part of several faces); jaxmatch meshes one region: "
                         f"choose a face with FILE#N (faces: {', '.join(map(str, faces[:20]))})", where=source)
    return faces[0]


def _outline(gmsh, face: int, source: str) -> Outline:
    """The face's loops in its plane's coordinates."""
    box = np.array(gmsh.model.getBoundingBox(2, face), np.float64)
    size = float(np.max(box[3:] - box[:3]))
    if not (math.isfinite(size) and size > 0):
        raise InputError(f"face {face} has zero or non-finite size", where=source)
    curves = [abs(t) for _, t in gmsh.model.getBoundary([(2, face)], combined=False, oriented=False)]
    samples = [(c, _sample(gmsh, c, CURVE_TOLERANCE * size)) for c in curves]
    frame = _plane(gmsh, face, np.vstack([p for _, p in samples]), size, source)
    pieces = [Piece(p @ frame.T, f"curve {c} ({gmsh.model.getType(1, c)}) of face {face}") for c, p in samples]
    found = regions(chain(pieces, CHAIN_TOLERANCE * size, source), pieces, source)
    if len(found) != 1:
        raise InputError(f"face {face}'s edges make {len(found)} separate regions", where=source)
    outer, holes = found[0]
    return Outline(outer.points, None, tuple(h.points for h in holes))


def _plane(gmsh, face: int, boundary: np.ndarray, size: float, source: str) -> np.ndarray:
    """``(2, 3)`` an orthonormal frame of the face's plane (the x and y axes for a plane
    ``z = const``); :class:`InputError` when the face is not planar."""
    kind = gmsh.model.getType(2, face)
    lo, hi = (np.asarray(b, np.float64) for b in gmsh.model.getParametrizationBounds(2, face))
    u, v = np.meshgrid(np.linspace(lo[0], hi[0], 7), np.linspace(lo[1], hi[1], 7))
    inner = np.asarray(gmsh.model.getValue(2, face, np.c_[u.ravel(), v.ravel()].ravel()), np.float64).reshape(-1, 3)
    pts = np.vstack([boundary, inner[np.isfinite(inner).all(axis=1)]])
    centre = pts.mean(axis=0)
    normal = np.linalg.svd(pts - centre, full_matrices=False)[2][2]
    off = float(np.max(np.abs((pts - centre) @ normal)))
    if off > CHAIN_TOLERANCE * size * 10:
        raise InputError(f"face {face} is not planar (a {kind}; its points leave their best plane by {off:.3g}): jaxmatch "
                         "meshes planar faces", where=source)
    if abs(abs(normal[2]) - 1.0) <= 1e-9:
        return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    axis = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = axis - (axis @ normal) * normal
    e1 /= np.linalg.norm(e1)
    return np.array([e1, np.cross(normal, e1)])


def _sample(gmsh, curve: int, tol: float) -> np.ndarray:
    """``(k, 3)`` points on ``curve`` from its start to its end, on the curve (gmsh's ``getValue``):
    a line's two ends; a curve's points at equal arc-length steps, so many that each chord strays
    at most ``tol`` from the curve (its largest curvature ``kappa``: chord ``<= sqrt(8 tol / kappa)``)
    and turns at most :data:`MAX_CURVE_TURN` degrees from the next."""
    lo, hi = (float(np.asarray(b).ravel()[0]) for b in gmsh.model.getParametrizationBounds(1, curve))
    if gmsh.model.getType(1, curve) == "Line":
        return np.asarray(gmsh.model.getValue(1, curve, [lo, hi]), np.float64).reshape(-1, 3)
    fine = np.linspace(lo, hi, 1025)
    xyz = np.asarray(gmsh.model.getValue(1, curve, fine), np.float64).reshape(-1, 3)
    step = np.diff(xyz, axis=0)
    length = np.linalg.norm(step, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(length)])
    d = step[length > 0] / length[length > 0, None]
    turn = float(np.sum(np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1), -1.0, 1.0))))
    kappa = float(np.max(np.abs(np.asarray(gmsh.model.getCurvature(1, curve, fine), np.float64)), initial=0.0))
    n = max(1, math.ceil(math.degrees(turn) / MAX_CURVE_TURN))
    if kappa > 0 and math.isfinite(kappa):
        n = max(n, math.ceil(cum[-1] / math.sqrt(8.0 * tol / kappa)))
    u = np.interp(np.linspace(0.0, cum[-1], n + 1), cum, fine)
    u[0], u[-1] = lo, hi
    return np.asarray(gmsh.model.getValue(1, curve, u), np.float64).reshape(-1, 3)
