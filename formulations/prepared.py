"""Prepare once, solve many: a formulation bound to one stack layout.

:func:`prioik.prepare` validates the options once and lets the plugin allocate its
workspaces once; :meth:`PreparedSolver.solve` then takes any stack (or
:class:`~prioik.hierarchy.StackData`) of that layout. :func:`prioik.solve` is prepare +
solve, so the one-off and the prepared answers are the same computation.

Each formulation provides its own prepared solver, a subclass of
:class:`~prioik.formulations.contract.Prepared` built by its
:class:`~prioik.formulations.contract.Formulation`; its ``solve_checked(data)`` returns
either an ``Outcome`` or, for a clean answer the plugin's kernel checked itself (what
``Outcome(..., checked=True)`` means: finite, of the right length, residuals given,
``‖x‖`` below the precision limit) with the status ``optimal``, the tuple ``(x,
residuals, snapshot)``: the :class:`~prioik.formulations.Solution`'s diagnostics are
built from ``snapshot`` (:data:`~prioik.formulations.base.DiagnosticsSnapshot`, the
values of that solve) at their first read — a control loop that reads ``x`` alone pays
for no record.

After the timed solve, :meth:`PreparedSolver.solve` runs the **verification stage**
(its ``verify`` mode, :data:`~prioik.formulations.base.VERIFY_MODES`), timed apart
(:attr:`~prioik.formulations.Solution.verify_time_s`): the one place an ``optimal``
answer is demoted to ``approximate``.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from prioik.hierarchy import (
    DEFAULT_CERTIFICATE_TOL,
    StackData,
    StackLayout,
    TaskStack,
    TaskStackError,
    hard_violations,
    level_residuals,
)
from prioik.hierarchy.linalg import PRECISION_LIMIT_NORM

from .base import (
    VERIFY_MODES,
    CheckRequest,
    ConcurrentUseError,
    Diagnostics,
    Fault,
    FormulationError,
    Outcome,
    Solution,
    Status,
    Verification,
    precision_holds,
)
from .contract import Formulation, check_layout_support, check_support  # noqa: F401
from .options import validate_options
from .verification import certify, lower_point_solver

__all__ = ["BatchSolution", "PreparedSolver", "check_layout_support", "check_support"]

_clock = time.perf_counter
_OPTIMAL = Status.OPTIMAL


def _step_options(formulation: Formulation, n: int, given: dict) -> dict:
    options = formulation.options
    declared = {k: options[k] for k in given if k in options}
    unknown = sorted(set(given) - set(declared))
    if unknown:
        raise FormulationError(f"formulation {formulation.name!r} has no option "
                               f"{', '.join(unknown)}; its options: "
                               f"{', '.join(options) or 'none'}")
    return validate_options(formulation.name, declared, given, n)


@dataclass
class BatchSolution:
    """The answers of one formulation to many stacks of the same shape.

    Attributes:
        X: Solutions, one row per stack (``B × n``).
        statuses: One :class:`~prioik.formulations.Status` per stack.
        formulation: Name of the formulation.
        options: Options it was called with.
        time_s: Wall time of the whole batch (solve alone).
        batched: Whether the plugin's own batched kernel ran (else a loop of ``solve``).
    """

    X: np.ndarray
    statuses: list[Status]
    formulation: str
    options: dict[str, Any]
    time_s: float
    batched: bool

    @property
    def time_per_stack_s(self) -> float:
        """``time_s`` divided by the number of stacks."""
        return self.time_s / max(1, len(self.statuses))


class PreparedSolver:
    """A formulation prepared for one :class:`~prioik.hierarchy.StackLayout`.

    Made by :func:`prioik.prepare`; options are validated and workspaces allocated
    once. Safe to use from one thread at a time: a call while another thread's solve is
    running raises :class:`~prioik.formulations.ConcurrentUseError` (it never returns a
    wrong answer); use one prepared solver per thread.

    Each :meth:`solve` is the formulation's solve (timed: ``Solution.time_s``), then the
    verification stage (timed apart: ``Solution.verify_time_s``), the one place an
    ``optimal`` answer is demoted to ``approximate``; its ``verify`` mode is one of

    * ``"auto"`` (default): what the formulation asks — its own options (e.g.
      ``check=True``) decide whether the answer is certified
      (:func:`~.verification.certify`, with the exact active set's comparison,
      :func:`~.verification.lower_point`), a solver's own certificate
      (``hierarchical_active_set``'s flagged steps) is applied, and an answer at a huge
      ``‖x‖`` is demoted where float64 cannot give a level's values
      (:func:`precision_holds`);
    * ``"none"``: nothing is checked, nothing demoted (``verify_time_s == 0``);
    * ``"certificate"``: every ``optimal`` answer is checked by
      :func:`~prioik.hierarchy.check_lexicographic` (and as ``"auto"``'s precision
      and solver checks);
    * ``"lower_point"``: the certificate, then the comparison with the exact active set.

    The active-set solver of that comparison is prepared once per prepared solver (at
    its first use).

    Attributes:
        formulation: Registry name.
        layout: The layout it solves.
        options: Every option's value (validated; defaults filled in).
        settings: The same values as the formulation's typed settings
            (:attr:`~prioik.formulations.contract.Formulation.settings`), what its
            prepared solver was built with.
        verify: The verification mode.
        compiled: The plugin solves the data's arrays in a compiled kernel.
    """

    def __init__(self, formulation: Formulation, layout: StackLayout,
                 options: dict[str, Any], given: dict[str, Any], verify: str = "auto"
                 ) -> None:
        check_layout_support(formulation.name, formulation.capabilities, layout)
        self._hard = layout.hard
        self.verify = verify
        #: the exact active set of the lower-point comparison (prepared at first use)
        self._lower_solver: Any = None
        self.formulation = formulation.name
        self.layout = layout
        self.options = options
        self.settings = formulation.settings_of(options)
        self._given = dict(given)
        self._plugin = formulation
        self._lock = threading.Lock()
        self._n = layout.n
        self._sqrt_n = float(np.sqrt(layout.n))
        self._needs_mass_matrix = formulation.capabilities.needs_mass_matrix
        self._impl = formulation.prepare(layout, self.settings)
        # a plugin's solve_checked may give its verified answers as a tuple (no Outcome)
        self._impl_solve = self._impl.solve_checked
        #: whether the plugin's prepared solver reads the data's arrays in a compiled
        #: kernel that checks its own answers (``solve_checked``)
        self.compiled = bool(self._impl.compiled)
        self._acquire, self._release = self._lock.acquire, self._lock.release

    @property
    def verify(self) -> str:
        """The verification mode (:data:`~prioik.formulations.base.VERIFY_MODES`)."""
        return self._verify

    @verify.setter
    def verify(self, mode: str) -> None:
        if mode not in VERIFY_MODES:
            raise FormulationError(f"verify must be one of {', '.join(VERIFY_MODES)}; "
                                   f"got {mode!r}")
        self._verify = mode
        #: every optimal answer is certified (not only those whose plugin asks)
        self._verify_every = mode in ("certificate", "lower_point")
        #: a clean answer (solve_checked's tuple) is returned as it is: no hard level to
        #: check, not every answer verified
        self._clean_is_final = not self._hard and not self._verify_every

    def _data(self, stack_or_data) -> StackData:
        if type(stack_or_data) is StackData:
            data = stack_or_data
        elif isinstance(stack_or_data, StackData):
            data = stack_or_data
        elif isinstance(stack_or_data, TaskStack):
            data = stack_or_data.data
        else:
            data = TaskStack(stack_or_data).data
        if data.layout is not self.layout and data.layout != self.layout:
            raise FormulationError(f"this {self.formulation!r} solver was prepared for the "
                                   f"layout {self.layout.describe()}; got a stack of the "
                                   f"layout {data.layout.describe()}")
        return data

    def solve(self, stack_or_data, **step_options: Any) -> Solution:
        """Solve one stack of the layout.

        Args:
            stack_or_data: A :class:`~prioik.hierarchy.TaskStack` or
                :class:`~prioik.hierarchy.StackData` of :attr:`layout`.
            **step_options: Options that change every step (e.g. ``mass_matrix`` and
                ``bias`` of the dynamics formulations), validated on each call and
                merged over the prepared ones; only for formulations without a
                prepared solver of their own (the others fix their options at
                :func:`prioik.prepare`).

        Returns:
            The :class:`~prioik.formulations.Solution` (a numerical failure inside the
            formulation gives ``status == "failed"`` with a
            :class:`~prioik.formulations.Fault`; so does an answer that leaves a hard
            level violated, :func:`~prioik.hierarchy.hard`, the fault's code
            ``"hard_level"``, the levels in ``diagnostics.hard_violated_levels``).

        Raises:
            FormulationError: the stack has another layout.
            TaskStackError: a value of the data is not valid (naming task, level, row).
            ConcurrentUseError: another thread is using this solver.
        """
        data = stack_or_data
        if type(data) is not StackData or data.layout is not self.layout:
            data = self._data(stack_or_data)
        merged = None
        if step_options or self._needs_mass_matrix:
            merged = self._step_options(step_options)
        if not self._acquire(False):       # (positional: a cheaper call)
            raise ConcurrentUseError(f"this prepared {self.formulation!r} solver is busy in "
                                     f"another thread; prepare one solver per thread")
        try:
            t0 = _clock()
            try:
                out = self._impl_solve(data) if merged is None else \
                    self._impl.solve(data, merged)
            except (np.linalg.LinAlgError, ArithmeticError) as exc:
                out = Outcome(np.full(self._n, np.nan)).fail(f"{type(exc).__name__}: {exc}")
            elapsed = _clock() - t0
            if self._clean_is_final and isinstance(out, tuple):
                # solve_checked's clean answer, final as it is (see the module doc)
                x, residuals, snapshot = out
                sol = Solution(x, self.formulation, self._given, _OPTIMAL, residuals, elapsed)
                sol._snapshot = snapshot
                return sol                  # (the lock is released on the way out)
            sol = self._finished(out, data, elapsed)
        finally:
            self._release()
        if self._hard and sol.status != Status.FAILED:
            self._check_hard(sol, data)
        return sol

    def _finished(self, out, data: StackData, elapsed: float) -> Solution:
        """The :class:`~prioik.formulations.Solution` of the plugin's answer ``out`` (an
        ``Outcome``, or ``solve_checked``'s clean tuple, see the module doc) to ``data``,
        ``elapsed`` its solve's time, after the verification stage — what :meth:`solve`
        returns before its hard-level check (:meth:`_check_hard`). The one place an
        answer is finished: :class:`prioik.robots.ControlStep` finishes its steps here."""
        if isinstance(out, tuple):  # solve_checked's clean answer (see the module doc)
            x, residuals, snapshot = out
            sol = Solution(x, self.formulation, self._given, _OPTIMAL, residuals, elapsed)
            sol._snapshot = snapshot
            if self._verify_every:
                self._verify_timed(sol, data, None, None)
            return sol
        sol = self._solution(out, data, elapsed)
        if sol.status == Status.OPTIMAL and self.verify != "none":
            self._verify_timed(sol, data, out.check, out.explain)
        return sol

    def _verify_timed(self, sol: Solution, data: StackData, check: CheckRequest | None,
                      explain) -> None:
        t0 = _clock()
        if not self._verified(sol.x, data, sol.diagnostics, check):
            sol.status = Status.APPROXIMATE
            if explain is not None:
                sol.diagnostics.add_reason(explain())
        sol.verify_time_s = _clock() - t0

    def _verified(self, x: np.ndarray, data: StackData, diagnostics: Diagnostics,
                  check: CheckRequest | None) -> bool:
        """The verification stage on an ``optimal`` answer (see the class doc): whether
        it stays ``optimal``; what was found goes in ``diagnostics``."""
        mode = self.verify
        own = diagnostics.verification
        if own is not None and own.method == "solver" and not own.ok:
            diagnostics.add_reason(own.reason)
            return False
        if x.size and float(np.abs(x).max()) * self._sqrt_n > PRECISION_LIMIT_NORM and \
                not precision_holds(diagnostics, data, x):
            if own is None:
                diagnostics.verification = Verification("precision", False)
            return False
        if mode == "auto":
            if check is None or not check.auto:
                return True
            compare = True
        else:
            compare = mode == "lower_point"
        check = check or CheckRequest()
        solver = None
        if compare:
            if self._lower_solver is None:
                self._lower_solver = lower_point_solver(self.layout)
            solver = self._lower_solver
        return certify(data, x, diagnostics, metric=check.metric,
                       minimum_norm=check.minimum_norm, compare=compare, solver=solver)

    def _check_hard(self, sol: Solution, data: StackData) -> None:
        """``sol`` made ``"failed"`` when it leaves a hard level violated
        (:func:`~prioik.hierarchy.hard_violations`), its fault naming the first such
        level and its tasks — the one place every formulation's answer is checked."""
        violated = hard_violations(data, sol.x, sol.residuals)
        if not violated:
            return
        level, r, scale = violated[0]
        names = self.layout.names[level]
        message = (f"hard level {level} ({', '.join(names)}) is left violated: residual "
                   f"{r:.3g}, beyond {DEFAULT_CERTIFICATE_TOL:g} of its scale {scale:.3g} "
                   f"(its tasks cannot all hold{' under the levels above' if level else ''}"
                   f"; x is the least-squares compromise)")
        if len(violated) > 1:
            message += (f"; hard levels {', '.join(str(i) for i, _, _ in violated[1:])} "
                        "too")
        d = sol.diagnostics
        d.hard_violated_levels = [i for i, _, _ in violated]
        d.fault = Fault(level, tuple(names), "hard_level", message)
        d.reason = message
        sol.status = Status.FAILED

    def reset(self) -> None:
        """Forget what the formulation kept from the last solve (``hierarchical_active_set``:
        the working sets its warm start begins from): the next solve starts cold, as after
        :func:`prioik.prepare`. For a control loop whose state jumps (a new task, a reset
        robot), where the last answer says nothing of the next. A formulation that keeps
        nothing between solves is unchanged by it.

        Raises:
            ConcurrentUseError: another thread is using this solver.
        """
        if not self._acquire(False):
            raise ConcurrentUseError(f"this prepared {self.formulation!r} solver is busy in "
                                     f"another thread; prepare one solver per thread")
        try:
            self._impl.reset()
        finally:
            self._release()

    def _step_options(self, step_options: dict) -> Any:
        """The settings of one call: the prepared ones with ``step_options`` over them
        (validated; ``dataclasses.replace``), or ``None`` when there are none; a
        formulation that needs ``mass_matrix`` refuses a call without one."""
        merged = None
        if step_options:
            if not self._impl.accepts_step_options:
                raise FormulationError(f"formulation {self.formulation!r} fixes its options "
                                       f"when prepared; prepare another solver for "
                                       f"{', '.join(step_options)}")
            merged = dataclasses.replace(self.settings, **_step_options(self._plugin, self._n,
                                                                        step_options))
        if self._needs_mass_matrix and \
                (self.settings if merged is None else merged).mass_matrix is None:
            raise FormulationError(f"formulation {self.formulation!r} needs mass_matrix=M "
                                   f"(the {self._n}x{self._n} joint-space inertia matrix, "
                                   f"SPD)")
        return merged

    def _solution(self, out: Outcome, data: StackData, elapsed: float) -> Solution:
        status = out.status
        if status.__class__ is not Status:
            try:
                status = Status(status)
            except ValueError:
                raise FormulationError(f"formulation {self.formulation!r} returned unknown "
                                       f"status {status!r}") from None
        diagnostics = out.diagnostics
        if out.checked and out.residuals is not None:   # verified by the plugin (compiled)
            return Solution(out.x, self.formulation, self._given, status, out.residuals,
                            elapsed, diagnostics)
        x = out.x
        residuals = out.residuals
        if not (isinstance(x, np.ndarray) and x.shape == (self._n,) and x.dtype == np.float64):
            try:
                x = np.asarray(x, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                x = np.full(0, np.nan)
            if x.shape != (self._n,):
                status = Status.FAILED
                message = f"solution has shape {x.shape}, expected ({self._n},)"
                diagnostics.fault = Fault(None, (), "shape", message)
                diagnostics.add_reason(message)
                x = np.full(self._n, np.nan)
                residuals = None
        if residuals is None:
            finite = bool(np.isfinite(x).all())
            residuals = level_residuals(data, x) if finite else np.full(self.layout.k, np.nan)
        else:
            finite = bool(np.isfinite(residuals).all())   # NaN in x shows in a residual
        if status != Status.FAILED and not finite:
            status = Status.FAILED
            if diagnostics.fault is None:
                message = "the formulation produced non-finite values"
                diagnostics.fault = Fault(None, (), "non_finite", message)
                diagnostics.add_reason(message)
        return Solution(x, self.formulation, self._given, status, residuals, elapsed,
                        diagnostics)

    def solve_batch(self, stacks_or_data: Sequence) -> BatchSolution:
        """Solve many stacks of the layout (the plugin's batched kernel when it has one,
        else a loop of :meth:`solve`), each on its own: a plugin's warm start is reset
        before each stack, so that row ``i`` equals ``prioik.solve(stacks[i])``. The
        verification stage runs on every ``optimal`` answer as in :meth:`solve`: the
        precision check; under ``verify="auto"`` the certificate of the answers whose
        plugin asked for it; under ``"certificate"``/``"lower_point"`` that of every one
        (``"none"``: nothing). A loop of :meth:`solve` runs the stage in each solve.

        Raises:
            TaskStackError: an empty batch.
            FormulationError: a stack has another layout (naming its index).
        """
        if len(stacks_or_data) == 0:
            raise TaskStackError("solve_batch needs at least one stack")
        datas = []
        for i, s in enumerate(stacks_or_data):
            try:
                datas.append(self._data(s))
            except FormulationError as exc:
                raise FormulationError(f"stack {i} of the batch: {exc}") from None
        t0 = time.perf_counter()
        try:
            out = self._impl.solve_batch(datas)     # None: the plugin has no batched kernel
            batched = out is not None
        except (np.linalg.LinAlgError, ArithmeticError):
            # a stack the batched kernel cannot take (e.g. an SVD that does not
            # converge): one by one, so that stack alone is "failed", as in solve
            out, batched = None, True
        checks = None
        if out is None:
            X, statuses = self._one_by_one(datas)
        else:
            X, statuses, checks = out[0], list(out[1]), out[2]
        elapsed = time.perf_counter() - t0
        X = np.asarray(X, dtype=np.float64)
        bad = ~np.isfinite(X).all(axis=1)
        checked: list[Status] = [Status.FAILED if b else Status(st)
                                 for b, st in zip(bad, statuses, strict=False)]
        # solve's verification stage on the batched kernel's optimal answers (a loop of
        # solve ran it already)
        if self.verify != "none" and out is not None:
            for i in [i for i, st in enumerate(checked) if st == Status.OPTIMAL]:
                check = None if checks is None else checks[i]
                if not self._verified(X[i], datas[i], Diagnostics(), check):
                    checked[i] = Status.APPROXIMATE
        if self._hard:          # as solve: a hard level left violated fails the answer
            checked = [Status.FAILED if st != Status.FAILED and hard_violations(d, x) else st
                       for st, d, x in zip(checked, datas, X, strict=False)]
        return BatchSolution(X, checked, self.formulation, dict(self._given), elapsed, batched)

    def _one_by_one(self, datas: list[StackData]) -> tuple[np.ndarray, list]:
        # the stacks of a batch are independent: a plugin that warm-starts from its last
        # solve (``reset()``) starts each one cold, so row i is prioik.solve(stack_i)
        # (a warm start decides ranks on another path, which may give another status
        # on a rank near its threshold); a sequence of solve() calls stays warm
        X = np.empty((len(datas), self._n))
        statuses = []
        for i, d in enumerate(datas):
            self._impl.reset()
            sol = self.solve(d)
            X[i] = sol.x
            statuses.append(sol.status)
        return X, statuses

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self._given.items())
        return (f"PreparedSolver({self.formulation!r}{', ' + opts if opts else ''}; "
                f"{self.layout.describe()})")
