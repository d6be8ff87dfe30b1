# Shared by scripts/demo and scripts/test: create .venv if missing and install the project.
# Re-installs when pyproject.toml is newer than the last install.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
PY="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "creating .venv" >&2
  "$PY" -m venv .venv
fi
if [ ! -f .venv/.installed ] || [ pyproject.toml -nt .venv/.installed ]; then
  echo "installing jaxmatch and its dependencies into .venv" >&2
  .venv/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -e ".[dev]"
  touch .venv/.installed
  rm -f .venv/.warmed
fi
if [ ! -f .venv/.warmed ]; then
  # Fill what a first command would otherwise make (bytecode of the sources, compiled-code
  # caches of any kernel the meshing and scoring paths use), so a newcomer's first `jaxmatch`
  # command is as fast as the second (docs/perf.md, "Start-up").
  echo "warming the caches (bytecode, one mesh and one score)" >&2
  .venv/bin/python -m compileall -q jaxmatch >/dev/null 2>&1 || true
  WARM="$(mktemp -d)"
  .venv/bin/jaxmatch mesh examples/lshape.json examples/circle.json --out-dir "$WARM" --jobs 1 >/dev/null 2>&1 || true
  .venv/bin/jaxmatch score examples/lshape.json --top 1 >/dev/null 2>&1 || true
  rm -rf "$WARM"
  touch .venv/.warmed
fi
