"""The reference: independent checks of minimum norm, optimality and the metric."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from prioik import formulations
from prioik.hierarchy import Task, TaskStack, check_lexicographic, nested_null_spaces
from prioik.hierarchy.families import FAMILIES, compatible, near_singular

#: rounding edges: `make test-forced-cpu` (and CI) runs this module again with OpenBLAS on
#: another core type
pytestmark = pytest.mark.rounding_edge


@pytest.mark.parametrize("seed", range(10))
def test_compatible_equals_min_norm_of_stacked_system(seed):
    rng = np.random.default_rng(seed)
    s = compatible(rng, 20, 4)
    A = np.vstack([lv.A for lv in s])
    b = np.concatenate([lv.b for lv in s])
    expected = np.linalg.lstsq(A, b, rcond=None)[0]   # min-norm exact solution
    np.testing.assert_allclose(formulations.solve(s, "reference").x, expected,
                               rtol=0, atol=1e-10 * np.linalg.norm(expected))


@pytest.mark.parametrize("family", sorted(FAMILIES))
@pytest.mark.parametrize("seed", range(5))
def test_solution_is_lexicographic_and_orthogonal_to_remaining_null_space(family, seed):
    rng = np.random.default_rng(seed)
    s = FAMILIES[family](rng, 15, 3)
    x = formulations.solve(s, "reference").x
    assert check_lexicographic(s, x, tol=1e-10).ok
    Z = nested_null_spaces(s)[-1]
    assert np.linalg.norm(Z.T @ x) <= 1e-10 * max(1.0, np.linalg.norm(x))


def test_strict_priority_matches_the_limit_of_heavy_weights():
    """Two conflicting levels: the lexicographic optimum is the limit of a weighted
    least-squares problem as the weight ratio grows (an independent route)."""
    rng = np.random.default_rng(3)
    A1, b1 = rng.standard_normal((3, 5)), rng.standard_normal(3)
    A2 = np.vstack([A1[0] + A1[1], rng.standard_normal((2, 5))])
    b2 = rng.standard_normal(3)
    x = formulations.solve(TaskStack([Task("a", A1, b1), Task("b", A2, b2)]), "reference").x
    w = 1e6
    A = np.vstack([w * A1, A2, 1e-7 * np.eye(5)])
    y = np.linalg.lstsq(A, np.concatenate([w * b1, b2, np.zeros(5)]), rcond=None)[0]
    np.testing.assert_allclose(x, y, atol=1e-5)


def test_metric_minimises_weighted_norm_on_the_optimal_set():
    rng = np.random.default_rng(4)
    s = compatible(rng, 8, 2)
    L = rng.standard_normal((8, 8))
    W = L @ L.T + 8 * np.eye(8)
    x = formulations.solve(s, "reference", metric=W).x
    assert check_lexicographic(s, x).ok
    # closed form: argmin xᵀWx s.t. A x = b  ->  x = W⁻¹Aᵀ(AW⁻¹Aᵀ)⁻¹b
    A = np.vstack([lv.A for lv in s])
    b = np.concatenate([lv.b for lv in s])
    Wi = np.linalg.inv(W)
    np.testing.assert_allclose(x, Wi @ A.T @ np.linalg.solve(A @ Wi @ A.T, b), rtol=1e-9)


def test_metric_that_is_not_positive_semidefinite_is_refused():
    s = TaskStack([Task("a", np.eye(3)[[0]], [1.0])])
    with pytest.raises(formulations.FormulationError,
                       match="option 'metric': must be symmetric positive semidefinite"):
        formulations.solve(s, "reference", metric=-np.eye(3))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 12), k=st.integers(1, 4))
def test_first_level_is_solved_alone_in_least_squares(seed, n, k):
    rng = np.random.default_rng(seed)
    s = FAMILIES["rank_deficient"](rng, n, k)
    x = formulations.solve(s, "reference").x
    A1, b1 = s[0].A, s[0].b
    best = np.linalg.norm(A1 @ np.linalg.lstsq(A1, b1, rcond=None)[0] - b1)
    assert np.linalg.norm(A1 @ x - b1) <= best + 1e-9 * max(1.0, np.linalg.norm(b1))


def test_level_damping_is_damped_least_squares_per_level():
    """Two levels, the second damped: y = (MᵀM + μ²I)⁻¹Mᵀc on the free directions."""
    stack = near_singular(1e-2)
    mu2 = 0.3
    sol = formulations.solve(stack, "reference", level_damping=[0.0, mu2])
    # level 1 fixes x0 = x1 = 0; level 2 over (x2, …, x5): damped least squares
    M = stack.levels[1].A[:, 2:]
    c = stack.levels[1].b
    y = np.linalg.solve(M.T @ M + mu2 * np.eye(M.shape[1]), M.T @ c)
    np.testing.assert_allclose(sol.x, np.concatenate([[0.0, 0.0], y]), atol=1e-12)
    assert sol.status == "approximate"
    with pytest.raises(formulations.FormulationError, match="option 'level_damping'"):
        formulations.solve(stack, "reference", level_damping=[0.1, -1.0])


def test_near_singular_growth_is_the_target_component_over_sigma():
    """The exact optimum near an algorithmic singularity grows like
    ``|u_minᵀ(h_2 − J_2 θ̈_1)| / σ``, not like 1/σ whatever the target: with the
    near-conflicting row's target shrinking like sin σ (a consistent target) it stays
    bounded, with a fixed target it is 1/sin σ."""
    from prioik.hierarchy.families import near_singular
    for sigma in (1e-2, 1e-4, 1e-6):
        stack = near_singular(sigma)
        fixed = np.linalg.norm(formulations.solve(stack, "reference").x)
        A2 = stack.levels[1].A
        consistent = TaskStack([stack.levels[0][0],
                                Task("low", A2, np.array([np.sin(sigma), 0.5]))])
        x = formulations.solve(consistent, "reference").x
        assert fixed >= 0.9 / np.sin(sigma)
        assert abs(x[2] - 1.0) <= 1e-6 and np.linalg.norm(x) <= 2.0
