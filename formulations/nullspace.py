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

import numpy as np

from prioik.hierarchy import (
    AMBIGUITY,
    DEFAULT_RCOND,
    StackData,
    StackLayout,
    TaskStack,
    ambiguity_reason,
    ambiguous_decision,
    rank_threshold,
)

from ._compiled import _core, resolve_kernel, solve_compiled, solve_rescaled
from .base import (
    Capabilities,
    Diagnostics,
    FormulationError,
    Outcome,
    ReportVariant,
    Status,
    in_original_units,
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


def check_nonnegative(**values: float) -> None:
    """Raise :class:`FormulationError` for an option that is not a finite number ≥ 0."""
    for key, val in values.items():
        try:
            v = float(val)
        except (TypeError, ValueError):
            raise FormulationError(f"{key} must be a number ≥ 0, got {val!r}") from None
        if not np.isfinite(v) or v < 0:
            raise FormulationError(f"{key} must be a finite number ≥ 0, got {val}")


def truncated_svd(M: np.ndarray, tol: float, report: bool = False):
    """``(U_r, s_r, V_r)`` of ``M`` keeping the singular values ``σ > tol``.

    ``U_r`` is ``m × r``, ``V_r`` is ``n × r``. An empty ``M`` (or ``tol ≤ 0`` with a
    zero scale) gives ``r = 0``. With ``report``, a fourth value says whether the
    decision was ambiguous (:func:`hierarchy.ambiguous_decision`).
    """
    m, n = M.shape
    if M.size == 0:
        out = np.zeros((m, 0)), np.zeros(0), np.zeros((n, 0))
        return (*out, False) if report else out
    u, s, vt = np.linalg.svd(M, full_matrices=False)
    r = int(np.count_nonzero(s > tol)) if tol > 0 else 0
    out = u[:, :r], s[:r], vt[:r].T
    return (*out, ambiguous_decision(s, tol)) if report else out


def generalized_inverse(M: np.ndarray, tol: float, damping: float = 0.0
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``M^#`` and the orthonormal bases of ``M``'s kept row and column spaces.

    ``M^# = V diag(σ/(σ² + λ)) Uᵀ`` over the singular values ``σ > tol``; with
    ``damping = λ = 0`` that is the truncated pseudo-inverse ``M⁺``.

    Returns:
        ``(M^#, V_r, U_r)``; ``V_r V_rᵀ = M⁺ M`` is the projector onto the kept row space.
    """
    U, s, V = truncated_svd(M, tol)
    gain = s / (s * s + damping) if damping > 0 else 1.0 / s
    return (V * gain) @ U.T, V, U


#: Steps of :func:`refinement` a level's least-squares step gets: one left a level of a
#: task at 6e-10 beside rows of 0.5 and zero rows with targets 6e-6 off, two reach ε.
REFINEMENT_STEPS = 2


def refinement(M: np.ndarray, c: np.ndarray, y: np.ndarray, Vt: np.ndarray,
               keep: np.ndarray, sv: np.ndarray) -> np.ndarray:
    """The correction of a least-squares step ``y ≈ M_r⁺ c`` computed from an SVD
    ``M = U Σ Vᵀ`` (rank rule ``keep``): ``V_r Σ_r⁻² V_rᵀ Mᵀ (c − M y)``, one step of
    iterative refinement, for ``B`` stacks at once (``B × m × d`` ``M``, ``B × m × 1``
    ``c``, ``B × d × 1`` ``y``, ``B × p × d`` ``Vt``, ``B × p`` ``keep`` and ``sv``).

    An SVD is backward stable in norm only: a level's rows far smaller than its norm
    (zero or tiny rows beside large ones, tasks decades apart) are read with errors of
    ``ε ‖M‖``, and where their targets are large their residuals leak into ``U_rᵀ c``
    and the step by ``ε ‖M‖ ‖c‖ / σ²``. ``Mᵀ (c − M y)`` is formed row by row, each
    row's term on its own scale (a zero row adds exactly nothing), so the correction
    removes that error; on a level whose rows share one scale it is at rounding level.
    """
    r = c - M @ y                                                      # B × m × 1
    g = Vt @ (np.swapaxes(M, 1, 2) @ r)                                # B × p × 1
    safe = np.where(keep, sv, 1.0)
    return np.swapaxes(Vt, 1, 2) @ (np.where(keep, 1.0 / (safe * safe), 0.0)[:, :, None] * g)


def project_levels(A: np.ndarray, b: np.ndarray, X: np.ndarray, N: np.ndarray,
                   tol: np.ndarray, damping: float = 0.0, reproject: bool = True
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One level of the recursion (module docstring) for ``B`` stacks at once:
    ``Ĵ_i = A N_{i-1}``, the step ``x_i = x_{i-1} + N_{i-1} Ĵ_i^# (b − A x_{i-1})``
    (without the leading ``N_{i-1}`` when not ``reproject``) and
    ``N_i = N_{i-1} − V Vᵀ`` with ``V`` re-orthonormalised in ``range(N_{i-1})``.

    The one implementation of a level: :func:`solve` runs it on one stack (``B = 1``),
    :func:`solve_batch` on many, ``sns`` for its unbounded step — so every path makes
    the same rank decisions with the same arithmetic (a stacked SVD or product is the
    per-matrix one), and ``solve`` equals ``solve_batch`` bit for bit. Singular values
    are masked by the rank rule instead of truncated, so stacks of different ranks
    share the arrays.

    Args:
        A, b: ``B × m × n`` rows and ``B × m`` targets of the level (weighted).
        X, N: ``B × n`` answers and ``B × n × n`` projectors so far (not modified).
        tol: ``B`` absolute rank thresholds (:func:`hierarchy.rank_threshold` of each
            ``A``; ``≤ 0``: the level keeps nothing).
        damping: ``λ`` of the damped inverse (0: pseudo-inverse).
        reproject: Multiply the step by ``N_{i-1}`` once more.

    Returns:
        ``(X_i, N_i, keep, σ, ambiguous)``: ``keep`` (``B × p``) masks the kept singular
        values ``σ`` of ``Ĵ_i`` (sorted, largest first); ``ambiguous`` (``B``) flags a
        singular value within :data:`hierarchy.AMBIGUITY` of ``tol``.
    """
    count, m, n = A.shape
    if m == 0:
        return (X, N, np.zeros((count, 0), dtype=bool), np.zeros((count, 0)),
                np.zeros(count, dtype=bool))
    J = A @ N
    U, sv, Vt = np.linalg.svd(J, full_matrices=False)
    t = tol[:, None]
    keep = (sv > t) & (t > 0)
    near = ((sv > t / AMBIGUITY) & (sv <= t * AMBIGUITY) & (t > 0)).any(axis=1)
    safe = np.where(keep, sv, 1.0)
    gain = np.where(keep, safe / (safe * safe + damping) if damping > 0 else 1.0 / safe, 0.0)
    residual = b[:, :, None] - A @ X[:, :, None]                       # B × m × 1
    step = np.swapaxes(Vt, 1, 2) @ (gain[:, :, None] * (np.swapaxes(U, 1, 2) @ residual))
    if damping == 0:
        for _ in range(REFINEMENT_STEPS):
            step = step + refinement(J, residual, step, Vt, keep, sv)
    if reproject:
        step = N @ step                                            # N_{i-1} Ĵ_i^# = Ĵ_i^#
    X = X + step[:, :, 0]
    # V in range(N_{i-1}) to rounding (module docstring): the kept singular vectors come
    # first (σ sorted), so the QR's leading columns span N V_r; the others are masked
    V, _ = np.linalg.qr(N @ np.swapaxes(Vt, 1, 2))                  # B × n × p
    V = V * keep[:, None, :]
    return X, N - V @ np.swapaxes(V, 1, 2), keep, sv, near         # N_i = N_{i-1} − Ĵ⁺Ĵ


def project_level(A: np.ndarray, b: np.ndarray, x: np.ndarray, N: np.ndarray, tol: float,
                  damping: float = 0.0, reproject: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """:func:`project_levels` on one stack: ``(x_i, N_i, σ_kept, ambiguous)``."""
    X, N, keep, sv, near = project_levels(A[None], b[None], x[None], N[None],
                                          np.array([tol]), damping, reproject)
    return X[0], N[0], sv[0][keep[0]], bool(near[0])


def solve(stack: TaskStack, **options) -> Outcome:
    """Recursive null-space projection: :class:`Prepared` for the stack's layout, then
    its :meth:`Prepared.solve` (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, opts).solve(stack.data)


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

class Prepared:
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
        options: Every option of :data:`OPTIONS`, validated.
    """

    def __init__(self, layout: StackLayout, options: dict) -> None:
        self.layout = layout
        self.kernel = resolve_kernel(options["kernel"])
        check_nonnegative(damping=options["damping"], rcond=options["rcond"])
        self.damping = float(options["damping"])
        self.rcond = float(options["rcond"])
        self.reproject = bool(options["reproject"])
        self.compiled = self.kernel == "cpp"
        if self.compiled:
            self._core = _core.NullspaceSolver([int(s) for s in layout.starts], layout.n,
                                               rcond=self.rcond, damping=self.damping,
                                               reproject=self.reproject)

    def solve(self, data: StackData) -> Outcome:
        """Solve one stack of the layout.

        Raises:
            TaskStackError: a value is not finite (naming the task, level and row).
        """
        if not self.compiled:
            stack, levels = data.as_stack().equilibrated()
            out = solve_readable(stack, damping=self.damping, rcond=self.rcond,
                                 reproject=self.reproject)
            return in_original_units(out, data, levels) if levels else out
        res = solve_compiled(self._core, data)
        if not res.solved:
            return solve_rescaled(self.solve, data)
        levels = np.flatnonzero(res.margins <= AMBIGUITY).tolist() if res.ambiguous else []
        out = _outcome(res.x, res.ranks.copy(), res.min_pivots.tolist(), self.damping, "cpp",
                       res.flops, levels, res.residuals)
        out.diagnostics.margins = np.asarray(res.margins).copy()
        return out

    def solve_batch(self, datas: list[StackData]) -> tuple[np.ndarray, list[str]]:
        """Many stacks of the layout: ``(X, statuses)`` (:func:`solve_batch` on the
        numpy kernel, one compiled solve after the other on the cpp kernel)."""
        if not self.compiled:
            stacks = [d.as_stack().equilibrated()[0] for d in datas]
            return solve_batch(stacks, damping=self.damping, rcond=self.rcond,
                               reproject=self.reproject)
        outs = [self.solve(d) for d in datas]
        return np.array([o.x for o in outs]), [o.status for o in outs]


# ------------------------------------------------------------------------ reports
#: rows of prioik's reports beside the default one (prioik.benchmarks.variants)
REPORT_VARIANTS = (
    ReportVariant("numpy", {"kernel": "numpy"}, reports=("bench",),
                  note="the readable numpy SVD recursion (the default, kernel='auto', is the "
                       "compiled C++ core)"),
    ReportVariant("damped", {"damping": 0.05}, reports=("scenario",),
                  note="the SR (damped least-squares) inverse on every level, λ = 0.05 "
                       "(λ = 1e-2 left q̈ peaks of 355 in the incompatible fencing run, 0.05 "
                       "keeps them at 65)"),
    ReportVariant("damping=0.01", {"damping": 1e-2}, reports=("properties",),
                  note="the damped least-squares inverse with the λ of eq. 27's rows"),
    ReportVariant("reproject=False", {"reproject": False}, reports=("roundoff",),
                  note="the textbook projector step, without the extra N_{i-1}"),
)
