"""The tables of ``prioik bench``: every variant timed on every case.

Per case (a set of stacks, :mod:`prioik.benchmarks.stacks`) and per variant of the
``bench`` report (:func:`prioik.benchmarks.variants.table`: one row per back-end of the
formulations that have several, and the rows plugins declare for ``bench``): the timed
loop of :func:`prioik.benchmarks.timing.timed_calls`, each solve through a solver
prepared once per layout (:func:`prioik.prepare`, the path a control loop runs), then
per row:

* **success**: status not ``"failed"`` and, at every level, the residual
  ``‖A_i x − b_i‖`` within ``SUCCESS_TOL · max(1, ‖b_i‖)`` of ``reference``'s (the same
  lexicographic optimum values, level by level);
* **distance**: ``‖x − x_ref‖ / max(1, ‖x_ref‖)`` (median and max over the solves),
  with ``x_ref`` from ``reference`` — with ``metric=M`` for formulations that take a
  mass matrix (their remaining freedom is fixed by ``θ̈ᵀ M θ̈``).

A variant over the time cap on a smaller random case is not tried on larger ones, nor
one whose p90 there (≥ 5 ms a solve) scaled by ``(n ratio)³`` exceeds four caps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from prioik import formulations
from prioik.benchmarks.progress import Progress
from prioik.benchmarks.results import TimingRow
from prioik.benchmarks.stacks import Case, random_case
from prioik.benchmarks.timing import percentile, timed_calls
from prioik.benchmarks.variants import Variant, capabilities
from prioik.formulations.registry import check_support
from prioik.hierarchy import TaskStack, UnsupportedTaskError, relative_distance

from .settings import SUCCESS_TOL, Settings

__all__ = ["References", "references", "time_case", "prewarm", "measure_tables"]


@dataclass
class References:
    """``reference``'s answers to a case's stacks (and with ``metric=M``)."""

    x: list[np.ndarray]
    residuals: list[np.ndarray]
    x_metric: list[np.ndarray | None]


def references(case: Case, with_metric: bool) -> References:
    """Solve every stack of ``case`` with ``reference`` (and ``metric=M``)."""
    xs, res, xm = [], [], []
    for stack, M in zip(case.stacks, case.mass_matrices, strict=False):
        sol = formulations.solve(stack, "reference")
        xs.append(sol.x)
        res.append(sol.residuals)
        xm.append(formulations.solve(stack, "reference", metric=M).x if with_metric else None)
    return References(xs, res, xm)


def _scales(stack: TaskStack) -> np.ndarray:
    return np.array([max(1.0, float(np.linalg.norm(level.b))) for level in stack.levels])


def _row(case: Case, v: Variant, **kw) -> TimingRow:
    return TimingRow(case.suite, case.name, case.n, case.k, case.rows, v.label,
                     v.formulation, v.backend, v.options_text(), **kw)


def time_case(case: Case, variant: Variant, ref: References, settings: Settings
              ) -> TimingRow:
    """Time ``variant`` on ``case`` under the settings' budget, cycling over the stacks."""
    row = _row(case, variant)
    try:
        check_support(variant.formulation, capabilities(variant.formulation), case.stacks[0])
    except UnsupportedTaskError as exc:
        row.status, row.note = "unsupported", str(exc)
        return row
    solvers = {}      # the path a control loop runs: one prepared solver per layout
    mass = variant.needs_mass_matrix

    def run(i: int):
        stack = case.stacks[i]
        solver = solvers.get(stack.layout)
        if solver is None:
            solver = solvers[stack.layout] = formulations.prepare(
                stack.layout, variant.formulation, **variant.options)
        if mass:
            return solver.solve(stack, mass_matrix=case.mass_matrices[i])
        return solver.solve(stack)

    timed = timed_calls(run, len(case.stacks), settings.budget)
    row.status, row.note, row.probe_s = timed.status, timed.note, timed.probe_s
    if timed.status == "skipped":
        return row
    scales = [_scales(s) for s in case.stacks]
    ok, dist = [], []
    for i, sol in timed.results:
        xr = ref.x_metric[i] if mass else ref.x[i]
        if sol.ok:
            dist.append(relative_distance(sol.x, xr))
            ok.append(bool(np.all(np.abs(sol.residuals - ref.residuals[i])
                                  <= SUCCESS_TOL * scales[i])))
        else:
            ok.append(False)
    times = timed.times
    row.repeats = timed.repeats
    row.median_us = float(np.median(times)) * 1e6
    row.p10_us = percentile(times, 10) * 1e6
    row.p90_us = percentile(times, 90) * 1e6
    verify = np.array([sol.verify_time_s for _, sol in timed.results])
    if verify.size and (verify > 0).any():
        row.verify_median_us = float(np.median(verify)) * 1e6
    row.success_rate = float(np.mean(ok)) if ok else math.nan
    finite = np.array([d for d in dist if np.isfinite(d)])
    row.dist_median = float(np.median(finite)) if finite.size else math.nan
    row.dist_max = float(finite.max()) if finite.size else math.nan
    return row


def prewarm(variants: list[Variant]) -> None:
    """Solve one tiny stack with every variant (imports, JIT compilation, caches), so
    that no case pays for them."""
    case = random_case(6, 2, samples=1)
    for v in variants:
        opts = dict(v.options)
        if v.needs_mass_matrix:
            opts["mass_matrix"] = case.mass_matrices[0]
        try:
            formulations.solve(case.stacks[0], v.formulation, **opts)
        except UnsupportedTaskError:
            pass


def measure_tables(cases: list[Case], variants: list[Variant], settings: Settings,
                   progress: Progress | None = None) -> list[TimingRow]:
    """One :class:`~prioik.benchmarks.results.TimingRow` per (case, variant), with the
    skip rules of the module docstring; a plugin that raises gives an ``error`` row
    and the run goes on."""
    prewarm(variants)
    rows: list[TimingRow] = []
    too_slow: dict[str, list[tuple[int, int, str]]] = {}
    observed: dict[str, list[tuple[int, int, float, str]]] = {}
    with_metric = any(v.needs_mass_matrix for v in variants)
    for case in cases:
        ref = references(case, with_metric)
        for v in variants:
            if progress is not None:
                progress.step(f"{case.name}: {v.label}")
            smaller = [c for (n, k, c) in too_slow.get(v.label, [])
                       if case.suite == "random" and n <= case.n and k <= case.k]
            if smaller:
                rows.append(_row(case, v, status="skipped",
                                 note=f"not tried: over the cap already at {smaller[0]}"))
                continue
            # O(n³) from a smaller case where the arithmetic dominates (≥ 5 ms a solve)
            guess = [(t * (case.n / n) ** 3, c) for (n, k, t, c) in observed.get(v.label, [])
                     if case.suite == "random" and n < case.n and k <= case.k and t >= 5e-3]
            if guess and max(guess)[0] > 4 * settings.cap_s:
                t, c = max(guess)
                rows.append(_row(case, v, status="skipped",
                                 note=f"not tried: one solve predicted at {t:.1f} s > 4·cap "
                                      f"= {4 * settings.cap_s:g} s (p90 at {c} × (n ratio)³)"))
                too_slow.setdefault(v.label, []).append((case.n, case.k, case.name))
                continue
            try:
                row = time_case(case, v, ref, settings)
            except Exception as exc:  # noqa: BLE001 - one plugin's bug must not end the run
                row = _row(case, v, status="error", note=f"{type(exc).__name__}: {exc}"[:300])
            if case.suite == "random":
                if row.status == "skipped":
                    too_slow.setdefault(v.label, []).append((case.n, case.k, case.name))
                t = row.p90_us * 1e-6 if math.isfinite(row.p90_us) else row.probe_s
                if math.isfinite(t):
                    observed.setdefault(v.label, []).append((case.n, case.k, t, case.name))
            rows.append(row)
    return rows
