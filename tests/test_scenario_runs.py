"""benchmarks.scenario_runs: runs advanced in turns, as run_scenario times them."""

import numpy as np
import pytest

from prioik.benchmarks.scenario_runs import in_turns, run_one, run_steps, run_table
from prioik.robots import run_to_end


def _counting(label, steps, log):
    for k in range(steps):
        log.append((label, k))
        yield k
    return f"{label} done after {steps}"


def test_in_turns_alternates_blocks_until_every_run_ends():
    log: list = []
    turns: list = []
    runs = {"a": _counting("a", 5, log), "b": _counting("b", 2, log),
            "c": _counting("c", 4, log)}
    results, seconds = in_turns(runs, 2, turns.append)
    assert results == {"a": "a done after 5", "b": "b done after 2", "c": "c done after 4"}
    assert list(results) == ["a", "b", "c"] and set(seconds) == {"a", "b", "c"}
    assert all(s >= 0.0 for s in seconds.values())
    assert [label for label, _ in log] == ["a", "a", "b", "b", "c", "c", "a", "a", "c",
                                           "c", "a"]
    # every step of a run in its order; the turns report the steps they took
    assert [k for label, k in log if label == "a"] == list(range(5))
    assert sum(turns) == 11


def test_in_turns_with_zero_runs_each_to_its_end():
    log: list = []
    results, _ = in_turns({"a": _counting("a", 3, log), "b": _counting("b", 2, log)}, 0)
    assert [label for label, _ in log] == ["a", "a", "a", "b", "b"]
    assert results["b"] == "b done after 2"


def test_a_run_advanced_in_turns_equals_the_run_alone():
    """Two runs advanced in turns of 7 steps: each trajectory is bit for bit the one the
    run gives alone (a run's state is its own; only its timing shares the machine)."""
    table = run_table("fencing")
    labels = ("extended_jacobian", "hierarchical_active_set")
    runs = {label: run_steps(table[label], "compatible", 0.06, 0.002,
                             algorithmic_error=False) for label in labels}
    results, _ = in_turns(runs, 7)
    for label in labels:
        alone = run_one(table[label], "compatible", 0.06, 0.002, algorithmic_error=False)
        assert results[label].steps == alone.steps == 30
        np.testing.assert_array_equal(results[label].q, alone.q)
        assert results[label].info["label"] == label
        assert results[label].q_names == alone.q_names


def test_run_steps_checks_the_run_before_its_first_step():
    from prioik.benchmarks.variants import Variant
    from prioik.hierarchy import UnsupportedTaskError
    variant = Variant("extended_jacobian", level="velocity")
    with pytest.raises(UnsupportedTaskError, match="velocity-level runs"):
        run_steps(variant, "compatible", 0.01, 0.002)


def test_placo_baseline_runs_in_turns_like_alone():
    pytest.importorskip("placo")
    table = run_table("fencing")
    steps = run_steps(table["placo_kinematics_solver"], "compatible", 0.02, 0.002)
    assert next(steps) == 0
    res = run_to_end(steps)
    alone = run_one(table["placo_kinematics_solver"], "compatible", 0.02, 0.002)
    assert res.steps == alone.steps == 10
    np.testing.assert_allclose(res.q, alone.q, rtol=0, atol=1e-12)


def test_without_the_view_extra_the_meshed_page_is_left_out_with_a_note(monkeypatch,
                                                                       tmp_path, capsys):
    import prioik.extras
    from prioik.benchmarks import scenario_runs
    monkeypatch.setattr(prioik.extras, "missing_distributions",
                        lambda extra: ("fast-simplification",) if extra == "view" else ())
    page = tmp_path / "reach_replay_meshes.html"
    assert scenario_runs._write_mesh_replay(page, "arm", "reach", {}) is None
    assert not page.exists() and "`view` extra" in capsys.readouterr().err
