"""The benchmark harness on tiny configurations: files, columns, consistent numbers.

No timing assertions: only that what is written is complete and self-consistent.
"""

import csv
import json
import math

import numpy as np
import pytest

from prioik.benchmarks.bench import CSV_COLUMNS, Row, Settings, page, ratios, run_benchmark, tables
from prioik.benchmarks.bench.choice import choice_markdown
from prioik.benchmarks.results import TimingRow, read_csv
from prioik.benchmarks.stacks import random_case, random_mass_matrix
from prioik.benchmarks.variants import table
from prioik.cli import main

#: whole-scenario runs (see the `slow` marker in pyproject.toml)
pytestmark = pytest.mark.slow

TINY = dict(sizes=(6, 9), levels=(2, 3), repeats=6, min_repeats=2, warmup=1, cap_s=2.0,
            samples=2, g1=False, blas_threads=1,
            only=("reference", "extended_jacobian", "nullspace", "operational_space",
                  "cascaded_qp"))


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    doc = out / "doc" / "benchmarks.md"
    summary = run_benchmark(Settings(**TINY), out, doc, command="prioik bench (test)")
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    return out, doc, summary, rows


def test_writes_csv_markdown_plots_summary_and_doc(tiny_run):
    out, doc, summary, rows = tiny_run
    for name in ("results.csv", "results.md", "choice.md", "summary.json", "time_vs_n.png",
                 "time_vs_k.png"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "time_vs_n.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((out / "summary.json").read_text())["ratios"]
    text = doc.read_text()
    assert "prioik bench (test)" in text and "**Machine**" in text
    assert "](../time_vs_n.png)" in text           # plot paths relative to the page
    assert "G1 part skipped: --no-g1" in text
    # the decision table's figures, from the CSV just written
    assert (out / "choice.md").read_text() == choice_markdown(
        read_csv(out / "results.csv", TimingRow), out / "results.csv", out)


def test_one_row_per_case_and_variant_with_the_csv_columns(tiny_run):
    _, _, _, rows = tiny_run
    assert tuple(rows[0].keys()) == CSV_COLUMNS
    cases = {r["case"] for r in rows}
    assert cases == {f"random n={n} k={k}" for n in (6, 9) for k in (2, 3)}
    labels = {r["label"] for r in rows}
    # one row per back-end of cascaded_qp, plus the extra extended_jacobian paths
    from prioik import formulations
    qp = formulations.get("cascaded_qp").backends()
    assert {f"cascaded_qp[{b}]" for b in qp} <= labels
    assert {"reference", "extended_jacobian", "extended_jacobian[svd]", "nullspace",
            "operational_space"} <= labels
    assert len(rows) == len(cases) * len(labels)


def _capped(r) -> bool:
    """A QP back-end row the bench's per-case time cap left untimed (SCS takes seconds
    per solve on some of these stacks): the one documented reason a row is untimed."""
    return (r["status"] == "skipped" and r["label"].startswith("cascaded_qp[")
            and ("> 2·cap/min_repeats" in r["note"] or "over the cap" in r["note"]))


def test_every_row_is_timed_and_no_formulation_errors(tiny_run):
    """On the tiny configuration every variant runs: a formulation that raised
    ("error"), an unsupported row or an untimed row is a failure (not a tolerated
    fraction), except a QP back-end over the time cap (:func:`_capped`)."""
    _, _, _, rows = tiny_run
    bad = [(r["case"], r["label"], r["status"], r["note"]) for r in rows
           if r["status"] not in ("ok", "reduced") and not _capped(r)]
    assert not bad, bad


def test_numbers_are_consistent(tiny_run):
    _, _, _, rows = tiny_run
    timed = [r for r in rows if r["status"] in ("ok", "reduced")]
    assert timed and len(timed) == len([r for r in rows if not _capped(r)])
    for r in timed:
        p10, med, p90 = float(r["p10_us"]), float(r["median_us"]), float(r["p90_us"])
        assert 0 < p10 <= med <= p90, r
        assert 0.0 <= float(r["success_rate"]) <= 1.0
        assert 1 <= int(r["repeats"]) <= TINY["repeats"]
        if r["status"] == "ok":
            assert int(r["repeats"]) == TINY["repeats"]
        dmed, dmax = float(r["dist_median"]), float(r["dist_max"])
        assert math.isnan(dmed) or 0.0 <= dmed <= dmax
    for r in rows:
        if r["status"] not in ("ok", "reduced"):
            assert r["note"], r               # a skipped row says why


def test_exact_formulations_succeed_and_match_reference(tiny_run):
    """reference is its own reference; extended_jacobian and nullspace are exact on
    these stacks; operational_space is measured against reference with metric=M."""
    _, _, _, rows = tiny_run
    exact = ("reference", "extended_jacobian", "extended_jacobian[svd]", "nullspace",
             "operational_space")
    checked = [r for r in rows if r["label"] in exact]
    # every exact variant on every case: a missing or errored row fails here
    assert {(r["case"], r["label"]) for r in checked} == \
        {(c, label) for c in {r["case"] for r in rows} for label in exact}
    for r in checked:
        assert r["status"] in ("ok", "reduced"), r
        assert float(r["success_rate"]) == 1.0, r
        assert float(r["dist_max"]) <= 1e-8, r
        if r["label"] == "reference":
            assert float(r["dist_max"]) == 0.0


def test_markdown_tables_have_every_row(tiny_run):
    out, _, _, rows = tiny_run
    md = (out / "results.md").read_text()
    for k in (2, 3):
        assert f"### k = {k} levels" in md
    assert "| formulation | n=6 | n=9 |" in md
    for label in {r["label"] for r in rows}:
        assert f"| {label} |" in md


def _row(case, label, median, suite="g1", formulation=None, k=5, n=35):
    return Row(suite, case, n, k, 46, label, formulation or label.split("[")[0], "", "",
               repeats=200, median_us=median, p10_us=median, p90_us=median,
               success_rate=1.0)


def test_ratios_are_the_quotients_of_the_medians():
    rows = [_row("g1 compatible", "extended_jacobian", 20.0),
            _row("g1 compatible", "nullspace", 100.0),
            _row("g1 compatible", "cascaded_qp[daqp]", 400.0),
            _row("g1 compatible", "cascaded_qp[osqp]", 900.0),
            _row("g1 compatible", "daqp_hierarchical", 25.0),
            _row("g1 compatible", "daqp_hierarchical[raw]", 16.0, formulation="daqp_hierarchical"),
            _row("random n=100 k=2", "extended_jacobian", 50.0, "random", k=2, n=100),
            _row("random n=100 k=16", "extended_jacobian", 80.0, "random", k=16, n=100),
            _row("random n=100 k=2", "nullspace", 100.0, "random", k=2, n=100),
            _row("random n=100 k=16", "nullspace", 700.0, "random", k=16, n=100)]
    batch = {"size": 1000, "batch_us": {"extended_jacobian": 5.0},
             "single_us": {"daqp_hierarchical": 20.0, "daqp_hierarchical[raw]": 10.0},
             "loop_us": {"extended_jacobian": 40.0}}
    ik = {"prioik_oneoff_step_us": 150.0, "prioik_prepared_step_us": 70.0, "placo_step_us": 100.0,
          "panda": {"control_step_us": 2.4, "prepared_step_us": 6.0, "oneoff_step_us": 60.0,
                    "placo_step_us": 3.0}}
    got = {r.name: r for r in ratios(rows, batch, ik)}
    assert got["extended_jacobian / nullspace (λ=0), g1 compatible"].value == pytest.approx(0.2)
    fastest = got["extended_jacobian / fastest cascaded_qp (cascaded_qp[daqp]), g1 compatible"]
    assert fastest.value == pytest.approx(0.05) and fastest.met == "yes"
    daqp = got["extended_jacobian / daqp_hierarchical, g1 compatible"]
    assert daqp.value == pytest.approx(0.8) and daqp.met == "yes"
    raw = got["extended_jacobian / daqp_hierarchical[raw], g1 compatible"]
    assert raw.value == pytest.approx(1.25) and raw.met == "no"
    assert got["extended_jacobian k=16 / k=2 at n=100"].value == pytest.approx(1.6)
    assert got["nullspace k=16 / k=2 at n=100"].value == pytest.approx(7.0)

    def named(*parts):
        (hit,) = [r for name, r in got.items() if all(p in name for p in parts)]
        return hit
    assert named("of 1000 G1 stacks", "one daqp_hierarchical solve").value == \
        pytest.approx(0.25)
    assert named("of 1000 G1 stacks", "daqp_hierarchical[raw]").value == pytest.approx(0.5)
    assert named("loop of extended_jacobian through solve").value == pytest.approx(0.125)
    fast = named("G1 IK step", "prepared solver")
    stack_path = named("G1 IK step", "one-off")
    assert fast.value == pytest.approx(0.7) and fast.met == "yes"
    assert stack_path.value == pytest.approx(1.5) and math.isinf(stack_path.target)
    control = named("Panda reach step", "ControlStep")
    assert control.value == pytest.approx(0.8) and control.target == 1.0 and control.met == "yes"
    panda = named("Panda reach step", "prepared path")
    assert panda.value == pytest.approx(2.0) and math.isinf(panda.target)
    assert math.isinf(named("Panda reach step", "one-off").target)
    # with the shared references timed, the step without them is reported too
    own = ratios(rows, batch, {**ik, "references_us": 20.0})[-1]
    assert "without the shared references" in own.name
    assert own.value == pytest.approx(50.0 / 80.0) and math.isinf(own.target)


def test_solve_overhead_and_row_writing_rows_are_the_measured_times():
    ik = {"solve_overhead": {"g1": {"solve_us": 12.0, "kernel_us": 10.5, "overhead_us": 1.5},
                             "panda": {"solve_us": 4.0, "kernel_us": 1.5, "overhead_us": 2.5},
                             "g1_bounds": {"solve_us": 7.0, "kernel_us": 6.0,
                                           "overhead_us": 1.0},
                             "panda_limits": {"solve_us": 3.5, "kernel_us": 2.0,
                                              "overhead_us": 1.5}},
          "rows": {"none": {"write_us": 8.0, "rows": 46},
                   "bounds": {"write_us": 11.0, "rows": 75}}}
    got = {r.name: r for r in ratios([], {}, ik)}

    def named(*parts):
        (hit,) = [r for name, r in got.items() if all(p in name for p in parts)]
        return hit
    g1 = named("prepared.solve overhead", "G1 fencing rows")
    assert g1.value == 1.5 and g1.target == 2.0 and g1.met == "yes"
    panda = named("prepared.solve overhead", "Panda reach rows")
    assert panda.value == 2.5 and panda.met == "no"
    assert named("prepared.solve overhead", "active_set, G1").value == 1.0
    assert named("prepared.solve overhead", "active_set, Panda").value == 1.5
    rows = named("G1 fencing rows", "five fencing tasks")
    assert rows.value == 8.0 and rows.target == 10.0 and rows.met == "yes"
    assert named("G1 fencing rows", "bounds").value == 11.0
    empty = {r.name: r for r in ratios([], {}, {"placo_step_us": 1.0})}
    assert all(math.isnan(r.value) for name, r in empty.items()
               if "overhead" in name or "fencing rows" in name)


def test_solve_overhead_times_the_public_call_and_its_kernel_on_the_same_rows():
    import prioik
    from prioik.benchmarks import solve_overhead
    solver, datas = solve_overhead.panda_rows(states=3)
    r = solve_overhead.solve_overhead(solver, datas, rounds=1, calls=5)
    assert set(r) >= {"solve_us", "kernel_us", "overhead_us"}
    # the median of the paired differences (public minus kernel, call by call): every
    # difference is below its public call's time, so the median is below theirs
    assert 0.0 < r["kernel_us"] and 0.0 < r["solve_us"]
    assert math.isfinite(r["overhead_us"]) and r["overhead_us"] < r["solve_us"]
    lapack = prioik.prepare(solver.layout, "extended_jacobian", kernel="lapack")
    with pytest.raises(RuntimeError, match="compiled"):
        solve_overhead.solve_overhead(lapack, datas, rounds=1, calls=5)


def test_solve_overhead_times_the_active_set_beside_a_twin_kernel():
    """The Panda reach with limits (hierarchical_active_set): the public call beside a twin
    ActiveSetSolver solving the same sequence (the same answers, bit for bit, checked by
    solve_overhead itself)."""
    from prioik.benchmarks import solve_overhead
    solver, datas = solve_overhead.panda_rows(states=3, limits=True)
    assert solver.formulation == "hierarchical_active_set"
    r = solve_overhead.solve_overhead(solver, datas, rounds=1, calls=5)
    assert 0.0 < r["kernel_us"] and 0.0 < r["solve_us"]
    assert math.isfinite(r["overhead_us"]) and r["overhead_us"] < r["solve_us"]


def test_missing_measurements_give_nan_not_a_number():
    got = ratios([_row("g1 compatible", "extended_jacobian", 20.0)], {}, {})
    for r in got:
        assert math.isnan(r.value) and r.met == "n/a"


def test_skipped_and_unsupported_rows_are_recorded_not_timed():
    """A per-case cap below one solve records the variant as skipped with a reason."""
    case = random_case(12, 2, samples=2)
    variants = table("bench").only(("reference",))
    settings = Settings(cap_s=1e-9, min_repeats=2)
    ref = tables.references(case, False)
    row = tables.time_case(case, variants[0], ref, settings)
    assert row.status == "skipped" and row.repeats == 0 and "ms" in row.note
    assert math.isnan(row.median_us)


def test_random_cases_are_seeded_and_mass_matrices_spd():
    a, b = random_case(20, 4, samples=3), random_case(20, 4, samples=3)
    for s, t in zip(a.stacks, b.stacks, strict=False):
        for la, lb in zip(s.levels, t.levels, strict=False):
            assert np.array_equal(la.A, lb.A) and np.array_equal(la.b, lb.b)
    assert all(len(s) == 4 and s.n == 20 for s in a.stacks)
    M = random_mass_matrix(20)
    assert np.array_equal(M, M.T)
    w = np.linalg.eigvalsh(M)
    assert w.min() == pytest.approx(0.1, rel=1e-8) and w.max() == pytest.approx(10.0, rel=1e-8)


def test_cli_runs_a_tiny_benchmark(tmp_path, capsys):
    code = main(["bench", "--out", str(tmp_path), "--no-g1", "--sizes", "5",
                 "--levels", "2", "--samples", "1", "--repeats", "3",
                 "--formulations", "reference,extended_jacobian"])
    assert code == 0
    with open(tmp_path / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["label"] for r in rows} == {"reference", "extended_jacobian",
                                         "extended_jacobian[svd]",
                                         "extended_jacobian[lapack]"}
    assert all(r["repeats"] == "3" for r in rows)
    assert "wrote" in capsys.readouterr().out


def test_cli_rejects_bad_lists(tmp_path, capsys):
    assert main(["bench", "--out", str(tmp_path), "--no-g1", "--sizes", "a,b"]) == 2
    assert "--sizes" in capsys.readouterr().err


def test_blas_threads_are_set_and_restored():
    from prioik.threads import blas_info, blas_threads
    before = [p["num_threads"] for p in blas_info()]
    assert before, "no BLAS found in this process"
    with blas_threads(1):
        assert all(p["num_threads"] == 1 for p in blas_info())
    assert [p["num_threads"] for p in blas_info()] == before



def test_g1_fencing_samples_give_robot_stacks_and_mass_matrices():
    pytest.importorskip("pinocchio")
    from prioik.benchmarks.stacks import g1_fencing_samples
    samples = g1_fencing_samples("compatible", 3, dt=0.01, duration=0.1)
    assert len(samples.stacks) == 3 and samples.times[0] == 0.0
    for stack, M in zip(samples.stacks, samples.mass_matrices, strict=False):
        assert stack.n == 35 and stack.is_equality
        assert stack.levels[0].names == ("support_foot",)
        assert np.array_equal(M, M.T) and np.linalg.eigvalsh(M).min() > 0
    more = samples.stacks_at(5)
    assert len(more) == 5 and all(s.n == 35 for s in more)


def test_a_plugin_error_is_recorded_and_the_run_goes_on(tmp_path, monkeypatch):
    real = tables.time_case

    def broken(case, variant, ref, settings):
        if variant.label == "extended_jacobian[svd]":
            raise RuntimeError("boom in a plugin")
        return real(case, variant, ref, settings)

    monkeypatch.setattr(tables, "time_case", broken)
    settings = Settings(sizes=(5,), levels=(2,), repeats=3, min_repeats=2, warmup=1,
                        samples=1, g1=False, only=("reference", "extended_jacobian"))
    run_benchmark(settings, tmp_path)
    with open(tmp_path / "results.csv") as fh:
        rows = {r["label"]: r for r in csv.DictReader(fh)}
    assert rows["extended_jacobian[svd]"]["status"] == "error"
    assert "boom in a plugin" in rows["extended_jacobian[svd]"]["note"]
    assert rows["extended_jacobian"]["status"] == "ok"
    assert "| extended_jacobian[svd] | error" in (tmp_path / "results.md").read_text()


def test_control_step_table_normalises_to_the_extended_jacobian():
    control = [
        {"label": "extended_jacobian", "formulation": "extended_jacobian", "paper_ms": 1.4,
         "steps": 5, "kinematics_us": 1.0, "solve_us": 2.0, "torque_us": 3.0,
         "total_us": 6.0, "note": ""},
        {"label": "nullspace", "formulation": "nullspace", "paper_ms": 2.7, "steps": 5,
         "kinematics_us": 1.0, "solve_us": 5.0, "torque_us": 3.0, "total_us": 9.0,
         "note": "shortened to 5 steps (time cap)"},
        {"label": "reference", "formulation": "reference", "paper_ms": None, "steps": 0,
         "note": "t = 0.1 s: diverged"}]
    md = page.results_markdown([], [], {}, {}, control, [], Settings(), [])
    assert ("| `nullspace` — resolved acceleration method | 5 | 1.0 | 5.0 | 3.0 | 9.0 | "
            "1.50 | 2.7 | 1.93 | shortened to 5 steps (time cap) |") in md
    assert "| `reference` | 0 |" in md and "stopped: t = 0.1 s: diverged" in md
