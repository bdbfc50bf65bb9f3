"""The import structure of prioik's modules, read from their source with ``ast``
(module-level and function-local imports alike)."""

from __future__ import annotations

import ast
from pathlib import Path

from prioik.formulations import registry

ROOT = Path(__file__).resolve().parents[1]
#: installed sub-package → its folder in the repository (pyproject.toml's wheel.packages)
PACKAGES = {"prioik": "prioik", "prioik.hierarchy": "hierarchy",
            "prioik.formulations": "formulations", "prioik.robots": "robots",
            "prioik.benchmarks": "benchmarks"}


def module_files() -> dict[str, Path]:
    """Every module of prioik (dotted name → file), from the folders."""
    out = {}
    for package, folder in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def imported_names(module: str, path: Path) -> list[tuple[str, str | None]]:
    """``(module, name)`` of every import in the file, anywhere in it (``name``: what
    ``from module import name`` takes; ``None`` for ``import module``), relative
    imports resolved."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[tuple[str, str | None]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            out += [(base, a.name) for a in node.names]
    return out


def test_no_plugin_imports_another_plugin():
    """A plugin takes shared numerics from formulations._numerics (or _compiled), never
    from another plugin: adding, removing or changing one plugin touches no other."""
    files = module_files()
    plugins = {module for module, _ in registry.PLUGINS.values()}
    assert plugins <= set(files)
    found = []
    for module in sorted(plugins):
        for target, name in imported_names(module, files[module]):
            full = f"{target}.{name}" if name else target
            if (target in plugins or full in plugins) and module not in (target, full):
                found.append(f"{module} imports {full}")
    assert found == []


def _type_checking_only(tree: ast.AST) -> set[int]:
    """ids of the import nodes inside ``if TYPE_CHECKING:`` blocks (never run)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return out


def import_graph() -> dict[str, set[str]]:
    """module → the prioik modules it imports (module-level and function-local imports;
    ``from package import name`` is an edge to ``package.name`` when that is a module,
    else to ``package``; imports under ``if TYPE_CHECKING:`` are left out: they never
    run)."""
    files = module_files()
    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _type_checking_only(tree)
        edges: set[str] = set()
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                edges |= {a.name for a in node.names if a.name in files}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")
                    anchor = anchor[:len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                for a in node.names:
                    if f"{base}.{a.name}" in files:
                        edges.add(f"{base}.{a.name}")
                    elif base in files:
                        edges.add(base)
        edges.discard(module)
        graph[module] = edges
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted:
    every import circle lies in one of them."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
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
    return sorted(out)


def test_the_import_graph_is_read_whole():
    graph = import_graph()
    assert "prioik.formulations.registry" in graph["prioik.formulations"]
    assert "prioik.formulations.base" in graph["prioik.formulations.prepared"]
    assert "prioik.benchmarks.fencing" not in graph["prioik.cli"]     # (named as strings)
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == \
        [["a", "b", "c"]]


def test_no_import_circle_between_prioik_modules():
    """No module of prioik imports, directly or through others, a module that imports it
    back — neither at module level nor inside a function (a function-local import only
    hides a circle): each concern sits on a layer above the modules it uses."""
    assert import_cycles(import_graph()) == []
