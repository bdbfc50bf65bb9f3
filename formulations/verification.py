"""Verification of a formulation's answer, above the plugins: the lexicographic
certificate with the minimum-norm tie-break (:func:`certify`) and the witness of a lower
point found by the exact active-set solver (:func:`lower_point`, with the solver
:func:`lower_point_solver` prepares once per prepared solver).

The verification stage of :class:`~prioik.formulations.PreparedSolver` calls them after
the timed solve; it alone demotes an answer. The certificate itself is
:func:`prioik.check_lexicographic`.
"""

from __future__ import annotations

import numpy as np

from prioik.hierarchy import (
    DEFAULT_CERTIFICATE_TOL,
    X_PRECISION,
    StackData,
    TaskStack,
    TaskStackError,
    ambiguity_reason,
    check_lexicographic,
    level_residuals,
)

from . import hierarchical_active_set as active_set
from .base import Diagnostics, Fault, FormulationError, LowerPoint, Verification
from .options import validate_options

__all__ = ["certify", "lower_point", "lower_point_solver"]


def certify(stack, x: np.ndarray, diagnostics: Diagnostics, *, metric=None,
            tol: float | None = None, minimum_norm: bool = True, compare: bool = True,
            solver=None) -> bool:
    """Whether ``x`` passes the lexicographic certificate; what it found goes in
    ``diagnostics`` (:attr:`Diagnostics.verification`, and on failure
    :attr:`Diagnostics.fault` and :attr:`Diagnostics.reason`). The caller, the
    verification stage of :class:`~prioik.formulations.PreparedSolver`, demotes an answer
    that does not pass to ``approximate``.

    The certificate is :func:`hierarchy.check_lexicographic` with the minimum-norm
    tie-break (``xᵀ W x`` with ``metric``; ``minimum_norm=False``: the levels only, for
    a formulation without that tie-break) at ``tol`` (default
    :data:`hierarchy.DEFAULT_CERTIFICATE_TOL`). An answer that fails it has a
    :class:`Fault` of code ``"certificate"`` (level ``k`` for the tie-break). An answer
    that passes but where the check took an ambiguous rank decision
    (``report.ambiguous_levels``: a singular value within :data:`hierarchy.AMBIGUITY` of
    the rank rule's threshold) does not pass either (its levels in
    :attr:`Diagnostics.ambiguous_levels`): it is the rank rule's optimum, and the exact
    solvers say ``approximate`` at such a decision. With ``compare``, any other answer
    that passes is compared with the exact active-set solver's answer on the same stack
    (:func:`lower_point`, with ``solver``: that solver prepared once by the caller):
    when that point is no higher at every level above some level and lower there by more
    than ``tol · max(1, value)`` (and the values' rounding), the answer is not the
    lexicographic optimum whatever the check read (a :class:`Fault` of code
    ``"lower_point"``, the witness in :attr:`Verification.lower_point`). The check reads
    rows a solver left violated within its tolerance at a level above as that level's
    optimal violation, fixed for the levels below, which can pin them far from their
    optimum; the comparison does not depend on that reading.
    """
    tol = DEFAULT_CERTIFICATE_TOL if tol is None else float(tol)
    x = np.asarray(x, dtype=np.float64).reshape(-1)
    if x.shape != (stack.n,) or not np.isfinite(x).all():
        return True
    method = "lower_point" if compare else "certificate"
    report = check_lexicographic(stack, x, tol=tol, minimum_norm=minimum_norm, metric=metric)
    bad = report.first_failure
    worst = float(report.worst_relative)
    if bad is not None:
        what = ("the minimum-norm tie-break" if bad.tasks == ("minimum-norm",)
                else f"level {bad.level} ({', '.join(bad.tasks)})")
        message = (f"the answer fails the lexicographic certificate at {what}: "
                   f"{bad.failure(tol)}")
        diagnostics.verification = Verification(method, False, tol, worst)
        diagnostics.fault = Fault(bad.level, tuple(bad.tasks), "certificate", message)
        diagnostics.add_reason(message)
        return False
    if report.ambiguous_levels:
        levels = list(report.ambiguous_levels)
        diagnostics.verification = Verification(method, False, tol, worst)
        diagnostics.ambiguous_levels = sorted(set(diagnostics.ambiguous_levels) | set(levels))
        diagnostics.add_reason(ambiguity_reason(levels))
        return False
    lower = lower_point(stack, x, tol, solver=solver) if compare else None
    if lower is None:
        diagnostics.verification = Verification(method, True, tol, worst)
        return True
    level, value, reached = lower
    data = stack if isinstance(stack, StackData) else stack.data
    names = tuple(data.layout.names[level])
    message = (f"not the lexicographic optimum: hierarchical_active_set reaches "
               f"{reached:.10g} at level {level} ({', '.join(names)}) where the answer "
               f"has {value:.10g}, no higher at every level above")
    diagnostics.verification = Verification(method, False, tol, worst,
                                            LowerPoint(level, value, reached))
    diagnostics.fault = Fault(level, names, "lower_point", message)
    diagnostics.add_reason(message)
    return False


def lower_point_solver(layout):
    """The exact active-set solver :func:`lower_point` compares with, prepared for
    ``layout`` with its default options (:func:`lower_point` resets it before each
    answer: every comparison starts cold, as a freshly prepared one)."""
    opts = validate_options(active_set.NAME, active_set.OPTIONS, {}, layout.n)
    return active_set.Prepared(layout, active_set.FORMULATION.settings_of(opts))


def lower_point(stack: TaskStack | StackData, x: np.ndarray,
                tol: float = DEFAULT_CERTIFICATE_TOL, solver=None
                ) -> tuple[int, float, float] | None:
    """A witness against ``x``: the exact active-set solver's answer ``x_a`` on the same
    stack, when it is lexicographically lower — at the first level ``i`` where the two
    differ beyond rounding, ``‖w_i(x_a)‖² < ‖w_i(x)‖² − tol · max(1, ‖w_i(x)‖²)``, and
    no higher at every level above (each within ``1e-12 · max(1, value)``). The values'
    rounding is added to both margins (``r_i = X_PRECISION · max(‖x‖, ‖x_a‖) ·
    ‖√W_i A_i‖_F``, a value's ``2 r_i ‖w_i‖ + r_i²``). A point that used a level's
    tolerance above to gain below is no witness (it is higher there), so an exact answer
    is never refuted by the solver's own slack.

    Args:
        stack: The stack (or its data).
        x: The answer.
        tol: The certificate's relative tolerance.
        solver: The active-set solver to compare with (:func:`lower_point_solver`,
            prepared once for the layout, reset here; ``None``: one is prepared for
            this call).

    Returns:
        ``(i, value at x, value at x_a)``, or ``None`` (no such level, or the solver gave
        no finite point).
    """
    data = stack if isinstance(stack, StackData) else stack.data
    try:
        if solver is None:
            solver = lower_point_solver(data.layout)
        solver.reset()      # cold: the answer does not depend on the last one checked
        xa = solver.solve(data).x
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
