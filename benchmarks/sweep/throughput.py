"""Throughput of a sweep against its number of workers (``prioik sweep --throughput N``).

The same ``N`` runs of the sweep — spread over its points and formulation variants, so
that slow and fast variants are mixed as in the whole sweep — are run once per worker
count (1, then one per core; each a fresh embedded ``LocalCluster``, one BLAS thread per
worker) into scratch folders ``DIR/throughput/workers-W``. Each run's wall time is taken
from the cluster's start to its last row (the cluster start itself is reported apart), so
the ratio of runs per minute is the speed-up the workers give on the machine as it is
(each worker imports the modules and loads the compiled kernels before the clock starts);
the load average before and after each pass is recorded beside it (a machine shared with
other processes cannot show the speed-up of its idle cores). The result goes to
``DIR/throughput.json`` and into the page's "How it ran" section.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Any

from .config import Plan, SweepConfigError
from .execute import run_sweep

#: file of the result in the sweep's output folder
FILE = "throughput.json"


def spread_runs(plan: Plan, n: int) -> Plan:
    """``plan`` restricted to ``n`` of its runs, taken evenly along its run order (which
    goes point by point through every variant).

    Raises:
        SweepConfigError: ``n`` is not at least 2 or exceeds the sweep's runs.
    """
    total = len(plan.runs)
    if not 2 <= n <= total:
        raise SweepConfigError(f"--throughput takes 2 to {total} runs (the sweep's size), "
                               f"got {n}")
    picks = sorted({round(i * (total - 1) / (n - 1)) for i in range(n)})
    return replace(plan, runs=[plan.runs[i] for i in picks])


def measure(plan: Plan, out, n: int, worker_counts: tuple[int, ...] | None = None,
            repeats: int = 2, progress: bool = False) -> dict[str, Any]:
    """Run ``n`` runs of ``plan`` on each worker count and compare their rates.

    Args:
        plan: The sweep.
        out: The sweep's output folder (scratch under ``out/throughput``; the result in
            ``out/throughput.json``).
        n: Runs per pass.
        worker_counts: Worker counts to compare (default: 1 and one per core).
        repeats: Passes per worker count, the counts alternating (1, 2, 1, 2, …: a
            passing load on a shared machine hits both); each count's fastest pass is
            compared.
        progress: Progress bars on stderr.

    Returns:
        ``{"runs": n, "passes": [{"workers", "wall_time_s", "runs_per_minute",
        "load_average_start", "load_average_end", ...}, ...], "best": {workers: rate},
        "speedup": best(last count) / best(first count)}``.
    """
    sub = spread_runs(plan, n)
    cores = os.cpu_count() or 1
    counts = worker_counts or tuple(sorted({1, cores}))
    scratch = Path(out) / "throughput"
    passes = []
    for _ in range(max(1, repeats)):
        for w in counts:
            folder = scratch / f"workers-{w}"
            if folder.exists():
                shutil.rmtree(folder)          # every pass computes all of its runs
            outcome = run_sweep(sub, folder, workers=w, progress=progress)
            info = outcome.info
            passes.append({k: info.get(k) for k in (
                "workers", "runs_computed", "wall_time_s", "cluster_start_s",
                "runs_per_minute", "load_average_start", "load_average_end",
                "cpu_pressure_avg60_start", "cpu_count")})
    best = {w: max((p["runs_per_minute"] or 0.0) for p in passes if p["workers"] == w)
            for w in counts}
    result = {"runs": len(sub.runs), "worker_counts": list(counts), "repeats": repeats,
              "passes": passes, "best": {str(w): r for w, r in best.items()},
              "speedup": (best[counts[-1]] / best[counts[0]])
              if len(counts) > 1 and best[counts[0]] > 0 else None}
    (Path(out) / FILE).write_text(json.dumps(result, indent=2) + "\n")
    return result


def load(out) -> dict[str, Any] | None:
    """The result :func:`measure` wrote in ``out``, if any."""
    path = Path(out) / FILE
    if not path.exists():
        return None
    try:
        return json.loads(path.read_text())
    except ValueError:
        return None


def describe(result: dict[str, Any]) -> str:
    """One markdown list item of the result (for the page's "How it ran")."""
    parts = []
    for p in result["passes"]:
        rate = p["runs_per_minute"]
        parts.append(f"{p['workers']} worker(s) {p['wall_time_s']:.1f} s"
                     + (f" ({rate:.1f} runs/min)" if rate else "")
                     + f", load average {p['load_average_start']} → {p['load_average_end']}")
    speed = result.get("speedup")
    counts = result["worker_counts"]
    ratio = (f" — fastest passes: {counts[-1]} workers {speed:.2f} × the rate of "
             f"{counts[0]}" if speed else "")
    return (f"- Throughput (`--throughput {result['runs']}`: the same {result['runs']} runs, "
            f"spread over the sweep, on each worker count, the counts alternating): "
            + "; ".join(parts) + ratio + ".")
