"""Task builders: robot state → ``hierarchy`` tasks at acceleration or velocity level.

Every builder returns a :class:`TaskTerm` holding, for one task ``x = f(q)``:
its Jacobian ``J`` (``ẋ = J q̇``), the drift ``J̇ q̇`` (``None`` from a
``KinematicState(drift=False)``), the error ``e = x* − x``, the rate error
``ė = ẋ* − ẋ`` and the feed-forward ``ẍ*``. The builders are one-off, readable
wrappers over the task kinds of :mod:`robots.kinds`: each builds its kind's task and
returns its :meth:`~robots.rows.RobotTask.term` (written by a one-task
:class:`~robots.rows.TaskWriter` per kind, kept per thread): the same rows as a
writer's, copied out. From these

* :meth:`TaskTerm.acceleration` gives the paper's task ``J θ̈ = h`` with
  ``h = ẍ* + K_d (ẋ* − ẋ) + K_p (x* − x) − J̇ θ̇`` (eq. 2-4);
* :meth:`TaskTerm.velocity` gives ``J q̇ = ẋ* + K e`` for velocity-level tools.

Kinematic quantities come from pinocchio, once per state, in
:class:`KinematicState`: frame Jacobians in ``LOCAL_WORLD_ALIGNED`` (linear rows are
the world velocity of the frame origin, angular rows the world angular velocity),
``J̇ q̇`` as the frame's classical acceleration at ``q̈ = 0``, and the centre of mass
with its Jacobian and its drift (``pin.centerOfMass`` at ``q̈ = 0``).

Joint limits come in two forms (see :func:`joint_limit_rows`, :func:`joint_limit_bounds`
and :func:`joint_velocity_bounds`): activation rows for the equality formulations and
bounds on ``q̈`` or ``q̇`` for the QP formulations. :func:`frame_region` and
:func:`com_region` are inequality tasks keeping a point inside ``lower ≤ C p ≤ upper``
(:func:`polygon_region`: a support polygon's rows).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from prioik._core import rows as _core_rows
from prioik.hierarchy import Task, TaskStackError

from .kinds import (
    ComRegionTask,
    ComTask,
    ContactTask,
    FrameOrientationTask,
    FramePoseTask,
    FramePositionTask,
    FrameRegionTask,
    JointLimitsTask,
    PointTask,
    PostureTask,
)
from .models import UNIT_NORM_TOL, RobotModel, StateError, check_configuration, check_velocity
from .references import Reference
from .rows import JointLimitActivation, TaskTerm

__all__ = ["KinematicState", "TaskTerm", "frame_position", "point_position",
           "frame_orientation", "frame_pose", "com_position", "contact", "posture",
           "joint_limit_rows", "joint_limit_bounds", "joint_velocity_bounds",
           "frame_region", "com_region", "polygon_region", "JointLimitActivation"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


_F64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_state_is_valid = _core_rows.state_is_valid
_joint_jacobians = pin.computeJointJacobians
_frame_placements = pin.updateFramePlacements
_center_of_mass = pin.centerOfMass
#: n_v → zeros(n_v), the q̈ = 0 of the drift pass (never written)
_ZERO_ACCELERATION: dict[int, np.ndarray] = {}


class KinematicState:
    """Pinocchio kinematics of one state ``(q, v)``, computed once.

    Args:
        robot: The robot.
        q: Configuration (``n_q``); copied.
        v: Velocity (``n_v``); copied.
        data: A ``pin.Data`` to reuse (a fresh one if omitted).
        drift: Compute the drift terms ``J̇ q̇`` (acceleration level); ``False``
            skips them (velocity level: ``frame_drift`` raises, ``acom_drift`` is
            ``None`` and the builders' terms have ``drift=None``).

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
        self.model = m = robot.model
        # the common case (float arrays of the right sizes, finite, unit quaternions) in
        # one compiled pass; the naming checks of check_configuration otherwise
        sizes = robot.__dict__.get("_state_sizes")      # RobotModel.state_sizes, cached
        if sizes is None or sizes[0] is not m:
            sizes = robot.state_sizes()
        unit = sizes[3]
        if (q.__class__ is _NDARRAY and v.__class__ is _NDARRAY and q.dtype is _F64
                and v.dtype is _F64 and q.shape == sizes[4] and v.shape == sizes[5]):
            qc = q.copy()
            vc = v.copy()
            if not _state_is_valid(qc, vc, unit, UNIT_NORM_TOL):
                qc, vc = check_configuration(robot, q), check_velocity(robot, v)
        else:
            qc, vc = check_configuration(robot, q), check_velocity(robot, v)
        self.q = qc
        self.v = vc
        self.data = d = data if data is not None else m.createData()
        self.has_drift = drift = bool(drift)
        # one forward pass (at q̈ = 0 for the drifts); the Jacobians, frames and the
        # centre of mass are then read from it
        if drift:
            zeros = _ZERO_ACCELERATION.get(vc.shape[0])
            if zeros is None:
                zeros = np.zeros(vc.shape[0])
                zeros.setflags(write=False)
                zeros = _ZERO_ACCELERATION.setdefault(vc.shape[0], zeros)
            _center_of_mass(m, d, qc, vc, zeros, False)     # with forwardKinematics
            _joint_jacobians(m, d)
        else:
            _joint_jacobians(m, d, qc)     # placements and Jacobians
        _frame_placements(m, d)
        self._cache: dict = {}        # copies of what is read from data, on first use

    #: data.Jcom and data.com[0] computed for this state (on first use)
    _com_ready = False

    @property
    def acom_drift(self) -> np.ndarray | None:
        """``J̇_com q̇`` (3), ``None`` from a ``drift=False`` state."""
        if not self.has_drift:
            return None
        if "acom" not in self._cache:
            self._cache["acom"] = np.array(self.data.acom[0])
        return self._cache["acom"]

    def ensure_com(self) -> None:
        """Compute ``data.Jcom`` and ``data.com[0]`` once for this state (the writers of
        CoM tasks call it; a state without a CoM task never pays for it)."""
        if not self._com_ready:
            pin.jacobianCenterOfMass(self.model, self.data, False)
            self._com_ready = True

    @property
    def limit_violation(self) -> float:
        """How far (rad, ≥ 0) an actuated joint of ``q`` is past a limit
        (:func:`joint_limit_violation`)."""
        return joint_limit_violation(self.robot, self.q)

    @property
    def Jcom(self) -> np.ndarray:
        """``3 × n_v`` Jacobian of the centre of mass."""
        if "Jcom" not in self._cache:
            self.ensure_com()
            self._cache["Jcom"] = np.array(self.data.Jcom)
        return self._cache["Jcom"]

    @property
    def com(self) -> np.ndarray:
        """Centre of mass (world, 3)."""
        if "com" not in self._cache:
            self.ensure_com()
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
            StateError: the state was built with ``drift=False``.
        """
        if not self.has_drift:
            raise StateError("this KinematicState was built with drift=False "
                             "(velocity level): it has no J̇q̇ terms")
        key = ("dJv", frame)
        if key not in self._cache:
            acc = pin.getFrameClassicalAcceleration(self.model, self.data,
                                                    self.robot.frame_id(frame), _LWA)
            self._cache[key] = np.array(acc.vector)
        return self._cache[key]


def frame_position(state: KinematicState, frame: str, ref: Reference,
                   name: str | None = None) -> TaskTerm:
    """Position of a frame origin, world coordinates (3 rows;
    :class:`~robots.kinds.FramePositionTask`)."""
    return FramePositionTask(name or f"{frame}_position", frame).term(
        state, ref.x, ref.xd, ref.xdd)


def point_position(state: KinematicState, frame: str, offset, ref: Reference,
                   name: str | None = None) -> TaskTerm:
    """Position of a point fixed on a frame (``offset`` in the frame's coordinates),
    world coordinates (3 rows; :class:`~robots.kinds.PointTask`);
    :meth:`RobotModel.with_point_frame` is the other way."""
    return PointTask(name or f"{frame}_point", frame, offset).term(
        state, ref.x, ref.xd, ref.xdd)


def frame_orientation(state: KinematicState, frame: str, rotation: np.ndarray,
                      name: str | None = None, angular_velocity=None,
                      angular_acceleration=None) -> TaskTerm:
    """Orientation of a frame (3 rows; :class:`~robots.kinds.FrameOrientationTask`):
    error ``log(R* Rᵀ)`` in world coordinates.

    Args:
        rotation: Target rotation ``R*`` (3×3).
        angular_velocity: ``ω*`` (world), zero if omitted.
        angular_acceleration: ``ω̇*`` (world), zero if omitted.
    """
    return FrameOrientationTask(name or f"{frame}_orientation", frame).term(
        state, rotation, angular_velocity, angular_acceleration)


def frame_pose(state: KinematicState, frame: str, ref: Reference, rotation: np.ndarray,
               name: str | None = None) -> TaskTerm:
    """Position (rows 0-2, following ``ref``) and orientation (rows 3-5, fixed
    ``rotation``) of a frame: 6 rows (:class:`~robots.kinds.FramePoseTask`)."""
    return FramePoseTask(name or f"{frame}_pose", frame).term(
        state, ref.x, rotation, ref.xd, ref.xdd)


def contact(state: KinematicState, frame: str, placement: pin.SE3,
            name: str | None = None) -> TaskTerm:
    """A support contact: the frame held at ``placement`` (6 rows, zero reference
    velocity and acceleration; with gains this is ``ẍ = −K_d ẋ + K_p e``;
    :class:`~robots.kinds.ContactTask`)."""
    return ContactTask(name or f"{frame}_contact", frame).term(state, placement)


def com_position(state: KinematicState, ref: Reference, axes=(0, 1),
                 name: str = "com") -> TaskTerm:
    """Centre of mass (eq. 32-33) on the selected world axes (default horizontal;
    :class:`~robots.kinds.ComTask`); ``ref`` given on those axes or as 3-vectors."""
    task = ComTask(name, axes=axes)
    idx = tuple(int(a) for a in task.axes)
    return task.term(state, *(_on_axes(v, idx) for v in (ref.x, ref.xd, ref.xdd)))


def _on_axes(values, idx: tuple) -> np.ndarray:
    """A CoM reference on the axes ``idx``: given so, or as a 3-vector."""
    v = np.asarray(values, dtype=float).reshape(-1)
    return v[list(idx)] if v.shape == (3,) and len(idx) != 3 else v


def posture(state: KinematicState, q_ref, name: str = "posture") -> TaskTerm:
    """Actuated joints to ``q_ref`` (rows ``n_base:`` of the velocity); no drift
    (:class:`~robots.kinds.PostureTask`)."""
    return PostureTask(name).term(state, q_ref)


# ---------------------------------------------------------------------- regions
def frame_region(state: KinematicState, frame: str, normals, lower=None, upper=None, *,
                 dt: float, horizon: float | None = None, offset=None,
                 mode: str | None = None, name: str | None = None) -> Task:
    """Inequality task keeping a point of a frame inside ``lower ≤ C p ≤ upper`` (world
    coordinates; ``p`` the frame's origin or ``offset`` in its coordinates): rows
    ``C J`` with bounds on ``q̇`` (velocity level) or ``q̈`` (acceleration level; the
    default with a drift state), see :class:`~robots.kinds.FrameRegionTask`."""
    return FrameRegionTask(name or f"{frame}_region", frame, normals, lower, upper, dt=dt,
                           horizon=horizon, offset=offset).term(state, mode=mode)


def com_region(state: KinematicState, normals, lower=None, upper=None, *, dt: float,
               horizon: float | None = None, mode: str | None = None,
               name: str = "com_region") -> Task:
    """Inequality task keeping the centre of mass inside ``lower ≤ C c ≤ upper`` (e.g.
    the support polygon of :func:`polygon_region`; :class:`~robots.kinds.ComRegionTask`);
    see :func:`frame_region`."""
    return ComRegionTask(name, normals, lower, upper, dt=dt, horizon=horizon).term(
        state, mode=mode)


def polygon_region(points, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The horizontal convex hull of ``points`` as a region ``C p ≤ upper``: one row per
    edge, ``C``'s rows the edges' outward unit normals in the ``xy`` plane (``z`` = 0),
    ``upper`` the edges' offsets less ``margin`` (a support polygon shrunk by a safety
    margin: pass to :func:`com_region` or :meth:`~robots.rows.TaskWriter.add_com_region`
    with ``lower=None``).

    Args:
        points: ``k × 2`` or ``k × 3`` world points (``z`` ignored), e.g. the corners
            of the feet's soles.
        margin: Distance (m, ≥ 0) the edges are moved inwards.

    Raises:
        TaskStackError: fewer than three points not on one line, a non-finite point, or a
            margin that leaves nothing of the polygon.
    """
    try:
        P = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise TaskStackError(f"points must be numbers, got {points!r}") from None
    if P.ndim != 2 or P.shape[1] not in (2, 3) or not np.isfinite(P).all():
        raise TaskStackError(f"points must be finite k × 2 or k × 3, got shape {P.shape}")
    if not (np.isscalar(margin) and np.isfinite(margin) and margin >= 0):
        raise TaskStackError(f"margin must be a finite number ≥ 0, got {margin!r}")
    hull = _convex_hull(P[:, :2])
    if hull.shape[0] < 3:
        raise TaskStackError("the points' horizontal hull has no area (fewer than three "
                             "points off one line)")
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.column_stack([edges[:, 1], -edges[:, 0]])      # outward: hull is CCW
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    upper = np.einsum("ij,ij->i", normals, hull) - margin
    inner = hull.mean(axis=0)
    if margin > 0 and np.any(normals @ inner > upper):
        # the centroid is inside every edge of the hull; off one of the moved edges the
        # margin is (near) the polygon's inradius
        raise TaskStackError(f"a margin of {margin:g} m leaves (almost) nothing of the "
                             "polygon")
    return np.column_stack([normals, np.zeros(len(hull))]), upper


def _convex_hull(P: np.ndarray) -> np.ndarray:
    """Vertices of the convex hull of 2-D points, counter-clockwise (Andrew's monotone
    chain), collinear points dropped."""
    P = np.unique(P, axis=0)            # sorted by x, then y
    if P.shape[0] < 3:
        return P

    def half(points):
        chain: list = []
        for p in points:
            while len(chain) >= 2 and _turn(chain[-2], chain[-1], p) <= 0.0:
                chain.pop()
            chain.append(p)
        return chain

    lower = half(P)
    upper = half(P[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _turn(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


# ------------------------------------------------------------------ joint limits
def joint_limit_rows(state: KinematicState, params: JointLimitActivation | None = None,
                     name: str = "joint_limits", mode: str = "acceleration") -> Task | None:
    """Equality form of joint limits: one row per joint inside its margin (see
    :class:`JointLimitActivation`), or ``None`` when no joint is. ``mode``
    ``"acceleration"``: ``q̈_j = ± s (K_p y − K_d ẏ)``; ``"velocity"``: ``q̇_j = ± s k y``.

    The task's rows are unit rows on the actuated joints' columns (the active rows of
    the writer's fixed-size, masked task). ``params`` defaults to
    ``JointLimitActivation()``.
    """
    return JointLimitsTask(name, form="activation", activation=params).term(state,
                                                                            mode=mode)


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
    return JointLimitsTask(name, form="bounds", horizon=horizon, dt=dt).term(
        state, mode="acceleration")


def joint_velocity_bounds(state: KinematicState, dt: float, horizon: float | None = None,
                          name: str = "joint_limits") -> Task:
    """Inequality form of joint limits at velocity level: bounds on ``q̇``, with
    ``q + q̇ T`` within the position limits (``T = horizon``, default ``dt``) and
    ``|q̇| ≤ q̇_max``; a joint past a limit by more than ``q̇_max T`` gets
    ``lower = upper`` (the fastest return)."""
    return JointLimitsTask(name, form="bounds", horizon=horizon, dt=dt).term(
        state, mode="velocity")


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
