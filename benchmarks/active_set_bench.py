"""Timing of ``hierarchical_active_set`` on the G1 fencing stacks with joint limits as
bounds, cold and warm, beside ``cascaded_qp[daqp]`` and DAQP's raw hierarchical call.

The stacks: the fencing run of :func:`prioik.benchmarks.stacks.g1_fencing_samples`
(each variant), at consecutive simulated steps (``dt = 5 ms``) spread over the run in
``windows`` stretches of ``steps`` steps; at each step the acceleration-level stack with
joint position/velocity limits as bounds on ``q̈`` (``limits="bounds"``) and the
velocity-level stack with bounds on ``q̇``. Every solver gets the same stacks:

* ``active_set cold``: ``prioik.prepare(layout, "hierarchical_active_set",
  warm_start=False).solve(stack)`` (the registry's prepared path);
* ``active_set warm``: the same with ``warm_start=True``, the steps solved in order
  (each solve starts from the previous step's working sets);
* ``daqp raw``: ``daqp.solve(None, None, A, bu, bl, sense, break_points=…)`` alone, on
  arrays built beforehand (:func:`prioik.formulations.daqp_hierarchical.build` without
  level compression, as ``daqp_hierarchical[raw]``);
* ``cascaded_qp[daqp]``: ``prioik.solve(stack, "cascaded_qp", solver="daqp")``.

Times are medians of per-solve ``perf_counter`` wall times (numba compiled beforehand,
BLAS limited to one thread). Exactness: every level's ``‖w_i‖²`` of the active-set
answer against ``cascaded_qp[quadprog]``'s (relative to ``max(1, value)``; where they
differ the lower one at the first differing level is the better answer).

Run: ``python -m prioik.benchmarks.active_set_bench [--windows 4 --steps 6 --repeats 3]``.
"""

from __future__ import annotations

import argparse
import time
from ctypes import c_int
from typing import Any

import numpy as np

NAME = "hierarchical_active_set"


def bounds_stacks(variant: str, windows: int, steps: int, level: str) -> list:
    """Stacks with joint limits as bounds at ``windows × steps`` consecutive steps of
    the fencing run (``level``: ``"acceleration"`` or ``"velocity"``), in time order."""
    from prioik.benchmarks.stacks import g1_fencing_samples
    from prioik.robots.tasks import KinematicState
    run_samples = g1_fencing_samples(variant, 2)
    run, scenario = run_samples.run, run_samples.scenario
    data = scenario.robot.model.createData()
    firsts = np.linspace(0, run.steps - steps, windows).round().astype(int)
    out = []
    for f in firsts:
        for i in range(f, f + steps):
            state = KinematicState(scenario.robot, run.q[i], run.v[i], data)
            t = float(run.t[i])
            if level == "acceleration":
                out.append(scenario.acceleration_stack(state, t, limits="bounds").stack)
            else:
                out.append(scenario.velocity_stack(state, t, limits="bounds").stack)
    return out


def _time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure(stacks: list, repeats: int = 3, cascade_every: int = 1) -> dict[str, Any]:
    """Median per-solve times (s) of each solver on ``stacks`` and the active set's
    agreement with ``cascaded_qp[quadprog]``."""
    import daqp

    import prioik
    from prioik.formulations.daqp_hierarchical import build
    from prioik.hierarchy import lexicographic_residuals

    layout = stacks[0].layout
    same = [s for s in stacks if s.layout == layout]
    cold = prioik.prepare(layout, NAME, warm_start=False)
    warm = prioik.prepare(layout, NAME)
    cold.solve(same[0])                       # numba compiled (cached) before timing
    t_cold = [_time(lambda s=s: cold.solve(s), repeats) for s in same]
    t_warm = []
    for _ in range(repeats):                  # passes over the trajectory, in order
        times = []
        for s in same:
            t0 = time.perf_counter()
            warm.solve(s)
            times.append(time.perf_counter() - t0)
        t_warm.append(times)
    t_warm = np.min(np.array(t_warm), axis=0)
    t_daqp = []
    for s in same:
        A, bu, bl, bps, _ = build(s, False, 1e-9)
        sense = np.zeros(len(bu), dtype=c_int)
        t_daqp.append(_time(lambda: daqp.solve(None, None, A, bu.copy(), bl.copy(), sense,
                                               break_points=bps, primal_tol=1e-10,
                                               dual_tol=1e-12), repeats))
    sub = same[::cascade_every]
    t_cas = [_time(lambda s=s: prioik.solve(s, "cascaded_qp", solver="daqp"), 1) for s in sub]
    worst, statuses, cold_warm = 0.0, set(), 0.0
    for s in same:
        a = cold.solve(s)
        statuses.add(a.status)
        q = prioik.solve(s, "cascaded_qp", solver="quadprog")
        wa = lexicographic_residuals(s, a.x) ** 2
        wq = lexicographic_residuals(s, q.x) ** 2
        worst = max(worst, float(np.max(np.abs(wa - wq) / np.maximum(1.0, wq))))
    for s in same:            # warm vs cold answers along the trajectory
        b = warm.solve(s)
        a = cold.solve(s)
        cold_warm = max(cold_warm, float(np.linalg.norm(a.x - b.x)
                                         / max(1.0, np.linalg.norm(a.x))))
    med = {k: float(np.median(v)) for k, v in (("active_set cold", t_cold),
                                               ("active_set warm", t_warm),
                                               ("daqp raw", t_daqp),
                                               ("cascaded_qp[daqp]", t_cas))}
    return {"stacks": len(same), "n": layout.n, "rows": layout.m, "median_s": med,
            "cold/daqp_raw": med["active_set cold"] / med["daqp raw"],
            "warm/daqp_raw": med["active_set warm"] / med["daqp raw"],
            "warm/cascaded_qp[daqp]": med["active_set warm"] / med["cascaded_qp[daqp]"],
            "cold/cascaded_qp[daqp]": med["active_set cold"] / med["cascaded_qp[daqp]"],
            "max_level_rel_diff_vs_quadprog_cascade": worst, "statuses": sorted(statuses),
            "max_warm_vs_cold_rel": cold_warm}


def run(windows: int = 4, steps: int = 6, repeats: int = 3) -> list[dict[str, Any]]:
    """:func:`measure` on both fencing variants at acceleration and velocity level."""
    from prioik.benchmarks.threads import blas_threads
    out = []
    with blas_threads(1):
        for variant in ("compatible", "incompatible"):
            for level in ("acceleration", "velocity"):
                res = measure(bounds_stacks(variant, windows, steps, level), repeats)
                res.update(variant=variant, level=level)
                out.append(res)
    return out


def format_table(results: list[dict[str, Any]]) -> str:
    head = ("| stacks | n, rows | cold µs | warm µs | DAQP raw µs | cascaded_qp[daqp] µs | "
            "cold/raw | warm/raw | warm/cascade | max Δ‖w‖² vs quadprog cascade |")
    lines = [head, "|" + "---|" * 10]
    for r in results:
        m = r["median_s"]
        lines.append(f"| {r['variant']} {r['level']} ({r['stacks']}) | {r['n']}, {r['rows']} | "
                     f"{m['active_set cold'] * 1e6:.1f} | {m['active_set warm'] * 1e6:.1f} | "
                     f"{m['daqp raw'] * 1e6:.1f} | {m['cascaded_qp[daqp]'] * 1e6:.0f} | "
                     f"{r['cold/daqp_raw']:.2f} | {r['warm/daqp_raw']:.2f} | "
                     f"{r['warm/cascaded_qp[daqp]']:.3f} | "
                     f"{r['max_level_rel_diff_vs_quadprog_cascade']:.1e} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--windows", type=int, default=4, help="stretches of the run")
    p.add_argument("--steps", type=int, default=6, help="consecutive steps per stretch")
    p.add_argument("--repeats", type=int, default=3, help="timing repeats (best of)")
    a = p.parse_args(argv)
    from prioik.extras import MissingExtraError, require
    try:
        require("robots", "qp", what="active_set_bench")
    except MissingExtraError as exc:
        raise SystemExit(f"active_set_bench: error: {exc}") from None
    results = run(a.windows, a.steps, a.repeats)
    print(format_table(results))
    for r in results:
        print(r["variant"], r["level"], "statuses", r["statuses"], "warm vs cold",
              f"{r['max_warm_vs_cold_rel']:.1e}")


if __name__ == "__main__":
    main()
