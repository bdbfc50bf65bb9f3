"""daqp_hierarchical: exact where DAQP's free-direction count is right, flagged otherwise."""

import numpy as np
import pytest
from conftest import assert_truthful

from prioik import formulations
from prioik.formulations import FormulationError
from prioik.hierarchy import (
    Task,
    TaskStack,
    check_lexicographic,
    conflicting_levels,
    relative_distance,
)
from prioik.hierarchy.families import FAMILIES


@pytest.mark.parametrize("family", ["compatible", "rank_deficient"])
@pytest.mark.parametrize("seed", range(4))
def test_exact_on_non_conflicting_stacks(family, seed):
    rng = np.random.default_rng(20 + seed)
    stack = FAMILIES[family](rng, int(rng.integers(4, 16)), int(rng.integers(2, 5)))
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "daqp_hierarchical")
    assert_truthful(sol, stack)
    if not any(conflicting_levels(stack)):
        assert sol.status == "optimal", sol.diagnostics
    if sol.status == "optimal":
        assert relative_distance(sol.x, ref) <= 1e-8      # measured ≤ 1.3e-10 with primal_tol 1e-10


def test_rank_deficient_level_needs_compression():
    stack = FAMILIES["rank_deficient"](np.random.default_rng(21), 10, 3)
    raw = formulations.solve(stack, "daqp_hierarchical", compress_levels=False)
    assert raw.status == "failed" and raw.detail.exitflag == -6
    assert "overdetermined" in raw.diagnostics.reason


def test_conflicting_stacks_are_flagged_approximate():
    flagged = 0
    for seed in range(6):
        rng = np.random.default_rng(30 + seed)
        stack = FAMILIES["conflicting"](rng, int(rng.integers(5, 14)), 3)
        ref = formulations.solve(stack, "reference").x
        sol = formulations.solve(stack, "daqp_hierarchical")
        assert_truthful(sol, stack)
        if sol.status == "optimal":
            assert relative_distance(sol.x, ref) <= 1e-8
        else:
            assert sol.detail.conflicting_levels and "certificate" in sol.diagnostics.reason
            assert relative_distance(sol.x, ref) > 1e-3          # and it is indeed off
            flagged += 1
    assert flagged >= 1


def test_default_primal_tol_is_the_accurate_setting():
    tight, loose = [], []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        stack = FAMILIES["compatible"](rng, int(rng.integers(4, 16)), 3)
        ref = formulations.solve(stack, "reference").x
        tight.append(relative_distance(formulations.solve(stack, "daqp_hierarchical").x, ref))
        loose_x = formulations.solve(stack, "daqp_hierarchical", primal_tol=1e-6).x
        loose.append(relative_distance(loose_x, ref))
    # DAQP's default 1e-6 leaves ~1e-7..1e-6; 1e-10 leaves ~1e-10
    assert max(tight) <= 1e-8 < max(loose)


def test_box_then_task():
    stack = TaskStack([Task("box", np.eye(2), lower=-np.ones(2), upper=np.ones(2)),
                       Task("goal", np.eye(2), [2.0, 0.5])])
    sol = formulations.solve(stack, "daqp_hierarchical")
    np.testing.assert_allclose(sol.x, [1.0, 0.5], atol=1e-8)
    # the goal's row x0 depends on the active box row x0 ≤ 1, where DAQP's count of free
    # directions is not to be trusted; here the answer is right, and the certificate says so
    # (the conflicting levels are computed only for an answer the certificate rejects)
    assert sol.status == "optimal" and sol.diagnostics.verification.ok
    assert sol.detail.conflicting_levels is None
    lone = formulations.solve(TaskStack([Task("goal", np.eye(2), [2.0, 0.5])]),
                              "daqp_hierarchical")
    assert lone.status == "optimal"


def test_bad_settings():
    stack = FAMILIES["compatible"](np.random.default_rng(0), 5, 2)
    with pytest.raises(FormulationError):
        formulations.solve(stack, "daqp_hierarchical", primal_tol=0.0)
    with pytest.raises(FormulationError):
        formulations.solve(stack, "daqp_hierarchical", settings=[1])


def test_optimal_status_is_truthful_on_badly_scaled_stacks():
    # tasks scaled by 1e-6 and 1e4 (‖x‖ up to 1e6): "optimal" answers are checked
    checked = 0
    for seed in range(12):
        rng = np.random.default_rng(777 + seed)
        stack = FAMILIES["degenerate"](rng, int(rng.integers(3, 20)), int(rng.integers(2, 6)))
        sol = formulations.solve(stack, "daqp_hierarchical")
        if sol.status == "optimal":
            ref = formulations.solve(stack, "reference").x
            assert relative_distance(sol.x, ref) <= 1e-6
            checked += 1
    assert checked >= 4


def test_zero_row_with_unreachable_bounds_keeps_its_fixed_violation():
    from pathlib import Path

    from prioik.hierarchy import load_peer_json
    p = load_peer_json(Path(__file__).parent / "data" / "peer" / "daqp_jl_degenerate1.json")
    sol = formulations.solve(p.stack, "daqp_hierarchical")
    assert sol.status == "optimal", sol.diagnostics.reason
    np.testing.assert_allclose(sol.x, [3.0, 1.5, 0.0], atol=1e-7)
    np.testing.assert_allclose(sol.residuals ** 2, [0.0, 2.25, 20.0], atol=1e-6)


def test_wrong_answers_are_not_optimal_on_inequality_stacks():
    """DAQP's raw hierarchical answer is off on some random inequality stacks; with the
    certificate every one of them says "approximate" (without it: "optimal")."""
    from prioik.hierarchy.families import random_inequality_hierarchy
    wrong_raw = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        stack = random_inequality_hierarchy(rng, int(rng.integers(3, 12)), int(rng.integers(2, 5)))
        raw = formulations.solve(stack, "daqp_hierarchical", check=False)
        if raw.status != "optimal":
            continue
        wrong_raw += not check_lexicographic(stack, raw.x, minimum_norm=True).ok
        assert_truthful(formulations.solve(stack, "daqp_hierarchical"), stack)
    assert wrong_raw >= 1


def test_a_stack_of_zero_rows_only_gives_x_zero():
    """Every row zero (an all-zero inequality task): nothing for DAQP to solve (it
    crashed on numpy's empty vstack)."""
    from prioik.hierarchy import Task, TaskStack
    stack = TaskStack([[Task("z", np.zeros((2, 3)), lower=[-1.0, 1.0], upper=[1.0, 2.0])]])
    sol = formulations.solve(stack, "daqp_hierarchical")
    assert sol.status != "failed"
    np.testing.assert_array_equal(sol.x, np.zeros(3))
