"""The package import graph has no cycle: roboisf's subpackages form layers.

The graph is built from the source with ``ast`` — module-level imports, imports inside functions
and ``TYPE_CHECKING`` imports alike, since each is a dependency a reader has to follow — and an
arrow ``a -> b`` means some module of subpackage ``a`` imports something of subpackage ``b``.
A cycle is reported with the imports that make it, so the message says which line to move.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = "roboisf"

Graph = dict[str, dict[str, list[str]]]


def _module_name(path: Path, src: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(src).with_suffix("").parts)
    is_pkg = parts[-1] == "__init__"
    if is_pkg:
        parts = parts[:-1]
    return ".".join(parts), is_pkg


def _imported(node: ast.AST, module: str, is_pkg: bool) -> list[str]:
    """The absolute module names an import statement names (``from m import x`` → m and m.x)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = module.split(".") if is_pkg else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            target = ".".join([*base, node.module] if node.module else base)
        else:
            target = node.module or ""
        return [target, *(f"{target}.{a.name}" for a in node.names)]
    return []


def package_graph(src: Path = SRC, package: str = PACKAGE) -> Graph:
    """``graph[a][b]``: the imports (``"module:line -> target"``) by which subpackage ``a`` of
    ``package`` imports subpackage ``b`` (a ≠ b). Top-level modules (``errors``, ``_lazy``) are no
    package and import none, so they are left out."""
    root = src / package
    subpackages = {p.name for p in root.iterdir() if (p / "__init__.py").is_file()}
    graph: Graph = defaultdict(lambda: defaultdict(list))
    for path in sorted(root.rglob("*.py")):
        module, is_pkg = _module_name(path, src)
        parts = module.split(".")
        if len(parts) < 2 or parts[1] not in subpackages:
            continue
        here = parts[1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            for target in _imported(node, module, is_pkg):
                t = target.split(".")
                if len(t) < 2 or t[0] != package or t[1] not in subpackages or t[1] == here:
                    continue
                graph[here][t[1]].append(f"{module}:{node.lineno} -> {target}")
                break
    return graph


def cycles(graph: Graph) -> list[list[str]]:
    """The strongly connected components of more than one package (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def describe(graph: Graph, component: list[str]) -> str:
    """The arrows inside a cycle, each with the first import that makes it."""
    lines = [" <-> ".join(component)]
    for a in component:
        for b in component:
            if b in graph.get(a, {}):
                imports = graph[a][b]
                more = f" (+{len(imports) - 1} more)" if len(imports) > 1 else ""
                lines.append(f"  {a} -> {b}: {imports[0]}{more}")
    return "\n".join(lines)


def test_no_import_cycle_between_packages():
    graph = package_graph()
    assert graph, "no package imports found: the graph builder is looking in the wrong place"
    found = cycles(graph)
    assert not found, "package import cycles:\n" + "\n".join(describe(graph, c) for c in found)


def test_the_checker_finds_a_cycle_through_a_function_level_import(tmp_path):
    # the test above is not vacuous: a lazy import inside a function still closes a cycle
    pkg = tmp_path / "demo"
    for name in ("a", "b", "c"):
        (pkg / name).mkdir(parents=True)
        (pkg / name / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "a" / "x.py").write_text("from demo.b.y import f\n")
    (pkg / "b" / "y.py").write_text("def f():\n    from ..c import z\n    return z\n")
    (pkg / "c" / "z.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from demo.a import x\n"
    )
    graph = package_graph(tmp_path, "demo")
    assert cycles(graph) == [["a", "b", "c"]]
    text = describe(graph, ["a", "b", "c"])
    assert "b -> c: demo.b.y:2 -> demo.c" in text and "c -> a: demo.c.z:3 -> demo.a" in text
    (pkg / "c" / "z.py").write_text("")
    assert cycles(package_graph(tmp_path, "demo")) == []


@pytest.mark.parametrize(
    ("lower", "higher"),
    [
        ("path", "io"),  # the Toolpath value object is below every format
        ("io", "robot"),  # the robot reads tables and units; formats do not need the robot
        ("robot", "programs"),  # controllers' programs use the arm configuration, not back
        ("io", "programs"),
        ("toolpath", "study"),  # a study reads toolpaths; the toolpath package knows no study
        ("scan", "decompose"),
    ],
)
def test_layer_order(lower, higher):
    graph = package_graph()
    assert higher not in graph.get(lower, {}), f"{lower} must not import {higher}: " + "; ".join(
        graph[lower][higher][:3]
    )
