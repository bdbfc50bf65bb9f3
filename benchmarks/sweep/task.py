"""One sweep run: plain data in, one summary row out (what a worker executes).

The run goes through the same path as ``prioik fencing``
(:func:`prioik.benchmarks.scenario_runs.run_one`: a solver prepared once per stack
layout, :func:`prioik.robots.simulate`), with one BLAS thread (``threadpoolctl``) so that
the workers of one machine do not compete inside each solve.
"""

from __future__ import annotations

import os
import socket
import time
import traceback
from typing import Any

from .schema import empty_row, metrics

__all__ = ["run_task"]


def run_task(task: dict[str, Any]) -> dict[str, Any]:
    """Simulate the run ``task`` (:meth:`.config.Run.task`) and return its row
    (:mod:`.schema`). A formulation that cannot take the stack gives a row with
    ``status = "unsupported"``; any other exception a row with ``status = "error"``
    and the message — both are results, written like any row."""
    from prioik.benchmarks.scenario_runs import run_one, scenario_class, summarize
    from prioik.benchmarks.variants import Variant
    from prioik.hierarchy import UnsupportedTaskError
    from prioik.threads import blas_threads

    from .scenarios import SWEEP_SCENARIOS

    t0 = time.perf_counter()
    params = task["params"]
    row = empty_row(task)
    try:
        with blas_threads(1):
            sc = SWEEP_SCENARIOS[task["scenario"]]().build(params)
            res = run_one(Variant.from_dict(task["variant"]), "sweep", params["duration"],
                          params["dt"], scenario=sc,
                          algorithmic_error=task["algorithmic_error"],
                          velocity_gain=params.get("velocity_gain", 20.0))
        s = summarize(res, tuple(scenario_class(task["scenario"]).summary_errors))
        for key in metrics(task["scenario"]):
            row[key] = s[key]
        row["steps"] = res.steps
        row["failed"] = bool(res.failed)
        row["message"] = res.message
        row["status"] = "ok"
    except UnsupportedTaskError as exc:
        row.update(status="unsupported", message=str(exc), failed=True)
    except Exception as exc:  # noqa: BLE001 - a run's error is its row, not the sweep's
        row.update(status="error", failed=True,
                   message=f"{type(exc).__name__}: {exc} "
                           f"[{traceback.format_exc(limit=-1).strip().splitlines()[0]}]")
    row["wall_s"] = time.perf_counter() - t0
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    return row
