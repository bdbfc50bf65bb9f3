"""Running a plan: in-process, on an embedded ``LocalCluster`` or on an existing scheduler.

Every run is an independent ``dask.distributed`` task (:func:`.task.run_task`, key
``run-<run_id>``). The driver writes each row as its task finishes
(:class:`.store.RowStore`), so:

* an interrupted sweep resumes: runs whose rows are present are not submitted;
* a worker that dies mid-run loses nothing written: the scheduler reschedules its
  tasks on the other workers (the embedded cluster's nanny restarts it); a run that
  kills ``distributed.scheduler.allowed-failures`` + 1 workers becomes an ``error`` row.

The embedded cluster has one process per core, one thread each, and every task limits
BLAS to one thread (``threadpoolctl``), so the workers do not compete inside a solve.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .config import Plan
from .schema import columns
from .store import RowStore
from .task import run_task

__all__ = ["SweepOutcome", "run_sweep"]


@dataclass
class SweepOutcome:
    """What one invocation did.

    Attributes:
        rows: Every row of the plan now in the rows file (run id → row).
        computed: Run ids computed by this invocation, in finishing order.
        skipped: Run ids already present (not recomputed).
        wall_s: From the first submission to the last row.
        cluster_s: Starting (or connecting to) the cluster.
        workers: Worker processes (0: in-process).
        info: What ``run_info.json`` records.
    """

    rows: dict[str, dict[str, Any]]
    computed: list[str]
    skipped: list[str]
    wall_s: float
    cluster_s: float
    workers: int
    info: dict = field(default_factory=dict)


def _loadavg() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:  # pragma: no cover - platforms without it
        return None


def _cpu_pressure() -> float | None:
    """Share of the last 60 s in which some runnable task waited for a CPU (Linux PSI, %)."""
    try:
        first = Path("/proc/pressure/cpu").read_text().splitlines()[0]
        return float(first.split("avg60=")[1].split()[0])
    except (OSError, IndexError, ValueError):
        return None


def _progress(total: int, done: int, enabled: bool):
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, initial=done, desc="sweep", unit="run", file=sys.stderr,
                dynamic_ncols=True, smoothing=0.1,
                bar_format="{desc}: {n}/{total} runs [{elapsed}<{remaining}, {rate_fmt}]"
                           "{postfix}")


def warm_up() -> None:
    """What every worker process does once before its first run (part of the cluster
    start, not of the runs' wall time): import the scenario and solver modules."""
    from prioik import formulations
    from prioik.benchmarks import fencing  # noqa: F401

    from . import task  # noqa: F401 - the worker's entry point and its imports

    formulations.get("extended_jacobian")
    formulations.get("hierarchical_active_set")


def run_sweep(plan: Plan, out, *, workers: int | None = None, scheduler: str | None = None,
              progress: bool = True,
              on_row: Callable[[dict, Any], None] | None = None) -> SweepOutcome:
    """Run every run of ``plan`` whose row is not yet in ``out/rows.csv``.

    Args:
        plan: From :func:`.config.plan_from_config`.
        out: Output folder (``rows.csv``, ``sweep.json``, ``run_info.json``).
        workers: Worker processes of the embedded cluster (``None``: one per core;
            ``0``: run in this process, without dask).
        scheduler: Address of an existing scheduler (``tcp://host:port``) instead.
        progress: A progress bar with counts, rate and ETA on stderr.
        on_row: Called as ``on_row(row, client)`` after each row is written
            (``client`` is ``None`` in-process).

    Returns:
        A :class:`SweepOutcome`.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(json.dumps(
        {"config": plan.config, "fingerprint": plan.fingerprint(), "runs": len(plan.runs)},
        indent=2, default=str) + "\n")
    store = RowStore(out / "rows.csv", columns(plan.runs[0].params, plan.scenario))
    todo = [r for r in plan.runs if r.run_id not in store]
    skipped = [r.run_id for r in plan.runs if r.run_id in store]
    computed: list[str] = []
    bar = _progress(len(plan.runs), len(skipped), progress)
    if skipped:
        print(f"resuming: {len(skipped)} of {len(plan.runs)} rows already in "
              f"{store.path}; running the {len(todo)} missing", file=sys.stderr)
    load0, pressure0 = _loadavg(), _cpu_pressure()
    cluster_s, n_workers, client, cluster = 0.0, 0, None, None

    def record(row: dict) -> None:
        store.append(row)
        computed.append(row["run_id"])
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"{row['label']}: {row['status']}"
                                f"{' FAILED' if row['failed'] else ''}", refresh=False)
        if on_row is not None:
            on_row(row, client)

    t_start = time.perf_counter()
    try:
        if not todo:
            pass
        elif workers == 0 and scheduler is None:
            for r in todo:
                record(run_task(r.task(plan.scenario, plan.algorithmic_error)))
        else:
            from distributed import Client, LocalCluster, as_completed
            if scheduler is not None:
                client = Client(scheduler)
            else:
                cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1,
                                       threads_per_worker=1, processes=True,
                                       dashboard_address=None)
                client = Client(cluster)
            n_workers = len(client.scheduler_info()["workers"])
            client.run(warm_up)
            cluster_s = time.perf_counter() - t_start
            t_start = time.perf_counter()
            by_key = {f"run-{r.run_id}": r for r in todo}
            futures = client.map(run_task,
                                 [r.task(plan.scenario, plan.algorithmic_error) for r in todo],
                                 key=list(by_key), pure=False)
            from distributed import KilledWorker
            for fut in as_completed(futures):
                try:
                    row = fut.result()
                except KilledWorker as exc:
                    from .schema import empty_row
                    r = by_key[fut.key]
                    row = empty_row(r.task(plan.scenario, plan.algorithmic_error))
                    row.update(status="error", message=f"killed its worker repeatedly: {exc}")
                record(row)
                fut.release()
    finally:
        wall = time.perf_counter() - t_start
        if bar is not None:
            bar.close()
        store.close()
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    info = {"runs_total": len(plan.runs), "runs_computed": len(computed),
            "runs_skipped": len(skipped), "workers": n_workers,
            "mode": ("nothing to run" if not todo else f"scheduler {scheduler}" if scheduler
                     else "in-process" if workers == 0 else "LocalCluster"),
            "blas_threads_per_worker": 1, "wall_time_s": wall, "cluster_start_s": cluster_s,
            "runs_per_minute": (60.0 * len(computed) / wall) if computed and wall > 0 else None,
            "cpu_count": os.cpu_count(), "load_average_start": load0,
            "load_average_end": _loadavg(), "cpu_pressure_avg60_start": pressure0,
            "cpu_pressure_avg60_end": _cpu_pressure()}
    info_path = out / "run_info.json"
    previous = []
    if info_path.exists():
        try:
            previous = json.loads(info_path.read_text()).get("invocations", [])
        except (ValueError, AttributeError):
            previous = []
    info["invocations"] = previous + [{k: v for k, v in info.items()}]
    info_path.write_text(json.dumps(info, indent=2) + "\n")
    ids = {r.run_id for r in plan.runs}
    rows = {k: v for k, v in rows_by_id(out / "rows.csv").items() if k in ids}
    rate = f", {info['runs_per_minute']:.1f} runs/min" if info["runs_per_minute"] else ""
    print(f"sweep: {len(computed)} run(s) computed, {len(skipped)} already present, "
          f"{len(rows)}/{len(plan.runs)} rows in {out / 'rows.csv'}; {wall:.1f} s on "
          f"{n_workers or 'no'} worker(s){rate}", file=sys.stderr)
    return SweepOutcome(rows, computed, skipped, wall, cluster_s, n_workers, info)


def rows_by_id(path) -> dict[str, dict]:
    """Run id → row of a rows file."""
    from .store import read_rows
    return {r["run_id"]: r for r in read_rows(path)}
