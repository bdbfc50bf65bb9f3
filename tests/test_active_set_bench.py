"""benchmarks/active_set_bench.py: run() returns its rows and the ratios against
issue 13's targets (structure and exactness only; timings are never asserted)."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("daqp")
pytest.importorskip("pinocchio")
pytest.importorskip("proxsuite")


def test_run_returns_rows_and_ratios_for_the_g1_bounds_stacks():
    from prioik.benchmarks.active_set_bench import format_table, lexls_available, run
    out = run(windows=1, steps=2, repeats=1, ik=False)
    assert [(r["variant"], r["level"]) for r in out["rows"]] == [
        ("compatible", "acceleration"), ("compatible", "velocity"),
        ("incompatible", "acceleration"), ("incompatible", "velocity")]
    for r in out["rows"]:
        assert r["statuses"] == ["optimal"]
        assert r["max_warm_vs_cold_rel"] <= 1e-9
        # issue 13's exactness target against the strict reference (cascaded_qp on
        # ProxQP at 1e-12), per level ‖w_i‖² relative to max(1, value)
        assert r["reference_statuses"] == ["optimal"]
        assert r["max_level_rel_diff_vs_reference"] <= 1e-9
        # the whole trajectory's ratio is a weighted mean of the per-stack ones: at most the worst
        for path in ("cold", "warm"):
            worst, total = r[f"worst {path}/daqp_raw"], r[f"total {path}/daqp_raw"]
            assert math.isfinite(worst) and worst > 0 and math.isfinite(total) and total > 0
            assert worst >= total * (1 - 1e-12)
    names = [x["name"] for x in out["ratios"]]
    # with lexls built: its cold and hot-started rows and two ratios per stack set
    with_lexls = lexls_available()
    expected = 16 + (8 if with_lexls else 0)
    assert len(names) == expected and len(set(names)) == expected
    for r in out["rows"]:
        assert ("cold/lexls_cold" in r) == with_lexls
        if with_lexls:
            assert r["median_s"]["lexls cold"] > 0 and r["median_s"]["lexls hot"] > 0
    assert all(math.isfinite(x["value"]) and x["value"] > 0 for x in out["ratios"])
    table = format_table(out)
    assert "cold/raw" in table and "worst warm/raw" in table
    assert ("warm / lexls hot" in table) == with_lexls


def test_each_window_comes_with_the_step_before_it():
    """The warm solver solves the step before each window, untimed, so that no timed
    warm solve starts from another window's state: it is the neighbour of the window's
    first step (their rows differ by one 5 ms step, far less than across windows)."""
    import numpy as np

    from prioik.benchmarks.active_set_bench import bounds_stacks
    stacks, before = bounds_stacks("incompatible", 3, 2, "velocity")
    assert len(stacks) == 6 and sorted(before) == [0, 2, 4]
    for i, prev in before.items():
        assert prev.layout == stacks[i].layout
        step = np.linalg.norm(prev.data.A - stacks[i].data.A)
        assert step > 0
        if i:       # across windows the rows differ by far more
            assert step < 0.1 * np.linalg.norm(stacks[i - 1].data.A - stacks[i].data.A)


def test_balance_step_runs_both_loops_and_holds_the_com():
    """benchmarks/balance_step.py: prioik's own loop and PlaCo's, the same task; the
    answers optimal, prioik's CoM over its polygon (to the velocity level's
    linearization, 1e-3 m), its equality-first try answering most steps of its own loop
    (the kept working set right), and the reach met where PlaCo's soft task trades it
    against the posture. Timings are reported, not asserted."""
    pytest.importorskip("placo")
    from prioik.benchmarks.balance_step import balance_step_times
    out = balance_step_times(steps=120, rounds=1)
    assert out["statuses"] == ["optimal"]
    assert out["prioik_com_excursion_m"] <= 1e-3
    assert out["equality_first_share"] >= 0.9
    assert out["prioik_hand_error_m"] <= 1e-3 < out["placo_hand_error_m"]
    for key in ("prioik_step_us", "prioik_at_placo_states_us", "placo_step_us"):
        assert math.isfinite(out[key]) and out[key] > 0


@pytest.mark.parametrize("which", ["panda_limits_step", "g1_limits_step"])
def test_ik_steps_time_the_control_step_beside_the_writer_loop(which):
    """The IK steps' ratio path is ControlStep, checked against the writer loop it
    compiles (the function raises when they differ); the writer loop is reported."""
    pytest.importorskip("placo")
    from prioik.benchmarks import active_set_bench
    out = getattr(active_set_bench, which)(steps=20, rounds=1)
    assert out["statuses"] == ["optimal"]
    for key in ("prioik_step_us", "prioik_writer_loop_us", "placo_step_us"):
        assert math.isfinite(out[key]) and out[key] > 0
