"""The centre-of-mass task kind: the centre of mass on chosen world axes (eq. 32-33).

Rows ``J_com`` on the axes, drift ``J̇_com q̇``; written by the compiled
``prioik._core.rows.com_rows`` from ``data.Jcom``, ``data.com[0]`` and ``data.acom[0]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from prioik._core import rows as _k
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import TaskStackError

from ..rows import RobotTask, _refused, _vec, register_task_kind

__all__ = ["ComTask"]


@register_task_kind
class ComTask(RobotTask):
    """The centre of mass on world ``axes`` (default horizontal; eq. 32-33), one row per
    axis; ``max_rate`` (velocity level, m/s): the target's speed capped at it.

    Written with ``write(state, x, xd=None, xdd=None)``: ``x*``, ``ẋ*``, ``ẍ*`` on the
    task's axes. Baselines (the horizontal centre of mass, a 2-vector target): PlaCo's
    CoM task masked to ``xy`` (its height held where it starts), pink's and mink's CoM
    task with no vertical cost.

    Raises:
        TaskStackError: ``axes`` not distinct among 0, 1, 2.
    """

    kind = "com"
    capped = True

    def __init__(self, name: str = "com", *, gain=None, axes: Sequence[int] = (0, 1),
                 level=None, weight=1.0, max_rate=None, keep=False) -> None:
        super().__init__(name, gain=gain, level=level, weight=weight, max_rate=max_rate,
                         keep=keep)
        try:
            idx = np.array(axes, dtype=np.int64).reshape(-1)
        except (TypeError, ValueError):
            idx = np.zeros(0, dtype=np.int64)
        if idx.size < 1 or idx.size > 3 or not np.all((idx >= 0) & (idx < 3)) \
                or np.unique(idx).size != idx.size:
            raise TaskStackError(f"com axes must be distinct among 0, 1, 2, got {axes!r}",
                                 task=name)
        idx.setflags(write=False)
        self.axes = idx
        self._zeros = np.zeros(idx.size)          # never written

    def key(self) -> tuple:
        return tuple(int(a) for a in self.axes)

    def declare(self, writer) -> int:
        return self.axes.size

    def write(self, state, x, xd=None, xdd=None) -> None:
        """The rows at ``state`` for ``x*``, ``ẋ*``, ``ẍ*`` (on the task's axes)."""
        if not state._com_ready:
            state.ensure_com()
        hot = self.hot
        writer = self.writer
        if hot is None or hot[0] is not state.data:
            writer = self._unwritable()
            views = writer._data_views(state)      # refuses another robot's state
            hot = self.hot = (state.data, (writer._data.A, writer._Q, self.start, views.Jcom,
                                           views.com, views.acom, self.axes))
        accel = writer._accel
        if accel and not state.has_drift:
            self._refuse_drift_free(state)
        try:      # as given first (see FramePositionTask.write)
            _k.com_rows(*hot[1], x, self._zeros if xd is None else xd,
                        self._zeros if xdd is None else xdd, not accel)
        except CoreInputError:
            rows, name = self.rows, self.name
            x, xd, xdd = (_vec(x, rows, name, "x"), _vec(xd, rows, name, "xd"),
                          _vec(xdd, rows, name, "xdd"))
            try:
                _k.com_rows(*hot[1], x, xd, xdd, not accel)
            except CoreInputError as exc:
                raise _refused(self, exc) from None
        self.stamp = writer._stamp

    def compiled_op(self, step):
        """Its CoM op; the reference ``(x, xd=None)`` on the task's axes."""
        ref = step.com(self)
        name, k, shape = self.name, self.rows, (self.rows,)

        def reference(x, xd=None) -> None:
            step.put(ref, 0, x, shape, name, "x")
            step.put(ref, k, xd, shape, name, "xd")
        return reference

    @classmethod
    def baseline_task(cls, library, spec, target, context):
        c = context.get("cost")
        if library == "placo":
            com0 = np.array(context["robot_wrapper"].com_world())
            task = context["solver"].add_com_task(com0)
            task.configure(spec.name, context["priority"], spec.weight)
            task.mask.set_axises("xy")
            task.com0 = com0
            return task
        if library == "tsid":
            return "com_xy"
        if library == "pink":
            from pink.tasks import ComTask as PinkComTask
            return PinkComTask(cost=[c, c, 0.0])
        if library == "mink":
            import mink
            return mink.ComTask(cost=[c, c, 0.0], gain=context["gain"])
        return super().baseline_task(library, spec, target, context)

    @classmethod
    def baseline_reference(cls, library, targets, step, context):
        if library != "tsid":
            return super().baseline_reference(library, targets, step, context)
        x0, x1, x2 = targets
        vel, acc = (x2 - x0) / (2 * step), (x2 - 2 * x1 + x0) / step ** 2
        return np.append(x1, 0.0), np.append(vel, 0.0), np.append(acc, 0.0)

    @classmethod
    def baseline_target(cls, library, task, target, context) -> None:
        if library == "placo":
            com = task.com0.copy()
            com[:2] = target
            task.target_world = com
        elif library == "pink":
            com = np.zeros(3)
            com[:2] = target
            task.set_target(com)
        elif library == "mink":
            task.set_target(np.array([target[0], target[1], context["com_height"]]))
        else:
            super().baseline_target(library, task, target, context)
