"""A scenario with pink (``pin-pink``) — the Python IK library most pinocchio users start with.

pink solves, each control step, one weighted least-squares QP for the velocity
``v = Δq / dt``: every task is a cost ``‖cost ∘ (J Δq + gain·e)‖²`` (dead-beat at
``gain = 1``), plus pink's own :class:`~pink.limits.ConfigurationLimit` (joint position
limits over the step, with its ``config_limit_gain``) and
:class:`~pink.limits.VelocityLimit` (``|v| ≤ v_max``) as QP inequalities. There are no
priorities: the scenario's hierarchy becomes cost weights, one decade per level
(:data:`LEVEL_COSTS`), from :meth:`robots.scenario.Scenario.baseline_tasks`, each task
mapped by its kind (:meth:`prioik.robots.RobotTask.baseline_task`):

* ``frame_pose`` → ``FrameTask(frame, position_cost=c, orientation_cost=c)``;
* ``frame_position`` → ``FrameTask(frame, position_cost=c, orientation_cost=0)``;
* ``frame_orientation`` → ``FrameTask(frame, position_cost=0, orientation_cost=c)``;
* ``com`` (horizontal) → ``ComTask(cost=[c, c, 0])``;
* ``posture`` → ``PostureTask(cost=POSTURE_COST)``.

Targets are the scenario's references at ``t + dt``. The QP back-end is a qpsolvers
name (:data:`DEFAULT_SOLVER` — the one pink's examples use — or any in
``qpsolvers.available_solvers``). pink works on a copy of the robot's model (it
attaches its limit objects to the model).
"""

from __future__ import annotations

import time

import numpy as np

#: cost of a task by its level in the scenario (0 = highest)
LEVEL_COSTS = (100.0, 10.0, 1.0, 0.1, 0.01)
POSTURE_COST = 1e-3
#: pink's examples pick quadprog when it is installed
DEFAULT_SOLVER = "quadprog"

#: the baseline's name in the scenario reports (:data:`prioik.benchmarks.variants.BASELINES`)
NAME = "pink"
DESCRIPTION = ("pink's solve_ik at velocity level: every task a weighted cost (one decade "
               "per level), its ConfigurationLimit and VelocityLimit; QP back-end "
               f"{DEFAULT_SOLVER} (pink's examples' choice)")
#: the level the library solves at (the scenario pages' baseline table)
LEVEL = "velocity"


def profile() -> dict:
    """What the scenario pages say of this baseline (see
    :func:`prioik.benchmarks.placo_baseline.profile`)."""
    from .external import distribution_version
    return {"library": f"pink {distribution_version('pin-pink')}", "level": LEVEL,
            "priorities": f"weights: one QP, one decade of cost per level "
                          f"({', '.join(f'{c:g}' for c in LEVEL_COSTS)}; posture "
                          f"{POSTURE_COST:g})",
            "given": f"QP back-end {DEFAULT_SOLVER} (qpsolvers; a daqp row beside it), task "
                     "gains 1 (dead-beat), ConfigurationLimit and VelocityLimit"}


def unavailable_reason(options: dict | None = None) -> str | None:
    """Why pink cannot run here with ``options`` (its ``solver``), or ``None``."""
    try:
        import pink  # noqa: F401
    except ImportError as exc:
        return f"pink is not installed ({exc}); install it with `pip install pin-pink==4.4.0`"
    solver = (options or {}).get("solver", DEFAULT_SOLVER)
    import qpsolvers
    if solver not in qpsolvers.available_solvers:
        return f"QP back-end {solver} is not available here"
    return None


def steps(scenario, variant, *, duration: float, dt: float, progress=None):
    """A scenario run of ``variant`` (:class:`prioik.benchmarks.variants.Variant`), one
    step at a time (:func:`pink_steps`)."""
    return pink_steps(scenario, duration=duration, dt=dt, progress=progress,
                      solver=variant.options.get("solver", DEFAULT_SOLVER),
                      label=variant.label)


def run_pink(scenario, *, duration: float, dt: float, solver: str = DEFAULT_SOLVER,
             progress=None, label: str = "pink"):
    """Run ``scenario`` with pink's ``solve_ik``; returns a :class:`robots.SimulationResult`
    (:func:`pink_steps` to its end)."""
    from prioik.robots import run_to_end
    return run_to_end(pink_steps(scenario, duration=duration, dt=dt, solver=solver,
                                 progress=progress, label=label))


def pink_steps(scenario, *, duration: float, dt: float, solver: str = DEFAULT_SOLVER,
               progress=None, label: str = "pink"):
    """``scenario`` with pink's ``solve_ik``, set up now and run one step at a time: a
    generator that yields after each step and returns the
    :class:`robots.SimulationResult` (:func:`prioik.benchmarks.external.record_steps`).

    Raises:
        ValueError: ``solver`` is not a QP back-end qpsolvers has here.
    """
    import pinocchio as pin
    import qpsolvers
    from pink import Configuration, solve_ik
    from pink.exceptions import PinkError
    from pink.limits import ConfigurationLimit, VelocityLimit

    from prioik.benchmarks.external import record_steps
    from prioik.robots import task_kind

    if solver not in qpsolvers.available_solvers:
        raise ValueError(f"pink: QP back-end {solver!r} is not available here; available: "
                         f"{', '.join(qpsolvers.available_solvers)}")
    robot = scenario.robot
    model = robot.model.copy()
    data = model.createData()
    tasks, setters = [], []
    context = {"robot": robot, "level_costs": LEVEL_COSTS, "posture_cost": POSTURE_COST}
    for spec in scenario.baseline_tasks():
        kind = task_kind(spec.kind)             # the kind maps itself onto pink's task
        context["cost"] = kind.baseline_cost(spec, context)
        task = kind.baseline_task("pink", spec, scenario.baseline_target(spec.name, 0.0),
                                  context)
        tasks.append(task)
        setters.append((spec, kind, task))
    limits = [ConfigurationLimit(model), VelocityLimit(model)]
    config = Configuration(model, data, robot.q0.copy())

    def step(q, v, t):
        t0 = time.perf_counter()
        config.update(q)
        for spec, kind, task in setters:
            kind.baseline_target("pink", task, scenario.baseline_target(spec.name, t + dt),
                                 context)
        t1 = time.perf_counter()
        try:
            vel = solve_ik(config, tasks, dt, solver=solver, limits=limits,
                           safety_break=False)
        except PinkError as exc:
            raise RuntimeError(f"{type(exc).__name__}: {exc}") from None
        t2 = time.perf_counter()
        return pin.integrate(model, q, vel * dt), np.asarray(vel), t1 - t0, t2 - t1

    return record_steps(scenario, step, duration=duration, dt=dt, progress=progress,
                        label=label, info={"qp_solver": solver})
