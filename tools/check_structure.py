"""The structure of the ``clfza`` package, checked (issue 32).

Rules, over every module under ``clfza/``:

1. **No import cycle**, module-level and function-level imports counted alike. Importing
   ``clfza.a.b`` runs ``clfza/a/__init__.py`` first, so an import also depends on the packages
   above its target (the root ``clfza`` aside: it is always imported first, and no module
   inside it may import it, but for ``__version__``, which it binds before any import).
2. **No module imports its own package's ``__init__``** (it may not have run yet: import the
   sibling module), **no private name imported from another module** (``from .x import
   _name``), and no private module of another subpackage imported (``from ..solvers._twist
   import X``): a subpackage is
   reached through its ``__init__``, its public surface.
3. **A function-level import only for a heavy or optional dependency loaded lazily, with the
   reason beside it**: a comment on the import's line, or on the line above, that starts with
   ``lazy:``, e.g. ``import pyopencl as cl  # lazy: pyopencl loads only when a device is used``.

Usage: ``python tools/check_structure.py [ROOT]``; prints what it finds and exits 1 when it
finds anything.
"""

from __future__ import annotations

import ast
import os
import sys
from dataclasses import dataclass


@dataclass(frozen=True)
class Edge:
    target: str  # the imported module
    name: str | None  # the imported name (from-imports), else None
    line: int
    in_function: bool


def modules(root: str) -> dict[str, str]:
    """Module name -> file path, for every ``.py`` file under ``root/clfza``."""
    out = {}
    for d, _, fs in os.walk(os.path.join(root, "clfza")):
        for f in fs:
            if f.endswith(".py"):
                p = os.path.join(d, f)
                name = os.path.relpath(p, root)[:-3].replace(os.sep, ".")
                out[name.removesuffix(".__init__")] = p
    return out


def _function_imports(tree: ast.AST) -> set[int]:
    inner = set()
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            inner.update(id(n) for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom)))
    return inner


def edges(mods: dict[str, str], m: str) -> tuple[list[Edge], list[tuple[int, str]]]:
    """The clfza imports of module ``m``, and its external function-level imports."""
    p = mods[m]
    tree = ast.parse(open(p).read())
    inner = _function_imports(tree)
    pkg = m.split(".") if p.endswith("__init__.py") else m.split(".")[:-1]
    found: list[Edge] = []
    external: list[tuple[int, str]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(pkg[:len(pkg) - node.level + 1] + ([node.module] if node.module
                                                                    else []))
            else:
                base = node.module or ""
            if not (base == "clfza" or base.startswith("clfza.")):
                if id(node) in inner:
                    external.append((node.lineno, base))
                continue
            for a in node.names:
                full = f"{base}.{a.name}"
                if full in mods:
                    found.append(Edge(full, None, node.lineno, id(node) in inner))
                else:
                    found.append(Edge(base, a.name, node.lineno, id(node) in inner))
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "clfza" or a.name.startswith("clfza."):
                    found.append(Edge(a.name, None, node.lineno, id(node) in inner))
                elif id(node) in inner:
                    external.append((node.lineno, a.name))
    return found, external


def _packages_of(target: str) -> list[str]:
    """``clfza.a.b.c`` -> ``["clfza.a", "clfza.a.b"]``: the package inits an import runs."""
    parts = target.split(".")
    return [".".join(parts[:i]) for i in range(2, len(parts))]


def graph(mods: dict[str, str]) -> dict[str, set[str]]:
    g: dict[str, set[str]] = {m: set() for m in mods}
    for m in mods:
        for e in edges(mods, m)[0]:
            t = e.target
            while t and t not in mods:
                t = t.rpartition(".")[0]
            for dep in [*_packages_of(t), t]:
                if dep in mods and dep != m and dep != "clfza" and not m.startswith(dep + "."):
                    g[m].add(dep)
    return g


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(g[v]):
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
                found.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(g):
        if v not in index:
            visit(v)
    return found


def _subpackage(m: str, mods: dict[str, str]) -> str:
    """The package a module belongs to (itself for a package's ``__init__``)."""
    return m if mods[m].endswith("__init__.py") else m.rpartition(".")[0]


def _has_reason(lines: list[str], line: int) -> bool:
    here = lines[line - 1]
    above = lines[line - 2].strip() if line >= 2 else ""
    return "# lazy:" in here or above.startswith("# lazy:")


def private_imports(mods: dict[str, str], m: str) -> list[str]:
    out = []
    for e in edges(mods, m)[0]:
        if e.target == "clfza" and e.name != "__version__" and m != "clfza.__main__":
            out.append(f"{mods[m]}:{e.line}: imports the root package clfza")
            continue
        if e.name is not None and e.name.startswith("_") and not e.name.startswith("__") \
                and e.target != m:
            out.append(f"{mods[m]}:{e.line}: imports the private name {e.name} from {e.target}")
        if m.startswith(e.target + ".") and e.target != "clfza":
            out.append(f"{mods[m]}:{e.line}: imports its own package {e.target} (import the "
                       f"sibling module instead: the package may not be initialised yet)")
        private = [p for p in e.target.split(".") if p.startswith("_") and p != "__init__"]
        if private:
            owner = e.target.rpartition(".")[0] if e.target in mods and not mods[
                e.target].endswith("__init__.py") else e.target
            owner = owner.split("._")[0]
            mine = _subpackage(m, mods)
            if not (mine == owner or mine.startswith(owner + ".")):
                out.append(f"{mods[m]}:{e.line}: imports {e.target}, a private module of "
                           f"{owner} (import from {owner} instead)")
    return out


def lazy_imports(mods: dict[str, str], m: str) -> list[str]:
    lines = open(mods[m]).read().split("\n")
    found, external = edges(mods, m)
    out = []
    for e in found:
        if e.in_function and not _has_reason(lines, e.line):
            out.append(f"{mods[m]}:{e.line}: function-level import of {e.target} without a "
                       f"'# lazy:' reason")
    for line, name in external:
        if not _has_reason(lines, line):
            out.append(f"{mods[m]}:{line}: function-level import of {name} without a "
                       f"'# lazy:' reason")
    return sorted(set(out))


def main(root: str = ".") -> int:
    mods = modules(root)
    g = graph(mods)
    problems: list[str] = []
    for comp in cycles(g):
        problems.append(f"import cycle: {', '.join(comp)}")
        problems.extend(f"    {m} -> {', '.join(sorted(g[m] & set(comp)))}" for m in comp)
    for m in sorted(mods):
        problems.extend(private_imports(mods, m))
        problems.extend(lazy_imports(mods, m))
    top = sorted(e for e in os.listdir(os.path.join(root, "clfza"))
                 if e not in ("__init__.py", "__main__.py", "__pycache__")
                 and (e.endswith(".py") or os.path.isdir(os.path.join(root, "clfza", e))))
    if len(top) > 17:  # 17 since denoisers/ (issue 38)
        problems.append(f"clfza/ has {len(top)} top-level entries (at most 17): {', '.join(top)}")
    problems = list(dict.fromkeys(problems))
    print("\n".join(problems) if problems else "structure: clean")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "."))
