"""The base of every error prioik raises.

``except prioik.PrioikError`` catches whatever the library refuses or fails at, and
nothing else (a bug in the caller's own code, a ``KeyboardInterrupt``). Each subclass
also keeps the builtin base it had before (``FormulationError`` is a ``ValueError``,
``MissingExtraError`` an ``ImportError``, ...), so ``except ValueError`` still works.

Subclasses (defined where they are raised):

* :class:`prioik.hierarchy.TaskStackError` (``ValueError``) — a task, a level or a task
  stack is malformed (shapes, non-finite values, a negative or non-finite gain or a
  non-finite reference given to a robot task writer, a declared task not written before
  ``TaskWriter.targets``); it names the task and level;

  * :class:`prioik.hierarchy.UnsupportedTaskError` — a formulation cannot take a task
    (e.g. an inequality in a closed-form method);

* :class:`UnknownNameError` (``KeyError``) — a name that is not there (a task of a
  stack or layout, a robot's frame or joint, an extra);
* :class:`prioik.formulations.FormulationError` (``ValueError``) — a formulation cannot
  be used as asked (unknown name, not installed, an unknown or missing option);

  * :class:`prioik.formulations.base.CoreInputError` — an array the compiled core
    cannot take;

* :class:`prioik.formulations.ConcurrentUseError` (``RuntimeError``) — a prepared
  solver called from a second thread during a solve;
* :class:`prioik.extras.MissingExtraError` (``ImportError``) — a part needs an extra
  that is not installed;
* :class:`prioik.robots.StateError` (``ValueError``) — a robot state (``q``, ``v``) that
  cannot be used;
* :class:`prioik.robots.models.ModelNotFoundError` (``FileNotFoundError``) — a robot
  model that cannot be found;
* :class:`prioik.robots.models.RobotModelError` (``ValueError``) — a robot model that
  cannot be built or changed as asked (a URDF or SRDF that does not parse or contradicts
  itself, a bad ``q0``, an unknown robot name);
* :class:`prioik.robots.simulate.SimulationError` (``ValueError``) — a simulation or a
  scenario that cannot run as asked (duration, step, level, variant, limits), or a saved
  run that cannot be read or written;
* :class:`prioik.robots.mujoco_model.MujocoModelError` (``ValueError``) — a URDF MuJoCo
  cannot load, or a MuJoCo model that does not match the robot;
* :class:`prioik.benchmarks.sweep.config.SweepConfigError` (``ValueError``) — a sweep
  file that cannot run.
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
