"""benchmarks/variants.py: the rows of every report come from the registry.

The toy plugin (``conftest.toy_plugin``) is registered and nothing else is edited: it must
appear in validate, properties, bench, the scenario reports and the sweep, its declared
row where it declares it, and its opt-out must keep it out of that report's selection.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import TOY

from prioik.benchmarks.variants import (
    REPORTS,
    Variant,
    VariantTable,
    parse_label,
    split_labels,
    table,
)


def test_labels_have_one_syntax():
    assert Variant("cascaded_qp", "daqp", {"solver": "daqp"}).label == "cascaded_qp[daqp]"
    assert Variant("nullspace").label == "nullspace"
    assert parse_label("cascaded_qp[daqp,velocity]") == ("cascaded_qp", "daqp,velocity")
    assert parse_label("sns") == ("sns", "")
    with pytest.raises(ValueError, match="not a run label"):
        parse_label("cascaded_qp:daqp")
    assert split_labels("a, b[x,y],c[z]") == ["a", "b[x,y]", "c[z]"]
    v = Variant("sns", "velocity", {}, level="velocity", limits="hard_bounds",
                only_in=("compatible",))
    assert Variant.from_dict(v.to_dict()) == v


@pytest.mark.parametrize("report", REPORTS)
def test_every_report_builds_and_its_labels_parse(report):
    """Every plugin's declarations name options it has, and every label is unique and
    parses back to its formulation."""
    t = table(report, scenario="fencing" if report == "sweep" else None)
    assert t.rows and len(t.known) >= len(t.rows)
    for label, v in t.known.items():
        assert parse_label(label) == (v.formulation, v.tag)


def test_plugin_declarations_land_in_their_reports():
    bench = table("bench").labels
    assert {"extended_jacobian[svd]", "extended_jacobian[lapack]",
            "daqp_hierarchical[raw]"} <= set(bench)
    assert "extended_jacobian[svd]" not in table("validate").labels
    fencing = table("fencing")
    assert "cascaded_qp[daqp]" in fencing.labels and "cascaded_qp" not in fencing.known
    assert table("arm")["cascaded_qp[quadprog]"].backend == "quadprog"
    assert fencing["sns"].limits == "hard_bounds"                 # replaces the default row
    assert fencing["extended_jacobian[step_bound]"].only_in == ("incompatible",)  # a study
    assert "reference" in fencing.known and "reference" not in fencing.labels     # opt-out
    ablations = [v for v in table("validate").rows if v.origin == "declared"]
    assert "cascaded_qp[clarabel,fixing=rows]" in {v.label for v in ablations}


def test_report_rows_are_declared_by_the_benchmarks_for_known_names():
    """The table of benchmarks/report_rows.py is keyed by registry (or baseline) names,
    and no solver module declares report rows of its own."""
    import ast
    import pathlib

    from prioik import formulations
    from prioik.benchmarks import report_rows
    from prioik.benchmarks.variants import BASELINES
    known = set(formulations.names()) | set(BASELINES)
    assert set(report_rows.REPORT_VARIANTS) <= known
    assert set(report_rows.REPORT_OPT_OUTS) <= known
    assert report_rows.declared("extended_jacobian")[0].tag == "svd"
    assert report_rows.declared("no such formulation") == ()
    # the table is plain data (building the parser imports no solver module): a number
    # it quotes is the module's
    from prioik.formulations.extended_jacobian import AUTO_CPP_MAX_N
    lapack = [rv for rv in report_rows.declared("extended_jacobian") if rv.tag == "lapack"]
    assert f"up to n = {AUTO_CPP_MAX_N}," in lapack[0].note
    root = pathlib.Path(formulations.__file__).parent
    for path in root.glob("*.py"):
        names = {t.id for node in ast.parse(path.read_text()).body
                 if isinstance(node, ast.Assign) for t in node.targets
                 if isinstance(t, ast.Name)}
        assert not names & {"REPORT_VARIANTS", "REPORT_OPT_OUTS", "ReportVariant"}, path.name


def test_a_declared_row_with_an_unknown_option_is_refused(monkeypatch):
    from prioik.benchmarks import report_rows
    monkeypatch.setitem(report_rows.REPORT_VARIANTS, "nullspace",
                        (report_rows.ReportVariant("bad", {"no_such_option": 1}),))
    with pytest.raises(ValueError, match="nullspace.*'bad'.*no_such_option"):
        table("bench")


def test_select_names_unknown_and_unavailable_runs():
    t = VariantTable("fencing", [Variant("a")], {"a": Variant("a")}, [],
                     {"b": "not available here (missing)"})
    assert t.select("") == ([Variant("a")], [])
    chosen, skipped = t.select("a,b")
    assert chosen == [Variant("a")] and skipped == ["b: not available here (missing)"]
    with pytest.raises(ValueError, match="unknown run.*c; known: a"):
        t.select("a,c")


def test_a_registered_toy_plugin_is_in_every_report_without_an_edit(toy_plugin):
    for report in ("validate", "properties", "bench", "control_step", "fencing", "sweep"):
        assert TOY in table(report, scenario="fencing").labels, report
    assert f"{TOY}[half]" in table("bench").labels                  # declared for bench
    assert f"{TOY}[half]" not in table("validate").known
    arm = table("arm")                                             # opted out of arm
    assert TOY not in arm.labels and TOY in arm.known
    assert any(n.startswith(f"{TOY}: left out of arm (a toy") for n in arm.notes)


@pytest.mark.slow
def test_the_toy_plugin_runs_in_validate_properties_bench_and_scenarios(toy_plugin, tmp_path):
    """Each command's own path, with the toy among its rows: a validation row, a
    properties column, bench rows (its default and its declared one) and a fencing run."""
    from prioik.benchmarks import validation
    from prioik.benchmarks.bench import Settings, run_benchmark
    from prioik.benchmarks.results import TimingRow, read_csv
    from prioik.benchmarks.scenario_runs import run_one
    from prioik.cli import main

    text = validation.report(2, ["compatible"], (4, 8), (2, 3), only=[TOY, "reference"],
                             stream=open("/dev/null", "w"))
    row = next(line for line in text.splitlines() if line.startswith(f"| {TOY} |"))
    assert row.split("|")[6].strip() == "0/2/0"         # optimal / approximate / failed

    page = tmp_path / "properties.md"
    assert main(["properties", "--out", str(page), "--stacks", "1"]) == 0
    text = page.read_text()
    assert "| σ | reference |" in text and f" {TOY} |" in text.splitlines()[
        text.splitlines().index("### ‖θ̈‖ against σ") + 2]
    assert f"* `{TOY}` is" in text                      # an approximate method's finding

    run_benchmark(Settings(sizes=(6,), levels=(2,), samples=1, repeats=3, min_repeats=2,
                           warmup=1, g1=False, only=(TOY, "reference")), tmp_path / "b")
    rows = {r.label: r for r in read_csv(tmp_path / "b" / "results.csv", TimingRow)}
    assert set(rows) == {TOY, f"{TOY}[half]", "reference"}
    assert rows[TOY].status == "ok" and rows[TOY].repeats == 3
    assert rows[f"{TOY}[half]"].options == "scale=0.5"

    res = run_one(table("fencing")[TOY], "compatible", 0.02, 0.002)
    assert res.steps == 10 and res.info["formulation"] == TOY
    assert np.isfinite(res.errors["tip_error_m"]).all()
