"""benchmarks.mink_step: the three IK steps with limits side by side (a few steps)."""

import pytest

from prioik.benchmarks import mink_step

pytest.importorskip("placo")


@pytest.mark.parametrize("measure", [mink_step.panda_mink_step, mink_step.g1_feet_mink_step])
def test_every_path_is_timed_and_keeps_its_limits(measure):
    out = measure(steps=8, rounds=1)
    for path in ("mink", "prioik", "placo"):
        assert 0 < out[f"{path}_step_us"] <= out[f"{path}_p90_us"]
    assert out["mink/prioik"] == pytest.approx(out["mink_step_us"] / out["prioik_step_us"])
    assert out["solver"] == "daqp"
    if "joint_limit_violation_rad" in out:
        assert max(out["joint_limit_violation_rad"].values()) == 0.0
    else:                    # the feet held: drift after integration, on each own loop
        assert set(out["feet_drift_m"]) == {"mink", "prioik", "placo"}
        assert all(0.0 <= d < 0.5 for d in out["feet_drift_m"].values())
    table = mink_step.format_table({"case": out})
    assert table.splitlines()[2].startswith("| case | ")
