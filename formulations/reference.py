"""Exact minimum-norm lexicographic least squares by nested SVD null spaces.

The ground truth of the tests. For levels ``i = 1..k`` (highest first)::

    M_i = A_i Z_i,                y_i = M_i⁺ (b_i − A_i x),     x ← x + Z_i y_i,
    Z_{i+1} = Z_i · null(M_i)

with ``Z_1 = I`` and every pseudo-inverse and null space from an SVD in float64
(rank threshold ``rcond · ‖A_i‖_F``, :mod:`hierarchy.linalg`; a decision within
``AMBIGUITY`` of it makes the status ``approximate``). Each level is solved in the least-squares
sense, so rank-deficient and infeasible levels are handled; the step ``y_i`` gets
``REFINEMENT_STEPS`` steps of iterative refinement from the level's residual, formed
row by row (:func:`formulations._numerics.refinement`): the SVD reads rows far smaller
than the level's norm with errors of ``ε ‖M_i‖``, which their large targets would carry
into the step. Because every ``y_i``
lies in the row space of ``M_i``, the result is the minimum-norm point of the
lexicographic optimal set; ``metric=W`` instead minimises ``xᵀ W x`` over that set.

``level_damping=(μ_1², …, μ_k²)`` solves each level by damped least squares instead,
``y_i = argmin ‖M_i y − c_i‖² + μ_i² ‖y‖²`` (``σ ↦ σ / (σ² + μ_i²)`` on the kept
singular values): the damped hierarchy that ``extended_jacobian`` (selective damping,
``step_bound``) and ``cascaded_qp`` (``level_damping``) also solve, here as its oracle.

Two kernels (option ``kernel``): ``"cpp"`` (the default; :class:`Prepared`) runs the
recursion in the C++ core over one workspace (``prioik._core.ReferenceSolver``). Its SVD
of ``M_i`` is a Householder LQ, ``M_i = [L 0] Q``, then a one-sided (Hestenes) Jacobi SVD
of ``L``'s columns, ``L W = U Σ``: the singular values of ``M_i`` to its accuracy, so the
rank rule (``σ > rcond · ‖A_i‖_F``) and the ambiguity rule are the readable path's, on
singular values; ``V = Qᵀ [W; 0]``, and the null space is spanned by the columns of
``Qᵀ`` past ``L``'s and the right singular vectors with ``σ`` at or below the threshold.
It counts its floating-point operations (:attr:`Detail.flops`; :attr:`Detail.jacobi_sweeps`
and :attr:`Detail.jacobi_rotations` over the levels). ``"numpy"`` is
:func:`solve_readable`, ``np.linalg.svd`` (LAPACK) as written above, the oracle the tests
hold the compiled kernel to.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from prioik.hierarchy import (
    AMBIGUITY,
    DEFAULT_RCOND,
    StackData,
    StackLayout,
    TaskStack,
    ambiguity_reason,
    ambiguous_decision,
    level_scale,
    rank_threshold,
)

from . import contract
from ._compiled import (
    _core,
    resolve_kernel,
    solve_compiled,
    solve_each,
    solve_readable_equilibrated,
    solve_rescaled,
)
from ._numerics import REFINEMENT_STEPS, refinement
from .base import (
    Capabilities,
    Diagnostics,
    FormulationError,
    Outcome,
    Status,
)
from .options import (
    Option,
    per_level_nonnegative,
    positive_semidefinite,
    rcond_option,
    validate_options,
)


@dataclass(frozen=True, slots=True)
class Detail:
    """``reference``'s own record (``sol.diagnostics.detail``).

    Attributes:
        null_space_dim: Dimension of the null space left below the last level.
        kernel: ``"cpp"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` on the numpy path).
        jacobi_sweeps: The compiled kernel's one-sided Jacobi sweeps over the levels
            (``None`` on the numpy path).
        jacobi_rotations: Its Jacobi rotations over the levels (``None`` on the numpy
            path).
    """

    null_space_dim: int
    kernel: str = "numpy"
    flops: int | None = None
    jacobi_sweeps: int | None = None
    jacobi_rotations: int | None = None


NAME = "reference"
DESCRIPTION = "exact lexicographic least squares, nested SVD null spaces (ground truth)"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "rcond": rcond_option(),
    "metric": Option(None, "matrix", "SPD n×n W: the final tie-break minimises xᵀWx instead "
                     "of xᵀx", optional=True, check=positive_semidefinite),
    "level_damping": Option(None, "any", "k values μ_i² ≥ 0: level i by damped least squares "
                            "(σ ↦ σ/(σ² + μ_i²))", optional=True,
                            check=per_level_nonnegative),
    "kernel": Option("auto", "str", "'cpp': the compiled C++ core (prioik._core, LQ then "
                     "Jacobi SVD); 'numpy': the readable np.linalg.svd recursion; 'auto': "
                     "cpp where built", choices=("auto", "cpp", "numpy")),
}

#: the message of a metric the last null space cannot take (both kernels)
METRIC_NOT_DEFINITE = "metric is not positive definite on the remaining null space"


def level_damping_values(levels: int, level_damping) -> np.ndarray:
    """``level_damping`` as ``levels`` finite values ``≥ 0`` (zeros for ``None``).

    Raises:
        FormulationError: wrong length, a negative or non-finite value.
    """
    k = int(levels)
    if level_damping is None:
        return np.zeros(k)
    mu2 = np.array(level_damping, dtype=np.float64).ravel()
    if mu2.shape != (k,) or not np.all(np.isfinite(mu2)) or np.any(mu2 < 0):
        raise FormulationError(f"level_damping must hold {k} finite values ≥ 0 (one μ² "
                               f"per level), got {mu2.tolist()}")
    return mu2


def solve(stack: TaskStack, **options) -> Outcome:
    """The nested-SVD reference: :class:`Prepared` for the stack's layout, then its
    :meth:`Prepared.solve` (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


def solve_readable(stack: TaskStack, *, rcond: float, metric, level_damping) -> Outcome:
    """Lexicographic minimum-norm (or minimum ``xᵀWx``) solution of an equality stack in
    numpy (``kernel="numpy"``), the readable oracle of the compiled kernel.

    Returns:
        ``Outcome`` with ``diagnostics.ranks`` (the kept rank of each ``M_i``) and
        :attr:`Detail.null_space_dim` (the columns of the last ``Z``).

    Raises:
        numpy.linalg.LinAlgError: ``metric`` is not positive definite on the last null
            space (the prepared solver reports it as status ``"failed"``).
    """
    mu2 = level_damping_values(len(stack), level_damping)
    n = stack.n
    x = np.zeros(n)
    Z = np.eye(n)
    ranks, ambiguous = [], []
    for i, level in enumerate(stack.levels):
        A, b = level.A, level.b
        if Z.shape[1] == 0:
            ranks.append(0)
            continue
        M = A @ Z
        u, s, vt = np.linalg.svd(M, full_matrices=True)
        tol = rank_threshold(A, rcond)
        r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
        if ambiguous_decision(s, tol):
            ambiguous.append(i)
        if r:
            c = b - A @ x
            y = vt[:r].T @ ((u[:, :r].T @ c) * s[:r] / (s[:r] ** 2 + mu2[i]))
            for _ in range(0 if mu2[i] else REFINEMENT_STEPS):   # _numerics.refinement
                y = y + vt[:r].T @ ((vt[:r] @ (M.T @ (c - M @ y))) / s[:r] ** 2)
            x = x + Z @ y
        Z = Z @ vt[r:].T
        ranks.append(r)
    if metric is not None and Z.shape[1]:
        W = np.asarray(metric)
        G = Z.T @ W @ Z
        try:
            L = np.linalg.cholesky(G)
        except np.linalg.LinAlgError:
            raise np.linalg.LinAlgError(METRIC_NOT_DEFINITE) from None
        z = np.linalg.solve(L.T, np.linalg.solve(L, -(Z.T @ (W @ x))))
        x = x + Z @ z
    return _outcome(x, ranks, ambiguous, bool(mu2.any()), Detail(int(Z.shape[1]), "numpy"))


def _outcome(x, ranks, ambiguous, damped: bool, detail: Detail, residuals=None) -> Outcome:
    """The answer with its diagnostics (``approximate`` when damped or ambiguous)."""
    diagnostics = Diagnostics(ranks=np.asarray(ranks), ambiguous_levels=list(ambiguous),
                              detail=detail)
    if ambiguous:
        diagnostics.reason = ambiguity_reason(ambiguous)
    elif damped:
        diagnostics.reason = "damped levels (level_damping): a damped least-squares answer"
    return Outcome(x, Status.APPROXIMATE if damped or ambiguous else Status.OPTIMAL,
                   diagnostics, residuals)


def solve_batch(stacks, *, rcond: float = DEFAULT_RCOND, metric=None, level_damping=None
                ) -> tuple[np.ndarray, list[str]]:
    """:func:`solve_readable` for ``B`` stacks of one shape, with stacked linear algebra.

    The same nested-SVD recursion as :func:`solve_readable`, run on ``(G, m_i, d)`` arrays by
    ``np.linalg.svd``. Stacks whose null spaces have the same dimension ``d`` form a
    group; each level's rank ``r`` (``σ > rcond · ‖A_i‖_F``, per stack) enters the
    update ``y = V_r Σ_r⁻¹ U_rᵀ c`` through a mask over the singular values, and the
    group is then split by ``d − r`` (stacks that lose the same number of directions
    keep sharing arrays). With ``metric=W`` the final tie-break solves
    ``(ZᵀWZ) z = −ZᵀW x`` per group by a batched Cholesky factorization.

    Args:
        stacks: Equality :class:`TaskStack` objects of one shape (checked by
            :func:`formulations.solve_batch`).
        rcond: Relative rank threshold (as :func:`solve_readable`).
        metric: SPD ``n × n`` ``W`` shared by every stack, or ``None``.
        level_damping: ``k`` values ``μ_i²`` shared by every stack, or ``None``.

    Returns:
        ``(X, statuses)``: ``X`` is ``B × n`` (row ``b`` is :func:`solve_readable` of
        stack ``b``); a status is ``"optimal"``, ``"approximate"`` (damped, or a rank
        decision ambiguous as in :func:`solve_readable`), or ``"failed"`` (row of NaN) where
        ``ZᵀWZ`` is not positive definite.
    """
    stacks = list(stacks)
    B, n = len(stacks), stacks[0].n
    mu2 = level_damping_values(len(stacks[0]), level_damping)
    X = np.zeros((B, n))
    statuses = ["approximate" if mu2.any() else "optimal"] * B
    ambiguous: list[list[int]] = [[] for _ in range(B)]
    # groups: null-space dimension d -> (stack indices, Z of shape (G, n, d))
    groups: dict[int, tuple[np.ndarray, np.ndarray]] = {
        n: (np.arange(B), np.broadcast_to(np.eye(n), (B, n, n)))}
    for li in range(len(stacks[0].levels)):
        A_all = np.stack([s.levels[li].A for s in stacks])       # (B, m, n)
        b_all = np.stack([s.levels[li].b for s in stacks])       # (B, m)
        tol_all = rcond * np.array([level_scale(a) for a in A_all])   # (B,)
        new_groups: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {}
        for d, (idx, Z) in groups.items():
            if d == 0:
                new_groups.setdefault(0, []).append((idx, Z))
                continue
            A, b, tol = A_all[idx], b_all[idx], tol_all[idx]
            M = A @ Z                                             # (G, m, d)
            u, s, vt = np.linalg.svd(M, full_matrices=True)      # s: (G, p), p = min(m, d)
            p = s.shape[1]
            keep = (s > tol[:, None]) & (tol[:, None] > 0)        # σ_j counts, per stack
            r = keep.sum(axis=1)                                  # rank per stack
            near = ((s > tol[:, None] / AMBIGUITY) & (s <= tol[:, None] * AMBIGUITY)
                    & (tol[:, None] > 0)).any(axis=1)             # ambiguous decision
            for gi in idx[near]:
                ambiguous[gi].append(li)
            c = b - np.einsum("gmn,gn->gm", A, X[idx])            # c = b − A x
            w = np.einsum("gmp,gm->gp", u[:, :, :p], c)           # U_pᵀ c
            w = np.where(keep, w * s / np.where(keep, s * s + mu2[li], 1.0), 0.0)
            #   Σ_r⁻¹ U_rᵀ c (σ/(σ² + μ²) when damped), masked
            y = np.einsum("gpd,gp->gd", vt[:, :p, :], w)          # V_r (…)
            for _ in range(0 if mu2[li] else REFINEMENT_STEPS):  # _numerics.refinement
                y = y + refinement(M, c[:, :, None], y[:, :, None], vt[:, :p, :], keep,
                                   s)[:, :, 0]
            X[idx] += np.einsum("gnd,gd->gn", Z, y)
            for rank in np.unique(r):
                sel = np.flatnonzero(r == rank)
                Znew = Z[sel] @ np.swapaxes(vt[sel, rank:, :], 1, 2)   # Z · null(M)
                new_groups.setdefault(d - int(rank), []).append((idx[sel], Znew))
        groups = {d: (np.concatenate([i for i, _ in parts]),
                      np.concatenate([z for _, z in parts]))
                  for d, parts in new_groups.items()}
    statuses = ["approximate" if amb else st for st, amb in zip(statuses, ambiguous, strict=False)]
    if metric is not None:
        W = np.asarray(metric, dtype=np.float64)
        for d, (idx, Z) in groups.items():
            if d == 0:
                continue
            G = np.swapaxes(Z, 1, 2) @ W @ Z                       # (G, d, d)
            rhs = -np.einsum("gnd,gn->gd", Z, X[idx] @ W)          # −Zᵀ W x
            try:
                L = np.linalg.cholesky(G)
                ok = np.ones(len(idx), dtype=bool)
            except np.linalg.LinAlgError:    # some stack's ZᵀWZ is not SPD: find which
                L = np.zeros_like(G)
                ok = np.zeros(len(idx), dtype=bool)
                for j in range(len(idx)):
                    try:
                        L[j] = np.linalg.cholesky(G[j])
                        ok[j] = True
                    except np.linalg.LinAlgError:
                        pass
            if ok.any():
                Lk = L[ok]
                v = np.linalg.solve(Lk, rhs[ok][..., None])
                z = np.linalg.solve(np.swapaxes(Lk, 1, 2), v)[..., 0]
                X[idx[ok]] += np.einsum("gnd,gd->gn", Z[ok], z)
            for gi in idx[~ok]:
                X[gi] = np.nan
                statuses[gi] = "failed"
    return X, statuses


class Prepared(contract.Prepared):
    """The nested-SVD reference prepared for one layout: options checked, and on the
    compiled kernel (``kernel="cpp"``) the C++ solver with every workspace allocated once
    (``prioik._core.ReferenceSolver``, the module docstring's LQ and Jacobi SVD; the
    rank rule on singular values, :attr:`Detail.flops` counted in the kernel).
    ``kernel="numpy"`` is :func:`solve_readable` (and :func:`solve_batch`).

    Args:
        layout: The stack layout (equality tasks only; the registry checked it).
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).

    Raises:
        FormulationError: ``level_damping`` does not hold one value ``≥ 0`` per level.
    """

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.layout = layout
        self.kernel = resolve_kernel(settings.kernel)
        self.rcond = float(settings.rcond)
        self.metric = settings.metric
        self.level_damping = settings.level_damping
        self.mu2 = level_damping_values(layout.k, settings.level_damping)
        self._cpp = self.kernel == "cpp"
        if self._cpp:
            metric = (None if self.metric is None
                      else np.ascontiguousarray(self.metric, dtype=np.float64))
            self._core = _core.ReferenceSolver([int(s) for s in layout.starts], layout.n,
                                               rcond=self.rcond,
                                               level_damping=self.mu2.tolist(),
                                               metric=metric)

    def _readable(self, stack: TaskStack) -> Outcome:
        return solve_readable(stack, rcond=self.rcond, metric=self.metric,
                              level_damping=self.level_damping)

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout.

        Raises:
            TaskStackError: a value is not finite (naming the task, level and row).
            numpy.linalg.LinAlgError: ``metric`` is not positive definite on the last
                null space (the prepared solver's status ``"failed"``).
        """
        if not self._cpp:
            return solve_readable_equilibrated(self._readable, data)
        res = solve_compiled(self._core, data)
        if not res.solved:
            return solve_rescaled(self.solve, data)
        if not res.metric_positive_definite:
            raise np.linalg.LinAlgError(METRIC_NOT_DEFINITE)
        detail = Detail(int(res.null_space_dim), "cpp", res.flops, res.sweeps, res.rotations)
        return _outcome(res.x, res.ranks.copy(), np.flatnonzero(res.ambiguous).tolist(),
                        bool(self.mu2.any()), detail, res.residuals)

    def solve_batch(self, datas: list[StackData]) -> contract.BatchOutcome:
        """Many stacks of the layout: ``(X, statuses)`` (:func:`solve_batch`, the stacked
        SVDs, on the numpy kernel; one compiled solve after the other on the cpp kernel)."""
        if not self._cpp:
            stacks = [d.as_stack().equilibrated()[0] for d in datas]
            X, statuses = solve_batch(stacks, rcond=self.rcond, metric=self.metric,
                                      level_damping=self.level_damping)
            return X, statuses, None
        return solve_each(self.solve, datas)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
