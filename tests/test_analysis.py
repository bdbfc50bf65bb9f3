"""Stack analysis: rank profile (eq. 12), conflicts (eq. 35), singularity distance and
the lexicographic check, which must be able to fail."""

import numpy as np
import pytest

from prioik import formulations
from prioik.hierarchy import (
    Task,
    TaskStack,
    TaskStackError,
    check_lexicographic,
    conflicting_levels,
    lexicographic_residuals,
    nested_null_spaces,
    rank_profile,
    singularity_distance,
)
from prioik.hierarchy.families import FAMILIES, near_singular


def _stack_with_shared_row():
    e = np.eye(4)
    return TaskStack([Task("a", e[[0, 1]], [1.0, 2.0]),
                      Task("b", np.vstack([e[0] + e[1], e[2]]), [0.0, 1.0]),
                      Task("c", e[[3]], [5.0])])


def test_rank_profile_and_conflicts():
    s = _stack_with_shared_row()
    assert rank_profile(s) == [2, 1, 1]
    assert conflicting_levels(s) == [False, True, False]
    Zs = nested_null_spaces(s)
    assert [Z.shape[1] for Z in Zs] == [4, 2, 1, 0]
    for Z in Zs:
        np.testing.assert_allclose(Z.T @ Z, np.eye(Z.shape[1]), atol=1e-12)


@pytest.mark.parametrize("sigma", [0.5, 1e-2, 1e-4, 1e-6])
def test_singularity_distance_is_the_projected_sigma(sigma):
    d = singularity_distance(near_singular(sigma))
    assert d[0] == pytest.approx(1.0)
    # A_2 Z_2 = [[sin σ, 0, 0], [0, r]] (r: the free row's norm): σ_min = sin σ
    assert d[1] == pytest.approx(np.sin(sigma), rel=1e-9)


def test_singularity_distance_zero_when_fully_conflicting():
    e = np.eye(3)
    s = TaskStack([Task("a", e[[0, 1, 2]], [0, 0, 0]), Task("b", e[[0]], [1.0])])
    assert singularity_distance(s) == [1.0, 0.0]


def test_lexicographic_residuals_measure_equality_and_inequality():
    e = np.eye(3)
    s = TaskStack([Task("a", e[[0]], [1.0], weight=4.0),
                   [Task("box", e[[1, 2]], lower=[0.0, -np.inf], upper=[1.0, 0.5])]])
    r = lexicographic_residuals(s, np.array([0.0, 2.0, 1.5]))
    np.testing.assert_allclose(r, [2.0 * 1.0, np.hypot(1.0, 1.0)])


@pytest.mark.parametrize("family", sorted(FAMILIES))
@pytest.mark.parametrize("seed", range(6))
def test_check_passes_reference_and_fails_on_perturbations(family, seed):
    rng = np.random.default_rng(seed)
    stack = FAMILIES[family](rng, int(rng.integers(4, 30)), int(rng.integers(2, 6)))
    x = formulations.solve(stack, "reference").x
    assert check_lexicographic(stack, x).ok
    Zs = nested_null_spaces(stack)
    # a move inside the null space of levels < i that changes level i breaks level i
    for i, level in enumerate(stack.levels):
        Z = Zs[i]
        if Z.shape[1] == 0:
            continue
        direction = Z @ (Z.T @ level.A.T @ rng.standard_normal(level.A.shape[0]))
        if np.linalg.norm(level.A @ direction) < 1e-6:
            continue
        direction *= 1e-3 * max(1.0, np.linalg.norm(x)) / np.linalg.norm(direction)
        report = check_lexicographic(stack, x + direction)
        assert not report.ok
        assert report.first_failure.level == i, str(report)
        break
    else:  # pragma: no cover - every family leaves room for at least one move
        pytest.fail("no perturbation found")


def test_check_accepts_any_point_of_the_optimal_set_and_reports_levels():
    s = _stack_with_shared_row()
    x = formulations.solve(s, "reference").x
    assert check_lexicographic(s, x).ok
    report = check_lexicographic(s, x + np.array([0.0, 0.0, 0.0, 1e-3]))
    assert not report.ok and report.first_failure.tasks == ("c",)
    assert "FAIL" in str(report)


@pytest.mark.parametrize("x", [np.zeros(2), np.zeros((1, 4)), np.zeros(5), [[1.0], [2.0]],
                               "abc", [1.0, "a", 2.0, 3.0]])
def test_check_refuses_a_wrong_shape_x_with_a_task_stack_error(x):
    stack = TaskStack([Task("a", np.eye(4), np.ones(4))])
    with pytest.raises(TaskStackError, match="x "):      # was numpy's plain ValueError
        check_lexicographic(stack, x)
