"""What :meth:`PreparedSolver.solve` costs on top of the compiled kernel it calls.

A prepared ``extended_jacobian`` solve is one call of the compiled C++ core
(``prioik._core.ExtendedJacobian.solve``, ``core/src/extended_jacobian.cpp``) plus the
Python around it: the layout check, the one-thread-at-a-time guard, the timing and the
:class:`~prioik.formulations.Solution` (the plugin's ``Outcome``, ``info``, residuals).
Both are timed here on the same rows, alternating call by call: ``solver.solve(data)``
(the public call) and the core called directly, the solver's own prepared
``ExtendedJacobian`` writing into arrays allocated once (the floor; a measurement only). The
overhead is
the median of the paired differences (each public call minus the kernel call beside
it, the two taking turns to go first), the lowest over the rounds: the kernel's own time varies by
more than the
overhead between rounds on a shared machine, and a difference of two separately timed
medians carried that variation.

Run: ``python -m prioik.benchmarks.solve_overhead`` (the Panda reach and G1 fencing
rows at a few states).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["solve_overhead", "panda_rows", "fencing_rows"]


def solve_overhead(solver, datas: Sequence, rounds: int = 7, calls: int = 2000
                   ) -> dict[str, Any]:
    """Medians (µs) of ``solver.solve(data)`` and of its compiled kernel alone.

    Args:
        solver: A prepared ``extended_jacobian`` solver on its compiled path.
        datas: :class:`~prioik.hierarchy.StackData` of the solver's layout, cycled
            through (the same ones for both calls).
        rounds: Rounds (the machine is shared): per figure, the lowest round median
            is kept.
        calls: Paired calls per round.

    Returns:
        ``{"solve_us", "kernel_us", "overhead_us", "rounds", "calls"}``.

    Raises:
        RuntimeError: the solver is not on the compiled path, or the two calls give
            different answers.
    """
    impl = solver._impl
    if solver.formulation != "extended_jacobian" or not getattr(impl, "compiled", False):
        raise RuntimeError(f"{solver!r} is not on the compiled extended_jacobian path")
    core = impl._core                       # the prepared C++ solver the plugin calls
    n, k = solver.layout.n, solver.layout.k
    x, res, ranks = np.empty(n), np.empty(k), np.empty(k, dtype=np.int64)
    for d in datas:                         # the same answers, bit for bit
        result = core.solve(d.A, d.b, d.sqrt_weight, x, res, ranks)
        if not result.clear or not np.array_equal(x, solver.solve(d).x):
            raise RuntimeError("the kernel and solver.solve disagree")
    N = len(datas)
    clock = time.perf_counter

    def public(i: int) -> None:
        solver.solve(datas[i % N])

    def floor(i: int) -> None:
        d = datas[i % N]
        core.solve(d.A, d.b, d.sqrt_weight, x, res, ranks)

    best = {"solve": np.inf, "kernel": np.inf, "overhead": np.inf}
    for _ in range(rounds):
        # the two calls alternate on the same rows, so both see the machine in the same
        # state, and which goes first alternates too (the second finds the rows in the
        # cache); the overhead is the median of their paired differences
        public_s, kernel_s = np.empty(calls), np.empty(calls)
        for i in range(calls):
            odd = i & 1
            first, second = (floor, public) if odd else (public, floor)
            t0 = clock()
            first(i)
            t1 = clock()
            second(i)
            t2 = clock()
            public_s[i], kernel_s[i] = (t2 - t1, t1 - t0) if odd else (t1 - t0, t2 - t1)
        best["solve"] = min(best["solve"], float(np.median(public_s)))
        best["kernel"] = min(best["kernel"], float(np.median(kernel_s)))
        best["overhead"] = min(best["overhead"], float(np.median(public_s - kernel_s)))
    return {"solve_us": best["solve"] * 1e6, "kernel_us": best["kernel"] * 1e6,
            "overhead_us": best["overhead"] * 1e6, "rounds": rounds, "calls": calls}


def panda_rows(states: int = 20, seed: int = 0) -> tuple[Any, list]:
    """The Panda reach's prepared solver and its rows (:mod:`.panda_step`'s tasks) at
    ``states`` configurations near ``q0``."""
    import prioik
    from prioik.robots import KinematicState, TaskWriter, load

    from .panda_step import GAINS, HAND_TARGET
    robot = load("panda")
    rows = TaskWriter(robot, "velocity")
    rows.add_frame_position("hand", robot.frames["hand"], gain=GAINS["hand"], level=0)
    rows.add_posture("posture", gain=GAINS["posture"], level=1)
    solver = prioik.prepare(rows.layout, "extended_jacobian")
    rng = np.random.default_rng(seed)
    data, zero, datas = robot.data(), np.zeros(robot.nv), []
    for _ in range(states):
        q = robot.q0 + rng.uniform(-0.1, 0.1, robot.nq)
        state = KinematicState(robot, q, zero, data, drift=False)
        rows.frame_position(state, "hand", HAND_TARGET)
        rows.posture(state, "posture", robot.q0)
        datas.append(rows.targets(state).copy())
    return solver, datas


def fencing_rows(states: int = 20, seed: int = 0) -> tuple[Any, list]:
    """The G1 fencing step's prepared solver and its velocity rows
    (:meth:`~prioik.robots.fencing.FencingScenario.velocity_rows`, the five tasks of
    :mod:`.placo_step`) at ``states`` perturbed standing states."""
    import prioik
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario

    from .placo_step import DT, GAIN
    scenario = FencingScenario("compatible")
    robot = scenario.robot
    rows = scenario.velocity_rows(GAIN)
    solver = prioik.prepare(rows.layout, "extended_jacobian")
    rng = np.random.default_rng(seed)
    data, datas = robot.data(), []
    for i in range(states):
        q = robot.q0.copy()
        q[7:] += rng.uniform(-0.1, 0.1, robot.nq - 7)
        state = KinematicState(robot, q, np.zeros(robot.nv), data, drift=False)
        datas.append(scenario.write_rows(rows, state, 50 * i * DT).copy())
    return solver, datas


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--calls", type=int, default=2000)
    args = parser.parse_args(argv)
    for label, make in (("Panda reach", panda_rows), ("G1 fencing", fencing_rows)):
        r = solve_overhead(*make(), rounds=args.rounds, calls=args.calls)
        print(f"{label}: solver.solve {r['solve_us']:.2f} µs, kernel {r['kernel_us']:.2f} µs, "
              f"overhead {r['overhead_us']:.2f} µs (lowest of {args.rounds} round medians "
              f"of {args.calls} paired calls)")


if __name__ == "__main__":
    main()
