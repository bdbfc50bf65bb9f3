"""The result records of the benchmark commands and their files.

One dataclass per kind of row — :class:`TimingRow` (``prioik bench``: one variant timed
on one case) and :class:`RunSummary` (one scenario run: ``prioik fencing``, ``arm``,
``sweep``) — and one CSV writer and reader for every record: the columns are the
record's fields, in order (a field with ``metadata={"csv": False}`` stays out), and the
reader converts each cell back to its field's type (``nan``, ``inf`` and empty cells
included), so a written file reads back as the records that were written.
"""

from __future__ import annotations

import csv
import math
import typing
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

__all__ = ["TimingRow", "RunSummary", "csv_columns", "write_csv", "read_csv"]

R = TypeVar("R")


@dataclass
class TimingRow:
    """One variant timed on one case (``results.csv`` of ``prioik bench``; times in µs).

    Attributes:
        suite: ``"random"`` or ``"g1"``.
        case: The case's name (``"random n=35 k=4"``, ``"g1 compatible"``).
        n, k, rows: Unknowns, levels and total rows of the case.
        label: The variant's label (:mod:`prioik.benchmarks.variants`).
        formulation, backend, options: What the label stands for.
        repeats: Timed solves.
        median_us, p10_us, p90_us: Of the timed solves (the formulation's solve alone,
            ``Solution.time_s``).
        success_rate: Share of solves that are not failed and match ``reference``'s
            residuals level by level.
        dist_median, dist_max: ``‖x − x_ref‖ / max(1, ‖x_ref‖)`` over the solves.
        verify_median_us: Median of the verification stage after each solve
            (``Solution.verify_time_s``); NaN where no verification ran.
        status: ``ok``, ``reduced``, ``skipped``, ``unsupported`` or ``error``.
        note: Why, when the status is not ``ok``.
        probe_s: A skipped row's measured solve (s; not written to the CSV).
    """

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
    verify_median_us: float = math.nan
    status: str = "ok"
    note: str = ""
    probe_s: float = field(default=math.nan, metadata={"csv": False})


def _finite(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _max(values) -> float | None:
    a = np.asarray(values, dtype=float)
    return _finite(np.nanmax(a)) if a.size and not np.isnan(a).all() else None


def _verify_median(times) -> float | None:
    """The median verification time of a run, ``None`` when it records none or none ran."""
    if times is None or not len(times) or not (np.asarray(times) > 0).any():
        return None
    return _finite(np.median(times))


@dataclass
class RunSummary:
    """What one scenario run measured (a ``summary.json`` entry, a sweep row's metrics).

    Non-finite values are ``None``. Errors in m or rad, times in s.

    Attributes:
        final_tip_error_m: The tip's distance to its target at the last step.
        max_algorithmic_error: Largest ``‖e_algorithm‖`` (eq. 29).
        maxima: ``max_<error>`` of each of the scenario's ``summary_errors``.
        max_qdd_norm: Largest ``‖q̈‖``.
        median_step_time_s, p90_step_time_s: Of kinematics + solve + torque.
        median_solve_time_s: Of the solve alone (less prioik's verification stage).
        median_verify_time_s: Of prioik's verification stage (``None`` where the run
            records none, or none ran).
        failed: The run stopped early.
    """

    final_tip_error_m: float | None = None
    max_algorithmic_error: float | None = None
    maxima: dict[str, float | None] = field(default_factory=dict)
    max_qdd_norm: float | None = None
    median_step_time_s: float | None = None
    p90_step_time_s: float | None = None
    median_solve_time_s: float | None = None
    median_verify_time_s: float | None = None
    failed: bool = False

    @classmethod
    def of(cls, res, errors: tuple[str, ...]) -> RunSummary:
        """The summary of a :class:`~prioik.robots.SimulationResult` with the maxima of
        ``errors`` (keys of ``res.errors``; a missing one is ``None``)."""
        tip = res.errors.get("tip_error_m", np.array([]))
        steps = res.steps
        return cls(
            final_tip_error_m=_finite(tip[-1]) if len(tip) else None,
            max_algorithmic_error=_max(res.algorithmic_error),
            maxima={f"max_{e}": _max(res.errors.get(e, [])) for e in errors},
            max_qdd_norm=_max(np.linalg.norm(res.a, axis=1)) if steps else None,
            median_step_time_s=_finite(np.median(res.step_time_s)) if steps else None,
            p90_step_time_s=_finite(np.percentile(res.step_time_s, 90)) if steps else None,
            median_solve_time_s=_finite(np.median(res.solve_time_s)) if steps else None,
            median_verify_time_s=_verify_median(res.verify_time_s),
            failed=bool(res.failed))

    @staticmethod
    def keys(errors: tuple[str, ...]) -> tuple[str, ...]:
        """The keys of :meth:`to_dict` for a scenario whose summary errors are ``errors``."""
        return ("final_tip_error_m", "max_algorithmic_error",
                *(f"max_{e}" for e in errors), "max_qdd_norm", "median_step_time_s",
                "p90_step_time_s", "median_solve_time_s", "median_verify_time_s", "failed")

    def to_dict(self) -> dict[str, Any]:
        """Flat, in the order of :meth:`keys`."""
        return {"final_tip_error_m": self.final_tip_error_m,
                "max_algorithmic_error": self.max_algorithmic_error, **self.maxima,
                "max_qdd_norm": self.max_qdd_norm,
                "median_step_time_s": self.median_step_time_s,
                "p90_step_time_s": self.p90_step_time_s,
                "median_solve_time_s": self.median_solve_time_s,
                "median_verify_time_s": self.median_verify_time_s, "failed": self.failed}


# ------------------------------------------------------------------------ CSV
def csv_columns(cls) -> tuple[str, ...]:
    """The CSV columns of record class ``cls``: its fields in order, those with
    ``metadata={"csv": False}`` left out."""
    return tuple(f.name for f in fields(cls) if f.metadata.get("csv", True))


def write_csv(path, records: list, cls=None) -> Path:
    """Write ``records`` (dataclass instances of one class; ``cls`` names it when the
    list may be empty) with a header line of :func:`csv_columns`."""
    path = Path(path)
    cls = cls or (type(records[0]) if records else None)
    if cls is None:
        raise ValueError(f"{path}: no records and no record class to name the columns")
    cols = csv_columns(cls)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, extrasaction="ignore")
        w.writeheader()
        for r in records:
            w.writerow({k: v for k, v in asdict(r).items() if k in cols})
    return path


def _convert(text: str, kind, default):
    if kind in (float, "float"):
        return float(text) if text != "" else default
    if kind in (int, "int"):
        return int(text) if text != "" else default
    if kind in (bool, "bool"):
        return text == "True"
    return text


def read_csv(path, cls: type[R]) -> list[R]:
    """The records of a file written by :func:`write_csv` for ``cls``.

    A file written before a column with a default existed (e.g. ``verify_median_us``)
    reads with that column at its default.

    Raises:
        ValueError: the header is not ``cls``'s columns, in order, up to columns with a
            default that the file lacks (names the file).
    """
    path = Path(path)
    hints = typing.get_type_hints(cls)
    cols = csv_columns(cls)
    defaults = {f.name: f.default for f in fields(cls)}
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        found = tuple(reader.fieldnames or ())
        optional = {c for c in cols if defaults[c] is not MISSING}
        if found != tuple(c for c in cols if c in found) or not set(cols) - set(found) <= \
                optional:
            raise ValueError(f"{path}: columns {reader.fieldnames} are not those of "
                             f"{cls.__name__} ({', '.join(cols)})")
        return [cls(**{k: _convert(row[k], hints[k], defaults[k]) if k in row
                       else defaults[k] for k in cols}) for row in reader]
