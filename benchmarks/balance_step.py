"""The whole G1 IK step of a balance reach — feet held, joint position and velocity
limits, the centre of mass over the support polygon — in prioik and in PlaCo.

The task: the G1 from its standing configuration reaches with its left hand 0.45 m
forward, 0.1 m left and 0.35 m down (velocity level, ``dt`` = 10 ms), both feet held,
the CoM kept over the feet's soles (corners 5 cm behind and 10 cm ahead of each foot
frame, 3 cm to each side; the hull shrunk by a 2 cm margin).

* **prioik** (prepared path): ``KinematicState(drift=False)``, a
  :class:`~prioik.robots.TaskWriter` — level 0 the two feet (contacts, ``K = 10``), the
  joint-limit bounds on ``q̇`` and the CoM region
  (:func:`~prioik.robots.polygon_region`, :meth:`~prioik.robots.TaskWriter.add_com_region`);
  level 1 the hand position (``K = 10``); level 2 the posture (``K = 1``) — and a
  ``hierarchical_active_set`` solver prepared once (warm-started).
* **PlaCo** (``KinematicsSolver``): the feet as hard frame tasks, the CoM polygon as a
  hard ``add_com_polygon_constraint`` (the same hull, clockwise, the same margin), the
  hand as a soft position task (weight 1), the posture as a soft joints task (1e-4),
  ``enable_joint_limits`` and ``enable_velocity_limits``; its step is
  ``update_kinematics`` + ``solve(True)``.

Each is timed on its own closed loop from the same start (a control loop solves its
own states), and prioik also at PlaCo's states (PlaCo's trajectory, where its CoM rides
the polygon's edge one step inside and the next on it: prioik's kept working set is then
wrong every other step). Rounds interleave the paths (the fastest round's median per
path).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: control step (s), hand offset from its start (m), support polygon margin (m)
DT = 0.01
REACH = np.array([0.45, 0.1, -0.35])
MARGIN = 0.02
#: sole corners around each foot frame (m): x behind/ahead, y to each side
SOLE_X = (-0.05, 0.1)
SOLE_Y = (-0.03, 0.03)
FEET = ("left_foot", "right_foot")


def balance_setup(robot) -> dict[str, Any]:
    """The task's fixed data at the robot's ``q0``: foot placements, sole corners, the
    polygon's rows ``C, upper`` (:func:`~prioik.robots.polygon_region`) and the hand's
    target."""
    from prioik.robots import KinematicState, polygon_region

    start = KinematicState(robot, robot.q0, np.zeros(robot.nv), drift=False)
    places = {f: start.placement(f).copy() for f in FEET}
    soles = np.array([places[f].act(np.array([dx, dy, 0.0])) for f in FEET
                      for dx in SOLE_X for dy in SOLE_Y])
    C, upper = polygon_region(soles, margin=MARGIN)
    return {"places": places, "soles": soles, "C": C, "upper": upper,
            "target": start.placement("left_hand").translation + REACH}


def prioik_balance(robot, setup: dict[str, Any]):
    """prioik's writer and prepared solver; returns ``(step, writer, solver)`` where
    ``step(q) -> Outcome`` writes the rows at ``q`` (zero velocity) and solves."""
    import prioik
    from prioik.robots import KinematicState, TaskWriter

    w = TaskWriter(robot, "velocity")
    for f in FEET:
        w.add_contact(f, f, gain=10.0, level=0)
    w.add_joint_limits("limits", form="bounds", dt=DT, level=0)
    w.add_com_region("balance", setup["C"], upper=setup["upper"], dt=DT, level=0)
    w.add_frame_position("reach", "left_hand", gain=10.0, level=1)
    w.add_posture("posture", gain=1.0, level=2)
    solver = prioik.prepare(w.layout, "hierarchical_active_set")
    data = robot.model.createData()
    zero = np.zeros(robot.nv)
    places, target, q0 = setup["places"], setup["target"], robot.q0

    def step(q):
        state = KinematicState(robot, q, zero, data, drift=False)
        for f in FEET:
            w.contact(state, f, places[f])
        w.joint_limits(state, "limits")
        w.com_region(state, "balance")
        w.frame_position(state, "reach", target)
        w.posture(state, "posture", q0)
        return solver.solve(w.targets(state))

    return step, w, solver


def placo_balance(robot, setup: dict[str, Any], steps: int):
    """PlaCo's solver for the same task; returns ``(step, states, reset)`` as
    :func:`prioik.benchmarks.panda_step.placo_panda`: one PlaCo step, PlaCo's own
    ``steps`` configurations from ``q0``, and a reset to ``q0`` (done once here)."""
    return placo_feet(robot, setup, steps, DT, balance=True)


def placo_feet(robot, setup: dict[str, Any], steps: int, dt: float, *, balance: bool):
    """PlaCo's ``KinematicsSolver`` on the G1 with both feet held (hard), the CoM in the
    feet's support polygon when ``balance`` (hard, :data:`MARGIN` inside), the left hand
    reaching ``setup["target"]`` (soft, 1), the joints at ``q0`` (soft, 1e-4), its joint
    and velocity limits, step ``dt``; returns ``(step, states, reset)`` as
    :func:`placo_balance`."""
    import placo
    from scipy.spatial import ConvexHull

    from prioik.robots.models import example_robot_data_dir

    frames = robot.frames
    share = example_robot_data_dir().parent.parent
    pw = placo.RobotWrapper(str(share), placo.Flags.ignore_collisions,
                            Path(robot.source).read_text())
    pw.state.q = robot.q0.copy()
    pw.update_kinematics()
    solver = placo.KinematicsSolver(pw)
    solver.enable_joint_limits(True)
    solver.enable_velocity_limits(True)
    solver.dt = dt
    for f in FEET:
        solver.add_frame_task(frames[f], setup["places"][f].homogeneous).configure(
            f, "hard", 1.0, 1.0)
    if balance:
        soles = setup["soles"][:, :2]
        hull = soles[ConvexHull(soles).vertices][::-1]           # PlaCo's order: clockwise
        solver.add_com_polygon_constraint([np.array(v) for v in hull], MARGIN).configure(
            "balance", "hard", 1.0)
    solver.add_position_task(frames["left_hand"], setup["target"]).configure(
        "reach", "soft", 1.0)
    joints = solver.add_joints_task()
    model = robot.model
    joints.set_joints({n: float(robot.q0[model.joints[model.getJointId(n)].idx_q])
                       for n in list(model.names)[2:]})
    joints.configure("posture", "soft", 1e-4)
    states = []
    for _ in range(steps):
        states.append(np.array(pw.state.q))
        pw.update_kinematics()
        solver.solve(True)

    def reset() -> None:
        pw.state.q = robot.q0.copy()

    def step(_i: int = 0) -> None:
        pw.update_kinematics()
        solver.solve(True)
    reset()
    return step, states, reset


def balance_step_times(steps: int = 300, rounds: int = 5) -> dict[str, Any]:
    """Median step times (µs) of prioik on its own loop and at PlaCo's states, and of
    PlaCo; the CoM's worst excursion past the shrunk polygon (m) and the hand's final
    error (m) on each own loop; prioik's statuses and how often its equality-first try
    answered.

    Raises:
        ImportError: placo, scipy or pinocchio is missing.
    """
    import pinocchio as pin

    from prioik.robots import KinematicState, load

    from .panda_step import _rounds

    robot = load("g1")
    setup = balance_setup(robot)
    C, upper, target = setup["C"], setup["upper"], setup["target"]
    placo_step, placo_states, placo_reset = placo_balance(robot, setup, steps)
    solve, _, _ = prioik_balance(robot, setup)
    data = robot.model.createData()
    zero = np.zeros(robot.nv)

    def excursion(q) -> float:
        com = KinematicState(robot, q, zero, data, drift=False).com
        return float(np.max(C @ com - upper))

    def hand_error(q) -> float:
        hand = KinematicState(robot, q, zero, data, drift=False).placement("left_hand")
        return float(np.linalg.norm(hand.translation - target))

    own = [robot.q0.copy()]
    for _ in range(steps - 1):
        own.append(pin.integrate(robot.model, own[-1], solve(own[-1]).x * DT))
    statuses: set[str] = set()
    first: list[bool] = []

    def prioik_own(i: int) -> None:
        out = solve(own[i])
        statuses.add(out.status)
        first.append(bool(out.detail.equality_first))

    def prioik_at_placo(i: int) -> None:
        statuses.add(solve(placo_states[i]).status)

    placo_reset()
    best = _rounds({"own": prioik_own, "at_placo_states": prioik_at_placo,
                    "placo": placo_step}, steps, rounds)
    return {"steps": steps,
            "prioik_step_us": float(np.median(best["own"])) * 1e6,
            "prioik_at_placo_states_us": float(np.median(best["at_placo_states"])) * 1e6,
            "placo_step_us": float(np.median(best["placo"])) * 1e6,
            "prioik_com_excursion_m": max(excursion(q) for q in own),
            "placo_com_excursion_m": max(excursion(q) for q in placo_states),
            "prioik_hand_error_m": hand_error(own[-1]),
            "placo_hand_error_m": hand_error(placo_states[-1]),
            "equality_first_share": float(np.mean(first[:steps])) if first else 0.0,
            "statuses": sorted(str(s) for s in statuses)}
