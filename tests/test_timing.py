"""benchmarks/timing.py: the timed loop keeps its budget and says why it did not."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from prioik.benchmarks.timing import Budget, median, percentile, timed_calls


def calls(seconds):
    """A call that reports ``seconds(i)`` as its time and records its inputs."""
    seen = []

    def call(i):
        seen.append(i)
        return SimpleNamespace(time_s=seconds(i))
    return call, seen


def test_every_repeat_within_the_budget_cycles_over_the_inputs():
    call, seen = calls(lambda i: 1e-3)
    t = timed_calls(call, 3, Budget(repeats=7, min_repeats=2, warmup=2, cap_s=1.0))
    assert t.status == "ok" and t.repeats == 7 and np.all(t.times == 1e-3)
    assert seen == [0, 1, 2] + [0, 1, 2, 0, 1, 2, 0]        # first, warm-up, timed
    assert [i for i, _ in t.results] == [0, 1, 2, 0, 1, 2, 0]


def test_reduced_and_skipped_rows_say_why():
    call, _ = calls(lambda i: 0.1)
    t = timed_calls(call, 1, Budget(repeats=100, min_repeats=2, warmup=1, cap_s=1.0))
    assert t.status == "reduced" and t.repeats == 10 and "10 repeats instead of 100" in t.note
    call, _ = calls(lambda i: 2.0)
    t = timed_calls(call, 1, Budget(cap_s=1.0))
    assert t.status == "skipped" and t.repeats == 0 and t.probe_s == 2.0 and "cap" in t.note
    # a few calls far slower than the warm-up: stopped at twice the cap
    call, _ = calls(lambda i: 0.9 if i == 2 else 0.01)
    t = timed_calls(call, 3, Budget(repeats=10, min_repeats=2, warmup=1, cap_s=1.0))
    assert t.status == "reduced" and t.repeats == 9
    assert "stopped after 9 of 10 repeats" in t.note and "twice the cap" in t.note


def test_percentiles_of_nothing_are_nan():
    assert math.isnan(median([])) and math.isnan(percentile([], 90))
    assert median([1.0, 3.0, 2.0]) == 2.0
