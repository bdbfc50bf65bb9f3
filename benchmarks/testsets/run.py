"""Run a test set: every formulation row on every problem, timed with its prepared
solver, judged at every tolerance profile, one CSV row per problem × row.

Rows are the ``bench`` report's variants (:func:`prioik.benchmarks.variants.table`: every
available formulation, one row per QP back-end of ``cascaded_qp``, the plugins' declared
settings) except ``cvxpy`` (a modelling layer over the back-ends ``cascaded_qp``'s rows
cover, tens of ms per level: ask for it with ``labels``). On a sequential test set a
formulation with a warm or hot start (``warm_start``, ``hot_start``) follows each
sequence warm in its default row and gets a ``[cold]`` row beside it; on the others
every solve is cold.

Timing: ``repeats`` passes over the problems in order, the rows interleaved within a
pass; per problem the fastest pass's wall time of ``solver.solve(data)``
(``perf_counter``, the prepared solver of :func:`prioik.prepare`, prepared untimed: one
per layout, anew at each sequence's start). The answer judged is the first pass's, and
so is its flop count (``flops``: the compiled kernel's ``sol.flops`` for the
formulations that count them, empty for the others).

The exact answer of each problem is ``hierarchical_active_set``'s (cold); where the
source states a solution or level values, the CSV records how far the exact answer's
level values are from them.
"""

from __future__ import annotations

import csv
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from prioik.hierarchy import check_lexicographic, level_residuals

from .base import Problem, TestSet
from .metrics import (
    JUDGED_BY_CERTIFICATE,
    JUDGED_BY_VALUES,
    PROFILES,
    VALUE_JUDGED,
    certificate_success,
    value_success,
)
from .report import GENERIC_UNSUPPORTED

__all__ = ["Row", "EXACT", "default_rows", "run_test_set", "write_csv", "load_csv",
           "CSV_FIELDS"]

#: the formulation whose answer is each problem's exact answer
EXACT = "hierarchical_active_set"
#: options that make a prepared solver follow a sequence (formulation option → warm value)
WARM_OPTIONS = ("warm_start", "hot_start")
#: rows left out of the default selection, with why
LEFT_OUT = {"cvxpy": "a modelling layer over the back-ends cascaded_qp's rows cover "
                     "(tens of ms per level QP); ask for it with --formulations"}


@dataclass(frozen=True)
class Row:
    """A formulation row of a test-set run: its label, formulation and options."""

    label: str
    formulation: str
    options: dict[str, Any] = field(default_factory=dict, hash=False)


#: the CSV's columns (lists are JSON; success columns ``1``/``0``, empty when not judged;
#: ``flops`` empty where the formulation does not count them)
CSV_FIELDS = ("test_set", "problem", "sequence", "row", "formulation", "n", "levels",
              "rows", "status", "time_s", "verify_time_s", "flops", "judged_by",
              *(f"success_{p}" for p in PROFILES), *(f"reason_{p}" for p in PROFILES),
              "values", "exact_values", "exact_status", "stated_values", "stated_by",
              "exact_vs_stated", "message")


def _warm_option(formulation: str) -> str | None:
    from prioik import formulations
    opts = formulations.get(formulation).options
    return next((o for o in WARM_OPTIONS if o in opts), None)


def default_rows(sequential: bool, labels: list[str] | None = None
                 ) -> tuple[list[Row], list[str]]:
    """The rows of a run (see the module docstring) and notes on those left out or not
    available here.

    Raises:
        ValueError: a label the bench report does not know.
    """
    from prioik.benchmarks.variants import table
    tab = table("bench")
    chosen, notes = tab.select(labels)
    notes = list(notes) + list(tab.notes)
    if not labels:
        notes += [f"{name}: {why}" for name, why in LEFT_OUT.items()
                  if any(v.formulation == name for v in chosen)]
        chosen = [v for v in chosen if v.formulation not in LEFT_OUT]
    rows: list[Row] = []
    for v in chosen:
        warm = _warm_option(v.formulation)
        if warm is None or warm in v.options:
            rows.append(Row(v.label, v.formulation, dict(v.options)))
            continue
        rows.append(Row(v.label, v.formulation, {**v.options, warm: sequential}))
        if sequential and not v.tag:
            rows.append(Row(f"{v.formulation}[cold]", v.formulation,
                            {**v.options, warm: False}))
    return rows, notes


def _fixed_mass_matrix(n: int) -> np.ndarray:
    from prioik.benchmarks.stacks import random_mass_matrix
    return random_mass_matrix(n)


class _Solvers:
    """One row's prepared solvers (per layout), anew at each sequence's start."""

    def __init__(self, row: Row) -> None:
        from prioik import formulations
        self.row = row
        self.caps = formulations.get(row.formulation).capabilities
        self._by_layout: dict = {}
        self._sequence: str | None = None

    def get(self, problem: Problem, sequential: bool):
        import prioik
        if sequential and problem.sequence != self._sequence:
            self._by_layout = {}
            self._sequence = problem.sequence
        layout = problem.stack.layout
        solver = self._by_layout.get(layout)
        if solver is None:
            solver = prioik.prepare(layout, self.row.formulation, **self.row.options)
            self._by_layout[layout] = solver
        return solver


#: the message of a solve the formulation refused as a kind of stack it cannot take
UNSUPPORTED = "unsupported: "


def _solve(solvers: _Solvers, problem: Problem, sequential: bool, mass: np.ndarray | None
           ) -> tuple[Any, float, str]:
    """``(solution or None, wall time of the solve, message)``: the call's wall time less
    the verification stage's (``Solution.verify_time_s``, reported apart); the message
    starts with :data:`UNSUPPORTED` when the formulation refused the stack's kind of
    task."""
    from prioik.formulations import FormulationError
    from prioik.hierarchy import TaskStackError, UnsupportedTaskError
    data = problem.stack.data
    step = {"mass_matrix": mass} if solvers.caps.needs_mass_matrix else {}
    try:
        solver = solvers.get(problem, sequential)
        t0 = time.perf_counter()
        sol = solver.solve(data, **step)
        elapsed = time.perf_counter() - t0 - sol.verify_time_s
    except UnsupportedTaskError as exc:
        return None, math.nan, f"{UNSUPPORTED}{exc}"
    except (FormulationError, TaskStackError, ValueError, ArithmeticError) as exc:
        return None, math.nan, f"{type(exc).__name__}: {exc}"
    return sol, elapsed, ""


def _supported(caps, problem: Problem) -> bool:
    return caps.inequalities or not problem.has_inequalities


def _values(problem: Problem, x: np.ndarray) -> np.ndarray:
    with np.errstate(all="ignore"):
        return level_residuals(problem.stack.data, np.asarray(x, float)) ** 2


def _exact_answers(problems: list[Problem]) -> list[tuple[np.ndarray | None, str]]:
    """Per problem, the exact answer's level values and status (cold active set)."""
    import prioik
    out, solvers = [], {}
    for p in problems:
        layout = p.stack.layout
        if layout not in solvers:
            solvers[layout] = prioik.prepare(layout, EXACT, warm_start=False)
        sol = solvers[layout].solve(p.stack.data)
        out.append((None if sol.status == "failed" else _values(p, sol.x), sol.status))
    return out


def _judge(row: Row, problem: Problem, sol, exact: np.ndarray | None
           ) -> tuple[str, dict[str, bool], dict[str, str]]:
    """``(judged_by, success per profile, reason per profile)``."""
    judged_by = (JUDGED_BY_VALUES if row.formulation in VALUE_JUDGED
                 else JUDGED_BY_CERTIFICATE)
    success, reason = {}, {}
    message = sol.diagnostics.reason[:160]
    for name, tol in PROFILES.items():
        if sol.status == "failed":
            success[name], reason[name] = False, message or "no message"
            continue
        if judged_by == JUDGED_BY_VALUES:
            ok = value_success(sol.status, _values(problem, sol.x), exact, tol)
            success[name] = ok
            reason[name] = "" if ok else ("no exact answer" if exact is None else
                                          "level values off the exact answer's")
            continue
        report = check_lexicographic(problem.stack, sol.x, tol=tol)
        ok = certificate_success(sol.status, report)
        success[name] = ok
        if ok:
            reason[name] = ""
        elif not report.ok:
            bad = [i for i, lv in enumerate(report.levels) if not lv.ok]
            reason[name] = f"certificate fails at level {bad[0] if bad else '?'}"
        else:
            reason[name] = f"says {sol.status} though the certificate holds at this tolerance"
    return judged_by, success, reason


def _flops(sol) -> float | str:
    """The solve's floating-point operation count (:attr:`Solution.flops`), ``""`` when
    the formulation does not count them."""
    flops = sol.flops
    if flops is None:
        return ""
    flops = float(flops)
    return flops if math.isfinite(flops) and flops >= 0 else ""


def _json(values) -> str:
    return "" if values is None else json.dumps([float(v) for v in values])


def run_test_set(test_set: TestSet, rows: list[Row] | None = None, repeats: int = 3,
                 progress: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
    """Run ``rows`` (default :func:`default_rows`) on every problem of ``test_set``;
    returns the CSV's rows (:data:`CSV_FIELDS`), problem-major: level values as float
    arrays (``None`` where there are none), ``""`` where a field does not apply.

    Raises:
        ValueError: ``repeats < 1``.
    """
    if repeats < 1:
        raise ValueError(f"repeats must be ≥ 1, got {repeats}")
    sequential = test_set.sequential
    if rows is None:
        rows, _ = default_rows(sequential)
    problems = list(test_set.problems())
    exact = _exact_answers(problems)
    masses = [p.mass_matrix if p.mass_matrix is not None else _fixed_mass_matrix(p.stack.n)
              for p in problems]
    solvers = [_Solvers(r) for r in rows]
    times = np.full((len(rows), len(problems)), math.inf)
    answers: list[list[Any]] = [[None] * len(problems) for _ in rows]
    messages = [[""] * len(problems) for _ in rows]
    for rep in range(repeats):
        if progress:
            progress(f"{test_set.name}: pass {rep + 1}/{repeats}")
        for r, s in enumerate(solvers):
            for j, p in enumerate(problems):
                if not _supported(s.caps, p):
                    continue
                sol, t, msg = _solve(s, p, sequential, masses[j])
                if rep == 0:
                    answers[r][j], messages[r][j] = sol, msg
                if sol is not None:
                    times[r, j] = min(times[r, j], t)
    out = []
    for j, p in enumerate(problems):
        n, k, m = p.shape
        exact_values, exact_status = exact[j]
        stated = p.level_values
        gap = ""
        if stated is not None and exact_values is not None and len(stated) == len(exact_values):
            gap = float(np.max(np.abs(exact_values - stated) / np.maximum(1.0, np.abs(stated))))
        for r, row in enumerate(rows):
            rec: dict[str, Any] = {
                "test_set": test_set.name, "problem": p.name, "sequence": p.sequence,
                "row": row.label, "formulation": row.formulation, "n": n, "levels": k,
                "rows": m, "exact_values": exact_values, "exact_status": exact_status,
                "stated_values": None if stated is None else np.asarray(stated, float),
                "stated_by": p.stated_by, "exact_vs_stated": gap}
            sol = answers[r][j]
            if not _supported(solvers[r].caps, p):
                rec.update(status="unsupported", time_s="", judged_by="", values=None,
                           message=GENERIC_UNSUPPORTED)
            elif sol is None and messages[r][j].startswith(UNSUPPORTED):
                rec.update(status="unsupported", time_s="", judged_by="", values=None,
                           message=messages[r][j][len(UNSUPPORTED):])
            elif sol is None:
                rec.update(status="error", time_s="", judged_by="", values=None,
                           message=messages[r][j])
                for name in PROFILES:
                    rec[f"success_{name}"] = 0
                    rec[f"reason_{name}"] = messages[r][j][:160]
            else:
                judged_by, success, reason = _judge(row, p, sol, exact_values)
                rec.update(status=sol.status, time_s=float(times[r, j]),
                           verify_time_s=float(sol.verify_time_s), flops=_flops(sol),
                           judged_by=judged_by,
                           values=_values(p, sol.x),
                           message=sol.diagnostics.reason[:200])
                for name in PROFILES:
                    rec[f"success_{name}"] = int(success[name])
                    rec[f"reason_{name}"] = reason[name]
            out.append({f: rec.get(f, "") for f in CSV_FIELDS})
    return out


def write_csv(records: list[dict[str, Any]], path: str | Path) -> Path:
    """Write :func:`run_test_set`'s records (:data:`CSV_FIELDS`)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_FIELDS)
        writer.writeheader()
        for rec in records:
            writer.writerow({f: (_json(rec.get(f)) if f in _LIST else
                                 "" if rec.get(f) is None else rec.get(f))
                             for f in CSV_FIELDS})
    return path


_INT = ("n", "levels", "rows", *(f"success_{p}" for p in PROFILES))
_FLOAT = ("time_s", "verify_time_s", "flops", "exact_vs_stated")
_LIST = ("values", "exact_values", "stated_values")
#: columns added after the first files were written: empty when a file lacks them
_ADDED = ("flops",)


def load_csv(path: str | Path) -> list[dict[str, Any]]:
    """The records of a CSV written by :func:`write_csv`, typed as
    :func:`run_test_set` returns them (lists as float arrays, ``None`` where empty).

    A file written before the ``flops`` column was added loads with it empty.

    Raises:
        ValueError: the file lacks a column of :data:`CSV_FIELDS`.
    """
    path = Path(path)
    with path.open(newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [f for f in CSV_FIELDS if f not in (reader.fieldnames or ())
                   and f not in _ADDED]
        if missing:
            raise ValueError(f"{path}: not a test-set results file (missing columns "
                             f"{', '.join(missing)})")
        out = []
        for row in reader:
            raw = {f: "" for f in _ADDED} | row
            rec: dict[str, Any] = dict(raw)
            for f in _INT:
                rec[f] = int(raw[f]) if raw[f] != "" else ""
            for f in _FLOAT:
                rec[f] = float(raw[f]) if raw[f] != "" else ""
            for f in _LIST:
                rec[f] = np.array(json.loads(raw[f]), float) if raw[f] else None
            out.append(rec)
    return out
