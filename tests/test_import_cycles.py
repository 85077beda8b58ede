"""vibromodel's modules import each other without cycles, counting function-local imports too: a cycle hidden by
an import inside a function still ties the modules into one (issue 22). Run as a script to print the graph's cycles.

The graph: an edge a -> b for every `import` / `from ... import` in a's source (module level or inside a function)
that names vibromodel module b (`from . import forces`, `from .models import ...`, `import vibromodel.plant`).
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "fmu_src" / "vibromodel"


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """module -> the package's modules it imports anywhere in its source."""
    modules = {path.stem for path in package.glob("*.py")} - {"__init__"}
    graph = {}
    for module in sorted(modules):
        edges = set()
        for node in ast.walk(ast.parse((package / f"{module}.py").read_text())):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level == 1 or (node.level == 0 and base.split(".")[0] == package.name):
                    name = base.split(".", 1)[1] if node.level == 0 and "." in base else ("" if node.level == 0 else base)
                    targets = [name] if name else [alias.name for alias in node.names]  # `from . import forces`
                    edges.update(t.split(".")[0] for t in targets)
            elif isinstance(node, ast.Import):
                edges.update(alias.name.split(".")[1] for alias in node.names
                             if alias.name.startswith(package.name + "."))
        graph[module] = (edges & modules) - {module}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in sorted(graph[node]):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_graph_sees_function_local_imports():
    graph = import_graph()
    assert "forces" in graph["models"]  # `from . import forces` at module level
    assert {"averaging", "slowflow"} <= graph["fidelities"]  # imported inside a function (fidelity 3 only)


def test_a_cycle_is_found():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_vibromodel_has_no_import_cycles():
    assert cycles(import_graph()) == []


if __name__ == "__main__":
    graph = import_graph()
    for component in cycles(graph):
        print("cycle:", " <-> ".join(component))
        for module in component:
            print(f"  {module} -> {', '.join(sorted(graph[module] & set(component)))}")
    sys.exit(1 if cycles(graph) else 0)
