"""robots.fencing (the scenario), benchmarks.fencing (the command) and the PlaCo baseline,
on short durations."""

import json

import numpy as np
import pytest

from prioik import formulations
from prioik.benchmarks import fencing as cmd
from prioik.benchmarks.results import RunSummary
from prioik.benchmarks.scenario_runs import run_one, run_table
from prioik.benchmarks.variants import Variant
from prioik.cli import main
from prioik.robots import KinematicState, simulate
from prioik.robots.fencing import LEVEL_NAMES, TARGETS, FencingScenario

#: whole-scenario runs (see the `slow` marker in pyproject.toml)
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scenarios():
    return {v: FencingScenario(v) for v in ("compatible", "incompatible")}


def test_stack_levels_follow_the_paper_priorities(scenarios):
    sc = scenarios["compatible"]
    state = KinematicState(sc.robot, sc.robot.q0, np.zeros(35))
    step = sc.acceleration_stack(state, 0.0, "bounds")
    names = [lv.names[0] for lv in step.stack.levels]
    assert names == list(LEVEL_NAMES)
    assert step.stack.n == 35 and not step.stack.levels[1].is_equality
    assert step.algorithmic_levels == 5                # posture left out of eq. 29
    assert [lv.m for lv in step.stack.levels] == [6, 29, 2, 6, 3, 29]
    # standing posture: no joint in its margin, so no activation rows
    step = sc.acceleration_stack(state, 0.0, "activation")
    assert [lv.names[0] for lv in step.stack.levels] == \
        ["support_foot", "com", "left_foot", "sword_tip", "posture"]
    assert step.algorithmic_levels == 4 and step.stack.is_equality
    q = sc.robot.q0.copy()
    q[7 + 3] = -0.05                                   # left knee near its -0.087 limit
    step = sc.acceleration_stack(KinematicState(sc.robot, q, np.zeros(35)), 0.0)
    assert step.stack.levels[1].names == ("joint_limits",) and step.stack.levels[1].m == 1
    with pytest.raises(ValueError, match="limits"):
        sc.acceleration_stack(state, 0.0, "soft")
    with pytest.raises(ValueError, match="unknown fencing variant"):
        FencingScenario("easy")


def test_velocity_stack_uses_the_same_terms(scenarios):
    sc = scenarios["compatible"]
    rng = np.random.default_rng(0)
    v = rng.normal(scale=0.1, size=35)
    state = KinematicState(sc.robot, sc.robot.q0, v)
    terms = sc.terms(state, 1.0)
    step = sc.velocity_stack(state, 1.0, gain=5.0, limits="bounds")
    tip = step.stack.task("sword_tip")
    assert np.allclose(tip.A, terms["sword_tip"].J)
    assert np.allclose(tip.b, terms["sword_tip"].velocity_ref + 5.0 * terms["sword_tip"].error)
    jl = step.stack.task("joint_limits")
    assert np.all(jl.lower <= 0) and np.all(jl.upper >= 0)   # standing: q̇ = 0 admissible


def test_references_are_smooth_and_reach_their_targets(scenarios):
    sc = scenarios["incompatible"]
    data = sc.robot.data()
    import pinocchio as pin
    com0 = pin.centerOfMass(sc.robot.model, data, sc.robot.q0)[:2]
    assert np.allclose(sc.com_ref(0.0).x, com0, atol=1e-12)
    end = sc.left_foot_ref(5.0)
    assert end.x == pytest.approx(sc.left_foot0.translation + [0.2, 0, 0], abs=1e-12)
    mid = sc.left_foot_ref(0.7)
    assert mid.x[2] == pytest.approx(sc.left_foot0.translation[2] + 0.04, abs=1e-12)
    mid_feet = 0.5 * (end.x[:2] + sc.right_foot0.translation[:2])
    assert np.allclose(sc.com_ref(5.0).x, mid_feet, atol=1e-12)
    assert np.allclose(sc.tip_ref(2.5).x, TARGETS["incompatible"]) and \
        np.allclose(sc.tip_ref(0.5).x, sc.tip0)
    # no step anywhere: references 0.1 ms apart differ by < 0.2 mm (speed < 2 m/s),
    # and the velocities are continuous too (< 0.1 mm/s apart)
    ts = np.arange(0, 3, 1e-4)
    for ref in (sc.tip_ref, sc.com_ref, sc.left_foot_ref):
        xs = np.array([ref(t).x for t in ts])
        vs = np.array([ref(t).xd for t in ts])
        assert np.abs(np.diff(xs, axis=0)).max() < 2e-4
        assert np.abs(np.diff(vs, axis=0)).max() < 1e-3


def test_short_compatible_run_keeps_higher_levels_exact(scenarios):
    sc = scenarios["compatible"]
    res = simulate(sc.robot, lambda s, t: sc.acceleration_stack(s, t, "activation"),
                   lambda st, **kw: formulations.solve(st, "extended_jacobian"),
                   duration=0.2, dt=0.002)
    assert not res.failed and res.steps == 100
    assert res.errors["support_foot_error_m"].max() < 1e-5
    assert res.errors["com_error_m"].max() < 1e-3
    assert np.nanmax(res.algorithmic_error) < 1e-8
    assert res.errors["joint_limit_violation_rad"].max() == 0.0
    # eq. 18 equals the cascaded QP on the scenario's stacks along the run
    check = cmd.crosscheck("compatible", res, 0.002, every=20)
    assert check["steps_with_damping"] == 0 and check["steps_compared"] == 5
    assert check["max_rel_diff_qdd_undamped_steps"] < 1e-6


def test_step_bound_run_equals_the_cascade_with_the_same_damping(scenarios):
    """A bound small enough to act at every step: the tip level is damped, the levels
    above stay exact, and the whole q̈ equals cascaded_qp given the same μ²."""
    sc = scenarios["compatible"]
    opts = {"step_bound": {"sword_tip": 0.05, "left_foot": 0.05}}
    res = simulate(sc.robot, lambda s, t: sc.acceleration_stack(s, t, "activation"),
                   lambda st, **kw: formulations.solve(st, "extended_jacobian", **opts),
                   duration=0.1, dt=0.002)
    assert not res.failed
    assert res.errors["support_foot_error_m"].max() < 1e-5
    check = cmd.crosscheck("compatible", res, 0.002, every=10, run_options=opts)
    assert check["steps_with_damping"] >= 3
    assert check["max_rel_diff_qdd_damped_steps"] < 1e-6


def test_fencing_command_writes_summary_csv_plots_and_doc(tmp_path, capsys):
    out = tmp_path / "results"
    doc = tmp_path / "docs" / "reproduction.md"
    rc = main(["fencing", "--variant", "both", "--formulations",
               "extended_jacobian,nullspace", "--duration", "0.1", "--out", str(out),
               "--doc", str(doc), "--quiet", "--save-runs", "--like-for-like-samples", "2"])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "fencing — compatible tasks" in printed and "fencing — incompatible tasks" in printed
    summary = json.loads((out / "summary.json").read_text())
    assert list(summary) == ["compatible", "incompatible"]
    for variant in summary:
        assert list(summary[variant]) == ["extended_jacobian", "nullspace"]
        for run in summary[variant].values():
            assert tuple(run) == RunSummary.keys(FencingScenario.summary_errors)
            assert run["failed"] is False and run["median_step_time_s"] > 0
            assert run["max_support_foot_error_m"] < 1e-4
        csv = out / f"{variant}_extended_jacobian.csv"
        header = csv.read_text().splitlines()[0].split(",")
        assert header[0] == "t" and "tip_error_m" in header
        assert "q:root_joint.qw" in header and "qdd:right_wrist_yaw_joint" in header
        assert np.loadtxt(csv, delimiter=",", skiprows=1).shape == (50, len(header))
        assert (out / f"{variant}_extended_jacobian.npz").is_file()
        assert (out / f"{variant}_replay.html").stat().st_size > 1000
        assert (out / f"{variant}_replay_meshes.html").stat().st_size > 1e6
        for key in ("tip_error", "algorithmic_error", "qdd"):
            assert (out / f"{variant}_{key}.png").stat().st_size > 1000
    text = doc.read_text()
    assert "| `extended_jacobian` |" in text
    # the like-for-like measurement: every closed form on the same 2 + 2 G1 stacks
    lfl = json.loads((out / "run_info.json").read_text())["like_for_like"]
    assert lfl["stacks"] == 4 and lfl["n"] == 35
    assert lfl["measured"]["extended_jacobian"]["compiled"]
    assert "like for like: median solve on 4 G1 stacks" in printed
    assert "**Like for like.**" in text and "| `nullspace` | resolved acceleration" in text
    for line in text.splitlines():
        if line.startswith("!["):
            assert (doc.parent / line.rsplit("](", 1)[1].rstrip(")")).is_file()


def test_fencing_command_writes_what_a_reader_looks_at_by_default(tmp_path, capsys):
    """Without --save-runs: the summary, plots and replay pages, no trajectory files; the
    printout is the labelled tables and the cross-check table, no dict dumps."""
    out = tmp_path / "results"
    rc = main(["fencing", "--variant", "both", "--formulations",
               "extended_jacobian,extended_jacobian[step_bound]", "--duration", "0.04",
               "--out", str(out), "--quiet", "--headline-rounds", "0"])
    assert rc == 0
    printed = capsys.readouterr().out
    names = {p.name for p in out.iterdir()}
    assert not [n for n in names if n.endswith((".csv", ".npz"))]
    assert {"summary.json", "run_info.json", "crosscheck.json", "step_time.png",
            "compatible_replay.html", "incompatible_replay.html",
            "compatible_tip_error.png", "incompatible_qdd.png"} <= names
    # a 0.04 s run: the two meshed replay pages ~2 MB each (meshcat's script and the
    # decimated meshes), the rest a few hundred kB (the 3 s default run: under 20 MB)
    assert {"compatible_replay_meshes.html", "incompatible_replay_meshes.html"} <= names
    assert sum(p.stat().st_size for p in out.iterdir()) < 6_000_000
    assert "columns:" in printed and "step ms   " in printed
    assert "cross-check:" in printed and "{" not in printed
    assert "σ_min" not in printed
    info = json.loads((out / "run_info.json").read_text())
    assert info["saved_runs"] is False
    assert set(info["diagnostics"]) >= {"standing_sigmas", "sigma_trace", "max_limit_target"}


def test_fencing_command_times_the_headline_pair_side_by_side(tmp_path):
    """extended_jacobian and PlaCo's KinematicsSolver simulated in alternating rounds: each
    one's round medians, the fastest kept, their ratio, in run_info.json and on the page."""
    pytest.importorskip("placo")
    out, doc = tmp_path / "results", tmp_path / "reproduction.md"
    rc = main(["fencing", "--variant", "compatible", "--formulations",
               "extended_jacobian,placo_kinematics_solver", "--duration", "0.02",
               "--headline-rounds", "2", "--out", str(out), "--doc", str(doc), "--quiet",
               "--no-crosscheck"])
    assert rc == 0
    side = json.loads((out / "run_info.json").read_text())["headline_timing"]["compatible"]
    steps, best = side["median_step_s"], side["best_median_step_s"]
    assert side["rounds"] == 2 and list(steps) == list(cmd.HEADLINE)
    assert all(len(v) == 2 and min(v) > 0 for v in steps.values())
    assert best == {k: min(v) for k, v in steps.items()}
    assert side["ratio"] == pytest.approx(best["extended_jacobian"]
                                          / best["placo_kinematics_solver"])
    assert "**Side by side.**" in doc.read_text()
    # the table's runs advanced in turns (the default), which the page says
    assert json.loads((out / "run_info.json").read_text())["turn_steps"] == 100
    assert "advanced in turns of 100 steps each" in doc.read_text()


def test_fencing_command_rejects_unknown_runs_and_skips_unavailable(tmp_path, monkeypatch,
                                                                     capsys):
    rc = main(["fencing", "--formulations", "no_such_method", "--out", str(tmp_path)])
    assert rc == 2 and "unknown run(s) no_such_method" in capsys.readouterr().err
    rc = main(["fencing", "--like-for-like-samples", "-1", "--out", str(tmp_path)])
    assert rc == 2 and "--like-for-like-samples must be ≥ 0" in capsys.readouterr().err
    real_get = formulations.get

    def get(name):
        if name == "nullspace":
            raise formulations.FormulationError("formulation 'nullspace' is not available")
        return real_get(name)

    monkeypatch.setattr(formulations, "get", get)
    chosen, skipped = run_table("fencing").select("extended_jacobian,nullspace")
    assert [c.label for c in chosen] == ["extended_jacobian"]
    assert skipped and "nullspace" in skipped[0] and "not available" in skipped[0]


def test_placo_baseline_runs_the_same_scenario(scenarios):
    pytest.importorskip("placo")
    from prioik.benchmarks.placo_baseline import run_placo
    res = run_placo(scenarios["compatible"], duration=0.1, dt=0.002)
    assert not res.failed and res.steps == 50
    assert res.errors["support_foot_error_m"].max() < 1e-4       # a hard task in PlaCo
    assert res.errors["joint_limit_violation_rad"].max() < 1e-9
    assert np.isnan(res.algorithmic_error).all()
    assert np.all(res.solve_time_s > 0)


def test_velocity_level_qp_run(scenarios):
    spec = run_table("fencing")["cascaded_qp[daqp,velocity]"]
    res = run_one(spec, "compatible", 0.05, 0.002)
    assert not res.failed and res.steps == 25
    assert res.errors["support_foot_error_m"].max() < 1e-5
    assert np.nanmax(res.algorithmic_error) < 1e-6
    unsupported = Variant("nullspace", "velocity", level="velocity")
    from prioik.hierarchy import UnsupportedTaskError
    with pytest.raises(UnsupportedTaskError, match="inequality"):
        run_one(unsupported, "compatible", 0.01, 0.002)


@pytest.mark.parametrize("t", [0.05, 0.15, 0.3, 0.55, 0.72, 0.95, 1.1, 1.6, 2.2])
def test_reference_velocities_and_accelerations_are_the_derivatives(scenarios, t):
    """ẋ* and ẍ* of every reference equal central differences of x* and ẋ*
    (h = 1e-6 s: truncation ~h² ẍ, rounding ~1e-16/h; tolerance 1e-6 relative).
    Times avoid the waypoints (0.2, 0.5, 0.7, 1.2, 2.5 s), where the jerk jumps and a
    central difference of ẋ* is only O(h) accurate."""
    sc = scenarios["compatible"]
    h = 1e-6
    for ref in (sc.com_ref, sc.left_foot_ref, sc.tip_ref):
        now, up, down = ref(t), ref(t + h), ref(t - h)
        scale = 1.0 + np.abs(now.xd).max() + np.abs(now.xdd).max()
        assert np.allclose((up.x - down.x) / (2 * h), now.xd, rtol=0, atol=1e-6 * scale)
        assert np.allclose((up.xd - down.xd) / (2 * h), now.xdd, rtol=0, atol=1e-6 * scale)


def test_fencing_diagnostics_are_measured(tmp_path):
    """The figures the reproduction page explains the runs with are computed by the
    command: per-level projected σ at standing (the left foot's is below the selective
    damping's 0.05 trigger), the σ trace of the eq. 18 run, cond(M) with armature."""
    sig = cmd.standing_sigmas()
    assert set(sig) >= {"support_foot", "com", "left_foot", "sword_tip"}
    assert 0 < sig["left_foot"] < 0.05 < sig["com"]
    rc = main(["fencing", "--variant", "incompatible", "--formulations",
               "extended_jacobian,extended_jacobian[eq27]", "--duration", "0.06",
               "--out", str(tmp_path), "--quiet", "--no-crosscheck"])
    assert rc == 0
    meta = json.loads((tmp_path / "run_info.json").read_text())
    trace = meta["diagnostics"]["sigma_trace"]
    assert trace and trace[-1]["t"] == pytest.approx(0.058)
    assert all(0 < r["sigma_tip"] < 1 and r["qdd_norm"] >= 0 for r in trace)
    ud = cmd.unifying_diagnostic()
    assert ud["cond_M"] > ud["cond_M_armature"]["0.02"] > ud["cond_M_armature"]["0.1"] > 1


def test_step_builder_writes_rows_in_place_where_it_can(scenarios):
    """The scenario interface's step builder: written rows (StackData) for the forms the
    fencing writers have, equal to the stack built from task objects; the other forms
    through acceleration_stack / velocity_stack."""
    from prioik.hierarchy import StackData, TaskStack
    sc = scenarios["compatible"]
    rng = np.random.default_rng(3)
    state = KinematicState(sc.robot, sc.robot.q0, rng.normal(scale=0.1, size=35))
    for level, limits in (("acceleration", "bounds"), ("velocity", "bounds")):
        step = sc.step_builder(level, limits, 0.002, 20.0)(state, 0.7)
        assert isinstance(step.stack, StackData), (level, limits)
        ref = (sc.acceleration_stack(state, 0.7, limits, 0.002) if level == "acceleration"
               else sc.velocity_stack(state, 0.7, 20.0, limits, 0.002)).stack
        assert np.allclose(step.stack.A, np.vstack([t.A for t in ref.tasks]), atol=1e-10)
        assert step.algorithmic_levels == 5
    hard = sc.step_builder("velocity", "hard_bounds", 0.002, 20.0)(state, 0.7)
    assert isinstance(hard.stack, TaskStack) and hard.stack.levels[0].names == ("joint_limits",)
    plain = sc.step_builder("velocity")(state, 0.7).stack          # default: no limits
    assert "joint_limits" not in [t.name for t in plain.tasks]
