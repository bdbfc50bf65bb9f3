"""The extended-precision truth (hierarchy/exact.py) and the mixed-scale stacks it
judges: every level's optimal value, exact answers within the value tolerance, and the
paths that read a level's small rows to the precision of its large ones."""

from pathlib import Path

import numpy as np
import pytest

from prioik import formulations
from prioik.hierarchy import Task, TaskStack, check_lexicographic, load_stack, rank_threshold
from prioik.hierarchy.exact import VALUE_TOL, exact_optimum
from prioik.hierarchy.fuzz import equality_case, mixed_scale_case

pytest.importorskip("mpmath")

DATA = Path(__file__).parent / "data" / "fuzz"


def _hand_stack() -> TaskStack:
    """x₁ = 3 at 1e-11; a level of two tasks at 1e9 that disagree on x₂ (2 and 4, weights
    1 and 3: x₂ = 3.5, value 1e18 (1.5² + 3·0.5²) = 3e18); x₁ + x₂ = 0 (value 6.5²)."""
    return TaskStack([
        [Task("tiny", 1e-11 * np.array([[1.0, 0.0]]), 1e-11 * np.array([3.0]))],
        [Task("huge_a", 1e9 * np.array([[0.0, 1.0]]), 1e9 * np.array([2.0])),
         Task("huge_b", 1e9 * np.array([[0.0, 1.0]]), 1e9 * np.array([4.0]), weight=3.0)],
        [Task("sum", np.array([[1.0, 1.0]]), np.array([0.0]))],
    ])


def test_the_truth_of_a_hand_solvable_mixed_scale_stack():
    e = exact_optimum(_hand_stack())
    assert e.ranks == [1, 1, 0] and not e.ambiguous
    np.testing.assert_allclose(e.x, [3.0, 3.5], rtol=1e-15)
    np.testing.assert_allclose(e.values, [0.0, 3e18, 6.5 ** 2], rtol=1e-14, atol=1e-40)
    assert e.x_norm == pytest.approx(np.hypot(3.0, 3.5), rel=1e-15)


def test_excess_flags_a_level_value_beyond_the_tolerance_and_not_the_optimum():
    e = exact_optimum(_hand_stack())
    assert np.all(e.excess(e.x) <= 1.0)
    # x₂ moved by 1e-3 from its optimum: level 1's value rises by (1 + 3)·(1e9·1e-3)²,
    # 4e12 on 3e18 (relative 1.3e-6); by 1e-6: 4e6, within the tolerance
    off = e.x + np.array([0.0, 1e-3])
    assert e.relative_excess(off)[1] == pytest.approx(4e12 / 3e18, rel=1e-6)
    assert e.excess(off)[1] > 1.0
    assert e.excess(e.x + np.array([0.0, 1e-6]))[1] <= 1.0


def test_a_singular_value_at_the_threshold_marks_the_truth_ambiguous():
    # the second row 1e-9 (the threshold rcond·‖A‖_F ≈ 1e-9) off the first: σ₂ ≈ 7e-10
    A = np.array([[1.0, 0.0], [1.0, 1e-9]])
    stack = TaskStack([Task("t", A, np.array([1.0, 2.0]))])
    e = exact_optimum(stack)
    assert e.ambiguous_levels == [0]
    assert rank_threshold(A) == pytest.approx(np.sqrt(2) * 1e-9, rel=1e-6)


def test_the_truth_refuses_large_stacks():
    big = TaskStack([[Task("t", np.ones((1, 41)), np.ones(1))]])
    assert exact_optimum(big) is None
    assert exact_optimum(big, max_n=41) is not None


@pytest.mark.parametrize("seed", range(6))
def test_the_truth_agrees_with_reference_on_well_conditioned_stacks(seed):
    rng = np.random.default_rng([31, seed])
    case = equality_case(rng, max_n=12, max_levels=5, max_rows=8)
    if not case.well_conditioned:
        pytest.skip("not well-conditioned")
    e = exact_optimum(case.stack)
    sol = formulations.solve(case.stack, "reference")
    assert np.all(e.excess(sol.x, case.rounding_error) <= 1.0)
    assert np.linalg.norm(sol.x - e.x) <= 1e-8 * max(1.0, e.x_norm)


def test_mixed_scale_stacks_span_the_scales():
    scales = []
    for i in range(40):
        case = mixed_scale_case(np.random.default_rng([5, i]), truth=False)
        assert case.kind == "mixed_scale"
        for level in case.stack.levels:
            peak = float(np.max(np.abs(level.A))) if level.A.size else 0.0
            if peak > 0:
                scales.append(peak)
    assert min(scales) < 1e-9 and max(scales) > 1e15


@pytest.mark.parametrize("path", ["reference", "nullspace", "sns", "extended_jacobian",
                                  "hierarchical_active_set"])
def test_a_level_of_zero_rows_with_huge_targets_leaves_lower_levels_at_their_optimum(path):
    """mixed_scale-7-570: level 1 holds zero rows with targets of 1e15 beside rows of 0.24;
    an SVD reads the small rows to ε of the level's norm, so without refinement their
    targets moved x by 2e-5 (relative) and lower levels' values by up to 4.7e-5."""
    stack = load_stack(DATA / "mixed_scale-7-570.json")
    e = exact_optimum(stack)
    sol = formulations.solve(stack, path)
    assert sol.status == "optimal"
    rel = e.relative_excess(sol.x)[1:]             # (level 0's optimum is 0)
    assert np.all(np.abs(rel) <= VALUE_TOL), rel


def test_the_certificate_rejects_a_step_its_small_rows_moved():
    """The nested SVD without the refinement on mixed_scale-7-570: the step of level 1,
    2e-5 off along its small rows' directions, passed the check when the rows' scale
    counted the targets of its zero rows (1e15) in full."""
    stack = load_stack(DATA / "mixed_scale-7-570.json")
    x = np.zeros(stack.n)
    Z = np.eye(stack.n)
    for level in stack.levels:
        if Z.shape[1] == 0:
            break
        M = level.A @ Z
        u, s, vt = np.linalg.svd(M, full_matrices=True)
        r = int(np.count_nonzero(s > rank_threshold(level.A)))
        x = x + Z @ (vt[:r].T @ ((u[:, :r].T @ (level.b - level.A @ x)) / s[:r]))
        Z = Z @ vt[r:].T
    e = exact_optimum(stack)
    assert np.max(np.abs(e.relative_excess(x)[1:])) > 1e-6     # the answer is off
    report = check_lexicographic(stack, x)
    assert not report.ok and report.fault_level == 1
    assert check_lexicographic(stack, e.x).ok


@pytest.mark.parametrize("seed, index", [(1000, 56), (1002, 92)])
@pytest.mark.parametrize("path, options", [
    ("extended_jacobian", {"kernel": "cpp"}), ("extended_jacobian", {"kernel": "lapack"}),
    ("hierarchical_active_set", {})])
def test_a_full_rank_level_of_zero_rows_with_targets_is_solved_to_rounding(
        seed, index, path, options):
    """Fuzz equality stacks at the suite's sizes whose first level holds zero rows with
    targets of 1e6 beside rows of 2e-7: the column-pivoted QR of a full-rank level reads
    them to ε of the level's norm, and without the refinement by the corrected
    semi-normal equations x came out 8.3e-4 (56) and 2.1e-6 (92) from the optimum."""
    from prioik.benchmarks import fuzz
    stack = fuzz.draw("equality", seed, index,
                      {"max_n": 12, "max_levels": 5, "max_rows": 8}).stack
    e = exact_optimum(stack)
    sol = formulations.solve(stack, path, **options)
    assert sol.status == "optimal"
    assert np.linalg.norm(sol.x - e.x) <= 1e-13 * max(1.0, e.x_norm)
    assert check_lexicographic(stack, sol.x).ok


def test_the_svd_path_meets_a_level_met_exactly_to_rounding():
    """mixed_scale seed 7 case 618: level 0 (rows of 1.5e-3, met exactly, v* = 0); the svd
    path's answer, ε κ(J_E) off, left it 20-80 times what float64 can tell apart
    before its refinement step."""
    case = mixed_scale_case(np.random.default_rng([7, 618]))
    e = exact_optimum(case.stack)
    sol = formulations.solve(case.stack, "extended_jacobian", nullspace="svd")
    assert sol.status == "optimal"
    assert np.all(e.excess(sol.x) <= 1.0)
    assert np.linalg.norm(sol.x - e.x) <= 1e-13 * max(1.0, e.x_norm)
