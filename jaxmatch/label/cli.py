"""``jaxmatch label``: the command behind the thin typer command in :mod:`jaxmatch.cli`."""

from __future__ import annotations

import sys
from pathlib import Path

from jaxmatch.errors import InputError
from jaxmatch.label.store import tune_labels
from jaxmatch.lazy import Later

__all__ = ["run_label"]

_later = Later(app="jaxmatch.label.app")
"""The web app (starlette, uvicorn): not for ``label --tune``."""


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}%"


def run_label(shapes, labels: Path, *, internal=None, size=None, top: int = 5, port: int = 8765, host: str = "127.0.0.1",
              lattice: str = "fine", catalogue=None, corner_angle=None, tune: bool = False, out=None, epochs: int = 10) -> None:
    """Serve the labelling page (prints ``http://HOST:PORT/``) or, with ``tune``, tune the lattice
    on ``labels`` and write it to ``out``. Bad input: :class:`InputError` naming the option.
    (The command enables the compiled-code cache before calling this.)"""
    if tune:
        if out is None:
            raise InputError("--tune needs --out FILE (where the tuned lattice is written)", where="--out")
        if shapes:
            raise InputError("--tune reads the labels file; give no shapes", where="--tune")
        r = tune_labels(labels, out, lattice=lattice, catalogue=catalogue, epochs=epochs,
                        stage=lambda text: print(text, file=sys.stderr, flush=True))
        print(f"{r['examples']} labelled shapes ({r['skipped']} bad lines skipped); {r['lattice']} -> {r['tuned']}")
        print(f"{'set':8} {'shapes':>6} {'top-1 before':>13} {'top-1 after':>12} {'top-5 before':>13} {'top-5 after':>12}")
        for key in ("train", "heldout"):
            s = r[key]
            print(f"{key:8} {s['examples']:>6} {_pct(s['top1']['before']):>13} {_pct(s['top1']['after']):>12} "
                  f"{_pct(s['top5']['before']):>13} {_pct(s['top5']['after']):>12}")
        print(f"wrote {r['out']} ({r['seconds']} s)")
        return
    if not host or any(c.isspace() for c in host):
        raise InputError(f"expected a host name or address, got {host!r}", where="--host")
    session = _later.app.LabelSession(shapes, labels, internal=internal, top=top, size=size, out=out, lattice=lattice,
                           catalogue=catalogue, corner_angle=corner_angle, epochs=epochs)
    if host not in ("127.0.0.1", "localhost", "::1"):
        print(f"warning: listening on {host}: anyone who can reach it can read the shapes and add labels", file=sys.stderr)
    st = session.state()

    def announce(url: str) -> None:  # once the port is bound (a busy port stays a one-line error)
        print(f"{st['total']} shapes, {st['labelled']} labelled in {labels}; Ctrl-C stops", file=sys.stderr, flush=True)
        print(url, flush=True)

    _later.app.serve(session, host, port, announce=announce)
