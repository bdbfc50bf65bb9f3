"""Analysis of a task stack and of a candidate solution ``x``.

Notation (Jeong & Chang 2009): ``J_i^A`` is the augmented Jacobian of levels
``1..i`` (eq. 7), ``Z_i`` an orthonormal basis of the null space of ``J_{i-1}^A``
(eq. 13; here stored as columns, ``n × d_i``), ``r_i = ρ(J_i^A) − ρ(J_{i-1}^A)`` the
rank a level adds (eq. 12). A level *conflicts* with the levels above when
``ρ(J_i^A) < ρ(J_{i-1}^A) + ρ(J_i)`` (eq. 35).

The feasible/conflicting split of eq. 19-21 is made basis-free: the feasible task
directions of level ``i`` are ``range(A_i Z_i)`` (an ``m_i × r_i`` orthonormal basis
``U_f``), the conflicting ones its complement ``U_c``. ``J_i_feasible = U_fᵀ A_i`` and
``h_i_feasible = U_fᵀ b_i`` span the same rows as the paper's row selection, and the
algorithmic error (eq. 29) is ``e_i = U_fᵀ (b_i − A_i x)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .errors import TaskStackError, UnsupportedTaskError
from .linalg import (
    CERTIFICATE_SIGMA_FLOOR,
    DEFAULT_CERTIFICATE_TOL,
    DEFAULT_RCOND,
    X_PRECISION,
    ambiguous_decision,
    level_scale,
    matrix_rank,
    nested_null_spaces,
    nonnegative_least_squares,
    range_basis,
    rank_profile,
    row_activity_from_values,
    svd,
)
from .stack import StackData, level_residuals

if TYPE_CHECKING:
    from .stack import TaskStack


def _require_equality(stack: TaskStack, what: str) -> None:
    for i, level in enumerate(stack.levels):
        for t in level:
            if not t.is_equality:
                raise UnsupportedTaskError("it is defined for equality tasks only",
                                           formulation=what, task=t.name, level=i)


def conflicting_levels(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[bool]:
    """For each level, whether it conflicts with the levels above (eq. 35)."""
    prof = rank_profile(stack, rcond)
    return [matrix_rank(level.A, rcond) > r for level, r in zip(stack.levels, prof, strict=False)]


def singularity_distance(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[float]:
    """Distance of each level to an algorithmic singularity.

    The smallest singular value of ``A_i Z_i`` above the rank threshold: the
    null-space projection methods divide by it (they grow like ``1/σ``). For the
    first level it is the smallest non-zero singular value of ``A_1`` (a kinematic
    singularity). ``0.0`` when the level has no feasible direction left.
    """
    Zs = nested_null_spaces(stack, rcond)
    out = []
    for level, Z in zip(stack.levels, Zs, strict=False):
        A = level.A
        if A.shape[0] == 0 or Z.shape[1] == 0:
            out.append(0.0)
            continue
        s = np.linalg.svd(A @ Z, compute_uv=False)
        s = s[s > rcond * float(np.linalg.norm(A))]
        out.append(float(s.min()) if s.size else 0.0)
    return out


@dataclass(frozen=True)
class FeasibleSplit:
    """Feasible and conflicting task directions of one level (eq. 19-21).

    Attributes:
        level: Level index.
        feasible: ``m_i × r_i`` orthonormal basis of ``range(A_i Z_i)``.
        conflicting: ``m_i × (m_i − r_i)`` basis of its orthogonal complement.
        J_feasible: ``U_fᵀ A_i`` (``r_i × n``), the rows the level can still achieve.
        h_feasible: ``U_fᵀ b_i``.
    """

    level: int
    feasible: np.ndarray
    conflicting: np.ndarray
    J_feasible: np.ndarray
    h_feasible: np.ndarray


def feasible_split(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[FeasibleSplit]:
    """The feasible/conflicting split of every equality level (eq. 19-21)."""
    _require_equality(stack, "feasible_split")
    Zs = nested_null_spaces(stack, rcond)
    out = []
    for i, (level, Z) in enumerate(zip(stack.levels, Zs, strict=False)):
        A, b = level.A, level.b
        Uf, Uc, _ = range_basis(A @ Z, rcond, scale=float(np.linalg.norm(A)))
        out.append(FeasibleSplit(i, Uf, Uc, Uf.T @ A, Uf.T @ b))
    return out


def algorithmic_error(stack: TaskStack, x: np.ndarray, rcond: float = DEFAULT_RCOND
                      ) -> list[np.ndarray]:
    """Algorithmic error ``e_i = h_i_feasible − J_i_feasible x`` of each level (eq. 29).

    Zero at every level for a lexicographic optimum; Chiaverini's method and the
    unifying framework leave it non-zero on coupled lower levels.
    """
    x = np.asarray(x, dtype=np.float64)
    return [sp.h_feasible - sp.J_feasible @ x for sp in feasible_split(stack, rcond)]


def algorithmic_error_norms(stack: TaskStack, x: np.ndarray,
                            rcond: float = DEFAULT_RCOND) -> np.ndarray:
    """``‖e_i‖`` of :func:`algorithmic_error` for each level."""
    return np.array([float(np.linalg.norm(e)) for e in algorithmic_error(stack, x, rcond)])


def relative_distance(x: np.ndarray, ref: np.ndarray) -> float:
    """``‖x − ref‖ / max(1, ‖ref‖)``: the distance to a reference answer that every test
    and report uses (relative for large answers, absolute for small ones)."""
    return float(np.linalg.norm(np.asarray(x) - ref) / max(1.0, float(np.linalg.norm(ref))))


def lexicographic_residuals(stack: TaskStack, x: np.ndarray) -> np.ndarray:
    """Per level, the norm of the weighted equality residual and inequality violation.

    For level ``i``: ``sqrt(Σ_t ‖√w_t (A_t x − b_t)‖² + Σ_t ‖√w_t viol_t(x)‖²)``, with
    ``viol_t = max(lower − A x, 0) + max(A x − upper, 0)``.
    """
    x = np.asarray(x, dtype=np.float64)
    if stack.is_equality:   # one mat-vec over the stack's data
        return level_residuals(stack.data, x)
    out = np.empty(len(stack))
    for i, level in enumerate(stack.levels):
        total = 0.0
        for t in level:
            Ax = t.A @ x
            if t.is_equality:
                r = Ax - t.b
            else:
                lo, up = t.bounds()
                r = np.maximum(lo - Ax, 0.0) + np.maximum(Ax - up, 0.0)
            total += float(np.sum(t.weight * r * r))
        out[i] = np.sqrt(total)
    return out


@dataclass(frozen=True)
class LevelCheck:
    """Optimality of one level (or of the final minimum-norm step).

    Attributes:
        level: Level index (``k`` for the minimum-norm step of a ``k``-level stack).
        tasks: Names of the level's tasks (``("minimum-norm",)`` for the final step).
        residual: ``‖w_i(x)‖``, the level's weighted equality residual and inequality
            violation (``‖x‖`` for the minimum-norm step).
        projected_gradient: The KKT residual in task space (see
            :func:`check_lexicographic`): on equality stacks ``‖U_fᵀ (A_i x − b_i)‖``, the
            algorithmic error of eq. 29, i.e. how far ``A_i x`` is from the level's best
            reachable value; for the minimum-norm step ``min_μ ‖Z_kᵀ (x + A_Sᵀ μ)‖``.
        scale: ``‖√w ∘ (|A_i| |x| + |t_i|)‖ + ‖√W_i A_i‖_F`` with ``t_i`` the level's targets
            (``b`` on equality rows, the nearest point of ``[lower, upper]`` on inequality
            rows): the size of the terms that make ``A_i x − t_i``, absolute for
            ``|x| ≲ 1``; ``max(1, ‖x‖)`` for the minimum-norm step.
        ok: ``projected_gradient ≤ tol · scale``, and for a level also
            ``value_gap ≤ tol · max(1, residual²)`` unless ``projected_gradient`` is at the
            level's rounding (``≤ X_PRECISION · max(scale, ‖x‖ ‖√W_i A_i‖_F)``: its terms',
            and that of coordinates known to ``X_PRECISION ‖x‖``).
        value_gap: ``projected_gradient²``: how much the level's value ``‖w_i‖²`` could
            still drop along the directions the KKT residual reads (for a least-squares
            level, the square of the reachable part of its weighted violation; with rows
            held at a bound, the projection on their cone) — or, when larger, the drop of
            a point along its descent direction that refuted ``x``. ``0`` for the
            minimum-norm step.
        fixed_rows: Higher rows kept at their value at ``x`` (equality rows, violated rows,
            rows at both bounds): free multipliers.
        active_rows: Higher rows at one bound: sign-constrained multipliers.
    """

    level: int
    tasks: tuple[str, ...]
    residual: float
    projected_gradient: float
    scale: float
    ok: bool
    fixed_rows: int = 0
    active_rows: int = 0
    value_gap: float = 0.0

    @property
    def relative(self) -> float:
        """``projected_gradient / scale``, what ``tol`` is compared with."""
        return self.projected_gradient / max(self.scale, 1e-300)

    def failure(self, tol: float) -> str:
        """Why the check fails at ``tol`` (the KKT residual, or the value it could still
        gain), for a status message."""
        if not self.relative <= tol:
            return f"KKT residual {self.relative:.2g} relative > tol {tol:g}"
        value = self.residual * self.residual
        return (f"its value {value:.6g} could drop by {self.value_gap:.2g} > tol {tol:g} x "
                f"max(1, value)")


@dataclass(frozen=True)
class LexicographicReport:
    """Result of :func:`check_lexicographic`.

    Attributes:
        ok: Every level passes, and the minimum-norm step when it was checked.
        tol: Relative tolerance used.
        levels: One :class:`LevelCheck` per level.
        minimum_norm: The check of the final minimum-norm step (``None`` when not asked).
        band_rows_fixed: Rows beyond a bound within the activity tolerance that the
            check read as fixed rather than held (``0``: the first reading; see
            :func:`check_lexicographic`).
        snapped_rows: Rows just inside a bound that the check moved onto it: ``x`` failed,
            the point it checked instead (within ``tol · max(1, ‖x‖)`` of ``x``, every
            level's value within ``tol · scale_i`` of ``x``'s) passed, and the report is
            that point's (``0``: ``x``'s own; see :func:`check_lexicographic`).
        ambiguous_levels: Levels where a rank decision the check took at ``x`` (the
            rows fixed there, or the level's own rows) was ambiguous: a singular value
            within :data:`~hierarchy.linalg.AMBIGUITY` of its threshold. The check reads
            them by the rank rule, as the exact solvers do; at such a decision another
            threshold gives another optimum, so a passing answer is the rank rule's
            optimum, not necessarily the exact-arithmetic one (the exact solvers then say
            ``approximate``, and so does :func:`formulations.verification.certify`).
    """

    ok: bool
    tol: float
    levels: tuple[LevelCheck, ...] = field(default_factory=tuple)
    minimum_norm: LevelCheck | None = None
    band_rows_fixed: int = 0
    snapped_rows: int = 0
    ambiguous_levels: tuple[int, ...] = ()

    @property
    def first_failure(self) -> LevelCheck | None:
        """The highest-priority level that fails, then the minimum-norm step, if any."""
        bad = next((c for c in self.levels if not c.ok), None)
        if bad is None and self.minimum_norm is not None and not self.minimum_norm.ok:
            return self.minimum_norm
        return bad

    @property
    def fault_level(self) -> int | None:
        """Index of :attr:`first_failure` (``len(levels)`` for the minimum-norm step)."""
        bad = self.first_failure
        return None if bad is None else bad.level

    @property
    def worst_relative(self) -> float:
        """The largest ``projected_gradient / scale`` over the checks."""
        checks = self.levels + ((self.minimum_norm,) if self.minimum_norm is not None else ())
        return max((c.relative for c in checks), default=0.0)

    def __str__(self) -> str:
        band = (f"; {self.band_rows_fixed} row(s) just beyond a bound read as fixed"
                if self.band_rows_fixed else "")
        if self.snapped_rows:
            band += (f"; {self.snapped_rows} row(s) just inside a bound moved onto it "
                     "(the report of that point, within the tolerance of x)")
        rows = [f"lexicographic check: {'ok' if self.ok else 'FAILED'} (tol {self.tol:g}{band})"]
        checks = self.levels + ((self.minimum_norm,) if self.minimum_norm is not None else ())
        for c in checks:
            gap = f", value gap {c.value_gap:.1e}" if c.level < len(self.levels) else ""
            rows.append(f"  level {c.level} {','.join(c.tasks)}: residual {c.residual:.3e}, "
                        f"KKT residual {c.projected_gradient:.3e} "
                        f"(relative {c.relative:.1e}{gap}; {c.fixed_rows} fixed, "
                        f"{c.active_rows} active rows above) {'ok' if c.ok else 'FAIL'}")
        return "\n".join(rows)


def _candidate(x, n: int) -> np.ndarray:
    """``x`` as a float64 vector of length ``n``; :class:`TaskStackError` otherwise."""
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TaskStackError(f"x cannot be read as a vector of numbers ({exc})") from None
    if arr.shape != (n,):
        raise TaskStackError(f"x has shape {arr.shape}, the stack has n = {n} "
                             f"(x must have shape ({n},))", shape=arr.shape)
    return arr


@dataclass
class _LevelRows:
    """One level's rows: unweighted ``A``, bounds (``l = u = b`` on equality rows), √w."""

    A: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    sqrt_weight: np.ndarray


def check_lexicographic(stack: TaskStack | StackData, x: np.ndarray,
                        tol: float = DEFAULT_CERTIFICATE_TOL,
                        rcond: float = DEFAULT_RCOND, minimum_norm: bool = False,
                        metric: np.ndarray | None = None) -> LexicographicReport:
    """Certificate that ``x`` is a lexicographic optimum of a stack of equality and
    inequality tasks (weights inside a level).

    Level ``i`` minimises ``‖w_i(x)‖²`` (weighted equality residuals and distances of
    ``A x`` to ``[lower, upper]``) over the set where every higher level keeps its
    optimal violation. ``x`` passes when, level by level, it solves that problem with
    the higher levels fixed at ``x``'s own violations: the KKT system
    ``A_iᵀ W_i r_i + Σ_{j<i} A_{S_j}ᵀ μ_j = 0`` over the higher rows ``S_j`` active at
    ``x`` (``μ ≥ 0`` at an upper bound, ``≤ 0`` at a lower one, free on equality and
    violated rows), its residual measured in task space (on equality stacks, the
    algorithmic error of eq. 29), ``≤ tol · scale_i``, and no feasible descent
    direction lowering the level's value by more than ``tol · max(1, ‖w_i‖²)``. Rows
    within the activity tolerance of a bound, rows a little violated and rows just
    inside a bound are read as ``docs/theory.md`` ("The certificate") states; levels of
    extreme scale are checked rescaled by a power of two (the same verdict).

    Args:
        stack: The stack, or its rows (:class:`StackData`, e.g. the data a prepared
            solver read: checked as they are, without building the stack's tasks).
        x: Candidate answer (``n``).
        tol: Relative tolerance of the KKT residuals and of the activity rule.
        rcond: Relative rank threshold of the nested null spaces.
        minimum_norm: Also check the minimum-norm tie-break, ``x`` minimising ``‖x‖²``
            (``xᵀ W x``) over the optimal set (reported as level ``k``; off by default:
            formulations differ in their tie-break).
        metric: SPD ``n × n`` ``W`` of the tie-break ``min xᵀ W x`` (default identity).

    Returns:
        A :class:`LexicographicReport`: ``ok``, one :class:`LevelCheck` per level,
        ``fault_level`` and the rank decisions that were ambiguous.

    Raises:
        TaskStackError: ``x`` is not a vector of ``n`` numbers, or a value of writable
            ``StackData`` is not valid (:meth:`StackData.check`).
    """
    # levels of extreme scale rescaled by a power of two (the same optimal set and
    # tie-break): squares of entries below ~1e-154 underflow, and a 1e-200·I level
    # read as zero rows passed x = 0
    if isinstance(stack, StackData):
        if stack.writeable:         # (a stack's frozen data was checked with its tasks)
            stack.check()
        x = _candidate(x, stack.n)
        data = stack
        if data.extreme_levels():
            data = data.as_stack().equilibrated()[0].data
    else:
        x = _candidate(x, stack.n)
        data = stack.equilibrated()[0].data
    report = _read(data, x, tol, rcond, minimum_norm, metric)
    if report.ok or not np.isfinite(x).all():
        return report
    snapped = _snapped(data, x, tol)
    if snapped is None:
        return report
    near, count = snapped
    again = _read(data, near, tol, rcond, minimum_norm, metric)
    checks = list(report.levels)
    near_checks = list(again.levels)
    if minimum_norm and report.minimum_norm is not None and again.minimum_norm is not None:
        checks.append(report.minimum_norm)
        near_checks.append(again.minimum_norm)
    if again.ok and all(abs(c.residual - d.residual) <= tol * d.scale
                        for c, d in zip(checks, near_checks, strict=False)):
        return dataclasses.replace(again, snapped_rows=count)
    return report


def _read(data: StackData, x: np.ndarray, tol: float, rcond: float, minimum_norm: bool,
          metric: np.ndarray | None) -> LexicographicReport:
    """The check of ``x`` (:func:`_check_lexicographic`), read again with the band rows
    fixed when that first reading fails and there are such rows."""
    report = _check_lexicographic(data, x, tol, rcond, minimum_norm, metric, False)
    if not report.ok and report.band_rows_fixed:
        retry = _check_lexicographic(data, x, tol, rcond, minimum_norm, metric, True)
        if retry.ok:
            return retry
    return dataclasses.replace(report, band_rows_fixed=0)


def _empty() -> np.ndarray:
    return np.zeros(0)


@dataclass
class _Activity:
    """Every row's activity at ``x`` (:func:`~hierarchy.linalg.row_activity`), with what
    it is read from: the interval ``[lower, upper]`` (``b`` on equality rows), the norms
    ``‖a_r‖``, and at a finite ``x`` the values ``a = A x``, ``terms = |A| |x|``, the
    sizes ``terms + norms``, the side and the violation (empty arrays otherwise)."""

    lower: np.ndarray
    upper: np.ndarray
    norms: np.ndarray
    a: np.ndarray = field(default_factory=_empty)
    terms: np.ndarray = field(default_factory=_empty)
    size: np.ndarray = field(default_factory=_empty)
    side: np.ndarray = field(default_factory=_empty)
    v: np.ndarray = field(default_factory=_empty)

    @classmethod
    def of(cls, data: StackData, x: np.ndarray, tol: float) -> _Activity:
        eq = data.layout.row_is_equality
        A = data.A
        act = cls(np.where(eq, data.b, data.lower), np.where(eq, data.b, data.upper),
                  np.linalg.norm(A, axis=1))
        if np.isfinite(x).all():
            act.a = A @ x
            act.terms = np.abs(A) @ np.abs(x)
            act.size = act.terms + act.norms
            act.side, act.v = row_activity_from_values(act.a, act.lower, act.upper,
                                                       act.size, tol)
        return act


#: rows inside their interval, off a bound by more than the activity tolerance and at
#: most this (relative to the activity rule's size plus ``|bound|``): the near-active rows
#: a failed check moves onto their bounds (:func:`_snapped`)
_NEAR_ACTIVE = 1e-6


def _snapped(data: StackData, x: np.ndarray, tol: float
             ) -> tuple[np.ndarray, int] | None:
    """``x`` with its near-active rows moved onto their bounds — the least-norm step that
    puts them there and keeps every row read at a bound or met as an equality where it
    is (rows left violated, the levels' objectives, may move) — and their count; ``None``
    when there are none or the step is longer than ``tol · max(1, ‖x‖)`` (not within the
    check's precision of ``x``)."""
    A = data.A
    act = _Activity.of(data, x, tol)
    lo, up, a, size, side, v = act.lower, act.upper, act.a, act.size, act.side, act.v
    inside = (side == 0) & (v == 0)
    with np.errstate(invalid="ignore"):
        near_up = inside & np.isfinite(up) & (up - a <= _NEAR_ACTIVE * (size + np.abs(up)))
        near_lo = inside & np.isfinite(lo) & (a - lo <= _NEAR_ACTIVE * (size + np.abs(lo)))
    snap = near_up | near_lo
    count = int(snap.sum())
    if not count:
        return None
    target = np.where(near_up & (~near_lo | (up - a <= a - lo)), up, lo)
    # the rows that constrain x where it is: at a bound, or met equalities (within the
    # activity tolerance); rows left violated are objectives, free to change
    with np.errstate(invalid="ignore"):
        met = np.abs(v) <= tol * (size + np.abs(a - v))
    keep = (np.abs(side) == 1) | ((side == 2) & met)
    M = np.vstack([A[snap], A[keep]])
    rhs = np.concatenate([(target - a)[snap], np.zeros(int(keep.sum()))])
    try:
        step = np.linalg.lstsq(M, rhs, rcond=None)[0]
    except np.linalg.LinAlgError:        # (an SVD that did not converge: no such point)
        return None
    if not np.linalg.norm(step) <= tol * max(1.0, float(np.linalg.norm(x))):
        return None
    return x + step, count


#: rows violated by at most this (relative to the activity rule's size) are checked for
#: being a solver's slack (:func:`_feasible`)
_NEARLY_FEASIBLE = 1e-6


def _feasible(A: np.ndarray, act: _Activity, fixed: np.ndarray, s1: int,
              small: np.ndarray) -> bool:
    """Whether some point keeps the rows above level ``rows[s0:s1]`` as read (``fixed``,
    their mask of rows read as fixed: at their values at ``x``, the others inside their
    intervals), meets the level's ``small`` rows and keeps its other rows at their
    values at ``x`` (violated) or inside their intervals (an LP, HiGHS, tolerance 1e-10
    on unit rows): then the level's value can drop by what the ``small`` rows add (and
    is zero when they are all of its violation). ``act`` holds every row's ``A x``."""
    from scipy.optimize import linprog
    s0 = fixed.shape[0]
    a, lo, up = act.a[:s1], act.lower[:s1], act.upper[:s1]
    own = ~small & ~((a[s0:] >= lo[s0:]) & (a[s0:] <= up[s0:]))   # violated rows kept
    fix = np.concatenate([fixed, own])
    A = A[:s1]
    lo, up = np.where(fix, a, lo), np.where(fix, a, up)
    norm = np.linalg.norm(A, axis=1)
    norm[norm == 0] = 1.0
    A, lo, up = A / norm[:, None], lo / norm, up / norm
    eq = lo == up
    ub = ~eq & np.isfinite(up)
    lb = ~eq & np.isfinite(lo)
    A_ub = np.vstack([A[ub], -A[lb]])
    b_ub = np.concatenate([up[ub], -lo[lb]])
    try:
        out = linprog(np.zeros(A.shape[1]), A_ub=A_ub if A_ub.shape[0] else None,
                      b_ub=b_ub if A_ub.shape[0] else None,
                      A_eq=A[eq] if eq.any() else None, b_eq=lo[eq] if eq.any() else None,
                      bounds=(None, None), method="highs",
                      options={"primal_feasibility_tolerance": 1e-10})
    except ValueError:
        return False
    return out.status == 0


def _precision(tol: float) -> float:
    """The relative precision an answer checked at ``tol`` is taken to have:
    :data:`X_PRECISION` (float64 rounding through orthogonal transformations), times how
    much ``tol`` is looser than :data:`DEFAULT_CERTIFICATE_TOL` (a caller checking the
    SVD extended Jacobian at ``1e3 eps κ`` declares its answers that much less precise:
    a "huge" level's rows of 1e11 left at 0.11 by an answer 6e-12 from the reference)."""
    return X_PRECISION * max(1.0, tol / DEFAULT_CERTIFICATE_TOL)


def _rounding(tol: float, scale: float, x_norm: float, level_norm: float) -> float:
    """How far rounding alone may leave a level's weighted rows ``√W_i A_i x`` from
    where they belong, at an answer checked at ``tol``: :func:`_precision` times the
    larger of the level's ``scale`` (the rounding of its terms, ``|A_i| |x|`` and its
    targets) and ``‖x‖ ‖√W_i A_i‖_F``. An answer computed through orthogonal
    transformations has every coordinate known to about ``X_PRECISION ‖x‖``, whatever
    its size, so a level that a huge ``x`` barely touches (its columns small where ``x``
    is large) still has its rows moved by up to ``X_PRECISION ‖x‖ ‖√W_i A_i‖_F``: the
    bound :func:`~hierarchy.stack.precision_limited_levels`,
    :func:`~hierarchy.exact.ExactOptimum.floors` and the solvers' comparison with the
    exact active-set answer read too."""
    return _precision(tol) * max(scale, x_norm * level_norm)


def _level_passes(res: float, scale: float, violation: float, tol: float,
                  rounding: float) -> bool:
    """A level's verdict from its KKT residual ``res`` (task space), scale, violation
    and rounding (:func:`_rounding`).

    ``res ≤ tol · scale`` reads the residual against the size of the level's terms; on
    its own it lets the value ``‖w_i‖²`` sit ``res²`` above its optimum, up to
    ``(tol · scale)²``, which is large where the level's satisfied rows dwarf the ones
    that carry its violation (rows of 1e4 beside rows of 1e-3: a point whose small rows
    were 0.1 off, the level 3e-4 above its optimum of 0, passed at 2.6e-11). So the
    value the level could still gain, ``res²``, must also be ``≤ tol · max(1, value)``,
    the accuracy the value is asked to — except where ``res`` is at the level's rounding
    (``≤ rounding``, :func:`_rounding`), below which the answer is not asked to go.
    """
    if not (np.isfinite(res) and res <= tol * max(scale, 1e-300)):
        return False
    return bool(res * res <= tol * max(1.0, violation * violation) or res <= rounding)


#: how many of a descent's best points :func:`_descent_drop` checks before it gives up
_DESCENT_TRIES = 4


def _descent_drop(A: np.ndarray, s0: int, s1: int, fixed: np.ndarray, act: _Activity,
                  sqrt_weight: np.ndarray, x: np.ndarray, x_norm: float, d: np.ndarray,
                  limit: float) -> float:
    """How much level ``rows[s0:s1]``'s value drops at the best point of ``x + α d``
    (``α ≥ 0``, at most ``max(1, ‖x‖)`` from ``x``) that keeps the rows above where the
    check reads them: fixed rows (``fixed``, the rows above) at their values and rows at
    a bound on it or inside, both to the rounding of their values (``X_PRECISION`` of
    their size), the other rows inside their intervals. Only a point that gives nothing
    up above counts: a held row allowed beyond its bound by the activity tolerance let a
    robot reach gain 2e-7 at its exact optimum, first order in that tolerance. The point
    is checked from its own ``A x``: a verified drop, whatever the KKT residual read (of
    the :data:`_DESCENT_TRIES` best points of the walk, the best that holds; ``0.0``
    when none does). ``0.0`` also when the drop cannot exceed ``limit``:
    the value is convex along ``d``, so above its tangent, and drops by at most
    ``2 |slope| α`` within the step allowed."""
    with np.errstate(all="ignore"):
        lo, up, sw = act.lower[s0:s1], act.upper[s0:s1], sqrt_weight[s0:s1]
        a, h, v0 = act.a[s0:s1], A[s0:s1] @ d, act.v[s0:s1]
        slope = float(np.sum(sw * sw * v0 * h))       # half the derivative at α = 0+
        if not slope < 0:
            return 0.0                                # the value does not drop along d
        # no further than ‖x‖ (or 1): beyond, the point's own rounding (eps |A| |x'|) is
        # coarser than x's, and a drop of 3.5e-4 read at ‖x'‖ = 1e14 was rounding
        # (‖d‖ overflowing to inf: no step, underflowing to 0: the ratios cap it)
        d_norm = float(np.sqrt(d @ d))
        cap = max(1.0, x_norm) / d_norm if d_norm > 0 else np.inf
        if s0:
            side = act.side[:s0]
            at_u, at_l = fixed | (side == 1), fixed | (side == -1)
            lo_h, up_h, a_h, hh = act.lower[:s0], act.upper[:s0], act.a[:s0], A[:s0] @ d
            rounding = X_PRECISION * (act.size[:s0] + np.abs(a_h))
            room_u = np.where(at_u, rounding, np.maximum(up_h - a_h, 0.0))
            room_l = np.where(at_l, rounding, np.maximum(a_h - lo_h, 0.0))
            ratio = np.where(hh > 0, room_u / hh, np.where(hh < 0, room_l / -hh, np.inf))
            cap = min(cap, float(np.min(ratio)))
        if not (cap > 0 and -2.0 * slope * cap > limit):
            return 0.0
        def value(vals: np.ndarray) -> np.ndarray:
            """The level's value at rows' values ``vals`` (one column per point)."""
            viol = vals - np.clip(vals, lo[:, None], up[:, None])
            return np.sum((sw[:, None] * viol) ** 2, axis=0)

        curve = float(np.sum((sw * h)[v0 != 0] ** 2))
        top = min(cap, -slope / curve) if curve > 0 else cap
        alphas = top * 0.5 ** np.arange(0, 24)
        if cap > top:
            alphas = np.concatenate([[cap], alphas])
        along = value(a[:, None] + h[:, None] * alphas[None, :])
        if not np.isfinite(along).any():
            return 0.0
        # the best point that holds, from its own rows' values: the step the ratios
        # allow can end a held row at the edge of its rounding room, where the product's
        # own rounding puts it beyond (a projected direction, 1e-14 off two held rows
        # between near-opposite multipliers of 1.5e15, was refused at the cap and its
        # level, 12.8 above its optimum, passed): the next shorter steps are tried
        best = float(np.sum((sw * v0) ** 2))
        if s0:      # where the rows above may end (fixed ones: within rounding of a_h)
            top_h = np.maximum(up_h, a_h) + np.where(at_u, rounding, 0.0)
            bottom_h = np.minimum(lo_h, a_h) - np.where(at_l, rounding, 0.0)
        for j in np.argsort(np.where(np.isfinite(along), along, np.inf))[:_DESCENT_TRIES]:
            if not along[j] < best:
                break
            ap = A[:s1] @ (x + float(alphas[j]) * d)
            if s0 and not np.where(fixed, np.abs(ap[:s0] - a_h) <= rounding,
                                   (ap[:s0] <= top_h) & (ap[:s0] >= bottom_h)).all():
                continue
            return max(best - float(value(ap[s0:, None])[0]), 0.0)
        return 0.0


#: rows beyond a bound by more than this (relative to the activity rule's size) and
#: within the activity tolerance are the band :func:`check_lexicographic` may read as fixed
_BAND_FLOOR = 1e-12


def _check_lexicographic(data: StackData, x: np.ndarray, tol: float, rcond: float,
                         minimum_norm: bool, metric: np.ndarray | None,
                         fix_band: bool) -> LexicographicReport:
    """:func:`check_lexicographic` with the band rows read as held (``fix_band=False``;
    the report's ``band_rows_fixed`` then counts the band rows found) or as fixed."""
    n = data.n
    xn = level_scale(x)
    Z = np.eye(n)                      # null space of the fixed rows of the levels above
    # the whole stack's rows at once, each level a slice: the activity rule is row by row
    layout = data.layout
    starts = layout.starts
    A_all, sw_all = data.A, data.sqrt_weight
    WA_all = sw_all[:, None] * A_all
    finite = bool(np.isfinite(x).all())
    act = _Activity.of(data, x, tol)
    lo_all, up_all, norms_all = act.lower, act.upper, act.norms
    if finite:
        a_all, terms_all, size_all = act.a, act.terms, act.size
        side_all, v_all = act.side, act.v
    # unit rows at one bound, oriented (multiplier ≥ 0): the first `n_signed` rows
    signed = np.empty((A_all.shape[0], n))
    fixed_all = np.zeros(A_all.shape[0], dtype=bool)   # rows read fixed, level by level
    n_signed = 0
    fixed_count = 0
    checks = []
    ambiguous: list[int] = []       # levels of an ambiguous rank decision (in order)
    level = 0

    def kkt(g: np.ndarray, B: np.ndarray | None, floor_scale: float
            ) -> tuple[float, list]:
        """``min_μ≥0 ‖D Vᵀ Zᵀ (g + Cᵀ μ)‖`` with ``B Z = U Σ Vᵀ``, ``D = 1/max(σ, floor)``,
        and the descent directions it stands for, each computed when called: the
        steepest in its metric, ``−Z V D ρ`` with ``ρ`` the minimising residual (feasible
        for the rows held above: ``c_jᵀ d = −‖·‖ m_jᵀ ρ ≤ 0`` at the NNLS optimum), and
        the gradient projected off the rows held above (``−Z P Zᵀ g``), which stays on
        them where the residual does not resolve a direction: at rounding level (an
        improving direction of gain 2e-8 between near-parallel held rows), or read at
        ``1/‖B‖`` (a level's row of norm 1e3 a multiple of a held row); none where
        nothing moves. (Off the rows of positive multipliers only, the second left
        the held rows of zero multiplier, and was blocked by them.) Where the rank rule
        reads coordinates as null, a third: the first's with the multipliers made to
        cancel there as in the floored ones."""
        d = Z.shape[1]
        if d == 0:
            return 0.0, []
        zg = Z.T @ g
        y = zg.copy()                  # (zeroed below where null; zg serves the descents)
        if B is None:
            D = None
        else:
            bn = float(np.linalg.norm(B))
            floor = CERTIFICATE_SIGMA_FLOOR * (bn or floor_scale)
            if floor == 0.0:
                return 0.0, []        # a level of zero rows: nothing x can change
            if B.shape[0]:
                _, s, vt = svd(B @ Z)
                sig = np.zeros(d)
                sig[:s.shape[0]] = s
            else:
                vt, sig = None, np.zeros(d)
            # the solvers' rank rule: rcond times the whole level's ‖√W A_i‖_F (its held
            # and inactive rows too), not the active rows' alone: a level whose violated
            # rows are 1e-13 of its satisfied ones cannot move them, and reading them as
            # movable would fail an exact answer
            threshold = rcond * max(bn, floor_scale)
            null = sig <= threshold
            if ambiguous_decision(sig, threshold) and level not in ambiguous:
                ambiguous.append(level)
            D = 1.0 / np.maximum(sig, floor)
            # the gradient lies in the row space of B: its part along directions that B Z
            # cannot move by the rank rule is round-off (amplified by 1/floor it would
            # fail exact answers); the multipliers must still cancel there. Those
            # directions do not move A_i x at all, so there is no task-space change to
            # map the residual to: it is read at the level's own gain 1/‖B‖ (with
            # 1/floor, the rounding of Σ μ_j c_j there, ~eps·κ·|μ|, was read as a
            # task-space change up to 1e6 times larger and failed exact answers)
            if bn > 0:
                D[null] = 1.0 / bn
            if vt is not None:
                y = vt @ y
            y[null] = 0.0
            y = D * y

        def back(rho: np.ndarray) -> np.ndarray:
            step = rho if D is None else D * rho
            return -(Z @ (vt.T @ step if D is not None and vt is not None else step))

        if not n_signed:
            return level_scale(y), [lambda: back(y)]
        M = Z.T @ signed[:n_signed].T
        held = M
        # a unit row at a bound in the span of the fixed rows (by the rank rule) has no
        # direction left in Z: made a unit column, its rounding cancelled any
        # gradient (a level 0 of a·x = 1 and a·x ≤ 1 passed a level 1 at 0.45 against
        # its optimum 0.20)
        keep = np.linalg.norm(M, axis=0) > rcond
        if D is not None:
            M = D[:, None] * (vt @ M if vt is not None else M)
        norms = np.linalg.norm(M, axis=0)
        keep &= norms > 0
        # unit columns: the same cone, and a well-scaled NNLS (D spans up to 1e6)
        unit = M[:, keep] / norms[keep]
        mu, res = nonnegative_least_squares(unit, -y)

        def projected() -> np.ndarray:
            face = held[:, keep]            # (the span rule's columns out)
            u = range_basis(face, 1e-15)[0]  # (dependent columns out)
            return -(Z @ (zg - u @ (u.T @ zg)))

        def pinned() -> np.ndarray:
            # the null coordinates weighted as the floored ones (1/floor), not 1/‖B‖: the
            # multipliers must cancel the gradient there alone, and a residual left there
            # stands for free moves that let the level's rows move elsewhere (a level at
            # 1.08e-2 over a box, its optimum 0 at 240 away, read at 5.5e-13: along this
            # direction a point 5.6e-4 lower)
            assert D is not None            # (made only where B gave the metric)
            weight = D.copy()
            weight[null] = 1.0 / floor
            w = weight * (vt @ zg if vt is not None else zg)
            w[null] = 0.0
            cols = weight[:, None] * (vt @ held if vt is not None else held)
            lengths = np.linalg.norm(cols, axis=0)
            use = keep & (lengths > 0)
            cols = cols[:, use] / lengths[use]
            rho = w + cols @ nonnegative_least_squares(cols, -w)[0]
            step = weight * rho
            return -(Z @ (vt.T @ step if vt is not None else step))

        return res, [lambda: back(y + unit @ mu), projected] + (
            [pinned] if D is not None and null.any() else [])

    def add_level(rows: _LevelRows, side: np.ndarray, norms: np.ndarray, start: int) -> None:
        nonlocal Z, fixed_count, n_signed
        fix = side == 2
        fixed_all[start:start + fix.shape[0]] = fix
        if fix.any():
            F = rows.sqrt_weight[fix, None] * rows.A[fix]
            tol_r = rcond * float(np.linalg.norm(F))
            if Z.shape[1] and tol_r > 0:
                _, s, vt = svd(F @ Z)
                r = int(np.count_nonzero(s > tol_r))
                Z = Z @ vt[r:].T
                if ambiguous_decision(s, tol_r) and level not in ambiguous:
                    ambiguous.append(level)
            fixed_count += int(fix.sum())
        one = ((side == 1) | (side == -1)) & (norms > 0)
        count = int(np.count_nonzero(one))
        if count:
            signed[n_signed:n_signed + count] = \
                (side[one][:, None] * rows.A[one]) / norms[one][:, None]
            n_signed += count

    band = 0
    for i, names in enumerate(layout.names):
        level = i
        s0, s1 = int(starts[i]), int(starts[i + 1])
        rows = _LevelRows(A_all[s0:s1], lo_all[s0:s1], up_all[s0:s1], sw_all[s0:s1])
        norms = norms_all[s0:s1]
        if finite:
            side, v = side_all[s0:s1], v_all[s0:s1]
            size = size_all[s0:s1]
        else:
            side, v = np.full(s1 - s0, 2), np.full(s1 - s0, np.nan)
        sw = rows.sqrt_weight
        WA = WA_all[s0:s1]
        g = WA.T @ (sw * v)
        an = float(np.linalg.norm(WA))
        if finite:
            target = a_all[s0:s1] - v
            # a row's target counts as its rounding reaches the gradient: in proportion
            # to the row's norm against the level's largest (zero rows with targets of
            # 1e15 beside rows of 0.24 made the scale 7.5e14 and passed a step 2e-5 off
            # along the small rows' directions, at a relative residual of 2.5e-17)
            reach = sw * norms
            top = float(reach.max()) if reach.size else 0.0
            share = reach / top if top > 0 else reach
            scale = level_scale(sw * (terms_all[s0:s1] + np.abs(target) * share)) + an
        else:
            scale = np.nan
        res, descents = kkt(g, WA[(side == 2) | (v != 0)], an) if finite else (np.nan, [])
        violation = level_scale(sw * v)
        rounding = _rounding(tol, scale, xn, an) if finite else np.nan
        ok = _level_passes(res, scale, violation, tol, rounding)
        gap = float(res) * float(res)
        if ok and res > 0:
            # the KKT residual reads directions of small gain at 1/‖B‖ or 1/floor, where
            # a step may still lower the value a lot (two of a level's rows multiples of
            # a fixed row, 1e3-1e4 times its third: 2.4e2 above its optimum of 2.49e7,
            # read at 9e-9 and a value gap of 3.9e-5): walk the direction, and reject x
            # when a point that keeps the rows above lowers the value
            # — beyond the tolerance and the rounding of both points' values (x' within
            # ‖x‖ of x: its terms at most twice x's)
            limit = tol * max(1.0, violation * violation) + 8 * rounding * (
                2 * violation + 2 * rounding)
            # (the value cannot drop by more than itself)
            for direction in descents if violation * violation > limit else ():
                drop = _descent_drop(A_all, s0, s1, fixed_all[:s0], act, sw_all, x, xn,
                                     direction(), limit)
                if drop > limit:
                    ok, gap = False, max(gap, drop)
                    break
        slack = None
        if finite and ok:
            # rows left violated by little (beyond rounding, within _NEARLY_FEASIBLE of
            # their size) may be a solver's slack on rows the level's optimum satisfies.
            # If a point keeps the rows above and the level's other violations and meets
            # these rows, the level's value can drop by what they add: x is not optimal
            # when that exceeds the tolerance. When they are all the level's violation
            # (zero rows aside), that point makes the level's optimum zero, so its
            # (unique) violation vector is zero on them and the lower levels may move
            # them inward: held, not fixed. Read as fixed they had pinned the lower levels
            # far from their optimum (cascaded_qp[highs]: level 1 left 3e-8 violated,
            # level 2 worse by 0.7, passed on the KKT test alone)
            nearly = (np.abs(v) > _BAND_FLOOR * size) & (np.abs(v) <= _NEARLY_FEASIBLE * size)
            alone = not ((np.abs(v) > _BAND_FLOOR * size) & ~nearly & (norms > 0)).any()
            # an equality row's small residual beside large ones is the least-squares
            # spread of a level that cannot meet its rows, which the KKT test above
            # judges with the rank rule; the LP, without it, met such rows along
            # directions of gain far below the level's and would reject right answers
            small = nearly & ((rows.lower != rows.upper) | alone)
            extra = float(np.linalg.norm(sw[small] * v[small]))
            # the LP only where its answer changes the check: the level's value could fail,
            # or rows beyond the activity tolerance would be fixed (equality rows stay
            # fixed; rows inside it are read as held already)
            reread = alone and (small & (side == 2) & (rows.lower != rows.upper)).any()
            if (extra > tol * scale or reread) and _feasible(A_all, act, fixed_all[:s0], s1,
                                                             small):
                if extra > tol * scale:
                    res, ok = extra, False
                if alone:
                    slack = small & (rows.lower != rows.upper)   # equality rows stay fixed
                    side = side.copy()
                    side[slack] = np.where(v[slack] > 0, 1, -1)
        checks.append(LevelCheck(i, names, violation, float(res), scale, ok,
                                 fixed_count, n_signed, gap))
        in_band = None
        if finite and violation > tol * scale:
            # only a level left violated beyond the tolerance can hold a row at a small
            # optimal violation; on a feasible level such a row's violation is a
            # solver's slack and the lower levels may move it (cascaded_qp[daqp] and
            # daqp_hierarchical answers, 1e-10 beyond level 0's bounds and worse at a
            # lower level, passed when it was read as fixed there)
            in_band = (np.abs(side) == 1) & (np.abs(v) > _BAND_FLOOR * size)
            if slack is not None:       # shown satisfiable by the level's optimum
                in_band &= ~slack
            band += int(in_band.sum())
        if fix_band and in_band is not None and in_band.any():
            side = side.copy()
            side[in_band] = 2
        add_level(rows, side, norms, s0)
    final = None
    if minimum_norm:
        W = np.eye(n) if metric is None else np.asarray(metric, dtype=np.float64)
        scale = (1.0 if metric is None else float(np.linalg.norm(W, 2))) * max(1.0, xn)
        res = kkt(W @ x, None, 1.0)[0] if finite else np.nan
        final = LevelCheck(layout.k, ("minimum-norm",), xn, float(res), scale,
                           bool(np.isfinite(res) and res <= tol * scale),
                           fixed_count, n_signed)
    ok = all(c.ok for c in checks) and (final is None or final.ok)
    return LexicographicReport(ok, tol, tuple(checks), final, band,
                               ambiguous_levels=tuple(sorted(ambiguous)))
