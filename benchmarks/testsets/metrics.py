"""Tolerance profiles, what counts as a success, and the aggregate measures.

Profiles (qpbenchmark's): ``low`` 1e-3, ``mid`` 1e-6, ``high`` 1e-9.

Success of one solve at a profile's tolerance ``tol``:

* a formulation exact by design (every one but :data:`VALUE_JUDGED`): its status is
  ``optimal`` — or ``approximate`` where the certificate reads a rank decision at ``x``
  as ambiguous (:attr:`~prioik.hierarchy.LexicographicReport.ambiguous_levels`: there the
  exact solvers themselves say ``approximate``) — and
  ``check_lexicographic(stack, x, tol=tol)`` holds (:data:`JUDGED_BY_CERTIFICATE`);
* a formulation not exact by design (:data:`VALUE_JUDGED`: algorithmic error or soft
  priorities): it answers (status not ``failed``) and every level's residual
  ``‖w_i(x)‖`` is within ``tol · max(1, ‖w_i*‖)`` of the exact answer's ``‖w_i*‖``
  (:func:`value_success`; :data:`JUDGED_BY_VALUES`). The residuals, not their squares
  ``v_i = ‖w_i‖²``: on a level the exact answer meets (``v_i* = 0``) a residual of
  ``√tol`` would pass a rule on squares.

Aggregates (:func:`shifted_geometric_mean`): ``exp(mean(log(t + s))) − s`` with the
shift ``s`` on the scale of the data (:data:`TIME_SHIFT_S`, 10 µs: the solves take
1 µs to a few ms; :data:`FLOP_SHIFT`, 10⁴ flops: the same weight at 1 Gflop/s, the
counted solves take 10³ to 10⁶ flops), normalised to the best row of the test set.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

__all__ = ["PROFILES", "VALUE_JUDGED", "TIME_SHIFT_S", "JUDGED_BY_CERTIFICATE",
           "JUDGED_BY_VALUES", "FLOP_SHIFT", "shifted_geometric_mean", "values_within",
           "certificate_success", "value_success"]

#: tolerance profile → relative tolerance
PROFILES: dict[str, float] = {"low": 1e-3, "mid": 1e-6, "high": 1e-9}
#: formulations not exact by design (``CAPABILITIES.exact`` is ``False`` for their
#: algorithmic error or soft priorities): judged by their level values against the
#: exact answer, not by the certificate
VALUE_JUDGED = ("chiaverini", "unifying", "placo")
JUDGED_BY_CERTIFICATE = "certificate"
JUDGED_BY_VALUES = "values"
#: the shift of the shifted geometric mean of times (s)
TIME_SHIFT_S = 1e-5
#: the shift of the shifted geometric mean of flop counts (floating-point operations):
#: the time shift at 1 Gflop/s
FLOP_SHIFT = 1e4


def shifted_geometric_mean(values: Iterable[float], shift: float = TIME_SHIFT_S) -> float:
    """``exp(mean(log(v + shift))) − shift`` (NaN for no value).

    Raises:
        ValueError: a value is negative or not finite, or ``shift`` is not positive.
    """
    v = np.asarray(list(values), dtype=float)
    if not shift > 0:
        raise ValueError(f"the shift must be > 0, got {shift}")
    if v.size == 0:
        return math.nan
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise ValueError("the shifted geometric mean takes finite non-negative values")
    return float(np.exp(np.mean(np.log(v + shift))) - shift)


def values_within(values: np.ndarray, exact: np.ndarray, tol: float) -> bool:
    """Every entry's ``|v_i − v_i*| ≤ tol · max(1, |v_i*|)`` (``False`` on a count
    mismatch or a value that is not finite)."""
    values, exact = np.asarray(values, float), np.asarray(exact, float)
    if values.shape != exact.shape or not np.all(np.isfinite(values)):
        return False
    return bool(np.all(np.abs(values - exact) <= tol * np.maximum(1.0, np.abs(exact))))


def certificate_success(status: str, report) -> bool:
    """Success of a formulation exact by design given its status and the certificate
    (:func:`~prioik.hierarchy.check_lexicographic`) of its answer at the profile's
    tolerance."""
    if not report.ok:
        return False
    return status == "optimal" or (status == "approximate" and bool(report.ambiguous_levels))


def value_success(status: str, values: np.ndarray, exact: np.ndarray | None,
                  tol: float) -> bool:
    """Success of a formulation not exact by design: it answered and its level
    residuals ``√v_i`` are within ``tol`` of the exact answer's (:func:`values_within`
    on the square roots of the level values ``v_i = ‖w_i‖²``; ``False`` without an
    exact answer)."""
    if status == "failed" or exact is None:
        return False
    with np.errstate(invalid="ignore"):
        return values_within(np.sqrt(np.asarray(values, float)),
                             np.sqrt(np.asarray(exact, float)), tol)
