"""Shape file readers: every format a user may already have, into one :class:`~jaxmatch.shape.Shape`.

Formats (detected by the file's suffix, else by its content; see :func:`detect_format`):

* ``json``: ``{"boundary": [[x, y], ...], "corners": [i, ...], "holes": [[[x, y], ...], ...],
  "hole_corners": [[i, ...] or null, ...], "tags": {"name": ["i-j", "hole h", ...]},
  "periodic": [["i-j", "k-l"], ...]}`` (all but ``boundary`` optional; sides named as the output's
  ``side i-j`` groups, :func:`jaxmatch.shape.check_groups`).
  Other keys (``"name"``, ``"units"``, ...) are ignored with one :class:`InputWarning` naming
  them.
* ``geojson`` (``.geojson``, or JSON with a ``"type"`` key): a ``Polygon``, a ``Feature`` of
  one, a ``MultiPolygon`` / ``FeatureCollection`` holding exactly one polygon (or the one
  chosen by ``element``: a feature's ``id`` or ``properties.name``). The outer ring is the
  boundary, interior rings are holes; a Feature's ``properties.tags`` / ``properties.periodic``
  as the JSON keys.
* ``text`` (``.txt .csv .tsv .xy .xyz .dat`` only): one point per row, ``x y``, ``x,y``, ``x;y`` or
  tab-separated; ``#`` starts a comment; blank lines are skipped. An optional first row of
  column names (a header) is allowed: the columns named ``x`` and ``y`` are read (any other
  columns are ignored), or the two columns when there are only two. (A plain loop, not
  ``numpy.loadtxt``: 32 ms against 11 ms for the largest accepted file, 10,000 rows, and it
  names the bad line, finds the columns by name and takes any of the separators.)
* ``svg``: one closed shape element (``<path>``, ``<polygon>``, ``<rect>``, ``<circle>``,
  ``<ellipse>``, ...) parsed with `svgelements` (transforms applied, in the units of the
  ``viewBox``). Straight segments keep
  their end points; curves are sampled evenly by arc length (:data:`SVG_SAMPLES` points over
  the loop's perimeter, at least :data:`MIN_CURVE_SAMPLES` per curve). With several shape
  elements, ``element`` names the one to read by its ``id``. Coordinates are the SVG's user
  units (y down, as drawn; jaxmatch tries mirror images anyway).
* ``dxf``: closed polylines, or a drawing of lines, arcs, circles, ellipses, splines and
  polylines (blocks inserted), chained into loops and nested into a region with holes
  (:mod:`jaxmatch.io.dxf`); ``element`` names a layer or an entity's handle.
* ``step``, ``iges``, ``brep`` (``.step .stp .iges .igs .brep``): one planar face through
  gmsh's OpenCASCADE reader (:mod:`jaxmatch.io.cad`, the optional extra ``jaxmatch[cad]``);
  ``element`` names the face's number when there are several.

In every format the loop may be closed (last point = first): the repeated point is dropped.
Then (:func:`jaxmatch.io.outline.tidy`) repeated consecutive points are merged and outlines over
:data:`~jaxmatch.shape.MAX_POINTS` points simplified, each said in one warning.
Corners come from the ``corners`` key of the jaxmatch JSON format only; in the other formats
they are detected from angles (``corner_angle``).

``element`` can also be given in the path: ``drawing.svg#outline`` (see :func:`split_element`).
Every problem raises :class:`~jaxmatch.errors.InputError` naming the file.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import warnings
from pathlib import Path

import numpy as np

from jaxmatch.errors import InputError, InputWarning
from jaxmatch.files import read_limited
from jaxmatch.io import registry
from jaxmatch.io.outline import MAX_READ_POINTS, MIN_CURVE_SAMPLES, SVG_SAMPLES, Outline, tidy
from jaxmatch.io.outline import as_text as _text
from jaxmatch.io.outline import nested as _nested
from jaxmatch.io.outline import short as _short
from jaxmatch.lazy import Later
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, MAX_BYTES, Shape, check_corner_angle, make_shape

later = Later(dxf="jaxmatch.io.dxf",  # ezdxf: only for DXF files
              cad="jaxmatch.io.cad")  # gmsh (the optional extra jaxmatch[cad]): only for STEP, IGES and BREP files

__all__ = [
    "FORMATS",
    "MIN_CURVE_SAMPLES",
    "SUFFIXES",
    "SVG_SAMPLES",
    "detect_format",
    "load_shape",
    "parse_shape",
    "read_outline",
    "split_element",
]

def _formats():
    """Register the shape formats (:mod:`jaxmatch.io.registry`); return their names and suffixes."""
    for name, sfx, reader in (("json", (".json",), lambda d, src, el: _read_json_or_geojson(d, src, el, False)),
                              ("geojson", (".geojson",), lambda d, src, el: _read_json_or_geojson(d, src, el, True)),
                              ("text", TEXT_SUFFIXES, lambda d, src, el: Outline(_read_text(_text(d, src), src))),
                              ("svg", (".svg",), lambda d, src, el: _read_svg(d, src, el)),
                              ("dxf", (".dxf",), lambda d, src, el: later.dxf.read_dxf(d, src, el)),
                              ("step", (".step", ".stp"), lambda d, src, el: later.cad.read_cad(d, src, el, "step")),
                              ("iges", (".iges", ".igs"), lambda d, src, el: later.cad.read_cad(d, src, el, "iges")),
                              ("brep", (".brep",), lambda d, src, el: later.cad.read_cad(d, src, el, "brep"))):
        registry.register_format(name, "shape", sfx, reader=reader)
    return tuple(f.name for f in registry.formats("shape")), registry.suffixes("shape")


FORMATS: tuple[str, ...]
"""Shape file formats, as accepted by ``fmt`` (registered in :mod:`jaxmatch.io.registry`)."""

SUFFIXES: dict[str, str]
"""File suffix (lower case) -> format."""

TEXT_SUFFIXES = (".txt", ".csv", ".tsv", ".xy", ".xyz", ".dat")
"""The suffixes of point rows (a file of another suffix is never read as rows)."""

JSON_KEYS = ("boundary", "corners", "holes", "hole_corners", "tags", "periodic")
"""Keys of the jaxmatch JSON shape format."""

def split_element(path) -> tuple[str, str | None]:
    """``"a.svg#outline"`` -> ``("a.svg", "outline")`` when no file of the full name exists and
    the part after the last ``#`` names no folder; otherwise ``(path, None)``."""
    text = os.fspath(path)
    if "#" not in text or os.path.exists(text):
        return text, None
    file, _, element = text.rpartition("#")
    if not element or "/" in element or os.sep in element:
        return text, None
    return file, element


def load_shape(path, *, corner_angle: float = DEFAULT_CORNER_ANGLE, element: str | None = None, fmt: str | None = None) -> Shape:
    """Read a shape file of any supported format (see the module docstring).

    path: the file; ``file#element`` chooses an element (SVG id, DXF handle or layer, GeoJSON
    feature id or name) when ``element`` is not given. Errors name the path as given.
    """
    check_corner_angle(corner_angle)
    file, part = split_element(path)
    if element is None:
        element = part
    data = read_limited(file, MAX_BYTES, "shape file")
    return parse_shape(data, os.fspath(path), corner_angle=corner_angle, fmt=fmt, element=element, _file=file)


def parse_shape(data, source: str = "<input>", *, corner_angle: float = DEFAULT_CORNER_ANGLE, fmt: str | None = None,
                element: str | None = None, _file: str | None = None) -> Shape:
    """Parse shape bytes (or text) into a :class:`~jaxmatch.shape.Shape`.

    fmt: one of :data:`FORMATS`, or None to detect it (:func:`detect_format` on ``source``).
    element: which element of an SVG / DXF / GeoJSON file (see the module docstring).
    Raises :class:`~jaxmatch.errors.InputError` with ``source`` for any problem.
    """
    check_corner_angle(corner_angle)
    region = tidy(read_outline(data, source, fmt=fmt, element=element, _file=_file), source)
    return make_shape(region.points, region.corners, corner_angle=corner_angle, source=source, holes=region.holes,
                      hole_corners=region.hole_corners, tags=region.tags, periodic=region.periodic)


def detect_format(source: str, data: bytes | str) -> str:
    """Format of a shape file: by suffix (:data:`SUFFIXES`), else by content: ``svg`` when it
    starts with ``<`` (after a byte-order mark and blanks), ``dxf`` when its first line is a
    group code ``0`` and the second ``SECTION``, ``step`` when it starts with ``ISO-10303-21``,
    ``json``/``geojson`` when it starts with ``{`` or ``[`` (``geojson`` if the object has a
    ``"type"`` key), else ``text`` for a name without a suffix. Raises :class:`InputError`
    (``unsupported format '.sldprt'; supported: ...``) for a file of another suffix that is none
    of these (point rows are read from :data:`TEXT_SUFFIXES` only) and for binary content
    without a suffix."""
    suffix = Path(split_element(source)[0]).suffix.lower()
    if suffix in SUFFIXES:
        return SUFFIXES[suffix]
    head = data[:4096]
    binary = False
    if isinstance(head, bytes):
        binary = b"\0" in head
        try:
            head = head.decode("utf-8")
        except UnicodeDecodeError as err:
            binary = binary or err.start < len(head) - 4  # (not a character cut at the end of the head)
            head = head.decode("utf-8", errors="replace")
    head = head.lstrip("\ufeff \t\r\n")
    lines = head.splitlines()
    if binary:
        fmt = None
    elif head.startswith("<"):
        fmt = "svg"
    elif len(lines) >= 2 and lines[0].strip() == "0" and lines[1].strip().upper() == "SECTION":
        fmt = "dxf"
    elif head.startswith("ISO-10303-21"):
        fmt = "step"
    elif head[:1] in ("{", "["):
        fmt = "geojson" if re.search(r'"type"\s*:', head) and not re.search(r'"boundary"\s*:', head) else "json"
    else:
        fmt = None if suffix else "text"
    if fmt is None:
        what = f"format {suffix!r}" if suffix else "format (a binary file without a suffix)"
        raise InputError(f"unsupported {what}; supported: {', '.join(SUFFIXES)}", where=split_element(source)[0])
    return fmt


def read_outline(data, source: str, *, fmt: str | None = None, element: str | None = None,
                 _file: str | None = None) -> Outline:
    """The region of a shape file as an :class:`Outline`. No validation beyond the format's own."""
    if not isinstance(data, str) and len(data) > MAX_BYTES:
        raise InputError(f"file is larger than {MAX_BYTES} bytes", where=source)
    fmt = detect_format(_file or source, data) if fmt is None else fmt
    if fmt not in FORMATS:
        raise InputError(f"unknown shape format {fmt!r} (known: {', '.join(FORMATS)})", where=source)
    if element is not None and fmt in ("json", "text"):
        raise InputError(f"a {fmt} shape file has one loop; there is no element {element!r} to choose", where=source)
    return registry.find("shape", name=fmt).reader(data, source, element)


def _read_json_or_geojson(data, source: str, element: str | None, geojson: bool) -> Outline:
    doc = _load_json(_text(data, source), source)
    if geojson or (isinstance(doc, dict) and "type" in doc and "boundary" not in doc):
        return _read_geojson(doc, source, element)
    return _read_json(doc, source)


# ---------------------------------------------------------------------------------------------
# helpers


def _number_pairs(rows, source: str, what: str) -> list[list[float]]:
    """``rows`` (a JSON list) as ``[[x, y], ...]`` floats; third coordinates are ignored when
    ``what`` allows them (GeoJSON positions)."""
    if not isinstance(rows, list):
        raise InputError(f"{what} must be a list of [x, y] pairs", where=source)
    if len(rows) > MAX_READ_POINTS + 1:
        raise InputError(f"{what} has {len(rows)} points, more than the {MAX_READ_POINTS} read", where=source)
    extra_ok = what != "boundary"
    points = []
    for i, row in enumerate(rows):
        if not isinstance(row, list) or not (len(row) == 2 or (extra_ok and len(row) in (3, 4))):
            raise InputError(f"{what}[{i}] must be a pair [x, y], got {_short(row)}", where=source)
        xy = []
        for value in row[:2]:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"{what}[{i}] has a non-number {_short(value)}", where=source)
            try:
                f = float(value)
            except OverflowError:
                f = math.inf
            if not math.isfinite(f):
                raise InputError(f"{what}[{i}] has a number that is not finite", where=source)
            xy.append(f)
        points.append(xy)
    return points


# ---------------------------------------------------------------------------------------------
# JSON and GeoJSON


class _Dup(Exception):
    pass


class _Const(Exception):
    pass


def _no_duplicate_keys(pairs):
    out = {}
    for k, v in pairs:
        if k in out:
            raise _Dup(k)
        out[k] = v
    return out


def _reject_constant(name):
    raise _Const(name)


def _load_json(text: str, source: str):
    try:
        return json.loads(text, object_pairs_hook=_no_duplicate_keys, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise InputError(f"not valid JSON: {err.msg} (column {err.colno})", where=f"{source}:{err.lineno}") from None
    except _Dup as err:
        raise InputError(f"duplicate key {_short(str(err.args[0]))}", where=source) from None
    except _Const as err:
        raise InputError(f"{err.args[0]} is not a finite number", where=source) from None
    except (ValueError, RecursionError) as err:  # huge integers, absurd nesting
        raise InputError(f"not valid JSON ({type(err).__name__}: {_short(str(err), 60)})", where=source) from None


def _read_json(doc, source: str):
    if not isinstance(doc, dict):
        raise InputError('top level must be a JSON object {"boundary": [[x, y], ...]} (or GeoJSON)', where=source)
    unknown = [k for k in doc if k not in JSON_KEYS]
    names = ", ".join(_short(k) for k in unknown[:5]) + (f" and {len(unknown) - 5} more" if len(unknown) > 5 else "")
    if "boundary" not in doc:
        found = f" (found: {names})" if unknown else ""
        raise InputError(f'missing key "boundary"{found}', where=source)
    points = _number_pairs(doc["boundary"], source, "boundary")
    corners = doc.get("corners")
    if "corners" in doc and not isinstance(corners, list):
        raise InputError('"corners" must be a list of integer point indices', where=source)
    holes = doc.get("holes", [])
    if not isinstance(holes, list):
        raise InputError('"holes" must be a list of loops [[[x, y], ...], ...]', where=source)
    holes = [_number_pairs(h, source, f"holes[{k}]") for k, h in enumerate(holes)]
    hole_corners = doc.get("hole_corners")
    if hole_corners is not None and (not isinstance(hole_corners, list) or len(hole_corners) != len(holes)
                                     or not all(c is None or isinstance(c, list) for c in hole_corners)):
        raise InputError('"hole_corners" must be a list with one list of point indices (or null) per hole', where=source)
    if unknown:  # warned once the file is known to be good (a bad file gets its one error line only)
        warnings.warn(InputWarning(f"ignored key{'s' if len(unknown) > 1 else ''} {names} (known keys: {', '.join(JSON_KEYS)})",
                                   where=source), stacklevel=2)
    return Outline(points, corners, tuple(holes), hole_corners, doc.get("tags"), doc.get("periodic"))


def _read_geojson(doc, source: str, element: str | None):
    """Outer ring of the one polygon of a GeoJSON document."""
    if not isinstance(doc, dict):
        raise InputError("GeoJSON top level must be an object with a \"type\"", where=source)
    kind = doc.get("type")
    if kind == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list):
            raise InputError('GeoJSON FeatureCollection needs a "features" list', where=source)
        if element is not None:
            chosen = [f for f in feats if isinstance(f, dict) and element in _feature_names(f)]
            if not chosen:
                names = sorted({n for f in feats if isinstance(f, dict) for n in _feature_names(f)})
                raise InputError(f"no feature with id or name {element!r} (there are: {', '.join(names) or 'none named'})", where=source)
            return _read_geojson(chosen[0], source, None)
        polys = [f for f in feats if isinstance(f, dict) and isinstance(f.get("geometry"), dict)
                 and f["geometry"].get("type") in ("Polygon", "MultiPolygon")]
        if len(polys) != 1:
            raise InputError(f"GeoJSON FeatureCollection has {len(polys)} polygon features; jaxmatch reads one "
                             "(choose one with FILE#ID, the feature's id or properties.name)", where=source)
        return _read_geojson(polys[0], source, None)
    if kind == "Feature":
        geom = doc.get("geometry")
        if not isinstance(geom, dict):
            raise InputError('GeoJSON Feature has no "geometry" object', where=source)
        props = doc.get("properties") if isinstance(doc.get("properties"), dict) else {}
        return _read_geojson(geom, source, None)._replace(tags=props.get("tags"), periodic=props.get("periodic"))
    if kind == "MultiPolygon":
        polys = doc.get("coordinates")
        if not isinstance(polys, list) or len(polys) != 1:
            count = len(polys) if isinstance(polys, list) else 0
            raise InputError(f"GeoJSON MultiPolygon has {count} polygons; jaxmatch reads one", where=source)
        return _rings(polys[0], source)
    if kind == "Polygon":
        return _rings(doc.get("coordinates"), source)
    raise InputError(f"GeoJSON type {_short(kind)} is not a polygon (supported: Polygon, MultiPolygon of one, "
                     "Feature, FeatureCollection of one polygon)", where=source)


def _feature_names(feature: dict) -> set[str]:
    props = feature.get("properties") if isinstance(feature.get("properties"), dict) else {}
    return {str(v) for v in (feature.get("id"), props.get("name"), props.get("id")) if v is not None}


def _rings(rings, source: str):
    if not isinstance(rings, list) or not rings:
        raise InputError('GeoJSON Polygon needs "coordinates": a list of rings', where=source)
    holes = tuple(_number_pairs(r, source, f"interior ring {k + 1}") for k, r in enumerate(rings[1:]))
    return Outline(_number_pairs(rings[0], source, "outer ring"), None, holes)


# ---------------------------------------------------------------------------------------------
# text / CSV / TSV

_SEPARATORS = ("\t", ",", ";")


def _split_row(body: str) -> list[str]:
    for sep in _SEPARATORS:
        if sep in body:
            return [tok.strip().strip('"').strip("'").strip() for tok in body.split(sep)]
    return body.split()


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _read_text(text: str, source: str) -> list[list[float]]:
    points = []
    columns: tuple[int, int] | None = None  # (x column, y column) from a header
    width = 2
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        tokens = _split_row(body)
        if not points and columns is None and not all(_is_number(t) for t in tokens):  # the header
            names = [t.lower() for t in tokens]
            if "x" in names and "y" in names:
                columns = (names.index("x"), names.index("y"))
            elif len(tokens) == 2:
                columns = (0, 1)
            else:
                raise InputError(f"header {_short(body)} names no columns 'x' and 'y' (and has {len(tokens)} columns, not 2)",
                                 where=f"{source}:{lineno}")
            width = len(tokens)
            continue
        if len(points) >= MAX_READ_POINTS + 1:
            raise InputError(f"more than the {MAX_READ_POINTS} points read", where=f"{source}:{lineno}")
        if len(tokens) != width:
            expect = f"{width} columns as in the header" if columns is not None else "two numbers 'x y' or 'x,y'"
            raise InputError(f"expected {expect}, got {_short(body)}", where=f"{source}:{lineno}")
        xy = []
        for tok in (tokens[columns[0]], tokens[columns[1]]) if columns is not None else tokens:
            try:
                f = float(tok)
            except ValueError:
                raise InputError(f"not a number: {_short(tok)}", where=f"{source}:{lineno}") from None
            if not math.isfinite(f):
                raise InputError(f"{_short(tok)} is not a finite number", where=f"{source}:{lineno}")
            xy.append(f)
        points.append(xy)
    if not points:
        raise InputError("no points (expected rows 'x y' or 'x,y')", where=source)
    return points


# ---------------------------------------------------------------------------------------------
# SVG


def _read_svg(data, source: str, element: str | None) -> Outline:
    import svgelements as se

    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            doc = se.SVG.parse(io.BytesIO(raw), reify=True)
        shapes = [e for e in doc.elements() if isinstance(e, se.Shape)]
    except Exception as err:  # svgelements raises ParseError, ValueError, IndexError ... on broken files
        raise InputError(f"not a readable SVG file ({type(err).__name__}: {_short(str(err), 60)})", where=source) from None
    if element is not None:
        chosen = [e for e in shapes if e.id == element]
        if not chosen:
            ids = [str(e.id) for e in shapes if e.id is not None]
            raise InputError(f"no shape element with id {element!r} (ids: {', '.join(ids[:10]) or 'none'})", where=source)
        shapes = chosen[:1]
    shapes = [e for e in shapes if len(list(se.Path(e).segments())) > 1]
    if not shapes:
        raise InputError("no path or shape element in the SVG", where=source)
    def loops_of(shape) -> list[np.ndarray]:
        path = se.Path(shape)
        if doc.viewbox_transform:  # back from the viewport (px) to the drawing's own units (the viewBox)
            path = path * ~se.Matrix(doc.viewbox_transform)
            path.reify()
        return _svg_loops(path, source)

    if len(shapes) > 1:  # several shapes: one region only when one of them holds all the others
        try:
            return _nested([lp for e in shapes for lp in loops_of(e)], "evenodd", source, strict=True)
        except InputError:
            ids = [str(e.id) for e in shapes if e.id is not None]
            listing = f"; ids: {', '.join(ids[:10])}" if ids else " (none has an id)"
            raise InputError(f"the SVG has {len(shapes)} shape elements that are not one region with holes; choose one "
                             f"with FILE#ID{listing}", where=source) from None
    values = getattr(shapes[0], "values", None) or {}
    rule = str(values.get("fill-rule", "nonzero")).strip().lower()
    return _nested(loops_of(shapes[0]), rule, source)


def _svg_loops(path, source: str) -> list[np.ndarray]:
    """The closed loops of an SVG path, one per subpath (``M`` command)."""
    import svgelements as se

    groups: list[list] = []
    for seg in path.segments():
        if isinstance(seg, se.Move):
            groups.append([])
        elif seg.start is not None:
            if not groups:
                groups.append([])
            groups[-1].append(seg)
    loops = [_svg_loop(g, source) for g in groups if g]
    if not loops:
        raise InputError("the SVG path draws nothing", where=source)
    return loops


def _svg_loop(drawn: list, source: str) -> np.ndarray:
    """Vertices of one closed SVG subpath (its drawn segments): line end points, curves sampled
    by arc length."""
    import svgelements as se

    lengths = np.array([float(s.length()) for s in drawn])
    total = float(lengths.sum())
    if not (math.isfinite(total) and total > 0):
        raise InputError("the SVG path has zero or non-finite length", where=source)
    spacing = total / SVG_SAMPLES
    pts = [np.array([drawn[0].start.x, drawn[0].start.y], dtype=np.float64)]
    for s, length in zip(drawn, lengths):
        end = np.array([s.end.x, s.end.y], dtype=np.float64)
        if isinstance(s, (se.Line, se.Close)):
            pts.append(end)
            continue
        k = max(MIN_CURVE_SAMPLES, math.ceil(length / spacing))
        pts.extend(_by_arc_length(s, k)[1:])
    loop = np.array(pts)
    if np.allclose(loop[0], loop[-1], rtol=0, atol=1e-12 * max(1.0, float(np.abs(loop).max()))):
        loop = loop[:-1]  # closed (Z, or ends where it starts)
    else:
        raise InputError("the SVG path is open (it does not end where it starts; close it with Z)", where=source)
    keep = np.ones(len(loop), bool)
    keep[1:] = np.any(loop[1:] != loop[:-1], axis=1)  # zero-length segments (e.g. a Z after the last point)
    return loop[keep]


def _by_arc_length(segment, k: int) -> np.ndarray:
    """``k + 1`` points along ``segment`` at equal arc-length steps (ends included)."""
    fine = np.linspace(0.0, 1.0, 64 * k + 1)
    xy = np.asarray(segment.npoint(fine), dtype=np.float64)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    target = np.linspace(0.0, cum[-1], k + 1)
    u = np.interp(target, cum, fine)
    out = np.asarray(segment.npoint(u), dtype=np.float64)
    out[0], out[-1] = xy[0], xy[-1]
    return out


FORMATS, SUFFIXES = _formats()
