#!/usr/bin/env python3
"""Automatic sizing on the engineering parts: ``docs/graded.md``'s table.

Each part of ``examples/parts/`` at h = outer perimeter / 40 and / 80, meshed in this process by
``jaxmatch.mesh(part, size=h)`` and with ``auto_size=True``: quads, min scaled Jacobian, valid (no
inverted quad, every corner a vertex), seconds (first call of the pair), and with automatic sizing
the share of edges within [0.5, 1.6] of the field.

Usage: ``python scripts/autosize_table.py`` (prints the Markdown table).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jaxmatch

PARTS = Path(__file__).resolve().parent.parent / "examples" / "parts"


def cell(m, seconds: float, auto: bool) -> str:
    text = f"{len(m.quads)} q, SJ {m.min_scaled_jacobian:.3f}, {'valid' if m.valid else 'NOT valid'}, {seconds:.2f} s"
    return text + (f", field share {m.field_share:.2f}" if auto and m.field_share is not None else "")


def main() -> None:
    print("| part | P/h | size h | with --auto-size |")
    print("|---|---:|---|---|")
    for path in sorted(PARTS.glob("*.json")):
        truth = json.loads((PARTS / "truth" / path.name).read_text())
        for fraction in (40, 80):
            h = truth["outer_perimeter"] / fraction
            cells = []
            for auto in (False, True):
                t0 = time.perf_counter()
                try:
                    m = jaxmatch.mesh(path, size=h, auto_size=auto)
                except jaxmatch.InputError as e:
                    cells.append(f"error: {e}")
                    continue
                cells.append(cell(m, time.perf_counter() - t0, auto))
            print(f"| {path.stem} | {fraction} | {cells[0]} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
