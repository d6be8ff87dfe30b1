"""The installable package: a wheel built from the sources carries the lattices and the
default catalogue, and its ``jaxmatch`` command runs from a folder outside the repository.

Offline and quick: the wheel is built without build isolation (setuptools from the test
environment), the fresh virtual environment has no pip and sees the test environment's
dependencies (numpy, JAX, ...) through a ``.pth`` line, and only the wheel is installed into it
(``pip --python``), so the test needs no network.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.slow

SKIP = shutil.ignore_patterns(".venv", ".git", "build", "dist", "*.egg-info", "__pycache__", ".hypothesis", ".pytest_cache",
                              ".cache", "out")


CLEAN_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
"""The environment of the package's commands: a ``PYTHONPATH`` pointing at the checkout would make
pip see jaxmatch as installed already (and skip the wheel) and hide a wheel missing a module."""


def _run(cmd, **kw):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600, **kw)
    assert r.returncode == 0, (cmd, r.stdout[-2000:], r.stderr[-2000:])
    return r


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(fresh venv's bin folder, the wheel) with the wheel installed into the fresh venv."""
    base = tmp_path_factory.mktemp("package")
    src = base / "src"
    shutil.copytree(ROOT, src, ignore=SKIP, symlinks=True)  # build from a copy: the checkout stays clean
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q", "-w", base / "dist", src],
         env=CLEAN_ENV)
    wheel = next((base / "dist").glob("jaxmatch-*.whl"))
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], env=CLEAN_ENV)
    py = venv / "bin" / "python"
    site = Path(_run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], env=CLEAN_ENV).stdout.strip())
    (site / "_test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([sys.executable, "-m", "pip", "--python", py, "install", "--no-deps", "--no-index", "-q", wheel], env=CLEAN_ENV)
    return venv / "bin", wheel


def test_wheel_carries_lattices_and_catalogue(installed):
    _, wheel = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"jaxmatch/data/fine.toml", "jaxmatch/data/coarse.toml", "jaxmatch/data/catalogue-k0-5.npz",
            "jaxmatch/io/readers.py", "jaxmatch/__main__.py"} <= names
    fine = zipfile.ZipFile(wheel).read("jaxmatch/data/fine.toml")
    assert fine == (ROOT / "lattices" / "fine.toml").read_bytes()  # the file, not a link to it


def test_installed_command_runs_outside_the_repository(installed, tmp_path):
    bin_dir, _ = installed
    work = tmp_path / "elsewhere"
    work.mkdir()
    shutil.copy(ROOT / "examples" / "lshape.csv", work / "part.csv")
    env = dict(CLEAN_ENV)
    env["JAXMATCH_CACHE"] = str(tmp_path / "cache")
    where = _run([bin_dir / "python", "-c", "import jaxmatch, jaxmatch.scoring.lattice as l; print(jaxmatch.__file__); "
                  "print(l.BUILTIN_DIR.is_dir())"], cwd=work, env=env).stdout.split()
    assert where[0].startswith(str(bin_dir.parent)) and where[1] == "False"  # the wheel's code, no lattices/ folder
    r = _run([bin_dir / "jaxmatch", "score", "part.csv", "--internal", "3", "--top", "2", "--json"], cwd=work, env=env)
    d = json.loads(r.stdout)
    assert d["lattice"] == "fine" and len(d["results"]) == 2 and d["results"][0]["mesh_id"].startswith("k3-")
    assert "jaxmatch" in _run([bin_dir / "jaxmatch", "--version"], cwd=work, env=env).stdout
    assert "convex" in _run([bin_dir / "python", "-m", "jaxmatch", "lattice", "show", "coarse"], cwd=work, env=env).stdout
