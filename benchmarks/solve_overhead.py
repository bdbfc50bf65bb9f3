"""What :meth:`PreparedSolver.solve` costs on top of the compiled kernel it calls.

A prepared ``extended_jacobian`` or ``hierarchical_active_set`` solve with a clean
answer is one call of the compiled C++ core (``prioik._core.ExtendedJacobian.solve``;
``ActiveSetSolver.equality_first``, else ``.solve``) plus the Python around it: the
layout check, the one-thread-at-a-time guard, the timing and the
:class:`~prioik.formulations.Solution` (``x``, the residuals and the snapshot its
diagnostics are built from when read). Both are timed here on the same rows,
alternating call by call: ``solver.solve(data)`` (the public call) and the kernel
called directly (the floor; a measurement only) — for the extended Jacobian the
solver's own prepared ``ExtendedJacobian`` writing into arrays allocated once, for the
active set a twin ``ActiveSetSolver`` of the same layout and options that solves the
same sequence, so that its warm start is the solver's. The overhead is the median of
the paired differences (each public call minus the kernel call beside it, the two
taking turns to go first), the lowest over the rounds: the kernel's own time varies by
more than the overhead between rounds on a shared machine, and a difference of two
separately timed medians carried that variation.

Run: ``python -m prioik.benchmarks.solve_overhead`` (the Panda reach and G1 fencing
rows at a few states: ``extended_jacobian`` without limits, ``hierarchical_active_set``
with the joint limits as bounds).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["solve_overhead", "panda_rows", "fencing_rows"]

#: the formulations whose compiled kernel :func:`solve_overhead` can call on its own
KERNELS = ("extended_jacobian", "hierarchical_active_set")


def _extended_jacobian_kernel(solver) -> Callable[[Any], np.ndarray]:
    """The solver's own prepared C++ core, writing into arrays allocated once; returns
    ``x``."""
    core = solver._impl._core
    n, k = solver.layout.n, solver.layout.k
    x, res, ranks = np.empty(n), np.empty(k), np.empty(k, dtype=np.int64)

    def kernel(d) -> np.ndarray:
        if not core.solve(d.A, d.b, d.sqrt_weight, x, res, ranks).clear:
            raise RuntimeError("an answer that is not clear: the solver does more than "
                               "its kernel")
        return x
    return kernel


def _active_set_kernel(solver) -> Callable[[Any], np.ndarray]:
    """A twin of the solver's ``ActiveSetSolver`` (same layout and options) called as the
    plugin calls it on a clean answer (the equality-first try when warm, else the active
    set); returns ``x`` (a view of its result)."""
    from prioik._core import ACTIVE_SET_CODES as codes
    impl = solver._impl
    twin = type(impl)(solver.layout, solver.settings)._cpp
    equality_first, active_set, x = twin.equality_first, twin.solve, twin.x
    try_first = impl._try_first
    not_tried = codes["NOT_TRIED"]
    clean = (codes["SOLVED_CLEAN"], codes["SOLVED_INFEASIBLE"])

    def kernel(d) -> np.ndarray:
        A, b, lower, upper, sw = d.A, d.b, d.lower, d.upper, d.sqrt_weight
        code = equality_first(A, b, lower, upper, sw) if try_first else not_tried
        if code == not_tried:
            code = active_set(A, b, lower, upper, sw)
        if code not in clean:
            raise RuntimeError("an answer that is not clean: the solver does more than "
                               "its kernel")
        return x
    return kernel


def solve_overhead(solver, datas: Sequence, rounds: int = 7, calls: int = 2000
                   ) -> dict[str, Any]:
    """Medians (µs) of ``solver.solve(data)`` and of its compiled kernel alone.

    Args:
        solver: A prepared ``extended_jacobian`` solver on its compiled path, or a
            prepared ``hierarchical_active_set`` solver.
        datas: :class:`~prioik.hierarchy.StackData` of the solver's layout, cycled
            through (the same ones for both calls), each with a clean answer.
        rounds: Rounds (the machine is shared): per figure, the lowest round median
            is kept.
        calls: Paired calls per round.

    Returns:
        ``{"solve_us", "kernel_us", "overhead_us", "rounds", "calls"}``.

    Raises:
        RuntimeError: the solver is not on a compiled path of :data:`KERNELS`, an
            answer is not clean, or the two calls give different answers.
    """
    impl = solver._impl
    if solver.formulation not in KERNELS or not getattr(impl, "compiled", False):
        raise RuntimeError(f"{solver!r} is not on the compiled path of "
                           f"{' or '.join(KERNELS)}")
    floor = (_extended_jacobian_kernel if solver.formulation == "extended_jacobian"
             else _active_set_kernel)(solver)
    for d in datas:                         # the same answers, bit for bit
        if not np.array_equal(floor(d), solver.solve(d).x):
            raise RuntimeError("the kernel and solver.solve disagree")
    N = len(datas)
    clock = time.perf_counter

    def public(i: int) -> None:
        solver.solve(datas[i % N])

    def kernel(i: int) -> None:
        floor(datas[i % N])

    best = {"solve": np.inf, "kernel": np.inf, "overhead": np.inf}
    for _ in range(rounds):
        # the two calls alternate on the same rows, so both see the machine in the same
        # state, and which goes first alternates too (the second finds the rows in the
        # cache); the overhead is the median of their paired differences
        public_s, kernel_s = np.empty(calls), np.empty(calls)
        for i in range(calls):
            odd = i & 1
            first, second = (kernel, public) if odd else (public, kernel)
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


def panda_rows(states: int = 20, seed: int = 0, limits: bool = False) -> tuple[Any, list]:
    """The Panda reach's prepared solver and its rows (:mod:`.panda_step`'s tasks) at
    ``states`` configurations near ``q0``: ``extended_jacobian``, or with ``limits`` the
    joint-limit bounds on ``q̇`` above the hand above the posture and
    ``hierarchical_active_set`` (:mod:`.mink_step`'s Panda reach with limits)."""
    import prioik
    from prioik.robots import KinematicState, TaskWriter, load

    from .panda_step import DT, GAINS, HAND_TARGET
    robot = load("panda")
    rows = TaskWriter(robot, "velocity")
    above = int(limits)
    if limits:
        rows.add_joint_limits("joint_limits", form="bounds", dt=DT, level=0)
    rows.add_frame_position("hand", robot.frames["hand"], gain=GAINS["hand"], level=above)
    rows.add_posture("posture", gain=GAINS["posture"], level=above + 1)
    solver = prioik.prepare(rows.layout, "hierarchical_active_set" if limits
                            else "extended_jacobian")
    rng = np.random.default_rng(seed)
    data, zero, datas = robot.data(), np.zeros(robot.nv), []
    for _ in range(states):
        q = robot.q0 + rng.uniform(-0.1, 0.1, robot.nq)
        state = KinematicState(robot, q, zero, data, drift=False)
        if limits:
            rows.joint_limits(state, "joint_limits")
        rows.frame_position(state, "hand", HAND_TARGET)
        rows.posture(state, "posture", robot.q0)
        datas.append(rows.targets(state).copy())
    return solver, datas


def fencing_rows(states: int = 20, seed: int = 0, limits: bool = False) -> tuple[Any, list]:
    """The G1 fencing step's prepared solver and its velocity rows
    (:meth:`~prioik.robots.fencing.FencingScenario.velocity_rows`, the five tasks of
    :mod:`.placo_step`) at ``states`` perturbed standing states: ``extended_jacobian``,
    or with ``limits`` the joint limits as bounds on ``q̇`` (``limits="bounds"``) and
    ``hierarchical_active_set``."""
    import prioik
    from prioik.robots import KinematicState
    from prioik.robots.fencing import FencingScenario

    from .placo_step import DT, GAIN
    scenario = FencingScenario("compatible")
    robot = scenario.robot
    rows = scenario.velocity_rows(GAIN, limits="bounds" if limits else "none", dt=DT)
    solver = prioik.prepare(rows.layout, "hierarchical_active_set" if limits
                            else "extended_jacobian")
    rng = np.random.default_rng(seed)
    data, datas = robot.data(), []
    for i in range(states):
        q = robot.q0.copy()
        q[7:] += rng.uniform(-0.1, 0.1, robot.nq - 7)
        state = KinematicState(robot, q, np.zeros(robot.nv), data, drift=False)
        datas.append(scenario.write_rows(rows, state, 50 * i * DT).copy())
    return solver, datas


#: the rows :func:`main` times: label, rows function, ``limits``
CASES = (("Panda reach, extended_jacobian", panda_rows, False),
         ("G1 fencing, extended_jacobian", fencing_rows, False),
         ("Panda reach with limits, hierarchical_active_set", panda_rows, True),
         ("G1 fencing with bounds, hierarchical_active_set", fencing_rows, True))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--calls", type=int, default=2000)
    args = parser.parse_args(argv)
    for label, make, limits in CASES:
        r = solve_overhead(*make(limits=limits), rounds=args.rounds, calls=args.calls)
        print(f"{label}: solver.solve {r['solve_us']:.2f} µs, kernel {r['kernel_us']:.2f} µs, "
              f"overhead {r['overhead_us']:.2f} µs (lowest of {args.rounds} round medians "
              f"of {args.calls} paired calls)")


if __name__ == "__main__":
    main()
