"""prioik.smoke: PRIOIK_SMOKE=1 shrinks a command's work, never its command line."""

import argparse
from pathlib import Path

import pytest

from prioik import smoke
from prioik.benchmarks.bench.settings import Settings, quick_settings

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def smoke_on(monkeypatch):
    monkeypatch.setenv(smoke.ENV, "1")


@pytest.mark.parametrize("value, expected", [("", False), ("0", False), ("1", True),
                                             ("yes", True)])
def test_active_reads_the_variable(value, expected, monkeypatch):
    monkeypatch.setenv(smoke.ENV, value)
    assert smoke.active() is expected


def test_nothing_changes_without_the_variable(monkeypatch):
    monkeypatch.delenv(smoke.ENV, raising=False)
    args = argparse.Namespace(duration=3.0, n_stacks=200)
    assert smoke.shrink_arguments(args) is args
    assert smoke.cap(300, 20) == 300
    settings = Settings()
    assert smoke.shrink_bench_settings(settings) == Settings()
    cfg = {"sample": {"n": 200}}
    assert smoke.shrink_sweep_config(cfg, {"duration": 0.02}) is cfg


def test_arguments_are_capped_in_a_new_namespace(smoke_on):
    args = argparse.Namespace(duration=3.0, n_stacks=200, repeats=None, n=1, quick=True,
                              out="results")
    shrunk = smoke.shrink_arguments(args)
    assert vars(shrunk) == {"duration": 0.02, "n_stacks": 2, "repeats": None, "n": 1,
                            "quick": True, "out": "results"}
    assert args.duration == 3.0 and args.n_stacks == 200          # the caller's, unchanged
    assert isinstance(shrunk.n_stacks, int)
    assert smoke.cap(300, 20) == 20 and smoke.cap(5, 20) == 5


def test_bench_settings_shrink_to_small_cases(smoke_on):
    settings = smoke.shrink_bench_settings(Settings())
    assert settings.sizes == (12, 35) and settings.levels == (2, 4)
    assert (settings.repeats, settings.samples, settings.g1_samples) == (2, 1, 1)
    quick = smoke.shrink_bench_settings(quick_settings())
    assert quick.sizes == (12,) and quick.levels == (2,)


def test_sweep_config_keeps_its_shape(smoke_on):
    cfg = {"fixed": {"duration": 3.0, "dt": 0.004},
           "grid": {"kp": [1.0, 2.0, 3.0], "step_length": {"from": 0, "to": 1, "n": 4}},
           "sample": {"n": 200, "reach_margin_m": [-0.4, 0.5], "duration": [1, 2]}}
    fixed = {"tip_start_s": 0.0, "duration": 0.02}
    shrunk = smoke.shrink_sweep_config(cfg, fixed)
    assert shrunk["fixed"] == {"duration": 0.02, "dt": 0.004, "tip_start_s": 0.0}
    assert shrunk["grid"] == {"kp": [1.0, 2.0], "step_length": {"from": 0, "to": 1, "n": 2}}
    assert shrunk["sample"] == {"n": 2, "reach_margin_m": [-0.4, 0.5]}
    assert cfg["sample"]["n"] == 200 and cfg["fixed"]["duration"] == 3.0    # unchanged
    only_fixed = smoke.shrink_sweep_config({"sample": {"n": 5, "duration": [1, 2]}}, fixed)
    assert "sample" not in only_fixed                 # nothing left to draw


def test_the_shipped_sweep_plans_a_short_run(smoke_on):
    pytest.importorskip("pinocchio")
    from prioik.benchmarks.sweep.config import load_config, plan_from_config
    plan = plan_from_config(load_config(ROOT / "docs" / "sweeps" / "fencing_reach.toml"))
    assert plan.points == 2 and len(plan.runs) == 2 * len(plan.variants)
    assert {r.params["duration"] for r in plan.runs} == {0.02}


def test_help_names_the_variable():
    from prioik.cli import build_parser
    assert smoke.ENV in build_parser().format_help()
