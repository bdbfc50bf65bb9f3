"""A prepared velocity-level control step: ``q ↦ q ⊕ q̇ dt`` in one compiled call.

:class:`ControlStep` runs the writer loop of :mod:`robots.rows` — the kinematics, every
task's rows, the targets ``b = ẋ* + K e``, the hierarchical active set, the integration
— with pinocchio as the kinematics authority and everything after it in C++
(``prioik._core.ControlStep``, ``core/src/control_step.cpp``)::

    step = ControlStep(rows, "hierarchical_active_set", dt=0.002)
    step.reference("hand", target)
    q = step(q)

Per step, Python calls ``pin.computeJointJacobians(model, data, q)`` (and
``pin.jacobianCenterOfMass(model, data, False)`` when a task reads the centre of mass),
then one C++ call reads views of ``data`` taken once (its storage is fixed at
creation): each frame's placement ``oMf = oMi[parent] · placement``, every task's rows
by the compiled row writers, the velocity targets with the ``max_rate`` caps, the
active set on the prepared solver's workspace (the warm start's equality-first try, the
active set, a cold re-solve after an ambiguous warm one) and, on a clean answer, the
integration (``q + q̇ dt`` for joints with ``n_q = n_v``, pinocchio's SE(3) exponential
for a free flyer; ``pin.integrate`` for any other joint).

A step whose kernel answer is not clean (capped, ambiguous, flagged, non-finite, of
extreme scale) is finished by the prepared solver's own code
(:meth:`~prioik.formulations.hierarchical_active_set.Prepared.answer`,
:meth:`~prioik.formulations.PreparedSolver._finished`): its status, diagnostics,
certificate, refinement, verification stage and hard-level check are those of
``PreparedSolver.solve`` on the same rows. So is every step of a solver prepared with
``verify="certificate"`` or ``"lower_point"``, and a clean step of a layout with hard
levels unless C++ finds each held with a factor 2 to spare (the check of
:func:`~prioik.hierarchy.hard_violations`).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pinocchio as pin

import prioik._core as _core
from prioik.formulations.base import ConcurrentUseError, CoreInputError, FormulationError, Status
from prioik.hierarchy import DEFAULT_CERTIFICATE_TOL, TaskStackError

from .models import StateError, check_configuration
from .rows import TaskWriter

__all__ = ["ControlStep", "StepBuilder"]

_NDARRAY = np.ndarray
_F64 = np.dtype(np.float64)
_CLEAN, _INFEASIBLE, _INVALID_STATE, _HARD_UNCLEAR = 1, 2, -3, 4
_clock = time.perf_counter
_OPTIMAL, _FAILED = Status.OPTIMAL, Status.FAILED


class StepBuilder:
    """What a task kind's :meth:`~robots.rows.RobotTask.compiled_op` adds its op with:
    the compiled step, the writer and the pinocchio ``Data`` whose views it reads."""

    def __init__(self, core, writer: TaskWriter, data: pin.Data) -> None:
        self.core = core
        self.writer = writer
        self.data = data
        self.needs_reference: list[str] = []

    def _frame_views(self, task) -> tuple:
        model = self.writer.robot.model
        joint = self.data.oMi[task.joint]
        placement = model.frames[task.fid].placement
        return (joint.translation, joint.rotation, np.array(placement.translation),
                np.array(placement.rotation))

    def frame(self, task) -> np.ndarray:
        """A frame task's op (rows.hpp's frame writers); returns its reference buffer
        (18: ``x``, ``ẋ*``, ``R*`` row-major, ``ω*``), needed before the first step."""
        index = self.core.add_frame(*self._frame_views(task), task.spec, task.geo,
                                    task.frame_mode == _core.rows.POSITION)
        self.needs_reference.append(task.name)
        return self.core.frame_reference(index)

    def com(self, task) -> np.ndarray:
        """A CoM task's op; returns its reference buffer (``x``, ``ẋ*`` on its axes)."""
        index = self.core.add_com(task.start, task.axes)
        self.needs_reference.append(task.name)
        return self.core.com_reference(index)

    def posture(self, task) -> np.ndarray:
        """A posture's op; returns its reference buffer (``q_ref``, ``n_q``).

        Raises:
            TaskStackError: an actuated joint has several coordinates (its error needs
                pinocchio's ``difference``: the writer loop writes it).
        """
        iq = self.writer._posture_q
        if iq is None:
            raise TaskStackError("a posture over joints of several coordinates has no "
                                 "compiled op (its error is pinocchio's difference): write "
                                 "it in the writer loop", task=task.name)
        index = self.core.add_posture(task.start, np.ascontiguousarray(iq, dtype=np.int64))
        self.needs_reference.append(task.name)
        return self.core.posture_reference(index)

    def limits(self, task) -> None:
        """A joint-limit task's op (bounds or activation rows)."""
        iq = self.writer._q_index
        if np.any(iq < 0):
            raise TaskStackError("joint limits over joints of several coordinates have no "
                                 "compiled op", task=task.name)
        self.core.add_limits(task.inequality, np.ascontiguousarray(iq, dtype=np.int64),
                             task.limits, task.bound_params)

    def region(self, task) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A region task's op (a frame region's point, or the centre of mass); returns
        its buffers ``C`` (flat, row-major), ``lower``, ``upper``."""
        reg = task.region
        frame = (None,) * 6
        if hasattr(task, "fid"):
            spec = np.array([0, _core.rows.POSITION, 1, *task.cols], dtype=np.int64)
            frame = (*self._frame_views(task), spec, task.geo)
        index = self.core.add_region(task.start, reg.C, reg.horizon, reg.dt, *frame)
        return self.core.region_reference(index)

    @staticmethod
    def put(buffer: np.ndarray, offset: int, value, shape: tuple, task: str, what: str
            ) -> None:
        """``value`` (of ``shape``: ``(m,)``, or ``(3, 3)`` for a rotation, copied row by
        row; ``None``: zeros) into ``buffer[offset:]``.

        Raises:
            TaskStackError: ``value`` of another shape, not numbers, or not finite
                (naming the task and the reference).
        """
        rows, cols = shape[0], shape[1] if len(shape) == 2 else -1
        if value is None:
            value = _zeros(shape)
        try:
            bad = _put(buffer, offset, value, rows, cols)
        except CoreInputError:
            try:
                given = np.array(value, dtype=np.float64)     # aligned, any strides
            except (TypeError, ValueError):
                raise TaskStackError(f"{what} must be numbers of shape {shape}, got "
                                     f"{value!r}", task=task) from None
            if given.shape != shape:
                raise TaskStackError(f"{what} must have shape {shape}, got {given.shape}",
                                     task=task) from None
            bad = _put(buffer, offset, given, rows, cols)
        if bad >= 0:
            flat = np.asarray(value, dtype=np.float64).reshape(-1)
            raise TaskStackError(f"{what}[{bad}] is not finite ({flat[bad]})", task=task)


_put = _core.put_reference
_ZERO_REFERENCES: dict[tuple, np.ndarray] = {}


def _zeros(shape: tuple) -> np.ndarray:
    """Zeros of ``shape`` (kept, never written)."""
    zeros = _ZERO_REFERENCES.get(shape)
    if zeros is None:
        zeros = _ZERO_REFERENCES[shape] = np.zeros(shape)
        zeros.setflags(write=False)
    return zeros


def _joint_segments(model) -> tuple[np.ndarray, bool]:
    """Per joint ``(idx_q, idx_v, n_q, n_v, free flyer)`` and whether C++ integrates
    every one (``n_q == n_v``, or a free flyer; none listed when it does not)."""
    rows, integrable = [], True
    for j in range(1, model.njoints):
        joint = model.joints[j]
        free = joint.shortname() == "JointModelFreeFlyer"
        if not free and joint.nq != joint.nv:
            integrable = False
        rows.append((joint.idx_q, joint.idx_v, joint.nq, joint.nv, int(free)))
    segments = np.array(rows if integrable else [], dtype=np.int64).reshape(-1, 5)
    return segments, integrable


class ControlStep:
    """A prepared velocity-level control step over a :class:`~robots.rows.TaskWriter`'s
    tasks: ``q_next = step(q)``.

    Args:
        writer: The tasks (a velocity-level writer; its layout is fixed here). The step
            writes its rows into ``writer.data`` (what :attr:`solution` was solved on).
        formulation: ``"hierarchical_active_set"`` (the one with a compiled step).
        dt: The step (s): ``q_next = q ⊕ q̇ dt``.
        verify: As :func:`prioik.prepare`.
        **options: The formulation's options (:func:`prioik.prepare`).

    References are kept until changed (:meth:`reference`, copied in); every task that
    takes one needs it before the first step.

    Each call returns the next configuration — a buffer of the step, overwritten by the
    next call (copy it to keep it); the caller's ``q`` is never written. When the
    status is ``optimal`` or ``approximate`` the step integrates ``q̇``; when it is
    ``failed`` it keeps ``q`` (``q_next = q``, :attr:`velocity` zero) — the answer, if
    any, is in :meth:`solution`.

    Use from one thread at a time (a call from another thread while one runs raises
    :class:`~prioik.formulations.ConcurrentUseError`); the prepared solver
    (:attr:`solver`) is the step's: use it only between steps.

    Attributes:
        writer: The writer.
        robot: Its robot.
        solver: The prepared :class:`~prioik.formulations.PreparedSolver`.
        data: The ``pin.Data`` of the last step (its joint placements and Jacobians at
            the last ``q``; its frame placements ``oMf`` are not updated).
        dt: The step.
        status: The last step's :class:`~prioik.formulations.Status`.

    Raises:
        TaskStackError: an acceleration-level writer, ``dt`` not finite and > 0, or a
            task of a kind without a compiled op (naming the kind and the task).
        FormulationError: another formulation, or an option refused.
    """

    def __init__(self, writer: TaskWriter, formulation: str = "hierarchical_active_set",
                 *, dt: float, verify: str = "auto", **options) -> None:
        import prioik
        if not isinstance(writer, TaskWriter):
            raise TaskStackError(f"a ControlStep takes a TaskWriter, got {writer!r}")
        if writer.mode != "velocity":
            raise TaskStackError("ControlStep is a velocity-level step (q ⊕ q̇ dt): an "
                                 "acceleration-level writer runs in the writer loop")
        if formulation != "hierarchical_active_set":
            raise FormulationError(f"ControlStep runs the compiled hierarchical_active_set, "
                                   f"not {formulation!r} (solve other formulations in the "
                                   "writer loop)")
        if not (isinstance(dt, (int, float)) and not isinstance(dt, bool)
                and math.isfinite(dt) and dt > 0):
            raise TaskStackError(f"dt must be finite and > 0, got {dt!r}")
        self.writer, self.robot, self.dt = writer, writer.robot, float(dt)
        layout = writer.layout
        self.solver = solver = prioik.prepare(layout, formulation, verify=verify, **options)
        self._impl = solver._impl
        model = self._model = self.robot.model
        self.data = data = model.createData()
        rows = writer.data
        self._unit = unit = self.robot.state_sizes()[3]
        segments, self._integrable = _joint_segments(model)
        self._core = core = _core.ControlStep(
            self._impl._cpp, rows.A, rows.b, rows.lower, rows.upper, rows.sqrt_weight,
            writer._Q, data.J, self.robot.nq, self.dt, unit, segments, self._integrable)
        kinds = {type(t).kind for t in writer._order}
        self._com = bool(kinds & {"com", "com_region"})
        if self._com:
            core.set_com(data.Jcom, data.com[0])
        builder = StepBuilder(core, writer, data)
        self._references = {t.name: t.compiled_op(builder) for t in writer._order}
        for start, stop, cap in writer._capped:
            core.add_cap(start, stop, cap)
        self._missing = set(builder.needs_reference)
        if layout.hard:        # a clean answer holding them clearly is the step's
            core.set_hard(np.asarray(layout.hard, dtype=np.int64), DEFAULT_CERTIFICATE_TOL)
        # the fast path: a clean kernel answer is the step's answer as it is
        self._fast = verify not in ("certificate", "lower_point")
        self._q_shape = (self.robot.nq,)
        self._q_next = core.q_next
        self._velocity = core.velocity
        self._zero_velocity = np.zeros(self.robot.nv)
        self._step = core.step
        self._jacobians = pin.computeJointJacobians
        self._com_jacobian = pin.jacobianCenterOfMass
        self._acquire, self._release = solver._acquire, solver._release
        self.status: Status | None = None
        self._solution = None
        self._code = 0
        self._solve_time = 0.0

    # --------------------------------------------------------------- references
    def reference(self, name: str, *values, **named) -> None:
        """Set task ``name``'s reference (copied in; kept until changed), as its
        writer method takes it: ``reference("hand", x)`` (or ``(x, xd)``),
        ``reference("foot", placement)`` (a contact), ``reference("posture", q_ref)``,
        a CoM's ``(x, xd=None)`` on its axes, a region's ``(normals=None, lower=None,
        upper=None)``.

        Raises:
            TaskStackError: no such task, a task that takes no reference, or a value of
                the wrong shape or not finite (naming the task).
        """
        setter = self._references.get(name, False)
        if setter is False:
            raise TaskStackError(f"no task {name!r} declared (tasks: "
                                 f"{', '.join(self._references)})")
        if setter is None:
            raise TaskStackError("it takes no reference (its rows follow the state)",
                                 task=name)
        try:
            setter(*values, **named)
        except TypeError as exc:
            raise TaskStackError(f"its reference is not {values!r} ({exc})",
                                 task=name) from None
        self._missing.discard(name)

    # --------------------------------------------------------------------- step
    def __call__(self, q) -> np.ndarray:
        """One control step from ``q`` (``n_q``, not written): returns ``q ⊕ q̇ dt`` (a
        buffer of the step; see the class doc).

        Raises:
            StateError: ``q`` of the wrong size, not finite, or a joint's quaternion not
                of unit norm (naming ``q``, the entry and the joint).
            TaskStackError: a task without its reference yet, or a value of the rows not
                valid (naming the task).
            ConcurrentUseError: another thread is in a step of this object.
        """
        if not self._acquire(False):
            raise ConcurrentUseError("this ControlStep is busy in another thread; build "
                                     "one step per thread")
        try:
            if self._missing:
                self._refuse_missing()
            if q.__class__ is not _NDARRAY or q.dtype is not _F64 or q.shape != self._q_shape:
                q = check_configuration(self.robot, q)        # StateError naming q
            self._jacobians(self._model, self.data, q)
            if self._com:
                self._com_jacobian(self._model, self.data, False)
            try:
                code = self._step(q)
            except CoreInputError:          # a strided or unaligned view: a plain copy
                q = np.array(q, dtype=np.float64, order="C")
                code = self._step(q)
            if code == _HARD_UNCLEAR:       # a clean answer, its hard levels checked here
                code = self._code = self._core.code
                return self._finish(code, q)
            self._code = code
            if (code == _CLEAN or code == _INFEASIBLE) and self._fast:
                self.status = _OPTIMAL
                self._solution = None
                if not self._integrable:      # a joint C++ does not integrate
                    self._q_next[:] = pin.integrate(self._model, q, self._velocity * self.dt)
                return self._q_next
            return self._finish(code, q)
        finally:
            self._release()

    def _refuse_missing(self) -> None:
        names = sorted(self._missing)
        raise TaskStackError(f"no reference yet (missing: {', '.join(names)}): call "
                             f"step.reference({names[0]!r}, ...) before the first step",
                             task=names[0])

    def _answer(self):
        """The solver's answer to the step's rows (its own finishing code)."""
        impl, core = self._impl, self._core
        t0 = _clock()
        out = impl.answer(self._code, core.equality_first, self.writer.data)
        return out, core.solve_time_s + (_clock() - t0)

    def _finish(self, code: int, q: np.ndarray) -> np.ndarray:
        """A step the fast path does not finish: the prepared solver's answer, its
        status, and the integration it decides."""
        if code == _INVALID_STATE:
            check_configuration(self.robot, q)           # raises, naming the entry
            raise StateError("q is not a valid configuration (a non-finite entry or a "
                             "quaternion not of unit norm)")
        solver, data = self.solver, self.writer.data
        out, elapsed = self._answer()
        sol = solver._finished(out, data, elapsed)
        if solver._hard and sol.status != _FAILED:
            solver._check_hard(sol, data)
        self._solution = sol
        self.status = sol.status
        if sol.status == _FAILED:
            self._velocity[:] = 0.0
            self._q_next[:] = q
            return self._q_next
        self._velocity[:] = sol.x
        if self._integrable:
            self._core.integrate(q, self._velocity, self._q_next)
        else:
            self._q_next[:] = pin.integrate(self._model, q, self._velocity * self.dt)
        return self._q_next

    # ------------------------------------------------------------------ results
    @property
    def velocity(self) -> np.ndarray:
        """``q̇`` of the last step (``n_v``; zero after a ``failed`` step): a view,
        overwritten by the next step."""
        return self._velocity

    def solution(self):
        """The last step's full :class:`~prioik.formulations.Solution` (built on first
        request after a clean step, from the solver's result: ask before using
        :attr:`solver` again).

        Raises:
            TaskStackError: no step yet.
        """
        if self._solution is None:
            if self.status is None:
                raise TaskStackError("no step yet: call the step first")
            out, elapsed = self._answer()
            self._solution = self.solver._finished(out, self.writer.data, elapsed)
        return self._solution

    def integrate(self, q, v) -> np.ndarray:
        """``q ⊕ v dt`` (a new array) as the step integrates it (C++ for joints with
        ``n_q = n_v`` and the free flyer, ``pin.integrate`` otherwise).

        Raises:
            StateError: ``q`` or ``v`` not valid (naming it).
        """
        from .models import check_velocity
        qc = check_configuration(self.robot, q)
        vc = check_velocity(self.robot, v)
        if not self._integrable:
            return np.asarray(pin.integrate(self._model, qc, vc * self.dt))
        out = np.empty_like(qc)
        self._core.integrate(qc, vc, out)
        return out

    def reset(self) -> None:
        """The next step's solve starts cold (:meth:`PreparedSolver.reset`)."""
        self.solver.reset()

    def __repr__(self) -> str:
        return (f"ControlStep({self.robot.name!r}, dt={self.dt}; "
                f"{self.writer.layout.describe()})")
