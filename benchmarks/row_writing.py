"""Per-step cost of writing the G1 fencing rows with :class:`prioik.robots.TaskWriter`.

The fencing scenario's velocity-level rows (support-foot contact, CoM, left-foot pose,
sword-tip position, posture; optionally the joint-limit bounds on ``q̇``) are written
from a ``KinematicState(drift=False)`` computed once, with the references computed
beforehand: what is timed is the writer calls and :meth:`TaskWriter.targets` alone
(the references cost the same in every path). Reported as the minimum over ``repeats``
of the median over ``n_steps`` steps (the first calls excluded by a warm-up). The
writers are the C++ core's (``prioik._core.rows``, what :mod:`prioik.robots.rows`
calls); :func:`writer_calls` times each one's own call.

Run: ``python -m prioik.benchmarks.row_writing [--calls]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

__all__ = ["time_fencing_rows", "writer_calls"]


def time_fencing_rows(n_steps: int = 300, repeats: int = 7, limits: str = "none",
                      seed: int = 0) -> dict[str, float]:
    """Median per-step time (µs) of writing the G1 fencing rows.

    Args:
        n_steps: Steps per median (the references of ``t = 0, 0.01, ...``).
        repeats: Medians taken; the smallest is reported (the machine is shared).
        limits: ``"none"`` (the five fencing tasks) or ``"bounds"`` (plus the joint-limit
            bounds on ``q̇``).
        seed: Seed of the perturbed standing state.

    Returns:
        ``{"write_us": ..., "medians_us": [...], "rows": m}``.
    """
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario

    sc = FencingScenario("compatible")
    robot = sc.robot
    writer = sc.velocity_rows(10.0, limits=limits)
    rng = np.random.default_rng(seed)
    q = robot.q0.copy()
    q[7:] += rng.uniform(-0.1, 0.1, robot.nq - 7)
    state = KinematicState(robot, q, rng.normal(size=robot.nv), robot.data(), drift=False)
    refs = [(sc.com_ref(0.01 * i), sc.left_foot_ref(0.01 * i), sc.tip_ref(0.01 * i))
            for i in range(n_steps)]
    support_x, support_R, foot_R = sc._support_x, sc._support_R, sc._left_foot_R
    with_limits = "joint_limits" in writer

    def write(com, foot, tip):
        writer.contact(state, "support_foot", translation=support_x, rotation=support_R)
        if with_limits:
            writer.joint_limits(state, "joint_limits")
        writer.com(state, "com", com.x, com.xd, com.xdd)
        writer.frame_pose(state, "left_foot", foot.x, foot_R, foot.xd, foot.xdd)
        writer.frame_position(state, "sword_tip", tip.x, tip.xd, tip.xdd)
        writer.posture(state, "posture", robot.q0)
        return writer.targets(state)

    for _ in range(100):                       # compile and warm up
        write(*refs[0])
    medians = []
    clock = time.perf_counter
    for _ in range(repeats):
        times = np.empty(n_steps)
        for i, (com, foot, tip) in enumerate(refs):
            t0 = clock()
            write(com, foot, tip)
            times[i] = clock() - t0
        medians.append(float(np.median(times)) * 1e6)
    return {"write_us": min(medians), "medians_us": medians, "rows": writer.layout.m}


def writer_calls(number: int = 5000, repeats: int = 3) -> dict[str, float]:
    """Each row writer's own call on the G1 (an acceleration-level writer with a pose, a
    position, the CoM, posture, both joint-limit forms and a CoM region: ``m = 100``,
    ``n_v = 35``): ``{writer: ns}``, the smallest of ``repeats`` means over ``number``
    calls."""
    import functools
    import timeit

    from prioik._core import rows as k
    from prioik.robots import KinematicState, TaskWriter, g1

    robot = g1()
    w = TaskWriter(robot, "acceleration")
    w.add_frame_pose("pose", "left_foot", gain=(1.0, 1.0))
    w.add_frame_position("position", "right_foot", gain=(1.0, 1.0))
    w.add_com("com", gain=(1.0, 1.0))
    w.add_posture("posture", gain=(1.0, 1.0))
    w.add_joint_limits("bounds", form="bounds", dt=0.002, horizon=0.05)
    w.add_joint_limits("activation", form="activation")
    w.add_com_region("com_region", np.eye(3)[:2], lower=-0.1, upper=0.1, dt=0.002)
    state = KinematicState(robot, robot.q0, np.random.default_rng(0).normal(size=robot.nv))
    tasks = {name: w._task(name, None) for name in w.tasks()}
    _, pose = w._frame_args(tasks["pose"], state)
    _, position = w._frame_args(tasks["position"], state)
    views = w._data_views(state)
    d, Q, z, eye = w.data, w._Q, np.zeros(3), np.eye(3)
    com, lb, la, cr = tasks["com"], tasks["bounds"], tasks["activation"], tasks["com_region"]
    reg = cr.region
    unit = robot.state_sizes()[3]
    calls = {
        "frame_rows (pose)": lambda k: k.frame_rows(*pose, z, z, z, eye, z, z),
        "position_target_rows": lambda k: k.position_target_rows(*position, z),
        "com_rows": lambda k: k.com_rows(d.A, Q, com.start, views.Jcom, views.com,
                                         views.acom, com.axes, z[:2], z[:2], z[:2], False),
        "posture_error": lambda k: k.posture_error(Q, tasks["posture"].start, state.q,
                                                   robot.q0, w._posture_q),
        "bounds_at": lambda k: k.bounds_at(d.lower, d.upper, state.q, state.v, w._q_index,
                                           lb.limits, lb.bound_params, w._qa),
        "activation_at": lambda k: k.activation_at(d.A, Q, state.q, w._q_index, la.limits,
                                                   la.bound_params, w._qa),
        "region_rows (CoM)": lambda k: k.region_rows(
            d.A, d.lower, d.upper, cr.start, reg.C, views.Jcom, views.com, 1.0, state.v,
            views.acom, reg.lower, reg.upper, reg.y, reg.yd, reg.no_speed_limit,
            reg.horizon, reg.dt, True),
        "acceleration_targets": lambda k: k.acceleration_targets(d.A, d.b, Q, state.v),
        "velocity_targets": lambda k: k.velocity_targets(d.b, Q),
        "state_is_valid": lambda k: k.state_is_valid(state.q, state.v, unit, 1e-6),
    }
    out = {}
    for name, call in calls.items():
        call(k)                                          # warm
        out[name] = min(timeit.timeit(functools.partial(call, k), number=number)
                        / number * 1e9 for _ in range(repeats))
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--calls", action="store_true", help="also each writer's own call")
    args = parser.parse_args(argv)
    for limits in ("none", "bounds"):
        r = time_fencing_rows(args.steps, args.repeats, limits)
        print(f"G1 fencing rows, limits={limits} ({r['rows']} rows): "
              f"{r['write_us']:.2f} µs per step (min of {args.repeats} medians over "
              f"{args.steps} steps)")
    if args.calls:
        for name, ns in writer_calls().items():
            print(f"  {name:22s} {ns:6.0f} ns")


if __name__ == "__main__":
    main()
