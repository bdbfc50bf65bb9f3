"""Success rates with Wilson score intervals, per formulation variant."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

__all__ = ["wilson", "Rate", "judge_rows", "success_table"]

#: criteria reported per variant, in order
CRITERIA = ("success", "ok_tip", "ok_foot", "ok_com", "ok_divergence")


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """The Wilson score interval of a proportion ``k / n`` (95 % for the default
    ``z``); ``(nan, nan)`` when ``n = 0``."""
    if n <= 0:
        return math.nan, math.nan
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True)
class Rate:
    """``k`` successes of ``n`` runs and the interval of the rate."""

    k: int
    n: int

    @property
    def rate(self) -> float:
        return self.k / self.n if self.n else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        return wilson(self.k, self.n)

    def text(self) -> str:
        if not self.n:
            return "—"
        lo, hi = self.interval
        return f"{100 * self.rate:.0f} % ({self.k}/{self.n}; {100 * lo:.0f}–{100 * hi:.0f})"


def judge_rows(rows: Iterable[dict[str, Any]], scenario, criteria: dict[str, float]
               ) -> list[dict[str, Any]]:
    """Rows with the scenario's verdicts added (``reachable``, ``ok_*``, ``success``);
    ``unsupported`` rows are left out (the formulation cannot take the stack)."""
    out = []
    for row in rows:
        if row["status"] == "unsupported":
            continue
        out.append({**row, **scenario.judge(row, criteria)})
    return out


def success_table(judged: list[dict[str, Any]], labels: list[str]) -> dict[str, dict[str, Rate]]:
    """Label → criterion → :class:`Rate` (a criterion counts the rows where it applies)."""
    table: dict[str, dict[str, Rate]] = {}
    for label in labels:
        rows = [r for r in judged if r["label"] == label]
        table[label] = {}
        for c in CRITERIA:
            vals = [r[c] for r in rows if r[c] is not None]
            table[label][c] = Rate(sum(bool(v) for v in vals), len(vals))
    return table
