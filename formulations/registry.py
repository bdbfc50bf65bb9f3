"""The formulation registry: one line per plugin module, imported on demand.

A plugin is a module that defines ``FORMULATION``, a
:class:`~prioik.formulations.contract.Formulation`: its name, one-line description,
:class:`Capabilities`, typed ``{option: Option(...)}`` (:mod:`.options`, the only options
it accepts, validated once by the registry), the back-ends it can use here, and its own
:class:`~prioik.formulations.contract.Prepared` subclass (``solve(data)``, and when it
has them ``solve_checked``, ``solve_batch``, ``reset``), built once per layout by
:func:`prepare` as ``Prepared(layout, settings)``: ``settings`` is an instance of the
formulation's typed settings dataclass
(:attr:`~prioik.formulations.contract.Formulation.settings`) holding every option,
clean. Adding a formulation is its module and one line of :data:`PLUGINS`.

The rows a formulation adds to prioik's reports are declared by the benchmarks
(:mod:`prioik.benchmarks.report_rows`), not here: a new plugin appears in every report
with its defaults by itself.

A plugin whose optional dependency is not installed is unavailable; the reason,
ending with the extra to install (``install it with `pip install prioik[qp]```), is
recorded and repeated when that formulation is asked for.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from prioik.extras import install_hint
from prioik.hierarchy import StackData, StackLayout, TaskStack

from .base import Capabilities, FormulationError, Solution
from .contract import Formulation
from .options import Option, validate_options
from .prepared import BatchSolution, PreparedSolver, check_support  # noqa: F401  (re-exported)

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
    "hierarchical_active_set": ("prioik.formulations.hierarchical_active_set", ""),
    "sns": ("prioik.formulations.sns", ""),
    "lexls": ("prioik.formulations.lexls_", ""),
}

_loaded: dict[str, Formulation] = {}
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
        options: Accepted options (typed :class:`~prioik.formulations.options.Option`).
        backends: Back-ends it can use here (QP solvers), if it has any.
        extra: The extra that brings its dependencies (``""``: in the core).
    """

    name: str
    available: bool
    reason: str = ""
    description: str = ""
    capabilities: Capabilities | None = None
    options: dict[str, Option] = field(default_factory=dict)
    backends: tuple[str, ...] = ()
    extra: str = ""


def _load(name: str) -> Formulation | None:
    if name in _loaded:
        return _loaded[name]
    if name in _failed:
        return None
    module_name, extra = PLUGINS[name]
    try:
        mod = importlib.import_module(module_name)
    except ImportError as exc:
        missing = exc.name or ""
        own = missing == module_name or missing.startswith("prioik.")
        if extra and not own:  # an optional dependency: say which extra brings it
            _failed[name] = f"{exc} (the `{extra}` extra); {install_hint(extra)}"
        else:  # a broken installation or a bug: the error as it is
            _failed[name] = f"{type(exc).__name__}: {exc}"
        return None
    formulation = mod.FORMULATION
    if not isinstance(formulation, Formulation) or formulation.name != name:
        raise FormulationError(f"module {module_name} declares no Formulation named "
                               f"{name!r} as its FORMULATION")
    _loaded[name] = formulation
    return formulation


def names() -> list[str]:
    """Every registered formulation name, available here or not."""
    return list(PLUGINS)


def available() -> list[FormulationInfo]:
    """Every registered formulation, with whether it can run here and why not."""
    out = []
    for name in PLUGINS:
        form = _load(name)
        extra = PLUGINS[name][1]
        if form is None:
            out.append(FormulationInfo(name, False, _failed[name], extra=extra))
            continue
        out.append(FormulationInfo(name, True, "", form.description, form.capabilities,
                                   dict(form.options), tuple(form.backends()), extra))
    return out


#: what :func:`compile_kernels` and ``prioik compile`` say
NOTHING_TO_COMPILE = ("nothing to compile: prioik's compiled solvers are C++ (prioik._core), "
                      "built when prioik is installed; a first solve does not wait for a "
                      "compiler")


def compile_kernels(names: list[str] | None = None,
                    progress: Callable[[str, float | None], None] | None = None
                    ) -> list[tuple[str, float]]:
    """Nothing: prioik's compiled solvers (``extended_jacobian``'s nested QR,
    ``hierarchical_active_set``) are the C++ core ``prioik._core``, compiled when prioik
    is installed (:data:`NOTHING_TO_COMPILE`). Kept so that scripts calling it run;
    returns ``[]`` and never calls ``progress``.

    Args:
        names: Formulations; each must be known and available here.
        progress: Not called (accepted for the scripts that pass it).

    Raises:
        FormulationError: a name is unknown or not available here.
    """
    for name in names or ():
        get(name)
    return []


def get(name: str) -> Formulation:
    """The formulation called ``name`` (its plugin's
    :class:`~prioik.formulations.contract.Formulation`).

    Raises:
        FormulationError: unknown name (lists the known ones) or not available here
            (says why, e.g. which import failed).
    """
    if name not in PLUGINS:
        raise FormulationError(f"unknown formulation {name!r}; known: {', '.join(PLUGINS)}")
    form = _load(name)
    if form is None:
        raise FormulationError(f"formulation {name!r} is not available here: {_failed[name]}")
    return form


def prepare(stack_or_layout, formulation: str = "extended_jacobian", *, verify: str = "auto",
            **options: Any) -> PreparedSolver:
    """A formulation prepared for one stack layout: options validated and workspaces
    allocated once, then ``solver.solve(stack_or_data)`` per step.

    Args:
        stack_or_layout: A :class:`~prioik.hierarchy.StackLayout`, or a stack (its layout
            is used).
        formulation: Registry name (see :func:`available`).
        verify: The verification stage run after each timed solve (timed apart), the one
            place an answer is demoted to ``approximate``: ``"auto"`` (what the
            formulation's options ask), ``"none"``, ``"certificate"`` or
            ``"lower_point"`` (see :class:`PreparedSolver`).
        **options: The formulation's options (:attr:`Formulation.options`).

    Raises:
        FormulationError: unknown/unavailable formulation, unknown or invalid option or
            ``verify`` mode.
        UnsupportedTaskError: the layout holds a task kind the formulation cannot take.

    A formulation that needs ``mass_matrix`` may get it here or with every solve
    (``solver.solve(stack, mass_matrix=M, bias=b)``: it changes with the state).
    """
    form = get(formulation)
    if isinstance(stack_or_layout, StackLayout):
        layout = stack_or_layout
    elif isinstance(stack_or_layout, (TaskStack, StackData)):
        layout = stack_or_layout.layout
    else:
        layout = TaskStack(stack_or_layout).layout
    opts = validate_options(formulation, form.options, options, layout.n)
    return PreparedSolver(form, layout, opts, options, verify)


def solve(stack, formulation: str = "extended_jacobian", *, verify: str = "auto",
          **options: Any) -> Solution:
    """Solve a task stack with the named formulation: :func:`prepare` + ``solve``.

    Args:
        stack: A :class:`~prioik.hierarchy.TaskStack` (or anything ``TaskStack``
            accepts), or a :class:`~prioik.hierarchy.StackData`.
        formulation: Registry name (see :func:`available`).
        verify: The verification stage (see :func:`prepare`).
        **options: The formulation's options (:attr:`Formulation.options`).

    Returns:
        A :class:`Solution`. A numerical failure inside the formulation gives
        ``status == "failed"`` with ``diagnostics.fault`` and ``diagnostics.reason``,
        not an exception. An exact formulation solves the stack with its levels of
        extreme scale equilibrated (:meth:`~hierarchy.TaskStack.equilibrated`;
        ``diagnostics.equilibrated_levels``).

    Raises:
        FormulationError: unknown/unavailable formulation, unknown, invalid or missing
            option.
        UnsupportedTaskError: the stack holds a task the formulation cannot take.
    """
    if not isinstance(stack, (TaskStack, StackData)):
        stack = TaskStack(stack)
    return prepare(stack.layout, formulation, verify=verify, **options).solve(stack)


def stack_shape(stack: TaskStack) -> tuple:
    """What must agree for stacks to share a batch: ``n`` and each task's rows and kind
    (the stack's layout, as a tuple)."""
    return (stack.n,) + tuple(tuple((t.m, t.is_equality) for t in level) for level in stack)


def solve_batch(stacks, formulation: str = "extended_jacobian", *, verify: str = "auto",
                **options: Any) -> BatchSolution:
    """Solve many stacks of one layout (sampled states, retargeting frames, sweeps): one
    prepared solver over every stack.

    Uses the plugin's batched kernel when it has one (``Prepared.solve_batch``),
    otherwise loops over the prepared solve. ``verify`` as :func:`prepare` (a batched
    kernel's statuses get the precision check only).

    Raises:
        TaskStackError: an empty batch.
        FormulationError: the stacks do not share one layout (names the first that
            differs), and as :func:`solve`.
        UnsupportedTaskError: as :func:`solve`.
    """
    from prioik.hierarchy import TaskStackError
    stacks = [s if isinstance(s, (TaskStack, StackData)) else TaskStack(s) for s in stacks]
    if not stacks:
        raise TaskStackError("solve_batch needs at least one stack")
    return prepare(stacks[0].layout, formulation, verify=verify,
                   **options).solve_batch(stacks)
