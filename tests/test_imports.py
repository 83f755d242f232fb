"""The package's import graph, read from the source with ``ast`` (nothing of rmbench is imported,
so neither torch nor mujoco loads): it has no cycle, and every import points down the layers.

An import counts wherever it stands, at module level or inside a function: a deferred import
still makes the importer depend on the imported at run time. Importing ``rmbench.a.b`` runs
``rmbench/a/__init__.py`` first, so it depends on ``rmbench.a`` too, unless the importer sits
inside ``rmbench.a`` (its own package is already running by then).
"""

from __future__ import annotations

import ast
import importlib.util
import pkgutil
from pathlib import Path

ROOT = "rmbench"

# Lowest first; a module may import its own layer and those below, never one above. Keyed by
# the name under rmbench (rmbench.<name>...); the rmbench package itself, the public facade,
# is left out.
LAYERS: list[set[str]] = [
    # utilities: they import only each other (video writes through files, parallel checks the source)
    {"files", "identity", "seeds", "video", "video_rule", "source", "parallel", "machine"},
    {"sim"},  # MuJoCo station, robot, objects, rendering backend
    {"tasks"},  # task definitions over the simulator
    {"envs", "experts"},  # the gymnasium env, and the scripted experts beside it
    {"rollout", "aliasing", "quickstart", "robustness"},  # expert rollouts over envs
    {"data"},  # demonstration datasets: collection (envs + experts), reading, checking
    {"training"},  # the loop and batch sources learned policies train with
    {"policies"},  # the policy interface, its spec registry, the built-in and learned policies
    {"eval"},  # the harness that runs a policy spec on expert-verified seeds
    {"suite"},  # the benchmark's tables: collect, train and evaluate every cell
    # the websocket policy server and the remote: client policy; rmbench inside LeRobot
    {"serve", "lerobot"},
    {"cli"},  # the command line
]
LAYER = {name: depth for depth, names in enumerate(LAYERS) for name in names}


def package_dir() -> Path:
    # find_spec on a top-level name locates it without running its __init__
    spec = importlib.util.find_spec(ROOT)
    assert spec is not None and spec.submodule_search_locations, f"{ROOT} is not importable"
    return Path(next(iter(spec.submodule_search_locations)))


def modules() -> dict[str, Path]:
    """Every module of the package: its dotted name -> its file (``__init__.py`` for a package).
    pkgutil.iter_modules level by level, as walk_packages would, without importing packages."""
    found: dict[str, Path] = {ROOT: package_dir() / "__init__.py"}
    stack = [(package_dir(), ROOT)]
    while stack:
        folder, prefix = stack.pop()
        for info in pkgutil.iter_modules([str(folder)]):
            name = f"{prefix}.{info.name}"
            if info.ispkg:
                found[name] = folder / info.name / "__init__.py"
                stack.append((folder / info.name, name))
            else:
                found[name] = folder / f"{info.name}.py"
    return found


def imported(name: str, path: Path, known: set[str]) -> set[str]:
    """The package's modules that ``name`` (its source at ``path``) imports, anywhere in it."""
    is_package = path.name == "__init__.py"
    # what a relative import of level 1 is relative to
    here = name if is_package else name.rpartition(".")[0]
    targets: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = here.split(".")
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            targets.add(base)
            # ``from pkg import sub`` imports the submodule when there is one
            targets.update(f"{base}.{alias.name}" for alias in node.names
                           if f"{base}.{alias.name}" in known)
    deps: set[str] = set()
    for target in targets:
        if target != ROOT and not target.startswith(ROOT + "."):
            continue
        parts = target.split(".")
        for end in range(1, len(parts) + 1):  # the target and the packages it runs first
            dep = ".".join(parts[:end])
            # the importer's own packages are initialised already (rmbench itself included)
            if dep in known and dep != name and not name.startswith(dep + "."):
                deps.add(dep)
    return deps


def import_graph() -> dict[str, set[str]]:
    found = modules()
    known = set(found)
    return {name: imported(name, path, known) for name, path in found.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Within each strongly connected component (Tarjan's algorithm) of more than one module,
    or of one that imports itself: a shortest cycle through each of its modules, each a path
    that ends where it starts (one cycle per component would hide the others in it)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[set[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.add(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph[v]:
                components.append(component)

    for v in sorted(graph):
        if v not in index:
            connect(v)
    found: list[list[str]] = []
    for component in components:
        for start in sorted(component):
            cycle = _shortest_cycle(start, component, graph)
            if not any(_same_cycle(cycle, other) for other in found):
                found.append(cycle)
    return found


def _shortest_cycle(start: str, members: set[str], graph: dict[str, set[str]]) -> list[str]:
    """A shortest path from ``start`` back to itself through ``members`` (breadth first)."""
    previous: dict[str, str] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(graph[v] & members):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(previous[path[-1]])
                    return [*reversed(path), start]
                if w not in previous:
                    previous[w] = v
                    following.append(w)
        frontier = following
    raise AssertionError(f"no cycle through {start}")


def _same_cycle(a: list[str], b: list[str]) -> bool:
    if len(a) != len(b):
        return False
    ring = a[:-1]
    i = ring.index(b[0]) if b[0] in ring else -1
    return i >= 0 and ring[i:] + ring[:i] == b[:-1]


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The graph between rmbench's top-level packages and modules (rmbench.<name>)."""
    top = {name: ".".join(name.split(".")[:2]) for name in graph if name != ROOT}
    out: dict[str, set[str]] = {t: set() for t in top.values()}
    for name, deps in graph.items():
        if name != ROOT:
            out[top[name]].update(top[d] for d in deps if d != ROOT and top[d] != top[name])
    return out


def _report(found: list[list[str]]) -> str:
    return "\n".join("  " + " -> ".join(c) for c in found)


def test_the_graph_is_read():
    graph = import_graph()
    # spot checks that the walk and the parsing see what is there
    assert "rmbench.policies.mem0.agent" in graph and "rmbench.cli.main" in graph
    assert "rmbench.data.layout" in graph["rmbench.policies.mem0.train"]  # from pkg import sub
    assert "rmbench.data" in graph["rmbench.policies.mem0.train"]  # the package it runs first
    assert "rmbench.eval" in graph["rmbench.cli.evaluate"]  # an import inside a function
    assert "rmbench.sim" in graph[ROOT]  # from rmbench import sim


def test_the_cycle_check_finds_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}, "f": {"a"}}
    assert cycles(graph) == [["a", "b", "c", "a"], ["e", "e"]]
    graph["d"] = {"c"}
    assert cycles(graph) == [["a", "b", "c", "a"], ["c", "d", "c"], ["e", "e"]]


def test_no_import_cycles():
    found = cycles(import_graph())
    assert not found, "import cycles between modules:\n" + _report(found)


def test_no_cycles_between_packages():
    # e.g. training.loop -> policies.checkpoint beside policies.visuomotor -> training.loop:
    # no cycle of modules, but the two packages could no longer be layered
    found = cycles(package_graph(import_graph()))
    assert not found, "import cycles between rmbench's packages:\n" + _report(found)


def test_imports_point_down_the_layers():
    graph = import_graph()
    tops = {name.split(".")[1] for name in graph if name != ROOT}
    assert tops <= set(LAYER), f"not in LAYERS, place them: {sorted(tops - set(LAYER))}"
    upward = sorted(f"{name} ({LAYER[name.split('.')[1]]}) -> {dep} ({LAYER[dep.split('.')[1]]})"
                    for name, deps in graph.items() if name != ROOT
                    for dep in deps if dep != ROOT
                    and LAYER[dep.split(".")[1]] > LAYER[name.split(".")[1]])
    assert not upward, "imports of a higher layer:\n" + "\n".join("  " + u for u in upward)
