"""Exact minimum-norm lexicographic least squares by nested SVD null spaces.

The ground truth of the tests. For levels ``i = 1..k`` (highest first)::

    M_i = A_i Z_i,                y_i = M_i⁺ (b_i − A_i x),     x ← x + Z_i y_i,
    Z_{i+1} = Z_i · null(M_i)

with ``Z_1 = I`` and every pseudo-inverse and null space from an SVD in float64
(rank threshold ``rcond · ‖A_i‖_F``). Each level is solved in the least-squares
sense, so rank-deficient and infeasible levels are handled. Because every ``y_i``
lies in the row space of ``M_i``, the result is the minimum-norm point of the
lexicographic optimal set; ``metric=W`` instead minimises ``xᵀ W x`` over that set.
"""

from __future__ import annotations

import numpy as np

from hierarchy import DEFAULT_RCOND, TaskStack

from .base import Capabilities, Outcome

NAME = "reference"
DESCRIPTION = "exact lexicographic least squares, nested SVD null spaces (ground truth)"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "rcond": (DEFAULT_RCOND, "relative rank threshold: σ counts if σ > rcond·‖A_i‖_F"),
    "metric": (None, "SPD n×n W: the final tie-break minimises xᵀWx instead of xᵀx"),
}


def solve(stack: TaskStack, *, rcond: float = DEFAULT_RCOND, metric=None) -> Outcome:
    """Lexicographic minimum-norm (or minimum ``xᵀWx``) solution of an equality stack."""
    n = stack.n
    x = np.zeros(n)
    Z = np.eye(n)
    ranks = []
    for level in stack.levels:
        A, b = level.A, level.b
        if Z.shape[1] == 0:
            ranks.append(0)
            continue
        M = A @ Z
        u, s, vt = np.linalg.svd(M, full_matrices=True)
        tol = rcond * float(np.linalg.norm(A))
        r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
        if r:
            c = b - A @ x
            y = vt[:r].T @ ((u[:, :r].T @ c) / s[:r])
            x = x + Z @ y
        Z = Z @ vt[r:].T
        ranks.append(r)
    if metric is not None and Z.shape[1]:
        W = np.asarray(metric)
        G = Z.T @ W @ Z
        try:
            L = np.linalg.cholesky(G)
        except np.linalg.LinAlgError:
            raise np.linalg.LinAlgError("metric is not positive definite on the "
                                        "remaining null space") from None
        z = np.linalg.solve(L.T, np.linalg.solve(L, -(Z.T @ (W @ x))))
        x = x + Z @ z
    return Outcome(x, "optimal", {"rank_profile": ranks, "null_space_dim": int(Z.shape[1])})
