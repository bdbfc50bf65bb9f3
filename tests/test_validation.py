"""benchmarks/validation.py on a tiny N (the committed report uses N ≥ 200)."""

import numpy as np
import pytest

from prioik import cli
from prioik.benchmarks import validation

#: whole-scenario runs (see the `slow` marker in pyproject.toml)
pytestmark = pytest.mark.slow


def test_validate_writes_a_table_for_every_family(tmp_path, capsys):
    out = tmp_path / "validation.md"
    rc = cli.main(["validate", "--n-stacks", "2", "--n-max", "8", "--k-max", "3",
                   "--out", str(out)])
    assert rc == 0
    text = out.read_text(encoding="utf-8")
    for family in validation.EQUALITY_FAMILY_NAMES + validation.INEQUALITY_FAMILY_NAMES:
        assert f"## {family}" in text
    for label in ("cascaded_qp[clarabel]", "cascaded_qp[quadprog]", "cvxpy", "placo",
                  "daqp_hierarchical", "reference", "cascaded_qp[clarabel,fixing=rows]"):
        assert f"| {label} |" in text
    # closed-form methods are skipped on inequality stacks, with the reason
    ineq = text.split("## with_inequalities")[1]
    assert "| extended_jacobian |" not in ineq and "`extended_jacobian` skipped" in ineq
    # the reference agrees with itself, and progress went to stderr
    assert "| reference | 0.0e+00 | 0.0e+00 | 0.0e+00 | 2/2 | 2/0/0 | 0 (0) |" in text
    assert "validate: compatible 2/2" in capsys.readouterr().err


def test_draw_is_seeded_and_family_specific():
    a = validation.draw("conflicting", 3, (4, 10), (2, 4))
    b = validation.draw("conflicting", 3, (4, 10), (2, 4))
    c = validation.draw("compatible", 3, (4, 10), (2, 4))
    assert np.array_equal(a.levels[0].A, b.levels[0].A)
    assert a.n != c.n or not np.array_equal(a.levels[0].A, c.levels[0].A)


def test_unknown_family_is_an_error(tmp_path):
    assert cli.main(["validate", "--n-stacks", "1", "--families", "nope",
                     "--out", str(tmp_path / "v.md")]) == 2


def test_no_inequality_answer_says_optimal_and_fails_the_certificate(tmp_path):
    out = tmp_path / "v.md"
    rc = cli.main(["validate", "--n-stacks", "4", "--n-max", "10", "--k-max", "4",
                   "--families", "random_inequality", "--no-ablations", "--formulations",
                   "cascaded_qp,cvxpy,daqp_hierarchical,placo", "--out", str(out)])
    assert rc == 0
    rows = [r for r in out.read_text(encoding="utf-8").splitlines()
            if r.startswith("| cascaded_qp[") or r.startswith("| cvxpy |")
            or r.startswith("| daqp_hierarchical |") or r.startswith("| placo |")]
    assert len(rows) >= 4
    for row in rows:
        cells = [c.strip() for c in row.strip("|").split("|")]
        wrong = cells[7]                     # "optimal ∧ fails cert. (without cert.)"
        assert wrong.startswith("0 ("), row
