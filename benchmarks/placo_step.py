"""The whole G1 IK step (kinematics + solve): prioik's ``extended_jacobian`` against
PlaCo's ``KinematicsSolver`` on the same robot, tasks and states.

PlaCo runs the compatible fencing scenario through
:func:`benchmarks.placo_baseline.run_placo` (support foot and centre of mass hard;
left foot, sword tip and posture soft; joint and velocity limits); its step is
``update_kinematics`` plus the target updates (kinematics) and
``KinematicsSolver.solve(True)`` (solve), as that function times them.

prioik's step is timed at the same states (PlaCo's trajectory), two ways, one after
the other at every state:

* **TaskStack path** — :class:`robots.tasks.KinematicState` (pinocchio Jacobians,
  frame placements, centre of mass), building the velocity-level stack of the same
  five tasks in the scenario's priority order (support foot, com, left foot, sword
  tip, posture; ``J q̇ = ẋ* + K e``, ``K = 10``, the posture its ``K_p = 4``) —
  :meth:`robots.fencing.FencingScenario.terms`, :meth:`robots.tasks.TaskTerm.velocity`
  and :class:`hierarchy.TaskStack` — and ``extended_jacobian``'s plugin ``solve``
  (called directly, without the registry's checks);
* **preallocated path** — ``KinematicState(..., drift=False)``,
  :meth:`robots.fencing.FencingScenario.write_velocity_rows` into a
  :class:`robots.TaskRows` buffer, and
  :class:`formulations.extended_jacobian.BufferSolver` (same kernel, no ``Task``
  objects). Both paths' answers are compared at every state (``max_path_distance``).

Both paths and PlaCo compute the same minimum-jerk references in Python
(:meth:`~robots.fencing.FencingScenario.com_ref`, ``left_foot_ref``, ``tip_ref``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from hierarchy import TaskStack

#: task order of the velocity stack (the scenario's priorities, joint limits omitted:
#: PlaCo handles its limits as inequalities, and the equality formulation has none)
ORDER = ("support_foot", "com", "left_foot", "sword_tip", "posture")
GAIN = 10.0
DT = 0.002


def ik_step_times(steps: int = 300, formulation: str = "extended_jacobian"
                  ) -> dict[str, Any]:
    """Median, p10 and p90 (µs) of PlaCo's step and of prioik's two step paths (with
    their phases) over ``steps`` control steps of the compatible fencing scenario.

    Raises:
        ImportError: placo, pinocchio or :mod:`robots` is missing.
        RuntimeError: PlaCo's run failed, or a prioik path failed.
    """
    import formulations
    from formulations.extended_jacobian import BufferSolver
    from hierarchy import relative_distance
    from robots.fencing import FencingScenario
    from robots.tasks import KinematicState

    from .placo_baseline import run_placo

    scenario = FencingScenario("compatible")
    robot = scenario.robot
    placo_run = run_placo(scenario, duration=steps * DT, dt=DT)
    if placo_run.failed or placo_run.steps == 0:
        raise RuntimeError(f"PlaCo's run failed: {placo_run.message}")
    placo_step = placo_run.kinematics_time_s + placo_run.solve_time_s

    mod = formulations.get(formulation)
    data = robot.model.createData()
    data_fast = robot.model.createData()
    rows = scenario.velocity_rows(GAIN)
    gains = scenario.velocity_gains(GAIN)
    solver = BufferSolver(rows.buffer)
    kin, build, solve, fkin, fbuild, fsolve = [], [], [], [], [], []
    distance = 0.0
    for i in range(placo_run.steps):
        q, v, t = placo_run.q[i], placo_run.v[i], float(placo_run.t[i])
        t0 = time.perf_counter()
        state = KinematicState(robot, q, v, data)
        t1 = time.perf_counter()
        terms = scenario.terms(state, t)
        stack = TaskStack([terms[name].velocity(gains[name]) for name in ORDER if name in terms])
        t2 = time.perf_counter()
        out = mod.solve(stack)
        t3 = time.perf_counter()
        fstate = KinematicState(robot, q, v, data_fast, drift=False)
        t4 = time.perf_counter()
        scenario.write_velocity_rows(rows, fstate, t)
        t5 = time.perf_counter()
        fast = solver.solve()
        t6 = time.perf_counter()
        if out.status == "failed" or fast.status == "failed":
            raise RuntimeError(f"{formulation} failed at t = {t:.3f} s")
        distance = max(distance, relative_distance(fast.x, out.x))
        for lst, val in ((kin, t1 - t0), (build, t2 - t1), (solve, t3 - t2),
                         (fkin, t4 - t3), (fbuild, t5 - t4), (fsolve, t6 - t5)):
            lst.append(val)
    kin, build, solve, fkin, fbuild, fsolve = (np.array(a) for a in
                                               (kin, build, solve, fkin, fbuild, fsolve))
    ours = kin + build + solve
    fast_step = fkin + fbuild + fsolve

    def us(a, q):
        return float(np.percentile(a, q)) * 1e6

    return {
        "steps": int(placo_run.steps),
        "formulation": formulation,
        "placo_step_us": us(placo_step, 50), "placo_p10_us": us(placo_step, 10),
        "placo_p90_us": us(placo_step, 90),
        "placo_kinematics_us": us(placo_run.kinematics_time_s, 50),
        "placo_solve_us": us(placo_run.solve_time_s, 50),
        "prioik_step_us": us(ours, 50), "prioik_p10_us": us(ours, 10),
        "prioik_p90_us": us(ours, 90),
        "prioik_kinematics_us": us(kin, 50), "prioik_build_us": us(build, 50),
        "prioik_solve_us": us(solve, 50),
        "prioik_buffer_step_us": us(fast_step, 50), "prioik_buffer_p10_us": us(fast_step, 10),
        "prioik_buffer_p90_us": us(fast_step, 90),
        "prioik_buffer_kinematics_us": us(fkin, 50), "prioik_buffer_build_us": us(fbuild, 50),
        "prioik_buffer_solve_us": us(fsolve, 50),
        "max_path_distance": distance,
        "description": (f"{int(placo_run.steps)} control steps (2 ms) of the compatible "
                        "fencing scenario, at PlaCo's own states. PlaCo: "
                        "`update_kinematics` + target updates, then "
                        "`KinematicsSolver.solve(True)` (support foot and CoM hard; left "
                        "foot, sword tip, posture soft; joint and velocity limits). prioik, "
                        "the velocity stack of the same five tasks as five strict levels "
                        f"solved by `{formulation}`, two ways at every state: the TaskStack "
                        "path (`KinematicState`, task terms, `Task`/`TaskStack`, plugin "
                        "`solve`) and the preallocated path (`KinematicState(drift=False)`, "
                        "`FencingScenario.write_velocity_rows` into a `TaskRows` buffer, "
                        "`BufferSolver.solve`); their answers differ by at most "
                        f"{distance:.1e} (relative). All three compute the same Python "
                        "references. Phase medians (µs): PlaCo kinematics "
                        f"{us(placo_run.kinematics_time_s, 50):.1f}, solve "
                        f"{us(placo_run.solve_time_s, 50):.1f}; TaskStack path kinematics "
                        f"{us(kin, 50):.1f}, stack building {us(build, 50):.1f}, solve "
                        f"{us(solve, 50):.1f}; preallocated path kinematics "
                        f"{us(fkin, 50):.1f}, rows {us(fbuild, 50):.1f}, solve "
                        f"{us(fsolve, 50):.1f}."),
    }
