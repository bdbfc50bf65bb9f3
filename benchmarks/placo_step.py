"""The whole G1 IK step (kinematics + solve): prioik's ``extended_jacobian`` against
PlaCo's ``KinematicsSolver`` on the same robot, tasks and states.

PlaCo runs the compatible fencing scenario through
:func:`benchmarks.placo_baseline.run_placo` (support foot and centre of mass hard;
left foot, sword tip and posture soft; joint and velocity limits); its step is
``update_kinematics`` plus the target updates (kinematics) and
``KinematicsSolver.solve(True)`` (solve), as that function times them.

prioik's step is timed at the same states (PlaCo's trajectory), two ways, each in its
own loop over the states (as PlaCo's step runs in its own):

* **one-off path** — :class:`robots.tasks.KinematicState` (pinocchio Jacobians,
  frame placements, centre of mass), building the velocity-level stack of the same
  five tasks in the scenario's priority order (support foot, com, left foot, sword
  tip, posture; ``J q̇ = ẋ* + K e``, ``K = 10``, the posture its ``K_p = 4``) —
  :meth:`robots.fencing.FencingScenario.terms`, :meth:`robots.tasks.TaskTerm.velocity`
  and :class:`hierarchy.TaskStack` — and ``prioik.solve`` (prepare + solve each step);
* **prepared path** — ``KinematicState(..., drift=False)``,
  :meth:`robots.fencing.FencingScenario.write_velocity_rows` into a
  :class:`robots.TaskWriter`'s data, and a solver prepared once
  (``prioik.prepare(layout, "extended_jacobian").solve(data)``: the same kernel, no
  per-step objects). Both paths' answers are compared at every state
  (``max_path_distance``).

The references alone are timed in a third loop (``references_us``), so that a
reader can subtract them from every step.

Both paths and PlaCo compute the same minimum-jerk references in Python
(:meth:`~robots.fencing.FencingScenario.com_ref`, ``left_foot_ref``, ``tip_ref``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from prioik.hierarchy import TaskStack

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
    from prioik import formulations
    from prioik.hierarchy import relative_distance
    from prioik.robots.fencing import FencingScenario
    from prioik.robots.tasks import KinematicState

    from .placo_baseline import run_placo

    scenario = FencingScenario("compatible")
    robot = scenario.robot
    placo_run = run_placo(scenario, duration=steps * DT, dt=DT)
    if placo_run.failed or placo_run.steps == 0:
        raise RuntimeError(f"PlaCo's run failed: {placo_run.message}")
    placo_step = placo_run.kinematics_time_s + placo_run.solve_time_s

    states = [(placo_run.q[i], placo_run.v[i], float(placo_run.t[i]))
              for i in range(placo_run.steps)]
    # each path in its own loop over the same states, as a control loop runs one path
    # (interleaving them let each evict the other's working set from the caches)
    data = robot.model.createData()
    gains = scenario.velocity_gains(GAIN)

    def stack_of(state, t):
        terms = scenario.terms(state, t)
        return TaskStack([terms[name].velocity(gains[name]) for name in ORDER if name in terms])

    (kin, build, solve), xs = _time_path(
        states, "TaskStack path", formulation,
        lambda q, v: KinematicState(robot, q, v, data), stack_of,
        lambda stack: formulations.solve(stack, formulation))
    data_fast = robot.model.createData()
    rows = scenario.velocity_rows(GAIN)
    solver = formulations.prepare(rows.data.layout, formulation)
    (fkin, fbuild, fsolve), fxs = _time_path(
        states, "preallocated path", formulation,
        lambda q, v: KinematicState(robot, q, v, data_fast, drift=False),
        lambda state, t: scenario.write_velocity_rows(rows, state, t), solver.solve)
    refs = []          # the references alone, as all three steps compute them
    for _, _, t in states:
        t0 = time.perf_counter()
        scenario.com_ref(t), scenario.left_foot_ref(t), scenario.tip_ref(t)
        refs.append(time.perf_counter() - t0)
    distance = max(relative_distance(a, b) for a, b in zip(fxs, xs, strict=False))
    refs = np.array(refs)
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
        "prioik_oneoff_step_us": us(ours, 50), "prioik_oneoff_p10_us": us(ours, 10),
        "prioik_oneoff_p90_us": us(ours, 90),
        "prioik_oneoff_kinematics_us": us(kin, 50), "prioik_oneoff_build_us": us(build, 50),
        "prioik_oneoff_solve_us": us(solve, 50),
        "prioik_prepared_step_us": us(fast_step, 50), "prioik_prepared_p10_us": us(fast_step, 10),
        "prioik_prepared_p90_us": us(fast_step, 90),
        "prioik_prepared_kinematics_us": us(fkin, 50), "prioik_prepared_build_us": us(fbuild, 50),
        "prioik_prepared_solve_us": us(fsolve, 50),
        "references_us": us(refs, 50),
        "max_path_distance": distance,
        "description": (f"{int(placo_run.steps)} control steps (2 ms) of the compatible "
                        "fencing scenario, at PlaCo's own states. PlaCo: "
                        "`update_kinematics` + target updates, then "
                        "`KinematicsSolver.solve(True)` (support foot and CoM hard; left "
                        "foot, sword tip, posture soft; joint and velocity limits). prioik, "
                        "the velocity stack of the same five tasks as five strict levels "
                        f"solved by `{formulation}`, two ways, each in its own loop over the "
                        "states: the TaskStack "
                        "path (`KinematicState`, task terms, `Task`/`TaskStack`, plugin "
                        "`solve`) and the preallocated path (`KinematicState(drift=False)`, "
                        "`FencingScenario.write_velocity_rows` into a `TaskWriter`'s data, "
                        "a solver prepared once, `solver.solve(rows.data)`); their answers "
                        "differ by at most "
                        f"{distance:.1e} (relative). All three compute the same Python "
                        "references. Phase medians (µs): PlaCo kinematics "
                        f"{us(placo_run.kinematics_time_s, 50):.1f}, solve "
                        f"{us(placo_run.solve_time_s, 50):.1f}; TaskStack path kinematics "
                        f"{us(kin, 50):.1f}, stack building {us(build, 50):.1f}, solve "
                        f"{us(solve, 50):.1f}; preallocated path kinematics "
                        f"{us(fkin, 50):.1f}, rows {us(fbuild, 50):.1f}, solve "
                        f"{us(fsolve, 50):.1f}; the references alone (in every "
                        f"kinematics or rows phase) {us(refs, 50):.1f}."),
    }


def _time_path(states, label: str, formulation: str, kinematics, build, solve
               ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Time one path over ``states`` (``(q, v, t)``): ``kinematics(q, v)``,
    ``build(state, t)``, ``solve(problem)``; returns the ``3 × N`` phase times (s)
    and the answers.

    Raises:
        RuntimeError: a solve failed (naming the path and the time).
    """
    times = np.empty((3, len(states)))
    xs = []
    for i, (q, v, t) in enumerate(states):
        t0 = time.perf_counter()
        state = kinematics(q, v)
        t1 = time.perf_counter()
        problem = build(state, t)
        t2 = time.perf_counter()
        out = solve(problem)
        t3 = time.perf_counter()
        if out.status == "failed":
            raise RuntimeError(f"{formulation} failed at t = {t:.3f} s ({label})")
        xs.append(out.x)
        times[:, i] = (t1 - t0, t2 - t1, t3 - t2)
    return times, xs
