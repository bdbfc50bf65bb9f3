"""One set of robot task writers: robot state → rows of a :class:`~prioik.hierarchy.StackData`.

A :class:`TaskWriter` is declared once — its tasks, their priority levels, gains and
weights (``writer.add_frame_pose("left_foot", "left_foot", level=3, gain=10.0)``, ...) —
which fixes ``writer.layout`` (a :class:`~prioik.hierarchy.StackLayout`) and
``writer.data`` (its preallocated :class:`~prioik.hierarchy.StackData`). At every step
each writer call fills its task's rows in place from a
:class:`~robots.tasks.KinematicState`: the Jacobian rows ``J`` into ``data.A`` and, per
row, the error ``e = x* − x``, the reference velocity ``ẋ*``, the feed-forward ``ẍ*`` and
the drift ``J̇ q̇``; :meth:`TaskWriter.targets` then forms every equality target in one
pass:

* ``mode="velocity"``: ``b = ẋ* + K e`` (``J q̇ = ẋ* + K e``; no drift is computed, so a
  ``KinematicState(drift=False)`` suffices), scaled down to ``‖b‖ = max_rate`` for a
  task declared with a ``max_rate`` that it exceeds;
* ``mode="acceleration"``: ``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇`` (eq. 2-4).

Task kinds: frame position, a point fixed on a frame, frame orientation (error
``log(R* Rᵀ)``), frame pose, contact (a pose held at a placement), centre of mass,
posture, damping (``q̇ = 0`` or ``q̈ = 0`` on every coordinate, weighted within its
level: that level's damped least squares), and joint limits in two forms — activation
rows (one per actuated joint, masked to zero outside the margins: fixed size, for the
equality formulations) and
bounds (an inequality task: ``data.lower``/``data.upper`` on ``q̇`` or ``q̈`` from the
position limits, the velocity limits or both, for the inequality formulations), and
regions (inequality tasks keeping a frame's point or the centre of mass inside
``lower ≤ C p ≤ upper``).

Each writer is one compiled call (``prioik._core.rows``, C++: ``core/src/rows.cpp``) on
views of the state's ``pin.Data`` — the world-frame joint Jacobians ``data.J`` (a frame's
LOCAL_WORLD_ALIGNED Jacobian is formed from them), ``data.oMf``, ``data.Jcom``,
``data.com[0]``, and for the drifts the joints' spatial velocities and accelerations at
``q̈ = 0`` ``data.v``, ``data.a`` and ``data.acom[0]`` — taken once per ``Data``.
The readable builders of :mod:`robots.tasks` (``frame_position(state, frame, ref)`` →
``TaskTerm`` → ``Task``) are thin wrappers over these writers; ``tests/test_rows.py`` checks the
writers against
independent pinocchio/numpy formulas and ``tests/test_tasks.py`` every Jacobian and drift
against finite differences.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from prioik._core import rows as _k
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import StackData, StackLayout, TaskStackError

from .models import RobotModel, StateError

__all__ = ["MODES", "TaskWriter", "JointLimitActivation"]


MODES = ("velocity", "acceleration")
"""The levels a :class:`TaskWriter` writes rows at."""


@dataclass(frozen=True)
class JointLimitActivation:
    """Parameters of the equality (activation-row) form of joint limits.

    A joint's row is active while it is within ``margin`` of a limit. With
    ``s ∈ (0, 1]`` the depth into the margin (0 at the margin's edge, 1 at the limit)
    and ``y = s·margin`` the same depth in radians, the row is
    ``q̈_j = ± s (K_p y + K_d ẏ)`` pointing away from the limit (acceleration level) or
    ``q̇_j = ± s k y`` (velocity level). The blend ``s`` makes the target continuous: a
    row enters asking ``q̈_j = 0`` and grows stiffer the deeper the joint goes; with the
    defaults (margin 0.1 rad, ``K_p = 2500``, ``K_d = 100``) a joint entering at up to
    ~5 rad/s stops inside the margin (a 1-D check is in ``tests/test_tasks.py``). The row
    *set* still switches discretely (an exact hierarchy enforces any present row fully),
    which is what makes ``q̈`` jump at activation; the rows never ask more than the
    pushing target, so ``q`` and ``q̇`` stay continuous.

    Attributes:
        margin: Width of the activation zone inside each limit (rad); it is capped
            at a quarter of the joint's range.
        kp: Stiffness of the push-back (acceleration level).
        kd: Damping of the push-back (acceleration level).
        k: Gain of the push-back at velocity level (1/s).
    """

    margin: float = 0.1
    kp: float = 2500.0
    kd: float = 100.0
    k: float = 20.0


@dataclass
class _Task:
    """One declared task: what its writer needs, fixed at declaration."""

    kind: str                 # "position", "orientation", "pose", "contact", "com",
    #                           "posture", "damping", "limits", "frame_region", "com_region"
    name: str
    level: int
    rows: int
    inequality: bool
    kp: float = 0.0
    kd: float = 0.0
    weight: float = 1.0
    max_rate: float = 0.0                # velocity level: ‖b‖ ≤ max_rate (0: no cap)
    start: int = -1
    fid: int = -1
    cols: np.ndarray | None = None
    spec: np.ndarray | None = None       # frame tasks: the kernels' int64 spec (at _fix)
    hot: tuple | None = None             # frame, CoM tasks: (pin.Data, the kernel's arguments)
    offset: np.ndarray | None = None     # point on the frame (frame coordinates)
    joint: int = -1                      # frame tasks: the frame's parent joint
    geo: np.ndarray | None = None        # frame tasks: the kernels' constant geometry
    axes: np.ndarray | None = None       # com axes
    shape: tuple = ()                    # (rows,): a reference's shape
    form: str = ""                       # limits: "activation" or "bounds"
    position: bool = True                # limits: position limits in the bounds
    velocity: bool = True                # limits: velocity limits in the bounds
    horizon: float = 0.0
    dt: float = 0.0
    activation: JointLimitActivation | None = None
    keep: bool = False                   # keep its last rows when not written before targets
    stamp: int = -1                      # the writer's step count at its last write
    limits: np.ndarray | None = None     # lo, hi, then q̇_max (bounds) or margin widths (3 × n_a)
    bound_params: np.ndarray | None = None   # the kernel's parameters (at _fix)
    region: _Region | None = None        # region tasks: C, lower, upper and scratch


@dataclass
class _Region:
    """A region task's ``lower ≤ C p ≤ upper`` (validated copies) and its writer's
    scratch: ``C p`` and its rate per row, and no speed limit (the bound kernels'
    ``q̇_max``)."""

    C: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    horizon: float
    dt: float
    y: np.ndarray
    yd: np.ndarray
    no_speed_limit: np.ndarray
    #: a frame region's point: its rows ``J_p`` and, per row, ``−p`` and ``J̇_p q̇`` (the
    #: compiled position writer's output: a target of 0 makes its error ``−p``)
    point_rows: np.ndarray | None = None
    point_values: np.ndarray | None = None

    @classmethod
    def of(cls, name: str, normals, lower, upper, dt, horizon) -> _Region:
        if not _positive(dt):
            raise TaskStackError(f"a region needs dt > 0, got {dt!r}", task=name)
        T = dt if horizon is None else horizon
        if not _positive(T):
            raise TaskStackError(f"horizon must be > 0, got {horizon!r}", task=name)
        C, lo, hi = _region_rows(name, normals, lower, upper, None)
        k = C.shape[0]
        return cls(C, lo, hi, float(T), float(dt), np.zeros(k), np.zeros(k),
                   np.full(k, np.inf))

    def update(self, name: str, normals, lower, upper) -> None:
        """New normals and/or bounds (``None``: kept; the rows' count stays)."""
        C, lo, hi = _region_rows(name, self.C if normals is None else normals,
                                 self.lower if lower is None else lower,
                                 self.upper if upper is None else upper, self.C.shape[0])
        self.C, self.lower, self.upper = C, lo, hi


def _positive(value) -> bool:
    """Whether ``value`` is a finite number > 0 (not a bool)."""
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, bool) and bool(np.isfinite(value)) and value > 0)


def _region_rows(name: str, normals, lower, upper, k: int | None):
    """``C`` (``k × 3``), ``lower``, ``upper`` (``k``) of a region, validated and copied."""
    try:
        C = np.array(normals, dtype=np.float64)
    except (TypeError, ValueError):
        raise TaskStackError(f"normals must be numbers, got {normals!r}", task=name) from None
    if C.ndim == 1:
        C = C.reshape(1, -1)
    if C.ndim != 2 or C.shape[1] != 3 or C.shape[0] < 1:
        raise TaskStackError(f"normals must be k × 3 (world axes), got shape "
                             f"{np.shape(normals)}", task=name)
    if k is not None and C.shape[0] != k:
        raise TaskStackError(f"the region was declared with {k} rows, got "
                             f"{C.shape[0]} normals", task=name)
    if not np.isfinite(C).all():
        raise TaskStackError("normals must be finite", task=name)
    zero = np.flatnonzero(~np.any(C != 0.0, axis=1))
    if zero.size:
        raise TaskStackError(f"normal {int(zero[0])} is zero", task=name)
    k = C.shape[0]
    bounds = []
    for what, value, fill in (("lower", lower, -np.inf), ("upper", upper, np.inf)):
        try:
            b = np.full(k, fill) if value is None else np.broadcast_to(
                np.asarray(value, dtype=np.float64), (k,)).copy()
        except (TypeError, ValueError):
            raise TaskStackError(f"{what} must be a number or {k} numbers, got "
                                 f"{value!r}", task=name) from None
        if np.isnan(b).any():
            raise TaskStackError(f"{what} bound {int(np.flatnonzero(np.isnan(b))[0])} "
                                 "is NaN", task=name)
        bounds.append(b)
    lo, hi = bounds
    if np.any(lo == np.inf) or np.any(hi == -np.inf):
        raise TaskStackError("a lower bound of +inf or an upper bound of -inf leaves no "
                             "point", task=name)
    bad = np.flatnonzero(lo > hi)
    if bad.size:
        i = int(bad[0])
        raise TaskStackError(f"row {i} has lower {lo[i]:g} > upper {hi[i]:g}", task=name)
    free = np.flatnonzero(~(np.isfinite(lo) | np.isfinite(hi)))
    if free.size:
        raise TaskStackError(f"row {int(free[0])} has no finite bound", task=name)
    return C, lo, hi


class TaskWriter:
    """Robot task writers over one :class:`~prioik.hierarchy.StackData`.

    Args:
        robot: The robot (its ``n_v`` is the layout's width).
        mode: ``"velocity"`` (``J q̇ = ẋ* + K e``) or ``"acceleration"`` (eq. 2-4).
        hard: The levels declared hard (``layout.hard``; :func:`~prioik.hierarchy.hard`):
            a solution that leaves one violated is ``"failed"``, naming it and its
            tasks (e.g. ``hard=(0,)`` for support contacts that must hold). Checked
            against the declared levels when the layout is fixed.
    Declare tasks with the ``add_*`` methods (each takes ``level``: the priority, 0 the
    highest; ``None`` puts the task on a new level below every level so far; tasks of one
    level keep their declaration order). Gains: ``gain=K`` at velocity level,
    ``gain=(K_p, K_d)`` at acceleration level, finite and ≥ 0; ``weight`` is the task's
    weight within its level (its rows of ``data.sqrt_weight`` hold ``√weight``);
    ``keep=True``: the task keeps its last rows on a step where it is not written (see
    :meth:`targets`). At velocity level the frame-position, point, orientation and CoM
    tasks take ``max_rate``: their target ``b = ẋ* + K e`` is scaled down to
    ``‖b‖ = max_rate`` (m/s, rad/s) where it is larger — a bounded task-space speed
    towards a far target. The first read of :attr:`layout` or :attr:`data` (or the first
    write) fixes the layout; no task can be added after.

    Per step: one writer call per task (named like the ``add_`` method without its
    prefix), then :meth:`targets`, which refuses a task not written since the last call
    unless it was declared with ``keep=True``. A writer refuses a reference that is not
    finite (naming the task and the argument) before writing anything, and at
    acceleration level a ``KinematicState(drift=False)`` for tasks that have a drift
    (frames, CoM).

    A writer writes into its one :class:`~prioik.hierarchy.StackData`: use it from one
    thread at a time (one writer per thread; the builders of :mod:`robots.tasks` keep
    one per thread).

    Attributes:
        robot: The robot.
        mode: ``"velocity"`` or ``"acceleration"``.
        error, velocity_ref, feedforward, drift, kp, kd: Per-row ``e``, ``ẋ*``, ``ẍ*``,
            ``J̇q̇`` and gains (views of one ``6 × m`` array, valid once the layout is
            fixed; ``kp`` is ``K`` at velocity level).
    """

    def __init__(self, robot: RobotModel, mode: str = "velocity", *,
                 hard: Sequence[int] = ()) -> None:
        if mode not in MODES:
            raise TaskStackError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        self.robot = robot
        self.mode = mode
        self._hard = hard                 # checked with the layout, at _fix
        self._accel = mode == "acceleration"
        self._tasks: dict[str, _Task] = {}
        self._layout: StackLayout | None = None
        self._data: StackData | None = None
        self._Q = np.zeros((6, 0))
        self._views: _DataViews | None = None
        self._last_level = -1
        self._capped: tuple = ()                # (start, stop, max_rate) per capped task
        self._stamp = 0                         # targets() calls so far
        q_index = robot.actuated_q_index()
        self._q_index = q_index
        #: q entries of the actuated joints when q_ref ⊖ q is q_ref − q for all of them
        self._posture_q = q_index if np.all(q_index >= 0) else None
        self._limits = None                     # (lo, hi, vmax) of the actuated joints
        self._nq = robot.nq
        self._q_shape = (robot.nq,)
        self._qa = np.zeros(robot.nv - robot.n_base)

    # ----------------------------------------------------------------- declaring
    def add_frame_position(self, name: str, frame: str, *, gain, level: int | None = None,
                           weight: float = 1.0, max_rate: float | None = None,
                           keep: bool = False) -> None:
        """A frame origin's world position (3 rows); ``max_rate`` (velocity level, m/s):
        the target's speed ``‖ẋ* + K e‖`` capped at it."""
        cap = self._max_rate(name, max_rate)
        self._add_frame(name, frame, "position", 3, gain, level, weight, np.zeros(3), keep)
        self._tasks[name].max_rate = cap

    def add_point(self, name: str, frame: str, offset, *, gain, level: int | None = None,
                  weight: float = 1.0, max_rate: float | None = None,
                  keep: bool = False) -> None:
        """The world position of a point fixed on a frame (3 rows), ``offset`` in the
        frame's coordinates (e.g. a tool tip; no extra frame is added to the model);
        ``max_rate`` as in :meth:`add_frame_position`."""
        off = np.array(offset, dtype=float).reshape(-1)
        if off.shape != (3,) or not np.isfinite(off).all():
            raise TaskStackError(f"offset must be 3 finite numbers, got {offset!r}", task=name)
        cap = self._max_rate(name, max_rate)
        self._add_frame(name, frame, "position", 3, gain, level, weight, off, keep)
        self._tasks[name].max_rate = cap

    def add_frame_orientation(self, name: str, frame: str, *, gain,
                              level: int | None = None, weight: float = 1.0,
                              max_rate: float | None = None, keep: bool = False) -> None:
        """A frame's orientation (3 rows, world axes; error ``log(R* Rᵀ)``);
        ``max_rate`` (velocity level, rad/s): the target's angular speed capped at it."""
        cap = self._max_rate(name, max_rate)
        self._add_frame(name, frame, "orientation", 3, gain, level, weight, np.zeros(3), keep)
        self._tasks[name].max_rate = cap

    def add_frame_pose(self, name: str, frame: str, *, gain, level: int | None = None,
                       weight: float = 1.0, keep: bool = False) -> None:
        """A frame's position (rows 0-2) and orientation (rows 3-5)."""
        self._add_frame(name, frame, "pose", 6, gain, level, weight, np.zeros(3), keep)

    def add_contact(self, name: str, frame: str, *, gain, level: int | None = None,
                    weight: float = 1.0, keep: bool = False) -> None:
        """A support contact: the frame's pose held at a placement (6 rows, zero reference
        velocity and acceleration); write it with :meth:`contact`."""
        self._add_frame(name, frame, "pose", 6, gain, level, weight, np.zeros(3), keep)
        self._tasks[name].kind = "contact"

    def add_com(self, name: str = "com", *, gain, axes: Sequence[int] = (0, 1),
                level: int | None = None, weight: float = 1.0,
                max_rate: float | None = None, keep: bool = False) -> None:
        """The centre of mass on world ``axes`` (default horizontal; eq. 32-33);
        ``max_rate`` as in :meth:`add_frame_position`."""
        idx = np.array(axes, dtype=np.int64).reshape(-1)
        if idx.size < 1 or idx.size > 3 or not np.all((idx >= 0) & (idx < 3)) \
                or np.unique(idx).size != idx.size:
            raise TaskStackError(f"com axes must be distinct among 0, 1, 2, got {list(axes)}",
                                 task=name)
        cap = self._max_rate(name, max_rate)
        task = self._add(name, "com", idx.size, level, gain, weight, keep=keep)
        task.axes = idx
        task.max_rate = cap

    def add_posture(self, name: str = "posture", *, gain, level: int | None = None,
                    weight: float = 1.0, keep: bool = False) -> None:
        """The actuated joints (velocity rows ``n_base:``) to a reference configuration."""
        self._add(name, "posture", self.robot.nv - self.robot.n_base, level, gain, weight,
                  keep=keep)

    def add_damping(self, name: str = "damping", *, weight: float,
                    level: int | None = None) -> None:
        """Damping of a level: one row per velocity coordinate (floating base included),
        ``q̇ = 0`` at velocity level, ``q̈ = 0`` at acceleration level, of weight
        ``weight = λ²`` within its level.

        With the level's other tasks (rows ``J``, target ``b``) the level then solves
        the damped least squares ``min ‖J q̇ − b‖² + λ² ‖q̇‖²`` (Levenberg-Marquardt;
        Wampler 1986, Nakamura & Hanafusa 1986) under the higher levels: where ``J`` is well
        conditioned (singular values ``σ ≫ λ``) nothing visible changes, and along a
        direction of singular value ``σ`` the step is ``σ b / (σ² + λ²)``, at most
        ``‖b‖ / 2λ``, instead of the least-squares ``b / σ``. Its rows have full rank,
        so the damped level leaves no freedom to the levels below it. Use it at
        velocity level on the level of a task whose target may leave the robot's
        reach: at the edge of the workspace the exact least-squares step along the
        lost direction grows as ``1/σ`` and flips sign as a step crosses the
        singularity (joints flipping between their velocity bounds every step);
        damped, the loop settles. At acceleration level the rows damp ``q̈`` (the
        level's Tikhonov term on the acceleration).

        Args:
            weight: ``λ²`` (``(m/rad)²`` against a position task: ``λ`` is the singular
                value below which the level is damped), finite and > 0.

        The rows are constant (written once): no writer call per step.
        """
        if not (np.isscalar(weight) and not isinstance(weight, (str, bool))
                and np.isfinite(weight) and weight > 0):
            raise TaskStackError(f"damping weight must be finite and > 0, got {weight!r}",
                                 task=name if isinstance(name, str) else None)
        self._add(name, "damping", self.robot.nv, level, None, weight)

    def add_joint_limits(self, name: str = "joint_limits", *, form: str,
                         level: int | None = None, position: bool = True,
                         velocity: bool = True, horizon: float | None = None,
                         dt: float | None = None,
                         activation: JointLimitActivation | None = None,
                         weight: float = 1.0, keep: bool = False) -> None:
        """Joint limits of the actuated joints, one row per joint.

        Args:
            form: ``"activation"`` — equality rows pushing a joint out of its margin
                (:class:`JointLimitActivation`; position limits only), masked to zero
                rows while outside; ``"bounds"`` — an inequality task.
            position: The bounds hold the position limits.
            velocity: The bounds hold the velocity limits.
            horizon: Bounds: at velocity level ``q + q̇ T`` stays within the position
                limits for ``T = horizon`` (default ``dt``); at acceleration level the
                constant-acceleration position at ``T`` does (required).
            dt: The control step (required for the bounds; see
                :func:`robots.tasks.joint_limit_bounds`).
            activation: Parameters of the activation rows (defaults if omitted).
        """
        if form not in ("activation", "bounds"):
            raise TaskStackError(f"form must be 'activation' or 'bounds', got {form!r}",
                                 task=name)
        lo, hi, _ = self._joint_limits()
        if form == "activation":
            params = activation or JointLimitActivation()
            task = self._add(name, "limits", lo.size, level, None, weight, keep=keep)
            task.form, task.activation = form, params
            task.kp, task.kd = (params.kp, params.kd) if self._accel else (params.k, 0.0)
            with np.errstate(invalid="ignore"):
                width = np.where(np.isfinite(lo) & np.isfinite(hi),
                                 np.minimum(params.margin, 0.25 * (hi - lo)), 1.0)
            task.limits = np.ascontiguousarray(np.vstack([lo, hi, width]),
                                               dtype=np.float64)
            task.limits.setflags(write=False)
            return
        if not (position or velocity):
            raise TaskStackError("bounds need position or velocity limits", task=name)
        if not _positive(dt):
            raise TaskStackError(f"joint-limit bounds need dt > 0, got {dt!r}", task=name)
        if horizon is None and self._accel and position:
            raise TaskStackError("acceleration-level bounds need a horizon", task=name)
        T = dt if horizon is None else horizon
        if not _positive(T):
            raise TaskStackError(f"horizon must be > 0, got {horizon!r}", task=name)
        task = self._add(name, "limits", lo.size, level, None, weight, inequality=True,
                         keep=keep)
        task.form = form
        task.position, task.velocity = bool(position), bool(velocity)
        task.horizon, task.dt = float(T), float(dt)
        _, _, vmax = self._joint_limits()
        task.limits = np.ascontiguousarray(np.vstack([lo, hi, vmax]), dtype=np.float64)
        task.limits.setflags(write=False)

    def add_frame_region(self, name: str, frame: str, normals, lower=None, upper=None, *,
                         dt: float, horizon: float | None = None, offset=None,
                         level: int | None = None, weight: float = 1.0,
                         keep: bool = False) -> None:
        """Keep a point of a frame inside a region: ``lower ≤ C p ≤ upper`` (an inequality
        task, one row per row of ``C``), ``p`` the frame's origin or the point ``offset``
        (frame coordinates) fixed on it, world coordinates: a hand inside a workspace box,
        a foot above the floor, a tool on one side of a wall.

        Args:
            normals: ``C`` (``k × 3``, or one 3-vector): the directions, world axes; rows
                finite and non-zero.
            lower: ``k`` lower bounds on ``C p`` (numbers broadcast; ``None``: none on
                that side); ``lower ≤ upper``, every row with a finite bound.
            upper: ``k`` upper bounds on ``C p``, as ``lower``.
            dt: The control step; horizon: ``T`` (default ``dt``). The rows bound what
                a step does to ``C p`` as the joint-limit bounds bound ``q``
                (:meth:`add_joint_limits`): at velocity level ``C (p + J q̇ T)`` within
                the bounds; at acceleration level ``C J q̈`` such that the
                constant-acceleration path of ``C p`` is within them at ``T`` and after
                the next step ``dt``, braking of at least ``ẏ²/2d`` where the path would
                peak before ``T`` (``prioik._core.rows.acceleration_bounds`` with no
                speed limit), the drift ``C J̇ q̇`` taken off.
        """
        fid = self.robot.frame_id(frame)              # KeyError naming a missing frame
        try:
            off = np.zeros(3) if offset is None else np.array(offset, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            off = np.zeros(0)
        if off.shape != (3,) or not np.isfinite(off).all():
            raise TaskStackError(f"offset must be 3 finite numbers, got {offset!r}", task=name)
        region = _Region.of(name, normals, lower, upper, dt, horizon)
        region.point_rows = np.zeros((3, self.robot.nv))
        region.point_values = np.zeros((6, 3))
        task = self._add(name, "frame_region", region.C.shape[0], level, None, weight,
                         inequality=True, keep=keep)
        task.region = region
        self._frame_geometry(task, fid, off)

    def add_com_region(self, name: str, normals, lower=None, upper=None, *, dt: float,
                       horizon: float | None = None, level: int | None = None,
                       weight: float = 1.0, keep: bool = False) -> None:
        """Keep the centre of mass inside a region: ``lower ≤ C c ≤ upper`` (e.g. over
        the support polygon, :func:`polygon_region`); the arguments and the rows'
        meaning as in :meth:`add_frame_region`."""
        region = _Region.of(name, normals, lower, upper, dt, horizon)
        task = self._add(name, "com_region", region.C.shape[0], level, None, weight,
                         inequality=True, keep=keep)
        task.region = region

    def _add_frame(self, name, frame, kind, rows, gain, level, weight, offset, keep) -> None:
        fid = self.robot.frame_id(frame)              # KeyError naming a missing frame
        task = self._add(name, kind, rows, level, gain, weight, keep=keep)
        self._frame_geometry(task, fid, offset)

    def _frame_geometry(self, task: _Task, fid: int, offset: np.ndarray) -> None:
        """A frame task's columns (the frame's supporting joints) and the compiled
        writers' constant geometry of its point."""
        model = self.robot.model
        joint = model.frames[fid].parentJoint
        cols = [c for j in model.supports[joint] if j > 0
                for c in range(model.joints[j].idx_v,
                               model.joints[j].idx_v + model.joints[j].nv)]
        task.fid = fid
        task.joint = joint
        task.cols = np.array(sorted(cols), dtype=np.int64)
        task.offset = offset
        placement = model.frames[fid].placement          # in the parent joint's frame
        rotation = np.array(placement.rotation)
        task.geo = np.vstack([offset, placement.translation + rotation @ offset, rotation])
        task.geo.setflags(write=False)

    def _add(self, name, kind, rows, level, gain, weight, inequality=False,
             keep=False) -> _Task:
        if self._layout is not None:
            raise TaskStackError("the layout is fixed (it was read or written): declare "
                                 "every task before", task=name)
        if not isinstance(name, str) or not name:
            raise TaskStackError(f"a task name must be a non-empty string, got {name!r}")
        if name in self._tasks:
            raise TaskStackError("duplicate task name", task=name)
        if level is None:
            level = self._last_level + 1
        if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or level < 0:
            raise TaskStackError(f"level must be an integer ≥ 0 or None, got {level!r}",
                                 task=name)
        if not (np.isfinite(weight) and weight > 0):
            raise TaskStackError(f"weight must be finite and > 0, got {weight!r}", task=name)
        if not isinstance(keep, (bool, np.bool_)):
            raise TaskStackError(f"keep must be True or False, got {keep!r}", task=name)
        task = _Task(kind, name, int(level), int(rows), inequality, weight=float(weight),
                     shape=(int(rows),), keep=bool(keep))
        if kind not in ("limits", "frame_region", "com_region", "damping"):
            task.kp, task.kd = self._gains(name, gain)
        self._last_level = max(self._last_level, int(level))
        self._tasks[name] = task
        return task

    def _max_rate(self, name: str, max_rate) -> float:
        """A task's validated ``max_rate`` (velocity level; ``None``: 0, no cap)."""
        if max_rate is None:
            return 0.0
        if self._accel:
            raise TaskStackError("max_rate caps a velocity-level target; at acceleration "
                                 "level bound the reference instead", task=name)
        if not (np.isscalar(max_rate) and not isinstance(max_rate, (str, bool))
                and np.isfinite(max_rate) and max_rate > 0):
            raise TaskStackError(f"max_rate must be finite and > 0, got {max_rate!r}",
                                 task=name)
        return float(max_rate)

    def _gains(self, name: str, gain) -> tuple[float, float]:
        """``(K_p, K_d)`` from a declared ``gain``: finite and ≥ 0 (a negative gain
        drives the task away from its target)."""
        if self._accel:
            try:
                kp, kd = (float(g) for g in gain)
            except (TypeError, ValueError):
                raise TaskStackError(f"at acceleration level gain is (K_p, K_d), got "
                                     f"{gain!r}", task=name) from None
        else:
            if not np.isscalar(gain) or isinstance(gain, (str, bool)):
                raise TaskStackError(f"at velocity level gain is one number K, got {gain!r}",
                                     task=name)
            kp, kd = float(gain), 0.0
        if not (math.isfinite(kp) and math.isfinite(kd)):
            raise TaskStackError(f"gain must be finite, got {gain!r}", task=name)
        if kp < 0 or kd < 0:
            raise TaskStackError(f"gain must be ≥ 0, got {gain!r}", task=name)
        return kp, kd

    # ------------------------------------------------------------------- layout
    @property
    def layout(self) -> StackLayout:
        """The layout of the declared tasks (fixes it)."""
        if self._layout is None:
            self._fix()
        return self._layout

    @property
    def data(self) -> StackData:
        """The preallocated rows (fixes the layout)."""
        if self._data is None:
            self._fix()
        return self._data

    def _fix(self) -> None:
        if not self._tasks:
            raise TaskStackError("no task declared: add tasks before reading the layout")
        levels: dict[int, list[_Task]] = {}
        for task in self._tasks.values():
            levels.setdefault(task.level, []).append(task)
        missing = sorted(set(range(max(levels) + 1)) - set(levels))
        if missing:
            raise TaskStackError(f"levels {missing} have no task (levels are 0, 1, ... "
                                 "without gaps)", level=missing[0])
        self._layout = StackLayout(self.robot.nv, [
            [(t.name, t.rows, "inequality" if t.inequality else "equality")
             for t in levels[i]] for i in range(len(levels))], hard=self._hard)
        self._data = data = self._layout.data()
        self._Q = np.zeros((6, data.m))
        nb = self.robot.n_base
        for task in self._tasks.values():
            sl = self._layout.task_slice(task.name)
            task.start = sl.start
            if task.kind in _FRAME_MODES:
                task.spec = np.array([sl.start, _FRAME_MODES[task.kind], not self._accel,
                                      *task.cols], dtype=np.int64)
                task.spec.setflags(write=False)
            elif task.kind == "frame_region":        # the point's rows, in its scratch
                task.spec = np.array([0, _k.POSITION, not self._accel, *task.cols],
                                     dtype=np.int64)
                task.spec.setflags(write=False)
            elif task.kind == "limits" and task.form != "activation":
                task.bound_params = np.array([sl.start, task.horizon, task.dt,
                                              task.position, task.velocity, self._accel],
                                             dtype=np.float64)
                task.bound_params.setflags(write=False)
            elif task.kind == "limits":
                task.bound_params = np.array([sl.start, nb, task.kp, task.kd],
                                             dtype=np.float64)
                task.bound_params.setflags(write=False)
            data.sqrt_weight[sl] = np.sqrt(task.weight)
            if task.kind != "limits" or task.form == "bounds":
                self._Q[_k.KP, sl] = task.kp
                self._Q[_k.KD, sl] = task.kd
            if task.kind in ("posture", "limits") and not (
                    task.kind == "limits" and task.form == "activation"):
                A = data.A[sl]
                A[:, nb:] = np.eye(task.rows)      # constant unit rows, written once
            elif task.kind == "damping":
                data.A[sl] = np.eye(task.rows)      # every coordinate, the base's too
                task.keep, task.stamp = True, 0     # (written here, once for good)
        self._capped = tuple((t.start, t.start + t.rows, t.max_rate)
                             for t in self._tasks.values() if t.max_rate > 0)

    error = property(lambda self: self._Q[_k.ERROR],
                     doc="Per-row error ``e = x* − x`` (a view).")
    velocity_ref = property(lambda self: self._Q[_k.VELOCITY_REF],
                            doc="Per-row reference velocity ``ẋ*`` (a view).")
    feedforward = property(lambda self: self._Q[_k.FEEDFORWARD],
                           doc="Per-row feed-forward ``ẍ*`` (a view).")
    drift = property(lambda self: self._Q[_k.DRIFT], doc="Per-row drift ``J̇ q̇`` (a view).")
    kp = property(lambda self: self._Q[_k.KP],
                  doc="Per-row ``K_p`` (``K`` at velocity level; a view).")
    kd = property(lambda self: self._Q[_k.KD], doc="Per-row ``K_d`` (a view).")

    def set_gains(self, name: str, gain) -> None:
        """New gains of one task (``K`` or ``(K_p, K_d)`` as at declaration)."""
        task = self._task(name, None)
        if task.kind == "limits":
            raise TaskStackError("joint-limit gains are set by its JointLimitActivation",
                                 task=name)
        if task.kind == "damping":
            raise TaskStackError("a damping task has no gain (its weight is λ²)", task=name)
        task.kp, task.kd = self._gains(name, gain)
        if self._layout is not None:
            sl = slice(task.start, task.start + task.rows)
            self.kp[sl] = task.kp
            self.kd[sl] = task.kd

    def tasks(self) -> tuple[str, ...]:
        """The declared tasks' names, in declaration order."""
        return tuple(self._tasks)

    def __contains__(self, name: str) -> bool:
        return name in self._tasks

    # ------------------------------------------------------------------ writers
    def frame_position(self, state, name: str, x, xd=None, xdd=None) -> None:
        """A frame origin's (or a point's, :meth:`add_point`) position: ``x*`` and its
        rates ``ẋ*``, ``ẍ*`` (zero if omitted)."""
        task = self._tasks.get(name)
        if task is None or task.kind != "position" or task.spec is None:
            task = self._task(name, "position")
        hot = task.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(task, state)
        if not (x.__class__ is _NDARRAY and x.dtype is _F64 and x.shape == _SHAPE3):
            x = _vec3(x, name, "x")
        if self._accel and not state.has_drift:
            self._drift(state, task)                          # refuses a drift-free state
        try:
            if xd is None and xdd is None:        # a fixed target: two arguments fewer
                _k.position_target_rows(*hot[1], x)
            else:
                _k.position_rows(*hot[1], x, _vec3(xd, name, "xd"), _vec3(xdd, name, "xdd"))
        except CoreInputError as exc:
            raise _refused(task, exc) from None
        task.stamp = self._stamp

    point = frame_position

    def frame_orientation(self, state, name: str, rotation, angular_velocity=None,
                          angular_acceleration=None) -> None:
        """A frame's orientation: target ``R*`` (3×3), ``ω*``, ``ω̇*`` (world; zero if
        omitted)."""
        task = self._task(name, "orientation")
        self._frame(state, task, _ZERO3, _ZERO3, _ZERO3, _rotation(rotation, name),
                    _vec3(angular_velocity, name, "ω*"),
                    _vec3(angular_acceleration, name, "ω̇*"))

    def frame_pose(self, state, name: str, x, rotation, xd=None, xdd=None,
                   angular_velocity=None, angular_acceleration=None) -> None:
        """A frame's pose: position ``x*`` (rates ``ẋ*``, ``ẍ*``) and rotation ``R*``
        (rates ``ω*``, ``ω̇*``); omitted rates are zero."""
        task = self._tasks.get(name)
        if task is None or task.kind != "pose" or task.spec is None:
            task = self._task(name, "pose")
        # the common case (float64 arrays of the right shapes) checked inline: a helper
        # call per argument costs more than the compiled call itself
        if not (x.__class__ is _NDARRAY and x.dtype is _F64 and x.shape == _SHAPE3):
            x = _vec3(x, name, "x")
        if not (rotation.__class__ is _NDARRAY and rotation.dtype is _F64
                and rotation.shape == _SHAPE33):
            rotation = _rotation(rotation, name)
        if xd is None:
            xd = _ZERO3
        elif not (xd.__class__ is _NDARRAY and xd.dtype is _F64 and xd.shape == _SHAPE3):
            xd = _vec3(xd, name, "xd")
        if xdd is None:
            xdd = _ZERO3
        elif not (xdd.__class__ is _NDARRAY and xdd.dtype is _F64 and xdd.shape == _SHAPE3):
            xdd = _vec3(xdd, name, "xdd")
        self._frame(state, task, x, xd, xdd, rotation,
                    _vec3(angular_velocity, name, "ω*"),
                    _vec3(angular_acceleration, name, "ω̇*"))

    def contact(self, state, name: str, placement: pin.SE3 | None = None, *,
                translation=None, rotation=None) -> None:
        """A contact held at ``placement`` (or ``translation`` and ``rotation``: the same
        without building an SE3), zero reference velocity and acceleration."""
        task = self._tasks.get(name)
        if task is None or task.kind != "contact" or task.spec is None:
            task = self._task(name, "contact")
        if placement is not None:
            translation, rotation = placement.translation, placement.rotation
        if not (translation.__class__ is _NDARRAY and translation.dtype is _F64
                and translation.shape == _SHAPE3):
            translation = _vec(translation, 3, name, "translation")
        if not (rotation.__class__ is _NDARRAY and rotation.dtype is _F64
                and rotation.shape == _SHAPE33):
            rotation = _rotation(rotation, name)
        self._frame(state, task, translation, _ZERO3, _ZERO3, rotation, _ZERO3, _ZERO3)

    def com(self, state, name: str, x, xd=None, xdd=None) -> None:
        """The centre of mass: ``x*``, ``ẋ*``, ``ẍ*`` given on the task's axes."""
        task = self._tasks.get(name)
        if task is None or task.kind != "com" or self._layout is None:
            task = self._task(name, "com")
        if not state._com_ready:
            state.ensure_com()
        hot = task.hot
        if hot is None or hot[0] is not state.data:
            views = self._data_views(state)      # refuses another robot's state
            hot = task.hot = (state.data, (self._data.A, self._Q, task.start, views.Jcom,
                                           views.com, views.acom, task.axes))
        shape = task.shape
        if not (x.__class__ is _NDARRAY and x.dtype is _F64 and x.shape == shape):
            x = _vec(x, task.rows, name, "x")
        if xd is None or not (xd.__class__ is _NDARRAY and xd.dtype is _F64
                              and xd.shape == shape):
            xd = _vec(xd, task.rows, name, "xd")
        if xdd is None or not (xdd.__class__ is _NDARRAY and xdd.dtype is _F64
                               and xdd.shape == shape):
            xdd = _vec(xdd, task.rows, name, "xdd")
        try:
            _k.com_rows(*hot[1], x, xd, xdd, not (self._accel and self._drift(state, task)))
        except CoreInputError as exc:
            raise _refused(task, exc) from None
        task.stamp = self._stamp

    def posture(self, state, name: str, q_ref) -> None:
        """The actuated joints to ``q_ref`` (``n_q``): error ``q_ref ⊖ q`` on rows
        ``n_base:`` of the velocity (``q_ref − q`` where every actuated joint has one
        coordinate; pinocchio's ``difference`` otherwise), no drift."""
        task = self._tasks.get(name)
        if task is None or task.kind != "posture" or self._layout is None:
            task = self._task(name, "posture")
        if not (q_ref.__class__ is _NDARRAY and q_ref.dtype is _F64
                and q_ref.shape == self._q_shape):
            q_ref = _vec(q_ref, self._nq, name, "q_ref")
        if self._posture_q is not None:
            try:
                _k.posture_error(self._Q, task.start, state.q, q_ref, self._posture_q)
            except CoreInputError as exc:
                raise _refused(task, exc) from None
        else:
            if not np.isfinite(q_ref).all():
                bad = int(np.flatnonzero(~np.isfinite(q_ref))[0])
                raise TaskStackError(f"q_ref[{bad}] is not finite ({q_ref[bad]})",
                                     task=name, level=task.level)
            robot = self.robot
            sl = slice(task.start, task.start + task.rows)
            self.error[sl] = pin.difference(robot.model, state.q, q_ref)[robot.n_base:]
            self.velocity_ref[sl] = 0.0
            self.feedforward[sl] = 0.0
            self.drift[sl] = 0.0
        task.stamp = self._stamp

    def joint_limits(self, state, name: str = "joint_limits") -> int:
        """The joint-limit rows at ``state``: activation rows (returns how many are
        active) or bounds (``data.lower``/``upper``; returns the row count)."""
        task = self._tasks.get(name)
        if task is None or task.kind != "limits" or self._layout is None:
            task = self._task(name, "limits")
        data = self._data
        if task.form != "activation":
            _k.bounds_at(data.lower, data.upper, state.q, state.v, self._q_index,
                         task.limits, task.bound_params, self._qa)
            task.stamp = self._stamp
            return task.rows
        active = _k.activation_at(data.A, self._Q, state.q, self._q_index, task.limits,
                                  task.bound_params, self._qa)
        task.stamp = self._stamp
        return active

    def frame_region(self, state, name: str, normals=None, lower=None, upper=None) -> None:
        """A frame point's region rows at ``state`` (:meth:`add_frame_region`): the rows
        ``C J`` into ``data.A`` and their bounds into ``data.lower``/``upper``.
        ``normals``, ``lower``, ``upper`` given here replace the declared ones from this
        step on (a region that moves with the robot's supports); the row count stays."""
        task = self._tasks.get(name)
        if task is None or task.kind != "frame_region" or task.spec is None:
            task = self._task(name, "frame_region")
        hot = task.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(task, state, task.region.point_rows,
                                   task.region.point_values)
        accel = self._drift(state, task)                  # refuses a drift-free state
        # the point's rows J_p, −p and J̇_p q̇ by the compiled position writer (target 0)
        _k.position_target_rows(*hot[1], _ZERO3)
        values = task.region.point_values
        self._region(task, hot[1][0], values[_k.ERROR], -1.0, state.v, values[_k.DRIFT],
                     accel, normals, lower, upper)

    def com_region(self, state, name: str, normals=None, lower=None, upper=None) -> None:
        """The centre of mass's region rows at ``state`` (:meth:`add_com_region`); the
        arguments as in :meth:`frame_region`."""
        task = self._task(name, "com_region")
        if not state._com_ready:
            state.ensure_com()
        views = self._data_views(state)          # refuses another robot's state
        accel = self._drift(state, task)
        self._region(task, views.Jcom, views.com, 1.0, state.v, views.acom, accel, normals,
                     lower, upper)

    def _region(self, task: _Task, Jp, p, psign, v, drift, accel, normals, lower,
                upper) -> None:
        """``C J_p`` into the task's rows, bounds on ``C J_p q̇`` (velocity level) or
        ``C J_p q̈`` (acceleration level, ``drift`` = ``J̇_p q̇``) from ``C p`` (``p`` given
        as ``psign · p``) and its rate: ``prioik._core.rows.region_rows``."""
        reg = task.region
        if normals is not None or lower is not None or upper is not None:
            reg.update(task.name, normals, lower, upper)
        data = self._data
        _k.region_rows(data.A, data.lower, data.upper, task.start, reg.C, Jp, p, psign, v,
                       drift, reg.lower, reg.upper, reg.y, reg.yd, reg.no_speed_limit,
                       reg.horizon, reg.dt, accel)
        task.stamp = self._stamp

    # ------------------------------------------------------------------ targets
    def targets(self, state) -> StackData:
        """Every equality target from the rows written (velocity level:
        ``b = ẋ* + K e``; acceleration level: eq. 2-4 with ``q̇ = state.v``); returns
        :attr:`data`. Inequality rows keep the bounds their writer set (``b`` = 0).

        Every declared task must have been written since the previous call (or, the
        first time, at all): rows left from an earlier step would be solved as if they
        were current. A task declared with ``keep=True`` keeps its last rows when it
        is not written (a fixed target written once); it must be written once.

        Raises:
            TaskStackError: a task not written since the last call, naming it (and
                every other such task).
        """
        if self._accel:
            return self.acceleration_targets(state.v)
        return self.velocity_targets()

    def velocity_targets(self) -> StackData:
        """``b = ẋ* + K e`` into the data, each ``max_rate`` task's part scaled down to
        ``‖b‖ = max_rate`` where it is larger; returns the data.

        Raises:
            TaskStackError: a task not written since the last call (see :meth:`targets`).
        """
        data = self._data
        if data is None:
            data = self.data
        self._check_written()
        b = data.b
        _k.velocity_targets(b, self._Q)
        for start, stop, cap in self._capped:
            part = b[start:stop]
            norm = math.sqrt(float(part @ part))
            if norm > cap:
                part *= cap / norm
        return data

    def acceleration_targets(self, v: np.ndarray) -> StackData:
        """``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇`` (eq. 2-4) into the data; returns it.

        Raises:
            TaskStackError: a task not written since the last call (see :meth:`targets`).
        """
        data = self.data
        self._check_written()
        _k.acceleration_targets(data.A, data.b, self._Q, v)
        return data

    def _check_written(self) -> None:
        """Refuses targets while a task has not been written since the last targets
        (a task declared with ``keep=True``: not written at all); counts the call."""
        stamp = self._stamp
        for task in self._tasks.values():
            if task.stamp != stamp and (task.stamp < 0 or not task.keep):
                stale = [t for t in self._tasks.values()
                         if t.stamp != stamp and (t.stamp < 0 or not t.keep)]
                first = stale[0]
                raise TaskStackError(
                    f"not written {'yet' if first.stamp < 0 else 'since the last targets()'}"
                    f" (unwritten: {', '.join(t.name for t in stale)}); call its writer "
                    f"({first.kind if first.kind != 'limits' else 'joint_limits'}) every "
                    "step before targets(), or declare it with keep=True to keep its last "
                    "rows", task=first.name, level=first.level)
        self._stamp = stamp + 1

    # ------------------------------------------------------------------ helpers
    def _task(self, name: str, kind: str | None) -> _Task:
        task = self._tasks.get(name)
        if task is None:
            raise TaskStackError(f"no task {name!r} declared (tasks: "
                                 f"{', '.join(self._tasks) or 'none'})")
        if kind is not None and task.kind != kind:
            raise TaskStackError(f"task {name!r} was declared as {task.kind}, not {kind}",
                                 task=name)
        if self._layout is None:
            self._fix()
        return task

    def _frame(self, state, task: _Task, x, xd, xdd, rot, w, wd) -> None:
        hot = task.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(task, state)
        if self._accel and not state.has_drift:
            self._drift(state, task)                          # refuses a drift-free state
        try:
            _k.frame_rows(*hot[1], x, xd, xdd, rot, w, wd)
        except CoreInputError as exc:
            raise _refused(task, exc, _CONTACT_ARGUMENTS if task.kind == "contact"
                           else _ARGUMENTS) from None
        task.stamp = self._stamp

    def _frame_args(self, task: _Task, state, A=None, Q=None) -> tuple:
        """``(state.data, (A, Q, J, t, R, spec, geo, a_j, v_j))``: the frame kernels'
        arguments that stay the same while the states share one ``pin.Data`` (its storage
        is fixed, so the views follow every later kinematics call), kept on the task.
        ``A``, ``Q``: where the kernels write (default the data's rows and the per-row
        quantities; a frame region's point writes into its own scratch)."""
        views = self._data_views(state)          # refuses another robot's state
        t, R = views.frame(task.fid)
        aj, vj = views.motion(task.joint)
        task.hot = (state.data, (self._data.A if A is None else A,
                                 self._Q if Q is None else Q, views.J, t, R, task.spec,
                                 task.geo, aj, vj))
        return task.hot

    def _drift(self, state, task: _Task) -> bool:
        """Whether to write the drift: at acceleration level (refusing a drift-free
        state), never at velocity level."""
        if not self._accel:
            return False
        if not state.has_drift:
            raise TaskStackError("an acceleration-level writer needs J̇q̇, but the "
                                 "KinematicState was built with drift=False", task=task.name)
        return True

    def _data_views(self, state) -> _DataViews:
        views = self._views
        if views is None or views.data is not state.data:
            if state.robot.model is not self.robot.model:
                raise StateError(f"the state is of robot {state.robot.name!r}, the writer "
                                 f"of {self.robot.name!r}")
            views = self._views = _DataViews(state.data)
        return views

    def _joint_limits(self):
        if self._limits is None:
            self._limits = self.robot.joint_limits()
        return self._limits


class _DataViews:
    """Views into one ``pin.Data`` (its storage is fixed at creation, so views taken
    once follow every later kinematics call on it): ``J`` (``6 × n_v`` world-frame
    joint Jacobians), ``Jcom``, ``com``, ``acom`` (the centre of mass's acceleration),
    per frame the placement's translation and rotation and per joint its spatial
    acceleration and velocity. Holds ``data`` so that the views never outlive it."""

    def __init__(self, data: pin.Data) -> None:
        self.data = data
        self.J = data.J
        self.Jcom = data.Jcom
        self.com = data.com[0]
        self.acom = data.acom[0]
        self._frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def motion(self, joint: int) -> tuple[np.ndarray, np.ndarray]:
        """Views of ``data.a[joint]`` and ``data.v[joint]`` (6 each: linear, angular;
        the joint's frame)."""
        return self.data.a[joint].vector, self.data.v[joint].vector

    def frame(self, fid: int) -> tuple[np.ndarray, np.ndarray]:
        views = self._frames.get(fid)
        if views is None:      # views of data.oMf[fid]: they follow every later update
            placement = self.data.oMf[fid]
            views = self._frames[fid] = (placement.translation, placement.rotation)
        return views


_ZERO3 = np.zeros(3)                     # never written
#: the kernels' row set of each frame task kind
_FRAME_MODES = {"position": _k.POSITION, "orientation": _k.ORIENTATION, "pose": _k.POSE,
                "contact": _k.POSE}
_F64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_ZEROS: dict[int, np.ndarray] = {}        # m -> zeros(m), never written


#: the compiled writers' names of the writers' arguments, where they differ
_ARGUMENTS = {"Rstar": "rotation", "w": "angular_velocity", "wd": "angular_acceleration"}
_CONTACT_ARGUMENTS = {"x": "translation", "Rstar": "rotation"}


def _refused(task: _Task, exc: CoreInputError, names: dict = _ARGUMENTS) -> Exception:
    """A reference the compiled writer refused (an entry not finite) as the task's
    :class:`TaskStackError` naming the writer's argument; any other refusal as it was."""
    message = str(exc)
    array, bracket, rest = message.partition("[")
    if not bracket or "] is not finite" not in rest:
        return exc
    return TaskStackError(f"{names.get(array, array)}[{rest}", task=task.name,
                          level=task.level)


def _vec(value, m: int, task: str, what: str) -> np.ndarray:
    """``value`` as a float64 vector of ``m`` entries (zeros for ``None``); the common
    case (such an ndarray already) is checked first and passed through as is."""
    if value is None:
        zeros = _ZEROS.get(m)
        if zeros is None:
            zeros = _ZEROS[m] = np.zeros(m)
        return zeros
    if type(value) is np.ndarray and value.dtype == _F64 and value.shape == (m,):
        return value
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TaskStackError(f"{what} must be {m} numbers, got {value!r}", task=task) from None
    if out.shape != (m,):
        raise TaskStackError(f"{what} must have {m} entries, got shape {out.shape}", task=task)
    return out


def _vec3(value, task: str, what: str) -> np.ndarray:
    """:func:`_vec` of 3 entries (the frame writers' references)."""
    if value is None:
        return _ZERO3
    if type(value) is np.ndarray and value.dtype is _F64 and value.shape == _SHAPE3:
        return value
    return _vec(value, 3, task, what)


_SHAPE3 = (3,)
_SHAPE33 = (3, 3)


def _rotation(rotation, task: str) -> np.ndarray:
    rot = rotation
    if type(rot) is not np.ndarray or rot.dtype != _F64:
        try:
            rot = np.asarray(rotation, dtype=np.float64)
        except (TypeError, ValueError):
            raise TaskStackError(f"rotation must be 3 × 3 numbers, got {rotation!r}",
                                 task=task) from None
    if rot.shape != (3, 3):
        raise TaskStackError(f"rotation must be 3 × 3, got {rot.shape}", task=task)
    return rot
