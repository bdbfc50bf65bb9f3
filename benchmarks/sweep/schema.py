"""The one schema of a sweep's rows (``rows.csv``): identity, parameters, metrics.

Identity and variant: ``run_id``, ``point``, ``scenario``, ``label``, ``formulation``,
``options`` (JSON), ``level``. Parameters: one column per scenario parameter (a
3-vector as ``<name>_x``, ``_y``, ``_z``). Metrics (:func:`metrics`: the scenario's
:class:`~prioik.benchmarks.results.RunSummary` without ``failed``; empty when not
measured): errors in m / rad, ``max_qdd_norm``, median and 90th-percentile step time and
median solve time (s). Outcome: ``steps``, ``failed`` (stopped early: a failed solve, a
non-finite value or divergence), ``status`` (``ok``, ``unsupported``, ``error``),
``message``, ``wall_s`` (the run's wall time on its worker) and ``worker``
(``host:pid``).

Success is judged from these columns at report time (:mod:`.stats`), so changing a
bound needs no rerun.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["metrics", "IDENTITY", "OUTCOME", "columns", "empty_row", "flatten_params",
           "DETERMINISTIC_EXCLUDE"]

IDENTITY = ("run_id", "point", "scenario", "label", "formulation", "options", "level")
OUTCOME = ("steps", "failed", "status", "message", "wall_s", "worker")
#: columns that depend on the machine and its load, not on the computation
DETERMINISTIC_EXCLUDE = ("median_step_time_s", "p90_step_time_s", "median_solve_time_s",
                         "median_verify_time_s",
                         "wall_s", "worker")


def flatten_params(params: dict[str, Any]) -> dict[str, Any]:
    """Parameters as columns (3-vectors split into ``_x``, ``_y``, ``_z``)."""
    out: dict[str, Any] = {}
    for k, v in params.items():
        if isinstance(v, (list, tuple)):
            for axis, x in zip("xyz", v, strict=False):
                out[f"{k}_{axis}"] = x
        else:
            out[k] = v
    return out


def metrics(scenario: str) -> tuple[str, ...]:
    """The metric columns of ``scenario``'s runs: its run summary's keys
    (:meth:`~prioik.benchmarks.results.RunSummary.keys`) but ``failed``."""
    from prioik.benchmarks.results import RunSummary
    from prioik.benchmarks.scenario_runs import scenario_class
    keys = RunSummary.keys(tuple(scenario_class(scenario).summary_errors))
    return tuple(k for k in keys if k != "failed")


def columns(params: dict[str, Any], scenario: str) -> list[str]:
    """Every column, in order, of a sweep of ``scenario`` whose runs have ``params``."""
    return [*IDENTITY, *flatten_params(params), *metrics(scenario), *OUTCOME]


def empty_row(task: dict[str, Any]) -> dict[str, Any]:
    """The row of ``task`` with identity and parameters set, metrics empty."""
    v = task["variant"]
    row: dict[str, Any] = {"run_id": task["run_id"], "point": task["point"],
                           "scenario": task["scenario"], "label": v["label"],
                           "formulation": v["formulation"],
                           "options": json.dumps(v["options"], sort_keys=True),
                           "level": v["level"]}
    row.update(flatten_params(task["params"]))
    row.update({k: None for k in metrics(task["scenario"])})
    row.update({"steps": 0, "failed": True, "status": "", "message": "", "wall_s": None,
                "worker": ""})
    return row
