"""Velocity-level loops with a target out of reach: the chatter of an undamped level and
the feet that slide under large steps, and their remedies.

* **Panda** — docs/usage.md's joint-limits loop: the Panda (9 DoF), joint position and velocity
  limits as bounds at level 0, the hand (``panda_hand``, ``K = 10``) at level 1 with a
  target 0.9 m away (:data:`PANDA_TARGET`, out of reach), ``dt`` = 2 ms,
  ``hierarchical_active_set``. With the remedy the hand's level also holds a damping task
  (:meth:`~prioik.robots.TaskWriter.add_damping`, ``weight = λ²``
  :data:`DAMPING`). Reported: the most sign changes of any joint's ``q̇`` in a window of
  100 steps, over the windows after the hand stopped making progress
  (:func:`settled_step`).
* **Humanoid** (G1, TALOS) — the balance loop of ``docs/robots.md``: both feet
  (contacts, ``K = 10``), the joint-limit bounds and the CoM over the feet's polygon
  (2 cm margin) at level 0, the left hand (``K = 10``) at level 1 with a target 1.5 m
  ahead of it (:data:`HAND_OFFSET`), the posture (``K = 1``) at level 2, ``dt`` = 10 ms,
  300 steps. With the remedy the hand's target speed is capped (``max_rate``
  :data:`HAND_MAX_RATE`) and its level damped (:data:`DAMPING`). Reported: how far the
  integrated feet leave their start (m, the worst step), the largest joint speed, every
  status.

The baselines, where installed, with the same targets, ``dt`` and counts: on the
Panda's loop (:func:`baseline_runs`) PlaCo's ``KinematicsSolver``
(:func:`prioik.benchmarks.panda_step.placo_panda`: hand soft 1, joints soft 1e-4, its
joint and velocity limits) and mink's ``solve_ik`` (:mod:`prioik.benchmarks.mink_step`:
``FrameTask`` position cost 1, ``PostureTask`` 1e-2, ``ConfigurationLimit``,
``VelocityLimit``, DAQP); on the G1's (:func:`placo_humanoid_run`) PlaCo's, feet and
CoM polygon hard (:func:`prioik.benchmarks.balance_step.placo_feet`).

``python -m prioik.benchmarks.out_of_reach`` prints both, the remedy off and on, and the
baselines.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

__all__ = ["PANDA_TARGET", "HAND_OFFSET", "HAND_MAX_RATE", "DAMPING", "ZERO_SPEED",
           "sign_changes", "settled_step", "panda_run", "humanoid_run", "baseline_runs",
           "placo_humanoid_run", "run",
           "format_table"]

#: the Panda's hand target of docs/usage.md's joint-limits loop (m), ~0.95 m from the shoulder
PANDA_TARGET = (0.9, 0.3, 0.4)
#: the humanoid's hand target, from the hand's start (m)
HAND_OFFSET = (1.5, 0.0, 0.0)
#: the humanoid's hand target speed cap (m/s)
HAND_MAX_RATE = 0.5
#: the damping task's weight λ² ((m/rad)²: λ = 0.1 m)
DAMPING = 1e-2
#: a joint speed below this (rad/s) counts as zero when sign changes are counted: the
#: rounding of a q̇ = 0 answer (2e-9 rad per 2 ms step)
ZERO_SPEED = 1e-6
#: the hand has stopped making progress once its error never improves by more than
#: this (m) again
SETTLED = 1e-4


def sign_changes(qdot, start: int = 0, window: int = 100,
                 zero: float = ZERO_SPEED) -> np.ndarray:
    """Sign changes of each joint's speed per window of ``window`` steps from ``start``
    (``windows × n_v``): a change is a step whose speed has the opposite sign of the
    previous step's, both beyond ``zero`` in magnitude."""
    v = np.asarray(qdot, dtype=float)[start:]
    sign = np.sign(np.where(np.abs(v) < zero, 0.0, v))
    flips = (sign[1:] * sign[:-1]) < 0
    return np.array([flips[k:k + window].sum(axis=0)
                     for k in range(0, flips.shape[0] - window + 1, window)], dtype=int)


def settled_step(errors, tol: float = SETTLED) -> int:
    """The first step from which a task's error (one value per step) never improves by
    more than ``tol`` again: every later step's error is within ``tol`` of the smallest
    error after it. A loop that flips between two states has stopped making progress
    as much as one at rest."""
    e = np.asarray(errors, dtype=float)
    later_best = np.minimum.accumulate(e[::-1])[::-1]
    improving = np.flatnonzero(e - later_best > tol)
    return int(improving[-1]) + 1 if improving.size else 0


def panda_run(damping: float | None = DAMPING, steps: int = 2500) -> dict[str, Any]:
    """docs/usage.md's joint-limits loop (the hand's level damped by ``damping``; ``None``: not
    damped) for ``steps`` steps; returns ``qdot`` (steps × n_v), the hand's position after
    every step ``hand``, the statuses and the wall time."""
    import pinocchio as pin

    import prioik
    from prioik.robots import KinematicState, TaskWriter, load

    robot = load("panda")
    rows = TaskWriter(robot, "velocity")
    rows.add_joint_limits("limits", form="bounds", dt=0.002, level=0)
    rows.add_frame_position("hand", "panda_hand", gain=10.0, level=1)
    if damping is not None:
        rows.add_damping("damping", weight=damping, level=1)
    solver = prioik.prepare(rows.layout, "hierarchical_active_set")
    q, dt = robot.q0.copy(), 0.002
    target = np.array(PANDA_TARGET)
    data = robot.model.createData()
    qdot, hand, statuses = np.zeros((steps, robot.nv)), np.zeros((steps, 3)), set()
    fid = robot.frame_id("panda_hand")
    start = time.perf_counter()
    for step in range(steps):
        state = KinematicState(robot, q, np.zeros(robot.nv), data, drift=False)
        rows.joint_limits(state, "limits")
        rows.frame_position(state, "hand", target)
        sol = solver.solve(rows.targets(state))
        statuses.add(sol.status)
        qdot[step] = sol.x
        q = pin.integrate(robot.model, q, sol.x * dt)
        pin.framesForwardKinematics(robot.model, data, q)
        hand[step] = data.oMf[fid].translation
    return {"qdot": qdot, "hand": hand, "statuses": statuses,
            "wall_s": time.perf_counter() - start}


def humanoid_run(name: str, remedy: bool = True, steps: int = 300) -> dict[str, Any]:
    """The humanoid balance loop with the hand :data:`HAND_OFFSET` away (the remedy: the
    hand's ``max_rate`` and the damping task; off: neither) for ``steps`` steps; returns
    the feet's worst distance from their start ``feet_drift_m`` (after each step's
    integration), ``max_joint_speed``, the statuses, the hand's last distance from its
    target and the wall time."""
    import pinocchio as pin

    import prioik
    from prioik.robots import KinematicState, TaskWriter, load, polygon_region

    robot = load(name)
    dt, feet = 0.01, ("left_foot", "right_foot")
    start_state = KinematicState(robot, robot.q0, np.zeros(robot.nv), drift=False)
    places = {f: start_state.placement(f).copy() for f in feet}
    soles = [places[f].act(np.array([dx, dy, 0.0])) for f in feet
             for dx in (-0.05, 0.1) for dy in (-0.03, 0.03)]
    C, upper = polygon_region(soles, margin=0.02)
    target = start_state.placement("left_hand").translation + np.array(HAND_OFFSET)

    w = TaskWriter(robot, "velocity")
    for f in feet:
        w.add_contact(f, f, gain=10.0, level=0)
    w.add_joint_limits("limits", form="bounds", dt=dt, level=0)
    w.add_com_region("balance", C, upper=upper, dt=dt, level=0)
    w.add_frame_position("reach", "left_hand", gain=10.0, level=1,
                         max_rate=HAND_MAX_RATE if remedy else None)
    if remedy:
        w.add_damping("damping", weight=DAMPING, level=1)
    w.add_posture("posture", gain=1.0, level=2)
    solver = prioik.prepare(w.layout, "hierarchical_active_set")

    q, v = robot.q0.copy(), np.zeros(robot.nv)
    data = robot.data()
    ids = [robot.frame_id(f) for f in feet]
    drift, speed, statuses = 0.0, 0.0, set()
    start = time.perf_counter()
    for _ in range(steps):
        state = KinematicState(robot, q, v, data, drift=False)
        for f in feet:
            w.contact(state, f, places[f])
        w.joint_limits(state, "limits")
        w.com_region(state, "balance")
        w.frame_position(state, "reach", target)
        w.posture(state, "posture", robot.q0)
        sol = solver.solve(w.targets(state))
        statuses.add(sol.status)
        v = sol.x
        speed = max(speed, float(np.abs(v[robot.n_base:]).max()))
        q = pin.integrate(robot.model, q, v * dt)
        pin.framesForwardKinematics(robot.model, data, q)
        drift = max(drift, max(float(np.linalg.norm(data.oMf[i].translation
                                                    - places[f].translation))
                               for i, f in zip(ids, feet, strict=False)))
    hand = data.oMf[robot.frame_id("left_hand")].translation
    return {"robot": name, "remedy": remedy, "feet_drift_m": drift,
            "max_joint_speed": speed, "statuses": statuses,
            "hand_error_m": float(np.linalg.norm(target - hand)),
            "wall_s": time.perf_counter() - start}


def _chatter(label: str, qdot, hand, statuses) -> dict[str, Any]:
    """A Panda run's record: where the hand stopped, the windows after it and their
    most sign changes of a joint's q̇, the hand's last error."""
    errors = np.linalg.norm(np.asarray(hand) - np.array(PANDA_TARGET), axis=1)
    settled = settled_step(errors)
    counts = sign_changes(qdot, settled)
    return {"label": label, "settled_step": settled,
            "max_sign_changes_per_100": int(counts.max()) if counts.size else None,
            "windows": int(counts.shape[0]), "hand_error_m": float(errors[-1]),
            "statuses": sorted(statuses)}


def baseline_runs(steps: int = 2500) -> list[dict[str, Any]]:
    """PlaCo and mink on the Panda's loop (see the module docstring), each run for
    ``steps`` steps; a baseline whose extra is missing gives a record saying so."""
    import pinocchio as pin

    from prioik.extras import installed
    from prioik.robots import load

    from .panda_step import DT, placo_panda

    robot = load("panda")
    data, fid = robot.model.createData(), robot.frame_id("panda_hand")

    def hand_of(q):
        pin.framesForwardKinematics(robot.model, data, q)
        return data.oMf[fid].translation.copy()

    out = []
    if "placo" in installed():
        _, states, _ = placo_panda(robot, steps + 1, limits=True, target=PANDA_TARGET)
        q = np.array(states)
        out.append(_chatter("PlaCo (hand 1, joints 1e-4)", np.diff(q, axis=0) / DT,
                            np.array([hand_of(x) for x in q[1:]]), ()))
    else:
        out.append({"label": "PlaCo", "missing": "the `placo` extra is not installed"})
    if "mink" in installed():
        from .mink_baseline import DEFAULT_SOLVER
        from .mink_step import POSTURE_COST, _mink
        _, advance = _mink(robot, None, "panda_hand", np.array(PANDA_TARGET), {},
                           DEFAULT_SOLVER)
        q, qdot, hand = robot.q0.copy(), [], []
        for _ in range(steps):                 # mink's step, integrated by MuJoCo
            after = advance(q, DT)
            qdot.append(pin.difference(robot.model, q, after) / DT)
            q = after
            hand.append(hand_of(q))
        out.append(_chatter(f"mink (hand 1, posture {POSTURE_COST:g}, {DEFAULT_SOLVER})",
                            np.array(qdot), np.array(hand), ()))
    else:
        out.append({"label": "mink", "missing": "the `mink` extra is not installed"})
    return out


def placo_humanoid_run(steps: int = 300) -> dict[str, Any]:
    """PlaCo's ``KinematicsSolver`` on the G1's loop (its feet hard, the CoM polygon hard,
    the hand soft 1 to the same target, the joints soft 1e-4, its joint and velocity
    limits: :func:`prioik.benchmarks.balance_step.placo_feet`); the record of
    :func:`humanoid_run` without statuses (a record saying so without the extra)."""
    import pinocchio as pin

    from prioik.extras import installed
    from prioik.robots import load

    from .balance_step import FEET, REACH, balance_setup, placo_feet

    if "placo" not in installed():
        return {"robot": "g1", "remedy": "PlaCo", "missing": "the `placo` extra is not "
                "installed"}
    robot, dt = load("g1"), 0.01
    setup = balance_setup(robot)
    setup["target"] = setup["target"] - REACH + np.array(HAND_OFFSET)    # the hand's start

    _, states, _ = placo_feet(robot, setup, steps + 1, dt, balance=True)
    data = robot.model.createData()
    ids = [robot.frame_id(f) for f in FEET]
    drift, speed = 0.0, 0.0
    for before, after in zip(states[:-1], states[1:], strict=False):
        pin.framesForwardKinematics(robot.model, data, after)
        drift = max(drift, max(float(np.linalg.norm(data.oMf[i].translation
                                                    - setup["places"][f].translation))
                               for i, f in zip(ids, FEET, strict=False)))
        v = pin.difference(robot.model, before, after) / dt
        speed = max(speed, float(np.abs(v[robot.n_base:]).max()))
    hand = data.oMf[robot.frame_id("left_hand")].translation
    return {"robot": "g1", "remedy": "PlaCo (hand 1, joints 1e-4)", "feet_drift_m": drift,
            "max_joint_speed": speed, "statuses": [],
            "hand_error_m": float(np.linalg.norm(setup["target"] - hand))}


def run(panda_steps: int = 2500, humanoid_steps: int = 300) -> dict[str, Any]:
    """Both loops, the remedy off and on, and the baselines on the Panda's."""
    out: dict[str, Any] = {"panda": [], "humanoid": []}
    for damping in (None, DAMPING):
        res = panda_run(damping, panda_steps)
        label = ("prioik, undamped" if damping is None
                 else f"prioik, damping λ² = {damping:g}")
        out["panda"].append(_chatter(label, res["qdot"], res["hand"], res["statuses"]))
    out["panda"] += baseline_runs(panda_steps)
    for name in ("g1", "talos"):
        for remedy in (False, True):
            res = humanoid_run(name, remedy, humanoid_steps)
            res["statuses"] = sorted(res["statuses"])
            out["humanoid"].append(res)
        if name == "g1":
            out["humanoid"].append(placo_humanoid_run(humanoid_steps))
    return out


def format_table(res: dict[str, Any]) -> str:
    """The two tables of :func:`run` in markdown."""
    lines = ["| Panda, docs/usage.md's loop | no progress from step | windows of 100 after | "
             "most sign changes of a joint's q̇ per 100 steps | hand error (m) | "
             "statuses |",
             "|---|---:|---:|---:|---:|---|"]
    for r in res["panda"]:
        if "missing" in r:
            lines.append(f"| {r['label']} | {r['missing']} | | | | |")
            continue
        lines.append(f"| {r['label']} | {r['settled_step']} | {r['windows']} | "
                     f"{r['max_sign_changes_per_100']} | {r['hand_error_m']:.4f} | "
                     f"{', '.join(r['statuses']) or '—'} |")
    lines += ["", "| humanoid, hand 1.5 m out of reach | remedy | feet drift (mm) | "
              "largest joint speed (rad/s) | hand error (m) | statuses |",
              "|---|---|---:|---:|---:|---|"]
    for r in res["humanoid"]:
        if "missing" in r:
            lines.append(f"| {r['robot']} | {r['remedy']}: {r['missing']} | | | | |")
            continue
        remedy = r["remedy"] if isinstance(r["remedy"], str) else (
            f"max_rate {HAND_MAX_RATE:g} m/s, damping λ² = {DAMPING:g}" if r["remedy"]
            else "off")
        lines.append(f"| {r['robot']} | {remedy} | {1e3 * r['feet_drift_m']:.3f} | "
                     f"{r['max_joint_speed']:.2f} | {r['hand_error_m']:.3f} | "
                     f"{', '.join(r['statuses']) or '—'} |")
    return "\n".join(lines)


if __name__ == "__main__":   # pragma: no cover - the measurement's command
    print(format_table(run()))
