"""The house rules for the library's layout, measured from the source (no import is executed).

Run as a script for a report (``python tests/layout.py [PATH ...]``, default: designkit,
firmware_io, cad and studies); ``tests/test_layout.py`` asserts the same rules. The limits are
the house style's: one concept a file (<= 700 lines), named phases (<= 100 lines a function),
short timeless module docstrings, top-level imports except heavy optional ones, imports that
point one way.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("designkit", "firmware_io", "cad")
# checked by the same rules, outside the library (the import budget MAX_INNER_IMPORTS is the
# library's)
STUDIES = ("studies",)
CHECKED = PACKAGES + STUDIES
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 100
MAX_DOCSTRING_LINES = 25
MAX_INNER_IMPORTS = 60
# heavy or optional dependencies whose import inside a function saves start-up time
LAZY_OK = ("pyvista", "vtkmodules", "build123d", "OCP", "gmsh", "dask", "distributed",
           "matplotlib", "smbus2", "meshio", "magpylib", "cfsem", "psutil")
# (magpylib, cfsem: the test extra's peers; psutil: comes with dask[distributed]). A library
# module that imports one of these at its top is as heavy: importing it late is allowed too.
# functions allowed past MAX_FUNCTION_LINES: "module:function" -> the benchmark that shows a
# split costs time
LONG_FUNCTIONS: dict[str, str] = {}
# docstrings whose flagged words are datasheet facts, not run logs: "module:name" -> source
DATASHEET_TIMES: dict[str, str] = {}
# words that mark run logs, machine state or history in a docstring
STALE = re.compile(r"\b(\d+(\.\d+)?\s?(us|ms|µs)\b|was \S+,? now|OpenBLAS|(machine|while|when) "
                   r"(was )?(loaded|idle)|under load|20[12]\d-\d\d-\d\d|\bsession \d|"
                   r"\bissue \d)", re.I)


def modules(paths=None) -> list[Path]:
    """Every .py file of the library (or of the given files/folders)."""
    roots = [ROOT / p for p in (paths or PACKAGES)]
    files = []
    for r in roots:
        files += [r] if r.is_file() else sorted(r.rglob("*.py"))
    return [f for f in files if "__pycache__" not in f.parts]


def module_name(path: Path) -> str:
    rel = path.resolve().relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _absolute(node: ast.ImportFrom, name: str, is_pkg: bool) -> str:
    if not node.level:
        return node.module or ""
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    base = base[:len(base) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def _inside_functions(tree) -> set[int]:
    ids = set()
    for f in ast.walk(tree):
        if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef)):
            ids |= {id(s) for s in ast.walk(f) if isinstance(s, (ast.Import, ast.ImportFrom))}
    return ids


def imports(path: Path, known: set[str]) -> tuple[set[str], list[str]]:
    """(library modules imported anywhere, every import made inside a function)."""
    top, lazy, _ = _imports(path, known)
    return top, lazy


def _imports(path: Path, known: set[str]) -> tuple[set[str], list[str], set[str]]:
    """imports() and the top-level names of what the module imports outside functions."""
    tree = ast.parse(path.read_text())
    name, is_pkg = module_name(path), path.name == "__init__.py"
    inner = _inside_functions(tree)
    typing_only = {id(s) for b in ast.walk(tree) if isinstance(b, ast.If)
                   and "TYPE_CHECKING" in ast.unparse(b.test) for s in ast.walk(b)}
    top, lazy, eager = set(), [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = _absolute(node, name, is_pkg)
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in known else mod
                       for a in node.names]
        else:
            continue
        if id(node) in inner:
            lazy += targets
        elif id(node) not in typing_only:
            eager |= {t.split(".")[0] for t in targets} | {t for t in targets if t in known}
        # a lazy or type-checking import hides a cycle, it does not break it
        top |= {t for t in targets if t in known and t != name}
    return top, lazy, eager


def heavy(eager: dict[str, set[str]]) -> set[str]:
    """Library modules that load a LAZY_OK dependency when imported (directly or through the
    library modules they import outside functions)."""
    out = {m for m, e in eager.items() if set(LAZY_OK) & e}
    grown = True
    while grown:
        new = {m for m, e in eager.items() if m not in out and e & out}
        grown = bool(new)
        out |= new
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
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

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def report(paths=None) -> dict[str, list[str]]:
    """Every breach of the rules, by rule (default: the library and the studies)."""
    files = modules(paths or CHECKED)
    library = modules()
    every = library + modules(STUDIES)
    known = {module_name(f) for f in every}
    out = {"module lines": [], "function lines": [], "docstring lines": [],
           "stale docstring": [], "lazy import": [], "cycle": []}
    graph, eager, inner, n_lazy = {}, {}, {}, 0
    for f in every:
        top, inner[f], eager[module_name(f)] = _imports(f, known)
        # a package's __init__ is loaded before its children: that edge is implicit, not a cycle
        graph[module_name(f)] = {t for t in top if not module_name(f).startswith(t + ".")}
        if f in files and f in library:
            n_lazy += len(inner[f])
    slow = heavy(eager)
    for f in files:
        lazy = inner[f] if f in inner else imports(f, known)[1]
        bad = [m for m in lazy if m.split(".")[0] not in LAZY_OK and m not in slow]
        out["lazy import"] += [f"{module_name(f)}: {m}" for m in bad]
    for f in files:
        src = f.read_text()
        tree = ast.parse(src)
        rel = f.relative_to(ROOT)
        if src.count("\n") > MAX_MODULE_LINES:
            out["module lines"].append(f"{rel} ({src.count(chr(10))} lines)")
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = fn.end_lineno - fn.lineno + 1
                key = f"{module_name(f)}:{fn.name}"
                if n > MAX_FUNCTION_LINES and key not in LONG_FUNCTIONS:
                    out["function lines"].append(f"{rel}:{fn.lineno} {fn.name} ({n} lines)")
        doc = ast.get_docstring(tree) or ""
        if doc.count("\n") + 1 > MAX_DOCSTRING_LINES:
            out["docstring lines"].append(f"{rel} ({doc.count(chr(10)) + 1} lines)")
        for node in ast.walk(tree):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                 ast.AsyncFunctionDef)):
                d = ast.get_docstring(node) or ""
                m = STALE.search(d)
                where = getattr(node, "name", "module")
                if m and f"{module_name(f)}:{where}" not in DATASHEET_TIMES:
                    out["stale docstring"].append(f"{rel} {where}: {m.group(0)!r}")
    if n_lazy > MAX_INNER_IMPORTS and paths is None:
        out["lazy import"].append(f"{n_lazy} imports inside functions (at most "
                                  f"{MAX_INNER_IMPORTS})")
    out["cycle"] = [" <-> ".join(c) for c in cycles(graph)]
    return out


if __name__ == "__main__":
    found = report(sys.argv[1:] or None)
    for rule, items in found.items():
        print(f"{rule}: {len(items)}")
        for it in items:
            print(f"    {it}")
    sys.exit(1 if any(found.values()) else 0)
