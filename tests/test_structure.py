"""The package's structure as the design asks for it, read from the source
(``scripts/import_graph.py``): no import cycle between modules nor between folders (no import from
a lower layer up), few imports inside functions, no file over 1,000 lines, and a layout table in
``docs/reference.md`` that names every module of the tree."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def graph():
    spec = importlib.util.spec_from_file_location("import_graph", ROOT / "scripts" / "import_graph.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod, mod.report(mod.read_graph())


def test_no_import_cycle_between_modules_or_folders(graph):
    _, r = graph
    assert r["module_cycles"] == []
    assert r["folder_cycles"] == []


def test_few_imports_inside_functions_and_no_long_file(graph):
    mod, r = graph
    assert r["function_imports"] <= mod.MAX_FUNCTION_IMPORTS, r["function_import_places"]
    assert r["files_over_limit"] == {}


def test_the_cycle_finder_finds_cycles(graph):
    mod, _ = graph
    assert mod.cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert mod.cycles({"a": {"b"}, "b": set()}) == []


def test_the_kernels_are_the_bottom_floor(graph):
    mod, _ = graph
    g = mod.read_graph()["modules"]
    for name, m in g.items():
        if name.startswith("jaxmatch.kernels"):
            above = [t for t in m["imports"] if not t.startswith("jaxmatch.kernels") and t not in ("jaxmatch.errors", "jaxmatch.lazy")]
            assert above == [], (name, above)


def test_the_reference_layout_table_names_every_module():
    text = (ROOT / "docs" / "reference.md").read_text()
    table = text[text.index("## Layout\n"):text.index("### Kernels: one per role")]
    rows = {}
    for line in table.splitlines():
        cells = line.split("|")
        if len(cells) > 2 and "`jaxmatch/" in cells[1]:
            for place in re.findall(r"`(jaxmatch/[^`]*)`", cells[1]):
                rows[place] = cells[2]
    files = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "jaxmatch").rglob("*")
                   if p.suffix in (".py", ".c") and p.name not in ("__init__.py", "__main__.py")
                   and "__pycache__" not in p.parts)
    missing = []
    for f in files:
        folder, name = f.rsplit("/", 1)
        if f in rows or (folder + "/" in rows and f"`{name}`" in rows[folder + "/"]):
            continue
        missing.append(f)
    assert missing == []
    for place in rows:
        assert (ROOT / place).exists(), place  # nothing listed that is gone


def test_the_performance_page_is_a_current_state_page():
    """docs/perf.md says how speed is measured and today's figures (at most 300 lines); its
    history is git's."""
    assert len((ROOT / "docs" / "perf.md").read_text().splitlines()) <= 300
