"""Cascaded QP: one quadratic program per level (Kanoun, Lamiraux & Wieber 2011).

Level ``j`` (highest first) solves, over ``x`` and its slacks,

    min  Σ_t ‖√w_t (A_t x − b_t)‖²  +  Σ_t ‖√w_t v_t‖²
    s.t. lower_t ≤ A_t x − v_t ≤ upper_t            (the level's inequality tasks)
         every higher level's optimum kept fixed

(equality tasks through residual variables ``r = √W (A x − b)``, at the conditioning
of ``A``), then a last level minimises ``‖x‖²`` (``xᵀWx`` with ``metric``) over the
lexicographic optimal set; on equality stacks this is the extended Jacobian's eq. 18.
A level's optimum is kept for the levels below by fixing its equality rows'
values (``fixing``: ``"basis"``, an orthonormal basis of their row space, default;
``"rows"``, the literal rows; ``"nullspace"``, ``x = x* + Z y``), relaxing its
inequality rows by their optimal slacks, and holding its strongly active rows as
equalities. ``level_damping=(μ_1², …)`` adds ``μ_i² ‖x‖²`` to level ``i`` (the
hierarchy the extended Jacobian's selective damping and ``step_bound`` solve).

Back-ends: ``solver=`` any of ``qpsolvers.available_solvers`` (default Clarabel);
:func:`backend_settings` maps ``tolerance`` onto each back-end's options
(:data:`DEFAULT_TOLERANCES`); DAQP is called as ``daqp.solve`` directly.

Statuses: ``optimal`` only when the answer passes the verification stage's
certificate (:func:`~prioik.formulations.verification.certify`, asked by ``certify=True``: the
lexicographic certificate with the minimum-norm tie-break, no ambiguous rank decision,
no lower point found), else ``approximate`` with ``diagnostics.fault``. A back-end that
raises or finds no solution gives ``failed`` with a
:class:`~prioik.formulations.base.Fault` naming the level, and
:attr:`Detail.fixed_tasks`; an infeasible inequality level keeps its least violation
(``diagnostics.infeasible_levels``, the violated tasks in :attr:`Detail.violated`;
``on_infeasible="fail"`` makes it a failure).

In detail: ``docs/formulations.md``; settings and measurements per back-end:
``docs/qp-formulations.md``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import qpsolvers
import scipy.sparse as spa

from prioik.hierarchy import TaskStack

from . import contract
from ._numerics import (
    ACTIVE_TOL,
    MULTIPLIER_TOL,
    Fixed,
    LevelRows,
    level_rows,
    level_scale,
    quiet_unless_verbose,
    record_level,
    scaled_level,
    unit_rows,
)
from .base import (
    Capabilities,
    CheckRequest,
    Diagnostics,
    FormulationError,
    Outcome,
    Status,
)
from .options import Option, dictionary, per_level_nonnegative, positive_semidefinite, rcond_option


@dataclass(slots=True)
class Detail:
    """``cascaded_qp``'s own record (``sol.diagnostics.detail``).

    Attributes:
        backend: The QP back-end.
        fixing: How the higher optima were fixed (option ``fixing``).
        levels: One record per level QP (the back-end's status and counts; ``violated``
            when some inequality task of the level is left violated), then the final
            regularisation level's.
        violated: Per infeasible level: ``{"level", "tasks", "violation"}`` (the
            violated inequality tasks and their weighted violation).
        fixed_tasks: A failed solve: the higher tasks whose optima were constraints of
            the QP that failed.
        x_partial: A failed solve: the answer of the levels above (``None``: none).
        settings: The back-end settings used.
    """

    backend: str
    fixing: str
    levels: list[dict] = field(default_factory=list)
    violated: list[dict] = field(default_factory=list)
    fixed_tasks: list[str] = field(default_factory=list)
    x_partial: np.ndarray | None = None
    settings: dict = field(default_factory=dict)


NAME = "cascaded_qp"
DESCRIPTION = "one QP per level through qpsolvers (Kanoun et al. 2011), any back-end"
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=True)

#: Default back-end: the most accurate solver measured on the validation families
#: (docs/qp-formulations.md, "Choosing the default back-end").
DEFAULT_SOLVER = "clarabel"

#: Default accuracy per back-end, passed through :func:`backend_settings`.
DEFAULT_TOLERANCES: dict[str, float | None] = {
    "clarabel": 1e-10,
    "daqp": 1e-10,
    "highs": 1e-10,
    "osqp": 1e-9,
    "proxqp": 1e-10,
    "quadprog": None,      # dual active set, no tolerance setting
    "scs": 1e-9,
}

#: Regularisation ``ε`` added to the ``x`` block of each level's Hessian (relative to
#: ``‖A_level‖_F²``) for back-ends that need a positive-definite ``P``.
NEEDS_DEFINITE_P = {"quadprog": 1e-12, "daqp": 1e-10}

OPTIONS = {
    "solver": Option(DEFAULT_SOLVER, "str", "qpsolvers back-end (see backends())"),
    "tolerance": Option(None, "float", "back-end accuracy (None: DEFAULT_TOLERANCES[solver])",
                        minimum=0.0, exclusive_minimum=True, optional=True),
    "backend_options": Option(None, "any", "dict of extra keyword arguments for the back-end "
                              "(override)", optional=True, check=dictionary),
    "fixing": Option("basis", "str", "how higher equality optima are kept: 'basis', 'rows' or "
                     "'nullspace'", choices=("basis", "rows", "nullspace")),
    "metric": Option(None, "matrix", "SPD n×n W: the final level minimises xᵀWx instead of "
                     "xᵀx", optional=True, check=positive_semidefinite),
    "rcond": rcond_option(),
    "regularization": Option(None, "float", "ε·‖A‖_F² on each level's x block (None: 1e-12 "
                             "for quadprog, else 0)", minimum=0.0, optional=True),
    "fix_active": Option(True, "bool", "fix strongly active inequalities (positive "
                         "multiplier) as equalities for the lower levels (exact; avoids "
                         "degenerate faces)"),
    "margin": Option(0.0, "float", "fixed higher inequality rows are relaxed by "
                     "margin·max(1, ‖x*‖) (unit rows) so degenerate active sets stay "
                     "solvable", minimum=0.0),
    "on_infeasible": Option("relax", "str", "'relax': least-violation answer; 'fail': "
                            "failed status", choices=("relax", "fail")),
    "level_damping": Option(None, "any", "k values μ_i² ≥ 0: level i minimises "
                            "‖A_i x − b_i‖² + μ_i²‖x‖² (damped least squares within the "
                            "optimal set above)", optional=True, check=per_level_nonnegative),
    "infeasibility_tol": Option(1e-7, "float", "an inequality task counts as violated above "
                                "this (relative to max(1, ‖A_t‖_F‖x‖))", minimum=0.0,
                                exclusive_minimum=True),
    "certify": Option(True, "bool", "'optimal' only when the answer passes check_lexicographic "
                      "(DEFAULT_CERTIFICATE_TOL, minimum-norm tie-break), else 'approximate'"),
}

FIXINGS = ("basis", "rows", "nullspace")


def backends() -> list[str]:
    """The qpsolvers back-ends available here."""
    return sorted(qpsolvers.available_solvers)


def backend_settings(solver: str, tolerance: float | None) -> dict[str, Any]:
    """Keyword arguments that set ``solver``'s accuracy to ``tolerance``.

    Args:
        solver: qpsolvers back-end name.
        tolerance: Absolute and relative accuracy asked for (``None``: the
            back-end's own defaults).

    Returns:
        The back-end's option names with values (empty for quadprog, which has no
        tolerance, and for back-ends not listed here).
    """
    if tolerance is None:
        return {}
    t = float(tolerance)
    if solver == "clarabel":
        return {"tol_gap_abs": t, "tol_gap_rel": t, "tol_feas": t, "tol_ktratio": max(t, 1e-12),
                "max_iter": 500}
    if solver == "osqp":
        return {"eps_abs": t, "eps_rel": t, "polishing": True, "max_iter": 200_000}
    if solver == "scs":
        return {"eps_abs": t, "eps_rel": t, "max_iters": 200_000}
    if solver == "proxqp":
        return {"eps_abs": t, "eps_rel": t, "max_iter": 10_000}
    if solver == "highs":
        return {"primal_feasibility_tolerance": t, "dual_feasibility_tolerance": t,
                "qp_iteration_limit": 10_000}
    if solver == "daqp":
        return {"primal_tol": t, "dual_tol": min(t, 1e-12)}
    return {}


def resolve_solver(solver: str) -> str:
    """Check that ``solver`` is a qpsolvers back-end available here.

    Raises:
        FormulationError: naming the back-end and listing the available ones.
    """
    available = backends()
    if not isinstance(solver, str) or solver not in available:
        raise FormulationError(f"QP back-end {solver!r} is not available here; "
                               f"available: {', '.join(available)}")
    return solver


@dataclass
class LevelQP:
    """One QP ``min ½ zᵀPz + qᵀz, G z ≤ h, E z = e`` over ``z = (y, r, v)``,
    ``x = x0 + Z y``."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray | None
    h: np.ndarray | None
    E: np.ndarray | None
    e: np.ndarray | None
    x0: np.ndarray
    Z: np.ndarray
    G_x: np.ndarray | None = None


def _two_sided(M: np.ndarray, lower: np.ndarray, upper: np.ndarray, offset: np.ndarray,
               X: np.ndarray, G_x: list[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Rows of ``lower ≤ M z + offset ≤ upper`` as ``G z ≤ h`` (finite sides only);
    appends the matching rows of ``X`` (the same constraints in ``x`` space) to ``G_x``."""
    G, h = [], []
    up = np.isfinite(upper)
    lo = np.isfinite(lower)
    if up.any():
        G.append(M[up])
        h.append(upper[up] - offset[up])
        G_x.append(X[up])
    if lo.any():
        G.append(-M[lo])
        h.append(offset[lo] - lower[lo])
        G_x.append(X[lo])
    return G, h


def build_level_qp(rows: LevelRows | None, fixed: Fixed, fixing: str, eps: float,
                   metric: np.ndarray | None = None, margin: float = 0.0,
                   damping: float = 0.0) -> LevelQP:
    """The QP of one level (``rows``) or, with ``rows=None``, of the final level.

    The level's rows are divided by their RMS row norm (which leaves the minimiser
    unchanged) and the fixed higher inequality rows are scaled to unit norm, so that
    tasks of very different scales give back-ends a well-scaled problem. ``damping``
    is the level's ``μ²`` (the term ``μ² ‖x‖²``, in the level's own units).
    """
    n = fixed.x.shape[0]
    damp = 0.0
    if rows is not None:
        damp = 2.0 * damping / level_scale(rows) ** 2   # ½ yᵀPy with the rows scaled by s
        rows = scaled_level(rows)
    if fixing == "nullspace":
        Z, x0 = fixed.Z, fixed.x
    else:
        Z, x0 = np.eye(n), np.zeros(n)
    ny = Z.shape[1]
    if rows is None:
        W = np.eye(n) if metric is None else metric
        me = mi = 0
        P = Z.T @ W @ Z
        P = 0.5 * (P + P.T)
        q = Z.T @ (W @ x0)
    else:
        me, mi = rows.A_eq.shape[0], rows.A_in.shape[0]
        P = np.zeros((ny + me + mi, ny + me + mi))
        P[:ny, :ny] = (eps + damp) * np.eye(ny)          # ZᵀZ = I
        P[ny:ny + me, ny:ny + me] = 2.0 * np.eye(me)
        P[ny + me:, ny + me:] = 2.0 * np.diag(rows.w_in)
        q = np.zeros(ny + me + mi)
        q[:ny] = damp * (Z.T @ x0)                        # μ²‖x0 + Z y‖² up to a constant
    nz = ny + me + mi
    E: list[np.ndarray] = []
    e: list[np.ndarray] = []
    G: list[np.ndarray] = []
    h: list[np.ndarray] = []
    G_x: list[np.ndarray] = []
    if rows is not None and me:
        # √W A (x0 + Z y) − r = √W b
        blk = np.zeros((me, nz))
        blk[:, :ny] = rows.A_eq @ Z
        blk[:, ny:ny + me] = -np.eye(me)
        E.append(blk)
        e.append(rows.b_eq - rows.A_eq @ x0)
    if rows is not None and mi:
        blk = np.zeros((mi, nz))
        blk[:, :ny] = rows.A_in @ Z
        blk[:, ny + me:] = -np.eye(mi)
        A_unit = rows.A_in / np.maximum(np.linalg.norm(rows.A_in, axis=1), 1e-300)[:, None]
        g, hh = _two_sided(blk, rows.lower, rows.upper, rows.A_in @ x0, A_unit, G_x)
        G += g
        h += hh
    if fixing == "basis" and fixed.R.shape[1]:
        blk = np.zeros((fixed.R.shape[1], nz))
        blk[:, :ny] = fixed.R.T
        E.append(blk)
        e.append(fixed.R.T @ fixed.x)
    elif fixing == "rows":
        for A_h in fixed.eq_rows:
            A_h = A_h / max(float(np.linalg.norm(A_h)) / np.sqrt(A_h.shape[0]), 1e-300)
            blk = np.zeros((A_h.shape[0], nz))
            blk[:, :ny] = A_h
            E.append(blk)
            e.append(A_h @ fixed.x)
    delta = margin * max(1.0, float(np.linalg.norm(fixed.x)))
    for A_h, lo, up in zip(fixed.A_in, fixed.lower, fixed.upper, strict=False):
        A_h, lo, up = unit_rows(A_h, lo, up)
        lo, up = lo - delta, up + delta
        blk = np.zeros((A_h.shape[0], nz))
        blk[:, :ny] = A_h @ Z
        g, hh = _two_sided(blk, lo, up, A_h @ x0, A_h, G_x)
        G += g
        h += hh
    return LevelQP(P, q, np.vstack(G) if G else None, np.concatenate(h) if h else None,
                   np.vstack(E) if E else None, np.concatenate(e) if e else None, x0, Z,
                   np.vstack(G_x) if G_x else None)


_CAUGHT = (qpsolvers.QPError, ValueError, RuntimeError, ArithmeticError,
           np.linalg.LinAlgError, MemoryError)


def solve_level_qp(qp: LevelQP, solver: str, settings: dict[str, Any]
                   ) -> tuple[np.ndarray | None, str, dict[str, Any]]:
    """Solve one level's QP with a qpsolvers back-end.

    Returns:
        ``(x, message, extras)``: ``x`` is ``None`` when the back-end failed, with
        ``message`` saying how; ``extras`` holds primal residual and warnings.
    """
    if qp.G is None and qp.E is None:
        # Only the final level of fixing="nullspace" without inequalities: an
        # unconstrained strictly convex QP (some back-ends refuse those).
        y = np.linalg.solve(qp.P, -qp.q)
        return qp.x0 + qp.Z @ y, "", {"closed_form": True}
    if solver == "daqp":
        return _solve_daqp(qp, settings)
    sparse = solver not in qpsolvers.dense_solvers
    conv = (lambda M: None if M is None else spa.csc_matrix(M)) if sparse else (lambda M: M)
    problem = qpsolvers.Problem(conv(qp.P), qp.q, conv(qp.G), qp.h, conv(qp.E), qp.e)
    extras: dict[str, Any] = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with quiet_unless_verbose(settings):
                sol = qpsolvers.solve_problem(problem, solver=solver, **settings)
        except (AttributeError, TypeError) as exc:
            # a back-end refusing a keyword: the settings came from backend_options
            raise FormulationError(f"option 'backend_options': the {solver} back-end "
                                   f"does not take these settings "
                                   f"({', '.join(sorted(settings))}): "
                                   f"{type(exc).__name__}: {exc}") from None
        except _CAUGHT as exc:
            return None, f"{solver} raised {type(exc).__name__}: {exc}", extras
    if caught:
        extras["warnings"] = sorted({str(w.message) for w in caught})
    status = sol.extras.get("status") if isinstance(sol.extras, dict) else None
    if not sol.found or sol.x is None:
        why = f" (status {status})" if status is not None else ""
        warn = f"; {extras['warnings'][0]}" if extras.get("warnings") else ""
        return None, f"{solver} found no solution{why}{warn}", extras
    z = np.asarray(sol.x, dtype=np.float64).reshape(-1)
    if not np.isfinite(z).all():
        return None, f"{solver} returned non-finite values", extras
    ny = qp.Z.shape[1]
    try:
        extras["primal_residual"] = float(sol.primal_residual())
    except (ValueError, TypeError, AttributeError):  # pragma: no cover - defensive
        pass
    if qp.G is not None and sol.z is not None and np.shape(sol.z) == (qp.G.shape[0],):
        extras["_active"] = strongly_active(qp, z, np.asarray(sol.z, dtype=np.float64))
    return qp.x0 + qp.Z @ z[:ny], "", extras


def _solve_daqp(qp: LevelQP, settings: dict[str, Any]
                ) -> tuple[np.ndarray | None, str, dict[str, Any]]:
    """The DAQP back-end, called as ``daqp.solve`` on the problem qpsolvers would build.

    qpsolvers 4.13 hands DAQP its equality rows with ``blower = −1e30`` (not ``b``);
    when DAQP moves such a row to its lower side the level fails (measured: 8 % of
    the inequality levels of the validation families, and a 3-variable example in
    tests/test_cascaded_qp.py). Passing ``blower = bupper = b`` fixes it.
    """
    from ctypes import c_int

    import daqp

    n_z = qp.P.shape[0]
    G = qp.G if qp.G is not None else np.zeros((0, n_z))
    h = qp.h if qp.h is not None else np.zeros(0)
    E = qp.E if qp.E is not None else np.zeros((0, n_z))
    e = qp.e if qp.e is not None else np.zeros(0)
    A = np.ascontiguousarray(np.vstack([G, E]))
    bu = np.ascontiguousarray(np.concatenate([h, e]))
    bl = np.ascontiguousarray(np.concatenate([np.full(h.shape, -1e30), e]))
    sense = np.concatenate([np.zeros(h.shape[0]), np.full(e.shape[0], 5)]).astype(c_int)
    try:
        z, _, flag, result = daqp.solve(np.ascontiguousarray(qp.P), np.ascontiguousarray(qp.q),
                                        A, bu, bl, sense, **settings)
    except TypeError as exc:
        raise FormulationError(f"daqp.solve rejected the settings: {exc}") from None
    extras: dict[str, Any] = {"exitflag": int(flag)}
    if flag <= 0 or not np.isfinite(z).all():
        return None, f"daqp found no solution (exit flag {flag})", extras
    ny = qp.Z.shape[1]
    if qp.G is not None:
        extras["_active"] = strongly_active(qp, z, np.asarray(result["lam"][:h.shape[0]]))
    return qp.x0 + qp.Z @ z[:ny], "", extras


def strongly_active(qp: LevelQP, z: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Unit ``x``-space rows of the inequality constraints strongly active at ``z``."""
    if qp.G is None or qp.h is None or qp.G_x is None:      # (no inequality constraint)
        return np.zeros((0, qp.x0.shape[0]))
    slack = qp.h - qp.G @ z
    lam_tol = MULTIPLIER_TOL * max(1.0, float(np.max(np.abs(lam), initial=0.0)))
    act = (lam > lam_tol) & (slack <= ACTIVE_TOL * np.maximum(1.0, np.abs(qp.h)))
    return qp.G_x[act]


def run_cascade(stack: TaskStack, solve_qp, *, fixing: str, metric, rcond: float,
                eps: float, on_infeasible: str, infeasibility_tol: float,
                backend: str, margin: float = 0.0, fix_active: bool = True,
                level_damping: np.ndarray | None = None) -> Outcome:
    """The cascade shared by the back-ends: ``solve_qp(LevelQP) -> (x, msg, extras)``."""
    n = stack.n
    fixed = Fixed.start(n)
    detail = Detail(backend, fixing)
    diagnostics = Diagnostics(detail=detail)

    def fail(level_index, tasks, message, partial):
        detail.fixed_tasks = list(fixed.tasks)
        detail.x_partial = partial
        return Outcome(np.full(n, np.nan), Status.FAILED, diagnostics).fail(
            message, "solver_error", level_index, tasks)

    for j, level in enumerate(stack.levels):
        rows = level_rows(level)
        if rows.A_eq.shape[0] == 0 and rows.A_in.shape[0] == 0:
            detail.levels.append({"level": j, "skipped": "no row with a finite bound that "
                                                         "x can change"})
            fixed.tasks += list(level.names)
            continue
        scale = float(rows.A_eq.shape[0] + rows.A_in.shape[0])   # ‖A‖_F² after scaling
        qp = build_level_qp(rows, fixed, fixing, eps * max(scale, 1e-300), margin=margin,
                            damping=0.0 if level_damping is None else float(level_damping[j]))
        x, message, extras = solve_qp(qp)
        if x is None:
            return fail(j, level.names, f"level {j} ({', '.join(level.names)}): {message}",
                        fixed.x.copy() if j else None)
        active = extras.pop("_active", None) if fix_active else None
        if active is not None:
            extras["strongly_active"] = int(active.shape[0])
        fixed.add(rows, level.names, x, rcond, active)
        failed = record_level(diagnostics, {"level": j, "tasks": list(level.names), **extras},
                              level, x, infeasibility_tol, on_infeasible, fail)
        if failed is not None:
            return failed
    qp = build_level_qp(None, fixed, fixing, 0.0, metric, margin=margin)
    x, message, extras = solve_qp(qp)
    extras.pop("_active", None)
    if x is None:
        return fail(len(stack), [], f"final regularisation level: {message}", fixed.x.copy())
    detail.levels.append({"level": "regularisation", **extras})
    return Outcome(x, Status.OPTIMAL, diagnostics)


def solve(stack: TaskStack, *, solver: str, tolerance: float | None, backend_options: dict
          | None, fixing: str, metric, rcond: float, regularization: float | None,
          on_infeasible: str, infeasibility_tol: float, margin: float, fix_active: bool,
          level_damping, certify: bool) -> Outcome:
    """Solve the stack by one QP per level plus a regularisation level.

    See the module docstring; every option is listed in :data:`OPTIONS`.
    """
    if level_damping is not None:
        level_damping = np.array(level_damping, dtype=np.float64).ravel()
        if level_damping.shape != (len(stack),) or not np.all(np.isfinite(level_damping)) \
                or np.any(level_damping < 0):
            raise FormulationError(f"level_damping must hold {len(stack)} finite values "
                                   f"≥ 0 (one μ² per level), got {level_damping.tolist()}")
    solver = resolve_solver(solver)
    extra = dict(backend_options or {})   # OPTIONS validated fixing, tolerance, ...
    tol = DEFAULT_TOLERANCES.get(solver) if tolerance is None else float(tolerance)
    settings = {**backend_settings(solver, tol), **extra}
    eps = NEEDS_DEFINITE_P.get(solver, 0.0) if regularization is None else float(regularization)
    if not np.isfinite(eps) or eps < 0:
        raise FormulationError(f"regularization must be a finite number ≥ 0, "
                               f"got {regularization}")
    out = run_cascade(stack, lambda qp: solve_level_qp(qp, solver, settings), fixing=fixing,
                      metric=metric, rcond=rcond, eps=eps, on_infeasible=on_infeasible,
                      infeasibility_tol=float(infeasibility_tol), backend=solver,
                      margin=float(margin), fix_active=bool(fix_active),
                      level_damping=level_damping)
    out.diagnostics.detail.settings = settings
    out.check = CheckRequest(auto=bool(certify) and level_damping is None, metric=metric)
    return out


class Prepared(contract.StackPrepared):
    """The QP cascade prepared for one layout: :func:`solve` on each stack (one QP
    per level, built per solve)."""

    name = NAME
    capabilities = CAPABILITIES

    def solve_stack(self, stack: TaskStack, settings: Any) -> Outcome:
        s = settings
        return solve(stack, solver=s.solver, tolerance=s.tolerance,
                     backend_options=s.backend_options, fixing=s.fixing, metric=s.metric,
                     rcond=s.rcond, regularization=s.regularization,
                     on_infeasible=s.on_infeasible, infeasibility_tol=s.infeasibility_tol,
                     margin=s.margin, fix_active=s.fix_active, level_damping=s.level_damping,
                     certify=s.certify)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared,
                                   backends=backends)
