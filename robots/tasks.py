"""Task builders: robot state → ``hierarchy`` tasks at acceleration or velocity level.

Every builder returns a :class:`TaskTerm` holding, for one task ``x = f(q)``:
its Jacobian ``J`` (``ẋ = J q̇``), the drift ``J̇ q̇``, the error ``e = x* − x``, the
rate error ``ė = ẋ* − ẋ`` and the feed-forward ``ẍ*``. From these

* :meth:`TaskTerm.acceleration` gives the paper's task ``J θ̈ = h`` with
  ``h = ẍ* + K_d (ẋ* − ẋ) + K_p (x* − x) − J̇ θ̇`` (eq. 2-4);
* :meth:`TaskTerm.velocity` gives ``J q̇ = ẋ* + K e`` for velocity-level tools.

Kinematic quantities come from pinocchio, once per state, in
:class:`KinematicState`: frame Jacobians in ``LOCAL_WORLD_ALIGNED`` (linear rows are
the world velocity of the frame origin, angular rows the world angular velocity),
``J̇ q̇`` as the frame's classical acceleration at ``q̈ = 0``, and the centre of mass
with its Jacobian and its drift (``pin.centerOfMass`` at ``q̈ = 0``).

Joint limits come in two forms (see :func:`joint_limit_rows` and
:func:`joint_limit_bounds`): activation rows for the equality formulations and bounds
on ``q̈`` for the QP formulations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from prioik.hierarchy import Task

from .models import RobotModel, check_configuration, check_velocity
from .references import Reference

__all__ = ["KinematicState", "TaskTerm", "frame_position", "frame_orientation",
           "frame_pose", "com_position", "contact", "posture", "joint_limit_rows",
           "joint_limit_bounds", "JointLimitActivation"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class KinematicState:
    """Pinocchio kinematics of one state ``(q, v)``, computed once.

    Args:
        robot: The robot.
        q: Configuration (``n_q``); copied.
        v: Velocity (``n_v``); copied.
        data: A ``pin.Data`` to reuse (a fresh one if omitted).
        drift: Compute the drift terms ``J̇ q̇`` (acceleration level); ``False``
            skips them (velocity level: ``frame_drift`` and ``acom_drift`` are then
            unavailable).

    Raises:
        StateError: ``q`` or ``v`` of the wrong size or not finite, or a joint's
            quaternion not of unit norm (a zero quaternion included). A ``q``
            outside the joint limits is accepted: :func:`joint_limit_rows` and
            :func:`joint_limit_bounds` push it back and :attr:`limit_violation`
            reports it.

    After construction ``data`` holds the joint Jacobians, frame placements, the
    velocities and the accelerations at ``q̈ = 0`` (the drift terms), the centre of
    mass ``com``, its velocity ``vcom``, drift ``acom_drift`` and Jacobian ``Jcom``.
    ``com``, ``Jcom`` and ``vcom`` are copied out of ``data`` when first read, like
    the frame quantities: a state is valid until its ``data`` is reused for another.
    """

    def __init__(self, robot: RobotModel, q, v, data: pin.Data | None = None,
                 drift: bool = True) -> None:
        self.robot = robot
        self.model = robot.model
        self.q = check_configuration(robot, q)
        self.v = check_velocity(robot, v)
        self.data = data if data is not None else robot.model.createData()
        self.has_drift = bool(drift)
        m, d = self.model, self.data
        # one forward pass (at q̈ = 0 for the drifts); the Jacobians, frames and the
        # centre of mass are then read from it (was three passes: 9.5 -> 4.6 µs on G1)
        if self.has_drift:
            pin.forwardKinematics(m, d, self.q, self.v, np.zeros(robot.nv))
            pin.computeJointJacobians(m, d)
            pin.centerOfMass(m, d, pin.KinematicLevel.ACCELERATION, False)
            self.acom_drift = np.array(d.acom[0])
        else:
            pin.computeJointJacobians(m, d, self.q)     # placements and Jacobians
            self.acom_drift = None
        pin.updateFramePlacements(m, d)
        pin.jacobianCenterOfMass(m, d, False)           # data.Jcom and data.com[0]
        self._cache: dict = {}

    @property
    def limit_violation(self) -> float:
        """How far (rad, ≥ 0) an actuated joint of ``q`` is past a limit
        (:func:`joint_limit_violation`)."""
        return joint_limit_violation(self.robot, self.q)

    @property
    def Jcom(self) -> np.ndarray:
        """``3 × n_v`` Jacobian of the centre of mass."""
        if "Jcom" not in self._cache:
            self._cache["Jcom"] = np.array(self.data.Jcom)
        return self._cache["Jcom"]

    @property
    def com(self) -> np.ndarray:
        """Centre of mass (world, 3)."""
        if "com" not in self._cache:
            self._cache["com"] = np.array(self.data.com[0])
        return self._cache["com"]

    @property
    def vcom(self) -> np.ndarray:
        """Centre-of-mass velocity ``J_com q̇`` (3)."""
        if "vcom" not in self._cache:
            self._cache["vcom"] = self.Jcom @ self.v
        return self._cache["vcom"]

    @property
    def n(self) -> int:
        """Number of task columns (``n_v``)."""
        return self.robot.nv

    def placement(self, frame: str) -> pin.SE3:
        """World placement of a frame (or role)."""
        return self.data.oMf[self.robot.frame_id(frame)]

    def frame_jacobian(self, frame: str) -> np.ndarray:
        """``6 × n_v`` Jacobian of the frame (LOCAL_WORLD_ALIGNED; linear then angular)."""
        key = ("J", frame)
        if key not in self._cache:
            self._cache[key] = np.array(pin.getFrameJacobian(
                self.model, self.data, self.robot.frame_id(frame), _LWA))
        return self._cache[key]

    def frame_velocity(self, frame: str) -> np.ndarray:
        """World-aligned velocity ``J q̇`` of the frame origin (6)."""
        return self.frame_jacobian(frame) @ self.v

    def frame_drift(self, frame: str) -> np.ndarray:
        """``J̇ q̇`` (6): classical acceleration of the frame origin at ``q̈ = 0``.

        Raises:
            ValueError: the state was built with ``drift=False``.
        """
        if not self.has_drift:
            raise ValueError("this KinematicState was built with drift=False "
                             "(velocity level): it has no J̇q̇ terms")
        key = ("dJv", frame)
        if key not in self._cache:
            acc = pin.getFrameClassicalAcceleration(self.model, self.data,
                                                    self.robot.frame_id(frame), _LWA)
            self._cache[key] = np.array(acc.vector)
        return self._cache[key]


@dataclass
class TaskTerm:
    """One task's kinematics at one state; see the module docstring.

    Attributes:
        name: Task name (unique in a stack).
        J: Task Jacobian (``m × n``).
        drift: ``J̇ q̇`` (``m``).
        error: ``e = x* − x`` (``m``).
        rate_error: ``ė = ẋ* − ẋ`` (``m``).
        feedforward: ``ẍ*`` (``m``).
        velocity_ref: ``ẋ*`` (``m``).
    """

    name: str
    J: np.ndarray
    drift: np.ndarray
    error: np.ndarray
    rate_error: np.ndarray
    feedforward: np.ndarray
    velocity_ref: np.ndarray

    def acceleration(self, kp: float, kd: float, weight=1.0) -> Task:
        """``J θ̈ = ẍ* + K_d ė + K_p e − J̇ θ̇`` (eq. 2-4)."""
        h = self.feedforward + kd * self.rate_error + kp * self.error - self.drift
        return Task(self.name, self.J, h, weight=weight)

    def velocity(self, k: float, weight=1.0) -> Task:
        """``J q̇ = ẋ* + K e`` (velocity-level closed-loop inverse kinematics)."""
        return Task(self.name, self.J, self.velocity_ref + k * self.error, weight=weight)

    def select(self, rows) -> "TaskTerm":
        """The term restricted to some rows (e.g. the horizontal axes)."""
        idx = list(rows)
        return TaskTerm(self.name, self.J[idx], self.drift[idx], self.error[idx],
                        self.rate_error[idx], self.feedforward[idx], self.velocity_ref[idx])


def _ref3(ref: Reference | None, fallback: np.ndarray) -> Reference:
    if ref is None:
        return Reference(fallback.copy(), np.zeros(3), np.zeros(3))
    return ref


def frame_position(state: KinematicState, frame: str, ref: Reference,
                   name: str | None = None) -> TaskTerm:
    """Position of a frame origin (a point fixed on a body: add it with
    :meth:`RobotModel.with_point_frame`), world coordinates (3 rows)."""
    J = state.frame_jacobian(frame)[:3]
    p = state.placement(frame).translation
    return TaskTerm(name or f"{frame}_position", J, state.frame_drift(frame)[:3],
                    np.asarray(ref.x) - p, np.asarray(ref.xd) - J @ state.v,
                    np.asarray(ref.xdd, dtype=float), np.asarray(ref.xd, dtype=float))


def frame_orientation(state: KinematicState, frame: str, rotation: np.ndarray,
                      name: str | None = None, angular_velocity=None,
                      angular_acceleration=None) -> TaskTerm:
    """Orientation of a frame (3 rows): error ``log(R* Rᵀ)`` in world coordinates.

    Args:
        rotation: Target rotation ``R*`` (3×3).
        angular_velocity: ``ω*`` (world), zero if omitted.
        angular_acceleration: ``ω̇*`` (world), zero if omitted.
    """
    J = state.frame_jacobian(frame)[3:]
    R = state.placement(frame).rotation
    err = pin.log3(np.asarray(rotation) @ R.T)
    w_ref = np.zeros(3) if angular_velocity is None else np.asarray(angular_velocity, float)
    dw_ref = np.zeros(3) if angular_acceleration is None else np.asarray(angular_acceleration,
                                                                          float)
    return TaskTerm(name or f"{frame}_orientation", J, state.frame_drift(frame)[3:], err,
                    w_ref - J @ state.v, dw_ref, w_ref)


def frame_pose(state: KinematicState, frame: str, ref: Reference, rotation: np.ndarray,
               name: str | None = None) -> TaskTerm:
    """Position (rows 0-2, following ``ref``) and orientation (rows 3-5, fixed
    ``rotation``) of a frame: 6 rows."""
    p = frame_position(state, frame, ref)
    o = frame_orientation(state, frame, rotation)
    return TaskTerm(name or f"{frame}_pose", np.vstack([p.J, o.J]),
                    np.concatenate([p.drift, o.drift]), np.concatenate([p.error, o.error]),
                    np.concatenate([p.rate_error, o.rate_error]),
                    np.concatenate([p.feedforward, o.feedforward]),
                    np.concatenate([p.velocity_ref, o.velocity_ref]))


def contact(state: KinematicState, frame: str, placement: pin.SE3,
            name: str | None = None) -> TaskTerm:
    """A support contact: the frame held at ``placement`` (6 rows, zero reference
    velocity and acceleration; with gains this is ``ẍ = −K_d ẋ + K_p e``)."""
    ref = Reference(np.array(placement.translation), np.zeros(3), np.zeros(3))
    return frame_pose(state, frame, ref, np.array(placement.rotation),
                      name=name or f"{frame}_contact")


def com_position(state: KinematicState, ref: Reference, axes=(0, 1),
                 name: str = "com") -> TaskTerm:
    """Centre of mass (eq. 32-33) on the selected world axes (default horizontal)."""
    idx = list(axes)
    ref_x = np.asarray(ref.x, float)
    full = TaskTerm(name, state.Jcom, state.acom_drift,
                    _pad(ref_x, idx) - state.com,
                    _pad(np.asarray(ref.xd, float), idx) - state.Jcom @ state.v,
                    _pad(np.asarray(ref.xdd, float), idx), _pad(np.asarray(ref.xd, float), idx))
    return full.select(idx)


def _pad(values: np.ndarray, idx) -> np.ndarray:
    """A 3-vector from values given on the axes ``idx`` (or already 3 long)."""
    if values.shape == (3,):
        return values
    out = np.zeros(3)
    out[idx] = values
    return out


def posture(state: KinematicState, q_ref, name: str = "posture") -> TaskTerm:
    """Actuated joints to ``q_ref`` (rows ``n_base:`` of the velocity)."""
    robot = state.robot
    nb = robot.n_base
    k = robot.nv - nb
    J = np.zeros((k, robot.nv))
    J[:, nb:] = np.eye(k)
    err = pin.difference(robot.model, state.q, np.asarray(q_ref, float))[nb:]
    return TaskTerm(name, J, np.zeros(k), err, -state.v[nb:], np.zeros(k), np.zeros(k))


# ------------------------------------------------------------------ joint limits
@dataclass(frozen=True)
class JointLimitActivation:
    """Parameters of the equality (activation-row) form of joint limits.

    A joint's row is active while it is within ``margin`` of a limit. With
    ``s ∈ (0, 1]`` the depth into the margin (0 at the margin's edge, 1 at the limit)
    and ``y = s·margin`` the same depth in radians, the row is
    ``q̈_j = ± s (K_p y + K_d ẏ)`` pointing away from the limit. The blend ``s``
    makes the target continuous: a row enters asking ``q̈_j = 0`` and grows
    stiffer the deeper the joint goes; with the defaults (margin 0.1 rad,
    ``K_p = 2500``, ``K_d = 100``) a joint entering at up to ~5 rad/s stops inside the
    margin (a 1-D check is in ``tests/test_tasks.py``). The row *set* still switches
    discretely (an exact hierarchy enforces any present row fully), which is what
    makes ``q̈`` jump at activation; the rows never ask more than the pushing
    target, so ``q`` and ``q̇`` stay continuous.

    Attributes:
        margin: Width of the activation zone inside each limit (rad); it is capped
            at a quarter of the joint's range.
        kp: Stiffness of the push-back.
        kd: Damping of the push-back.
    """

    margin: float = 0.1
    kp: float = 2500.0
    kd: float = 100.0


def joint_limit_rows(state: KinematicState, params: JointLimitActivation = JointLimitActivation(),
                     name: str = "joint_limits") -> Task | None:
    """Equality form of joint limits: one row ``q̈_j = target`` per joint inside its
    margin (see :class:`JointLimitActivation`), or ``None`` when no joint is.

    The task's rows are unit rows on the actuated joints' columns.
    """
    robot = state.robot
    nb = robot.n_base
    lo, hi, _ = robot.joint_limits()
    qa = _actuated_positions(state)
    va = state.v[nb:]
    finite = np.isfinite(lo) & np.isfinite(hi)
    with np.errstate(invalid="ignore"):
        width = np.where(finite, np.minimum(params.margin, 0.25 * (hi - lo)), 1.0)
        y_lo = np.where(finite, lo + width - qa, -1.0)     # depth into the lower margin
        y_hi = np.where(finite, qa - (hi - width), -1.0)   # depth into the upper margin
    in_lo = y_lo > 0
    in_hi = (y_hi > 0) & ~in_lo
    s_lo = np.minimum(y_lo / width, 1.0)
    s_hi = np.minimum(y_hi / width, 1.0)
    # lower margin: ẏ = −q̇, push towards +q; upper margin: ẏ = q̇, push towards −q
    target = np.where(in_lo, s_lo * (params.kp * y_lo - params.kd * va),
                      -s_hi * (params.kp * y_hi + params.kd * va))
    rows = np.flatnonzero(in_lo | in_hi)
    if rows.size == 0:
        return None
    A = np.zeros((rows.size, robot.nv))
    A[np.arange(rows.size), nb + rows] = 1.0
    return Task(name, A, target[rows])


def joint_limit_bounds(state: KinematicState, horizon: float, dt: float,
                       name: str = "joint_limits") -> Task:
    """Inequality form of joint limits for the QP formulations: bounds on ``q̈``.

    For each actuated joint, with ``d`` the distance left to the limit the joint
    moves towards:

    * horizon: ``q + q̇ T + ½ q̈ T² ∈ [q_min, q_max]`` over the horizon ``T``;
    * next step: ``q + (q̇ + q̈ dt) dt ∈ [q_min, q_max]``;
    * braking: when the horizon bound would make the constant-acceleration path
      peak before ``T`` (it then overshoots the limit in between), the joint must
      instead decelerate by at least ``q̇² / 2d``, so that the peak
      ``q − q̇²/2q̈`` stays inside; far from a limit this never binds;
    * speed: ``|q̇ + q̈ dt| ≤ q̇_max`` over the next step.

    Where the ranges do not intersect (a joint moving too fast towards a limit to
    stop in time), both bounds become the position bound of the limit it moves
    towards, clipped to the speed range (the hardest admissible braking), so the
    task stays feasible.
    """
    robot = state.robot
    nb = robot.n_base
    lo, hi, vmax = robot.joint_limits()
    qa = _actuated_positions(state)
    va = state.v[nb:]
    T = float(horizon)
    with np.errstate(invalid="ignore", divide="ignore"):
        h_lo = 2.0 * (lo - qa - va * T) / T ** 2          # horizon bounds
        h_hi = 2.0 * (hi - qa - va * T) / T ** 2
        d_hi = np.maximum(hi - qa, 1e-9)
        d_lo = np.maximum(qa - lo, 1e-9)
        # the constant-acceleration path peaks before T (and would overshoot) when
        # the horizon bound decelerates faster than -v/T: then brake by v²/2d
        brake_hi = np.where((va > 0) & (h_hi < -va / T), -va ** 2 / (2.0 * d_hi), np.inf)
        brake_lo = np.where((va < 0) & (h_lo > -va / T), va ** 2 / (2.0 * d_lo), -np.inf)
        p_hi = np.minimum.reduce([np.nan_to_num(h_hi, nan=np.inf), brake_hi,
                                  (hi - qa - va * dt) / dt ** 2])
        p_lo = np.maximum.reduce([np.nan_to_num(h_lo, nan=-np.inf), brake_lo,
                                  (lo - qa - va * dt) / dt ** 2])
        p_hi = np.nan_to_num(p_hi, nan=np.inf)
        p_lo = np.nan_to_num(p_lo, nan=-np.inf)
        v_lo = (-vmax - va) / dt
        v_hi = (vmax - va) / dt
    lower = np.maximum(p_lo, np.nan_to_num(v_lo, nan=-np.inf))
    upper = np.minimum(p_hi, np.nan_to_num(v_hi, nan=np.inf))
    bad = lower > upper
    if bad.any():
        mid = np.where(va[bad] > 0, np.clip(p_hi[bad], v_lo[bad], v_hi[bad]),
                       np.clip(p_lo[bad], v_lo[bad], v_hi[bad]))
        mid = np.where(np.isfinite(mid), mid, 0.0)
        lower[bad] = upper[bad] = mid
    k = lo.size
    A = np.zeros((k, robot.nv))
    A[np.arange(k), nb + np.arange(k)] = 1.0
    return Task(name, A, lower=lower, upper=upper)


def _actuated_positions(state: KinematicState) -> np.ndarray:
    """Positions of the actuated one-dof joints, ordered like their velocity rows
    (0 for a row without a single configuration entry)."""
    idx = state.robot.actuated_q_index()
    return np.where(idx >= 0, state.q[np.maximum(idx, 0)], 0.0)


def joint_limit_violation(robot: RobotModel, q) -> float:
    """Largest amount by which an actuated joint of ``q`` is past a limit (rad, ≥ 0).

    Raises:
        StateError: ``q`` of the wrong size or not finite (a NaN ``q`` is not within
            its limits, nor 0 rad past them).
    """
    lo, hi, _ = robot.joint_limits()
    idx = robot.actuated_q_index()
    q = check_configuration(robot, q)
    st = np.where(idx >= 0, q[np.maximum(idx, 0)], 0.0)
    with np.errstate(invalid="ignore"):
        over = np.maximum(np.nan_to_num(lo - st, nan=0.0, neginf=0.0),
                          np.nan_to_num(st - hi, nan=0.0, neginf=0.0))
    return float(max(0.0, over.max(initial=0.0)))
