"""operational_space: prioritized operational-space control (Khatib, Sentis)."""

import numpy as np
import pytest

from prioik import formulations
from prioik.formulations.operational_space import task_space_torque
from prioik.hierarchy import Task, TaskStack, UnsupportedTaskError, check_lexicographic
from prioik.hierarchy.families import FAMILIES, compatible, near_singular, random_spd


@pytest.mark.parametrize("seed", range(15))
def test_compatible_meets_every_task_and_equals_reference_with_metric_m(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 40))
    stack = compatible(rng, n, int(rng.integers(1, 6)))
    M = random_spd(rng, n)
    sol = formulations.solve(stack, "operational_space", mass_matrix=M)
    assert sol.status == "optimal"
    for level, r in zip(stack.levels, sol.residuals, strict=False):
        assert r <= 1e-9 * max(1.0, np.linalg.norm(level.b))
    ref = formulations.solve(stack, "reference", metric=M).x
    assert np.linalg.norm(sol.x - ref) <= 1e-9 * max(1.0, np.linalg.norm(ref))


@pytest.mark.parametrize("family", ["conflicting", "rank_deficient", "weighted", "coupled"])
@pytest.mark.parametrize("seed", range(8))
def test_conflicting_is_lexicographic_and_equals_reference_with_metric_m(family, seed):
    rng = np.random.default_rng(4000 + seed)
    n = int(rng.integers(3, 40))
    stack = FAMILIES[family](rng, n, int(rng.integers(2, 7)))
    M = random_spd(rng, n)
    sol = formulations.solve(stack, "operational_space", mass_matrix=M)
    report = check_lexicographic(stack, sol.x, tol=1e-8)
    assert report.ok, str(report)
    ref = formulations.solve(stack, "reference", metric=M).x
    assert np.linalg.norm(sol.x - ref) <= 1e-8 * max(1.0, np.linalg.norm(ref))


def test_identity_metric_equals_nullspace():
    rng = np.random.default_rng(11)
    stack = FAMILIES["conflicting"](rng, 20, 5)
    a = formulations.solve(stack, "operational_space", mass_matrix=np.eye(20)).x
    b = formulations.solve(stack, "nullspace").x
    np.testing.assert_allclose(a, b, atol=1e-10 * max(1.0, np.linalg.norm(b)))


@pytest.mark.parametrize("family", ["compatible", "conflicting"])
@pytest.mark.parametrize("seed", range(5))
def test_torque_forms_agree_and_projectors_are_dynamically_consistent(family, seed):
    rng = np.random.default_rng(500 + seed)
    n = int(rng.integers(4, 25))
    stack = FAMILIES[family](rng, n, int(rng.integers(2, 5)))
    M = random_spd(rng, n)
    bias = 3.0 * rng.standard_normal(n)
    # the per-level quantities are the readable kernel's
    sol = formulations.solve(stack, "operational_space", mass_matrix=M, bias=bias,
                             kernel="numpy")
    tau = sol.detail.tau
    levels, N = sol.detail.levels, sol.detail.null_projector
    scale = max(1.0, np.linalg.norm(tau))
    # τ = Σ J_{i|prev}ᵀ F_i + C + G  (task forces F_i = Λ_{i|prev}(h_i − J_i θ̈_{i-1}))
    forces = sum(lv.J_projected.T @ lv.force for lv in levels) + bias
    assert np.linalg.norm(forces - tau) <= 1e-9 * scale
    # the Λ ẍ* + μ + p form with the bias split over the levels and N_kᵀ
    assert np.linalg.norm(task_space_torque(levels, N, bias) - tau) <= 1e-9 * scale
    # dynamic consistency: M N_k is symmetric, and J̄ = M⁻¹ J_{i|prev}ᵀ Λ_{i|prev}
    MN = M @ N
    assert np.abs(MN - MN.T).max() <= 1e-9 * np.abs(M).max()
    for lv in levels:
        np.testing.assert_allclose(M @ lv.J_bar, lv.J_projected.T @ lv.Lambda,
                                   atol=1e-9 * max(1.0, np.abs(lv.J_projected).max()))
    # a torque in range(N_kᵀ) accelerates no task: J_i M⁻¹ N_kᵀ = 0
    for level in stack.levels:
        JMN = level.A @ np.linalg.solve(M, N.T)
        assert np.abs(JMN).max() <= 1e-9 * np.linalg.norm(level.A) * max(1.0, np.abs(N).max())


def test_grows_like_one_over_sigma_like_every_exact_method():
    """Exact with metric M, so near the algorithmic singularity it follows the exact
    optimum: slope of log‖θ̈‖ against log σ is −1 (σ = 1e-1 … 1e-7)."""
    M = random_spd(np.random.default_rng(2), 6)
    sigmas = np.logspace(-1, -7, 7)
    norms = [np.linalg.norm(formulations.solve(near_singular(s), "operational_space",
                                               mass_matrix=M).x) for s in sigmas]
    slope = np.polyfit(np.log(sigmas), np.log(norms), 1)[0]
    assert -1.02 <= slope <= -0.98
    sol = formulations.solve(near_singular(0.0), "operational_space", mass_matrix=M)
    ref = formulations.solve(near_singular(0.0), "reference", metric=M).x
    np.testing.assert_allclose(sol.x, ref, atol=1e-12)


def test_reprojected_step_keeps_round_off_at_eps_over_sigma():
    """Rotated near-singular stack, σ = 1e-7 (‖θ̈‖ ≈ 1e7), M and Q seeded: with the extra
    N_{i-1} both residuals stay ≤ 1e-8 (measured 9.9e-10); the textbook step leaks like
    ε/σ² (measured 1.8e-2)."""
    Q, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((6, 6)))
    stack = TaskStack([Task(level.names[0], level.A @ Q, level.b)
                       for level in near_singular(1e-7).levels])
    M = random_spd(np.random.default_rng(0), 6)
    default = formulations.solve(stack, "operational_space", mass_matrix=M)
    textbook = formulations.solve(stack, "operational_space", mass_matrix=M, reproject=False)
    assert default.residuals.max() <= 1e-8
    assert textbook.residuals.max() >= 1e-4
    ref = formulations.solve(stack, "reference", metric=M).x
    for sol in (default, textbook):
        assert np.linalg.norm(sol.x - ref) <= 1e-6 * np.linalg.norm(ref)


def test_needs_an_spd_mass_matrix():
    stack = near_singular(0.1)
    with pytest.raises(formulations.FormulationError, match="needs mass_matrix"):
        formulations.solve(stack, "operational_space")
    with pytest.raises(formulations.FormulationError, match="positive definite"):
        formulations.solve(stack, "operational_space", mass_matrix=np.diag([1, 1, 1, 1, 1, 0.0]))
    with pytest.raises(formulations.FormulationError, match="symmetric"):
        formulations.solve(stack, "operational_space", mass_matrix=np.triu(np.ones((6, 6))))
    s = TaskStack([Task("eq", np.eye(3), np.ones(3)),
                   Task("limits", np.eye(3), lower=-np.ones(3), upper=np.ones(3))])
    with pytest.raises(UnsupportedTaskError, match="limits"):
        formulations.solve(s, "operational_space", mass_matrix=np.eye(3))


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 30), k=st.integers(1, 6),
       family=st.sampled_from(sorted(FAMILIES)), cond=st.sampled_from([1.0, 10.0, 1e3]))
def test_property_shape_finite_and_lexicographic_on_any_family(seed, n, k, family, cond):
    """Any family, M with condition 1 … 1e3: shape (n,), finite, lexicographic (1e-8)."""
    rng = np.random.default_rng(seed)
    stack = FAMILIES[family](rng, n, k)
    M = random_spd(rng, n, cond)
    sol = formulations.solve(stack, "operational_space", mass_matrix=M,
                             bias=rng.standard_normal(n))
    assert sol.ok and sol.x.shape == (stack.n,) and np.isfinite(sol.x).all()
    assert sol.detail.tau.shape == (stack.n,)
    report = check_lexicographic(stack, sol.x, tol=1e-8)
    assert report.ok, str(report)
