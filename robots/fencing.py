"""The paper's fencing scenario (Jeong & Chang 2009, Sec. III) on the Unitree G1.

The G1 (29 joints, floating base, ``n_v = 35``) holds a sword in its left hand — a
point 0.5 m along the x axis of ``left_rubber_hand`` — and, priorities highest
first:

0. ``support_foot`` — right foot contact: 6 rows, the foot's pose held
   (``ẍ* = 0``, ``K_p = 100``, ``K_d = 20`` to cancel integration drift);
1. ``joint_limits`` — activation rows (equality formulations) or bounds on ``q̈``
   (QP formulations), see :mod:`robots.tasks`;
2. ``com`` — the centre of mass, horizontally, over the middle of the feet
   (the midpoint of the support foot and the stepping foot's reference);
3. ``left_foot`` — the left foot steps 0.2 m forward with a 4 cm clearance
   (minimum-jerk, ``0.2 → 1.2 s``), orientation held (6 rows);
4. ``sword_tip`` — the tip to the target (minimum-jerk, ``0.5 → 2.5 s``, then hold);
5. ``posture`` — the actuated joints to the standing posture with low gains
   (``K_p = 4``, ``K_d = 4``). The paper has no such level; it damps the motion left
   in the null space of the five tasks above, which would otherwise drift at
   constant velocity under minimum-norm solutions. It never competes with a
   higher level in an exact hierarchy, and the recorded algorithmic error (eq. 29)
   covers levels 0-4 only.

Variants: ``compatible`` — target ``(0.55, 0.25, 0.85)`` m (world; the left shoulder is
near ``(0, 0.1, 1.02)``), reachable; ``incompatible`` — target ``(1.6, 0.2, 1.0)`` m,
about 1.6 m from the shoulder while the arm plus sword are ~0.93 m long, i.e. far
(≥ 0.3 m) beyond what the higher levels allow. Tracking gains of levels 2-4 are
``K_p = 25``, ``K_d = 10``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from prioik.errors import UnknownNameError
from prioik.hierarchy import StackData, TaskStack

from .models import RobotModel, g1
from .references import Reference, Waypoints, minimum_jerk_profile
from .rows import TaskWriter
from .scenario import BaselineTask, Scenario
from .simulate import SimulationError, StepTasks
from .tasks import (
    JointLimitActivation,
    KinematicState,
    com_position,
    contact,
    frame_pose,
    frame_position,
    joint_limit_bounds,
    joint_limit_rows,
    joint_limit_violation,
    joint_velocity_bounds,
    posture,
)

__all__ = ["VARIANTS", "TARGETS", "FencingScenario", "LEVEL_NAMES"]

VARIANTS = ("compatible", "incompatible")
#: sword-tip targets (world, m)
TARGETS = {"compatible": (0.55, 0.25, 0.85), "incompatible": (1.6, 0.2, 1.0)}
#: task names, highest priority first
LEVEL_NAMES = ("support_foot", "joint_limits", "com", "left_foot", "sword_tip", "posture")
SWORD_LENGTH = 0.5


@dataclass(repr=False)
class FencingScenario(Scenario):
    """The fencing scenario: robot, references and gains; builds each step's stack
    (the :class:`~robots.scenario.Scenario` interface).

    Attributes:
        variant: ``"compatible"`` or ``"incompatible"``.
        robot: The G1 with the ``sword_tip`` frame (built if omitted).
        gains: Task name → ``(K_p, K_d)``.
        step_length: Forward step of the left foot (m).
        step_height: Clearance of the stepping foot (m).
        step_window: Start and end of the step (s).
        tip_window: Start and end of the sword move (s); held afterwards.
        limits: Parameters of the activation-row form of the joint limits.
        bound_horizon: Horizon ``T`` of the inequality form (s).
        with_posture: Include the lowest ``posture`` level.
        target: The sword-tip target (world, m); ``None``: the variant's
            (:data:`TARGETS`). Sweeps (``prioik sweep``) set it.
    """

    name = "fencing"
    variants = VARIANTS
    tip_frame = "sword_tip"
    tip_label = "sword-tip"
    summary_errors = ("com_error_m", "support_foot_error_m", "left_foot_error_m",
                      "joint_limit_violation_rad")
    default_duration = 3.0

    variant: str = "compatible"
    robot: RobotModel | None = None
    gains: dict[str, tuple[float, float]] = field(default_factory=lambda: {
        "support_foot": (100.0, 20.0), "com": (25.0, 10.0), "left_foot": (25.0, 10.0),
        "sword_tip": (25.0, 10.0), "posture": (4.0, 4.0)})
    step_length: float = 0.2
    step_height: float = 0.04
    step_window: tuple[float, float] = (0.2, 1.2)
    tip_window: tuple[float, float] = (0.5, 2.5)
    limits: JointLimitActivation = JointLimitActivation()
    bound_horizon: float = 0.1
    with_posture: bool = True
    target: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.variant not in VARIANTS:
            raise SimulationError(f"unknown fencing variant {self.variant!r}; "
                             f"known: {', '.join(VARIANTS)}")
        if self.robot is None:
            self.robot = g1().with_point_frame("sword_tip", "left_hand",
                                               (SWORD_LENGTH, 0.0, 0.0))
        r = self.robot
        data = r.data()
        pin.framesForwardKinematics(r.model, data, r.q0)
        self.right_foot0 = data.oMf[r.frame_id("right_foot")].copy()
        self.left_foot0 = data.oMf[r.frame_id("left_foot")].copy()
        self.tip0 = data.oMf[r.frame_id("sword_tip")].translation.copy()
        com0 = np.array(pin.centerOfMass(r.model, data, r.q0))[:2]
        self.com_offset0 = com0 - 0.5 * (self.left_foot0.translation[:2]
                                         + self.right_foot0.translation[:2])
        self.target = np.array(TARGETS[self.variant] if self.target is None else self.target,
                               dtype=float).reshape(3)
        p0 = self.left_foot0.translation
        s0, s1 = self.step_window
        mid = 0.5 * (s0 + s1)
        self._lift = Waypoints((s0, mid, s1), (p0[2], p0[2] + self.step_height, p0[2]))
        # the references' constants as plain floats and arrays (computed every step)
        self._left0 = tuple(float(v) for v in p0)
        self._right_xy = tuple(float(v) for v in self.right_foot0.translation[:2])
        self._com_offset = tuple(float(v) for v in self.com_offset0)
        self._tip0 = tuple(float(v) for v in self.tip0)
        self._tip_move_xyz = tuple(float(v) for v in self.target - self.tip0)
        self._support_x = np.array(self.right_foot0.translation)
        self._support_R = np.array(self.right_foot0.rotation)
        self._left_foot_R = np.array(self.left_foot0.rotation)

    # ----------------------------------------------------------------- references
    def left_foot_ref(self, t: float) -> Reference:
        """Reference of the stepping foot's origin (x: one minimum-jerk move;
        z: up and down through two)."""
        x, xd, xdd = self._foot_x(t)
        z, zd, zdd = self._lift.scalar(t)
        return Reference(np.array([x, self._left0[1], z]), np.array([xd, 0.0, zd]),
                         np.array([xdd, 0.0, zdd]))

    def _foot_x(self, t: float) -> tuple[float, float, float]:
        """The stepping foot's forward reference (its y holds): position, velocity and
        acceleration along x (floats: this runs every control step)."""
        s0, s1 = self.step_window
        p, dp, ddp = minimum_jerk_profile(s0, s1 - s0, t)
        L = self.step_length
        return self._left0[0] + p * L, dp * L, ddp * L

    def com_ref(self, t: float) -> Reference:
        """Horizontal centre of mass over the middle of the feet (xy).

        The standing posture's centre of mass is not exactly there, so its initial
        offset is removed by a minimum-jerk move over the first ``step_window[0]``
        seconds (no step in the reference at ``t = 0``)."""
        x, xd, xdd = self._foot_x(t)
        p, dp, ddp = minimum_jerk_profile(0.0, self.step_window[0], t)
        (ox, oy), (rx, ry) = self._com_offset, self._right_xy
        return Reference(np.array([0.5 * (x + rx) + (1.0 - p) * ox,
                                   0.5 * (self._left0[1] + ry) + (1.0 - p) * oy]),
                         np.array([0.5 * xd - dp * ox, -dp * oy]),
                         np.array([0.5 * xdd - ddp * ox, -ddp * oy]))

    def tip_ref(self, t: float) -> Reference:
        """Minimum-jerk from the initial tip to the target, then hold."""
        a, b = self.tip_window
        p, dp, ddp = minimum_jerk_profile(a, b - a, t)
        (x, y, z), (dx, dy, dz) = self._tip0, self._tip_move_xyz
        return Reference(np.array([x + p * dx, y + p * dy, z + p * dz]),
                         np.array([dp * dx, dp * dy, dp * dz]),
                         np.array([ddp * dx, ddp * dy, ddp * dz]))

    # --------------------------------------------------------------------- stacks
    def terms(self, state: KinematicState, t: float) -> dict:
        """The task terms (name → :class:`~robots.tasks.TaskTerm`) at ``(state, t)``."""
        r = self.robot
        out = {
            "support_foot": contact(state, "right_foot", self.right_foot0,
                                    name="support_foot"),
            "com": com_position(state, self.com_ref(t), axes=(0, 1), name="com"),
            "left_foot": frame_pose(state, "left_foot", self.left_foot_ref(t),
                                    np.array(self.left_foot0.rotation), name="left_foot"),
            "sword_tip": frame_position(state, "sword_tip", self.tip_ref(t),
                                        name="sword_tip"),
        }
        if self.with_posture:
            out["posture"] = posture(state, r.q0, name="posture")
        return out

    def errors(self, state: KinematicState, t: float, terms: dict) -> dict[str, float]:
        """Recorded errors: tip to the final target and to its reference, CoM,
        feet (m) and the largest joint-limit violation (rad)."""
        tip = state.placement("sword_tip").translation
        sup = state.placement("right_foot")
        return {
            "tip_error_m": float(np.linalg.norm(self.target - tip)),
            "tip_tracking_error_m": float(np.linalg.norm(terms["sword_tip"].error)),
            "com_error_m": float(np.linalg.norm(terms["com"].error)),
            "support_foot_error_m": float(np.linalg.norm(sup.translation
                                                         - self.right_foot0.translation)),
            "support_foot_rotation_error_rad": float(np.linalg.norm(
                terms["support_foot"].error[3:])),
            "left_foot_error_m": float(np.linalg.norm(terms["left_foot"].error[:3])),
            "joint_limit_violation_rad": joint_limit_violation(self.robot, state.q),
        }

    def acceleration_stack(self, state: KinematicState, t: float, limits: str = "activation",
                           dt: float = 0.002) -> StepTasks:
        """The acceleration-level stack (eq. 2-4) and the errors to record.

        Args:
            limits: ``"activation"`` (equality rows; level omitted when no joint is
                near a limit), ``"bounds"`` (inequality on ``q̈``, level 1) or
                ``"hard_bounds"`` (the same bounds as level 0, above the support
                foot: the form SNS takes).
            dt: Control step, for the velocity part of the bounds.
        """
        terms = self.terms(state, t)
        g = self.gains
        levels = [terms["support_foot"].acceleration(*g["support_foot"])]
        if limits == "activation":
            jl = joint_limit_rows(state, self.limits)
            if jl is not None:
                levels.append(jl)
        elif limits == "bounds":
            levels.append(joint_limit_bounds(state, self.bound_horizon, dt))
        elif limits == "hard_bounds":
            levels.insert(0, joint_limit_bounds(state, self.bound_horizon, dt))
        else:
            raise SimulationError(f"limits must be 'activation', 'bounds' or 'hard_bounds', "
                             f"got {limits!r}")
        for name in ("com", "left_foot", "sword_tip"):
            levels.append(terms[name].acceleration(*g[name]))
        n_tasks = len(levels)
        if "posture" in terms:
            levels.append(terms["posture"].acceleration(*g["posture"]))
        return StepTasks(TaskStack(levels), lambda: self.errors(state, t, terms), n_tasks)

    def velocity_stack(self, state: KinematicState, t: float, gain: float = 10.0,
                       limits: str = "none", dt: float = 0.002) -> StepTasks:
        """The velocity-level stack ``J q̇ = ẋ* + K e`` of the same tasks.

        Args:
            gain: ``K`` of every task but the posture (which keeps its ``K_p``).
            limits: ``"bounds"`` for position/velocity bounds on ``q̇``
                (``q + q̇ dt`` within limits, ``|q̇| ≤ q̇_max``) at level 1,
                ``"hard_bounds"`` for the same at level 0, ``"none"`` to omit.
            dt: Step used by the bounds.
        """
        terms = self.terms(state, t)
        k = self.velocity_gains(gain)
        levels = [terms["support_foot"].velocity(k["support_foot"])]
        if limits == "bounds":
            levels.append(joint_velocity_bounds(state, dt))
        elif limits == "hard_bounds":
            levels.insert(0, joint_velocity_bounds(state, dt))
        elif limits != "none":
            raise SimulationError(f"limits must be 'bounds', 'hard_bounds' or 'none', "
                             f"got {limits!r}")
        for name in ("com", "left_foot", "sword_tip"):
            levels.append(terms[name].velocity(k[name]))
        n_tasks = len(levels)
        if "posture" in terms:
            levels.append(terms["posture"].velocity(k["posture"]))
        return StepTasks(TaskStack(levels), lambda: self.errors(state, t, terms), n_tasks)

    def velocity_gains(self, gain: float = 10.0) -> dict[str, float]:
        """``K`` per task at velocity level: ``gain`` for every task but the posture,
        which keeps its ``K_p`` (used by :meth:`velocity_stack` and
        :meth:`velocity_rows`)."""
        out = {name: gain for name in ("support_foot", "com", "left_foot", "sword_tip")}
        if self.with_posture:
            out["posture"] = self.gains["posture"][0]
        return out

    # ------------------------------------------------------------ baselines
    def baseline_tasks(self) -> list[BaselineTask]:
        """Hard support foot and CoM, soft left foot and sword tip (weight 1), soft
        posture (1e-4): the mapping of ``benchmarks/placo_baseline.py``."""
        out = [BaselineTask("support_foot", "frame_pose", self.robot.frames["right_foot"], 0,
                            hard=True),
               BaselineTask("com", "com", None, 1, hard=True),
               BaselineTask("left_foot", "frame_pose", self.robot.frames["left_foot"], 2),
               BaselineTask("sword_tip", "frame_position", "sword_tip", 3)]
        if self.with_posture:
            out.append(BaselineTask("posture", "posture", None, 4, weight=1e-4))
        return out

    def baseline_target(self, name: str, t: float):
        if name == "support_foot":
            return np.array(self.right_foot0.homogeneous)
        if name == "com":
            return self.com_ref(t).x
        if name == "left_foot":
            T = np.array(self.left_foot0.homogeneous)
            T[:3, 3] = self.left_foot_ref(t).x
            return T
        if name == "sword_tip":
            return self.tip_ref(t).x
        if name == "posture":
            return self.robot.q0.copy()
        raise UnknownNameError(f"the fencing scenario has no baseline task {name!r}")

    def markers(self, t: float) -> dict[str, np.ndarray]:
        """The sword target and the tip's reference."""
        return {"target": self.target.copy(), "reference": self.tip_ref(t).x}

    def urdf_text(self) -> str:
        """The G1 URDF with a ``sword_tip`` link fixed 0.5 m along the left hand's x."""
        from pathlib import Path
        text = Path(self.robot.source).read_text()
        extra = (f'  <link name="sword_tip"/>\n'
                 f'  <joint name="sword_tip_joint" type="fixed">\n'
                 f'    <parent link="{self.robot.frames["left_hand"]}"/>\n'
                 f'    <child link="sword_tip"/>\n'
                 f'    <origin xyz="{SWORD_LENGTH} 0 0" rpy="0 0 0"/>\n  </joint>\n')
        end = text.rindex("</robot>")
        return text[:end] + extra + text[end:]

    # ------------------------------------------------------- preallocated rows
    def velocity_rows(self, gain: float = 10.0, limits: str = "none",
                      dt: float = 0.002) -> TaskWriter:
        """The writer of :meth:`velocity_stack`'s levels and gains (``limits``
        ``"none"`` or ``"bounds"``: bounds on ``q̇``), for :meth:`write_rows` in a
        control loop."""
        if limits not in ("none", "bounds"):
            raise SimulationError(f"limits must be 'bounds' or 'none', got {limits!r}")
        k = self.velocity_gains(gain)
        w = TaskWriter(self.robot, "velocity")
        w.add_contact("support_foot", "right_foot", gain=k["support_foot"])
        if limits == "bounds":
            w.add_joint_limits("joint_limits", form="bounds", dt=dt)
        self._add_tracking_tasks(w, k)
        return w

    def acceleration_rows(self, limits: str = "activation", dt: float = 0.002) -> TaskWriter:
        """The writer of :meth:`acceleration_stack`'s levels and gains. ``limits``
        ``"activation"``: one row per joint, masked outside the margins (fixed size:
        the level is always there, zero rows where :meth:`acceleration_stack` has
        none); ``"bounds"``: bounds on ``q̈`` over ``bound_horizon``."""
        if limits not in ("activation", "bounds"):
            raise SimulationError(f"limits must be 'activation' or 'bounds', got {limits!r}")
        w = TaskWriter(self.robot, "acceleration")
        w.add_contact("support_foot", "right_foot", gain=self.gains["support_foot"])
        if limits == "activation":
            w.add_joint_limits("joint_limits", form="activation", activation=self.limits)
        else:
            w.add_joint_limits("joint_limits", form="bounds", horizon=self.bound_horizon,
                               dt=dt)
        self._add_tracking_tasks(w, self.gains)
        return w

    def _add_tracking_tasks(self, w: TaskWriter, gains: dict) -> None:
        w.add_com("com", gain=gains["com"], axes=(0, 1))
        w.add_frame_pose("left_foot", "left_foot", gain=gains["left_foot"])
        w.add_frame_position("sword_tip", "sword_tip", gain=gains["sword_tip"])
        if self.with_posture:
            w.add_posture("posture", gain=gains["posture"])

    def write_rows(self, rows: TaskWriter, state: KinematicState, t: float) -> StackData:
        """Fill ``rows`` (from :meth:`velocity_rows` or :meth:`acceleration_rows`) at
        ``(state, t)``; returns its data (equal to :meth:`velocity_stack` /
        :meth:`acceleration_stack` to rounding, the masked activation rows aside)."""
        rows.contact(state, "support_foot", translation=self._support_x,
                     rotation=self._support_R)
        if "joint_limits" in rows:
            rows.joint_limits(state, "joint_limits")
        com = self.com_ref(t)
        rows.com(state, "com", com.x, com.xd, com.xdd)
        foot = self.left_foot_ref(t)
        rows.frame_pose(state, "left_foot", foot.x, self._left_foot_R, foot.xd, foot.xdd)
        tip = self.tip_ref(t)
        rows.frame_position(state, "sword_tip", tip.x, tip.xd, tip.xdd)
        if self.with_posture:
            rows.posture(state, "posture", self.robot.q0)
        return rows.targets(state)

    def step_references(self, step, t: float, fixed: bool = True) -> None:
        """:meth:`write_rows`' references at ``t`` into ``step`` (a
        :class:`~robots.control_step.ControlStep` of :meth:`velocity_rows`); ``fixed``:
        the support foot's and the posture's too (they do not move: once suffices)."""
        if fixed:
            step.reference("support_foot", translation=self._support_x,
                           rotation=self._support_R)
            if self.with_posture:
                step.reference("posture", self.robot.q0)
        com = self.com_ref(t)
        step.reference("com", com.x, com.xd)
        foot = self.left_foot_ref(t)
        step.reference("left_foot", foot.x, self._left_foot_R, foot.xd)
        tip = self.tip_ref(t)
        step.reference("sword_tip", tip.x, tip.xd)

    #: the same as :meth:`write_rows` (the name the benchmarks use)
    write_velocity_rows = write_rows

    def written_step(self, rows: TaskWriter, state: KinematicState, t: float) -> StepTasks:
        """:meth:`write_rows`, as the step a simulation solves: the writer's data (no
        per-step objects) and the errors of :meth:`errors`, read from the writer's own
        per-row errors after the step's timed phases."""
        data = self.write_rows(rows, state, t)
        levels = len(data.layout) - (1 if self.with_posture else 0)
        return StepTasks(data, lambda: self._written_errors(rows, state), levels)

    def step_builder(self, level: str = "acceleration", limits: str | None = None,
                     dt: float = 0.002, gain: float = 10.0):
        """As :meth:`Scenario.step_builder`, with the rows written in place
        (:meth:`written_step`: no per-step objects) wherever a writer exists: bounds at
        velocity level, activation rows or bounds at acceleration level."""
        if limits is None:
            limits = "none" if level == "velocity" else "activation"
        if level == "velocity" and limits == "bounds":
            rows = self.velocity_rows(gain, limits=limits, dt=dt)
        elif level == "acceleration" and limits in ("activation", "bounds"):
            rows = self.acceleration_rows(limits=limits, dt=dt)
        else:
            return super().step_builder(level, limits, dt, gain)
        return lambda state, t: self.written_step(rows, state, t)

    def _written_errors(self, rows: TaskWriter, state: KinematicState) -> dict[str, float]:
        layout = rows.layout

        def error(name):
            return rows.error[layout.task_slice(name)]
        tip = state.placement("sword_tip").translation
        sup = state.placement("right_foot")
        return {
            "tip_error_m": float(np.linalg.norm(self.target - tip)),
            "tip_tracking_error_m": float(np.linalg.norm(error("sword_tip"))),
            "com_error_m": float(np.linalg.norm(error("com"))),
            "support_foot_error_m": float(np.linalg.norm(sup.translation
                                                         - self.right_foot0.translation)),
            "support_foot_rotation_error_rad": float(np.linalg.norm(
                error("support_foot")[3:])),
            "left_foot_error_m": float(np.linalg.norm(error("left_foot")[:3])),
            "joint_limit_violation_rad": joint_limit_violation(self.robot, state.q),
        }
