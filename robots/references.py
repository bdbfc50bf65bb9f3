"""Smooth references: minimum-jerk moves to a target, then hold.

A minimum-jerk move from ``x0`` to ``x1`` over ``[t0, t0 + T]`` follows
``x(t) = x0 + (x1 − x0) (10 s³ − 15 s⁴ + 6 s⁵)`` with ``s = (t − t0)/T``; velocity and
acceleration are zero at both ends, so the task references ``x*, ẋ*, ẍ*`` of eq. 4
are continuous (no step in ``h``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from prioik.hierarchy import TaskStackError

__all__ = ["Reference", "minimum_jerk", "minimum_jerk_profile", "Waypoints"]


class Reference(NamedTuple):
    """Reference position, velocity and acceleration at one instant (a named tuple:
    references are made every control step, and a tuple is the cheapest record)."""

    x: np.ndarray
    xd: np.ndarray
    xdd: np.ndarray


def minimum_jerk_profile(t0: float, duration: float, t: float) -> tuple[float, float, float]:
    """The time scaling of a minimum-jerk move and its derivatives at ``t``:
    ``p = 10 s³ − 15 s⁴ + 6 s⁵``, ``ṗ``, ``p̈`` with ``s = (t − t0)/T`` clipped to
    ``[0, 1]`` (floats; the move is ``x0 + p (x1 − x0)``).

    Raises:
        ValueError: ``duration`` is not > 0.
    """
    if not duration > 0:
        raise TaskStackError(f"duration must be > 0, got {duration}")
    s = min(max((t - t0) / duration, 0.0), 1.0)
    s2 = s * s
    p = s2 * s * (10.0 - 15.0 * s + 6.0 * s2)
    dp = s2 * (30.0 - 60.0 * s + 30.0 * s2) / duration
    ddp = s * (60.0 - 180.0 * s + 120.0 * s2) / (duration * duration)
    return p, dp, ddp


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
        raise TaskStackError(f"x0 and x1 differ in shape: {x0.shape} vs {x1.shape}")
    p, dp, ddp = minimum_jerk_profile(t0, duration, t)
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
            raise TaskStackError("Waypoints needs as many times as points (≥ 1)")
        if np.any(np.diff(np.asarray(self.times, float)) <= 0):
            raise TaskStackError(f"waypoint times must increase, got {list(self.times)}")
        pts = [np.asarray(p, float) for p in self.points]
        if any(p.shape != pts[0].shape for p in pts):
            raise TaskStackError(f"waypoints differ in shape: {[p.shape for p in pts]}")
        # converted once (a frozen dataclass: set through object.__setattr__)
        object.__setattr__(self, "_times", tuple(float(t) for t in self.times))
        object.__setattr__(self, "_points", tuple(pts))

    def _segment(self, t: float) -> tuple[int, float, float, float]:
        """The move at ``t``: its index ``i`` (from point ``i`` to ``i + 1``) and time
        scaling ``p, ṗ, p̈``; ``i = -1`` before the first time (hold the first point),
        and after the last the last move at its end."""
        times = self._times
        if t <= times[0] or len(times) == 1:
            return (-1 if t <= times[0] else len(times) - 1), 0.0, 0.0, 0.0
        i = len(times) - 2
        for j in range(len(times) - 1):
            if t < times[j + 1]:
                i = j
                break
        else:
            t = times[-1]
        return (i, *minimum_jerk_profile(times[i], times[i + 1] - times[i], t))

    def __call__(self, t: float) -> Reference:
        pts = self._points
        i, p, dp, ddp = self._segment(t)
        if i < 0 or i == len(pts) - 1:
            hold = pts[0] if i < 0 else pts[-1]
            return Reference(hold.copy(), np.zeros_like(hold), np.zeros_like(hold))
        d = pts[i + 1] - pts[i]
        return Reference(pts[i] + p * d, dp * d, ddp * d)

    def scalar(self, t: float) -> tuple[float, float, float]:
        """Position, velocity and acceleration at ``t`` as floats, for scalar waypoints
        (the value of ``self(t)`` without its three 0-d arrays: a control step's
        reference).

        Raises:
            ValueError: the waypoints are not scalars.
        """
        pts = self._points
        if pts[0].shape != ():
            raise TaskStackError(f"Waypoints.scalar needs scalar points, these have shape "
                             f"{pts[0].shape}")
        i, p, dp, ddp = self._segment(t)
        if i < 0 or i == len(pts) - 1:
            return float(pts[0] if i < 0 else pts[-1]), 0.0, 0.0
        a, b = float(pts[i]), float(pts[i + 1])
        return a + p * (b - a), dp * (b - a), ddp * (b - a)
