"""The closed-form formulations compiled in the C++ core (core/include/prioik/closed_form.hpp)
against their readable numpy paths (``kernel="numpy"``, the oracles): the same answer
(where the optimum is unique) and the same status on every family of
:data:`hierarchy.families.FAMILIES` and on the G1 fencing stacks; the flop counts the
kernels report; and the checks at the bindings' boundary."""

from __future__ import annotations

import numpy as np
import pytest

import prioik._core as core
from prioik import formulations
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import Task, TaskStack, UnsupportedTaskError, level_residuals
from prioik.hierarchy.families import FAMILIES, box_bounded, random_spd

#: relative agreement of the compiled and readable answers, ‖x_cpp − x_numpy‖ / max(1, ‖x‖):
#: the two factor Ĵ_i differently (row-pivoted LQ, SVD) and round differently
AGREEMENT = 1e-8
#: the nullspace settings compared: plain, damped (λ multiplies I), textbook step
NULLSPACE_SETTINGS = {"plain": {}, "damped": {"damping": 1e-2},
                      "no_reproject": {"reproject": False}}


def family_stacks(seeds: int = 12):
    for family, make in FAMILIES.items():
        for seed in range(seeds):
            rng = np.random.default_rng(7000 + seed)
            yield family, seed, make(rng, int(rng.integers(3, 40)), int(rng.integers(1, 7)))


def assert_kernels_agree(stack: TaskStack, name: str, **options) -> tuple:
    cpp = formulations.solve(stack, name, kernel="cpp", **options)
    ref = formulations.solve(stack, name, kernel="numpy", **options)
    assert cpp.detail.kernel == "cpp" and ref.detail.kernel == "numpy"
    assert cpp.status == ref.status, (cpp.status, ref.status, cpp.diagnostics.reason)
    scale = max(1.0, float(np.linalg.norm(ref.x)))
    assert np.linalg.norm(cpp.x - ref.x) <= AGREEMENT * scale, np.linalg.norm(cpp.x - ref.x)
    return cpp, ref


@pytest.mark.parametrize("setting", sorted(NULLSPACE_SETTINGS))
def test_nullspace_cpp_equals_numpy_on_every_family(setting):
    for family, seed, stack in family_stacks():
        cpp, ref = assert_kernels_agree(stack, "nullspace", **NULLSPACE_SETTINGS[setting])
        assert cpp.diagnostics.ranks.tolist() == ref.diagnostics.ranks.tolist(), (family, seed)


@pytest.fixture(scope="module")
def g1_runs():
    """6 states of each G1 fencing run."""
    pytest.importorskip("pinocchio")
    from prioik.benchmarks.stacks import g1_fencing_samples
    return [g1_fencing_samples(v, 6) for v in ("compatible", "incompatible")]


@pytest.fixture(scope="module")
def g1_samples(g1_runs):
    """(stack, M(q)) at 6 states of each G1 fencing run."""
    return [(s, M) for run in g1_runs
            for s, M in zip(run.stacks, run.mass_matrices, strict=False)]


@pytest.fixture(scope="module")
def g1_stacks(g1_samples):
    return [stack for stack, _ in g1_samples]


@pytest.mark.parametrize("setting", sorted(NULLSPACE_SETTINGS))
def test_nullspace_cpp_equals_numpy_on_the_g1_fencing_stacks(g1_stacks, setting):
    for stack in g1_stacks:
        assert stack.n == 35
        assert_kernels_agree(stack, "nullspace", **NULLSPACE_SETTINGS[setting])


@pytest.mark.parametrize("damping", [0.0, 1e-2])
def test_chiaverini_cpp_equals_numpy_on_every_family(damping):
    for _family, _seed, stack in family_stacks():
        cpp, ref = assert_kernels_agree(stack, "chiaverini", damping=damping)
        for own, own_ref in zip(cpp.detail.task_solutions, ref.detail.task_solutions,
                                strict=True):
            assert np.linalg.norm(own - own_ref) <= AGREEMENT * max(1.0, np.linalg.norm(own_ref))


@pytest.mark.parametrize("damping", [0.0, 1e-2])
def test_chiaverini_cpp_equals_numpy_on_the_g1_fencing_stacks(g1_stacks, damping):
    for stack in g1_stacks:
        assert_kernels_agree(stack, "chiaverini", damping=damping)


def test_unifying_cpp_equals_numpy_on_every_family():
    for _family, seed, stack in family_stacks():
        M = random_spd(np.random.default_rng(seed), stack.n)
        bias = np.linspace(-1.0, 1.0, stack.n)
        cpp, ref = assert_kernels_agree(stack, "unifying", mass_matrix=M, bias=bias)
        np.testing.assert_allclose(cpp.detail.tau, M @ cpp.x + bias, rtol=0, atol=1e-12 *
                                   max(1.0, float(np.abs(M @ cpp.x).max())))


def test_unifying_cpp_equals_numpy_on_the_g1_fencing_stacks(g1_samples):
    for stack, M in g1_samples:
        assert_kernels_agree(stack, "unifying", mass_matrix=M)


@pytest.mark.parametrize("reproject", [True, False])
def test_operational_space_cpp_equals_numpy_on_every_family(reproject):
    for family, seed, stack in family_stacks():
        M = random_spd(np.random.default_rng(seed), stack.n)
        cpp, ref = assert_kernels_agree(stack, "operational_space", mass_matrix=M,
                                        reproject=reproject)
        assert cpp.diagnostics.ranks.tolist() == ref.diagnostics.ranks.tolist(), (family, seed)


def test_operational_space_cpp_equals_numpy_on_the_g1_fencing_stacks(g1_samples):
    for stack, M in g1_samples:
        assert_kernels_agree(stack, "operational_space", mass_matrix=M)


@pytest.mark.parametrize("name", ["unifying", "operational_space"])
def test_mass_matrix_solvers_take_m_per_solve(name):
    """A prepared solver takes a new M (and bias) with every solve, as the readable one."""
    rng = np.random.default_rng(11)
    stack = FAMILIES["coupled"](rng, 9, 3)
    solver = formulations.prepare(stack, name)
    for seed in range(3):
        M = random_spd(np.random.default_rng(seed), 9)
        got = solver.solve(stack, mass_matrix=M)
        ref = formulations.solve(stack, name, mass_matrix=M, kernel="numpy")
        assert np.linalg.norm(got.x - ref.x) <= AGREEMENT * max(1.0, np.linalg.norm(ref.x))


def test_unifying_cpp_names_a_mass_matrix_it_cannot_take():
    stack = FAMILIES["conflicting"](np.random.default_rng(2), 6, 2)
    with pytest.raises(formulations.FormulationError, match="positive definite"):
        formulations.solve(stack, "unifying", kernel="cpp", mass_matrix=-np.eye(6))
    # the binding checks M itself (the plugin's options refuse these before it)
    solver = core.UnifyingSolver([int(s) for s in stack.layout.starts], 6, rcond=1e-9)
    data = stack.data
    bad = np.eye(6)
    bad[2, 1] = np.inf
    with pytest.raises(CoreInputError, match=r"mass_matrix\[2, 1\] is not finite"):
        solver.solve(data.A, data.b, data.sqrt_weight, bad)
    with pytest.raises(CoreInputError, match="mass_matrix must have shape"):
        solver.solve(data.A, data.b, data.sqrt_weight, np.eye(5))
    assert solver.solve(data.A, data.b, data.sqrt_weight, np.eye(6)).finite


def test_nullspace_auto_is_the_compiled_kernel_and_reports_flops():
    stack = FAMILIES["conflicting"](np.random.default_rng(1), 12, 3)
    sol = formulations.solve(stack, "nullspace")
    assert sol.detail.kernel == "cpp" and sol.detail.flops > 0
    batch = formulations.solve_batch([stack, stack], "nullspace")
    np.testing.assert_array_equal(batch.X[0], sol.x)
    assert batch.statuses == [sol.status] * 2


# ------------------------------------------------------------------------------ flops
def householder_lq_applications(m: int, n: int) -> int:
    """The flops of a dense Householder LQ of an ``m × n`` matrix (``m ≤ n``, full row
    rank) in its reflector applications: reflector ``r`` updates the ``m − r − 1`` rows
    below it on ``n − r`` columns, a dot product and an update, ``4 (n − r)`` each; in
    total ``2 n m² − 2 m³ / 3`` to first order (the QR of the transposed ``n × m``)."""
    return sum(4 * (m - r - 1) * (n - r) for r in range(m))


@pytest.mark.parametrize("m, n", [(20, 40), (60, 90), (35, 35)])
def test_nullspace_flops_of_one_level_are_a_householder_lq_and_lower_order_terms(m, n):
    """One level of full row rank: N = I, so the kernel does one row-pivoted Householder
    LQ of the m × n level, a forward substitution and the reflectors on the step; every
    other operation is O(m n)."""
    rng = np.random.default_rng(m * n)
    stack = TaskStack([Task("only", rng.standard_normal((m, n)), rng.standard_normal(m))])
    flops = formulations.solve(stack, "nullspace", kernel="cpp").detail.flops
    lq = householder_lq_applications(m, n)
    assert abs(lq - (2 * n * m * m - 2 * m ** 3 / 3)) <= 4 * m * n     # the dense count
    assert lq <= flops <= lq + 16 * m * n + m * m, (flops, lq)


def test_nullspace_flops_grow_with_the_projections_of_the_lower_levels():
    """A second level adds Ĵ_2 = A_2 N (2 m_2 n² flops) and the projector update
    (≥ r_1 n² flops) to the first level's count."""
    rng = np.random.default_rng(5)
    n, m1, m2 = 30, 6, 8
    first = Task("a", rng.standard_normal((m1, n)), rng.standard_normal(m1))
    second = Task("b", rng.standard_normal((m2, n)), rng.standard_normal(m2))
    one = formulations.solve(TaskStack([first]), "nullspace", kernel="cpp").detail.flops
    two = formulations.solve(TaskStack([first, second]), "nullspace",
                             kernel="cpp").detail.flops
    assert two - one >= 2 * m2 * n * n + m1 * n * n


def test_one_level_flops_of_the_other_kernels():
    """One level of full row rank (m < n): chiaverini does nullspace's LQ, solve and
    reflectors without the error b − A x (2 m n + m flops fewer, exactly); unifying and
    operational_space add M's Cholesky factorization (n³/3 to first order) and a
    triangular solve per row (n² each: B = A M⁻¹ takes two, A L⁻ᵀ one) to that LQ."""
    rng = np.random.default_rng(4)
    m, n = 12, 30
    stack = TaskStack([Task("only", rng.standard_normal((m, n)), rng.standard_normal(m))])
    M = random_spd(rng, n)
    count = {name: formulations.solve(stack, name, kernel="cpp", **opts).detail.flops
             for name, opts in [("nullspace", {}), ("chiaverini", {}),
                                ("unifying", {"mass_matrix": M}),
                                ("operational_space", {"mass_matrix": M})]}
    assert count["nullspace"] - count["chiaverini"] == 2 * m * n + m
    lq = householder_lq_applications(m, n)
    cholesky = sum(2 * b + 1 for a in range(n) for b in range(a + 1))
    assert count["unifying"] >= cholesky + 2 * m * n * n + lq
    assert count["operational_space"] >= cholesky + 2 * m * n * n + lq
    assert abs(cholesky - n ** 3 / 3) <= n * n


# ------------------------------------------------------------------------- boundary
@pytest.mark.parametrize("make", [core.NullspaceSolver, core.ChiaveriniSolver])
def test_the_closed_form_solvers_check_their_arrays(make):
    solver = make([0, 2, 3], 4, rcond=1e-9)
    A, b, w = np.ones((3, 4)), np.zeros(3), np.ones(3)
    with pytest.raises(CoreInputError, match="A must have shape"):
        solver.solve(np.ones((3, 5)), b, w)
    with pytest.raises(CoreInputError, match="sqrt_weight must be float64"):
        solver.solve(A, b, np.ones(3, dtype=np.int64))
    with pytest.raises(CoreInputError, match="C-contiguous"):
        solver.solve(np.ones((4, 3)).T, b, w)
    bad = A.copy()
    bad[1, 2] = np.nan
    with pytest.raises(CoreInputError, match=r"A\[1, 2\] is not finite"):
        solver.solve(bad, b, w)
    with pytest.raises(CoreInputError, match=r"sqrt_weight\[0\] must be finite and > 0"):
        solver.solve(A, b, np.array([0.0, 1.0, 1.0]))
    with pytest.raises(CoreInputError, match="damping must be finite"):
        make([0, 3], 4, rcond=1e-9, damping=-1.0)
    with pytest.raises(CoreInputError, match="starts must be non-decreasing"):
        make([0, 3, 2], 4, rcond=1e-9)
    assert solver.solve(A, b, w).finite        # the solver still works after refusals


def householder_qr_applications(m: int, n: int) -> int:
    """The flops of a dense Householder QR of an ``m × n`` matrix (``m ≥ n``, full column
    rank) in its reflector applications: column ``j``'s reflector updates the ``n − j − 1``
    later columns on ``m − j`` rows, ``4 (m − j)`` each; ``2 m n² − 2 n³ / 3`` to first
    order."""
    return sum(4 * (n - j - 1) * (m - j) for j in range(n))


@pytest.mark.parametrize("m, n", [(50, 20), (90, 60), (35, 35)])
def test_extended_jacobian_flops_of_a_full_rank_level_are_a_householder_qr(m, n):
    """One level of full column rank (m ≥ n): the nested QR solves it by one column-pivoted
    Householder QR, a back substitution and one refinement step; the rest is O(m n)."""
    rng = np.random.default_rng(m + n)
    stack = TaskStack([Task("only", rng.standard_normal((m, n)), rng.standard_normal(m))])
    sol = formulations.solve(stack, "extended_jacobian", kernel="cpp")
    qr = householder_qr_applications(m, n)
    assert abs(qr - (2 * m * n * n - 2 * n ** 3 / 3)) <= 4 * m * n
    assert qr <= sol.detail.flops <= qr + 16 * m * n + 4 * n * n, (sol.detail.flops, qr)


def test_extended_jacobian_and_nullspace_count_the_same_lq_on_one_level():
    """On one level of full row rank (m < n) both kernels do one row-pivoted LQ, a forward
    substitution and the reflectors on the answer: their counts differ by O(m n) only."""
    rng = np.random.default_rng(3)
    m, n = 25, 60
    stack = TaskStack([Task("only", rng.standard_normal((m, n)), rng.standard_normal(m))])
    ej = formulations.solve(stack, "extended_jacobian", kernel="cpp").detail.flops
    ns = formulations.solve(stack, "nullspace", kernel="cpp").detail.flops
    assert abs(ej - ns) <= 6 * m * n
    assert ej >= householder_lq_applications(m, n)


# ------------------------------------------------------------------------- reference
#: the reference's settings compared: minimum norm, damped levels, a metric's tie-break
REFERENCE_SETTINGS = ("plain", "damped", "metric")


def reference_options(setting: str, stack: TaskStack) -> dict:
    if setting == "damped":
        return {"level_damping": [1e-2] * len(stack)}
    if setting == "metric":
        return {"metric": random_spd(np.random.default_rng(stack.n), stack.n)}
    return {}


@pytest.mark.parametrize("setting", REFERENCE_SETTINGS)
def test_reference_cpp_equals_numpy_on_every_family(setting):
    for family, seed, stack in family_stacks():
        cpp, ref = assert_kernels_agree(stack, "reference", **reference_options(setting, stack))
        np.testing.assert_array_equal(cpp.diagnostics.ranks, ref.diagnostics.ranks)
        assert cpp.detail.null_space_dim == ref.detail.null_space_dim, (family, seed)


@pytest.mark.parametrize("setting", REFERENCE_SETTINGS)
def test_reference_cpp_equals_numpy_on_the_g1_fencing_stacks(g1_stacks, setting):
    for stack in g1_stacks:
        cpp, ref = assert_kernels_agree(stack, "reference", **reference_options(setting, stack))
        np.testing.assert_array_equal(cpp.diagnostics.ranks, ref.diagnostics.ranks)


def test_reference_cpp_names_a_metric_the_null_space_cannot_take():
    """A metric singular on the last null space fails the solve on both kernels (the
    readable path's LinAlgError, reported as status "failed")."""
    stack = FAMILIES["rank_deficient"](np.random.default_rng(3), 8, 2)
    W = np.zeros((8, 8))
    for kernel in ("cpp", "numpy"):
        sol = formulations.solve(stack, "reference", kernel=kernel, metric=W)
        assert sol.status == "failed" and "positive definite" in sol.diagnostics.reason


def test_reference_auto_is_the_compiled_kernel_and_batches_by_solves():
    stack = FAMILIES["conflicting"](np.random.default_rng(1), 12, 3)
    sol = formulations.solve(stack, "reference")
    assert sol.detail.kernel == "cpp" and sol.flops > 0
    batch = formulations.solve_batch([stack, stack], "reference")
    np.testing.assert_array_equal(batch.X[0], sol.x)
    assert batch.statuses == [sol.status] * 2


@pytest.mark.parametrize("m, n", [(6, 20), (15, 35), (30, 30)])
def test_reference_flops_of_one_level_are_counted_operation_by_operation(m, n):
    """One level of full row rank (m ≤ n, Z = I): M = A Z, the row-pivoted LQ of M, the
    Jacobi sweeps over L's m columns (each pair: three dot products; each rotation: two
    rows of L and of W turned), the step's coordinates, Z Qᵀ W, and the step with two
    refinements. Every term is written out here except the LQ's, bounded as nullspace's."""
    rng = np.random.default_rng(m + 100 * n)
    stack = TaskStack([Task("only", rng.standard_normal((m, n)), rng.standard_normal(m))])
    sol = formulations.solve(stack, "reference", kernel="cpp")
    info = sol.detail
    assert sol.diagnostics.ranks.tolist() == [m]
    pairs = m * (m - 1) // 2
    jacobi = (info.jacobi_sweeps * pairs * (6 * m + 3)
              + info.jacobi_rotations * (12 + 6 * (m + m)) + m * (2 * m + 1))
    formation = 2 * m * n * n + 2 * m * n + m
    coordinates = m * (2 * m + 3)
    rotate_z = n * sum(4 * (n - t) + 1 for t in range(m)) + 2 * n * m * m
    step = 3 * 2 * n * m + 2 * (4 * m * n + m + m * (2 * n + 3)) + n
    known = formation + jacobi + coordinates + rotate_z + step
    lq = householder_lq_applications(m, n)
    assert info.jacobi_sweeps >= 2 and info.jacobi_rotations >= pairs
    assert known + lq <= info.flops <= known + lq + 16 * m * n + m * m, (info, known + lq)


def test_reference_solver_checks_its_arrays_and_options():
    solver = core.ReferenceSolver([0, 2, 3], 4, rcond=1e-9)
    A, b, w = np.ones((3, 4)), np.zeros(3), np.ones(3)
    with pytest.raises(CoreInputError, match="A must have shape"):
        solver.solve(np.ones((3, 5)), b, w)
    with pytest.raises(CoreInputError, match="b must be float64"):
        solver.solve(A, np.zeros(3, dtype=np.float32), w)
    with pytest.raises(CoreInputError, match="C-contiguous"):
        solver.solve(np.ones((4, 3)).T, b, w)
    bad = A.copy()
    bad[2, 3] = np.inf
    with pytest.raises(CoreInputError, match=r"A\[2, 3\] is not finite"):
        solver.solve(bad, b, w)
    with pytest.raises(CoreInputError, match=r"sqrt_weight\[1\] must be finite and > 0"):
        solver.solve(A, b, np.array([1.0, -1.0, 1.0]))
    with pytest.raises(CoreInputError, match="level_damping must hold 2 values"):
        core.ReferenceSolver([0, 2, 3], 4, rcond=1e-9, level_damping=[0.1])
    with pytest.raises(CoreInputError, match="level_damping must be finite"):
        core.ReferenceSolver([0, 2, 3], 4, rcond=1e-9, level_damping=[0.1, -1.0])
    with pytest.raises(CoreInputError, match="metric must have shape"):
        core.ReferenceSolver([0, 2, 3], 4, rcond=1e-9, metric=np.eye(3))
    with pytest.raises(CoreInputError, match="metric must be finite"):
        core.ReferenceSolver([0, 2, 3], 4, rcond=1e-9, metric=np.full((4, 4), np.nan))
    with pytest.raises(CoreInputError, match="rcond must be in"):
        core.ReferenceSolver([0, 2, 3], 4, rcond=0.0)
    assert solver.solve(A, b, w).finite        # the solver still works after refusals


# ------------------------------------------------------------------------------- sns
def assert_sns_kernels_agree(stack: TaskStack, **options) -> tuple:
    """The same answer, status, scaling, saturated joints (in order) and rounds; the
    kernel's residuals (the bounds level's: the distance to the box) are the stack's, to
    1e-12 of each level's scale ‖√w ∘ (|A_i| |x| + |b_i|)‖ (the rows' rounding)."""
    cpp, ref = assert_kernels_agree(stack, "sns", **options)
    data = stack.data
    magnitude = data.sqrt_weight * (np.abs(data.A) @ np.abs(cpp.x) + np.abs(data.b))
    scale = np.sqrt(np.add.reduceat(magnitude ** 2, data.layout.starts[:-1]))
    assert np.all(np.abs(cpp.residuals - level_residuals(data, cpp.x)) <= 1e-12 * scale)
    np.testing.assert_allclose(cpp.detail.task_scaling, ref.detail.task_scaling, rtol=0,
                               atol=1e-9)
    for key in ("saturated", "iterations", "scaled_tasks", "bounds_level", "first_task_level"):
        mine, theirs = getattr(cpp.detail, key), getattr(ref.detail, key)
        assert mine == theirs, (key, mine, theirs)
    return cpp, ref


def test_sns_cpp_equals_numpy_on_every_family():
    """Without bounds SNS is null-space projection: the kernels agree as nullspace's do."""
    for _family, _seed, stack in family_stacks():
        assert_sns_kernels_agree(stack)


def test_sns_cpp_equals_numpy_on_the_g1_fencing_stacks(g1_stacks):
    for stack in g1_stacks:
        assert_sns_kernels_agree(stack)


def test_sns_cpp_equals_numpy_on_the_g1_hard_bounds_stacks(g1_runs):
    """The same states with the joint limits as hard bounds above every task (the form SNS
    takes; prioik.benchmarks.flop_rates' [bounds] rows)."""
    from prioik.benchmarks.flop_rates import bounded_stacks
    for run in g1_runs:
        for stack in bounded_stacks(run):
            assert stack.levels[0].has_inequality
            assert_sns_kernels_agree(stack)


@pytest.mark.parametrize("target_scale", [0.1, 1.0, 5.0, 50.0])
@pytest.mark.parametrize("offset", [False, True])
def test_sns_cpp_equals_numpy_under_box_bounds(target_scale, offset):
    """Hard box bounds over 1-4 equality levels, from inactive (0.1) to every level scaled
    or dropped (50; the later levels then start at a vertex of the box, where the rounds'
    ties are decided by SATURATION_TIE on both kernels)."""
    saturated = 0
    for seed in range(24):
        rng = np.random.default_rng(9000 + seed)
        n, k = int(rng.integers(2, 20)), int(rng.integers(1, 5))
        stack = box_bounded(rng, n, k, target_scale, offset)
        cpp, _ = assert_sns_kernels_agree(stack)
        saturated += sum(len(s) for s in cpp.detail.saturated)
    assert saturated > 0 or target_scale < 1.0      # the rounds ran


def test_sns_cpp_options_reach_the_kernel():
    rng = np.random.default_rng(4)
    stack = box_bounded(rng, 8, 2, 5.0)
    for options in ({"max_saturations": 1}, {"max_saturations": 0}, {"bound_tolerance": 1e-3},
                    {"rcond": 1e-6}):
        assert_sns_kernels_agree(stack, **options)
    capped = formulations.solve(stack, "sns", max_saturations=1)
    assert max(len(s) for s in capped.detail.saturated) <= 1


def test_sns_cpp_names_bounds_it_cannot_take():
    n = 4
    two_columns = np.zeros((1, n))
    two_columns[0, :2] = 1.0
    stack = TaskStack([Task("limits", two_columns, lower=[-1.0], upper=[1.0]),
                       Task("goal", np.ones((1, n)), [1.0])])
    with pytest.raises(UnsupportedTaskError, match="row 0 has 2 nonzero entries"):
        formulations.solve(stack, "sns", kernel="cpp")
    one = np.zeros((1, n))
    one[0, 1] = 1.0
    apart = TaskStack([[Task("low", one, lower=[-2.0], upper=[-1.0]),
                        Task("high", one, lower=[1.0], upper=[2.0])],
                       Task("goal", np.ones((1, n)), [1.0])])
    with pytest.raises(formulations.FormulationError, match="bounds of column 1 do not"):
        formulations.solve(apart, "sns", kernel="cpp")


def test_sns_solver_checks_its_arrays_and_options():
    solver = core.SnsSolver([0, 2, 3], 4, rcond=1e-9, bounds_level=True)
    A = np.array([[1.0, 0, 0, 0], [0, 2.0, 0, 0], [1.0, 1.0, 1.0, 1.0]])
    b, w = np.array([0.0, 0.0, 3.0]), np.ones(3)
    lo, up = np.array([-1.0, -1.0, -np.inf]), np.array([1.0, 1.0, np.inf])
    with pytest.raises(CoreInputError, match="lower must have shape"):
        solver.solve(A, b, w, lo[:2], up)
    with pytest.raises(CoreInputError, match="upper must be float64"):
        solver.solve(A, b, w, lo, up.astype(np.float32))
    with pytest.raises(CoreInputError, match=r"the bounds of row 1 are not an interval"):
        solver.solve(A, b, w, np.array([-1.0, np.nan, 0.0]), up)
    bad = A.copy()
    bad[2, 0] = np.nan
    with pytest.raises(CoreInputError, match=r"A\[2, 0\] is not finite"):
        solver.solve(bad, b, w, lo, up)
    with pytest.raises(CoreInputError, match="bound_tolerance must be finite"):
        core.SnsSolver([0, 2, 3], 4, rcond=1e-9, bound_tolerance=-1.0)
    with pytest.raises(CoreInputError, match="max_saturations must be"):
        core.SnsSolver([0, 2, 3], 4, rcond=1e-9, max_saturations=-2)
    res = solver.solve(A, b, w, lo, up)        # the solver still works after refusals
    assert res.solved and res.finite and res.bounds == 0
    x = res.x
    assert abs(x[0]) <= 1 + 1e-9 and abs(2 * x[1]) <= 1 + 1e-9
    np.testing.assert_allclose(res.lower[:2], [-1.0, -0.5])


def test_sns_flops_are_nullspace_flops_and_the_rounds():
    """Without saturation the kernel does nullspace's level and three residual norms per
    level (2 m n + 2 m + 1 each); every saturation round adds at least M = A_i P̄
    (2 m n² flops) to it."""
    rng = np.random.default_rng(12)
    n = 12
    tasks = [Task(f"t{i}", rng.standard_normal((m, n)), rng.standard_normal(m))
             for i, m in enumerate((2, 3, 1))]
    plain = formulations.solve(TaskStack(tasks), "sns", kernel="cpp").flops
    ns = formulations.solve(TaskStack(tasks), "nullspace", kernel="cpp").flops
    assert plain - ns == sum(3 * (2 * t.m * n + 2 * t.m + 1) for t in tasks)
    # a box too tight for the tasks: every level saturates
    box = Task("box", np.eye(n), lower=np.full(n, -0.05), upper=np.full(n, 0.05))
    sol = formulations.solve(TaskStack([box, *tasks]), "sns", kernel="cpp")
    rounds = sum(1 + len(s) for s in sol.detail.saturated if s)
    assert rounds > 3
    factorizations = sum((1 + len(s)) * 2 * t.m * n * n
                         for s, t in zip(sol.detail.saturated, tasks, strict=True) if s)
    assert sol.flops >= ns + factorizations
