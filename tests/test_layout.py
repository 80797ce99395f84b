"""The package's import graph is one-way: no module of ``wtcli`` imports, directly or through
others, a module that imports it back (an import inside a function counts too: it runs as soon
as that function does). The perception chain runs segment -> contours -> pitch -> chain.

The graph is built from the source with ``ast``, without importing anything: every ``import`` and
``from ... import`` of a ``wtcli`` module, relative ones resolved. ``from wtcli.a import b``
depends on ``wtcli.a.b`` when that is a module, else on ``wtcli.a``; importing ``wtcli.a.b``
also runs the ``__init__`` of every package above it, so it depends on those too (except the
importer's own packages, which are already running).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "wtcli"


def module_files(root: Path = ROOT, package: str = PACKAGE) -> dict[str, Path]:
    """{dotted module name: file} of every module of the package (``__init__`` as the package)."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _resolve(name: str, current: str, is_package: bool, level: int) -> str:
    if level == 0:
        return name
    base = current.split(".") if is_package else current.split(".")[:-1]
    base = base[:len(base) - (level - 1)]
    return ".".join(base + ([name] if name else []))


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that importing ``module`` (or calling any of its functions) runs."""
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    named: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            named.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node.module or "", module, is_package, node.level)
            named.add(base)
            named.update(f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in modules)
    own = {".".join(module.split(".")[:k]) for k in range(1, module.count(".") + 2)}
    out = set()
    for name in named:
        if name != PACKAGE and not name.startswith(PACKAGE + "."):
            continue
        parts = name.split(".")
        while parts and ".".join(parts) not in modules:  # wtcli.a.SomeName -> wtcli.a
            parts.pop()
        # Importing wtcli.a.b runs wtcli/__init__ and wtcli/a/__init__ first.
        out.update(".".join(parts[:k]) for k in range(1, len(parts) + 1))
    return out - own


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = module_files(root)
    return {m: imports_of(m, p, modules) for m, p in modules.items()}


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle per strongly connected component of more than one module (Tarjan), as a path
    ``[a, b, ..., a]`` through the graph's edges; a module importing itself is one too."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    comps: list[list[str]] = []

    def visit(v: str) -> None:  # the package is a few hundred modules at most: recursion is fine
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
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
            if len(comp) > 1 or v in graph.get(v, ()):
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return [_cycle_in(graph, set(c)) for c in comps]


def _cycle_in(graph: dict[str, set[str]], comp: set[str]) -> list[str]:
    """A shortest cycle through the component's first module (breadth-first)."""
    start = min(comp)
    prev: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph[v] & comp):
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return path[::-1] + [start]
                if w not in prev:
                    prev[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"no cycle through {start}")  # a strongly connected set always has one


def test_wtcli_imports_are_acyclic():
    cycles = find_cycles(import_graph())
    assert not cycles, "import cycles in wtcli:\n" + "\n".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("lower, upper", [("wtcli.segment", "wtcli.pitch"),
                                          ("wtcli.pitch", "wtcli.chain"),
                                          ("wtcli.plan", "wtcli.segment")])
def test_chain_runs_one_way(lower, upper):
    """segment never imports pitch; pitch never runs the chain; plan reaches the segmenter only
    through ``wtcli.chain``."""
    graph = import_graph()
    def within(m: str, package: str) -> bool:
        return m == package or m.startswith(package + ".")

    bad = sorted(f"{m} -> {d}" for m, deps in graph.items() if within(m, lower)
                 for d in deps if within(d, upper))
    assert not bad, f"{lower} must not import {upper}: " + ", ".join(bad)


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def test_finds_a_cycle_through_a_function_level_relative_import(tmp_path):
    _write(tmp_path, {"wtcli/__init__.py": "", "wtcli/a.py": "from wtcli.b import f\n",
                      "wtcli/b.py": "def f():\n    from . import c\n",
                      "wtcli/c.py": "import wtcli.a\n", "wtcli/d.py": "from wtcli import a\n"})
    cycles = find_cycles(import_graph(tmp_path))
    assert cycles == [["wtcli.a", "wtcli.b", "wtcli.c", "wtcli.a"]]


def test_a_submodule_import_runs_its_package(tmp_path):
    """``from wtcli.p.x import y`` in q runs ``wtcli/p/__init__``, which imports q: a cycle. A
    package's own submodules importing each other through it are not."""
    _write(tmp_path, {"wtcli/__init__.py": "", "wtcli/p/__init__.py": "from .x import y\n",
                      "wtcli/p/x.py": "from wtcli.p.z import y\n", "wtcli/p/z.py": "y = 1\n",
                      "wtcli/q.py": "from wtcli.p.z import y\n"})
    assert find_cycles(import_graph(tmp_path)) == []
    (tmp_path / "wtcli/p/z.py").write_text("from wtcli import q\ny = 1\n")
    assert find_cycles(import_graph(tmp_path)) == [["wtcli.p", "wtcli.p.x", "wtcli.p.z", "wtcli.q",
                                                    "wtcli.p"]]
