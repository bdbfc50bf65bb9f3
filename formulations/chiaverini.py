"""Singularity-robust task priority (Chiaverini 1997), in its k-level form.

Chiaverini (1997) treats two tasks, ``θ̈ = J_1^# h_1 + (I − J_1⁺J_1) J_2^# h_2``; the
sum over ``k`` levels with the augmented projectors below is the usual later
generalisation, not his paper's. Each level is first solved *on its own* —
``J_i^# h_i``, ignoring the levels above — and that solution is then projected into the
null space of the augmented Jacobian of the higher levels (``J_{i-1}^A``, eq. 7 of
Jeong & Chang 2009)::

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

Two kernels compute it (option ``kernel``): ``"cpp"`` (the default where prioik's
compiled core is built, :class:`Prepared`) in C++, each ``J_i^#`` and the projector
``N^A_i`` from row-pivoted LQs (the rank rule on their pivot norms), counting its
floating-point operations (:attr:`Detail.flops`); ``"numpy"`` is :func:`solve_readable`, the
sum as written here, the oracle the tests hold the compiled kernel to.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from prioik.hierarchy import StackData, StackLayout, TaskStack, nested_null_spaces

from . import contract
from ._compiled import _core, resolve_kernel, solve_compiled, solve_rescaled
from ._numerics import check_nonnegative, generalized_inverse
from .base import Capabilities, Diagnostics, Outcome, Status
from .options import Option, rcond_option, validate_options


@dataclass(slots=True)
class Detail:
    """``chiaverini``'s own record (``sol.diagnostics.detail``).

    Attributes:
        task_solutions: Each level's own solution ``J_i^# h_i``.
        damping: The damping ``λ`` of each level's inverse.
        kernel: ``"cpp"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` on the numpy path).
    """

    task_solutions: list[np.ndarray]
    damping: float
    kernel: str
    flops: int | None = None


NAME = "chiaverini"
DESCRIPTION = "singularity-robust task priority (Chiaverini 1997): Σ N^A_{i-1} J_i^# h_i"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=False)
OPTIONS = {
    "damping": Option(0.0, "float", "λ: J^# = Jᵀ(JJᵀ + λI)⁻¹ (λ multiplies I); 0: pseudo-inverse",
                      minimum=0.0),
    "rcond": rcond_option("‖J_i‖_F"),
    "kernel": Option("auto", "str", "'cpp': the compiled C++ core (prioik._core, row-pivoted "
                     "LQ); 'numpy': the readable SVD sum; 'auto': cpp where built",
                     choices=("auto", "cpp", "numpy")),
}


def solve(stack: TaskStack, **options) -> Outcome:
    """Chiaverini's task priority: :class:`Prepared` for the stack's layout, then its
    :meth:`Prepared.solve` (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


def solve_readable(stack: TaskStack, *, damping: float, rcond: float) -> Outcome:
    """Chiaverini's singularity-robust task priority in numpy (``kernel="numpy"``), the
    readable oracle of the compiled kernel; see the module docstring.

    Returns:
        ``Outcome`` (status ``"approximate"``: the method has algorithmic error) with
        :attr:`Detail.task_solutions`, each level's own solution ``J_i^# h_i``.
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
    return _outcome(x, own, damping, "numpy", None)


def _outcome(x, own, damping: float, kernel: str, flops, residuals=None) -> Outcome:
    """The answer (``approximate``: the method has algorithmic error) with its record."""
    return Outcome(x, Status.APPROXIMATE,
                   Diagnostics(reason="Chiaverini's task priority has algorithmic error "
                                      "(not the lexicographic optimum)",
                               detail=Detail(list(own), damping, kernel, flops)), residuals)


class Prepared(contract.Prepared):
    """Chiaverini's task priority prepared for one layout: options checked, and on the
    compiled kernel (``kernel="cpp"``) the C++ solver with every workspace allocated once
    (``prioik._core.ChiaveriniSolver``: each level's own inverse and the projector
    ``N^A_i`` from row-pivoted LQs, the rank rule on their pivots; :attr:`Detail.flops`
    counts the solve's floating-point operations). ``kernel="numpy"`` is
    :func:`solve_readable`.

    Args:
        layout: The stack layout (equality tasks only; the registry checked it).
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).
    """

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.layout = layout
        self.kernel = resolve_kernel(settings.kernel)
        check_nonnegative(damping=settings.damping, rcond=settings.rcond)
        self.damping = float(settings.damping)
        self.rcond = float(settings.rcond)
        self._cpp = self.kernel == "cpp"
        if self._cpp:
            self._core = _core.ChiaveriniSolver([int(s) for s in layout.starts], layout.n,
                                                rcond=self.rcond, damping=self.damping)

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout.

        Raises:
            TaskStackError: a value is not finite (naming the task, level and row).
        """
        if not self._cpp:
            return solve_readable(data.as_stack(), damping=self.damping, rcond=self.rcond)
        res = solve_compiled(self._core, data)
        if not res.solved:
            return solve_rescaled(self.solve, data)
        own = res.task_solutions.reshape(self.layout.k, self.layout.n)
        return _outcome(res.x, own, self.damping, "cpp", res.flops, res.residuals)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
