"""The figures of the decision table of ``docs/how-to/choose-a-formulation.md``, written
from a ``prioik bench`` run's ``results.csv`` (``choice.md``, included by the page).

Every figure is a median of ``results.csv``: per use case (:data:`CHOICES`), the row it
names on the two G1 fencing cases, the ratio to the fastest row of the case that matched
``reference`` on every solve (success 100 %), and the share of solves that matched; then
how the cost grows on the random cases (:data:`GROWTH_LABELS`). A row the CSV does not
hold, or holds without a time (skipped, unsupported, error), reads
:data:`NOT_MEASURED` — never a number from elsewhere.

``prioik bench`` writes ``choice.md`` beside ``results.csv`` in every run;
``prioik bench --from-csv CSV --out DIR`` writes it from a CSV alone, no run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from prioik.benchmarks.report import table, us
from prioik.benchmarks.results import TimingRow

from .settings import SUCCESS_TOL

__all__ = ["Choice", "CHOICES", "G1_CASES", "GROWTH_LABELS", "NOT_MEASURED", "FILE_NAME",
           "choice_markdown", "write_choice"]

#: the file written beside ``results.csv``
FILE_NAME = "choice.md"
#: what a cell says when the CSV holds no time for its row
NOT_MEASURED = "not measured in the last run"
#: the G1 cases of the table's columns, in order
G1_CASES = ("g1 compatible", "g1 incompatible")
#: the formulations of the growth table (random cases)
GROWTH_LABELS = ("extended_jacobian", "nullspace")
#: the statuses of rows that hold a time
_TIMED = ("ok", "reduced")


@dataclass(frozen=True)
class Choice:
    """A row of the decision table.

    Attributes:
        need: The reader's stack and need.
        label: A row label of ``results.csv`` (``"nullspace"``,
            ``"daqp_hierarchical[raw]"``); with ``backends``, a formulation name whose
            rows (one per back-end, ``NAME[backend]``) give a range.
        backends: ``label`` names a formulation timed once per back-end.
    """

    need: str
    label: str
    backends: bool = False


#: the use cases of the decision table, in the page's order
CHOICES: tuple[Choice, ...] = (
    Choice("equality tasks, exact strict priorities, a control loop", "extended_jacobian"),
    Choice("the same by null-space projections (the classic recursion)", "nullspace"),
    Choice("inequality tasks (joint limits as bounds, regions), exact",
           "hierarchical_active_set"),
    Choice("hard joint bounds, and a task allowed to shrink when it cannot be met", "sns"),
    Choice("torque-level control with the mass matrix, exact in the metric M",
           "operational_space"),
    Choice("torque-level control, the unifying framework", "unifying"),
    Choice("a ground truth for tests", "reference"),
    Choice("your own QP back-end, or another cost (one QP per level)", "cascaded_qp",
           backends=True),
    Choice("an independent check of an inequality stack", "cvxpy", backends=True),
    Choice("LexLS's solver, for comparison", "lexls"),
    Choice("DAQP's hierarchical solver, for comparison", "daqp_hierarchical"),
    Choice("DAQP's C call alone (no level compression, no check)", "daqp_hierarchical[raw]"),
    Choice("PlaCo's solver, for comparison", "placo"),
)


def _timed(r: TimingRow | None) -> bool:
    return r is not None and r.status in _TIMED and math.isfinite(r.median_us)


def _time(v: float) -> str:
    text = us(v)
    return text if text.endswith("ms") else f"{text} µs"


def _ratio(v: float) -> str:
    return f"{v:.1f}×" if v < 10 else f"{v:,.0f}×"


def _share(v: float) -> str:
    return f"{v:.0%}" if math.isfinite(v) else "–"


def _fastest_exact(rows: list[TimingRow], case: str) -> TimingRow | None:
    """The fastest row of ``case`` that matched ``reference`` on every solve."""
    exact = [r for r in rows if r.case == case and _timed(r) and r.success_rate >= 1.0]
    return min(exact, key=lambda r: r.median_us, default=None)


def _matching(rows: list[TimingRow], case: str, choice: Choice) -> list[TimingRow]:
    if choice.backends:
        return [r for r in rows if r.case == case and r.formulation == choice.label
                and r.label.startswith(f"{choice.label}[")]
    return [r for r in rows if r.case == case and r.label == choice.label]


def _cells(rows: list[TimingRow], case: str, choice: Choice) -> tuple[str, str, str]:
    """Median, ratio to the fastest exact row and success of ``choice`` on ``case``."""
    found = _matching(rows, case, choice)
    timed = sorted((r for r in found if _timed(r)), key=lambda r: r.median_us)
    if not timed:
        status = sorted({r.status for r in found})
        why = f" ({', '.join(status)})" if status else ""
        return NOT_MEASURED + why, "–", "–"
    base = _fastest_exact(rows, case)
    lo, hi = timed[0], timed[-1]
    if lo is hi:
        median = _time(lo.median_us)
        ratio = _ratio(lo.median_us / base.median_us) if base else "–"
        success = _share(lo.success_rate)
    else:
        median = f"{_time(lo.median_us)} (`{lo.label}`) to {_time(hi.median_us)}"
        ratio = (f"{_ratio(lo.median_us / base.median_us)} to "
                 f"{_ratio(hi.median_us / base.median_us)}" if base else "–")
        rates = sorted(r.success_rate for r in timed if math.isfinite(r.success_rate))
        success = ("–" if not rates else _share(rates[0]) if rates[0] == rates[-1]
                   else f"{_share(rates[0])} to {_share(rates[-1])}")
    return median, ratio, success


def _case_title(case: str) -> str:
    return case.removeprefix("g1 ")


def choice_table(rows: list[TimingRow]) -> str:
    """The decision table: per use case, its row's median on each G1 case, the ratio to
    the case's fastest exact row and the share of solves that matched ``reference``."""
    body = []
    for choice in CHOICES:
        cells = [_cells(rows, case, choice) for case in G1_CASES]
        use = f"`{choice.label}`" + (" (one row per back-end)" if choice.backends else "")
        body.append([choice.need, use, *(c[0] for c in cells), *(c[1] for c in cells),
                     " / ".join(c[2] for c in cells)])
    head = ["your stack and need", "use",
            *(f"median, {_case_title(c)}" for c in G1_CASES),
            *(f"× fastest exact, {_case_title(c)}" for c in G1_CASES),
            "matched `reference` (" + " / ".join(_case_title(c) for c in G1_CASES) + ")"]
    return table(head, body, "ll" + "r" * (2 * len(G1_CASES)) + "r")


def _fastest_line(rows: list[TimingRow]) -> str:
    parts = []
    for case in G1_CASES:
        base = _fastest_exact(rows, case)
        parts.append(f"`{base.label}` ({_time(base.median_us)}) on {_case_title(case)}"
                     if base else f"none on {_case_title(case)}")
    return ", ".join(parts)


def _g1_shape(rows: list[TimingRow]) -> str:
    g1 = [r for r in rows if r.case in G1_CASES]
    if not g1:
        return "no G1 case in this CSV"
    shapes = sorted({(r.n, r.k, r.rows) for r in g1})
    return "; ".join(f"n = {n}, {k} levels, {m} rows" for n, k, m in shapes)


def growth_table(rows: list[TimingRow]) -> str:
    """Median of each of :data:`GROWTH_LABELS` on the random cases over ``n`` (columns),
    at the fewest and the most levels of the run."""
    random_rows = [r for r in rows if r.suite == "random"]
    ns = sorted({r.n for r in random_rows})
    ks = sorted({r.k for r in random_rows})
    if not ns:
        return NOT_MEASURED + " (no random case in this CSV)"
    body = []
    for label in GROWTH_LABELS:
        for k in dict.fromkeys((ks[0], ks[-1])):
            cells = []
            for n in ns:
                r = next((r for r in random_rows if r.label == label and r.n == n
                          and r.k == k), None)
                if _timed(r):
                    cells.append(us(r.median_us))
                elif r is not None:
                    cells.append(f"{NOT_MEASURED} ({r.status})")
                else:
                    cells.append(NOT_MEASURED)
            body.append([f"`{label}`", k, *cells])
    return table(["formulation", "levels", *(f"n = {n}" for n in ns)], body,
                 "lr" + "r" * len(ns))


def choice_markdown(rows: list[TimingRow], csv_path: str | Path, out: str | Path) -> str:
    """``choice.md``: the decision table and the growth table of ``rows`` (the records
    of ``csv_path``, named as the figures' source; ``out``: the folder it is written to,
    named in the command that rewrites it)."""
    csv_path = Path(csv_path)
    return "\n".join([
        f"<!-- generated from {csv_path} by `prioik bench --from-csv {csv_path} "
        f"--out {out}`; do not edit by hand -->",
        "",
        f"Medians from `{csv_path}` (the G1 fencing stacks: {_g1_shape(rows)}; joint "
        f"limits as activation rows, so that every formulation takes the same stacks). "
        f"**Matched `reference`**: the share of solves whose residual at every level is "
        f"within {SUCCESS_TOL:g}·max(1, ‖b_i‖) of `reference`'s. **× fastest exact**: the "
        f"median over that of the fastest row of the case that matched `reference` on "
        f"every solve: {_fastest_line(rows)}.",
        "",
        choice_table(rows),
        "",
        f"**How the cost grows** (random stacks, median µs; from `{csv_path}`):",
        "",
        growth_table(rows),
        "",
    ])


def write_choice(rows: list[TimingRow], csv_path: str | Path, out: str | Path) -> Path:
    """Write ``out/choice.md`` (:func:`choice_markdown`); returns its path."""
    path = Path(out) / FILE_NAME
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(choice_markdown(rows, csv_path, out))
    return path
