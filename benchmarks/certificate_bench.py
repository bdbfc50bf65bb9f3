"""The tail of a warm ``hierarchical_active_set`` trajectory, and what the certificate of
its flagged steps costs: the core's (``prioik._core.Certificate``, C++) against the
Python oracle (:func:`~prioik.hierarchy.check_lexicographic`) in its place.

Trajectories (each solved warm, in order, by one prepared solver):

* the G1 fencing runs' stacks with joint limits as bounds on ``q̈`` and on ``q̇``
  (:func:`prioik.benchmarks.active_set_bench.bounds_stacks`, both variants, ``steps``
  consecutive steps from the first);
* TALOS balancing while reaching out of reach (velocity level, ``dt`` = 10 ms): level 0
  both feet, the joint-limit bounds and the CoM over the soles
  (:func:`prioik.benchmarks.balance_step.prioik_balance`), level 1 the left hand at a
  target :data:`TALOS_REACH` from its start (beyond the arm), level 2 the posture; its
  stacks are recorded along the closed loop of the core-certified solver.

Per trajectory and certificate, ``rounds`` passes interleaved (per step the fastest;
each pass starts warm, from the trajectory's first stack solved untimed):
the median step, the slowest, their ratio, and the flagged steps (those whose answer is
certified). Then, on the flagged steps' answers, one certificate against the other
(the same data and ``x``; per step the fastest of ``rounds`` calls; the median ratio).

Run: ``OPENBLAS_NUM_THREADS=1 python -m prioik.benchmarks.certificate_bench``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

#: the TALOS hand's target from its start (m): out of reach
TALOS_REACH = np.array([1.5, 0.0, 0.0])


def g1_trajectories(steps: int) -> dict[str, list]:
    """The G1 bounds trajectories: ``name → [StackData, ...]`` (``steps`` each)."""
    from .active_set_bench import bounds_stacks
    out = {}
    for variant in ("compatible", "incompatible"):
        for level in ("acceleration", "velocity"):
            stacks, _ = bounds_stacks(variant, 1, steps, level)
            out[f"G1 bounds {variant} {level}"] = [s.data for s in stacks]
    return out


def talos_trajectory(steps: int) -> list:
    """The TALOS reach's stacks along its closed loop (see the module docstring)."""
    import pinocchio as pin

    from prioik.robots import load

    from .balance_step import DT, REACH, balance_setup, prioik_balance
    robot = load("talos")
    setup = balance_setup(robot)
    setup["target"] = setup["target"] - REACH + TALOS_REACH
    step, writer, _ = prioik_balance(robot, setup)
    q, out = robot.q0.copy(), []
    for _ in range(steps):
        sol = step(q)
        out.append(writer.data.copy())
        q = pin.integrate(robot.model, q, sol.x * DT)
    return out


def _oracle(data, x, minimum_norm):
    """The Python certificate in the solver's place (what the solver ran before)."""
    from prioik.hierarchy import check_lexicographic
    report = check_lexicographic(data, x, minimum_norm=minimum_norm)
    return report.ok, report.first_failure


def _solver(layout, certificate: str, record: list | None = None):
    """A prepared solver whose flagged answers the ``certificate`` (``"cpp"`` or
    ``"python"``) certifies; the certified ``(data, x, minimum_norm)`` appended to
    ``record``."""
    import prioik
    solver = prioik.prepare(layout, "hierarchical_active_set")
    impl = solver._impl
    chain = [impl, impl._refiner(), impl._refiner()._refiner()]
    for part in chain:
        inner = part._certify if certificate == "cpp" else _oracle

        def certify(data, x, minimum_norm, inner=inner):
            if record is not None:
                record.append((data.copy(), x.copy(), minimum_norm))
            return inner(data, x, minimum_norm)
        part._certify = certify
    return solver


def step_times(stacks: list, rounds: int) -> dict[str, Any]:
    """Per certificate, the per-step times (s, fastest of ``rounds`` interleaved warm
    passes; the first stack solved untimed before each pass, as a control loop's last
    step), and the steps it certified."""
    layout = stacks[0].layout
    times = {c: np.full(len(stacks) - 1, np.inf) for c in ("python", "cpp")}
    flagged: list = []
    for r in range(rounds):
        for certificate in ("python", "cpp"):
            # (the certified answers recorded on the first pass, not timed after it)
            record: list | None = [] if r == 0 else None
            solver = _solver(layout, certificate, record)
            solver.solve(stacks[0])
            if record is not None:
                del record[:]
            for i, data in enumerate(stacks[1:]):
                before = len(record) if record is not None else 0
                t0 = time.perf_counter()
                solver.solve(data)
                dt = time.perf_counter() - t0
                times[certificate][i] = min(times[certificate][i], dt)
                if record is not None and certificate == "cpp" and len(record) > before:
                    flagged.append(i)
            if record is not None and certificate == "cpp":
                checks = record
    return {"times": times, "flagged": flagged, "checks": checks}


def certificate_times(checks: list, rounds: int) -> dict[str, float]:
    """The two certificates on the same answers: per check the fastest of ``rounds``;
    their medians (s) and the median of the per-check ratio."""
    import prioik._core as core
    from prioik.hierarchy import DEFAULT_CERTIFICATE_TOL, check_lexicographic
    if not checks:
        return {}
    layout = checks[0][0].layout
    cert = core.Certificate(layout.n, np.ascontiguousarray(layout.starts, dtype=np.int64),
                            np.ascontiguousarray(layout.row_is_equality, dtype=np.int8),
                            DEFAULT_CERTIFICATE_TOL)
    py, cpp, agree = [], [], 0
    for data, x, mn in checks:
        tp = tc = np.inf
        for _ in range(rounds):
            t0 = time.perf_counter()
            ok = check_lexicographic(data, x, minimum_norm=mn).ok
            tp = min(tp, time.perf_counter() - t0)
            t0 = time.perf_counter()
            cert.check(data.A, data.b, data.lower, data.upper, data.sqrt_weight, x, mn)
            tc = min(tc, time.perf_counter() - t0)
        agree += bool(cert.ok) == ok
        py.append(tp)
        cpp.append(tc)
    py, cpp = np.array(py), np.array(cpp)
    return {"python": float(np.median(py)), "cpp": float(np.median(cpp)),
            "ratio": float(np.median(cpp / py)), "checks": len(checks), "agree": agree}


def run(steps: int = 200, talos_steps: int = 300, rounds: int = 3) -> list[dict[str, Any]]:
    """Every trajectory's row (see the module docstring)."""
    from prioik.threads import blas_threads
    rows = []
    with blas_threads(1):
        trajectories = g1_trajectories(steps)
        trajectories["TALOS reach out of reach"] = talos_trajectory(talos_steps)
        for name, stacks in trajectories.items():
            res = step_times(stacks, rounds)
            row = {"name": name, "steps": len(stacks) - 1, "flagged": len(res["flagged"])}
            for c, t in res["times"].items():
                row[c] = {"median": float(np.median(t)), "max": float(t.max()),
                          "ratio": float(t.max() / np.median(t))}
            row["certificate"] = certificate_times(res["checks"], rounds)
            rows.append(row)
    return rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    lines = ["| trajectory | steps | flagged | certificate | median step µs | slowest µs | "
             "slowest / median |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        for c in ("python", "cpp"):
            t = r[c]
            lines.append(f"| {r['name']} | {r['steps']} | {r['flagged']} | {c} | "
                         f"{t['median'] * 1e6:.1f} | {t['max'] * 1e6:.1f} | {t['ratio']:.2f} |")
    lines += ["", "| trajectory | checks | agree | Python µs (median) | C++ µs (median) | "
              "C++ / Python (median) |", "|---|---|---|---|---|---|"]
    for r in rows:
        c = r["certificate"]
        if c:
            lines.append(f"| {r['name']} | {c['checks']} | {c['agree']} | "
                         f"{c['python'] * 1e6:.1f} | {c['cpp'] * 1e6:.1f} | {c['ratio']:.3f} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=200, help="G1 steps per trajectory")
    p.add_argument("--talos-steps", type=int, default=300, help="TALOS closed-loop steps")
    p.add_argument("--rounds", type=int, default=3, help="interleaved timing passes")
    args = p.parse_args(argv)
    print(format_rows(run(args.steps, args.talos_steps, args.rounds)))


if __name__ == "__main__":
    main()
