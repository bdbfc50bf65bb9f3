"""``prioik bench``: time every formulation and back-end on G1 fencing and random stacks.

In one process, per case (a set of stacks) and per formulation variant (one row per
back-end of formulations that have ``backends()``): a few warm-up solves, then
``--repeats`` (default 200) timed solves cycling over the case's stacks, each through a
solver prepared once per layout (:func:`prioik.prepare`, the path a control loop
runs). The time of a solve is :attr:`formulations.Solution.time_s` —
``time.perf_counter`` around the plugin's solve alone (option checks happen at prepare;
the residual evaluation is outside it). Each row reports the median, p10 and p90 of those times, the success
rate and the distance to ``reference``:

* **success**: status not ``"failed"`` and, at every level, the residual
  ``‖A_i x − b_i‖`` within ``1e-6 · max(1, ‖b_i‖)`` of ``reference``'s (the same
  lexicographic optimum values, level by level);
* **distance**: ``‖x − x_ref‖ / max(1, ‖x_ref‖)`` (median and max over the solves),
  with ``x_ref`` from ``reference`` — with ``metric=M`` for formulations that take a
  mass matrix (their remaining freedom is fixed by ``θ̈ᵀ M θ̈``).

A row whose estimated time exceeds the per-case cap (``--cap`` seconds of timed
solves) gets fewer repeats (status ``reduced``, the count is in the row); one whose
single solve exceeds ``cap / min_repeats`` is not timed (status ``skipped``).

Then, from the same run, the ratios the benchmark issue names (see :func:`ratios`),
the batch experiment (:func:`measure_batch`), the whole G1 IK step against PlaCo
(:func:`measure_ik_step`) and the paper's per-control-step comparison
(:func:`measure_control_step`). Outputs in ``--out``: ``results.csv``, ``results.md``,
``summary.json``, ``time_vs_n.png``, ``time_vs_k.png``; ``--doc FILE`` also writes the
documentation page.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from prioik import formulations
from prioik.formulations.registry import check_support
from prioik.hierarchy import TaskStack, UnsupportedTaskError, relative_distance

from .threads import blas_info, blas_threads
from .stacks import (G1_DURATION_S, Case, FencingSamples, g1_fencing_cases, random_case,
                     same_shape_batch)

#: ``n`` and ``k`` of the random cases (default and ``--quick``)
SIZES = (12, 35, 100, 300)
LEVELS = (2, 4, 8, 16)
QUICK_SIZES = (12, 100)
QUICK_LEVELS = (2, 16)

#: extra rows beside each formulation's defaults: (formulation, label suffix, options)
EXTRA_VARIANTS = (
    ("extended_jacobian", "svd", {"nullspace": "svd"}),
    ("extended_jacobian", "lapack", {"kernel": "lapack"}),
    # DAQP's C call alone: no SVD compression of the levels, no conflicting-level check
    ("daqp_hierarchical", "raw", {"compress_levels": False, "check": False}),
)
#: residual tolerance of the success test (relative to max(1, ‖b_i‖))
SUCCESS_TOL = 1e-6

CSV_COLUMNS = ("suite", "case", "n", "k", "rows", "label", "formulation", "backend",
               "options", "repeats", "median_us", "p10_us", "p90_us", "success_rate",
               "dist_median", "dist_max", "status", "note")


@dataclass(frozen=True)
class Variant:
    """A formulation with fixed options, one row of every table.

    Attributes:
        label: Row name, e.g. ``"nullspace"``, ``"cascaded_qp[daqp]"``.
        formulation: Registry name.
        options: Options passed to every solve.
        backend: The back-end, for formulations that have several.
        needs_mass_matrix: Gets ``mass_matrix=M`` of the case.
        capabilities: The formulation's :class:`~formulations.Capabilities`.
    """

    label: str
    formulation: str
    options: dict = field(default_factory=dict, hash=False)
    backend: str = ""
    needs_mass_matrix: bool = False
    capabilities: Any = field(default=None, hash=False)


@dataclass
class Row:
    """One variant timed on one case (one CSV line; times in µs)."""

    suite: str
    case: str
    n: int
    k: int
    rows: int
    label: str
    formulation: str
    backend: str
    options: str
    repeats: int = 0
    median_us: float = math.nan
    p10_us: float = math.nan
    p90_us: float = math.nan
    success_rate: float = math.nan
    dist_median: float = math.nan
    dist_max: float = math.nan
    status: str = "ok"
    note: str = ""
    probe_s: float = math.nan     # a skipped row's measured solve (not in the CSV)


@dataclass
class Settings:
    """What a run measures (``--quick`` shrinks it)."""

    sizes: tuple[int, ...] = SIZES
    levels: tuple[int, ...] = LEVELS
    repeats: int = 200
    min_repeats: int = 10
    warmup: int = 3
    cap_s: float = 1.5
    samples: int = 8
    g1_samples: int = 24
    family: str = "conflicting"
    batch_size: int = 1000
    batch_rounds: int = 5
    control_duration_s: float = 1.0
    ik_steps: int = 300
    only: tuple[str, ...] = ()
    g1: bool = True
    blas_threads: int = 1
    quick: bool = False


def quick_settings() -> Settings:
    """The ``--quick`` run (under a minute): fewer cases, repeats and samples."""
    return Settings(sizes=QUICK_SIZES, levels=QUICK_LEVELS, repeats=30, min_repeats=5,
                    warmup=1, cap_s=0.15, samples=4, g1_samples=6, batch_size=1000,
                    batch_rounds=2, control_duration_s=0.1, ik_steps=50, quick=True)


# --------------------------------------------------------------------- progress
class Progress:
    """A progress bar on stderr (one line, redrawn; plain lines when not a terminal)."""

    def __init__(self, total: int, stream=None) -> None:
        self.total = max(1, total)
        self.done = 0
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = time.perf_counter()

    def step(self, what: str, advance: int = 1) -> None:
        self.done = min(self.total, self.done + advance)
        frac = self.done / self.total
        bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
        line = (f"[{bar}] {self.done}/{self.total} {time.perf_counter() - self.t0:6.1f}s "
                f"{what}")
        if self.tty:
            self.stream.write("\r" + line[:120].ljust(120))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def message(self, text: str) -> None:
        self.stream.write(("\n" if self.tty else "") + text + "\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()


# --------------------------------------------------------------------- variants
def variants(only: tuple[str, ...] = ()) -> tuple[list[Variant], list[str]]:
    """Every available formulation with its default options, one variant per back-end
    (``solver=``) for those that have several, and :data:`EXTRA_VARIANTS`.

    Returns:
        The variants and, for each unavailable formulation, why not.
    """
    out, unavailable = [], []
    for info in formulations.available():
        if only and info.name not in only:
            continue
        if not info.available:
            unavailable.append(f"{info.name}: {info.reason}")
            continue
        needs_m = bool(info.capabilities and info.capabilities.needs_mass_matrix)
        if info.backends and "solver" in info.options:
            for b in info.backends:
                out.append(Variant(f"{info.name}[{b}]", info.name, {"solver": b}, b, needs_m,
                                   info.capabilities))
        else:
            out.append(Variant(info.name, info.name, {}, "", needs_m, info.capabilities))
        for name, suffix, opts in EXTRA_VARIANTS:
            if name == info.name and set(opts) <= set(info.options):
                out.append(Variant(f"{name}[{suffix}]", name, dict(opts), "", needs_m,
                                   info.capabilities))
    return out, unavailable


# ----------------------------------------------------------------------- timing
@dataclass
class _Reference:
    x: list[np.ndarray]
    residuals: list[np.ndarray]
    x_metric: list[np.ndarray | None]


def _references(case: Case, with_metric: bool) -> _Reference:
    xs, res, xm = [], [], []
    for stack, M in zip(case.stacks, case.mass_matrices):
        sol = formulations.solve(stack, "reference")
        xs.append(sol.x)
        res.append(sol.residuals)
        xm.append(formulations.solve(stack, "reference", metric=M).x if with_metric else None)
    return _Reference(xs, res, xm)


def _percentile(values: np.ndarray, q: float) -> float:
    return float(np.percentile(values, q)) if values.size else math.nan


def _scales(stack: TaskStack) -> np.ndarray:
    return np.array([max(1.0, float(np.linalg.norm(level.b))) for level in stack.levels])


def time_case(case: Case, variant: Variant, ref: _Reference, settings: Settings) -> Row:
    """Time ``variant`` on ``case``: warm-up, then up to ``settings.repeats`` timed
    solves (fewer when they would exceed ``settings.cap_s``), cycling over the stacks."""
    row = Row(case.suite, case.name, case.n, case.k, case.rows, variant.label,
              variant.formulation, variant.backend,
              " ".join(f"{k}={v}" for k, v in variant.options.items()))
    try:
        check_support(variant.formulation, variant.capabilities, case.stacks[0])
    except UnsupportedTaskError as exc:
        row.status, row.note = "unsupported", str(exc)
        return row
    S = len(case.stacks)
    scales = [_scales(s) for s in case.stacks]

    solvers = {}      # the path a control loop runs: one prepared solver per layout

    def run(i: int):
        stack = case.stacks[i]
        solver = solvers.get(stack.layout)
        if solver is None:
            solver = solvers[stack.layout] = formulations.prepare(
                stack.layout, variant.formulation, **variant.options)
        if variant.needs_mass_matrix:
            return solver.solve(stack, mass_matrix=case.mass_matrices[i])
        return solver.solve(stack)

    first = run(0)                     # untimed for the decision: imports, JIT, caches
    if first.time_s > settings.cap_s:
        row.status = "skipped"
        row.note = f"one solve took {first.time_s * 1e3:.0f} ms > cap {settings.cap_s:g} s"
        row.probe_s = first.time_s
        return row
    warm: list[float] = []
    for i in range(1, max(2, settings.warmup + 1)):
        warm.append(run(i % S).time_s)
        if sum(warm) > settings.cap_s:
            break
    budget_one = 2 * settings.cap_s / settings.min_repeats
    if min(warm) > budget_one:
        row.status = "skipped"
        row.note = (f"one solve takes {min(warm) * 1e3:.0f} ms > 2·cap/min_repeats = "
                    f"{budget_one * 1e3:.0f} ms")
        row.probe_s = min(warm)
        return row
    estimate = float(np.median(warm))
    repeats = settings.repeats
    if estimate * repeats > settings.cap_s:
        repeats = max(settings.min_repeats, int(settings.cap_s / max(estimate, 1e-9)))
        if repeats < settings.repeats:
            row.status = "reduced"
            row.note = (f"{repeats} repeats instead of {settings.repeats} "
                        f"(≈{estimate * 1e3:.1f} ms per solve, cap {settings.cap_s:g} s)")
    times = np.empty(repeats)
    ok = np.zeros(repeats, dtype=bool)
    dist = np.full(repeats, np.nan)
    spent, done = 0.0, 0
    for r in range(repeats):
        if spent > 2 * settings.cap_s:        # a few solves far slower than the estimate
            row.status = "reduced"
            row.note = (f"stopped after {r} of {repeats} repeats: {spent:.1f} s > twice "
                        f"the cap {settings.cap_s:g} s (some solves are much slower)")
            break
        i = r % S
        sol = run(i)
        times[r] = sol.time_s
        spent += sol.time_s
        done = r + 1
        xr = ref.x_metric[i] if variant.needs_mass_matrix else ref.x[i]
        if sol.ok:
            dist[r] = relative_distance(sol.x, xr)
            ok[r] = bool(np.all(np.abs(sol.residuals - ref.residuals[i])
                                <= SUCCESS_TOL * scales[i]))
    times, ok, dist = times[:done], ok[:done], dist[:done]
    row.repeats = done
    row.median_us = float(np.median(times)) * 1e6
    row.p10_us = _percentile(times, 10) * 1e6
    row.p90_us = _percentile(times, 90) * 1e6
    row.success_rate = float(ok.mean())
    finite = dist[np.isfinite(dist)]
    row.dist_median = float(np.median(finite)) if finite.size else math.nan
    row.dist_max = float(finite.max()) if finite.size else math.nan
    return row


def prewarm(vars_: list[Variant]) -> None:
    """Solve one tiny stack with every variant (imports, JIT compilation, caches), so
    that no case pays for them."""
    case = random_case(6, 2, samples=1)
    for v in vars_:
        opts = dict(v.options)
        if v.needs_mass_matrix:
            opts["mass_matrix"] = case.mass_matrices[0]
        try:
            formulations.solve(case.stacks[0], v.formulation, **opts)
        except UnsupportedTaskError:
            pass


# ------------------------------------------------------------------ experiments
def measure_batch(runs: list[FencingSamples], settings: Settings,
                  progress: Progress | None = None) -> dict[str, Any]:
    """``solve_batch`` of ``batch_size`` G1 stacks of one shape against single solves.

    Per-stack times (µs): each available formulation's ``solve_batch`` (median over
    ``batch_rounds`` calls, and whether its own batched kernel ran), a loop of
    ``formulations.solve`` over the same stacks (wall time per stack, what a user
    writes today), and the median single solve (``Solution.time_s``) of
    ``daqp_hierarchical`` and ``extended_jacobian`` on the first 200 stacks.
    """
    per_run = -(-settings.batch_size // max(1, len(runs)))
    stacks_all = [s for run in runs for s in run.stacks_at(per_run)]
    batch, note = same_shape_batch(stacks_all, settings.batch_size)
    out: dict[str, Any] = {"size": len(batch), "note": note, "n": batch[0].n,
                           "rows": sum(lvl.m for lvl in batch[0].levels),
                           "k": len(batch[0]), "batch_us": {}, "batched": {},
                           "loop_us": {}, "single_us": {}}
    names = [f.name for f in formulations.available() if f.available
             and not (f.capabilities and f.capabilities.needs_mass_matrix)]
    for name in ("extended_jacobian", "reference", "nullspace"):
        if name not in names:
            continue
        times = []
        res = None
        for _ in range(max(1, settings.batch_rounds)):
            res = formulations.solve_batch(batch, name)
            times.append(res.time_per_stack_s)
        out["batch_us"][name] = float(np.median(times)) * 1e6
        out["batched"][name] = bool(res.batched)
        if progress:
            progress.step(f"batch: solve_batch {name}")
    for name in ("extended_jacobian",):
        if name in names:
            t0 = time.perf_counter()
            for s in batch:
                formulations.solve(s, name)
            out["loop_us"][name] = (time.perf_counter() - t0) / len(batch) * 1e6
    for label, name, opts in (("daqp_hierarchical", "daqp_hierarchical", {}),
                              ("daqp_hierarchical[raw]", "daqp_hierarchical",
                               {"compress_levels": False, "check": False}),
                              ("extended_jacobian", "extended_jacobian", {})):
        if name in names:
            sub = batch[:200]
            for s in sub[:5]:
                formulations.solve(s, name, **opts)
            out["single_us"][label] = float(np.median(
                [formulations.solve(s, name, **opts).time_s for s in sub])) * 1e6
    if progress:
        progress.step("batch: loops and single solves")
    return out


def measure_control_step(settings: Settings, progress: Progress | None = None,
                         solve_estimates_us: dict[str, float] | None = None
                         ) -> tuple[list[dict[str, Any]], str]:
    """The paper's per-control-step comparison (kinematics + solve + torque) on G1.

    :func:`robots.simulate.simulate` runs the compatible fencing scenario for
    ``control_duration_s`` at ``dt = 2 ms`` with each formulation's plugin ``solve``
    called directly; ``unifying`` and ``operational_space`` get ``M(q)`` and the bias
    and return the torque themselves (the kinematics phase then includes
    ``crba`` and ``nonLinearEffects``); the others get the torque by RNEA.
    A formulation whose solve (``solve_estimates_us``, from the G1 table) would make
    the run exceed ``4 · cap`` seconds is simulated for fewer steps (at least 20).
    Returns per formulation the median of each phase (µs), or a reason it cannot run.
    """
    try:
        from prioik.robots.fencing import FencingScenario
        from prioik.robots.simulate import simulate
    except ImportError as exc:
        return [], f"robots cannot be imported ({type(exc).__name__}: {exc})"
    avail = {f.name: f for f in formulations.available() if f.available}
    plan = [("extended_jacobian", "extended Jacobian (this paper)", "1.4"),
            ("nullspace", "resolved acceleration (null-space projection)", "2.7"),
            ("unifying", "unifying framework", "3.2"),
            ("operational_space", "operational space", "4.8"),
            ("reference", "reference (nested SVD, ground truth)", ""),
            ("daqp_hierarchical", "DAQP hierarchical QP", "")]
    rows = []
    scenario = FencingScenario("compatible")
    for name, what, paper in plan:
        if name not in avail:
            continue
        mod = formulations.get(name)
        dyn = bool(avail[name].capabilities.needs_mass_matrix)
        duration = settings.control_duration_s
        est = (solve_estimates_us or {}).get(name, math.nan)
        if math.isfinite(est):
            per_step = est * 1e-6 + 2e-3            # solve + kinematics and torque
            steps = int(min(duration / 0.002, max(20, 4 * settings.cap_s / per_step)))
            duration = steps * 0.002
        try:
            sim = simulate(scenario.robot,
                           lambda state, t: scenario.acceleration_stack(state, t),
                           lambda stack, **kw: mod.solve(stack, **kw),
                           duration=duration, dt=0.002, needs_dynamics=dyn,
                           torque_from_solution=dyn, algorithmic_error=False)
        except Exception as exc:  # noqa: BLE001 - recorded in the table, the run goes on
            rows.append({"formulation": name, "what": what, "paper_ms": paper, "steps": 0,
                         "note": f"{type(exc).__name__}: {exc}"[:300]})
            continue
        if sim.steps == 0:
            rows.append({"formulation": name, "what": what, "paper_ms": paper,
                         "steps": 0, "note": sim.message})
            continue
        rows.append({"formulation": name, "what": what, "paper_ms": paper,
                     "steps": sim.steps,
                     "kinematics_us": float(np.median(sim.kinematics_time_s)) * 1e6,
                     "solve_us": float(np.median(sim.solve_time_s)) * 1e6,
                     "torque_us": float(np.median(sim.torque_time_s)) * 1e6,
                     "total_us": float(np.median(sim.step_time_s)) * 1e6,
                     "note": sim.message if sim.failed else (
                         f"shortened to {sim.steps} steps (time cap)"
                         if duration < settings.control_duration_s - 1e-9 else "")})
        if progress:
            progress.step(f"control step: {name}")
    return rows, ""


def measure_ik_step(settings: Settings, progress: Progress | None = None
                    ) -> tuple[dict[str, Any], str]:
    """The whole G1 IK step (kinematics + solve) of ``extended_jacobian`` against
    PlaCo's ``KinematicsSolver`` (see :mod:`benchmarks.placo_step`)."""
    from prioik.extras import MissingExtraError, require
    try:
        require("robots", "placo", what="the PlaCo IK step")
    except MissingExtraError as exc:
        return {}, str(exc)
    try:
        from .placo_step import ik_step_times
    except ImportError as exc:
        return {}, f"PlaCo step unavailable ({type(exc).__name__}: {exc})"
    try:
        out = ik_step_times(settings.ik_steps)
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        return {}, f"PlaCo step failed ({type(exc).__name__}: {exc})"
    from .panda_step import panda_step_times
    try:
        out["panda"] = panda_step_times(settings.ik_steps)
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["panda_error"] = f"{type(exc).__name__}: {exc}"
    # hierarchical_active_set with joint limits as bounds: the G1 bounds stacks (cold,
    # warm, DAQP's raw call, cascaded_qp[daqp]) and the like-for-like IK steps with limits
    from . import active_set_bench
    try:
        sizes = dict(windows=1, steps=3, repeats=1) if settings.quick else {}
        out["active_set"] = active_set_bench.run(ik_steps=settings.ik_steps, **sizes)
        out["active_set_table"] = active_set_bench.format_table(out["active_set"])
    except (ImportError, FileNotFoundError, RuntimeError) as exc:
        out["active_set_error"] = f"{type(exc).__name__}: {exc}"
    if progress:
        progress.step("IK step: PlaCo vs extended_jacobian")
    return out, ""


# ----------------------------------------------------------------------- ratios
def _median(rows: list[Row], case: str, label: str) -> float:
    for r in rows:
        if r.case == case and r.label == label and r.status in ("ok", "reduced"):
            return r.median_us
    return math.nan


@dataclass
class Ratio:
    """One target of the benchmark issue, measured in this run."""

    name: str
    value: float
    target: float
    detail: str

    @property
    def met(self) -> str:
        if not math.isfinite(self.value):
            return "n/a"
        return "yes" if self.value <= self.target else "no"


def ratios(rows: list[Row], batch: dict[str, Any], ik: dict[str, Any]) -> list[Ratio]:
    """The ratios the issue's targets name, from this run's medians."""
    out = []
    ej = "extended_jacobian"
    for case in sorted({r.case for r in rows if r.suite == "g1"}):
        e = _median(rows, case, ej)
        out.append(Ratio(f"{ej} / nullspace (λ=0), {case}", e / _median(rows, case, "nullspace"),
                         0.5, f"{e:.1f} / {_median(rows, case, 'nullspace'):.1f} µs"))
        qp = [(r.median_us, r.label) for r in rows if r.case == case
              and r.formulation == "cascaded_qp" and r.status in ("ok", "reduced")]
        best = min(qp) if qp else (math.nan, "cascaded_qp")
        out.append(Ratio(f"{ej} / fastest cascaded_qp ({best[1]}), {case}", e / best[0], 0.2,
                         f"{e:.1f} / {best[0]:.1f} µs"))
        for label in ("daqp_hierarchical", "daqp_hierarchical[raw]"):
            d = _median(rows, case, label)
            out.append(Ratio(f"{ej} / {label}, {case}", e / d, 1.0, f"{e:.1f} / {d:.1f} µs"))
    for label, target in ((ej, 2.0), ("nullspace", math.inf)):
        a = _median(rows, "random n=100 k=16", label)
        b = _median(rows, "random n=100 k=2", label)
        out.append(Ratio(f"{label} k=16 / k=2 at n=100", a / b, target,
                         f"{a:.1f} / {b:.1f} µs"))
    bt = batch.get("batch_us", {}).get(ej, math.nan)
    lp = batch.get("loop_us", {}).get(ej, math.nan)
    size = batch.get("size", 0)
    for label in ("daqp_hierarchical", "daqp_hierarchical[raw]"):
        d1 = batch.get("single_us", {}).get(label, math.nan)
        out.append(Ratio(f"solve_batch({ej}) of {size} G1 stacks per stack / one "
                         f"{label} solve", bt / d1, 0.5, f"{bt:.1f} / {d1:.1f} µs"))
    out.append(Ratio(f"solve_batch({ej}) per stack / loop of {ej} through solve",
                     bt / lp, 0.5, f"{bt:.1f} / {lp:.1f} µs"))
    for key, what, target in (("prioik_prepared_step_us", "rows written in place + prepared "
                               "solver (public API)", 0.8),
                              ("prioik_oneoff_step_us", "Task/TaskStack + one-off prioik.solve",
                               math.inf)):
        name = f"G1 IK step (kinematics + solve), {what}: {ej} / PlaCo KinematicsSolver"
        if ik:
            a, b = ik.get(key, math.nan), ik.get("placo_step_us", math.nan)
            out.append(Ratio(name, a / b, target, f"{a:.1f} / {b:.1f} µs"))
        else:
            out.append(Ratio(name, math.nan, target, "not measured"))
    for r in (ik.get("active_set", {}).get("ratios", []) if ik else []):
        out.append(Ratio(r["name"], float(r["value"]), float(r["target"]),
                         "hierarchical_active_set (benchmarks/active_set_bench.py)"))
    panda = ik.get("panda", {}) if ik else {}
    for key, what, target in (("prepared_step_us", "prepared path", 2.5),
                              ("oneoff_step_us", "one-off prioik.solve", math.inf)):
        name = f"Panda reach step (kinematics + rows + solve), {what}: {ej} / PlaCo"
        a, b = panda.get(key, math.nan), panda.get("placo_step_us", math.nan)
        out.append(Ratio(name, a / b, target, f"{a:.1f} / {b:.1f} µs" if panda
                         else "not measured"))
    if ik and "references_us" in ik:
        # the minimum-jerk references are the same Python in all three steps
        r = ik["references_us"]
        a, b = ik["prioik_prepared_step_us"] - r, ik["placo_step_us"] - r
        out.append(Ratio(f"G1 IK step without the shared references ({r:.1f} µs), "
                         f"prepared path / PlaCo", a / b, math.inf,
                         f"{a:.1f} / {b:.1f} µs"))
    return out


# ---------------------------------------------------------------------- outputs
def write_csv(rows: list[Row], path: Path) -> None:
    """All rows, one per (case, variant), columns :data:`CSV_COLUMNS`."""
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: v for k, v in asdict(r).items()})


def _fmt_us(v: float) -> str:
    if not math.isfinite(v):
        return "–"
    if v >= 1e5:
        return f"{v / 1e3:.0f} ms"
    if v >= 1e4:
        return f"{v / 1e3:.1f} ms"
    return f"{v:.1f}"


def _fmt_dist(v: float) -> str:
    return "–" if not math.isfinite(v) else f"{v:.1e}"


def detail_table(rows: list[Row]) -> str:
    """Markdown: every row of one case in full."""
    lines = ["| formulation | median µs | p10 µs | p90 µs | success | dist. median | "
             "dist. max | repeats | status |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in sorted(rows, key=lambda r: (math.isnan(r.median_us), r.median_us)):
        if r.status in ("skipped", "unsupported", "error"):
            lines.append(f"| {r.label} | – | – | – | – | – | – | 0 | {r.status}: "
                         f"{r.note} |")
            continue
        status = r.status if r.status == "ok" else f"{r.status}: {r.note}"
        lines.append(f"| {r.label} | {_fmt_us(r.median_us)} | {_fmt_us(r.p10_us)} | "
                     f"{_fmt_us(r.p90_us)} | {r.success_rate:.0%} | "
                     f"{_fmt_dist(r.dist_median)} | {_fmt_dist(r.dist_max)} | "
                     f"{r.repeats} | {status} |")
    return "\n".join(lines)


def pivot_table(rows: list[Row], k: int) -> str:
    """Markdown: median µs of every variant (rows) over ``n`` (columns) at ``k`` levels;
    ``†`` marks reduced repeats, ``*`` a success rate below 100 %."""
    sub = [r for r in rows if r.suite == "random" and r.k == k]
    ns = sorted({r.n for r in sub})
    labels = sorted({r.label for r in sub},
                    key=lambda l: min((r.median_us for r in sub if r.label == l
                                       and math.isfinite(r.median_us)), default=math.inf))
    lines = ["| formulation | " + " | ".join(f"n={n}" for n in ns) + " |",
             "|---|" + "---:|" * len(ns)]
    for label in labels:
        cells = []
        for n in ns:
            r = next((r for r in sub if r.label == label and r.n == n), None)
            if r is None:
                cells.append("")
            elif r.status in ("skipped", "unsupported", "error"):
                cells.append(r.status)
            else:
                mark = ("†" if r.status == "reduced" else "") + \
                    ("*" if r.success_rate < 1.0 else "")
                cells.append(f"{_fmt_us(r.median_us)}{mark}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(rows: list[Row], out: Path) -> list[str]:
    """Log-log plots of the median time against ``n`` (one panel per ``k``) and
    against ``k`` (one panel per ``n``); returns the file names written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sub = [r for r in rows if r.suite == "random" and math.isfinite(r.median_us)]
    if not sub:
        return []
    labels = sorted({r.label for r in sub})
    from matplotlib.ticker import NullFormatter
    cmap = plt.get_cmap("tab10")
    families = sorted({l.split("[")[0] for l in labels})

    def style(label: str) -> dict:
        fam = label.split("[")[0]
        if label == "extended_jacobian":
            return {"color": "black", "lw": 2.6, "ls": "-", "marker": "o", "zorder": 5}
        if fam in ("cascaded_qp", "cvxpy"):
            backs = sorted(l for l in labels if l.startswith(fam + "["))
            i = backs.index(label) if label in backs else 0
            return {"color": cmap(i % 10), "lw": 1.0, "marker": "x",
                    "ls": "--" if fam == "cascaded_qp" else ":"}
        if "[" in label:            # extra paths of one formulation: same colour, own marker
            extra = sorted(l for l in labels if l.startswith(fam + "["))
            return {"color": cmap(families.index(fam) % 10), "lw": 1.4, "ls": "-.",
                    "marker": "s^vD"[extra.index(label) % 4]}
        return {"color": cmap(families.index(fam) % 10), "lw": 1.6, "marker": "o", "ls": "-"}

    written = []
    for axis, other, fname in (("n", "k", "time_vs_n.png"), ("k", "n", "time_vs_k.png")):
        panels = sorted({getattr(r, other) for r in sub})
        ticks = sorted({getattr(r, axis) for r in sub})
        fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels) + 2.5, 4.6),
                                 squeeze=False, sharey=True)
        for ax, p in zip(axes[0], panels):
            for l in labels:
                pts = sorted((getattr(r, axis), r.median_us) for r in sub
                             if r.label == l and getattr(r, other) == p)
                if pts:
                    xs, ys = zip(*pts)
                    ax.plot(xs, ys, ms=3, label=l, **style(l))
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xticks(ticks)
            ax.set_xticklabels([str(t) for t in ticks])
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_title(f"{other} = {p}")
            ax.set_xlabel(axis + (" (unknowns)" if axis == "n" else " (levels)"))
            ax.grid(True, which="both", alpha=0.3)
        axes[0][0].set_ylabel("median solve time (µs)")
        handles, names = axes[0][0].get_legend_handles_labels()
        fig.legend(handles, names, loc="center right", fontsize=7)
        fig.tight_layout(rect=(0, 0, 1 - 2.3 / (4.2 * len(panels) + 2.5), 1))
        fig.savefig(out / fname, dpi=110)
        plt.close(fig)
        written.append(fname)
    return written


def machine() -> dict[str, str]:
    """CPU model, cores, OS and library versions."""
    cpu = platform.processor() or platform.machine()
    fields: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                key = key.strip().lower()
                if key in ("model name", "cpu mhz", "cache size") and key not in fields:
                    fields[key] = value.strip()
    except OSError:
        pass
    if "model name" in fields:
        cpu = fields["model name"]
        extra = [f"{float(fields['cpu mhz']):.0f} MHz" if "cpu mhz" in fields else "",
                 f"cache {fields['cache size']}" if "cache size" in fields else ""]
        extra = [e for e in extra if e]
        if extra:
            cpu += f" ({', '.join(extra)})"
    from importlib import metadata
    versions = {}
    for dist in ("numpy", "scipy", "numba", "pin", "placo", "qpsolvers", "daqp", "cvxpy",
                 "clarabel", "osqp", "proxsuite", "quadprog", "scs", "highspy",
                 "matplotlib"):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            pass
    try:
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        blas_name = f"{blas.get('name', '?')} {blas.get('version', '')}".strip()
    except Exception:  # noqa: BLE001 - older numpy: no dict mode
        blas_name = "unknown"
    return {"cpu": cpu, "cores": str(os.cpu_count()), "python": platform.python_version(),
            "os": f"{platform.system()} {platform.release()}", "blas": blas_name,
            "versions": ", ".join(f"{k} {v}" for k, v in versions.items())}


def markdown_report(rows: list[Row], rats: list[Ratio], batch: dict, ik: dict,
                    control: list[dict], notes: list[str], settings: Settings,
                    plots: list[str], plot_prefix: str = "") -> str:
    """The results as markdown (tables, ratios, batch, IK step, control step, notes)."""
    md = []
    md.append("## Targets (ratios of medians measured side by side in this run)\n")
    md.append("| ratio | measured | target | met | medians |")
    md.append("|---|---:|---:|---|---|")
    for r in rats:
        tgt = "report" if math.isinf(r.target) else f"≤ {r.target:g}"
        val = f"{r.value:.2f}" if math.isfinite(r.value) else "n/a"
        met = "–" if math.isinf(r.target) else r.met
        md.append(f"| {r.name} | {val} | {tgt} | {met} | {r.detail} |")
    g1 = sorted({r.case for r in rows if r.suite == "g1"})
    for case in g1:
        sub = [r for r in rows if r.case == case]
        md.append(f"\n## {case}: n = {sub[0].n}, {sub[0].k} levels (most common), "
                  f"{sub[0].rows} rows (median)\n")
        md.append(detail_table(sub))
    if batch:
        md.append(f"\n## solve_batch: {batch['size']} G1 stacks of one shape "
                  f"(n = {batch['n']}, {batch['k']} levels, {batch['rows']} rows)\n")
        md.append(f"{batch['note']}. Per-stack times in µs.\n")
        md.append("| what | µs per stack |")
        md.append("|---|---:|")
        for name, v in batch["batch_us"].items():
            kind = "own batched kernel" if batch["batched"][name] else "loop inside solve_batch"
            md.append(f"| `solve_batch(..., \"{name}\")` ({kind}) | {_fmt_us(v)} |")
        for name, v in batch["loop_us"].items():
            md.append(f"| loop of `formulations.solve(s, \"{name}\")` (wall) | {_fmt_us(v)} |")
        for name, v in batch["single_us"].items():
            md.append(f"| one `{name}` solve (median `time_s`, 200 stacks) | {_fmt_us(v)} |")
    if ik:
        md.append("\n## Whole G1 IK step (kinematics + solve)\n")
        md.append(ik.get("description", ""))
        md.append("\n| step | median µs | p10 µs | p90 µs |")
        md.append("|---|---:|---:|---:|")
        for key, what in (("prioik_prepared", "prioik, prepared: kinematics + "
                                              "`write_velocity_rows` + `solver.solve(data)`"),
                          ("prioik_oneoff", "prioik, one-off: kinematics + `Task`/`TaskStack` "
                                            "+ `prioik.solve`"),
                          ("placo", "PlaCo: update_kinematics + KinematicsSolver.solve")):
            md.append(f"| {what} | {_fmt_us(ik[key + '_step_us'])} | "
                      f"{_fmt_us(ik[key + '_p10_us'])} | {_fmt_us(ik[key + '_p90_us'])} |")
    if ik and ik.get("active_set_table"):
        md.append("\n## hierarchical_active_set: bounds stacks and IK steps with limits\n")
        md.append("Joint position and velocity limits as bounds (inequality rows) on the G1 "
                  "fencing stacks, and the whole IK step with the same limits on both sides "
                  "(prioik's prepared path against PlaCo's `KinematicsSolver`); "
                  "see docs/active-set.md.\n")
        md.append(ik["active_set_table"])
    if ik and ik.get("panda"):
        panda = ik["panda"]
        md.append("\n## Panda reach step (kinematics + rows + solve)\n")
        md.append(panda.get("description", ""))
        md.append("\n| step | median µs | p10 µs | p90 µs |")
        md.append("|---|---:|---:|---:|")
        for key, what in (("prepared", "prioik, prepared"), ("oneoff", "prioik, one-off"),
                          ("placo", "PlaCo KinematicsSolver")):
            md.append(f"| {what} | {_fmt_us(panda[key + '_step_us'])} | "
                      f"{_fmt_us(panda[key + '_p10_us'])} | {_fmt_us(panda[key + '_p90_us'])} |")
    if control:
        md.append("\n## Per control step on G1 (the paper's comparison re-measured)\n")
        md.append("Compatible fencing scenario on the G1 (n = 35: 29 joints and the floating "
                  "base; 5-6 levels), steps of 2 ms, median per phase; kinematics = "
                  "pinocchio kinematics and building the stack (plus `crba` and "
                  "`nonLinearEffects` for the torque-level formulations), torque = RNEA "
                  "(or the formulation's own τ). Paper: 28 DOF, 4 tasks, 2.4 GHz Pentium "
                  "(2009).\n")
        md.append("| formulation | steps | kinematics µs | solve µs | torque µs | total µs | "
                  "total / extended Jacobian | paper ms | paper / extended Jacobian | run |")
        md.append("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
        base = next((c.get("total_us", math.nan) for c in control
                     if c["formulation"] == "extended_jacobian"), math.nan)
        base_paper = next((float(c["paper_ms"]) for c in control
                           if c["formulation"] == "extended_jacobian" and c["paper_ms"]), 0.0)
        for c in control:
            note = c.get("note", "")
            run_note = (note if note.startswith("shortened") else f"stopped: {note}") \
                if note else "completed"
            paper = (f"{float(c['paper_ms']) / base_paper:.2f}"
                     if c["paper_ms"] and base_paper else "–")
            if not c.get("steps"):
                md.append(f"| {c['what']} | 0 | – | – | – | – | – | {c['paper_ms'] or '–'} | "
                          f"{paper} | {run_note} |")
                continue
            rel = c["total_us"] / base if math.isfinite(base) else math.nan
            md.append(f"| {c['what']} (`{c['formulation']}`) | {c['steps']} | "
                      f"{_fmt_us(c['kinematics_us'])} | {_fmt_us(c['solve_us'])} | "
                      f"{_fmt_us(c['torque_us'])} | {_fmt_us(c['total_us'])} | "
                      f"{rel:.2f} | {c['paper_ms'] or '–'} | {paper} | {run_note} |")
    ks = sorted({r.k for r in rows if r.suite == "random"})
    if ks:
        md.append("\n## Random stacks: median solve time (µs)\n")
        md.append(f"Family `{settings.family}`, {settings.samples} stacks per case. "
                  "`†`: reduced repeats (time cap), `*`: success rate below 100 % "
                  "(see results.csv for p10/p90, success and distance).\n")
        for k in ks:
            md.append(f"\n### k = {k} levels\n")
            md.append(pivot_table(rows, k))
    for p in plots:
        md.append(f"\n![{p}]({plot_prefix}{p})")
    if notes:
        md.append("\n## Notes\n")
        md.extend(f"- {n}" for n in notes)
    return "\n".join(md) + "\n"


def _count_by_n(rows: list[Row]) -> dict[str, int]:
    """Rows per G1 / random ``n``, in that order."""
    out: dict[str, int] = {}
    for r in sorted(rows, key=lambda r: (r.suite != "g1", r.n)):
        key = "G1" if r.suite == "g1" else f"n={r.n}"
        out[key] = out.get(key, 0) + 1
    return out


def doc_page(report: str, info: dict[str, str], settings: Settings, command: str,
             elapsed_s: float, rows: list[Row] | None = None) -> str:
    """``docs/benchmarks.md``: how it was measured, the machine, then the report."""
    mode = "quick" if settings.quick else "default"
    rows = rows or []
    status = {st: [r for r in rows if r.status == st]
              for st in ("ok", "reduced", "skipped", "unsupported", "error")}
    words = {"ok": "with every repeat", "reduced": "reduced", "skipped": "skipped",
             "unsupported": "unsupported", "error": "with an error"}
    counts = ", ".join(f"{len(v)} rows {words[k]}" + (
        " (" + ", ".join(f"{n}: {c}" for n, c in _count_by_n(v).items()) + ")"
        if k in ("reduced", "skipped") and v else "")
        for k, v in status.items() if v) or "no rows"
    threads = (f"OpenBLAS was limited to {settings.blas_threads} thread(s) while measuring "
               "(`--blas-threads`), as in a control loop that solves one problem at a time; "
               "with BLAS's default threads on this shared 2-core machine, solves at "
               "n ≥ 100 were up to 100× slower and erratic."
               if settings.blas_threads > 0 else "BLAS ran with its default thread count.")
    return f"""# Benchmarks

Generated by `{command}` ({mode} run, {elapsed_s / 60:.1f} min); do not edit by hand.

**Machine**: {info['cpu']}, {info['cores']} cores, {info['os']}, Python {info['python']},
BLAS {info['blas']}. **Libraries**: {info['versions']}.
{threads}
The machine was shared with other processes while measuring: compare ratios measured
side by side in one run, not absolute times across runs.

**Method.** For each case (a set of stacks) and each formulation variant (one row per
QP back-end), after {settings.warmup + 1} warm-up solves, up to {settings.repeats} timed
solves cycle over the case's stacks; the time of a solve is `Solution.time_s`
(`time.perf_counter` around the plugin's `solve`, without the registry's option checks
and residual evaluation). Rows give the median, p10 and p90; **success** is the share of
solves whose status is not `failed` and whose residual at every level is within
{SUCCESS_TOL:g}·max(1, ‖b_i‖) of `reference`'s; **distance** is
‖x − x_ref‖ / max(1, ‖x_ref‖) to `reference` (to `reference` with `metric=M` for
formulations that take a mass matrix). Formulations that need a mass matrix get the
robot's M(q) on G1 stacks and a fixed SPD M (eigenvalues 0.1–10, seeded rotation) on
random stacks. Time budget: a variant whose timed solves would exceed {settings.cap_s:g} s
per case gets fewer repeats (at least {settings.min_repeats}, and the loop stops at
twice the cap; marked `reduced`/`†`); it is `skipped` when one solve takes more than
{2 * settings.cap_s / settings.min_repeats * 1e3:.0f} ms after warm-up (or the first
more than {settings.cap_s:g} s), when it was skipped on a smaller random case, or when
its p90 on a smaller case (≥ 5 ms) scaled by (n ratio)³ exceeds {4 * settings.cap_s:g} s.
In this run: {counts}. The reason for each is in the `note` column of `results.csv`.

Extra rows beside each formulation's defaults: `extended_jacobian[svd]` (the paper's
SVD path), `extended_jacobian[lapack]` (the readable LAPACK nested-QR path; the default
row is `kernel="auto"`: the compiled kernel up to n = 160, LAPACK above), `daqp_hierarchical[raw]` (`compress_levels=False,
check=False`: DAQP's C call alone, without the plugin's SVD compression of the levels and
its conflicting-level check — faster, but not exact on conflicting levels).

G1 stacks: the fencing scenario (`robots.fencing`, both variants, acceleration level,
joint limits as activation rows so every equality formulation can take them) at
{settings.g1_samples} states evenly spread over a {G1_DURATION_S:g} s run (5 ms steps) driven
by `reference` (compatible) or by the selectively damped `extended_jacobian` of
`prioik fencing` (incompatible: exact methods blow up at its algorithmic singularity);
every formulation is then timed with its default options (λ = 0) on those stacks.

{report}"""


# ------------------------------------------------------------------------- main
def run_benchmark(settings: Settings, out: Path, doc: Path | None = None,
                  command: str = "prioik bench") -> dict[str, Any]:
    """Run everything, write the outputs; returns the summary (also ``summary.json``)."""
    with blas_threads(settings.blas_threads):
        return _run_benchmark(settings, out, doc, command, settings.blas_threads > 0 and bool(blas_info()))


def _run_benchmark(settings: Settings, out: Path, doc: Path | None, command: str,
                   blas_limited: bool) -> dict[str, Any]:
    t_start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    vars_, unavailable = variants(settings.only)
    notes = [f"not available here: {u}" for u in unavailable]
    if settings.blas_threads > 0 and not blas_limited:
        notes.append(f"could not limit BLAS to {settings.blas_threads} thread(s): no "
                     "OpenBLAS found in the process; BLAS ran with its default threads")

    cases: list[Case] = []
    phases: dict[str, float] = {}
    mark = time.perf_counter()
    if settings.g1:
        print("prioik bench: simulating the G1 fencing runs to sample states ...",
              file=sys.stderr, flush=True)
        g1_cases, runs, reason = g1_fencing_cases(settings.g1_samples)
    else:
        g1_cases, runs, reason = [], [], "--no-g1"
    if reason:
        notes.append(f"G1 part skipped: {reason}")
        print(f"prioik bench: G1 part skipped: {reason}", file=sys.stderr)
    cases.extend(g1_cases)
    for n in settings.sizes:
        for k in settings.levels:
            cases.append(random_case(n, k, settings.samples, settings.family))

    phases["drawing stacks"] = time.perf_counter() - mark
    mark = time.perf_counter()
    total = len(cases) * len(vars_) + (4 if runs else 0) + (6 if runs else 0) + 1
    progress = Progress(total)
    prewarm(vars_)
    rows: list[Row] = []
    too_slow: dict[str, list[tuple[int, int, str]]] = {}
    observed: dict[str, list[tuple[int, int, float, str]]] = {}
    for case in cases:
        with_metric = any(v.needs_mass_matrix for v in vars_)
        ref = _references(case, with_metric)
        for v in vars_:
            progress.step(f"{case.name}: {v.label}")
            smaller = [c for (n, k, c) in too_slow.get(v.label, [])
                       if case.suite == "random" and n <= case.n and k <= case.k]
            if smaller:
                rows.append(Row(case.suite, case.name, case.n, case.k, case.rows, v.label,
                                v.formulation, v.backend,
                                " ".join(f"{a}={b}" for a, b in v.options.items()),
                                status="skipped",
                                note=f"not tried: over the cap already at {smaller[0]}"))
                continue
            # O(n³) from a smaller case where the arithmetic dominates (≥ 5 ms a solve)
            guess = [(t * (case.n / n) ** 3, c) for (n, k, t, c) in observed.get(v.label, [])
                     if case.suite == "random" and n < case.n and k <= case.k and t >= 5e-3]
            if guess and max(guess)[0] > 4 * settings.cap_s:
                t, c = max(guess)
                rows.append(Row(case.suite, case.name, case.n, case.k, case.rows, v.label,
                                v.formulation, v.backend,
                                " ".join(f"{a}={b}" for a, b in v.options.items()),
                                status="skipped",
                                note=f"not tried: one solve predicted at {t:.1f} s > 4·cap "
                                     f"= {4 * settings.cap_s:g} s (p90 at {c} × (n ratio)³)"))
                too_slow.setdefault(v.label, []).append((case.n, case.k, case.name))
                continue
            try:
                row = time_case(case, v, ref, settings)
            except Exception as exc:  # noqa: BLE001 - one plugin's bug must not end the run
                row = Row(case.suite, case.name, case.n, case.k, case.rows, v.label,
                          v.formulation, v.backend,
                          " ".join(f"{a}={b}" for a, b in v.options.items()),
                          status="error", note=f"{type(exc).__name__}: {exc}"[:300])
            if case.suite == "random":
                if row.status == "skipped":
                    too_slow.setdefault(v.label, []).append((case.n, case.k, case.name))
                t = row.p90_us * 1e-6 if math.isfinite(row.p90_us) else row.probe_s
                if math.isfinite(t):
                    observed.setdefault(v.label, []).append((case.n, case.k, t, case.name))
            rows.append(row)
    phases["tables"] = time.perf_counter() - mark
    reduced = [r for r in rows if r.status == "reduced"]
    skipped = [r for r in rows if r.status == "skipped"]
    if reduced:
        notes.append(f"{len(reduced)} rows have fewer than {settings.repeats} repeats "
                     f"(time cap {settings.cap_s:g} s per case): "
                     + ", ".join(sorted({f'{r.label} @ {r.case}' for r in reduced})[:40])
                     + (", …" if len(reduced) > 40 else ""))
    if skipped:
        notes.append(f"{len(skipped)} rows skipped (over the time cap; the reason is in "
                     f"the note column of results.csv): "
                     + ", ".join(sorted({f'{r.label} @ {r.case}' for r in skipped})))

    batch: dict[str, Any] = {}
    control: list[dict] = []
    ik: dict[str, Any] = {}
    if runs:
        mark = time.perf_counter()
        batch = measure_batch(runs, settings, progress)
        phases["batch"] = time.perf_counter() - mark
        mark = time.perf_counter()
        estimates = {r.formulation: r.median_us for r in rows if r.case == "g1 compatible"
                     and r.label == r.formulation and math.isfinite(r.median_us)}
        control, why = measure_control_step(settings, progress, estimates)
        phases["control step"] = time.perf_counter() - mark
        if why:
            notes.append(f"control-step comparison skipped: {why}")
        mark = time.perf_counter()
        ik, why = measure_ik_step(settings, progress)
        phases["IK step"] = time.perf_counter() - mark
        if why:
            notes.append(f"IK-step comparison skipped: {why}")
    else:
        notes.append("batch, IK-step and control-step experiments need the G1 stacks")
    progress.step("writing outputs")
    progress.close()
    notes.append("wall time per phase: " + ", ".join(f"{k} {v:.0f} s"
                                                     for k, v in phases.items()))

    rats = ratios(rows, batch, ik)
    write_csv(rows, out / "results.csv")
    plots = plot(rows, out)
    report = markdown_report(rows, rats, batch, ik, control, notes, settings, plots)
    (out / "results.md").write_text(report)
    info = machine()
    elapsed = time.perf_counter() - t_start
    summary = {"machine": info, "elapsed_s": elapsed, "phases_s": phases,
               "settings": asdict(settings),
               "ratios": [{"name": r.name, "value": r.value, "target": r.target,
                           "met": r.met, "detail": r.detail} for r in rats],
               "batch": batch, "ik_step": ik, "control_step": control, "notes": notes}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    if doc is not None:
        doc.parent.mkdir(parents=True, exist_ok=True)
        prefix = os.path.relpath(out.resolve(), doc.parent.resolve()) + "/"
        report_doc = markdown_report(rows, rats, batch, ik, control, notes, settings,
                                     plots, prefix)
        doc.write_text(doc_page(report_doc, info, settings, command, elapsed, rows))
    return summary


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="time every formulation and back-end (G1 and random "
                                     "stacks); CSV, markdown and plots",
                       description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=Path("bench-results"),
                   help="output directory (default: bench-results)")
    p.add_argument("--doc", type=Path, default=None,
                   help="also write the documentation page here (e.g. docs/benchmarks.md)")
    p.add_argument("--quick", action="store_true", help="a smaller run (under a minute)")
    p.add_argument("--repeats", type=int, default=None, help="timed solves per case")
    p.add_argument("--cap", type=float, default=None,
                   help="seconds of timed solves per (case, formulation) before repeats "
                        "are reduced")
    p.add_argument("--family", default=None, help="random stack family (hierarchy.families)")
    p.add_argument("--formulations", default="", help="comma-separated names (default: all)")
    p.add_argument("--sizes", default=None, help="comma-separated n of the random cases "
                                                 f"(default: {','.join(map(str, SIZES))})")
    p.add_argument("--levels", default=None, help="comma-separated k of the random cases "
                                                  f"(default: {','.join(map(str, LEVELS))})")
    p.add_argument("--samples", type=int, default=None,
                   help="stacks per random case (default: 8)")
    p.add_argument("--blas-threads", type=int, default=1,
                   help="threads of OpenBLAS while measuring (default 1, as in a control "
                        "loop; 0: leave BLAS's default)")
    p.add_argument("--no-g1", action="store_true",
                   help="random stacks only (no G1 cases, batch, IK-step or control-step runs)")
    p.set_defaults(func=run, extras=("plots",))


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces this run (printed in the doc page)."""
    parts = ["prioik bench"]
    if args.quick:
        parts.append("--quick")
    parts.append(f"--out {args.out}")
    if args.doc:
        parts.append(f"--doc {args.doc}")
    for flag, value in (("--repeats", args.repeats), ("--cap", args.cap),
                        ("--family", args.family), ("--formulations", args.formulations),
                        ("--sizes", args.sizes), ("--levels", args.levels),
                        ("--samples", args.samples)):
        if value not in (None, ""):
            parts.append(f"{flag} {value}")
    if args.blas_threads != 1:
        parts.append(f"--blas-threads {args.blas_threads}")
    if args.no_g1:
        parts.append("--no-g1")
    return " ".join(parts)


def _int_list(text: str, what: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise ValueError(f"{what} takes comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1:
        raise ValueError(f"{what} takes positive integers, got {text!r}")
    return values


def run(args: argparse.Namespace) -> int:
    settings = quick_settings() if args.quick else Settings()
    if args.repeats is not None:
        if args.repeats < 1:
            raise ValueError(f"--repeats must be ≥ 1, got {args.repeats}")
        settings.repeats = args.repeats
        settings.min_repeats = min(settings.min_repeats, args.repeats)
    if args.cap is not None:
        if not args.cap > 0:
            raise ValueError(f"--cap must be > 0, got {args.cap}")
        settings.cap_s = args.cap
    if args.family:
        settings.family = args.family
    settings.only = tuple(s for s in args.formulations.split(",") if s)
    if args.sizes:
        settings.sizes = _int_list(args.sizes, "--sizes")
    if args.levels:
        settings.levels = _int_list(args.levels, "--levels")
    if args.samples is not None:
        if args.samples < 1:
            raise ValueError(f"--samples must be ≥ 1, got {args.samples}")
        settings.samples = args.samples
    settings.g1 = not args.no_g1
    if args.blas_threads < 0:
        raise ValueError(f"--blas-threads must be ≥ 0, got {args.blas_threads}")
    settings.blas_threads = args.blas_threads
    command = _command(args)
    summary = run_benchmark(settings, args.out, args.doc, command)
    print(f"wrote {args.out}/results.csv, results.md, summary.json and plots "
          f"in {summary['elapsed_s']:.0f} s")
    for r in summary["ratios"]:
        v = r["value"]
        if not math.isfinite(v):
            print(f"  {r['name']}: n/a")
        elif math.isinf(r["target"]):
            print(f"  {r['name']}: {v:.2f} (reported beside the target)")
        else:
            print(f"  {r['name']}: {v:.2f} (target ≤ {r['target']:g}, met: {r['met']})")
    return 0
