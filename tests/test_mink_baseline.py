"""benchmarks.mink_baseline: mink on the Panda (tip error falls, limits kept, the same
steps as pink's identical QP) and the G1 (the held foot as an equality constraint);
a missing mink is reported as the extra to install, never a failure."""

import numpy as np
import pytest

from prioik import extras
from prioik.benchmarks import mink_baseline
from prioik.benchmarks.scenario_runs import run_table
from prioik.robots.arm import ArmScenario


def test_mink_is_installed_here():
    # `make test` installs .[all,test]: the baseline must run, not be skipped
    assert extras.missing_distributions("mink") == ()
    assert mink_baseline.unavailable_reason({}) is None
    table = run_table("arm")
    assert {"mink", "mink[quadprog]"} <= set(table.known) and "mink" not in table.unavailable


def test_a_missing_mink_is_reported_as_the_extra_to_install(monkeypatch):
    real = extras._installed
    monkeypatch.setattr(extras, "_installed", lambda name: name != "mink" and real(name))
    why = mink_baseline.unavailable_reason({})
    assert why == "mink not installed; install it with `pip install prioik[mink]`"
    table = run_table("arm")
    assert table.unavailable["mink"] == why
    assert "mink" not in {v.formulation for v in table.rows}
    chosen, skipped = table.select("extended_jacobian,mink[quadprog]")
    assert [v.label for v in chosen] == ["extended_jacobian"]
    assert skipped == [f"mink[quadprog]: {why}"]


def test_a_missing_back_end_is_named():
    assert mink_baseline.unavailable_reason({"solver": "no_such_solver"}) == (
        "QP back-end no_such_solver is not available here")
    with pytest.raises(ValueError, match="'no_such_solver' is not available here"):
        mink_baseline.run_mink(ArmScenario(), duration=0.01, dt=0.002,
                               solver="no_such_solver")


@pytest.fixture(scope="module")
def arm():
    return ArmScenario()


def test_mink_steps_reduce_the_tip_error_within_the_limits(arm):
    res = mink_baseline.run_mink(arm, duration=0.2, dt=0.002)
    assert not res.failed and res.steps == 100 and res.info["qp_solver"] == "daqp"
    tip = res.errors["tip_error_m"]
    assert np.all(np.diff(tip) < 0) and tip[-1] < tip[0] - 0.02
    assert res.errors["tip_tracking_error_m"].max() < 1e-5      # dead-beat, weighted
    assert res.errors["joint_limit_violation_rad"].max() == 0.0
    assert res.errors["joint_velocity_violation_rad_s"].max() <= 1e-9
    lo, hi, vmax = arm.robot.joint_limits()
    assert np.all(res.q >= lo) and np.all(res.q <= hi)
    assert np.all(np.abs(res.v) <= vmax * (1 + 1e-9))


def test_mink_and_pink_take_the_same_steps(arm):
    """The same weighted QP (costs, gains, limits) on the converted model: the same
    trajectory as pink's on pinocchio's, which checks the conversion end to end."""
    from prioik.benchmarks.pink_baseline import run_pink
    a = mink_baseline.run_mink(arm, duration=0.05, dt=0.002)
    b = run_pink(arm, duration=0.05, dt=0.002, solver="daqp")
    assert np.max(np.abs(a.q - b.q)) < 1e-6


def test_the_held_foot_is_an_equality_constraint_on_the_g1():
    from prioik.robots.fencing import FencingScenario
    scenario = FencingScenario("compatible")
    _, config, tasks, constraints, limits, _ = mink_baseline.mink_problem(scenario, 0.002)
    assert [t.frame_name for t in constraints] == [scenario.robot.frames["right_foot"]]
    assert len(tasks) == 4 and len(limits) == 2
    res = mink_baseline.run_mink(scenario, duration=0.02, dt=0.002)
    assert not res.failed and res.steps == 10
    assert res.errors["support_foot_error_m"].max() < 1e-6
    assert res.errors["joint_limit_violation_rad"].max() == 0.0


def test_the_description_says_version_level_priorities_back_end_and_gains():
    import importlib.metadata
    text = mink_baseline.DESCRIPTION
    assert text.startswith(f"mink {importlib.metadata.version('mink')} (mujoco "
                           f"{importlib.metadata.version('mujoco')})")
    for part in ("velocity level", "weighted tasks", "equality constraints",
                 "task gains 1", "QP back-end daqp"):
        assert part in text
