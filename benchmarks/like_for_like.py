"""The paper's formulations compared like for like: per formulation, the median solve time
on the same G1 fencing stacks, every solver prepared in one process, the stacks and
formulations interleaved, one BLAS thread; its flop count; and the ratios to the extended
Jacobian's beside the paper's per-step ratios (Jeong & Chang 2009, Sec. III-B.3,
:data:`benchmarks.paper.STEP_TIMES_MS`). ``prioik fencing`` measures it
(``run_info.json``'s ``like_for_like``) and the reproduction page shows it.

What enters which column is read from the solvers, not from a list: a formulation is
*compiled* when its prepared solver says so (:attr:`~prioik.PreparedSolver.compiled`) or
its solve reports a flop count (:attr:`~prioik.formulations.Solution.flops`, counted in
the compiled kernel); only
compiled formulations, against a compiled extended Jacobian, get a time ratio (a numpy
formulation's time measures the interpreter, not the formulation), and only those that
count flops get a flop ratio.

Ratios to the extended Jacobian's (``EJ``): time ``t_f / t_EJ``, flops
``F_f / F_EJ``, and the flop rate ``(F_f / t_f) / (F_EJ / t_EJ)`` = flop ratio / time
ratio — the formulations' own cost is the flop ratio; how far the time ratio departs
from it (the rate) is the implementation's and the machine's.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from . import paper

__all__ = ["FORMULATIONS", "BASE", "measure", "ratio_rows", "measure_fencing"]

#: the extended Jacobian, every ratio's denominator
BASE = "extended_jacobian"
#: the formulations measured: the paper's four, then the other closed forms of the
#: registry (only those available here are measured)
FORMULATIONS = (BASE, "nullspace", "unifying", "operational_space", "chiaverini", "sns",
                "reference")


def _prepare(name: str, layout):
    from prioik import formulations
    return formulations.prepare(layout, name)


def measure(samples: list[tuple[Any, np.ndarray]], names: tuple[str, ...] = FORMULATIONS,
            repeats: int = 20) -> dict[str, dict[str, Any]]:
    """Per formulation of ``names`` (in that order, the unavailable ones left out): its
    median solve time over ``samples`` (``(stack, mass_matrix)`` pairs) × ``repeats``,
    every formulation solving each stack in turn; whether it is compiled (see the module
    docstring); its median flop count (``None`` when it does not count them); the
    statuses of its first solves.

    Returns:
        ``{name: {"compiled", "median_solve_s", "flops", "statuses", "solves"}}``.

    Raises:
        ValueError: no sample, or ``repeats < 1``.
    """
    from prioik import formulations
    if not samples:
        raise ValueError("the like-for-like measurement needs at least one stack")
    if repeats < 1:
        raise ValueError(f"repeats must be ≥ 1, got {repeats}")
    available = {info.name for info in formulations.available()}
    names = tuple(n for n in names if n in available)
    needs_mass = {n: formulations.get(n).capabilities.needs_mass_matrix for n in names}
    times: dict[str, list[float]] = {n: [] for n in names}
    flops: dict[str, list[float]] = {n: [] for n in names}
    compiled = dict.fromkeys(names, False)
    statuses: dict[str, dict[str, int]] = {n: {} for n in names}
    for stack, mass in samples:
        data = stack.data
        solvers = {n: _prepare(n, stack.layout) for n in names}
        step = {n: ({"mass_matrix": mass} if needs_mass[n] else {}) for n in names}
        for n, solver in solvers.items():        # untimed: the counts and statuses
            sol = solver.solve(data, **step[n])
            statuses[n][sol.status] = statuses[n].get(sol.status, 0) + 1
            count = sol.flops
            if count is not None:
                flops[n].append(float(count))
            compiled[n] = compiled[n] or bool(solver.compiled) or count is not None
        for _ in range(repeats):
            for n, solver in solvers.items():
                t0 = time.perf_counter()
                solver.solve(data, **step[n])
                times[n].append(time.perf_counter() - t0)
    return {n: {"compiled": compiled[n], "median_solve_s": float(np.median(times[n])),
                "flops": float(np.median(flops[n])) if flops[n] else None,
                "statuses": statuses[n], "solves": len(times[n])} for n in names}


def ratio_rows(measured: dict[str, dict[str, Any]],
               paper_ms: dict[str, float] | None = None) -> list[dict[str, Any]]:
    """The like-for-like table's rows, one per measured formulation (in ``measured``'s
    order): ``formulation``, ``paper_name`` (``""`` where the paper did not run it),
    ``paper_ratio`` (its per-step time over the extended Jacobian's), ``compiled``,
    ``time_s``, ``flops``, ``time_ratio`` (compiled formulation and compiled extended
    Jacobian only), ``flop_ratio`` (both count flops) and ``rate_ratio`` (flop ratio /
    time ratio: its flops per second relative to the extended Jacobian's); ``None``
    where a ratio does not apply.

    Raises:
        ValueError: ``measured`` has no extended Jacobian row.
    """
    paper_ms = paper.STEP_TIMES_MS if paper_ms is None else paper_ms
    base = measured.get(BASE)
    if base is None:
        raise ValueError(f"the like-for-like ratios are to {BASE!r}, which was not measured")
    rows = []
    for name, m in measured.items():
        time_ratio = flop_ratio = rate_ratio = None
        if m["compiled"] and base["compiled"] and base["median_solve_s"] > 0:
            time_ratio = m["median_solve_s"] / base["median_solve_s"]
        if m["flops"] is not None and base["flops"]:
            flop_ratio = m["flops"] / base["flops"]
        if time_ratio and flop_ratio is not None:
            rate_ratio = flop_ratio / time_ratio
        in_paper = name in paper_ms and BASE in paper_ms
        rows.append({"formulation": name,
                     "paper_name": paper.METHOD_NAMES.get(name, name) if in_paper else "",
                     "paper_ratio": paper_ms[name] / paper_ms[BASE] if in_paper else None,
                     "compiled": m["compiled"], "time_s": m["median_solve_s"],
                     "flops": m["flops"], "time_ratio": time_ratio,
                     "flop_ratio": flop_ratio, "rate_ratio": rate_ratio})
    return rows


def measure_fencing(variants: list[str], samples: int = 16, repeats: int = 20
                    ) -> dict[str, Any]:
    """:func:`measure` on the G1 fencing stacks of ``variants``
    (:func:`~prioik.benchmarks.stacks.g1_fencing_samples`: ``samples`` states of each
    variant's driven run, each with its mass matrix), one BLAS thread; returns
    ``{"stacks", "n", "repeats", "variants", "measured"}`` for ``run_info.json``.

    Raises:
        ValueError: ``samples < 1`` or ``repeats < 1``.
    """
    from prioik.threads import blas_threads

    from .stacks import g1_fencing_samples
    if samples < 1:
        raise ValueError(f"samples must be ≥ 1, got {samples}")
    pairs = []
    for variant in variants:
        run = g1_fencing_samples(variant, samples)
        pairs += list(zip(run.stacks, run.mass_matrices, strict=True))
    with blas_threads(1):
        measured = measure(pairs, FORMULATIONS, repeats)
    return {"stacks": len(pairs), "n": pairs[0][0].n, "repeats": repeats,
            "variants": list(variants), "measured": measured}
