"""The assemblies of docs/meshing.md ("Assemblies"), each meshed by ``jaxmatch.mesh`` (after one
warm-up), with the time and per region its quads and min scaled Jacobian.

    python scripts/assembly_table.py            # a Markdown table on stdout
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import jaxmatch  # noqa: E402
from jaxmatch.meshing.pipeline import warm_up  # noqa: E402

SQUARE = [[0, 0], [1, 0], [1, 1], [0, 1]]
INLINE = {
    "two rectangles": {"regions": [{"name": "left", "boundary": SQUARE},
                                   {"name": "right", "boundary": [[1, 0], [3, 0], [3, 1], [1, 1]]}]},
    "lug on a block's side": {"regions": [{"name": "block", "boundary": [[0, 0], [4, 0], [4, 1], [0, 1]]},
                                          {"name": "lug", "boundary": [[1.5, 1], [2.5, 1], [2.5, 1.6], [1.5, 1.6]]}]},
    "two L shapes": {"regions": [{"name": "a", "boundary": [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]]},
                                 {"name": "b", "boundary": [[2, 0], [3, 0], [3, 2], [1, 2], [1, 1], [2, 1]]}]},
}
CASES = [("two rectangles", 0.25), ("lug on a block's side", 0.1), ("two L shapes", 0.2),
         ("examples/assemblies/inclusion.json", 0.1), ("examples/assemblies/laminate.json", 0.1),
         ("examples/assemblies/crack.json", 0.1), ("examples/assemblies/motor.json", 0.1), ("SVG: two rects", 0.25)]
SVG = ('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 3 1"><rect id="left" width="1" height="1"/>'
       '<rect id="right" x="1" width="2" height="1"/></svg>')


def main() -> None:
    warm_up()
    print("| assembly | h | quads | time s | min SJ per region (quads) | irregular (bound) | valid |")
    print("|---|---:|---:|---:|---|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, h in CASES:
            if name in INLINE:
                path = Path(tmp) / "model.json"
                path.write_text(json.dumps(INLINE[name]))
            elif name.startswith("SVG"):
                path = Path(tmp) / "model.svg"
                path.write_text(SVG)
            else:
                path = ROOT / name
            t0 = time.perf_counter()
            m = jaxmatch.mesh(str(path), size=h)
            dt = time.perf_counter() - t0
            regions = ", ".join(f"{c.name.split(' (')[0][7:]} {c.mesh.min_scaled_jacobian:.3f} ({c.mesh.quads.shape[0]})"
                                for c in m.tried)
            print(f"| {name} | {h:g} | {m.quads.shape[0]} | {dt:.2f} | {regions} | {m.irregular.size} ({m.irregular_bound}) "
                  f"| {'yes' if m.valid else 'no'} |")


if __name__ == "__main__":
    main()
