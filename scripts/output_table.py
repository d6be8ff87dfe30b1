"""The table of docs/output.md: every solver format written for the L-shape and the plate with a
hole, read back with meshio, its area and groups as read beside those written.

Usage: python scripts/output_table.py   (from the repository root; prints Markdown)
"""

from __future__ import annotations

import sys
import tempfile
import warnings
from pathlib import Path

import meshio
import numpy as np

import jaxmatch
from jaxmatch.io.meshfile import write_mesh

ROOT = Path(__file__).resolve().parent.parent
REGIONS = {"L-shape": (ROOT / "examples/lshape.json", 0.25), "plate-bolt": (ROOT / "examples/holes/plate-bolt.json", 0.4)}
SUFFIXES = [".msh", ".inp", ".xdmf", ".bdf", ".e", ".vtu", ".mesh"]


def area(points, quads) -> float:
    p = points[quads][..., :2]
    q = np.roll(p, -1, axis=1)
    return float(0.5 * np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]))


def groups_read(back: meshio.Mesh, suffix: str, folder: Path) -> str:
    """What the file holds of the groups, as read back."""
    if suffix == ".msh":
        return f"{len(back.field_data)} physical groups"
    if suffix == ".inp":
        return f"{len(back.cell_sets)} element sets, {len(back.point_sets)} node sets"
    if suffix == ".e":
        return f"{len(back.cells)} blocks, {len(back.point_sets)} node sets (+ side sets)"
    if suffix == ".xdmf":
        f = meshio.read(folder / "m_facets.xdmf")
        return f"{len(np.unique(back.cell_data['patch'][0]))} cell tags, {len(np.unique(f.cell_data['group'][0]))} facet tags"
    if suffix == ".mesh":
        refs = back.cell_data["medit:ref"]
        return f"{len(np.unique(refs[0]))} cell refs, {len(np.unique(refs[1]))} edge refs"
    if suffix == ".vtu":
        return f"{len(np.unique(back.cell_data['patch'][0]))} patches, {len(np.unique(back.cell_data['line_group'][1]))} line groups"
    return f"{len(np.unique(back.cell_data['nastran:ref'][0]))} property ids"


def main() -> int:
    print("| region | format | quads written / read | area of the region | area read back | groups written | read back |")
    print("|---|---|---|---|---|---|---|")
    for name, (path, size) in REGIONS.items():
        m = jaxmatch.mesh(path, size=size)
        written = f"{m.n_patches} patches, {len(m.line_sets)} line groups"
        for suffix in SUFFIXES:
            with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out = Path(tmp) / f"m{suffix}"
                write_mesh(out, m)
                back = meshio.read(out)
                quads = np.concatenate([c.data for c in back.cells if c.type == "quad"])
                print(f"| {name} | {suffix} | {len(m.quads)} / {len(quads)} | {m.region_area:.6f} | "
                      f"{area(back.points, quads):.6f} | {written} | {groups_read(back, suffix, Path(tmp))} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
