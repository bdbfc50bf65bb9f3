"""The ratios the benchmark issues' targets name, from one run's medians.

Each is a quotient of medians measured side by side in one run (the tables, the batch
experiment, the IK steps). The targets name formulations and rows by label: they are
the issues' own figures of merit, not a list of what is benchmarked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from prioik.benchmarks.results import TimingRow

__all__ = ["Ratio", "ratios", "SINGLE_SOLVES"]

#: the rows whose single-solve median the batch ratios divide by (and the extended
#: Jacobian's own, for comparison)
SINGLE_SOLVES = ("daqp_hierarchical", "daqp_hierarchical[raw]", "extended_jacobian")


def _median(rows: list[TimingRow], case: str, label: str) -> float:
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


def ratios(rows: list[TimingRow], batch: dict[str, Any], ik: dict[str, Any]) -> list[Ratio]:
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
    for key, what, target in (("control_step_us", "ControlStep (hierarchical_active_set, "
                               "integrated)", 1.0),
                              ("prepared_step_us", f"prepared path: {ej}", math.inf),
                              ("oneoff_step_us", f"one-off prioik.solve: {ej}", math.inf)):
        name = f"Panda reach step (kinematics + rows + solve), {what} / PlaCo"
        a, b = panda.get(key, math.nan), panda.get("placo_step_us", math.nan)
        out.append(Ratio(name, a / b, target, f"{a:.1f} / {b:.1f} µs" if panda
                         else "not measured"))
    overhead = ik.get("solve_overhead", {}) if ik else {}
    for key, what in (("g1", "G1 fencing rows"), ("panda", "Panda reach rows"),
                      ("g1_bounds", "hierarchical_active_set, G1 fencing bounds rows"),
                      ("panda_limits", "hierarchical_active_set, Panda reach limits rows")):
        r = overhead.get(key)
        out.append(Ratio(f"prepared.solve overhead on top of the compiled kernel (µs), {what}",
                         r["overhead_us"] if r else math.nan, 2.0,
                         f"paired; solve {r['solve_us']:.2f}, kernel {r['kernel_us']:.2f} µs"
                         if r
                         else "not measured"))
    written = ik.get("rows", {}) if ik else {}
    for key, what, target in (("none", "the five fencing tasks", 10.0),
                              ("bounds", "plus joint-limit bounds", math.inf)):
        r = written.get(key)
        out.append(Ratio(f"Writing the G1 fencing rows per step, references excluded (µs), "
                         f"{what}", r["write_us"] if r else math.nan, target,
                         f"{r['rows']} rows (benchmarks/row_writing.py)" if r
                         else "not measured"))
    if ik and "references_us" in ik:
        # the minimum-jerk references are the same Python in all three steps
        r = ik["references_us"]
        a, b = ik["prioik_prepared_step_us"] - r, ik["placo_step_us"] - r
        out.append(Ratio(f"G1 IK step without the shared references ({r:.1f} µs), "
                         f"prepared path / PlaCo", a / b, math.inf,
                         f"{a:.1f} / {b:.1f} µs"))
    return out
