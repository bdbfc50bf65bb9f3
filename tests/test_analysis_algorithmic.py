"""The feasible/conflicting split (eq. 19-21) and the algorithmic error (eq. 29) of
``hierarchy.analysis``, used to score every formulation the same way."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from prioik import formulations
from prioik.hierarchy import (
    Task,
    TaskStack,
    UnsupportedTaskError,
    algorithmic_error,
    algorithmic_error_norms,
    feasible_split,
    matrix_rank,
    rank_profile,
)
from prioik.hierarchy.families import FAMILIES, compatible, near_singular

EQUALITY_FAMILIES = sorted(FAMILIES)


def draw(family, seed, n_max=30):
    rng = np.random.default_rng(seed)
    return FAMILIES[family](rng, int(rng.integers(2, n_max)), int(rng.integers(1, 6))), rng


@pytest.mark.parametrize("family", [f for f in EQUALITY_FAMILIES if f != "degenerate"])
@pytest.mark.parametrize("seed", range(6))
def test_split_matches_eq_19_20_and_rank_profile(family, seed):
    """(``degenerate`` is left out: its levels differ in scale by 1e10, so one rank
    threshold for the augmented matrix J_i^A cannot match the per-level rule.)"""
    stack, _ = draw(family, 7000 + seed)
    above = np.zeros((0, stack.n))
    for sp, level, r in zip(feasible_split(stack), stack.levels, rank_profile(stack), strict=False):
        A = level.A
        m = A.shape[0]
        assert sp.feasible.shape == (m, r) and sp.conflicting.shape == (m, m - r)
        U = np.hstack([sp.feasible, sp.conflicting])
        np.testing.assert_allclose(U.T @ U, np.eye(m), atol=1e-12)
        np.testing.assert_allclose(sp.J_feasible, sp.feasible.T @ A, atol=1e-12)
        np.testing.assert_allclose(sp.h_feasible, sp.feasible.T @ level.b, atol=1e-12)
        scale = max(np.linalg.norm(above), np.linalg.norm(A))

        def rank(X, scale=scale):
            return matrix_rank(X, 1e-9 * scale / max(np.linalg.norm(X), 1e-300))

        base = rank(above) if above.size else 0
        # eq. 19: the feasible rows add as much rank as the whole level ...
        assert rank(np.vstack([above, sp.J_feasible])) == rank(np.vstack([above, A]))
        assert rank(np.vstack([above, A])) == base + r
        # eq. 20: ... and the conflicting rows add none
        if m > r:
            assert rank(np.vstack([above, sp.conflicting.T @ A])) == base
        above = np.vstack([above, A])


def test_exactly_conflicting_row_is_split_off():
    """near_singular(0): level 2's first row e_0ᵀ lies in level 1's row space."""
    sp = feasible_split(near_singular(0.0))[1]
    assert sp.feasible.shape == (2, 1) and sp.conflicting.shape == (2, 1)
    conflict_row = (sp.conflicting.T @ near_singular(0.0)[1].A).ravel()
    np.testing.assert_allclose(np.abs(conflict_row), np.eye(6)[0], atol=1e-14)


@pytest.mark.parametrize("seed", range(5))
def test_compatible_levels_are_entirely_feasible(seed):
    """If the i-th task is compatible, J_i_feasible = J_i (eq. 21, up to a rotation)."""
    rng = np.random.default_rng(seed)
    stack = compatible(rng, 20, 4)
    for sp, level in zip(feasible_split(stack), stack.levels, strict=False):
        assert sp.conflicting.shape[1] == 0
        np.testing.assert_allclose(sp.feasible @ sp.J_feasible, level.A, atol=1e-12)


@pytest.mark.parametrize("formulation,options", [
    ("reference", {}), ("nullspace", {}), ("extended_jacobian", {}),
    ("extended_jacobian", {"nullspace": "svd"})])
@pytest.mark.parametrize("family", EQUALITY_FAMILIES)
@pytest.mark.parametrize("seed", range(5))
def test_zero_for_exact_solutions_at_every_level(formulation, options, family, seed):
    stack, _ = draw(family, 8000 + seed)
    x = formulations.solve(stack, formulation, **options).x
    for e, level in zip(algorithmic_error(stack, x), stack.levels, strict=False):
        scale = np.linalg.norm(level.A) * np.linalg.norm(x) + np.linalg.norm(level.b)
        assert np.linalg.norm(e) <= 1e-9 * max(scale, 1e-300)


@pytest.mark.parametrize("family", ["compatible", "conflicting", "coupled"])
@pytest.mark.parametrize("seed", range(5))
def test_perturbation_shows_up_linearly(family, seed):
    """e_i(x* + δv) = −δ U_fᵀ A_i v: non-zero wherever the level has feasible rows."""
    stack, rng = draw(family, 9000 + seed)
    x = formulations.solve(stack, "reference").x
    v = rng.standard_normal(stack.n)
    delta = 1e-3
    errors = algorithmic_error(stack, x + delta * v)
    for e, sp in zip(errors, feasible_split(stack), strict=False):
        np.testing.assert_allclose(e, -delta * (sp.J_feasible @ v),
                                   atol=1e-9 * (1.0 + np.linalg.norm(sp.h_feasible)))
    assert errors[0].size and np.linalg.norm(errors[0]) > 1e-6   # level 1 always has rows


def test_non_zero_for_chiaverini_on_conflicting_stacks():
    """Where some lower level keeps feasible directions, Chiaverini misses them."""
    checked = 0
    for seed in range(300, 320):
        stack, _ = draw("conflicting", seed)
        if sum(rank_profile(stack)[1:]) == 0:
            continue                  # level 1 takes every direction: nothing to miss
        x = formulations.solve(stack, "chiaverini").x
        err = algorithmic_error_norms(stack, x)
        assert err[0] <= 1e-10 * max(1.0, np.linalg.norm(stack[0].b))
        assert err[1:].max() > 1e-3, (seed, err)
        checked += 1
    assert checked >= 12


@pytest.mark.parametrize("family", ["compatible", "conflicting", "rank_deficient"])
@pytest.mark.parametrize("seed", range(5))
def test_invariant_to_rotating_a_levels_rows(family, seed):
    """Basis-free: replacing (A_i, b_i) by (Q A_i, Q b_i), Q orthogonal, changes no norm."""
    stack, rng = draw(family, 9500 + seed)
    rotated = []
    for level in stack.levels:
        Q, _ = np.linalg.qr(rng.standard_normal((level.m, level.m)))
        rotated.append(Task(level.names[0], Q @ level.A, Q @ level.b))
    rotated = TaskStack(rotated)
    for x in (formulations.solve(stack, "chiaverini").x, rng.standard_normal(stack.n)):
        np.testing.assert_allclose(algorithmic_error_norms(rotated, x),
                                   algorithmic_error_norms(stack, x),
                                   atol=1e-10 * (1.0 + np.linalg.norm(x)), rtol=1e-9)


def test_needs_equality_tasks():
    s = TaskStack([Task("eq", np.eye(3), np.ones(3)),
                   Task("limits", np.eye(3), lower=-np.ones(3), upper=np.ones(3))])
    with pytest.raises(UnsupportedTaskError, match="limits"):
        algorithmic_error(s, np.zeros(3))


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 30), k=st.integers(1, 6),
       family=st.sampled_from(EQUALITY_FAMILIES))
def test_property_error_is_a_projection_of_the_residual(seed, n, k, family):
    """‖e_i‖ ≤ ‖A_i x − b_i‖ for any x, and e_i = 0 at the reference solution."""
    rng = np.random.default_rng(seed)
    stack = FAMILIES[family](rng, n, k)
    x = rng.standard_normal(n)
    residual = np.array([np.linalg.norm(lv.A @ x - lv.b) for lv in stack.levels])
    err = algorithmic_error_norms(stack, x)
    assert err.shape == (len(stack),) and np.isfinite(err).all()
    assert (err <= residual * (1 + 1e-12) + 1e-300).all()
    ref = formulations.solve(stack, "reference").x
    scale = np.array([np.linalg.norm(lv.A) * np.linalg.norm(ref) + np.linalg.norm(lv.b)
                      for lv in stack.levels])
    assert (algorithmic_error_norms(stack, ref) <= 1e-9 * np.maximum(scale, 1e-300)).all()
