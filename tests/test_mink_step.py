"""benchmarks.mink_step: the three IK steps with limits side by side (a few steps)."""

import pytest

from prioik.benchmarks import mink_step


@pytest.mark.parametrize("measure", [mink_step.panda_mink_step, mink_step.g1_feet_mink_step])
def test_every_path_is_timed_and_keeps_its_limits(measure):
    out = measure(steps=8, rounds=1)
    for path in ("mink", "prioik", "control", "placo"):
        assert 0 < out[f"{path}_step_us"] <= out[f"{path}_p90_us"]
    assert out["mink/prioik"] == pytest.approx(out["mink_step_us"] / out["prioik_step_us"])
    assert out["control/placo"] == pytest.approx(out["control_step_us"]
                                                 / out["placo_step_us"])
    assert out["solver"] == "daqp"
    if "joint_limit_violation_rad" in out:
        assert max(out["joint_limit_violation_rad"].values()) == 0.0
    else:                    # the feet held: drift after integration, on each own loop
        assert set(out["feet_drift_m"]) == {"mink", "prioik", "placo"}
        assert all(0.0 <= d < 0.5 for d in out["feet_drift_m"].values())
    table = mink_step.format_table({"case": out})
    assert table.splitlines()[2].startswith("| case | ")


def test_the_bench_page_shows_the_mink_table_or_why_not():
    from prioik.benchmarks.bench import page
    from prioik.benchmarks.bench.settings import Settings
    ik = {f"{path}_{q}_us": 1.0 for path in ("prioik_prepared", "prioik_oneoff", "placo")
          for q in ("step", "p10", "p90")}
    md = page.results_markdown([], [], {}, ik | {"mink_table": "| the table |"}, [], [],
                               Settings(), [])
    assert "## mink beside prioik and PlaCo" in md and "| the table |" in md
    why = "the mink IK step needs the `mink` extra"
    md = page.results_markdown([], [], {}, ik | {"mink_error": why}, [], [], Settings(), [])
    assert f"Not measured: {why}" in md
    assert "## mink beside" not in page.results_markdown([], [], {}, ik, [], [],
                                                           Settings(), [])


def test_run_gives_one_row_per_problem_and_back_end():
    out = mink_step.run(steps=5, solvers=("daqp", "quadprog"), rounds=1)
    assert list(out) == ["panda[daqp]", "g1_feet[daqp]", "panda[quadprog]",
                         "g1_feet[quadprog]"]
    assert out["g1_feet[quadprog]"]["solver"] == "quadprog"
