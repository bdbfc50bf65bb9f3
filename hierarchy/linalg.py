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
``approximate`` with ``info["reason"]`` naming the levels
(:func:`ambiguous_decision`).
"""

from __future__ import annotations

import numpy as np

#: Default relative rank threshold (see module docstring).
DEFAULT_RCOND = 1e-9

#: A singular value within this factor of the rank threshold makes the decision
#: ambiguous (see module docstring): three decades either side.
AMBIGUITY = 1e3


def level_scale(A: np.ndarray) -> float:
    """``‖A‖_F``, without the overflow or underflow of the squares (entries beyond
    1e154 or below 1e-154 would give ``inf`` or 0 from ``np.linalg.norm``)."""
    if A.size == 0:
        return 0.0
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


def ambiguity_reason(levels: list[int]) -> str:
    """The ``info["reason"]`` of an ``approximate`` status due to ambiguous levels."""
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
    u, s, _ = np.linalg.svd(A, full_matrices=True)
    tol = rcond * (float(np.linalg.norm(A)) if scale is None else scale)
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    return u[:, :r], u[:, r:], s[:r]
