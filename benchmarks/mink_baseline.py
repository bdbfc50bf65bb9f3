"""A scenario with mink — differential IK on MuJoCo, weighted tasks in one QP.

mink solves, each control step, one QP for the displacement ``Δq = v dt``: every task
a weighted cost ``‖cost ∘ (J Δq + gain·e)‖²`` (dead-beat at ``gain = 1``, mink's default),
tasks given as ``constraints`` as equalities ``J Δq = −gain·e``, and its
:class:`~mink.ConfigurationLimit` (joint position limits over the step, gain 0.95) and
:class:`~mink.VelocityLimit` (``|v| ≤ v_max``) as inequalities. There are no
priorities: the scenario's hierarchy becomes cost weights, one decade per level, as in
the pink baseline (:data:`~prioik.benchmarks.pink_baseline.LEVEL_COSTS`), from
:meth:`robots.scenario.Scenario.baseline_tasks`, each task mapped by its kind
(:meth:`prioik.robots.RobotTask.baseline_task`):

* ``frame_pose`` held by the scenario (``hard``: a foot in contact) → ``FrameTask`` as an
  equality constraint (``solve_ik(..., constraints=[...])``);
* ``frame_pose`` → ``FrameTask(body, position_cost=c, orientation_cost=c)``;
* ``frame_position`` → ``FrameTask(body, position_cost=c, orientation_cost=0)`` (a
  position target is never a constraint: the arm's tool target can be out of reach);
* ``frame_orientation`` → ``FrameTask(body, position_cost=0, orientation_cost=c)``;
* ``com`` (horizontal) → ``ComTask(cost=[c, c, 0])``;
* ``posture`` → ``PostureTask(cost=POSTURE_COST)`` (the free joint excluded, as mink does).

The robot is the scenario's URDF (:meth:`~robots.scenario.Scenario.urdf_text`) converted
by :func:`prioik.robots.mujoco_model.to_mujoco`; every frame is a MuJoCo body. The
velocity limits are pinocchio's (the URDF's). Targets are the scenario's references at
``t + dt``. The QP back-end is a qpsolvers name: :data:`DEFAULT_SOLVER`, the one mink's
documentation uses (``solve_ik(configuration, tasks, dt, "daqp")``, and mink requires
``qpsolvers[daqp]``), or any in ``qpsolvers.available_solvers``.

The step's kinematics time is ``Configuration.update`` and the target updates; its
solve time is ``solve_ik`` (building the QP in Python and solving it). The next
configuration is MuJoCo's integration of ``v`` (``Configuration.integrate``), mapped
back to pinocchio's ``q``.
"""

from __future__ import annotations

import time

from .external import distribution_version as _version
from .pink_baseline import LEVEL_COSTS, POSTURE_COST

#: the back-end of mink's documentation (its quickstart's ``solve_ik(..., "daqp")``)
DEFAULT_SOLVER = "daqp"
#: mink's task gain (dead-beat: the error is driven to zero within one step)
GAIN = 1.0



#: the baseline's name in the scenario reports (:data:`prioik.benchmarks.variants.BASELINES`)
NAME = "mink"
#: what the scenario pages say of the run: version, level, priority model, what it is given
DESCRIPTION = (f"mink {_version('mink')} (mujoco {_version('mujoco')}), solve_ik at "
               "velocity level on the URDF converted to MuJoCo: weighted tasks in one QP "
               "(one decade of cost per level), held feet as equality constraints, its "
               "ConfigurationLimit and VelocityLimit as inequalities; task gains "
               f"{GAIN:g} (dead-beat); QP back-end {DEFAULT_SOLVER} (mink's "
               "documentation's choice)")
#: the level the library solves at (the scenario pages' baseline table)
LEVEL = "velocity"


def profile() -> dict:
    """What the scenario pages say of this baseline (see
    :func:`prioik.benchmarks.placo_baseline.profile`)."""
    return {"library": f"mink {_version('mink')} (mujoco {_version('mujoco')})",
            "level": LEVEL,
            "priorities": "weights: one QP, one decade of cost per level (as pink); held "
                          "feet as equality constraints",
            "given": f"QP back-end {DEFAULT_SOLVER} (mink's documentation's; a quadprog row "
                     f"beside it), task gains {GAIN:g} (dead-beat), ConfigurationLimit and "
                     "VelocityLimit, the URDF converted to MuJoCo"}


def unavailable_reason(options: dict | None = None) -> str | None:
    """Why mink cannot run here with ``options`` (its ``solver``), or ``None``."""
    from prioik.extras import install_hint, missing_distributions
    missing = missing_distributions("mink")
    if missing:
        return f"{', '.join(missing)} not installed; {install_hint('mink')}"
    solver = (options or {}).get("solver", DEFAULT_SOLVER)
    import qpsolvers
    if solver not in qpsolvers.available_solvers:
        return f"QP back-end {solver} is not available here"
    return None


def steps(scenario, variant, *, duration: float, dt: float, progress=None):
    """A scenario run of ``variant`` (:class:`prioik.benchmarks.variants.Variant`), one
    step at a time (:func:`mink_steps`)."""
    return mink_steps(scenario, duration=duration, dt=dt, progress=progress,
                      solver=variant.options.get("solver", DEFAULT_SOLVER),
                      label=variant.label)


def run_mink(scenario, *, duration: float, dt: float, solver: str = DEFAULT_SOLVER,
             progress=None, label: str = "mink"):
    """Run ``scenario`` with mink's ``solve_ik``; returns a :class:`robots.SimulationResult`
    (:func:`mink_steps` to its end)."""
    from prioik.robots import run_to_end
    return run_to_end(mink_steps(scenario, duration=duration, dt=dt, solver=solver,
                                 progress=progress, label=label))


def mink_problem(scenario, dt: float):
    """mink's objects for ``scenario``: ``(mj, configuration, tasks, constraints, limits,
    set_targets)`` — the converted model (:class:`prioik.robots.mujoco_model.MujocoModel`),
    a ``mink.Configuration`` at ``q0``, the cost tasks, the equality-constraint tasks,
    the limits, and ``set_targets(t)`` giving every task its target at ``t``."""
    import mink

    from prioik.robots import task_kind
    from prioik.robots.mujoco_model import to_mujoco

    robot = scenario.robot
    mj = to_mujoco(robot, scenario.urdf_text())
    config = mink.Configuration(mj.model, mj.to_qpos(robot.q0))
    tasks, constraints, setters = [], [], []
    context = {"robot": robot, "model": mj.model, "gain": GAIN, "level_costs": LEVEL_COSTS,
               "posture_cost": POSTURE_COST,
               "to_qpos": mj.to_qpos,
               "com_height": float(config.data.subtree_com[1][2])}
    for spec in scenario.baseline_tasks():
        kind = task_kind(spec.kind)             # the kind maps itself onto mink's task
        context["cost"] = kind.baseline_cost(spec, context)
        task = kind.baseline_task("mink", spec, scenario.baseline_target(spec.name, 0.0),
                                  context)
        hard = spec.hard and kind.hard_is_constraint
        (constraints if hard else tasks).append(task)
        setters.append((spec, kind, task))
    limits = [mink.ConfigurationLimit(mj.model),
              mink.VelocityLimit(mj.model, mj.velocity_limits())]

    def set_targets(t: float) -> None:
        for spec, kind, task in setters:
            kind.baseline_target("mink", task, scenario.baseline_target(spec.name, t),
                                 context)

    return mj, config, tasks, constraints, limits, set_targets


def mink_steps(scenario, *, duration: float, dt: float, solver: str = DEFAULT_SOLVER,
               progress=None, label: str = "mink"):
    """``scenario`` with mink's ``solve_ik``, set up now and run one step at a time: a
    generator that yields after each step and returns the
    :class:`robots.SimulationResult` (:func:`prioik.benchmarks.external.record_steps`).

    Raises:
        ValueError: ``solver`` is not a QP back-end qpsolvers has here.
        prioik.robots.mujoco_model.MujocoModelError: MuJoCo cannot load the scenario's
            URDF as the robot's model.
    """
    import pinocchio as pin
    import qpsolvers
    from mink import solve_ik
    from mink.exceptions import MinkError

    from prioik.benchmarks.external import record_steps

    if solver not in qpsolvers.available_solvers:
        raise ValueError(f"mink: QP back-end {solver!r} is not available here; available: "
                         f"{', '.join(qpsolvers.available_solvers)}")
    model = scenario.robot.model
    mj, config, tasks, constraints, limits, set_targets = mink_problem(scenario, dt)

    def step(q, v, t):
        t0 = time.perf_counter()
        config.update(mj.to_qpos(q))
        set_targets(t + dt)
        t1 = time.perf_counter()
        try:
            vel = solve_ik(config, tasks, dt, solver, limits=limits,
                           constraints=constraints or None, safety_break=False)
        except MinkError as exc:
            raise RuntimeError(f"{type(exc).__name__}: {exc}") from None
        t2 = time.perf_counter()
        q_next = mj.to_q(config.integrate(vel, dt))
        return q_next, pin.difference(model, q, q_next) / dt, t1 - t0, t2 - t1

    return record_steps(scenario, step, duration=duration, dt=dt, progress=progress,
                        label=label, info={"qp_solver": solver})
