"""The arm-reach scenario: a Franka Panda reaching a sequence of targets, one out of reach.

The Panda (``panda_description/urdf/panda.urdf`` of example-robot-data; fixed base,
the two finger joints locked open: ``n_v = 7``) moves its tool point
``panda_hand_tcp`` through :data:`TARGETS` (world, m): each target is reached by a
minimum-jerk move of ``move_time`` and held for ``hold_time``. The third target,
``(1.0, 0.1, 0.55)``, is about 0.97 m from the shoulder (joint 2 at ``z = 0.333``)
while the arm reaches about 0.86 m: the tool stretches towards it, against its
joint limits, then comes back. Priorities, highest first:

0. ``joint_limits`` — activation rows (equality formulations) or bounds (QP
   formulations, SNS): position, velocity and acceleration limits
   (:data:`ACCELERATION_LIMITS`, Franka's datasheet values; the URDF has none);
1. ``tool_position`` — the tool point to its reference (3 rows);
2. ``tool_orientation`` — the hand keeps its initial orientation (3 rows);
3. ``posture`` — the joints to the ready posture, low gains (regularising level).

Gains at acceleration level: ``K_p = 25``, ``K_d = 10`` (posture ``4, 4``); at velocity
level ``J q̇ = ẋ* + K e``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from prioik.errors import UnknownNameError
from prioik.hierarchy import Task, TaskStack

from .models import RobotModel, example_robot_data_dir
from .references import Reference, minimum_jerk
from .scenario import BaselineTask, Scenario
from .simulate import SimulationError, StepTasks
from .tasks import (
    JointLimitActivation,
    KinematicState,
    frame_orientation,
    frame_position,
    joint_limit_bounds,
    joint_limit_rows,
    joint_limit_violation,
    posture,
)

__all__ = ["ArmScenario", "TARGETS", "PANDA_URDF", "panda", "ACCELERATION_LIMITS"]

PANDA_URDF = "panda_description/urdf/panda.urdf"
#: the ready posture of the Panda (rad)
PANDA_READY = (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)
#: joint acceleration limits (rad/s², Franka Panda datasheet)
ACCELERATION_LIMITS = (15.0, 7.5, 10.0, 12.5, 15.0, 20.0, 20.0)
#: tool targets (world, m), visited in order; the third is out of reach
TARGETS = ((0.45, 0.30, 0.45), (0.40, -0.30, 0.30), (1.00, 0.10, 0.55), (0.35, 0.0, 0.60))
OUT_OF_REACH = 2
TOOL = "panda_hand_tcp"


def panda() -> RobotModel:
    """The Panda with its fingers locked (``n_q = n_v = 7``, fixed base), ``q0`` the
    ready posture: :func:`robots.from_urdf` with ``locked_joints=PANDA_FINGERS``."""
    from .models import PANDA_FINGERS, from_urdf
    path = example_robot_data_dir() / PANDA_URDF
    names = [f"panda_joint{i}" for i in range(1, 8)]
    return from_urdf(path, floating_base=False, locked_joints=PANDA_FINGERS,
                     q0=dict(zip(names, PANDA_READY, strict=False)), name="panda",
                     frames={"tool": TOOL, "hand": "panda_hand", "base": "panda_link0"})


@dataclass(repr=False)
class ArmScenario(Scenario):
    """The arm-reach scenario; see the module docstring.

    Attributes:
        variant: ``"reach"`` (the only variant).
        robot: The Panda (built if omitted).
        targets: Tool targets, visited in order.
        move_time: Duration of each minimum-jerk move (s).
        hold_time: Hold at each target (s).
        gains: Task name → ``(K_p, K_d)``.
        limits: Parameters of the activation-row form of the joint limits.
        bound_horizon: Horizon ``T`` of the acceleration-level bounds (s).
    """

    name = "arm"
    variants = ("reach",)
    tip_frame = TOOL
    tip_label = "tool"
    summary_errors = ("orientation_error_rad", "joint_limit_violation_rad",
                      "joint_velocity_violation_rad_s")
    default_duration = 6.0

    variant: str = "reach"
    robot: RobotModel | None = None
    targets: tuple = TARGETS
    move_time: float = 0.8
    hold_time: float = 0.4
    gains: dict[str, tuple[float, float]] = field(default_factory=lambda: {
        "tool_position": (25.0, 10.0), "tool_orientation": (25.0, 10.0), "posture": (4.0, 4.0)})
    limits: JointLimitActivation = JointLimitActivation()
    bound_horizon: float = 0.1

    def __post_init__(self) -> None:
        if self.variant not in self.variants:
            raise SimulationError(f"unknown arm variant {self.variant!r}; known: "
                             f"{', '.join(self.variants)}")
        if self.robot is None:
            self.robot = panda()
        r = self.robot
        data = r.data()
        pin.framesForwardKinematics(r.model, data, r.q0)
        tool = data.oMf[r.frame_id(TOOL)]
        self.tool0 = np.array(tool.translation)
        self.rotation0 = np.array(tool.rotation)
        self.amax = np.array(ACCELERATION_LIMITS, dtype=float)
        self._points = np.vstack([self.tool0, np.asarray(self.targets, dtype=float)])

    # ----------------------------------------------------------------- references
    def segment(self, t: float) -> int:
        """Index (into :attr:`targets`) of the target being approached or held at ``t``."""
        period = self.move_time + self.hold_time
        return int(min(len(self.targets) - 1, max(0.0, t) // period))

    def tool_ref(self, t: float) -> Reference:
        """Minimum-jerk from the previous target to the current one, then hold."""
        i = self.segment(t)
        start = (self.move_time + self.hold_time) * i
        return minimum_jerk(self._points[i], self._points[i + 1], start, self.move_time, t)

    def target(self, t: float) -> np.ndarray:
        """The target being approached or held at ``t``."""
        return self._points[self.segment(t) + 1].copy()

    # --------------------------------------------------------------------- stacks
    def terms(self, state: KinematicState, t: float) -> dict:
        """The task terms at ``(state, t)``."""
        return {"tool_position": frame_position(state, TOOL, self.tool_ref(t),
                                                name="tool_position"),
                "tool_orientation": frame_orientation(state, TOOL, self.rotation0,
                                                      name="tool_orientation"),
                "posture": posture(state, self.robot.q0, name="posture")}

    def errors(self, state: KinematicState, t: float, terms: dict) -> dict[str, float]:
        """Recorded errors: tool to the current target and to its reference (m), hand
        orientation (rad), joint position / velocity limit violations."""
        tool = state.placement(TOOL).translation
        _, _, vmax = self.robot.joint_limits()
        return {
            "tip_error_m": float(np.linalg.norm(self.target(t) - tool)),
            "tip_tracking_error_m": float(np.linalg.norm(terms["tool_position"].error)),
            "orientation_error_rad": float(np.linalg.norm(terms["tool_orientation"].error)),
            "joint_limit_violation_rad": joint_limit_violation(self.robot, state.q),
            "joint_velocity_violation_rad_s": float(max(0.0, np.max(np.abs(state.v) - vmax))),
        }

    def acceleration_bounds(self, state: KinematicState, dt: float) -> Task:
        """Bounds on ``q̈``: :func:`robots.tasks.joint_limit_bounds` (position over a
        horizon, braking, next step, speed) intersected with ``|q̈| ≤ q̈_max``; where
        they do not meet, the acceleration limit wins (clipped braking)."""
        base = joint_limit_bounds(state, self.bound_horizon, dt)
        lo = np.maximum(base.lower, -self.amax)
        hi = np.minimum(base.upper, self.amax)
        bad = lo > hi
        lo[bad] = hi[bad] = np.clip(np.where(base.upper[bad] < -self.amax[bad],
                                             base.upper[bad], base.lower[bad]),
                                    -self.amax[bad], self.amax[bad])
        return Task("joint_limits", base.A, lower=lo, upper=hi)

    def velocity_bounds(self, state: KinematicState, dt: float) -> Task:
        """Bounds on ``q̇`` (the velocity-level box of Flacco et al. 2012): next-step
        position ``(q_lim − q)/dt``, speed, and the braking distance ``√(2 q̈_max d)``
        (so that the joint can still stop before its limit). As in the paper the
        acceleration limit enters only through the braking term; 0 is inside the box
        whenever ``q`` is within its limits."""
        lo, hi, vmax = self.robot.joint_limits()
        idx = self.robot.actuated_q_index()          # a fixed-base arm: every joint
        q = np.where(idx >= 0, state.q[np.maximum(idx, 0)], 0.0)
        d_lo, d_hi = np.maximum(q - lo, 0.0), np.maximum(hi - q, 0.0)
        lower = np.maximum.reduce([(lo - q) / dt, -vmax, -np.sqrt(2 * self.amax * d_lo)])
        upper = np.minimum.reduce([(hi - q) / dt, vmax, np.sqrt(2 * self.amax * d_hi)])
        return Task("joint_limits", np.eye(self.robot.nv), lower=lower, upper=upper)

    def acceleration_stack(self, state: KinematicState, t: float, limits: str = "activation",
                           dt: float = 0.002) -> StepTasks:
        """The acceleration-level stack and the errors to record.

        Args:
            limits: ``"activation"`` (equality rows, omitted when no joint is near a
                limit), ``"bounds"`` or ``"hard_bounds"`` (the same here: the limits
                are the first level already).
        """
        terms = self.terms(state, t)
        levels = []
        if limits == "activation":
            jl = joint_limit_rows(state, self.limits)
            if jl is not None:
                levels.append(jl)
        elif limits in ("bounds", "hard_bounds"):
            levels.append(self.acceleration_bounds(state, dt))
        else:
            raise SimulationError(f"limits must be 'activation', 'bounds' or 'hard_bounds', "
                             f"got {limits!r}")
        for name in ("tool_position", "tool_orientation"):
            levels.append(terms[name].acceleration(*self.gains[name]))
        n_tasks = len(levels)
        levels.append(terms["posture"].acceleration(*self.gains["posture"]))
        return StepTasks(TaskStack(levels), lambda: self.errors(state, t, terms), n_tasks)

    def velocity_stack(self, state: KinematicState, t: float, gain: float = 10.0,
                       limits: str = "none", dt: float = 0.002) -> StepTasks:
        """The velocity-level stack ``J q̇ = ẋ* + K e`` of the same tasks (the posture
        keeps its ``K_p``); ``limits``: ``"bounds"``/``"hard_bounds"`` (first level) or
        ``"none"``."""
        terms = self.terms(state, t)
        levels = []
        if limits in ("bounds", "hard_bounds"):
            levels.append(self.velocity_bounds(state, dt))
        elif limits != "none":
            raise SimulationError(f"limits must be 'bounds', 'hard_bounds' or 'none', got "
                                  f"{limits!r}")
        levels.append(terms["tool_position"].velocity(gain))
        levels.append(terms["tool_orientation"].velocity(gain))
        n_tasks = len(levels)
        levels.append(terms["posture"].velocity(self.gains["posture"][0]))
        return StepTasks(TaskStack(levels), lambda: self.errors(state, t, terms), n_tasks)

    # ----------------------------------------------------------------- baselines
    def baseline_tasks(self) -> list[BaselineTask]:
        """Tool position (hard in PlaCo), hand orientation (soft, 0.1), posture (1e-4)."""
        return [BaselineTask("tool_position", "frame_position", TOOL, 0, hard=True),
                BaselineTask("tool_orientation", "frame_orientation", TOOL, 1, weight=0.1),
                BaselineTask("posture", "posture", None, 2, weight=1e-4)]

    def baseline_target(self, name: str, t: float):
        if name == "tool_position":
            return self.tool_ref(t).x
        if name == "tool_orientation":
            return self.rotation0
        if name == "posture":
            return self.robot.q0.copy()
        raise UnknownNameError(f"the arm scenario has no baseline task {name!r}")

    def markers(self, t: float) -> dict[str, np.ndarray]:
        """The current target and the tool's reference."""
        return {"target": self.target(t), "reference": self.tool_ref(t).x}

    def urdf_text(self) -> str:
        """The Panda URDF with the finger joints made fixed (as in :func:`panda`)."""
        import re
        text = (example_robot_data_dir() / PANDA_URDF).read_text()
        for j in ("panda_finger_joint1", "panda_finger_joint2"):
            text = re.sub(rf'(<joint[^>]*name="{j}"[^>]*type=")prismatic(")', r"\1fixed\2",
                          text)
            text = re.sub(rf'(<joint[^>]*type=")prismatic("[^>]*name="{j}")', r"\1fixed\2",
                          text)
        return text
