"""The 9-DoF Panda reach step: prioik's ControlStep, its writer loop, its one-off path
and PlaCo.

A fixed-base arm (example-robot-data's Panda, 7 arm joints + 2 fingers) reaches a hand
target at velocity level: two strict levels, the hand position (3 rows,
``J q̇ = K e``, ``K = 10``) above the posture (9 rows, ``q̇ = K_p (q_0 − q)``,
``K_p = 1``), no limits. Timed per control step, each path in its own loop over the
same states (PlaCo's trajectory), median of several interleaved rounds:

* prioik, ``ControlStep`` (:class:`prioik.robots.ControlStep`,
  ``hierarchical_active_set``): pinocchio's Jacobians, then the rows, the solve and
  the integration in one compiled call — the README's control loop;
* prioik, prepared: ``KinematicState(drift=False)``, the rows written in place
  (``TaskWriter.frame_position``, ``posture``, ``targets``) and ``extended_jacobian``
  prepared once (``solver.solve(rows.data)``) — what ControlStep does, step by step
  in Python;
* prioik, one-off: the same kinematics, ``Task`` objects and ``prioik.solve``;
* PlaCo: ``update_kinematics`` + ``KinematicsSolver.solve(True)`` with a soft position
  task (weight 1) and a soft joints task (weight 1e-4), base masked — PlaCo's
  two-priority QP for the same two tasks, without limits.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["panda_step_times", "reach_rows", "HAND_TARGET"]

#: The hand target (world, m): in front of and above the base, reachable.
HAND_TARGET = np.array([0.45, 0.2, 0.45])
DT = 0.002
GAINS = {"hand": 10.0, "posture": 1.0}


def _rounds(paths: dict[str, Callable[[int], None]], states: int, rounds: int
            ) -> dict[str, np.ndarray]:
    """Per path, the per-step times (s) of its fastest round (lowest median): rounds
    interleave the paths so that each sees the same machine load."""
    best: dict[str, np.ndarray] = {}
    for _ in range(rounds):
        for name, step in paths.items():
            times = np.empty(states)
            for i in range(states):
                t0 = time.perf_counter()
                step(i)
                times[i] = time.perf_counter() - t0
            if name not in best or np.median(times) < np.median(best[name]):
                best[name] = times
    return best


def placo_panda(robot, steps: int, limits: bool = False, target=None):
    """PlaCo's ``KinematicsSolver`` on the Panda with the reach's two soft tasks (hand
    position to ``target``, default :data:`HAND_TARGET`, weight 1; joints, 1e-4), base
    masked, and its joint and velocity limits when ``limits``; returns ``(step, states,
    reset)``: a function doing one PlaCo step (``update_kinematics`` + ``solve``), the
    ``steps`` configurations of PlaCo's own trajectory from ``robot.q0``, and a function
    putting PlaCo back at ``q0`` (done once here)."""
    import placo

    from prioik.robots.models import example_robot_data_dir

    model, q0, hand = robot.model, robot.q0, robot.frames["hand"]
    share = example_robot_data_dir().parent.parent
    pw = placo.RobotWrapper(str(share), placo.Flags.ignore_collisions,
                            Path(robot.source).read_text())
    base = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])     # PlaCo adds a free flyer
    pw.state.q = np.concatenate([base, q0])
    pw.update_kinematics()
    solver = placo.KinematicsSolver(pw)
    solver.mask_fbase(True)
    if limits:
        solver.enable_joint_limits(True)
        solver.enable_velocity_limits(True)
    solver.dt = DT
    solver.add_position_task(hand, HAND_TARGET if target is None else np.asarray(
        target, dtype=float)).configure("hand", "soft", 1.0)
    joints = solver.add_joints_task()
    joints.set_joints({name: float(q0[model.joints[model.getJointId(name)].idx_q])
                       for name in pw.joint_names()})
    joints.configure("posture", "soft", 1e-4)
    states = []
    for _ in range(steps):
        states.append(np.array(pw.state.q)[7:].copy())
        pw.update_kinematics()
        solver.solve(True)

    def reset() -> None:
        pw.state.q = np.concatenate([base, q0])

    def step(_i: int = 0) -> None:
        pw.update_kinematics()
        solver.solve(True)
    reset()
    return step, states, reset


def reach_rows(robot, limits: bool = False):
    """The Panda reach's levels, declared on a velocity-level writer: the hand position
    (``K = 10``) above the posture (``K_p = 1``), below joint-limit bounds (``dt`` =
    :data:`DT`) at level 0 when ``limits``."""
    from prioik.robots import TaskWriter

    rows = TaskWriter(robot, "velocity")
    level = 0
    if limits:
        rows.add_joint_limits("joint_limits", form="bounds", dt=DT, level=0)
        level = 1
    rows.add_frame_position("hand", robot.frames["hand"], gain=GAINS["hand"], level=level)
    rows.add_posture("posture", gain=GAINS["posture"], level=level + 1)
    return rows


def panda_step_times(steps: int = 300, rounds: int = 7) -> dict[str, Any]:
    """Median, p10 and p90 (µs) of the three step paths; see the module docstring.

    Raises:
        ImportError: placo or pinocchio is missing.
        RuntimeError: a path failed, or the prioik paths disagree.
    """
    import prioik
    from prioik.hierarchy import Task, TaskStack, relative_distance
    from prioik.robots import ControlStep, KinematicState, load

    robot = load("panda")
    model, q0, nv = robot.model, robot.q0, robot.nv
    hand = robot.frames["hand"]

    # PlaCo: its trajectory gives the states every path is timed on
    placo_step, states, placo_reset = placo_panda(robot, steps)

    data = model.createData()
    zero = np.zeros(nv)
    rows = reach_rows(robot)
    prepared = prioik.prepare(rows.layout, "extended_jacobian")
    control = ControlStep(reach_rows(robot), "hierarchical_active_set", dt=DT)
    control.reference("hand", HAND_TARGET)
    control.reference("posture", q0)
    xs: dict[str, list] = {"prepared": [None] * steps, "one-off": [None] * steps,
                           "control": [None] * steps}

    def prepared_step(i: int) -> None:
        state = KinematicState(robot, states[i], zero, data, drift=False)
        rows.frame_position(state, "hand", HAND_TARGET)
        rows.posture(state, "posture", q0)
        xs["prepared"][i] = prepared.solve(rows.velocity_targets()).x

    def oneoff_step(i: int) -> None:
        state = KinematicState(robot, states[i], zero, data, drift=False)
        J = state.frame_jacobian(hand)[:3]
        e = HAND_TARGET - state.placement(hand).translation
        stack = TaskStack([Task("hand", J, GAINS["hand"] * e),
                           Task("posture", np.eye(nv), GAINS["posture"] * (q0 - states[i]))])
        xs["one-off"][i] = prioik.solve(stack, "extended_jacobian").x

    def control_step(i: int) -> None:
        control(states[i])
        xs["control"][i] = control.velocity.copy()

    paths = {"prepared": prepared_step, "one-off": oneoff_step, "control": control_step,
             "placo": placo_step}
    for path in paths.values():     # warm-up: caches, first calls
        for i in range(min(50, steps)):
            path(i)
    placo_reset()
    best = _rounds(paths, steps, rounds)
    distance = max(relative_distance(a, b)
                   for a, b in zip(xs["prepared"], xs["one-off"], strict=False))
    if not distance <= 1e-9:
        raise RuntimeError(f"the prepared and one-off Panda paths differ by {distance:.2e}")
    control_distance = max(relative_distance(a, b)
                           for a, b in zip(xs["prepared"], xs["control"], strict=False))
    if not control_distance <= 1e-9:
        raise RuntimeError(f"ControlStep and the prepared Panda path differ by "
                           f"{control_distance:.2e}")

    def us(key, q):
        return float(np.percentile(best[key], q)) * 1e6

    out = {"steps": steps, "rounds": rounds, "max_path_distance": distance,
           "control_distance": control_distance}
    for key in best:
        tag = key.replace("-", "")
        out.update({f"{tag}_step_us": us(key, 50), f"{tag}_p10_us": us(key, 10),
                    f"{tag}_p90_us": us(key, 90)})
    out["description"] = (
        f"{steps} control steps (2 ms) of a 9-DoF Panda (example-robot-data, fixed base) "
        f"reaching {HAND_TARGET.tolist()} m at velocity level: hand position (K = "
        f"{GAINS['hand']:g}) strictly above the posture (K_p = {GAINS['posture']:g}), no "
        "limits, at PlaCo's own states. Each path in its own loop, "
        f"{rounds} interleaved rounds, the fastest round's median: prioik prepared "
        "(`KinematicState(drift=False)` + `TaskWriter` writers + `solver.solve(data)`), "
        "prioik one-off (`Task`/`TaskStack` + `prioik.solve`), prioik `ControlStep` "
        "(`hierarchical_active_set`, the step integrated too: the README's loop), PlaCo "
        "(`update_kinematics` + `KinematicsSolver.solve`, soft position and joints "
        "tasks, integrated). The two writer paths agree to "
        f"{distance:.1e} (relative), ControlStep's q̇ with the prepared path's to "
        f"{control_distance:.1e}.")
    return out
