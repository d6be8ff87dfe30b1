"""What a mesh file and a picture are asked to be: :class:`MeshOutput` (format, MSH version, binary
or ASCII, Abaqus element type, order, extrusion) and :class:`PictureOutput` (size, colouring,
histogram), each checked once with a one-line :class:`~jaxmatch.errors.InputError` naming the
option; the ``mesh`` command's options map one to one onto their fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from jaxmatch.errors import InputError

__all__ = ["MSH_VERSIONS", "MeshOutput", "PictureOutput", "parse_png_size"]

MSH_VERSIONS = ("4.1", "2.2")
"""Gmsh file versions written; the first is the default."""


@dataclass(frozen=True)
class MeshOutput:
    """How a mesh file is written.

    format: a registered mesh format's name or suffix (``"inp"``, ``".xdmf"``, ``"abaqus"``) or
    None (from the file's suffix); msh_version: ``"4.1"`` or ``"2.2"``; binary: binary MSH
    (False: ASCII); element_type: Abaqus ``CPS4`` (default), ``CPE4``, ``CAX4``, ``S4R`` (``C3D8``,
    ``C3D8R``, ``C3D8I`` for hexahedra); order: 1 or 2 (``quad9``, ``quad8`` with serendipity);
    extrude: thickness along z (user units) or None; layers: element layers through it;
    grading: the top layer's thickness over the bottom one's.
    """

    format: str | None = None
    msh_version: str = MSH_VERSIONS[0]
    binary: bool = True
    element_type: str | None = None
    order: int = 1
    serendipity: bool = False
    extrude: float | None = None
    layers: int = 1
    grading: float = 1.0

    def __post_init__(self) -> None:
        if str(self.msh_version) not in MSH_VERSIONS:
            raise InputError(f"expected {' or '.join(MSH_VERSIONS)}, got {self.msh_version!r}", "--msh-version")
        object.__setattr__(self, "msh_version", str(self.msh_version))
        if self.order not in (1, 2):
            raise InputError(f"expected 1 or 2, got {self.order!r}", "--order")
        if self.serendipity and self.order != 2:
            raise InputError("applies with --order 2 only", "--serendipity")
        if self.extrude is not None and not (self.extrude > 0 and math.isfinite(self.extrude)):
            raise InputError(f"must be a positive length, got {self.extrude:g}", "--extrude")
        if not (isinstance(self.layers, int) and self.layers >= 1):
            raise InputError(f"must be a whole number >= 1, got {self.layers!r}", "--layers")
        if not (self.grading > 0 and math.isfinite(self.grading)):
            raise InputError(f"must be a positive ratio, got {self.grading:g}", "--grading")
        if self.extrude is None:
            for opt, given in (("--layers", self.layers != 1), ("--grading", self.grading != 1.0)):
                if given:
                    raise InputError("applies with --extrude only", opt)

    @property
    def plain(self) -> bool:
        """First-order quads in the plane: what every format holds."""
        return self.order == 1 and self.extrude is None


def parse_png_size(text: str | None) -> tuple[int, int] | None:
    """``"1200,800"`` -> ``(1200, 800)`` pixels; InputError naming --png-size otherwise."""
    if text is None:
        return None
    try:
        w, h = (int(t) for t in text.lower().replace("x", ",").split(","))
    except ValueError:
        raise InputError(f"expected W,H in pixels like 1200,800, got {text!r}", "--png-size") from None
    if not (16 <= w <= 20000 and 16 <= h <= 20000):
        raise InputError(f"each side must lie in 16..20000 pixels, got {text!r}", "--png-size")
    return w, h


@dataclass(frozen=True)
class PictureOutput:
    """How a picture of a mesh is drawn.

    size: ``(W, H)`` pixels of the whole picture or None (fitted to the region's aspect);
    dpi: dots per inch (None: 120); color: ``"patch"`` (pale colour per patch) or ``"quality"``
    (scaled Jacobian, with a colour bar) or ``"size"`` (edge length / size, the size field's where
    the mesh has one: :func:`jaxmatch.io.plot.size_ratios`); histogram: add the scaled Jacobians' histogram.
    """

    size: tuple[int, int] | None = None
    dpi: int | None = None
    color: str = "patch"
    histogram: bool = False

    def __post_init__(self) -> None:
        if self.dpi is not None and not (10 <= self.dpi <= 1200):
            raise InputError(f"must lie in 10..1200, got {self.dpi}", "--dpi")
        if self.color not in ("patch", "quality", "size"):
            raise InputError(f"expected patch, quality or size, got {self.color!r}", "--color")
