"""One set of robot task writers: robot state → rows of a :class:`~prioik.hierarchy.StackData`.

A robot task is an object of one task kind (a :class:`RobotTask` subclass: frame
position, point, orientation, pose, contact, centre of mass, posture, damping, joint
limits, frame and CoM regions; :mod:`robots.kinds`). A :class:`TaskWriter` is declared
once — its tasks, their priority levels, gains and weights
(``writer.add(FramePoseTask("left_foot", "left_foot", gain=10.0, level=3))``, or its
shorthand ``writer.add_frame_pose("left_foot", "left_foot", level=3, gain=10.0)``) —
which fixes ``writer.layout`` (a :class:`~prioik.hierarchy.StackLayout`) and
``writer.data`` (its preallocated :class:`~prioik.hierarchy.StackData`). At every step
each task writes its rows in place from a :class:`~robots.tasks.KinematicState`
(``task.write(state, ...)``, or by name ``writer.frame_pose(state, "left_foot", ...)``):
the Jacobian rows ``J`` into ``data.A`` and, per row, the error ``e = x* − x``, the
reference velocity ``ẋ*``, the feed-forward ``ẍ*`` and the drift ``J̇ q̇``;
:meth:`TaskWriter.targets` then forms every equality target in one pass:

* ``mode="velocity"``: ``b = ẋ* + K e`` (``J q̇ = ẋ* + K e``; no drift is computed, so a
  ``KinematicState(drift=False)`` suffices), scaled down to ``‖b‖ = max_rate`` for a
  task declared with a ``max_rate`` that it exceeds;
* ``mode="acceleration"``: ``b = ẍ* + K_d (ẋ* − J q̇) + K_p e − J̇ q̇`` (eq. 2-4).

Task kinds are registered by name (:func:`register_task_kind`, :data:`TASK_KINDS`): the
writer, the one-off terms (:meth:`RobotTask.term`) and the PlaCo, pink and mink baselines
find a kind there, so a new kind is its class (registered) and nothing else.

The built-in kinds write through the compiled row writers (``prioik._core.rows``, C++:
``core/src/rows.cpp``) on views of the state's ``pin.Data`` — the world-frame joint
Jacobians ``data.J`` (a frame's LOCAL_WORLD_ALIGNED Jacobian is formed from them),
``data.oMf``, ``data.Jcom``, ``data.com[0]``, and for the drifts the joints' spatial
velocities and accelerations at ``q̈ = 0`` ``data.v``, ``data.a`` and ``data.acom[0]`` —
taken once per ``Data``. ``tests/test_rows.py`` checks the writers against independent
pinocchio/numpy formulas and ``tests/test_tasks.py`` every kind's Jacobian and drift
against finite differences.
"""

from __future__ import annotations

import copy
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from prioik._core import rows as _k
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import StackData, StackLayout, Task, TaskStackError

from .models import RobotModel, StateError

__all__ = ["MODES", "TASK_KINDS", "JointLimitActivation", "RobotTask", "TaskTerm",
           "TaskWriter", "register_task_kind", "task_kind"]


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
class TaskTerm:
    """One task's kinematics at one state (:meth:`RobotTask.term`).

    For one task ``x = f(q)``: its Jacobian ``J`` (``ẋ = J q̇``), the drift ``J̇ q̇``,
    the error ``e = x* − x``, the rate error ``ė = ẋ* − ẋ`` and the feed-forward ``ẍ*``.

    Attributes:
        name: Task name (unique in a stack).
        J: Task Jacobian (``m × n``).
        drift: ``J̇ q̇`` (``m``), or ``None`` when built from a
            ``KinematicState(drift=False)`` (then only :meth:`velocity` applies).
        error: ``e = x* − x`` (``m``).
        rate_error: ``ė = ẋ* − ẋ`` (``m``).
        feedforward: ``ẍ*`` (``m``).
        velocity_ref: ``ẋ*`` (``m``).
    """

    name: str
    J: np.ndarray
    drift: np.ndarray | None
    error: np.ndarray
    rate_error: np.ndarray
    feedforward: np.ndarray
    velocity_ref: np.ndarray

    def acceleration(self, kp: float, kd: float, weight=1.0) -> Task:
        """``J θ̈ = ẍ* + K_d ė + K_p e − J̇ θ̇`` (eq. 2-4).

        Raises:
            TaskStackError: the term has no drift (built with ``drift=False``), or a gain
                negative or not finite; naming the task.
        """
        if self.drift is None:
            raise TaskStackError("it was built from a KinematicState(drift=False): an "
                                 "acceleration task needs J̇q̇ (build the state with "
                                 "drift=True, or use .velocity(k))", task=self.name)
        _check_gain(self.name, "kp", kp)
        _check_gain(self.name, "kd", kd)
        h = self.feedforward + kd * self.rate_error + kp * self.error - self.drift
        return Task(self.name, self.J, h, weight=weight)

    def velocity(self, k: float, weight=1.0) -> Task:
        """``J q̇ = ẋ* + K e`` (velocity-level closed-loop inverse kinematics).

        Raises:
            TaskStackError: ``k`` negative or not finite, naming the task.
        """
        _check_gain(self.name, "k", k)
        return Task(self.name, self.J, self.velocity_ref + k * self.error, weight=weight)

    def select(self, rows) -> TaskTerm:
        """The term restricted to some rows (e.g. the horizontal axes)."""
        idx = list(rows)
        return TaskTerm(self.name, self.J[idx],
                        None if self.drift is None else self.drift[idx], self.error[idx],
                        self.rate_error[idx], self.feedforward[idx], self.velocity_ref[idx])


def _check_gain(task: str, what: str, gain) -> None:
    """Refuses a gain (a number, or one per row) that is not finite and ≥ 0, naming the
    task and the gain."""
    if isinstance(gain, (int, float)) and not isinstance(gain, bool):
        ok = math.isfinite(gain) and gain >= 0          # the common case, at once
    else:
        try:
            g = np.asarray(gain, dtype=np.float64)
            ok = (not isinstance(gain, (bool, str, bytes)) and g.ndim <= 1
                  and bool(np.isfinite(g).all() and (g >= 0).all()))
        except (TypeError, ValueError):
            ok = False
    if not ok:
        raise TaskStackError(f"gain {what} must be a finite number ≥ 0 (or one per row), "
                             f"got {gain!r}", task=task)


# ------------------------------------------------------------------ task kinds
TASK_KINDS: dict[str, type[RobotTask]] = {}
"""The registered task kinds: name (``RobotTask.kind``) → class
(:func:`register_task_kind`; the built-in kinds of :mod:`robots.kinds` register on
import)."""


def register_task_kind(cls: type[RobotTask]) -> type[RobotTask]:
    """Register a :class:`RobotTask` subclass under its ``kind`` (a class decorator);
    returns the class. The writer's :meth:`TaskWriter.write`, the one-off
    :meth:`RobotTask.term` and the baselines (:meth:`RobotTask.baseline_task`) then take
    it, and scenarios name it in their :class:`~robots.scenario.BaselineTask` records.

    Raises:
        TaskStackError: ``cls`` is not a :class:`RobotTask` subclass, its ``kind`` is
            not a non-empty identifier, or another class has that kind.
    """
    if not (isinstance(cls, type) and issubclass(cls, RobotTask)):
        raise TaskStackError(f"a task kind is a RobotTask subclass, got {cls!r}")
    kind = cls.kind
    if not (isinstance(kind, str) and kind.isidentifier()):
        raise TaskStackError(f"{cls.__name__}.kind must be an identifier, got {kind!r}")
    known = TASK_KINDS.get(kind)
    if known is not None and known is not cls:
        raise TaskStackError(f"task kind {kind!r} is already {known.__name__}")
    TASK_KINDS[kind] = cls
    return cls


def task_kind(kind: str) -> type[RobotTask]:
    """The registered class of task kind ``kind``.

    Raises:
        TaskStackError: no such kind (naming the registered ones).
    """
    cls = TASK_KINDS.get(kind)
    if cls is None:
        raise TaskStackError(f"no task kind {kind!r} (registered: "
                             f"{', '.join(sorted(TASK_KINDS))})")
    return cls


class RobotTask:
    """Base of the robot task kinds: one task, declared once, written every step.

    A task knows its rows (:attr:`rows`, fixed when a :class:`TaskWriter` takes it with
    :meth:`TaskWriter.add`), writes them in place (:meth:`write`: ``J`` into the writer's
    ``data.A`` and the per-row quantities, or bounds for an inequality kind), gives its
    one-off term (:meth:`term`) and maps itself onto the external libraries' tasks
    (:meth:`baseline_task`, :meth:`baseline_target`).

    Args:
        name: The task's name (unique in its writer).
        gain: ``K`` at velocity level, ``(K_p, K_d)`` at acceleration level, finite and
            ≥ 0 (kinds without a gain take none).
        level: Its priority, 0 the highest; ``None``: a new level below every level so
            far in its writer.
        weight: Its weight within its level (finite, > 0; its rows of
            ``data.sqrt_weight`` hold ``√weight``).
        keep: Keep its last rows on a step where it is not written
            (:meth:`TaskWriter.targets`).
        max_rate: Velocity level, kinds with ``capped``: ``‖ẋ* + K e‖`` capped at it.

    A subclass sets ``kind`` (its registry name and the :class:`TaskWriter` method that
    writes it by name), ``inequality`` and ``has_gain``, and implements
    :meth:`declare` (validates what depends on the robot and mode; returns the row
    count), :meth:`prepare` (once the layout is fixed: constant rows, the compiled
    writers' arguments) and :meth:`write` (fills its rows of :meth:`ready_writer`, then
    :meth:`mark_written`); :func:`register_task_kind` registers it.

    Attributes:
        name, level, weight, keep: As declared (``level`` an int once added).
        rows: Its row count (once added).
        start: Its first row in the writer's data (once the layout is fixed).
        kp, kd: Its gains (``kp`` is ``K`` at velocity level).
        writer: The :class:`TaskWriter` that holds it (``None`` before :meth:`TaskWriter.add`).
    """

    #: registry name; the :class:`TaskWriter` method writing it by name is the same
    kind: ClassVar[str] = ""
    #: an inequality task (bounds in ``data.lower``/``upper``)
    inequality: ClassVar[bool] = False
    #: declared with a ``gain`` (else why not, for :meth:`TaskWriter.set_gains`)
    has_gain: ClassVar[bool] = True
    no_gain_reason: ClassVar[str] = "it has no gain"
    #: takes ``max_rate`` at velocity level
    capped: ClassVar[bool] = False
    #: a ``hard`` baseline task of this kind is an equality constraint where the library
    #: has them (mink)
    hard_is_constraint: ClassVar[bool] = False
    #: the :class:`TaskWriter` method writing it by name (default: ``kind``)
    written_by: ClassVar[str] = ""

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if "written_by" not in cls.__dict__:
            cls.written_by = cls.kind

    def __init__(self, name: str, *, gain=None, level: int | None = None,
                 weight: float = 1.0, keep: bool = False, max_rate: float | None = None
                 ) -> None:
        if not isinstance(name, str) or not name:
            raise TaskStackError(f"a task name must be a non-empty string, got {name!r}")
        if max_rate is not None and not self.capped:
            raise TaskStackError(f"a {self.kind} task takes no max_rate", task=name)
        self.name = name
        self.gain = gain
        self.level = level
        self.weight = weight
        self.keep = keep
        self.max_rate = max_rate
        self.rows = 0
        self.start = -1
        self.kp = 0.0
        self.kd = 0.0
        self.cap = 0.0                 # the validated max_rate (0: no cap)
        self.stamp = -1                # the writer's targets() count at its last write
        self.writer: TaskWriter | None = None
        self.hot: tuple | None = None  # the compiled writer's arguments per pin.Data

    # ------------------------------------------------------------- the contract
    def declare(self, writer: TaskWriter) -> int:  # pragma: no cover - abstract
        """Validate what depends on ``writer`` (its robot, mode); returns the row count
        (called by :meth:`TaskWriter.add`)."""
        raise NotImplementedError

    def prepare(self, writer: TaskWriter, start: int) -> None:
        """Once the layout is fixed (``start``: the task's first row): constant rows, the
        compiled writers' arguments (called by the writer; default nothing)."""

    def write(self, state, *references) -> None:  # pragma: no cover - abstract
        """Write the task's rows at ``state`` (a :class:`~robots.tasks.KinematicState`)
        for its ``references``."""
        raise NotImplementedError

    def compiled_op(self, step):
        """Add the task to a :class:`~robots.control_step.ControlStep`'s compiled step
        (``step``: its :class:`~robots.control_step.StepBuilder`) and return the setter of
        its reference (what :meth:`ControlStep.reference` calls with the task's
        reference), or ``None`` for a task that takes none. A kind without a compiled op
        keeps this default.

        Raises:
            TaskStackError: the kind has no compiled op (naming it and the task).
        """
        raise TaskStackError(f"a {self.kind} task has no compiled op: ControlStep cannot "
                             "run it (write its rows in the writer loop instead)",
                             task=self.name)

    def _detach(self) -> None:
        """Give a copy of the task (:meth:`term`'s one-task writer holds one) its own
        copy of what its writes change (default: nothing; declared arrays are
        replaced, never written)."""

    def key(self) -> tuple:
        """What the rows depend on besides the state and references (frame, offset,
        axes, ...): tasks of one kind and key share a one-off writer (:meth:`term`)."""
        return ()

    # ----------------------------------------------------------------- one-off
    def term(self, state, *references, mode: str | None = None) -> TaskTerm | Task | None:
        """The task's one-off term at ``state``: its rows written by a one-task
        :class:`TaskWriter` of the task's kind and key (kept per thread) and copied out.

        Args:
            state: A :class:`~robots.tasks.KinematicState`.
            references: What :meth:`write` takes after the state.
            mode: The writer's level (default: ``"acceleration"`` with a drift state,
                else ``"velocity"``).

        Returns:
            An equality kind: a :class:`TaskTerm` (``J``, ``J̇q̇``, ``e``, ``ė``, ``ẍ*``,
            ``ẋ*``; gains apply with :meth:`TaskTerm.velocity` /
            :meth:`TaskTerm.acceleration`); an inequality kind: a
            :class:`~prioik.hierarchy.Task` with its bounds.

        Raises:
            TaskStackError: what the writer refuses, naming this task.
        """
        w = _one_task_writer(self, state, mode)
        try:
            w._tasks[_T].write(state, *references)
        except TaskStackError as exc:
            if exc.task != _T:
                raise
            raise TaskStackError(exc.reason, task=self.name, **exc.detail) from None
        return self._term_of(w, state)

    def _term_of(self, w: TaskWriter, state):
        """The one-task writer ``w``'s rows as this task's term (see :meth:`term`)."""
        sl = w.layout.task_slice(_T)
        if self.inequality:
            A, lower, upper = w.data.bounds(_T)
            return Task(self.name, A, lower=lower, upper=upper)
        J = w.data.A[sl].copy()
        vref = w.velocity_ref[sl].copy()
        drift = w.drift[sl].copy() if w.mode == "acceleration" else None
        return TaskTerm(self.name, J, drift, w.error[sl].copy(), vref - J @ state.v,
                        w.feedforward[sl].copy(), vref)

    # ---------------------------------------------------------------- baselines
    @classmethod
    def baseline_task(cls, library: str, spec, target, context: dict):
        """The task ``spec`` (a :class:`~robots.scenario.BaselineTask` of this kind) as
        ``library``'s task (``"placo"``, ``"pink"``, ``"mink"``), at ``target``
        (:meth:`~robots.scenario.Scenario.baseline_target` at 0).

        Args:
            library: The external library.
            spec: The scenario's record.
            target: Its first target.
            context: What the baseline gives: ``"solver"`` (PlaCo's
                ``KinematicsSolver``), ``"robot_wrapper"``, ``"cost"`` (pink, mink: the
                spec's cost), ``"model"`` (mink's MuJoCo model), ``"gain"`` (mink),
                ``"robot"`` (the :class:`~robots.models.RobotModel`).

        Returns:
            ``library``'s task object; for ``"tsid"`` (whose runner runs in its own
            process) the runner's task kind (:data:`prioik.benchmarks.tsid_runner.KINDS`).

        Raises:
            TaskStackError: the kind does not map onto ``library``.
        """
        raise TaskStackError(f"a {cls.kind} task has no {library} counterpart",
                             task=spec.name)

    @classmethod
    def baseline_cost(cls, spec, context: dict) -> float:
        """The cost of task ``spec`` in a library without priorities (pink, mink; TSID's
        weights are its square): ``context["level_costs"]`` at the spec's priority (the
        last beyond them) times its weight."""
        costs = context["level_costs"]
        return costs[min(spec.priority, len(costs) - 1)] * spec.weight

    @classmethod
    def baseline_target(cls, library: str, task, target, context: dict) -> None:
        """Give ``library``'s ``task`` (from :meth:`baseline_task`) the new ``target``."""
        raise TaskStackError(f"a {cls.kind} task has no {library} counterpart")

    @classmethod
    def baseline_reference(cls, library: str, targets, step: float, context: dict
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x*, ẋ*, ẍ*)`` as ``library`` takes them (TSID's runner:
        :mod:`prioik.benchmarks.tsid_runner`), from the targets at ``t − step``, ``t``,
        ``t + step`` (central differences); ``context`` gives ``"model"`` (pinocchio).

        Raises:
            TaskStackError: the kind does not map onto ``library``.
        """
        raise TaskStackError(f"a {cls.kind} task has no {library} counterpart")

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r}, level={self.level!r})"

    # ------------------------------------------------------------------ helpers
    def _refuse_drift_free(self, state) -> None:
        """Refuses a drift-free state at acceleration level (a kind with a drift)."""
        raise TaskStackError("an acceleration-level writer needs J̇q̇, but the "
                             "KinematicState was built with drift=False", task=self.name)

    def ready_writer(self) -> TaskWriter:
        """The task's writer, its layout fixed (what :meth:`write` writes into: its
        ``data``, ``error``, ``velocity_ref``, ``feedforward``, ``drift`` at rows
        ``start:start + rows``).

        Raises:
            TaskStackError: the task is in no writer.
        """
        return self._unwritable()

    def mark_written(self) -> None:
        """Record the task as written this step (:meth:`write` ends with it;
        :meth:`TaskWriter.targets` refuses a task not written since its last call)."""
        self.stamp = self.writer._stamp

    def _unwritable(self) -> TaskWriter:
        """The task's writer, its layout fixed (refusing a task in none)."""
        w = self.writer
        if w is None:
            raise TaskStackError("the task is in no TaskWriter: add it first "
                                 "(TaskWriter.add)", task=self.name)
        if w._layout is None:
            w._fix()
        return w


def _positive(value) -> bool:
    """Whether ``value`` is a finite number > 0 (not a bool)."""
    return (isinstance(value, (int, float, np.integer, np.floating))
            and not isinstance(value, bool) and bool(np.isfinite(value)) and value > 0)


class TaskWriter:
    """Robot task writers over one :class:`~prioik.hierarchy.StackData`.

    Args:
        robot: The robot (its ``n_v`` is the layout's width).
        mode: ``"velocity"`` (``J q̇ = ẋ* + K e``) or ``"acceleration"`` (eq. 2-4).
        hard: The levels declared hard (``layout.hard``; :func:`~prioik.hierarchy.hard`):
            a solution that leaves one violated is ``"failed"``, naming it and its
            tasks (e.g. ``hard=(0,)`` for support contacts that must hold). Checked
            against the declared levels when the layout is fixed.

    Declare tasks with :meth:`add` (a :class:`RobotTask` of any registered kind) or the
    ``add_*`` shorthands of the built-in kinds (each takes ``level``: the priority, 0 the
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

    Per step: each task written — ``task.write(state, ...)``, ``writer.write(state, name,
    ...)`` or the kind's named method (``writer.frame_pose(state, name, ...)``) — then
    :meth:`targets`, which refuses a task not written since the last call unless it was
    declared with ``keep=True``. A writer refuses a reference that is not finite (naming
    the task and the argument) before writing anything, and at acceleration level a
    ``KinematicState(drift=False)`` for tasks that have a drift (frames, CoM).

    A writer writes into its one :class:`~prioik.hierarchy.StackData`: use it from one
    thread at a time (one writer per thread; the one-off terms keep one per thread).

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
        self._tasks: dict[str, RobotTask] = {}
        self._layout: StackLayout | None = None
        self._data: StackData | None = None
        self._Q = np.zeros((6, 0))
        self._views: _DataViews | None = None
        self._last_level = -1
        self._capped: tuple = ()                # (start, stop, max_rate) per capped task
        self._stamp = 0                         # targets() calls so far
        self._order: tuple[RobotTask, ...] = ()     # the tasks (once the layout is fixed)
        q_index = robot.actuated_q_index()
        self._q_index = q_index
        #: q entries of the actuated joints when q_ref ⊖ q is q_ref − q for all of them
        self._posture_q = q_index if np.all(q_index >= 0) else None
        self._limits = None                     # (lo, hi, vmax) of the actuated joints
        self._nq = robot.nq
        self._q_shape = (robot.nq,)
        self._qa = np.zeros(robot.nv - robot.n_base)

    # ----------------------------------------------------------------- declaring
    def add(self, task: RobotTask) -> RobotTask:
        """Declare ``task`` (a :class:`RobotTask` of any kind); returns it (its
        :meth:`~RobotTask.write` then writes its rows).

        Raises:
            TaskStackError: the task's class is not a registered kind
                (:func:`register_task_kind`), the layout is fixed, the name taken, the
                task in another writer, or a declared value refused (the level, weight, keep, gain,
                max_rate, or what the kind checks), naming the task.
            KeyError: a frame the robot does not have.
        """
        if not isinstance(task, RobotTask):
            raise TaskStackError(f"a task is a RobotTask (a task kind's object), got "
                                 f"{task!r}")
        name = task.name
        if TASK_KINDS.get(task.kind) is not type(task):
            raise TaskStackError(f"{type(task).__name__} is not a registered task kind "
                                 "(register_task_kind)", task=name)
        if self._layout is not None:
            raise TaskStackError("the layout is fixed (it was read or written): declare "
                                 "every task before", task=name)
        if task.writer is not None:
            raise TaskStackError("the task is already in a TaskWriter", task=name)
        if name in self._tasks:
            raise TaskStackError("duplicate task name", task=name)
        level = task.level
        if level is None:
            level = self._last_level + 1
        if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or level < 0:
            raise TaskStackError(f"level must be an integer ≥ 0 or None, got {level!r}",
                                 task=name)
        weight = task.weight
        if not (isinstance(weight, (int, float, np.integer, np.floating))
                and not isinstance(weight, bool) and np.isfinite(weight) and weight > 0):
            raise TaskStackError(f"weight must be finite and > 0, got {weight!r}", task=name)
        if not isinstance(task.keep, (bool, np.bool_)):
            raise TaskStackError(f"keep must be True or False, got {task.keep!r}", task=name)
        cap = self._max_rate(name, task.max_rate)
        rows = int(task.declare(self))
        if task.has_gain:
            task.kp, task.kd = self._gains(name, task.gain)
        elif task.gain is not None:
            raise TaskStackError(f"a {task.kind} task takes no gain ({task.no_gain_reason})",
                                 task=name)
        task.level, task.weight, task.keep = int(level), float(weight), bool(task.keep)
        task.rows, task.cap, task.writer = rows, cap, self
        self._last_level = max(self._last_level, int(level))
        self._tasks[name] = task
        return task

    def _kind(self, kind: str) -> type[RobotTask]:
        return task_kind(kind)

    def add_frame_position(self, name: str, frame: str, *, gain, level: int | None = None,
                           weight: float = 1.0, max_rate: float | None = None,
                           keep: bool = False) -> None:
        """A frame origin's world position (3 rows; :class:`~robots.kinds.FramePositionTask`);
        ``max_rate`` (velocity level, m/s): the target's speed ``‖ẋ* + K e‖`` capped at it."""
        self.add(self._kind("frame_position")(name, frame, gain=gain, level=level,
                                              weight=weight, max_rate=max_rate, keep=keep))

    def add_point(self, name: str, frame: str, offset, *, gain, level: int | None = None,
                  weight: float = 1.0, max_rate: float | None = None,
                  keep: bool = False) -> None:
        """The world position of a point fixed on a frame (3 rows;
        :class:`~robots.kinds.PointTask`), ``offset`` in the frame's coordinates (e.g. a
        tool tip; no extra frame is added to the model); ``max_rate`` as in
        :meth:`add_frame_position`."""
        self.add(self._kind("point")(name, frame, offset, gain=gain, level=level,
                                     weight=weight, max_rate=max_rate, keep=keep))

    def add_frame_orientation(self, name: str, frame: str, *, gain,
                              level: int | None = None, weight: float = 1.0,
                              max_rate: float | None = None, keep: bool = False) -> None:
        """A frame's orientation (3 rows, world axes; error ``log(R* Rᵀ)``;
        :class:`~robots.kinds.FrameOrientationTask`); ``max_rate`` (velocity level,
        rad/s): the target's angular speed capped at it."""
        self.add(self._kind("frame_orientation")(name, frame, gain=gain, level=level,
                                                 weight=weight, max_rate=max_rate,
                                                 keep=keep))

    def add_frame_pose(self, name: str, frame: str, *, gain, level: int | None = None,
                       weight: float = 1.0, keep: bool = False) -> None:
        """A frame's position (rows 0-2) and orientation (rows 3-5;
        :class:`~robots.kinds.FramePoseTask`)."""
        self.add(self._kind("frame_pose")(name, frame, gain=gain, level=level,
                                          weight=weight, keep=keep))

    def add_contact(self, name: str, frame: str, *, gain, level: int | None = None,
                    weight: float = 1.0, keep: bool = False) -> None:
        """A support contact: the frame's pose held at a placement (6 rows, zero reference
        velocity and acceleration; :class:`~robots.kinds.ContactTask`); write it with
        :meth:`contact`."""
        self.add(self._kind("contact")(name, frame, gain=gain, level=level, weight=weight,
                                       keep=keep))

    def add_com(self, name: str = "com", *, gain, axes: Sequence[int] = (0, 1),
                level: int | None = None, weight: float = 1.0,
                max_rate: float | None = None, keep: bool = False) -> None:
        """The centre of mass on world ``axes`` (default horizontal; eq. 32-33;
        :class:`~robots.kinds.ComTask`); ``max_rate`` as in :meth:`add_frame_position`."""
        self.add(self._kind("com")(name, gain=gain, axes=axes, level=level, weight=weight,
                                   max_rate=max_rate, keep=keep))

    def add_posture(self, name: str = "posture", *, gain, level: int | None = None,
                    weight: float = 1.0, keep: bool = False) -> None:
        """The actuated joints (velocity rows ``n_base:``) to a reference configuration
        (:class:`~robots.kinds.PostureTask`)."""
        self.add(self._kind("posture")(name, gain=gain, level=level, weight=weight,
                                       keep=keep))

    def add_damping(self, name: str = "damping", *, weight: float,
                    level: int | None = None) -> None:
        """Damping of a level (:class:`~robots.kinds.DampingTask`): ``q̇ = 0`` (``q̈ = 0``)
        on every coordinate, of weight ``weight = λ²`` within its level: the level's
        damped least squares. The rows are constant (written once): no writer call per
        step."""
        self.add(self._kind("damping")(name, weight=weight, level=level))

    def add_joint_limits(self, name: str = "joint_limits", *, form: str,
                         level: int | None = None, position: bool = True,
                         velocity: bool = True, horizon: float | None = None,
                         dt: float | None = None,
                         activation: JointLimitActivation | None = None,
                         weight: float = 1.0, keep: bool = False) -> None:
        """Joint limits of the actuated joints, one row per joint
        (:class:`~robots.kinds.JointLimitsTask`: ``form`` ``"activation"`` or
        ``"bounds"``, and the other arguments)."""
        self.add(self._kind("joint_limits")(name, form=form, level=level, position=position,
                                            velocity=velocity, horizon=horizon, dt=dt,
                                            activation=activation, weight=weight,
                                            keep=keep))

    def add_frame_region(self, name: str, frame: str, normals, lower=None, upper=None, *,
                         dt: float, horizon: float | None = None, offset=None,
                         level: int | None = None, weight: float = 1.0,
                         keep: bool = False) -> None:
        """Keep a point of a frame inside a region ``lower ≤ C p ≤ upper`` (an inequality
        task, one row per row of ``C``; :class:`~robots.kinds.FrameRegionTask`)."""
        self.add(self._kind("frame_region")(name, frame, normals, lower, upper, dt=dt,
                                            horizon=horizon, offset=offset, level=level,
                                            weight=weight, keep=keep))

    def add_com_region(self, name: str, normals, lower=None, upper=None, *, dt: float,
                       horizon: float | None = None, level: int | None = None,
                       weight: float = 1.0, keep: bool = False) -> None:
        """Keep the centre of mass inside a region ``lower ≤ C c ≤ upper`` (e.g. over
        the support polygon, :func:`~robots.tasks.polygon_region`;
        :class:`~robots.kinds.ComRegionTask`)."""
        self.add(self._kind("com_region")(name, normals, lower, upper, dt=dt,
                                          horizon=horizon, level=level, weight=weight,
                                          keep=keep))

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
        levels: dict[int, list[RobotTask]] = {}
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
        for task in self._tasks.values():
            sl = self._layout.task_slice(task.name)
            task.start = sl.start
            data.sqrt_weight[sl] = np.sqrt(task.weight)
            self._Q[_k.KP, sl] = task.kp
            self._Q[_k.KD, sl] = task.kd
            task.prepare(self, sl.start)
        self._capped = tuple((t.start, t.start + t.rows, t.cap)
                             for t in self._tasks.values() if t.cap > 0)
        self._order = tuple(self._tasks.values())

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
        if not task.has_gain:
            raise TaskStackError(task.no_gain_reason, task=name)
        task.kp, task.kd = self._gains(name, gain)
        task.gain = gain
        if self._layout is not None:
            sl = slice(task.start, task.start + task.rows)
            self.kp[sl] = task.kp
            self.kd[sl] = task.kd

    def tasks(self) -> tuple[str, ...]:
        """The declared tasks' names, in declaration order."""
        return tuple(self._tasks)

    def task(self, name: str) -> RobotTask:
        """The declared task ``name``.

        Raises:
            TaskStackError: no such task (naming the declared ones).
        """
        return self._task(name, None, fix=False)

    def __contains__(self, name: str) -> bool:
        return name in self._tasks

    # ------------------------------------------------------------------ writers
    def write(self, state, name: str, *references) -> Any:
        """Write task ``name`` (any kind) at ``state``: its :meth:`RobotTask.write`."""
        return self._task(name, None).write(state, *references)

    def frame_position(self, state, name: str, x, xd=None, xdd=None) -> None:
        """A frame origin's (or a point's, :meth:`add_point`) position: ``x*`` and its
        rates ``ẋ*``, ``ẍ*`` (zero if omitted)."""
        task = self._tasks.get(name)
        if task is None or task.written_by != "frame_position":
            task = self._task(name, "frame_position")
        task.write(state, x, xd, xdd)

    point = frame_position

    def frame_orientation(self, state, name: str, rotation, angular_velocity=None,
                          angular_acceleration=None) -> None:
        """A frame's orientation: target ``R*`` (3×3), ``ω*``, ``ω̇*`` (world; zero if
        omitted)."""
        self._task(name, "frame_orientation").write(state, rotation, angular_velocity,
                                                    angular_acceleration)

    def frame_pose(self, state, name: str, x, rotation, xd=None, xdd=None,
                   angular_velocity=None, angular_acceleration=None) -> None:
        """A frame's pose: position ``x*`` (rates ``ẋ*``, ``ẍ*``) and rotation ``R*``
        (rates ``ω*``, ``ω̇*``); omitted rates are zero."""
        task = self._tasks.get(name)
        if task is None or task.written_by != "frame_pose":
            task = self._task(name, "frame_pose")
        task.write(state, x, rotation, xd, xdd, angular_velocity, angular_acceleration)

    def contact(self, state, name: str, placement: pin.SE3 | None = None, *,
                translation=None, rotation=None) -> None:
        """A contact held at ``placement`` (or ``translation`` and ``rotation``: the same
        without building an SE3), zero reference velocity and acceleration."""
        task = self._tasks.get(name)
        if task is None or task.written_by != "contact":
            task = self._task(name, "contact")
        task.write(state, placement, translation=translation, rotation=rotation)

    def com(self, state, name: str, x, xd=None, xdd=None) -> None:
        """The centre of mass: ``x*``, ``ẋ*``, ``ẍ*`` given on the task's axes."""
        task = self._tasks.get(name)
        if task is None or task.written_by != "com":
            task = self._task(name, "com")
        task.write(state, x, xd, xdd)

    def posture(self, state, name: str, q_ref) -> None:
        """The actuated joints to ``q_ref`` (``n_q``): error ``q_ref ⊖ q`` on rows
        ``n_base:`` of the velocity (``q_ref − q`` where every actuated joint has one
        coordinate; pinocchio's ``difference`` otherwise), no drift."""
        task = self._tasks.get(name)
        if task is None or task.written_by != "posture":
            task = self._task(name, "posture")
        task.write(state, q_ref)

    def joint_limits(self, state, name: str = "joint_limits") -> int:
        """The joint-limit rows at ``state``: activation rows (returns how many are
        active) or bounds (``data.lower``/``upper``; returns the row count)."""
        task = self._tasks.get(name)
        if task is None or task.written_by != "joint_limits":
            task = self._task(name, "joint_limits")
        return task.write(state)

    def frame_region(self, state, name: str, normals=None, lower=None, upper=None) -> None:
        """A frame point's region rows at ``state`` (:meth:`add_frame_region`): the rows
        ``C J`` into ``data.A`` and their bounds into ``data.lower``/``upper``.
        ``normals``, ``lower``, ``upper`` given here replace the declared ones from this
        step on (a region that moves with the robot's supports); the row count stays."""
        self._task(name, "frame_region").write(state, normals, lower, upper)

    def com_region(self, state, name: str, normals=None, lower=None, upper=None) -> None:
        """The centre of mass's region rows at ``state`` (:meth:`add_com_region`); the
        arguments as in :meth:`frame_region`."""
        self._task(name, "com_region").write(state, normals, lower, upper)

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
        stamp = self._stamp
        for task in self._order:
            if task.stamp != stamp and (task.stamp < 0 or not task.keep):
                self._refuse_unwritten()
        self._stamp = stamp + 1
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
        stamp = self._stamp
        for task in self._order:
            if task.stamp != stamp and (task.stamp < 0 or not task.keep):
                self._refuse_unwritten()
        self._stamp = stamp + 1
        _k.acceleration_targets(data.A, data.b, self._Q, v)
        return data

    def _refuse_unwritten(self) -> None:
        """Refuses targets while a task has not been written since the last targets
        (a task declared with ``keep=True``: not written at all), naming them."""
        stamp = self._stamp
        stale = [t for t in self._order if t.stamp != stamp and (t.stamp < 0 or not t.keep)]
        first = stale[0]
        raise TaskStackError(
            f"not written {'yet' if first.stamp < 0 else 'since the last targets()'}"
            f" (unwritten: {', '.join(t.name for t in stale)}); call its writer "
            f"({first.written_by}) every step before targets(), or declare it with "
            "keep=True to keep its last rows", task=first.name, level=first.level)

    # ------------------------------------------------------------------ helpers
    def _task(self, name: str, kind: str | None, fix: bool = True) -> RobotTask:
        """The declared task ``name`` (written by the writer method ``kind`` when given);
        fixes the layout."""
        task = self._tasks.get(name)
        if task is None:
            raise TaskStackError(f"no task {name!r} declared (tasks: "
                                 f"{', '.join(self._tasks) or 'none'})")
        if kind is not None and task.written_by != kind:
            raise TaskStackError(f"task {name!r} was declared as {task.kind}, not {kind}",
                                 task=name)
        if fix and self._layout is None:
            self._fix()
        return task

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


# ------------------------------------------------------- one-task writers, per thread
_LOCAL = threading.local()
_MAX_WRITERS = 256      # per thread; the cache is cleared beyond (a term is one-off)
_T = "task"             # the one task's name inside a one-off writer


def _one_task_writer(task: RobotTask, state, mode: str | None) -> TaskWriter:
    """The thread's one-task writer of ``state``'s robot for ``task``'s kind and key
    (a copy of ``task`` with zero gains, declared on first use); ``mode`` defaults to
    what the state allows (acceleration with drift, else velocity)."""
    cache = getattr(_LOCAL, "writers", None)
    if cache is None:
        cache = _LOCAL.writers = {}
    if mode is None:
        mode = "acceleration" if state.has_drift else "velocity"
    robot = state.robot
    full = (id(robot), mode, type(task), task.key())
    entry = cache.get(full)
    if entry is None or entry[0] is not robot:
        if len(cache) >= _MAX_WRITERS:
            cache.clear()
        w = TaskWriter(robot, mode)
        one = copy.copy(task)
        one.name, one.level, one.weight, one.keep, one.max_rate = _T, 0, 1.0, False, None
        one.writer, one.hot, one.stamp, one.start = None, None, -1, -1
        one._detach()
        if one.has_gain:
            one.gain = (0.0, 0.0) if mode == "acceleration" else 0.0
        try:
            w.add(one)
        except TaskStackError as exc:
            if exc.task != _T:
                raise
            raise TaskStackError(exc.reason, task=task.name, **exc.detail) from None
        _ = w.layout                       # (the layout built once, here)
        entry = cache[full] = (robot, w)
    return entry[1]


# ------------------------------------------------------------- references, checked
_ZERO3 = np.zeros(3)                     # never written
_F64 = np.dtype(np.float64)
_NDARRAY = np.ndarray
_ZEROS: dict[int, np.ndarray] = {}        # m -> zeros(m), never written
_SHAPE3 = (3,)
_SHAPE33 = (3, 3)

#: the compiled writers' names of the writers' arguments, where they differ
_ARGUMENTS = {"Rstar": "rotation", "w": "angular_velocity", "wd": "angular_acceleration"}


def _refused(task: RobotTask, exc: CoreInputError, names: dict = _ARGUMENTS) -> Exception:
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
