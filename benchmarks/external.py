"""The recording loop of the external IK baselines (PlaCo, pink, mink, TSID).

An external library steps the robot itself (its own kinematics, its own QP); this loop
gives it the scenario's references, records what :func:`robots.simulate` records —
computed with the toolkit's own kinematics on the library's configurations, so every
row of a comparison is measured the same way — and times the library's step
(``solve_time_s``: the library's solve; ``kinematics_time_s``: setting its targets and
its kinematics update). ``q̇ = Δq / dt``, ``q̈ = (q̇_{k+1} − q̇_k)/dt``, ``τ`` by RNEA. The
algorithmic error (eq. 29) is not defined for a weighted soft hierarchy and is NaN.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np


def distribution_version(distribution: str) -> str:
    """The installed version of ``distribution``, or ``"(not installed)"``."""
    import importlib.metadata
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return "(not installed)"


#: ``step(q, v, t) -> (q_next, v_next, t_targets, t_solve)``; raises ``RuntimeError``
#: when the library finds no solution.
StepFn = Callable[[np.ndarray, np.ndarray, float], tuple[np.ndarray, np.ndarray, float, float]]


def record(scenario, step: StepFn, *, duration: float, dt: float, progress=None,
           status: str = "approximate", label: str = "", info: dict | None = None):
    """Run ``step`` for ``duration`` and record a :class:`robots.SimulationResult`
    (``info``: added to the result's)."""
    from prioik.robots import run_to_end
    return run_to_end(record_steps(scenario, step, duration=duration, dt=dt,
                                   progress=progress, status=status, label=label, info=info))


def record_steps(scenario, step: StepFn, *, duration: float, dt: float, progress=None,
                 status: str = "approximate", label: str = "", info: dict | None = None):
    """:func:`record` one step at a time: a generator that yields after each step and
    returns the :class:`robots.SimulationResult` (as
    :func:`robots.simulation_steps`)."""
    import pinocchio as pin

    from prioik.robots import KinematicState, SimulationResult
    from prioik.robots.simulate import coordinate_names
    robot = scenario.robot
    model = robot.model
    data = model.createData()
    dyn = model.createData()
    steps = int(round(duration / dt))
    q = robot.q0.copy()
    v = np.zeros(robot.nv)
    rows = {k: [] for k in ("t", "q", "v", "a", "tau", "tk", "ts", "tt")}
    errors: dict[str, list] = {}
    statuses, failed, message = [], False, ""
    for k in range(steps):
        t = k * dt
        try:
            q_next, v_next, t_targets, t_solve = step(q, v, t)
        except RuntimeError as exc:
            failed, message = True, f"t = {t:.3f} s: {label or 'baseline'}: {exc}"
            break
        if not (np.isfinite(v_next).all() and np.isfinite(q_next).all()):
            failed, message = True, f"t = {t:.3f} s: {label} returned non-finite values"
            break
        a = (v_next - v) / dt
        t2 = time.perf_counter()
        tau = np.array(pin.rnea(model, dyn, q, v, a))
        t3 = time.perf_counter()
        state = KinematicState(robot, q, v, data)
        for name, value in scenario.errors(state, t, scenario.terms(state, t)).items():
            errors.setdefault(name, []).append(value)
        for key, val in (("t", t), ("q", q.copy()), ("v", v.copy()), ("a", a), ("tau", tau),
                         ("tk", t_targets), ("ts", t_solve), ("tt", t3 - t2)):
            rows[key].append(val)
        statuses.append(status)
        q, v = q_next, v_next
        if progress is not None and (k + 1) % 250 == 0:
            progress(t + dt)
        yield k

    def arr(key, width):
        return np.array(rows[key], dtype=float).reshape(-1, width)

    qn, vn = coordinate_names(robot)
    return SimulationResult(np.array(rows["t"], dtype=float), arr("q", robot.nq),
                            arr("v", robot.nv), arr("a", robot.nv), arr("tau", robot.nv),
                            {k: np.array(v_, dtype=float) for k, v_ in errors.items()},
                            np.full(len(rows["t"]), np.nan), np.array(rows["tk"]),
                            np.array(rows["ts"]), np.array(rows["tt"]), statuses, failed,
                            message, qn, vn,
                            {"label": label, **scenario.info(), **(info or {})})
