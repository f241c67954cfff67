"""Structure checks of issue 12: import cycles between clfza's modules (module-level and
function-level imports alike), modules above 600 lines, functions above 80 lines.

Usage: ``python tools/check_structure.py [ROOT]``; prints what it finds and exits 1 when it
finds anything (a module's reason for its size, at the top of its docstring, is printed too).
"""

from __future__ import annotations

import ast
import os
import sys

MAX_MODULE, MAX_FUNCTION = 600, 80


def modules(root: str) -> dict[str, str]:
    out = {}
    for d, _, fs in os.walk(os.path.join(root, "clfza")):
        for f in fs:
            if f.endswith(".py"):
                p = os.path.join(d, f)
                name = os.path.relpath(p, root)[:-3].replace(os.sep, ".")
                out[name.removesuffix(".__init__")] = p
    return out


def imports(mods: dict[str, str]) -> dict[str, set[str]]:
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        pkg = m.split(".") if p.endswith("__init__.py") else m.split(".")[:-1]
        for node in ast.walk(ast.parse(open(p).read())):
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = ".".join(pkg[:len(pkg) - node.level + 1] + ([node.module] if
                                node.module else [])) if node.level else (node.module or "")
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                           for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for t in targets:
                while t and t not in mods:
                    t = t.rpartition(".")[0]
                if t and t != m:
                    graph[m].add(t)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
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
        for w in graph[v]:
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
    for v in graph:
        if v not in index:
            visit(v)
    return found


def main(root: str = ".") -> int:
    mods = modules(root)
    graph = imports(mods)
    problems = 0
    for comp in cycles(graph):
        problems += 1
        print(f"import cycle: {', '.join(comp)}")
        for m in comp:
            print(f"    {m} -> {', '.join(sorted(graph[m] & set(comp)))}")
    for m, p in sorted(mods.items()):
        src = open(p).read()
        tree = ast.parse(src)
        n = src.count("\n")
        if n > MAX_MODULE:
            problems += 1
            doc = (ast.get_docstring(tree) or "").split("\n\n")[0].replace("\n", " ")
            print(f"module {m}: {n} lines ({doc[:90]}...)")
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION:
                    problems += 1
                    print(f"function {m}.{node.name} (line {node.lineno}): {length} lines")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else "."))
