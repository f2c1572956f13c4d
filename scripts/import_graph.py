"""The import graph of the pnlviz package, read from the code: every ``import`` statement,
function-level (lazy) ones included.

    python scripts/import_graph.py            # rooms and what they import, then any cycle
    python scripts/import_graph.py --modules  # the same, module by module

A *room* is a subpackage (``pnlviz.calib``, ``pnlviz.app``...) or a top-level module
(``pnlviz.conventions``). ``tests/test_architecture.py`` uses these functions: no cycle between
modules, none between rooms, and no room importing one that docs/architecture.md does not allow.
"""

from __future__ import annotations

import argparse
import ast
from collections.abc import Iterable
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "pnlviz"


def module_name(path: Path, root: Path = PACKAGE) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imported(node: ast.AST, module: str, is_package: bool, modules: set[str]) -> Iterable[str]:
    """The pnlviz modules an import statement loads (``from x import y`` counts ``x.y`` when
    that is a module, else ``x``)."""
    if isinstance(node, ast.Import):
        for alias in node.names:
            if alias.name.split(".")[0] == "pnlviz":
                yield alias.name
        return
    if not isinstance(node, ast.ImportFrom):
        return
    if node.level:  # relative: from the package of this module
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[: len(base) - node.level + 1]
        source = ".".join(base + ([node.module] if node.module else []))
    else:
        source = node.module or ""
    if source.split(".")[0] != "pnlviz":
        return
    for alias in node.names:
        yield f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """module -> the pnlviz modules it imports (anywhere in it)."""
    files = {module_name(p, root): p for p in sorted(root.rglob("*.py"))}
    modules = set(files)
    graph = {}
    for module, path in files.items():
        tree = ast.parse(path.read_text(), str(path))
        found = {m for node in ast.walk(tree) for m in _imported(node, module, path.name == "__init__.py", modules)}
        graph[module] = {m for m in found if m in modules and m != module}
    return graph


def room(module: str) -> str:
    parts = module.split(".")
    return ".".join(parts[:2])


def room_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """room -> the other rooms it imports."""
    out: dict[str, set[str]] = {}
    for module, deps in graph.items():
        out.setdefault(room(module), set()).update(room(d) for d in deps if room(d) != room(module))
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one node (Tarjan), each sorted."""
    index, low, on_stack, stack, out, counter = {}, {}, set(), [], [], [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--modules", action="store_true", help="module by module, not room by room")
    args = ap.parse_args()
    graph = import_graph()
    shown = graph if args.modules else room_graph(graph)
    for name in sorted(shown):
        print(f"{name:28s} -> {', '.join(sorted(shown[name])) or '(nothing of pnlviz)'}")
    found = cycles(graph) + [c for c in cycles(room_graph(graph))]
    print("\nno import cycle" if not found else "\ncycles:\n" + "\n".join("  " + " -> ".join(c) for c in found))


if __name__ == "__main__":
    main()
