"""The paper's per-control-step comparison (kinematics + solve + torque) on the G1."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from prioik.benchmarks import paper
from prioik.benchmarks.progress import Progress
from prioik.benchmarks.variants import Variant

from .settings import Settings

__all__ = ["measure_control_step"]

DT = 0.002


def measure_control_step(variants: list[Variant], settings: Settings,
                         progress: Progress | None = None,
                         solve_estimates_us: dict[str, float] | None = None
                         ) -> tuple[list[dict[str, Any]], str]:
    """Each variant of the ``control_step`` report on the compatible fencing scenario.

    Every run is a scenario run (:func:`prioik.benchmarks.scenario_runs.run_one`: the
    scenario's step builder, one prepared solver per stack layout, RNEA or the
    formulation's own torque; ``unifying`` and ``operational_space`` get ``M(q)`` and
    the bias, so their kinematics phase includes ``crba`` and ``nonLinearEffects``) of
    ``control_duration_s`` at ``dt = 2 ms``. A variant whose solve
    (``solve_estimates_us`` by label, from the G1 table) would make the run exceed
    ``4 · cap`` seconds is simulated for fewer steps (at least 20).

    Returns:
        Per variant ``label``, ``formulation``, ``paper_ms`` (Sec. III-B.3, ``None``
        when the paper has no figure), ``steps``, the median of each phase (µs) and a
        ``note``; or ``([], reason)`` when the robots cannot run here.
    """
    try:
        from prioik.benchmarks.scenario_runs import run_one
        from prioik.robots.fencing import FencingScenario  # noqa: F401
    except ImportError as exc:
        return [], f"robots cannot be imported ({type(exc).__name__}: {exc})"
    rows = []
    for v in variants:
        head = {"label": v.label, "formulation": v.formulation,
                "paper_ms": paper.STEP_TIMES_MS.get(v.formulation) if not v.tag else None}
        duration = settings.control_duration_s
        est = (solve_estimates_us or {}).get(v.label, math.nan)
        if math.isfinite(est):
            per_step = est * 1e-6 + 2e-3            # solve + kinematics and torque
            steps = int(min(duration / DT, max(20, 4 * settings.cap_s / per_step)))
            duration = steps * DT
        try:
            sim = run_one(v, "compatible", duration, DT, algorithmic_error=False)
        except Exception as exc:  # noqa: BLE001 - recorded in the table, the run goes on
            rows.append({**head, "steps": 0, "note": f"{type(exc).__name__}: {exc}"[:300]})
            continue
        if progress:
            progress.step(f"control step: {v.label}")
        if sim.steps == 0:
            rows.append({**head, "steps": 0, "note": sim.message})
            continue
        rows.append({**head, "steps": sim.steps,
                     "kinematics_us": float(np.median(sim.kinematics_time_s)) * 1e6,
                     "solve_us": float(np.median(sim.solve_time_s)) * 1e6,
                     "torque_us": float(np.median(sim.torque_time_s)) * 1e6,
                     "total_us": float(np.median(sim.step_time_s)) * 1e6,
                     "note": sim.message if sim.failed else (
                         f"shortened to {sim.steps} steps (time cap)"
                         if duration < settings.control_duration_s - 1e-9 else "")})
    return rows, ""
