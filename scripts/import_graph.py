#!/usr/bin/env python3
"""The package's import graph, read from the source (nothing is imported): cycles between
modules and between the package's folders (a folder importing a folder that imports it back is
an import from a lower layer up), imports inside functions of the package's own modules, and
files over a line limit.

    python scripts/import_graph.py            # a report; exit 1 when a rule is broken
    python scripts/import_graph.py --json     # the same as one JSON object
    python scripts/import_graph.py --root DIR # another checkout (e.g. an older commit, git worktree)

Edges: ``import jaxmatch.x``, ``from jaxmatch.x import y`` (and relative imports) anywhere in a
module, and the modules a :class:`jaxmatch.lazy.Later` declares (loaded on first use, but a
dependency all the same). ``if TYPE_CHECKING:`` imports are not edges (never run).
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "jaxmatch"

MAX_LINES = 1000
"""No file of the package longer than this."""

MAX_FUNCTION_IMPORTS = 40
"""At most this many imports of the package's own modules inside functions."""


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(mod: str, node: ast.ImportFrom) -> list[str]:
    """Absolute module names an ImportFrom in module ``mod`` refers to (the module and, for
    ``from pkg import sub``, the submodule when it is one)."""
    if node.level:  # relative to the module's package (a package's __init__ is its own package)
        pkg = mod.split(".") if Path(PACKAGE, *mod.split(".")[1:], "__init__.py").exists() else mod.split(".")[:-1]
        base = pkg[: len(pkg) - node.level + 1]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    out = [target]
    out += [f"{target}.{a.name}" for a in node.names]
    return out


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    ids = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test):
            ids.update(id(x) for s in n.body for x in ast.walk(s))
    return ids


def read_graph() -> dict:
    """``{"modules": {name: {"path", "lines", "imports": [...], "function_imports": [...]}}}``."""
    paths = sorted(PACKAGE.rglob("*.py"))
    names = {module_name(p) for p in paths}
    modules = {}
    for p in paths:
        mod = module_name(p)
        text = p.read_text()
        tree = ast.parse(text)
        skip = _type_checking_nodes(tree)
        funcs = {id(x) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for x in ast.walk(f) if x is not f}
        imports, in_functions = set(), []
        for n in ast.walk(tree):
            if id(n) in skip:
                continue
            found = []
            if isinstance(n, ast.Import):
                found = [a.name for a in n.names]
            elif isinstance(n, ast.ImportFrom):
                found = _resolve(mod, n)
            elif isinstance(n, ast.Call) and getattr(n.func, "id", getattr(n.func, "attr", None)) == "Later":
                found = [k.value.value for k in n.keywords if isinstance(k.value, ast.Constant)]
            found = [f for f in found if f in names and f != mod]
            imports.update(found)
            if found and isinstance(n, (ast.Import, ast.ImportFrom)) and id(n) in funcs:
                in_functions.append(f"{p.relative_to(PACKAGE.parent)}:{n.lineno}")
        modules[mod] = {"path": str(p.relative_to(PACKAGE.parent)), "lines": text.count("\n"), "imports": sorted(imports),
                        "function_imports": in_functions}
    return {"modules": modules}


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan, iterative)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges.get(root, ()))))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def folder(mod: str) -> str:
    """The layer a module belongs to: its folder under the package (``jaxmatch.placement``),
    or the module itself for the package's top-level files."""
    parts = mod.split(".")
    return ".".join(parts[:2]) if Path(PACKAGE, *parts[1:2]).is_dir() else mod


def report(graph: dict) -> dict:
    mods = graph["modules"]
    edges = {m: set(v["imports"]) for m, v in mods.items()}
    # a package's __init__ is not a layer of its own
    fedges: dict[str, set[str]] = {}
    for m, targets in edges.items():
        for t in targets:
            a, b = folder(m), folder(t)
            if a != b and a != "jaxmatch" and b != "jaxmatch":
                fedges.setdefault(a, set()).add(b)
    fn = [x for v in mods.values() for x in v["function_imports"]]
    long = {v["path"]: v["lines"] for v in mods.values() if v["lines"] > MAX_LINES}
    return {"modules": len(mods), "edges": sum(len(e) for e in edges.values()),
            "module_cycles": cycles(edges), "folder_cycles": cycles(fedges),
            "function_imports": len(fn), "function_import_places": fn, "files_over_limit": long}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--root", type=Path, default=ROOT, help="the checkout to read (default: this one)")
    args = ap.parse_args()
    global PACKAGE
    PACKAGE = args.root.resolve() / "jaxmatch"
    r = report(read_graph())
    broken = bool(r["module_cycles"] or r["folder_cycles"] or r["files_over_limit"]
                  or r["function_imports"] > MAX_FUNCTION_IMPORTS)
    if args.json:
        print(json.dumps(r))
    else:
        print(f"{r['modules']} modules, {r['edges']} import edges")
        print(f"module cycles: {r['module_cycles'] or 'none'}")
        print(f"folder cycles (an import from a lower layer up): {r['folder_cycles'] or 'none'}")
        print(f"imports of the package's own modules inside functions: {r['function_imports']} "
              f"(at most {MAX_FUNCTION_IMPORTS})")
        for place in r["function_import_places"]:
            print(f"  {place}")
        print(f"files over {MAX_LINES} lines: {r['files_over_limit'] or 'none'}")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
