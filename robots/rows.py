"""Task builders that write into a preallocated :class:`~hierarchy.StackBuffer`.

The builders of :mod:`robots.tasks` return one :class:`~robots.tasks.TaskTerm` (and
then a :class:`~hierarchy.Task`) per task and step: clear, and ~100 µs of Python
per G1 step. :class:`TaskRows` computes the same quantities — Jacobian rows ``J``,
error ``e = x* − x``, reference velocity ``ẋ*``, feed-forward ``ẍ*`` and drift
``J̇ q̇`` — straight into per-row arrays beside a buffer whose layout is fixed once,
then forms every target in one vectorised line:

* velocity level: ``b = ẋ* + K e`` (:meth:`TaskRows.velocity_targets`);
* acceleration level (eq. 2-4): ``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇``
  (:meth:`TaskRows.acceleration_targets`).

Each writer matches the builder of the same name in :mod:`robots.tasks` to rounding
(``tests/test_rows.py`` compares both on G1 states). Kinematics come from a
:class:`~robots.tasks.KinematicState` (``drift=False`` suffices at velocity level).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin

from hierarchy import StackBuffer

from .models import RobotModel
from .tasks import KinematicState

__all__ = ["TaskRows"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class TaskRows:
    """Per-row task quantities beside a :class:`~hierarchy.StackBuffer`.

    Args:
        robot: The robot (its ``n_v`` is the buffer's width).
        levels: Highest priority first; each level a sequence of ``(task name, rows)``.
        gains: Task name → ``K`` (velocity level) or ``(K_p, K_d)`` (acceleration
            level); tasks not named get ``K_p = K_d = 0``.

    Attributes:
        buffer: The rows ``A`` and targets ``b`` (what a solver reads).
        error, velocity_ref, feedforward, drift: Per-row ``e``, ``ẋ*``, ``ẍ*``, ``J̇q̇``.
        kp, kd: Per-row gains.
    """

    def __init__(self, robot: RobotModel, levels: Sequence[Sequence[tuple[str, int]]],
                 gains: dict | None = None) -> None:
        self.robot = robot
        self.buffer = StackBuffer(robot.nv, levels)
        m = self.buffer.m
        self.error = np.zeros(m)
        self.velocity_ref = np.zeros(m)
        self.feedforward = np.zeros(m)
        self.drift = np.zeros(m)
        self.kp = np.zeros(m)
        self.kd = np.zeros(m)
        self._posture_written: set[str] = set()
        for name, gain in (gains or {}).items():
            kp, kd = (gain, 0.0) if np.isscalar(gain) else gain
            self.set_gains(name, kp, kd)

    def set_gains(self, name: str, kp: float, kd: float = 0.0) -> None:
        """Gains of one task's rows (``kp`` is ``K`` at velocity level)."""
        sl = self.buffer.task_slice(name)
        self.kp[sl] = kp
        self.kd[sl] = kd

    # ------------------------------------------------------------------ writers
    def _check_rows(self, name: str, m: int) -> slice:
        sl = self.buffer.task_slice(name)   # raises for an unknown name, listing the tasks
        if sl.stop - sl.start != m:
            raise ValueError(f"task {name!r} has {sl.stop - sl.start} rows in the layout, "
                             f"the builder writes {m}")
        return sl

    def frame_position(self, state: KinematicState, name: str, frame: str, x,
                       xd=None, xdd=None) -> None:
        """A frame origin's world position (3 rows), as
        :func:`robots.tasks.frame_position`."""
        sl = self._check_rows(name, 3)
        fid = self.robot.frame_id(frame)
        m, d = state.model, state.data
        self.buffer.A[sl] = pin.getFrameJacobian(m, d, fid, _LWA)[:3]
        self.error[sl] = x
        self.error[sl] -= d.oMf[fid].translation
        self._refs(sl, xd, xdd)
        if state.has_drift:
            self.drift[sl] = pin.getFrameClassicalAcceleration(m, d, fid, _LWA).linear

    def frame_pose(self, state: KinematicState, name: str, frame: str, x,
                   rotation: np.ndarray, xd=None, xdd=None) -> None:
        """Position (rows 0-2, following ``x``) and orientation (rows 3-5, held at
        ``rotation``, error ``log(R* Rᵀ)``) of a frame, as
        :func:`robots.tasks.frame_pose` (and :func:`robots.tasks.contact` with
        ``xd = xdd = 0``)."""
        sl = self._check_rows(name, 6)
        fid = self.robot.frame_id(frame)
        m, d = state.model, state.data
        self.buffer.A[sl] = pin.getFrameJacobian(m, d, fid, _LWA)
        placement = d.oMf[fid]
        s = sl.start
        self.error[s:s + 3] = x
        self.error[s:s + 3] -= placement.translation
        self.error[s + 3:s + 6] = pin.log3(rotation @ placement.rotation.T)
        self._refs(slice(s, s + 3), xd, xdd)
        self.velocity_ref[s + 3:s + 6] = 0.0
        self.feedforward[s + 3:s + 6] = 0.0
        if state.has_drift:
            self.drift[sl] = pin.getFrameClassicalAcceleration(m, d, fid, _LWA).vector

    def com(self, state: KinematicState, name: str, x, xd=None, xdd=None,
            axes: Sequence[int] = (0, 1)) -> None:
        """The centre of mass on ``axes`` (``x``, ``xd``, ``xdd`` given on those axes),
        as :func:`robots.tasks.com_position`."""
        idx = list(axes)
        sl = self._check_rows(name, len(idx))
        self.buffer.A[sl] = state.Jcom[idx]
        self.error[sl] = x
        self.error[sl] -= state.com[idx]
        self._refs(sl, xd, xdd)
        if state.has_drift:
            self.drift[sl] = state.acom_drift[idx]

    def posture(self, state: KinematicState, name: str, q_ref) -> None:
        """The actuated joints to ``q_ref``, as :func:`robots.tasks.posture` (the
        constant unit rows are written on the first call only)."""
        robot = self.robot
        nb = robot.n_base
        sl = self._check_rows(name, robot.nv - nb)
        if name not in self._posture_written:
            A = self.buffer.A[sl]
            A[:] = 0.0
            A[:, nb:] = np.eye(robot.nv - nb)
            self._posture_written.add(name)
        self.error[sl] = pin.difference(robot.model, state.q, q_ref)[nb:]
        self.velocity_ref[sl] = 0.0
        self.feedforward[sl] = 0.0
        self.drift[sl] = 0.0

    def _refs(self, sl: slice, xd, xdd) -> None:
        self.velocity_ref[sl] = 0.0 if xd is None else xd
        self.feedforward[sl] = 0.0 if xdd is None else xdd

    # ------------------------------------------------------------------ targets
    def velocity_targets(self) -> StackBuffer:
        """``b = ẋ* + K e`` into the buffer; returns it."""
        b = self.buffer.b
        np.multiply(self.kp, self.error, out=b)
        b += self.velocity_ref
        return self.buffer

    def acceleration_targets(self, v: np.ndarray) -> StackBuffer:
        """``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇`` (eq. 2-4) into the buffer;
        returns it. The drifts must have been written (``drift=True`` state)."""
        buf = self.buffer
        rate = self.velocity_ref - buf.A @ v
        np.multiply(self.kd, rate, out=buf.b)
        buf.b += self.kp * self.error
        buf.b += self.feedforward
        buf.b -= self.drift
        return buf
