"""Atomic file writing and bounded file reading.

Writing: to a temporary name in the same folder, then rename. An interrupted write leaves the
previous file (if any) untouched and no partial file under the final name. The temporary is
``.<stem>.<pid>-<random>.tmp<suffix>`` beside the final file (hidden, never the final name, and
never read by jaxmatch). A process killed while writing cannot remove its temporary; the next
successful write of the same file removes such leftovers of processes that are gone (or that
are older than :data:`STALE_SECONDS`).

Reading: :func:`read_limited` reads at most a given number of bytes, so a huge file, a device
such as ``/dev/zero`` or an endless pipe cannot make a reader hang or exhaust memory.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
import time
from pathlib import Path
from typing import IO, Iterator

from jaxmatch.errors import InputError

STALE_SECONDS = 3600.0
"""A leftover temporary this old is removed even if its process id is in use again."""


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):  # someone else's process, or no way to tell
        return True
    return True


def _remove_stale(final: Path) -> None:
    """Remove leftover temporaries of ``final`` whose writer is gone (best effort)."""
    pattern = re.compile(rf"^\.{re.escape(final.stem)}\.(\d+)-[A-Za-z0-9_]+\.tmp{re.escape(final.suffix)}$")
    try:
        siblings = list(os.scandir(final.parent))
    except OSError:
        return
    now = time.time()
    for entry in siblings:
        m = pattern.match(entry.name)
        if not m:
            continue
        try:
            if not entry.is_file(follow_symlinks=False):
                continue
            old = now - entry.stat(follow_symlinks=False).st_mtime > STALE_SECONDS
            if old or not _alive(int(m.group(1))):
                os.unlink(entry.path)
        except (OSError, ValueError):
            pass


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    For writers that want a file name (matplotlib, meshio, numpy). The temporary keeps
    the final suffix so that format detection by extension still works. Operating-system
    errors (no permission, no space, the target is a folder) become :class:`InputError`
    naming ``path``; the previous file is left as it was and the temporary is removed.
    """
    final = Path(path)
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{final.stem}.{os.getpid()}-", suffix=f".tmp{final.suffix}", dir=final.parent)
        os.close(fd)
    except OSError as err:
        raise InputError(f"cannot write file: {err.strerror or err}", where=str(final)) from None
    tmp_path = Path(tmp)
    try:
        try:
            yield tmp_path
            if final.is_dir():
                raise IsADirectoryError(21, "Is a directory")
            with open(tmp_path, "rb+") as fh:
                os.fsync(fh.fileno())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
            os.replace(tmp_path, final)
        except OSError as err:
            raise InputError(f"cannot write file: {err.strerror or err}", where=str(final)) from None
        _remove_stale(final)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


@contextlib.contextmanager
def atomic_folder(finals: list) -> Iterator[Path]:
    """Yield a temporary folder beside ``finals[0]`` for writers that make several files at once
    (XDMF and its HDF5 file): on success each of ``finals`` (paths) is moved from the folder into
    place, the ones listed last last; the folder is removed either way. Operating-system errors
    become :class:`InputError` naming ``finals[0]``."""
    finals = [Path(f) for f in finals]
    parent = finals[0].parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmpdir = Path(tempfile.mkdtemp(prefix=f".{finals[0].stem}.{os.getpid()}-", dir=parent))
    except OSError as err:
        raise InputError(f"cannot write file: {err.strerror or err}", where=str(finals[0])) from None
    try:
        yield tmpdir
        for f in finals:
            os.replace(tmpdir / f.name, f)
    except OSError as err:
        raise InputError(f"cannot write file: {err.strerror or err}", where=str(finals[0])) from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", encoding: str | None = "utf-8") -> Iterator[IO]:
    """Open a temporary file beside ``path`` for writing; rename onto ``path`` on success."""
    if "b" in mode:
        encoding = None
    with atomic_path(path) as tmp:
        with open(tmp, mode, encoding=encoding) as fh:
            yield fh


def write_text_atomic(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path, "w") as fh:
        fh.write(text)


_PIECE = 1 << 16
"""Bytes :func:`read_limited` asks for at a time beyond the size a file reports (a pipe, a device,
a file still growing)."""


def read_limited(path: str | os.PathLike, limit: int, what: str = "file") -> bytes:
    """The bytes of ``path``, at most ``limit`` of them.

    Raises :class:`InputError` (``where=str(path)``) when the file cannot be read (missing, a
    folder, no permission) or holds more than ``limit`` bytes. Reads at most ``limit + 1``
    bytes, so devices and pipes cannot make it hang on an endless input. Reads the size the file
    reports first, then in pieces (``read(limit + 1)`` at once sets aside ``limit + 1`` bytes: 37 us
    of 16 MiB to read a 13 kB lattice file, which every meshing call reads).
    """
    src = str(path)
    try:
        with open(path, "rb") as fh:
            want = min(os.fstat(fh.fileno()).st_size + 1, limit + 1)
            parts, got = [], 0
            while got <= limit:
                part = fh.read(min(want, limit + 1 - got))
                if not part:
                    break
                parts.append(part)
                got += len(part)
                want = _PIECE
            data = b"".join(parts)
    except OSError as err:
        raise InputError(f"cannot read {what}: {err.strerror or err}", where=src) from None
    if len(data) > limit:
        raise InputError(f"{what} is larger than {limit} bytes", where=src)
    return data
