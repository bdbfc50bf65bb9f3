"""Singularity-robust task priority (Chiaverini 1997), in its k-level form.

Chiaverini (1997) treats two tasks, ``θ̈ = J_1^# h_1 + (I − J_1⁺J_1) J_2^# h_2``; the
sum over ``k`` levels with the augmented projectors below is the usual later
generalisation, not his paper's. Each level is first solved *on its own* — ``J_i^# h_i``, ignoring
the levels above —
and that solution is then projected into the null space of the augmented Jacobian
of the higher levels (``J_{i-1}^A``, eq. 7 of Jeong & Chang 2009)::

    θ̈ = Σ_i N^A_{i-1} J_i^# h_i ,     N^A_0 = I ,
    N^A_{i-1} = I − (J_{i-1}^A)⁺ J_{i-1}^A   (orthogonal projector onto null(J_{i-1}^A))

Because only each task's own inverse ``J_i^#`` appears (never the projected
``J_i N^A_{i-1}``), no algorithmic singularity can occur: ``θ̈`` is bounded by
``Σ_i ‖J_i^#‖ ‖h_i‖`` whatever the coupling between levels. The price is the
*algorithmic error* (eq. 29): ``h_i_feasible − J_i_feasible θ̈`` is in general
non-zero even when every task could be met. Rows orthogonal to the higher levels'
rows (decoupled tasks) are sufficient for it to vanish, not necessary: a level made
of rows orthogonal to the levels above plus copies of higher rows (its conflicting
part) has none either (tests).

``J_i^#`` is the pseudo-inverse (``damping = 0``, the default: the shared rank rule
``σ > rcond·‖J_i‖_F``) or the damped least-squares inverse
``J_iᵀ (J_i J_iᵀ + λ I)⁻¹`` (``damping = λ > 0``, λ multiplies ``I`` as in eq. 27),
which also bounds ``θ̈`` at *kinematic* singularities of a task. The projectors
``N^A_{i-1}`` are exact (nested SVD null spaces with the same rank rule).
"""

from __future__ import annotations

import numpy as np

from prioik.hierarchy import TaskStack, nested_null_spaces

from .base import Capabilities, Outcome
from .nullspace import check_nonnegative, generalized_inverse
from .options import Option, rcond_option

NAME = "chiaverini"
DESCRIPTION = "singularity-robust task priority (Chiaverini 1997): Σ N^A_{i-1} J_i^# h_i"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=False)
OPTIONS = {
    "damping": Option(0.0, "float", "λ: J^# = Jᵀ(JJᵀ + λI)⁻¹ (λ multiplies I); 0: pseudo-inverse",
                      minimum=0.0),
    "rcond": rcond_option("‖J_i‖_F"),
}


def solve(stack: TaskStack, *, damping: float, rcond: float) -> Outcome:
    """Chiaverini's singularity-robust task priority; see the module docstring.

    Returns:
        ``Outcome`` (status ``"approximate"``: the method has algorithmic error) with
        ``info["task_solutions"]``, each level's own solution ``J_i^# h_i``.
    """
    check_nonnegative(damping=damping, rcond=rcond)
    damping = float(damping)
    bases = nested_null_spaces(stack, float(rcond))      # Z_i: basis of null(J_{i-1}^A)
    x = np.zeros(stack.n)
    own = []
    for level, Z in zip(stack.levels, bases, strict=False):
        A, b = level.A, level.b
        tol = float(rcond) * float(np.linalg.norm(A))
        J_sharp, _, _ = generalized_inverse(A, tol, damping)
        x_own = J_sharp @ b
        own.append(x_own)
        x = x + Z @ (Z.T @ x_own)                        # N^A_{i-1} = Z_i Z_iᵀ
    return Outcome(x, "approximate", {"task_solutions": own, "damping": damping})
