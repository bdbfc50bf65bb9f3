"""The base of every error prioik raises.

``except prioik.PrioikError`` catches whatever the library refuses or fails at, and
nothing else (a bug in the caller's own code, a ``KeyboardInterrupt``). Each subclass
also keeps its builtin base (``FormulationError`` is a ``ValueError``,
``MissingExtraError`` an ``ImportError``, ...), so ``except ValueError`` still works.
The table of docs/usage.md ("Errors") says when each is raised.

Subclasses (defined where they are raised), with their builtin base:

* :class:`prioik.hierarchy.TaskStackError` (``ValueError``): a malformed task, level or
  stack, a robot task writer's bad gain or reference or unwritten task; names the task
  and level. Its :class:`prioik.hierarchy.UnsupportedTaskError`: a task a formulation
  cannot take.
* :class:`UnknownNameError` (``KeyError``): a task, frame, joint or extra not there.
* :class:`prioik.formulations.FormulationError` (``ValueError``): a formulation that
  cannot be used as asked; its :class:`prioik.formulations.base.CoreInputError`: an
  array the compiled core cannot take.
* :class:`prioik.formulations.ConcurrentUseError` (``RuntimeError``): a prepared solver
  called from a second thread during a solve.
* :class:`prioik.extras.MissingExtraError` (``ImportError``): an extra not installed.
* :class:`prioik.robots.StateError` (``ValueError``): an unusable ``q`` or ``v``.
* :class:`prioik.robots.models.ModelNotFoundError` (``FileNotFoundError``) and
  :class:`prioik.robots.models.RobotModelError` (``ValueError``): a robot model that
  cannot be found, or built as asked.
* :class:`prioik.robots.simulate.SimulationError` (``ValueError``): a simulation,
  scenario or saved run that cannot run or be read as asked.
* :class:`prioik.robots.mujoco_model.MujocoModelError` (``ValueError``): a URDF MuJoCo
  cannot load, or a MuJoCo model that does not match the robot;
  :class:`prioik.robots.mesh_replay.MeshReplayError` (``ValueError``): meshes that
  cannot be read, or malformed trajectories given to the meshed replay.
* :class:`prioik.benchmarks.sweep.config.SweepConfigError` (``ValueError``): a sweep
  file that cannot run; :class:`prioik.benchmarks.tsid_baseline.TsidError`
  (``RuntimeError``): the TSID baseline's process refused a scenario or stopped.
"""

from __future__ import annotations

__all__ = ["PrioikError", "UnknownNameError"]


class PrioikError(Exception):
    """The base of every error prioik raises (see :mod:`prioik.errors` for the list).

    Catch it to handle any refusal or failure of the library in one place; each
    subclass is also an instance of its builtin base (``ValueError``, ``RuntimeError``,
    ``ImportError`` or ``FileNotFoundError``) and names what is at fault in its message.
    """


class UnknownNameError(PrioikError, KeyError):
    """A name that is not there: a task of a stack or layout, a robot's frame or joint,
    an extra, a scenario's baseline task. A :class:`KeyError` (so ``except KeyError``
    still works); its message names what was asked and where it was looked for, and
    reads as written (no quotes added, as :class:`KeyError` adds)."""

    __str__ = Exception.__str__
