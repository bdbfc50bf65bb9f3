"""The formulation registry: one line per plugin module, imported on demand.

A plugin is a module that defines

* ``NAME`` (str), ``DESCRIPTION`` (one line), ``CAPABILITIES`` (:class:`Capabilities`),
* ``OPTIONS``: ``{option: (default, description)}``, the only options it accepts,
* ``solve(stack, **options) -> Outcome``,
* optionally ``backends() -> list[str]``, the back-ends it can use here,
* optionally ``solve_batch(stacks, **options) -> (X, statuses)`` for many stacks of one
  shape (stacked linear algebra); :func:`solve_batch` loops over ``solve`` otherwise.

A plugin whose optional dependency is not installed is unavailable; the reason,
ending with the extra to install (``install it with `pip install prioik[qp]```), is
recorded and repeated when that formulation is asked for.
"""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass, field
from types import ModuleType
from typing import Any

import numpy as np

from prioik.extras import install_hint
from prioik.hierarchy import TaskStack, UnsupportedTaskError, lexicographic_residuals

from .base import STATUSES, Capabilities, FormulationError, Outcome, Solution

#: name -> (module, the extra of pyproject.toml that brings its dependencies; "" for the
#: core). prioik.extras.EXTRAS names the extras.
PLUGINS: dict[str, tuple[str, str]] = {
    "reference": ("prioik.formulations.reference", ""),
    "extended_jacobian": ("prioik.formulations.extended_jacobian", ""),
    "nullspace": ("prioik.formulations.nullspace", ""),
    "chiaverini": ("prioik.formulations.chiaverini", ""),
    "unifying": ("prioik.formulations.unifying", ""),
    "operational_space": ("prioik.formulations.operational_space", ""),
    "cascaded_qp": ("prioik.formulations.cascaded_qp", "qp"),
    "cvxpy": ("prioik.formulations.cvxpy_", "cvxpy"),
    "placo": ("prioik.formulations.placo_", "placo"),
    "daqp_hierarchical": ("prioik.formulations.daqp_hierarchical", "qp"),
}

_loaded: dict[str, ModuleType] = {}
_failed: dict[str, str] = {}


@dataclass(frozen=True)
class FormulationInfo:
    """One row of :func:`available`.

    Attributes:
        name: Registry name.
        available: Whether it can run here.
        reason: Why not, when not available.
        description: One line.
        capabilities: What it supports (``None`` when it could not be imported).
        options: Accepted options with defaults and descriptions.
        backends: Back-ends it can use here (QP solvers), if it has any.
        extra: The extra that brings its dependencies (``""``: in the core).
    """

    name: str
    available: bool
    reason: str = ""
    description: str = ""
    capabilities: Capabilities | None = None
    options: dict[str, tuple[Any, str]] = field(default_factory=dict)
    backends: tuple[str, ...] = ()
    extra: str = ""


def _load(name: str) -> ModuleType | None:
    if name in _loaded:
        return _loaded[name]
    if name in _failed:
        return None
    module_name, extra = PLUGINS[name]
    try:
        mod = importlib.import_module(module_name)
    except ImportError as exc:
        missing = getattr(exc, "name", None) or ""
        own = missing == module_name or missing.startswith("prioik.")
        if extra and not own:  # an optional dependency: say which extra brings it
            _failed[name] = f"{exc} (the `{extra}` extra); {install_hint(extra)}"
        else:  # a broken installation or a bug: the error as it is
            _failed[name] = f"{type(exc).__name__}: {exc}"
        return None
    _loaded[name] = mod
    return mod


def names() -> list[str]:
    """Every registered formulation name, available here or not."""
    return list(PLUGINS)


def available() -> list[FormulationInfo]:
    """Every registered formulation, with whether it can run here and why not."""
    out = []
    for name in PLUGINS:
        mod = _load(name)
        extra = PLUGINS[name][1]
        if mod is None:
            out.append(FormulationInfo(name, False, _failed[name], extra=extra))
            continue
        backends = tuple(mod.backends()) if hasattr(mod, "backends") else ()
        out.append(FormulationInfo(name, True, "", mod.DESCRIPTION, mod.CAPABILITIES,
                                   dict(mod.OPTIONS), backends, extra))
    return out


def get(name: str) -> ModuleType:
    """The plugin module called ``name``.

    Raises:
        FormulationError: unknown name (lists the known ones) or not available here
            (says why, e.g. which import failed).
    """
    if name not in PLUGINS:
        raise FormulationError(f"unknown formulation {name!r}; known: {', '.join(PLUGINS)}")
    mod = _load(name)
    if mod is None:
        raise FormulationError(f"formulation {name!r} is not available here: {_failed[name]}")
    return mod


_MATRIX_OPTIONS = ("mass_matrix", "metric")
_VECTOR_OPTIONS = ("bias",)


def _check_options(name: str, mod: ModuleType, stack: TaskStack, options: dict) -> dict:
    unknown = sorted(set(options) - set(mod.OPTIONS))
    if unknown:
        raise FormulationError(f"formulation {name!r} has no option {', '.join(unknown)}; "
                               f"its options: {', '.join(mod.OPTIONS) or 'none'}")
    n = stack.n
    out = {}
    for key, value in options.items():
        if key in _MATRIX_OPTIONS and value is not None:
            arr = np.array(value, dtype=np.float64, copy=True)
            if arr.shape != (n, n):
                raise FormulationError(f"{key} must be {n}x{n} for this stack, got shape {arr.shape}")
            if not np.isfinite(arr).all():
                raise FormulationError(f"{key} holds NaN or inf")
            if not np.allclose(arr, arr.T, rtol=1e-10, atol=1e-12 * max(1.0, np.abs(arr).max())):
                raise FormulationError(f"{key} must be symmetric (max |M - Mᵀ| = "
                                       f"{np.abs(arr - arr.T).max():.3e})")
            arr.setflags(write=False)
            value = arr
        elif key in _VECTOR_OPTIONS and value is not None:
            arr = np.array(value, dtype=np.float64, copy=True).reshape(-1)
            if arr.shape != (n,) or not np.isfinite(arr).all():
                raise FormulationError(f"{key} must be a finite vector of length {n}, "
                                       f"got shape {np.shape(value)}")
            arr.setflags(write=False)
            value = arr
        out[key] = value
    if mod.CAPABILITIES.needs_mass_matrix and out.get("mass_matrix") is None:
        raise FormulationError(f"formulation {name!r} needs mass_matrix=M "
                               f"(the {n}x{n} joint-space inertia matrix, SPD)")
    return out


def check_support(name: str, caps: Capabilities, stack: TaskStack) -> None:
    """Raise :class:`UnsupportedTaskError` naming the first task ``caps`` cannot take."""
    for i, level in enumerate(stack.levels):
        for t in level:
            if not t.is_equality and not caps.inequalities:
                raise UnsupportedTaskError("inequality tasks are not supported",
                                           formulation=name, task=t.name, level=i)
            if t.is_equality and not caps.equalities:
                raise UnsupportedTaskError("equality tasks are not supported",
                                           formulation=name, task=t.name, level=i)
        if not caps.weights and len(level) > 1:
            w = {float(v) for t in level for v in np.unique(t.weight)}
            if len(w) > 1:
                raise UnsupportedTaskError("weighted tasks sharing a level are not "
                                           "supported", formulation=name,
                                           task=level[0].name, level=i)


def solve(stack, formulation: str = "extended_jacobian", **options: Any) -> Solution:
    """Solve a task stack with the named formulation.

    Args:
        stack: A :class:`~hierarchy.TaskStack` (or anything ``TaskStack`` accepts).
        formulation: Registry name (see :func:`available`).
        **options: The formulation's options (see its ``OPTIONS``).

    Returns:
        A :class:`Solution`. A numerical failure inside the formulation gives
        ``status == "failed"`` with ``info["message"]``, not an exception.

    Raises:
        FormulationError: unknown/unavailable formulation, unknown or missing option.
        UnsupportedTaskError: the stack holds a task the formulation cannot take.
    """
    mod = get(formulation)
    if not isinstance(stack, TaskStack):
        stack = TaskStack(stack)
    check_support(formulation, mod.CAPABILITIES, stack)
    opts = _check_options(formulation, mod, stack, options)
    t0 = time.perf_counter()
    try:
        out: Outcome = mod.solve(stack, **opts)
        elapsed = time.perf_counter() - t0
    except (np.linalg.LinAlgError, ArithmeticError) as exc:
        elapsed = time.perf_counter() - t0
        out = Outcome(np.full(stack.n, np.nan), "failed",
                      {"message": f"{type(exc).__name__}: {exc}"})
    x = np.asarray(out.x, dtype=np.float64).reshape(-1)
    info = dict(out.info)
    status = out.status
    if status not in STATUSES:
        raise RuntimeError(f"formulation {formulation!r} returned unknown status {status!r}")
    if x.shape != (stack.n,):
        status = "failed"
        info.setdefault("message", f"solution has shape {x.shape}, expected ({stack.n},)")
        x = np.full(stack.n, np.nan)
    elif status != "failed" and not np.isfinite(x).all():
        status = "failed"
        info.setdefault("message", "the formulation produced non-finite values")
    residuals = (lexicographic_residuals(stack, x) if np.isfinite(x).all()
                 else np.full(len(stack), np.nan))
    return Solution(x, formulation, dict(options), status, residuals, elapsed, info)


@dataclass
class BatchSolution:
    """The answers of one formulation to many stacks of the same shape.

    Attributes:
        X: Solutions, one row per stack (``B × n``).
        statuses: One status per stack.
        formulation: Name of the formulation.
        options: Options it was called with.
        time_s: Wall time of the whole batch (solve alone).
        batched: Whether the plugin's own batched kernel ran (else a loop of ``solve``).
    """

    X: np.ndarray
    statuses: list[str]
    formulation: str
    options: dict[str, Any]
    time_s: float
    batched: bool

    @property
    def time_per_stack_s(self) -> float:
        """``time_s`` divided by the number of stacks."""
        return self.time_s / max(1, len(self.statuses))


def stack_shape(stack: TaskStack) -> tuple:
    """What must agree for stacks to share a batch: ``n`` and each task's rows and kind."""
    return (stack.n,) + tuple(tuple((t.m, t.is_equality) for t in level) for level in stack)


def solve_batch(stacks, formulation: str = "extended_jacobian", **options: Any) -> BatchSolution:
    """Solve many stacks of the same shape (sampled states, retargeting frames, sweeps).

    Uses the plugin's ``solve_batch`` (stacked numpy linear algebra) when it has one,
    otherwise loops over its ``solve``.

    Raises:
        TaskStackError: the stacks do not share one shape (names the first that differs).
        FormulationError, UnsupportedTaskError: as :func:`solve`.
    """
    from prioik.hierarchy import TaskStackError
    stacks = [s if isinstance(s, TaskStack) else TaskStack(s) for s in stacks]
    if not stacks:
        raise TaskStackError("solve_batch needs at least one stack")
    mod = get(formulation)
    shape = stack_shape(stacks[0])
    for i, s in enumerate(stacks[1:], 1):
        if stack_shape(s) != shape:
            raise TaskStackError(f"stack {i} of the batch differs in shape from stack 0 "
                                 f"(n, rows and kinds of every task must agree)")
    check_support(formulation, mod.CAPABILITIES, stacks[0])
    opts = _check_options(formulation, mod, stacks[0], options)
    batched = hasattr(mod, "solve_batch")
    t0 = time.perf_counter()
    if batched:
        X, statuses = mod.solve_batch(stacks, **opts)
        X = np.asarray(X, dtype=np.float64)
        statuses = list(statuses)
    else:
        X = np.empty((len(stacks), shape[0]))
        statuses = []
        for i, s in enumerate(stacks):
            try:
                out = mod.solve(s, **opts)
                X[i], st = out.x, out.status
            except (np.linalg.LinAlgError, ArithmeticError):
                X[i], st = np.nan, "failed"
            statuses.append(st)
    elapsed = time.perf_counter() - t0
    bad = ~np.isfinite(X).all(axis=1)
    statuses = ["failed" if b else st for b, st in zip(bad, statuses)]
    return BatchSolution(X, statuses, formulation, dict(options), elapsed, batched)
