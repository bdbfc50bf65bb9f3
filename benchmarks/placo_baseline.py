"""The fencing scenario with PlaCo's own ``KinematicsSolver`` — what users run today.

PlaCo solves, each control step, one weighted QP for a displacement ``Δq`` with
*hard* tasks as equality constraints, *soft* tasks as weighted costs, and joint
position and velocity limits as inequalities (``enable_joint_limits``,
``enable_velocity_limits``, with ``solver.dt``). It has two priority levels, so the
scenario's strict hierarchy is mapped to:

* hard: the support (right) foot frame task and the horizontal centre of mass;
* soft: the left foot frame (weight 1), the sword tip (weight 1) and the posture
  (joints task, weight 1e-4);
* joint and velocity limits: PlaCo's own inequality constraints.

Targets are the scenario's references at the next step, ``x*(t + dt)``; PlaCo drives
each task's error to zero within one step when it can (its tasks are displacement-
level, ``J Δq = x* − x``, i.e. the velocity task ``J q̇ = e / dt``). The sword tip is a
fixed link added to a copy of the G1 URDF (``sword_tip``, 0.5 m along
``left_rubber_hand``), loaded from text; no file is written.

The recorded quantities are those of :func:`robots.simulate`, computed with the
toolkit's own kinematics on PlaCo's configurations: ``q̇ = Δq / dt``,
``q̈ = (q̇_{k+1} − q̇_k) / dt`` and ``τ`` by RNEA. The algorithmic error (eq. 29) is not
defined for a weighted soft hierarchy and is recorded as NaN.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pinocchio as pin

SOFT_WEIGHTS = {"left_foot": 1.0, "sword_tip": 1.0, "posture": 1e-4}


def _sword_urdf(urdf_path: str, parent: str, length: float) -> str:
    """The URDF text with a ``sword_tip`` link fixed ``length`` along ``parent``'s x."""
    text = Path(urdf_path).read_text()
    extra = (f'  <link name="sword_tip"/>\n'
             f'  <joint name="sword_tip_joint" type="fixed">\n'
             f'    <parent link="{parent}"/>\n    <child link="sword_tip"/>\n'
             f'    <origin xyz="{length} 0 0" rpy="0 0 0"/>\n  </joint>\n')
    end = text.rindex("</robot>")
    return text[:end] + extra + text[end:]


def run_placo(scenario, *, duration: float, dt: float, progress=None):
    """Run the scenario with ``placo.KinematicsSolver``; returns a
    :class:`robots.SimulationResult`.

    Args:
        scenario: A :class:`robots.fencing.FencingScenario` (its G1 model).
        duration: Simulated seconds.
        dt: Control step (s).
        progress: Called with the simulated time every 250 steps.
    """
    import placo

    from prioik.robots import KinematicState, SimulationResult
    from prioik.robots.fencing import SWORD_LENGTH
    from prioik.robots.models import example_robot_data_dir

    robot = scenario.robot
    hand = robot.frames["left_hand"]
    urdf = _sword_urdf(robot.source, hand, SWORD_LENGTH)
    # meshes are ``package://example-robot-data/...``: resolved from the share folder
    share = example_robot_data_dir().parent.parent
    pw = placo.RobotWrapper(str(share), placo.Flags.ignore_collisions, urdf)
    names = list(robot.model.names)[2:]
    if list(pw.joint_names()) != names:
        raise RuntimeError("PlaCo's joint order differs from pinocchio's for the G1")
    pw.state.q = robot.q0.copy()
    pw.update_kinematics()
    solver = placo.KinematicsSolver(pw)
    solver.mask_fbase(False)
    solver.enable_joint_limits(True)
    solver.enable_velocity_limits(True)
    solver.dt = dt
    support = solver.add_frame_task(robot.frames["right_foot"],
                                    scenario.right_foot0.homogeneous)
    support.configure("support_foot", "hard", 1.0, 1.0)
    com0 = np.array(pw.com_world())
    com = solver.add_com_task(com0)
    com.configure("com", "hard", 1.0)
    com.mask.set_axises("xy")
    foot = solver.add_frame_task(robot.frames["left_foot"], scenario.left_foot0.homogeneous)
    foot.configure("left_foot", "soft", SOFT_WEIGHTS["left_foot"], SOFT_WEIGHTS["left_foot"])
    tip = solver.add_position_task("sword_tip", scenario.tip0.copy())
    tip.configure("sword_tip", "soft", SOFT_WEIGHTS["sword_tip"])
    joints = solver.add_joints_task()
    q_ref = {n: float(robot.q0[robot.model.joints[robot.model.getJointId(n)].idx_q])
             for n in names}
    joints.set_joints(q_ref)
    joints.configure("posture", "soft", SOFT_WEIGHTS["posture"])

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
        t0 = time.perf_counter()
        pw.update_kinematics()
        ref_foot = scenario.left_foot_ref(t + dt)
        T = np.array(scenario.left_foot0.homogeneous)
        T[:3, 3] = ref_foot.x
        foot.T_world_frame = T
        c = com0.copy()
        c[:2] = scenario.com_ref(t + dt).x
        com.target_world = c
        tip.target_world = scenario.tip_ref(t + dt).x
        t1 = time.perf_counter()
        try:
            dq = np.array(solver.solve(True))
        except RuntimeError as exc:       # PlaCo raises on an infeasible QP
            failed, message = True, f"t = {t:.3f} s: PlaCo: {exc}"
            break
        t2 = time.perf_counter()
        v_next = dq / dt
        q_next = np.array(pw.state.q)
        if not (np.isfinite(v_next).all() and np.isfinite(q_next).all()):
            failed, message = True, f"t = {t:.3f} s: PlaCo returned non-finite values"
            break
        a = (v_next - v) / dt
        t2b = time.perf_counter()
        tau = np.array(pin.rnea(model, dyn, q, v, a))
        t3 = time.perf_counter()
        state = KinematicState(robot, q, v, data)
        step_errors = scenario.errors(state, t, scenario.terms(state, t))
        for name, value in step_errors.items():
            errors.setdefault(name, []).append(value)
        for key, val in (("t", t), ("q", q.copy()), ("v", v.copy()), ("a", a), ("tau", tau),
                         ("tk", t1 - t0), ("ts", t2 - t1), ("tt", t3 - t2b)):
            rows[key].append(val)
        statuses.append("approximate")
        q, v = q_next, v_next
        if progress is not None and (k + 1) % 250 == 0:
            progress(t + dt)

    def arr(key, width):
        return np.array(rows[key], dtype=float).reshape(-1, width)

    return SimulationResult(np.array(rows["t"], dtype=float), arr("q", robot.nq),
                            arr("v", robot.nv), arr("a", robot.nv), arr("tau", robot.nv),
                            {k: np.array(v_, dtype=float) for k, v_ in errors.items()},
                            np.full(len(rows["t"]), np.nan), np.array(rows["tk"]),
                            np.array(rows["ts"]), np.array(rows["tt"]), statuses, failed,
                            message)
