"""benchmarks/plots.py: the step-time chart marks the side-by-side timing."""

import pytest

pytest.importorskip("matplotlib")


def _summary():
    run = {"median_step_time_s": 7e-5, "failed": False}
    return {"compatible": {"extended_jacobian": dict(run),
                           "placo_kinematics_solver": {**run, "median_step_time_s": 6e-5}}}


def test_step_time_chart_marks_the_side_by_side_medians(tmp_path):
    """With a headline_timing record the chart draws the pair's fastest-round medians
    (black diamonds and a legend with the ratio) over the table's bars: a different
    image from the chart without it, and the same one for the same inputs."""
    from prioik.benchmarks.plots import step_time_figure
    side = {"compatible": {"rounds": 5, "ratio": 0.86,
                           "best_median_step_s": {"extended_jacobian": 6.0e-5,
                                                  "placo_kinematics_solver": 6.9e-5}}}
    for name in ("plain", "marked", "again"):
        (tmp_path / name).mkdir()
    plain = step_time_figure(tmp_path / "plain", _summary())
    marked = step_time_figure(tmp_path / "marked", _summary(), side_by_side=side)
    again = step_time_figure(tmp_path / "again", _summary(), side_by_side=side)
    assert plain.read_bytes() != marked.read_bytes()
    assert marked.read_bytes() == again.read_bytes()
