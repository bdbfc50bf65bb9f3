"""Records shared by every formulation: what it supports, what it returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from prioik.errors import PrioikError
from prioik.hierarchy import (
    DEFAULT_CERTIFICATE_TOL,
    X_PRECISION,
    StackData,
    TaskStack,
    TaskStackError,
    ambiguity_reason,
    check_lexicographic,
    level_residuals,
    level_scale,
    precision_limited_levels,
    precision_reason,
)

#: Values of :attr:`Solution.status`.
STATUSES = ("optimal", "approximate", "failed")


class FormulationError(PrioikError, ValueError):
    """A formulation cannot be used as asked: unknown name, not installed here,
    an unknown option, or a required option (e.g. ``mass_matrix``) missing."""


class CoreInputError(FormulationError):
    """An array given to the compiled core (``prioik._core``) that it cannot take: not a
    C-contiguous float64 array of the layout's shape, empty, or holding a value that is
    not finite (or a ``√w ≤ 0``); the message names the array and the entry."""


class ConcurrentUseError(PrioikError, RuntimeError):
    """A prepared solver was called from a second thread while a solve was running
    (a prepared solver owns its workspaces: use one per thread)."""


@dataclass(frozen=True)
class Capabilities:
    """What a formulation can take.

    Attributes:
        equalities: Equality tasks ``A x ≈ b``.
        inequalities: Inequality tasks ``lower ≤ A x ≤ upper``.
        weights: Several weighted tasks in one level.
        needs_mass_matrix: Requires the option ``mass_matrix=M``.
        exact: Returns the lexicographic optimum of equality stacks (up to the
            solver's tolerance); ``False`` for methods with algorithmic error or
            soft-priority approximations.
    """

    equalities: bool = True
    inequalities: bool = False
    weights: bool = True
    needs_mass_matrix: bool = False
    exact: bool = True


@dataclass(slots=True)
class Outcome:
    """What a plugin's ``solve`` returns; the registry turns it into a :class:`Solution`.

    Attributes:
        x: The solution (``n``).
        status: One of :data:`STATUSES`.
        info: Formulation-specific data (ranks, iterations, torques, messages).
        residuals: Per-level residuals when the plugin computed them itself (a compiled
            kernel does, from the same rows); ``None``: the registry computes them.
        checked: The plugin guarantees that ``x`` is a finite float64 vector of the
            right length and ``residuals`` are given (the registry then skips its own
            checks: the compiled paths verify both in the kernel).
    """

    x: np.ndarray
    status: str = "optimal"
    info: dict[str, Any] = field(default_factory=dict)
    residuals: np.ndarray | None = None
    checked: bool = False


@dataclass(slots=True)
class Solution:
    """The answer of a formulation to a task stack.

    Attributes:
        x: The solution, shape ``(n,)`` (NaN-free unless ``status == "failed"``).
        formulation: Name of the formulation that produced it.
        options: Options it was called with.
        status: ``"optimal"``, ``"approximate"`` (a soft or regularised answer) or
            ``"failed"`` (see ``info["message"]``).
        residuals: Per level, ``‖A_i x − b_i‖`` plus inequality violation (weighted).
        time_s: Wall time of the formulation's solve alone (``perf_counter``).
        info: Formulation-specific data.
    """

    x: np.ndarray
    formulation: str
    options: dict[str, Any]
    status: str
    residuals: np.ndarray
    time_s: float
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """``True`` unless the status is ``"failed"``."""
        return self.status != "failed"

    def __repr__(self) -> str:
        x = np.asarray(self.x)
        head = np.array2string(x[:4], precision=4, separator=", ")[1:-1]
        more = f", … ({x.size} values)" if x.size > 4 else ""
        res = np.array2string(np.asarray(self.residuals), precision=2, separator=", ",
                              threshold=8)
        return (f"Solution({self.formulation!r}, {self.status}, x=[{head}{more}], "
                f"residuals={res}, {1e6 * self.time_s:.1f} µs)")

    def _repr_html_(self) -> str:
        from html import escape
        rows = [("formulation", self.formulation), ("status", self.status),
                ("x", f"{np.asarray(self.x).size} values, ‖x‖ = "
                      f"{float(np.linalg.norm(self.x)):.4g}"),
                ("residuals", np.array2string(np.asarray(self.residuals), precision=3)),
                ("time", f"{1e6 * self.time_s:.1f} µs"),
                ("options", repr(self.options)), ("info", ", ".join(self.info) or "—")]
        body = "".join(f"<tr><th style='text-align:left'>{escape(k)}</th>"
                       f"<td>{escape(v)}</td></tr>" for k, v in rows)
        return f"<table><caption>Solution</caption>{body}</table>"


def in_original_units(out: Outcome, data, levels: list[int]) -> Outcome:
    """``out``, solved on the stack ``data`` with ``levels`` equilibrated
    (:meth:`~prioik.hierarchy.TaskStack.equilibrated`: each of those levels' values
    multiplied by a power of two), with its residuals (and ``info["level_violation"]``,
    their squares) read on ``data`` itself, the user's units, and
    ``info["equilibrated_levels"]`` naming the levels."""
    if out.residuals is not None and np.isfinite(out.x).all():
        with np.errstate(over="ignore", invalid="ignore"):
            res = level_residuals(data, out.x)
        out.residuals = res
        if "level_violation" in out.info:
            out.info["level_violation"] = res * res
    out.info["equilibrated_levels"] = levels
    return out


def solve_equilibrated(solve: Callable[[Any], Outcome], data, message: str) -> Outcome:
    """A prepared solver's answer for ``data`` whose kernel refused a level of extreme
    scale: ``solve`` on :meth:`~prioik.hierarchy.TaskStack.equilibrated` (those levels
    rescaled by a power of two: the same optimum and tie-break), read in the user's units
    (:func:`in_original_units`).

    Raises:
        TaskStackError: ``message``, when no level's entries are extreme (rescaling
            cannot help: the weights or targets are at fault).
    """
    stack, levels = data.as_stack().equilibrated()
    if not levels:
        raise TaskStackError(message)
    return in_original_units(solve(stack.data), data, levels)


def precision_status(status: str, info: dict, data, x: np.ndarray) -> str:
    """``status``, or ``"approximate"`` when float64 cannot give some level's values at
    ``x`` to the certificate's tolerance (:func:`~prioik.hierarchy.precision_limited_levels`:
    a huge ``‖x‖`` along directions the level does not take); the levels go in
    ``info["precision_limited_levels"]`` and the reason in ``info["reason"]``. Only an
    ``optimal`` status changes; ``data`` is the stack's :class:`~prioik.hierarchy.StackData`.
    """
    if status != "optimal":
        return status
    levels = precision_limited_levels(data, x)
    if not levels:
        return status
    info["precision_limited_levels"] = levels
    reason = precision_reason(levels, level_scale(x))
    info["reason"] = f"{info['reason']}; {reason}" if info.get("reason") else reason
    return "approximate"


def certify(stack, outcome: Outcome, metric=None, tol: float | None = None,
            minimum_norm: bool = True) -> Outcome:
    """Keep ``status="optimal"`` only when ``outcome.x`` passes the certificate.

    The certificate is :func:`hierarchy.check_lexicographic` with the minimum-norm
    tie-break (``xᵀ W x`` with ``metric``; ``minimum_norm=False``: the levels only, for
    a formulation without that tie-break) at ``tol`` (default
    :data:`hierarchy.DEFAULT_CERTIFICATE_TOL`). An answer that fails becomes
    ``"approximate"``, with ``info["fault_level"]`` (``k`` for the tie-break),
    ``info["fault_tasks"]`` and ``info["message"]``; ``info["certificate"]`` records the
    check either way. An answer that passes but where the check took an ambiguous rank
    decision (``report.ambiguous_levels``: a singular value within
    :data:`hierarchy.AMBIGUITY` of the rank rule's threshold) becomes ``"approximate"``
    too, with ``info["ambiguous_levels"]`` and ``info["reason"]`` (``info["message"]``
    too: every answer it demotes says why there): it is the rank rule's
    optimum, and the exact solvers say ``approximate`` at such a decision. Any
    other answer that passes is compared with the exact active-set solver's answer on the
    same stack (:func:`lower_point`): when that point is no higher at every level above
    some level and lower there by more than ``tol · max(1, value)`` (and the values'
    rounding), the answer is not the lexicographic optimum whatever the check read, and
    it becomes ``"approximate"`` with ``info["fault_level"]``, ``info["fault_tasks"]``,
    ``info["message"]`` and ``info["lower_point"]`` (the two values). The check reads
    rows a solver left violated within its tolerance at a level above as that level's
    optimal violation, fixed for the levels below, which can pin them far from their
    optimum; the comparison does not depend on that reading. Other statuses are returned
    unchanged.
    """
    if outcome.status != "optimal":
        return outcome
    tol = DEFAULT_CERTIFICATE_TOL if tol is None else float(tol)
    x = np.asarray(outcome.x, dtype=np.float64).reshape(-1)
    if x.shape != (stack.n,) or not np.isfinite(x).all():
        return outcome
    report = check_lexicographic(stack, x, tol=tol, minimum_norm=minimum_norm, metric=metric)
    bad = report.first_failure
    outcome.info["certificate"] = {"ok": report.ok, "tol": tol,
                                   "worst_relative": report.worst_relative,
                                   "fault_level": None if bad is None else bad.level,
                                   "ambiguous_levels": list(report.ambiguous_levels)}
    if bad is not None:
        outcome.status = "approximate"
        outcome.info["fault_level"] = bad.level
        outcome.info["fault_tasks"] = list(bad.tasks)
        what = ("the minimum-norm tie-break" if bad.tasks == ("minimum-norm",)
                else f"level {bad.level} ({', '.join(bad.tasks)})")
        outcome.info["message"] = (f"the answer fails the lexicographic certificate at "
                                   f"{what}: {bad.failure(tol)}")
    elif report.ambiguous_levels:
        levels = list(report.ambiguous_levels)
        outcome.status = "approximate"
        outcome.info["ambiguous_levels"] = levels
        outcome.info["reason"] = outcome.info["message"] = ambiguity_reason(levels)
    else:
        lower = lower_point(stack, x, tol)
        if lower is not None:
            level, value, reached = lower
            data = stack if isinstance(stack, StackData) else stack.data
            names = list(data.layout.names[level])
            outcome.status = "approximate"
            outcome.info.update(fault_level=level, fault_tasks=names,
                                lower_point={"level": level, "value": value,
                                             "reached": reached})
            outcome.info["message"] = (
                f"not the lexicographic optimum: hierarchical_active_set reaches "
                f"{reached:.10g} at level {level} ({', '.join(names)}) where the answer "
                f"has {value:.10g}, no higher at every level above")
    return outcome


def lower_point(stack: TaskStack | StackData, x: np.ndarray,
                tol: float = DEFAULT_CERTIFICATE_TOL) -> tuple[int, float, float] | None:
    """A witness against ``x``: the exact active-set solver's answer ``x_a`` on the same
    stack, when it is lexicographically lower — at the first level ``i`` where the two
    differ beyond rounding, ``‖w_i(x_a)‖² < ‖w_i(x)‖² − tol · max(1, ‖w_i(x)‖²)``, and
    no higher at every level above (each within ``1e-12 · max(1, value)``). The values'
    rounding is added to both margins (``r_i = X_PRECISION · max(‖x‖, ‖x_a‖) ·
    ‖√W_i A_i‖_F``, a value's ``2 r_i ‖w_i‖ + r_i²``). A point that used a level's
    tolerance above to gain below is no witness (it is higher there), so an exact answer
    is never refuted by the solver's own slack.

    Returns:
        ``(i, value at x, value at x_a)``, or ``None`` (no such level, or the solver gave
        no finite point).
    """
    from . import hierarchical_active_set as active_set  # (it imports this module)
    from .options import validate_options
    data = stack if isinstance(stack, StackData) else stack.data
    try:
        opts = validate_options(active_set.NAME, active_set.OPTIONS, {}, data.n)
        xa = active_set.Prepared(data.layout, opts).solve(data).x
    except (FormulationError, TaskStackError, ArithmeticError, np.linalg.LinAlgError):
        return None
    if not np.isfinite(xa).all():
        return None
    wc = level_residuals(data, x) ** 2
    wa = level_residuals(data, xa) ** 2
    if not (np.isfinite(wc).all() and np.isfinite(wa).all()):
        return None
    WA = data.sqrt_weight[:, None] * data.A
    scale = np.sqrt(np.add.reduceat((WA * WA).sum(axis=1), data.layout.starts[:-1]))
    r = X_PRECISION * max(float(np.linalg.norm(x)), float(np.linalg.norm(xa))) * scale
    rounding = 2 * r * (np.sqrt(wc) + np.sqrt(wa)) + 2 * r * r
    for i in range(wc.shape[0]):
        if wa[i] < wc[i] - tol * max(1.0, wc[i]) - rounding[i]:
            return i, float(wc[i]), float(wa[i])
        if wa[i] > wc[i] + 1e-12 * max(1.0, wc[i]) + rounding[i]:
            return None
    return None
