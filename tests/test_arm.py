"""The arm-reach scenario (robots/arm.py) and its command (benchmarks/arm.py)."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest

import prioik
from prioik.benchmarks.scenario_runs import run_one, run_table
from prioik.robots import KinematicState
from prioik.robots.arm import ACCELERATION_LIMITS, OUT_OF_REACH, ArmScenario


@pytest.fixture(scope="module")
def scenario():
    return ArmScenario()


def test_panda_model_and_targets(scenario):
    r = scenario.robot
    assert (r.nq, r.nv, r.floating_base) == (7, 7, False)
    shoulder = np.array([0.0, 0.0, 0.333])
    reach = [np.linalg.norm(np.asarray(t) - shoulder) for t in scenario.targets]
    # the arm (shoulder to tool point, stretched) is about 0.86 m long
    assert reach[OUT_OF_REACH] > 0.95 and max(np.delete(reach, OUT_OF_REACH)) < 0.65


def test_stacks_have_the_documented_levels(scenario):
    state = KinematicState(scenario.robot, scenario.robot.q0, np.zeros(7))
    acc = scenario.acceleration_stack(state, 0.1, "bounds").stack
    assert [lv.names for lv in acc.levels] == [("joint_limits",), ("tool_position",),
                                                ("tool_orientation",), ("posture",)]
    lo, hi = acc.levels[0][0].bounds()
    assert np.all(lo >= -np.array(ACCELERATION_LIMITS) - 1e-12)
    assert np.all(hi <= np.array(ACCELERATION_LIMITS) + 1e-12)
    vel = scenario.velocity_stack(state, 0.1, 20.0, "hard_bounds").stack
    lo, hi = vel.levels[0][0].bounds()
    assert np.all(lo <= 0) and np.all(hi >= 0)          # 0 ∈ box within the limits
    with pytest.raises(ValueError, match="limits must be"):
        scenario.acceleration_stack(state, 0.1, "soft")


def test_sns_run_keeps_every_bound_and_reaches(scenario):
    """SNS at acceleration level through the shared runner: position, velocity and
    acceleration limits hold at every step, the first target is reached."""
    spec = run_table("arm")["sns"]
    res = run_one(spec, "reach", 1.0, 0.002, scenario="arm")
    assert not res.failed and res.steps == 500
    assert res.errors["joint_limit_violation_rad"].max() == 0.0
    assert res.errors["joint_velocity_violation_rad_s"].max() <= 1e-9
    assert np.all(np.abs(res.a) <= np.array(ACCELERATION_LIMITS) * (1 + 1e-9))
    assert res.errors["tip_error_m"][-1] < 1e-3
    assert res.info["scenario"] == "arm" and res.q_names[0] == "panda_joint1"


def test_out_of_reach_target_scales_the_sns_task(scenario):
    """At the out-of-reach target the velocity-level SNS scales the tool task: the
    solution's status says so and every bound holds."""
    dt = 0.002
    period = scenario.move_time + scenario.hold_time
    t = OUT_OF_REACH * period + 0.5 * scenario.move_time
    q = scenario.robot.q0.copy()
    # walk towards the far target quickly with SNS itself, then look at one step
    stats = []
    v = np.zeros(7)
    for k in range(int(t / dt)):
        state = KinematicState(scenario.robot, q, v)
        st = scenario.velocity_stack(state, k * dt, 20.0, "hard_bounds", dt).stack
        sol = prioik.solve(st, "sns")
        lo, hi = st.levels[0][0].bounds()
        assert np.all(sol.x >= lo - 1e-9) and np.all(sol.x <= hi + 1e-9)
        stats.append((sol.status, sol.detail.task_scaling[0]))
        v = sol.x
        q = pin.integrate(scenario.robot.model, q, v * dt)
    scaled = [s for st_, s in stats if s < 1.0]
    assert scaled and all(0.0 <= s < 1.0 for s in scaled)
    assert any(st_ == "approximate" for st_, s in stats if s < 1.0)


def test_pink_and_placo_baselines_run_on_the_arm(scenario):
    pytest.importorskip("pink")
    pytest.importorskip("placo")
    from prioik.benchmarks.pink_baseline import run_pink
    from prioik.benchmarks.placo_baseline import run_placo
    for res in (run_pink(scenario, duration=0.2, dt=0.002),
                run_placo(scenario, duration=0.2, dt=0.002)):
        assert not res.failed and res.steps == 100
        assert res.errors["joint_limit_violation_rad"].max() < 1e-9
        assert res.errors["tip_tracking_error_m"].max() < 1e-3
        assert np.all(res.solve_time_s > 0)
    with pytest.raises(ValueError, match="not available here"):
        run_pink(scenario, duration=0.01, dt=0.002, solver="no_such_solver")


def test_arm_command_writes_tables_runs_and_page(tmp_path, capsys):
    from prioik.cli import main
    doc = tmp_path / "docs" / "arm.md"
    out = tmp_path / "res"
    assert main(["arm", "--duration", "0.1", "--formulations", "extended_jacobian,sns,pink",
                 "--out", str(out), "--doc", str(doc), "--quiet", "--save-runs"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["reach"]) == {"extended_jacobian", "sns", "pink"}
    for label in ("extended_jacobian", "sns", "pink"):
        assert (out / f"reach_{label}.npz").is_file() and (out / f"reach_{label}.csv").is_file()
    page = doc.read_text()
    assert "| `sns` |" in page and "| `pink` |" in page and "img/arm_reach_tip_error.png" in page
    assert (out / "reach_replay.html").is_file()
    assert "MeshCat.Viewer" in (out / "reach_replay_meshes.html").read_text()
    assert "`reach_replay_meshes.html`" in page
    header = (out / "reach_sns.csv").read_text().splitlines()[0].split(",")
    assert "q:panda_joint1" in header and "tau:panda_joint7" in header
