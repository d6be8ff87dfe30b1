"""The labels file of ``jaxmatch label``: safe appends, resume, tuning from its labels.

Format
------
The JSON-lines format of :mod:`jaxmatch.tuning.labels` (what ``scripts/tune_lattice.py``
reads), one choice per line::

    {"shape": "../examples/lshape.json", "preferred": "k2-8240c8ef24de", "rotation": 0, "reflected": false}
    {"shape": {"boundary": [[0, 0], [1, 0], [1, 1], [0, 1]]}, "preferred": "k2-...", "rotation": 3, "reflected": false}

* ``shape``: a shape given on the command line is written as its path relative to the labels
  file's folder (so the file can be moved with its shapes); a drawn or dropped shape is written
  inline, ``{"boundary": [[x, y], ...], "corners": [i, ...]}`` in the user's units (``corners``
  only when the shape has corners).
* ``preferred``: the chosen catalogue id; ``rotation``/``reflected``: the orientation in which
  that mesh was ranked and shown (:mod:`jaxmatch.scoring.exact`'s convention).
* "none of these" is written as a comment line (``# none of these: {...}``), which the tuner
  skips; "skip" writes nothing.
* A shape chosen again gets a new line: the page and :func:`tune_labels` use the last line of
  each shape; ``scripts/tune_lattice.py`` reads every label line.

Safety
------
:meth:`LabelStore.append` writes one whole line with one ``write`` on a file opened with
``O_APPEND``, under a thread lock and an exclusive ``flock`` (two tabs, two servers), then
``fsync``\\ s it before returning, so a confirmed label survives a killed server. A write that
fails part-way is truncated back, so no half line stays; a half line left by something else is
closed with a newline before the next label.
"""

from __future__ import annotations

import fcntl
import json
import os
import threading
from pathlib import Path
from typing import Callable, NamedTuple

from jaxmatch.errors import InputError
from jaxmatch.files import read_limited
from jaxmatch.inputs import load_catalogue
from jaxmatch.lazy import Later
from jaxmatch.scoring.lattice import BUILTIN_DIR, load_lattice, save_lattice
from jaxmatch.tuning.labels import example_record, load_labels, mesh_index

_later = Later(tune="jaxmatch.tuning.tune")
"""The lattice tuner (JAX and optax): only when the page's tune action or ``label --tune`` runs."""

__all__ = ["NONE_PREFIX", "LabelStore", "Mark", "shape_key", "tune_labels"]

NONE_PREFIX = "# none of these: "
"""Start of the comment line that records "none of these" for a shape."""


def shape_key(spec) -> str:
    """A string that identifies a label record's ``shape`` value (a path, or an inline object)."""
    return spec if isinstance(spec, str) else json.dumps(spec, sort_keys=True, separators=(",", ":"))


class Mark(NamedTuple):
    """What the labels file says about one shape (its last line): ``preferred`` is a mesh id,
    or None for "none of these"; ``line`` is the 1-based line number."""

    preferred: str | None
    line: int


class LabelStore:
    """Appends label lines to ``path`` safely and reads back the marks of a file.

    path: the JSON-lines labels file (created on the first append; its folder must exist).
    """

    MAX_BYTES = 64 * 2**20

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._lock = threading.Lock()

    # -- reading ------------------------------------------------------------------------------

    def records(self) -> list[tuple[int, dict | None, str]]:
        """``(line number, record, kind)`` for each label line: kind ``"label"`` (record as in
        the file) or ``"none"`` (``{"shape": ...}``); blank, comment and broken lines are left out
        (the tuner reports broken ones)."""
        if not self.path.exists():
            return []
        text = read_limited(self.path, self.MAX_BYTES, "labels file").decode("utf-8-sig", errors="replace")
        out = []
        for lineno, line in enumerate(text.splitlines(), start=1):
            body = line.strip()
            kind = "label"
            if body.startswith(NONE_PREFIX.strip()):
                body, kind = body[len(NONE_PREFIX.strip()):].strip(), "none"
            elif not body or body.startswith("#"):
                continue
            try:
                rec = json.loads(body)
            except ValueError:
                continue
            if isinstance(rec, dict) and isinstance(rec.get("shape"), (str, dict)):
                if kind == "none" or isinstance(rec.get("preferred"), str):
                    out.append((lineno, rec, kind))
        return out

    def marks(self) -> dict[str, Mark]:
        """``shape_key -> Mark`` of the last line of each shape."""
        marks = {}
        for lineno, rec, kind in self.records():
            marks[shape_key(rec["shape"])] = Mark(rec.get("preferred") if kind == "label" else None, lineno)
        return marks

    # -- writing ------------------------------------------------------------------------------

    def append(self, line: str) -> None:
        """Append one line (no newline inside) durably: whole or not at all, flushed and fsynced.

        Raises :class:`InputError` naming the file when it cannot be written.
        """
        if "\n" in line or "\r" in line:
            raise ValueError("a label line must not contain a line break")
        data = (line + "\n").encode("utf-8")
        with self._lock:
            try:
                created = not self.path.exists()
                fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o666)
            except OSError as err:
                raise InputError(f"cannot write labels: {err.strerror or err}", where=str(self.path)) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX)
                size = os.fstat(fd).st_size
                if size and os.pread(fd, 1, size - 1) != b"\n":
                    data = b"\n" + data  # close a half line someone else left
                try:
                    view = memoryview(data)
                    while view:
                        view = view[os.write(fd, view):]
                    os.fsync(fd)
                except OSError as err:
                    try:
                        os.ftruncate(fd, size)  # no half line stays
                    except OSError:
                        pass
                    raise InputError(f"cannot write labels: {err.strerror or err}", where=str(self.path)) from None
            finally:
                os.close(fd)  # releases the flock
            if created:
                _fsync_dir(self.path.parent)

    def add_label(self, spec, preferred: str, rotation: int, reflected: bool) -> dict:
        """Append a label record (the :mod:`jaxmatch.tuning.labels` format); returns it."""
        rec = example_record(spec, preferred, rotation=rotation, reflected=reflected)
        self.append(json.dumps(rec, separators=(", ", ": ")))
        return rec

    def add_none(self, spec, shown: list[str]) -> dict:
        """Append "none of these" for a shape (a comment line the tuner skips); returns it."""
        rec = {"shape": spec, "shown": list(shown)}
        self.append(NONE_PREFIX + json.dumps(rec, separators=(", ", ": ")))
        return rec


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def tune_labels(labels: str | os.PathLike, out: str | os.PathLike, *, lattice: str = "fine", catalogue=None,
                epochs: int = 10, heldout: float = 0.25, seed: int = 0, max_candidates: int | None = 256,
                stage: Callable[[str], None] | None = None) -> dict:
    """Tune ``lattice`` on the labels of ``labels`` (as ``scripts/tune_lattice.py`` does, with its
    defaults) and write the tuned lattice TOML to ``out`` atomically.

    The last line of each shape decides (a shape relabelled counts once, a shape whose last line
    is "none of these" not at all); bad lines are skipped and counted. Returns a summary: ``examples``, ``skipped``, ``out``, ``seconds`` and, for
    ``train`` and ``heldout``, ``examples`` and ``top1``/``top5`` ``before``/``after`` (fractions
    in [0, 1], None without examples). Raises :class:`InputError` when there are fewer than 2
    labels.
    """
    cat = load_catalogue(catalogue)
    index = mesh_index(cat)
    lat = load_lattice(lattice)
    if not Path(labels).exists():
        raise InputError("no labels yet: choose a preferred mesh for some shapes first", where=str(labels))
    loaded = load_labels(labels, index, skip_bad=True)
    marks = LabelStore(labels).marks()  # the last line of each shape decides ("none of these" included)
    examples = [ex for ex in loaded.examples
                if (m := marks.get(shape_key(ex.record["shape"]))) is not None and f"{Path(labels)}:{m.line}" == ex.where]
    if len(examples) < 2:
        raise InputError(f"tuning needs at least 2 labelled shapes, the file has {len(examples)}", where=str(labels))
    tuned, rep = _later.tune.run_tuning(lat, examples, cat, heldout=heldout, seed=seed, epochs=epochs,
                                        max_candidates=max_candidates, stage=stage)
    save_lattice(tuned, out, template=_template(lattice))
    load_lattice(out)  # what was written loads
    summary = {"examples": len(examples), "skipped": len(loaded.problems), "out": str(out), "lattice": lat.name,
               "tuned": tuned.name, "seconds": rep.get("seconds")}
    for key in ("train", "heldout"):
        b, a = rep[key]["before"], rep[key]["after"]
        summary[key] = {"examples": b["examples"], "top1": {"before": b["top1"], "after": a["top1"]},
                        "top5": {"before": b["top5"], "after": a["top5"]}}
    return summary


def _template(lattice: str) -> str | None:
    """The input lattice's TOML text (its comments are kept in the tuned file), or None."""
    path = Path(lattice)
    if not path.is_file():
        path = BUILTIN_DIR / f"{lattice}.toml"
    if not path.is_file():
        return None
    return "# Level weights tuned by 'jaxmatch label --tune' from the labels of the page.\n" + path.read_text(encoding="utf-8")
