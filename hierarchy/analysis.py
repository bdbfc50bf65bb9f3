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

from dataclasses import dataclass, field

import numpy as np

from .layout import level_residuals
from .errors import UnsupportedTaskError
from .linalg import DEFAULT_RCOND, matrix_rank, range_basis
from .stack import TaskStack


def _require_equality(stack: TaskStack, what: str) -> None:
    for i, level in enumerate(stack.levels):
        for t in level:
            if not t.is_equality:
                raise UnsupportedTaskError("it is defined for equality tasks only",
                                           formulation=what, task=t.name, level=i)


def nested_null_spaces(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[np.ndarray]:
    """Bases ``Z_1 = I, Z_2, …, Z_{k+1}`` of the null spaces of ``J_0^A … J_k^A``.

    ``Z_{i+1} = Z_i · null(A_i Z_i)``, each rank decision on the scale of ``‖A_i‖_F``.
    Returned as ``n × d_i`` matrices with orthonormal columns (index ``i`` is the
    basis *before* level ``i``; the last is the null space of the whole stack).
    """
    Z = np.eye(stack.n)
    out = [Z]
    for level in stack.levels:
        A = level.A
        if A.shape[0] and Z.shape[1]:
            M = A @ Z
            _, s, vt = np.linalg.svd(M, full_matrices=True)
            tol = rcond * float(np.linalg.norm(A))
            r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
            Z = Z @ vt[r:].T
        out.append(Z)
    return out


def rank_profile(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[int]:
    """``r_i = ρ(J_i^A) − ρ(J_{i-1}^A)`` for each level (eq. 12)."""
    Zs = nested_null_spaces(stack, rcond)
    return [Zs[i].shape[1] - Zs[i + 1].shape[1] for i in range(len(stack))]


def conflicting_levels(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[bool]:
    """For each level, whether it conflicts with the levels above (eq. 35)."""
    prof = rank_profile(stack, rcond)
    return [matrix_rank(level.A, rcond) > r for level, r in zip(stack.levels, prof)]


def singularity_distance(stack: TaskStack, rcond: float = DEFAULT_RCOND) -> list[float]:
    """Distance of each level to an algorithmic singularity.

    The smallest singular value of ``A_i Z_i`` above the rank threshold: the
    null-space projection methods divide by it (they grow like ``1/σ``). For the
    first level it is the smallest non-zero singular value of ``A_1`` (a kinematic
    singularity). ``0.0`` when the level has no feasible direction left.
    """
    Zs = nested_null_spaces(stack, rcond)
    out = []
    for level, Z in zip(stack.levels, Zs):
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
    for i, (level, Z) in enumerate(zip(stack.levels, Zs)):
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
    """Optimality of one level.

    Attributes:
        level: Level index.
        tasks: Names of the level's tasks.
        residual: ``‖A_i x − b_i‖`` (weighted).
        projected_gradient: ``‖Z_iᵀ A_iᵀ (A_i x − b_i)‖``.
        scale: ``‖A_i‖_F (‖A_i‖_F ‖x‖ + ‖b_i‖)``, what the tolerance is relative to.
        ok: ``projected_gradient ≤ tol · max(scale, 1e-300)``.
    """

    level: int
    tasks: tuple[str, ...]
    residual: float
    projected_gradient: float
    scale: float
    ok: bool


@dataclass(frozen=True)
class LexicographicReport:
    """Result of :func:`check_lexicographic`.

    Attributes:
        ok: Every level passes.
        tol: Relative tolerance used.
        levels: One :class:`LevelCheck` per level.
    """

    ok: bool
    tol: float
    levels: tuple[LevelCheck, ...] = field(default_factory=tuple)

    @property
    def first_failure(self) -> LevelCheck | None:
        """The highest-priority level that fails, if any."""
        return next((c for c in self.levels if not c.ok), None)

    def __str__(self) -> str:
        rows = [f"lexicographic check: {'ok' if self.ok else 'FAILED'} (tol {self.tol:g})"]
        for c in self.levels:
            rel = c.projected_gradient / max(c.scale, 1e-300)
            rows.append(f"  level {c.level} {','.join(c.tasks)}: residual {c.residual:.3e}, "
                        f"projected gradient {c.projected_gradient:.3e} "
                        f"(relative {rel:.1e}) {'ok' if c.ok else 'FAIL'}")
        return "\n".join(rows)


def check_lexicographic(stack: TaskStack, x: np.ndarray, tol: float = 1e-8,
                        rcond: float = DEFAULT_RCOND) -> LexicographicReport:
    """Whether ``x`` is a lexicographic optimum of an equality stack.

    ``x`` is optimal iff at every level the gradient of the level's least-squares
    objective, projected on the null space of the levels above, vanishes:
    ``Z_iᵀ A_iᵀ (A_i x − b_i) = 0``. Each level is judged relative to its own scale
    (see :class:`LevelCheck`).

    Raises:
        UnsupportedTaskError: for a stack with inequality tasks.
    """
    _require_equality(stack, "check_lexicographic")
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (stack.n,):
        raise ValueError(f"x has shape {x.shape}, the stack has n = {stack.n}")
    Zs = nested_null_spaces(stack, rcond)
    xn = float(np.linalg.norm(x))
    checks = []
    for i, (level, Z) in enumerate(zip(stack.levels, Zs)):
        A, b = level.A, level.b
        r = A @ x - b
        g = Z.T @ (A.T @ r)
        an = float(np.linalg.norm(A))
        scale = an * (an * xn + float(np.linalg.norm(b)))
        gn = float(np.linalg.norm(g))
        ok = bool(np.isfinite(gn) and gn <= tol * max(scale, 1e-300))
        checks.append(LevelCheck(i, level.names, float(np.linalg.norm(r)), gn, scale, ok))
    return LexicographicReport(all(c.ok for c in checks), tol, tuple(checks))
