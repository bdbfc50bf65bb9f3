"""nullspace: recursive null-space projection, plain and damped (singularity-robust)."""

import numpy as np
import pytest

from prioik import formulations
from prioik.hierarchy import Task, TaskStack, UnsupportedTaskError, check_lexicographic
from prioik.hierarchy.families import FAMILIES, compatible, near_singular

SIGMAS = np.logspace(-1, -7, 7)


@pytest.mark.parametrize("seed", range(15))
def test_compatible_equals_reference_and_meets_every_task(seed):
    rng = np.random.default_rng(seed)
    stack = compatible(rng, int(rng.integers(4, 40)), int(rng.integers(1, 6)))
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "nullspace")
    assert sol.status == "optimal"
    assert np.linalg.norm(sol.x - ref) <= 1e-9 * max(1.0, np.linalg.norm(ref))
    for level, r in zip(stack.levels, sol.residuals, strict=False):
        assert r <= 1e-9 * max(1.0, np.linalg.norm(level.b))


@pytest.mark.parametrize("family", ["conflicting", "rank_deficient", "weighted",
                                    "degenerate", "coupled"])
@pytest.mark.parametrize("seed", range(10))
def test_conflicting_equals_reference_and_is_lexicographic(family, seed):
    rng = np.random.default_rng(2000 + seed)
    stack = FAMILIES[family](rng, int(rng.integers(3, 40)), int(rng.integers(2, 7)))
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "nullspace")
    assert np.linalg.norm(sol.x - ref) <= 1e-8 * max(1.0, np.linalg.norm(ref))
    report = check_lexicographic(stack, sol.x, tol=1e-8)
    assert report.ok, str(report)


def test_grows_like_one_over_sigma_near_an_algorithmic_singularity():
    """log‖θ̈‖ against log σ has slope −1 (fitted over σ = 1e-1 … 1e-7): measured −1.00."""
    norms = np.array([np.linalg.norm(formulations.solve(near_singular(s), "nullspace").x)
                      for s in SIGMAS])
    slope = np.polyfit(np.log(SIGMAS), np.log(norms), 1)[0]
    assert -1.02 <= slope <= -0.98, slope
    # and the smallest kept σ of the projected Jacobian is reported as sin σ
    detail = formulations.solve(near_singular(1e-4), "nullspace").detail
    assert detail.min_singular_values[1] == pytest.approx(np.sin(1e-4), rel=1e-6)


@pytest.mark.parametrize("lam", [1e-2, 1e-4])
def test_damped_is_bounded_near_singularity(lam):
    # Ĵ^# = Ĵᵀ(ĴĴᵀ + λI)⁻¹ gives x_2 = s/(s² + λ) ≤ 1/(2√λ); the free row adds < 1
    bound = 1.0 / (2 * np.sqrt(lam)) + 1.0
    for s in np.concatenate([SIGMAS, [1e-12, 0.0]]):
        sol = formulations.solve(near_singular(s), "nullspace", damping=lam)
        assert sol.status == "approximate"
        assert np.linalg.norm(sol.x) <= bound
        assert sol.residuals[0] <= 1e-14          # the higher level stays exact


def test_damped_tends_to_reference_as_lambda_vanishes():
    rng = np.random.default_rng(5)
    stack = FAMILIES["conflicting"](rng, 15, 4)
    ref = formulations.solve(stack, "reference").x
    errs = [np.linalg.norm(formulations.solve(stack, "nullspace", damping=lam).x - ref)
            for lam in (1e-2, 1e-4, 1e-6, 1e-8)]
    assert all(b < a for a, b in zip(errs, errs[1:], strict=False))
    assert errs[-1] < 1e-5 * max(1.0, np.linalg.norm(ref))


def test_exactly_conflicting_limit_is_finite_and_equals_reference():
    """σ = 0: the lower row lies in the higher level's row space; it is dropped by the
    rank rule instead of blowing up, and the answer is the lexicographic optimum."""
    stack = near_singular(0.0)
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "nullspace")
    assert np.isfinite(sol.x).all() and np.linalg.norm(sol.x) < 1.0
    np.testing.assert_allclose(sol.x, ref, atol=1e-14)
    assert sol.diagnostics.ranks.tolist() == [2, 1]


def rotated_near_singular(sigma):
    """near_singular(σ) with its columns rotated by a fixed random orthogonal Q."""
    Q, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((6, 6)))
    return TaskStack([Task(level.names[0], level.A @ Q, level.b)
                      for level in near_singular(sigma).levels])


def test_reprojected_step_keeps_round_off_at_eps_over_sigma():
    """Rotated near-singular stack, σ = 1e-7, ‖θ̈‖ = 1e7: with the extra N_{i-1} both
    residuals stay ≤ 1e-8 (measured 9.6e-10, like reference's 4.7e-10); the textbook step
    leaks like ε/σ² (measured 1.9e-2)."""
    stack = rotated_near_singular(1e-7)
    default = formulations.solve(stack, "nullspace")
    textbook = formulations.solve(stack, "nullspace", reproject=False)
    assert default.residuals.max() <= 1e-8
    assert textbook.residuals.max() >= 1e-4
    ref = formulations.solve(stack, "reference").x
    for sol in (default, textbook):            # both are the optimum to ~ε/σ² relative
        assert np.linalg.norm(sol.x - ref) <= 1e-6 * np.linalg.norm(ref)


@pytest.mark.parametrize("family", ["compatible", "conflicting", "degenerate"])
@pytest.mark.parametrize("seed", range(5))
def test_textbook_step_equals_reference_away_from_singularities(family, seed):
    rng = np.random.default_rng(6000 + seed)
    stack = FAMILIES[family](rng, int(rng.integers(3, 40)), int(rng.integers(1, 7)))
    ref = formulations.solve(stack, "reference").x
    x = formulations.solve(stack, "nullspace", reproject=False).x
    assert np.linalg.norm(x - ref) <= 1e-8 * max(1.0, np.linalg.norm(ref))


def test_bad_options_and_inequalities_are_named():
    stack = near_singular(0.1)
    with pytest.raises(formulations.FormulationError, match="option 'damping' must be"):
        formulations.solve(stack, "nullspace", damping=-1.0)
    with pytest.raises(formulations.FormulationError, match="no option"):
        formulations.solve(stack, "nullspace", mass_matrix=np.eye(6))
    s = TaskStack([Task("eq", np.eye(3), np.ones(3)),
                   Task("limits", np.eye(3), lower=-np.ones(3), upper=np.ones(3))])
    with pytest.raises(UnsupportedTaskError, match="limits"):
        formulations.solve(s, "nullspace")


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=80, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 30), k=st.integers(1, 6),
       family=st.sampled_from(sorted(FAMILIES)), damping=st.sampled_from([0.0, 1e-3]))
def test_property_shape_finite_and_exact_on_any_family(seed, n, k, family, damping):
    """Any family (degenerate ones included): shape (n,), finite; undamped = reference
    (relative 1e-8) and lexicographic."""
    stack = FAMILIES[family](np.random.default_rng(seed), n, k)
    sol = formulations.solve(stack, "nullspace", damping=damping)
    assert sol.ok and sol.x.shape == (stack.n,) and np.isfinite(sol.x).all()
    if damping == 0.0:
        ref = formulations.solve(stack, "reference").x
        assert np.linalg.norm(sol.x - ref) <= 1e-8 * max(1.0, np.linalg.norm(ref))
        assert check_lexicographic(stack, sol.x, tol=1e-8).ok


@pytest.mark.parametrize("damping", [0.0, 1e-2])
@pytest.mark.parametrize("family", ["compatible", "conflicting", "rank_deficient", "degenerate"])
def test_solve_batch_matches_the_loop(family, damping):
    """Stacked SVDs with per-stack rank masks = a loop of solve, bit for bit (both run
    ``project_levels``), statuses included."""
    from prioik.hierarchy.families import same_shape_batch
    rng = np.random.default_rng(31)
    stacks = same_shape_batch(FAMILIES[family](rng, 12, 4), rng, 20, reduce=0.3)
    batch = formulations.solve_batch(stacks, "nullspace", damping=damping)
    assert batch.batched
    for x, status, s in zip(batch.X, batch.statuses, stacks, strict=False):
        one = formulations.solve(s, "nullspace", damping=damping)
        assert np.array_equal(x, one.x) and status == one.status


def test_solve_batch_equals_solve_on_the_fuzz_stack():
    """``prioik fuzz --n 10000 --seed 2026 --kind equality`` case 2083 (50 unknowns, 10
    levels, scales 7e-5 to 6e5): the batched recursion (its own einsum products and
    QR of every singular vector) and ``solve`` (truncated SVD, 2-D products) answered
    1.04e-6 apart, both ``optimal``; on this stack rounding moves the answer by ~1e-6.
    Both now run one level implementation."""
    from pathlib import Path

    from prioik.hierarchy import load_stack
    from prioik.hierarchy.families import same_shape_batch
    stack = load_stack(Path(__file__).parent / "data" / "fuzz" / "equality-2026-2083.json")
    stacks = [stack] + same_shape_batch(stack, np.random.default_rng(2090), 2, reduce=0.3)
    batch = formulations.solve_batch(stacks, "nullspace")
    for x, status, s in zip(batch.X, batch.statuses, stacks, strict=False):
        one = formulations.solve(s, "nullspace")
        assert np.array_equal(x, one.x) and status == one.status
