"""Task builders that write into a preallocated :class:`~prioik.hierarchy.StackData`.

The builders of :mod:`robots.tasks` return one :class:`~robots.tasks.TaskTerm` (and
then a :class:`~hierarchy.Task`) per task and step: clear, and ~100 µs of Python
per G1 step. :class:`TaskRows` computes the same quantities — Jacobian rows ``J``,
error ``e = x* − x``, reference velocity ``ẋ*``, feed-forward ``ẍ*`` and drift
``J̇ q̇`` — straight into per-row arrays beside a buffer whose layout is fixed once,
then forms every target in one line:

* velocity level: ``b = ẋ* + K e`` (:meth:`TaskRows.velocity_targets`);
* acceleration level (eq. 2-4): ``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇``
  (:meth:`TaskRows.acceleration_targets`).

Each writer is one compiled call (:mod:`robots._rows_kernel`) on views of the
state's ``pin.Data`` — the joint Jacobians ``data.J`` (a frame's LOCAL_WORLD_ALIGNED
Jacobian is formed from them), ``data.oMf``, ``data.Jcom``, ``data.com[0]`` — taken
once per ``Data``, so that a G1 step of five tasks costs a few µs instead of ~20.
Each writer matches the builder of the same name in :mod:`robots.tasks` to rounding
(``tests/test_rows.py`` compares both on G1 states). Kinematics come from a
:class:`~robots.tasks.KinematicState` (``drift=False`` suffices at velocity level).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin

from prioik.hierarchy import StackData, StackLayout

from . import _rows_kernel as _k
from .models import RobotModel
from .tasks import KinematicState

__all__ = ["TaskRows"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class TaskRows:
    """Per-row task quantities beside a :class:`~prioik.hierarchy.StackData`.

    Args:
        robot: The robot (its ``n_v`` is the layout's width).
        levels: Highest priority first; each level a sequence of ``(task name, rows)``.
        gains: Task name → ``K`` (velocity level) or ``(K_p, K_d)`` (acceleration
            level); tasks not named get ``K_p = K_d = 0``.

    Attributes:
        data: The rows ``A`` and targets ``b`` (what a solver reads; ``data.layout`` is
            the layout to prepare a solver for).
        error, velocity_ref, feedforward, drift: Per-row ``e``, ``ẋ*``, ``ẍ*``, ``J̇q̇``
            (writable views of one ``6 × M`` array; change them in place).
        kp, kd: Per-row gains (views, likewise).
    """

    def __init__(self, robot: RobotModel, levels: Sequence[Sequence[tuple[str, int]]],
                 gains: dict | None = None) -> None:
        self.robot = robot
        self.data = StackLayout(robot.nv, levels).data()
        self._Q = np.zeros((6, self.data.m))   # rows: _rows_kernel.ERROR ... KD
        self._plans: dict = {}            # (writer, task, frame) -> constants of one writer
        self._views = None                # _DataViews of the last state's pin.Data
        self._without_drift: set[str] = set()
        q_index = robot.actuated_q_index()
        #: q entries of the actuated joints when q_ref ⊖ q is q_ref − q for all of them
        self._posture_q = q_index if np.all(q_index >= 0) else None
        for name, gain in (gains or {}).items():
            kp, kd = (gain, 0.0) if np.isscalar(gain) else gain
            self.set_gains(name, kp, kd)

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

    def set_gains(self, name: str, kp: float, kd: float = 0.0) -> None:
        """Gains of one task's rows (``kp`` is ``K`` at velocity level)."""
        sl = self.data.layout.task_slice(name)
        self.kp[sl] = kp
        self.kd[sl] = kd

    # ------------------------------------------------------------------ writers
    def frame_position(self, state: KinematicState, name: str, frame: str, x,
                       xd=None, xdd=None) -> None:
        """A frame origin's world position (3 rows), as
        :func:`robots.tasks.frame_position`."""
        self._frame(state, name, frame, 3, x, _EYE3, xd, xdd)

    def frame_pose(self, state: KinematicState, name: str, frame: str, x,
                   rotation: np.ndarray, xd=None, xdd=None) -> None:
        """Position (rows 0-2, following ``x``) and orientation (rows 3-5, held at
        ``rotation``, error ``log(R* Rᵀ)``) of a frame, as
        :func:`robots.tasks.frame_pose` (and :func:`robots.tasks.contact` with
        ``xd = xdd = 0``)."""
        rot = rotation
        if type(rot) is not np.ndarray or rot.dtype != _F64:
            rot = np.asarray(rotation, dtype=np.float64)
        if rot.shape != (3, 3):
            raise ValueError(f"task {name!r}: rotation must be 3 × 3, got {rot.shape}")
        self._frame(state, name, frame, 6, x, rot, xd, xdd)

    def _frame(self, state: KinematicState, name: str, frame: str, nrows: int, x,
               rotation: np.ndarray, xd, xdd) -> None:
        """The frame writers' common body: ``nrows`` 3 (position) or 6 (pose)."""
        s, fid, cols = self._frame_plan(name, frame, nrows)
        views = self._data_views(state)
        p, R = views.frame(fid)
        drift = self._note_drift(state, name)
        _k.frame_rows(self.data.A, self._Q, s, nrows, views.J, cols, p, R,
                      _vec(x, 3, name, "x"), rotation, _vec(xd, 3, name, "xd"),
                      _vec(xdd, 3, name, "xdd"), not drift)
        if drift:
            acc = pin.getFrameClassicalAcceleration(state.model, state.data, fid, _LWA)
            self.drift[s:s + nrows] = acc.vector[:nrows]

    def com(self, state: KinematicState, name: str, x, xd=None, xdd=None,
            axes: Sequence[int] = (0, 1)) -> None:
        """The centre of mass on ``axes`` (``x``, ``xd``, ``xdd`` given on those axes),
        as :func:`robots.tasks.com_position`."""
        key = ("com", name, tuple(axes))
        plan = self._plans.get(key)
        if plan is None:
            idx = np.array(axes, dtype=np.int64)
            if idx.ndim != 1 or not np.all((idx >= 0) & (idx < 3)):
                raise ValueError(f"task {name!r}: com axes must be among 0, 1, 2, got "
                                 f"{list(axes)}")
            plan = self._plans[key] = (self._check_rows(name, idx.size), idx)
        s, idx = plan
        views = self._data_views(state)
        m = idx.size
        drift = self._note_drift(state, name)
        _k.com_rows(self.data.A, self._Q, s, views.Jcom, views.com, idx,
                    _vec(x, m, name, "x"), _vec(xd, m, name, "xd"), _vec(xdd, m, name, "xdd"),
                    not drift)
        if drift:
            self.drift[s:s + m] = state.acom_drift[idx]

    def posture(self, state: KinematicState, name: str, q_ref) -> None:
        """The actuated joints to ``q_ref``, as :func:`robots.tasks.posture` (the
        constant unit rows are written on the first call only)."""
        robot = self.robot
        nb = robot.n_base
        key = ("posture", name)
        s = self._plans.get(key)
        if s is None:
            s = self._check_rows(name, robot.nv - nb)
            A = self.data.A[s:s + robot.nv - nb]
            A[:] = 0.0
            A[:, nb:] = np.eye(robot.nv - nb)
            self._plans[key] = s
        q_ref = _vec(q_ref, robot.nq, name, "q_ref")
        if self._posture_q is not None:
            _k.posture_error(self._Q, s, state.q, q_ref, self._posture_q)
        else:
            sl = slice(s, s + robot.nv - nb)
            self.error[sl] = pin.difference(robot.model, state.q, q_ref)[nb:]
            self.velocity_ref[sl] = 0.0
            self.feedforward[sl] = 0.0
            self.drift[sl] = 0.0
        self._without_drift.discard(name)      # a posture has no drift

    # ------------------------------------------------------------------ helpers
    def _check_rows(self, name: str, m: int) -> int:
        sl = self.data.layout.task_slice(name)   # raises for an unknown name, listing the tasks
        if sl.stop - sl.start != m:
            raise ValueError(f"task {name!r} has {sl.stop - sl.start} rows in the layout, "
                             f"the builder writes {m}")
        return sl.start

    def _frame_plan(self, name: str, frame: str, m: int):
        key = (m, name, frame)
        plan = self._plans.get(key)
        if plan is None:
            start = self._check_rows(name, m)
            fid = self.robot.frame_id(frame)
            model = self.robot.model
            joint = model.frames[fid].parentJoint
            cols = [c for j in model.supports[joint] if j > 0
                    for c in range(model.joints[j].idx_v,
                                   model.joints[j].idx_v + model.joints[j].nv)]
            plan = self._plans[key] = (start, fid, np.array(sorted(cols), dtype=np.int64))
        return plan

    def _data_views(self, state: KinematicState) -> "_DataViews":
        views = self._views
        if views is None or views.data is not state.data:
            views = self._views = _DataViews(state.data)
        return views

    def _note_drift(self, state: KinematicState, name: str) -> bool:
        if state.has_drift:
            self._without_drift.discard(name)
            return True
        self._without_drift.add(name)
        return False

    # ------------------------------------------------------------------ targets
    def velocity_targets(self) -> StackData:
        """``b = ẋ* + K e`` into the buffer; returns it."""
        _k.velocity_targets(self.data.b, self._Q)
        return self.data

    def acceleration_targets(self, v: np.ndarray) -> StackData:
        """``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇`` (eq. 2-4) into the buffer;
        returns it.

        Raises:
            ValueError: a task was last written from a ``drift=False`` state (its
                ``J̇ q̇`` is unknown), naming it.
        """
        if self._without_drift:
            raise ValueError(f"tasks {sorted(self._without_drift)} were written from a "
                             "KinematicState(drift=False): acceleration targets need "
                             "J̇q̇ (build the state with drift=True)")
        buf = self.data
        rate = self.velocity_ref - buf.A @ v
        np.multiply(self.kd, rate, out=buf.b)
        buf.b += self.kp * self.error
        buf.b += self.feedforward
        buf.b -= self.drift
        return buf


class _DataViews:
    """Views into one ``pin.Data`` (its storage is fixed at creation, so views taken
    once follow every later kinematics call on it): ``J`` (``6 × n_v`` world-frame
    joint Jacobians), ``Jcom``, ``com``, and per frame the placement's translation
    and rotation. Holds ``data`` so that the views never outlive it."""

    def __init__(self, data: pin.Data) -> None:
        self.data = data
        self.J = data.J
        self.Jcom = data.Jcom
        self.com = data.com[0]
        self._frames: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def frame(self, fid: int) -> tuple[np.ndarray, np.ndarray]:
        views = self._frames.get(fid)
        if views is None:
            placement = self.data.oMf[fid]
            views = self._frames[fid] = (placement.translation, placement.rotation)
        return views


_EYE3 = np.eye(3)
_F64 = np.dtype(np.float64)
_ZEROS: dict[int, np.ndarray] = {}        # m -> zeros(m), never written


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
    out = np.asarray(value, dtype=np.float64)
    if out.shape != (m,):
        raise ValueError(f"task {task!r}: {what} must have {m} entries, got shape {out.shape}")
    return out
