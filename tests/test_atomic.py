"""Atomic writes: every file jaxmatch writes appears complete or not at all.

Design (:mod:`jaxmatch.files`): a writer writes ``.<stem>.<pid>-<random>.tmp<suffix>`` in the
target's folder, fsyncs it and renames it onto the target. A failed or interrupted write
leaves the previous file byte-identical. A process that is killed (SIGKILL) cannot remove its
temporary; such a leftover is hidden, never read, and the next successful write of the same
target removes it (its process is gone). Write errors (no permission, the target is a folder,
disk full) are one-line :class:`InputError`\\ s naming the target (CLI: exit 2).
"""

from __future__ import annotations

import ast
import errno
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from jaxmatch.catalogue import store as cm
from jaxmatch import files
from jaxmatch.errors import InputError
from jaxmatch.files import atomic_open, atomic_path, write_text_atomic

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "jaxmatch"
TEMP = re.compile(r"^\.(?P<stem>.+)\.(?P<pid>\d+)-[A-Za-z0-9_]+\.tmp(?P<suffix>\.[^.]*)?$")


def listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


# ---------------------------------------------------------------------------------------------
# the mechanism


def test_temporary_name_and_place(tmp_path):
    target = tmp_path / "sub dir" / "résumé 形.npz"
    with atomic_path(target) as tmp:
        assert tmp.parent == target.parent and tmp.exists()
        m = TEMP.match(tmp.name)
        assert m and m["stem"] == "résumé 形" and m["suffix"] == ".npz" and int(m["pid"]) == os.getpid()
        assert not target.exists()
        tmp.write_bytes(b"data")
    assert target.read_bytes() == b"data"
    assert listing(target.parent) == [target.name]
    umask = os.umask(0)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask


@pytest.mark.parametrize("failure", [RuntimeError("boom"), KeyboardInterrupt(), OSError(errno.ENOSPC, "No space left on device")])
def test_failed_write_keeps_the_old_file(tmp_path, failure):
    target = tmp_path / "f.txt"
    target.write_text("old")
    with pytest.raises((type(failure), InputError)) as exc:
        with atomic_open(target) as fh:
            fh.write("half of the new")
            raise failure
    if isinstance(failure, OSError):  # the writer's OS errors become one-line input errors
        assert isinstance(exc.value, InputError) and str(target) in str(exc.value) and "No space" in str(exc.value)
    assert target.read_text() == "old"
    assert listing(tmp_path) == ["f.txt"]


@pytest.mark.parametrize("where", ["folder", "under a file"])
def test_unwritable_targets_are_input_errors(tmp_path, where):
    if where == "folder":
        target = tmp_path / "a folder"
        target.mkdir()
    else:
        (tmp_path / "plain").write_text("x")
        target = tmp_path / "plain" / "f.txt"
    with pytest.raises(InputError) as exc:
        write_text_atomic(target, "text")
    assert str(target) in str(exc.value) and "cannot write" in str(exc.value) and "\n" not in str(exc.value)
    assert not [n for n in listing(tmp_path) if TEMP.match(n)]


def dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_leftovers_of_dead_writers_are_removed(tmp_path):
    target = tmp_path / "c.npz"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        dead = tmp_path / f".c.{dead_pid()}-abc123xy.tmp.npz"
        alive = tmp_path / f".c.{sleeper.pid}-def456zz.tmp.npz"
        ancient = tmp_path / f".c.{sleeper.pid}-old789ww.tmp.npz"
        unrelated = [tmp_path / ".c.npz.bak", tmp_path / f".d.{dead_pid()}-abc123xy.tmp.npz", tmp_path / f".c.{dead_pid()}-abc123xy.tmp.txt"]
        for p in [dead, alive, ancient, *unrelated]:
            p.write_bytes(b"partial")
        old = time.time() - files.STALE_SECONDS - 10
        os.utime(ancient, (old, old))
        write_text_atomic(target, "new")
        assert target.read_text() == "new"
        assert sorted(listing(tmp_path)) == sorted([target.name, alive.name, *(p.name for p in unrelated)])
    finally:
        sleeper.kill()
        sleeper.wait()


# ---------------------------------------------------------------------------------------------
# every writer of the package


def _placement():
    """A placed 2x2 grid as a QuadMesh (what the writers take)."""
    from jaxmatch.placement.embed import arc_lengths, place
    from jaxmatch.catalogue.mesh import from_quads
    from jaxmatch.meshing.build import from_placement

    vid = np.arange(9).reshape(3, 3)
    quads = [[vid[j, i], vid[j, i + 1], vid[j + 1, i + 1], vid[j + 1, i]] for j in range(2) for i in range(2)]
    xy = np.array([[i, j] for j in range(3) for i in range(3)], float)
    mesh = from_quads(quads)
    pts = xy[mesh.boundary]
    return from_placement(None, place(pts, arc_lengths(pts)[:-1], np.arange(len(pts)), mesh, 0, False))


def _figure():
    from jaxmatch.io.plot import new_figure

    fig, axes = new_figure(1)
    axes[0].plot([0, 1], [0, 1])
    return fig


def writers():
    from jaxmatch.scoring.lattice import load_lattice, save_lattice
    from jaxmatch.io.meshfile import write_mesh
    from jaxmatch.io.plot import save_figure

    return {
        "catalogue.npz": lambda p: cm.save(cm.generate(1), p),
        "lattice.toml": lambda p: save_lattice(load_lattice("coarse"), p),
        "mesh.json": lambda p: write_mesh(p, _placement()),
        "mesh.vtk": lambda p: write_mesh(p, _placement()),
        "picture.png": lambda p: save_figure(_figure(), p),
        "picture.svg": lambda p: save_figure(_figure(), p),
    }


@pytest.mark.parametrize("name", list(writers()))
@pytest.mark.parametrize("failure", ["rename fails", "interrupted"])
def test_every_writer_is_atomic(tmp_path, monkeypatch, name, failure):
    write = writers()[name]
    target = tmp_path / f"目標 {name}"
    write(target)
    assert listing(tmp_path) == [target.name]
    target.write_bytes(b"previous contents")
    real_replace, real_fsync = os.replace, os.fsync

    def bad_replace(src, dst):
        if Path(dst) == target:
            raise OSError(errno.EACCES, "Permission denied")
        return real_replace(src, dst)

    def interrupted_fsync(fd):
        raise KeyboardInterrupt

    if failure == "rename fails":
        monkeypatch.setattr(files.os, "replace", bad_replace)
        with pytest.raises(InputError, match="cannot write file: Permission denied"):
            write(target)
    else:
        monkeypatch.setattr(files.os, "fsync", interrupted_fsync)
        with pytest.raises(KeyboardInterrupt):
            write(target)
    monkeypatch.setattr(files.os, "replace", real_replace)
    monkeypatch.setattr(files.os, "fsync", real_fsync)
    assert target.read_bytes() == b"previous contents"
    assert listing(tmp_path) == [target.name]


def _non_atomic_writes(source: str, filename: str) -> list[str]:
    """Calls in ``source`` that write a file outside a ``with atomic_path/atomic_open`` block:
    ``open`` for writing, ``write_text``/``write_bytes``/``touch``/``tofile``/``savefig``,
    ``np.save*``, ``meshio.write``, ``shutil.copy*``/``move``, ``os.replace``/``rename`` and
    one-argument ``.replace``/``.rename`` (``Path``; ``str.replace`` takes two). Writes to an
    open handle (``fh.write``, ``json.dump(x, fh)``) are judged where the handle is opened."""
    tree = ast.parse(source, filename)
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}

    def name_of(fn) -> str:
        return fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")

    def in_atomic_block(node) -> bool:
        while node in parents:
            node = parents[node]
            if isinstance(node, ast.With) and any(
                isinstance(item.context_expr, ast.Call) and name_of(item.context_expr.func) in ("atomic_path", "atomic_open", "atomic_folder")
                for item in node.items
            ):
                return True
        return False

    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        fn, name = node.func, name_of(node.func)
        owner = ast.unparse(fn.value) if isinstance(fn, ast.Attribute) else ""
        if name == "open" and owner in ("", "io", "Path", "path", "p"):
            mode = node.args[1] if len(node.args) > 1 else next((k.value for k in node.keywords if k.arg == "mode"), None)
            writes = mode is not None and not (isinstance(mode, ast.Constant) and not any(c in str(mode.value) for c in "wax+"))
        elif name in ("write_text", "write_bytes", "touch", "tofile", "savefig", "symlink_to"):
            writes = True
        elif name in ("save", "savez", "savez_compressed", "savetxt"):
            writes = owner in ("np", "numpy")
        elif name == "write":
            writes = owner == "meshio"
        elif name in ("copy", "copyfile", "copy2", "move"):
            writes = owner == "shutil"
        elif name in ("replace", "rename"):
            writes = owner in ("os", "shutil") or (len(node.args) == 1 and not node.keywords)
        else:
            writes = False
        if writes and not in_atomic_block(node):
            found.append(f"{filename}:{node.lineno}: {ast.unparse(node)[:80]}")
    return found


def test_no_module_writes_a_file_in_place():
    """Static check of the package: every file write sits inside ``with atomic_path(...)`` or
    ``with atomic_open(...)`` (:mod:`jaxmatch.files` itself implements them)."""
    problems = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name != "files.py":
            problems += _non_atomic_writes(path.read_text(encoding="utf-8"), path.name)
    assert not problems, "\n".join(problems)


def test_static_check_catches_in_place_writes():
    bad = ("def f(p, fig, x, t):\n    open(p, 'w').write('x')\n    p.write_text('x')\n    fig.savefig(p)\n    np.save(p, x)\n"
           "    os.replace(t, p)\n    t.rename(p)\n    open(p, mode='a')\n")
    good = ("def g(p, fig, x):\n    with atomic_path(p) as t:\n        fig.savefig(t)\n        np.save(t, x)\n"
            "    with atomic_open(p) as fh:\n        fh.write('x')\n    open(p).read()\n    'a'.replace('a', 'b')\n")
    assert len(_non_atomic_writes(bad, "bad.py")) == 7
    assert _non_atomic_writes(good, "good.py") == []


# ---------------------------------------------------------------------------------------------
# an interrupted catalogue build (real processes)


CLI_WITH_CTRL_C = ("import signal, sys\n"
                   "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
                   "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})\n"
                   "sys.argv[0] = 'jaxmatch'\n"
                   "from jaxmatch.cli import main\n"
                   "main()\n")
"""The command with Ctrl-C as in a terminal (KeyboardInterrupt, SIGINT not blocked), whatever
disposition the test process hands down: two background runs of the whole suite had the builds
of the interrupt tests ignore SIGINT and run to their end. Set in the child's own interpreter,
not by a ``preexec_fn`` (Python code between fork and exec deadlocks when the test process
runs threads, e.g. JAX's)."""


class Cli:
    """The command (``jaxmatch ARGS``, :data:`CLI_WITH_CTRL_C`) in its own process group, stderr
    to a file (so that it can be watched while the process runs and read completely after it ends)."""

    def __init__(self, tmp: Path, *args):
        self.err_path = tmp.parent / f"{tmp.name}-stderr.txt"
        self.err_file = open(self.err_path, "w")
        self.proc = subprocess.Popen([sys.executable, "-c", CLI_WITH_CTRL_C, *map(str, args)], cwd=ROOT, stdout=subprocess.DEVNULL,
                                     stderr=self.err_file, text=True, start_new_session=True,
                                     env={**os.environ, "JAX_PLATFORMS": "cpu", "JAXMATCH_PROGRESS": ""})
        self.pid = self.proc.pid

    def stderr(self) -> str:
        return self.err_path.read_text()

    def wait_for(self, prefix: str, timeout: float = 120.0) -> None:
        t0 = time.perf_counter()
        while not any(line.startswith(prefix) for line in self.stderr().splitlines()):
            if self.proc.poll() is not None:
                raise AssertionError(f"exit {self.proc.returncode} before {prefix!r}: {self.stderr()}")
            assert time.perf_counter() - t0 < timeout
            time.sleep(0.02)

    def finish(self, timeout: float = 600.0) -> tuple[int, str]:
        try:
            self.proc.wait(timeout=timeout)
        finally:
            kill_group(self)
            self.proc.wait()
            self.err_file.close()
        return self.proc.returncode, self.stderr()


def kill_group(proc, sig=signal.SIGKILL):
    """Signal the process group we started (the build and its worker processes)."""
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass


def test_killed_build_leaves_the_old_catalogue_and_a_rerun_finishes(tmp_path):
    out = tmp_path / "目録 X.npz"
    cm.save(cm.generate(2), out)
    before = out.read_bytes()

    # 1. kill -9 the build (and its workers) while it generates
    build = Cli(tmp_path.parent / f"{tmp_path.name}-build1", "catalogue", "build", "--internal", "0..4", "--out", out)
    try:
        build.wait_for("k=1:")
    finally:
        kill_group(build)
    code, _ = build.finish()
    assert code == -signal.SIGKILL
    assert out.read_bytes() == before
    assert listing(tmp_path) == [out.name]

    # 2. kill -9 a writer in the middle of writing the file: its temporary stays behind
    code = ("import sys, time\nfrom jaxmatch.files import atomic_path\n"
            "with atomic_path(sys.argv[1]) as tmp:\n    tmp.write_bytes(b'PK half a catalogue')\n"
            "    print('ready', flush=True)\n    time.sleep(120)\n")
    writer = subprocess.Popen([sys.executable, "-c", code, str(out)], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == "ready"
    finally:
        writer.kill()
        writer.wait()
    leftovers = [n for n in listing(tmp_path) if n != out.name]
    assert len(leftovers) == 1 and TEMP.match(leftovers[0])
    assert out.read_bytes() == before
    assert cm.load(out).counts()["per_k"]["2"]["meshes"] == 12  # the leftover is never read

    # 3. the rerun finishes the job, the file loads, the leftover is gone
    code, err = Cli(tmp_path.parent / f"{tmp_path.name}-build2", "catalogue", "build", "--internal", "0..4", "--out", out).finish()
    assert code == 0, err
    assert cm.load(out).counts()["per_k"]["4"] == {"meshes": 1283, "up_to_rotation": 2332}
    assert listing(tmp_path) == [out.name]


def interrupt_build(tmp_path: Path, workers: int) -> tuple[int, str]:
    """Ctrl-C (SIGINT to the process group) while a build generates; the target must survive."""
    out = tmp_path / "X.npz"
    cm.save(cm.generate(1), out)
    before = out.read_bytes()
    build = Cli(tmp_path.parent / f"{tmp_path.name}-int{workers}", "catalogue", "build", "--internal", "0..5", "--out", out,
                "--workers", workers)
    build.wait_for("k=2:")
    time.sleep(0.5)
    kill_group(build, signal.SIGINT)
    code, err = build.finish(timeout=120)
    assert out.read_bytes() == before
    assert listing(tmp_path) == [out.name]
    return code, err


@pytest.mark.parametrize("workers", [1, 2])
def test_interrupted_build_keeps_the_old_file(tmp_path, workers):
    code, err = interrupt_build(tmp_path, workers)
    assert code != 0, err


@pytest.mark.parametrize("workers", [1, 2])
def test_interrupted_build_says_aborted(tmp_path, workers):
    code, err = interrupt_build(tmp_path, workers)
    assert code == 130 and "Traceback" not in err and err.strip().splitlines()[-1] == "aborted", err


@pytest.mark.parametrize("args", [["score", "examples/square.json", "--top", "0"], ["score", "--bogus"], ["catalogue", "build"]])
def test_cli_usage_errors_are_one_line(tmp_path, args):
    code, err = Cli(tmp_path / "usage", *args).finish(120)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


def test_cli_write_error_is_one_line_exit_2(tmp_path):
    folder = tmp_path / "a folder.npz"
    folder.mkdir()
    code, err = Cli(tmp_path.parent / f"{tmp_path.name}-werr", "catalogue", "build", "--internal", "0", "--out", folder, "--workers", "1").finish(120)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(folder) in lines[0] and "cannot write" in lines[0] and "Traceback" not in err
    assert listing(tmp_path) == [folder.name]
