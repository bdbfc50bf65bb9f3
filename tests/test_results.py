"""benchmarks/results.py: one schema per record, and its CSV reads back as written."""

from __future__ import annotations

import math

import numpy as np
import pytest

from prioik.benchmarks.results import RunSummary, TimingRow, csv_columns, read_csv, write_csv


def test_timing_rows_read_back_as_written(tmp_path):
    rows = [TimingRow("random", "random n=5 k=2", 5, 2, 7, "cascaded_qp[daqp]", "cascaded_qp",
                      "daqp", "solver=daqp", 3, 12.5, 10.0, 20.0, 1.0, 1e-15, 2e-15, 40.0),
            TimingRow("g1", "g1 compatible", 35, 5, 46, "sns", "sns", "", "", status="skipped",
                      note="one solve took 9 ms > cap 0.001 s", probe_s=0.009)]
    path = write_csv(tmp_path / "r.csv", rows)
    assert path.read_text().splitlines()[0].split(",") == list(csv_columns(TimingRow))
    assert "probe_s" not in csv_columns(TimingRow)          # not part of the file
    back = read_csv(path, TimingRow)
    assert back[0] == rows[0]
    assert back[1].status == "skipped" and math.isnan(back[1].median_us)
    assert back[1].repeats == 0 and math.isnan(back[1].probe_s)


def test_reading_another_records_file_names_it(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match="x.csv: columns"):
        read_csv(path, TimingRow)
    with pytest.raises(ValueError, match="no records and no record class"):
        write_csv(tmp_path / "y.csv", [])


def test_a_file_without_a_later_defaulted_column_reads_it_at_its_default(tmp_path):
    """A results file written before ``verify_median_us`` existed reads it as NaN; a file
    lacking a column without a default, or with its columns reordered, is refused."""
    row = TimingRow("random", "random n=5 k=2", 5, 2, 7, "nullspace", "nullspace", "", "", 3,
                    12.5, 10.0, 20.0, 1.0, 1e-15, 2e-15, 40.0)
    lines = write_csv(tmp_path / "r.csv", [row]).read_text().splitlines()
    cols = lines[0].split(",")

    def without(name: str, text: list[str]) -> str:
        i = cols.index(name)
        return "\n".join(",".join(c for j, c in enumerate(line.split(",")) if j != i)
                         for line in text) + "\n"
    old = tmp_path / "old.csv"
    old.write_text(without("verify_median_us", lines))
    (back,) = read_csv(old, TimingRow)
    assert math.isnan(back.verify_median_us) and back.median_us == 12.5
    assert (back.formulation, back.repeats, back.dist_max) == ("nullspace", 3, 2e-15)
    bad = tmp_path / "bad.csv"
    bad.write_text(without("label", lines))             # a column with no default
    with pytest.raises(ValueError, match="bad.csv: columns"):
        read_csv(bad, TimingRow)
    swapped = tmp_path / "swapped.csv"
    swapped.write_text("\n".join([",".join([cols[1], cols[0], *cols[2:]]), lines[1]]) + "\n")
    with pytest.raises(ValueError, match="swapped.csv: columns"):
        read_csv(swapped, TimingRow)


def test_run_summary_keys_follow_the_scenario_errors():
    class Res:
        steps = 3
        errors = {"tip_error_m": np.array([0.3, 0.2, 0.1]), "com_error_m": np.array([1, 2, np.nan])}
        algorithmic_error = np.array([np.nan, np.nan, np.nan])
        a = np.ones((3, 2))
        step_time_s = np.array([1.0, 2.0, 3.0])
        solve_time_s = np.array([0.5, 0.5, 0.5])
        verify_time_s = np.array([0.0, 0.25, 0.25])
        failed = False

    s = RunSummary.of(Res(), ("com_error_m", "missing_m")).to_dict()
    assert s["median_verify_time_s"] == 0.25
    assert tuple(s) == RunSummary.keys(("com_error_m", "missing_m"))
    assert s["final_tip_error_m"] == pytest.approx(0.1) and s["max_com_error_m"] == 2.0
    assert s["max_missing_m"] is None and s["max_algorithmic_error"] is None
    assert s["median_step_time_s"] == 2.0 and s["max_qdd_norm"] == pytest.approx(np.sqrt(2))
