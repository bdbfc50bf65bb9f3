"""The whole velocity IK step with limits in mink, in prioik and in PlaCo, side by side.

Two problems, each timed in one process, the three paths alternating round by round at
the same states (PlaCo's own trajectory; :func:`prioik.benchmarks.panda_step._rounds`:
the fastest round's median per path):

* **Panda reach with limits** — the 9-DoF Panda of
  :func:`prioik.benchmarks.active_set_bench.panda_limits_step` (hand position to
  :data:`~prioik.benchmarks.panda_step.HAND_TARGET`, posture, joint position and velocity
  limits, ``dt`` = 2 ms). prioik: joint-limit bounds above the hand (``K = 10``) above
  the posture (``K = 1``), ``hierarchical_active_set`` prepared once. PlaCo:
  :func:`~prioik.benchmarks.panda_step.placo_panda` with limits (soft hand weight 1,
  soft joints 1e-4). mink: ``FrameTask`` on ``panda_hand`` (position cost 1,
  orientation 0), ``PostureTask`` (cost 1e-2: PlaCo's weight 1e-4 on the squared error),
  ``ConfigurationLimit``, ``VelocityLimit``.
* **G1 with both feet held** — the G1 reaching with its left hand as in
  :mod:`prioik.benchmarks.balance_step` (``dt`` = 10 ms, the same target), without the
  CoM polygon (mink has no such constraint). prioik: the two feet (contacts, ``K = 10``)
  and the joint-limit bounds at level 0, the hand (``K = 10``) at level 1, the posture
  (``K = 1``) at level 2, ``hierarchical_active_set``. PlaCo: the feet as hard frame
  tasks, the hand soft (1), the joints soft (1e-4), its joint and velocity limits. mink:
  the feet as ``FrameTask`` equality constraints, the hand ``FrameTask`` (position cost
  1), ``PostureTask`` (1e-2), ``ConfigurationLimit``, ``VelocityLimit``.

mink's step is ``Configuration.update`` at the state (its MuJoCo kinematics), the map
of the state to MuJoCo's ``qpos`` and ``solve_ik``; prioik's is timed twice: the writer
loop (``KinematicState``, the writers, ``solver.solve``) and
:class:`prioik.robots.ControlStep` over the same tasks (its step integrated too, as
PlaCo's); each step computes its own kinematics. mink's QP back-end is ``solver`` (default
:data:`prioik.benchmarks.mink_baseline.DEFAULT_SOLVER`, DAQP).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["panda_mink_step", "g1_feet_mink_step", "run", "format_table"]

#: mink's posture cost: PlaCo's joints weight 1e-4 is on the squared error, mink's cost
#: on the error
POSTURE_COST = 1e-2


def _mink(robot, urdf_text: str | None, hand: str, target, feet: dict, solver: str):
    """``(solve, advance)``: mink's velocity at a pinocchio configuration, and the next
    configuration after it (integrated by MuJoCo: its free joint's linear velocity is in
    the world frame, pinocchio's in the base frame)."""
    import mink

    from prioik.robots.mujoco_model import to_mujoco
    mj = to_mujoco(robot, urdf_text)
    config = mink.Configuration(mj.model, mj.to_qpos(robot.q0))
    reach = mink.FrameTask(hand, "body", position_cost=1.0, orientation_cost=0.0)
    reach.set_target(mink.SE3.from_translation(np.asarray(target, dtype=float)))
    posture = mink.PostureTask(mj.model, cost=POSTURE_COST)
    posture.set_target(mj.to_qpos(robot.q0))
    constraints = []
    for frame, placement in feet.items():
        task = mink.FrameTask(frame, "body", position_cost=1.0, orientation_cost=1.0)
        task.set_target(mink.SE3.from_matrix(np.asarray(placement.homogeneous)))
        constraints.append(task)
    limits = [mink.ConfigurationLimit(mj.model),
              mink.VelocityLimit(mj.model, mj.velocity_limits())]
    tasks = [reach, posture]

    def solve(q, dt):
        config.update(mj.to_qpos(q))
        return mink.solve_ik(config, tasks, dt, solver, limits=limits,
                             constraints=constraints or None, safety_break=False)

    def advance(q, dt):
        return mj.to_q(config.integrate(solve(q, dt), dt))
    return solve, advance


def _g1_rows(robot, dt: float):
    """The G1's levels: both feet held and the joint-limit bounds, the left hand, the
    posture."""
    from prioik.robots import TaskWriter

    from .balance_step import FEET
    w = TaskWriter(robot, "velocity")
    for f in FEET:
        w.add_contact(f, f, gain=10.0, level=0)
    w.add_joint_limits("limits", form="bounds", dt=dt, level=0)
    w.add_frame_position("reach", "left_hand", gain=10.0, level=1)
    w.add_posture("posture", gain=1.0, level=2)
    return w


def panda_mink_step(steps: int = 300, rounds: int = 7, solver: str | None = None
                    ) -> dict[str, Any]:
    """Median step times (µs) of mink, prioik and PlaCo on the Panda reach with limits
    (see the module docstring), at PlaCo's states; and each one's hand error at the last
    state of its own closed loop (m)."""
    import pinocchio as pin

    import prioik
    from prioik.robots import ControlStep, KinematicState, load

    from .mink_baseline import DEFAULT_SOLVER
    from .panda_step import DT, HAND_TARGET, _rounds, placo_panda, reach_rows

    solver = solver or DEFAULT_SOLVER
    robot = load("panda")
    model, q0, nv = robot.model, robot.q0, robot.nv
    hand = robot.frames["hand"]
    placo_step, states, placo_reset = placo_panda(robot, steps, limits=True)
    mink_solve, mink_advance = _mink(robot, None, hand, HAND_TARGET, {}, solver)

    data = model.createData()
    zero = np.zeros(nv)
    rows = reach_rows(robot, limits=True)
    solver_ = prioik.prepare(rows.layout, "hierarchical_active_set")
    control = ControlStep(reach_rows(robot, limits=True), "hierarchical_active_set", dt=DT)
    control.reference("hand", HAND_TARGET)
    control.reference("posture", q0)

    def prioik_solve(q):
        state = KinematicState(robot, q, zero, data, drift=False)
        rows.joint_limits(state, "joint_limits")
        rows.frame_position(state, "hand", HAND_TARGET)
        rows.posture(state, "posture", q0)
        return solver_.solve(rows.targets(state)).x

    paths = {"prioik": lambda i: prioik_solve(states[i]),
             "control": lambda i: control(states[i]),
             "mink": lambda i: mink_solve(states[i], DT),
             "placo": placo_step}
    for path in paths.values():               # warm-up: caches
        for i in range(min(50, steps)):
            path(i)
    placo_reset()
    best = _rounds(paths, steps, rounds)
    own = {"prioik": q0.copy(), "mink": q0.copy()}
    for _ in range(steps):
        own["prioik"] = pin.integrate(model, own["prioik"], prioik_solve(own["prioik"]) * DT)
        own["mink"] = mink_advance(own["mink"], DT)
    own["placo"] = states[-1]
    hand_error = {k: float(np.linalg.norm(
        KinematicState(robot, q, zero, data, drift=False).placement(hand).translation
        - HAND_TARGET)) for k, q in own.items()}
    lo, hi, _ = robot.joint_limits()
    violation = {k: float(max(0.0, np.max(lo - q), np.max(q - hi))) for k, q in own.items()}
    return _times(best) | {"steps": steps, "solver": solver, "hand_error_m": hand_error,
                           "joint_limit_violation_rad": violation}


def g1_feet_mink_step(steps: int = 300, rounds: int = 5, solver: str | None = None
                      ) -> dict[str, Any]:
    """Median step times (µs) of mink, prioik and PlaCo on the G1 with both feet held
    (see the module docstring), at PlaCo's states; and on each one's own closed loop the
    feet's worst drift (m) and the hand's final error (m)."""
    import pinocchio as pin

    import prioik
    from prioik.robots import ControlStep, KinematicState, load

    from .balance_step import DT, FEET, balance_setup, placo_feet
    from .mink_baseline import DEFAULT_SOLVER
    from .panda_step import _rounds

    solver = solver or DEFAULT_SOLVER
    robot = load("g1")
    setup = balance_setup(robot)
    places, target, q0 = setup["places"], setup["target"], robot.q0
    placo_step, states, placo_reset = placo_feet(robot, setup, steps, DT, balance=False)
    mink_solve, mink_advance = _mink(robot, None, robot.frames["left_hand"], target,
                          {robot.frames[f]: places[f] for f in FEET}, solver)

    w = _g1_rows(robot, DT)
    solver_ = prioik.prepare(w.layout, "hierarchical_active_set")
    control = ControlStep(_g1_rows(robot, DT), "hierarchical_active_set", dt=DT)
    for f in FEET:
        control.reference(f, places[f])
    control.reference("reach", target)
    control.reference("posture", q0)
    data = robot.model.createData()
    zero = np.zeros(robot.nv)
    statuses: set[str] = set()

    def prioik_solve(q):
        state = KinematicState(robot, q, zero, data, drift=False)
        for f in FEET:
            w.contact(state, f, places[f])
        w.joint_limits(state, "limits")
        w.frame_position(state, "reach", target)
        w.posture(state, "posture", q0)
        sol = solver_.solve(w.targets(state))
        statuses.add(sol.status)
        return sol.x

    paths = {"prioik": lambda i: prioik_solve(states[i]),
             "control": lambda i: control(states[i]),
             "mink": lambda i: mink_solve(states[i], DT),
             "placo": placo_step}
    for path in paths.values():
        for i in range(min(50, steps)):
            path(i)
    placo_reset()
    best = _rounds(paths, steps, rounds)
    loops = {"placo": states, "prioik": [q0.copy()], "mink": [q0.copy()]}
    for _ in range(steps - 1):
        q = loops["prioik"][-1]
        loops["prioik"].append(pin.integrate(robot.model, q, prioik_solve(q) * DT))
        loops["mink"].append(mink_advance(loops["mink"][-1], DT))

    def feet_drift(q) -> float:
        s = KinematicState(robot, q, zero, data, drift=False)
        return max(float(np.linalg.norm(s.placement(f).translation - places[f].translation))
                   for f in FEET)

    def hand_error(q) -> float:
        s = KinematicState(robot, q, zero, data, drift=False)
        return float(np.linalg.norm(s.placement("left_hand").translation - target))

    return _times(best) | {
        "steps": steps, "solver": solver, "prioik_statuses": sorted(statuses),
        "feet_drift_m": {k: max(feet_drift(q) for q in qs) for k, qs in loops.items()},
        "hand_error_m": {k: hand_error(qs[-1]) for k, qs in loops.items()}}


def _times(best: dict[str, np.ndarray]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, t in best.items():
        out[f"{key}_step_us"] = float(np.median(t)) * 1e6
        out[f"{key}_p90_us"] = float(np.percentile(t, 90)) * 1e6
    out["mink/prioik"] = out["mink_step_us"] / out["prioik_step_us"]
    out["control/placo"] = out["control_step_us"] / out["placo_step_us"]
    out["mink/placo"] = out["mink_step_us"] / out["placo_step_us"]
    return out


def run(steps: int = 300, solvers: tuple[str, ...] | None = None,
        rounds: int | None = None) -> dict[str, Any]:
    """:func:`panda_mink_step` and :func:`g1_feet_mink_step` with each of ``solvers``
    (default: mink's documented back-end) as mink's back-end, one BLAS thread;
    ``rounds``: each function's default unless given."""
    from prioik.threads import blas_threads

    from .mink_baseline import DEFAULT_SOLVER
    out: dict[str, Any] = {}
    with blas_threads(1):
        for solver in solvers or (DEFAULT_SOLVER,):
            kw = {"solver": solver} | ({"rounds": rounds} if rounds else {})
            out[f"panda[{solver}]"] = panda_mink_step(steps, **kw)
            out[f"g1_feet[{solver}]"] = g1_feet_mink_step(steps, **kw)
    return out


def format_table(results: dict[str, Any]) -> str:
    """A markdown table of :func:`run`'s result."""
    lines = ["| problem [mink back-end] | mink µs | prioik µs (writer loop) | prioik µs "
             "(ControlStep) | PlaCo µs | mink/prioik | mink/PlaCo | ControlStep/PlaCo |",
             "|---|---|---|---|---|---|---|---|"]
    for key, r in results.items():
        lines.append(f"| {key} | {r['mink_step_us']:.1f} | {r['prioik_step_us']:.1f} | "
                     f"{r['control_step_us']:.1f} | {r['placo_step_us']:.1f} | "
                     f"{r['mink/prioik']:.2f} | {r['mink/placo']:.2f} | "
                     f"{r['control/placo']:.2f} |")
    return "\n".join(lines)


if __name__ == "__main__":   # pragma: no cover - the measurement's command
    import json
    import sys

    from prioik.smoke import active, cap
    res = run(cap(int(sys.argv[1]) if len(sys.argv) > 1 else 300, 20),   # PRIOIK_SMOKE=1
              tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else None,
              rounds=1 if active() else None)
    print(format_table(res))
    print(json.dumps(res, indent=1, default=str))
