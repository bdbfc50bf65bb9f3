"""Closed-loop robot test sets: TALOS, Panda and Go2 reaching with a limb beyond its
workspace, at velocity level (``J q̇ = ẋ* + K e``, ``K = 10``, ``dt = 10 ms``).

Level 0: the joint position and velocity limits as bounds on ``q̇``; level 1: the
support contacts (TALOS: both feet; Go2: three feet; Panda: none) and the limb's
position, its target 0.4, -0.3, 0.5 m from its start (out of reach); level 2: the
posture. The loop is closed by ``hierarchical_active_set`` (warm-started): each problem
is the stack at the state its previous answer led to. One sequence of ``steps``
consecutive steps (sequential); the mass matrix of each problem is ``M(q)``.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .base import Problem, TestSet

__all__ = ["TalosReach", "PandaReach", "Go2Reach", "LOOP_DT"]

#: time step of the closed loops (s)
LOOP_DT = 0.01
#: the limb's target from its start (m)
REACH_OFFSET = (0.4, -0.3, 0.5)


def _loop(robot_name: str, contacts: tuple[str, ...], limb: str, steps: int
          ) -> Iterator[Problem]:
    import pinocchio as pin

    import prioik
    from prioik.benchmarks.stacks import _mass_matrix
    from prioik.robots import KinematicState, TaskWriter, load
    robot = load(robot_name)
    w = TaskWriter(robot, "velocity")
    w.add_joint_limits("limits", form="bounds", dt=LOOP_DT, level=0)
    for c in contacts:
        w.add_contact(c, c, gain=10.0, level=1)
    w.add_frame_position("reach", limb, gain=10.0, level=1)
    w.add_posture("posture", gain=1.0, level=2)
    driver = prioik.prepare(w.layout, "hierarchical_active_set")
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    start = KinematicState(robot, q, v, drift=False)
    places = {c: start.placement(c).copy() for c in contacts}
    target = start.placement(limb).translation + np.array(REACH_OFFSET)
    data, dyn = robot.data(), robot.model.createData()
    for step in range(steps):
        state = KinematicState(robot, q, v, data, drift=False)
        w.joint_limits(state, "limits")
        for c in contacts:
            w.contact(state, c, places[c])
        w.frame_position(state, "reach", target)
        w.posture(state, "posture", robot.q0)
        rows = w.targets(state)
        stack = rows.as_stack()
        yield Problem(f"step {step}", stack, sequence="loop",
                      mass_matrix=_mass_matrix(robot.model, dyn, q))
        sol = driver.solve(rows)
        if sol.status == "failed":
            raise RuntimeError(f"the {robot_name} loop's driver failed at step {step}: "
                               f"{sol.diagnostics.reason}")
        v = np.array(sol.x)
        q = pin.integrate(robot.model, q, v * LOOP_DT)


class _Loop(TestSet):
    sequential = True
    needs = ("robots",)
    robot = ""
    contacts: tuple[str, ...] = ()
    limb = ""

    def __init__(self, steps: int = 24) -> None:
        if steps < 1:
            raise ValueError(f"steps must be ≥ 1, got {steps}")
        self.steps = steps

    def problems(self) -> Iterator[Problem]:
        return _loop(self.robot, self.contacts, self.limb, self.steps)


class TalosReach(_Loop):
    name = "talos_reach"
    description = ("TALOS closed loop (velocity level): feet, right hand out of reach, "
                   "joint limits as bounds, posture")
    robot, contacts, limb = "talos", ("left_foot", "right_foot"), "right_hand"


class PandaReach(_Loop):
    name = "panda_reach"
    description = ("Panda closed loop (velocity level): tool out of reach, joint limits as "
                   "bounds, posture")
    robot, contacts, limb = "panda", (), "tcp"


class Go2Reach(_Loop):
    name = "go2_reach"
    description = ("Go2 closed loop (velocity level): three feet, the fourth out of reach, "
                   "joint limits as bounds, posture")
    robot, contacts, limb = ("go2", ("front_right_foot", "rear_left_foot", "rear_right_foot"),
                             "front_left_foot")
