"""Timing: repeats under a time budget, medians and percentiles.

:func:`timed_calls` is the loop of ``prioik bench``'s tables: an untimed first call
(imports, JIT compilation, caches), a few warm-up calls, then up to ``repeats`` timed
calls cycling over the inputs — fewer when their estimated total exceeds the budget's
cap (status ``reduced``), none when one call is over the cap (status ``skipped``), and
stopping at twice the cap when some calls turn out far slower than the estimate. The
time of a call is what the call reports (``Solution.time_s``: ``time.perf_counter``
around the plugin's solve alone), not the loop's wall time.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Budget", "Timed", "timed_calls", "percentile", "median"]


def percentile(values, q: float) -> float:
    """The ``q``-th percentile (NaN for no values)."""
    a = np.asarray(values, dtype=float)
    return float(np.percentile(a, q)) if a.size else math.nan


def median(values) -> float:
    """The median (NaN for no values)."""
    return percentile(values, 50.0)


@dataclass(frozen=True)
class Budget:
    """How many calls to time and how long that may take.

    Attributes:
        repeats: Timed calls wanted.
        min_repeats: Fewest timed calls of a row that is not skipped.
        warmup: Untimed calls after the first.
        cap_s: Seconds of timed calls (the sum of their times) per row.
    """

    repeats: int = 200
    min_repeats: int = 10
    warmup: int = 3
    cap_s: float = 1.5


@dataclass
class Timed:
    """What :func:`timed_calls` measured.

    Attributes:
        status: ``"ok"`` (every repeat), ``"reduced"`` or ``"skipped"``.
        note: Why, when not ``"ok"``.
        times: Seconds of each timed call.
        results: What each timed call returned, with the index of its input.
        probe_s: A skipped row's measured call (s).
    """

    status: str = "ok"
    note: str = ""
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    results: list[tuple[int, Any]] = field(default_factory=list)
    probe_s: float = math.nan

    @property
    def repeats(self) -> int:
        return int(self.times.size)


def timed_calls(call: Callable[[int], Any], inputs: int, budget: Budget,
                seconds: Callable[[Any], float] = lambda r: r.time_s) -> Timed:
    """Time ``call(i)`` (``i``: the index of an input, cycling over ``inputs``) under
    ``budget``; ``seconds(result)`` is a call's time (see the module docstring)."""
    first = call(0)
    if seconds(first) > budget.cap_s:
        return Timed("skipped", f"one solve took {seconds(first) * 1e3:.0f} ms > cap "
                                f"{budget.cap_s:g} s", probe_s=seconds(first))
    warm: list[float] = []
    for i in range(1, max(2, budget.warmup + 1)):
        warm.append(seconds(call(i % inputs)))
        if sum(warm) > budget.cap_s:
            break
    one = 2 * budget.cap_s / budget.min_repeats
    if min(warm) > one:
        return Timed("skipped", f"one solve takes {min(warm) * 1e3:.0f} ms > "
                                f"2·cap/min_repeats = {one * 1e3:.0f} ms", probe_s=min(warm))
    out = Timed()
    estimate = float(np.median(warm))
    repeats = budget.repeats
    if estimate * repeats > budget.cap_s:
        repeats = max(budget.min_repeats, int(budget.cap_s / max(estimate, 1e-9)))
        if repeats < budget.repeats:
            out.status = "reduced"
            out.note = (f"{repeats} repeats instead of {budget.repeats} "
                        f"(≈{estimate * 1e3:.1f} ms per solve, cap {budget.cap_s:g} s)")
    times: list[float] = []
    spent = 0.0
    for r in range(repeats):
        if spent > 2 * budget.cap_s:        # a few calls far slower than the estimate
            out.status = "reduced"
            out.note = (f"stopped after {r} of {repeats} repeats: {spent:.1f} s > twice "
                        f"the cap {budget.cap_s:g} s (some solves are much slower)")
            break
        i = r % inputs
        res = call(i)
        t = seconds(res)
        times.append(t)
        spent += t
        out.results.append((i, res))
    out.times = np.array(times)
    return out
