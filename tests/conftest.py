"""Shared test setup: import path and hypothesis profiles.

Profiles (``HYPOTHESIS_PROFILE=<name>`` picks one):

* ``dev`` (the local default): modest example counts, no deadline (the first call of a shape
  compiles), a random seed each run; a failing example is kept in ``.hypothesis/`` and replayed
  first on later runs until it passes. Run chosen seeds with ``pytest --hypothesis-seed=N``
  (add ``-p no:cacheprovider`` and delete ``.hypothesis/`` to see a seed without the replays).
* ``ci``: loaded when the environment variable ``CI`` is set (``bash .ci/run`` runs with
  ``CI=true``): the same counts and health checks, derandomized (each test's examples follow from
  the test itself, so a submission cannot fail by chance) and no example database (nothing is
  replayed from an earlier run).
* ``thorough``: more examples (``HYPOTHESIS_PROFILE=thorough pytest``).
"""

import os
import sys
from pathlib import Path

from hypothesis import HealthCheck, settings

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# parent: hypothesis's own defaults, not the profile it may have loaded already (recent versions load
# a built-in "ci" profile of their own when they see CI; "dev" must stay random even then)
_COMMON = dict(parent=settings.get_profile("default"), deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=80, **_COMMON)
settings.register_profile("ci", max_examples=80, derandomize=True, database=None, print_blob=True, **_COMMON)
settings.register_profile("thorough", max_examples=500, **_COMMON)


def hypothesis_profile(environ=os.environ) -> str:
    """The profile to load: ``HYPOTHESIS_PROFILE`` when set, else ``ci`` when ``CI`` is set (to
    anything but empty, ``0`` or ``false``), else ``dev``."""
    if environ.get("HYPOTHESIS_PROFILE"):
        return environ["HYPOTHESIS_PROFILE"]
    return "ci" if environ.get("CI", "").strip().lower() not in ("", "0", "false") else "dev"


settings.load_profile(hypothesis_profile())


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def cat():
    """The shipped default catalogue (k = 0..5)."""
    from jaxmatch.catalogue.store import default_catalogue

    return default_catalogue()


@pytest.fixture(scope="session")
def index(cat):
    """Mesh index of the default catalogue (for label files)."""
    from jaxmatch.tuning.labels import mesh_index

    return mesh_index(cat)


@pytest.fixture
def cli(capsys, monkeypatch, tmp_path):
    """``cli(*args) -> (exit code, stdout, stderr)``: the ``jaxmatch`` command run in-process."""
    from jaxmatch.cli import main

    monkeypatch.setenv("JAXMATCH_CACHE", str(tmp_path / "cache"))
    for name in ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                 "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"):  # set by the command while JAX is not loaded:
        monkeypatch.delenv(name, raising=False)  # restored when the test ends

    def run(*args):
        monkeypatch.setattr(sys, "argv", ["jaxmatch", *map(str, args)])
        capsys.readouterr()
        try:
            main()
            code = 0
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else 1
        out, err = capsys.readouterr()
        return code, out, err

    return run


CLI_THEN = """
import sys
from jaxmatch.cli import main
sys.argv = ["jaxmatch", *sys.argv[1:]]
try:
    main()
except SystemExit as e:
    assert not e.code, e.code
"""


@pytest.fixture
def cli_then():
    """``cli_then(after) -> str``: a ``python -c`` program that runs the ``jaxmatch`` command given
    as its arguments in-process (a nonzero exit fails it), then the lines ``after`` (e.g. a look
    at ``sys.modules``)."""
    return lambda after: CLI_THEN + after


@pytest.fixture
def recorded(monkeypatch):
    """``recorded(module, name, run)``: the ``(args, kwargs)`` of every call of ``module.name``
    while ``run()`` runs, in order (the function itself still answers each call; restored after)."""

    def record(module, name: str, run) -> list:
        calls, real = [], getattr(module, name)

        def keep(*a, **k):
            calls.append((a, k))
            return real(*a, **k)

        monkeypatch.setattr(module, name, keep)
        try:
            run()
        finally:
            monkeypatch.setattr(module, name, real)
        return calls

    return record


@pytest.fixture(scope="session")
def bulk_parts():
    """``bulk_parts(folder, count) -> [Path]``: the first ``count`` random parts of
    ``scripts/make_bulk_parts.py`` (the bulk benchmark's, seed 38) written as
    ``folder/part-NNN.json``, in order."""
    import importlib.util
    import json

    spec = importlib.util.spec_from_file_location("make_bulk_parts", Path(__file__).resolve().parent.parent / "scripts"
                                                  / "make_bulk_parts.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)

    def write(folder: Path, count: int) -> list[Path]:
        folder.mkdir(parents=True, exist_ok=True)
        paths = []
        for i, doc in enumerate(mod.parts(count)):
            paths.append(folder / f"part-{i:03d}.json")
            paths[-1].write_text(json.dumps(doc) + "\n")
        return paths

    return write
