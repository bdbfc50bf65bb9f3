"""The fencing scenario with PlaCo's own ``KinematicsSolver`` — what users run today.

PlaCo solves, each control step, one weighted QP for a displacement ``Δq`` with
*hard* tasks as equality constraints, *soft* tasks as weighted costs, and joint
position and velocity limits as inequalities (``enable_joint_limits``,
``enable_velocity_limits``, with ``solver.dt``). It has two priority levels, so the
scenario's strict hierarchy is mapped to:

* hard: the support (right) foot frame task and the horizontal centre of mass;
* soft: the left foot frame (weight 1), the sword tip (weight 1) and the posture
  (joints task, weight 1e-4);
* joint and velocity limits: PlaCo's own inequality constraints.

Targets are the scenario's references at the next step, ``x*(t + dt)``; PlaCo drives
each task's error to zero within one step when it can (its tasks are displacement-
level, ``J Δq = x* − x``, i.e. the velocity task ``J q̇ = e / dt``). The sword tip is a
fixed link added to a copy of the G1 URDF (``sword_tip``, 0.5 m along
``left_rubber_hand``), loaded from text; no file is written.

The recorded quantities are those of :func:`robots.simulate`, computed with the
toolkit's own kinematics on PlaCo's configurations (:mod:`benchmarks.external`).
The same runner takes any :class:`robots.scenario.Scenario` (the arm scenario:
hard tool position, soft hand orientation and posture).
"""

from __future__ import annotations

import time

import numpy as np

#: the baseline's name in the scenario reports (:data:`prioik.benchmarks.variants.BASELINES`)
NAME = "placo_kinematics_solver"
DESCRIPTION = ("PlaCo's own KinematicsSolver at velocity level (hard tasks, soft weighted "
               "tasks, its joint and velocity limits): what users run today")
#: the level the library solves at (the scenario pages' baseline table)
LEVEL = "velocity"


def profile() -> dict:
    """What the scenario pages say of this baseline: ``library`` (with its version),
    ``level``, ``priorities`` (its priority model) and ``given`` (back-end, gains)."""
    from .external import distribution_version
    return {"library": f"PlaCo {distribution_version('placo')}", "level": LEVEL,
            "priorities": "two levels: hard tasks as equality constraints (support foot "
                          "and CoM; the arm's tool position), the others weighted",
            "given": "its KinematicsSolver's own QP, joint and velocity limits "
                     "(enable_joint_limits, enable_velocity_limits); displacement tasks "
                     "J Δq = x* − x (dead-beat)"}


def unavailable_reason(options: dict | None = None) -> str | None:
    """Why PlaCo cannot run here, or ``None``."""
    from prioik.extras import install_hint, missing_distributions
    if missing_distributions("placo"):
        return f"placo is not installed; {install_hint('placo')}"
    return None


def steps(scenario, variant, *, duration: float, dt: float, progress=None):
    """A scenario run of ``variant`` (:class:`prioik.benchmarks.variants.Variant`), one
    step at a time (:func:`placo_steps`)."""
    return placo_steps(scenario, duration=duration, dt=dt, progress=progress,
                       label=variant.label)


def run_placo(scenario, *, duration: float, dt: float, progress=None,
              label: str = "placo_kinematics_solver"):
    """Run the scenario with ``placo.KinematicsSolver``; returns a
    :class:`robots.SimulationResult` (:func:`placo_steps` to its end)."""
    from prioik.robots import run_to_end
    return run_to_end(placo_steps(scenario, duration=duration, dt=dt, progress=progress,
                                  label=label))


def placo_steps(scenario, *, duration: float, dt: float, progress=None,
                label: str = "placo_kinematics_solver"):
    """The scenario with ``placo.KinematicsSolver``, set up now and run one step at a
    time: a generator that yields after each step and returns the
    :class:`robots.SimulationResult` (:func:`prioik.benchmarks.external.record_steps`).

    The tasks come from :meth:`robots.scenario.Scenario.baseline_tasks` (``hard``
    ones as PlaCo hard tasks, the others soft with their ``weight``), each mapped by its
    task kind (:meth:`prioik.robots.RobotTask.baseline_task`), the URDF from
    :meth:`~robots.scenario.Scenario.urdf_text`. PlaCo always models a floating base;
    for a fixed-base robot it is masked (``mask_fbase(True)``) at the identity.

    Args:
        scenario: A :class:`robots.scenario.Scenario`.
        duration: Simulated seconds.
        dt: Control step (s).
        progress: Called with the simulated time every 250 steps.
    """
    import placo

    from prioik.benchmarks.external import record_steps
    from prioik.robots import task_kind
    from prioik.robots.models import example_robot_data_dir

    robot = scenario.robot
    # meshes are ``package://example-robot-data/...``: resolved from the share folder
    share = example_robot_data_dir().parent.parent
    pw = placo.RobotWrapper(str(share), placo.Flags.ignore_collisions, scenario.urdf_text())
    names = list(robot.model.names)[2 if robot.floating_base else 1:]
    if list(pw.joint_names()) != names:
        raise RuntimeError(f"PlaCo's joint order differs from pinocchio's for {robot.name}")
    nb_q = 0 if robot.floating_base else 7          # PlaCo's own base coordinates
    nb_v = 0 if robot.floating_base else 6

    def to_placo(q):
        if robot.floating_base:
            return q.copy()
        return np.concatenate([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], q])

    pw.state.q = to_placo(robot.q0)
    pw.update_kinematics()
    solver = placo.KinematicsSolver(pw)
    solver.mask_fbase(not robot.floating_base)
    solver.enable_joint_limits(True)
    solver.enable_velocity_limits(True)
    solver.dt = dt
    context = {"solver": solver, "robot_wrapper": pw, "robot": robot, "joint_names": names}
    setters = []
    for spec in scenario.baseline_tasks():
        kind = task_kind(spec.kind)             # the kind maps itself onto PlaCo's task
        context["priority"] = "hard" if spec.hard else "soft"
        task = kind.baseline_task("placo", spec, scenario.baseline_target(spec.name, 0.0),
                                  context)
        setters.append((spec, kind, task))

    def step(q, v, t):
        t0 = time.perf_counter()
        pw.update_kinematics()
        for spec, kind, task in setters:
            kind.baseline_target("placo", task, scenario.baseline_target(spec.name, t + dt),
                                 context)
        t1 = time.perf_counter()
        dq = np.array(solver.solve(True))           # raises RuntimeError when infeasible
        t2 = time.perf_counter()
        return np.array(pw.state.q)[nb_q:], dq[nb_v:] / dt, t1 - t0, t2 - t1

    return record_steps(scenario, step, duration=duration, dt=dt, progress=progress,
                        label=label)
