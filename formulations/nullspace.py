"""Recursive null-space projection, resolved-acceleration form.

The classical task-priority scheme of Nakamura, Hanafusa & Yoshikawa (1987) and
Siciliano & Slotine (1991), written for accelerations (``J_i θ̈ = h_i``, eq. 3 of
Jeong & Chang 2009). With ``θ̈_0 = 0`` and ``N_0 = I``, for each level ``i = 1..k``::

    Ĵ_i   = J_i N_{i-1}                              (the projected Jacobian)
    θ̈_i  = θ̈_{i-1} + Ĵ_i^# (h_i − J_i θ̈_{i-1})
    N_i   = N_{i-1} − Ĵ_i⁺ Ĵ_i

``Ĵ_i^#`` is the Moore-Penrose pseudo-inverse when ``damping = 0`` (SVD, the shared
rank rule ``σ > rcond·‖J_i‖_F``; the result equals ``reference`` on compatible and
conflicting stacks). ``damping = λ > 0`` uses the damped least-squares inverse
``Ĵ_iᵀ (Ĵ_i Ĵ_iᵀ + λ I)⁻¹`` on every level (``λ`` not squared, as the paper's eq. 27);
the projectors stay exact, so a lower level never disturbs a higher one, and the
status is ``approximate``.

``reproject=True`` (default) multiplies each step by ``N_{i-1}`` once more, which keeps
the higher levels' residuals at ``ε/σ`` near an algorithmic singularity (``ε/σ²``
without it; ``docs/properties.md`` measures both). The kept singular vectors are
re-orthonormalised inside ``range(N_{i-1})`` before each projector update, so ``N_i``
stays a projector to rounding over any number of levels.

Two kernels (option ``kernel``): ``"cpp"`` (the default; :class:`Prepared`) runs the
recursion in the C++ core over one workspace, a row-pivoted LQ of ``Ĵ_i`` in place of
its SVD (rank rule on the pivot norms), and counts its floating-point operations
(:attr:`Detail.flops`); ``"numpy"`` is :func:`solve_readable`, the SVD recursion as
written, the oracle the tests hold the compiled kernel to. In detail:
``docs/formulations.md``.
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
from ._numerics import check_nonnegative, project_level, project_levels
from .base import (
    Capabilities,
    Diagnostics,
    Outcome,
    Status,
)
from .options import Option, rcond_option, validate_options


@dataclass(slots=True)
class Detail:
    """``nullspace``'s own record (``sol.diagnostics.detail``).

    Attributes:
        min_singular_values: Smallest kept ``σ`` of each ``Ĵ_i`` (the compiled kernel:
            its smallest kept pivot norm), ``0`` when none: the distance to an
            algorithmic singularity.
        damping: The damping ``λ`` of every level's inverse.
        kernel: ``"cpp"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` on the numpy path).
    """

    min_singular_values: list[float]
    damping: float
    kernel: str
    flops: int | None = None


NAME = "nullspace"
DESCRIPTION = "recursive null-space projection (Nakamura 1987), damped LS inverse option"
CAPABILITIES = Capabilities(equalities=True, inequalities=False, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "damping": Option(0.0, "float", "λ: Ĵ^# = Ĵᵀ(ĴĴᵀ + λI)⁻¹ (λ multiplies I, as eq. 27); "
                      "0: pseudo-inverse", minimum=0.0),
    "rcond": rcond_option("‖J_i‖_F"),
    "reproject": Option(True, "bool", "apply N_{i-1} to each step (exact no-op; keeps "
                        "round-off ≈ ε/σ)"),
    "kernel": Option("auto", "str", "'cpp': the compiled C++ core (prioik._core, row-pivoted "
                     "LQ); 'numpy': the readable SVD recursion; 'auto': cpp where built",
                     choices=("auto", "cpp", "numpy")),
}


def solve(stack: TaskStack, **options) -> Outcome:
    """Recursive null-space projection: :class:`Prepared` for the stack's layout, then
    its :meth:`Prepared.solve` (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


def solve_readable(stack: TaskStack, *, damping: float, rcond: float, reproject: bool
                   ) -> Outcome:
    """Recursive null-space projection in numpy (``kernel="numpy"``), the readable
    oracle of the compiled kernel; see the module docstring.

    Returns:
        ``Outcome`` with ``diagnostics.ranks`` (kept rank of each ``Ĵ_i``) and
        :attr:`Detail.min_singular_values` (smallest kept ``σ`` of each ``Ĵ_i``, ``0``
        when none: the distance to an algorithmic singularity).
    """
    check_nonnegative(damping=damping, rcond=rcond)
    damping = float(damping)
    n = stack.n
    x = np.zeros(n)
    N = np.eye(n)
    ranks, sigmas, ambiguous = [], [], []
    for i, level in enumerate(stack.levels):
        x, N, s, near = project_level(level.A, level.b, x, N,
                                      rank_threshold(level.A, float(rcond)), damping,
                                      reproject)
        if near:
            ambiguous.append(i)
        ranks.append(int(s.size))
        sigmas.append(float(s.min()) if s.size else 0.0)
    return _outcome(x, ranks, sigmas, damping, "numpy", None, ambiguous)


def _outcome(x, ranks, sigmas, damping: float, kernel: str, flops, ambiguous,
             residuals=None) -> Outcome:
    """The answer with its diagnostics (``approximate`` when damped or ambiguous)."""
    diagnostics = Diagnostics(ranks=np.asarray(ranks), ambiguous_levels=list(ambiguous),
                              detail=Detail(list(sigmas), damping, kernel, flops))
    if ambiguous:
        diagnostics.reason = ambiguity_reason(list(ambiguous))
    elif damping > 0:
        diagnostics.reason = f"damped least squares (damping={damping:g})"
    status = Status.APPROXIMATE if damping > 0 or ambiguous else Status.OPTIMAL
    return Outcome(x, status, diagnostics, residuals)


def solve_batch(stacks: list[TaskStack], *, damping: float = 0.0,
                rcond: float = DEFAULT_RCOND, reproject: bool = True
                ) -> tuple[np.ndarray, list[str]]:
    """:func:`solve_readable` for many stacks of one shape: :func:`project_levels` on the
    stacked levels (one stacked SVD per level), the same arithmetic as :func:`solve`."""
    check_nonnegative(damping=damping, rcond=rcond)
    damping = float(damping)
    count, n = len(stacks), stacks[0].n
    X = np.zeros((count, n))
    N = np.broadcast_to(np.eye(n), (count, n, n)).copy()
    near = np.zeros(count, dtype=bool)          # some rank decision was ambiguous
    for li in range(len(stacks[0])):
        A = np.stack([s.levels[li].A for s in stacks])              # B × m × n
        b = np.stack([s.levels[li].b for s in stacks])              # B × m
        tol = np.array([rank_threshold(a, float(rcond)) for a in A])
        X, N, _, _, amb = project_levels(A, b, X, N, tol, damping, reproject)
        near |= amb
    return X, ["approximate" if damping > 0 or amb else "optimal" for amb in near]

class Prepared(contract.Prepared):
    """Null-space projection prepared for one layout: options checked, and on the
    compiled kernel (``kernel="cpp"``) the C++ solver with every workspace allocated
    once (``prioik._core.NullspaceSolver``).

    The compiled kernel runs the recursion of the module docstring with a row-pivoted
    LQ of ``Ĵ_i`` (Householder reflectors) in place of its SVD: the rank rule tests the
    pivot norms (the rank-revealing estimates of ``σ``, :mod:`hierarchy.linalg`),
    :attr:`Detail.min_singular_values` holds the smallest kept pivot norm of each ``Ĵ_i``
    (``σ_min`` itself where the kept rows are orthogonal), and :attr:`Detail.flops` the
    solve's floating-point operations, counted in the kernel. ``kernel="numpy"`` is
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
        self.reproject = bool(settings.reproject)
        self._cpp = self.kernel == "cpp"
        if self._cpp:
            self._core = _core.NullspaceSolver([int(s) for s in layout.starts], layout.n,
                                               rcond=self.rcond, damping=self.damping,
                                               reproject=self.reproject)

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout.

        Raises:
            TaskStackError: a value is not finite (naming the task, level and row).
        """
        if not self._cpp:
            return solve_readable_equilibrated(
                lambda stack: solve_readable(stack, damping=self.damping, rcond=self.rcond,
                                             reproject=self.reproject), data)
        res = solve_compiled(self._core, data)
        if not res.solved:
            return solve_rescaled(self.solve, data)
        levels = np.flatnonzero(res.margins <= AMBIGUITY).tolist() if res.ambiguous else []
        out = _outcome(res.x, res.ranks.copy(), res.min_pivots.tolist(), self.damping, "cpp",
                       res.flops, levels, res.residuals)
        out.diagnostics.margins = np.asarray(res.margins).copy()
        return out

    def solve_batch(self, datas: list[StackData]) -> contract.BatchOutcome:
        """Many stacks of the layout: ``(X, statuses)`` (:func:`solve_batch` on the
        numpy kernel, one compiled solve after the other on the cpp kernel)."""
        if not self._cpp:
            stacks = [d.as_stack().equilibrated()[0] for d in datas]
            X, statuses = solve_batch(stacks, damping=self.damping, rcond=self.rcond,
                                      reproject=self.reproject)
            return X, statuses, None
        return solve_each(self.solve, datas)


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
