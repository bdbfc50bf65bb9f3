"""The C++ row writers (``prioik._core.rows``, what :mod:`robots.rows` and
:mod:`robots.tasks` call) against the same formulas in plain Python (``tests/rows_reference.py``,
the readable
reference): every writer's rows equal within 1e-13 relative, row for
row, on random states of the Panda, G1 and TALOS at velocity and acceleration level;
``log3`` near θ = 0 and θ = π; the bound and activation formulas on joints inside,
at and past their limits; a closed loop (a Panda reach with limits: docs/usage.md's,
undamped and with a posture level) gives
the same trajectory with both; bad inputs at the binding boundary raise
:class:`~prioik.formulations.base.CoreInputError` naming the array."""

import numpy as np
import pinocchio as pin
import pytest

import prioik
from prioik import _core
from prioik.formulations.base import CoreInputError
from prioik.robots import KinematicState, TaskWriter, g1, panda, talos
from prioik.robots import rows as rows_module
from prioik.robots import tasks as tasks_module
from prioik.robots.kinds import com, frame, joints, regions
from tests import rows_reference as reference_rows

#: the modules that call the compiled row writers (``_k``)
WRITER_MODULES = (rows_module, frame, com, joints, regions)

cpp_rows = _core.rows

#: row for row: |C++ − reference| ≤ RTOL · the row's largest magnitude
RTOL = 1e-13

ROBOTS = {"panda": panda, "g1": g1, "talos": talos}


@pytest.fixture(scope="module")
def robots():
    return {name: make() for name, make in ROBOTS.items()}


@pytest.fixture
def with_reference(monkeypatch):
    """Run :mod:`robots.rows`, the task kinds and :mod:`robots.tasks` on the plain-Python
    reference."""
    def switch():
        for module in WRITER_MODULES:
            monkeypatch.setattr(module, "_k", reference_rows)
        monkeypatch.setattr(tasks_module, "_state_is_valid", reference_rows.state_is_valid)
    return switch


def worst_row_difference(a, b) -> float:
    """The largest ``|a − b| / max|row|`` over the rows of ``a`` and ``b`` (1-D: one row
    per entry); entries that are not finite must be the same."""
    a = np.atleast_2d(np.asarray(a, dtype=float).T).T if np.ndim(a) == 1 else np.asarray(a)
    b = np.atleast_2d(np.asarray(b, dtype=float).T).T if np.ndim(b) == 1 else np.asarray(b)
    assert a.shape == b.shape
    finite = np.isfinite(a)
    assert np.array_equal(finite, np.isfinite(b)), "non-finite entries differ"
    assert np.array_equal(a[~finite], b[~finite]), "infinite entries differ"
    a0, b0 = np.where(finite, a, 0.0), np.where(finite, b, 0.0)
    scale = np.maximum(np.abs(a0).max(axis=1, keepdims=True),
                       np.abs(b0).max(axis=1, keepdims=True))
    diff = np.abs(a0 - b0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(diff == 0.0, 0.0, diff / scale)
    return float(rel.max(initial=0.0))


def test_the_writers_call_the_cpp_core():
    """robots/ runs on prioik._core.rows, not on the reference."""
    assert all(module._k is cpp_rows for module in WRITER_MODULES)
    assert tasks_module._state_is_valid is cpp_rows.state_is_valid


# ----------------------------------------------------------- whole writers
def _random_state(robot, rng, drift):
    """A state with the actuated joints spread over their limits and a little past them
    (activation margins and bounds on every branch), a random velocity."""
    q = robot.q0.copy()
    lo, hi, _ = robot.joint_limits()
    iq = robot.actuated_q_index()
    for k, i in enumerate(iq):
        if i < 0:
            continue
        if np.isfinite(lo[k]) and np.isfinite(hi[k]):
            q[i] = rng.uniform(lo[k] - 0.05, hi[k] + 0.05) if rng.random() < 0.5 else (
                rng.choice([lo[k], hi[k]]) + rng.uniform(-0.12, 0.12))
        else:
            q[i] += rng.uniform(-0.5, 0.5)
    return KinematicState(robot, q, rng.normal(size=robot.nv), drift=drift)


def _body_frames(robot, rng, count):
    names = [f.name for f in robot.model.frames
             if f.type == pin.FrameType.BODY and f.parentJoint > 0]
    return list(rng.choice(names, size=count, replace=False))


def _declare(robot, mode, rng):
    """A writer with every task kind: frame position, point, orientation, pose, contact,
    CoM, posture, both joint-limit forms, a frame region and a CoM region."""
    accel = mode == "acceleration"
    gain = (lambda: (float(rng.uniform(1, 50)), float(rng.uniform(1, 20)))) if accel else (
        lambda: float(rng.uniform(1, 50)))
    f = _body_frames(robot, rng, 5)
    w = TaskWriter(robot, mode)
    w.add_joint_limits("limit_bounds", form="bounds", dt=0.002, level=0,
                       horizon=0.05 if accel else None)
    w.add_frame_region("region", f[0], rng.normal(size=(2, 3)), lower=[-0.3, -np.inf],
                       upper=[0.4, 0.2], dt=0.002, horizon=0.05, offset=[0.01, 0.02, 0.03],
                       level=0)
    w.add_com_region("com_region", rng.normal(size=(3, 3)), lower=-0.1, upper=0.1,
                     dt=0.002, level=0)
    w.add_joint_limits("limit_rows", form="activation", level=1)
    w.add_contact("contact", f[1], gain=gain(), level=1)
    w.add_com("com", gain=gain(), axes=(0, 1, 2), level=2)
    w.add_frame_position("position", f[2], gain=gain(), level=2)
    w.add_point("point", f[3], rng.normal(size=3) * 0.1, gain=gain(), level=2)
    w.add_frame_orientation("orientation", f[4], gain=gain(), level=3)
    w.add_frame_pose("pose", f[2], gain=gain(), level=3)
    w.add_posture("posture", gain=gain(), level=4)
    return w


def _references(robot, rng):
    def rot():
        return pin.exp3(rng.normal(size=3) * rng.uniform(0, 3))
    return {"x": rng.normal(size=(4, 3)), "rates": rng.normal(size=(8, 3)),
            "R": [rot() for _ in range(3)], "C": rng.normal(size=(3, 3)) * 0.1,
            "q_ref": _random_state(robot, rng, False).q,
            "region": rng.normal(size=(2, 3))}


def _write(w, state, refs):
    """Every task written at ``state``; returns the active activation rows."""
    x, r, R = refs["x"], refs["rates"], refs["R"]
    w.joint_limits(state, "limit_bounds")
    w.frame_region(state, "region")
    w.com_region(state, "com_region", lower=refs["C"][0], upper=refs["C"][0] + 0.2)
    active = w.joint_limits(state, "limit_rows")
    w.contact(state, "contact", translation=x[0], rotation=R[0])
    w.com(state, "com", x[1], r[0], r[1])
    w.frame_position(state, "position", x[2], r[2], r[3])
    w.point(state, "point", x[3])
    w.frame_orientation(state, "orientation", R[1], r[4], r[5])
    w.frame_pose(state, "pose", x[2], R[2], r[6], r[7], r[4], r[5])
    w.posture(state, "posture", refs["q_ref"])
    w.targets(state)
    return active


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_every_writer_equals_the_reference(robots, with_reference, name, mode):
    """The C++ writers and the reference on the same states and references, each task's
    rows compared."""
    robot = robots[name]
    cases = []
    for seed in range(12):
        srng = np.random.default_rng([seed, len(name), mode == "velocity"])
        state = _random_state(robot, srng, drift=mode == "acceleration")
        cases.append((state, _references(robot, srng)))
    cpp = _declare(robot, mode, np.random.default_rng(1))
    cpp_out = [(_write(cpp, s, r), _snapshot(cpp)) for s, r in cases]
    with_reference()
    oracle = _declare(robot, mode, np.random.default_rng(1))
    reference_out = [(_write(oracle, s, r), _snapshot(oracle)) for s, r in cases]
    for kernel in ("frame_rows", "position_rows", "position_target_rows", "com_rows",
                   "posture_error", "bounds_at", "activation_at", "region_rows"):
        assert kernel in reference_rows.CALLED, f"the reference never ran {kernel}"
    worst = 0.0
    layout = cpp.layout
    for (active_c, c), (active_n, n) in zip(cpp_out, reference_out, strict=False):
        assert active_c == active_n
        for task in cpp.tasks():
            sl = layout.task_slice(task)
            for key in c:
                a, b = c[key], n[key]
                part = a[sl] if a.ndim == 1 or key == "A" else a[:, sl].T
                ref = b[sl] if b.ndim == 1 or key == "A" else b[:, sl].T
                d = worst_row_difference(part, ref)
                assert d <= RTOL, (task, key, d)
                worst = max(worst, d)
    active = [a for a, _ in cpp_out]
    assert max(active) > 0, "no activation row was active: the states miss the margins"
    print(f"\n{name} {mode}: {len(cases)} states x {len(cpp.tasks())} tasks, worst "
          f"relative row difference {worst:.1e}")


def _snapshot(w):
    d = w.data
    return {"A": d.A.copy(), "b": d.b.copy(), "lower": d.lower.copy(),
            "upper": d.upper.copy(), "Q": w._Q.copy()}


# ------------------------------------------------------------------ log3
def _rotations_near(theta, rng, count):
    out = []
    for _ in range(count):
        u = rng.normal(size=3)
        out.append(pin.exp3(theta * u / np.linalg.norm(u)))
    for axis in np.eye(3):                # the near-π branches by the largest diagonal
        out.append(pin.exp3(theta * axis))
        out.append(pin.exp3(theta * (axis + 1e-3 * rng.normal(size=3))))
    return out


THETAS = [0.0, 1e-14, 1e-9, 1e-6, 5e-5, 9.99999e-5, 1e-4, 1.000001e-4, 0.3, 1.0, 2.5,
          np.pi - 2e-3, np.pi - 1.000001e-3, np.pi - 1e-3, np.pi - 9.99e-4, np.pi - 1e-6,
          np.pi - 1e-10, np.pi]


@pytest.mark.parametrize("theta", THETAS)
def test_log3_equals_the_reference_near_zero_and_pi(theta):
    rng = np.random.default_rng(int(theta * 1e6) % 2**32)
    worst = 0.0
    for R in _rotations_near(theta, rng, 20):
        a, b = np.full(5, 7.0), np.full(5, 7.0)
        cpp_rows.log3(R, a, 1)
        reference_rows.log3(R, b, 1)
        assert a[0] == 7.0 and a[4] == 7.0
        worst = max(worst, worst_row_difference(a[None, 1:4], b[None, 1:4]))
        # and what it is: pinocchio's log up to the sign ambiguity at π
        ref = pin.log3(R)
        if theta < np.pi - 1e-3:
            assert np.allclose(a[1:4], ref, rtol=1e-9, atol=1e-12)
        else:
            assert np.isclose(np.linalg.norm(a[1:4]), np.linalg.norm(ref), atol=1e-6)
    assert worst <= RTOL


# ------------------------------------------- the bound and activation formulas
def _joint_cases(rng, na=40):
    lo = rng.uniform(-2, 0, na)
    hi = lo + rng.uniform(0.2, 3, na)
    lo[::7], hi[::7] = -np.inf, np.inf                  # continuous joints
    vmax = rng.uniform(0.5, 3, na)
    vmax[::5] = np.inf
    # inside, in the margins, at and past the limits
    flo, fhi = np.where(np.isfinite(lo), lo, -2.0), np.where(np.isfinite(hi), hi, 2.0)
    qa = np.where(rng.random(na) < 0.5, rng.uniform(flo - 0.3, fhi + 0.3),
                  np.where(rng.random(na) < 0.5, flo, fhi) + rng.uniform(-0.1, 0.1, na))
    va = rng.normal(size=na) * 3
    return qa, va, lo, hi, vmax


@pytest.mark.parametrize("seed", range(20))
def test_bound_formulas_equal_the_reference(seed):
    rng = np.random.default_rng(seed)
    qa, va, lo, hi, vmax = _joint_cases(rng)
    na, s = qa.size, 3
    for T, dt in ((0.05, 0.002), (0.002, 0.002), (0.5, 0.01)):
        for position in (True, False):
            for velocity in (True, False):
                out = []
                for mod in (cpp_rows, reference_rows):
                    lower, upper = np.full(na + 5, 9.0), np.full(na + 5, 9.0)
                    mod.acceleration_bounds(lower, upper, s, qa, va, lo, hi, vmax, T, dt,
                                            position, velocity)
                    l2, u2 = np.full(na + 5, 9.0), np.full(na + 5, 9.0)
                    mod.velocity_bounds(l2, u2, s, qa, lo, hi, vmax, T, position, velocity)
                    out.append(np.stack([lower, upper, l2, u2]))
                assert worst_row_difference(out[0].T, out[1].T) <= RTOL


@pytest.mark.parametrize("seed", range(10))
def test_activation_rows_equal_the_reference(seed):
    rng = np.random.default_rng(seed)
    qa, _, lo, hi, _ = _joint_cases(rng)
    width = np.where(np.isfinite(lo) & np.isfinite(hi), np.minimum(0.1, 0.25 * (hi - lo)), 1.0)
    na, m, nb = qa.size, qa.size + 4, 6
    out = []
    for mod in (cpp_rows, reference_rows):
        A, Q = np.full((m, nb + na), 5.0), np.full((6, m), 5.0)
        active = mod.limit_activation_rows(A, Q, 2, nb, qa, lo, hi, width, 2500.0, 100.0)
        out.append((active, A, Q))
    assert out[0][0] == out[1][0] > 0
    assert np.array_equal(out[0][1], out[1][1])
    assert worst_row_difference(out[0][2], out[1][2]) <= RTOL


def test_state_is_valid_equals_the_reference(robots):
    robot = robots["g1"]
    unit = robot.state_sizes()[3]
    assert unit.size == 2
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    cases = [(q, v)]
    for i, value in ((0, np.nan), (5, np.inf), (3, 2.0), (7, 10.0)):
        bad = q.copy()
        bad[i] = value
        cases.append((bad, v))
    cases.append((q, np.full(robot.nv, -np.inf)))
    verdicts = [(cpp_rows.state_is_valid(a, b, unit, 1e-6),
                 reference_rows.state_is_valid(a, b, unit, 1e-6)) for a, b in cases]
    assert [c for c, _ in verdicts] == [n for _, n in verdicts]
    assert [c for c, _ in verdicts] == [True, False, False, False, True, False]


# --------------------------------------------------------- the closed loop
def _readme_loop(robot, steps):
    rows = TaskWriter(robot, "velocity")
    rows.add_joint_limits("limits", form="bounds", dt=0.002, level=0)
    rows.add_frame_position("hand", "panda_hand", gain=10.0, level=1)
    rows.add_posture("posture", gain=1.0, level=2)
    solver = prioik.prepare(rows.layout, "hierarchical_active_set")
    q, dt = robot.q0.copy(), 0.002
    data = robot.model.createData()
    trajectory, at_bound = [], 0
    target = np.array([0.9, 0.3, 0.4])
    for _ in range(steps):
        state = KinematicState(robot, q, np.zeros(robot.nv), data, drift=False)
        rows.joint_limits(state, "limits")
        rows.frame_position(state, "hand", target)
        rows.posture(state, "posture", robot.q0)
        sol = solver.solve(rows.targets(state))
        d = rows.data
        sl = rows.layout.task_slice("limits")
        arm = sol.x[:7]                   # the arm's joints at a (non-zero) bound
        at_bound += int(np.any((np.abs(arm - d.upper[sl][:7]) <= 1e-9)
                               | (np.abs(arm - d.lower[sl][:7]) <= 1e-9)))
        q = pin.integrate(robot.model, q, sol.x * dt)
        trajectory.append(q)
    return np.array(trajectory), at_bound


def test_closed_loop_trajectory_equals_the_reference(robots, with_reference):
    """A Panda reach with limits (docs/usage.md's, undamped, a posture level), 300 steps,
    on each path."""
    robot = robots["panda"]
    cpp, at_bound = _readme_loop(robot, 300)
    with_reference()
    oracle, _ = _readme_loop(robot, 300)
    assert at_bound > 0, "no step held an arm joint at a limit bound"
    worst = float(np.abs(cpp - oracle).max())
    print(f"\nclosed loop: 300 steps, {at_bound} with an arm joint at a bound, "
          f"max |Δq| {worst:.1e}")
    assert worst <= 1e-12


# ------------------------------------------------------- the binding boundary
@pytest.fixture(scope="module")
def frame_call(robots):
    """A valid frame_rows call's arguments (a dict, by name) on the G1."""
    robot = robots["g1"]
    w = TaskWriter(robot, "acceleration")
    w.add_frame_pose("pose", "left_foot", gain=(1.0, 1.0))
    state = KinematicState(robot, robot.q0, np.zeros(robot.nv))
    task = w.task("pose")
    _, args = task._frame_args(state)
    names = ("A", "Q", "J", "t", "R", "spec", "geo", "aj", "vj")
    call = dict(zip(names, args, strict=False))
    call.update(x=np.zeros(3), xd=np.zeros(3), xdd=np.zeros(3), Rstar=np.eye(3),
                w=np.zeros(3), wd=np.zeros(3))
    cpp_rows.frame_rows(**call)                   # valid as given
    return call


@pytest.mark.parametrize("name, value, words", [
    ("A", lambda a: a.astype(np.float32), "A must be float64"),
    ("A", lambda a: a.tolist(), "A must be a writable float64 numpy array"),
    ("A", lambda a: _read_only(a), "A must be a writable"),
    ("Q", lambda a: a[:5], "Q must have shape (6, "),
    ("J", lambda a: a[:, :-1], "J must have shape (6, "),
    ("J", lambda a: a.ravel(), "J must have 2 dimensions"),
    ("t", lambda a: a[:2], "t must have 3 entries"),
    ("R", lambda a: np.zeros((3, 0)), "R must have shape (3, 3)"),
    ("spec", lambda a: a.astype(np.float64), "spec must be int64"),
    ("spec", lambda a: np.array([0, 9, 1], dtype=np.int64), "spec[1] = 9"),
    ("spec", lambda a: np.r_[a, 10_000].astype(np.int64), "is not an index of A's columns"),
    ("spec", lambda a: np.r_[10_000, a[1:]].astype(np.int64), "outside A's"),
    ("spec", lambda a: np.r_[a[:3], -1].astype(np.int64), "is not an index of A's columns"),
    ("spec", lambda a: np.zeros(0, dtype=np.int64), "spec must hold at least 3"),
    ("geo", lambda a: a[:4], "geo must have shape (5, 3)"),
    ("vj", lambda a: np.zeros(5), "vj must have 6 entries"),
    ("x", lambda a: np.zeros(0), "x must have 3 entries"),
    ("x", lambda a: None, "x must be a float64 numpy array, got NoneType"),
    ("Rstar", lambda a: np.eye(3, dtype=np.int64), "Rstar must be float64"),
])
def test_frame_rows_bad_input_names_the_array(frame_call, name, value, words):
    call = dict(frame_call)
    call[name] = value(call[name])
    with pytest.raises(CoreInputError) as err:
        cpp_rows.frame_rows(**call)
    assert words in str(err.value)


def _read_only(a):
    b = a.copy()
    b.setflags(write=False)
    return b


def test_strided_views_are_read_as_they_are(frame_call):
    """pinocchio's column-major matrices and views with steps give the same rows as
    contiguous copies."""
    call = dict(frame_call)
    call["Rstar"] = pin.exp3(np.array([0.3, -0.2, 0.5]))
    call["x"] = np.array([0.1, 0.2, 0.3])
    A0, Q0 = call["A"].copy(), call["Q"].copy()
    cpp_rows.frame_rows(**call)
    A1, Q1 = call["A"].copy(), call["Q"].copy()
    strided = dict(call, J=np.ascontiguousarray(call["J"]),
                   R=np.asfortranarray(call["R"]), x=np.repeat(call["x"], 2)[::2],
                   Rstar=np.asfortranarray(call["Rstar"]))
    call["A"][:], call["Q"][:] = A0, Q0
    cpp_rows.frame_rows(**strided)
    assert not call["J"].flags.c_contiguous            # pinocchio's own layout taken
    assert np.array_equal(call["A"], A1) and np.array_equal(call["Q"], Q1)


@pytest.mark.parametrize("call, words", [
    (lambda: cpp_rows.posture_error(np.zeros((6, 4)), 0, np.zeros(5), np.zeros(5),
                                    np.array([0, 9])), "iq[1] = 9"),
    (lambda: cpp_rows.posture_error(np.zeros((6, 4)), 3, np.zeros(5), np.zeros(5),
                                    np.array([0, 1])), "outside Q's 4 rows"),
    (lambda: cpp_rows.posture_error(np.zeros((6, 4)), 0, np.zeros(5), np.zeros(4),
                                    np.array([0, 1])), "q_ref must have 5 entries"),
    (lambda: cpp_rows.com_rows(np.zeros((3, 4)), np.zeros((6, 3)), 0, np.zeros((3, 4)),
                               np.zeros(3), np.zeros(3), np.array([0, 3]), np.zeros(2),
                               np.zeros(2), np.zeros(2), True), "axes[1] = 3"),
    (lambda: cpp_rows.velocity_targets(np.zeros(4), np.zeros((6, 3))), "Q must have shape"),
    (lambda: cpp_rows.acceleration_targets(np.zeros((4, 3)), np.zeros(4), np.zeros((6, 4)),
                                           np.zeros(2)), "v must have 3 entries"),
    (lambda: cpp_rows.state_is_valid(np.zeros(4), np.zeros(3), np.array([0, 4, 2]), 1e-6),
     "unit must hold (start, size) pairs"),
    (lambda: cpp_rows.state_is_valid(np.zeros(4), np.zeros(3), np.array([2, 4]), 1e-6),
     "unit's part 0 (2, 4)"),
    (lambda: cpp_rows.bounds_at(np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(2),
                                np.array([0, 1, 2]), np.zeros((3, 3)),
                                np.array([0.0, 0.1, 0.1, 1, 1, 1]), np.zeros(3)),
     "v has 2 entries"),
    (lambda: cpp_rows.bounds_at(np.zeros(3), np.zeros(3), np.zeros(4), np.zeros(4),
                                np.array([0, 1, 2]), np.zeros((3, 3)),
                                np.array([0.5, 0.1, 0.1, 1, 1, 1]), np.zeros(3)),
     "params[0] (the first row) must be a whole number"),
    (lambda: cpp_rows.activation_at(np.zeros((3, 4)), np.zeros((6, 3)), np.zeros(4),
                                    np.array([0, 1, 2]), np.zeros((3, 3)),
                                    np.array([0.0, 2.0, 1.0, 1.0]), np.zeros(3)),
     "params[1] (n_base)"),
    (lambda: cpp_rows.region_rows(np.zeros((2, 4)), np.zeros(2), np.zeros(2), 0,
                                  np.zeros((2, 3)), np.zeros((3, 4)), np.zeros(3), 1.0,
                                  np.zeros(4), np.zeros(3), np.zeros(2), np.zeros(2),
                                  np.zeros(1), np.zeros(2), np.zeros(2), 0.1, 0.1, True),
     "y must have 2 entries"),
    (lambda: cpp_rows.log3(np.eye(3), np.zeros(3), 1), "outside out's 3 entries"),
    (lambda: cpp_rows.acceleration_bounds(np.zeros(2), np.zeros(3), 0, np.zeros(2),
                                          np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2),
                                          0.1, 0.1, True, True), "upper must have 2 entries"),
    (lambda: cpp_rows.velocity_bounds(np.zeros(2), np.zeros(2), 1, np.zeros(2), np.zeros(2),
                                      np.zeros(2), np.zeros(2), 0.1, True, True),
     "outside lower's 2 rows"),
    (lambda: cpp_rows.actuated_positions(np.zeros(3), np.array([-1, 3]), np.zeros(2)),
     "iq[1] = 3"),
    (lambda: cpp_rows.limit_activation_rows(np.zeros((3, 4)), np.zeros((6, 3)), 0, 2,
                                            np.zeros(3), np.zeros(3), np.zeros(3),
                                            np.ones(3), 1.0, 1.0), "joints' columns"),
])
def test_bad_input_raises_prioiks_error(call, words):
    with pytest.raises(CoreInputError) as err:
        call()
    assert words in str(err.value)


def test_numpy_arrays_are_read_by_their_fields():
    """The bindings read numpy's array struct directly (the layout check at import
    held): the fast path is the one the writers take."""
    assert cpp_rows.READS_NUMPY_FIELDS is True


def test_other_buffers_give_the_same_rows(frame_call):
    """An array that is not a numpy.ndarray (a memoryview) goes through the buffer
    protocol: the same rows, and the same errors."""
    call = dict(frame_call)
    call["Rstar"] = pin.exp3(np.array([0.3, -0.2, 0.5]))
    call["x"] = np.array([0.1, 0.2, 0.3])
    A0, Q0 = call["A"].copy(), call["Q"].copy()
    cpp_rows.frame_rows(**call)
    A1, Q1 = call["A"].copy(), call["Q"].copy()
    call["A"][:], call["Q"][:] = A0, Q0
    cpp_rows.frame_rows(**{k: memoryview(v) for k, v in call.items()})
    assert np.array_equal(call["A"], A1) and np.array_equal(call["Q"], Q1)
    b, Q = np.zeros(4), np.arange(24.0).reshape(6, 4)
    cpp_rows.velocity_targets(memoryview(b), memoryview(Q))
    assert np.array_equal(b, Q[1] + Q[4] * Q[0])
    with pytest.raises(CoreInputError, match="b must be float64"):
        cpp_rows.velocity_targets(memoryview(np.zeros(4, dtype=np.int64)), memoryview(Q))
    with pytest.raises(CoreInputError, match="b must be a writable float64 numpy array, "
                                             "got a read-only array"):
        cpp_rows.velocity_targets(memoryview(b).toreadonly(), Q)


def _mutations(value, rng):
    """Arrays the bindings must refuse or take without harm in place of ``value``:
    other shapes, dtypes, strides, read-only copies, huge or negative indices,
    non-finite entries, empty arrays, None."""
    a = np.asarray(value)
    shape = tuple(int(s) for s in rng.integers(0, 5, size=rng.integers(0, 4)))
    kinds = [
        lambda: np.zeros(shape),
        lambda: a.astype(rng.choice([np.float32, np.int32, np.int64, np.float64, bool])),
        lambda: np.repeat(a, 2, axis=-1)[..., ::2] if a.ndim else a,
        lambda: _read_only(a),
        lambda: np.full(a.shape, rng.choice([np.nan, np.inf, -np.inf, 1e300])),
        lambda: np.full(a.shape, rng.choice([-1, 2**62, -2**62, 7]), dtype=np.int64),
        lambda: a.reshape(-1)[:0],
        lambda: a.T,
        lambda: None,
        lambda: a[::-1] if a.ndim else a,
    ]
    return kinds[rng.integers(len(kinds))]()


@pytest.mark.parametrize("seed", range(4))
def test_the_bindings_refuse_or_take_any_array_without_harm(frame_call, seed):
    """A short fuzz at the boundary: each entry point's valid call with one or two of
    its arrays replaced at random; every call returns or raises CoreInputError (a crash
    ends the test run)."""
    rng = np.random.default_rng(seed)
    m, n = frame_call["A"].shape
    valid = {
        cpp_rows.frame_rows: dict(frame_call),
        cpp_rows.position_target_rows: {k: frame_call[k] for k in (
            "A", "Q", "J", "t", "R", "geo", "aj", "vj", "x")} | {
            "spec": np.array([0, 0, 1, 0, 3], dtype=np.int64)},
        cpp_rows.com_rows: dict(A=np.zeros((5, n)), Q=np.zeros((6, 5)), s=1,
                                Jcom=np.ones((3, n)), com=np.ones(3), acom=np.ones(3),
                                axes=np.array([0, 2]), x=np.ones(2), xd=np.ones(2),
                                xdd=np.ones(2), zero_drift=False),
        cpp_rows.posture_error: dict(Q=np.zeros((6, 5)), s=1, q=np.ones(6), q_ref=np.ones(6),
                                     iq=np.array([0, 3, 5])),
        cpp_rows.bounds_at: dict(lower=np.zeros(5), upper=np.zeros(5), q=np.ones(6),
                                 v=np.ones(6), iq=np.array([0, -1, 5]),
                                 lim=np.ones((3, 3)), params=np.array([1.0, .1, .01, 1, 1, 1]),
                                 qa=np.zeros(3)),
        cpp_rows.activation_at: dict(A=np.zeros((5, 6)), Q=np.zeros((6, 5)), q=np.ones(6),
                                     iq=np.array([0, 2, 5]), lim=np.ones((3, 3)),
                                     params=np.array([1.0, 2.0, 1.0, 1.0]), qa=np.zeros(3)),
        cpp_rows.region_rows: dict(A=np.zeros((4, n)), lower=np.zeros(4), upper=np.ones(4),
                                   s=1, C=np.ones((2, 3)), Jp=np.ones((3, n)), p=np.ones(3),
                                   psign=1.0, v=np.ones(n), drift=np.ones(3), lo=np.zeros(2),
                                   hi=np.ones(2), y=np.zeros(2), yd=np.zeros(2),
                                   vmax=np.full(2, np.inf), T=0.1, dt=0.01, accel=True),
        cpp_rows.acceleration_targets: dict(A=np.ones((4, 3)), b=np.zeros(4),
                                            Q=np.ones((6, 4)), v=np.ones(3)),
        cpp_rows.state_is_valid: dict(q=np.ones(7), v=np.ones(6), unit=np.array([3, 4]),
                                      tol=1e-6),
    }
    refused = 0
    for fn, kwargs in valid.items():
        fn(**kwargs)                                        # valid as given
        arrays = [k for k, v in kwargs.items() if isinstance(v, np.ndarray)]
        for _ in range(60):
            call = dict(kwargs)
            for name in rng.choice(arrays, size=rng.integers(1, 3), replace=False):
                with np.errstate(invalid="ignore"):     # NaN cast to an integer type
                    call[name] = _mutations(call[name], rng)
            try:
                fn(**{k: (v.copy() if isinstance(v, np.ndarray) and v.flags.writeable
                          else v) for k, v in call.items()})
            except CoreInputError:
                refused += 1
    assert refused > 0
