"""The decision table's figures (benchmarks/bench/choice.py): every cell from the CSV's
rows, "not measured" where a row is absent or untimed, and the committed snippet is what
the generator writes from the committed CSV."""

from __future__ import annotations

import math
from pathlib import Path

from prioik.benchmarks.bench import choice
from prioik.benchmarks.results import TimingRow, read_csv, write_csv
from prioik.cli import main

ROOT = Path(__file__).resolve().parents[1]
CSV = Path("docs/benchmarks/results.csv")          # as the page and the snippet name it
SNIPPET = ROOT / "docs" / "benchmarks" / choice.FILE_NAME
PAGE = ROOT / "docs" / "how-to" / "choose-a-formulation.md"


def _row(case: str, label: str, median: float, success: float = 1.0, status: str = "ok",
         n: int = 35, k: int = 5) -> TimingRow:
    formulation = label.split("[")[0]
    suite = "g1" if case.startswith("g1") else "random"
    return TimingRow(suite=suite, case=case, n=n, k=k, rows=46, label=label,
                     formulation=formulation, backend="", options="", repeats=10,
                     median_us=median, p10_us=median, p90_us=median, success_rate=success,
                     status=status)


def _hand_made() -> list[TimingRow]:
    rows = []
    for case, scale in (("g1 compatible", 1.0), ("g1 incompatible", 2.0)):
        rows += [_row(case, "extended_jacobian", 5.0 * scale),
                 _row(case, "nullspace", 20.0 * scale),
                 # faster, but it did not match reference: not the denominator
                 _row(case, "placo", 1.0 * scale, success=0.5),
                 _row(case, "cascaded_qp[daqp]", 1000.0 * scale),
                 _row(case, "cascaded_qp[osqp]", 4000.0 * scale, success=0.25)]
    rows.append(_row("g1 compatible", "sns", math.nan, status="skipped"))
    rows.append(_row("g1 compatible", "lexls", 50.0, success=math.nan))
    rows += [_row("random n=12 k=2", "extended_jacobian", 3.0, n=12, k=2),
             _row("random n=100 k=2", "extended_jacobian", 100.0, n=100, k=2),
             _row("random n=12 k=16", "extended_jacobian", 2.5, n=12, k=16)]
    return rows


def _table(text: str, first: str) -> dict[str, list[str]]:
    """The markdown table of ``text`` whose header starts with ``first``, by the first
    code span of each row (a formulation label)."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first} "))
    out: dict[str, list[str]] = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        key = next(c for c in cells if c.startswith("`"))
        out.setdefault(key, cells)
    return out


def _growth(text: str) -> dict[tuple[str, str], list[str]]:
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| formulation "))
    out = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        out[(cells[0], cells[1])] = cells[2:]
    return out


def test_cells_are_the_csv_medians_and_their_ratios_to_the_fastest_exact_row():
    text = choice.choice_markdown(_hand_made(), CSV, CSV.parent)
    rows = _table(text, "your stack and need")
    ej, ns = rows["`extended_jacobian`"], rows["`nullspace`"]
    assert ej[2:7] == ["5.0 µs", "10.0 µs", "1.0×", "1.0×", "100% / 100%"]
    assert ns[2:7] == ["20.0 µs", "40.0 µs", "4.0×", "4.0×", "100% / 100%"]
    # placo is faster but matched reference on half its solves only
    assert rows["`placo`"][2:7] == ["1.0 µs", "2.0 µs", "0.2×", "0.2×", "50% / 50%"]
    assert "`extended_jacobian` (5.0 µs) on compatible" in text
    assert rows["`lexls`"][2:7] == ["50.0 µs", choice.NOT_MEASURED, "10×", "–", "– / –"]
    qp = rows["`cascaded_qp` (one row per back-end)"]
    assert qp[2] == "1000.0 µs (`cascaded_qp[daqp]`) to 4000.0 µs"
    assert qp[4] == "200× to 800×"
    assert qp[6] == "25% to 100% / 25% to 100%"


def test_rows_absent_or_untimed_say_not_measured():
    rows = _table(choice.choice_markdown(_hand_made(), CSV, CSV.parent),
                  "your stack and need")
    assert rows["`sns`"][2:4] == [f"{choice.NOT_MEASURED} (skipped)", choice.NOT_MEASURED]
    assert rows["`sns`"][4:6] == ["–", "–"]
    for absent in ("`reference`", "`hierarchical_active_set`",
                   "`cvxpy` (one row per back-end)"):
        assert rows[absent][2:4] == [choice.NOT_MEASURED] * 2, absent
    assert len(rows) == len(choice.CHOICES)


def test_growth_table_is_the_random_rows_with_gaps_named():
    growth = _growth(choice.choice_markdown(_hand_made(), CSV, CSV.parent))
    assert growth[("`extended_jacobian`", "2")] == ["3.0", "100.0"]
    assert growth[("`extended_jacobian`", "16")] == ["2.5", choice.NOT_MEASURED]
    assert growth[("`nullspace`", "2")] == [choice.NOT_MEASURED] * 2


def test_no_g1_case_gives_no_number():
    text = choice.choice_markdown([r for r in _hand_made() if r.suite == "random"], CSV,
                                  CSV.parent)
    assert "µs |" not in text.split("**How the cost grows**")[0]
    assert "none on compatible" in text


def test_from_csv_writes_the_snippet_without_a_run(tmp_path, capsys):
    csv_path = write_csv(tmp_path / "results.csv", _hand_made(), TimingRow)
    assert main(["bench", "--from-csv", str(csv_path), "--out", str(tmp_path / "out")]) == 0
    written = (tmp_path / "out" / choice.FILE_NAME).read_text()
    assert written == choice.choice_markdown(read_csv(csv_path, TimingRow), csv_path,
                                             tmp_path / "out")
    assert f"prioik bench --from-csv {csv_path} --out {tmp_path / 'out'}" in written
    assert not (tmp_path / "out" / "results.csv").exists()        # nothing was run


def test_from_csv_refuses_doc(tmp_path, capsys):
    csv_path = write_csv(tmp_path / "results.csv", _hand_made(), TimingRow)
    assert main(["bench", "--from-csv", str(csv_path), "--out", str(tmp_path),
                 "--doc", str(tmp_path / "page.md")]) == 2
    assert "--doc needs a run" in capsys.readouterr().err
    assert not (tmp_path / choice.FILE_NAME).exists()


def test_committed_snippet_is_what_the_committed_csv_gives():
    """A stale snippet fails: regenerate it with the command it names."""
    rows = read_csv(ROOT / CSV, TimingRow)
    assert SNIPPET.read_text() == choice.choice_markdown(rows, CSV, CSV.parent), \
        f"regenerate: prioik bench --from-csv {CSV} --out {CSV.parent}"


def test_the_page_includes_the_snippet_and_names_its_commands():
    text = PAGE.read_text()
    assert f'--8<-- "{SNIPPET.relative_to(ROOT)}"' in text
    assert "prioik bench --out docs/benchmarks --doc docs/benchmarks.md" in text
    assert f"prioik bench --from-csv {CSV} --out {CSV.parent}" in text
