"""DAQP's native hierarchical solve: one ``daqp.solve`` call for the whole stack.

DAQP (Arnström, Bemporad & Axehill 2022) takes the rows of every level stacked,
``blower ≤ A x ≤ bupper``, and ``break_points`` (the end row of each level). With
no cost it minimises, level by level, the squared violation of the level's rows
inside the optimal set of the levels above, and returns the minimum-norm point of
the last set. An equality task is the row pair ``b ≤ A x ≤ b`` (weighted by ``√w``);
an inequality task keeps its bounds (``∓inf`` sent as ``∓1e30``). Each level is
divided by its RMS row norm (DAQP's absolute tolerances become relative per level).

Where it is exact: DAQP counts one free direction per active soft row, which holds
when a level's active rows add as much rank as their number. A rank-deficient level
is made full-rank first (``compress_levels=True``, default: its ``r`` SVD rows, the
same least-squares optimum). A level whose active rows depend on those above (a
*conflicting* level) can leave the lower levels far from their optimum; no DAQP
setting changes this, and the status says so.

Statuses: ``optimal`` when DAQP exits with flag 1 or 2 and, with ``check=True``, the
answer passes the verification stage's certificate
(:func:`~prioik.formulations.verification.certify`, run after the timed solve); ``approximate``
otherwise, with ``diagnostics.fault`` and, computed then, :attr:`Detail.conflicting_levels`;
``failed`` on a negative exit flag (``diagnostics.fault``, for infeasibility the hard
inequality tasks involved). ``check=False`` skips the certificate. ``primal_tol``
defaults to 1e-10. The timed solve is DAQP's call and the level compression alone.

In detail: ``docs/formulations.md``; measurements: ``docs/qp-formulations.md``.
"""

from __future__ import annotations

from ctypes import c_int
from dataclasses import dataclass, field
from typing import Any

import daqp
import numpy as np

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
from .options import Option, dictionary, rcond_option


@dataclass(slots=True)
class Detail:
    """``daqp_hierarchical``'s own record (``sol.diagnostics.detail``).

    Attributes:
        exitflag: DAQP's exit flag (:data:`EXIT_FLAGS`).
        exit: Its name.
        iterations: DAQP's iterations.
        daqp_solve_time_s: DAQP's own timing of its C solve.
        break_points: The end row of each level given to DAQP.
        settings: The ``daqp.solve`` settings used.
        conflicting_levels: Levels whose active rows at ``x`` depend on those above
            (:func:`dependent_active_levels`): computed when the verification stage
            demotes the answer, else ``None``.
    """

    exitflag: int
    exit: str
    iterations: int
    daqp_solve_time_s: float = 0.0
    break_points: list[int] = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    conflicting_levels: list[int] | None = None


NAME = "daqp_hierarchical"
DESCRIPTION = "DAQP's hierarchical QP: the whole stack in one daqp.solve call (break_points)"
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=False)
OPTIONS = {
    "primal_tol": Option(1e-10, "float", "DAQP primal feasibility tolerance (DAQP's default: "
                         "1e-6)", minimum=0.0, exclusive_minimum=True),
    "dual_tol": Option(1e-12, "float", "DAQP dual feasibility tolerance", minimum=0.0,
                       exclusive_minimum=True),
    "compress_levels": Option(True, "bool", "replace each equality level by its SVD rows "
                              "(full row rank)"),
    "check": Option(True, "bool", "'optimal' only when the answer passes check_lexicographic "
                    "(DEFAULT_CERTIFICATE_TOL, minimum-norm tie-break), else 'approximate'"),
    "rcond": rcond_option(),
    "settings": Option(None, "any", "dict of extra daqp.solve settings (e.g. iter_limit, "
                       "rho_soft)", optional=True, check=dictionary),
}

#: DAQP exit flags (DAQP's constants.h).
EXIT_FLAGS = {1: "optimal", 2: "soft optimal", -1: "infeasible", -2: "cycling",
              -3: "unbounded", -4: "iteration limit", -5: "non-convex",
              -6: "overdetermined initial active set"}

_INF = 1e30


def build(stack: TaskStack, compress: bool, rcond: float, scale: bool = True):
    """Stacked ``A``, ``bupper``, ``blower``, ``break_points`` and each row's task name.

    With ``scale``, each level's rows and finite bounds are divided by the level's RMS
    row norm: the same minimiser (priorities are per level), and DAQP's absolute
    tolerances become relative to each level.
    """
    rows, up, lo, bps, names = [], [], [], [], []
    total = 0
    for level in stack.levels:
        l_rows, l_up, l_lo = [], [], []
        A, b = level.A, level.b
        if A.shape[0]:
            if compress:
                # every equality level, full rank or not: compressing only the
                # rank-deficient ones left DAQP answers on 46 of 100 conflicting stacks
                # that pass the lexicographic check yet differ from reference (median
                # 1.6e-3)
                u, s, vt = np.linalg.svd(A, full_matrices=False)
                tol = rcond * float(np.linalg.norm(A))
                r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
                A, b = s[:r, None] * vt[:r], u[:, :r].T @ b
                names += [",".join(t.name for t in level if t.is_equality)] * r
            else:
                names += [t.name for t in level if t.is_equality for _ in range(t.m)]
            l_rows.append(A)
            l_up.append(b)
            l_lo.append(b)
        for t in level:
            if t.is_equality:
                continue
            # a zero row's violation is fixed whatever x is: it stays out of DAQP's
            # problem (DAQP would report it infeasible)
            keep = np.any(t.A != 0.0, axis=1)
            tl, tu = t.bounds()
            tl, tu = tl[keep], tu[keep]
            sw = np.sqrt(np.broadcast_to(t.weight, (t.m,)))[keep]
            l_rows.append(sw[:, None] * t.A[keep])
            l_up.append(np.where(np.isfinite(tu), sw * tu, np.inf))
            l_lo.append(np.where(np.isfinite(tl), sw * tl, -np.inf))
            names += [t.name] * int(keep.sum())
        if not l_rows or sum(r.shape[0] for r in l_rows) == 0:
            continue                       # nothing x can change on this level
        L = np.vstack(l_rows)
        bu_l, bl_l = np.concatenate(l_up), np.concatenate(l_lo)
        sc = float(np.sqrt(np.sum(L ** 2) / max(L.shape[0], 1))) if scale and L.size else 1.0
        if not np.isfinite(sc) or sc == 0:
            sc = 1.0
        rows.append(L / sc)
        up.append(np.where(np.isfinite(bu_l), bu_l / sc, _INF))
        lo.append(np.where(np.isfinite(bl_l), bl_l / sc, -_INF))
        total += L.shape[0]
        bps.append(total)
    if not rows:      # no level has a row x can change (all zero): nothing to solve
        return (np.zeros((0, stack.n)), np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.intc),
                names)
    A = np.ascontiguousarray(np.vstack(rows), dtype=np.float64)
    return (A, np.ascontiguousarray(np.concatenate(up)), np.ascontiguousarray(np.concatenate(lo)),
            np.array(bps, dtype=np.intc), names)


def solve(stack: TaskStack, *, primal_tol: float, dual_tol: float, compress_levels: bool,
          check: bool, rcond: float, settings: dict | None) -> Outcome:
    """One hierarchical ``daqp.solve`` call; see the module docstring."""
    if settings is not None and not isinstance(settings, dict):
        raise FormulationError("settings must be a dict of daqp.solve keyword arguments")
    for key, val in (("primal_tol", primal_tol), ("dual_tol", dual_tol)):
        if not np.isfinite(float(val)) or float(val) <= 0:
            raise FormulationError(f"{key} must be a finite number > 0, got {val}")
    A, bu, bl, bps, names = build(stack, bool(compress_levels), float(rcond))
    request = CheckRequest(auto=bool(check))
    if A.shape[0] == 0:     # every row is zero: any x keeps the (fixed) violations; x = 0
        return Outcome(np.zeros(stack.n), Status.OPTIMAL,
                       Diagnostics(detail=Detail(1, "no row to solve (every row is zero)", 0)),
                       check=request)
    sense = np.zeros(len(bu), dtype=c_int)
    kwargs = {"primal_tol": float(primal_tol), "dual_tol": float(dual_tol), **(settings or {})}
    try:
        x, _, flag, dinfo = daqp.solve(None, None, A, bu.copy(), bl.copy(), sense,
                                       break_points=bps, **kwargs)
    except TypeError as exc:
        raise FormulationError(f"daqp.solve rejected the settings: {exc}") from None
    detail = Detail(int(flag), EXIT_FLAGS.get(int(flag), "unknown"),
                    int(dinfo.get("iterations", 0)), float(dinfo.get("solve_time", 0.0)),
                    bps.tolist(), kwargs)
    out = Outcome(np.asarray(x, dtype=np.float64).copy(), Status.OPTIMAL,
                  Diagnostics(detail=detail), check=request)
    if flag < 0:
        msg = f"DAQP exit flag {flag} ({detail.exit})"
        if flag == -6:
            msg += ("; the first activation of a level was singular: a level's rows are "
                    "dependent (try compress_levels=True) or repeat higher rows")
        if flag == -1:
            ineq = [(j, [t.name for t in lvl if not t.is_equality])
                    for j, lvl in enumerate(stack.levels)]
            ineq = [(j, n) for j, n in ineq if n]
            if ineq:
                return out.fail(msg + f"; hard inequality tasks involved: "
                                f"{', '.join(n for _, ns in ineq for n in ns)}", "infeasible",
                                ineq[0][0], ineq[0][1])
        return out.fail(msg)

    def explain() -> str:
        # the verification stage demoted the answer: which levels DAQP miscounts
        conflicts = dependent_active_levels(A, bu, bl, bps, out.x, float(rcond))
        detail.conflicting_levels = conflicts
        return (f"levels {conflicts} conflict with the levels above (eq. 35), where DAQP's "
                f"count of free directions goes wrong" if conflicts else "")

    out.explain = explain
    return out


#: A row counts as active when ``|A x − bound| ≤ ACTIVE_TOL · max(1, |bound|)`` or violated.
ACTIVE_TOL = 1e-7


def _active_rows(A, bu, bl, x):
    Ax = A @ x
    tol_u = ACTIVE_TOL * np.maximum(1.0, np.abs(bu))
    tol_l = ACTIVE_TOL * np.maximum(1.0, np.abs(bl))
    active = (bu == bl) | (Ax >= bu - tol_u) | (Ax <= bl + tol_l)
    unit = A / np.maximum(np.linalg.norm(A, axis=1), 1e-300)[:, None]
    return active, unit


def _rank(rows: np.ndarray, rcond: float) -> int:
    if rows.shape[0] == 0:
        return 0
    s = np.linalg.svd(rows, compute_uv=False)
    return int(np.count_nonzero(s > rcond * max(float(s[0]), 1e-300) * np.sqrt(rows.shape[0])))


def dependent_active_levels(A: np.ndarray, bu: np.ndarray, bl: np.ndarray, bps: np.ndarray,
                            x: np.ndarray, rcond: float) -> list[int]:
    """Levels whose active rows at ``x`` do not add their own count to the rank.

    DAQP's hierarchical loop removes one degree of freedom per active soft row; the
    count is right exactly when, level by level, the active rows (equalities,
    inequalities at a bound or violated) are independent of each other and of the
    active rows above. Returns the levels where that fails (empty: DAQP's answer is
    the lexicographic optimum up to its tolerances).
    """
    active, unit = _active_rows(A, bu, bl, x)
    out, rank, start = [], 0, 0
    rows = np.zeros((0, A.shape[1]))
    for j, stop in enumerate(bps):
        new = unit[start:stop][active[start:stop]]
        if new.shape[0]:
            rows = np.vstack([rows, new])
            r = _rank(rows, rcond)
            if r - rank < new.shape[0]:
                out.append(j)
            rank = r
        start = stop
    return out


class Prepared(contract.StackPrepared):
    """DAQP's hierarchical solve prepared for one layout: :func:`solve` on each
    stack."""

    name = NAME
    capabilities = CAPABILITIES

    def solve_stack(self, stack: TaskStack, settings: Any) -> Outcome:
        s = settings
        return solve(stack, primal_tol=s.primal_tol, dual_tol=s.dual_tol,
                     compress_levels=s.compress_levels, check=s.check, rcond=s.rcond,
                     settings=s.settings)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
