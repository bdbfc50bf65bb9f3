"""Prioritized operational-space control (Khatib 1987; Sentis & Khatib 2005; Khatib,
Sentis & Park 2008), in joint accelerations and torques.

With ``M`` the joint-space inertia, a task Jacobian ``J`` has the operational-space
inertia ``Λ = (J M⁻¹ Jᵀ)⁺`` and the *dynamically consistent* generalized inverse
``J̄ = M⁻¹ Jᵀ Λ``; ``N = I − J̄ J`` is the dynamically consistent null-space
projector (``M N`` is symmetric: torques in ``range(Nᵀ)`` produce no acceleration
of the task). Levels are prioritized through the projected Jacobians::

    J_{i|prev} = J_i N_{i-1} ,   Λ_{i|prev} = (J_{i|prev} M⁻¹ J_{i|prev}ᵀ)⁺ ,
    J̄_{i|prev} = M⁻¹ J_{i|prev}ᵀ Λ_{i|prev} ,
    F_i = Λ_{i|prev} (h_i − J_i θ̈_{i-1})                   (task force)
    θ̈_i = θ̈_{i-1} + J̄_{i|prev} (h_i − J_i θ̈_{i-1}) ,   N_i = N_{i-1} − J̄_{i|prev} J_{i|prev}

with ``θ̈_0 = 0``, ``N_0 = I`` (Jeong & Chang 2009 compare with it in §III; ``h_i``
is eq. 4, so ``J̇θ̇`` is already in it). The torque is ``τ = M θ̈ + C + G``, equal to
the operational-space form ``Σ_i J_{i|prev}ᵀ F_i + C + G``; splitting the bias
over the levels gives the classical ``Λ ẍ* + μ + p`` form
``Σ_i J_{i|prev}ᵀ (F_i + J̄_{i|prev}ᵀ (C + G)) + N_kᵀ (C + G)``
(see :func:`task_space_torque`).

On an equality stack the result is the lexicographic optimum whose remaining
freedom is fixed by the smallest kinetic metric ``θ̈ᵀ M θ̈`` — ``reference`` with
``metric=M`` — because ``J_i J̄_{i|prev}`` is the orthogonal projector onto
``range(J_{i|prev})``. Like ``nullspace``, it divides by the singular values of the
projected Jacobians, so near an algorithmic singularity ``θ̈`` grows like ``1/σ``.

Numerics: ``M = L Lᵀ`` (Cholesky); with ``B = J_{i|prev} L⁻ᵀ`` one has
``Λ = (B Bᵀ)⁺`` and ``J̄ = L⁻ᵀ B⁺``, so no inverse of ``M`` and no squared condition
number: ``B⁺`` comes from an SVD keeping ``σ > rcond·‖J_i L⁻ᵀ‖_F``. As in
``nullspace``, ``reproject=True`` (default) applies ``N_{i-1}`` once more to each step
(``N_{i-1} J̄_{i|prev} = J̄_{i|prev}`` exactly, but not in round-off): without it the
higher levels' residuals grow like ``ε/σ²`` near an algorithmic singularity instead of
``ε/σ`` (measured in ``docs/properties.md``).

Two kernels compute it (option ``kernel``): ``"cpp"`` (the default where prioik's
compiled core is built, :class:`Prepared`) in C++, counting its floating-point operations
(:attr:`Detail.flops`); ``"numpy"`` is :func:`solve_readable`, the recursion as written here
with its per-level quantities in :attr:`Detail.levels`, the oracle the tests hold the
compiled kernel to.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import solve_triangular

from prioik.hierarchy import StackData, StackLayout, TaskStack

from . import contract
from ._compiled import MassMatrixPrepared, _core, mass_matrix_outcome
from ._numerics import check_nonnegative, truncated_svd
from .base import (
    Capabilities,
    Diagnostics,
    FormulationError,
    Outcome,
    Status,
)
from .options import Option, rcond_option, validate_options


@dataclass(slots=True)
class Detail:
    """``operational_space``'s own record (``sol.diagnostics.detail``).

    Attributes:
        kernel: ``"cpp"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` on the numpy path).
        tau: ``M θ̈ + C + G`` when the option ``bias`` is given, else ``None``.
        levels: The readable path's per-level quantities (one :class:`PrioritizedLevel`
            each; ``None`` on the compiled path).
        null_projector: The readable path's ``N_k`` (``None`` on the compiled path).
    """

    kernel: str
    flops: int | None = None
    tau: np.ndarray | None = None
    levels: list | None = None
    null_projector: np.ndarray | None = None


NAME = "operational_space"
DESCRIPTION = "prioritized operational-space control (Khatib, Sentis), mass_matrix=M"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=True, exact=True)
OPTIONS = {
    "mass_matrix": Option(None, "matrix", "SPD n×n joint-space inertia M (required)",
                          optional=True),
    "bias": Option(None, "vector", "C + G (n): with it, Detail.tau = M θ̈ + C + G",
                   optional=True),
    "rcond": rcond_option("‖J_i L⁻ᵀ‖_F"),
    "reproject": Option(True, "bool", "apply N_{i-1} to each step (exact no-op; keeps "
                        "round-off ≈ ε/σ)"),
    "kernel": Option("auto", "str", "'cpp': the compiled C++ core (prioik._core, row-pivoted "
                     "LQ); 'numpy': the readable recursion (with Detail.levels); 'auto': "
                     "cpp where built", choices=("auto", "cpp", "numpy")),
}


@dataclass
class PrioritizedLevel:
    """The operational-space quantities of one level.

    Attributes:
        J_projected: ``J_{i|prev} = J_i N_{i-1}`` (``m_i × n``).
        Lambda: ``Λ_{i|prev}`` (``m_i × m_i``), the operational-space inertia.
        J_bar: ``J̄_{i|prev}`` (``n × m_i``), the dynamically consistent inverse.
        force: ``F_i = Λ_{i|prev} (h_i − J_i θ̈_{i-1})``.
        rank: Kept rank of ``J_{i|prev}``.
    """

    J_projected: np.ndarray
    Lambda: np.ndarray
    J_bar: np.ndarray
    force: np.ndarray
    rank: int


def _cholesky_lower(M: np.ndarray) -> np.ndarray:
    try:
        return np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        w = np.linalg.eigvalsh(M)
        raise FormulationError(f"mass_matrix must be positive definite "
                               f"(smallest eigenvalue {w.min():.3e})") from None


def task_space_torque(levels: list[PrioritizedLevel], null_projector: np.ndarray,
                      bias: np.ndarray) -> np.ndarray:
    """``Σ_i J_{i|prev}ᵀ (F_i + μ_i + p_i) + N_kᵀ (C + G)``, ``μ_i + p_i = J̄_{i|prev}ᵀ (C + G)``.

    The operational-space (``Λ ẍ* + μ + p``) form of the torque; it equals
    ``M θ̈ + C + G`` because ``Σ_i J̄_{i|prev} J_{i|prev} + N_k = I``.
    """
    tau = null_projector.T @ bias
    for lv in levels:
        tau = tau + lv.J_projected.T @ (lv.force + lv.J_bar.T @ bias)
    return tau


def solve(stack: TaskStack, **options) -> Outcome:
    """Prioritized operational-space control: :class:`Prepared` for the stack's layout,
    then its :meth:`Prepared.solve` (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


def solve_readable(stack: TaskStack, *, mass_matrix, bias, rcond: float, reproject: bool
                   ) -> Outcome:
    """Prioritized operational-space control in numpy (``kernel="numpy"``), the readable
    oracle of the compiled kernel; see the module docstring.

    Returns:
        ``Outcome`` whose :class:`Detail` holds ``levels`` (one
        :class:`PrioritizedLevel` each), ``null_projector`` (``N_k``) and, when ``bias``
        is given, ``tau = M θ̈ + C + G``.
    """
    if mass_matrix is None:
        raise FormulationError("formulation 'operational_space' needs mass_matrix=M")
    check_nonnegative(rcond=rcond)
    M = np.asarray(mass_matrix, dtype=np.float64)
    L = _cholesky_lower(M)
    n = stack.n
    x = np.zeros(n)
    N = np.eye(n)
    levels = []
    for level in stack.levels:
        A, b = level.A, level.b
        Jp = A @ N                                                   # J_{i|prev}
        B = solve_triangular(L, Jp.T, lower=True).T                  # J_{i|prev} L⁻ᵀ
        scale = float(np.linalg.norm(solve_triangular(L, A.T, lower=True)))
        U, s, V = truncated_svd(B, float(rcond) * scale)
        B_pinv = (V / s) @ U.T if s.size else np.zeros((n, A.shape[0]))
        J_bar = solve_triangular(L, B_pinv, lower=True, trans="T")   # L⁻ᵀ B⁺
        Lam = (U / (s * s)) @ U.T if s.size else np.zeros((A.shape[0], A.shape[0]))
        err = b - A @ x
        levels.append(PrioritizedLevel(Jp, Lam, J_bar, Lam @ err, int(s.size)))
        step = J_bar @ err
        x = x + (N @ step if reproject else step)   # N_{i-1} J̄_{i|prev} = J̄_{i|prev}
        N = N - J_bar @ Jp
    tau = None if bias is None else M @ x + np.asarray(bias, dtype=np.float64)
    return Outcome(x, Status.OPTIMAL,
                   Diagnostics(ranks=np.array([lv.rank for lv in levels]),
                               detail=Detail("numpy", None, tau, levels, N)))


class Prepared(MassMatrixPrepared):
    """Prioritized operational-space control prepared for one layout: options checked, and
    on the compiled kernel (``kernel="cpp"``) the C++ solver with every workspace allocated
    once (``prioik._core.OperationalSpaceSolver``: ``M = L Lᵀ`` factored in the solve,
    ``B = J_{i|prev} L⁻ᵀ`` by a row-pivoted LQ with the rank rule on its pivots,
    ``J̄ = L⁻ᵀ B⁺`` applied to the level's error, ``N_i = N_{i-1} − (L⁻ᵀ V)(L V)ᵀ``
    with ``V`` the LQ's kept row space, which is ``N_{i-1} − J̄ J_{i|prev}``;
    :attr:`Detail.flops` counts the solve's floating-point operations). The per-level
    quantities (:attr:`Detail.levels`, :attr:`Detail.null_projector`) are the readable path's
    (``kernel="numpy"``, :func:`solve_readable`). ``mass_matrix`` and ``bias`` may change
    with every solve.

    Args:
        layout: The stack layout (equality tasks only; the registry checked it).
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).
    """

    name = NAME

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.reproject = bool(settings.reproject)
        super().__init__(layout, settings)

    def compiled_solver(self, starts: list[int], n: int) -> Any:
        return _core.OperationalSpaceSolver(starts, n, rcond=self.rcond,
                                            reproject=self.reproject)

    def readable(self, data: StackData, mass, bias) -> Outcome:
        return solve_readable(data.as_stack(), mass_matrix=mass, bias=bias,
                              rcond=self.rcond, reproject=self.reproject)

    def outcome(self, res, M: np.ndarray, bias) -> Outcome | None:
        return mass_matrix_outcome(res, M, bias, Status.OPTIMAL, Detail)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
