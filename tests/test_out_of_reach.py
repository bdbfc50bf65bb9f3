"""Velocity-level loops with a target out of reach (:mod:`prioik.benchmarks.out_of_reach`):
the Panda's joints stop flipping between their velocity bounds once the hand's level is
damped, and a humanoid's integrated feet stay where they were when its hand's target
speed is capped and its level damped; without the remedy both fail."""

import numpy as np
import pytest

from prioik.benchmarks.out_of_reach import (
    PANDA_TARGET,
    ZERO_SPEED,
    humanoid_run,
    panda_run,
    settled_step,
    sign_changes,
)

#: the most sign changes of a joint's q̇ per 100 steps once the hand stopped moving
MAX_SIGN_CHANGES = 2
#: how far the feet may leave their start after integration (m)
FEET_TOL = 1e-3


def test_sign_changes_count_flips_beyond_the_zero_band_per_window():
    qdot = np.zeros((201, 2))
    qdot[:, 0] = np.where(np.arange(201) % 2, 1.0, -1.0)      # flips every step
    qdot[:100, 1] = 1e-3
    qdot[100:, 1] = -1e-3                                      # one flip, at step 100
    qdot[150, 1] = 0.1 * ZERO_SPEED                            # zero: no flip around it
    assert sign_changes(qdot).tolist() == [[100, 1], [100, 0]]
    assert sign_changes(qdot, start=100).tolist() == [[100, 0]]
    assert sign_changes(qdot, start=101).shape[0] == 0         # no whole window left


def test_settled_step_is_where_the_error_stops_improving():
    e = np.array([1.0, 0.5, 0.2, 0.1, 0.1, 0.1002, 0.1, 0.1002])      # flips: no progress
    assert settled_step(e, tol=1e-3) == 3
    assert settled_step(e, tol=1e-5) == 6                # 0.1002 -> 0.1 is a gain of 2e-4
    assert settled_step(np.full(4, 0.3)) == 0


@pytest.mark.parametrize("damping", [None, 1e-2])
def test_the_panda_out_of_reach_stops_flipping_its_joints_once_damped(damping):
    """2,500 steps of docs/usage.md's joint-limits loop, the hand ~0.95 m from the shoulder:
    damped, at most 2 sign changes of any joint's q̇ per 100 steps after the hand
    stopped making progress (at least 10 windows); undamped, joints flip every step."""
    res = panda_run(damping, 2500)
    assert res["statuses"] == {"optimal"}
    start = settled_step(np.linalg.norm(res["hand"] - np.array(PANDA_TARGET), axis=1))
    counts = sign_changes(res["qdot"], start)
    assert counts.shape[0] >= 10, start
    if damping is None:
        assert counts.max() > 50, counts.max(axis=1)
    else:
        assert counts.max() <= MAX_SIGN_CHANGES, counts.max(axis=1)


@pytest.mark.parametrize("name", ["g1", "talos"])
def test_a_humanoid_reaching_out_of_reach_keeps_its_feet_with_the_remedy(name):
    """Both feet, joint limits and the CoM region at level 0, the hand 1.5 m out of
    reach, 300 steps of 10 ms: with the hand's max_rate and its level damped the feet
    stay within 1 mm of their start after integration, every answer optimal; without,
    they slide further."""
    on = humanoid_run(name, True, 300)
    assert on["statuses"] == {"optimal"}
    assert on["feet_drift_m"] <= FEET_TOL, on["feet_drift_m"]
    off = humanoid_run(name, False, 300)
    assert off["feet_drift_m"] > 5 * FEET_TOL, off["feet_drift_m"]


def test_the_report_has_every_row_and_the_baselines_or_why_not():
    """:func:`run` on short loops: prioik's rows with and without the remedy, PlaCo's and
    mink's (or the extra that is missing), formatted as two tables."""
    from prioik.benchmarks.out_of_reach import format_table, run

    res = run(panda_steps=300, humanoid_steps=20)
    labels = [r["label"] for r in res["panda"]]
    assert labels[:2] == ["prioik, undamped", "prioik, damping λ² = 0.01"]
    assert [label.split(" ")[0] for label in labels[2:]] == ["PlaCo", "mink"]
    assert [(r["robot"], r["remedy"]) for r in res["humanoid"]
            if not isinstance(r["remedy"], str)] == [
        ("g1", False), ("g1", True), ("talos", False), ("talos", True)]
    table = format_table(res)
    assert table.count("\n|---") == 2 and "feet drift (mm)" in table
