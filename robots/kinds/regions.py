"""Region task kinds: inequality tasks keeping a frame's point or the centre of mass
inside ``lower ≤ C p ≤ upper`` (world coordinates).

Rows ``C J_p``; bounds on ``C J_p q̇`` (velocity level) or ``C J_p q̈`` (acceleration
level) from ``C p`` and its rate, written by the compiled
``prioik._core.rows.region_rows``.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from prioik._core import rows as _k
from prioik.hierarchy import TaskStackError

from ..rows import _ZERO3, RobotTask, _positive, register_task_kind
from .frame import FrameTask

__all__ = ["ComRegionTask", "FrameRegionTask"]


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

    def copy(self) -> _Region:
        """A copy with its own scratch (the validated arrays are replaced, never
        written: shared)."""
        out = copy.copy(self)
        out.y, out.yd = np.zeros_like(self.y), np.zeros_like(self.yd)
        if self.point_rows is not None:
            out.point_rows = np.zeros_like(self.point_rows)
            out.point_values = np.zeros_like(self.point_values)
        return out


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


class _RegionTask(RobotTask):
    """The region kinds' common part: the region, its bounds written per step."""

    inequality = True
    has_gain = False
    no_gain_reason = "a region task has no gain"

    def _detach(self) -> None:
        self.region = self.region.copy()

    def _write_region(self, state, Jp, p, psign, drift, normals, lower, upper) -> None:
        """``C J_p`` into the task's rows, bounds on ``C J_p q̇`` (velocity level) or
        ``C J_p q̈`` (acceleration level, ``drift`` = ``J̇_p q̇``) from ``C p`` (``p`` given
        as ``psign · p``) and its rate: ``prioik._core.rows.region_rows``."""
        w = self.writer
        accel = w._accel
        if accel and not state.has_drift:
            self._refuse_drift_free(state)
        reg = self.region
        if normals is not None or lower is not None or upper is not None:
            reg.update(self.name, normals, lower, upper)
        data = w._data
        _k.region_rows(data.A, data.lower, data.upper, self.start, reg.C, Jp, p, psign,
                       state.v, drift, reg.lower, reg.upper, reg.y, reg.yd,
                       reg.no_speed_limit, reg.horizon, reg.dt, accel)
        self.stamp = w._stamp

    def compiled_op(self, step):
        """Its region op (declared normals and bounds copied in); the reference
        ``(normals=None, lower=None, upper=None)`` replaces them as :meth:`write`'s
        arguments do (``None``: kept)."""
        C, lo, hi = step.region(self)
        reg = self.region

        def reference(normals=None, lower=None, upper=None) -> None:
            reg.update(self.name, normals, lower, upper)
            C[:] = reg.C.reshape(-1)
            lo[:] = reg.lower
            hi[:] = reg.upper
        reference()
        return reference

    def term(self, state, normals=None, lower=None, upper=None, *, mode=None):
        """The region's bounds task at ``state`` (:meth:`RobotTask.term`), for its
        normals and bounds or the ones given."""
        reg = self.region
        return super().term(state, reg.C if normals is None else normals,
                            reg.lower if lower is None else lower,
                            reg.upper if upper is None else upper, mode=mode)


@register_task_kind
class FrameRegionTask(_RegionTask, FrameTask):
    """Keep a point of a frame inside a region: ``lower ≤ C p ≤ upper`` (an inequality
    task, one row per row of ``C``), ``p`` the frame's origin or the point ``offset``
    (frame coordinates) fixed on it, world coordinates: a hand inside a workspace box,
    a foot above the floor, a tool on one side of a wall.

    Args:
        name: The task's name.
        frame: The frame.
        normals: ``C`` (``k × 3``, or one 3-vector): the directions, world axes; rows
            finite and non-zero.
        lower: ``k`` lower bounds on ``C p`` (numbers broadcast; ``None``: none on
            that side); ``lower ≤ upper``, every row with a finite bound.
        upper: ``k`` upper bounds on ``C p``, as ``lower``.
        dt: The control step; horizon: ``T`` (default ``dt``). The rows bound what
            a step does to ``C p`` as the joint-limit bounds bound ``q``
            (:class:`JointLimitsTask`): at velocity level ``C (p + J q̇ T)`` within
            the bounds; at acceleration level ``C J q̈`` such that the
            constant-acceleration path of ``C p`` is within them at ``T`` and after
            the next step ``dt``, braking of at least ``ẏ²/2d`` where the path would
            peak before ``T`` (``prioik._core.rows.acceleration_bounds`` with no
            speed limit), the drift ``C J̇ q̇`` taken off.
        offset: The point on the frame (frame coordinates; default its origin).
        level: As :class:`~robots.rows.RobotTask`.
        weight: As :class:`~robots.rows.RobotTask`.
        keep: As :class:`~robots.rows.RobotTask`.

    Written with ``write(state, normals=None, lower=None, upper=None)``: the ones given
    replace the declared ones from this step on (a region that moves with the robot's
    supports); the row count stays.
    """

    kind = "frame_region"
    frame_mode = _k.POSITION

    def __init__(self, name: str, frame: str, normals, lower=None, upper=None, *,
                 dt: float, horizon: float | None = None, offset=None, level=None,
                 weight=1.0, keep=False) -> None:
        FrameTask.__init__(self, name, frame, offset=offset, level=level, weight=weight,
                           keep=keep)
        self.region = _Region.of(name, normals, lower, upper, dt, horizon)
        self._horizon = horizon

    def key(self) -> tuple:
        reg = self.region
        return (self.frame, tuple(self.offset), reg.C.shape[0], reg.dt, self._horizon)

    def declare(self, writer) -> int:
        FrameTask.declare(self, writer)
        self.region.point_rows = np.zeros((3, writer.robot.nv))
        self.region.point_values = np.zeros((6, 3))
        return self.region.C.shape[0]

    def prepare(self, writer, start: int) -> None:
        FrameTask.prepare(self, writer, 0)           # the point's rows, in its scratch

    def write(self, state, normals=None, lower=None, upper=None) -> None:
        """The region's rows and bounds at ``state``."""
        hot = self.hot
        reg = self.region
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(state, reg.point_rows, reg.point_values)
        if self.writer._accel and not state.has_drift:
            self._refuse_drift_free(state)
        # the point's rows J_p, −p and J̇_p q̇ by the compiled position writer (target 0)
        _k.position_target_rows(*hot[1], _ZERO3)
        values = reg.point_values
        self._write_region(state, hot[1][0], values[_k.ERROR], -1.0, values[_k.DRIFT],
                           normals, lower, upper)


@register_task_kind
class ComRegionTask(_RegionTask):
    """Keep the centre of mass inside a region: ``lower ≤ C c ≤ upper`` (e.g. over the
    support polygon, :func:`~robots.tasks.polygon_region`); the arguments and the rows'
    meaning as in :class:`FrameRegionTask`."""

    kind = "com_region"

    def __init__(self, name: str, normals, lower=None, upper=None, *, dt: float,
                 horizon: float | None = None, level=None, weight=1.0,
                 keep=False) -> None:
        super().__init__(name, level=level, weight=weight, keep=keep)
        self.region = _Region.of(name, normals, lower, upper, dt, horizon)
        self._horizon = horizon

    def key(self) -> tuple:
        reg = self.region
        return (reg.C.shape[0], reg.dt, self._horizon)

    def declare(self, writer) -> int:
        return self.region.C.shape[0]

    def write(self, state, normals=None, lower=None, upper=None) -> None:
        """The region's rows and bounds at ``state``."""
        w = self._unwritable()
        if not state._com_ready:
            state.ensure_com()
        views = w._data_views(state)          # refuses another robot's state
        self._write_region(state, views.Jcom, views.com, 1.0, views.acom, normals, lower,
                           upper)
