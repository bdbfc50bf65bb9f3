"""The simulation loop: integrate the accelerations any formulation returns.

:func:`simulate` runs, at a fixed step ``dt``:

1. **kinematics** — :class:`~robots.tasks.KinematicState` of ``(q, q̇)`` and the task
   stack from the caller's ``build(state, t)`` (plus ``M(q)`` and the bias
   ``b(q, q̇) = C q̇ + g`` when the formulation works at torque level);
2. **solve** — the caller's ``solve(stack, mass_matrix=..., bias=...)`` (any object
   with ``x``, ``status``, ``info``), giving ``q̈``;
3. **torque** — inverse dynamics by RNEA (``τ = M q̈ + b``, O(n)) for acceleration-
   resolved formulations, or the formulation's own ``info["tau"]`` (unifying /
   operational space);
4. semi-implicit Euler: ``q̇ ← q̇ + q̈ dt``, ``q ← q ⊕ q̇ dt`` (``pin.integrate``).

It records ``q, q̇, q̈, τ``, every task's error (from ``build``), the algorithmic
error of eq. 29 (:func:`hierarchy.algorithmic_error_norms`, the norm over the
levels) of the equality view of the stack (:func:`equality_view`), and the wall time of the three phases. A failed
solution, a non-finite value or ``‖q̈‖`` above ``divergence_limit`` stops the run
cleanly with ``failed = True``.

The floating base is integrated like the joints (no contact forces are modelled);
``τ`` of the base rows is then the wrench the contacts would have to supply.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import pinocchio as pin

from prioik.hierarchy import StackData, Task, TaskStack, algorithmic_error_norms

from .models import RobotModel
from .tasks import KinematicState

__all__ = ["StepTasks", "SimulationResult", "simulate", "equality_view"]


@dataclass
class StepTasks:
    """What a scenario's ``build(state, t)`` returns for one step.

    Attributes:
        stack: The task stack to solve (columns: ``n_v`` accelerations), or the
            :class:`~prioik.hierarchy.StackData` a writer filled in place.
        errors: Task errors to record (name → value, e.g. a norm in metres).
        algorithmic_levels: Number of leading levels over which the algorithmic error
            is recorded (``None``: every level), e.g. to leave out a regularising
            lowest level that is not one of the scenario's tasks.
    """

    stack: TaskStack | StackData
    errors: dict[str, float] = field(default_factory=dict)
    algorithmic_levels: int | None = None


@dataclass
class SimulationResult:
    """Trajectory and timings of one run.

    Attributes:
        t: Times of the recorded steps (``k``).
        q, v, a, tau: ``k × n_q``, ``k × n_v`` arrays (``a`` is ``q̈`` of the step).
        errors: Task error name → ``k`` values.
        algorithmic_error: ``k`` values, ``‖e_algorithm‖`` over every level (eq. 29).
        kinematics_time_s, solve_time_s, torque_time_s: ``k`` wall times per step.
        statuses: Solution status per step.
        failed: Whether the run stopped early.
        message: Why it stopped (empty when it completed).
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

    @property
    def steps(self) -> int:
        """Number of recorded steps."""
        return int(self.t.size)

    @property
    def step_time_s(self) -> np.ndarray:
        """Kinematics + solve + torque per step."""
        return self.kinematics_time_s + self.solve_time_s + self.torque_time_s


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
        torque_from_solution: Take ``τ`` from ``info["tau"]`` instead of RNEA.
        algorithmic_error: Record eq. 29 (costs an SVD per level per step).
        divergence_limit: Stop (``failed``) when ``‖q̈‖`` exceeds this: the run has
            diverged and would only overflow to NaN a few steps later.
        level: ``"acceleration"`` (``x`` is ``q̈``, the default) or ``"velocity"``
            (``x`` is the next velocity: ``q̇ ← x``, ``q ← q ⊕ x dt``, and the recorded
            ``q̈ = (x − q̇)/dt``, used for RNEA), for velocity-level stacks.
        progress: Called with the simulated time every 250 steps.

    Returns:
        A :class:`SimulationResult`.
    """
    if not (dt > 0 and duration > 0):
        raise ValueError(f"dt and duration must be > 0, got dt={dt}, duration={duration}")
    if level not in ("acceleration", "velocity"):
        raise ValueError(f"level must be 'acceleration' or 'velocity', got {level!r}")
    model = robot.model
    data = model.createData()
    dyn = model.createData()
    q = np.array(robot.q0 if q0 is None else q0, dtype=float, copy=True)
    v = np.zeros(robot.nv) if v0 is None else np.array(v0, dtype=float, copy=True)
    steps = int(round(duration / dt))
    T, Q, V, A, TAU, ALG, TK, TS, TT, ST = [], [], [], [], [], [], [], [], [], []
    errors: dict[str, list[float]] = {}
    failed, message = False, ""
    for k in range(steps):
        t = k * dt
        t0 = time.perf_counter()
        state = KinematicState(robot, q, v, data)
        step = build(state, t)
        kw = {}
        if needs_dynamics:
            M = pin.crba(model, dyn, q)
            M = np.triu(M) + np.triu(M, 1).T
            kw = {"mass_matrix": M, "bias": np.array(pin.nonLinearEffects(model, dyn, q, v))}
        t1 = time.perf_counter()
        sol = solve(step.stack, **kw)
        t2 = time.perf_counter()
        x = np.asarray(sol.x, dtype=float)
        x_solved = x
        if level == "velocity" and np.isfinite(x).all():
            x = (x_solved - v) / dt                    # recorded q̈
        if sol.status == "failed" or not np.isfinite(x).all():
            failed = True
            message = (f"t = {t:.3f} s: solution {sol.status}"
                       f"{': ' + str(sol.info.get('message', '')) if sol.info else ''}")
            break
        if np.linalg.norm(x) > divergence_limit:
            failed = True
            message = (f"t = {t:.3f} s: diverged (‖q̈‖ = {np.linalg.norm(x):.3g} > "
                       f"{divergence_limit:g})")
            break
        if torque_from_solution:
            if "tau" not in sol.info:
                raise ValueError("torque_from_solution=True but the solution has no "
                                 "info['tau']")
            tau = np.asarray(sol.info["tau"], dtype=float)
        else:
            tau = np.array(pin.rnea(model, dyn, q, v, x))
        t3 = time.perf_counter()
        T.append(t)
        Q.append(q.copy())
        V.append(v.copy())
        A.append(x.copy())
        TAU.append(tau.copy())
        TK.append(t1 - t0)
        TS.append(t2 - t1)
        TT.append(t3 - t2)
        ST.append(sol.status)
        for name, value in step.errors.items():
            errors.setdefault(name, [np.nan] * (len(T) - 1)).append(float(value))
        for name in errors:
            if len(errors[name]) < len(T):
                errors[name].append(np.nan)
        ALG.append(_algorithmic_error(step.stack, x_solved, step.algorithmic_levels)
                   if algorithmic_error else np.nan)
        v = v + x * dt if level == "acceleration" else x_solved.copy()
        q = pin.integrate(model, q, v * dt)
        if not (np.isfinite(q).all() and np.isfinite(v).all()):
            failed, message = True, f"t = {t:.3f} s: state became non-finite"
            break
        if progress is not None and (k + 1) % 250 == 0:
            progress(t + dt)
    nq, nv = robot.nq, robot.nv

    def arr(rows, width):
        return np.array(rows, dtype=float).reshape(-1, width)

    return SimulationResult(np.array(T, dtype=float), arr(Q, nq), arr(V, nv), arr(A, nv),
                            arr(TAU, nv), {k: np.array(v_, dtype=float)
                                           for k, v_ in errors.items()},
                            np.array(ALG, dtype=float), np.array(TK), np.array(TS),
                            np.array(TT), ST, failed, message)
