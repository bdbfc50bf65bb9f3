"""prioik: task-priority inverse kinematics for highly redundant robots.

One task-stack spec, every major formulation behind it by name, a lexicographic
certificate for any answer, and a prepared solve path for control loops::

    import prioik
    stack = prioik.Task("contact", J1, h1) / prioik.Task("tip", J2, h2)
    sol = prioik.solve(stack, "extended_jacobian")
    prioik.check_lexicographic(stack, sol.x).ok
    solver = prioik.prepare(stack.layout, "extended_jacobian")   # once
    solver.solve(data)                                            # every step

Sub-packages (data flows one way, top to bottom):

* :mod:`prioik.hierarchy` — the pure-numpy spec: tasks, levels, stacks, layouts,
  analysis and the lexicographic certificate;
* :mod:`prioik.formulations` — the formulation plugins and their registry;
* :mod:`prioik.robots` — robot models (pinocchio) and task writers (imported on first
  use: it needs the ``robots`` extra);
* :mod:`prioik.benchmarks` — comparisons, reports and their commands (the ``prioik``
  command line itself: :mod:`prioik.cli`);
* :mod:`prioik.errors` — :class:`PrioikError`, the base of every error prioik raises;
* :mod:`prioik.extras` — which ``pip install prioik[EXTRA]`` brings which part
  (``pip install prioik`` is the core: numpy, scipy, threadpoolctl, tqdm and the
  compiled C++ core ``prioik._core``).

Importing prioik changes nothing in the process (no environment variable, no BLAS
thread setting).
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

from . import errors, extras, formulations, hierarchy
from .errors import PrioikError, UnknownNameError
from .extras import MissingExtraError
from .formulations import (
    BatchSolution,
    Capabilities,
    ConcurrentUseError,
    Diagnostics,
    Fault,
    FormulationError,
    Option,
    PreparedSolver,
    Solution,
    Status,
    Verification,
    available,
    prepare,
    solve,
    solve_batch,
)
from .hierarchy import (
    Level,
    LexicographicReport,
    StackData,
    StackLayout,
    Task,
    TaskStack,
    TaskStackError,
    UnsupportedTaskError,
    check_lexicographic,
    hard,
    load_stack,
    save_stack,
)


def _installed_version() -> str:
    try:
        return _version("prioik")
    except PackageNotFoundError:  # pragma: no cover - a source tree that was never installed
        return "0+unknown"


__version__: str = _installed_version()
"""The installed distribution's version (``"0+unknown"`` for a source tree never installed)."""

_LAZY = ("robots", "benchmarks")


def __getattr__(name: str):
    # robots needs pinocchio and benchmarks the plotting/QP stack: import them on first use
    if name in _LAZY:
        module = importlib.import_module(f"{__name__}.{name}")
        globals()[name] = module
        return module
    raise AttributeError(f"module 'prioik' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "BatchSolution", "Capabilities", "ConcurrentUseError", "Diagnostics", "Fault",
    "FormulationError", "Level", "LexicographicReport", "MissingExtraError", "Option",
    "PreparedSolver", "PrioikError", "Solution", "StackData", "StackLayout", "Status", "Task",
    "TaskStack", "TaskStackError", "UnknownNameError", "UnsupportedTaskError", "Verification",
    "__version__", "available", "benchmarks", "check_lexicographic", "errors", "extras",
    "formulations", "hard", "hierarchy", "load_stack", "prepare", "robots", "save_stack",
    "solve", "solve_batch",
]
