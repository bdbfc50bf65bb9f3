"""Small dense linear-algebra helpers shared by the analysis and the formulations.

Rank decisions use one rule everywhere: a singular value ``σ`` of a level's
projected matrix counts when ``σ > rcond · ‖A_i‖_F`` with ``‖A_i‖_F`` the Frobenius
norm of the level's own (weighted) rows, so that a row "in the row space of a higher
level" is judged on the scale of its own task, not of the whole stack.
"""

from __future__ import annotations

import numpy as np

#: Default relative rank threshold (see module docstring).
DEFAULT_RCOND = 1e-9


def rank_threshold(A: np.ndarray, rcond: float = DEFAULT_RCOND) -> float:
    """Absolute threshold below which a singular value of ``A``'s level is zero."""
    scale = float(np.linalg.norm(A)) if A.size else 0.0
    return rcond * scale if scale > 0 else 0.0


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
