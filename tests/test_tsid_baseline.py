"""benchmarks.tsid_baseline and benchmarks.tsid_runner: the scenario mapped to TSID's
two levels, the runner's JSON-lines protocol, TSID's runs on the arm and the G1 (run for
real in the TSID environment that `make tsid` builds), and a missing environment
reported as not installed, never as a failure."""

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from prioik.benchmarks import tsid_baseline as tb
from prioik.benchmarks.pink_baseline import LEVEL_COSTS, POSTURE_COST
from prioik.benchmarks.variants import baseline_profiles, table
from prioik.robots.arm import ArmScenario
from prioik.robots.fencing import FencingScenario

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def arm():
    return ArmScenario()


@pytest.fixture(scope="module")
def fencing():
    return FencingScenario("compatible")


@pytest.fixture
def bogus_environment(monkeypatch, tmp_path):
    path = tmp_path / "no-such-venv" / "bin" / "python"
    monkeypatch.setenv(tb.PYTHON_VARIABLE, str(path))
    return path


def tsid_here() -> bool:
    return tb.unavailable_reason() is None


needs_tsid = pytest.mark.skipif(not tsid_here(), reason="no TSID environment here: "
                                f"{tb.unavailable_reason()} (`make tsid` builds it)")


# ------------------------------------------------------------ the environment
def test_the_makefile_installs_the_requirements():
    text = (REPO / "Makefile").read_text()
    line = re.search(r"^TSID_REQUIRES\s*:=\s*(.*)$", text, re.M).group(1)
    assert re.findall(r'"([^"]+)"', line) == list(tb.REQUIREMENTS)


def test_a_missing_environment_is_reported_as_not_installed(bogus_environment):
    why = tb.unavailable_reason()
    assert why.startswith(f"not installed (no TSID environment at {bogus_environment})")
    assert "make tsid" in why
    runs = table("arm", scenario="arm")
    assert runs.unavailable["tsid"] == why
    assert "tsid" not in {v.formulation for v in runs.rows}
    chosen, skipped = runs.select("hierarchical_active_set,tsid")
    assert [v.label for v in chosen] == ["hierarchical_active_set"]
    assert skipped == [f"tsid: {why}"]
    profile = baseline_profiles()["tsid"]
    assert profile["here"] == why and profile["level"] == "acceleration"
    from prioik.benchmarks.report import baselines_table
    row = next(line for line in baselines_table({"baselines": baseline_profiles()}
                                                ).splitlines() if line.startswith("| `tsid`"))
    assert row.endswith(f"| {why} |") and "TSID (tsid==1.7.1: not installed here)" in row
    assert "not installed" in tb.DESCRIPTION
    with pytest.raises(tb.TsidError, match="not installed"):
        tb.run_tsid(ArmScenario(), duration=0.01, dt=0.002)


def test_an_environment_without_tsid_is_reported_as_not_installed(monkeypatch):
    import sys
    monkeypatch.setenv(tb.PYTHON_VARIABLE, sys.executable)     # pin 3.8.0, no tsid
    why = tb.unavailable_reason()
    assert why.startswith(f"not installed (the environment at {sys.executable} cannot "
                          "import tsid")


def test_every_baseline_states_version_level_priorities_and_what_it_is_given():
    profiles = baseline_profiles()
    assert set(profiles) == {"placo_kinematics_solver", "pink", "mink", "tsid"}
    for name, p in profiles.items():
        assert set(p) == {"library", "level", "priorities", "given", "here"}, name
        assert p["level"] in ("velocity", "acceleration")
        assert re.search(r"\d+\.\d+", p["library"]) or "not installed" in p["library"]
    assert profiles["tsid"]["level"] == "acceleration"
    assert "eiquadprog" in profiles["tsid"]["given"]


# ----------------------------------------------------------------- the mapping
def test_the_arm_maps_to_weighted_tasks_and_bounds(arm):
    setup = tb.setup_request(arm, 0.002)
    assert setup["protocol"] == 1 and setup["floating_base"] is False
    assert setup["joint_names"] == [f"panda_joint{i}" for i in range(1, 8)]
    tasks = {t["name"]: t for t in setup["tasks"]}
    assert {n: (t["kind"], t["role"]) for n, t in tasks.items()} == {
        "tool_position": ("position", "weighted"),
        "tool_orientation": ("orientation", "weighted"),
        "posture": ("posture", "weighted")}
    # the squares of pink's and mink's costs: one decade per level
    assert tasks["tool_position"]["weight"] == LEVEL_COSTS[0] ** 2
    assert tasks["tool_orientation"]["weight"] == pytest.approx((LEVEL_COSTS[1] * 0.1) ** 2)
    assert tasks["posture"]["weight"] == POSTURE_COST ** 2
    for name, t in tasks.items():
        assert (t["kp"], t["kd"]) == arm.gains[name]
    lo, hi, vmax = arm.robot.joint_limits()
    assert setup["limits"]["lower"] == lo.tolist() and setup["limits"]["upper"] == hi.tolist()
    assert setup["limits"]["velocity"] == vmax.tolist()
    assert setup["limits"]["acceleration"] == arm.amax.tolist()
    json.dumps(setup)                                     # JSON as it stands


def test_the_held_foot_is_a_contact_and_the_rest_weighted(fencing):
    setup = tb.setup_request(fencing, 0.002)
    assert setup["floating_base"] is True and len(setup["q0"]) == fencing.robot.nq
    tasks = {t["name"]: t for t in setup["tasks"]}
    assert tasks["support_foot"]["role"] == "contact"
    assert tasks["support_foot"]["frame"] == fencing.robot.frames["right_foot"]
    assert len(tasks["support_foot"]["contact"]["points"]) == 4
    # the CoM is hard in PlaCo's two levels, weighted (its level's cost) in TSID's
    assert tasks["com"]["role"] == "weighted" and tasks["com"]["kind"] == "com_xy"
    assert tasks["com"]["weight"] == LEVEL_COSTS[1] ** 2
    assert {n for n, t in tasks.items() if t["role"] == "weighted"} == {
        "com", "left_foot", "sword_tip", "posture"}
    # no acceleration limits in the scenario: TSID's bounds task gets the stated one
    assert set(setup["limits"]["acceleration"]) == {tb.ACCELERATION_LIMIT}


def test_a_task_without_gains_is_named(arm):
    import dataclasses
    bare = dataclasses.replace(arm, gains={"tool_position": (25.0, 10.0)})
    with pytest.raises(ValueError, match="task 'tool_orientation' no gains"):
        tb.setup_request(bare, 0.002)


@pytest.mark.parametrize("t", [0.0, 0.3, 0.55, 1.7])
def test_references_are_the_scenarios_with_their_rates(arm, fencing, t):
    tasks = tb.setup_request(arm, 0.002)["tasks"]
    refs = tb.step_references(arm, tasks, t)
    ref = arm.tool_ref(t)
    x, xd, xdd = (np.array(r) for r in refs["tool_position"])
    np.testing.assert_array_equal(x, ref.x)
    # central differences, step 1e-4 s: the velocity to 1e-7 m/s; the acceleration to
    # 2e-3 m/s² (of up to ~4.5: the step straddles the moves' clipped ends)
    np.testing.assert_allclose(xd[:3], ref.xd, atol=1e-7)
    np.testing.assert_allclose(xdd[:3], ref.xdd, atol=2e-3)
    assert not xd[3:].any() and not xdd[3:].any()
    R, w, dw = (np.array(r) for r in refs["tool_orientation"])
    np.testing.assert_array_equal(R, arm.rotation0)
    assert np.abs(w).max() < 1e-12 and np.abs(dw).max() < 1e-6
    f_tasks = tb.setup_request(fencing, 0.002)["tasks"]
    f_refs = tb.step_references(fencing, f_tasks, t)
    assert "support_foot" not in f_refs                   # a contact holds its pose
    foot = fencing.left_foot_ref(t)
    T, v, a = (np.array(r) for r in f_refs["left_foot"])
    np.testing.assert_array_equal(T[:3, 3], foot.x)
    np.testing.assert_allclose(v[:3], foot.xd, atol=1e-6)
    np.testing.assert_allclose(a[:3], foot.xdd, atol=2e-3)
    com = fencing.com_ref(t)
    c, cv, _ = (np.array(r) for r in f_refs["com"])
    np.testing.assert_array_equal(c[:2], com.x)
    np.testing.assert_allclose(cv[:2], com.xd, atol=1e-6)


# ------------------------------------------------------------------ the runner
def _runner(lines: list[dict | str]) -> tuple[list[dict], int]:
    text = "".join((line if isinstance(line, str) else json.dumps(line)) + "\n"
                   for line in lines)
    out = subprocess.run([str(tb.python_path()), str(tb.RUNNER)], input=text,
                         capture_output=True, text=True, timeout=300)
    return [json.loads(line) for line in out.stdout.splitlines()], out.returncode


@needs_tsid
def test_the_runner_answers_the_setup_and_each_request(arm):
    setup = tb.setup_request(arm, 0.002)
    step = tb.step_references(arm, setup["tasks"], 0.0)
    replies, status = _runner([setup, {"targets": [step] * 3}, {"reset": True},
                               {"targets": [step]}])
    assert status == 0 and len(replies) == 4
    ready, three, reset, one = replies
    assert ready["ready"] is True and ready["tsid"] == "1.7.1"
    assert (ready["nq"], ready["nv"], ready["na"]) == (7, 7, 7)
    assert {k: len(v) for k, v in three.items()} == {
        "q": 3, "v": 3, "a": 3, "reference_time_s": 3, "solve_time_s": 3}
    assert reset == {"reset": True}
    # after the reset the first step is taken again, bit for bit
    assert one["q"][0] == three["q"][0] and one["a"][0] == three["a"][0]
    # semi-implicit Euler: v₁ = q̈₀ dt
    np.testing.assert_allclose(three["v"][0], np.array(three["a"][0]) * 0.002, rtol=1e-15)


@needs_tsid
@pytest.mark.parametrize("change, message", [
    (lambda s: s.update(protocol=2), "protocol must be 1"),
    (lambda s: s["joint_names"].reverse(), "are not the scenario's"),
    (lambda s: s["tasks"][0].update(frame="no_such_frame"), "no frame 'no_such_frame'"),
    (lambda s: s["tasks"][0].update(kind="wrench"), "kind must be one of"),
    (lambda s: s["limits"].update(lower=[0.0]), "limits.lower must be 7 finite numbers"),
    (lambda s: s.pop("dt"), "the setup has no 'dt'"),
])
def test_the_runner_refuses_a_bad_setup_by_name(arm, change, message):
    setup = tb.setup_request(arm, 0.002)
    change(setup)
    replies, status = _runner([setup])
    assert status == 2 and len(replies) == 1 and message in replies[0]["error"]


@needs_tsid
def test_the_runner_refuses_a_bad_request_by_name(arm):
    setup = tb.setup_request(arm, 0.002)
    good = tb.step_references(arm, setup["tasks"], 0.0)
    missing = {k: v for k, v in good.items() if k != "posture"}
    replies, status = _runner([setup, {"targets": [good, missing]}])
    assert status == 2 and "step 1: no reference for task 'posture'" in replies[1]["error"]
    replies, status = _runner([setup, "not json"])
    assert status == 2 and "JSONDecodeError" in replies[1]["error"]
    replies, status = _runner([setup, {"steps": 3}])
    assert status == 2 and "must hold 'targets' or 'reset'" in replies[1]["error"]


@needs_tsid
def test_a_refused_setup_is_the_baselines_error(arm, monkeypatch):
    real = tb.setup_request
    monkeypatch.setattr(tb, "setup_request",
                        lambda sc, dt: {**real(sc, dt), "protocol": 0})
    with pytest.raises(tb.TsidError, match="refused the request: .*protocol must be 1"):
        tb.run_tsid(arm, duration=0.01, dt=0.002)


# ------------------------------------------------------------------- the runs
@needs_tsid
def test_tsid_on_the_arm_matches_prioiks_acceleration_stack(arm):
    """Within reach, TSID's weighted level 1 and prioik's strict levels give the same
    motion (the position and the orientation take 6 of the 7 joints, exactly, in both):
    within 1e-5 rad over 0.3 s, what the references' accelerations by central
    differences (≤ 2e-3 m/s² off) and the weighted posture leave (1.2e-6 rad here)."""
    from prioik.benchmarks.scenario_runs import run_one
    from prioik.benchmarks.variants import Variant
    res = tb.run_tsid(arm, duration=0.3, dt=0.002)
    assert not res.failed and res.steps == 150
    assert res.info["timed_in"] == "the TSID process" and res.info["tsid"] == "1.7.1"
    assert np.all(res.solve_time_s > 0) and np.all(res.kinematics_time_s > 0)
    ref = run_one(Variant("hierarchical_active_set"), "reach", 0.3, 0.002, scenario=arm,
                  algorithmic_error=False)
    np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-5)
    assert res.errors["joint_limit_violation_rad"].max() == 0.0


@needs_tsid
def test_the_chunks_do_not_change_the_run(arm):
    from prioik.robots import run_to_end
    a = run_to_end(tb.tsid_steps(arm, duration=0.05, dt=0.002, chunk=7))
    b = run_to_end(tb.tsid_steps(arm, duration=0.05, dt=0.002))
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.v, b.v)


@needs_tsid
def test_tsid_holds_the_g1_foot_as_a_contact(fencing):
    res = tb.run_tsid(fencing, duration=0.4, dt=0.002)
    assert not res.failed and res.steps == 200
    # the contact's forces take whatever the tasks ask: the foot stays (1.5e-5 m over 1 s
    # here), the CoM follows (1.4e-4 m) and ‖q̈‖ stays that of prioik's runs (≤ 12.4)
    assert res.errors["support_foot_error_m"].max() < 1e-4
    assert res.errors["com_error_m"].max() < 1e-3
    assert np.linalg.norm(res.a, axis=1).max() < 50.0
    assert res.errors["joint_limit_violation_rad"].max() == 0.0


@needs_tsid
def test_tsid_runs_in_the_arm_report(tmp_path):
    from prioik.benchmarks.arm import write_page
    from prioik.benchmarks.scenario_runs import run_scenario
    runs = run_scenario("arm", ["reach"], tmp_path, "hierarchical_active_set,tsid",
                        duration=0.04, dt=0.002, progress=False)
    s = runs.summary["reach"]["tsid"]
    assert not s["failed"] and s["median_step_time_s"] > 0
    page = write_page(tmp_path / "arm.md", runs.summary, runs.meta, runs.pngs, "cmd", 20.0)
    text = page.read_text()
    assert "| `tsid` | TSID 1.7.1 (pin 3.4.0, its own environment) | acceleration |" in text
    assert "In the reach run TSID's median step (its own process)" in text


@needs_tsid
def test_the_step_comparison_runs_the_three_loops():
    from prioik.benchmarks import tsid_step
    r = tsid_step.panda_tsid_step(steps=60, rounds=1)
    assert (r["steps"], r["rounds"], r["tsid"], r["tsid_pinocchio"]) == (60, 1, "1.7.1",
                                                                        "3.4.0")
    for path in ("tsid", "prioik_acceleration", "prioik_velocity"):
        assert r[f"{path}_step_us"] > 0 and r[f"{path}_limit_violation_rad"] == 0.0
    # the same gains at acceleration level: the tool moves alike (TSID's posture weight
    # 1e-3 against the tool's 1 leaves it within 2 mm of the strict hierarchy's)
    assert abs(r["tsid_tool_error_m"] - r["prioik_acceleration_tool_error_m"]) < 2e-3
    assert r["tsid/prioik_acceleration"] == pytest.approx(
        r["tsid_step_us"] / r["prioik_acceleration_step_us"])
    table = tsid_step.format_table(r)
    assert table.count("\n") == 4 and "| TSID 1.7.1 (its own process) |" in table
