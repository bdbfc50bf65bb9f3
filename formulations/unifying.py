"""The unifying framework of Peters, Mistry, Udwadia, Nakanishi & Schaal (2008),
as reformulated in the appendix of Jeong & Chang (2009), eq. 36-40.

With the joint-space dynamics ``τ = M θ̈ + C + G`` (eq. 36), the framework computes
one torque per level, lowest priority first (eq. 37)::

    τ = Σ_i τ_i + C + G ,
    τ_i = (J_i M⁻¹)⁺ (h_i − J_i M⁻¹ τ_i_post) ,   τ_i_post = Σ_{j>i} τ_j

so the highest level, computed last, corrects whatever the lower ones did to it.
Implemented is eq. 40's reading (the paper's eq. 37-39 carry the bias ``C+G`` inside
the bracket, eq. 40 does not; ``docs/formulations.md``): with the bias compensated
outside the sum, ``M θ̈ = Σ_i τ_i``. Using ``(J M⁻¹)⁺ = M J^{M²+}`` with the
``M²``-weighted pseudo-inverse

    J^{M²+} = M⁻² Jᵀ (J M⁻² Jᵀ)⁺        (check: M J^{M²+} = M⁻¹Jᵀ(JM⁻¹(JM⁻¹)ᵀ)⁺ = (JM⁻¹)⁺)

the recursion unrolls into eq. 40::

    τ = M Σ_i θ̈_i + C + G ,   θ̈_i = N_i J_i^{M²+} h_i ,
    N_1 = I ,  N_i = N_{i-1} (I − J_{i-1}^{M²+} J_{i-1})

``solve`` evaluates eq. 40 forwards (top level first); :func:`torque_recursion` is
eq. 37 without the bias (bottom level first), and the tests check that both agree.
Like Chiaverini's method, each level uses its own inverse ``J_i^{M²+}`` rather than
that of a projected Jacobian, so there is no algorithmic singularity but there is
algorithmic error (eq. 34); the top level is met exactly. A lower level has none when
``J_i M⁻² J_jᵀ = 0`` for the levels ``j`` above it (sufficient, not necessary; with
``M = I``: mutually orthogonal rows). With ``M = I`` the method equals Chiaverini's
for two levels only: beyond, eq. 40's ``N_i = Π_{j<i}(I − J_j⁺ J_j)`` is a product of
the levels' own projectors, not the projector ``N^A_{i-1}`` onto the null space of the
augmented Jacobian that Chiaverini's k-level sum uses (tests).

Every ``M⁻¹`` is applied through the Cholesky factor of ``M``; the pseudo-inverse of
``B_i = J_i M⁻¹`` uses an SVD with the shared rank rule relative to ``‖B_i‖_F``.

Two kernels compute it (option ``kernel``): ``"cpp"`` (the default where prioik's
compiled core is built, :class:`Prepared`) in C++, counting its floating-point operations
(:attr:`Detail.flops`); ``"numpy"`` is :func:`solve_readable`, eq. 40 as written here, the
oracle the tests hold the compiled kernel to.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import cho_factor, cho_solve

from prioik.hierarchy import DEFAULT_RCOND, StackData, TaskStack

from . import contract
from ._compiled import MassMatrixPrepared, _core, mass_matrix_outcome
from ._numerics import check_nonnegative, generalized_inverse
from .base import (
    Capabilities,
    Diagnostics,
    FormulationError,
    Outcome,
    Status,
)
from .options import Option, rcond_option, validate_options

#: the reason of every answer's ``approximate`` status
ALGORITHMIC_ERROR = ("the unifying framework's projectors are the levels' own (eq. 40): "
                     "algorithmic error beyond two levels, not the lexicographic optimum")


@dataclass(slots=True)
class Detail:
    """``unifying``'s own record (``sol.diagnostics.detail``).

    Attributes:
        kernel: ``"cpp"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` on the numpy path).
        tau: ``M θ̈ + C + G`` when the option ``bias`` is given, else ``None``.
    """

    kernel: str
    flops: int | None = None
    tau: np.ndarray | None = None


NAME = "unifying"
DESCRIPTION = "unifying framework (Peters et al. 2008), paper's eq. 36-40 with mass_matrix=M"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=True, exact=False)
OPTIONS = {
    "mass_matrix": Option(None, "matrix", "SPD n×n joint-space inertia M (required)",
                          optional=True),
    "bias": Option(None, "vector", "C + G (n): with it, Detail.tau = M θ̈ + C + G (eq. 40)",
                   optional=True),
    "rcond": rcond_option("‖J_i M⁻¹‖_F"),
    "kernel": Option("auto", "str", "'cpp': the compiled C++ core (prioik._core, row-pivoted "
                     "LQ); 'numpy': the readable eq. 40; 'auto': cpp where built",
                     choices=("auto", "cpp", "numpy")),
}


def cholesky(mass_matrix: np.ndarray) -> tuple[np.ndarray, bool]:
    """Cholesky factor of ``M`` for :func:`scipy.linalg.cho_solve`.

    Raises:
        FormulationError: ``M`` is not positive definite.
    """
    try:
        return cho_factor(np.asarray(mass_matrix, dtype=np.float64), lower=True)
    except np.linalg.LinAlgError:
        w = np.linalg.eigvalsh(mass_matrix)
        raise FormulationError(f"mass_matrix must be positive definite "
                               f"(smallest eigenvalue {w.min():.3e})") from None


def weighted_pinv(J: np.ndarray, factor, rcond: float = DEFAULT_RCOND) -> np.ndarray:
    """``J^{M²+} = M⁻² Jᵀ (J M⁻² Jᵀ)⁺ = M⁻¹ (J M⁻¹)⁺`` (``factor``: Cholesky of ``M``)."""
    B = cho_solve(factor, J.T).T                         # J M⁻¹ (M symmetric)
    B_pinv, _, _ = generalized_inverse(B, float(rcond) * float(np.linalg.norm(B)))
    return cho_solve(factor, B_pinv)


def torque_recursion(stack: TaskStack, mass_matrix: np.ndarray, bias=None,
                     rcond: float = DEFAULT_RCOND) -> tuple[np.ndarray, list[np.ndarray]]:
    """Eq. 37 literally: ``τ_i = (J_i M⁻¹)⁺ (h_i − J_i M⁻¹ τ_i_post)``, lowest level first.

    Args:
        stack: Equality task stack (``J_i = A_i``, ``h_i = b_i``).
        mass_matrix: SPD ``M``.
        bias: ``C + G`` (default zero).
        rcond: Relative rank threshold for ``(J_i M⁻¹)⁺``.

    Returns:
        ``(τ, [τ_1, …, τ_k])`` with ``τ = Σ τ_i + C + G``.
    """
    factor = cholesky(mass_matrix)
    n = stack.n
    taus: list[np.ndarray] = [np.zeros(n)] * len(stack)
    tau_post = np.zeros(n)
    for i in range(len(stack) - 1, -1, -1):
        A, b = stack.levels[i].A, stack.levels[i].b
        B = cho_solve(factor, A.T).T                     # J_i M⁻¹
        B_pinv, _, _ = generalized_inverse(B, float(rcond) * float(np.linalg.norm(B)))
        taus[i] = B_pinv @ (b - B @ tau_post)
        tau_post = tau_post + taus[i]
    bias_vec = np.zeros(n) if bias is None else np.asarray(bias, dtype=np.float64)
    return tau_post + bias_vec, taus


def solve(stack: TaskStack, **options) -> Outcome:
    """Eq. 40: :class:`Prepared` for the stack's layout, then its :meth:`Prepared.solve`
    (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


def solve_readable(stack: TaskStack, *, mass_matrix, bias, rcond: float) -> Outcome:
    """Eq. 40 in numpy, ``θ̈ = Σ_i N_i J_i^{M²+} h_i`` (``kernel="numpy"``), the readable
    oracle of the compiled kernel; see the module docstring.

    Returns:
        ``Outcome`` (status ``"approximate"``: the method has algorithmic error) with
        :attr:`Detail.tau` ``= M θ̈ + C + G`` when ``bias`` is given.
    """
    if mass_matrix is None:
        raise FormulationError("formulation 'unifying' needs mass_matrix=M")
    check_nonnegative(rcond=rcond)
    M = np.asarray(mass_matrix, dtype=np.float64)
    factor = cholesky(M)
    n = stack.n
    x = np.zeros(n)
    N = np.eye(n)
    for level in stack.levels:
        A, b = level.A, level.b
        K = weighted_pinv(A, factor, rcond)              # J_i^{M²+}
        x = x + N @ (K @ b)                              # θ̈_i = N_i J_i^{M²+} h_i
        N = N - (N @ K) @ A                              # N_{i+1} = N_i (I − J_i^{M²+} J_i)
    tau = None if bias is None else M @ x + np.asarray(bias, dtype=np.float64)
    return Outcome(x, Status.APPROXIMATE,
                   Diagnostics(reason=ALGORITHMIC_ERROR, detail=Detail("numpy", None, tau)))


class Prepared(MassMatrixPrepared):
    """The unifying framework prepared for one layout: options checked, and on the compiled
    kernel (``kernel="cpp"``) the C++ solver with every workspace allocated once
    (``prioik._core.UnifyingSolver``: ``M = L Lᵀ`` factored in the solve, each
    ``(A_i M⁻¹)⁺`` from a row-pivoted LQ with the rank rule on its pivots, and
    ``N_{i+1} = N_i − (N_i M⁻¹ V)(M V)ᵀ`` with ``V`` the LQ's kept row space, which is
    ``N_i (I − J_i^{M²+} J_i)`` since ``J^{M²+} J = M⁻¹ B⁺ B M``; :attr:`Detail.flops` counts
    the solve's floating-point operations). ``kernel="numpy"`` is :func:`solve_readable`.
    ``mass_matrix`` and ``bias`` may change with every solve.

    Args:
        layout: The stack layout (equality tasks only; the registry checked it).
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).
    """

    name = NAME

    def compiled_solver(self, starts: list[int], n: int) -> Any:
        return _core.UnifyingSolver(starts, n, rcond=self.rcond)

    def readable(self, data: StackData, mass, bias) -> Outcome:
        return solve_readable(data.as_stack(), mass_matrix=mass, bias=bias, rcond=self.rcond)

    def outcome(self, res, M: np.ndarray, bias) -> Outcome | None:
        out = mass_matrix_outcome(res, M, bias, Status.APPROXIMATE, Detail)
        if out is not None:
            out.diagnostics.reason = ALGORITHMIC_ERROR
        return out


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
