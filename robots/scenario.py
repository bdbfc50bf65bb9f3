"""The scenario interface shared by ``prioik fencing`` and ``prioik arm``.

A scenario builds its robot and references once and, at each step, the task stack and
the errors to record. Everything that runs a scenario — :func:`robots.simulate` with
any formulation, the PlaCo, pink and mink baselines, the replay — goes through these
members only:

* ``name``, ``variants``, ``variant``, ``robot``, ``default_duration``;
* :meth:`Scenario.terms` (the task terms at a state: references and Jacobians) and
  :meth:`Scenario.errors` (the errors to record, name → value); ``summary_errors``,
  the recorded errors whose maxima summarise a run beside the tip's final error, and
  ``tip_label``, what the tip is (for figure labels);
* :meth:`Scenario.acceleration_stack` / :meth:`Scenario.velocity_stack` — the step's
  :class:`~robots.simulate.StepTasks` (stack + errors), with joint limits as
  ``"activation"`` rows, ``"bounds"`` (inequality rows at the scenario's level for
  them) or ``"hard_bounds"`` (the same bounds as the *first* level: the form SNS
  takes, see :mod:`prioik.formulations.sns`);
* :meth:`Scenario.step_builder` — the ``build(state, t)`` a simulation calls: one of
  the two above, or the scenario's own faster path (the fencing scenario writes its
  rows in place);
* :meth:`Scenario.baseline_tasks` and :meth:`Scenario.baseline_target` — the same
  tasks as declarative records for the external IK libraries (PlaCo, pink, mink): each
  record names a registered task kind, whose class builds the library's task;
* :meth:`Scenario.markers` — world points to draw in the replay (targets, references),
  and ``tip_frame``, the frame whose path the replay traces;
* :meth:`Scenario.urdf_text` — the robot's URDF as the baselines must load it (with
  the scenario's extra frames and locked joints), and ``info()`` to rebuild the
  scenario from a saved run (:func:`robots.scenarios.make`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .models import RobotModel
from .simulate import SimulationError, StepTasks
from .tasks import KinematicState

__all__ = ["BaselineTask", "Scenario"]

LIMIT_FORMS_ACCELERATION = ("activation", "bounds", "hard_bounds")
LIMIT_FORMS_VELOCITY = ("none", "bounds", "hard_bounds")


@dataclass(frozen=True)
class BaselineTask:
    """One task as an external IK library sees it.

    Attributes:
        name: The scenario's task name.
        kind: A registered task kind (:data:`~robots.rows.TASK_KINDS`), whose class
            maps the task onto each library (:meth:`~robots.rows.RobotTask.baseline_task`):
            ``"frame_pose"`` (pose of ``frame``), ``"frame_position"`` (origin of
            ``frame``), ``"frame_orientation"`` (rotation of ``frame``), ``"com"``
            (horizontal centre of mass), ``"posture"``, or any other registered kind.
        frame: Frame name (``None`` for ``com`` and ``posture``).
        priority: The task's level in the scenario's stack (0 highest, limits excluded).
        hard: Whether a two-level library (PlaCo) makes it a hard constraint.
        weight: Its weight among the soft tasks.
    """

    name: str
    kind: str
    frame: str | None
    priority: int
    hard: bool = False
    weight: float = 1.0


class Scenario:
    """Base of the scenarios; see the module docstring for the contract."""

    name: ClassVar[str] = ""
    variants: ClassVar[tuple[str, ...]] = ()
    default_duration: ClassVar[float] = 3.0
    tip_frame: ClassVar[str] = ""
    #: what the tip is, in words (``"sword-tip"``, ``"tool"``)
    tip_label: ClassVar[str] = "tip"
    #: recorded errors (keys of :meth:`errors`) whose maxima summarise a run
    summary_errors: ClassVar[tuple[str, ...]] = ("joint_limit_violation_rad",)
    variant: str
    robot: RobotModel

    def terms(self, state: KinematicState, t: float) -> dict:  # pragma: no cover - abstract
        """The task terms (name → :class:`~robots.tasks.TaskTerm`) at ``(state, t)``."""
        raise NotImplementedError

    def errors(self, state: KinematicState, t: float, terms: dict
               ) -> dict[str, float]:  # pragma: no cover - abstract
        """The errors to record at ``(state, t)`` (``terms`` from :meth:`terms`); the
        final target's distance is ``"tip_error_m"``."""
        raise NotImplementedError

    def step_builder(self, level: str = "acceleration", limits: str | None = None,
                     dt: float = 0.002, gain: float = 10.0):
        """The ``build(state, t) -> StepTasks`` of a simulation at ``level``
        (``"acceleration"`` or ``"velocity"``, with ``gain`` ``K``) with the joint
        limits as ``limits`` (default: ``"activation"`` rows at acceleration level, none
        at velocity level): :meth:`acceleration_stack` or :meth:`velocity_stack`."""
        if limits is None:
            limits = "none" if level == "velocity" else "activation"
        if level == "velocity":
            return lambda state, t: self.velocity_stack(state, t, gain=gain, limits=limits,
                                                        dt=dt)
        if level != "acceleration":
            raise SimulationError(f"level must be 'acceleration' or 'velocity', got {level!r}")
        return lambda state, t: self.acceleration_stack(state, t, limits=limits, dt=dt)

    def acceleration_stack(self, state: KinematicState, t: float, limits: str = "activation",
                           dt: float = 0.002) -> StepTasks:  # pragma: no cover - abstract
        raise NotImplementedError

    def velocity_stack(self, state: KinematicState, t: float, gain: float = 10.0,
                       limits: str = "none", dt: float = 0.002
                       ) -> StepTasks:  # pragma: no cover - abstract
        raise NotImplementedError

    def baseline_tasks(self) -> list[BaselineTask]:  # pragma: no cover - abstract
        raise NotImplementedError

    def baseline_target(self, name: str, t: float):  # pragma: no cover - abstract
        """Target of baseline task ``name`` at ``t``: a 4×4 pose (``frame_pose``), a
        3-vector (``frame_position``), a 3×3 rotation (``frame_orientation``), a 2-vector
        (``com``) or ``q`` (``posture``): what the kind's
        :meth:`~robots.rows.RobotTask.baseline_target` takes."""
        raise NotImplementedError

    def markers(self, t: float) -> dict[str, np.ndarray]:  # pragma: no cover - abstract
        raise NotImplementedError

    def urdf_text(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def info(self) -> dict:
        """What :func:`robots.scenarios.make` needs to rebuild this scenario."""
        return {"scenario": self.name, "variant": self.variant, "robot": self.robot.name}

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(variant={self.variant!r}, robot={self.robot.name!r}, "
                f"n_v={self.robot.nv})")
