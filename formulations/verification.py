"""Verification of a formulation's answer, above the plugins: the lexicographic
certificate with the minimum-norm tie-break (:func:`certify`) and the witness of a lower
point found by the exact active-set solver (:func:`lower_point`).

A plugin that cannot stand behind its answer by construction calls :func:`certify`
before saying ``optimal``; the certificate itself is :func:`prioik.check_lexicographic`.
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
from .base import FormulationError, Outcome
from .options import validate_options

__all__ = ["certify", "lower_point"]


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
