#!/usr/bin/env python3
"""The engineering-parts table: ``jaxmatch mesh`` beside gmsh's quasi-structured quads on the
parts of ``examples/parts/`` (written by ``scripts/make_parts.py``) at h = outer perimeter / 40
and / 80, both meshes read back with meshio and measured by ``scripts/part_measures.py``
(numpy, shapely; no jaxmatch code).

    .venv/bin/python scripts/parts_table.py [--parts gear,keyhole] [--fractions 40,80] [--out DIR]
        [--json] [--doc docs/parts.md] [--timeout 120] [--explicit-corners] [--no-gmsh]

* jaxmatch: ``python -m jaxmatch mesh PART --size h --out DIR/PART-F-jaxmatch.msh``, a subprocess
  from the repository root (this checkout's jaxmatch), timed as the whole command (start-up
  included). Exit 3 (a fold or a missed corner) still gives a mesh, which is measured; any other
  failure or a run past ``--timeout`` is a row with its error.
* gmsh: a subprocess of this script (``--gmsh-worker``) with the gmsh Python package: straight
  sides as lines, curved stretches as splines through their sample points (a closed curve as two
  splines), holes as curve loops, ``Mesh.Algorithm = 11`` (quasi-structured quads),
  ``Mesh.RecombineAll = 1``, size ``2h`` at every point and ``Mesh.MeshSizeMax = 2h`` (its
  quasi-structured pipeline cuts each triangle of that size into quads, so its edges come out
  near h), a 2D mesh written to ``DIR/PART-F-gmsh.msh``; timed as the whole command too.

``--json`` prints one JSON object per part and fraction (``part``, ``fraction``, ``h``,
``jaxmatch`` and ``gmsh`` with every figure of :func:`part_measures.measure`, ``seconds``,
``error``); otherwise a Markdown table. ``--doc`` writes the page (intro, table, the issue's
pass criteria, pictures of every part at the first fraction into a ``parts/`` folder beside it).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import numpy as np
import typer

sys.path.insert(0, str(Path(__file__).resolve().parent))

from part_measures import measure, quads_of  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PARTS = ROOT / "examples" / "parts"
METHODS = ("jaxmatch", "gmsh")

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)


def load_part(name: str, folder: Path = PARTS) -> tuple[dict, dict]:
    """``(input document, truth document)`` of the part ``name``."""
    doc = json.loads((folder / f"{name}.json").read_text())
    truth = json.loads((folder / "truth" / f"{name}.json").read_text())
    return doc, truth


def part_names(folder: Path = PARTS) -> list[str]:
    """The parts with a truth file, in the generator's order when it is importable."""
    names = sorted(p.stem for p in (folder / "truth").glob("*.json"))
    try:
        import make_parts
        order = [p.name for p in make_parts.parts()]
        names.sort(key=lambda n: order.index(n) if n in order else len(order))
    except Exception:  # the generator's order is only a nicety
        pass
    return names


def rings_of(doc: dict) -> list[np.ndarray]:
    """The rings of an input document: the boundary, then the holes."""
    return [np.asarray(doc["boundary"], float)] + [np.asarray(h, float) for h in doc.get("holes", [])]


def piece_indices(start: int, end: int, n: int) -> list[int]:
    """Point indices of a piece running forward from ``start`` to ``end`` on a ring of ``n``
    points (``end == start``: once around)."""
    stop = end if end > start else end + n
    return [i % n for i in range(start, stop + 1)]


# ---------------------------------------------------------------------------------------------
# the two meshers


def run_command(cmd: list[str], timeout: float, env: dict | None = None) -> tuple[int | None, str, str, float]:
    """``(exit code or None on timeout, stdout, stderr, seconds)`` of ``cmd`` run from the
    repository root in its own process group (killed, group and all, past ``timeout``)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                         start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, err = p.communicate()
        return None, out, err, time.perf_counter() - t0
    return p.returncode, out, err, time.perf_counter() - t0


def last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def run_jaxmatch(path: Path, h: float, out: Path, timeout: float) -> dict:
    """Mesh ``path`` with the jaxmatch command at size ``h`` into ``out``: ``seconds``,
    ``exit``, ``chosen`` (the candidate it printed) or ``error``."""
    env = {**os.environ, "JAX_PLATFORMS": os.environ.get("JAX_PLATFORMS", "cpu")}
    cmd = [sys.executable, "-m", "jaxmatch", "mesh", str(path), "--size", repr(h), "--out", str(out)]
    rc, stdout, stderr, sec = run_command(cmd, timeout, env)
    rec = {"seconds": sec, "exit": rc}
    if rc is None:
        return {**rec, "error": f"timeout after {timeout:g} s"}
    if rc not in (0, 3) or not out.exists():
        return {**rec, "error": f"exit {rc}: {last_line(stderr) or last_line(stdout)}"}
    chosen = [ln.split()[1] for ln in stdout.splitlines() if ln.startswith("chosen:")]
    return {**rec, "chosen": chosen[0] if chosen else ""}


def run_gmsh(name: str, h: float, out: Path, timeout: float, folder: Path) -> dict:
    """Mesh part ``name`` with gmsh (:func:`gmsh_worker` in a subprocess) into ``out``."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--gmsh-worker", str(folder), name, repr(h), str(out)]
    rc, stdout, stderr, sec = run_command(cmd, timeout)
    rec = {"seconds": sec, "exit": rc}
    if rc is None:
        return {**rec, "error": f"timeout after {timeout:g} s"}
    if rc != 0 or not out.exists():
        return {**rec, "error": f"exit {rc}: {last_line(stderr) or last_line(stdout)}"}
    try:
        rec["mesh_seconds"] = float(last_line(stdout))
    except ValueError:
        pass
    return rec


def gmsh_worker(folder: str, name: str, h: str, out: str) -> None:
    """Build the part's geometry in gmsh (lines and splines from the truth's pieces), mesh it
    with quasi-structured quads at size ``2h`` and write ``out``; prints the seconds of the
    geometry and meshing."""
    import gmsh

    doc, truth = load_part(name, Path(folder))
    size = 2 * float(h)
    t0 = time.perf_counter()
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
        geo = gmsh.model.geo
        loops = []
        for ring, info in zip(rings_of(doc), truth["rings"]):
            n = len(ring)
            tags: dict[int, int] = {}

            def point(i: int) -> int:
                if i not in tags:
                    tags[i] = geo.addPoint(float(ring[i, 0]), float(ring[i, 1]), 0.0, size)
                return tags[i]

            curves = []
            for kind, start, end in info["pieces"]:
                idx = piece_indices(start, end, n)
                if kind == "line":
                    curves.append(geo.addLine(point(idx[0]), point(idx[-1])))
                    continue
                if idx[0] == idx[-1]:  # a closed curve: two splines
                    half = len(idx) // 2
                    parts = [idx[:half + 1], idx[half:]]
                else:
                    parts = [idx]
                curves += [geo.addSpline([point(i) for i in p]) for p in parts]
            loops.append(geo.addCurveLoop(curves))
        geo.addPlaneSurface(loops)
        geo.synchronize()
        gmsh.option.setNumber("Mesh.Algorithm", 11)
        gmsh.option.setNumber("Mesh.RecombineAll", 1)
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(2)
        sec = time.perf_counter() - t0
        gmsh.write(out)
    finally:
        gmsh.finalize()
    print(f"{sec:.6f}")


# ---------------------------------------------------------------------------------------------
# one case


def with_corners(doc: dict, truth: dict, folder: Path) -> Path:
    """A copy of the input with the truth's corners given explicitly (``corners``,
    ``hole_corners``), in ``folder``."""
    d = dict(doc)
    d["corners"] = truth["rings"][0]["corners"]
    if doc.get("holes"):
        d["hole_corners"] = [r["corners"] for r in truth["rings"][1:]]
    path = folder / f"{truth['name']}-corners.json"
    path.write_text(json.dumps(d))
    return path


def mesh_case(name: str, fraction: int, out: Path, *, timeout: float, gmsh: bool = True,
              explicit_corners: bool = False, folder: Path = PARTS) -> tuple[dict, dict]:
    """One part at h = outer perimeter / ``fraction``: ``(row, meshes)``; the row holds both
    methods' figures (or errors), ``meshes`` the points and quads read back, per method."""
    import meshio

    doc, truth = load_part(name, folder)
    h = truth["outer_perimeter"] / fraction
    rings = rings_of(doc)
    row = {"part": name, "fraction": fraction, "h": h}
    meshes = {}
    src = with_corners(doc, truth, out) if explicit_corners else folder / f"{name}.json"
    if src.resolve().is_relative_to(ROOT):  # errors name the file as from the repository root
        src = src.resolve().relative_to(ROOT)
    for method in METHODS if gmsh else METHODS[:1]:
        msh = out / f"{name}-{fraction}-{method}.msh"
        msh.unlink(missing_ok=True)
        rec = (run_jaxmatch(src, h, msh, timeout) if method == "jaxmatch"
               else run_gmsh(name, h, msh, timeout, folder))
        if "error" not in rec:
            try:
                with contextlib.redirect_stdout(io.StringIO()):  # meshio prints a blank line per .msh
                    m = meshio.read(msh)
                cells = [(c.type, c.data) for c in m.cells]
                rec.update(measure(m.points, cells, rings, truth["corners"], truth["area"], h))
                meshes[method] = (np.asarray(m.points)[:, :2], quads_of(cells)[0])
            except Exception as e:  # an unreadable mesh file is a row too
                rec["error"] = f"reading {msh.name}: {type(e).__name__}: {e}"
        rec.setdefault("valid", False)
        row[method] = rec
    return row, meshes


# ---------------------------------------------------------------------------------------------
# reports


def fmt(rec: dict, key: str, spec: str) -> str:
    v = rec.get(key)
    return "-" if v is None or "error" in rec else format(v, spec)


def pair(row: dict, key: str, spec: str) -> str:
    return " / ".join(fmt(row.get(m, {}), key, spec) for m in METHODS if m in row)


def table(rows: list[dict]) -> str:
    """The Markdown table: each cell ``jaxmatch / gmsh``."""
    head = ("| part | P/h | h | quads | min SJ | mean SJ | longest / h | in [0.5h, 1.5h] | irregular | corners | valid "
            "| time s |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|")
    lines = [head]
    for r in rows:
        corners = " / ".join("-" if "error" in r[m] else f"{r[m]['corners_kept']}/{r[m]['corners']}"
                             for m in METHODS if m in r)
        valid = " / ".join("error" if "error" in r[m] else ("yes" if r[m]["valid"] else "NO") for m in METHODS if m in r)
        sec = " / ".join(f"{r[m]['seconds']:.2f}" if r[m].get("seconds") is not None else "-" for m in METHODS if m in r)
        lines.append(f"| {r['part']} | {r['fraction']} | {r['h']:.3g} | {pair(r, 'quads', 'd')} | {pair(r, 'min_sj', '.3f')} "
                     f"| {pair(r, 'mean_sj', '.3f')} | {pair(r, 'longest', '.2f')} | {pair(r, 'in_band', '.0%')} "
                     f"| {pair(r, 'irregular', 'd')} | {corners} | {valid} | {sec} |")
    return "\n".join(lines)


def problems(rows: list[dict]) -> list[str]:
    """One line per error or invalid mesh."""
    out = []
    for r in rows:
        for m in METHODS:
            rec = r.get(m)
            if rec is None:
                continue
            why = rec.get("error") or (rec.get("problem") if not rec.get("valid") else None)
            if why:
                out.append(f"- {r['part']} P/{r['fraction']}, {m}: {why}")
    return out


def criteria(rows: list[dict]) -> list[tuple[str, int, int, bool, str]]:
    """The issue's pass criteria: ``(criterion, cases met, cases counted, pass, note)``."""
    both = [r for r in rows if "gmsh" in r]
    jv = [r for r in rows if r["jaxmatch"].get("valid")]
    gv = [r for r in both if r["gmsh"].get("valid")]
    sj = lambda rec: rec.get("min_sj", 0.0) if "error" not in rec else 0.0  # noqa: E731
    close = [r for r in gv if sj(r["jaxmatch"]) >= r["gmsh"]["min_sj"] - 0.05]
    mean_j = float(np.mean([sj(r["jaxmatch"]) for r in gv])) if gv else math.nan
    mean_g = float(np.mean([r["gmsh"]["min_sj"] for r in gv])) if gv else math.nan
    short = [r for r in both if "error" not in r["gmsh"] and r["gmsh"]["longest"] <= 2.0]
    short_j = [r for r in short if "error" not in r["jaxmatch"] and r["jaxmatch"]["longest"] <= 2.0]
    band = [r for r in both if "error" not in r["gmsh"] and r["gmsh"]["in_band"] >= 0.8]
    band_j = [r for r in band if "error" not in r["jaxmatch"] and r["jaxmatch"]["in_band"] >= 0.75]
    return [
        ("every jaxmatch mesh valid (all quads, no fold, a loop per ring, every corner, on the rings, area 1 %)",
         len(jv), len(rows), len(jv) == len(rows), ""),
        ("min SJ >= gmsh's - 0.05 on >= 90 % of the cases gmsh meshes validly", len(close), len(gv),
         bool(gv) and len(close) >= 0.9 * len(gv), ""),
        ("mean of min SJ >= gmsh's (over the cases gmsh meshes validly; a jaxmatch error counts 0)",
         None, len(gv), mean_j >= mean_g, f"jaxmatch {mean_j:.3f}, gmsh {mean_g:.3f}"),
        ("no edge longer than 2h where gmsh's longest is within 2h", len(short_j), len(short), len(short_j) == len(short), ""),
        ("where gmsh has >= 80 % of its edges in [0.5h, 1.5h], jaxmatch >= 75 %", len(band_j), len(band),
         len(band_j) == len(band), ""),
    ]


def picture(name: str, fraction: int, h: float, meshes: dict, row: dict, doc: dict, truth: dict, path: Path) -> None:
    """jaxmatch (left) beside gmsh (right), the input rings in blue, corners as black squares;
    written as a small palette PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from PIL import Image

    rings = rings_of(doc)
    allp = np.concatenate(rings)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    w, ht = hi - lo
    fig, axes = plt.subplots(1, 2, figsize=(8.0, max(2.2, min(4.5, 4.0 * ht / w + 0.6))), dpi=100)
    corners = np.asarray(truth["corners"], float).reshape(-1, 2)
    for ax, method in zip(axes, METHODS):
        rec = row.get(method, {})
        if method in meshes:
            xy, quads = meshes[method]
            ax.add_collection(PolyCollection(xy[quads], facecolor="#e8eef7", edgecolor="#222222", linewidths=0.35))
            title = (f"{method}: {rec['quads']} quads, min SJ {rec['min_sj']:.2f}, longest {rec['longest']:.2f} h"
                     + ("" if rec.get("valid") else " (NOT valid)"))
        else:
            title = f"{method}: {rec.get('error', 'not run')[:60]}"
        for r in rings:
            c = np.vstack([r, r[:1]])
            ax.plot(c[:, 0], c[:, 1], color="#1f5fbf", lw=0.6)
        if len(corners):
            ax.plot(corners[:, 0], corners[:, 1], "s", color="k", ms=2.5)
        ax.set_title(title, fontsize=7)
        ax.set_xlim(lo[0] - 0.02 * w, hi[0] + 0.02 * w)
        ax.set_ylim(lo[1] - 0.02 * ht, hi[1] + 0.02 * ht)
        ax.set_aspect("equal")
        ax.axis("off")
    fig.suptitle(f"{name}, h = P/{fraction} = {h:.3g}", fontsize=8)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp)
    plt.close(fig)
    Image.open(tmp).convert("RGB").quantize(colors=32).save(tmp, optimize=True)
    os.replace(tmp, path)


def band_misses(rows: list[dict]) -> list[str]:
    """The cases of the size band criterion that jaxmatch misses: ``"PART P/F (jm %, gmsh %)"``."""
    return [f"{r['part']} P/{r['fraction']} ({r['jaxmatch'].get('in_band', 0.0):.0%}, gmsh {r['gmsh']['in_band']:.0%})"
            for r in rows if "gmsh" in r and "error" not in r["gmsh"] and r["gmsh"]["in_band"] >= 0.8
            and ("error" in r["jaxmatch"] or r["jaxmatch"]["in_band"] < 0.75)]


def worst(rows: list[dict]) -> list[str]:
    """Summary lines: jaxmatch's lowest min SJ and longest edges, and the times beside gmsh's."""
    jm = [r for r in rows if "error" not in r["jaxmatch"] and "min_sj" in r["jaxmatch"]]
    out = []
    if jm:
        low = sorted(jm, key=lambda r: r["jaxmatch"]["min_sj"])[:5]
        out.append("- lowest jaxmatch min SJ: " + ", ".join(
            f"{r['part']} P/{r['fraction']} {r['jaxmatch']['min_sj']:.3f}"
            + (f" (gmsh {r['gmsh']['min_sj']:.3f})" if "min_sj" in r.get("gmsh", {}) else "") for r in low))
        long = sorted(jm, key=lambda r: -r["jaxmatch"]["longest"])[:5]
        out.append("- longest jaxmatch edges: " + ", ".join(
            f"{r['part']} P/{r['fraction']} {r['jaxmatch']['longest']:.2f} h" for r in long))
    both = [r for r in rows if "gmsh" in r and r["jaxmatch"].get("seconds") and r["gmsh"].get("seconds")
            and "error" not in r["jaxmatch"] and "error" not in r["gmsh"]]
    if both:
        ratio = [r["jaxmatch"]["seconds"] / r["gmsh"]["seconds"] for r in both]
        out.append(f"- time, whole commands: jaxmatch median {np.median([r['jaxmatch']['seconds'] for r in both]):.2f} s, "
                   f"gmsh median {np.median([r['gmsh']['seconds'] for r in both]):.2f} s; jaxmatch / gmsh median "
                   f"{np.median(ratio):.1f}x, range {min(ratio):.1f}-{max(ratio):.1f}x over the {len(both)} cases both meshed")
    return out


def page(rows: list[dict], pictures: list[str], command: str, load: str = "") -> str:
    """The Markdown page of ``docs/parts.md``."""
    crit = criteria(rows)
    n_parts = len(dict.fromkeys(r["part"] for r in rows))
    lines = [
        "# Engineering parts beside gmsh",
        "",
        f"{n_parts} parts of the kinds a meshing engineer brings (`examples/parts/`, written by",
        "`scripts/make_parts.py` from exact geometry: round holes, fillets, arcs, the airfoil and the cam are",
        "densely sampled curves, at most 3 degrees apart; `examples/parts/truth/` holds each part's exact area,",
        "its pieces and its corners, every point where the outline turns by more than 30 degrees), meshed by",
        "`jaxmatch mesh` and by gmsh's quasi-structured quads (`Mesh.Algorithm = 11`, curved stretches as",
        "splines, straight sides as lines, size 2h because it cuts each triangle into quads) at h = outer",
        "perimeter / 40 and / 80. Both meshes are read back with meshio and measured by",
        "`scripts/part_measures.py` (numpy and shapely, no jaxmatch code). Produced by",
        "",
        "```bash",
        command,
        "```",
        "",
        "Valid: all quads, no fold (every corner Jacobian positive, one orientation), the boundary edges form",
        "one closed loop per input ring, every corner a vertex (within 1e-6 of the part's extent), every",
        "boundary vertex within 0.01 h of the input rings, area within 1 % of the exact area. Min / mean SJ:",
        "per quad the smallest scaled Jacobian of its corners, then min / mean over quads. Irregular:",
        "interior vertices of valence other than 4. Time: the whole command for jaxmatch (start-up",
        "included), the whole worker process for gmsh (Python start, geometry, meshing, writing). A regular",
        "12-gon turns by exactly 30 degrees at its vertices, so it has no corners by the rule.",
        f"{load}Each cell: jaxmatch / gmsh.",
        "",
        table(rows),
        "",
    ]
    bad = problems(rows)
    if bad:
        lines += ["Errors and invalid meshes:", "", *bad, ""]
    lines += worst(rows) + [""]
    lines += ["## The pass criteria of the issue", "", "| criterion | cases met | pass |", "|---|---:|---|"]
    for text, met, n, ok, note in crit:
        cases = f"{note} over {n} cases" if met is None else f"{met} of {n}"
        lines.append(f"| {text} | {cases} | {'yes' if ok else 'no'} |")
    missed = band_misses(rows)
    if missed:
        lines += ["", "Off the size band where gmsh is in it: " + ", ".join(missed)
                  + " (why: [meshing.md](meshing.md), \"The size band\")."]
    lines += ["", "## Rerunning", "", "```bash",
              ".venv/bin/python scripts/make_parts.py     # writes examples/parts/ and examples/parts/truth/",
              ".venv/bin/python scripts/parts_table.py --parts gear,keyhole --fractions 40 --json   # rows as JSON",
              ".venv/bin/python scripts/parts_table.py --parts gear --explicit-corners   # the truth's corners given",
              ".venv/bin/python scripts/parts_table.py --no-gmsh --out meshes   # jaxmatch only, mesh files kept",
              "```", "", "A part jaxmatch cannot mesh, or one past `--timeout` (120 s), is a row with its error.",
              "", "## Pictures at h = P/40", "", "jaxmatch left, gmsh right; blue: the input rings, black squares: corners.", ""]
    lines += [f"![{p}](parts/{p})" for p in pictures]
    return "\n".join(lines) + "\n"


def parse_ints(text: str, what: str) -> list[int]:
    try:
        vals = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        vals = []
    if not vals or any(v < 1 for v in vals):
        raise typer.BadParameter(f"{what}: expected positive integers separated by commas, got {text!r}")
    return vals


@app.command()
def main(parts: Optional[str] = typer.Option(None, help="Comma-separated part names (default: all)."),
         fractions: str = typer.Option("40,80", help="h = outer perimeter / each of these."),
         out: Optional[Path] = typer.Option(None, help="Folder for the mesh files (default: a new temporary folder)."),
         json_rows: bool = typer.Option(False, "--json", help="Print one JSON object per part and fraction."),
         doc: Optional[Path] = typer.Option(None, help="Write the Markdown page here and its pictures into parts/ beside it."),
         timeout: float = typer.Option(120.0, help="Seconds per mesher run before it is a timeout row."),
         explicit_corners: bool = typer.Option(False, help="Give jaxmatch the truth's corners explicitly."),
         no_gmsh: bool = typer.Option(False, "--no-gmsh", help="jaxmatch only (quicker while tuning).")) -> None:
    """jaxmatch beside gmsh on the engineering parts, measured independently."""
    known = part_names()
    names = known if parts is None else [p.strip() for p in parts.split(",") if p.strip()]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise typer.BadParameter(f"--parts: unknown part(s) {', '.join(unknown) or '(none given)'} (known: {', '.join(known)})")
    fracs = parse_ints(fractions, "--fractions")
    out = Path(tempfile.mkdtemp(prefix="parts-")) if out is None else out
    out.mkdir(parents=True, exist_ok=True)
    rows, pictures = [], []
    load0 = os.getloadavg()[0]
    for name in names:
        for f in fracs:
            row, meshes = mesh_case(name, f, out, timeout=timeout, gmsh=not no_gmsh, explicit_corners=explicit_corners)
            rows.append(row)
            if json_rows:
                print(json.dumps(row), flush=True)
            else:
                print(f"{name} P/{f}: " + ", ".join(
                    f"{m} {'error' if 'error' in row[m] else ('valid' if row[m]['valid'] else 'NOT valid')}"
                    f" {row[m].get('seconds', 0):.2f} s" for m in METHODS if m in row), file=sys.stderr, flush=True)
            if doc is not None and f == fracs[0]:
                folder = doc.parent / "parts"
                folder.mkdir(parents=True, exist_ok=True)
                d, t = load_part(name)
                picture(name, f, row["h"], meshes, row, d, t, folder / f"{name}.png")
                pictures.append(f"{name}.png")
    if not json_rows:
        print(table(rows))
        print("\n".join(problems(rows) + worst(rows)))
        for text, met, n, ok, note in criteria(rows) if not no_gmsh else []:
            print(f"{'PASS' if ok else 'FAIL'} {note + ' over ' + str(n) if met is None else f'{met}/{n}'}: {text}")
    print(f"meshes in {out}", file=sys.stderr)
    if doc is not None:
        args = [a for i, a in enumerate(sys.argv[1:]) if a != "--out" and not a.startswith("--out=")
                and (i == 0 or sys.argv[i] != "--out")]  # the mesh folder is the runner's own
        argv = " ".join(a if a.replace(",", "").replace("/", "").replace(".", "").replace("-", "").isalnum() else repr(a)
                        for a in args)
        tmp = doc.with_suffix(".md.tmp")
        load = (f"Run on a machine of {os.cpu_count()} CPUs (load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the "
                "end): the times are of that machine. ")
        tmp.write_text(page(rows, pictures, f".venv/bin/python scripts/parts_table.py {argv}".strip(), load))
        os.replace(tmp, doc)
        print(f"wrote {doc}", file=sys.stderr)


if __name__ == "__main__":
    if len(sys.argv) == 6 and sys.argv[1] == "--gmsh-worker":
        gmsh_worker(*sys.argv[2:])
    else:
        from jaxmatch.cli import run_typer

        run_typer(app)
