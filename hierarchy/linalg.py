"""Small dense linear-algebra helpers shared by the analysis and the formulations.

Rank decisions use one rule everywhere (every formulation, ``solve`` and
``solve_batch`` alike, and :func:`hierarchy.check_lexicographic`): a singular value
``σ`` of a level's projected matrix ``A_i Z_i`` counts when
``σ > rcond · ‖A_i‖_F`` with ``‖A_i‖_F`` the Frobenius norm of the level's own
(weighted) rows (:func:`level_scale`), so that a row "in the row space of a higher
level" is judged on the scale of its own level, not of the whole stack. A zero
level (``‖A_i‖_F = 0``) has rank 0. Paths that factor by pivoted QR apply the same
threshold to their pivots' norms (the rank-revealing estimates of ``σ``).

A decision is *ambiguous* when a singular value (or pivot norm) lies within a factor
:data:`AMBIGUITY` of the threshold, ``rcond·‖A_i‖_F / AMBIGUITY < σ ≤ AMBIGUITY ·
rcond·‖A_i‖_F``: rounding of the rows, or the difference between a pivot norm and
``σ``, may then flip it, and with it the answer by ``O(1)``. A formulation that
meets an ambiguous decision does not say ``optimal``: its status is
``approximate`` with ``diagnostics.reason`` naming the levels
(:func:`ambiguous_decision`).

A clear decision within a factor :data:`NEAR_AMBIGUITY` of the band is *near-ambiguous*
(:func:`decision_margin`): the exact solvers then certify their answer
(:func:`hierarchy.check_lexicographic`) before they say ``optimal``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .stack import TaskStack

#: Default relative rank threshold (see module docstring).
DEFAULT_RCOND = 1e-9

#: A singular value within this factor of the rank threshold makes the decision
#: ambiguous (see module docstring): three decades either side.
AMBIGUITY = 1e3

#: A clear decision whose margin (:func:`decision_margin`) is at most this factor times
#: :data:`AMBIGUITY` is near-ambiguous: the null space it leaves, accurate to about ε
#: over the margin's pivot, is turned by rows of a lower level whose scale may dwarf what
#: they keep in it, into an error the certificate can reject. An exact solver certifies
#: such an answer first.
NEAR_AMBIGUITY = 10.0

_EPS = float(np.finfo(np.float64).eps)


def level_scale(A: np.ndarray) -> float:
    """``‖A‖_F`` (``‖x‖₂`` of a vector), without the overflow or underflow of the
    squares (entries beyond 1e154 or below 1e-154 would give ``inf``, with a warning, or
    0 from ``np.linalg.norm``; an answer ``x = 1e200``, the exact solution of
    ``1e-200 x = 1``, is valid). ``inf`` or NaN when an entry is."""
    A = np.asarray(A)
    if A.size == 0:
        return 0.0
    with np.errstate(over="ignore"):    # the squares' overflow: handled below
        norm = float(np.linalg.norm(A))
    if 1e-150 < norm < 1e150:
        return norm
    peak = float(np.max(np.abs(A)))
    if peak == 0.0 or not np.isfinite(peak):
        return peak
    return peak * float(np.linalg.norm(A / peak))


def rank_threshold(A: np.ndarray, rcond: float = DEFAULT_RCOND) -> float:
    """Absolute threshold below which a singular value of ``A``'s level is zero."""
    scale = level_scale(A)
    return rcond * scale if scale > 0 else 0.0


def ambiguous_decision(values: np.ndarray, tol: float) -> bool:
    """Whether singular values (or pivot norms) ``values`` hold one within
    :data:`AMBIGUITY` of the threshold ``tol`` (see module docstring)."""
    if tol <= 0 or values.size == 0:
        return False
    return bool(np.any((values > tol / AMBIGUITY) & (values <= tol * AMBIGUITY)))


def decision_margin(values: np.ndarray, tol: float) -> float:
    """How far the rank decision of pivots or singular values ``values`` at threshold
    ``tol`` is from flipping: the smallest of ``σ / tol`` over the values kept and
    ``tol / σ`` over the non-zero values dropped (``inf`` when there are none, or
    ``tol ≤ 0``). Within :data:`AMBIGUITY` the decision is ambiguous
    (:func:`ambiguous_decision`), within ``NEAR_AMBIGUITY · AMBIGUITY`` near-ambiguous;
    the compiled kernels compute the same margin per level."""
    values = np.abs(np.asarray(values, dtype=np.float64))
    if tol <= 0 or values.size == 0:
        return float("inf")
    kept, dropped = values[values > tol], values[(values <= tol) & (values > 0)]
    margin = float(kept.min()) / tol if kept.size else float("inf")
    if dropped.size:
        margin = min(margin, tol / float(dropped.max()))
    return margin


def near_ambiguity_reason(levels: list[int]) -> str:
    """Why levels whose rank decision is near-ambiguous (:data:`NEAR_AMBIGUITY`) had
    their answer certified."""
    return (f"rank decision near-ambiguous at level{'s' if len(levels) > 1 else ''} "
            f"{', '.join(map(str, levels))}: a pivot within "
            f"{NEAR_AMBIGUITY * AMBIGUITY:g}x of the threshold rcond·‖A_i‖_F")


def ambiguity_reason(levels: list[int]) -> str:
    """The ``diagnostics.reason`` of an ``approximate`` status due to ambiguous levels."""
    return (f"rank decision ambiguous at level{'s' if len(levels) > 1 else ''} "
            f"{', '.join(map(str, levels))}: a singular value lies within "
            f"{AMBIGUITY:g}x of the threshold rcond·‖A_i‖_F")


def matrix_rank(A: np.ndarray, rcond: float = DEFAULT_RCOND) -> int:
    """Numerical rank of ``A`` with the module's threshold rule."""
    if A.size == 0:
        return 0
    s = np.linalg.svd(A, compute_uv=False)
    tol = rank_threshold(A, rcond)
    return int(np.count_nonzero(s > tol)) if tol > 0 else 0


def null_space_basis(A: np.ndarray, rcond: float = DEFAULT_RCOND,
                     scale: float | None = None) -> np.ndarray:
    """Orthonormal basis ``Z`` (``n × d``) of the null space of ``A`` (``A Z = 0``).

    The paper's ``Z_i`` (eq. 13) is ``Z.T`` of this basis for ``A = J_{i-1}^A``.

    Args:
        A: ``m × n`` matrix (``m`` may be 0).
        rcond: Relative rank threshold.
        scale: Scale the threshold multiplies (default ``‖A‖_F``).
    """
    n = A.shape[1]
    if A.shape[0] == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(A, full_matrices=True)
    tol = rcond * (float(np.linalg.norm(A)) if scale is None else scale)
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    return vt[r:].T.copy()


def range_basis(A: np.ndarray, rcond: float = DEFAULT_RCOND,
                scale: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal bases of the range of ``A`` and of its complement, with the kept σ.

    Returns:
        ``(U_r, U_0, s_r)``: ``U_r`` (``m × r``) spans ``range(A)``, ``U_0`` (``m × (m−r)``)
        its orthogonal complement, ``s_r`` the ``r`` singular values kept.
    """
    m = A.shape[0]
    if A.size == 0:
        return np.zeros((m, 0)), np.eye(m), np.zeros(0)
    u, s, _ = svd(A, full_matrices=True)
    tol = rcond * (float(np.linalg.norm(A)) if scale is None else scale)
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    return u[:, :r], u[:, r:], s[:r]


#: Default relative tolerance of the lexicographic certificate (KKT residual and
#: activity of inequality rows, see :func:`row_activity`).
DEFAULT_CERTIFICATE_TOL = 1e-8

#: The coordinates of an answer computed through orthogonal transformations (nested QR,
#: the reflectors mapping rotated coordinates back to ``x``) are known to about this
#: times ``‖x‖`` (16 eps: each reflector rounds every coordinate to eps ‖x‖).
X_PRECISION = 16 * float(np.finfo(np.float64).eps)

#: ``‖x‖`` above which :data:`X_PRECISION` may limit a level at
#: :data:`DEFAULT_CERTIFICATE_TOL` (``X_PRECISION ‖x‖ ‖√W A_i‖_F`` can only exceed the
#: tolerance times the level's scale, itself at least ``‖√W A_i‖_F``, beyond it): the
#: compiled solvers check :func:`~prioik.hierarchy.precision_limited_levels` only then.
PRECISION_LIMIT_NORM = DEFAULT_CERTIFICATE_TOL / X_PRECISION


#: Singular values of a level's active rows below this fraction of their Frobenius norm
#: are raised to it when the certificate maps a KKT residual back to task space
#: (bounds the amplification of rounding errors to ``eps / 1e-6 ≈ 2e-10``).
CERTIFICATE_SIGMA_FLOOR = 1e-6


def row_activity(A: np.ndarray, lower: np.ndarray, upper: np.ndarray, x: np.ndarray,
                 tol: float = DEFAULT_CERTIFICATE_TOL) -> tuple[np.ndarray, np.ndarray]:
    """Which rows of ``lower ≤ A x ≤ upper`` are at a bound or violated at ``x``.

    The one activity rule of the library: row ``r`` is *at* its upper bound when
    ``|a_r x − u_r| ≤ tol · (|a_r| |x| + |u_r| + ‖a_r‖)`` (``|a_r| |x| = Σ_j |a_rj x_j|``,
    the size of the terms that make ``a_r x``; the last term makes it absolute for
    ``|x| ≲ 1``), likewise for the lower bound; it is *violated* when it lies beyond a
    bound by more than that.

    Returns:
        ``(side, v)``: ``side[r]`` is ``0`` inactive, ``+1`` at the upper bound only,
        ``−1`` at the lower bound only, ``2`` fixed (equality row ``l = u``, violated
        row, or at both bounds); ``v = A x − clip(A x, lower, upper)`` the signed
        violation.
    """
    a = A @ x
    size = np.abs(A) @ np.abs(x) + np.linalg.norm(A, axis=1)
    return row_activity_from_values(a, lower, upper, size, tol)


def row_activity_from_values(a: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                             size: np.ndarray, tol: float = DEFAULT_CERTIFICATE_TOL
                             ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`row_activity` from the rows' values ``a = A x`` and sizes
    ``size = |A| |x| + ‖a_r‖`` (for a caller that has them already)."""
    v = a - np.clip(a, lower, upper)
    with np.errstate(invalid="ignore"):
        eps_u = tol * (size + np.where(np.isfinite(upper), np.abs(upper), 0.0))
        eps_l = tol * (size + np.where(np.isfinite(lower), np.abs(lower), 0.0))
        at_u = np.isfinite(upper) & (np.abs(a - upper) <= eps_u)
        at_l = np.isfinite(lower) & (np.abs(a - lower) <= eps_l)
        violated = (a > upper + eps_u) | (a < lower - eps_l)
    side = np.zeros(a.shape[0], dtype=np.int64)
    side[at_u] = 1
    side[at_l] = -1
    side[(at_u & at_l) | violated | (lower == upper)] = 2
    return side, v


#: scipy's LAPACK ``dgesdd`` and ``dgesvd``, imported at the first :func:`svd`
#: (``import prioik`` loads no scipy)
_GESDD = _GESVD = None


def svd(A: np.ndarray, full_matrices: bool = True
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.linalg.svd(A, full_matrices)`` of a real matrix, through LAPACK's ``dgesdd``
    directly: the routine numpy calls, without its per-call wrapping (~4-7 µs less on
    the certificate's small matrices, which it factors dozens of times a check). Where
    ``dgesdd``'s divide and conquer does not converge (it can, on ill-conditioned
    matrices such as an extended Jacobian ``J_E`` of κ 1e14), ``dgesvd`` (QR iteration,
    slower and more robust) factors it. numpy's own call (and its ``LinAlgError``) where both
    report a failure or a non-finite singular value, and for an empty matrix."""
    global _GESDD, _GESVD
    if A.shape[0] and A.shape[1]:
        if _GESDD is None:
            from scipy.linalg.lapack import dgesdd, dgesvd
            _GESDD, _GESVD = dgesdd, dgesvd
        u, s, vt, info = _GESDD(A, compute_uv=1, full_matrices=int(full_matrices))
        if info > 0 and np.isfinite(A).all():    # no convergence (not a bad argument)
            u, s, vt, info = _GESVD(A, compute_uv=1, full_matrices=int(full_matrices))
        if info == 0 and s[0] < np.inf:       # (False for NaN)
            return u, s, vt
    return np.linalg.svd(A, full_matrices=full_matrices)


def numpy_svd(A: np.ndarray, full_matrices: bool = True
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.linalg.svd(A, full_matrices)``, or :func:`svd` where numpy's ``dgesdd`` does
    not converge (its ``dgesvd`` fallback). For callers whose answers
    must stay numpy's to the bit where numpy converges (:func:`svd` calls LAPACK
    directly and rounds differently)."""
    try:
        return np.linalg.svd(A, full_matrices=full_matrices)
    except np.linalg.LinAlgError:
        return svd(A, full_matrices=full_matrices)


def _face_solve(M: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``min ‖M s − y‖`` (``lstsq``'s rank rule) and its residual
    ``y − U Uᵀ y``, projected: accurate to ``eps ‖y‖`` where ``y − M s`` carries the
    rounding of ``M s``, ``eps ‖M‖ ‖s‖`` (huge for an ill-conditioned face)."""
    u, sig, vt = svd(M, full_matrices=False)
    r = int(np.count_nonzero(sig > _EPS * max(M.shape) * sig[0])) \
        if sig.size and sig[0] > 0 else 0
    c = u[:, :r].T @ y
    return vt[:r].T @ (c / sig[:r]), y - u[:, :r] @ c


def nonnegative_least_squares(M: np.ndarray, y: np.ndarray, max_iter: int | None = None
                              ) -> tuple[np.ndarray, float]:
    """``min ‖M μ − y‖`` over ``μ ≥ 0`` (Lawson & Hanson's active-set NNLS, 1974).

    At a face's least-squares solution the residual (and the gradient ``Mᵀ r`` whose
    sign decides whether a column joins) is the projection of ``y`` off the face's
    columns, not ``y − M μ``: on an ill-conditioned face ``μ`` reaches 1e10 and the
    rounding of ``M μ`` (``eps ‖M‖ ‖μ‖``, 1e-6) swamped a gradient of 1e-7, ending the
    search at a residual 1e8 times the optimum (a certificate failing an exact answer).

    Args:
        M: ``d × p`` matrix.
        y: ``d`` vector.
        max_iter: Cap on inner iterations (default ``3 p + 10``).

    Returns:
        ``(μ, ‖M μ − y‖)``.
    """
    d, p = M.shape
    mu = np.zeros(p)
    if p == 0 or d == 0:
        return mu, float(np.linalg.norm(y))
    cap = 3 * p + 10 if max_iter is None else max_iter
    if p > 1:
        # the whole matrix's least-squares solution, when it is positive, is the optimum
        # (the unconstrained minimum is feasible): at a certified answer every row at a
        # bound typically has a positive multiplier, and this is one face solve where
        # the search below adds the columns one by one (a face solve each)
        s, face_res = _face_solve(M, y)
        if float(s.min()) > 0:
            return s, float(np.linalg.norm(face_res))
    # the gradient Mᵀ r scales with ‖M‖ ‖y‖: a tolerance of ‖M‖ alone stopped searches
    # on a small y (1e-4) early, at residuals 1e-9 where the optimum is 1e-20
    tol = 10.0 * _EPS * max(d, p) * max(float(np.abs(M).sum(axis=0).max()), 1e-300) \
        * max(float(np.linalg.norm(y)), 1e-300)
    passive = np.zeros(p, dtype=bool)
    res = y.astype(np.float64, copy=True)     # y − M μ (projected at a face's solution)
    w = M.T @ res
    it = 0
    while it < cap:
        # the column of the largest gradient outside the face joins it, if positive
        outside = np.where(passive, -np.inf, w)
        j = int(np.argmax(outside))
        if not outside[j] > tol:      # (every column in the face: -inf)
            break
        passive[j] = True
        while it < cap and passive.any():
            it += 1
            s = np.zeros(p)
            s[passive], face_res = _face_solve(M[:, passive], y)
            if float(s[passive].min()) > 0:
                mu = s
                res = face_res
                break
            neg = passive & (s <= 0)
            den = mu[neg] - s[neg]
            # a column just added with s = 0 exactly (0/0): it leaves again, alpha = 0
            alpha = float(np.min(np.where(den > 0, mu[neg] / np.where(den > 0, den, 1.0),
                                          0.0)))
            mu = mu + alpha * (s - mu)
            passive &= mu > tol
            mu[~passive] = 0.0
            res = y - M @ mu
        w = M.T @ res
    return mu, float(np.linalg.norm(res))


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
