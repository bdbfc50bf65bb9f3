"""prioik sweep: config validation, LocalCluster == in-process, a killed worker, resume."""

from __future__ import annotations

import csv
import math
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

pytest.importorskip("distributed")

from prioik.benchmarks.sweep import SweepConfigError, load_config, plan_from_config, run_sweep  # noqa: E402
from prioik.benchmarks.sweep.schema import DETERMINISTIC_EXCLUDE  # noqa: E402
from prioik.benchmarks.sweep.stats import wilson  # noqa: E402
from prioik.cli import main  # noqa: E402

TINY = """
title = "tiny"
scenario = "fencing"
formulations = {formulations}
seed = 3
[fixed]
duration = {duration}
dt = 0.004
tip_start_s = 0.0
tip_move_s = 0.1
[sample]
n = {n}
reach_margin_m = [-0.4, 0.4]
azimuth_deg = [-30.0, 30.0]
"""


def write_config(tmp_path: Path, name="tiny.toml",
                 formulations='["extended_jacobian", "nullspace"]',
                 duration=0.2, n=2, text=None) -> Path:
    path = tmp_path / name
    path.write_text(text if text is not None else
                    TINY.format(formulations=formulations, duration=duration, n=n))
    return path


def raw_ids(path: Path) -> list[str]:
    with open(path) as f:
        return [row["run_id"] for row in csv.DictReader(f)]


def deterministic(rows: dict) -> dict:
    return {k: {c: v for c, v in r.items() if c not in DETERMINISTIC_EXCLUDE}
            for k, r in rows.items()}


# ------------------------------------------------------------------ config
@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("[sample]", "[sample]\nwingspan = [0.0, 1.0]"),
     "unknown parameter 'wingspan'"),
    (lambda t: t.replace('"nullspace"', '"nullspace_typo"'),
     "unknown formulation 'nullspace_typo'"),
    (lambda t: t.replace("[fixed]", '[fixed]\nrobot = "atlas"'), "'atlas' is not one of 'g1'"),
    (lambda t: t.replace("[sample]", "[grid]\nkp = []\n[sample]"), "grid axis 'kp' is empty"),
    (lambda t: t.replace("n = 2", "n = 0"), "n must be an integer ≥ 1"),
    (lambda t: t.replace('formulations = ["extended_jacobian", "nullspace"]', "formulations = []"),
     "'formulations' is empty"),
    (lambda t: t.replace('title = "tiny"', 'title = "tiny"\nworkers = 3'),
     "unknown key(s) workers"),
    (lambda t: t.replace("duration = 0.2", "duration = 0.05"), "ends before the sword move"),
    (lambda t: t.replace("[sample]", "[grid]\nazimuth_deg = [0.0]\n[sample]"),
     "'azimuth_deg' is in both [grid] and [sample]"),
])
def test_bad_config_is_one_clear_error_before_anything_runs(tmp_path, capsys, edit, message):
    cfg = write_config(tmp_path)
    cfg.write_text(edit(cfg.read_text()))
    with pytest.raises(SweepConfigError) as exc:
        plan_from_config(load_config(cfg))
    assert message in str(exc.value) and str(cfg) in str(exc.value)
    out = tmp_path / "out"
    assert main(["sweep", str(cfg), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not out.exists()                      # nothing ran, nothing written


def test_plan_grid_sample_and_run_ids(tmp_path):
    text = TINY.format(formulations='["extended_jacobian"]', duration=0.2, n=3).replace(
        "[sample]", "[grid]\nkp = {from = 20.0, to = 30.0, n = 2}\n[sample]")
    plan = plan_from_config(load_config(write_config(tmp_path, text=text)))
    assert len(plan.runs) == 6 and plan.points == 6
    assert sorted({r.params["kp"] for r in plan.runs}) == [20.0, 30.0]
    margins = [r.params["reach_margin_m"] for r in plan.runs]
    assert all(-0.4 - 1e-9 <= m <= 0.4 + 1e-9 for m in margins)
    again = plan_from_config(load_config(write_config(tmp_path, "b.toml", text=text)))
    assert [r.run_id for r in again.runs] == [r.run_id for r in plan.runs]   # seeded


def test_wilson_interval_known_values():
    lo, hi = wilson(5, 10)
    assert lo == pytest.approx(0.2366, abs=1e-4) and hi == pytest.approx(0.7634, abs=1e-4)
    lo, hi = wilson(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    assert all(math.isnan(x) for x in wilson(0, 0))


# ------------------------------------------------------- cluster == process
@pytest.mark.slow
def test_local_cluster_rows_equal_in_process_rows(tmp_path):
    cfg = write_config(tmp_path, formulations='["extended_jacobian", "nullspace", "sns[velocity]"]')
    plan = plan_from_config(load_config(cfg))
    a = run_sweep(plan, tmp_path / "inproc", workers=0, progress=False)
    assert main(["sweep", str(cfg), "--out", str(tmp_path / "cluster"), "--workers", "2",
                 "--quiet"]) == 0
    from prioik.benchmarks.sweep.execute import rows_by_id
    b = rows_by_id(tmp_path / "cluster" / "rows.csv")
    assert len(a.rows) == len(plan.runs) == 6 and set(b) == set(a.rows)
    # Floats to 1e-9 relative, everything else exactly: a worker and the test process
    # run the same code on the same rows, but the BLAS calls around it (the references,
    # the scenario's kinematics) may take other kernels on other threads.
    da, db = deterministic(a.rows), deterministic(b)

    def same(x, y):
        if isinstance(x, float) and isinstance(y, float):
            return math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12)
        return x == y
    diff = [(da[k]["label"], c, da[k][c], db[k][c]) for k in da for c in da[k]
            if not same(da[k][c], db[k][c])]
    assert not diff, diff
    assert all(r["status"] == "ok" and (r["steps"] == 50 or r["failed"]) for r in b.values())
    assert sum(r["steps"] == 50 for r in b.values()) >= 4
    assert len({r["worker"] for r in b.values()}) == 2           # both workers ran
    report = (tmp_path / "cluster" / "report.md").read_text()
    assert "| `extended_jacobian` |" in report and "sweep_success.png" in report
    assert (tmp_path / "cluster" / "sweep_tip_error.png").stat().st_size > 0


# ------------------------------------------------------------ killed worker
@pytest.mark.slow
def test_worker_killed_mid_sweep_every_row_once(tmp_path):
    from distributed import LocalCluster
    cfg = write_config(tmp_path, formulations='["extended_jacobian", "nullspace"]',
                       duration=0.8, n=3)
    plan = plan_from_config(load_config(cfg))
    killed: dict = {}

    def on_row(row, client):
        if killed:
            return
        processing = {w: list(keys) for w, keys in client.processing().items() if keys}
        if not processing:
            return
        addr, keys = next(iter(processing.items()))
        pid = client.run(os.getpid, workers=[addr])[addr]
        os.kill(pid, signal.SIGKILL)
        killed.update(pid=pid, keys=keys)

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster:
        out = run_sweep(plan, tmp_path / "out", scheduler=cluster.scheduler_address,
                        progress=False, on_row=on_row)
    assert killed, "no worker was processing a run when the first row arrived"
    ids = raw_ids(tmp_path / "out" / "rows.csv")
    assert Counter(ids) == Counter(r.run_id for r in plan.runs)     # every row, once
    assert all(r["status"] == "ok" for r in out.rows.values())
    for key in killed["keys"]:                                      # rerun elsewhere
        row = out.rows[key.removeprefix("run-")]
        assert not row["worker"].endswith(f":{killed['pid']}")


# ------------------------------------------------------------------ resume
@pytest.mark.slow
def test_interrupted_sweep_resumes_running_only_the_missing_rows(tmp_path):
    # 40 runs: the process is killed after the second row, long before the last (with 6
    # runs of the compiled solvers the whole sweep could end between two polls)
    cfg = write_config(tmp_path, formulations='["extended_jacobian", "nullspace"]', n=20)
    plan = plan_from_config(load_config(cfg))
    out = tmp_path / "out"
    rows_csv = out / "rows.csv"
    proc = subprocess.Popen([sys.executable, "-m", "prioik.cli", "sweep", str(cfg),
                             "--out", str(out), "--workers", "0", "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if rows_csv.exists() and len(rows_csv.read_text().splitlines()) >= 3:
            break
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    lines = rows_csv.read_text().splitlines(keepends=True)
    done_ids = raw_ids(rows_csv)
    assert 2 <= len(done_ids) < len(plan.runs), "the sweep was not interrupted mid-way"
    with open(rows_csv, "a") as f:                  # a row cut short by the interruption
        f.write(lines[-1][: len(lines[-1]) // 2])
    outcome = run_sweep(plan, out, workers=0, progress=False)
    assert sorted(outcome.skipped) == sorted(done_ids)
    assert sorted(outcome.computed) == sorted(set(r.run_id for r in plan.runs) - set(done_ids))
    after = rows_csv.read_text().splitlines(keepends=True)
    assert after[:len(lines)] == lines              # the written rows untouched
    assert Counter(raw_ids(rows_csv)) == Counter(r.run_id for r in plan.runs)
    again = run_sweep(plan, out, workers=0, progress=False)
    assert again.computed == [] and len(again.skipped) == len(plan.runs)


# ------------------------------------------------------ registry variants
@pytest.mark.slow
def test_a_registered_toy_plugin_appears_in_a_registry_sweep_and_runs(tmp_path, toy_plugin):
    from conftest import TOY

    from prioik.benchmarks.variants import table
    from prioik.formulations import registry

    found = table("sweep")
    labels = [v.label for v in found.rows if v.origin not in ("study", "baseline")]
    assert TOY in labels and "extended_jacobian" in labels
    assert not any(lb.startswith("cvxpy") for lb in labels)         # cvxpy_ opts out
    if any(i.name == "cvxpy" and i.available for i in registry.available()):
        assert any(n.startswith("cvxpy: left out of sweep (a modelling layer")
                   for n in found.notes)
    text = TINY.format(formulations='"registry"', duration=0.2, n=1)
    plan = plan_from_config(load_config(write_config(tmp_path, text=text)))
    assert [v.label for v in plan.variants] == labels
    toy_plan = type(plan)(plan.scenario, [r for r in plan.runs if r.variant.label == TOY],
                          [v for v in plan.variants if v.label == TOY], plan.criteria,
                          plan.config, False, plan.swept)
    out = run_sweep(toy_plan, tmp_path / "toy", workers=0, progress=False)
    (row,) = out.rows.values()
    assert row["label"] == TOY and row["status"] == "ok" and row["steps"] > 0


def test_two_sweeps_never_write_one_rows_file(tmp_path):
    from prioik.benchmarks.sweep.store import RowStore
    cols = ["run_id", "label"]
    with RowStore(tmp_path / "rows.csv", cols) as first:
        first.append({"run_id": "a", "label": "x"})
        with pytest.raises(ValueError, match="being written by another prioik sweep"):
            RowStore(tmp_path / "rows.csv", cols)
    with RowStore(tmp_path / "rows.csv", cols) as again:        # free once closed
        assert "a" in again and list(again.rows) == ["a"]


# ------------------------------------------------------------------ throughput
def test_spread_runs_takes_runs_evenly_and_refuses_bad_counts(tmp_path):
    from prioik.benchmarks.sweep.throughput import spread_runs
    plan = plan_from_config(load_config(write_config(tmp_path, n=5)))      # 10 runs
    sub = spread_runs(plan, 4)
    ids = [r.run_id for r in plan.runs]
    assert [ids.index(r.run_id) for r in sub.runs] == [0, 3, 6, 9]
    assert {r.variant.label for r in sub.runs} == {v.label for v in plan.variants}
    for bad in (1, 11):
        with pytest.raises(SweepConfigError, match="--throughput takes 2 to 10 runs"):
            spread_runs(plan, bad)


def test_throughput_runs_each_worker_count_from_scratch_and_reports_it(tmp_path):
    """`prioik sweep --throughput 3` times the same 3 runs on 1 and 2 workers, twice,
    alternating, every run computed in each pass (a pass never resumes from another's
    rows), then runs the sweep; the page reports the rates and the fastest passes' ratio."""
    import json
    cfg = write_config(tmp_path, n=2)
    out = tmp_path / "out"
    assert main(["sweep", str(cfg), "--out", str(out), "--quiet", "--throughput", "3"]) == 0
    result = json.loads((out / "throughput.json").read_text())
    assert result["runs"] == 3 and [p["workers"] for p in result["passes"]] == [1, 2, 1, 2]
    assert [p["runs_computed"] for p in result["passes"]] == [3, 3, 3, 3]
    best = {w: max(p["runs_per_minute"] for p in result["passes"] if p["workers"] == w)
            for w in (1, 2)}
    assert result["speedup"] == pytest.approx(best[2] / best[1])
    for w in (1, 2):
        assert len(raw_ids(out / "throughput" / f"workers-{w}" / "rows.csv")) == 3
    assert len(raw_ids(out / "rows.csv")) == 4        # the sweep itself, complete
    page = (out / "report.md").read_text()
    assert "Throughput (`--throughput 3`" in page and f"{result['speedup']:.2f} ×" in page
