"""The robot task kinds: one class per kind, registered by name (:data:`~robots.rows.TASK_KINDS`).

Each kind (a :class:`~robots.rows.RobotTask`) knows its rows, writes them in place
through the compiled row writers (``prioik._core.rows``), gives its one-off term
(:meth:`~robots.rows.RobotTask.term`) and maps itself onto the PlaCo, pink and mink
tasks (:meth:`~robots.rows.RobotTask.baseline_task`):

* :mod:`.frame` — :class:`FramePositionTask`, :class:`PointTask`,
  :class:`FrameOrientationTask`, :class:`FramePoseTask`, :class:`ContactTask`;
* :mod:`.com` — :class:`ComTask`;
* :mod:`.joints` — :class:`PostureTask`, :class:`DampingTask`, :class:`JointLimitsTask`;
* :mod:`.regions` — :class:`FrameRegionTask`, :class:`ComRegionTask`.

A new kind is a :class:`~robots.rows.RobotTask` subclass decorated with
:func:`~robots.rows.register_task_kind`: :meth:`~robots.rows.TaskWriter.add` and
:meth:`~robots.rows.TaskWriter.write` take it, its :meth:`~robots.rows.RobotTask.term`
gives one-off stacks, and the baselines find it by its ``kind``.
"""

from .com import ComTask
from .frame import ContactTask, FrameOrientationTask, FramePoseTask, FramePositionTask, PointTask
from .joints import DampingTask, JointLimitsTask, PostureTask
from .regions import ComRegionTask, FrameRegionTask

__all__ = ["ComRegionTask", "ComTask", "ContactTask", "DampingTask", "FrameOrientationTask",
           "FramePoseTask", "FramePositionTask", "FrameRegionTask", "JointLimitsTask",
           "PointTask", "PostureTask"]
