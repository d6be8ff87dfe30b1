"""Labelled shapes for lattice tuning: label files, a synthetic generator, the designer rule.

Label files (JSON lines)
------------------------
One example per line, a JSON object::

    {"shape": "shapes/lshape.json", "preferred": "k3-0123456789ab"}
    {"shape": {"boundary": [[0, 0], [2, 0], [2, 1], [0, 1]], "corners": [0, 1, 2, 3]},
     "preferred": "k3-...", "rotation": 2, "reflected": false, "note": "why"}

* ``shape``: a shape file path (relative paths are resolved against the label file's folder;
  JSON or text, as ``jaxmatch score`` reads them) or an inline shape object
  ``{"boundary": [[x, y], ...], "corners": [i, ...]}`` (``corners`` optional);
* ``preferred``: the stable catalogue id ``k<K>-<hex>`` of the preferred mesh; its size ``K``
  (internal vertices) is the size the user fixed: the mesh competes with the catalogue meshes
  of the same size;
* ``rotation`` (int >= 0, less than the mesh's boundary length) and ``reflected`` (bool),
  optional: the preferred orientation in :mod:`jaxmatch.scoring.exact`'s convention. They are
  validated and kept on :class:`Example` but not used by the tuner's loss (see
  :mod:`jaxmatch.tuning.tune`);
* ``note``, optional: free text (e.g. why the label was chosen).

Blank lines and lines whose first non-blank character is ``#`` are skipped. Any other problem
(not JSON, unknown or missing keys, bad values, unknown mesh id, unreadable or invalid shape)
is an :class:`~jaxmatch.errors.InputError` with ``where="<file>:<line>"``;
:func:`load_labels` raises the first one, or with ``skip_bad=True`` collects them all and
keeps the good lines.

Ideal mesh boundaries
---------------------
A boundary vertex of valence ``v`` lies in ``v - 1`` quads, so its ideal interior angle is
``(v - 1) * 90`` degrees: the boundary turns by ``(3 - v) * 90`` (valence 2: +90, a convex
corner; 3: straight; 4: -90, a concave corner; 5: -180, clipped to -135 here, a sharp notch).
These turns add up to 360 degrees only when all internal vertices are regular (sum over the
boundary of ``3 - v`` is ``4 - sum over internal vertices of (4 - v)``); :func:`ideal_turns`
spreads the difference evenly over all boundary vertices so that the ideal boundary closes.
Drawn with equal edge lengths it is the mesh's *ideal outline*. Both the synthetic generator
and the designer rule use it; neither looks at any lattice.

Synthetic shapes (:func:`synthetic_examples`)
---------------------------------------------
For every catalogue mesh of size ``k``: walk its ideal outline with perturbed turns
(Gaussian, ``turn_noise``) and log-normal edge lengths (``length_var``), close the walk by
spreading the closing error along it, jitter the vertices (``jitter``, relative to the mean
edge), bend a random part of the edges into curved polylines (parabolic arcs, ``curve_prob``,
up to ``max_bend``), mark the vertices of valence other than 3 as explicit corners, and keep
the shape when :func:`jaxmatch.shape.make_shape` accepts it (no self-intersection) and every
corner's convexity matches its valence (2 convex; 4, 5 concave); otherwise draw again (at
most ``tries`` times, then the mesh is skipped). The label is the source mesh, or, when other
meshes of size ``k`` have the same boundary valence cycle up to rotation and reflection (no
lattice and no outline can tell them apart), the one with the smallest id. Everything is
drawn from ``numpy.random.default_rng(seed)`` in catalogue order: same seed, same file.

Designer rule (:func:`design_ranking`)
--------------------------------------
A mechanical stand-in for a designer's choice among the meshes of the size ``k`` the user
fixed; it never looks at a lattice. In order:

1. *corners*: valence-2 vertices belong on convex corners and valence-4/5 vertices on concave
   corners. The shape's corner cycle (``x`` convex, ``v`` concave, in loop order) is compared
   with the mesh's (``x`` for each valence-2 vertex, ``v`` for each valence 4 or 5; valence 3
   is no corner) by the cyclic edit distance (insertions and deletions cost 1, an ``x``/``v``
   swap 2; minimised over rotations and the mirror image): the number of corners that do not
   meet a mesh corner of their kind plus mesh corners left over. Keep the meshes with the
   smallest distance.
2. *fit and spacing*: among them, compare the shape's *turning function* (cumulative turning
   angle against arc length, perimeter scaled to 1) with the mesh's ideal outline drawn with
   equal edges (so mesh vertices spread evenly along the boundary), minimised over the start
   position (a grid of ``samples`` positions), the mirror image and a constant angle offset, as
   the root-mean-square difference in radians (the L2 turning-function distance of Arkin et
   al., 1991); keep those within ``tolerance`` (relative, default 10 %) of the best.
3. *regularity*: among them, fewest irregular internal vertices (valence other than 4);
4. then the smaller turning distance; then the smaller id.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from jaxmatch.catalogue.store import Catalogue
from jaxmatch.errors import InputError
from jaxmatch.files import read_limited
from jaxmatch.catalogue.mesh import valences
from jaxmatch.io.readers import load_shape, parse_shape
from jaxmatch.shape import Shape, make_shape, turning_angles, cumulative_length

__all__ = [
    "Example",
    "LabelSet",
    "MeshIndex",
    "boundary_key",
    "corner_cycle",
    "cyclic_edit_distance",
    "design_ranking",
    "dump_labels",
    "example_record",
    "ideal_turns",
    "irregular_internal",
    "load_labels",
    "mesh_index",
    "parse_label_line",
    "parse_labels",
    "shape_corner_cycle",
    "synthetic_examples",
    "synthetic_shape",
    "turning_distances",
]

_ID_RE = re.compile(r"^k(\d+)-[0-9a-f]+$")
_KEYS = ("shape", "preferred", "rotation", "reflected", "note")


# ---------------------------------------------------------------------------------------------
# catalogue index


class MeshIndex(NamedTuple):
    """Where each catalogue mesh is: ``id -> (k, n, row in bucket n)``, and meshes per size.

    by_k: ``k -> list of ids`` in ranking order (shorter boundary first, then id), the order
    ``jaxmatch score --internal K`` uses among equal utilities.
    """

    where: dict
    by_k: dict
    vals: dict  # id -> (n,) int32 boundary valences (ccw)


def mesh_index(catalogue: Catalogue) -> MeshIndex:
    """Index every mesh of ``catalogue`` (ids, sizes, boundary valences)."""
    where, by_k, vals = {}, {}, {}
    for b in catalogue.buckets():
        for i, (mid, k) in enumerate(zip(b.ids.tolist(), b.k.tolist())):
            where[mid] = (int(k), int(b.n), i)
            vals[mid] = np.asarray(b.valences[i], np.int32)
    for mid, (k, n, _) in sorted(where.items(), key=lambda kv: (kv[1][0], kv[1][1], kv[0])):
        by_k.setdefault(k, []).append(mid)
    return MeshIndex(where, by_k, vals)


def boundary_key(vals) -> tuple[int, ...]:
    """The boundary valence cycle up to rotation and reflection (lexicographically smallest)."""
    v = [int(x) for x in np.asarray(vals).reshape(-1)]
    n = len(v)
    r = v[::-1]
    return min(min(tuple(v[i:] + v[:i]) for i in range(n)), min(tuple(r[i:] + r[:i]) for i in range(n)))


def irregular_internal(catalogue: Catalogue, mesh_id: str) -> int:
    """Number of internal vertices of valence other than 4."""
    m = catalogue.mesh(mesh_id)
    val = valences(m.quads, m.n_vertices)
    internal = np.ones(m.n_vertices, bool)
    internal[m.boundary] = False
    return int(np.sum(val[internal] != 4))


# ---------------------------------------------------------------------------------------------
# label files


@dataclass(frozen=True, eq=False)
class Example:
    """One labelled shape.

    shape: the validated shape; preferred: mesh id; k: its internal vertices;
    rotation, reflected: the optional preferred orientation (None when absent);
    where: ``"<file>:<line>"``; note: free text; record: the JSON object as read (inline
    shapes stay inline, paths stay paths).
    """

    shape: Shape
    preferred: str
    k: int
    rotation: int | None = None
    reflected: bool | None = None
    where: str = "<labels>"
    note: str = ""
    record: dict = field(default_factory=dict)


class LabelSet(NamedTuple):
    """Result of :func:`load_labels`: the good examples and the problems (skipped lines)."""

    examples: list
    problems: list


def _short(value, limit: int = 60) -> str:
    r = json.dumps(value) if not isinstance(value, str) else repr(value)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def _reject_constant(name):
    raise ValueError(f"{name} is not a finite number")


def parse_label_line(text: str, where: str, index: MeshIndex, base_dir: Path | None = None) -> Example:
    """Parse one JSON-lines record (see the module docstring); InputError at ``where``."""
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as err:
        raise InputError(f"not valid JSON: {err.msg} (column {err.colno})", where=where) from None
    except (ValueError, RecursionError) as err:
        raise InputError(f"not valid JSON ({err})", where=where) from None
    if not isinstance(doc, dict):
        raise InputError('a label line must be a JSON object {"shape": ..., "preferred": ...}', where=where)
    unknown = [k for k in doc if k not in _KEYS]
    if unknown:
        raise InputError(f"unknown key {_short(unknown[0])} (allowed: {', '.join(_KEYS)})", where=where)
    for key in ("shape", "preferred"):
        if key not in doc:
            raise InputError(f'missing key "{key}"', where=where)
    pid = doc["preferred"]
    if not isinstance(pid, str) or not _ID_RE.match(pid):
        raise InputError(f'"preferred" must be a catalogue id like "k3-0123456789ab", got {_short(pid)}', where=where)
    if pid not in index.where:
        raise InputError(f"mesh {pid} is not in the catalogue", where=where)
    k, n, _ = index.where[pid]
    rotation = doc.get("rotation")
    if rotation is not None and (isinstance(rotation, bool) or not isinstance(rotation, int) or not 0 <= rotation < n):
        raise InputError(f'"rotation" must be an integer in 0..{n - 1} (mesh {pid} has {n} boundary vertices), got {_short(rotation)}', where=where)
    reflected = doc.get("reflected")
    if reflected is not None and not isinstance(reflected, bool):
        raise InputError(f'"reflected" must be true or false, got {_short(reflected)}', where=where)
    note = doc.get("note", "")
    if not isinstance(note, str):
        raise InputError(f'"note" must be a string, got {_short(note)}', where=where)
    spec = doc["shape"]
    if isinstance(spec, str):
        path = Path(spec)
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        try:
            shape = load_shape(path)
        except InputError as err:
            raise InputError(f"shape {spec}: {err.problem}", where=where) from None
    elif isinstance(spec, dict):
        shape = parse_shape(json.dumps(spec), where, fmt="json")
    else:
        raise InputError(f'"shape" must be a file path or an object {{"boundary": ...}}, got {_short(spec)}', where=where)
    return Example(shape=shape, preferred=pid, k=k, rotation=rotation, reflected=reflected, where=where, note=note, record=doc)


def parse_labels(text: str, source: str, index: MeshIndex, *, base_dir: Path | None = None, skip_bad: bool = False) -> LabelSet:
    """Parse label-file text; ``where`` of each problem is ``"<source>:<line>"``."""
    examples, problems = [], []
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.strip()
        if not body or body.startswith("#"):
            continue
        try:
            examples.append(parse_label_line(body, f"{source}:{lineno}", index, base_dir))
        except InputError as err:
            if not skip_bad:
                raise
            problems.append(err)
    return LabelSet(examples, problems)


MAX_LABEL_BYTES = 64 * 2**20
"""Largest label file read (bytes)."""


def load_labels(path, catalogue_or_index, *, skip_bad: bool = False) -> LabelSet:
    """Read a JSON-lines label file (see the module docstring).

    Raises the first bad line's :class:`InputError` (``where="<path>:<line>"``) unless
    ``skip_bad``; then bad lines are skipped and returned in ``problems``. A file without any
    example is an InputError either way.
    """
    index = catalogue_or_index if isinstance(catalogue_or_index, MeshIndex) else mesh_index(catalogue_or_index)
    p = Path(path)
    raw = read_limited(p, MAX_LABEL_BYTES, "label file")  # bounded: /dev/zero cannot hang it
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise InputError(f"not UTF-8 text (byte {err.start})", where=str(p)) from None
    out = parse_labels(text, str(p), index, base_dir=p.parent, skip_bad=skip_bad)
    if not out.examples:
        more = f" ({len(out.problems)} bad lines skipped)" if out.problems else ""
        raise InputError(f"no labelled examples{more}", where=str(p))
    return out


def example_record(shape_spec, preferred: str, *, note: str = "", rotation: int | None = None, reflected: bool | None = None) -> dict:
    """A label record (JSON-ready dict) in the file format."""
    rec = {"shape": shape_spec, "preferred": preferred}
    if rotation is not None:
        rec["rotation"] = int(rotation)
    if reflected is not None:
        rec["reflected"] = bool(reflected)
    if note:
        rec["note"] = note
    return rec


def dump_labels(records) -> str:
    """JSON-lines text for label records (one compact object per line)."""
    return "".join(json.dumps(r, separators=(", ", ": ")) + "\n" for r in records)


# ---------------------------------------------------------------------------------------------
# ideal outlines and turning functions

MAX_NOTCH = 0.75 * math.pi
"""Largest inward turn of an ideal outline (valence 5 would turn by pi, a degenerate fold)."""


def ideal_turns(vals) -> np.ndarray:
    """Turning angles (radians, ``(n,)``) of a mesh's ideal outline: ``(3 - v) * pi / 2``,
    clipped below at ``-MAX_NOTCH``, plus an equal share of ``2 pi - sum`` each."""
    v = np.asarray(vals, np.float64).reshape(-1)
    t = np.maximum((3.0 - v) * (math.pi / 2), -MAX_NOTCH)
    return t + (2 * math.pi - t.sum()) / t.shape[0]


def _periodic_part(pos, turns, samples: int) -> np.ndarray:
    """``Theta(s) - 2 pi s`` at ``s = (g + 0.5) / samples``: ``Theta`` steps by ``turns[i]`` at
    ``pos[i]`` in [0, 1) (the total is 2 pi)."""
    s = (np.arange(samples) + 0.5) / samples
    cum = np.concatenate([[0.0], np.cumsum(turns)])
    idx = np.searchsorted(np.asarray(pos, np.float64), s, side="right")
    return cum[idx] - 2 * math.pi * s


def shape_turning(shape: Shape, samples: int) -> np.ndarray:
    """Periodic part of the shape's turning function (perimeter scaled to 1), sampled."""
    cum = cumulative_length(shape.points)
    pos = cum[:-1] / cum[-1]
    turns = turning_angles(shape.points)
    turns = turns + (2 * math.pi - turns.sum()) / turns.shape[0]  # exactly 2 pi (round-off)
    return _periodic_part(pos, turns, samples)


def turning_fits(shape: Shape, vals_list, samples: int = 720) -> list[tuple[float, float, bool]]:
    """Best fit of each mesh's ideal outline (equal edges) to ``shape``'s turning function.

    Per mesh ``(distance, shift, reflected)``: the RMS turning-function distance (radians),
    minimised over the start position (a grid of ``samples`` positions), the mirror image and
    a constant angle offset; with the best fit, vertex ``j`` of ``vals`` (of ``vals[::-1]``
    when ``reflected``) sits at arc position ``(shift + j / n) mod 1`` (perimeter scaled to 1,
    from ``shape.points[0]``, counter-clockwise).
    """
    f = shape_turning(shape, samples)
    f = f - f.mean()
    ff = np.fft.rfft(f)
    out = []
    for vals in vals_list:
        v = np.asarray(vals).reshape(-1)
        best = (math.inf, 0.0, False)
        for refl, seq in ((False, v), (True, v[::-1])):
            n = seq.shape[0]
            g = _periodic_part(np.arange(n) / n, ideal_turns(seq), samples)
            g = g - g.mean()
            # cov[d] = mean_s f(s) g(s - d): circular cross-correlation via FFT
            cov = np.fft.irfft(ff * np.conj(np.fft.rfft(g)), n=samples) / samples
            d = int(np.argmax(cov))
            d2 = float(np.mean(f * f) + np.mean(g * g) - 2 * cov[d])
            if d2 < best[0] - 1e-12:
                best = (d2, d / samples, refl)
        out.append((math.sqrt(max(best[0], 0.0)), best[1], best[2]))
    return out


def turning_distances(shape: Shape, vals_list, samples: int = 720) -> np.ndarray:
    """The distances of :func:`turning_fits`, ``(N,) float64``."""
    return np.asarray([d for d, _, _ in turning_fits(shape, vals_list, samples)])


def corner_cycle(vals) -> str:
    """The mesh's corners in boundary order: ``x`` per valence 2, ``v`` per valence 4 or 5."""
    return "".join("x" if v == 2 else "v" for v in np.asarray(vals).reshape(-1).tolist() if v != 3)


def shape_corner_cycle(shape: Shape) -> str:
    """The shape's corners in loop order: ``x`` convex, ``v`` concave."""
    return "".join("x" if c else "v" for c in shape.convex.tolist())


def _edit(a: str, b: str) -> int:
    """Edit distance: insert/delete 1, substitute 2 (= delete + insert)."""
    prev = list(range(len(b) + 1))
    for i, ca in enumerate(a, 1):
        cur = [i] + [0] * len(b)
        for j, cb in enumerate(b, 1):
            cur[j] = min(prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (0 if ca == cb else 2))
        prev = cur
    return prev[-1]


def cyclic_edit_distance(a: str, b: str) -> int:
    """Edit distance between cyclic strings ``a`` and ``b`` (rotations of ``b`` and of its
    mirror image ``b[::-1]``; rotating one string suffices, Maes 1990)."""
    if not b:
        return len(a)
    best = len(a) + len(b)
    for seq in (b, b[::-1]):
        for r in range(len(seq)):
            best = min(best, _edit(a, seq[r:] + seq[:r]))
    return best


class DesignChoice(NamedTuple):
    """One row of :func:`design_ranking`: the corner distance, the fit and the orientation it
    implies (``rotation``/``reflected`` in :mod:`jaxmatch.scoring.exact`'s convention: the first mesh
    vertex along the boundary from the shape's first corner, by the turning fit)."""

    mesh_id: str
    corners: int
    distance: float
    irregular: int
    within_tolerance: bool
    rotation: int
    reflected: bool


def design_ranking(shape: Shape, catalogue: Catalogue, k: int, *, index: MeshIndex | None = None, tolerance: float = 0.10, samples: int = 720) -> list[DesignChoice]:
    """All meshes of size ``k`` ordered by the designer rule (module docstring); the first
    is the label."""
    index = index or mesh_index(catalogue)
    ids = index.by_k.get(k, [])
    if not ids:
        raise InputError(f"the catalogue has no mesh with {k} internal vertices", where=str(catalogue.path))
    target = shape_corner_cycle(shape)
    cache: dict = {}
    corner = []
    for mid in ids:
        cyc = corner_cycle(index.vals[mid])
        if cyc not in cache:
            cache[cyc] = cyclic_edit_distance(target, cyc)
        corner.append(cache[cyc])
    fits = turning_fits(shape, [index.vals[i] for i in ids], samples)
    best_corner = min(corner)
    limit = min(d for c, (d, _, _) in zip(corner, fits) if c == best_corner) * (1.0 + tolerance) + 1e-12
    rows = []
    for mid, c, (d, shift, refl) in zip(ids, corner, fits):
        n = index.vals[mid].shape[0]
        rotation = int(np.argmin(np.mod(shift + np.arange(n) / n + 1e-9, 1.0)))
        within = c == best_corner and d <= limit
        rows.append(DesignChoice(mid, int(c), float(d), irregular_internal(catalogue, mid), bool(within), rotation, bool(refl)))
    rows.sort(key=lambda r: (r.corners, not r.within_tolerance, r.irregular if r.within_tolerance else 0, r.distance, r.mesh_id))
    return rows


# ---------------------------------------------------------------------------------------------
# synthetic shapes


def _arc(a, b, bend: float, pieces: int) -> np.ndarray:
    """Interior points of a parabolic arc from ``a`` to ``b`` bulging left by angle ``bend``."""
    d = b - a
    normal = np.array([-d[1], d[0]])
    sag = 0.5 * math.tan(bend / 2.0)  # sagitta / chord
    t = np.arange(1, pieces) / pieces
    return a + t[:, None] * d + (4.0 * sag * t * (1.0 - t))[:, None] * normal


def synthetic_shape(vals, rng: np.random.Generator, *, turn_noise: float = 0.12, length_var: float = 0.2, jitter: float = 0.03, curve_prob: float = 0.3, max_bend: float = 0.6, pieces: int = 4, tries: int = 20) -> dict | None:
    """One perturbed outline of a mesh with boundary valences ``vals`` (module docstring):
    ``{"boundary": [[x, y], ...], "corners": [...]}`` (6 decimals), or None when ``tries``
    draws all failed. Angles in radians; ``length_var`` is the log-normal sigma."""
    v = np.asarray(vals, np.int64).reshape(-1)
    n = v.shape[0]
    base = ideal_turns(v)
    for _ in range(tries):
        noise = rng.normal(0.0, turn_noise, n)
        turns = base + noise - noise.mean()
        lengths = np.exp(rng.normal(0.0, length_var, n))
        heading = rng.uniform(0.0, 2 * math.pi) + np.cumsum(turns) - turns[0]  # edge j leaves vertex j
        steps = lengths[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        pts = np.concatenate([[np.zeros(2)], np.cumsum(steps, axis=0)])
        frac = np.concatenate([[0.0], np.cumsum(lengths)]) / lengths.sum()
        pts = (pts - frac[:, None] * pts[-1])[:-1]  # close the walk
        pts = pts + rng.normal(0.0, jitter * lengths.mean(), pts.shape)
        bends = np.where(rng.random(n) < curve_prob, rng.uniform(-max_bend, max_bend, n), 0.0)
        loop, corners = [], []
        for j in range(n):
            if v[j] != 3:
                corners.append(len(loop))
            loop.append(pts[j])
            if bends[j] != 0.0:
                loop.extend(_arc(pts[j], pts[(j + 1) % n], bends[j], pieces))
        boundary = np.round(np.asarray(loop), 6)
        try:
            shape = make_shape(boundary, corners)
        except InputError:
            continue
        # convexity per corner, in input order (make_shape rotates/reverses the loop)
        if shape.n_corners != len(corners) or not _corner_types_match(boundary, corners, v):
            continue
        return {"boundary": boundary.tolist(), "corners": corners}
    return None


def _corner_types_match(boundary: np.ndarray, corners: list, v: np.ndarray) -> bool:
    """Every corner turns the way its valence says (2: left/convex, 4 and 5: right/concave)."""
    p = boundary if _ccw(boundary) else boundary[::-1]
    turn = turning_angles(p)
    m = len(boundary)
    idx = corners if _ccw(boundary) else [(m - 1 - c) for c in corners]
    kinds = [vv for vv in v if vv != 3]
    return all((turn[i] > 0) == (kind == 2) for i, kind in zip(idx, kinds))


def _ccw(p: np.ndarray) -> bool:
    q = np.roll(p, -1, axis=0)
    return float(np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1])) > 0


def synthetic_examples(catalogue: Catalogue, k: int, *, variants: int = 2, seed: int = 0, index: MeshIndex | None = None, **shape_options) -> tuple[list[dict], list[str]]:
    """Label records for perturbed outlines of every mesh of size ``k`` (module docstring).

    Returns ``(records, skipped ids)``; records carry the shape inline and a note naming the
    source mesh. ``shape_options`` go to :func:`synthetic_shape`.
    """
    index = index or mesh_index(catalogue)
    ids = index.by_k.get(k, [])
    if not ids:
        raise InputError(f"the catalogue has no mesh with {k} internal vertices", where=str(catalogue.path))
    rep: dict = {}
    for mid in ids:  # ids are sorted within k by (n, id): the first of a twin class is the smallest id
        rep.setdefault(boundary_key(index.vals[mid]), mid)
    rng = np.random.default_rng(seed)
    records, skipped = [], []
    for mid in ids:
        label = rep[boundary_key(index.vals[mid])]
        for j in range(variants):
            spec = synthetic_shape(index.vals[mid], rng, **shape_options)
            if spec is None:
                skipped.append(mid)
                continue
            note = f"synthetic: outline of {mid}, variant {j}" + ("" if label == mid else f" (same boundary as {label})")
            records.append(example_record(spec, label, note=note))
    return records, skipped
