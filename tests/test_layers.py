"""roboisf's subpackages form layers: every import goes down, none climbs back, none is private.

The graph is built from the source with ``ast`` — module-level imports, imports inside functions
and ``TYPE_CHECKING`` imports alike, since each is a dependency a reader has to follow — and an
arrow ``a -> b`` means some module of subpackage (or top-level module) ``a`` imports something of
``b``. :data:`LAYERS` declares the order, lowest first; an arrow may only point to a lower layer.
A cycle or a climbing arrow is reported with the imports that make it, so the message says which
line to move. A name with a leading underscore is private to its subpackage: importing it from
another one is reported too (make it public, or move it).
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

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


def nodes(src: Path = SRC, package: str = PACKAGE) -> set[str]:
    """The subpackages and top-level modules (but ``__init__``) of ``package``."""
    root = src / package
    subpackages = {p.name for p in root.iterdir() if (p / "__init__.py").is_file()}
    modules = {p.stem for p in root.glob("*.py") if p.stem != "__init__"}
    return subpackages | modules


def package_graph(src: Path = SRC, package: str = PACKAGE) -> Graph:
    """``graph[a][b]``: the imports (``"module:line -> target"``) by which subpackage ``a`` of
    ``package`` imports subpackage ``b`` (a ≠ b). A top-level module (``errors``, ``progress``,
    ``_lazy``, ``__main__``) is a node of its own; the package's ``__init__`` is left out."""
    subpackages = nodes(src, package)
    graph: Graph = defaultdict(lambda: defaultdict(list))
    for path in sorted((src / package).rglob("*.py")):
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


# The layers, lowest first. A package may import only packages of lower layers: not one of its
# own layer (peers are independent) and never one above. A new subpackage or top-level module
# must be placed here before the test passes.
LAYERS: list[tuple[str, set[str]]] = [
    ("foundation", {"errors", "progress", "_lazy"}),  # error classes, progress, lazy loading
    # the file-format registry (formats register by module name, so it imports none of them)
    # and the numba shim (its builder imports the kernel modules by name, in its own process)
    ("registries", {"formats", "jit"}),
    ("value objects", {"frames", "path", "plausible"}),  # transforms, Toolpath
    ("io base", {"io"}),  # tables, text, units, atomic writes, output folders
    ("file formats", {"cam", "logs"}),  # the Toolpath value object is below every format
    # the robot reads tables and units, not formats; summary.json's typed layout is a value
    # written by decompose and read by compensate and history
    ("models", {"robot", "fem", "sensor", "summary"}),
    ("parts and programs", {"parts", "programs"}),  # controllers' programs use the robot
    ("toolpaths and scans", {"toolpath", "scan"}),
    ("study", {"study"}),  # a study reads toolpaths and scans; neither knows a study
    ("cell", {"cell"}),
    ("cell consumers", {"plan", "learn", "sync", "history"}),  # history reads summary.json
    ("report and virtual cell", {"report", "virtual"}),  # plotting only in report
    ("decomposition", {"decompose"}),  # scan below decompose
    ("compensation", {"compensate"}),
    ("online", {"online"}),
    ("command line", {"cli"}),
    ("python -m roboisf", {"__main__"}),
]


def layer_of(layers: list[tuple[str, set[str]]]) -> dict[str, int]:
    """Each package's layer index (0 = lowest); a package declared twice is an error."""
    out: dict[str, int] = {}
    for i, (_, members) in enumerate(layers):
        for m in members:
            assert m not in out, f"{m} is declared in two layers"
            out[m] = i
    return out


def climbing(graph: Graph, layers: list[tuple[str, set[str]]]) -> list[str]:
    """Every arrow that does not go to a strictly lower layer, with its first import."""
    level = layer_of(layers)
    found = []
    for a in sorted(graph):
        for b in sorted(graph[a]):
            if level[b] >= level[a]:
                how = "climbs to" if level[b] > level[a] else "imports its peer"
                imports = graph[a][b]
                more = f" (+{len(imports) - 1} more)" if len(imports) > 1 else ""
                found.append(
                    f"{a} ({layers[level[a]][0]}) {how} {b} ({layers[level[b]][0]}): "
                    f"{imports[0]}{more}"
                )
    return found


def test_every_package_has_a_layer():
    declared = set(layer_of(LAYERS))
    present = nodes()
    assert not present - declared, f"declare a layer in LAYERS for {sorted(present - declared)}"
    assert not declared - present, f"LAYERS names what does not exist: {sorted(declared - present)}"


def test_no_arrow_climbs():
    graph = package_graph()
    assert "errors" in graph["cli"], "the graph misses top-level modules"
    found = climbing(graph, LAYERS)
    assert not found, "imports against the layer order:\n" + "\n".join(found)


def test_the_layer_check_finds_a_climbing_and_a_sideways_import(tmp_path):
    pkg = tmp_path / "demo"
    for name in ("low", "mid", "peer", "top"):
        (pkg / name).mkdir(parents=True)
        (pkg / name / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "base.py").write_text("")
    (pkg / "top" / "t.py").write_text("from demo.mid import m\nfrom demo import base\n")
    (pkg / "mid" / "m.py").write_text("from ..low import x\n")
    layers = [("b", {"base"}), ("l", {"low"}), ("m", {"mid", "peer"}), ("t", {"top"})]
    assert climbing(package_graph(tmp_path, "demo"), layers) == []
    (pkg / "low" / "x.py").write_text("def f():\n    from demo.top import t\n")
    (pkg / "peer" / "p.py").write_text("import demo.mid.m\n")
    found = climbing(package_graph(tmp_path, "demo"), layers)
    assert found == [
        "low (l) climbs to top (t): demo.low.x:2 -> demo.top",
        "peer (m) imports its peer mid (m): demo.peer.p:1 -> demo.mid.m",
    ]


def private_imports(src: Path = SRC, package: str = PACKAGE) -> list[str]:
    """Imports of a private name (a leading underscore, not a dunder) from outside the
    subpackage that owns it: ``from roboisf.robot.model import _x`` in ``roboisf.compensate``.
    The owner is the subpackage of the first private part of the dotted name (the package itself
    for a top-level private module such as ``roboisf._lazy``)."""
    found: list[tuple[str, int, str]] = []
    for path in sorted((src / package).rglob("*.py")):
        module, is_pkg = _module_name(path, src)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.ImportFrom):
                names = _imported(node, module, is_pkg)[1:]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            for name in names:
                parts = name.split(".")
                if parts[0] != package:
                    continue
                private = [
                    i for i, x in enumerate(parts) if x.startswith("_") and not x.endswith("__")
                ]
                if not private:
                    continue
                owner = ".".join(parts[: min(private[0], 2)])
                if module != owner and not module.startswith(owner + "."):
                    found.append((module, node.lineno, name))
    return [f"{m}:{line} imports {name}" for m, line, name in sorted(found)]


def test_no_private_name_is_imported_across_packages():
    found = private_imports()
    assert not found, "private names used outside their package (make them public):\n" + "\n".join(
        found
    )


def test_the_private_check_finds_a_private_name_from_another_package(tmp_path):
    pkg = tmp_path / "demo"
    for name in ("a", "b"):
        (pkg / name).mkdir(parents=True)
        (pkg / name / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "_helper.py").write_text("")
    (pkg / "a" / "x.py").write_text("def _f():\n    pass\n__version__ = 1\n")
    (pkg / "a" / "y.py").write_text("from .x import _f\n")  # its own package: fine
    (pkg / "b" / "z.py").write_text(
        "from demo._helper import g\nfrom demo.a.x import __version__\nfrom demo.a import x\n"
    )
    assert private_imports(tmp_path, "demo") == []
    (pkg / "b" / "z.py").write_text("def h():\n    from ..a.x import _f\nimport demo.a._m\n")
    assert private_imports(tmp_path, "demo") == [
        "demo.b.z:2 imports demo.a.x._f",
        "demo.b.z:3 imports demo.a._m",
    ]
