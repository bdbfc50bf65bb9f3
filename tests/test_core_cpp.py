"""The compiled core (``prioik._core``, core/): how it was built, that its answers equal
the readable LAPACK path's (``kernel="lapack"``, the same nested QR in scipy calls), and
that every array it is handed is checked at the boundary."""

from __future__ import annotations

import platform
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import unaligned
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import prioik._core as core
from prioik import formulations
from prioik.formulations.base import ConcurrentUseError, CoreInputError
from prioik.hierarchy import Task, TaskStack, TaskStackError, linalg, load_stack
from prioik.hierarchy.families import FAMILIES, near_singular, same_shape_batch

#: rounding edges: `make test-forced-cpu` runs this module again with the LAPACK path (the
#: oracle) on OpenBLAS's kernels for another core type
pytestmark = pytest.mark.rounding_edge

DATA = Path(__file__).parent / "data"
EPS = float(np.finfo(np.float64).eps)
SAVED = sorted((DATA / "fuzz").glob("*.json")) + sorted((DATA / "adversarial").glob("*.json"))

#: the option sets of the prepared solve: plain eq. 18, selective damping, step bounds
OPTION_SETS = {"plain": {}, "selective": {"level_damping": 0.1, "singular_threshold": 0.05},
               "step_bound": {"step_bound": 0.5}}


def test_core_is_built_with_the_stated_rounding_rule():
    info = core.build_info()
    assert info.fast_math is False
    assert info.fp_contract is False      # a * b + c is rounded twice, as written
    assert info.eigen.startswith("3.4.")
    assert info.compiler
    # the AVX2 and baseline clones of the hot functions: a portable GCC build on x86-64 Linux
    portable_gcc = (not info.native and not info.sanitized and info.compiler.startswith("GNU")
                    and sys.platform == "linux" and platform.machine() == "x86_64")
    assert info.vector_clones in (("avx2", "default") if portable_gcc else ("none",))


def test_core_constants_are_the_hierarchy_s():
    assert core.AMBIGUITY == linalg.AMBIGUITY
    assert core.NEAR_AMBIGUITY == linalg.NEAR_AMBIGUITY
    assert core.PRECISION_LIMIT_NORM == linalg.PRECISION_LIMIT_NORM
    # the extreme scales solved equilibrated (formulations.extended_jacobian's docstring)
    assert (core.SCALE_HIGH, core.SCALE_LOW) == (1e100, 1e-100)


# ------------------------------------------------------------- the LAPACK oracle
def _moved(stack: TaskStack, seed: int) -> TaskStack:
    """``stack`` with every entry of every ``A_i`` times ``1 ± ε`` (seeded signs)."""
    rng = np.random.default_rng(seed)
    return TaskStack([[Task(t.name, t.A * (1.0 + EPS * rng.choice([-1.0, 1.0], t.A.shape)),
                            t.b, weight=t.weight) for t in level] for level in stack.levels])


def assert_same_answer(stack: TaskStack, **options) -> None:
    """The C++ core's answer equals the LAPACK path's on ``stack``: the same status,
    rank profile and flagged levels; per level ‖w_i‖² within 1e-12 relative; and ``x``
    within 1e-10 where no rank decision is near its threshold (the optimum is then well
    determined). Where a level's rank decision is ambiguous (both say which), the rank
    profile and the residuals are compared above it.

    The two round differently (LAPACK's blocked Householder steps and its SVD in the
    trust-region step, the core's written-out sums and one-sided Jacobi), and an
    ill-conditioned level turns that into differences beyond those bounds. So the bounds
    also hold when the core is within 32 times the distance the LAPACK answer moves when
    ``A`` moves by one ulp (two seeded draws: how far rounding alone moves the stack's
    answer), and a status the moved stacks give is taken (a decision at the edge of its
    threshold), the values compared then; a residual is compared to what a
    backward-stable solve determines, ``64 ε (‖A_i‖ ‖x‖ + ‖b_i‖)``; and where a step
    bound damped a level, whose step the Newton iteration finds to 1e-12 of the bound,
    ``x`` and the residuals are compared to 1e-10 of their scale.
    """
    prepare = formulations.prepare
    ref = prepare(stack.layout, "extended_jacobian", kernel="lapack", **options).solve(stack)
    got = prepare(stack.layout, "extended_jacobian", kernel="cpp", **options).solve(stack)
    moved = [prepare(stack.layout, "extended_jacobian", kernel="lapack", **options)
             .solve(_moved(stack, seed)) for seed in range(2)]
    assert got.detail.kernel == "cpp" and ref.detail.kernel == "lapack"
    flipped = got.status != ref.status and got.status in {m.status for m in moved}
    assert got.status == ref.status or flipped, (got.diagnostics, ref.diagnostics)
    def levels(sol):        # the flagged levels of an answer, by kind
        return {"damped_levels": sol.detail.damped_levels or [],
                "ambiguous_levels": sol.diagnostics.ambiguous_levels,
                "near_ambiguous_levels": sol.detail.near_ambiguous_levels or []}

    # an ambiguous level's rank is either reading (its rounding decides): the levels
    # from there down may take the other one's consequences
    first = min(ref.diagnostics.ambiguous_levels or [len(stack.levels)])
    if not flipped:
        np.testing.assert_array_equal(got.diagnostics.ranks[:first],
                                      ref.diagnostics.ranks[:first])
        assert levels(got) == levels(ref)
    bounded = "step_bound" in options and bool(ref.detail.damped_levels)
    spread_w = np.max([np.abs(m.residuals ** 2 - ref.residuals ** 2) for m in moved], axis=0)
    spread_x = max(np.linalg.norm(m.x - ref.x) for m in moved)
    for i, level in enumerate(stack.levels[:first]):
        w_got, w_ref = got.residuals[i], ref.residuals[i]
        scale = np.linalg.norm(level.A) * np.linalg.norm(ref.x) + np.linalg.norm(level.b)
        rounding = 64 * EPS * scale          # a backward-stable residual's resolution
        allowed = max(1e-12 * w_ref ** 2, rounding * (2 * w_ref + rounding),
                      32 * spread_w[i], 2 * w_ref * 1e-10 * scale if bounded else 0.0)
        assert abs(w_got ** 2 - w_ref ** 2) <= allowed, (i, w_got, w_ref, spread_w[i], scale)
    if not flipped and not (ref.diagnostics.ambiguous_levels or ref.detail.near_ambiguous_levels):
        size = max(1.0, np.linalg.norm(ref.x))
        allowed = max(1e-10 * size, 32 * spread_x)
        assert np.linalg.norm(got.x - ref.x) <= allowed, (np.linalg.norm(got.x - ref.x),
                                                          spread_x)


def _equality_part(stack: TaskStack, bounds_as_targets: bool) -> TaskStack | None:
    """The stack's equality tasks (``bounds_as_targets``: and its inequality rows as
    equalities aiming at their bounds' midpoint, or the finite bound)."""
    levels = []
    for level in stack.levels:
        tasks = []
        for t in level:
            if t.is_equality:
                tasks.append(Task(t.name, t.A, t.b, weight=t.weight))
            elif bounds_as_targets:
                lo = (np.asarray(t.lower, dtype=float) if t.lower is not None
                      else np.full(t.m, -np.inf))
                up = (np.asarray(t.upper, dtype=float) if t.upper is not None
                      else np.full(t.m, np.inf))
                target = np.where(np.isfinite(lo) & np.isfinite(up), 0.5 * (lo + up),
                                  np.where(np.isfinite(lo), lo, np.where(np.isfinite(up),
                                                                         up, 0.0)))
                tasks.append(Task(t.name, t.A, target, weight=t.weight))
        if tasks:
            levels.append(tasks)
    return TaskStack(levels) if levels else None


@pytest.mark.parametrize("options", sorted(OPTION_SETS))
@pytest.mark.parametrize("family", sorted(FAMILIES))
@pytest.mark.parametrize("seed", range(8))
def test_core_equals_lapack_on_the_shared_families(family, seed, options):
    rng = np.random.default_rng(4000 + seed)
    stack = FAMILIES[family](rng, int(rng.integers(3, 45)), int(rng.integers(1, 8)))
    assert_same_answer(stack, **OPTION_SETS[options])


@pytest.mark.parametrize("bounds_as_targets", [False, True])
@pytest.mark.parametrize("path", SAVED, ids=[p.stem for p in SAVED])
def test_core_equals_lapack_on_the_saved_fuzz_and_adversarial_stacks(path, bounds_as_targets):
    stack = _equality_part(load_stack(path), bounds_as_targets)
    if stack is None:
        pytest.skip("no equality rows")
    for options in OPTION_SETS.values():
        assert_same_answer(stack, **options)


def test_the_saved_stacks_cover_every_rank_decision_kind():
    """The saved stacks reach the ambiguous and near-ambiguous branches (so the equality
    test above compares them), not only clear decisions."""
    seen = set()
    for path in SAVED:
        stack = _equality_part(load_stack(path), True)
        if stack is None:
            continue
        sol = formulations.solve(stack, "extended_jacobian", kernel="cpp")
        seen.update(key for key, at in (("ambiguous_levels", sol.diagnostics.ambiguous_levels),
                                         ("near_ambiguous_levels",
                                          sol.detail.near_ambiguous_levels)) if at)
    assert seen == {"ambiguous_levels", "near_ambiguous_levels"}


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(family=st.sampled_from(sorted(FAMILIES)), seed=st.integers(0, 2 ** 31),
       n=st.integers(1, 60), k=st.integers(1, 9), options=st.sampled_from(sorted(OPTION_SETS)))
def test_core_equals_lapack_on_seeded_stacks(family, seed, n, k, options):
    try:
        stack = FAMILIES[family](np.random.default_rng(seed), n, k)
    except (ValueError, TaskStackError):
        return                          # a family that does not take this n, k
    assert_same_answer(stack, **OPTION_SETS[options])


@pytest.mark.parametrize("sigma", [1e-1, 1e-4, 1e-8, 0.0])
@pytest.mark.parametrize("options", sorted(OPTION_SETS))
def test_core_equals_lapack_near_a_singularity(sigma, options):
    assert_same_answer(near_singular(sigma), **OPTION_SETS[options])


def test_core_equals_lapack_on_a_unit_row_posture_below_a_floating_base():
    """The deferred unit-row level (a posture of uniform weight on all but a floating
    base's six columns) solved by the Woodbury step, after tasks that fix coordinates."""
    rng = np.random.default_rng(3)
    n = 30
    posture = np.zeros((n - 6, n))
    posture[np.arange(n - 6), np.arange(6, n)] = 2.0
    for top in (3, 8, 14):
        contact = Task("contact", rng.standard_normal((top, n)), rng.standard_normal(top))
        stack = TaskStack([[contact],
                           [Task("posture", posture, rng.standard_normal(n - 6))]])
        assert_same_answer(stack)
        sol = formulations.solve(stack, "extended_jacobian", kernel="cpp")
        assert sol.status == "optimal"
        assert sol.diagnostics.ranks[1] == min(n - 6, n - top)   # Woodbury when top ≥ 6


@pytest.mark.parametrize("options", sorted(OPTION_SETS))
def test_core_batch_equals_the_lapack_answers(options):
    rng = np.random.default_rng(21)
    stacks = same_shape_batch(FAMILIES["conflicting"](rng, 18, 4), rng, 9, reduce=0.3)
    ref = formulations.solve_batch(stacks, "extended_jacobian", kernel="lapack",
                                   **OPTION_SETS[options])
    got = formulations.solve_batch(stacks, "extended_jacobian", kernel="cpp",
                                   **OPTION_SETS[options])
    assert got.batched
    assert list(got.statuses) == list(ref.statuses)
    for x, y in zip(got.X, ref.X, strict=False):
        assert np.linalg.norm(x - y) <= 1e-10 * max(1.0, np.linalg.norm(y))
    for s, x in zip(stacks, got.X, strict=False):       # each row is that stack's own solve
        one = formulations.solve(s, "extended_jacobian", kernel="cpp", **OPTION_SETS[options])
        np.testing.assert_array_equal(x, one.x)


def test_core_batch_on_threads_equals_one_thread_and_names_the_first_bad_stack():
    rng = np.random.default_rng(22)
    stacks = same_shape_batch(FAMILIES["rank_deficient"](rng, 16, 4), rng, 11, reduce=0.3)
    A = np.stack([s.data.A for s in stacks])
    b = np.stack([s.data.b for s in stacks])
    w = np.stack([s.data.sqrt_weight for s in stacks])
    solver = core.ExtendedJacobian(list(stacks[0].layout.starts), stacks[0].n, rcond=1e-10)
    one = solver.solve_batch(A, b, w, threads=1).x.copy()
    for threads in (2, 4, 0):
        np.testing.assert_array_equal(solver.solve_batch(A, b, w, threads=threads).x, one)
    A[7, 2, 3] = np.inf
    A[9, 0, 0] = np.nan
    with pytest.raises(CoreInputError, match=r"^stack 7: A\[2, 3\]"):
        solver.solve_batch(A, b, w, threads=4)


def test_core_solves_rows_of_extreme_scale_by_equilibrating():
    stack = TaskStack([[Task("a", 1e-200 * np.eye(2), np.array([1.0, 2.0]))]])
    sol = formulations.solve(stack, "extended_jacobian", kernel="cpp")
    np.testing.assert_allclose(sol.x * 1e-200, [1.0, 2.0], rtol=1e-10)


# ------------------------------------------------------------------- boundary
def _solver(M=4, n=3, k=2):
    starts = [0, M // 2, M][:k + 1]
    return core.ExtendedJacobian(starts, n, rcond=1e-10)


def _good(M=4, n=3):
    rng = np.random.default_rng(0)
    return rng.standard_normal((M, n)), rng.standard_normal(M), np.ones(M)


def _with(index, value, arrays):
    out = list(arrays)
    out[index] = value
    return out


def _nan_at(array, where):
    bad = array.copy()
    bad[where] = np.nan
    return bad


A, B, W = _good()
BAD_ARRAYS = {
    "A float32": (_with(0, A.astype(np.float32), (A, B, W)), "A"),
    "A int64": (_with(0, A.astype(np.int64), (A, B, W)), "A"),
    "A complex": (_with(0, A.astype(complex), (A, B, W)), "A"),
    "A list": (_with(0, A.tolist(), (A, B, W)), "A"),
    "A None": (_with(0, None, (A, B, W)), "A"),
    "A 1-D": (_with(0, A.ravel(), (A, B, W)), "A"),
    "A transposed": (_with(0, np.ascontiguousarray(A.T), (A, B, W)), "A"),
    "A too many rows": (_with(0, np.vstack([A, A]), (A, B, W)), "A"),
    "A Fortran order": (_with(0, np.asfortranarray(A), (A, B, W)), "A"),
    "A strided view": (_with(0, np.hstack([A, A])[:, ::2], (A, B, W)), "A"),
    "A empty": (_with(0, np.empty((0, 3)), (A, B, W)), "A"),
    "A NaN": (_with(0, _nan_at(A, (1, 2)), (A, B, W)), "A[1, 2]"),
    "A inf": (_with(0, np.where(np.arange(3) == 0, np.inf, A), (A, B, W)), "A[0, 0]"),
    "b float32": (_with(1, B.astype(np.float32), (A, B, W)), "b"),
    "b 2-D": (_with(1, B[:, None], (A, B, W)), "b"),
    "b short": (_with(1, B[:2].copy(), (A, B, W)), "b"),
    "b strided": (_with(1, np.repeat(B, 2)[::2], (A, B, W)), "b"),
    "b empty": (_with(1, np.empty(0), (A, B, W)), "b"),
    "b NaN": (_with(1, _nan_at(B, 3), (A, B, W)), "b[3]"),
    "b -inf": (_with(1, np.where(np.arange(4) == 2, -np.inf, B), (A, B, W)), "b[2]"),
    "sqrt_weight int": (_with(2, np.ones(4, dtype=np.int32), (A, B, W)), "sqrt_weight"),
    "sqrt_weight zero": (_with(2, np.array([1.0, 0.0, 1.0, 1.0]), (A, B, W)), "sqrt_weight[1]"),
    "sqrt_weight negative": (_with(2, np.array([1.0, 1.0, -2.0, 1.0]), (A, B, W)),
                             "sqrt_weight[2]"),
    "sqrt_weight NaN": (_with(2, _nan_at(W, 0), (A, B, W)), "sqrt_weight[0]"),
    "sqrt_weight inf": (_with(2, np.array([1.0, np.inf, 1.0, 1.0]), (A, B, W)),
                        "sqrt_weight[1]"),
}


@pytest.mark.parametrize("case", sorted(BAD_ARRAYS))
def test_every_bad_array_gives_prioik_s_error_naming_it(case):
    arrays, name = BAD_ARRAYS[case]
    solver = _solver()
    with pytest.raises(CoreInputError) as err:
        solver.solve(*arrays)
    assert name in str(err.value)
    assert isinstance(err.value, formulations.FormulationError)
    # the solver still works after refusing an input
    x = solver.solve(A, B, W).x
    assert np.all(np.isfinite(x))


@pytest.mark.parametrize("case", sorted(BAD_ARRAYS))
def test_every_bad_array_of_a_batch_gives_prioik_s_error_naming_it(case):
    """A bad value in the second stack names the stack and the entry; an array that is
    not a batch of the layout's arrays names the array."""
    arrays, name = BAD_ARRAYS[case]
    solver = _solver()
    batch = []
    for good, bad in zip((A, B, W), arrays, strict=False):
        if (isinstance(bad, np.ndarray) and bad.shape == good.shape
                and bad.dtype == np.float64 and bad.flags.c_contiguous):
            batch.append(np.stack([good, bad]))   # a bad value (or the good array)
        else:
            batch.append(bad)                     # not a batch of the layout's arrays
    base = name.split("[")[0]
    pattern = (rf"^stack 1: {base}\[" if name.endswith("]") else rf"^{base} ")
    with pytest.raises(CoreInputError, match=pattern):
        solver.solve_batch(*batch)


def test_a_batch_of_non_contiguous_stacks_is_refused_by_name():
    solver = _solver()
    As = np.stack([A, A, A])[::2]
    bs, ws = np.stack([B, B]), np.stack([W, W])
    with pytest.raises(CoreInputError, match="A must be C-contiguous"):
        solver.solve_batch(As, bs, ws)
    with pytest.raises(CoreInputError, match="b must have shape"):
        solver.solve_batch(np.stack([A, A]), np.stack([B, B, B]), ws)


@pytest.mark.parametrize("starts, n, opts, word", [
    ([], 3, {}, "starts"), ([1, 2], 3, {}, "starts"), ([0, 3, 2], 3, {}, "non-decreasing"),
    ([0, 2], 0, {}, "n must be positive"), ([0, 0], 3, {}, "no rows"),
    ([0, 2], 3, {"rcond": 0.0}, "rcond"), ([0, 2], 3, {"rcond": float("nan")}, "rcond"),
    ([0, 2], 3, {"level_damping": -1.0}, "level_damping"),
    ([0, 2], 3, {"singular_threshold": float("inf")}, "singular_threshold"),
    ([0, 2], 3, {"step_bound": [1.0, 2.0]}, "step_bound"),
    ([0, 2], 3, {"step_bound": [float("nan")]}, "step_bound")])
def test_a_malformed_layout_or_option_is_refused_by_name(starts, n, opts, word):
    options = {"rcond": 1e-10, **opts}
    with pytest.raises(CoreInputError, match=word):
        core.ExtendedJacobian(starts, n, **options)


def test_prepared_cpp_solver_names_the_task_of_a_nan():
    rng = np.random.default_rng(1)
    stack = FAMILIES["compatible"](rng, 10, 3)
    solver = formulations.prepare(stack.layout, "extended_jacobian", kernel="cpp")
    data = stack.data.copy()
    task = stack.levels[1][0].name
    data.rows(task)[0][0, 0] = np.nan
    with pytest.raises(TaskStackError, match=task):
        solver.solve(data)


def test_the_result_is_read_by_name_and_each_answer_is_its_own():
    stack = FAMILIES["conflicting"](np.random.default_rng(2), 12, 3)
    solver = formulations.prepare(stack.layout, "extended_jacobian", kernel="cpp")
    first = solver.solve(stack)
    x = first.x.copy()
    other = stack.data.copy()
    other.A[:] = np.random.default_rng(3).standard_normal(other.A.shape)
    second = solver.solve(other)
    assert not np.array_equal(second.x, x)
    np.testing.assert_array_equal(first.x, x)     # a later solve leaves the answer alone
    core_solver = core.ExtendedJacobian(list(stack.layout.starts), stack.n, rcond=1e-10)
    d = stack.data
    res = core_solver.solve(d.A, d.b, d.sqrt_weight)
    assert res.solved and res.finite and res.clear and not res.ambiguous
    a, b = res.x, res.x                           # each read is a new array
    assert a is not b and np.array_equal(a, b) and a.shape == (stack.n,)
    np.testing.assert_array_equal(res.ranks, first.diagnostics.ranks)
    assert res.ranks.dtype == np.int64
    # the answer written into the caller's arrays
    out, w = np.full(stack.n, np.nan), np.full(len(stack), np.nan)
    r = np.zeros(len(stack), np.int64)
    core_solver.solve(d.A, d.b, d.sqrt_weight, out, w, r)
    np.testing.assert_array_equal(out, first.x)
    np.testing.assert_array_equal(w, first.residuals)
    np.testing.assert_array_equal(r, first.diagnostics.ranks)


@pytest.mark.parametrize("which, bad, word", [
    ("x", np.empty(12, dtype=np.float32), "x must be float64"),
    ("x", np.empty(11), "x must have shape (12,)"),
    ("x", np.empty(24)[::2], "x must be C-contiguous"),
    ("residuals", [0.0, 0.0, 0.0], "residuals must be a float64 numpy array"),
    ("ranks", np.empty(3), "ranks must be int64"),
    ("x", "read-only", "x must be a float64 numpy array (writable)"),
    ("x", "unaligned", "x is not aligned")])
def test_a_bad_output_array_is_refused_by_name(which, bad, word):
    stack = FAMILIES["conflicting"](np.random.default_rng(2), 12, 3)
    d = stack.data
    solver = core.ExtendedJacobian(list(stack.layout.starts), stack.n, rcond=1e-10)
    outputs = {"x": np.empty(12), "residuals": np.empty(3), "ranks": np.empty(3, np.int64)}
    if isinstance(bad, str) and bad == "read-only":
        bad = np.empty(12)
        bad.setflags(write=False)
    elif isinstance(bad, str) and bad == "unaligned":
        bad = unaligned(np.zeros(12))
    outputs[which] = bad
    with pytest.raises(CoreInputError) as err:
        solver.solve(d.A, d.b, d.sqrt_weight, outputs["x"], outputs["residuals"],
                     outputs["ranks"])
    assert word in str(err.value)


def test_an_unaligned_input_array_is_refused_by_name():
    stack = FAMILIES["conflicting"](np.random.default_rng(2), 12, 3)
    d = stack.data
    solver = core.ExtendedJacobian(list(stack.layout.starts), stack.n, rcond=1e-10)
    with pytest.raises(CoreInputError, match="A is not aligned"):
        solver.solve(unaligned(d.A), d.b, d.sqrt_weight)
    res = solver.solve(np.array(unaligned(d.A)), d.b, d.sqrt_weight)   # an aligned copy
    assert res.solved


def test_a_solve_releases_the_gil_and_one_solver_serves_one_thread():
    """While one thread solves (the GIL released), another thread's call on the same
    solver raises ConcurrentUseError; on their own solvers both run, with the right
    answers."""
    rng = np.random.default_rng(8)
    stack = FAMILIES["conflicting"](rng, 150, 6)
    d = stack.data
    shared = core.ExtendedJacobian(list(stack.layout.starts), stack.n, rcond=1e-10)
    expected = shared.solve(d.A, d.b, d.sqrt_weight).x.copy()
    stop = threading.Event()
    wrong = []
    refused = [0, 0]            # the worker's, the main thread's

    def solve_until_stopped(who):
        while not stop.is_set():
            try:
                x = shared.solve(d.A, d.b, d.sqrt_weight).x
            except ConcurrentUseError:
                refused[who] += 1
                continue
            if not np.array_equal(x, expected):
                wrong.append(x)
    worker = threading.Thread(target=solve_until_stopped, args=(0,))
    worker.start()
    deadline = time.monotonic() + 20.0
    try:
        while sum(refused) < 10 and time.monotonic() < deadline:
            try:
                shared.solve(d.A, d.b, d.sqrt_weight)
            except ConcurrentUseError:
                refused[1] += 1
    finally:
        stop.set()
        worker.join()
    assert sum(refused) >= 10          # the two calls overlapped: the GIL was released
    assert not wrong
    own = core.ExtendedJacobian(list(stack.layout.starts), stack.n, rcond=1e-10)
    np.testing.assert_array_equal(own.solve(d.A, d.b, d.sqrt_weight).x, expected)


def test_the_core_is_the_default_kernel_up_to_the_crossover():
    from prioik.formulations.extended_jacobian import AUTO_CPP_MAX_N
    stack = FAMILIES["compatible"](np.random.default_rng(4), 8, 2)
    assert formulations.solve(stack, "extended_jacobian").detail.kernel == "cpp"
    assert formulations.solve(stack, "extended_jacobian", kernel="cpp").detail.kernel == "cpp"
    big = FAMILIES["compatible"](np.random.default_rng(4), AUTO_CPP_MAX_N + 1, 2)
    assert formulations.solve(big, "extended_jacobian").detail.kernel == "lapack"
    assert formulations.solve(big, "extended_jacobian", kernel="cpp").detail.kernel == "cpp"


# -------------------------------------------------------------- C++ without Python
def _tool(name: str) -> str:
    """The build tool of this environment (the venv's CMake and Ninja first)."""
    import shutil
    import sys
    here = Path(sys.executable).parent / name
    found = str(here) if here.exists() else shutil.which(name)
    if found is None:
        pytest.fail(f"{name} is not installed here: the C++ core cannot be built")
    return found


@pytest.mark.slow
def test_the_core_builds_alone_and_a_cpp_project_links_prioik_core(tmp_path):
    """core/ configured and built without Python (its C++ tests and the example program
    run by ctest), installed, and core/examples built as another project would build it:
    find_package(prioik), target prioik::core; the example solves a stack and checks it."""
    import subprocess
    import sys
    root = Path(__file__).parent.parent
    cmake, ninja = _tool("cmake"), _tool("ninja")
    build, prefix, example = tmp_path / "core", tmp_path / "prefix", tmp_path / "example"

    def run(*args):
        done = subprocess.run(args, capture_output=True, text=True)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        return done.stdout
    run(cmake, "-S", str(root / "core"), "-B", str(build), "-G", "Ninja",
        f"-DCMAKE_MAKE_PROGRAM={ninja}", "-DPRIOIK_BUILD_TESTS=ON",
        f"-DPython_EXECUTABLE={sys.executable}", f"-DCMAKE_INSTALL_PREFIX={prefix}")
    run(cmake, "--build", str(build))
    tested = run(_tool("ctest"), "--test-dir", str(build), "--output-on-failure")
    assert "100% tests passed" in tested
    run(cmake, "--install", str(build))
    assert (prefix / "include" / "prioik" / "householder.hpp").exists()
    eigen = run(sys.executable, "-m", "cmeel", "cmake").strip().replace(":", ";")
    run(cmake, "-S", str(root / "core" / "examples"), "-B", str(example), "-G", "Ninja",
        f"-DCMAKE_MAKE_PROGRAM={ninja}", f"-DCMAKE_PREFIX_PATH={prefix};{eigen}")
    run(cmake, "--build", str(example))
    out = run(str(example / "solve_stack"))
    assert out.strip().endswith("ok") and "ranks 6 3 3" in out
