"""cvxpy: the cascade modelled in cvxpy against reference and cascaded_qp."""

import numpy as np
import pytest
from conftest import assert_truthful

from prioik import formulations
from prioik.formulations import FormulationError, cvxpy_
from prioik.hierarchy import check_lexicographic, relative_distance
from prioik.hierarchy.families import FAMILIES, infeasible_inequality, with_inequalities

#: relative distance to reference per cvxpy solver (Clarabel measured ≤ 1e-10)
TOL = {"CLARABEL": 1e-8, "OSQP": 1e-5, "SCS": 1e-5}



@pytest.mark.parametrize("fixing", ["basis", "rows"])
@pytest.mark.parametrize("family", ["compatible", "conflicting", "rank_deficient"])
def test_equality_stacks_agree_with_reference(fixing, family):
    for seed in range(2):
        rng = np.random.default_rng(40 + seed)
        stack = FAMILIES[family](rng, int(rng.integers(4, 12)), int(rng.integers(2, 5)))
        ref = formulations.solve(stack, "reference").x
        sol = formulations.solve(stack, "cvxpy", fixing=fixing)
        assert sol.status == "optimal", sol.diagnostics.reason
        assert relative_distance(sol.x, ref) <= TOL["CLARABEL"]
        assert check_lexicographic(stack, sol.x, tol=1e-7).ok


@pytest.mark.parametrize("solver", [s for s in ("OSQP", "SCS") if s in cvxpy_.backends()])
def test_other_cvxpy_solvers_on_a_compatible_stack(solver):
    stack = FAMILIES["compatible"](np.random.default_rng(3), 8, 3)
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "cvxpy", solver=solver)
    assert sol.ok, sol.diagnostics.reason
    assert relative_distance(sol.x, ref) <= TOL[solver]


def test_inequality_stacks_agree_with_cascaded_qp():
    for seed in range(3):
        rng = np.random.default_rng(60 + seed)
        stack = with_inequalities(rng, int(rng.integers(5, 12)), int(rng.integers(3, 5)))
        a = formulations.solve(stack, "cvxpy")
        b = formulations.solve(stack, "cascaded_qp")
        assert_truthful(a, stack)
        assert_truthful(b, stack)
        assert relative_distance(a.x, b.x) <= 1e-7
        np.testing.assert_allclose(a.residuals, b.residuals, rtol=1e-6, atol=1e-8)


def test_infeasible_hard_level_least_violation_and_fail_option():
    stack = infeasible_inequality(np.random.default_rng(8), 6, 3)
    sol = formulations.solve(stack, "cvxpy")
    assert sol.status == "optimal"
    assert abs(stack.task("keepout").A[0] @ sol.x) <= 1e-6
    assert sol.detail.violated[0]["tasks"] == ["keepout"]
    bad = formulations.solve(stack, "cvxpy", on_infeasible="fail")
    assert bad.status == "failed" and bad.diagnostics.fault.level == 0
    assert bad.diagnostics.fault.tasks == ("keepout",)


def test_unavailable_solver_names_it_and_lists_available():
    stack = FAMILIES["compatible"](np.random.default_rng(0), 5, 2)
    with pytest.raises(FormulationError) as exc:
        formulations.solve(stack, "cvxpy", solver="NOPE")
    assert "NOPE" in str(exc.value)
    for s in cvxpy_.backends():
        assert s in str(exc.value)


def test_zero_row_with_unreachable_bounds_keeps_its_fixed_violation():
    from pathlib import Path

    from prioik.hierarchy import load_peer_json
    p = load_peer_json(Path(__file__).parent / "data" / "peer" / "daqp_jl_degenerate1.json")
    sol = formulations.solve(p.stack, "cvxpy")
    assert sol.status == "optimal", sol.diagnostics.reason
    np.testing.assert_allclose(sol.x, [3.0, 1.5, 0.0], atol=1e-7)
    np.testing.assert_allclose(sol.residuals ** 2, [0.0, 2.25, 20.0], atol=1e-6)
