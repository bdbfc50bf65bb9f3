"""The extended-Jacobian framework of Jeong & Chang (2009), eq. 15-18 and eq. 27.

Each level ``i > 1`` contributes the rows ``Z_i J_iᵀ J_i θ̈ = Z_i J_iᵀ h_i`` (eq. 14),
the stationarity condition of its least-squares error restricted to the null space
of the levels above; stacked under ``J_1`` they form the extended Jacobian ``J_E``
(eq. 15), ``h_E`` (eq. 16), and ``θ̈ = J_E⁺ h_E`` (eq. 18). Theorem 1 shows that the
system equals the full-row-rank system of the *feasible* rows (eq. 25-26).

Options (:data:`OPTIONS`):

* ``nullspace`` — ``"qr"`` (default): every ``Z_i`` from one nested Householder QR with
  column pivoting, no SVD, solved by forward substitution in the rotated coordinates
  (the C++ core up to ``n = 160`` with ``kernel="auto"``); ``"svd"``: as the paper, each
  ``Z_i`` from an SVD and ``J_E`` built literally (its error grows like ``ε κ(J_E)``:
  ``approximate`` when ``κ(J_E) > SVD_CERTIFIED_CONDITION``).
* ``damping=λ`` — eq. 27: the blocks below the first become ``Z_i (J_iᵀ J_i + λ I)``.
* ``z_basis`` — the reading of the paper's ``Z_i``: ``"task_range"`` (default; the
  ``r_i`` directions of the higher levels' null space level ``i`` can use, eq. 12) or
  ``"null_space"`` (a basis of the whole null space). Eq. 18 gives the same answer
  either way; eq. 27 does not.
* ``level_damping=λ_max`` with ``singular_threshold=ε`` — selective damping of a level
  whose projected ``σ_min < ε ‖A_i‖_F`` (``μ² = λ_max (1 − (σ/ε‖A_i‖_F)²)``).
* ``step_bound=Δ`` — each level's own step bounded, ``‖z_i‖ ≤ Δ`` (trust-region damping;
  one bound, one per level, or ``{task name: Δ}``).
* ``rcond`` (the rank rule of :mod:`hierarchy.linalg`), ``kernel``.

Statuses: ``optimal`` unless a rank decision is ambiguous, a near-ambiguous one's answer
fails the verification stage's certificate (:attr:`Detail.near_ambiguous_levels`: the
answer is then certified after the timed solve), the ``svd`` path's ``κ(J_E)`` exceeds
its bound, or a level was damped (:attr:`Detail.damped_levels`): then ``approximate``
with ``diagnostics.reason``. :attr:`Detail.level_damping` holds every level's ``μ_i²``
(0 where exact), so ``cascaded_qp`` with the same Tikhonov terms reproduces θ̈.
:func:`extended_system` returns ``J_E`` and ``h_E`` as built, for analysis.

The two paths, the two readings of ``Z_i`` and the damping rules in detail:
``docs/extended-jacobian.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import lapack

from prioik.hierarchy import (
    AMBIGUITY,
    NEAR_AMBIGUITY,
    StackData,
    StackLayout,
    TaskStack,
    UnsupportedTaskError,
    ambiguity_reason,
    ambiguous_decision,
    decision_margin,
    level_scale,
    near_ambiguity_reason,
    rank_threshold,
)
from prioik.hierarchy.linalg import numpy_svd

from . import contract
from ._compiled import _core, core_error, solve_each
from .base import (
    Capabilities,
    CheckRequest,
    CoreInputError,
    Diagnostics,
    FormulationError,
    Outcome,
    Status,
    solve_equilibrated,
)
from .options import Option, rcond_option, validate_options


@dataclass(slots=True)
class Detail:
    """``extended_jacobian``'s own record (``sol.diagnostics.detail``).

    Attributes:
        nullspace: ``"qr"`` or ``"svd"`` (option ``nullspace``).
        kernel: ``"cpp"``, ``"lapack"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` elsewhere).
        z_basis: The reading of ``Z_i`` (the ``svd`` path and eq. 27; ``None`` on the
            nested QR).
        damping: Eq. 27's ``λ`` (``0``: none).
        rank: The ``svd`` path: rank of the augmented Jacobian.
        extended_rows: Rows of ``J_E`` (the ``svd`` path and eq. 27).
        condition_number: The ``svd`` path's ``κ(J_E)``.
        damped_levels: Levels solved damped (selective damping, ``step_bound``, eq. 27).
        level_damping: Every level's ``μ_i²`` (0 where exact), when a level may be damped.
        near_ambiguous_levels: Levels whose rank decision was near-ambiguous: the
            verification stage certified the answer.
    """

    nullspace: str
    kernel: str
    flops: int | None = None
    z_basis: str | None = None
    damping: float = 0.0
    rank: int | None = None
    extended_rows: int | None = None
    condition_number: float | None = None
    damped_levels: list[int] | None = None
    level_damping: np.ndarray | None = None
    near_ambiguous_levels: list[int] | None = None

_INT64 = np.dtype(np.int64)


def _clean_diagnostics(values: tuple) -> Diagnostics:
    """The :class:`~prioik.formulations.Diagnostics` of a solve on the C++ core from the
    values it left (:meth:`Prepared.solve_checked`'s snapshot): ``(ranks, flops)``."""
    ranks, flops = values
    return Diagnostics(ranks=ranks, detail=Detail("qr", "cpp", flops))


def step_bound_value(value):
    """The ``step_bound`` option's type check (its per-level values are checked against
    the layout by :func:`level_step_bounds`)."""
    if isinstance(value, dict):
        for key, val in value.items():
            if not isinstance(key, str):
                raise ValueError(f"a step_bound mapping takes task names, got {key!r}")
            _nonnegative_number(val)
        return dict(value)
    if isinstance(value, (str, bytes)):
        raise ValueError(f"must be a number, one number per level or a task-name mapping, "
                         f"got {value!r}")
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"must be a number, one number per level or a task-name mapping, "
                         f"got {value!r}") from None
    if arr.ndim > 1 or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"must be finite and ≥ 0, got {value!r}")
    return value


def _nonnegative_number(val) -> float:
    if isinstance(val, bool) or not isinstance(val, (int, float, np.integer, np.floating)) \
            or not (0.0 <= float(val) < math.inf):
        raise ValueError(f"step bounds must be finite numbers ≥ 0, got {val!r}")
    return float(val)


NAME = "extended_jacobian"
DESCRIPTION = "Jeong & Chang extended Jacobian (eq. 15-18), damped form eq. 27"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "nullspace": Option("qr", "str", "'qr': nested pivoted QR, no SVD; 'svd': SVD of "
                        "J_{i-1}^A as the paper", choices=("qr", "svd")),
    "damping": Option(0.0, "float", "λ of eq. 27 (0: exact eq. 18)", minimum=0.0),
    "z_basis": Option("task_range", "str", "Z_i of eq. 13-16, 27 (svd path, damping): "
                      "'task_range': the paper's r_i rows spanning range(N_{i-1} J_iᵀ); "
                      "'null_space': a basis of the whole null(J_{i-1}^A)",
                      choices=("task_range", "null_space")),
    "rcond": rcond_option(),
    "level_damping": Option(0.0, "float", "λ_max of the selective damping (qr path; 0: off)",
                            minimum=0.0),
    "kernel": Option("auto", "str", "qr path: 'cpp' (the compiled C++ core, prioik._core), "
                     "'lapack' (readable scipy.linalg.lapack), 'auto' (cpp up to n = 160, "
                     "else lapack)", choices=("auto", "cpp", "lapack")),
    "singular_threshold": Option(0.0, "float", "ε: damp a level whose projected "
                                 "σ_min < ε·‖A_i‖_F", minimum=0.0),
    "step_bound": Option(0.0, "any", "Δ > 0: every level's step ‖x_i − x_{i−1}‖ ≤ Δ by "
                         "trust-region damping (qr path; 0: off); or k values (one per "
                         "level, 0: unbounded), or {task name: Δ} for the levels holding "
                         "those tasks", check=step_bound_value),
}

_dgeqp3 = lapack.dgeqp3
_dgeqrf = lapack.dgeqrf
_dormqr = lapack.dormqr
_dtrtrs = lapack.dtrtrs


#: ``kernel="auto"`` uses the compiled C++ core up to this many unknowns. Its loops win
#: where call overhead dominates; LAPACK's blocked Householder code wins on larger
#: problems. Measured median µs cpp/lapack (one thread, k = 2/16 levels): compatible
#: n=100 78/191 and 77/580, n=200 598/582 and 593/1079, n=300 7596/1655 and 9983/14156;
#: conflicting n=200 1193/979 and 1093/1691.
AUTO_CPP_MAX_N = 160


def _resolve_kernel(kernel: str, n: int = 0) -> str:
    """``"cpp"`` or ``"lapack"`` for the ``kernel`` option on ``n`` unknowns
    (``"auto"``: the C++ core up to :data:`AUTO_CPP_MAX_N`, LAPACK above).

    Raises:
        FormulationError: the compiled core is not importable here.
    """
    if kernel == "lapack" or (kernel == "auto" and n > AUTO_CPP_MAX_N):
        return "lapack"
    if _core is None:
        raise FormulationError(f"kernel={kernel!r} needs prioik's compiled core "
                               f"(prioik._core): {core_error}; reinstall prioik "
                               f"(`pip install -e .`) to build it")
    return "cpp"


def solve(stack: TaskStack, **options) -> Outcome:
    """Solve the extended system (eq. 17) for ``x``: :class:`Prepared` for the stack's
    layout, then its :meth:`Prepared.solve` (see the module docstring)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


class Prepared(contract.Prepared):
    """The extended Jacobian prepared for one layout: options checked, workspaces
    allocated once.

    On the default path (``nullspace="qr"``, no eq. 27 damping, compiled kernel) a
    :meth:`solve` is one compiled call on the data's arrays: rows weighed by ``√w`` into
    the workspace, level scales and the finite check in the same pass, the nested
    pivoted QR of eq. 15-18 and the per-level residuals — no allocation but the answer.
    The other paths (``svd``, eq. 27, the LAPACK kernel) solve the data's stack.

    Safe to use from one thread at a time (the registry's
    :class:`~prioik.formulations.PreparedSolver` enforces it).

    Args:
        layout: The stack layout (equality tasks only).
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).

    Raises:
        UnsupportedTaskError: the layout holds an inequality task.
        FormulationError: options that do not combine, or a ``step_bound`` naming a task
            the layout does not have.
    """

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        for i, level in enumerate(layout.levels):
            for name, _, kind in level:
                if kind != "equality":
                    raise UnsupportedTaskError("inequality tasks are not supported",
                                               formulation=NAME, task=name, level=i)
        self.layout = layout
        self.kernel = _resolve_kernel(settings.kernel, layout.n)
        self.nullspace = settings.nullspace
        self.damping = float(settings.damping)
        self.z_basis = str(settings.z_basis)
        self.rcond = float(settings.rcond)
        self.singular_threshold = float(settings.singular_threshold)
        selective = float(settings.level_damping) > 0 and self.singular_threshold > 0
        self.level_damping = float(settings.level_damping) if selective else 0.0
        self.step_bound = level_step_bounds(layout, settings.step_bound)
        self.step_bound.setflags(write=False)
        self._bounded = bool(self.step_bound.any())
        if (selective or self._bounded) and (self.damping > 0 or self.nullspace != "qr"):
            raise FormulationError("level_damping and step_bound work on the qr path without "
                                   "eq. 27 damping; use one or the other")
        self.compiled = (self.kernel == "cpp" and self.nullspace == "qr"
                         and self.damping == 0)
        self._selective = self.level_damping > 0
        self._damped = self._selective or self._bounded
        self._starts = layout.starts
        self._n, self._k = layout.n, layout.k
        if self.compiled:
            # the C++ core owns the parameters, the level offsets and every workspace
            self._core = _core.ExtendedJacobian(
                [int(s) for s in layout.starts], layout.n, rcond=self.rcond,
                level_damping=self.level_damping, singular_threshold=self.singular_threshold,
                step_bound=self.step_bound.tolist())

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout (its data; the registry checked the layout).

        Raises:
            TaskStackError: a value is not finite (naming the task, level and row), or
                the rows' squares overflow.
        """
        out = self.solve_checked(data)
        if isinstance(out, tuple):
            x, residuals, (diagnostics_of, values) = out
            return Outcome(x, Status.OPTIMAL, diagnostics_of(values), residuals=residuals,
                           checked=True)
        return out

    def solve_checked(self, data: StackData) -> tuple | Outcome:
        """:meth:`solve`, its common case (the compiled kernel's answer, finite, every
        rank decision clear, no damping) as the tuple ``(x, residuals, snapshot)`` of a
        checked ``optimal`` :class:`Outcome` without the object, its diagnostics built
        from ``snapshot`` when read (:func:`_clean_diagnostics`; the registry's
        :class:`~prioik.formulations.PreparedSolver` makes the Solution from it, see
        :meth:`prioik.formulations.contract.Prepared.solve_checked`); an
        :class:`Outcome` otherwise.

        Raises:
            TaskStackError: as :meth:`solve`.
        """
        if not self.compiled:
            return self._solve_stack(data.as_stack())
        return self._solve_core(data)

    def _solve_core(self, data: StackData) -> tuple | Outcome:
        """:meth:`solve_checked` on the C++ core (``kernel="cpp"``), its answer read from
        the core's result by name."""
        k = self._k
        x, residuals = np.empty(self._n), np.empty(k)    # the answer's own
        ranks = np.empty(k, _INT64)
        try:
            res = self._core.solve(data.A, data.b, data.sqrt_weight, x, residuals, ranks)
        except CoreInputError:
            data.check()     # names the task, level and row of a NaN, inf or bad √w
            raise
        if res.clear and not self._damped:     # the common case (clear: solved too)
            return (x, residuals, (_clean_diagnostics, (ranks, res.flops)))
        if not res.solved:
            # finite rows of extreme scale: solve the equilibrated stack (same optimum)
            return solve_equilibrated(self.solve, data, "the rows' scale overflows float64 "
                                      "(‖A_i‖_F² is not finite): scale the tasks down")
        diagnostics = _clean_diagnostics((ranks, res.flops))
        status = Status.OPTIMAL
        if self._damped:
            status = _damping_info(diagnostics, res.level_mu2, self._selective,
                                   self._bounded)
        margins = res.margins
        diagnostics.margins = np.array(margins)
        if res.ambiguous:
            status = _ambiguity_status(diagnostics, status,
                                       np.flatnonzero(margins <= AMBIGUITY))
        outcome = Outcome(x, status, diagnostics, residuals, res.finite)
        if res.near_ambiguous and status == Status.OPTIMAL and res.finite:
            _ask_certificate(outcome, margins)
        return outcome

    def _solve_stack(self, stack: TaskStack) -> Outcome:
        if self.damping > 0:
            return _solve_damped(stack, self.damping, self.rcond, self.nullspace,
                                 self.z_basis)
        if self.nullspace == "svd":
            return _solve_svd(stack, self.rcond, self.z_basis)
        return _solve_qr(stack, self.rcond, self.level_damping, self.singular_threshold,
                         self.step_bound)

    def solve_batch(self, datas: list[StackData]) -> contract.BatchOutcome:
        """Many stacks of the layout: ``(X, statuses, checks)`` (compiled, in parallel;
        a near-ambiguous answer asks the verification stage to certify it, as in
        :meth:`solve`)."""
        return _solve_batch(self, datas)


def level_step_bounds(stack: TaskStack | StackLayout, step_bound) -> np.ndarray:
    """The per-level bounds ``Δ_i`` (0: unbounded) of the ``step_bound`` option.

    Args:
        stack: The stack or its layout.
        step_bound: One ``Δ ≥ 0`` for every level, ``k`` values, or a mapping task
            name → ``Δ`` (a level gets the smallest bound of its tasks).

    Raises:
        FormulationError: a value is negative or not finite, the sequence has the
            wrong length, or a task name is not in the stack.
    """
    layout = stack.layout if isinstance(stack, TaskStack) else stack
    k = len(layout)
    if type(step_bound) in (float, int) and step_bound == 0:
        return np.zeros(k)                       # the default: every level unbounded
    if isinstance(step_bound, dict):
        out = np.zeros(k)
        for name, val in step_bound.items():
            try:
                i = layout.level_of(name)
            except KeyError:
                raise FormulationError(f"step_bound names task {name!r}, which is not in "
                                       f"the stack (tasks: {', '.join(layout.task_names())})"
                                       ) from None
            out[i] = float(val) if out[i] == 0 else min(out[i], float(val))
    else:
        try:
            out = np.broadcast_to(np.asarray(step_bound, dtype=np.float64), (k,)).copy()
        except ValueError:
            raise FormulationError(f"step_bound must be one number, {k} numbers (one per "
                                   f"level) or a task-name mapping, got {step_bound!r}"
                                   ) from None
    if not np.all(np.isfinite(out)) or np.any(out < 0):
        raise FormulationError(f"step_bound must be finite and ≥ 0, got {out.tolist()}")
    return out


def _damping_info(diagnostics: Diagnostics, mu2: np.ndarray, selective: bool,
                  bound: bool) -> Status:
    """Record the per-level damping in the detail record; the status it implies."""
    if not (selective or bound):
        return Status.OPTIMAL       # the kernels damp no level without either option
    flagged = np.flatnonzero(mu2 > 0).tolist()
    diagnostics.detail.damped_levels = flagged
    diagnostics.detail.level_damping = mu2.copy()
    if not flagged:
        return Status.OPTIMAL
    diagnostics.add_reason(f"levels {flagged} damped (selective damping or step_bound): a "
                           f"damped hierarchy, not the lexicographic optimum")
    return Status.APPROXIMATE


# --------------------------------------------------------------------------- qr
def _pivoted_lstsq_if_full_rank(K: np.ndarray, p: np.ndarray, tol: float
                                ) -> tuple[np.ndarray, float] | None:
    """``argmin ‖K z − p‖`` for ``K`` (``m × d``, ``m ≥ d``) of full column rank, by one
    QR with column pivoting (``dgeqp3``), and the rank decision's margin
    (:func:`hierarchy.decision_margin`); ``None`` when a pivot is ``≤ tol``
    (rank-deficient: the caller takes the row-pivoted path)."""
    d = K.shape[1]
    qr, jpvt, tau, _, _ = _dgeqp3(np.array(K, order="F"), overwrite_a=1)
    pivots = np.abs(np.diagonal(qr)[:d])
    if tol <= 0 or not np.all(pivots > tol):
        return None
    z = np.empty(d)
    Kp = K[:, jpvt - 1]
    z[jpvt - 1] = _refined(Kp, qr, _qr_least_squares(qr, tau, p), p)
    return z, decision_margin(pivots, tol)


def _lstsq_full_column_rank(K: np.ndarray, p: np.ndarray) -> np.ndarray:
    """min ‖K z − p‖ for ``K`` (m × r, m > r) of full column rank, by Householder QR."""
    qr, tau, _, _ = _dgeqrf(K)
    return _refined(K, qr, _qr_least_squares(qr, tau, p), p)


def _refined(K: np.ndarray, qr: np.ndarray, z: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``z ≈ argmin ‖K z − p‖`` (``K`` of full column rank, ``qr`` its compact QR) after
    one step of refinement by the corrected semi-normal equations, ``z + R⁻¹ R⁻ᵀ Kᵀ
    (p − K z)``. Householder QR is backward stable in norm only: rows of ``K`` far
    smaller than its norm (zero rows with targets, tasks decades apart in one level)
    are read with errors of ``ε ‖K‖``, and their large targets leak into ``Qᵀ p``;
    ``Kᵀ (p − K z)`` is formed row by row (a zero row adds exactly nothing)."""
    r = z.shape[0]
    if r == 0 or not np.isfinite(z).all():
        return z
    g = K.T @ (p - K @ z)
    w, _ = _dtrtrs(qr[:r, :r], g, trans=1)
    dz, _ = _dtrtrs(qr[:r, :r], w)
    return z + dz.ravel()


def _qr_least_squares(qr: np.ndarray, tau: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``R⁻¹ (Qᵀ p)[:r]`` from LAPACK's compact QR (``qr``, ``tau``) of an ``m × r``
    matrix of full column rank."""
    m, r = qr.shape
    qtp, _, _ = _dormqr("L", "T", qr, tau, p.reshape(m, 1), max(1, m))
    z, _ = _dtrtrs(qr[:r, :r], qtp[:r])
    return z.ravel()


def _damped_lstsq(K: np.ndarray, p: np.ndarray, mu2: float) -> np.ndarray:
    """min ‖K z − p‖² + μ² ‖z‖² through the QR of ``[K; μ I]``."""
    m, r = K.shape
    aug = np.zeros((m + r, r), order="F")
    aug[:m] = K
    aug[m:] = np.sqrt(mu2) * np.eye(r)
    rhs = np.zeros(m + r)
    rhs[:m] = p
    return _lstsq_full_column_rank(aug, rhs)


def _trust_region_step(K: np.ndarray, p: np.ndarray, mu2_min: float, step_bound: float
                       ) -> tuple[np.ndarray, float]:
    """``z`` of ``min ‖K z − p‖ s.t. ‖z‖ ≤ Δ`` with damping at least ``mu2_min``.

    ``K`` (``m × r``) has full column rank. Returns ``(z, μ²)``: ``z`` solves
    ``(KᵀK + μ² I) z = Kᵀp`` with the smallest ``μ² ≥ mu2_min`` for which ``‖z‖ ≤ Δ``
    (``μ² = mu2_min`` when that step is short enough; otherwise ``‖z‖ = Δ`` to 1e-12).
    """
    u, s, vt = np.linalg.svd(K, full_matrices=False)
    c = s * (u.T @ p)                                    # s_j (u_jᵀ p)
    s2 = s * s
    mu2 = mu2_min
    w = c / (s2 + mu2)
    norm = float(np.linalg.norm(w))
    if step_bound > 0 and norm > step_bound:
        for _ in range(100):   # Newton on 1/‖z(μ²)‖ − 1/Δ: concave, monotone from below
            dnorm = -float(np.sum(w * w / (s2 + mu2))) / norm     # d‖z‖/dμ²
            step = (1.0 / norm - 1.0 / step_bound) * norm * norm / dnorm
            mu2 = max(mu2 + step, mu2_min)
            w = c / (s2 + mu2)
            norm = float(np.linalg.norm(w))
            if abs(norm - step_bound) <= 1e-12 * step_bound:
                break
    return vt.T @ w, mu2


def _solve_qr(stack: TaskStack, rcond: float, level_damping: float = 0.0,
              singular_threshold: float = 0.0, step_bound: np.ndarray | None = None
              ) -> Outcome:
    n = stack.n
    mats = [(level.A, level.b) for level in stack.levels]
    B = np.vstack([A for A, _ in mats])          # working copy of all rows
    c = np.concatenate([b for _, b in mats])
    y = np.zeros(n)                               # solution in rotated coordinates
    reflectors = []                               # (col, qr[:, :r], tau[:r]) per level
    ranks = []
    margins = np.full(len(mats), np.inf)         # each level's rank decision's margin
    level_mu2 = np.zeros(len(mats))
    bounds = np.zeros(len(mats)) if step_bound is None else step_bound
    col = 0
    start = 0
    for index, (A, _) in enumerate(mats):
        m = A.shape[0]
        stop = start + m
        d = n - col
        if d == 0 or m == 0:
            ranks.append(0)
            start = stop
            continue
        rhs = c[start:stop] - B[start:stop, :col] @ y[:col]
        if m >= d and bounds[index] <= 0 and level_damping <= 0:
            full = _pivoted_lstsq_if_full_rank(B[start:stop, col:], rhs,
                                               rank_threshold(A, rcond))
            if full is not None:              # full column rank: no null space left
                ranks.append(d)
                y[col:] = full[0]
                margins[index] = full[1]
                col = n
                start = stop
                continue
        M_T = np.array(B[start:stop, col:].T, order="F")      # (A_i Z_i)ᵀ, d × m
        qr, jpvt, tau, _, _ = _dgeqp3(M_T, overwrite_a=1)
        diag = np.abs(np.diagonal(qr)[: min(d, m)])
        tol = rank_threshold(A, rcond)
        r = int(np.count_nonzero(diag > tol)) if tol > 0 else 0
        ranks.append(r)
        margins[index] = decision_margin(diag, tol)
        if r == 0:
            start = stop
            continue
        # In rotated coordinates level i reads  B_i[:, :col] y_prev + Pᵀ-permuted Rᵀ y_new.
        perm = jpvt - 1
        p = rhs[perm]
        mu2 = 0.0
        if level_damping > 0:
            sigma = float(diag[r - 1])                           # RRQR estimate of σ_min
            eps_abs = singular_threshold * float(np.linalg.norm(A))
            if sigma < eps_abs:
                mu2 = level_damping * (1.0 - (sigma / eps_abs) ** 2)
        if mu2 > 0:
            z = _damped_lstsq(np.triu(qr[:r, :]).T.copy(), p, mu2)
        elif r == m:
            z, _ = _dtrtrs(qr[:r, :r], p, trans=1)
        else:
            z = _lstsq_full_column_rank(np.triu(qr[:r, :]).T.copy(), p)
        if bounds[index] > 0 and float(np.linalg.norm(z)) > bounds[index]:
            z, mu2 = _trust_region_step(np.triu(qr[:r, :]).T, p, mu2, bounds[index])
        level_mu2[index] = mu2
        y[col:col + r] = z
        if stop < B.shape[0] and r < d:
            rest = B[stop:, col:]
            B[stop:, col:], _, _ = _dormqr("R", "N", qr[:, :r], tau[:r], rest,
                                           max(1, rest.shape[0]))
        reflectors.append((col, qr[:, :r], tau[:r]))
        col += r
        start = stop
    x = y
    for col_i, v, t in reversed(reflectors):
        seg = x[col_i:].reshape(-1, 1)
        out, _, _ = _dormqr("L", "N", v, t, seg, 1)
        x[col_i:] = out.ravel()
    diagnostics = Diagnostics(ranks=np.array(ranks), margins=np.asarray(margins),
                              detail=Detail("qr", "lapack"))
    status = _damping_info(diagnostics, level_mu2, level_damping > 0, bool(bounds.any()))
    status = _ambiguity_status(diagnostics, status, np.flatnonzero(margins <= AMBIGUITY))
    outcome = Outcome(x, status, diagnostics)
    if status == Status.OPTIMAL and np.isfinite(x).all():
        _ask_certificate(outcome, margins)
    return outcome


def _near_ambiguous_levels(margins: np.ndarray) -> list[int]:
    """The levels whose rank decision's margin is clear of the ambiguity band by less
    than :data:`~prioik.hierarchy.NEAR_AMBIGUITY` times it."""
    return np.flatnonzero((margins > AMBIGUITY)
                          & (margins <= NEAR_AMBIGUITY * AMBIGUITY)).tolist()


#: what the verification stage checks of a near-ambiguous answer (the certificate with
#: the minimum-norm tie-break and the exact active set's comparison)
_NEAR_AMBIGUOUS_CHECK = CheckRequest()


def _ask_certificate(outcome: Outcome, margins: np.ndarray) -> None:
    """Ask the verification stage to certify an ``optimal`` answer when a level's rank
    decision was near-ambiguous (``margins``: each level's): the null space such a
    decision leaves is accurate to ε over its smallest kept pivot, which rows of a lower
    level may turn into an error beyond what the certificate accepts
    (:data:`~prioik.hierarchy.NEAR_AMBIGUITY`). The levels go in
    :attr:`Detail.near_ambiguous_levels`; the answer stays ``optimal`` only when the
    certificate passes it (the reason then names those levels too)."""
    near = _near_ambiguous_levels(margins)
    if not near:
        return
    outcome.diagnostics.detail.near_ambiguous_levels = near
    outcome.check = _NEAR_AMBIGUOUS_CHECK
    outcome.explain = lambda: near_ambiguity_reason(near)


def _ambiguity_status(diagnostics: Diagnostics, status: Status, ambiguous) -> Status:
    """``status``, or ``APPROXIMATE`` with the reason when some level's rank decision was
    ambiguous (``ambiguous``: level indices)."""
    levels = [int(i) for i in ambiguous]
    if not levels:
        return status
    diagnostics.ambiguous_levels = levels
    diagnostics.add_reason(ambiguity_reason(levels))
    return Status.APPROXIMATE


# -------------------------------------------------------------------------- svd
#: The two readings of the paper's ``Z_i`` (option ``z_basis``): ``"task_range"``, the
#: ``r_i`` rows spanning ``range(N_{i-1} J_iᵀ)`` (eq. 12-13, 22-25), and
#: ``"null_space"``, a basis of the whole ``null(J_{i-1}^A)``.
Z_BASES = ("task_range", "null_space")


def _extended_blocks(stack: TaskStack, rcond: float, damping: float, zs,
                     equilibrate: bool = False, ranges=None, targets=None):
    """``J_E`` and ``h_E`` of eq. 15-16 (eq. 27 when ``damping > 0``); with ``targets``
    (one weighted vector per level) ``h_E`` of those targets instead of the levels'.

    ``zs[i]`` (columns) is a basis of ``null(J_{i-1}^A)``. With ``ranges`` (the paper's
    reading, ``z_basis="task_range"``) level ``i``'s block is built on ``ranges[i]``
    instead, the ``r_i`` columns spanning ``range(N_{i-1} J_iᵀ)``: ``r_i`` rows per
    level, ``ρ(J_k^A)`` rows in all, and eq. 27's ``λ Z_i`` only acts inside the
    level's own directions (``J_1``'s block is not damped, as in eq. 27). Without it
    (``"null_space"``) every damped block has ``n − ρ(J_{i-1}^A)`` rows, and
    ``λ Z_i`` also pulls on the directions that belong to the lower levels.

    With ``equilibrate`` each block is scaled to unit Frobenius norm, which leaves the
    solutions of the (consistent) undamped system unchanged and keeps the squared
    scale of ``J_iᵀJ_i`` from hiding a level's singular values.
    """
    rows, rhs = [], []
    n = stack.n
    for i, ((A, b), Z) in enumerate(zip(stack.equality_matrices(), zs, strict=False)):
        if targets is not None:
            b = targets[i]
        if ranges is not None:
            basis = ranges[i]
            if basis.shape[1] == 0:
                continue  # r_i = 0: no feasible direction, no equation (Theorem 1)
            if i == 0 and basis.shape[1] == A.shape[0]:
                rows.append(A)              # J_1 of full row rank: its own rows (eq. 15)
                rhs.append(b)
                continue
            lam = damping if i > 0 else 0.0
        else:
            if damping == 0 and i + 1 < len(zs) and zs[i + 1].shape[1] == Z.shape[1]:
                continue  # r_i = 0: Z_i J_iᵀ J_i = 0 up to rounding, no equation (Theorem 1)
            if i == 0 and Z.shape[1] == n:
                full_row_rank = np.linalg.matrix_rank(
                    A, tol=rcond * float(np.linalg.norm(A))) == A.shape[0]
                if full_row_rank or A.shape[0] == 0:
                    rows.append(A)
                    rhs.append(b)
                    continue
            if Z.shape[1] == 0:
                continue
            basis, lam = Z, damping
        # (J_i Z_iᵀ)ᵀ J_i, not Z_i (J_iᵀ J_i): see the module docstring (ε/σ² against ε/σ)
        AB = A @ basis
        block, target = AB.T @ A, AB.T @ b
        if lam > 0:
            block = block + lam * basis.T          # Z_i (J_iᵀJ_i + λ I), eq. 27
        if equilibrate:  # a consistent system keeps its solutions under row scaling
            norm = float(np.linalg.norm(block))
            if norm > 0:
                block, target = block / norm, target / norm
        rows.append(block)
        rhs.append(target)
    if not rows:
        return np.zeros((0, n)), np.zeros(0)
    return np.vstack(rows), np.concatenate(rhs)


def _augmented_null_spaces(stack: TaskStack, rcond: float) -> tuple[list[np.ndarray], int]:
    """``Z_1 … Z_{k+1}`` (columns) from the SVD of each augmented Jacobian (eq. 7, 13),
    and the rank ``ρ(J_k^A)`` (see :func:`_augmented_decomposition`)."""
    zs, rank, _ = _augmented_decomposition(stack, rcond)
    return zs, rank


def _augmented_decomposition(stack: TaskStack, rcond: float
                             ) -> tuple[list[np.ndarray], int, list[int]]:
    """``Z_1 … Z_{k+1}``, ``ρ(J_k^A)`` and the levels whose rank decision is ambiguous.

    Each level's block is first scaled to unit Frobenius norm (row equilibration: the
    null space is unchanged), so one threshold ``rcond`` judges every level on its own
    scale, as the nested rule of ``hierarchy.linalg`` does. ``J_i^A`` is kept as the
    triangular factor ``R_i`` of its QR (``J_i^A = Q_i R_i``, same singular values and
    right singular vectors; ``R_i`` from the QR of ``[R_{i-1}; A_i/‖A_i‖_F]``), so each
    level costs ``O((n + m_i) n²)`` instead of an SVD of all the rows above.
    """
    n = stack.n
    zs = [np.eye(n)]
    R = np.zeros((0, n))
    ambiguous = []
    for i, level in enumerate(stack.levels):
        A = level.A
        norm = level_scale(A)
        R = np.asarray(np.linalg.qr(np.vstack([R, A / norm if norm > 0 else A]), mode="r"))
        if R.shape[0] > n:
            R = R[:n]
        _, sv, vt = numpy_svd(R, full_matrices=True)
        r = int(np.count_nonzero(sv > rcond)) if rcond > 0 else 0
        if ambiguous_decision(sv, rcond):
            ambiguous.append(i)
        zs.append(vt[r:].T.copy())
    return zs, n - zs[-1].shape[1], ambiguous


#: ``nullspace="svd"`` says ``optimal`` only up to this condition number of ``J_E``:
#: its error is about ``ε κ(J_E)`` (measured ≤ 84 ε κ), ≤ 1.9e-9 relative here.
SVD_CERTIFIED_CONDITION = 1e5


def _svd_task_ranges(stack: TaskStack, zs: list[np.ndarray]) -> list[np.ndarray]:
    """The paper's ``Z_i`` (as columns) on the ``svd`` path: the ``r_i`` leading right
    singular vectors of ``J_i Z_i`` mapped back by ``Z_i``, with
    ``r_i = dim null(J_{i-1}^A) − dim null(J_i^A)`` (eq. 12) from ``zs``; they span
    ``range(N_{i-1} J_iᵀ)`` (``N_{i-1} = Z_i Z_iᵀ``)."""
    out = []
    for level, Z, Z_next in zip(stack.levels, zs, zs[1:], strict=False):
        r = Z.shape[1] - Z_next.shape[1]
        if r <= 0:
            out.append(np.zeros((stack.n, 0)))
            continue
        _, _, vt = numpy_svd(level.A @ Z, full_matrices=False)
        out.append(Z @ vt[:r].T)
    return out


def _solve_svd(stack: TaskStack, rcond: float, z_basis: str = "task_range") -> Outcome:
    zs, rank, ambiguous = _augmented_decomposition(stack, rcond)
    ranges = _svd_task_ranges(stack, zs) if z_basis == "task_range" else None
    if rank == 0:      # every level is zero: no equation, the minimum-norm x is 0
        return Outcome(np.zeros(stack.n), Status.OPTIMAL,
                       Diagnostics(detail=Detail("svd", "numpy", z_basis=z_basis, rank=0,
                                                 extended_rows=0, condition_number=1.0)))
    JE, hE = _extended_blocks(stack, rcond, 0.0, zs, equilibrate=True, ranges=ranges)
    if JE.shape[0] == 0:
        return Outcome(np.zeros(stack.n), Status.OPTIMAL,
                       Diagnostics(detail=Detail("svd", "numpy", z_basis=z_basis, rank=rank,
                                                 extended_rows=0, condition_number=1.0)))
    u, s, vt = numpy_svd(JE, full_matrices=False)
    r = min(rank, int(np.count_nonzero(s > 0)))
    x = vt[:r].T @ ((u[:, :r].T @ hE) / s[:r])
    # one step of refinement: the same solve for the levels' residuals at x. J_E's
    # blocks carry J_iᵀ J_i, so x is ε κ(J_E) off; the residuals are small where a level
    # is met, and their solve removes that error there (a level met exactly, rows of
    # 1e-3 at ‖x‖ 3.6, left at 1e-16 where the nested paths reach 1e-18)
    if r and np.isfinite(x).all():
        _, hR = _extended_blocks(stack, rcond, 0.0, zs, equilibrate=True, ranges=ranges,
                                 targets=[b - A @ x for A, b in stack.equality_matrices()])
        x = x + vt[:r].T @ ((u[:, :r].T @ hR) / s[:r])
    cond = float(s[0] / s[r - 1]) if r else 1.0
    diagnostics = Diagnostics(ambiguous_levels=list(ambiguous),
                              detail=Detail("svd", "numpy", z_basis=z_basis, rank=rank,
                                            extended_rows=int(JE.shape[0]),
                                            condition_number=cond))
    reasons = []
    if ambiguous:
        reasons.append(ambiguity_reason(ambiguous))
    if not cond <= SVD_CERTIFIED_CONDITION:
        reasons.append(f"κ(J_E) = {cond:.3g} > {SVD_CERTIFIED_CONDITION:g}: the svd path's "
                       f"error (≈ ε κ(J_E)) is beyond what it can certify; use "
                       f"nullspace='qr'")
    diagnostics.reason = "; ".join(reasons)
    return Outcome(x, Status.APPROXIMATE if reasons else Status.OPTIMAL, diagnostics)


# ----------------------------------------------------------------------- damped
def _qr_null_spaces(stack: TaskStack, rcond: float, ranges: bool = False
                    ) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
    """Explicit ``Z_i`` (columns) from the nested pivoted QR (no SVD).

    Returns ``(zs, vs)``: ``zs[i]`` spans ``null(J_{i-1}^A)`` (``i = 0 … k−1``); with
    ``ranges``, ``vs[i]`` holds the ``r_i`` columns spanning ``range(N_{i-1} J_iᵀ)``,
    the paper's ``Z_i``, from the same factorization: the pivoted QR of
    ``(J_i Z_i)ᵀ = Q R Pᵀ`` puts ``range`` in ``Q``'s first ``r_i`` columns and the next
    null space in the others (``vs`` is ``None`` without ``ranges``).
    """
    n = stack.n
    Z = np.eye(n)
    zs = [Z]
    vs: list[np.ndarray] = []
    levels = stack.levels if ranges else stack.levels[:-1]
    for level in levels:
        A = level.A
        d = Z.shape[1]
        V = np.zeros((n, 0))
        if d and A.shape[0]:
            M_T = np.array((A @ Z).T, order="F")
            qr, _, tau, _, _ = _dgeqp3(M_T, overwrite_a=1)
            k = min(M_T.shape)
            tol = rcond * float(np.linalg.norm(A))
            r = int(np.count_nonzero(np.abs(np.diagonal(qr)[:k]) > tol)) if tol > 0 else 0
            if r:
                # columns :r of the full Q span range((A_i Z_i)ᵀ), columns r.. its null
                # space, in the local coordinates
                Q, _, _ = _dormqr("L", "N", qr[:, :r], tau[:r], np.eye(d, order="F"), d)
                V = Z @ Q[:, :r]
                Z = Z @ Q[:, r:]
        vs.append(V)
        zs.append(Z)
    return zs[:len(stack.levels)], (vs if ranges else None)


def extended_system(stack: TaskStack, *, damping: float = 0.0,
                    z_basis: str = "task_range", nullspace: str = "qr",
                    rcond: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The extended Jacobian ``J_E`` and task vector ``h_E`` built literally.

    Eq. 15-16 (``damping = 0``) or the damped blocks of eq. 27 (``damping = λ > 0``),
    with the ``Z_i`` of either reading (``z_basis``) from the nested QR
    (``nullspace="qr"``) or from SVDs of the augmented Jacobians (``"svd"``); blocks
    not equilibrated. For analysis (its singular values, its size); :func:`solve`
    is the way to an answer. Options as in :data:`OPTIONS` (``rcond`` ``None``: its
    default).

    Raises:
        FormulationError: an option is out of range (naming it).
    """
    given = {"damping": damping, "z_basis": z_basis, "nullspace": nullspace}
    if rcond is not None:
        given["rcond"] = rcond
    opts = validate_options(NAME, OPTIONS, given, stack.n)
    zs, ranges = _damped_bases(stack, float(opts["rcond"]), opts["nullspace"],
                               opts["z_basis"])
    return _extended_blocks(stack, float(opts["rcond"]), float(opts["damping"]), zs,
                            ranges=ranges)


def _damped_bases(stack: TaskStack, rcond: float, nullspace: str, z_basis: str):
    """``(zs, ranges)`` for :func:`_extended_blocks` (``ranges`` ``None`` for the
    ``"null_space"`` reading)."""
    paper = z_basis == "task_range"
    if nullspace == "svd":
        zs, _ = _augmented_null_spaces(stack, rcond)
        return zs, (_svd_task_ranges(stack, zs) if paper else None)
    return _qr_null_spaces(stack, rcond, ranges=paper)


def _solve_damped(stack: TaskStack, damping: float, rcond: float, nullspace: str,
                  z_basis: str = "task_range") -> Outcome:
    zs, ranges = _damped_bases(stack, rcond, nullspace, z_basis)
    paper = ranges is not None
    # With the paper's Z_i, J_E has full row rank ρ(J_k^A): the system is consistent
    # and its solutions do not change when each block is scaled to unit norm, which
    # keeps a level's scale (1e-6 or 1e4) out of the conditioning. The whole-null-space
    # system is over-determined and solved in least squares: scaling its blocks would
    # change the fit, so it is built as printed.
    JE, hE = _extended_blocks(stack, rcond, damping, zs, equilibrate=paper, ranges=ranges)
    m, n = JE.shape
    if m == 0:
        x = np.zeros(n)
    elif nullspace == "svd":
        x = np.linalg.pinv(JE) @ hE
    elif paper:
        # full row rank: x = J_Eᵀ (J_E J_Eᵀ)⁻¹ h_E from the QR of J_Eᵀ (no truncation:
        # every row is a direction the rank rule kept)
        qr, tau, _, _ = _dgeqrf(np.array(JE.T, order="F"))
        w, _ = _dtrtrs(qr[:m, :m], hE, trans=1)
        full = np.zeros((n, 1))
        full[:m, 0] = w.ravel()
        xq, _, _ = _dormqr("L", "N", qr, tau, full, 1)
        x = xq.ravel()
    else:
        # complete orthogonal decomposition: the minimum-norm least-squares solution
        # of the over-determined system
        jpvt = np.zeros(n, dtype=np.int32)
        bb = np.zeros(max(m, n))
        bb[:m] = hE
        lwork = max(1, max(m, n) * 8 + 64)
        _, xb, _, _, _ = lapack.dgelsy(JE, bb.reshape(-1, 1), jpvt, 1e-12, lwork)
        x = xb[:n].ravel()
    detail = Detail(nullspace, "lapack" if nullspace == "qr" else "numpy", z_basis=z_basis,
                    damping=damping, extended_rows=int(m))
    if ranges is not None:
        # with the paper's Z_i, eq. 27 is the damped hierarchy μ² = (0, λ, …, λ) on
        # the levels that own directions (a cascade given these terms reproduces it)
        mu2 = np.array([damping if i > 0 and V.shape[1] else 0.0
                        for i, V in enumerate(ranges)])
        detail.level_damping = mu2
        detail.damped_levels = np.flatnonzero(mu2 > 0).tolist()
    return Outcome(x, Status.APPROXIMATE,
                   Diagnostics(reason=f"eq. 27's damping (damping={damping:g}): a damped "
                                      f"answer, not the lexicographic optimum",
                               detail=detail))


def _solve_batch(prepared: Prepared, datas: list[StackData]) -> contract.BatchOutcome:
    """Many stacks of one layout at once: the compiled kernel over the batch, stacks in
    parallel (a loop of :meth:`Prepared.solve` off the compiled path)."""
    if not prepared.compiled:
        return solve_each(prepared.solve, datas)
    return _solve_batch_core(prepared, datas)


def _solve_batch_core(prepared: Prepared, datas: list[StackData]) -> contract.BatchOutcome:
    """:func:`_solve_batch` on the C++ core: the stacks' rows copied into one array each,
    solved one after the other by the prepared core."""
    A = np.stack([d.A for d in datas])
    b = np.stack([d.b for d in datas])
    W = np.stack([d.sqrt_weight for d in datas])
    try:
        res = prepared._core.solve_batch(A, b, W)
    except CoreInputError:
        for d in datas:
            d.check()
        raise
    if not res.solved.all():
        # finite rows of extreme scale: one by one, equilibrated as in solve
        return solve_each(prepared.solve, datas)
    X = res.x.copy()
    return (X, *_batch_statuses(res.level_mu2, res.margins))


def _batch_statuses(mu2: np.ndarray, margins: np.ndarray
                    ) -> tuple[list[str], list[CheckRequest | None]]:
    """Each stack's status from its damping and rank decisions' margins, and the check
    a near-ambiguous ``optimal`` answer asks the verification stage for (as
    :meth:`Prepared.solve` reads them)."""
    approximate = np.asarray((mu2 > 0).any(axis=1) | (margins <= AMBIGUITY).any(axis=1))
    near = (margins <= NEAR_AMBIGUITY * AMBIGUITY).any(axis=1) & ~approximate
    statuses: list[str] = [Status.APPROXIMATE if a else Status.OPTIMAL
                           for a in approximate.tolist()]
    checks = [_NEAR_AMBIGUOUS_CHECK if n else None for n in near.tolist()]
    return statuses, checks


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
