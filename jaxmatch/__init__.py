"""jaxmatch: pick the best quadrilateral mesh from a catalogue for a planar shape.

Method: Surynkova, "Selecting the Best Quadrilateral Mesh for Given Planar Shape"
(weighted longest-common-subsequence between the shape's s/x/v annotation and the
mesh boundary's valence triples, scored by lattices).

The Python API (documented in :mod:`jaxmatch.api` and the README's "Python API")::

    import jaxmatch
    shape = jaxmatch.load_shape("examples/lshape.json")   # JSON, GeoJSON, CSV/TXT, SVG, DXF, STEP/IGES/BREP
    ranking = jaxmatch.rank(shape, internal=4, top=3)
    placement = jaxmatch.place(shape, ranking)            # the #1 mesh in the shape
    m = jaxmatch.mesh(shape, size=0.25)                   # the meshing pipeline: a QuadMesh
    jaxmatch.write_mesh("lshape.vtk", m)

The names are imported on first use, so ``import jaxmatch`` itself is quick (JAX is loaded
by the first call that scores).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_API = {
    # shapes
    "load_shape": "jaxmatch.api",
    "parse_shape": "jaxmatch.api",
    "make_shape": "jaxmatch.api",
    "annotate_shape": "jaxmatch.api",
    "Shape": "jaxmatch.shape",
    "Annotation": "jaxmatch.shape",
    # catalogue and lattices
    "load_catalogue": "jaxmatch.api",
    "load_lattice": "jaxmatch.api",
    "Catalogue": "jaxmatch.catalogue.store",
    "Lattice": "jaxmatch.scoring.lattice",
    # ranking and placing
    "rank": "jaxmatch.api",
    "place": "jaxmatch.api",
    "choose_mesh": "jaxmatch.api",
    "Ranking": "jaxmatch.scoring.rank",
    "Match": "jaxmatch.scoring.rank",
    "Placement": "jaxmatch.placement.embed",
    "MeshChoice": "jaxmatch.placement.choose",
    # the meshing pipeline (the front door)
    "mesh": "jaxmatch.meshing.pipeline",
    "load_region": "jaxmatch.meshing.pipeline",
    "Model": "jaxmatch.model",
    "Region": "jaxmatch.model",
    "make_model": "jaxmatch.model",
    "QuadMesh": "jaxmatch.meshing.result",
    "Quality": "jaxmatch.defaults",
    # size fields (graded meshes: mesh(region, size=Field(...)))
    "Field": "jaxmatch.field",
    "Near": "jaxmatch.field",
    "load_field": "jaxmatch.field",
    # sizes, concave shapes, layouts
    "refine_mesh": "jaxmatch.api",
    "mesh_concave": "jaxmatch.api",
    "mesh_layout": "jaxmatch.api",
    # writing
    "write_mesh": "jaxmatch.api",
    "draw_mesh": "jaxmatch.io.plot",
    # errors
    "InputError": "jaxmatch.errors",
    "InputWarning": "jaxmatch.errors",
    "UnmatchableError": "jaxmatch.errors",
}

__all__ = ["__version__", *sorted(_API)]


def __getattr__(name: str):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'jaxmatch' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
