"""Frame task kinds: a frame origin's or a point's position, a frame's orientation, its
pose, a contact (a pose held at a placement).

Rows (LOCAL_WORLD_ALIGNED, world axes): position rows 0-2 ``ṗ = J_p q̇``, orientation
rows ``ω = J_ω q̇`` with the error ``log(R* Rᵀ)``; a pose stacks both. Written by the
compiled ``prioik._core.rows.frame_rows`` / ``position_rows`` from the world-frame joint
Jacobians ``data.J`` on the frame's supporting joints.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import pinocchio as pin

from prioik._core import rows as _k
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import TaskStackError

from ..rows import (
    _ZERO3,
    RobotTask,
    _refused,
    _rotation,
    _vec,
    _vec3,
    register_task_kind,
)

__all__ = ["ContactTask", "FrameOrientationTask", "FramePoseTask", "FramePositionTask",
           "PointTask"]

_SHAPE3, _SHAPE33 = (3,), (3, 3)

#: a contact's compiled-writer argument names
_CONTACT_ARGUMENTS = {"x": "translation", "Rstar": "rotation"}


def _rates(p, R, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration (linear, angular: 6 each) by central differences of
    three positions ``p`` and rotations ``R`` ``step`` apart."""
    w01 = np.asarray(pin.log3(R[1] @ R[0].T))
    w12 = np.asarray(pin.log3(R[2] @ R[1].T))
    vel = np.concatenate([(p[2] - p[0]) / (2 * step), (w01 + w12) / (2 * step)])
    acc = np.concatenate([(p[2] - 2 * p[1] + p[0]) / step ** 2, (w12 - w01) / step ** 2])
    return vel, acc


def _offset(name: str, offset) -> np.ndarray:
    """A point's ``offset`` (frame coordinates): 3 finite numbers, copied, read-only."""
    try:
        off = np.zeros(3) if offset is None else np.array(offset, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        off = np.zeros(0)
    if off.shape != (3,) or not np.isfinite(off).all():
        raise TaskStackError(f"offset must be 3 finite numbers, got {offset!r}", task=name)
    off.setflags(write=False)
    return off


class FrameTask(RobotTask):
    """Base of the tasks on one frame's point (its origin or ``offset`` on it): the
    frame's supporting columns and the compiled writers' constant geometry.

    Args:
        name: The task's name.
        frame: The frame's (or role's) name in the robot.
        offset: The point on the frame (frame coordinates; default its origin).
        **declared: As :class:`~robots.rows.RobotTask`.
    """

    #: the compiled writers' row set (``_k.POSITION``, ``_k.ORIENTATION``, ``_k.POSE``)
    frame_mode: ClassVar[int] = _k.POSE
    frame_rows: ClassVar[int] = 6

    def __init__(self, name: str, frame: str, *, offset=None, **declared) -> None:
        super().__init__(name, **declared)
        self.frame = frame
        self.offset = _offset(name, offset)
        self.spec: np.ndarray | None = None

    def key(self) -> tuple:
        return (self.frame, tuple(self.offset))

    def declare(self, writer) -> int:
        model = writer.robot.model
        fid = writer.robot.frame_id(self.frame)          # KeyError naming a missing frame
        joint = model.frames[fid].parentJoint
        cols = [c for j in model.supports[joint] if j > 0
                for c in range(model.joints[j].idx_v,
                               model.joints[j].idx_v + model.joints[j].nv)]
        self.fid, self.joint = fid, joint
        self.cols = np.array(sorted(cols), dtype=np.int64)
        placement = model.frames[fid].placement          # in the parent joint's frame
        rotation = np.array(placement.rotation)
        self.geo = np.vstack([self.offset, placement.translation + rotation @ self.offset,
                              rotation])
        self.geo.setflags(write=False)
        return self.frame_rows

    def prepare(self, writer, start: int) -> None:
        self.spec = np.array([start, self.frame_mode, not writer._accel, *self.cols],
                             dtype=np.int64)
        self.spec.setflags(write=False)

    def _frame_args(self, state, A=None, Q=None) -> tuple:
        """``(state.data, (A, Q, J, t, R, spec, geo, a_j, v_j))``: the frame kernels'
        arguments that stay the same while the states share one ``pin.Data`` (its storage
        is fixed, so the views follow every later kinematics call), kept on the task.
        ``A``, ``Q``: where the kernels write (default the writer's rows and per-row
        quantities)."""
        w = self._unwritable()
        views = w._data_views(state)             # refuses another robot's state
        t, R = views.frame(self.fid)
        aj, vj = views.motion(self.joint)
        self.hot = (state.data, (w._data.A if A is None else A, w._Q if Q is None else Q,
                                 views.J, t, R, self.spec, self.geo, aj, vj))
        return self.hot

    def _frame(self, state, x, xd, xdd, rot, w, wd, names=None) -> None:
        hot = self.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(state)
        writer = self.writer
        if writer._accel and not state.has_drift:
            self._refuse_drift_free(state)
        try:
            _k.frame_rows(*hot[1], x, xd, xdd, rot, w, wd)
        except CoreInputError as exc:
            raise (_refused(self, exc, names) if names else _refused(self, exc)) from None
        self.stamp = writer._stamp

    #: its baselines' counterparts: PlaCo's ``KinematicsSolver`` method, TSID's task
    #: name, and which of (position, orientation) pink's and mink's frame task weigh
    placo_method: ClassVar[str] = ""
    tsid_name: ClassVar[str] = ""
    weighs: ClassVar[tuple[bool, bool]] = (False, False)

    @classmethod
    def baseline_task(cls, library, spec, target, context):
        if not cls.placo_method:
            return super().baseline_task(library, spec, target, context)
        if library == "placo":
            add = getattr(context["solver"], cls.placo_method)
            task = add(spec.frame, np.asarray(target))
            weights = (spec.weight, spec.weight) if all(cls.weighs) else (spec.weight,)
            task.configure(spec.name, context["priority"], *weights)
            return task
        if library == "tsid":
            return cls.tsid_name
        if library == "pink":
            return cls._pink_frame_task(spec, context, *cls.weighs)
        if library == "mink":
            return cls._mink_frame_task(spec, context, *cls.weighs)
        return super().baseline_task(library, spec, target, context)

    @staticmethod
    def _pink_frame_task(spec, context, position: bool, orientation: bool):
        c = context["cost"]
        from pink.tasks import FrameTask as PinkFrameTask
        return PinkFrameTask(spec.frame, position_cost=c if position else 0.0,
                             orientation_cost=c if orientation else 0.0)

    @staticmethod
    def _mink_frame_task(spec, context, position: bool, orientation: bool):
        import mink
        c = context["cost"]
        return mink.FrameTask(spec.frame, "body", position_cost=c if position else 0.0,
                              orientation_cost=c if orientation else 0.0,
                              gain=context["gain"])


@register_task_kind
class FramePositionTask(FrameTask):
    """A frame origin's world position (3 rows); ``max_rate`` (velocity level, m/s):
    the target's speed ``‖ẋ* + K e‖`` capped at it.

    Written with ``write(state, x, xd=None, xdd=None)``: ``x*`` and its rates (zero if
    omitted). Baselines: PlaCo's position task, pink's and mink's frame task with no
    orientation cost; the target a 3-vector.
    """

    kind = "frame_position"
    placo_method = "add_position_task"
    tsid_name = "position"
    weighs = (True, False)
    capped = True
    frame_mode = _k.POSITION
    frame_rows = 3

    def __init__(self, name: str, frame: str, *, gain=None, level=None, weight=1.0,
                 max_rate=None, keep=False) -> None:
        super().__init__(name, frame, gain=gain, level=level, weight=weight,
                         max_rate=max_rate, keep=keep)

    def write(self, state, x, xd=None, xdd=None) -> None:
        """The rows at ``state`` for the target ``x*`` (3) and its rates ``ẋ*``, ``ẍ*``."""
        hot = self.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(state)
        writer = self.writer
        if writer._accel and not state.has_drift:
            self._refuse_drift_free(state)
        # the compiled writer checks the references before writing anything: the common
        # case (float64 arrays of the right shapes) goes to it as given, anything it
        # refuses is converted (or refused naming the task) and written again
        try:
            if xd is None and xdd is None:        # a fixed target: two arguments fewer
                _k.position_target_rows(*hot[1], x)
            else:
                _k.position_rows(*hot[1], x, _ZERO3 if xd is None else xd,
                                 _ZERO3 if xdd is None else xdd)
        except CoreInputError:
            name = self.name
            x, xd, xdd = _vec3(x, name, "x"), _vec3(xd, name, "xd"), _vec3(xdd, name, "xdd")
            try:
                _k.position_rows(*hot[1], x, xd, xdd)
            except CoreInputError as exc:
                raise _refused(self, exc) from None
        self.stamp = writer._stamp

    def compiled_op(self, step):
        """Its frame op; the reference ``(x, xd=None)`` as :meth:`write`'s."""
        ref = step.frame(self)
        name = self.name

        def reference(x, xd=None) -> None:
            step.put(ref, 0, x, _SHAPE3, name, "x")
            step.put(ref, 3, xd, _SHAPE3, name, "xd")
        return reference

    @classmethod
    def baseline_reference(cls, library, targets, step, context):
        if library != "tsid":
            return super().baseline_reference(library, targets, step, context)
        x0, x1, x2 = targets
        vel, acc = (x2 - x0) / (2 * step), (x2 - 2 * x1 + x0) / step ** 2
        return x1, np.append(vel, np.zeros(3)), np.append(acc, np.zeros(3))

    @classmethod
    def baseline_target(cls, library, task, target, context) -> None:
        if library == "placo":
            task.target_world = np.asarray(target)
        elif library == "pink":
            task.set_target(pin.SE3(np.eye(3), np.asarray(target)))
        elif library == "mink":
            import mink
            task.set_target(mink.SE3.from_translation(np.asarray(target)))
        else:
            super().baseline_target(library, task, target, context)


@register_task_kind
class PointTask(FramePositionTask):
    """The world position of a point fixed on a frame (3 rows), ``offset`` in the
    frame's coordinates (e.g. a tool tip; no extra frame is added to the model);
    written as a :class:`FramePositionTask` (``writer.point`` is
    ``writer.frame_position``)."""

    kind = "point"
    written_by = "frame_position"

    def __init__(self, name: str, frame: str, offset, *, gain=None, level=None,
                 weight=1.0, max_rate=None, keep=False) -> None:
        off = _offset(name, offset)
        FrameTask.__init__(self, name, frame, offset=off, gain=gain, level=level,
                           weight=weight, max_rate=max_rate, keep=keep)

    @classmethod
    def baseline_task(cls, library, spec, target, context):
        raise TaskStackError(f"a point task has no {library} counterpart (the libraries' "
                             "frame tasks track a frame's origin)", task=spec.name)


@register_task_kind
class FrameOrientationTask(FrameTask):
    """A frame's orientation (3 rows, world axes; error ``log(R* Rᵀ)``); ``max_rate``
    (velocity level, rad/s): the target's angular speed capped at it.

    Written with ``write(state, rotation, angular_velocity=None,
    angular_acceleration=None)``: ``R*`` (3×3), ``ω*``, ``ω̇*`` (world; zero if omitted).
    Baselines: PlaCo's orientation task, pink's and mink's frame task with no position
    cost; the target a 3×3 rotation.
    """

    kind = "frame_orientation"
    placo_method = "add_orientation_task"
    tsid_name = "orientation"
    weighs = (False, True)
    capped = True
    frame_mode = _k.ORIENTATION
    frame_rows = 3

    def __init__(self, name: str, frame: str, *, gain=None, level=None, weight=1.0,
                 max_rate=None, keep=False) -> None:
        super().__init__(name, frame, gain=gain, level=level, weight=weight,
                         max_rate=max_rate, keep=keep)

    def write(self, state, rotation, angular_velocity=None,
              angular_acceleration=None) -> None:
        """The rows at ``state`` for the target ``R*`` and its rates."""
        name = self.name
        self._frame(state, _ZERO3, _ZERO3, _ZERO3, _rotation(rotation, name),
                    _vec3(angular_velocity, name, "ω*"),
                    _vec3(angular_acceleration, name, "ω̇*"))

    def compiled_op(self, step):
        """Its frame op; the reference ``(rotation, angular_velocity=None)``."""
        ref = step.frame(self)
        name = self.name

        def reference(rotation, angular_velocity=None) -> None:
            step.put(ref, 6, rotation, _SHAPE33, name, "rotation")
            step.put(ref, 15, angular_velocity, _SHAPE3, name, "angular_velocity")
        return reference

    @classmethod
    def baseline_reference(cls, library, targets, step, context):
        if library != "tsid":
            return super().baseline_reference(library, targets, step, context)
        return (targets[1], *_rates([np.zeros(3)] * 3, targets, step))

    @classmethod
    def baseline_target(cls, library, task, target, context) -> None:
        if library == "placo":
            task.R_world_frame = np.asarray(target)
        elif library == "pink":
            task.set_target(pin.SE3(np.asarray(target), np.zeros(3)))
        elif library == "mink":
            import mink
            task.set_target(mink.SE3.from_rotation(mink.SO3.from_matrix(np.asarray(target))))
        else:
            super().baseline_target(library, task, target, context)


@register_task_kind
class FramePoseTask(FrameTask):
    """A frame's position (rows 0-2) and orientation (rows 3-5).

    Written with ``write(state, x, rotation, xd=None, xdd=None, angular_velocity=None,
    angular_acceleration=None)``; omitted rates are zero. Baselines: PlaCo's frame task,
    pink's and mink's frame task (a hard one a constraint in mink); the target a 4×4
    placement.
    """

    kind = "frame_pose"
    placo_method = "add_frame_task"
    tsid_name = "frame"
    weighs = (True, True)
    hard_is_constraint = True

    def __init__(self, name: str, frame: str, *, gain=None, level=None, weight=1.0,
                 keep=False) -> None:
        super().__init__(name, frame, gain=gain, level=level, weight=weight, keep=keep)

    def write(self, state, x, rotation, xd=None, xdd=None, angular_velocity=None,
              angular_acceleration=None) -> None:
        """The rows at ``state`` for the position ``x*`` (rates ``ẋ*``, ``ẍ*``) and the
        rotation ``R*`` (rates ``ω*``, ``ω̇*``)."""
        hot = self.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(state)
        writer = self.writer
        if writer._accel and not state.has_drift:
            self._refuse_drift_free(state)
        try:      # as given first (see FramePositionTask.write)
            _k.frame_rows(*hot[1], x, _ZERO3 if xd is None else xd,
                          _ZERO3 if xdd is None else xdd, rotation,
                          _ZERO3 if angular_velocity is None else angular_velocity,
                          _ZERO3 if angular_acceleration is None else angular_acceleration)
        except CoreInputError:
            name = self.name
            self._frame(state, _vec3(x, name, "x"), _vec3(xd, name, "xd"),
                        _vec3(xdd, name, "xdd"), _rotation(rotation, name),
                        _vec3(angular_velocity, name, "ω*"),
                        _vec3(angular_acceleration, name, "ω̇*"))
        self.stamp = writer._stamp

    def compiled_op(self, step):
        """Its frame op; the reference ``(x, rotation, xd=None, angular_velocity=None)``."""
        ref = step.frame(self)
        name = self.name

        def reference(x, rotation, xd=None, angular_velocity=None) -> None:
            step.put(ref, 0, x, _SHAPE3, name, "x")
            step.put(ref, 6, rotation, _SHAPE33, name, "rotation")
            step.put(ref, 3, xd, _SHAPE3, name, "xd")
            step.put(ref, 15, angular_velocity, _SHAPE3, name, "angular_velocity")
        return reference

    @classmethod
    def baseline_reference(cls, library, targets, step, context):
        if library != "tsid":
            return super().baseline_reference(library, targets, step, context)
        return (targets[1], *_rates([x[:3, 3] for x in targets],
                                    [x[:3, :3] for x in targets], step))

    @classmethod
    def baseline_target(cls, library, task, target, context) -> None:
        if library == "placo":
            task.T_world_frame = np.asarray(target)
        elif library == "pink":
            task.set_target(pin.SE3(np.asarray(target)))
        elif library == "mink":
            import mink
            task.set_target(mink.SE3.from_matrix(np.asarray(target)))
        else:
            super().baseline_target(library, task, target, context)


@register_task_kind
class ContactTask(FramePoseTask):
    """A support contact: the frame's pose held at a placement (6 rows, zero reference
    velocity and acceleration; with gains ``ẍ = −K_d ẋ + K_p e``).

    Written with ``write(state, placement=None, *, translation=None, rotation=None)``
    (a ``pin.SE3``, or its translation and rotation without building one). Baselines as
    :class:`FramePoseTask`.
    """

    kind = "contact"

    def write(self, state, placement=None, *, translation=None, rotation=None) -> None:
        """The rows at ``state`` holding the frame at ``placement``."""
        if placement is not None:
            translation, rotation = placement.translation, placement.rotation
        hot = self.hot
        if hot is None or hot[0] is not state.data:
            hot = self._frame_args(state)
        writer = self.writer
        if writer._accel and not state.has_drift:
            self._refuse_drift_free(state)
        try:      # as given first (see FramePositionTask.write)
            _k.frame_rows(*hot[1], translation, _ZERO3, _ZERO3, rotation, _ZERO3, _ZERO3)
        except CoreInputError:
            name = self.name
            self._frame(state, _vec(translation, 3, name, "translation"),
                        _ZERO3, _ZERO3, _rotation(rotation, name), _ZERO3, _ZERO3,
                        _CONTACT_ARGUMENTS)
        self.stamp = writer._stamp

    def compiled_op(self, step):
        """Its frame op; the reference ``(placement=None, *, translation=None,
        rotation=None)`` as :meth:`write`'s."""
        ref = step.frame(self)
        name = self.name

        def reference(placement=None, *, translation=None, rotation=None) -> None:
            if placement is not None:
                translation, rotation = placement.translation, placement.rotation
            step.put(ref, 0, translation, _SHAPE3, name, "translation")
            step.put(ref, 6, rotation, _SHAPE33, name, "rotation")
        return reference
