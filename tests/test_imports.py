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
