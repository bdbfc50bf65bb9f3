"""Records shared by every formulation: what it supports, what it returns."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Any

import numpy as np

from prioik.errors import PrioikError
from prioik.hierarchy import (
    DEFAULT_CERTIFICATE_TOL,
    TaskStackError,
    level_residuals,
    level_scale,
    precision_limited_levels,
    precision_reason,
)


class Status(str, Enum):
    """What a formulation stands behind (:attr:`Solution.status`).

    String-valued: ``Status.OPTIMAL == "optimal"``, and it writes as its value in files
    and tables.

    Attributes:
        OPTIMAL: The lexicographic optimum, up to the formulation's tolerances.
        APPROXIMATE: A soft or regularised answer, or one a check could not stand behind
            (:attr:`Diagnostics.reason` says why).
        FAILED: No answer (``x`` is NaN, or breaks a hard level); :attr:`Diagnostics.fault`
            says why.
    """

    OPTIMAL = "optimal"
    APPROXIMATE = "approximate"
    FAILED = "failed"

    def __str__(self) -> str:
        return self.value

    def __format__(self, format_spec: str) -> str:
        return format(self.value, format_spec)


#: Values of :attr:`Solution.status` (the :class:`Status` values).
STATUSES = tuple(s.value for s in Status)

#: Values of the ``verify`` argument of :func:`prioik.prepare` and :func:`prioik.solve`.
VERIFY_MODES = ("auto", "none", "certificate", "lower_point")

class FormulationError(PrioikError, ValueError):
    """A formulation cannot be used as asked: unknown name, not installed here,
    an unknown option, or a required option (e.g. ``mass_matrix``) missing."""


class CoreInputError(FormulationError):
    """An array given to the compiled core (``prioik._core``) that it cannot take: not a
    C-contiguous float64 array of the layout's shape, empty, or holding a value that is
    not finite (or a ``√w ≤ 0``); the message names the array and the entry."""


class ConcurrentUseError(PrioikError, RuntimeError):
    """A prepared solver was called from a second thread while a solve was running
    (a prepared solver owns its workspaces: use one per thread)."""


@dataclass(frozen=True)
class Capabilities:
    """What a formulation can take.

    Attributes:
        equalities: Equality tasks ``A x ≈ b``.
        inequalities: Inequality tasks ``lower ≤ A x ≤ upper``.
        weights: Several weighted tasks in one level.
        needs_mass_matrix: Requires the option ``mass_matrix=M``.
        exact: Returns the lexicographic optimum of equality stacks (up to the
            solver's tolerance); ``False`` for methods with algorithmic error or
            soft-priority approximations.
    """

    equalities: bool = True
    inequalities: bool = False
    weights: bool = True
    needs_mass_matrix: bool = False
    exact: bool = True


#: Values of :attr:`Fault.code`.
FAULT_CODES = ("certificate", "lower_point", "hard_level", "iteration_cap", "non_finite",
               "solver_error", "infeasible", "shape")


@dataclass(frozen=True, slots=True)
class Fault:
    """What is wrong with an answer that is not ``optimal`` when a level is at fault.

    Attributes:
        level: The level at fault (``k``, the number of levels: the minimum-norm
            tie-break; ``None``: no level is named).
        tasks: The names of its tasks (``("minimum-norm",)`` for the tie-break).
        code: What failed, one of :data:`FAULT_CODES`: ``"certificate"`` (the answer
            fails :func:`~prioik.hierarchy.check_lexicographic`), ``"lower_point"``
            (the exact active set reaches a lower value, :func:`~.verification.lower_point`),
            ``"hard_level"`` (a hard level left violated, :func:`~prioik.hierarchy.hard`),
            ``"iteration_cap"``, ``"non_finite"``, ``"solver_error"`` (a back-end raised
            or found no answer), ``"infeasible"`` (hard inequalities that cannot hold
            together), ``"shape"`` (an answer of the wrong length).
        message: The fault in words.
    """

    level: int | None
    tasks: tuple[str, ...]
    code: str
    message: str


@dataclass(frozen=True, slots=True)
class LowerPoint:
    """A witness against an answer (:func:`~.verification.lower_point`): the exact active
    set's value at the first level where it is lower.

    Attributes:
        level: That level.
        value: The answer's squared weighted residual there.
        reached: The active set's.
    """

    level: int
    value: float
    reached: float


@dataclass(frozen=True, slots=True)
class Verification:
    """What the verification stage (or a solver's own certificate) found.

    Attributes:
        method: ``"certificate"`` (:func:`~prioik.hierarchy.check_lexicographic`),
            ``"lower_point"`` (the certificate, then :func:`~.verification.lower_point`),
            ``"precision"`` (only :func:`~prioik.hierarchy.precision_limited_levels`
            was read), or ``"solver"`` (the formulation's own certificate inside its
            solve: ``hierarchical_active_set``'s flagged steps).
        ok: The answer passed.
        tol: The certificate's relative tolerance.
        worst_relative: The certificate's worst relative residual (NaN when not run).
        lower_point: The witness that refuted the answer, if one did.
        reason: Why a solver's own certificate rejected its answer (``method ==
            "solver"``; the verification stage adds it to :attr:`Diagnostics.reason`
            when it demotes the answer).
    """

    method: str
    ok: bool
    tol: float = DEFAULT_CERTIFICATE_TOL
    worst_relative: float = float("nan")
    lower_point: LowerPoint | None = None
    reason: str = ""


@dataclass(frozen=True, slots=True)
class CheckRequest:
    """How an answer is to be certified (a plugin sets it on its :class:`Outcome`).

    Under ``verify="auto"`` the verification stage certifies an ``optimal`` answer
    (:func:`~.verification.certify`, with the comparison of
    :func:`~.verification.lower_point`) only when ``auto`` (the plugin's own option
    asked, e.g. ``check=True``); under ``"certificate"`` and
    ``"lower_point"`` every ``optimal`` answer is certified, with these settings.

    Attributes:
        auto: Certify under ``verify="auto"``.
        minimum_norm: Check the minimum-norm tie-break too (``False`` for a formulation
            without it).
        metric: The tie-break's metric ``W`` (``xᵀ W x``; ``None``: the identity).
    """

    auto: bool = True
    minimum_norm: bool = True
    metric: np.ndarray | None = None


@dataclass(slots=True)
class Diagnostics:
    """What a solve found, typed (:attr:`Solution.diagnostics`).

    Per-level arrays have one entry per level (``None``: the formulation does not report
    it). Level lists are sorted level indices (``k``: the minimum-norm tie-break;
    ``()`` when none).

    Attributes:
        ranks: Rank each level added (the rank rule's decision).
        iterations: Iterations of each level (active-set and QP formulations).
        margins: Each level's rank-decision margin (smallest ratio of a pivot to its
            threshold; at most :data:`~prioik.hierarchy.AMBIGUITY` is ambiguous).
        infeasible_levels: Levels whose optimum leaves a violation (``f_i* > 0``) of
            their inequality rows.
        capped_levels: Levels that hit an iteration cap.
        stalled_levels: Levels that stopped a cycle of working sets.
        ambiguous_levels: Levels whose rank decision was within the ambiguity band.
        equilibrated_levels: Levels solved rescaled by a power of two
            (:meth:`~prioik.hierarchy.TaskStack.equilibrated`).
        precision_limited_levels: Levels whose values float64 cannot give at ``‖x‖``
            (:func:`~prioik.hierarchy.precision_limited_levels`).
        hard_violated_levels: Hard levels left violated (:func:`~prioik.hierarchy.hard`).
        reason: Why the status is not ``optimal``, in words (``""`` when it is).
        fault: The level at fault, when one is named.
        verification: What the verification stage (or the solver's own certificate)
            found; ``None`` when nothing was checked.
        detail: The formulation's own record, a small dataclass documented in its
            plugin module (e.g. :class:`~prioik.formulations.extended_jacobian.Detail`).
    """

    ranks: np.ndarray | None = None
    iterations: np.ndarray | None = None
    margins: np.ndarray | None = None
    infeasible_levels: Sequence[int] = ()
    capped_levels: Sequence[int] = ()
    stalled_levels: Sequence[int] = ()
    ambiguous_levels: Sequence[int] = ()
    equilibrated_levels: Sequence[int] = ()
    precision_limited_levels: Sequence[int] = ()
    hard_violated_levels: Sequence[int] = ()
    reason: str = ""
    fault: Fault | None = None
    verification: Verification | None = None
    detail: Any = None

    def add_reason(self, reason: str) -> None:
        """Append ``reason`` to :attr:`reason` (``"; "``-separated; ``""`` adds nothing)."""
        if not reason:
            return
        self.reason = f"{self.reason}; {reason}" if self.reason else reason

    def as_dict(self) -> dict[str, Any]:
        """Every field as a plain dict, the detail record's fields under ``"detail"``
        (for JSON files and tables)."""
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in ("fault", "verification") and v is not None:
                v = {g.name: getattr(v, g.name) for g in fields(v)}
                if isinstance(v.get("lower_point"), LowerPoint):
                    lp = v["lower_point"]
                    v["lower_point"] = {"level": lp.level, "value": lp.value,
                                        "reached": lp.reached}
            elif f.name == "detail" and v is not None:
                v = {g.name: getattr(v, g.name) for g in fields(v)}
            out[f.name] = v
        return out


@dataclass(slots=True)
class Outcome:
    """What a plugin's ``solve`` returns; the registry turns it into a :class:`Solution`.

    Attributes:
        x: The solution (``n``).
        status: A :class:`Status` (or its string value).
        diagnostics: What the solve found (its ``detail``: the plugin's own record).
        residuals: Per-level residuals when the plugin computed them itself (a compiled
            kernel does, from the same rows); ``None``: the registry computes them.
        checked: The plugin guarantees that ``x`` is a finite float64 vector of the
            right length and ``residuals`` are given (the registry then skips its own
            checks: the compiled paths verify both in the kernel).
        check: How the verification stage is to certify the answer under
            ``verify="auto"`` (``None``: it is not certified then); see
            :class:`CheckRequest`.
        explain: Called by the verification stage when it demotes the answer: the
            formulation's own account of why (added to :attr:`Diagnostics.reason`;
            computed only then, outside the timed solve).
    """

    x: np.ndarray
    status: str = Status.OPTIMAL
    diagnostics: Diagnostics = field(default_factory=Diagnostics)
    residuals: np.ndarray | None = None
    checked: bool = False
    check: CheckRequest | None = None
    explain: Callable[[], str] | None = None

    def fail(self, message: str, code: str = "solver_error", level: int | None = None,
             tasks=()) -> Outcome:
        """This outcome made ``failed`` (``x`` NaN) with a :class:`Fault`; returns it."""
        self.x = np.full(np.asarray(self.x).shape, np.nan)
        self.status = Status.FAILED
        self.diagnostics.fault = Fault(level, tuple(tasks), code, message)
        self.diagnostics.add_reason(message)
        return self


#: A clean answer's diagnostics, not yet built (:attr:`Solution.diagnostics`): a function
#: and the values of one solve it reads (copies, the solve's own), ``diagnostics_of(values)``
#: giving the :class:`Diagnostics` on first read.
DiagnosticsSnapshot = tuple[Callable[[Any], "Diagnostics"], Any]


class Solution:
    """The answer of a formulation to a task stack.

    Attributes:
        x: The solution, shape ``(n,)`` (NaN-free unless ``status == "failed"``).
        formulation: Name of the formulation that produced it.
        options: Options it was called with.
        status: A :class:`Status`: ``OPTIMAL``, ``APPROXIMATE`` (a soft or regularised
            answer, or one the verification could not stand behind) or ``FAILED``;
            it compares equal to its string (``sol.status == "optimal"``). Why it is
            not optimal: :attr:`Diagnostics.reason`.
        residuals: Per level, ``‖A_i x − b_i‖`` plus inequality violation (weighted).
        time_s: Wall time of the formulation's solve alone (``perf_counter``).
        diagnostics: What the solve and the verification found (:class:`Diagnostics`;
            the formulation's own record in ``diagnostics.detail``). A compiled
            formulation's clean answer builds it at its first read, from the values of
            its own solve (kept when the solver solves again).
        verify_time_s: Wall time of the verification stage (``0.0`` when nothing was
            verified, e.g. ``verify="none"``).
    """

    __slots__ = ("x", "formulation", "options", "status", "residuals", "time_s",
                 "verify_time_s", "_diagnostics", "_snapshot")

    def __init__(self, x: np.ndarray, formulation: str, options: dict[str, Any],
                 status: Status, residuals: np.ndarray, time_s: float,
                 diagnostics: Diagnostics | None = None, verify_time_s: float = 0.0
                 ) -> None:
        self.x = x
        self.formulation = formulation
        self.options = options
        self.status = status
        self.residuals = residuals
        self.time_s = time_s
        self.verify_time_s = verify_time_s
        self._diagnostics = diagnostics
        #: the diagnostics not yet built (:data:`DiagnosticsSnapshot`), or ``None``
        self._snapshot: DiagnosticsSnapshot | None = None

    @property
    def diagnostics(self) -> Diagnostics:
        """What the solve and the verification found (:class:`Diagnostics`)."""
        d = self._diagnostics
        if d is None:
            snapshot = self._snapshot
            d = Diagnostics() if snapshot is None else snapshot[0](snapshot[1])
            self._diagnostics, self._snapshot = d, None
        return d

    @diagnostics.setter
    def diagnostics(self, value: Diagnostics) -> None:
        self._diagnostics, self._snapshot = value, None

    @property
    def ok(self) -> bool:
        """``True`` unless the status is ``"failed"``."""
        return self.status != Status.FAILED

    @property
    def detail(self) -> Any:
        """The formulation's own record (``diagnostics.detail``)."""
        return self.diagnostics.detail

    @property
    def flops(self) -> int | None:
        """The solve's floating-point operations as the formulation's compiled kernel
        counted them (its detail record's ``flops``: the closed forms on the compiled
        core); ``None`` when it does not count them."""
        return getattr(self.diagnostics.detail, "flops", None)

    def __repr__(self) -> str:
        x = np.asarray(self.x)
        head = np.array2string(x[:4], precision=4, separator=", ")[1:-1]
        more = f", … ({x.size} values)" if x.size > 4 else ""
        res = np.array2string(np.asarray(self.residuals), precision=2, separator=", ",
                              threshold=8)
        return (f"Solution({self.formulation!r}, {self.status}, x=[{head}{more}], "
                f"residuals={res}, {1e6 * self.time_s:.1f} µs)")

    def _repr_html_(self) -> str:
        from html import escape
        d = self.diagnostics
        rows = [("formulation", self.formulation), ("status", str(self.status)),
                ("x", f"{np.asarray(self.x).size} values, ‖x‖ = "
                      f"{float(np.linalg.norm(self.x)):.4g}"),
                ("residuals", np.array2string(np.asarray(self.residuals), precision=3)),
                ("time", f"{1e6 * self.time_s:.1f} µs (verification "
                         f"{1e6 * self.verify_time_s:.1f} µs)"),
                ("options", repr(self.options)), ("reason", d.reason or "—"),
                ("detail", type(d.detail).__name__ if d.detail is not None else "—")]
        body = "".join(f"<tr><th style='text-align:left'>{escape(k)}</th>"
                       f"<td>{escape(v)}</td></tr>" for k, v in rows)
        return f"<table><caption>Solution</caption>{body}</table>"


def in_original_units(out: Outcome, data, levels: list[int]) -> Outcome:
    """``out``, solved on the stack ``data`` with ``levels`` equilibrated
    (:meth:`~prioik.hierarchy.TaskStack.equilibrated`: each of those levels' values
    multiplied by a power of two), with its residuals read on ``data`` itself, the user's
    units, and :attr:`Diagnostics.equilibrated_levels` naming the levels."""
    if out.residuals is not None and np.isfinite(out.x).all():
        with np.errstate(over="ignore", invalid="ignore"):
            out.residuals = level_residuals(data, out.x)
    out.diagnostics.equilibrated_levels = list(levels)
    return out


def solve_equilibrated(solve: Callable[[Any], Outcome], data, message: str) -> Outcome:
    """A prepared solver's answer for ``data`` whose kernel refused a level of extreme
    scale: ``solve`` on :meth:`~prioik.hierarchy.TaskStack.equilibrated` (those levels
    rescaled by a power of two: the same optimum and tie-break), read in the user's units
    (:func:`in_original_units`).

    Raises:
        TaskStackError: ``message``, when no level's entries are extreme (rescaling
            cannot help: the weights or targets are at fault).
    """
    stack, levels = data.as_stack().equilibrated()
    if not levels:
        raise TaskStackError(message)
    return in_original_units(solve(stack.data), data, levels)


def precision_holds(diagnostics: Diagnostics, data, x: np.ndarray) -> bool:
    """Whether float64 gives every level's values at ``x`` to the certificate's
    tolerance (:func:`~prioik.hierarchy.precision_limited_levels`: a huge ``‖x‖`` along
    directions a level does not take can make them rounding). When not, the levels go in
    :attr:`Diagnostics.precision_limited_levels` and the reason in
    :attr:`Diagnostics.reason`; ``data`` is the stack's
    :class:`~prioik.hierarchy.StackData`. Called by the verification stage
    (:class:`~prioik.formulations.PreparedSolver`), which demotes the answer."""
    levels = precision_limited_levels(data, x)
    if not levels:
        return True
    diagnostics.precision_limited_levels = levels
    diagnostics.add_reason(precision_reason(levels, level_scale(x)))
    return False

