"""Assembly files: several named regions and embedded points and curves, read into a
:class:`~jaxmatch.model.Model`.

==========  ========================================================================================
format      an assembly is
==========  ========================================================================================
JSON        ``{"regions": [{"name": "steel", "boundary": [[x, y], ...], "holes": ..., "corners": ...,
            "embedded": ...}, ...], "embedded": {...}}``, or one region's file with ``"embedded":
            {"points": [[x, y], ...], "curves": [[[x, y], ...], ...]}``
GeoJSON     a FeatureCollection of two or more polygon features (the name: ``properties.name``, else
            the feature's ``id``); ``Point`` and ``LineString`` features are embedded points and curves
SVG         two or more shape elements that are not one region with holes, each named by its
            ``inkscape:label`` or ``id``
DXF         regions on two or more layers (each layer one region, named after the layer)
==========  ========================================================================================

Each region is read by the single-region reader of its format (:mod:`jaxmatch.io.readers`,
:mod:`jaxmatch.io.dxf`), so the same rules hold (corners, holes, curves sampled, points merged).
"""

from __future__ import annotations

import io
import re
import warnings

import numpy as np

from jaxmatch.errors import InputError
from jaxmatch.io.outline import Outline, tidy
from jaxmatch.io.readers import JSON_KEYS, _load_json, _read_geojson, _read_json, _read_svg, _text
from jaxmatch.lazy import Later
from jaxmatch.model import Embedded, Model, Region, join_embedded, make_model, parse_embedded
from jaxmatch.shape import DEFAULT_CORNER_ANGLE, make_shape

__all__ = ["model_from_json", "read_model", "several_regions"]

later = Later(dxf="jaxmatch.io.dxf")  # ezdxf: only for DXF assemblies

_REGION_KEYS = JSON_KEYS + ("name", "embedded")


def _region(outline: Outline, name: str, source: str, corner_angle: float) -> Region:
    where = f"{source}#{name}"
    o = tidy(outline, where)
    return Region(name, make_shape(o.points, o.corners, corner_angle=corner_angle, source=where, holes=o.holes,
                                   hole_corners=o.hole_corners))


def is_model_json(doc) -> bool:
    """A JSON document is an assembly: an object with ``"regions"``, or ``"embedded"``."""
    return isinstance(doc, dict) and ("regions" in doc or "embedded" in doc)


def model_from_json(doc, source: str, corner_angle: float = DEFAULT_CORNER_ANGLE) -> Model:
    """A :class:`Model` from a parsed JSON assembly (see the module docstring)."""
    if not isinstance(doc, dict):
        raise InputError('top level must be a JSON object {"regions": [...]}', where=source)
    parts = [parse_embedded(doc.get("embedded"), source)]
    if "regions" not in doc:  # one region with embedded points or curves
        unknown = [k for k in doc if k not in _REGION_KEYS]
        if unknown:
            raise InputError(f"unknown key {unknown[0]!r} (known: {', '.join(_REGION_KEYS)}, regions)", where=source)
        name = doc.get("name", "region")
        body = {k: v for k, v in doc.items() if k in JSON_KEYS}
        regions = [_region(_read_json(body, source), str(name), source, corner_angle)]
        return make_model(regions, parts[0], source=source)
    unknown = [k for k in doc if k not in ("regions", "embedded")]
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r} beside \"regions\" (known: regions, embedded)", where=source)
    items = doc["regions"]
    if not isinstance(items, list) or not items:
        raise InputError('"regions" must be a non-empty list of {"name": ..., "boundary": ...} objects', where=source)
    regions = []
    for k, item in enumerate(items):
        if not isinstance(item, dict):
            raise InputError(f"regions[{k}] must be an object with \"boundary\"", where=source)
        unknown = [key for key in item if key not in _REGION_KEYS]
        if unknown:
            raise InputError(f"regions[{k}]: unknown key {unknown[0]!r} (known: {', '.join(_REGION_KEYS)})",
                             where=source)
        name = item.get("name", f"region {k + 1}")
        if not isinstance(name, str):
            raise InputError(f"regions[{k}]: \"name\" must be a string, got {name!r:.40}", where=source)
        body = {key: v for key, v in item.items() if key in JSON_KEYS}
        regions.append(_region(_read_json(body, f"{source}#{name}"), name, source, corner_angle))
        parts.append(parse_embedded(item.get("embedded"), f"{source}#{name}"))
    return make_model(regions, join_embedded(parts), source=source)


def _geojson_model(doc, source: str, corner_angle: float) -> Model | None:
    """A FeatureCollection of two or more polygon features as a :class:`Model` (None: not one)."""
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        return None
    feats = [f for f in doc["features"] if isinstance(f, dict) and isinstance(f.get("geometry"), dict)]
    polys = [f for f in feats if f["geometry"].get("type") in ("Polygon", "MultiPolygon")]
    if len(polys) < 2:
        return None
    regions = []
    for k, f in enumerate(polys):
        props = f.get("properties") if isinstance(f.get("properties"), dict) else {}
        name = props.get("name", f.get("id", f"region {k + 1}"))
        regions.append(_region(_read_geojson(f, f"{source}#{name}", None), str(name), source, corner_angle))
    points = [f["geometry"].get("coordinates") for f in feats if f["geometry"].get("type") == "Point"]
    curves = [f["geometry"].get("coordinates") for f in feats if f["geometry"].get("type") == "LineString"]
    embedded = parse_embedded({"points": points, "curves": curves}, source) if points or curves else Embedded(np.zeros((0, 2)))
    return make_model(regions, join_embedded([embedded, parse_embedded(doc.get("embedded"), source)]), source=source)


def _dxf_layers(data, source: str) -> list[str]:
    """The layers of the model space that hold region entities (:data:`~jaxmatch.io.dxf.CURVES`)."""
    import ezdxf

    text = data if isinstance(data, str) else bytes(data).decode("utf-8", errors="replace")
    try:
        doc = ezdxf.read(io.StringIO(text))
    except Exception:  # (the single-region reader has said what is wrong)
        return []
    layers: list[str] = []
    for e in doc.modelspace():
        if (e.dxftype() in later.dxf.CURVES or e.dxftype() == "INSERT") and e.dxf.layer not in layers:
            layers.append(e.dxf.layer)
    return layers


def _svg_names(data) -> list[tuple[str, str]]:
    """``(id, name)`` of each shape element with an id: the name its ``inkscape:label`` or id."""
    import svgelements as se

    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        doc = se.SVG.parse(io.BytesIO(raw), reify=True)
    out = []
    for e in doc.elements():
        if isinstance(e, se.Shape) and e.id is not None and len(list(se.Path(e).segments())) > 1:
            values = getattr(e, "values", None) or {}
            label = next((v for k, v in values.items() if str(k).endswith("label")), None)
            out.append((str(e.id), str(label or e.id)))
    return out


def several_regions(err: InputError) -> bool:
    """The single-region reader refused a file because it holds several regions."""
    return bool(re.search(r"has \d+ (regions|shape elements|polygon features|polylines)", err.problem))


def read_model(data, source: str, fmt: str, corner_angle: float = DEFAULT_CORNER_ANGLE) -> Model | None:
    """The assembly in a file's ``data`` of format ``fmt`` (``json``, ``geojson``, ``svg``,
    ``dxf``), or None when the file holds one region (read it with
    :func:`jaxmatch.io.readers.load_shape`). Raises :class:`InputError` naming ``source``."""
    if fmt in ("json", "geojson"):
        doc = _load_json(_text(data, source), source)
        if fmt == "json" and is_model_json(doc):
            return model_from_json(doc, source, corner_angle)
        return _geojson_model(doc, source, corner_angle)
    if fmt == "dxf":
        layers = _dxf_layers(data, source)
        if len(layers) < 2:
            return None
        return make_model([_region(later.dxf.read_dxf(data, source, layer), layer, source, corner_angle) for layer in layers],
                          source=source)
    if fmt == "svg":
        names = _svg_names(data)
        if len(names) < 2:
            raise InputError("the SVG has several shape elements; an assembly needs an id on each (its name: "
                             "inkscape:label or id)", where=source)
        return make_model([_region(_read_svg(data, source, i), n, source, corner_angle) for i, n in names],
                          source=source)
    return None
