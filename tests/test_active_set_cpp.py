"""The C++ active set (``prioik._core.ActiveSetSolver``, the solver of
``hierarchical_active_set``) against the readable paths: on equality stacks the answer of
``reference`` (nested SVD null spaces) — the same status, each level's ``‖w_i‖²`` within
:data:`W2_REL` relative (plus :func:`w2_floor` where it is ~0), ``x`` within :data:`X_REL`
where both are optimal —; on every stack the certificate (an answer said ``optimal``
passes :func:`~prioik.hierarchy.check_lexicographic`, the minimum-norm tie-break
included); and a warm solver's answers equal the cold solver's to the same bounds. Over
the shared families, the saved fuzz and adversarial stacks, seeded random inequality
hierarchies, warm sequences of drifting stacks and closed-loop robot runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import unaligned

import prioik._core as core
from prioik import formulations
from prioik.formulations import hierarchical_active_set as has
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import Task, TaskStack, TaskStackError, check_lexicographic
from prioik.hierarchy.families import (
    FAMILIES,
    INEQUALITY_FAMILIES,
    box_bounded,
    random_inequality_hierarchy,
)
from prioik.hierarchy.io import load_stack

DATA = Path(__file__).parent / "data"
SAVED = sorted((DATA / "fuzz").glob("*.json")) + sorted((DATA / "adversarial").glob("*.json"))

#: per-level ‖w_i‖², relative
W2_REL = 1e-12
#: x, relative to max(1, ‖x‖), where both answers are optimal
X_REL = 1e-10
#: the absolute floor of a level's ‖w_i‖ where it is ~0, relative to the level's scale
#: ‖√W_i A_i‖_F ‖x‖ + ‖√W_i t_i‖ (t_i: the level's finite bounds and targets)
W_FLOOR = 1e-12

#: the factor over the solver's own rounding spread (:func:`rounding_spread`) within which
#: warm and cold answers on the saved ill-conditioned stacks must agree
SPREAD_FACTOR = 4.0

_OPTIONS = {"rcond": 1e-9, "primal_tol": 1e-10, "dual_tol": 1e-12, "max_iter": 500}


def prepared(stack: TaskStack, warm: bool = False) -> formulations.PreparedSolver:
    """The prepared solver (the plugin's solve, then the verification stage that applies
    its certificate's verdict)."""
    return formulations.prepare(stack.layout, has.NAME, **_OPTIONS, warm_start=warm)


def w2_floor(stack: TaskStack, x: np.ndarray) -> np.ndarray:
    """Each level's absolute floor on ``‖w_i‖²``: ``(W_FLOOR scale_i)² + 2 ‖w_i‖ W_FLOOR
    scale_i`` is the change of ``‖w_i‖²`` when ``w_i`` moves by ``W_FLOOR scale_i``."""
    data = stack.data
    out = []
    xn = float(np.linalg.norm(x))
    for i in range(stack.layout.k):
        a, b = int(data.layout.starts[i]), int(data.layout.starts[i + 1])
        sw = data.sqrt_weight[a:b]
        rows = sw[:, None] * data.A[a:b]
        t = np.concatenate([sw * data.b[a:b], sw * data.lower[a:b], sw * data.upper[a:b]])
        t = t[np.isfinite(t)]
        out.append(W_FLOOR * (np.linalg.norm(rows) * xn + np.linalg.norm(t)))
    return np.asarray(out)


def _violation(out) -> np.ndarray:
    """Each level's ``‖w_i‖²`` of an answer (the active set's own, or the residuals')."""
    w2 = getattr(out.detail, "level_violation", None)      # the reference has none
    return np.asarray(w2) if w2 is not None else np.asarray(out.residuals) ** 2


def differences(stack: TaskStack, got, ref) -> dict:
    """How far answer ``got`` is from ``ref``: each level's ``‖w_i‖²`` difference, the
    allowance of :data:`W2_REL` and :func:`w2_floor`, ``x``'s relative distance, and the
    statuses side by side."""
    floor = w2_floor(stack, ref.x)
    w_got, w_ref = _violation(got), _violation(ref)
    allowed = (W2_REL * np.maximum(w_ref, w_got)
               + floor * (floor + 2.0 * np.sqrt(np.maximum(w_ref, 0.0))))
    dw = np.abs(w_got - w_ref)
    dx = float(np.linalg.norm(got.x - ref.x)) / max(1.0, float(np.linalg.norm(ref.x)))
    return {"status": (got.status, ref.status), "dw": dw, "allowed": allowed, "dx": dx}


def rounding_spread(stack: TaskStack, ref, draws: int = 2) -> tuple[np.ndarray, float, set]:
    """How far the solver's own answer moves when ``A`` moves by one ulp (each entry
    times ``1 ± eps``, ``draws`` seeded draws): each level's largest ``‖w_i‖²`` change,
    ``x``'s largest relative change, and the statuses it gives (a stack at the edge of
    the certificate's tolerance is certified or not by rounding)."""
    data = stack.data
    dw = np.zeros(stack.layout.k)
    dx = 0.0
    statuses = {ref.status}
    for seed in range(draws):
        rng = np.random.default_rng(seed)
        moved = type(data)(data.layout)
        for name in ("A", "b", "lower", "upper", "sqrt_weight"):
            getattr(moved, name)[...] = getattr(data, name)
        moved.A[...] *= 1.0 + np.finfo(float).eps * rng.choice([-1.0, 1.0], data.A.shape)
        out = prepared(stack).solve(moved)
        statuses.add(out.status)
        dw = np.maximum(dw, np.abs(_violation(out) - _violation(ref)))
        dx = max(dx, float(np.linalg.norm(out.x - ref.x)) / max(1.0, float(np.linalg.norm(ref.x))))
    return dw, dx, statuses


def assert_close(stack: TaskStack, got, ref, what: str, spread=None) -> None:
    """Answer ``got`` equals ``ref``: the same status (or, with ``spread``
    (:func:`rounding_spread`), a status the one-ulp runs give, comparing the values alone
    then); each level's ``‖w_i‖²`` within its allowance (widened to ``SPREAD_FACTOR``
    times the spread) and, where both are optimal, ``x`` within :data:`X_REL`. An
    approximate ``ref`` with an ambiguous rank decision (rounding may flip it, and ``x``
    with it by ``O(1)``) is compared by its status only."""
    d = differences(stack, got, ref)
    flipped = spread is not None and got.status != ref.status and got.status in spread[2]
    assert got.status == ref.status or flipped, (what, d, got.diagnostics, ref.diagnostics)
    if ref.status != "optimal" and ref.diagnostics.ambiguous_levels:
        return
    allowed, dx_allowed = d["allowed"], X_REL
    if spread is not None:
        allowed = np.maximum(allowed, SPREAD_FACTOR * spread[0])
        dx_allowed = max(dx_allowed, SPREAD_FACTOR * spread[1])
    assert np.all(d["dw"] <= allowed), (what, d)
    if not flipped and ref.status == got.status == "optimal":
        assert d["dx"] <= dx_allowed, (what, d)


def assert_certified(stack: TaskStack, out, what: str) -> bool:
    """An ``optimal`` answer passes the certificate (minimum-norm tie-break included);
    whether it was optimal."""
    if out.status != "optimal":
        return False
    report = check_lexicographic(stack, out.x, minimum_norm=True)
    assert report.ok, (what, str(report))
    return True


def check_cold(stack: TaskStack, what: str) -> bool:
    """The cold answer: certified when optimal; on an equality stack, ``reference``'s.
    Whether it was optimal."""
    out = prepared(stack).solve(stack.data)
    if all(t.is_equality for t in stack.tasks):
        assert_close(stack, out, formulations.solve(stack, "reference"), what)
    return assert_certified(stack, out, what)


# ------------------------------------------------------------------ the path exists
def test_the_solver_is_the_compiled_core():
    stack = random_inequality_hierarchy(np.random.default_rng(3), 8, 3)
    solver = has.Prepared(stack.layout,
                          has.FORMULATION.settings(**_OPTIONS, warm_start=False))
    assert isinstance(solver._cpp, core.ActiveSetSolver)
    out = solver.solve(stack.data)
    np.testing.assert_array_equal(out.x, solver._cpp.x)
    assert out.diagnostics.iterations.sum() > 0
    assert formulations.prepare(stack.layout, "hierarchical_active_set",
                                kernel="cpp").solve(stack).x.tolist() == out.x.tolist()


def test_unknown_kernel_is_refused():
    from prioik.formulations.options import validate_options
    for bad in ("fortran", "numba"):
        with pytest.raises(ValueError, match="kernel"):
            validate_options(has.NAME, has.OPTIONS, {"kernel": bad}, 4)


# ------------------------------------------------------------------ the readable paths
@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_equality_families_equal_reference(family):
    rng = np.random.default_rng(460)
    optimal = 0
    for trial in range(12):
        n = int(rng.integers(4, 16))
        k = int(rng.integers(1, 5))
        optimal += check_cold(FAMILIES[family](rng, n, k), f"{family} trial {trial} n={n} k={k}")
    assert optimal >= 6


@pytest.mark.parametrize("family", sorted(INEQUALITY_FAMILIES))
def test_inequality_families_are_certified(family):
    rng = np.random.default_rng(461)
    optimal = 0
    for trial in range(25):
        n = int(rng.integers(3, 20))
        k = int(rng.integers(2, 6))
        optimal += check_cold(INEQUALITY_FAMILIES[family](rng, n, k),
                              f"{family} trial {trial} n={n} k={k}")
    assert optimal >= 20


def test_box_bounded_stacks_are_certified():
    rng = np.random.default_rng(462)
    optimal = 0
    for trial in range(25):
        n = int(rng.integers(3, 24))
        k = int(rng.integers(2, 5))
        optimal += check_cold(box_bounded(rng, n, k, float(rng.choice([0.5, 2.0, 10.0]))),
                              f"box_bounded trial {trial}")
    assert optimal >= 20


@pytest.mark.parametrize("path", SAVED, ids=[p.name for p in SAVED])
def test_saved_stacks_are_certified_and_warm_equals_cold(path):
    """The saved fuzz and adversarial stacks (scales spread up to 1e19): an optimal
    answer is certified; solved twice warm, the answers equal the cold one within the
    solver's own rounding spread where it exceeds the default allowance."""
    stack = load_stack(path)
    cold = prepared(stack).solve(stack.data)
    assert_certified(stack, cold, path.name)
    spread = rounding_spread(stack, cold)
    warm = prepared(stack, warm=True)
    for round_ in range(2):
        assert_close(stack, warm.solve(stack.data), cold, f"{path.name} warm round {round_}",
                     spread)


def test_seeded_random_inequality_stacks_are_certified():
    rng = np.random.default_rng(463)
    optimal = 0
    for trial in range(200):
        n = int(rng.integers(2, 30))
        k = int(rng.integers(2, 7))
        optimal += check_cold(random_inequality_hierarchy(rng, n, k),
                              f"random trial {trial} n={n} k={k}")
    assert optimal >= 180


def drift(stack: TaskStack, rng: np.random.Generator, scale: float) -> TaskStack:
    """``stack`` with its rows, targets and bounds moved by ``scale`` (the same layout:
    a control loop's next step)."""
    levels = []
    for level in stack.levels:
        tasks = []
        for t in level:
            A = t.A + scale * rng.standard_normal(t.A.shape)
            if t.is_equality:
                tasks.append(type(t)(t.name, A, t.b + scale * rng.standard_normal(t.m),
                                     weight=t.weight))
            else:
                lo, up = t.bounds()
                shift = scale * rng.standard_normal(t.m)
                tasks.append(type(t)(t.name, A, lower=lo + shift, upper=up + shift,
                                     weight=t.weight))
        levels.append(tasks)
    return TaskStack(levels)


@pytest.mark.parametrize("family", ["with_inequalities", "random_inequality",
                                    "box_bounded"])
def test_warm_sequences_equal_the_cold_answers(family):
    """A drifting stack solved warm along 30 steps: at every step the cold solver's
    answer and status, certified when optimal."""
    rng = np.random.default_rng(464)
    make = box_bounded if family == "box_bounded" else INEQUALITY_FAMILIES[family]
    for seq in range(6):
        stack = make(rng, int(rng.integers(6, 20)), int(rng.integers(3, 5)))
        warm, cold = prepared(stack, warm=True), prepared(stack)
        for step in range(30):
            stack = drift(stack, rng, 0.01)
            a, b = warm.solve(stack.data), cold.solve(stack.data)
            assert_close(stack, a, b, f"{family} sequence {seq} step {step}")
            assert_certified(stack, a, f"{family} sequence {seq} step {step}")


# ------------------------------------------------------------------ the boundary
def _solver_and_data():
    stack = random_inequality_hierarchy(np.random.default_rng(5), 6, 3)
    settings = has.FORMULATION.settings(**_OPTIONS, warm_start=False)
    return has.Prepared(stack.layout, settings)._cpp, stack.data


@pytest.mark.parametrize("name", ["A", "b", "lower", "upper", "sqrt_weight"])
def test_binding_refuses_wrong_dtype_shape_and_layout(name):
    solver, data = _solver_and_data()
    arrays = {"A": data.A, "b": data.b, "lower": data.lower, "upper": data.upper,
              "sqrt_weight": data.sqrt_weight}
    bad = {"must be float64": arrays[name].astype(np.float32),
           "must have shape": arrays[name][:-1],
           "is empty": arrays[name][:0],
           "must be a float64 numpy array": arrays[name].tolist()}
    bad["is not aligned"] = unaligned(arrays[name])
    if arrays[name].ndim == 2:
        bad["must be C-contiguous"] = np.asfortranarray(arrays[name])
    else:
        bad["must be C-contiguous"] = np.repeat(arrays[name], 2)[::2]
    for why, value in bad.items():
        args = dict(arrays, **{name: value})
        for entry in (solver.solve, solver.equality_first):
            with pytest.raises(CoreInputError, match=f"^{name} {why}"):
                entry(args["A"], args["b"], args["lower"], args["upper"], args["sqrt_weight"])


def test_snapshot_copies_the_last_solve_in_one_array():
    """``snapshot(out)`` writes the last solve's x, res, w2, ranks, over (k each) and
    iterations (k + 1) into one float64 array, the integers exactly; a later solve leaves
    it. A writable float64 array of another length, another dtype, a read-only one or a
    list is refused naming ``out``."""
    solver, data = _solver_and_data()
    n, k = solver.x.size, solver.w2.size
    assert solver.snapshot_size == n + 5 * k + 1
    solver.solve(data.A, data.b, data.lower, data.upper, data.sqrt_weight)
    out = np.empty(solver.snapshot_size)
    solver.snapshot(out)
    parts = np.split(out, np.cumsum([n, k, k, k, k]))
    want = [solver.x, solver.res, solver.w2, solver.ranks[:k], solver.over[:k],
            solver.iterations]
    for got, kernel in zip(parts, want, strict=True):
        np.testing.assert_array_equal(got, kernel)
    kept = out.copy()
    rng = np.random.default_rng(6)
    moved = [data.A + 0.1 * rng.standard_normal(data.A.shape)] + [
        v + 0.1 for v in (data.b, data.lower, data.upper)] + [data.sqrt_weight]
    solver.solve(*moved)
    assert not np.array_equal(solver.x, parts[0])
    np.testing.assert_array_equal(out, kept)
    read_only = np.empty(solver.snapshot_size)
    read_only.setflags(write=False)
    for bad in (np.empty(solver.snapshot_size - 1), np.empty(solver.snapshot_size, np.float32),
                read_only, [0.0] * solver.snapshot_size):
        with pytest.raises(CoreInputError, match="^out "):
            solver.snapshot(bad)


@pytest.mark.parametrize("name, value, message", [
    ("A", np.nan, r"A\[0, 0\] is not finite"), ("A", np.inf, r"A\[0, 0\] is not finite"),
    ("sqrt_weight", 0.0, r"sqrt_weight\[0\] must be finite and > 0"),
    ("sqrt_weight", np.inf, r"sqrt_weight\[0\] must be finite"),
    ("lower", np.nan, r"lower\[0\] is NaN"), ("upper", np.nan, r"upper\[0\] is NaN")])
def test_binding_names_values_it_cannot_read(name, value, message):
    solver, data = _solver_and_data()
    arrays = {"A": data.A.copy(), "b": data.b.copy(), "lower": data.lower.copy(),
              "upper": data.upper.copy(), "sqrt_weight": data.sqrt_weight.copy()}
    arrays[name].flat[0] = value
    # the equality-first try declines what it cannot read; the solve names it
    assert solver.equality_first(arrays["A"], arrays["b"], arrays["lower"], arrays["upper"],
                                 arrays["sqrt_weight"]) == core.ACTIVE_SET_CODES["NOT_TRIED"]
    with pytest.raises(CoreInputError, match=message):
        solver.solve(arrays["A"], arrays["b"], arrays["lower"], arrays["upper"],
                     arrays["sqrt_weight"])


def test_invalid_data_is_named_by_the_stack_check():
    stack = random_inequality_hierarchy(np.random.default_rng(6), 6, 3)
    data = stack.data
    bad = type(data)(data.layout)
    for name in ("A", "b", "lower", "upper", "sqrt_weight"):
        getattr(bad, name)[...] = getattr(data, name)
    bad.A[1, 0] = np.nan
    with pytest.raises(TaskStackError) as solved:
        prepared(stack).solve(bad)
    with pytest.raises(TaskStackError) as checked:
        bad.check()
    assert str(solved.value) == str(checked.value)


def limits_stack(rng: np.random.Generator, n: int, target: np.ndarray, redundant: bool,
                 level_of_box: int) -> TaskStack:
    """A reach of the first coordinates (``target``), joint-limit-like bounds ``|x| ≤
    u`` at ``level_of_box``, a posture below; ``redundant`` puts a level above that
    repeats one row (rank 1 of 2: held box rows below it are not fixed coordinates)."""
    m = target.shape[0]
    A = np.hstack([np.eye(m), 0.3 * rng.standard_normal((m, n - m))])
    u = np.ones(n)
    levels = [[Task("reach", A, target)],
              [Task("posture", np.eye(n), np.zeros(n), weight=0.1)]]
    levels.insert(level_of_box, [Task("limits", np.eye(n), lower=-u, upper=u)])
    if redundant:
        levels.insert(0, [Task("twice", np.eye(n)[[n - 1, n - 1]], [0.2, 0.2])])
    return TaskStack(levels)


@pytest.mark.parametrize("redundant", [False, True])
@pytest.mark.parametrize("level_of_box", [0, 1])
def test_warm_limit_sequences_equal_the_cold_answers(redundant, level_of_box):
    """Targets walking in and out of joint limits, solved warm: rows held and released
    from one step to the next (the equality-first try's held rows, fixed columns or,
    below a redundant level, equalities), the cold answers, certified."""
    rng = np.random.default_rng(465)
    for seq in range(4):
        n = int(rng.integers(4, 10))
        m = int(rng.integers(1, 3))
        walk = np.cumsum(0.25 * rng.standard_normal((40, m)), axis=0)
        first = limits_stack(np.random.default_rng(seq), n, walk[0], redundant, level_of_box)
        warm, cold = prepared(first, warm=True), prepared(first)
        tried = 0
        for step, target in enumerate(walk):
            stack = limits_stack(np.random.default_rng(seq), n, target, redundant,
                                 level_of_box)
            a, b = warm.solve(stack.data), cold.solve(stack.data)
            assert_close(stack, a, b, f"limits sequence {seq} step {step}")
            assert assert_certified(stack, a, f"limits sequence {seq} step {step}")
            tried += a.detail.equality_first
        assert tried > 0


def test_codes_and_flags_are_the_cores():
    codes = core.ACTIVE_SET_CODES
    assert vars(has._codes) == codes
    flags = [value for name, value in codes.items() if name.startswith("FLAG_")]
    assert len(set(flags)) == len(flags)
    assert {value for value, _, _ in has._CERTIFIED_FLAGS} <= set(flags)
    assert len({codes[name] for name in ("NOT_SOLVED", "SOLVED_CLEAN", "SOLVED_INFEASIBLE",
                                          "SOLVED_OTHER", "NOT_TRIED")}) == 5


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("name", ["panda", "talos", "g1", "go2"])
def test_closed_loop_robot_runs_are_certified(name, mode):
    """A limb reaching beyond its workspace with joint limits as bounds at level 0 and
    contacts at level 1 (tests/test_limits_on_robots.py's stack), closed loop for 40
    steps driven by the warm solver's answers: the cold solver's answer at every step,
    certified when optimal (most steps)."""
    pin = pytest.importorskip("pinocchio")
    from prioik.robots import KinematicState, TaskWriter, load
    contacts, limb = {"panda": ([], "tcp"), "talos": (["left_foot", "right_foot"], "right_hand"),
                      "g1": (["left_foot", "right_foot"], "right_hand"),
                      "go2": (["front_right_foot", "rear_left_foot", "rear_right_foot"],
                              "front_left_foot")}[name]
    robot = load(name)
    accel = mode == "acceleration"
    gain = (100.0, 20.0) if accel else 10.0
    w = TaskWriter(robot, mode)
    w.add_joint_limits("limits", form="bounds", dt=0.01, level=0,
                       **({"horizon": 0.1} if accel else {}))
    for c in contacts:
        w.add_contact(c, c, gain=gain, level=1)
    w.add_frame_position("reach", limb, gain=gain)
    w.add_posture("posture", gain=(10.0, 6.0) if accel else 1.0)
    solvers = {warm: formulations.prepare(w.layout, has.NAME, **_OPTIONS, warm_start=warm)
               for warm in (True, False)}
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    start = KinematicState(robot, q, v)
    places = {c: start.placement(c).copy() for c in contacts}
    target = start.placement(limb).translation + np.array([0.4, -0.3, 0.5])
    data = robot.data()
    optimal = 0
    for step in range(40):
        state = KinematicState(robot, q, v, data, drift=accel)
        for c in contacts:
            w.contact(state, c, places[c])
        w.frame_position(state, "reach", target)
        w.joint_limits(state, "limits")
        w.posture(state, "posture", robot.q0)
        rows = w.targets(state)
        stack = rows.as_stack()
        out = {warm: s.solve(rows) for warm, s in solvers.items()}
        assert_close(stack, out[True], out[False], f"{name} {mode} step {step}")
        optimal += assert_certified(stack, out[True], f"{name} {mode} step {step}")
        x = out[True].x
        v = v + x * 0.01 if accel else x
        q = pin.integrate(robot.model, q, v * 0.01)
    assert optimal >= 30, optimal
