"""Records shared by every formulation: what it supports, what it returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from prioik.errors import PrioikError
from prioik.hierarchy import (
    TaskStackError,
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
