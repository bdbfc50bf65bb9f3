"""Saturation in the Null Space (SNS): strict priorities under hard joint bounds.

Flacco, De Luca & Khatib (ICRA 2012, IROS 2012; IEEE T-RO 2015, the multi-task
algorithm), the same at velocity and at acceleration level: box bounds on ``x``
(``q̇`` or ``q̈``) and a priority list of equality tasks ``J_k x = b_k``.

Bounds: the stack's *first level* holds inequality tasks whose rows are single-column
rows ``lower ≤ c·x_j ≤ upper`` (``c ≠ 0``; :func:`prioik.robots.joint_limit_bounds`
writes them): hard, never violated. Every other level holds equality tasks. Any other
inequality task raises :class:`~prioik.hierarchy.UnsupportedTaskError` naming it. A
stack without inequality tasks is solved as recursive null-space projection.

Per task, the step of null-space projection is taken; when it leaves the bounds, the
most critical joint is saturated at its bound and the task is solved again in the
null space left, keeping the best feasible *task scaling* ``s ∈ [0, 1]`` (T-RO
Algorithm 2); when the task's rank would drop, the best scaled solution is kept, and
when no scale is feasible the task is dropped (``s = 0``). The returned ``x`` is always
within the bounds (to ``bound_tolerance``). The whole target ``b_k`` of a level is
scaled (the stack does not separate the drift from the command); the projector is
updated after a dropped task too, so a lower task never disturbs a higher one; a
stack without bounds gets ``nullspace``'s answer bit for bit.

Statuses: ``optimal`` when every level reached its least-squares residual without
bounds (then ``x`` is the exact lexicographic optimum with the bounds on top);
``approximate`` when a task was scaled, dropped or its residual grew
(:attr:`Detail.scaled_tasks`), or at an ambiguous rank decision
(``diagnostics.reason``). Its own record: :class:`Detail`.

Two kernels (option ``kernel``): ``"cpp"`` (the default; :class:`Prepared`) runs the
algorithm in the C++ core over one workspace (``prioik._core.SnsSolver``): the
unbounded step is ``nullspace``'s compiled level (a row-pivoted LQ of ``J_k P``, the rank
rule on its pivots), every pseudo-inverse of the saturation rounds a row-pivoted LQ
applied to vectors, and :attr:`Detail.flops` counts the solve's floating-point operations;
``"numpy"`` is :func:`solve_readable`, the SVD version as written, the oracle the tests
hold the compiled kernel to.

The algorithm step by step: ``docs/formulations.md``.
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
    UnsupportedTaskError,
    ambiguity_reason,
    rank_threshold,
)

from . import contract
from ._compiled import (
    _core,
    resolve_kernel,
    solve_compiled,
    solve_readable_equilibrated,
    solve_rescaled,
)
from ._numerics import check_nonnegative, project_level, truncated_svd
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
    """``sns``'s own record (``sol.diagnostics.detail``).

    Attributes:
        task_scaling: One scale ``s`` per equality level (``1``: met in full).
        scaled_tasks: The levels scaled or dropped (their task names, comma-joined).
        saturated: Per level, the saturated columns.
        iterations: Saturation rounds per equality level.
        bounds_level: The level of the bounds (``0``) or ``None``.
        first_task_level: The first level of equality tasks.
        kernel: ``"cpp"`` or ``"numpy"``.
        flops: Floating-point operations of the solve, counted in the compiled kernel
            (``None`` on the numpy path).
    """

    task_scaling: list[float]
    scaled_tasks: list[str]
    saturated: list
    iterations: list[int]
    bounds_level: int | None
    first_task_level: int
    kernel: str = "numpy"
    flops: int | None = None


NAME = "sns"
DESCRIPTION = ("Saturation in the Null Space (Flacco, De Luca, Khatib 2012/2015): strict "
               "priorities, first-level box bounds as hard limits, optimal task scaling")
#: ``inequalities``: only box bounds on single columns at the first level (see the
#: module docstring); ``exact``: equality stacks are solved exactly (null-space
#: projection), and with bounds the status says when the answer is not the optimum.
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "rcond": rcond_option("‖J_k‖_F"),
    "bound_tolerance": Option(1e-9, "float", "a bound counts as met within "
                              "tol·max(1, |bound|)", minimum=0.0),
    "max_saturations": Option(None, "int", "cap on saturated joints per task (default: "
                              "the number of bounded columns)", minimum=0, optional=True),
    "kernel": Option("auto", "str", "'cpp': the compiled C++ core (prioik._core, row-pivoted "
                     "LQs); 'numpy': the readable SVD version; 'auto': cpp where built",
                     choices=("auto", "cpp", "numpy")),
}


# --------------------------------------------------------------------- bounds
def split_bounds(stack: TaskStack) -> tuple[np.ndarray, np.ndarray, int | None]:
    """Box bounds on ``x`` from the first level's inequality tasks.

    Returns:
        ``(lower, upper, bounds_level)``: per column, ``∓inf`` where unbounded;
        ``bounds_level`` is ``0`` when the first level holds the bounds, else ``None``.

    Raises:
        UnsupportedTaskError: an inequality task below the first level, a first-level
            inequality row that is not a single-column row, or a first level that
            mixes bounds and equality tasks.
        FormulationError: bounds of one column that do not intersect.
    """
    n = stack.n
    lower, upper = np.full(n, -np.inf), np.full(n, np.inf)
    for i, level in enumerate(stack.levels):
        for t in level:
            if t.is_equality:
                if i == 0 and level.has_inequality:
                    raise UnsupportedTaskError(
                        "the first level holds the joint bounds; put equality tasks in "
                        "the levels below it", formulation=NAME, task=t.name, level=i)
                continue
            if i != 0:
                raise UnsupportedTaskError(
                    "inequality tasks are taken only as box bounds on single columns at "
                    "the first level (the hard joint bounds)", formulation=NAME,
                    task=t.name, level=i)
            nz = t.A != 0.0
            counts = nz.sum(axis=1)
            bad = np.flatnonzero(counts != 1)
            if bad.size:
                raise UnsupportedTaskError(
                    f"row {int(bad[0])} has {int(counts[bad[0]])} nonzero entries; bounds "
                    "must be single-column rows lower ≤ c·x_j ≤ upper", formulation=NAME,
                    task=t.name, level=i)
            cols = np.argmax(nz, axis=1)
            c = t.A[np.arange(t.m), cols]
            lo, up = t.bounds()
            lo_x = np.where(c > 0, lo / c, up / c)
            up_x = np.where(c > 0, up / c, lo / c)
            np.maximum.at(lower, cols, lo_x)
            np.minimum.at(upper, cols, up_x)
    bad = np.flatnonzero(lower > upper)
    if bad.size:
        j = int(bad[0])
        raise FormulationError(f"sns: the bounds of column {j} do not intersect "
                               f"({lower[j]} > {upper[j]})")
    has = any(not t.is_equality for t in stack.levels[0])
    return lower, upper, (0 if has else None)


def _scale_interval(a: np.ndarray, c: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                    tol: np.ndarray, free: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Interval of ``s`` with ``lo ≤ c + s a ≤ hi`` (per column, then intersected)
    and each column's upper end (``+inf`` where unconstrained). A saturated column
    (``free`` false) has ``a = 0`` exactly (``M`` acts in ``P̄``, whose rows of the
    saturated columns are zero): it takes no part whatever the rounding left in it."""
    small = ~free | (np.abs(a) <= 1e-14 * max(1.0, float(np.abs(a).max(initial=0.0))))
    with np.errstate(divide="ignore", invalid="ignore"):
        s_lo = np.where(a > 0, (lo - c) / a, (hi - c) / a)
        s_hi = np.where(a > 0, (hi - c) / a, (lo - c) / a)
    inside = (c >= lo - tol) & (c <= hi + tol)
    s_lo = np.where(small, np.where(inside, -np.inf, np.inf), np.nan_to_num(s_lo, nan=-np.inf))
    s_hi = np.where(small, np.where(inside, np.inf, -np.inf), np.nan_to_num(s_hi, nan=np.inf))
    return float(s_lo.max(initial=-np.inf)), float(s_hi.min(initial=np.inf)), s_hi


#: Scales within this factor of ``max(1, |s|)`` of each other are one: joints that leave
#: their bounds at such scales leave them together (the lowest column goes first), and a
#: scaling interval ``[s_min, s_t]`` that much narrower than empty is the point ``s_t``.
#: Both ties are exact when the levels above left ``x`` at a vertex of the box, and
#: rounding alone would otherwise decide them.
SATURATION_TIE = 1e-9


def _tie(s: float) -> float:
    """:data:`SATURATION_TIE` at the scale ``s`` (0 where ``s`` is not finite)."""
    return SATURATION_TIE * max(1.0, abs(s)) if np.isfinite(s) else 0.0


def _most_critical(cand: np.ndarray, col_hi: np.ndarray) -> int:
    """The column of ``cand`` (ascending) whose bound is left first as ``s`` grows (the
    smallest ``col_hi``), the lowest of those within :data:`SATURATION_TIE` of it."""
    first = float(col_hi.min())
    return int(cand[np.flatnonzero(col_hi <= first + _tie(first))[0]])


def _pinv(M: np.ndarray, tol: float) -> tuple[np.ndarray, int]:
    U, s, V = truncated_svd(M, tol)
    return (V / s) @ U.T, int(s.size)


def check_saturation_options(rcond, bound_tolerance, max_saturations) -> None:
    """Raise :class:`FormulationError` for ``rcond`` or ``bound_tolerance`` not a finite
    number ≥ 0, or ``max_saturations`` neither ``None`` nor an integer ≥ 0."""
    check_nonnegative(rcond=rcond, bound_tolerance=bound_tolerance)
    if max_saturations is not None and (not isinstance(max_saturations, (int, np.integer))
                                        or max_saturations < 0):
        raise FormulationError(f"max_saturations must be an integer ≥ 0 or None, "
                               f"got {max_saturations!r}")


# ---------------------------------------------------------------------- solve
def solve(stack: TaskStack, **options) -> Outcome:
    """SNS on ``stack``: :class:`Prepared` for the stack's layout, then its
    :meth:`Prepared.solve` (``kernel`` picks the compiled or the readable path)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


def solve_readable(stack: TaskStack, *, rcond: float = DEFAULT_RCOND,
                   bound_tolerance: float = 1e-9, max_saturations: int | None = None
                   ) -> Outcome:
    """SNS on ``stack`` in numpy (``kernel="numpy"``), the readable oracle of the compiled
    kernel; see the module docstring.

    Raises:
        UnsupportedTaskError, FormulationError: see :func:`split_bounds`; an option
            that is not a finite number ≥ 0.
    """
    check_saturation_options(rcond, bound_tolerance, max_saturations)
    lower, upper, bounds_level = split_bounds(stack)
    n = stack.n
    bounded = np.isfinite(lower) | np.isfinite(upper)
    cap = int(bounded.sum()) if max_saturations is None else int(max_saturations)
    tol = float(bound_tolerance) * np.maximum(1.0, np.maximum(
        np.nan_to_num(np.abs(lower), posinf=0.0), np.nan_to_num(np.abs(upper), posinf=0.0)))
    eye = np.eye(n)
    x = np.zeros(n)              # may lie outside the box (braking bounds): see the drop case
    P = eye.copy()
    levels = stack.levels[1:] if bounds_level == 0 else stack.levels
    first = 1 if bounds_level == 0 else 0
    scaling, scaled, saturated, iterations, ambiguous = [], [], [], [], []
    exact = True

    def feasible(v):
        return bool(np.all(v >= lower - tol) and np.all(v <= upper + tol))

    for li, level in enumerate(levels):
        J, b = level.A, level.b
        thr = rank_threshold(J, float(rcond))
        # the unbounded step and the next projector: null-space projection's own level
        x_free, P_next, sv, near = project_level(J, b, x, P, thr)
        if near:
            ambiguous.append(li + first)
        rank_avail = int(sv.size)
        res_free = float(np.linalg.norm(J @ x_free - b))
        s_level, rounds = 1.0, 0
        sat: list[int] = []
        if rank_avail == 0:
            x_new = x
        elif feasible(x_free):
            x_new = x_free
        else:
            JP = J @ P
            JP_pinv, _ = _pinv(JP, thr)
            free = np.ones(n, dtype=bool)             # every column starts free
            xN = np.zeros(n)
            best = (-np.inf, None)
            x_new = None
            Pbar, Mp, B_pinv, sat_idx = P, JP_pinv, None, np.zeros(0, dtype=int)
            while True:
                rounds += 1
                if sat_idx.size:
                    corr = (eye - Mp @ J) @ (B_pinv @ (xN[sat_idx] - x[sat_idx]))
                else:
                    corr = np.zeros(n)
                a = Mp @ b
                cvec = x - Mp @ (J @ x) + corr
                xs = cvec + a
                if feasible(xs):
                    x_new, s_level = xs, 1.0
                    break
                s_min, s_max, col_hi = _scale_interval(a, cvec, lower, upper, tol, free)
                s_t = min(1.0, s_max)
                if s_min <= s_t + _tie(s_t) and s_t >= 0.0 and s_t > best[0]:
                    best = (s_t, cvec + s_t * a)
                # most critical free bounded joint: the first to leave its bounds as s grows
                viol = (xs < lower - tol) | (xs > upper + tol)
                cand = np.flatnonzero(free & bounded & viol)
                if cand.size == 0 or len(sat) >= cap:
                    break
                j = _most_critical(cand, col_hi[cand])
                free[j] = False
                xN[j] = np.clip(xs[j], lower[j], upper[j])
                sat.append(j)
                sat_idx = np.array(sat, dtype=int)
                Bm = P[sat_idx, :]                      # the rows of (I − W) P_{k-1}
                B_pinv, _ = _pinv(Bm, 1e-12 * max(1.0, float(np.linalg.norm(Bm))))
                Pbar = P - B_pinv @ Bm
                Mp, r = _pinv(J @ Pbar, thr)
                if r < rank_avail:
                    break
            if x_new is None:
                if best[1] is not None and best[0] > 0.0:
                    s_level, x_new = best
                else:
                    s_level, x_new = 0.0, None
        if x_new is None or not feasible(x_new):   # dropped (or round-off)
            s_level, x_new = 0.0, (x if feasible(x) else np.clip(x, lower, upper))
        res = float(np.linalg.norm(J @ x_new - b))
        if res > res_free + 1e-9 * max(1.0, float(np.linalg.norm(b))):
            exact = False
        x = x_new
        scaling.append(float(s_level))
        if s_level < 1.0:
            scaled.append(", ".join(level.names))
        saturated.append(sat)
        iterations.append(rounds)
        P = P_next
    if not levels and not feasible(x):
        x = np.clip(x, lower, upper)        # bounds alone: the box's minimum-norm point
    return _outcome(x, scaling, scaled, saturated, iterations, bounds_level, first,
                    ambiguous, exact, "numpy", None)


def _outcome(x, scaling, scaled, saturated, iterations, bounds_level, first, ambiguous,
             exact: bool, kernel: str, flops, residuals=None, margins=None) -> Outcome:
    """The answer with its diagnostics: ``optimal`` when every level reached its
    unbounded residual, none was scaled and no rank decision was ambiguous."""
    optimal = exact and not scaled and not ambiguous
    diagnostics = Diagnostics(ambiguous_levels=list(ambiguous), margins=margins,
                              detail=Detail(scaling, scaled, saturated, iterations,
                                            bounds_level, first, kernel, flops))
    if ambiguous:
        diagnostics.add_reason(ambiguity_reason(ambiguous))
    if scaled:
        diagnostics.add_reason(f"task scaling under the bounds: {'; '.join(scaled)}")
    elif not optimal and not ambiguous:
        diagnostics.add_reason("a level's residual grew under the bounds")
    return Outcome(x, Status.OPTIMAL if optimal else Status.APPROXIMATE, diagnostics,
                   residuals)


def check_bounds_layout(layout: StackLayout) -> int | None:
    """The layout's bounds level (``0`` when its first level holds inequality tasks, else
    ``None``), as :func:`split_bounds` reads it.

    Raises:
        UnsupportedTaskError: an inequality task below the first level, or a first level
            that mixes bounds and equality tasks.
    """
    has = False
    for i, level in enumerate(layout.levels):
        kinds = [kind for _, _, kind in level]
        for task, _, kind in level:
            if kind == "equality":
                if i == 0 and "inequality" in kinds:
                    raise UnsupportedTaskError(
                        "the first level holds the joint bounds; put equality tasks in "
                        "the levels below it", formulation=NAME, task=task, level=i)
                continue
            if i != 0:
                raise UnsupportedTaskError(
                    "inequality tasks are taken only as box bounds on single columns at "
                    "the first level (the hard joint bounds)", formulation=NAME,
                    task=task, level=i)
            has = True
    return 0 if has else None


class Prepared(contract.Prepared):
    """SNS prepared for one layout: options checked, the bounds level read from the
    layout, and on the compiled kernel (``kernel="cpp"``) the C++ solver with every
    workspace allocated once (``prioik._core.SnsSolver``; :attr:`Detail.flops` counts the
    solve's floating-point operations). ``kernel="numpy"`` is :func:`solve_readable`.

    Args:
        layout: The stack layout.
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).

    Raises:
        UnsupportedTaskError: see :func:`check_bounds_layout`.
        FormulationError: an option out of its range.
    """

    def __init__(self, layout: StackLayout, settings: Any) -> None:
        self.layout = layout
        self.kernel = resolve_kernel(settings.kernel)
        self.rcond = settings.rcond
        self.bound_tolerance = settings.bound_tolerance
        self.max_saturations = settings.max_saturations
        check_saturation_options(self.rcond, self.bound_tolerance, self.max_saturations)
        self.bounds_level = check_bounds_layout(layout)
        self.first = 1 if self.bounds_level == 0 else 0
        self._cpp = self.kernel == "cpp"
        if self._cpp:
            self._core = _core.SnsSolver(
                [int(s) for s in layout.starts], layout.n, rcond=float(self.rcond),
                bound_tolerance=float(self.bound_tolerance),
                max_saturations=-1 if self.max_saturations is None else
                int(self.max_saturations), bounds_level=self.bounds_level == 0)

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout.

        Raises:
            TaskStackError: a value is not finite (naming the task, level and row).
            UnsupportedTaskError, FormulationError: see :func:`split_bounds`.
        """
        if not self._cpp:
            return solve_readable_equilibrated(
                lambda stack: solve_readable(stack, rcond=self.rcond,
                                             bound_tolerance=self.bound_tolerance,
                                             max_saturations=self.max_saturations), data)
        res = solve_compiled(self._core, data, data.lower, data.upper)
        if res.bounds != 0:
            split_bounds(data.as_stack())         # raises, naming the task or column
            raise FormulationError(f"sns: the bounds rows are malformed at entry "
                                   f"{res.bad_entry}")   # pragma: no cover - split_bounds raised
        if not res.solved:
            return solve_rescaled(self.solve, data)
        return self._outcome(res)

    def _outcome(self, res) -> Outcome:
        levels = range(self.first, self.layout.k)
        n = self.layout.n
        scaling = res.task_scaling.tolist()
        counts = res.saturated_count.tolist()
        sat = res.saturated.reshape(self.layout.k, n)
        names = self.layout.names
        margins = res.margins
        scaled = [", ".join(names[i]) for i in levels if scaling[i] < 1.0]
        ambiguous = [i for i in levels if margins[i] <= AMBIGUITY]
        return _outcome(res.x, [scaling[i] for i in levels], scaled,
                        [sat[i, :counts[i]].tolist() for i in levels],
                        [int(v) for v in res.iterations[self.first:]], self.bounds_level,
                        self.first, ambiguous, bool(res.exact), "cpp", res.flops,
                        res.residuals, np.asarray(margins).copy())


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
