#!/usr/bin/env python3
"""Dense, noisy and curved outlines (``examples/dense/``): ``jaxmatch.mesh`` at h = P/40 and
P/80, each mesh checked here from its points and quads and the input outline, independently of
jaxmatch's code.

    .venv/bin/python scripts/dense_table.py [--divisions 40,80] [--json OUT.jsonl] [--png FILE]

Checks: no fold, min scaled Jacobian >= 0.3, area within 1 %, every boundary vertex on the
outline (within 1e-9 of its extent), every sharp corner a vertex. A sharp corner is found here
with a rule of its own: the outline turns by more than 60 degrees between the chords from the
point h back and to the point h ahead; of the points within h of each other, the one of the
largest such turn; "a vertex" means a mesh vertex within h / 2 of it (a turn held over a stretch
of about h has its point defined to within that stretch: two 90-degree turns 0.4 h apart, the end
of a glyph's stroke, are one feature at this scale, and noise moves the exact point).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

sys.path.insert(0, str(Path(__file__).resolve().parent))

from jaxmatch.cli import run_typer  # noqa: E402
from jaxmatch.geometry import cumulative_length  # noqa: E402
from holes_table import check  # noqa: E402
from mesh_table import write_outputs  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DENSE = ROOT / "examples" / "dense"

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def sharp_corners(p: np.ndarray, h: float, angle: float = 60.0) -> np.ndarray:
    """``(c, 2)`` the sharp corners of the closed outline ``p`` at scale ``h`` (see the module docstring)."""
    seg = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    per = cum[-1]
    s = cum[:-1]

    def at(t):
        t = np.mod(t, per)
        i = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, len(p) - 1)
        f = (t - cum[i]) / np.where(seg[i] > 0, seg[i], 1)
        return p[i] + f[:, None] * (p[(i + 1) % len(p)] - p[i])

    a, b = p - at(s - h), at(s + h) - p
    turn = np.degrees(np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], np.sum(a * b, axis=1))))
    out = []
    for i in np.argsort(-turn):
        if turn[i] <= angle:
            break
        if all(min(abs(s[i] - s[j]), per - abs(s[i] - s[j])) >= h for j in out):
            out.append(int(i))
    return p[out] if out else np.zeros((0, 2))


@app.command()
def main(divisions: str = typer.Option("40,80", help="h = perimeter / each of these."),
         json_out: Optional[Path] = typer.Option(None, "--json", help="Also write one JSON line per mesh."),
         png: Optional[Path] = typer.Option(None, "--png", help="Draw the meshes at the first size (.png)."),
         picture: str = typer.Option("coastline,glyph-G,ellipse-1000,wiggly-square", help="Outlines drawn with --png.")) -> None:
    import jaxmatch

    cat = jaxmatch.load_catalogue()
    rows, panels = [], []
    draw = set(picture.split(",")) if png else set()
    divs = [int(d) for d in divisions.split(",")]
    for path in sorted(DENSE.glob("*.json")):
        name = path.stem
        shp = jaxmatch.load_shape(path)
        outline = shp.input_points
        per = float(cumulative_length(outline)[-1])
        for div in divs:
            h = per / div
            sharp = sharp_corners(outline, h)
            t0 = time.perf_counter()
            try:
                m = jaxmatch.mesh(shp, size=h, catalogue=cat)
            except Exception as e:  # a failure is a row
                rows.append({"outline": name, "points": len(outline), "div": div, "error": str(e), "valid": False})
                continue
            dt = time.perf_counter() - t0
            rec = check(m.xy, m.quads, outline, [], np.zeros((0, 2)), h)
            missed = int(sum(np.min(np.linalg.norm(m.xy - c, axis=1)) > h / 2 for c in sharp))
            ok = rec["valid"] and rec["min_sj"] >= 0.3 and missed == 0
            rows.append({"outline": name, "points": len(outline), "div": div, "chosen": m.chosen, "seconds": dt,
                         "sharp_corners": len(sharp), "missed_sharp": missed, "corners_used": int(m.corners.shape[0]),
                         **rec, "valid": ok})
            if name in draw and div == divs[0]:
                panels.append((f"{name} ({len(outline)} points), P/{div}: {m.chosen}", m.xy, m.quads, m.patch, None, m.corners))
    print("| outline | points | P/h | chosen | corners (sharp, missed) | quads | min SJ | mean SJ | area ratio | s | valid |")
    print("|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['outline']} | {r['points']} | {r['div']} | error: {r['error'][:70]} | | | | | | | no |")
            continue
        print(f"| {r['outline']} | {r['points']} | {r['div']} | {r['chosen']} | {r['corners_used']} ({r['sharp_corners']}, "
              f"{r['missed_sharp']}) | {r['quads']} | {r['min_sj']:.3f} | {r['mean_sj']:.3f} | {r['area_ratio']:.4f} | "
              f"{r['seconds']:.2f} | {'yes' if r['valid'] else 'NO'} |")
    ok = [r for r in rows if "error" not in r]
    print(f"valid {sum(r['valid'] for r in rows)}/{len(rows)}; worst min SJ {min(r['min_sj'] for r in ok):.3f}; "
          f"largest time {max(r['seconds'] for r in ok):.1f} s")
    write_outputs(rows, panels, png, json_out)


if __name__ == "__main__":
    run_typer(app)
