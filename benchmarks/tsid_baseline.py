"""A scenario with TSID — Stack-of-Tasks task-space inverse dynamics, in its own process.

TSID (tsid 1.7.1) is the acceleration-level whole-body controller of the Stack-of-Tasks
community: each control step one QP over ``(q̈, contact forces)`` with two levels —
the rigid dynamics, the rigid contacts and the joint bounds as constraints (level 0),
every motion task a weighted cost (level 1) — solved by eiquadprog
(``SolverHQuadProgFast``). It binds its own pinocchio (pin 3.4.0), which cannot share
prioik's environment (pin 3.8.0), so it runs in a separate virtual environment
(:data:`REQUIREMENTS`, built by ``make tsid`` into ``.venv-tsid``) and a subprocess:
:mod:`prioik.benchmarks.tsid_runner`, executed by that environment's python, receives
the scenario as JSON lines (its protocol) and returns the trajectory and the per-step
times, measured in its own process.

The scenario's tasks (:meth:`robots.scenario.Scenario.baseline_tasks`) map as TSID's
examples map theirs:

* ``frame_pose`` held by the scenario (``hard``, a foot in contact) on a floating base →
  ``Contact6d``, a rigid contact of level 0 (its pose held, gains of the scenario,
  force regularisation weight :data:`FORCE_WEIGHT`). The scenarios are kinematic (a
  held foot takes whatever wrench holding it needs), so the contact's sole is a
  virtual square of half-side :data:`SOLE_HALF_SIDE` with friction coefficient
  :data:`FRICTION`: the wrench is never what limits the motion;
* every other task → a motion task of level 1 (``TaskSE3Equality`` masked to the
  position or the orientation, ``TaskComEquality`` masked to x, y,
  ``TaskJointPosture``) with weight ``c²`` — ``c`` the cost of the pink and mink rows
  (one decade per level, :data:`~prioik.benchmarks.pink_baseline.LEVEL_COSTS`; the
  posture :data:`~prioik.benchmarks.pink_baseline.POSTURE_COST`), squared because TSID
  weighs squared residuals;
* the joint limits → ``TaskJointPosVelAccBounds`` (position, velocity and acceleration
  bounds, level 0) with the robot's position and velocity limits and the scenario's
  acceleration limits (``scenario.amax`` when it has them, the arm's Franka datasheet
  values, else :data:`ACCELERATION_LIMIT`).

Gains are the scenario's acceleration-level ``(K_p, K_d)`` (``scenario.gains``). The
references are the scenario's at ``t`` with their velocities and accelerations by
central differences (step :data:`DIFFERENCE_STEP`). The runner integrates as prioik's
simulations do (``q̇ ← q̇ + q̈ dt``, ``q ← q ⊕ q̇ dt``); this process records the
errors with prioik's kinematics (:func:`prioik.benchmarks.external.record_steps`).

The step's ``kinematics_time_s`` is setting TSID's references, its ``solve_time_s``
``computeProblemData`` (TSID's kinematics, dynamics and task rows) and the QP solve,
both timed in the TSID process. The runs advance in chunks of
:data:`~prioik.benchmarks.scenario_runs.TURN_STEPS` steps, as the other runs of a report
advance in turns.

The TSID environment is found at ``$PRIOIK_TSID_PYTHON`` (a python executable) or
else at ``.venv-tsid/bin/python`` in the repository; when it is missing the scenario
reports list TSID as not installed (:func:`unavailable_reason`).
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import weakref
from pathlib import Path

import numpy as np

from prioik.errors import PrioikError

#: the TSID environment's packages: the prebuilt tsid 1.7.1 wheel and the pinocchio it
#: was built against (``make tsid`` installs them into ``.venv-tsid``)
REQUIREMENTS = ("tsid==1.7.1", "pin==3.4.0", "cmeel-urdfdom>=4,<5", "cmeel-tinyxml2>=10,<11")
#: the environment variable naming the TSID environment's python
PYTHON_VARIABLE = "PRIOIK_TSID_PYTHON"
#: half-side (m) of a held frame's virtual square sole
SOLE_HALF_SIDE = 1.0
#: friction coefficient of a held frame's contact points
FRICTION = 10.0
#: weight of the contact forces' regularisation towards zero: small enough never to move
#: ``q̈`` (TSID's examples' 1e-5 sits beside task weights of order 1; beside these
#: scenarios' weights, down to 1e-6, and forces of hundreds of newtons it would pull the
#: robot's accelerations away from the tasks)
FORCE_WEIGHT = 1e-8
#: acceleration limit (rad/s²) of every joint when the scenario gives none
ACCELERATION_LIMIT = 1000.0
#: step (s) of the central differences giving the references' velocity and acceleration
DIFFERENCE_STEP = 1e-4
#: the runner script, executed by the TSID environment's python
RUNNER = Path(__file__).with_name("tsid_runner.py")

#: the baseline's name in the scenario reports (:data:`prioik.benchmarks.variants.BASELINES`)
NAME = "tsid"
#: the level the library solves at (the scenario pages' baseline table)
LEVEL = "acceleration"

__all__ = ["REQUIREMENTS", "NAME", "LEVEL", "profile", "python_path", "environment",
           "unavailable_reason", "setup_request", "step_references", "steps", "run_tsid",
           "TsidError"]


class TsidError(PrioikError, RuntimeError):
    """The TSID process refused the scenario or stopped (the message says why)."""


def python_path() -> Path:
    """The TSID environment's python: ``$PRIOIK_TSID_PYTHON`` or ``.venv-tsid`` in the
    repository this module is in."""
    env = os.environ.get(PYTHON_VARIABLE)
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent / ".venv-tsid" / "bin" / "python"


@functools.cache
def _probe(python: str) -> dict:
    if not Path(python).is_file():
        return {"error": f"not installed (no TSID environment at {python}); build it with "
                         f"`make tsid`, or set {PYTHON_VARIABLE} to the python of a venv "
                         f"with `pip install {' '.join(repr(r) for r in REQUIREMENTS)}`"}
    code = ("import json, importlib.metadata as m; from tsid import tsid_pywrap; "
            "import pinocchio; print(json.dumps({'tsid': m.version('tsid'), "
            "'pinocchio': pinocchio.__version__}))")
    try:
        out = subprocess.run([python, "-c", code], capture_output=True, text=True,
                             timeout=120)
    except OSError as exc:
        return {"error": f"not installed (the TSID environment's python {python} does not "
                         f"run: {exc})"}
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no message"])[-1]
        return {"error": f"not installed (the environment at {python} cannot import "
                         f"tsid: {last}); rebuild it with `make tsid`"}
    return json.loads(out.stdout)


def environment() -> dict:
    """``{"tsid": version, "pinocchio": version}`` of the TSID environment, or
    ``{"error": why}`` when it cannot run (checked once per python path)."""
    return _probe(str(python_path()))


def unavailable_reason(options: dict | None = None) -> str | None:
    """Why TSID cannot run here (``"not installed …"``), or ``None``."""
    return environment().get("error")


def __getattr__(name: str):
    # DESCRIPTION names the versions of the TSID environment, read when first asked for
    if name == "DESCRIPTION":
        env = environment()
        versions = (f"tsid {env['tsid']} (pin {env['pinocchio']}, its own environment)"
                    if "error" not in env else "tsid (not installed)")
        return (f"{versions}, timed in another process: inverse dynamics at acceleration "
                "level, two levels as in its examples — held feet as rigid contacts, the "
                "joint bounds (TaskJointPosVelAccBounds) and the dynamics as constraints, "
                "the other tasks weighted (one decade of cost per level, squared); the "
                "scenario's (K_p, K_d); QP back-end eiquadprog (SolverHQuadProgFast)")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def profile() -> dict:
    """What the scenario pages say of this baseline (see
    :func:`prioik.benchmarks.placo_baseline.profile`)."""
    env = environment()
    library = (f"TSID {env['tsid']} (pin {env['pinocchio']}, its own environment)"
               if "error" not in env else f"TSID ({REQUIREMENTS[0]}: not installed here)")
    return {"library": library, "level": LEVEL,
            "priorities": "two levels, as its examples: the dynamics, rigid contacts (held "
                          "feet) and joint bounds as constraints, every other task weighted "
                          "(the squares of pink's costs)",
            "given": "QP back-end eiquadprog (SolverHQuadProgFast), the scenario's "
                     "(K_p, K_d), TaskJointPosVelAccBounds with the robot's limits; timed "
                     "in its own process"}


# ---------------------------------------------------------------- the scenario
def setup_request(scenario, dt: float) -> dict:
    """The runner's setup (:mod:`prioik.benchmarks.tsid_runner`) for ``scenario``: each
    task as the runner's kind its task kind gives
    (:meth:`prioik.robots.RobotTask.baseline_task`).

    Raises:
        ValueError: a task without gains in ``scenario.gains``, or a kind TSID's
            mapping lacks.
    """
    from prioik.hierarchy import TaskStackError
    from prioik.robots import task_kind

    from .pink_baseline import LEVEL_COSTS, POSTURE_COST
    costs = {"level_costs": LEVEL_COSTS, "posture_cost": POSTURE_COST}
    robot = scenario.robot
    lower, upper, vmax = robot.joint_limits()
    amax = getattr(scenario, "amax", None)
    amax = np.full(len(vmax), ACCELERATION_LIMIT) if amax is None else np.asarray(amax)
    tasks = []
    for spec in scenario.baseline_tasks():
        if spec.name not in scenario.gains:
            raise ValueError(f"TSID baseline: the scenario gives task {spec.name!r} no "
                             f"gains (scenario.gains has {', '.join(scenario.gains)})")
        kind = task_kind(spec.kind)
        try:        # the kind maps itself onto the runner's task kinds
            runner_kind = kind.baseline_task("tsid", spec, None, {})
        except TaskStackError:
            raise ValueError(f"TSID baseline: no mapping for task kind {spec.kind!r}") from None
        kp, kd = scenario.gains[spec.name]
        task = {"name": spec.name, "kind": runner_kind, "frame": spec.frame,
                "kp": float(kp), "kd": float(kd),
                "weight": kind.baseline_cost(spec, costs) ** 2,
                "role": "weighted"}
        if kind.hard_is_constraint and spec.hard and robot.floating_base:
            s = SOLE_HALF_SIDE
            task.update(role="contact", contact={
                "points": [[s, s, 0.0], [s, -s, 0.0], [-s, s, 0.0], [-s, -s, 0.0]],
                "normal": [0.0, 0.0, 1.0], "mu": FRICTION, "min_force": 0.0,
                "max_force": 1e6, "force_weight": FORCE_WEIGHT})
        tasks.append(task)
    return {"protocol": 1, "urdf": scenario.urdf_text(),
            "floating_base": bool(robot.floating_base),
            "joint_names": list(robot.model.names)[1:], "q0": robot.q0.tolist(),
            "dt": float(dt), "tasks": tasks,
            "limits": {"lower": lower.tolist(), "upper": upper.tolist(),
                       "velocity": vmax.tolist(), "acceleration": amax.tolist()}}


def step_references(scenario, tasks: list, t: float) -> dict:
    """``{name: [x, ẋ, ẍ]}`` of the weighted ``tasks`` at ``t`` (JSON-ready): the
    scenario's targets and their central differences (:data:`DIFFERENCE_STEP`), as each
    task's kind gives them (:meth:`prioik.robots.RobotTask.baseline_reference`)."""
    from prioik.robots import task_kind
    h = DIFFERENCE_STEP
    kinds = {spec.name: task_kind(spec.kind) for spec in scenario.baseline_tasks()}
    context = {"model": scenario.robot.model}
    out = {}
    for spec in tasks:
        if spec["role"] == "contact":
            continue
        name = spec["name"]
        targets = [np.asarray(scenario.baseline_target(name, s), dtype=float)
                   for s in (t - h, t, t + h)]
        x1, vel, acc = kinds[name].baseline_reference("tsid", targets, h, context)
        out[name] = [x1.tolist(), vel.tolist(), acc.tolist()]
    return out


# --------------------------------------------------------------- the process
class _Runner:
    """The runner subprocess: one request, one reply."""

    def __init__(self, python: Path, setup: dict) -> None:
        self.proc = subprocess.Popen([str(python), str(RUNNER)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True)
        # a run set up but never advanced (its generator never started) ends it too
        self._finalizer = weakref.finalize(self, _end, self.proc)
        self.ready = self.ask(setup)

    def ask(self, request: dict) -> dict:
        try:
            self.proc.stdin.write(json.dumps(request) + "\n")
            self.proc.stdin.flush()
            line = self.proc.stdout.readline()
        except (BrokenPipeError, OSError):
            line = ""
        if not line:
            self.close()
            err = (self.proc.stderr.read() if self.proc.stderr else "").strip()
            raise TsidError(f"the TSID process stopped (status {self.proc.returncode}): "
                            f"{(err.splitlines() or ['no message'])[-1]}")
        reply = json.loads(line)
        if "error" in reply and "q" not in reply:
            self.close()
            raise TsidError(f"the TSID process refused the request: {reply['error']}")
        return reply

    def close(self) -> None:
        if self.proc.stdin and not self.proc.stdin.closed:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:  # pragma: no cover - a hung runner
            self.proc.kill()
            self.proc.wait()


def _end(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def steps(scenario, variant, *, duration: float, dt: float, progress=None):
    """A scenario run of ``variant`` (:class:`prioik.benchmarks.variants.Variant`), one
    step at a time (:func:`tsid_steps`)."""
    return tsid_steps(scenario, duration=duration, dt=dt, progress=progress,
                      label=variant.label)


def run_tsid(scenario, *, duration: float, dt: float, progress=None, label: str = "tsid"):
    """Run ``scenario`` with TSID; returns a :class:`robots.SimulationResult`
    (:func:`tsid_steps` to its end)."""
    from prioik.robots import run_to_end
    return run_to_end(tsid_steps(scenario, duration=duration, dt=dt, progress=progress,
                                 label=label))


def tsid_steps(scenario, *, duration: float, dt: float, progress=None, label: str = "tsid",
               python: Path | None = None, chunk: int | None = None):
    """``scenario`` with TSID in its own process, started now (the setup sent and
    accepted) and run one step at a time: a generator that yields after each step and
    returns the :class:`robots.SimulationResult`
    (:func:`prioik.benchmarks.external.record_steps`). A QP TSID cannot solve ends the
    run as failed, with TSID's status in its message.

    Args:
        python: The TSID environment's python (default :func:`python_path`).
        chunk: Steps asked of the process at a time (default
            :data:`~prioik.benchmarks.scenario_runs.TURN_STEPS`).

    Raises:
        TsidError: the environment is missing, or the process refused the scenario.
        ValueError: as :func:`setup_request`.
    """
    from .scenario_runs import TURN_STEPS
    python = Path(python) if python is not None else python_path()
    why = _probe(str(python)).get("error")
    if why:
        raise TsidError(f"TSID: {why}")
    setup = setup_request(scenario, dt)
    runner = _Runner(python, setup)
    chunk = TURN_STEPS if not chunk else int(chunk)
    total = int(round(duration / dt))
    buffer: list = []
    state = {"asked": 0, "error": None}

    def step(q, v, t):
        if not buffer:
            if state["error"]:
                raise RuntimeError(state["error"])
            k0 = state["asked"]
            n = max(1, min(chunk, total - k0))
            refs = [step_references(scenario, setup["tasks"], (k0 + i) * dt)
                    for i in range(n)]
            reply = runner.ask({"targets": refs})
            state["asked"] += n
            state["error"] = reply.get("error")
            buffer.extend(zip(reply["q"], reply["v"], reply["reference_time_s"],
                              reply["solve_time_s"], strict=False))
            if not buffer:
                raise RuntimeError(state["error"] or "TSID returned no step")
        q_next, v_next, t_ref, t_solve = buffer.pop(0)
        return np.array(q_next), np.array(v_next), t_ref, t_solve

    from .external import record_steps
    env = _probe(str(python))
    info = {"qp_solver": "eiquadprog", "tsid": env.get("tsid"),
            "tsid_pinocchio": env.get("pinocchio"), "timed_in": "the TSID process"}
    return _closing(record_steps(scenario, step, duration=duration, dt=dt,
                                 progress=progress, label=label, info=info), runner)


def _closing(steps, runner: _Runner):
    """``steps``, the runner's process ended when they end (or are closed)."""
    try:
        return (yield from steps)
    finally:
        runner.close()


if __name__ == "__main__":  # pragma: no cover
    print(json.dumps(environment()), file=sys.stdout)
