"""Exact lexicographic optimum of equality and inequality stacks by a compiled active set.

The problem (levels ``i = 1..k``, highest first; an equality row has
``lower = upper = b``; ``√w`` the row weights of :class:`~prioik.hierarchy.Task`)::

    f_i* = min Σ_rows (√w_j · dist(A_j x, [lower_j, upper_j]))²   over  X_{i−1},
    X_i  = { x ∈ X_{i−1} : the level's violation vector equals its optimal one },

and then the **minimum-norm** point of ``X_k`` (on equality stacks: the answer of
``reference`` and of the extended Jacobian's eq. 18).

Each level runs a primal active set (lexls, Dimitrov, Sherikov & Wieber 2015; HCOD,
Escande, Mansard & Wieber 2014) in the rotated coordinates of the extended Jacobian's
nested pivoted QR: minimum-norm steps of the working set's equality-constrained least
squares (Householder LQ, no SVD), a ratio test, multiplier tests; the level's violated and
equality rows are then fixed and rotate every row below. The kernel is the C++ core
(``prioik._core.ActiveSetSolver``), one call per solve, nothing allocated per solve.

Options: ``rcond`` (rank threshold ``rcond ‖A_i‖_F``, hard rows ``rcond ‖a_j‖``),
``primal_tol``, ``dual_tol``, ``max_iter``, ``warm_start``, ``kernel`` (:data:`OPTIONS`).

Statuses: ``optimal`` when every level's multiplier test passed with every rank decision
clear of the ambiguity band, or, for a level the kernel flags (:class:`Detail`'s
``ambiguous_path_levels``, ``near_ambiguous_levels``, ``near_release_levels``,
``held_off_bound_levels``; ``diagnostics.stalled_levels``), when the answer passes the
core's certificate, part of the solve (``check_lexicographic``'s verdict, after at most
:data:`REFINE_ROUNDS` re-solves at :data:`REFINE` times the tolerances; a rejected
answer carries the verdict, ``verification.method == "solver"``, for the verification
stage to demote). ``approximate`` with ``diagnostics.reason`` at an ambiguous rank
decision (``ambiguous_levels``), a rejected certificate, a precision-limited level or the
iteration cap (``capped_levels``); ``failed`` on non-finite values. ``infeasible_levels``
names the levels with ``f_i* > 0``, ``equilibrated_levels`` those solved rescaled.

Warm start (:class:`Prepared`): each level starts from the last solve's working set;
when the last answer fixed no inequality row at a violation, the equality rows and the
rows it held are first solved by one nested QR, and that point is returned
(:attr:`Detail.equality_first`) only when its multipliers prove it optimal.

The algorithm, its hard cases, tolerances and complexity: ``docs/active-set.md``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import partial
from types import SimpleNamespace
from typing import Any

import numpy as np

from prioik.hierarchy import (
    AMBIGUITY,
    DEFAULT_CERTIFICATE_TOL,
    NEAR_AMBIGUITY,
    X_PRECISION,
    StackData,
    StackLayout,
    TaskStack,
    ambiguity_reason,
    check_lexicographic,
)
from prioik.hierarchy.analysis import LevelCheck

from . import contract
from .base import (
    Capabilities,
    CoreInputError,
    Diagnostics,
    Fault,
    FormulationError,
    Outcome,
    Status,
    Verification,
    solve_equilibrated,
)
from .options import Option, rcond_option, validate_options

try:
    from prioik._core import ACTIVE_SET_CODES as _CORE_CODES
    _core_error = ""
except ImportError as exc:  # pragma: no cover - built by pip install
    _CORE_CODES = None
    _core_error = f"{type(exc).__name__}: {exc}"
#: the C++ kernel's return codes and level flags (prioik._core.ACTIVE_SET_CODES)
_codes: Any = SimpleNamespace(**_CORE_CODES) if _CORE_CODES is not None else None
#: the kernel's codes of a clean solve (module constants: read once, not per call)
_SOLVED_CLEAN, _SOLVED_INFEASIBLE, _SOLVED_OTHER, _NOT_TRIED = (
    (_codes.SOLVED_CLEAN, _codes.SOLVED_INFEASIBLE, _codes.SOLVED_OTHER, _codes.NOT_TRIED)
    if _codes is not None else (-1, -1, -1, -2))

_NEAR_AMBIGUITY = NEAR_AMBIGUITY
#: the kernel's level flags after which the answer is certified
#: (:meth:`Prepared._certify_flagged`): flag, :class:`Detail` field of the flagged levels
#: (``stalled_levels``: :attr:`~prioik.formulations.base.Diagnostics.stalled_levels`), and why
#: such a level may not be optimal
_CERTIFIED_FLAGS = (
    (_codes.FLAG_AMBIGUOUS_PATH if _codes is not None else -1, "ambiguous_path_levels",
     f"passed through an ambiguous rank decision (a pivot within {AMBIGUITY:g}x of its "
     f"threshold) before settling"),
    (_codes.FLAG_NEAR_RELEASE if _codes is not None else -1, "near_release_levels",
     "ended with a held row inside its bound by less than its release tolerance "
     "(releasing it may lower the level)"),
    (_codes.FLAG_HELD_OFF_BOUND if _codes is not None else -1, "held_off_bound_levels",
     "kept a row off its bound (within the dual tolerance) held at the bound for the "
     "levels below (it may block a direction they need)"),
    (_codes.FLAG_NEAR_AMBIGUOUS if _codes is not None else -1, "near_ambiguous_levels",
     f"settled on a rank decision within {_NEAR_AMBIGUITY:g}x of the ambiguity band (a "
     f"pivot within {_NEAR_AMBIGUITY * AMBIGUITY:g}x of its threshold)"),
    (_codes.FLAG_STALLED if _codes is not None else -1, "stalled_levels",
     "kept changing its working set without a step that moved (a cycle of rounding: "
     "its multipliers and steps disagree) and settled where it stood"),
)
#: the flags whose rejected answer is solved again (:meth:`Prepared._refined`): their
#: rows' treatment scales with the tolerances
_REFINED_KEYS = ("near_release_levels", "held_off_bound_levels")

#: ``primal_tol`` and ``dual_tol`` of the refining solve over the solver's
#: (:meth:`Prepared._refined`)
REFINE = 1e-2

#: how many times a rejected answer is refined (:meth:`Prepared._refined`), each at
#: :data:`REFINE` times the last tolerances: a row off its bound by less than the dual
#: tolerance stays held until that tolerance is below its distance
REFINE_ROUNDS = 2

NAME = "hierarchical_active_set"
DESCRIPTION = ("exact lexicographic optimum of equality and inequality stacks: compiled "
               "active set per level on the nested pivoted QR (warm-startable)")
CAPABILITIES = Capabilities(equalities=True, inequalities=True, weights=True,
                            needs_mass_matrix=False, exact=True)
OPTIONS = {
    "rcond": rcond_option("‖A_i‖_F (soft and fixed rows), rcond·‖a_j‖ (hard rows)"),
    "primal_tol": Option(1e-10, "float", "relative bound tolerance: a row is violated when "
                         "outside by more than primal_tol·(‖a_j‖‖x‖ + |bound|) "
                         "(a box row: primal_tol·(|a_jc|(|x_c| + 1) + |bound|))",
                         minimum=0.0, maximum=1.0, exclusive_maximum=True),
    "dual_tol": Option(1e-12, "float", "relative tolerance on the sign of a hard row's "
                       "multiplier", minimum=0.0, maximum=1.0, exclusive_maximum=True),
    "max_iter": Option(500, "int", "iteration cap of each level (status 'approximate' "
                       "naming the level when hit)", minimum=1),
    "warm_start": Option(True, "bool", "prepared solver: start each level from the last "
                         "solve's working set, and when it held no inequality row try "
                         "the equality rows' own solution first (False: every solve "
                         "cold)"),
    "kernel": Option("auto", "str", "the compiled kernel: 'cpp' (prioik._core."
                     "ActiveSetSolver, core/src/active_set*.cpp); 'auto' (cpp)",
                     choices=("auto", "cpp")),
}



@dataclass(slots=True)
class Detail:
    """``hierarchical_active_set``'s own record (``sol.diagnostics.detail``).

    Attributes:
        level_violation: Each level's optimal violation ``f_i*`` (squared residual).
        warm_start: The solve started from the last solve's working sets.
        equality_first: The equality-first try of the warm start gave the answer.
        ambiguous_path_levels: Levels that passed through an ambiguous rank decision
            before settling (the answer was then certified).
        near_release_levels: Levels that ended with a held row inside its bound within
            its release tolerance.
        held_off_bound_levels: Levels that kept a row off its bound held at it.
        near_ambiguous_levels: Levels that settled on a near-ambiguous rank decision.
        refined_primal_tol: ``primal_tol`` of the refining solve that gave the answer
            (``None``: not refined).
        refined_dual_tol: Its ``dual_tol``.
        refined_from: Why the first answer was rejected, when refined.
    """

    level_violation: np.ndarray
    warm_start: bool
    equality_first: bool = False
    ambiguous_path_levels: list[int] | None = None
    near_release_levels: list[int] | None = None
    held_off_bound_levels: list[int] | None = None
    near_ambiguous_levels: list[int] | None = None
    refined_primal_tol: float | None = None
    refined_dual_tol: float | None = None
    refined_from: str | None = None

def _clean_diagnostics(n: int, k: int, warm_start: bool, snapshot: tuple) -> Diagnostics:
    """The :class:`~prioik.formulations.Diagnostics` of a clean solve of a layout of
    ``n`` unknowns and ``k`` levels from what it left (:meth:`Prepared.solve_checked`):
    ``snapshot`` is ``(values, infeasible, equality_first)``, ``values`` the kernel's
    answer copied by ``ActiveSetSolver.snapshot`` — ``x`` (``n``), ``res``, ``w2``,
    ``ranks``, ``over`` (``k`` each), ``iterations`` (``k + 1``), the integers as exact
    doubles — and ``infeasible`` whether a level has ``f_i* > 0`` (its ``over`` flag
    set)."""
    values, infeasible, first = snapshot
    w2, ranks, over, iterations = (values[n + k:n + 2 * k], values[n + 2 * k:n + 3 * k],
                                   values[n + 3 * k:n + 4 * k], values[n + 4 * k:])
    return Diagnostics(ranks=ranks.astype(np.int64), iterations=iterations.astype(np.int64),
                       infeasible_levels=np.flatnonzero(over).tolist() if infeasible else (),
                       detail=Detail(w2, warm_start, first))


def _core_module():
    """``prioik._core`` (the compiled C++ core), or a FormulationError saying why not."""
    if _CORE_CODES is None:  # pragma: no cover - built by pip install
        raise FormulationError(f"{NAME} needs prioik's compiled core (prioik._core): "
                               f"{_core_error}; reinstall prioik with `pip install -e .`")
    import prioik._core as core
    return core


def solve(stack: TaskStack, **options) -> Outcome:
    """The lexicographic optimum of ``stack`` (a cold solve): :class:`Prepared` for the
    stack's layout, then its :meth:`Prepared.solve` (see the module docstring)."""
    opts = validate_options(NAME, OPTIONS, options, stack.n)
    return Prepared(stack.layout, FORMULATION.settings_of(opts)).solve(stack.data)


class Prepared(contract.Prepared):
    """The active-set solver prepared for one layout: workspaces allocated once, and the
    working set of every level kept from one solve to the next.

    A :meth:`solve` is one compiled call on the data's arrays (rows weighed by ``√w``
    into the workspace, the boundary check in the same pass, the level-by-level active
    set, the minimum-norm tie-break and the per-level residuals). With
    ``warm_start=True`` (default) each level first tries last solve's working set
    (see the module docstring); the answer is the same optimum either way.

    Safe to use from one thread at a time (the registry's
    :class:`~prioik.formulations.PreparedSolver` enforces it).

    Args:
        layout: The stack layout (equality and inequality tasks).
        settings: :data:`FORMULATION`'s settings (every option of :data:`OPTIONS`,
            validated).
        refine_rounds: How many times a rejected flagged answer is re-solved at finer
            tolerances (:meth:`_refined`; :data:`REFINE_ROUNDS`).

    Raises:
        FormulationError: the compiled core is not importable here.
    """

    #: its solve_checked is the compiled kernel's, reading the data's arrays
    compiled = True

    def __init__(self, layout: StackLayout, settings: Any, *,
                 refine_rounds: int | None = None) -> None:
        self.layout = layout
        self.settings = settings
        self.rcond = float(settings.rcond)
        self.primal_tol = float(settings.primal_tol)
        self.dual_tol = float(settings.dual_tol)
        self.max_iter = int(settings.max_iter)
        self.warm_start = bool(settings.warm_start)
        #: the compiled kernel: "cpp"
        self.kernel = "cpp"
        # the equality-first try needs the equality rows' solve (an inequality-only stack
        # has none to try)
        self._try_first = self.warm_start and bool(layout.row_is_equality.any())
        self._n, self._k = layout.n, layout.k
        self._prepare_cpp(layout)
        #: how many more times a rejected answer is re-solved (:meth:`_refined`)
        self._refine = REFINE_ROUNDS if refine_rounds is None else refine_rounds
        #: the solver that re-solves it (:meth:`_refiner`), prepared at the first
        #: refinement and kept
        self._refining: Prepared | None = None

    def _prepare_cpp(self, layout: StackLayout) -> None:
        """The C++ kernel's solver (``prioik._core.ActiveSetSolver``): its workspace is
        allocated here; the answer's parts are views of its result, read by name."""
        core = _core_module()
        k = layout.k
        self._cpp = cpp = core.ActiveSetSolver(
            layout.n, np.ascontiguousarray(layout.starts, dtype=np.int64),
            np.ascontiguousarray(layout.row_is_equality, dtype=np.int8), self.rcond,
            self.primal_tol, self.dual_tol, self.max_iter, self.warm_start)
        self._solve_data, self._equality_first_data = cpp.solve, cpp.equality_first
        self.warm_state, self.warm_valid = cpp.warm_state, cpp.warm_valid
        self._x, self._w2, self._res = cpp.x, cpp.w2, cpp.res
        self._margins, self._iterations, self._flags = cpp.margins, cpp.iterations, cpp.flags
        self._ranks, self._over = cpp.ranks[:k], cpp.over[:k]
        # a clean answer, copied in one (_clean_diagnostics): x (n), res (k), ...
        self._snapshot, self._snapshot_size = cpp.snapshot, cpp.snapshot_size
        self._x_res = layout.n + k
        self._diagnostics_of = partial(_clean_diagnostics, layout.n, k, self.warm_start)
        # the certificate of flagged answers (_certify): its workspace allocated here
        self._certificate = core.Certificate(
            layout.n, np.ascontiguousarray(layout.starts, dtype=np.int64),
            np.ascontiguousarray(layout.row_is_equality, dtype=np.int8),
            DEFAULT_CERTIFICATE_TOL)

    def _summary_values(self) -> tuple[float, float, float, float, float]:
        """The kernel's summary: ``‖x‖``, cap (``1``) or non-finite (``-1``) flag,
        whether ``‖x‖`` exceeds the precision limit, the count of ambiguous or flagged
        levels, of unresolved box rows."""
        cpp = self._cpp
        return (cpp.x_norm, cpp.cap_or_nonfinite, float(cpp.large), float(cpp.ambiguous),
                float(cpp.unresolved))

    def _ambiguous_count(self) -> float:
        return float(self._cpp.ambiguous)

    def _equality_first_answered(self) -> bool:
        return self._cpp.equality_first_state == 1.0

    def reset(self) -> None:
        """Forget the kept working sets (the next solve starts cold)."""
        self._cpp.reset()

    def solve(self, data: StackData, settings: Any = None) -> Outcome:
        """Solve one stack of the layout (its data; the registry checked the layout).

        Raises:
            TaskStackError: a value is not valid (naming the task, level and row).
        """
        out = self.solve_checked(data)
        if isinstance(out, tuple):
            x, residuals, (diagnostics_of, values) = out
            return Outcome(x, Status.OPTIMAL, diagnostics_of(values), residuals=residuals,
                           checked=True)
        return out

    def solve_checked(self, data: StackData) -> tuple | Outcome:
        """:meth:`solve`, its common case (settled, finite, every rank decision clear,
        every box row resolved) as the tuple ``(x, residuals, snapshot)`` of a checked
        ``optimal`` :class:`Outcome` without the object, its diagnostics built from
        ``snapshot`` when read (:func:`_clean_diagnostics`; see
        :meth:`prioik.formulations.contract.Prepared.solve_checked`).

        Raises:
            TaskStackError: as :meth:`solve`.
        """
        A, b, lower, upper, sw = data.A, data.b, data.lower, data.upper, data.sqrt_weight
        try:
            # the module doc's warm start; the kernel declines it (NOT_TRIED) when the
            # last answer fixed a row at a violation (params[11])
            code = (self._equality_first_data(A, b, lower, upper, sw)
                    if self._try_first else _NOT_TRIED)
            first = code != _NOT_TRIED
            if not first:
                code = self._solve_data(A, b, lower, upper, sw)
            if code == _SOLVED_OTHER and self.warm_start and self._ambiguous_count() > 0.0:
                # rank decisions ambiguous or flagged: the answer may depend on the path
                # (two certified answers may differ within the tolerances), so the warm
                # solver gives the cold one (the working sets kept are then its own)
                self.reset()
                first = False
                code = self._solve_data(A, b, lower, upper, sw)
        except CoreInputError:
            # the C++ kernel's binding refused a value: the data's own check names the
            # task, level and row at fault (else the binding's error, naming the array)
            self.reset()
            data.check()
            raise
        return self.answer(code, first, data)

    def answer(self, code: int, first: bool, data: StackData) -> tuple | Outcome:
        """The answer of the kernel's last solve of ``data``, which returned ``code``
        (``first``: the equality-first try gave it), read from the kernel's result: the
        clean tuple of :meth:`solve_checked`, an equilibrated re-solve of a level of
        extreme scale, or :meth:`_outcome` (capped, non-finite, ambiguous, flagged —
        certified, refined —, unresolved). :meth:`solve_checked` ends here, and so does a
        :class:`prioik.robots.ControlStep` step that ran the kernel in C++.

        Raises:
            TaskStackError: a value of ``data`` is not valid (naming the task, level and
                row).
        """
        if code == _SOLVED_CLEAN or code == _SOLVED_INFEASIBLE:
            # the answer in one copy (the snapshot the Solution keeps): x and the
            # residuals views of it, the diagnostics built from it when read
            values = np.empty(self._snapshot_size)
            self._snapshot(values)
            n = self._n
            return (values[:n], values[n:self._x_res],
                    (self._diagnostics_of, (values, code == _SOLVED_INFEASIBLE, first)))
        if code == _codes.NOT_SOLVED:
            self.reset()
            data.check()     # names the task, level and row at fault
            # a level of extreme scale (‖A_i‖_F beyond 1e100, or below 1e-100 with a
            # non-zero entry): solved rescaled, diagnostics.equilibrated_levels names it
            out = solve_equilibrated(self.solve, data, "the rows' values overflow float64 "
                                     "(‖√W_i A_i‖_F² is not finite or underflows): scale "
                                     "the tasks or their weights")
            if out.residuals is not None:   # f_i* in the user's units too
                out.diagnostics.detail.level_violation = out.residuals * out.residuals
            return out
        return self._outcome(data)

    def _outcome(self, data: StackData) -> Outcome:
        """The answer of a solve that is not clean (capped, non-finite, ambiguous,
        unresolved, or of an ``‖x‖`` at which float64 may limit a level), read from the
        kernel's summary: ``optimal`` only when none of these holds (the precision of a
        large ``‖x‖`` is the verification stage's check)."""
        k = self._k
        x, w2, residuals = self._x.copy(), self._w2.copy(), self._res.copy()
        xn, flag, _large, ambiguous, unresolved = self._summary_values()
        diagnostics = Diagnostics(
            ranks=self._ranks.copy(), iterations=self._iterations.copy(),
            margins=self._margins.copy(), infeasible_levels=np.flatnonzero(self._over).tolist(),
            detail=Detail(w2, self.warm_start, self._equality_first_answered()))
        if flag < 0.0:
            self.reset()
            return Outcome(x, Status.FAILED, diagnostics, residuals=residuals).fail(
                "the active-set iterations produced non-finite values", "non_finite")
        reasons = []
        if flag > 0.0:
            flags = self._flags
            capped = np.flatnonzero(flags == _codes.FLAG_ITERATION_CAP).tolist()
            lv = capped[0]
            names = tuple(self.layout.names[lv]) if lv < k else ("minimum-norm",)
            what = (f"level {lv} ({', '.join(names)})" if lv < k
                    else "the minimum-norm tie-break")
            message = (f"iteration cap max_iter={self.max_iter} hit at {what}: its "
                       f"working set did not settle (degenerate or cycling); the "
                       f"levels above are optimal and x keeps their optimum, but it "
                       f"is not certified optimal from that level down")
            diagnostics.capped_levels = capped
            diagnostics.fault = Fault(lv, names, "iteration_cap", message)
            reasons.append(message)
        levels = np.flatnonzero(self._margins <= AMBIGUITY).tolist() if ambiguous else []
        if levels:
            # a pivot within AMBIGUITY of its threshold: rounding may flip the decision
            # and with it x by O(1) (the shared rule of hierarchy.linalg)
            if levels[0] < k:
                reasons.append(ambiguity_reason([i for i in levels if i < k]))
            if levels[-1] == k:
                reasons.append(f"rank decision ambiguous at the minimum-norm tie-break (a "
                               f"pivot within {AMBIGUITY:g}x of its threshold)")
            diagnostics.ambiguous_levels = levels
        flags = self._flags
        flagged = {}
        if ambiguous:
            for value, key, _ in _CERTIFIED_FLAGS:
                at = np.flatnonzero(flags == value).tolist()
                if at:
                    flagged[key] = at
        rejected: list[str] = []
        if flagged and not levels and flag == 0.0:
            rejected = self._certify_flagged(data, x, flagged, diagnostics)
            if (rejected and self._refine > 0
                    and any(key in flagged for key in _REFINED_KEYS)):
                refined = self._refined(data, flagged, rejected[0])
                if refined is not None:
                    return refined
        if unresolved:
            reasons.append(f"‖x‖ = {xn:.3g}: x's coordinates are known to about "
                           f"{X_PRECISION * xn:.2g}, coarser than the primal tolerance of "
                           f"{int(unresolved)} box row(s) near a bound (whether they are "
                           f"held is rounding)")
        if rejected:
            # the core's certificate rejected the answer: its verdict, for the
            # verification stage to apply (or the solver's own reasons, when it is not
            # optimal anyway)
            diagnostics.verification = Verification(
                "solver", False, DEFAULT_CERTIFICATE_TOL, reason="; ".join(rejected))
            if reasons:
                reasons.extend(rejected)
        diagnostics.reason = "; ".join(reasons)
        status = Status.APPROXIMATE if (flag > 0.0 or reasons) else Status.OPTIMAL
        return Outcome(x, status, diagnostics, residuals=residuals, checked=True)

    def _refiner(self) -> Prepared:
        """The refining solver: this layout's, cold, at :data:`REFINE` times these
        tolerances, refining once less itself; prepared at the first refinement (a
        one-shot solve that needs none does not pay it) and kept for the next."""
        if self._refining is None:
            self._refining = Prepared(self.layout, dataclasses.replace(
                self.settings, primal_tol=self.primal_tol * REFINE,
                dual_tol=self.dual_tol * REFINE, warm_start=False),
                refine_rounds=self._refine - 1)
        return self._refining

    def _refined(self, data: StackData, flagged: dict[str, list[int]], rejected: str
                 ) -> Outcome | None:
        """The stack re-solved cold at :data:`REFINE` times ``primal_tol`` and
        ``dual_tol``, after the certificate rejected an answer with a near-release level
        or a row held off its bound: the release tolerance scales with ``primal_tol``,
        so a row kept held inside its bound is released, and the dual one with
        ``dual_tol``, so a row held off its bound may be fixed at its violation. The
        refining solver (:meth:`_refiner`, prepared once) refines its own rejected answer once
        more while rounds are left (:data:`REFINE_ROUNDS`). The refined answer is returned
        only when it is ``optimal`` and passes the certificate (:meth:`_certify`)
        (:attr:`Detail.refined_primal_tol` and :attr:`Detail.refined_dual_tol`: the
        tolerances that found it; the first answer's reason in
        :attr:`Detail.refined_from`); ``None`` otherwise."""
        tol, dual = self.primal_tol * REFINE, self.dual_tol * REFINE
        out = self._refiner().solve(data)
        if out.status != Status.OPTIMAL:
            return None
        # a refining solve that was flagged itself certified its answer already
        own = out.diagnostics.verification
        if own is not None and not own.ok:
            return None
        if own is None and not self._certify(data, out.x, False)[0]:
            return None
        detail = out.diagnostics.detail
        # a refining solve refined once more reports its own (finer) tolerances
        if detail.refined_primal_tol is None:
            detail.refined_primal_tol, detail.refined_dual_tol = tol, dual
        detail.refined_from = rejected
        detail.warm_start = self.warm_start
        out.diagnostics.verification = Verification("solver", True, DEFAULT_CERTIFICATE_TOL)
        for key in _REFINED_KEYS:
            if key in flagged:
                setattr(detail, key, flagged[key])
        return out

    def _certify(self, data: StackData, x: np.ndarray, minimum_norm: bool
                 ) -> tuple[bool, LevelCheck | None]:
        """:func:`~prioik.hierarchy.check_lexicographic`'s verdict on ``x`` (at its default
        tolerance and rank threshold; the tie-break too when ``minimum_norm``) by the
        core's certificate (``prioik._core.Certificate``, prepared with the solver: no
        step of a solve leaves C++): ``(True, None)``, or ``(False, the first failing
        level's check)``. A stack with a level of extreme scale (the solver equilibrates
        those before it gets here) is checked by the Python oracle."""
        cert = self._certificate
        if not cert.check(data.A, data.b, data.lower, data.upper, data.sqrt_weight, x,
                          minimum_norm):
            report = check_lexicographic(data, x, minimum_norm=minimum_norm)
            return report.ok, report.first_failure
        if cert.ok:
            return True, None
        lv = cert.failing_level
        return False, LevelCheck(
            lv, tuple(self.layout.names[lv]) if lv < self._k else ("minimum-norm",),
            float(cert.residual[lv]), float(cert.projected_gradient[lv]),
            float(cert.scale[lv]), False, value_gap=float(cert.value_gap[lv]))

    def _certify_flagged(self, data: StackData, x: np.ndarray, flagged: dict[str, list[int]],
                         diagnostics: Diagnostics) -> list[str]:
        """The reasons against ``x`` when the kernel flagged levels (``flagged``: a
        field of :data:`_CERTIFIED_FLAGS` → the levels, recorded in ``diagnostics``; the
        verdict in ``diagnostics.verification`` when it passes): an ambiguous rank
        decision before a level's clear last step (``FLAG_AMBIGUOUS_PATH``: the working
        set it led to may not be the level's optimum), a held soft row inside its bound
        within its release tolerance (``FLAG_NEAR_RELEASE``: releasing it may lower the
        level by more than the tolerance shows), a row off its bound kept held for the
        levels below (``FLAG_HELD_OFF_BOUND``: it may block a direction they need), or a
        clear rank decision within ``NEAR_AMBIGUITY`` times the ambiguity band
        (``FLAG_NEAR_AMBIGUOUS``), or a level that stopped a cycle of working sets
        without a step that moved (``FLAG_STALLED``). The answer is checked by the
        certificate (:meth:`_certify`: :func:`~prioik.hierarchy.check_lexicographic`'s
        verdict at its default tolerance, the minimum-norm tie-break too when it was
        flagged); ``[]`` when it passes, unless a
        level on an ambiguous path has rows spanning more than :data:`CERTIFIABLE_SPREAD`
        in scale (the certificate cannot vouch for it: the reason names the level)."""
        k = self._k
        tie_break = any(k in levels for levels in flagged.values())
        ok, bad = self._certify(data, x, tie_break)
        detail = diagnostics.detail
        for key, at in flagged.items():
            if key == "stalled_levels":
                diagnostics.stalled_levels = at
            else:
                setattr(detail, key, at)
        spread = _row_scale_spread(data, flagged.get("ambiguous_path_levels", ()))
        if ok and not spread:
            diagnostics.verification = Verification("solver", True, DEFAULT_CERTIFICATE_TOL)
            return []
        if ok:
            # the certificate's tolerances are relative to the terms of a level's rows:
            # where the largest dwarf the rows that carry its violation it passes answers
            # it cannot resolve (an independent check, exact arithmetic: of ten levels of
            # spreads 2e5-7e8 that said 'optimal' 1.4e-6 to 0.18 of max(1, value) above
            # their optimum, it rejects seven and passes three, up to 3.9e-5 above)
            where = ", ".join(f"level {i} ({ratio:.1e})" for i, ratio in spread)
            return [f"passed through an ambiguous rank decision at {where}, whose rows' "
                    f"weighted norms span more than {CERTIFIABLE_SPREAD:g}x: the "
                    f"certificate, relative to the terms of a level's rows, cannot vouch "
                    f"for its smallest"]
        assert bad is not None              # (a verdict that is not ok names its level)
        where = (f"level {bad.level} ({', '.join(bad.tasks)})" if bad.level < k
                 else "the minimum-norm tie-break")
        diagnostics.ambiguous_levels = sorted(set().union(*flagged.values()))
        rejects = f"the certificate rejects {where} ({bad.failure(DEFAULT_CERTIFICATE_TOL)})"
        reasons = []
        for _, key, why in _CERTIFIED_FLAGS:
            if key in flagged:
                named = ", ".join(f"level {i}" if i < k else "the tie-break"
                                  for i in flagged[key])
                reasons.append(f"{named} {why}")
        return [f"{'; '.join(reasons)}, and {rejects}"]


#: the largest spread of a level's weighted row norms ``max/min √w_j ‖a_j‖`` (non-zero
#: rows) over which :meth:`Prepared._certify_flagged` takes the certificate's word for a
#: level that passed through an ambiguous rank decision (an independent generator's
#: answers that the certificate passes above their optimum: levels spanning 6.8e6-4.1e8)
CERTIFIABLE_SPREAD = 1e5


def _row_scale_spread(data: StackData, levels) -> list[tuple[int, float]]:
    """The levels of ``levels`` (``k``, the tie-break, skipped) whose weighted row norms
    span more than :data:`CERTIFIABLE_SPREAD`, with their spread."""
    out = []
    starts = data.layout.starts
    for i in levels:
        if i >= data.layout.k:
            continue
        a, b = int(starts[i]), int(starts[i + 1])
        norms = data.sqrt_weight[a:b] * np.linalg.norm(data.A[a:b], axis=1)
        norms = norms[norms > 0]
        if norms.size and norms.max() > CERTIFIABLE_SPREAD * norms.min():
            out.append((i, float(norms.max() / norms.min())))
    return out


#: the plugin (:mod:`prioik.formulations.registry`)
FORMULATION = contract.Formulation(NAME, DESCRIPTION, CAPABILITIES, OPTIONS, Prepared)
