"""``solve_batch`` of many G1 stacks of one shape against single solves."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from prioik import formulations
from prioik.benchmarks.progress import Progress
from prioik.benchmarks.stacks import FencingSamples, same_shape_batch
from prioik.benchmarks.variants import Variant

from .settings import Settings

__all__ = ["batched_formulations", "measure_batch"]


def batched_formulations() -> list[str]:
    """The available formulations with a batched kernel of their own
    (:attr:`~prioik.formulations.contract.Formulation.batched`) that need no mass
    matrix."""
    out = []
    for info in formulations.available():
        if not info.available or (info.capabilities and info.capabilities.needs_mass_matrix):
            continue
        if formulations.get(info.name).batched:
            out.append(info.name)
    return out


def measure_batch(runs: list[FencingSamples], settings: Settings, singles: list[Variant],
                  loops: tuple[str, ...] = ("extended_jacobian",),
                  progress: Progress | None = None) -> dict[str, Any]:
    """``solve_batch`` of ``batch_size`` G1 stacks of one shape against single solves.

    Per-stack times (µs): the ``solve_batch`` of every formulation with a batched kernel
    (:func:`batched_formulations`; median over ``batch_rounds`` calls, and whether its
    own batched kernel ran), a loop of ``formulations.solve`` over the same stacks for
    each of ``loops`` (wall time per stack, what a user writes without the batch), and
    the median single solve (``Solution.time_s``) of each of ``singles`` on the first
    200 stacks.
    """
    per_run = -(-settings.batch_size // max(1, len(runs)))
    stacks_all = [s for run in runs for s in run.stacks_at(per_run)]
    batch, note = same_shape_batch(stacks_all, settings.batch_size)
    out: dict[str, Any] = {"size": len(batch), "note": note, "n": batch[0].n,
                           "rows": sum(lvl.m for lvl in batch[0].levels),
                           "k": len(batch[0]), "batch_us": {}, "batched": {},
                           "loop_us": {}, "single_us": {}}
    for name in batched_formulations():
        times = []
        res = None
        for _ in range(max(1, settings.batch_rounds)):
            res = formulations.solve_batch(batch, name)
            times.append(res.time_per_stack_s)
        out["batch_us"][name] = float(np.median(times)) * 1e6
        out["batched"][name] = bool(res.batched)
        if progress:
            progress.step(f"batch: solve_batch {name}")
    available = {f.name for f in formulations.available() if f.available}
    for name in loops:
        if name in available:
            t0 = time.perf_counter()
            for s in batch:
                formulations.solve(s, name)
            out["loop_us"][name] = (time.perf_counter() - t0) / len(batch) * 1e6
    sub = batch[:200]
    for v in singles:
        for s in sub[:5]:
            formulations.solve(s, v.formulation, **v.options)
        out["single_us"][v.label] = float(np.median(
            [formulations.solve(s, v.formulation, **v.options).time_s for s in sub])) * 1e6
    if progress:
        progress.step("batch: loops and single solves")
    return out
