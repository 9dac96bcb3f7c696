"""The tree's boundaries: layers that import only downwards, no import cycle (counting imports inside functions and under TYPE_CHECKING), and
rospy's internals reached only inside the TCPROS transport (micros_rt/transports/tcpros/)."""

from __future__ import annotations

import ast
import re
from pathlib import Path
from typing import Dict, List, Set

PACKAGE = Path(__file__).resolve().parents[2] / "micros_rt"


def _modules() -> Dict[str, Path]:
    mods: Dict[str, Path] = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        mods[name] = path
    return mods


def _imports(name: str, path: Path, mods: Dict[str, Path]) -> Set[str]:
    """Every micros_rt module ``name`` imports, anywhere in the file (functions, TYPE_CHECKING included)."""
    here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found: Set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = here[:len(here) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else [])) if node.level else str(node.module)
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                found.add(sub if sub in mods else target)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return {m for m in found if m in mods and m != name}


def _cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    out: List[List[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp: List[str] = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def _without_package_edges(graph: Dict[str, Set[str]]) -> Dict[str, Set[str]]:
    # a package's __init__ importing its own submodules (and they importing siblings through it) is how
    # Python packages are made, not a cycle between concerns
    return {m: {t for t in ts if not (m.startswith(t + ".") or t.startswith(m + "."))} for m, ts in graph.items()}


def test_no_import_cycle() -> None:
    mods = _modules()
    graph = _without_package_edges({name: _imports(name, path, mods) for name, path in mods.items()})
    assert _cycles(graph) == []


def test_cycle_finder_finds_a_cycle() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_rospy_internals_only_in_the_tcpros_transport() -> None:
    internal = re.compile(r"rospy\.impl|\.impl\.(add_|set_|publish|connections)|from rospy\.impl")
    tcpros = PACKAGE / "transports" / "tcpros"
    offenders = [f"{p.relative_to(PACKAGE.parent)}:{i}: {line.strip()}"
                 for p in PACKAGE.rglob("*.py") if p.parent != tcpros
                 for i, line in enumerate(p.read_text().splitlines(), 1) if internal.search(line)]
    assert offenders == []


#: lowest first; a module may import its own layer and the layers below it, never one above
LAYERS = (
    ("support", ("micros_rt.exceptions", "micros_rt.rostypes", "micros_rt.log", "micros_rt.ratelimit", "micros_rt.cyclone",
                 "micros_rt.settings")),
    ("qos and negotiation", ("micros_rt.qos", "micros_rt.negotiation")),
    ("transports", ("micros_rt.transports",)),
    ("core", ("micros_rt.core",)),
    ("public API", ("micros_rt", "micros_rt.node", "micros_rt.drop_in")),
    ("programs", ("micros_rt.bridges", "micros_rt.cli", "micros_rt.__main__")),
)


def _layer(module: str) -> int:
    best = (-1, 0)
    for rank, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best[1]:
                best = (rank, len(prefix))
    assert best[0] >= 0, f"{module} is in no layer of LAYERS"
    return best[0]


def _upward_imports(graph: Dict[str, Set[str]]) -> List[str]:
    return sorted(f"{m} ({LAYERS[_layer(m)][0]}) imports {t} ({LAYERS[_layer(t)][0]})"
                  for m, ts in graph.items() for t in ts if _layer(t) > _layer(m))


def test_layers_import_only_downwards() -> None:
    mods = _modules()
    graph = {name: _imports(name, path, mods) for name, path in mods.items()}
    assert _upward_imports(graph) == []


def test_layer_check_finds_an_upward_import() -> None:
    graph = {"micros_rt.transports.dds.backend": {"micros_rt.core.runtime", "micros_rt.qos.options"},
             "micros_rt.core.send_queue": {"micros_rt.transports.base"}}
    assert _upward_imports(graph) == ["micros_rt.transports.dds.backend (transports) imports micros_rt.core.runtime (core)"]
