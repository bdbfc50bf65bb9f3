"""benchmarks/properties.py: the generated report measures what it claims."""

import numpy as np

from prioik.benchmarks.properties import error_table, singularity_sweep
from prioik.cli import main


def test_sweep_slopes_and_bounds():
    sweep = singularity_sweep()
    slope = {v.label: s for v, s in zip(sweep.variants, sweep.slopes, strict=False)}
    for label in ("reference", "extended_jacobian", "extended_jacobian[svd]", "nullspace",
                  "operational_space"):
        assert -1.01 <= slope[label] <= -0.99, (label, slope[label])
    for label in ("chiaverini", "unifying[M=I]", "unifying", "nullspace[damping=0.01]"):
        assert abs(slope[label]) <= 0.2, (label, slope[label])
    assert np.isfinite(sweep.norms).all()
    damped = [j for j, v in enumerate(sweep.variants) if v.damped]
    assert len(damped) == 5
    assert sweep.norms[:, damped].max() <= 1 / (2 * np.sqrt(1e-2)) + 1
    # rotated coordinates: the basis methods keep both residuals at round-off × ‖θ̈‖
    # (measured ≤ 5.3e-9 at ‖θ̈‖ = 1e8)
    for label in ("reference", "extended_jacobian"):
        j = [v.label for v in sweep.variants].index(label)
        worst = np.maximum(sweep.rotated_top[:, j], sweep.rotated_lower[:, j])
        sig = np.array(sweep.sigmas)
        assert (worst[sig > 1e-9] <= 1e-7).all(), (label, worst)


def test_error_table_separates_exact_from_projected_methods():
    table = error_table(n_stacks=4, families=("coupled", "decoupled"))
    for label in ("reference", "extended_jacobian", "nullspace", "operational_space"):
        assert table["coupled"][label].lower_max <= 1e-10
        assert table["coupled"][label].lexicographic == 1.0
    for label in ("chiaverini", "unifying[M=I]", "unifying"):
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


def test_exactly_conflicting_limit_every_formulation_finite_exact_ones_equal_reference():
    """σ = 0 (Theorem 1's case): all variants finite; the exact ones equal reference
    (operational_space: reference with metric=M); the damped ones (λ = 1e-2) within
    5 % of it (measured 2.2 % = λ/(σ² + λ) for the free row, σ² = 0.44)."""
    from prioik import formulations
    from prioik.benchmarks.properties import MASS_CONDITION, report_variants, solve_variant
    from prioik.hierarchy.families import near_singular, random_spd
    stack = near_singular(0.0)
    mass = random_spd(np.random.default_rng(0), stack.n, MASS_CONDITION)
    ref = formulations.solve(stack, "reference").x
    ref_m = formulations.solve(stack, "reference", metric=mass).x
    for v in report_variants():
        sol = solve_variant(stack, v, mass)
        assert sol.ok and np.isfinite(sol.x).all() and np.linalg.norm(sol.x) < 2.0, v.label
        if v.label in ("extended_jacobian", "extended_jacobian[svd]", "nullspace"):
            np.testing.assert_allclose(sol.x, ref, atol=1e-12)
        elif v.label == "operational_space":
            np.testing.assert_allclose(sol.x, ref_m, atol=1e-12)
        elif v.damped:
            assert np.linalg.norm(sol.x - ref) <= 0.05 * np.linalg.norm(ref), v.label


def test_conditioning_of_the_extended_system_is_sigma_squared():
    """The report's Theorem 1 table: σ_min(J_E) ≈ σ², σ_min(J_2 Z_2) ≈ σ (within 5 %)."""
    from prioik.benchmarks.properties import conditioning
    cond = conditioning((1e-2, 1e-4, 0.0))
    assert np.allclose(cond.projected[:2], [1e-2, 1e-4], rtol=0.05)
    for zb, vals in cond.extended.items():
        assert np.allclose(vals[:2], [1e-4, 1e-8], rtol=0.05), zb
        assert vals[2] > 0.1            # σ = 0: the rank rule removed the direction
    assert list(cond.rows["task_range"]) == list(cond.rank)
