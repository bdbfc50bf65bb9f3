"""PlaCo's generic QP builder (``placo.Problem``): first level hard, the rest soft.

One QP (PlaCo eliminates the hard equalities by QR and calls eiquadprog):

    min  Σ_{j≥2} ρ^{j−2} ‖A_j x − b_j‖²  +  ε ‖x‖²
    s.t. A_1 x = b_1                         (the first level, hard)
         lower_t ≤ A_t x ≤ upper_t           (every inequality task, hard)

with ``A_j``, ``b_j`` the level's weighted equality rows, ``ρ = weight_ratio`` the
ratio between soft levels (default ``SOFT_SPAN^(1/(k−2))``, ``SOFT_SPAN = 1e-4``) and
``ε = regularization`` PlaCo's Tikhonov term (default 1e-8). A rank-deficient first
level is replaced by its feasible rows ``U_rᵀ A_1 x = U_rᵀ b_1``
(:attr:`Detail.first_level_rank`), which PlaCo's QR elimination needs.

Statuses: ``optimal`` only for two levels with an equality first level (the
lexicographic optimum up to ``ε``) whose answer passes the verification stage's
certificate (:func:`~prioik.formulations.verification.certify`, asked for every answer); deeper
stacks are a weighted compromise and, like any stack with an inequality task below the
first level, ``approximate``. PlaCo raises on infeasible hard inequalities: the status
is then ``failed`` with a :class:`~prioik.formulations.base.Fault` naming the first level
whose hard inequalities cannot hold with those above (``level=None`` when none can be
named).

In detail: ``docs/formulations.md``; measurements: ``docs/qp-formulations.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import placo

from prioik.hierarchy import TaskStack

from . import contract
from .base import (
    Capabilities,
    CheckRequest,
    Diagnostics,
    FormulationError,
    Outcome,
    Status,
)
from .options import Option, rcond_option


@dataclass(slots=True)
class Detail:
    """``placo``'s own record (``sol.diagnostics.detail``).

    Attributes:
        weight_ratio: ``ρ``, the weight ratio between soft levels.
        regularization: ``ε``, PlaCo's Tikhonov term.
        first_level_rank: Rank of the first level (its feasible rows, the hard ones).
        soft_weights: The weight of each soft level (``ρ^{j−2}``).
    """

    weight_ratio: float
    regularization: float
    first_level_rank: int
    soft_weights: list[float] = field(default_factory=list)


NAME = "placo"
DESCRIPTION = "PlaCo placo.Problem: first level hard, lower levels soft (geometric weights)"
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=False)
#: Smallest soft weight of the default geometric ratio: 10⁴× PlaCo's default
#: regularisation (1e-8), so the lowest level still dominates the Tikhonov term.
SOFT_SPAN = 1e-4

OPTIONS = {
    "weight_ratio": Option(None, "float", "ρ: soft level j (j ≥ 2) has weight ρ^(j−2); None: "
                           "ρ = SOFT_SPAN^(1/(k−2)) (weights from 1 down to SOFT_SPAN)",
                           minimum=0.0, exclusive_minimum=True, optional=True),
    "regularization": Option(1e-8, "float", "ε: PlaCo's ‖x‖² regularisation weight (PlaCo's "
                             "default, measured best)", minimum=0.0),
    "rcond": rcond_option(),
}


def _expression(variable, A: np.ndarray):
    return variable.expr().left_multiply(np.ascontiguousarray(A, dtype=np.float64))


def _add_inequalities(problem, variable, level) -> int:
    count = 0
    for t in level:
        if t.is_equality:
            continue
        lo, up = t.bounds()
        for side, keep in (("lower", np.isfinite(lo)), ("upper", np.isfinite(up))):
            if not keep.any():
                continue
            e = _expression(variable, t.A[keep])
            if side == "lower":
                problem.add_constraint(e >= np.ascontiguousarray(lo[keep]))
            else:
                problem.add_constraint(e <= np.ascontiguousarray(up[keep]))
            count += 1
    return count


def _first_level_rows(level, rcond: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Full-row-rank rows with the same least-squares optimal set as the level."""
    A, b = level.A, level.b
    if A.shape[0] == 0:
        return A, b, 0
    u, s, vt = np.linalg.svd(A, full_matrices=False)
    tol = rcond * float(np.linalg.norm(A))
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    if r == A.shape[0]:
        return A, b, r
    # U_rᵀ A = Σ_r V_rᵀ, U_rᵀ b
    return s[:r, None] * vt[:r], u[:, :r].T @ b, r


def _hard_infeasible_level(stack: TaskStack, regularization: float) -> int | None:
    """Index of the first level whose hard inequalities make the hard set infeasible."""
    problem = placo.Problem()
    problem.regularization = max(regularization, 1e-12)
    x = problem.add_variable(stack.n)
    for j, level in enumerate(stack.levels):
        if _add_inequalities(problem, x, level) == 0:
            continue
        try:
            problem.solve()
        except RuntimeError:
            return j
    return None


def default_weight_ratio(levels: int) -> float:
    """``ρ = SOFT_SPAN^(1/(k−2))``: the soft weights of ``k`` levels span ``[SOFT_SPAN, 1]``."""
    return SOFT_SPAN ** (1.0 / (levels - 2)) if levels > 2 else 1.0


def solve(stack: TaskStack, *, weight_ratio: float | None, regularization: float, rcond:
          float) -> Outcome:
    """Build and solve the single PlaCo QP; see the module docstring."""
    if weight_ratio is None:
        weight_ratio = default_weight_ratio(len(stack))
    for key, val in (("weight_ratio", weight_ratio), ("regularization", regularization)):
        if not np.isfinite(float(val)) or float(val) <= 0:
            raise FormulationError(f"{key} must be a finite number > 0, got {val}")
    if float(weight_ratio) > 1:
        raise FormulationError(f"weight_ratio must be ≤ 1 (a lower level weighs less), "
                               f"got {weight_ratio}")
    n = stack.n
    problem = placo.Problem()
    problem.regularization = float(regularization)
    x = problem.add_variable(n)
    first = stack.levels[0]
    A1, b1, r1 = _first_level_rows(first, rcond)
    detail = Detail(float(weight_ratio), float(regularization), r1)
    if r1:
        problem.add_constraint(_expression(x, A1) == np.ascontiguousarray(b1))
    _add_inequalities(problem, x, first)
    low_inequality = False
    for j, level in enumerate(stack.levels[1:], start=1):
        w = float(weight_ratio) ** (j - 1)
        if level.A.shape[0]:
            c = problem.add_constraint(_expression(x, level.A) == np.ascontiguousarray(level.b))
            c.configure("soft", w)
        detail.soft_weights.append(w)
        low_inequality |= _add_inequalities(problem, x, level) > 0
    try:
        problem.solve()
    except RuntimeError as exc:
        failed = Outcome(np.full(n, np.nan), Status.FAILED, Diagnostics(detail=detail))
        bad = _hard_infeasible_level(stack, float(regularization))
        if bad is None:
            return failed.fail(f"PlaCo failed: {exc}")
        names = [t.name for lvl in stack.levels[:bad + 1] for t in lvl if not t.is_equality]
        return failed.fail(f"PlaCo failed: {exc}; the hard inequalities of levels 0..{bad} "
                           f"({', '.join(names)}) cannot hold together", "infeasible", bad,
                           [t.name for t in stack.levels[bad] if not t.is_equality])
    exact = len(stack) <= 2 and first.is_equality and not low_inequality
    diagnostics = Diagnostics(detail=detail)
    if not exact:
        diagnostics.reason = ("a weighted compromise: PlaCo's soft levels are exact only for "
                              "two levels with an equality first level")
    return Outcome(np.array(x.value, dtype=np.float64),
                   Status.OPTIMAL if exact else Status.APPROXIMATE, diagnostics,
                   check=CheckRequest())


class Prepared(contract.StackPrepared):
    """PlaCo's problem prepared for one layout: :func:`solve` on each stack (built
    per solve)."""

    name = NAME
    capabilities = CAPABILITIES

    def solve_stack(self, stack: TaskStack, settings: Any) -> Outcome:
        return solve(stack, weight_ratio=settings.weight_ratio,
                     regularization=settings.regularization, rcond=settings.rcond)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
