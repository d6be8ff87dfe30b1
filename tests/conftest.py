"""Shared test setup: import path and hypothesis profiles.

Profiles: ``dev`` (default; modest example counts, no deadline because the first call of a
shape compiles) and ``thorough`` (``HYPOTHESIS_PROFILE=thorough pytest``).
"""

import os
import sys
from pathlib import Path

from hypothesis import HealthCheck, settings

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

settings.register_profile("dev", max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("thorough", max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


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
