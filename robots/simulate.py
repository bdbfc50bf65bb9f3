"""The simulation loop: integrate the accelerations any formulation returns.

:func:`simulate` runs, at a fixed step ``dt``:

1. **kinematics** — :class:`~robots.tasks.KinematicState` of ``(q, q̇)`` and the task
   stack from the caller's ``build(state, t)`` (plus ``M(q)`` and the bias
   ``b(q, q̇) = C q̇ + g`` when the formulation works at torque level);
2. **solve** — the caller's ``solve(stack, mass_matrix=..., bias=...)`` (any object
   with ``x``, ``status``, ``diagnostics``), giving ``q̈``;
3. **torque** — inverse dynamics by RNEA (``τ = M q̈ + b``, O(n)) for acceleration-
   resolved formulations, or the formulation's own ``diagnostics.detail.tau`` (unifying /
   operational space); the checks of the answer between solve and torque are the
   simulation's bookkeeping and are not timed;
4. semi-implicit Euler: ``q̇ ← q̇ + q̈ dt``, ``q ← q ⊕ q̇ dt`` (``pin.integrate``).

It records ``q, q̇, q̈, τ``, every task's error (from ``build``), the algorithmic
error of eq. 29 (:func:`hierarchy.algorithmic_error_norms`, the norm over the
levels) of the equality view of the stack (:func:`equality_view`), and the wall time
of the three phases. The run never loses what it recorded: an exception from
``build`` or ``solve``, a failed solution, a bad answer (``x`` missing, of the wrong
length or not finite, an unknown status), a non-finite state or ``‖q̈‖`` above
``divergence_limit`` ends it with ``failed = True``, the message (time, step and
cause), ``failed_step`` and the trajectory up to that step.

The floating base is integrated like the joints (no contact forces are modelled);
``τ`` of the base rows is then the wrench the contacts would have to supply.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from prioik.errors import PrioikError
from prioik.hierarchy import StackData, StackLayout, Task, TaskStack, algorithmic_error_norms

from .models import RobotModel
from .tasks import KinematicState

#: The statuses a solution may have (``formulations.STATUSES``; robots/ takes any
#: solver callable and does not import formulations/).
STATUSES = ("optimal", "approximate", "failed")
_ANSWERED = frozenset(("optimal", "approximate"))

__all__ = ["StepTasks", "SimulationError", "SimulationResult", "simulate", "simulation_steps",
           "run_to_end", "equality_view", "coordinate_names"]


@dataclass
class StepTasks:
    """What a scenario's ``build(state, t)`` returns for one step.

    Attributes:
        stack: The task stack to solve (columns: ``n_v`` accelerations), or the
            :class:`~prioik.hierarchy.StackData` a writer filled in place.
        errors: Task errors to record (name → value, e.g. a norm in metres), or a
            function of no arguments returning them: it is called after the step's
            timed phases, so that recording costs no control-loop time.
        algorithmic_levels: Number of leading levels over which the algorithmic error
            is recorded (``None``: every level), e.g. to leave out a regularising
            lowest level that is not one of the scenario's tasks.
    """

    stack: TaskStack | StackData
    errors: dict[str, float] | Callable[[], dict[str, float]] = field(default_factory=dict)
    algorithmic_levels: int | None = None


@dataclass
class SimulationResult:
    """Trajectory and timings of one run.

    Attributes:
        t: Times of the recorded steps (``k``).
        q, v, a, tau: ``k × n_q``, ``k × n_v`` arrays (``a`` is ``q̈`` of the step).
        errors: Task error name → ``k`` values.
        algorithmic_error: ``k`` values, ``‖e_algorithm‖`` over every level (eq. 29).
        kinematics_time_s, solve_time_s, torque_time_s: ``k`` wall times per step
            (``solve_time_s``: the solve less prioik's verification stage).
        statuses: Solution status per step.
        failed: Whether the run stopped early.
        message: Why it stopped (empty when it completed): the time, the step and
            the solver's error or what was wrong with its answer.
        q_names, v_names: Column names of ``q`` and of ``v``/``a``/``tau``
            (:func:`coordinate_names`; empty when the producer did not set them).
        info: Anything else the producer records (scenario, formulation, options);
            JSON-serialisable, saved with the run.
        failed_step: Index of the step that failed (the trajectory holds the
            ``failed_step`` steps before it), ``None`` when the run completed.
        verify_time_s: ``k`` wall times of prioik's verification stage per step
            (``Solution.verify_time_s``; ``None``: a producer without one, e.g. an
            external baseline).
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    tau: np.ndarray
    errors: dict[str, np.ndarray]
    algorithmic_error: np.ndarray
    kinematics_time_s: np.ndarray
    solve_time_s: np.ndarray
    torque_time_s: np.ndarray
    statuses: list[str]
    failed: bool = False
    message: str = ""
    q_names: tuple[str, ...] = ()
    v_names: tuple[str, ...] = ()
    info: dict[str, Any] = field(default_factory=dict)
    failed_step: int | None = None
    verify_time_s: np.ndarray | None = None

    @property
    def steps(self) -> int:
        """Number of recorded steps."""
        return int(self.t.size)

    @property
    def step_time_s(self) -> np.ndarray:
        """Kinematics + solve + torque per step."""
        return self.kinematics_time_s + self.solve_time_s + self.torque_time_s

    # ------------------------------------------------------------ save / load
    _ARRAYS = ("t", "q", "v", "a", "tau", "algorithmic_error", "kinematics_time_s",
               "solve_time_s", "torque_time_s")

    def save(self, path) -> Path:
        """Write the run to ``path`` (``.npz``, compressed; the suffix is added if
        missing): every array, every task error, the statuses, joint and task names,
        ``failed``/``message``, ``info`` and the versions of prioik, numpy and
        pinocchio. :meth:`load` gives back identical arrays.

        Raises:
            ValueError: ``info`` is not JSON-serialisable (names the key).
        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        for key, value in self.info.items():
            try:
                json.dumps(value)
            except TypeError as exc:
                raise SimulationError(f"SimulationResult.info[{key!r}] cannot be saved as JSON "
                                 f"({exc})") from None
        meta = {"format": "prioik.SimulationResult/1", "failed": bool(self.failed),
                "message": self.message, "failed_step": self.failed_step,
                "q_names": list(self.q_names),
                "v_names": list(self.v_names), "error_names": list(self.errors),
                "info": self.info, "versions": _versions()}
        arrays = {k: np.asarray(getattr(self, k)) for k in self._ARRAYS}
        if self.verify_time_s is not None:
            arrays["verify_time_s"] = np.asarray(self.verify_time_s)
        arrays.update({f"error:{k}": np.asarray(v) for k, v in self.errors.items()})
        arrays["statuses"] = np.array(self.statuses, dtype=str)
        arrays["meta"] = np.array(json.dumps(meta))
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **arrays)
        return path

    @classmethod
    def load(cls, path) -> SimulationResult:
        """Read a run written by :meth:`save`.

        Raises:
            ValueError: the file is not a saved :class:`SimulationResult` (names it).
            OSError: it cannot be read.
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                files = set(z.files)
                missing = [k for k in (*cls._ARRAYS, "statuses", "meta") if k not in files]
                if missing:
                    raise SimulationError(f"{path} is not a saved SimulationResult (no "
                                     f"{', '.join(missing)})")
                meta = json.loads(str(z["meta"]))
                arrays = {k: np.array(z[k]) for k in cls._ARRAYS}
                errors = {k: np.array(z[f"error:{k}"]) for k in meta["error_names"]}
                statuses = [str(s) for s in z["statuses"]]
                verify = np.array(z["verify_time_s"]) if "verify_time_s" in files else None
        except (KeyError, json.JSONDecodeError) as exc:
            raise SimulationError(f"{path} is not a saved SimulationResult ({exc})") from None
        info = dict(meta.get("info", {}))
        info.setdefault("versions", meta.get("versions", {}))
        return cls(arrays["t"], arrays["q"], arrays["v"], arrays["a"], arrays["tau"], errors,
                   arrays["algorithmic_error"], arrays["kinematics_time_s"],
                   arrays["solve_time_s"], arrays["torque_time_s"], statuses,
                   bool(meta["failed"]), str(meta["message"]), tuple(meta["q_names"]),
                   tuple(meta["v_names"]), info, meta.get("failed_step"), verify)

    # ---------------------------------------------------------------- display
    def _summary_items(self) -> list[tuple[str, str]]:
        items = [("steps", str(self.steps)),
                 ("time", f"{self.t[0]:.3g}–{self.t[-1]:.3g} s" if self.steps else "—"),
                 ("n_q, n_v", f"{self.q.shape[1]}, {self.v.shape[1]}"),
                 ("status", "failed: " + self.message if self.failed else "ran to the end")]
        if self.steps:
            items.append(("median step", f"{1e3 * float(np.median(self.step_time_s)):.3f} ms"))
        for k, v in self.errors.items():
            if v.size and np.isfinite(v).any():
                items.append((k, f"final {v[-1]:.3g}, max {np.nanmax(v):.3g}"))
        return items

    def __repr__(self) -> str:
        label = self.info.get("label") or self.info.get("formulation") or ""
        head = f"SimulationResult({label!r}, " if label else "SimulationResult("
        errs = ", ".join(self.errors)
        return (f"{head}{self.steps} steps, t ≤ {self.t[-1] if self.steps else 0:.3g} s, "
                f"{'failed' if self.failed else 'ok'}, errors: {errs or 'none'})")

    def _repr_html_(self) -> str:
        from html import escape
        rows = "".join(f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td>"
                       f"</tr>" for k, v in self._summary_items())
        return f"<table><caption>SimulationResult</caption>{rows}</table>"


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version
    out = {"numpy": np.__version__, "pinocchio": str(pin.__version__)}
    try:
        out["prioik"] = version("prioik")
    except PackageNotFoundError:  # pragma: no cover - a never-installed source tree
        out["prioik"] = "unknown"
    return out


def coordinate_names(robot: RobotModel) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Column names of ``q`` and of ``v`` for ``robot``: one per joint coordinate,
    ``<joint>`` for one-dof joints, ``<joint>.<coordinate>`` otherwise (a free flyer:
    ``root_joint.x y z qx qy qz qw`` in ``q``, ``.vx vy vz wx wy wz`` in ``v``)."""
    m = robot.model
    qn: list[str] = []
    vn: list[str] = []
    free_q, free_v = ("x", "y", "z", "qx", "qy", "qz", "qw"), ("vx", "vy", "vz", "wx", "wy", "wz")
    for j in range(1, m.njoints):
        jm, name = m.joints[j], m.names[j]
        if jm.nq == 1 and jm.nv == 1:
            qn.append(name)
            vn.append(name)
            continue
        cq = free_q if jm.nq == 7 and jm.nv == 6 else tuple(str(i) for i in range(jm.nq))
        cv = free_v if jm.nq == 7 and jm.nv == 6 else tuple(str(i) for i in range(jm.nv))
        qn += [f"{name}.{c}" for c in cq]
        vn += [f"{name}.{c}" for c in cv]
    return tuple(qn), tuple(vn)


def equality_view(stack: TaskStack, x: np.ndarray, tol: float = 1e-7) -> TaskStack | None:
    """The equality stack an answer ``x`` solved: each inequality task is replaced by
    its rows active at ``x`` (within ``tol``, relative) as equalities ``A_r x = bound``;
    a level left without rows is dropped. ``None`` when nothing is left.

    This is the stack on which eq. 29 is evaluated for QP formulations.
    """
    if stack.is_equality:
        return stack
    levels = []
    for level in stack.levels:
        tasks = []
        for t in level:
            if t.is_equality:
                tasks.append(t)
                continue
            ax = t.A @ x
            lo, up = t.bounds()
            scale = tol * (1.0 + np.abs(ax))
            at_lo = np.isfinite(lo) & (ax <= lo + scale)
            at_up = np.isfinite(up) & (ax >= up - scale)
            rows = np.flatnonzero(at_lo | at_up)
            if rows.size:
                b = np.where(at_lo[rows], lo[rows], up[rows])
                tasks.append(Task(t.name, t.A[rows], b, weight=t.weight[rows]))
        if tasks:
            levels.append(tasks)
    return TaskStack(levels) if levels else None


class _RowRecord:
    """The rows of a run's steps (its :class:`StackData` of one layout), kept for the
    algorithmic error evaluated after the run, in blocks of :attr:`CHUNK` steps
    allocated and touched once each (outside the timed phases).

    A fresh ``StackData.copy()`` per step (five arrays on new heap pages) cost the timed
    phases of the next steps: the first fencing run of a process (``make demo``'s
    ``extended_jacobian``) took ~10,000 minor page faults and a median step of 70 µs,
    against 58 µs without the algorithmic error; copying into blocks touched
    beforehand, ~400 faults and 59 µs.
    """

    CHUNK = 256

    def __init__(self, layout: StackLayout) -> None:
        self.layout = layout
        self.n = layout.n
        self.chunks: list[np.ndarray] = []
        self.count = 0

    def put(self, data: StackData) -> int:
        """Copy ``data``'s rows; returns their index."""
        k = self.count
        if k % self.CHUNK == 0:
            block = np.empty((self.CHUNK, self.layout.m, self.n + 4))
            block.fill(0.0)                  # every page touched now, not in the loop
            self.chunks.append(block)
        rows = self.chunks[-1][k % self.CHUNK]
        n = self.n
        rows[:, :n] = data.A
        rows[:, n] = data.b
        rows[:, n + 1] = data.lower
        rows[:, n + 2] = data.upper
        rows[:, n + 3] = data.sqrt_weight
        self.count += 1
        return k

    def get(self, k: int) -> StackData:
        """The rows copied at index ``k``, as data of the layout."""
        rows = self.chunks[k // self.CHUNK][k % self.CHUNK]
        n = self.n
        out = StackData(self.layout)
        out.A[...] = rows[:, :n]
        out.b[...] = rows[:, n]
        out.lower[...] = rows[:, n + 1]
        out.upper[...] = rows[:, n + 2]
        out.sqrt_weight[...] = rows[:, n + 3]
        return out


def _recorded_error(entry: tuple | None, record: _RowRecord | None) -> float:
    """The algorithmic error of one step's ``(stack or record index, x, levels)``
    (``NaN`` for a step recorded without it)."""
    if entry is None:
        return np.nan
    stack, x, levels = entry
    if type(stack) is int:
        stack = record.get(stack)
    return _algorithmic_error(stack, x, levels)


def _algorithmic_error(stack: TaskStack | StackData, x: np.ndarray,
                       levels: int | None = None) -> float:
    if isinstance(stack, StackData):
        stack = stack.as_stack()
    if levels is not None:
        stack = TaskStack(stack.levels[:levels])
    eq = equality_view(stack, x)
    if eq is None:
        return 0.0
    norms = algorithmic_error_norms(eq, x)
    return float(np.sqrt(np.sum(np.square(norms))))


class SimulationError(PrioikError, ValueError):
    """:func:`simulate` was called with a ``duration``, ``dt`` or ``level`` it cannot run,
    a scenario with a variant or limits it does not have, or a run cannot be saved or
    read (:meth:`SimulationResult.save`, :meth:`SimulationResult.load`)."""


def _check_times(duration: float, dt: float) -> None:
    """``duration`` and ``dt`` finite, > 0 and ``dt ≤ duration`` (at least one step)."""
    for name, value in (("duration", duration), ("dt", dt)):
        try:
            ok = math.isfinite(float(value)) and float(value) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise SimulationError(f"{name} must be a finite number > 0 (s), got {value!r}")
    if int(round(duration / dt)) < 1:
        raise SimulationError(f"dt = {dt} s is longer than duration = {duration} s: "
                         f"the run would have no step")


def _answer(sol: Any, nv: int) -> tuple[np.ndarray | None, str]:
    """``sol.x`` as ``nv`` finite floats, or ``(None, why not)``."""
    status = getattr(sol, "status", None)
    x = getattr(sol, "x", None)
    # the common case in one dot product: a finite x @ x means every entry is finite
    # (an overflowing sum takes the checks below, which name what is wrong, if anything)
    if (status in _ANSWERED and type(x) is np.ndarray and x.dtype == np.float64
            and x.shape == (nv,) and math.isfinite(float(x @ x))):
        return x, ""
    if status not in STATUSES:
        return None, f"the solver returned {type(sol).__name__} with status {status!r} " \
                     f"(expected one of {', '.join(STATUSES)})"
    if status == "failed":
        detail = getattr(getattr(sol, "diagnostics", None), "reason", "")
        return None, f"solution failed{': ' + str(detail) if detail else ''}"
    try:
        x = np.asarray(getattr(sol, "x", None), dtype=float)
    except (TypeError, ValueError) as exc:
        return None, f"solution x cannot be read as numbers ({exc}) (status {status})"
    if x.shape != (nv,):
        return None, f"solution x has shape {x.shape}, expected ({nv},) (status {status})"
    if not np.isfinite(x).all():
        bad = np.flatnonzero(~np.isfinite(x))[:5].tolist()
        return None, f"solution x holds non-finite values at {bad} although its " \
                     f"status is {status!r}"
    return x, ""


def _torque(sol: Any, nv: int) -> tuple[np.ndarray | None, str]:
    """``sol.diagnostics.detail.tau`` (the formulation's own record) as ``nv`` finite
    floats, or ``(None, why not)``."""
    detail = getattr(getattr(sol, "diagnostics", None), "detail", None)
    value = getattr(detail, "tau", None)
    if value is None:
        return None, ("torque_from_solution=True but the solution has no "
                      "diagnostics.detail.tau (give the formulation bias=C+G)")
    try:
        tau = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        return None, f"diagnostics.detail.tau cannot be read as numbers ({exc})"
    if tau.shape != (nv,) or not np.isfinite(tau).all():
        return None, (f"diagnostics.detail.tau must be {nv} finite values, got shape "
                      f"{tau.shape}")
    return tau, ""


SolveFn = Callable[..., Any]
BuildFn = Callable[[KinematicState, float], StepTasks]


def simulate(robot: RobotModel, build: BuildFn, solve: SolveFn, *, duration: float,
             dt: float, q0=None, v0=None, needs_dynamics: bool = False,
             torque_from_solution: bool = False, algorithmic_error: bool = True,
             divergence_limit: float = 1e6, level: str = "acceleration",
             progress: Callable[[float], None] | None = None) -> SimulationResult:
    """Run a fixed-step simulation; see the module docstring.

    Args:
        robot: The robot (its model is not changed).
        build: ``build(state, t) -> StepTasks``.
        solve: ``solve(stack, **kw)`` returning an object with ``x`` (``q̈``), ``status``
            and ``info``; ``kw`` holds ``mass_matrix`` and ``bias`` when
            ``needs_dynamics``.
        duration: Simulated time (s).
        dt: Step (s).
        q0: Initial configuration (``robot.q0`` if omitted); copied.
        v0: Initial velocity (zero if omitted); copied.
        needs_dynamics: Pass ``M(q)`` and ``b(q, q̇)`` to ``solve``.
        torque_from_solution: Take ``τ`` from ``sol.diagnostics.detail.tau`` instead of
            RNEA.
        algorithmic_error: Record eq. 29 (costs an SVD per level per step).
        divergence_limit: Stop (``failed``) when ``‖q̈‖`` exceeds this: the run has
            diverged and would only overflow to NaN a few steps later.
        level: ``"acceleration"`` (``x`` is ``q̈``, the default) or ``"velocity"``
            (``x`` is the next velocity: ``q̇ ← x``, ``q ← q ⊕ x dt``, and the recorded
            ``q̈ = (x − q̇)/dt``, used for RNEA), for velocity-level stacks.
        progress: Called with the simulated time every 250 steps.

    Returns:
        A :class:`SimulationResult`.

    Raises:
        SimulationError: (a ``ValueError``) ``duration`` or ``dt`` not finite and > 0,
            ``dt > duration``, or an unknown ``level``. Errors during the run end it as
            ``failed`` instead.
    """
    return run_to_end(simulation_steps(
        robot, build, solve, duration=duration, dt=dt, q0=q0, v0=v0,
        needs_dynamics=needs_dynamics, torque_from_solution=torque_from_solution,
        algorithmic_error=algorithmic_error, divergence_limit=divergence_limit, level=level,
        progress=progress))


def simulation_steps(robot: RobotModel, build: BuildFn, solve: SolveFn, *, duration: float,
                     dt: float, q0=None, v0=None, needs_dynamics: bool = False,
                     torque_from_solution: bool = False, algorithmic_error: bool = True,
                     divergence_limit: float = 1e6, level: str = "acceleration",
                     progress: Callable[[float], None] | None = None
                     ) -> Generator[int, None, SimulationResult]:
    """:func:`simulate` one step at a time: a generator that yields the step's index
    after each step (outside the timed phases) and returns the
    :class:`SimulationResult` (``StopIteration.value``; :func:`run_to_end` drives it).
    Several runs advanced in turns are timed under the same machine conditions (see
    :func:`prioik.benchmarks.scenario_runs.run_scenario`). The arguments are
    :func:`simulate`'s, checked here, before the first step.

    Raises:
        SimulationError: as :func:`simulate`.
    """
    _check_times(duration, dt)
    if level not in ("acceleration", "velocity"):
        raise SimulationError(f"level must be 'acceleration' or 'velocity', got {level!r}")
    return _steps(robot, build, solve, duration, dt, q0, v0, needs_dynamics,
                  torque_from_solution, algorithmic_error, divergence_limit, level, progress)


def _steps(robot, build, solve, duration, dt, q0, v0, needs_dynamics, torque_from_solution,
           algorithmic_error, divergence_limit, level, progress):
    """The generator of :func:`simulation_steps` (its arguments checked)."""
    model = robot.model
    data = model.createData()
    dyn = model.createData()
    q = np.array(robot.q0 if q0 is None else q0, dtype=float, copy=True)
    v = np.zeros(robot.nv) if v0 is None else np.array(v0, dtype=float, copy=True)
    steps = int(round(duration / dt))
    T, Q, V, A, TAU, ALG, TK, TS, TT, ST = [], [], [], [], [], [], [], [], [], []
    TV: list[float] = []
    record: _RowRecord | None = None
    errors: dict[str, list[float]] = {}
    failed, message, failed_step = False, "", None
    for k in range(steps):
        t = k * dt
        t0 = time.perf_counter()
        try:
            state = KinematicState(robot, q, v, data)
            step = build(state, t)
        except Exception as exc:  # noqa: BLE001 - the run ends, the trajectory is kept
            failed, failed_step = True, k
            message = f"t = {t:.3f} s (step {k}): build raised {type(exc).__name__}: {exc}"
            break
        kw = {}
        if needs_dynamics:
            M = pin.crba(model, dyn, q)
            M = np.triu(M) + np.triu(M, 1).T
            kw = {"mass_matrix": M, "bias": np.array(pin.nonLinearEffects(model, dyn, q, v))}
        t1 = time.perf_counter()
        try:
            sol = solve(step.stack, **kw)
        except Exception as exc:  # noqa: BLE001 - the run ends, the trajectory is kept
            failed, failed_step = True, k
            message = f"t = {t:.3f} s (step {k}): solve raised {type(exc).__name__}: {exc}"
            break
        t_solved = time.perf_counter()
        # checking the answer is the simulation's bookkeeping, not control work: it is
        # left out of the timed phases, as the external baselines' loops leave theirs
        x, why = _answer(sol, robot.nv)
        if why:
            failed, failed_step = True, k
            message = f"t = {t:.3f} s (step {k}): {why}"
            break
        x_solved = x
        if level == "velocity":
            x = (x_solved - v) / dt                    # recorded q̈
        if not math.sqrt(float(x @ x)) <= divergence_limit:
            failed, failed_step = True, k
            message = (f"t = {t:.3f} s (step {k}): diverged (‖q̈‖ = "
                       f"{np.linalg.norm(x):.3g} > {divergence_limit:g})")
            break
        t2 = time.perf_counter()
        if torque_from_solution:
            tau, why = _torque(sol, robot.nv)
            if why:
                failed, failed_step = True, k
                message = f"t = {t:.3f} s (step {k}): {why}"
                break
        else:
            tau = np.array(pin.rnea(model, dyn, q, v, x))
        t3 = time.perf_counter()
        T.append(t)
        Q.append(q.copy())
        V.append(v.copy())
        A.append(x.copy())
        TAU.append(tau.copy())
        TK.append(t1 - t0)
        verify = float(getattr(sol, "verify_time_s", 0.0))
        TS.append(t_solved - t1 - verify)
        TV.append(verify)
        TT.append(t3 - t2)
        ST.append(sol.status)
        recorded = step.errors() if callable(step.errors) else step.errors
        for name, value in recorded.items():
            errors.setdefault(name, [np.nan] * (len(T) - 1)).append(float(value))
        for name in errors:
            if len(errors[name]) < len(T):
                errors[name].append(np.nan)
        if algorithmic_error:     # evaluated after the run: an SVD per level between
            # steps would evict the control loop's working set and inflate its timed
            # phases, so the timed steps run without it
            stack = step.stack
            if isinstance(stack, StackData):     # written in place by the next step
                if record is None:
                    record = _RowRecord(stack.layout)
                stack = (record.put(stack) if stack.layout is record.layout
                         else stack.copy())
            ALG.append((stack, x_solved.copy(), step.algorithmic_levels))
        else:
            ALG.append(None)
        v = v + x * dt if level == "acceleration" else x_solved.copy()
        q = pin.integrate(model, q, v * dt)
        if not (np.isfinite(q).all() and np.isfinite(v).all()):
            failed, failed_step = True, k + 1
            message = f"t = {t + dt:.3f} s (step {k + 1}): state became non-finite"
            break
        if progress is not None and (k + 1) % 250 == 0:
            progress(t + dt)
        yield k
    nq, nv = robot.nq, robot.nv

    def arr(rows, width):
        return np.array(rows, dtype=float).reshape(-1, width)

    return SimulationResult(np.array(T, dtype=float), arr(Q, nq), arr(V, nv), arr(A, nv),
                            arr(TAU, nv), {k: np.array(v_, dtype=float)
                                           for k, v_ in errors.items()},
                            np.array([_recorded_error(a, record) for a in ALG],
                                     dtype=float),
                            np.array(TK), np.array(TS),
                            np.array(TT), ST, failed, message, failed_step=failed_step,
                            verify_time_s=np.array(TV, dtype=float))


def run_to_end(steps: Generator[Any, None, Any]) -> Any:
    """Advance a step generator (:func:`simulation_steps`) to its end; its return
    value (the result)."""
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value
