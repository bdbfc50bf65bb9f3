"""Per-step cost of writing the G1 fencing rows with :class:`prioik.robots.TaskWriter`.

The fencing scenario's velocity-level rows (support-foot contact, CoM, left-foot pose,
sword-tip position, posture; optionally the joint-limit bounds on ``q̇``) are written
from a ``KinematicState(drift=False)`` computed once, with the references computed
beforehand: what is timed is the writer calls and :meth:`TaskWriter.targets` alone
(the references cost the same in every path). Reported as the minimum over ``repeats``
of the median over ``n_steps`` steps (compile time excluded by a warm-up). ``writers`` picks the compiled row writers the
:class:`~prioik.robots.TaskWriter` calls: the C++ core's (``prioik._core.rows``, what
:mod:`prioik.robots.rows` uses) or numba's kernels (``robots/_rows_kernel.py``, the
oracle they were ported from); :func:`compare_writers` times both interleaved in one
process.

Run: ``python -m prioik.benchmarks.row_writing``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

__all__ = ["time_fencing_rows", "compare_writers"]

WRITERS = ("cpp", "numba")


def time_fencing_rows(n_steps: int = 300, repeats: int = 7, limits: str = "none",
                      seed: int = 0, writers: str = "cpp") -> dict[str, float]:
    """Median per-step time (µs) of writing the G1 fencing rows.

    Args:
        n_steps: Steps per median (the references of ``t = 0, 0.01, ...``).
        repeats: Medians taken; the smallest is reported (the machine is shared).
        limits: ``"none"`` (the five fencing tasks) or ``"bounds"`` (plus the joint-limit
            bounds on ``q̇``).
        seed: Seed of the perturbed standing state.
        writers: ``"cpp"`` or ``"numba"`` (see the module docstring).

    Returns:
        ``{"write_us": ..., "medians_us": [...], "rows": m}``.
    """
    from prioik.robots import rows as rows_module

    if writers not in WRITERS:
        raise ValueError(f"writers must be one of {WRITERS}, got {writers!r}")
    if writers == "numba":
        from prioik.robots import _rows_kernel as kernels
    else:
        from prioik._core import rows as kernels
    chosen, rows_module._k = rows_module._k, kernels
    try:
        return _time_fencing_rows(n_steps, repeats, limits, seed)
    finally:
        rows_module._k = chosen


def _time_fencing_rows(n_steps, repeats, limits, seed) -> dict[str, float]:
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


def compare_writers(n_steps: int = 300, repeats: int = 7, limits: str = "none",
                    seed: int = 0) -> dict[str, float]:
    """:func:`time_fencing_rows` of both row writers, one median of each in turn
    (``repeats`` times): ``{"cpp_us": ..., "numba_us": ..., "ratio": cpp / numba}``,
    each the smallest of its medians."""
    medians = {w: [] for w in WRITERS}
    for _ in range(repeats):
        for w in WRITERS:
            medians[w].append(time_fencing_rows(n_steps, 1, limits, seed, w)["write_us"])
    cpp, numba = min(medians["cpp"]), min(medians["numba"])
    return {"cpp_us": cpp, "numba_us": numba, "ratio": cpp / numba,
            "medians_us": medians}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    for limits in ("none", "bounds"):
        r = compare_writers(args.steps, args.repeats, limits)
        print(f"G1 fencing rows, limits={limits}: C++ {r['cpp_us']:.2f} µs, numba "
              f"{r['numba_us']:.2f} µs per step, C++/numba {r['ratio']:.2f} (min of "
              f"{args.repeats} interleaved medians over {args.steps} steps)")


if __name__ == "__main__":
    main()
