"""Exact lexicographic optimum of equality and inequality stacks by a compiled active set.

The problem (levels ``i = 1..k``, highest first; an equality row has
``lower = upper = b``; ``√w`` the row weights of :class:`~prioik.hierarchy.Task`)::

    f_i* = min Σ_rows (√w_j · dist(A_j x, [lower_j, upper_j]))²   over  X_{i−1},
    X_i  = { x ∈ X_{i−1} : the level's violation vector equals its optimal one },

and then the **minimum-norm** point of ``X_k`` (the tie-break; on equality stacks
``X_k`` is affine and this is the answer of ``reference`` and of the extended Jacobian's
eq. 18). The optimal violation vector ``w_i*`` of each level is unique (the objective
is strictly convex in it), so ``X_i`` is ``X_{i−1}`` with the level's violated rows and
equality rows fixed at their optimal values and its other inequality rows kept as
hard constraints ``lower ≤ A x ≤ upper`` for every level below.

*Algorithm* (a cascade in the lexicographic-least-squares family of lexls, Dimitrov,
Sherikov & Wieber 2015, and HCOD, Escande, Mansard & Wieber 2014, written for
prioik's kernel): the rows live in the rotated coordinates of the extended
Jacobian's nested pivoted QR (``formulations/_extended_jacobian_kernel.py``): the
fixed rows own leading coordinates, the rest are free. Each level runs a primal
active-set method on its piecewise-quadratic objective (equivalent to
``min ‖w‖²  s.t.  lower ≤ A x − w ≤ upper`` with the slack ``w`` eliminated):

* working set: the hard rows (inequality rows of the levels above with zero
  optimal violation) held at a bound, and the level's rows held at the bound they
  violate (an equality row is always in);
* step: the minimum-norm step of the equality-constrained least-squares problem of
  the working set (row-pivoted Householder LQ of the working hard rows, then of the
  working soft rows on the directions left; a small QR where they conflict; no
  SVD), cut at the first non-working row that would leave its interval (that row
  joins the working set at that bound);
* at a full step: a soft row on the wrong side of its bound leaves the set (or
  switches to its other bound when it overshoots it); otherwise the hard rows'
  multipliers ``ν`` (``C_Hᵀ ν = ∇f`` through the LQ of the hard rows) are checked and
  the most wrong-signed row released; none wrong-signed: the level is optimal.

After the level, its rows with non-zero violation and its equality rows are fixed
by one more row-pivoted LQ, whose reflectors rotate every row below (the extended
Jacobian's ``Z_{i+1}``), and the minimum-norm tie-break is a last level ``x = 0``
over the free coordinates (skipped when no inequality row is left, where it is
``y_free = 0``).

*Degenerate and hard cases.* Rank-deficient and redundant levels: every rank decision
is a pivot norm against a threshold (soft and fixed rows: ``rcond ‖A_i‖_F`` of the
level, as the extended Jacobian and ``reference``; hard rows: ``rcond ‖a_j‖`` of the
row), dependent rows are left out of the factorization (hard ones leave the working
set and are watched by the step test). An infeasible level keeps its least
violation (``info["infeasible_levels"]`` names the levels with ``f_i* > 0``). A zero
row with unreachable bounds (``0·x ∈ [2, 5]``) is a constant violation: it never
enters a factorization (zero pivot) and never blocks a step. Two-sided rows switch
sides through the wrong-side rule. Degenerate steps (length 0) switch the choices
to the smallest row index (Bland's rule) until a step makes progress, and every
level has an iteration cap (``max_iter``): when it is hit the status is
``approximate`` and ``info["message"]`` names the level.

*Tolerances.* A row counts as violated when it is outside its interval by more than
``primal_tol (‖√w_j a_j‖ ‖x‖ + |bound|)``; a multiplier is wrong-signed when
``|ν_j| ‖√w_j a_j‖ > dual_tol · max(‖∇f‖, ‖A_i‖_F (‖A_i‖_F ‖x‖ + ‖targets‖))``.

*Warm start.* :class:`Prepared` keeps each level's working set at its optimum; the
next solve first tries, per level, the step of last time's working set: when the
point it reaches keeps every hard row feasible, the level continues from there
(usually: one factorization and one multiplier check), else from the cold start.
Both paths end at the same optimum (within the tolerances above; tested at 1e-9).

*Complexity.* Per iteration ``O((h + w) d²)`` for ``h`` working hard rows, ``w``
working soft rows and ``d`` free coordinates, plus ``O(M n)`` for the step test;
the number of iterations is about the number of active-set changes (cold: one per
row that becomes active; warm along a trajectory: usually none).
"""

from __future__ import annotations

import numpy as np

from prioik.hierarchy import DEFAULT_RCOND, TaskStack

from .base import Capabilities, FormulationError, Outcome

try:
    from . import _active_set_kernel as _kernel
    _kernel_error = ""
except ImportError as exc:  # pragma: no cover - numba is a declared dependency
    _kernel = None
    _kernel_error = f"{type(exc).__name__}: {exc}"

NAME = "hierarchical_active_set"
DESCRIPTION = ("exact lexicographic optimum of equality and inequality stacks: compiled "
               "active set per level on the nested pivoted QR (warm-startable)")
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "rcond": (DEFAULT_RCOND, "relative rank threshold (rcond·‖A_i‖_F per level, "
                             "rcond·‖a_j‖ per hard row)"),
    "primal_tol": (1e-10, "relative tolerance on bounds: violated when outside by more "
                          "than primal_tol·(‖a_j‖‖x‖ + |bound|)"),
    "dual_tol": (1e-12, "relative tolerance on the sign of a hard row's multiplier"),
    "max_iter": (500, "iteration cap of each level (status 'approximate' when hit)"),
    "warm_start": (True, "prepared solver: start each level from the last solve's working "
                         "set (False: every solve cold)"),
}


def pack(stack: TaskStack) -> tuple[np.ndarray, ...]:
    """The stack's rows as the arrays of the layout/data API.

    Returns:
        ``(A, b, lower, upper, sqrt_weight, row_is_equality, starts)``: ``M × n``
        rows level after level; targets of equality rows (0 elsewhere); bounds of
        inequality rows (``±inf`` unbounded; ``b`` on equality rows); ``√w`` per row;
        the equality flags; ``k + 1`` row offsets of the levels.
    """
    A, b, lo, up, sw, eq, starts = [], [], [], [], [], [], [0]
    for level in stack.levels:
        for t in level:
            m = t.m
            A.append(t.A)
            w = np.broadcast_to(t.weight, (m,))
            sw.append(np.sqrt(w))
            if t.is_equality:
                b.append(t.b)
                lo.append(t.b)
                up.append(t.b)
                eq.append(np.ones(m, dtype=bool))
            else:
                tl, tu = t.bounds()
                b.append(np.zeros(m))
                lo.append(tl)
                up.append(tu)
                eq.append(np.zeros(m, dtype=bool))
        starts.append(starts[-1] + level.m)
    return (np.ascontiguousarray(np.vstack(A), dtype=np.float64),
            np.concatenate(b).astype(np.float64), np.concatenate(lo).astype(np.float64),
            np.concatenate(up).astype(np.float64), np.concatenate(sw).astype(np.float64),
            np.concatenate(eq), np.array(starts, dtype=np.int64))


def _options(options: dict) -> dict:
    """Defaults filled in and every value checked (FormulationError naming the option)."""
    unknown = sorted(set(options) - set(OPTIONS))
    if unknown:
        raise FormulationError(f"formulation {NAME!r} has no option {', '.join(unknown)}; "
                               f"its options: {', '.join(OPTIONS)}")
    out = {key: options.get(key, default) for key, (default, _) in OPTIONS.items()}
    for key in ("rcond", "primal_tol", "dual_tol"):
        try:
            val = float(out[key])
        except (TypeError, ValueError):
            raise FormulationError(f"{key} must be a number, got {out[key]!r}") from None
        if not (0.0 <= val < 1.0):     # also False for NaN
            raise FormulationError(f"{key} must be in [0, 1), got {out[key]!r}")
        out[key] = val
    it = out["max_iter"]
    if isinstance(it, bool) or not isinstance(it, (int, np.integer)) or it < 1:
        raise FormulationError(f"max_iter must be an integer ≥ 1, got {it!r}")
    out["max_iter"] = int(it)
    if not isinstance(out["warm_start"], (bool, np.bool_)):
        raise FormulationError(f"warm_start must be True or False, got {out['warm_start']!r}")
    out["warm_start"] = bool(out["warm_start"])
    return out


class Prepared:
    """A solver for one stack shape that keeps its workspaces and last active set.

    Args:
        layout: The shape to solve: a :class:`~prioik.hierarchy.TaskStack` (its
            levels' row counts and kinds; the rows themselves come with each
            :meth:`solve`).
        options: The formulation's options (see :data:`OPTIONS`).

    Raises:
        FormulationError: numba missing, or an option out of range.
    """

    def __init__(self, layout: TaskStack, options: dict | None = None) -> None:
        if _kernel is None:
            raise FormulationError(f"{NAME} needs numba: {_kernel_error}")
        self.options = _options(dict(options or {}))
        A, _, _, _, _, eq, starts = pack(layout)
        self.n = int(A.shape[1])
        self.starts = starts
        self.row_is_equality = eq
        self.names = tuple(level.names for level in layout.levels)
        M, n, k = A.shape[0], self.n, len(starts) - 1
        rows = M + n
        self._ws = dict(
            B=np.zeros((rows, n)), blo=np.zeros(rows), bup=np.zeros(rows),
            rnorm=np.zeros(rows), eqr=np.zeros(rows, dtype=np.bool_),
            state=np.zeros(rows, dtype=np.int8), saved=np.zeros(rows, dtype=np.int8),
            T=np.zeros((rows, n)), rhs=np.zeros(rows), norms=np.zeros(rows),
            rows=np.zeros(rows, dtype=np.int64), tgt=np.zeros(rows),
            V=np.zeros((n, n)), beta=np.zeros(n), vpos=np.zeros(n, dtype=np.int64),
            Vf=np.zeros((n, n)), betaf=np.zeros(n), posf=np.zeros(n, dtype=np.int64),
            y=np.zeros(n), p=np.zeros(n), g=np.zeros(n), nu=np.zeros(rows),
            Lw=np.zeros((rows, n)))
        self.warm_state = np.zeros((k + 1, rows), dtype=np.int8)
        self.warm_valid = np.zeros(k + 1, dtype=np.bool_)
        self._x = np.zeros(n)
        self._iters = np.zeros(k + 1, dtype=np.int64)
        self._flags = np.zeros(k + 1, dtype=np.int64)
        self._ranks = np.zeros(k + 1, dtype=np.int64)
        self._w2 = np.zeros(k)

    def reset(self) -> None:
        """Forget the last active set (the next solve starts cold)."""
        self.warm_valid[:] = False

    def solve(self, data: TaskStack) -> Outcome:
        """Solve one stack of this shape (warm-started from the last solve unless
        ``warm_start=False``).

        Raises:
            FormulationError: the stack's shape differs from the prepared one.
        """
        A, b, lo, up, sw, eq, starts = pack(data)
        if (A.shape[1] != self.n or not np.array_equal(starts, self.starts)
                or not np.array_equal(eq, self.row_is_equality)):
            raise FormulationError(f"{NAME}: the stack's shape (n, rows per level, kinds) "
                                   f"differs from the prepared one")
        return self.solve_arrays(A, b, lo, up, sw)

    def solve_arrays(self, A: np.ndarray, b: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray, sqrt_weight: np.ndarray) -> Outcome:
        """Solve from the packed arrays of :func:`pack` (shape as prepared; not
        validated here: the caller validated the stack)."""
        o, ws = self.options, self._ws
        _kernel.solve_kernel(A, b, lower, upper, sqrt_weight, self.row_is_equality,
                             self.starts, o["rcond"], o["primal_tol"], o["dual_tol"],
                             o["max_iter"], o["warm_start"], self.warm_state, self.warm_valid,
                             ws["B"], ws["blo"], ws["bup"], ws["rnorm"], ws["eqr"],
                             ws["state"], ws["saved"], ws["T"], ws["rhs"], ws["norms"],
                             ws["rows"], ws["tgt"], ws["V"], ws["beta"], ws["vpos"],
                             ws["Vf"], ws["betaf"], ws["posf"], ws["y"], ws["p"], ws["g"],
                             ws["nu"], ws["Lw"], self._x, self._iters, self._flags,
                             self._ranks, self._w2)
        return self._outcome()

    def _outcome(self) -> Outcome:
        x = self._x.copy()
        k = len(self.starts) - 1
        w2 = self._w2.copy()
        info = {"iterations": self._iters.copy(), "rank_profile": self._ranks[:k].copy(),
                "level_violation": w2,
                "infeasible_levels": [i for i in range(k)
                                      if w2[i] > 0.0 and np.sqrt(w2[i]) > self.options["primal_tol"]
                                      * max(1.0, float(np.linalg.norm(x)))],
                "warm_start": self.options["warm_start"]}
        capped = np.flatnonzero(self._flags == _kernel.FLAG_ITERATION_CAP).tolist()
        if not np.isfinite(x).all():
            info["message"] = "the active-set iterations produced non-finite values"
            return Outcome(x, "failed", info)
        if capped:
            lv = capped[0]
            what = (f"level {lv} ({', '.join(self.names[lv])})" if lv < k
                    else "the minimum-norm tie-break")
            info.update(capped_levels=capped, failed_level=lv,
                        message=f"iteration cap max_iter={self.options['max_iter']} hit at "
                                f"{what}: its working set did not settle (degenerate or "
                                f"cycling); levels above it are optimal, x is feasible for "
                                f"them but not certified optimal at and below it")
            return Outcome(x, "approximate", info)
        return Outcome(x, "optimal", info)


def solve(stack: TaskStack, **options) -> Outcome:
    """The lexicographic optimum of ``stack`` (cold start); see the module docstring."""
    return Prepared(stack, options).solve(stack)
