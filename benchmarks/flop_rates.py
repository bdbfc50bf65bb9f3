"""Compiled closed-form formulations against the extended Jacobian on the G1 fencing
stacks: per formulation, the median time of a prepared solve on the compiled kernel and
on the readable one, and the flop rate (the kernel's ``sol.detail.flops`` over the compiled
time) relative to the extended Jacobian's. Every solver runs in one process, the stacks
interleaved, one BLAS thread (only ratios measured side by side mean anything).

The rows marked ``[bounds]`` solve the same states' stacks with the joint limits as hard
bounds above every task (``limits="hard_bounds"``, the form ``sns`` takes: its
saturation rounds run); the others take the joint limits as activation rows.

Run: ``python -m prioik.benchmarks.flop_rates [--samples 24] [--repeats 30]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from prioik import formulations
from prioik.threads import blas_threads

from .stacks import g1_fencing_samples

#: formulation → (compiled options, readable options)
KERNELS = {"extended_jacobian": ({"kernel": "cpp"}, {"kernel": "lapack"}),
           "nullspace": ({"kernel": "cpp"}, {"kernel": "numpy"}),
           "nullspace[damped]": ({"kernel": "cpp", "damping": 0.05},
                                 {"kernel": "numpy", "damping": 0.05}),
           "chiaverini": ({"kernel": "cpp"}, {"kernel": "numpy"}),
           "unifying": ({"kernel": "cpp"}, {"kernel": "numpy"}),
           "operational_space": ({"kernel": "cpp"}, {"kernel": "numpy"}),
           "sns": ({"kernel": "cpp"}, {"kernel": "numpy"}),
           "sns[bounds]": ({"kernel": "cpp"}, {"kernel": "numpy"}),
           "reference": ({"kernel": "cpp"}, {"kernel": "numpy"})}


def _solver(label: str, layout, options: dict, mass_matrix: np.ndarray):
    name = label.split("[")[0]
    if formulations.get(name).capabilities.needs_mass_matrix:
        options = dict(options, mass_matrix=mass_matrix)
    return formulations.prepare(layout, name, **options)


def measure(samples: list, repeats: int) -> dict[str, dict[str, float]]:
    """Median µs per solve (compiled, readable) and the median flops, per formulation, over
    ``(stack, M, bounded stack)`` samples (the ``[bounds]`` rows solve the third)."""
    times = {(label, path): [] for label in KERNELS for path in (0, 1)}
    flops = {label: [] for label in KERNELS}
    for stack, mass, bounded in samples:
        chosen = {label: bounded if label.endswith("[bounds]") else stack for label in KERNELS}
        solvers = {(label, path): _solver(label, chosen[label].layout, KERNELS[label][path],
                                          mass)
                   for label in KERNELS for path in (0, 1)}
        for label in KERNELS:
            flops[label].append(solvers[label, 0].solve(chosen[label].data).flops)
        for _ in range(repeats):
            for (label, path), solver in solvers.items():
                data = chosen[label].data
                t0 = time.perf_counter()
                solver.solve(data)
                times[label, path].append(time.perf_counter() - t0)
    return {label: {"cpp_us": 1e6 * float(np.median(times[label, 0])),
                    "readable_us": 1e6 * float(np.median(times[label, 1])),
                    "flops": float(np.median(flops[label]))} for label in KERNELS}


def bounded_stacks(run) -> list:
    """The stacks of ``run``'s sampled states with the joint limits as hard bounds above
    every task (``limits="hard_bounds"``)."""
    from prioik.robots.tasks import KinematicState
    robot, scenario = run.scenario.robot, run.scenario
    data = robot.model.createData()
    return [scenario.acceleration_stack(KinematicState(robot, q, v, data), float(t),
                                        limits="hard_bounds").stack
            for (q, v), t in zip(run.states, run.times, strict=True)]


def table(rows: dict[str, dict[str, float]]) -> str:
    ej = rows["extended_jacobian"]
    ej_rate = ej["flops"] / ej["cpp_us"]
    out = ["| formulation | compiled µs | readable µs | readable / compiled | compiled / EJ "
           "| flops | Mflop/s | rate / EJ's |", "|---|---|---|---|---|---|---|---|"]
    for label, r in rows.items():
        rate = r["flops"] / r["cpp_us"]
        out.append(f"| {label} | {r['cpp_us']:.1f} | {r['readable_us']:.1f} | "
                   f"{r['readable_us'] / r['cpp_us']:.1f} | {r['cpp_us'] / ej['cpp_us']:.2f} | "
                   f"{r['flops']:.0f} | {rate:.0f} | {rate / ej_rate:.2f} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=24, help="states per fencing run")
    parser.add_argument("--repeats", type=int, default=30, help="solves per stack")
    args = parser.parse_args(argv)
    runs = [g1_fencing_samples(v, args.samples) for v in ("compatible", "incompatible")]
    samples = [(s, M, b) for run in runs
               for s, M, b in zip(run.stacks, run.mass_matrices, bounded_stacks(run),
                                  strict=True)]
    with blas_threads(1):
        rows = measure(samples, args.repeats)
    print(f"G1 fencing stacks: {len(samples)} (n = {samples[0][0].n}), {args.repeats} solves "
          f"each, medians")
    print(table(rows))


if __name__ == "__main__":
    main()
