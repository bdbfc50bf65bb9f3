"""The cascade of :mod:`formulations.cascaded_qp`, modelled in cvxpy.

An independent reference for stacks with inequality tasks: the same levels
(weighted least squares of the equality tasks plus weighted squared slacks of the
inequality tasks, every higher optimum fixed, a final minimum-norm level) written
as cvxpy expressions — ``sum_squares(√W (A x − b)) + sum_squares(√w ∘ v)`` with
``lower ≤ A x − v ≤ upper`` — canonicalised by cvxpy and solved by any cvxpy
solver that takes QPs (``solver=``, default Clarabel). Only the bookkeeping of
what a solved level fixes (the orthonormal row-space basis of the higher equality
rows, relaxed inequality bounds, strongly active rows read from cvxpy's dual
values) is shared with :mod:`formulations.cascaded_qp` (:mod:`formulations._numerics`);
the modelling, the canonicalisation and the solver interfaces are cvxpy's.

``fixing="basis"`` keeps the higher equality rows as ``Rᵀ x = Rᵀ x*`` with ``R`` an
orthonormal basis of their row space; ``fixing="rows"`` keeps the literal rows
``A_h x = A_h x*`` (redundant on rank-deficient or conflicting levels).

A solver status of ``optimal_inaccurate`` at some level gives
``status="approximate"`` (the levels are listed in :attr:`Detail.inaccurate_levels`);
any other non-optimal status gives ``status="failed"`` with a
:class:`~prioik.formulations.base.Fault` naming the level and its tasks. With
``certify=True`` (default) an ``optimal`` answer is certified by the verification stage
(:func:`~prioik.formulations.verification.certify`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np

from prioik.hierarchy import TaskStack

from . import contract
from ._numerics import (
    ACTIVE_TOL,
    MULTIPLIER_TOL,
    Fixed,
    level_rows,
    quiet_unless_verbose,
    record_level,
    scaled_level,
    unit_rows,
)
from .base import Capabilities, CheckRequest, Diagnostics, FormulationError, Outcome, Status
from .options import Option, dictionary, positive_semidefinite, rcond_option


@dataclass(slots=True)
class Detail:
    """``cvxpy``'s own record (``sol.diagnostics.detail``).

    Attributes:
        backend: The cvxpy solver.
        fixing: How the higher optima were fixed (option ``fixing``).
        levels: One record per level problem (cvxpy's status; ``violated`` when some
            inequality task of the level is left violated), then the final
            regularisation level's.
        violated: Per infeasible level: ``{"level", "tasks", "violation"}``.
        inaccurate_levels: Levels cvxpy solved as ``optimal_inaccurate``.
        fixed_tasks: A failed solve: the higher tasks whose optima were constraints.
        x_partial: A failed solve: the answer of the levels above (``None``: none).
        settings: The solver settings used.
    """

    backend: str
    fixing: str
    levels: list[dict] = field(default_factory=list)
    violated: list[dict] = field(default_factory=list)
    inaccurate_levels: list[int] = field(default_factory=list)
    fixed_tasks: list[str] = field(default_factory=list)
    x_partial: np.ndarray | None = None
    settings: dict = field(default_factory=dict)


NAME = "cvxpy"
DESCRIPTION = "the cascaded QP modelled in cvxpy (independent reference for inequalities)"
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=True)

#: cvxpy solvers that take QPs, in order of preference.
QP_SOLVERS = ("CLARABEL", "OSQP", "SCS", "PROXQP", "DAQP", "HIGHS", "ECOS", "PIQP",
              "CVXOPT", "MOSEK", "GUROBI")
DEFAULT_SOLVER = "CLARABEL"

#: Accuracy asked of each solver by default (keyword names are the solver's own).
DEFAULT_SETTINGS: dict[str, dict[str, Any]] = {
    "CLARABEL": {"tol_gap_abs": 1e-10, "tol_gap_rel": 1e-10, "tol_feas": 1e-10,
                 "tol_ktratio": 1e-10, "max_iter": 500},
    "OSQP": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iter": 200_000},
    "SCS": {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 200_000},
}

OPTIONS = {
    "solver": Option(DEFAULT_SOLVER, "str", "cvxpy solver name (see backends())"),
    "backend_options": Option(None, "any", "dict of keyword arguments for the solver "
                              "(override defaults)", optional=True, check=dictionary),
    "fixing": Option("basis", "str", "'basis' (orthonormal row-space basis) or 'rows' "
                     "(literal rows)", choices=("basis", "rows")),
    "metric": Option(None, "matrix", "SPD n×n W: the final level minimises xᵀWx instead of "
                     "xᵀx", optional=True, check=positive_semidefinite),
    "rcond": rcond_option(),
    "margin": Option(0.0, "float", "fixed higher inequality rows relaxed by "
                     "margin·max(1, ‖x*‖) (unit rows)", minimum=0.0),
    "on_infeasible": Option("relax", "str", "'relax': least-violation answer; 'fail': "
                            "failed status", choices=("relax", "fail")),
    "infeasibility_tol": Option(1e-7, "float", "an inequality task counts as violated above "
                                "this (relative to max(1, ‖A_t‖_F‖x‖))", minimum=0.0,
                                exclusive_minimum=True),
    "certify": Option(True, "bool", "'optimal' only when the answer passes check_lexicographic "
                      "(DEFAULT_CERTIFICATE_TOL, minimum-norm tie-break), else 'approximate'"),
}


def backends() -> list[str]:
    """cvxpy solvers installed here that take QPs."""
    installed = set(cp.installed_solvers())
    return [s for s in QP_SOLVERS if s in installed]


def _bounds(expr, lower: np.ndarray, upper: np.ndarray, rows: np.ndarray,
            cons: list, tracked: list) -> None:
    """Add ``lower ≤ expr ≤ upper`` (finite sides); remember each side's x-space rows."""
    up, lo = np.isfinite(upper), np.isfinite(lower)
    if up.any():
        c = expr[np.flatnonzero(up)] <= upper[up]
        cons.append(c)
        tracked.append((c, rows[up]))
    if lo.any():
        c = expr[np.flatnonzero(lo)] >= lower[lo]
        cons.append(c)
        tracked.append((c, rows[lo]))


def _solve(problem: cp.Problem, solver: str, settings: dict) -> tuple[str, str]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            with quiet_unless_verbose(settings):
                problem.solve(solver=solver, **settings)
        except (cp.error.SolverError, ValueError, ArithmeticError, RuntimeError) as exc:
            return "error", f"{solver} raised {type(exc).__name__}: {exc}"
    return problem.status, ""


def solve(stack: TaskStack, *, solver: str, backend_options: dict | None, fixing: str,
          metric, rcond: float, margin: float, on_infeasible: str, infeasibility_tol:
          float, certify: bool) -> Outcome:
    """Solve the stack level by level with cvxpy; see the module docstring."""
    available = backends()
    if not isinstance(solver, str) or solver.upper() not in available:
        raise FormulationError(f"cvxpy solver {solver!r} is not available here; "
                               f"available: {', '.join(available)}")
    solver = solver.upper()
    if fixing not in ("basis", "rows"):
        raise FormulationError(f"fixing must be 'basis' or 'rows', got {fixing!r}")
    if on_infeasible not in ("relax", "fail"):
        raise FormulationError(f"on_infeasible must be 'relax' or 'fail', got {on_infeasible!r}")
    if backend_options is not None and not isinstance(backend_options, dict):
        raise FormulationError("backend_options must be a dict")
    settings = {**DEFAULT_SETTINGS.get(solver, {}), **(backend_options or {})}
    n = stack.n
    fixed = Fixed.start(n)
    detail = Detail(solver, fixing, settings=settings)
    diagnostics = Diagnostics(detail=detail)

    def fail(j, tasks, message, partial):
        detail.fixed_tasks = list(fixed.tasks)
        detail.x_partial = partial
        return Outcome(np.full(n, np.nan), Status.FAILED, diagnostics).fail(
            message, "solver_error", j, tasks)

    def fixed_constraints(x: cp.Variable, tracked: list) -> list:
        cons = []
        if fixing == "basis" and fixed.R.shape[1]:
            cons.append(fixed.R.T @ x == fixed.R.T @ fixed.x)
        elif fixing == "rows":
            for A_h in fixed.eq_rows:
                cons.append(A_h @ x == A_h @ fixed.x)
        delta = margin * max(1.0, float(np.linalg.norm(fixed.x)))
        for A_h, lo, up in zip(fixed.A_in, fixed.lower, fixed.upper, strict=False):
            A_u, lo, up = unit_rows(A_h, lo, up)
            if A_u.shape[0]:
                _bounds(A_u @ x, lo - delta, up + delta, A_u, cons, tracked)
        return cons

    for j, level in enumerate(stack.levels):
        rows = level_rows(level)
        if rows.A_eq.shape[0] == 0 and rows.A_in.shape[0] == 0:
            fixed.tasks += list(level.names)
            continue
        srows = scaled_level(rows)
        x = cp.Variable(n)
        tracked: list = []
        cons = fixed_constraints(x, tracked)
        obj = 0
        if srows.A_eq.shape[0]:
            obj = obj + cp.sum_squares(srows.A_eq @ x - srows.b_eq)
        if srows.A_in.shape[0]:
            v = cp.Variable(srows.A_in.shape[0])
            obj = obj + cp.sum_squares(cp.multiply(np.sqrt(srows.w_in), v))
            norms = np.linalg.norm(srows.A_in, axis=1)
            _bounds(srows.A_in @ x - v, srows.lower, srows.upper,
                    srows.A_in / norms[:, None], cons, tracked)
        problem = cp.Problem(cp.Minimize(obj), cons)
        status, message = _solve(problem, solver, settings)
        if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or x.value is None:
            return fail(j, level.names, f"level {j} ({', '.join(level.names)}): "
                        f"{message or f'{solver} status {status}'}", fixed.x.copy() if j else None)
        if status == cp.OPTIMAL_INACCURATE:
            detail.inaccurate_levels.append(j)
        xv = np.asarray(x.value, dtype=np.float64)
        active = []
        lam_max = max([float(np.max(np.abs(c.dual_value), initial=0.0)) for c, _ in tracked
                       if c.dual_value is not None], default=0.0)
        for c, xrows in tracked:
            if c.dual_value is None:
                continue
            lam = np.atleast_1d(np.asarray(c.dual_value, dtype=np.float64))
            slack = np.abs(np.atleast_1d(c.args[1].value - c.args[0].value))
            act = (lam > MULTIPLIER_TOL * max(1.0, lam_max)) & \
                (slack <= ACTIVE_TOL * max(1.0, float(np.linalg.norm(xv))))
            if act.any():
                active.append(xrows[act])
        fixed.add(rows, level.names, xv, rcond, np.vstack(active) if active else None)
        rec: dict[str, Any] = {"level": j, "tasks": list(level.names), "status": status}
        failed = record_level(diagnostics, rec, level, xv, float(infeasibility_tol), on_infeasible,
                              fail)
        if failed is not None:
            return failed
    x = cp.Variable(n)
    W = np.eye(n) if metric is None else np.asarray(metric)
    obj = cp.sum_squares(x) if metric is None else cp.quad_form(x, cp.psd_wrap(0.5 * (W + W.T)))
    problem = cp.Problem(cp.Minimize(obj), fixed_constraints(x, []))
    status, message = _solve(problem, solver, settings)
    if status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or x.value is None:
        return fail(len(stack), [], f"final regularisation level: "
                    f"{message or f'{solver} status {status}'}", fixed.x.copy())
    if status == cp.OPTIMAL_INACCURATE:
        detail.inaccurate_levels.append(len(stack))
    detail.levels.append({"level": "regularisation", "status": status})
    if detail.inaccurate_levels:
        diagnostics.reason = (f"{solver} solved levels {detail.inaccurate_levels} only "
                              f"to reduced accuracy (optimal_inaccurate)")
    return Outcome(np.asarray(x.value, dtype=np.float64),
                   Status.APPROXIMATE if detail.inaccurate_levels else Status.OPTIMAL,
                   diagnostics, check=CheckRequest(auto=bool(certify), metric=metric))


class Prepared(contract.StackPrepared):
    """The cvxpy cascade prepared for one layout: :func:`solve` on each stack
    (modelled per solve)."""

    name = NAME
    capabilities = CAPABILITIES

    def solve_stack(self, stack: TaskStack, settings: Any) -> Outcome:
        s = settings
        return solve(stack, solver=s.solver, backend_options=s.backend_options,
                     fixing=s.fixing, metric=s.metric, rcond=s.rcond, margin=s.margin,
                     on_infeasible=s.on_infeasible, infeasibility_tol=s.infeasibility_tol,
                     certify=s.certify)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared,
                                   backends=backends)
