"""The C++ active set (``prioik._core.ActiveSetSolver``, ``kernel="cpp"``) against the
numba kernel, the oracle while both exist: the same statuses, each level's ``‖w_i‖²``
within :data:`W2_REL` relative (plus :func:`w2_floor` where it is ~0), ``x`` within
:data:`X_REL` where the answer is certified optimal by both, the same flags of the
answer's ``info``, over the shared families, the saved fuzz and adversarial stacks,
seeded random inequality hierarchies and warm sequences of drifting stacks.

The numba kernel rounds with fast math, the C++ one with IEEE arithmetic: the answers
agree to rounding, not to the bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import prioik._core as core

from prioik.formulations import hierarchical_active_set as has
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import Task, TaskStack, TaskStackError
from prioik.hierarchy.families import (FAMILIES, INEQUALITY_FAMILIES, box_bounded,
                                       random_inequality_hierarchy)
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

#: the factor over numba's own rounding spread (:func:`rounding_spread`) within which the
#: answers on the saved ill-conditioned stacks must agree
SPREAD_FACTOR = 4.0

_OPTIONS = {"rcond": 1e-9, "primal_tol": 1e-10, "dual_tol": 1e-12, "max_iter": 500}


def prepared(stack: TaskStack, kernel: str, warm: bool = False) -> has.Prepared:
    return has.Prepared(stack.layout, dict(_OPTIONS, warm_start=warm, kernel=kernel))


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


def differences(stack: TaskStack, cpp, ref) -> dict:
    """How far the C++ answer is from the numba one: each level's ``‖w_i‖²`` difference,
    the allowance of :data:`W2_REL` and :func:`w2_floor`, ``x``'s relative distance, and
    the statuses and the answer's ``info`` flags side by side."""
    floor = w2_floor(stack, ref.x)
    w_ref = np.sqrt(np.maximum(ref.info["level_violation"], 0.0))
    allowed = W2_REL * np.maximum(ref.info["level_violation"], cpp.info["level_violation"]) \
        + floor * (floor + 2.0 * w_ref)
    dw = np.abs(cpp.info["level_violation"] - ref.info["level_violation"])
    dx = float(np.linalg.norm(cpp.x - ref.x)) / max(1.0, float(np.linalg.norm(ref.x)))
    keys = ("infeasible_levels", "capped_levels", "ambiguous_levels", "path_certified",
            "equality_first")
    return {"status": (cpp.status, ref.status), "dw": dw, "allowed": allowed, "dx": dx,
            "w2_ratio": float(np.max(dw / np.maximum(allowed, 1e-300), initial=0.0)),
            "info": {k: (cpp.info.get(k), ref.info.get(k)) for k in keys}}


def rounding_spread(stack: TaskStack, ref, draws: int = 2) -> tuple[np.ndarray, float, set]:
    """How far the numba kernel's own answer moves when ``A`` moves by one ulp (each
    entry times ``1 ± eps``, ``draws`` seeded draws): each level's largest ``‖w_i‖²``
    change, ``x``'s largest relative change, and the statuses it gives (a stack at the
    edge of the certificate's tolerance is certified or not by rounding). Two kernels
    that round differently cannot agree closer than this on an ill-conditioned stack."""
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
        out = prepared(stack, "numba").solve(moved)
        statuses.add(out.status)
        dw = np.maximum(dw, np.abs(out.info["level_violation"] - ref.info["level_violation"]))
        dx = max(dx, float(np.linalg.norm(out.x - ref.x)) / max(1.0, float(np.linalg.norm(ref.x))))
    return dw, dx, statuses


#: the ``info`` keys that tell the path an answer took (the equality-first try's guesses
#: and whether the certificate ran), not the answer
PATH_KEYS = ("equality_first", "path_certified")


def assert_same(stack: TaskStack, cpp, ref, what: str, spread=None, path: bool = True) -> None:
    """The C++ answer ``cpp`` equals the numba answer ``ref``: the same status, rank
    profile and ``info`` flags; each level's ``‖w_i‖²`` within its allowance and, where
    ``ref`` is optimal, ``x`` within :data:`X_REL`. ``spread`` (:func:`rounding_spread`)
    widens both to ``SPREAD_FACTOR`` times numba's own change under a one-ulp change of
    ``A``, and takes a status it gives there (the certificate's verdict on a stack at
    the edge of its tolerance), comparing the values alone then. An approximate answer
    with an ambiguous rank decision (a pivot within
    ``AMBIGUITY`` of its threshold: rounding may flip it, and ``x`` with it by ``O(1)``)
    is compared by its status and its ambiguous levels only. ``path=False``: the
    :data:`PATH_KEYS` and the rank profile may differ (a heuristic's rounding-level
    decision, e.g. the equality-first try releasing a row whose multiplier is
    wrong-signed at the 1e-14 floor, takes another sequence of guesses to the same
    answer)."""
    d = differences(stack, cpp, ref)
    flipped = spread is not None and cpp.status != ref.status and cpp.status in spread[2]
    assert cpp.status == ref.status or flipped, (what, d)
    if ref.status != "optimal" and ref.info.get("ambiguous_levels"):
        assert cpp.info.get("ambiguous_levels") == ref.info.get("ambiguous_levels"), (what, d)
        return
    allowed, dx_allowed = d["allowed"], X_REL
    if spread is not None:
        allowed = np.maximum(allowed, SPREAD_FACTOR * spread[0])
        dx_allowed = max(dx_allowed, SPREAD_FACTOR * spread[1])
    assert np.all(d["dw"] <= allowed), (what, d, cpp.info["level_violation"],
                                         ref.info["level_violation"])
    if flipped:
        return          # certified or not by rounding: the values are what can agree
    if ref.status == "optimal":
        assert d["dx"] <= dx_allowed, (what, d)
    for key, (a, b) in d["info"].items():
        assert a == b or (not path and key in PATH_KEYS), (what, key, a, b)
    if path:        # the rows each level fixed: the equality-first try counts its own
        np.testing.assert_array_equal(cpp.info["rank_profile"], ref.info["rank_profile"],
                                      err_msg=what)


def compare_cold(stack: TaskStack, what: str) -> None:
    assert_same(stack, prepared(stack, "cpp").solve(stack.data),
                prepared(stack, "numba").solve(stack.data), what)


# ------------------------------------------------------------------ the path exists
def test_cpp_kernel_is_the_compiled_core():
    stack = random_inequality_hierarchy(np.random.default_rng(3), 8, 3)
    solver = prepared(stack, "cpp")
    assert isinstance(solver._cpp, core.ActiveSetSolver)
    out = solver.solve(stack.data)
    np.testing.assert_array_equal(out.x, solver._cpp.x)
    assert out.info["iterations"].sum() > 0


def test_unknown_kernel_is_refused():
    from prioik.formulations.options import validate_options
    with pytest.raises(ValueError, match="kernel"):
        validate_options(has.NAME, has.OPTIONS, {"kernel": "fortran"}, 4)


# ------------------------------------------------------------------ the oracle
@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_equality_families_match_numba(family):
    rng = np.random.default_rng(460)
    for trial in range(12):
        n = int(rng.integers(4, 16))
        k = int(rng.integers(1, 5))
        compare_cold(FAMILIES[family](rng, n, k), f"{family} trial {trial} n={n} k={k}")


@pytest.mark.parametrize("family", sorted(INEQUALITY_FAMILIES))
def test_inequality_families_match_numba(family):
    rng = np.random.default_rng(461)
    for trial in range(25):
        n = int(rng.integers(3, 20))
        k = int(rng.integers(2, 6))
        compare_cold(INEQUALITY_FAMILIES[family](rng, n, k),
                     f"{family} trial {trial} n={n} k={k}")


def test_box_bounded_stacks_match_numba():
    rng = np.random.default_rng(462)
    for trial in range(25):
        n = int(rng.integers(3, 24))
        k = int(rng.integers(2, 5))
        compare_cold(box_bounded(rng, n, k, float(rng.choice([0.5, 2.0, 10.0]))),
                     f"box_bounded trial {trial}")


@pytest.mark.parametrize("path", SAVED, ids=[p.name for p in SAVED])
def test_saved_stacks_match_numba(path):
    """The saved fuzz and adversarial stacks (scales spread up to 1e19): within numba's
    own rounding spread where it exceeds the default allowance."""
    stack = load_stack(path)
    ref = prepared(stack, "numba").solve(stack.data)
    spread = rounding_spread(stack, ref)
    assert_same(stack, prepared(stack, "cpp").solve(stack.data), ref, path.name, spread)
    # and solved twice warm (the second solve warm-started from the first's answer)
    warm_cpp, warm_ref = prepared(stack, "cpp", warm=True), prepared(stack, "numba", warm=True)
    for round_ in range(2):
        assert_same(stack, warm_cpp.solve(stack.data), warm_ref.solve(stack.data),
                    f"{path.name} warm round {round_}", spread)


def test_seeded_random_inequality_stacks_match_numba():
    rng = np.random.default_rng(463)
    for trial in range(200):
        n = int(rng.integers(2, 30))
        k = int(rng.integers(2, 7))
        compare_cold(random_inequality_hierarchy(rng, n, k), f"random trial {trial} n={n} k={k}")


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
def test_warm_sequences_match_numba(family):
    """A drifting stack solved warm along 30 steps by each kernel: the same answer,
    status, and equality-first and iteration counts at every step."""
    rng = np.random.default_rng(464)
    make = box_bounded if family == "box_bounded" else INEQUALITY_FAMILIES[family]
    for seq in range(6):
        stack = make(rng, int(rng.integers(6, 20)), int(rng.integers(3, 5)))
        cpp, ref = prepared(stack, "cpp", warm=True), prepared(stack, "numba", warm=True)
        for step in range(30):
            stack = drift(stack, rng, 0.01)
            a, b = cpp.solve(stack.data), ref.solve(stack.data)
            assert_same(stack, a, b, f"{family} sequence {seq} step {step}")
            assert a.info["equality_first"] == b.info["equality_first"]


# ------------------------------------------------------------------ the boundary
def _solver_and_data():
    stack = random_inequality_hierarchy(np.random.default_rng(5), 6, 3)
    return prepared(stack, "cpp")._cpp, stack.data


@pytest.mark.parametrize("name", ["A", "b", "lower", "upper", "sqrt_weight"])
def test_binding_refuses_wrong_dtype_shape_and_layout(name):
    solver, data = _solver_and_data()
    arrays = {"A": data.A, "b": data.b, "lower": data.lower, "upper": data.upper,
              "sqrt_weight": data.sqrt_weight}
    bad = {"must be float64": arrays[name].astype(np.float32),
           "must have shape": arrays[name][:-1],
           "is empty": arrays[name][:0],
           "must be a float64 numpy array": arrays[name].tolist()}
    if arrays[name].ndim == 2:
        bad["must be C-contiguous"] = np.asfortranarray(arrays[name])
    else:
        bad["must be C-contiguous"] = np.repeat(arrays[name], 2)[::2]
    for why, value in bad.items():
        args = dict(arrays, **{name: value})
        for entry in (solver.solve, solver.equality_first):
            with pytest.raises(CoreInputError, match=f"^{name} {why}"):
                entry(args["A"], args["b"], args["lower"], args["upper"], args["sqrt_weight"])


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
    errors = []
    for kernel in ("numba", "cpp"):
        with pytest.raises(TaskStackError) as info:
            prepared(stack, kernel).solve(bad)
        errors.append(str(info.value))
    assert errors[0] == errors[1]


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
def test_warm_limit_sequences_match_numba(redundant, level_of_box):
    """Targets walking in and out of joint limits, solved warm: rows held and released
    from one step to the next (the equality-first try's held rows, fixed columns or,
    below a redundant level, equalities), the same answers and the same path as numba."""
    rng = np.random.default_rng(465)
    for seq in range(4):
        n = int(rng.integers(4, 10))
        m = int(rng.integers(1, 3))
        walk = np.cumsum(0.25 * rng.standard_normal((40, m)), axis=0)
        first = limits_stack(np.random.default_rng(seq), n, walk[0], redundant, level_of_box)
        cpp, ref = prepared(first, "cpp", warm=True), prepared(first, "numba", warm=True)
        tried = 0
        for step, target in enumerate(walk):
            stack = limits_stack(np.random.default_rng(seq), n, target, redundant,
                                 level_of_box)
            a, b = cpp.solve(stack.data), ref.solve(stack.data)
            assert_same(stack, a, b, f"limits sequence {seq} step {step}")
            tried += a.info["equality_first"]
        assert tried > 0


def test_codes_and_flags_are_the_numba_kernels():
    from prioik.formulations import _active_set_kernel as numba_kernel
    assert core.ACTIVE_SET_CODES
    for name, value in core.ACTIVE_SET_CODES.items():
        assert getattr(numba_kernel, name) == value, name


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("name", ["panda", "talos", "g1", "go2"])
def test_closed_loop_robot_runs_match_numba(name, mode):
    """A limb reaching beyond its workspace with joint limits as bounds at level 0 and
    contacts at level 1 (tests/test_limits_on_robots.py's stack), closed loop for 40
    steps driven by the numba kernel's answers: the C++ kernel's warm and cold answers
    equal numba's at every step (by the paths of :data:`PATH_KEYS` at most a few
    steps apart: TALOS at velocity level, step 1, is the equality-first try's fifth guess
    in C++, numba's runs out of guesses on the rounding of a multiplier at the 1e-14
    floor and takes the active set to the same answer)."""
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
    solvers = {(kernel, warm): has.Prepared(w.layout, dict(_OPTIONS, warm_start=warm,
                                                           kernel=kernel))
               for kernel in ("cpp", "numba") for warm in (True, False)}
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    start = KinematicState(robot, q, v)
    places = {c: start.placement(c).copy() for c in contacts}
    target = start.placement(limb).translation + np.array([0.4, -0.3, 0.5])
    data = robot.data()
    paths = 0
    for step in range(40):
        state = KinematicState(robot, q, v, data, drift=accel)
        for c in contacts:
            w.contact(state, c, places[c])
        w.frame_position(state, "reach", target)
        w.joint_limits(state, "limits")
        w.posture(state, "posture", robot.q0)
        rows = w.targets(state)
        stack = rows.as_stack()
        out = {key: s.solve(rows) for key, s in solvers.items()}
        for warm in (True, False):
            assert_same(stack, out["cpp", warm], out["numba", warm],
                        f"{name} {mode} step {step} warm={warm}", path=False)
            paths += any(out["cpp", warm].info.get(k) != out["numba", warm].info.get(k)
                         for k in PATH_KEYS)
        x = out["numba", True].x
        v = v + x * 0.01 if accel else x
        q = pin.integrate(robot.model, q, v * 0.01)
    assert paths <= 4, paths


def test_the_kernels_benchmark_times_both_kernels_on_the_same_stacks():
    """benchmarks/active_set_kernels.py: per stack a time of each kernel (interleaved
    blocks), the row giving both means and their ratio."""
    from prioik.benchmarks.active_set_kernels import interleaved, random_row
    calls = []
    t = interleaved([(lambda: calls.append("cpp"), lambda: calls.append("numba"))], 3)
    assert t.shape == (1, 2) and np.all(t > 0)
    assert calls.count("cpp") == calls.count("numba") == 15
    assert calls[:5] == ["cpp"] * 5 and calls[10:15] == ["numba"] * 5   # order alternates
    cells = random_row(2, 2).strip("| ").split(" | ")
    cpp_us, numba_us, ratio = float(cells[1]), float(cells[2]), float(cells[3])
    assert cpp_us > 0 and numba_us > 0 and ratio == pytest.approx(cpp_us / numba_us, rel=0.05)
