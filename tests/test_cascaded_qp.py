"""cascaded_qp: every available qpsolvers back-end against reference and cvxpy.

Tolerances are relative distances ``‖x − x_ref‖ / max(1, ‖x_ref‖)``, per back-end,
each about 10-100× the largest distance measured on these families
(docs/qp-formulations.md): interior-point and active-set back-ends are tight;
DAQP carries the 1e-10 Hessian regularisation it needs; OSQP/SCS (ADMM) run with
their eps at 1e-9 (the default here); HiGHS is loose (its QP solver regularises).
"""

import numpy as np
import pytest
from conftest import assert_truthful
from hypothesis import given, settings
from hypothesis import strategies as st

from prioik import formulations
from prioik.formulations import FormulationError, cascaded_qp
from prioik.hierarchy import (
    Task,
    TaskStack,
    check_lexicographic,
    lexicographic_residuals,
    relative_distance,
)
from prioik.hierarchy.families import FAMILIES, infeasible_inequality, with_inequalities

BACKENDS = cascaded_qp.backends()

#: Tolerance for a back-end not listed in the tables below (e.g. one that the
#: registry's install hint, ``qpsolvers[open_source_solvers]``, adds): the loosest
#: measured first-order accuracy, 1e-4 relative.
DEFAULT_TOL = 1e-4
#: Bound violation allowed for a back-end not in BOUND_TOL.
DEFAULT_BOUND_TOL = 1e-7

#: back-end -> relative distance to reference allowed on equality stacks
EQUALITY_TOL = {"clarabel": 1e-8, "quadprog": 1e-6, "proxqp": 1e-6, "daqp": 1e-5,
                "osqp": 1e-6, "scs": 1e-6, "highs": 1e-3}
#: back-ends whose answers pass the certificate (DEFAULT_CERTIFICATE_TOL) on these
#: tests, so that they must say "optimal"; the others say what the certificate says
CERTIFIED = {"clarabel", "quadprog", "proxqp"}
#: back-end -> relative distance to cvxpy allowed on inequality stacks
INEQUALITY_TOL = {"clarabel": 1e-6, "quadprog": 1e-6, "proxqp": 1e-6, "daqp": 1e-6,
                  "osqp": 1e-6, "scs": 1e-6, "highs": 1e-2}
#: bound violation allowed (absolute, on unit-scale bounds)
BOUND_TOL = {"highs": 1e-6}
#: extra options per back-end on inequality stacks (none needed at the defaults)
INEQUALITY_OPTIONS: dict = {}


def tolerance(table: dict[str, float], backend: str) -> float:
    """The table's tolerance for ``backend``, :data:`DEFAULT_TOL` when it is not listed."""
    return table.get(backend, DEFAULT_TOL)


def test_tolerance_tables_have_a_default_for_unlisted_backends():
    assert tolerance(EQUALITY_TOL, "some_new_backend") == DEFAULT_TOL
    assert tolerance(EQUALITY_TOL, "clarabel") == 1e-8


@pytest.mark.skipif("osqp" not in BACKENDS, reason="OSQP not installed")
def test_osqp_prints_nothing_unless_verbose(capfd):
    stack = with_inequalities(np.random.default_rng(1), 6, 4)
    sol = formulations.solve(stack, "cascaded_qp", solver="osqp")
    assert sol.ok
    out = capfd.readouterr().out
    assert out == "", out          # OSQP printed "Polishing not needed ..." here



@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("family", ["compatible", "conflicting"])
@pytest.mark.parametrize("seed", range(3))
def test_equality_stacks_agree_with_reference(backend, family, seed):
    rng = np.random.default_rng(500 + seed)
    stack = FAMILIES[family](rng, int(rng.integers(4, 13)), int(rng.integers(2, 5)))
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "cascaded_qp", solver=backend)
    assert_truthful(sol, stack)
    if backend in CERTIFIED:
        assert sol.status == "optimal", sol.diagnostics.reason
    assert relative_distance(sol.x, ref) <= tolerance(EQUALITY_TOL, backend)
    assert sol.detail.backend == backend


@pytest.mark.parametrize("fixing", cascaded_qp.FIXINGS)
@pytest.mark.parametrize("family", ["rank_deficient", "conflicting", "weighted"])
def test_fixings_on_rank_deficient_and_conflicting_levels(fixing, family):
    # the literal rows A_h x = A_h x* are redundant here; Clarabel still takes them
    for seed in range(3):
        rng = np.random.default_rng(900 + seed)
        stack = FAMILIES[family](rng, int(rng.integers(4, 13)), int(rng.integers(2, 5)))
        ref = formulations.solve(stack, "reference").x
        sol = formulations.solve(stack, "cascaded_qp", fixing=fixing)
        assert sol.ok, sol.diagnostics.reason
        assert relative_distance(sol.x, ref) <= 1e-7
        assert check_lexicographic(stack, sol.x, tol=1e-7).ok


def test_metric_is_the_final_tie_break():
    rng = np.random.default_rng(3)
    stack = FAMILIES["compatible"](rng, 8, 2)
    B = rng.standard_normal((8, 8))
    W = B @ B.T + 8 * np.eye(8)
    ref = formulations.solve(stack, "reference", metric=W).x
    sol = formulations.solve(stack, "cascaded_qp", metric=W)
    assert relative_distance(sol.x, ref) <= 1e-8
    assert relative_distance(formulations.solve(stack, "cascaded_qp").x, ref) > 1e-3   # W matters


@pytest.fixture(scope="module")
def inequality_stacks():
    out = []
    for seed in range(3):
        rng = np.random.default_rng(700 + seed)
        stack = with_inequalities(rng, int(rng.integers(5, 13)), int(rng.integers(3, 5)))
        out.append((stack, formulations.solve(stack, "cvxpy")))
    return out


@pytest.mark.parametrize("backend", BACKENDS)
def test_inequality_stacks_agree_with_cvxpy_and_keep_bounds(backend, inequality_stacks):
    for stack, ref in inequality_stacks:
        assert ref.status == "optimal"
        sol = formulations.solve(stack, "cascaded_qp", solver=backend,
                                 **INEQUALITY_OPTIONS.get(backend, {}))
        assert_truthful(sol, stack)
        if backend in CERTIFIED:
            assert sol.status == "optimal", sol.diagnostics.reason
        assert relative_distance(sol.x, ref.x) <= tolerance(INEQUALITY_TOL, backend)
        # the box and the band (levels 1-2, feasible together) hold within tolerance
        tol = BOUND_TOL.get(backend, DEFAULT_BOUND_TOL)
        for level in stack.levels[:2]:
            for t in level:
                lo, up = t.bounds()
                Ax = t.A @ sol.x
                assert np.all(Ax >= lo - tol) and np.all(Ax <= up + tol), t.name
        # the higher levels keep their optimum: residuals equal cvxpy's, level by level
        res, ref_res = sol.residuals, ref.residuals
        assert np.all(np.abs(res - ref_res) <= tolerance(INEQUALITY_TOL, backend) * 10
                      * np.maximum(1.0, ref_res))


def test_inequality_level_above_equality_level_is_preserved():
    # level 1: x0 ≤ 0.5; level 2 wants x0 = 2 and x1 = 1
    stack = TaskStack([Task("limit", [[1.0, 0.0, 0.0]], upper=[0.5]),
                       Task("goal", np.eye(3)[:2], [2.0, 1.0])])
    for backend in BACKENDS:
        sol = formulations.solve(stack, "cascaded_qp", solver=backend)
        atol = tolerance(EQUALITY_TOL, backend) * 10
        assert np.allclose(sol.x, [0.5, 1.0, 0.0], atol=atol), backend


@pytest.mark.parametrize("backend", BACKENDS)
def test_infeasible_hard_level_gives_least_violation_with_diagnostics(backend):
    rng = np.random.default_rng(11)
    stack = infeasible_inequality(rng, 6, 3)
    sol = formulations.solve(stack, "cascaded_qp", solver=backend)
    assert_truthful(sol, stack)
    if backend in CERTIFIED:
        assert sol.status == "optimal", sol.diagnostics.reason
    c = stack.task("keepout").A[0]
    # least violation of c x ≥ 1, c x ≤ −1 (unit c, equal weights): c x = 0
    assert abs(c @ sol.x) <= 1e-5
    assert sol.residuals[0] == pytest.approx(np.sqrt(2.0), abs=1e-5)
    assert sol.diagnostics.infeasible_levels == [0]
    (entry,) = sol.detail.violated
    assert entry["level"] == 0 and entry["tasks"] == ["keepout"]


def test_infeasible_hard_level_fails_cleanly_when_asked():
    stack = infeasible_inequality(np.random.default_rng(12), 6, 3)
    sol = formulations.solve(stack, "cascaded_qp", on_infeasible="fail")
    assert sol.status == "failed" and not sol.ok
    assert sol.diagnostics.fault.level == 0
    assert sol.diagnostics.fault.tasks == ("keepout",)
    assert "keepout" in sol.diagnostics.reason
    assert np.isnan(sol.x).all()


def test_backend_failure_is_a_failed_status_naming_level_and_tasks():
    rng = np.random.default_rng(4)
    stack = FAMILIES["conflicting"](rng, 10, 3)
    # a one-iteration OSQP cannot converge: the cascade stops at the first level
    sol = formulations.solve(stack, "cascaded_qp", solver="osqp",
                             backend_options={"max_iter": 1, "polishing": False})
    assert sol.status == "failed"
    assert sol.diagnostics.fault.level == 0
    assert sol.diagnostics.fault.tasks == tuple(stack.levels[0].names)
    assert "osqp" in sol.diagnostics.reason and "level 0" in sol.diagnostics.reason


def test_unavailable_backend_names_it_and_lists_available():
    stack = FAMILIES["compatible"](np.random.default_rng(0), 5, 2)
    with pytest.raises(FormulationError) as exc:
        formulations.solve(stack, "cascaded_qp", solver="gurobi_not_here")
    msg = str(exc.value)
    assert "gurobi_not_here" in msg
    for be in BACKENDS:
        assert be in msg


@pytest.mark.parametrize("bad", [{"fixing": "lu"}, {"on_infeasible": "ignore"},
                                 {"tolerance": -1.0}, {"backend_options": [1]},
                                 {"regularization": -1.0}])
def test_bad_options_are_formulation_errors(bad):
    stack = FAMILIES["compatible"](np.random.default_rng(0), 5, 2)
    with pytest.raises(FormulationError):
        formulations.solve(stack, "cascaded_qp", **bad)


def test_inputs_are_not_mutated():
    stack = with_inequalities(np.random.default_rng(5), 6, 4)
    before = [(t.A.copy(), None if t.b is None else t.b.copy()) for t in stack.tasks]
    W = np.eye(6) * 2.0
    formulations.solve(stack, "cascaded_qp", metric=W)
    assert np.array_equal(W, np.eye(6) * 2.0)
    for (A, b), t in zip(before, stack.tasks, strict=False):
        assert np.array_equal(A, t.A) and (b is None or np.array_equal(b, t.b))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3, 10), k=st.integers(2, 4))
def test_default_backend_matches_reference_on_random_stacks(seed, n, k):
    rng = np.random.default_rng(seed)
    family = ("compatible", "conflicting", "rank_deficient")[seed % 3]
    stack = FAMILIES[family](rng, n, k)
    ref = formulations.solve(stack, "reference").x
    sol = formulations.solve(stack, "cascaded_qp")
    assert sol.status == "optimal"
    assert relative_distance(sol.x, ref) <= 1e-8
    np.testing.assert_allclose(sol.residuals, lexicographic_residuals(stack, ref),
                               rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("fixing", ["basis", "nullspace"])
@pytest.mark.parametrize("solver", [b for b in ("clarabel", "quadprog", "daqp") if b in BACKENDS])
@pytest.mark.parametrize("family", ["conflicting", "rank_deficient", "coupled"])
def test_level_damping_matches_the_damped_reference(family, solver, fixing):
    """``level_damping`` (μ_i²‖x‖² in level i) is the damped hierarchy of the oracle."""
    rng = np.random.default_rng(31)
    stack = FAMILIES[family](rng, 18, 4)
    mu2 = rng.uniform(0.0, 2.0, len(stack)) * (rng.uniform(size=len(stack)) < 0.7)
    ref = formulations.solve(stack, "reference", level_damping=mu2).x
    sol = formulations.solve(stack, "cascaded_qp", solver=solver, fixing=fixing,
                             level_damping=mu2)
    assert sol.ok
    assert relative_distance(sol.x, ref) <= tolerance(EQUALITY_TOL, solver)


def test_level_damping_of_wrong_length_is_named():
    stack = FAMILIES["conflicting"](np.random.default_rng(0), 10, 3)
    with pytest.raises(FormulationError, match="level_damping must hold 3"):
        formulations.solve(stack, "cascaded_qp", level_damping=[0.1, 0.2])


@pytest.mark.skipif("osqp" not in BACKENDS, reason="OSQP not installed")
def test_concurrent_quiet_solves_leave_stdout_alone(capfd):
    import sys
    from concurrent.futures import ThreadPoolExecutor
    stack = with_inequalities(np.random.default_rng(1), 6, 4)
    before = sys.stdout
    with ThreadPoolExecutor(4) as pool:
        sols = list(pool.map(lambda _: formulations.solve(stack, "cascaded_qp",
                                                          solver="osqp"), range(16)))
    assert sys.stdout is before            # redirect_stdout from threads left a StringIO
    print("still printing")
    assert capfd.readouterr().out == "still printing\n"
    assert all(np.array_equal(s.x, sols[0].x) for s in sols)


def _degenerate1():
    from pathlib import Path

    from prioik.hierarchy import load_peer_json
    return load_peer_json(Path(__file__).parent / "data" / "peer" / "daqp_jl_degenerate1.json")


@pytest.mark.parametrize("backend", sorted(CERTIFIED | {"daqp"}))
def test_zero_row_with_unreachable_bounds_keeps_its_fixed_violation(backend):
    """DAQP's degenerate test: ``0·x ∈ [2, 5]`` on level 2 (was NaN in every cascade)."""
    stack = _degenerate1().stack
    sol = formulations.solve(stack, "cascaded_qp", solver=backend)
    assert sol.status == "optimal", sol.diagnostics.reason
    np.testing.assert_allclose(sol.x, [3.0, 1.5, 0.0], atol=1e-7)
    # level 1: x0 = 3 is 1.5 short of 4.5; level 2: the zero row misses [2, 5] by 2
    # and x0 = 3 misses [7, 10] by 4
    np.testing.assert_allclose(sol.residuals ** 2, [0.0, 2.25, 20.0], atol=1e-6)


def test_backend_options_a_backend_refuses_name_the_option():
    """``backend_options={"bogus": 1}`` raised Clarabel's raw AttributeError."""
    stack = TaskStack([Task("a", np.eye(2), [1.0, 2.0]), Task("b", np.eye(2), [0.0, 0.0])])
    with pytest.raises(FormulationError, match="option 'backend_options': the clarabel "
                                               "back-end does not take .*bogus"):
        formulations.solve(stack, "cascaded_qp", solver="clarabel",
                           backend_options={"bogus": 1})
