#!/usr/bin/env python3
"""What the fast search gives up: every search of ``--searches`` meshes the same regions in this
one process, every figure measured here from the meshes' points and quads and the inputs
(``scripts/part_measures.py``: numpy and shapely), independently of jaxmatch's quality code.

    .venv/bin/python scripts/search_table.py [--parts 300] [--searches best,fast] [--json OUT]

The regions: the first ``--parts`` random parts of ``scripts/make_bulk_parts.py`` (the bulk
benchmark's, perimeter / 32) and the 50 cases of ``scripts/bench.py --mesh`` (13 shapes and 12
with holes, each at perimeter / 16 and / 32), and the 15 engineering parts of ``examples/parts``
(fillets, round holes, a gear, fins, an airfoil) at perimeter / 40. Every mesh is a first call: the meshing caches
cleared before each (``bench.clear_mesh_caches``); its CPU seconds are this process's
(``time.process_time``). Per search and set of regions: the CPU seconds and their ratio to the
first search's, the meshes that differ from the first search's (points or quads), valid meshes,
the mean and lowest min scaled Jacobian, the mean of the mean scaled Jacobians, irregular
vertices in all, the share of edges within [0.5, 1.5] h, and against the first search's mesh of
the same region: how many lose more than 0.05 of min scaled Jacobian, how many gain more, and
the largest loss. ``--variant NAME:FIELD=VALUE,...`` adds a search made of
:class:`jaxmatch.defaults.Search` fields (e.g. ``--variant k2:layouts=2,leave_out=Conforming/LeanCurves``; ``leave_out``'s names joined by ``/``).
"""

from __future__ import annotations

import importlib.util
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import List, Optional

import numpy as np
import shapely
import typer

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))

from part_measures import measure  # noqa: E402

import jaxmatch  # noqa: E402
from jaxmatch.cli import run_typer  # noqa: E402
from jaxmatch.defaults import SEARCHES, Search  # noqa: E402

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def _bench():
    spec = importlib.util.spec_from_file_location("bench", ROOT / "scripts" / "bench.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def variant(text: str) -> Search:
    """``NAME:FIELD=VALUE,...`` as a :class:`Search` (values: ints, true/false, none)."""
    name, _, fields = text.partition(":")
    kw = {}
    for item in filter(None, fields.split(",")):
        key, _, value = item.partition("=")
        low = value.strip().lower()
        if key.strip() == "leave_out":
            kw["leave_out"] = tuple(v for v in value.split("/") if v)
        else:
            kw[key.strip()] = None if low == "none" else (low == "true") if low in ("true", "false") else int(value)
    return Search(name, **kw)


def regions(parts: int, bench) -> list[tuple[str, object, dict]]:
    """``(key, shape, mesh keywords)``: the bulk parts (``bulk|i``), then the bench cases (``bench|name|div``)."""
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, doc in enumerate(bench._script("make_bulk_parts").parts(int(parts))):
            p = Path(tmp) / f"part-{i:03d}.json"
            p.write_text(json.dumps(doc) + "\n")
            out.append((f"bulk|{i}", jaxmatch.load_shape(p), {"divisions": 32}))
    for name in bench.mesh_regions(True):
        for div in bench.MESH_DIVISIONS:
            shp, _, _, _, h = bench._mesh_region(name, div)
            out.append((f"bench|{name}|{div}", shp, {"size": h}))
    for path in sorted((ROOT / "examples" / "parts").glob("*.json")):
        out.append((f"parts|{path.stem}", jaxmatch.load_shape(path), {"divisions": 40}))
    return out


def figures(m, shp) -> dict:
    """The independent figures of one mesh (:func:`part_measures.measure`) and a digest of it."""
    rings = [np.asarray(shp.user_points, float)] + [np.asarray(hh, float) for hh in shp.holes]
    corners = [shp.to_user(shp.points[shp.corners])] if shp.n_corners else []
    corners += [np.asarray(hh, float)[np.asarray(c, np.int64)] for hh, c in zip(shp.holes, shp.hole_corners or ())]
    corners = np.concatenate(corners) if corners else np.zeros((0, 2))
    area = shapely.Polygon(rings[0], rings[1:]).area
    rec = measure(m.xy, {"quad": m.quads}, rings, corners, area, float(m.size))
    rec["digest"] = hash((np.asarray(m.xy, np.float64).tobytes(), np.asarray(m.quads, np.int64).tobytes()))
    return rec


def run(searches: list[Search], parts: int) -> dict:
    """``{search name: {region key: figures and "cpu_s"}}``."""
    bench = _bench()
    todo = regions(parts, bench)
    bench.clear_mesh_caches()
    jaxmatch.mesh(todo[0][1], **todo[0][2])  # (warm: compiled code, the catalogue opened)
    out = {}
    for s in searches:
        rows = {}
        for key, shp, kw in todo:
            bench.clear_mesh_caches()
            t = time.process_time()
            m = jaxmatch.mesh(shp, search=s, **kw)
            cpu = time.process_time() - t
            rows[key] = {**figures(m, shp), "cpu_s": cpu}
        out[s.name] = rows
    return out


def summary(rows: dict, base: dict, prefix: str) -> dict:
    keys = [k for k in base if k.startswith(prefix)]
    new, old = [rows[k] for k in keys], [base[k] for k in keys]
    d = np.array([a["min_sj"] - b["min_sj"] for a, b in zip(new, old)])
    cpu, cpu0 = sum(r["cpu_s"] for r in new), sum(r["cpu_s"] for r in old)
    return {"regions": len(keys), "cpu_s": cpu, "ratio": cpu / cpu0, "changed": int(sum(a["digest"] != b["digest"] for a, b in zip(new, old))),
            "valid": int(sum(r["valid"] for r in new)), "mean_min_sj": float(np.mean([r["min_sj"] for r in new])),
            "lowest_min_sj": float(min(r["min_sj"] for r in new)), "mean_mean_sj": float(np.mean([r["mean_sj"] for r in new])),
            "irregular": int(sum(r["irregular"] for r in new)), "in_band": float(np.mean([r["in_band"] for r in new])),
            "worse": int(np.sum(d < -0.05)), "better": int(np.sum(d > 0.05)), "worst_loss": float(min(d.min(), 0.0))}


@app.command()
def main(parts: int = typer.Option(300, help="Random bulk parts (scripts/make_bulk_parts.py, seed 38)."),
         searches: str = typer.Option("best,fast", help="Named searches, the first the reference."),
         variants: Optional[List[str]] = typer.Option(None, "--variant", help="NAME:FIELD=VALUE,... a Search of these fields."),
         json_out: Optional[Path] = typer.Option(None, "--json", help="Write the per-set summaries here.")) -> None:
    chosen = [SEARCHES[n.strip()] for n in searches.split(",") if n.strip()] + [variant(v) for v in variants or ()]
    res = run(chosen, parts)
    base = res[chosen[0].name]
    table = {}
    cols = ("regions", "cpu_s", "ratio", "changed", "valid", "mean_min_sj", "lowest_min_sj", "mean_mean_sj", "irregular",
            "in_band", "worse", "better", "worst_loss")
    for prefix, title in (("bulk|", f"{parts} random bulk parts at perimeter / 32"), ("bench|", "the 50 bench.py --mesh cases"),
                          ("parts|", "the engineering parts of examples/parts at perimeter / 40")):
        print(f"\n{title}\n\n| search | " + " | ".join(c.replace("_", " ") for c in cols) + " |")
        print("|---" * (len(cols) + 1) + "|")
        for s in chosen:
            r = summary(res[s.name], base, prefix)
            table.setdefault(s.name, {})[prefix[:-1]] = r
            print(f"| {s.name} | " + " | ".join(f"{r[c]:.3f}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    if json_out is not None:
        json_out.write_text(json.dumps({"searches": {s.name: s.__dict__ for s in chosen}, "table": table}, indent=1) + "\n")


if __name__ == "__main__":
    run_typer(app)
