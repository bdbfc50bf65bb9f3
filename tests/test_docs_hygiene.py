"""Docstrings state contracts and user pages stay free of the lab notebook.

* Every public docstring — the modules, classes, functions, methods and properties
  reachable from ``prioik.__all__``, ``prioik.robots.__all__`` and the formulation
  modules' public names — is at most :data:`MAX_DOCSTRING_LINES` lines
  (``inspect.cleandoc``).
* No fuzz-case or stop identifier (:data:`IDENTIFIERS`) in any tracked text file
  outside ``tests/`` and ``docs/notes/`` (the design log): code, comments, docstrings,
  README and user pages name what holds, not which case found it.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import pkgutil
import re
import subprocess
import types
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_DOCSTRING_LINES = 40

#: the identifiers of the lab notebook, by what they name
IDENTIFIERS = {
    # a saved fuzz case: <kind>-<seed>-<index> (equality-1243-387, bounds-1205-1331,
    # inequality-drift-1478, independent-14-976)
    "fuzz case": re.compile(r"\b(?:equality|inequality|bounds|mixed_scale|independent)"
                            r"-(?:\d+|drift)-\d+\b"),
    # a fuzz case by seed and index: "fuzz 5-32", "fuzz inequality seed 1 case 448"
    "fuzz seed and index": re.compile(r"\bfuzz(?:ing)?\s+(?:\w+\s+)?(?:seed\s+)?\d+"
                                      r"(?:-\d+|\s+case\s+\d+)", re.I),
    # a fuzz seed named as the place something was found: "seed 1248's", "at seed 1250",
    # "--seed 1245", "seeds 1205 and 7"
    "fuzz seed": re.compile(r"(?:--seed[ =]\d{3,}|\bseeds?\s+\d{3,}(?:'s|\s+and\s+\d+)"
                            r"|\bat\s+seed\s+\d+)", re.I),
    # a development stop: "stop 37", "Stop 38", "(before stop 35)"
    "stop": re.compile(r"\bstops?\s+#?\d+\b", re.I),
}

#: tracked files that hold text a reader reads (data, images and generated tables aside)
TEXT_SUFFIXES = {".py", ".md", ".toml", ".txt", ".cfg", ".hpp", ".cpp", ".h", ".cmake",
                 ".yml", ".yaml", ".sh", ".in"}
TEXT_NAMES = {"Makefile", "CMakeLists.txt", "README.md", "run"}


def _scanned_files() -> list[Path]:
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True,
                             check=True).stdout.decode().split("\0")
    files = []
    for name in tracked:
        if not name or name.startswith(("tests/", "docs/notes/")):
            continue
        path = ROOT / name
        if (path.suffix in TEXT_SUFFIXES or path.name in TEXT_NAMES) and path.is_file():
            files.append(path)
    return files


def identifier_hits() -> list[str]:
    """``path:line: kind: text`` of every identifier outside tests/ and docs/notes/."""
    hits = []
    for path in _scanned_files():
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            for kind, pattern in IDENTIFIERS.items():
                match = pattern.search(line)
                if match:
                    hits.append(f"{path.relative_to(ROOT)}:{number}: {kind}: "
                                f"{match.group(0)!r}")
    return hits


def test_the_patterns_catch_the_notebooks_identifiers():
    caught = ["fuzz equality-1243-387", "(fuzz 5-32: rows of", "`bounds-1205-1331`",
              "`inequality-drift-1478`", "`independent-14-976`",
              "fuzz inequality seed 1 case 448", "seed 1248's first 200",
              "stacks at seed 1250, all", "``prioik fuzz --seed 1245``",
              "seeds 1205 and 7", "Stop 37. On the six", "(before stop 35)"]
    for text in caught:
        assert any(p.search(text) for p in IDENTIFIERS.values()), text
    kept = ["prioik fuzz --n 1000 --seed 1 --out /tmp/fuzz",
            "random (200 draws, seed 16): uniform", "one fixed SPD ``M``, seed 0",
            "stop when the step is shorter", "equality-S-i.json", "100 steps"]
    for text in kept:
        assert not any(p.search(text) for p in IDENTIFIERS.values()), text


def test_no_fuzz_or_stop_identifiers_outside_tests_and_notes():
    hits = identifier_hits()
    assert not hits, "\n".join(hits)


# ------------------------------------------------------------------ docstrings
def _public_objects() -> dict[str, object]:
    """Name → object of the public API (see the module docstring)."""
    import prioik
    import prioik.formulations
    found: dict[int, tuple[str, object]] = {}

    def visit(name: str, obj, members: bool) -> None:
        if id(obj) in found or not (isinstance(obj, (types.ModuleType, property))
                                    or inspect.isclass(obj) or callable(obj)):
            return
        found[id(obj)] = (name, obj)
        if inspect.isclass(obj):
            for key, value in vars(obj).items():
                if key.startswith("_"):
                    continue
                if isinstance(value, (staticmethod, classmethod)):
                    value = value.__func__
                if callable(value) or isinstance(value, property):
                    visit(f"{name}.{key}", value, False)
        if isinstance(obj, types.ModuleType) and members:
            for key in getattr(obj, "__all__", ()):
                visit(f"{name}.{key}", getattr(obj, key), False)

    visit("prioik", prioik, False)
    for key in prioik.__all__:
        if key in ("__version__", "robots", "benchmarks"):
            continue
        value = getattr(prioik, key)
        visit(f"prioik.{key}", value, isinstance(value, types.ModuleType))
    from prioik.formulations.registry import PLUGINS
    unavailable = {PLUGINS[f.name][0] for f in prioik.formulations.available()
                   if not f.available}          # (the registry says why: extra, build)
    for info in pkgutil.iter_modules(prioik.formulations.__path__):
        if f"prioik.formulations.{info.name}" in unavailable:
            continue
        module = importlib.import_module(f"prioik.formulations.{info.name}")
        visit(module.__name__, module, False)
        for key, value in vars(module).items():
            if not key.startswith("_") and getattr(value, "__module__", None) == module.__name__:
                visit(f"{module.__name__}.{key}", value, False)
    try:
        robots = importlib.import_module("prioik.robots")
    except ImportError:
        pass
    else:
        visit("prioik.robots", robots, True)
    benchmarks = importlib.import_module("prioik.benchmarks")
    visit("prioik.benchmarks", benchmarks, False)
    return {name: obj for name, obj in found.values()}


def docstring_lines(obj) -> int:
    doc = obj.__doc__ if isinstance(obj, types.ModuleType) else inspect.getdoc(obj)
    return len(inspect.cleandoc(doc).splitlines()) if doc else 0


def test_the_public_api_is_walked():
    import prioik
    from prioik.formulations import extended_jacobian, hierarchical_active_set
    walked = {id(obj) for obj in _public_objects().values()}
    for obj in (prioik.solve, prioik.check_lexicographic, prioik.PreparedSolver.solve,
                prioik.Solution, hierarchical_active_set, extended_jacobian,
                hierarchical_active_set.Prepared):
        assert id(obj) in walked, obj
    pytest.importorskip("pinocchio")
    from prioik.robots import TaskWriter
    assert id(TaskWriter.add_frame_region) in walked


def test_public_docstrings_are_at_most_40_lines():
    lengths = {name: docstring_lines(obj) for name, obj in _public_objects().items()}
    long = sorted((n, name) for name, n in lengths.items() if n > MAX_DOCSTRING_LINES)
    assert not long, "\n".join(f"{n} lines: {name}" for n, name in long)
