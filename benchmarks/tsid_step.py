"""The whole acceleration-level IK step on the Panda reach: TSID (in its own process)
beside prioik, round by round.

The problem: the arm scenario's Panda (:func:`prioik.robots.arm.panda`, 7 joints, tool
``panda_hand_tcp``) reaching the first target of :data:`prioik.robots.arm.TARGETS` from
its ready posture, ``dt`` = 2 ms, joint position and velocity limits.

* **TSID** (:mod:`prioik.benchmarks.tsid_runner` in the TSID environment): the tool
  position (``TaskSE3Equality`` masked to the position, ``K_p = 25``, ``K_d = 10``,
  weight 1) and the posture (``TaskJointPosture``, ``K_p = K_d = 4``, weight 1e-3: the
  weights of TSID's examples) at its second level, ``TaskJointPosVelAccBounds`` (the
  robot's limits, acceleration bound :data:`~prioik.benchmarks.tsid_baseline.
  ACCELERATION_LIMIT`: prioik's bounds hold no acceleration limit) at its first;
  eiquadprog. Its step: setting the references, ``computeProblemData``, the solve.
* **prioik, acceleration level**: joint-limit bounds on ``q̈`` (horizon 0.1 s) above the
  tool position (``K_p = 25``, ``K_d = 10``) above the posture (``4, 4``),
  ``hierarchical_active_set`` prepared once. Its step: the kinematic state (with the
  drift terms), the rows written in place, the solve.
* **prioik, velocity level**: the same tasks as ``J q̇ = ẋ* + K e`` (``K = 10``, posture
  ``1``), bounds on ``q̇``.

Each path runs its own closed loop from the ready posture (semi-implicit Euler at
acceleration level) for ``steps`` steps per round; the rounds alternate the three paths
(TSID's in its process, the others in this one), and each path's fastest round (lowest
median) is kept. Integration and the inter-process messages are outside the timed step.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

__all__ = ["panda_tsid_step", "run", "format_table"]

DT = 0.002
GAINS = {"tool": (25.0, 10.0), "posture": (4.0, 4.0)}
VELOCITY_GAINS = {"tool": 10.0, "posture": 1.0}
#: TSID's task weights (its examples': end effector 1, posture 1e-3)
WEIGHTS = {"tool": 1.0, "posture": 1e-3}


def _tsid_setup(scenario, robot) -> dict:
    from .tsid_baseline import ACCELERATION_LIMIT
    lower, upper, vmax = robot.joint_limits()
    from prioik.robots.arm import TOOL
    tasks = [{"name": "tool", "kind": "position", "frame": TOOL, "role": "weighted",
              "kp": GAINS["tool"][0], "kd": GAINS["tool"][1], "weight": WEIGHTS["tool"]},
             {"name": "posture", "kind": "posture", "frame": None, "role": "weighted",
              "kp": GAINS["posture"][0], "kd": GAINS["posture"][1],
              "weight": WEIGHTS["posture"]}]
    return {"protocol": 1, "urdf": scenario.urdf_text(), "floating_base": False,
            "joint_names": list(robot.model.names)[1:], "q0": robot.q0.tolist(),
            "dt": DT, "tasks": tasks,
            "limits": {"lower": lower.tolist(), "upper": upper.tolist(),
                       "velocity": vmax.tolist(),
                       "acceleration": [ACCELERATION_LIMIT] * len(vmax)}}


def panda_tsid_step(steps: int = 300, rounds: int = 7, python=None) -> dict[str, Any]:
    """Median step times (µs) of TSID and prioik (acceleration and velocity level) on
    the Panda reach (see the module docstring), each on its own closed loop; each one's
    final tool error (m) and worst joint-limit violation (rad).

    Raises:
        prioik.benchmarks.tsid_baseline.TsidError: the TSID environment is missing or
            refused the problem.
    """
    import pinocchio as pin

    import prioik
    from prioik.robots import KinematicState, TaskWriter
    from prioik.robots.arm import TARGETS, TOOL, ArmScenario

    from .tsid_baseline import TsidError, _probe, _Runner, python_path

    python = python or python_path()
    why = _probe(str(python)).get("error")
    if why:
        raise TsidError(f"TSID: {why}")
    scenario = ArmScenario()
    robot = scenario.robot
    model, q0, nv = robot.model, robot.q0, robot.nv
    target = np.array(TARGETS[0], dtype=float)
    data = model.createData()

    acc = TaskWriter(robot, "acceleration")
    acc.add_joint_limits("limits", form="bounds", horizon=scenario.bound_horizon, dt=DT,
                         level=0)
    acc.add_frame_position("tool", TOOL, gain=GAINS["tool"], level=1)
    acc.add_posture("posture", gain=GAINS["posture"], level=2)
    acc_solver = prioik.prepare(acc.layout, "hierarchical_active_set")
    vel = TaskWriter(robot, "velocity")
    vel.add_joint_limits("limits", form="bounds", dt=DT, level=0)
    vel.add_frame_position("tool", TOOL, gain=VELOCITY_GAINS["tool"], level=1)
    vel.add_posture("posture", gain=VELOCITY_GAINS["posture"], level=2)
    vel_solver = prioik.prepare(vel.layout, "hierarchical_active_set")

    def prioik_loop(level: str) -> tuple[np.ndarray, np.ndarray]:
        q, v = q0.copy(), np.zeros(nv)
        times = np.empty(steps)
        w, solver = (acc, acc_solver) if level == "acceleration" else (vel, vel_solver)
        zero = np.zeros(nv)
        for k in range(steps):
            t0 = time.perf_counter()
            state = (KinematicState(robot, q, v, data) if level == "acceleration"
                     else KinematicState(robot, q, zero, data, drift=False))
            w.joint_limits(state, "limits")
            w.frame_position(state, "tool", target)
            w.posture(state, "posture", q0)
            x = solver.solve(w.targets(state)).x
            times[k] = time.perf_counter() - t0
            if level == "acceleration":
                v = v + x * DT
                q = pin.integrate(model, q, v * DT)
            else:
                q = pin.integrate(model, q, x * DT)
        return times, q

    runner = _Runner(python, _tsid_setup(scenario, robot))
    refs = {"tool": [target.tolist(), [0.0] * 6, [0.0] * 6],
            "posture": [q0.tolist(), [0.0] * nv, [0.0] * nv]}

    def tsid_loop() -> tuple[np.ndarray, np.ndarray]:
        runner.ask({"reset": True})
        reply = runner.ask({"targets": [refs] * steps})
        if "error" in reply:
            raise TsidError(f"TSID: {reply['error']}")
        times = np.add(reply["reference_time_s"], reply["solve_time_s"])
        return times, np.array(reply["q"][-1])

    paths = {"tsid": tsid_loop, "prioik_acceleration": lambda: prioik_loop("acceleration"),
             "prioik_velocity": lambda: prioik_loop("velocity")}
    best: dict[str, np.ndarray] = {}
    final: dict[str, np.ndarray] = {}
    try:
        for _ in range(rounds):
            for name, loop in paths.items():
                times, q = loop()
                if name not in best or np.median(times) < np.median(best[name]):
                    best[name] = times
                final[name] = q
    finally:
        runner.close()
    lo, hi, _ = robot.joint_limits()
    out: dict[str, Any] = {"steps": steps, "rounds": rounds,
                           "tsid": runner.ready.get("tsid"),
                           "tsid_pinocchio": runner.ready.get("pinocchio")}
    for name, times in best.items():
        out[f"{name}_step_us"] = float(np.median(times)) * 1e6
        out[f"{name}_p90_us"] = float(np.percentile(times, 90)) * 1e6
        state = KinematicState(robot, final[name], np.zeros(nv), data, drift=False)
        out[f"{name}_tool_error_m"] = float(np.linalg.norm(
            state.placement(TOOL).translation - target))
        q = final[name]
        out[f"{name}_limit_violation_rad"] = float(max(0.0, np.max(lo - q), np.max(q - hi)))
    out["tsid/prioik_acceleration"] = out["tsid_step_us"] / out["prioik_acceleration_step_us"]
    out["tsid/prioik_velocity"] = out["tsid_step_us"] / out["prioik_velocity_step_us"]
    return out


def run(steps: int = 300, rounds: int | None = None) -> dict[str, Any]:
    """:func:`panda_tsid_step` with one BLAS thread."""
    from prioik.threads import blas_threads
    with blas_threads(1):
        return panda_tsid_step(steps, **({"rounds": rounds} if rounds else {}))


def format_table(r: dict[str, Any]) -> str:
    """A markdown table of :func:`run`'s result."""
    names = {"tsid": f"TSID {r.get('tsid')} (its own process)",
             "prioik_acceleration": "prioik, acceleration level",
             "prioik_velocity": "prioik, velocity level"}
    lines = ["| path | median step | p90 | TSID / this | final tool error | "
             "max joint-limit violation |", "|---|---|---|---|---|---|"]
    for key, label in names.items():
        ratio = r["tsid_step_us"] / r[f"{key}_step_us"]
        lines.append(f"| {label} | {r[f'{key}_step_us']:.1f} µs | {r[f'{key}_p90_us']:.1f} µs "
                     f"| {ratio:.2f} | {1e3 * r[f'{key}_tool_error_m']:.3g} mm | "
                     f"{r[f'{key}_limit_violation_rad']:.2g} rad |")
    return "\n".join(lines)


if __name__ == "__main__":   # pragma: no cover - the measurement's command
    import json
    import sys
    res = run(int(sys.argv[1]) if len(sys.argv) > 1 else 300)
    print(format_table(res))
    print(json.dumps(res, indent=1, default=str))
