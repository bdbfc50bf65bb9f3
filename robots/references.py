"""Smooth references: minimum-jerk moves to a target, then hold.

A minimum-jerk move from ``x0`` to ``x1`` over ``[t0, t0 + T]`` follows
``x(t) = x0 + (x1 − x0) (10 s³ − 15 s⁴ + 6 s⁵)`` with ``s = (t − t0)/T``; velocity and
acceleration are zero at both ends, so the task references ``x*, ẋ*, ẍ*`` of eq. 4
are continuous (no step in ``h``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["Reference", "minimum_jerk", "Waypoints"]


@dataclass(frozen=True)
class Reference:
    """Reference position, velocity and acceleration at one instant."""

    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray


def minimum_jerk(x0, x1, t0: float, duration: float, t: float) -> Reference:
    """Minimum-jerk reference from ``x0`` (before ``t0``) to ``x1`` (after ``t0 + duration``).

    Args:
        x0: Start (any shape, as an array).
        x1: Target (same shape).
        t0: Start time.
        duration: Length of the move (> 0).
        t: Query time.
    """
    x0 = np.asarray(x0, dtype=float)
    x1 = np.asarray(x1, dtype=float)
    if x0.shape != x1.shape:
        raise ValueError(f"x0 and x1 differ in shape: {x0.shape} vs {x1.shape}")
    if not duration > 0:
        raise ValueError(f"duration must be > 0, got {duration}")
    s = min(max((t - t0) / duration, 0.0), 1.0)
    p = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
    dp = (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / duration
    ddp = (60 * s - 180 * s ** 2 + 120 * s ** 3) / duration ** 2
    d = x1 - x0
    return Reference(x0 + p * d, dp * d, ddp * d)


@dataclass(frozen=True)
class Waypoints:
    """A chain of minimum-jerk moves through waypoints at given times, then hold.

    Attributes:
        times: Increasing times ``t_0 < t_1 < ...``.
        points: Positions at those times (same shape each).
    """

    times: Sequence[float]
    points: Sequence

    def __post_init__(self) -> None:
        if len(self.times) != len(self.points) or len(self.times) < 1:
            raise ValueError("Waypoints needs as many times as points (≥ 1)")
        if np.any(np.diff(np.asarray(self.times, float)) <= 0):
            raise ValueError(f"waypoint times must increase, got {list(self.times)}")

    def __call__(self, t: float) -> Reference:
        times = list(self.times)
        pts = [np.asarray(p, float) for p in self.points]
        if t <= times[0] or len(times) == 1:
            hold = pts[0] if t <= times[0] else pts[-1]
            return Reference(hold.copy(), np.zeros_like(hold), np.zeros_like(hold))
        for i in range(len(times) - 1):
            if t < times[i + 1]:
                return minimum_jerk(pts[i], pts[i + 1], times[i], times[i + 1] - times[i], t)
        return minimum_jerk(pts[-2], pts[-1], times[-2], times[-1] - times[-2], times[-1])
