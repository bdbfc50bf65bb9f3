"""benchmarks/properties.py: the generated report measures what it claims."""

import numpy as np

from benchmarks.cli import main
from benchmarks.properties import error_table, singularity_sweep


def test_sweep_slopes_and_bounds():
    sweep = singularity_sweep()
    slope = {v.label: s for v, s in zip(sweep.variants, sweep.slopes)}
    for label in ("reference", "ext_jac qr", "ext_jac svd", "nullspace", "op_space M"):
        assert -1.01 <= slope[label] <= -0.99, (label, slope[label])
    for label in ("chiaverini", "unifying M=I", "unifying M", "nullspace λ=0.01"):
        assert abs(slope[label]) <= 0.2, (label, slope[label])
    assert np.isfinite(sweep.norms).all()
    damped = [j for j, v in enumerate(sweep.variants) if "λ=" in v.label]
    assert sweep.norms[:, damped].max() <= 1 / (2 * np.sqrt(1e-2)) + 1


def test_error_table_separates_exact_from_projected_methods():
    table = error_table(n_stacks=4, families=("coupled", "decoupled"))
    for label in ("reference", "ext_jac qr", "nullspace", "op_space M"):
        assert table["coupled"][label].lower_max <= 1e-10
        assert table["coupled"][label].lexicographic == 1.0
    for label in ("chiaverini", "unifying M=I", "unifying M"):
        assert table["coupled"][label].lower_min > 0.05
        assert table["coupled"][label].top_max <= 1e-10
    assert table["decoupled"]["chiaverini"].lower_max <= 1e-10


def test_cli_writes_the_report(tmp_path, capsys):
    out = tmp_path / "properties.md"
    assert main(["properties", "--out", str(out), "--stacks", "2"]) == 0
    text = out.read_text(encoding="utf-8")
    assert "| **slope**" in text and "### `coupled`" in text and "### `conflicting`" in text
    assert "wrote" in capsys.readouterr().out
    assert main(["properties", "--out", str(out), "--stacks", "0"]) == 2
