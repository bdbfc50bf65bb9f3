"""Joint-space task kinds: posture, damping, and joint limits (activation rows or bounds).

Their rows are unit rows on the actuated joints' velocity coordinates (rows ``n_base:``)
— every coordinate for damping — written once; per step the compiled
``prioik._core.rows`` writers fill the posture error, the activation rows or the bounds.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from prioik._core import rows as _k
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import Task, TaskStackError

from ..rows import (
    _F64,
    _NDARRAY,
    _T,
    JointLimitActivation,
    RobotTask,
    _positive,
    _refused,
    _vec,
    register_task_kind,
)

__all__ = ["DampingTask", "JointLimitsTask", "PostureTask"]


@register_task_kind
class PostureTask(RobotTask):
    """The actuated joints (velocity rows ``n_base:``) to a reference configuration:
    ``n_v − n_base`` unit rows, no drift.

    Written with ``write(state, q_ref)`` (``n_q``): error ``q_ref ⊖ q`` (``q_ref − q``
    where every actuated joint has one coordinate; pinocchio's ``difference``
    otherwise). Baselines: PlaCo's joints task, pink's and mink's posture task (of cost
    ``context["posture_cost"]``); the target ``q``.
    """

    kind = "posture"

    def __init__(self, name: str = "posture", *, gain=None, level=None, weight=1.0,
                 keep=False) -> None:
        super().__init__(name, gain=gain, level=level, weight=weight, keep=keep)

    def declare(self, writer) -> int:
        return writer.robot.nv - writer.robot.n_base

    def prepare(self, writer, start: int) -> None:
        writer._data.A[start:start + self.rows, writer.robot.n_base:] = np.eye(self.rows)

    def write(self, state, q_ref) -> None:
        """The posture error at ``state`` for ``q_ref``."""
        w = self.writer
        if w is None or w._layout is None:
            w = self._unwritable()
        if not (q_ref.__class__ is _NDARRAY and q_ref.dtype is _F64
                and q_ref.shape == w._q_shape):
            q_ref = _vec(q_ref, w._nq, self.name, "q_ref")
        if w._posture_q is not None:
            try:
                _k.posture_error(w._Q, self.start, state.q, q_ref, w._posture_q)
            except CoreInputError as exc:
                raise _refused(self, exc) from None
        else:
            if not np.isfinite(q_ref).all():
                bad = int(np.flatnonzero(~np.isfinite(q_ref))[0])
                raise TaskStackError(f"q_ref[{bad}] is not finite ({q_ref[bad]})",
                                     task=self.name, level=self.level)
            robot = w.robot
            sl = slice(self.start, self.start + self.rows)
            w.error[sl] = pin.difference(robot.model, state.q, q_ref)[robot.n_base:]
            w.velocity_ref[sl] = 0.0
            w.feedforward[sl] = 0.0
            w.drift[sl] = 0.0
        self.stamp = w._stamp

    def compiled_op(self, step):
        """Its posture op (a robot whose actuated joints have one coordinate each); the
        reference ``(q_ref)`` (``n_q``)."""
        ref = step.posture(self)
        name, shape = self.name, (self.writer.robot.nq,)

        def reference(q_ref) -> None:
            step.put(ref, 0, q_ref, shape, name, "q_ref")
        return reference

    def _term_of(self, w, state):
        term = super()._term_of(w, state)
        if term.drift is None:
            term.drift = np.zeros(term.J.shape[0])     # a posture has no drift at all
        return term

    @classmethod
    def baseline_task(cls, library, spec, target, context):
        if library == "placo":
            task = context["solver"].add_joints_task()
            cls._placo_joints(task, target, context)
            task.configure(spec.name, context["priority"], spec.weight)
            task.q_ref = np.array(target, dtype=float)
            return task
        if library == "tsid":
            return "posture"
        if library == "pink":
            from pink.tasks import PostureTask as PinkPostureTask
            return PinkPostureTask(cost=context["cost"])
        if library == "mink":
            import mink
            return mink.PostureTask(context["model"], cost=context["cost"],
                                    gain=context["gain"])
        return super().baseline_task(library, spec, target, context)

    @classmethod
    def baseline_cost(cls, spec, context) -> float:
        """``context["posture_cost"]``, whatever the priority and weight."""
        return context["posture_cost"]

    @classmethod
    def baseline_reference(cls, library, targets, step, context):
        if library != "tsid":
            return super().baseline_reference(library, targets, step, context)
        model = context["model"]
        d01 = pin.difference(model, targets[0], targets[1])
        d12 = pin.difference(model, targets[1], targets[2])
        return targets[1], (d01 + d12) / (2 * step), (d12 - d01) / step ** 2

    @staticmethod
    def _placo_joints(task, q_ref, context) -> None:
        model = context["robot"].model
        q_ref = np.asarray(q_ref)
        task.set_joints({n: float(q_ref[model.joints[model.getJointId(n)].idx_q])
                         for n in context["joint_names"]})

    @classmethod
    def baseline_target(cls, library, task, target, context) -> None:
        if library == "placo":
            if not np.array_equal(task.q_ref, target):      # (a fixed posture: no call)
                cls._placo_joints(task, target, context)
                task.q_ref = np.array(target, dtype=float)
        elif library == "pink":
            task.set_target(np.asarray(target))
        elif library == "mink":
            task.set_target(context["to_qpos"](target))
        else:
            super().baseline_target(library, task, target, context)


@register_task_kind
class DampingTask(RobotTask):
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
        name: The task's name.
        weight: ``λ²`` (``(m/rad)²`` against a position task: ``λ`` is the singular
            value below which the level is damped), finite and > 0.
        level: As :class:`~robots.rows.RobotTask`.

    The rows are constant (written once, when the layout is fixed): no write per step
    (:meth:`write` does nothing).
    """

    kind = "damping"
    has_gain = False
    no_gain_reason = "a damping task has no gain (its weight is λ²)"

    def __init__(self, name: str = "damping", *, weight: float, level=None) -> None:
        if not (np.isscalar(weight) and not isinstance(weight, (str, bool))
                and np.isfinite(weight) and weight > 0):
            raise TaskStackError(f"damping weight must be finite and > 0, got {weight!r}",
                                 task=name if isinstance(name, str) else None)
        super().__init__(name, level=level, weight=weight)

    def declare(self, writer) -> int:
        return writer.robot.nv

    def prepare(self, writer, start: int) -> None:
        writer._data.A[start:start + self.rows] = np.eye(self.rows)   # the base's too
        self.keep, self.stamp = True, 0           # (written here, once for good)

    def write(self, state) -> None:
        """Nothing: the rows are constant."""

    def compiled_op(self, step):
        """Nothing per step (constant rows); no reference."""
        return None


@register_task_kind
class JointLimitsTask(RobotTask):
    """Joint limits of the actuated joints, one row per joint.

    Args:
        name: The task's name.
        form: ``"activation"`` — equality rows pushing a joint out of its margin
            (:class:`~robots.rows.JointLimitActivation`; position limits only), masked
            to zero rows while outside; ``"bounds"`` — an inequality task.
        position: The bounds hold the position limits.
        velocity: The bounds hold the velocity limits.
        horizon: Bounds: at velocity level ``q + q̇ T`` stays within the position
            limits for ``T = horizon`` (default ``dt``); at acceleration level the
            constant-acceleration position at ``T`` does (required).
        dt: The control step (required for the bounds; see
            :func:`robots.tasks.joint_limit_bounds`).
        activation: Parameters of the activation rows (defaults if omitted).
        level: As :class:`~robots.rows.RobotTask`.
        weight: As :class:`~robots.rows.RobotTask`.
        keep: As :class:`~robots.rows.RobotTask`.

    Written with ``write(state)``: returns how many activation rows are active, or the
    row count (bounds). No baseline counterpart (the libraries impose their own limits).
    """

    kind = "joint_limits"
    has_gain = False
    no_gain_reason = "joint-limit gains are set by its JointLimitActivation"

    def __init__(self, name: str = "joint_limits", *, form: str, level=None,
                 position: bool = True, velocity: bool = True,
                 horizon: float | None = None, dt: float | None = None,
                 activation: JointLimitActivation | None = None, weight=1.0,
                 keep=False) -> None:
        super().__init__(name, level=level, weight=weight, keep=keep)
        if form not in ("activation", "bounds"):
            raise TaskStackError(f"form must be 'activation' or 'bounds', got {form!r}",
                                 task=name)
        self.form = form
        self.inequality = form == "bounds"
        self.activation = activation or JointLimitActivation()
        self.position, self.velocity = bool(position), bool(velocity)
        self.horizon_given = horizon
        self.dt = dt
        if form == "bounds":
            if not (position or velocity):
                raise TaskStackError("bounds need position or velocity limits", task=name)
            if not _positive(dt):
                raise TaskStackError(f"joint-limit bounds need dt > 0, got {dt!r}",
                                     task=name)
            T = dt if horizon is None else horizon
            if not _positive(T):
                raise TaskStackError(f"horizon must be > 0, got {horizon!r}", task=name)
            self.horizon, self.dt = float(T), float(dt)

    def key(self) -> tuple:
        return (self.form, self.activation, self.position, self.velocity, self.dt,
                self.horizon_given)

    def declare(self, writer) -> int:
        lo, hi, vmax = writer._joint_limits()
        if self.form == "activation":
            params = self.activation
            self.push = (params.kp, params.kd) if writer._accel else (params.k, 0.0)
            with np.errstate(invalid="ignore"):
                width = np.where(np.isfinite(lo) & np.isfinite(hi),
                                 np.minimum(params.margin, 0.25 * (hi - lo)), 1.0)
            limits = np.vstack([lo, hi, width])
        else:
            if self.horizon_given is None and writer._accel and self.position:
                raise TaskStackError("acceleration-level bounds need a horizon",
                                     task=self.name)
            limits = np.vstack([lo, hi, vmax])
        self.limits = np.ascontiguousarray(limits, dtype=np.float64)
        self.limits.setflags(write=False)
        return lo.size

    def prepare(self, writer, start: int) -> None:
        nb = writer.robot.n_base
        if self.form == "activation":
            params = [start, nb, *self.push]
        else:
            params = [start, self.horizon, self.dt, self.position, self.velocity,
                      writer._accel]
            writer._data.A[start:start + self.rows, nb:] = np.eye(self.rows)   # constant
        self.bound_params = np.array(params, dtype=np.float64)
        self.bound_params.setflags(write=False)

    def write(self, state) -> int:
        """The rows at ``state``: activation rows (returns how many are active) or
        bounds (``data.lower``/``upper``; returns the row count)."""
        w = self.writer
        if w is None or w._layout is None:
            w = self._unwritable()
        data = w._data
        if self.inequality:
            _k.bounds_at(data.lower, data.upper, state.q, state.v, w._q_index,
                         self.limits, self.bound_params, w._qa)
            self.stamp = w._stamp
            return self.rows
        active = _k.activation_at(data.A, w._Q, state.q, w._q_index, self.limits,
                                  self.bound_params, w._qa)
        self.stamp = w._stamp
        return active

    def compiled_op(self, step):
        """Its joint-limit op (bounds or activation rows); no reference."""
        step.limits(self)
        return None

    def _term_of(self, w, state):
        """Bounds: the bounds task; activation rows: the active rows as a task (``None``
        when no joint is inside its margin)."""
        if self.inequality:
            return super()._term_of(w, state)
        A, b = w.targets(state).rows(_T)
        rows = np.flatnonzero(A.any(axis=1))
        if rows.size == 0:
            return None
        return Task(self.name, A[rows], b[rows])
