"""robots.rows: every task writer against independent pinocchio/numpy formulas (the
previous builders' math: frame Jacobians from ``pin.getFrameJacobian``, drifts from
``pin.getFrameClassicalAcceleration``, ``pin.log3``, the joint-limit formulas in numpy),
at velocity and acceleration level; the fencing rows against the scenario's stacks;
masked activation rows solve like the rows they mask; the errors name the task."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from prioik import formulations
from prioik._core import rows as _k  # the row writers robots.rows calls
from prioik.hierarchy import TaskStackError
from prioik.robots import (
    JointLimitActivation,
    KinematicState,
    Reference,
    TaskWriter,
    com_position,
    com_region,
    contact,
    frame_orientation,
    frame_pose,
    frame_position,
    frame_region,
    g1,
    joint_limit_bounds,
    joint_velocity_bounds,
    panda,
    point_position,
    posture,
    spatial_chain,
)
from prioik.robots.fencing import FencingScenario

#: the two paths do the same arithmetic in another order: rows agree to rounding
TOL = 1e-12
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@pytest.fixture(scope="module")
def robot():
    return g1().with_point_frame("sword_tip", "left_hand", (0.5, 0.0, 0.0))


def _state(robot, seed, drift=True, spread=0.2):
    rng = np.random.default_rng(seed)
    q = robot.q0.copy()
    nb = 7 if robot.floating_base else 0
    q[nb:] += rng.uniform(-spread, spread, robot.nq - nb)
    return KinematicState(robot, q, rng.normal(size=robot.nv), drift=drift)


def _close(a, b, tol=TOL):
    return np.allclose(a, b, rtol=tol, atol=tol)


# ------------------------------------------------- the oracle: the previous math
def _ref_frame(state, frame, offset=None):
    """(J, p, drift) of a point ``offset`` on ``frame`` (6 rows: the point's linear,
    the frame's angular), from pinocchio's frame Jacobian and classical acceleration."""
    offset = np.zeros(3) if offset is None else offset
    m, d = state.model, state.data
    fid = m.getFrameId(state.robot.frames.get(frame, frame))
    J = pin.computeFrameJacobian(m, m.createData(), state.q, fid, LWA)
    M = d.oMf[fid]
    r = M.rotation @ offset
    J = J.copy()
    J[:3] += -pin.skew(r) @ J[3:]                     # v_p = v_O + ω × r
    drift = None
    if state.has_drift:
        acc = pin.getFrameClassicalAcceleration(m, d, fid, LWA)
        om = pin.getFrameVelocity(m, d, fid, LWA).angular
        drift = np.concatenate([acc.linear + np.cross(acc.angular, r)
                                + np.cross(om, np.cross(om, r)), acc.angular])
    return J, M.translation + r, M.rotation, drift


def _targets(J, v, e, xd, xdd, drift, gain):
    """b at velocity (gain K) or acceleration level (gain (K_p, K_d), eq. 2-4)."""
    if np.isscalar(gain):
        return xd + gain * e
    kp, kd = gain
    return xdd + kd * (xd - J @ v) + kp * e - drift


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("seed", range(3))
def test_every_frame_and_com_writer_matches_pinocchios_formulas(robot, mode, seed):
    accel = mode == "acceleration"
    state = _state(robot, seed, drift=accel)
    rng = np.random.default_rng(50 + seed)
    x, xd, xdd = rng.normal(size=(3, 3))
    w_ref, dw_ref = rng.normal(size=(2, 3))
    rot = pin.exp3(rng.normal(size=3))
    off = np.array([0.1, -0.05, 0.2])
    c_x, c_xd, c_xdd = rng.normal(size=(3, 2))
    g = {"velocity": 3.0, "acceleration": (25.0, 10.0)}[mode]
    w = TaskWriter(robot, mode)
    w.add_frame_pose("pose", "left_foot", gain=g, level=0)
    w.add_frame_position("tip", "sword_tip", gain=g, level=1)
    w.add_point("point", "left_hand", off, gain=g, level=1)
    w.add_com("com", gain=g, level=1)
    w.add_frame_orientation("orient", "torso", gain=g, level=2)
    w.add_contact("contact", "right_foot", gain=g, level=2)
    w.add_posture("posture", gain=g, level=3)
    placement = pin.SE3(rot, x)
    w.frame_pose(state, "pose", x, rot, xd, xdd, w_ref, dw_ref)
    w.frame_position(state, "tip", x, xd, xdd)
    w.point(state, "point", x, xd, xdd)
    w.com(state, "com", c_x, c_xd, c_xdd)
    w.frame_orientation(state, "orient", rot, w_ref, dw_ref)
    w.contact(state, "contact", placement)
    w.posture(state, "posture", robot.q0)
    data = w.targets(state)
    v = state.v
    zero = np.zeros(3)
    for name, frame, o, rows in (("pose", "left_foot", zero, slice(0, 6)),
                                 ("tip", "sword_tip", zero, slice(0, 3)),
                                 ("point", "left_hand", off, slice(0, 3)),
                                 ("orient", "torso", zero, slice(3, 6)),
                                 ("contact", "right_foot", zero, slice(0, 6))):
        J, p, R, drift = _ref_frame(state, frame, o)
        e = np.concatenate([x - p, pin.log3(rot @ R.T)])
        ref_v = {"contact": np.zeros(6)}.get(name, np.concatenate([xd, w_ref]))
        ref_a = {"contact": np.zeros(6)}.get(name, np.concatenate([xdd, dw_ref]))
        d = None if drift is None else drift[rows]
        b = _targets(J[rows], v, e[rows], ref_v[rows], ref_a[rows], d, g)
        A, bw = data.rows(name)
        assert _close(A, J[rows]), name
        assert _close(bw, b, 1e-10), name
    Jc = pin.jacobianCenterOfMass(robot.model, robot.model.createData(), state.q)[:2]
    com = pin.centerOfMass(robot.model, robot.model.createData(), state.q)[:2]
    dc = state.acom_drift[:2] if accel else None
    A, b = data.rows("com")
    assert _close(A, Jc) and _close(b, _targets(Jc, v, c_x - com, c_xd, c_xdd, dc, g), 1e-10)
    A, b = data.rows("posture")
    Jp = np.hstack([np.zeros((29, 6)), np.eye(29)])
    e = pin.difference(robot.model, state.q, robot.q0)[6:]
    assert np.array_equal(A, Jp)
    assert _close(b, _targets(Jp, v, e, np.zeros(29), np.zeros(29), np.zeros(29), g))


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
def test_a_fixed_position_target_zeroes_the_rates_of_the_previous_step(robot, mode):
    """frame_position / point without ẋ*, ẍ* (their own compiled writer) after a step
    with them: the rows are those of zero rates, at both levels."""
    accel = mode == "acceleration"
    g = {"velocity": 3.0, "acceleration": (25.0, 10.0)}[mode]
    off = np.array([0.1, -0.05, 0.2])
    w = TaskWriter(robot, mode)
    w.add_frame_position("tip", "sword_tip", gain=g, level=0)
    w.add_point("point", "left_hand", off, gain=g, level=1)
    rng = np.random.default_rng(7)
    x, xd, xdd = rng.normal(size=(3, 3))
    before = _state(robot, 1, drift=accel)
    w.frame_position(before, "tip", x, xd, xdd)
    w.point(before, "point", x, xd, xdd)
    state = _state(robot, 2, drift=accel)
    w.frame_position(state, "tip", x)
    w.point(state, "point", list(x))            # converted like any reference
    data = w.targets(state)
    zero = np.zeros(3)
    for name, frame, o in (("tip", "sword_tip", zero), ("point", "left_hand", off)):
        J, p, _, drift = _ref_frame(state, frame, o)
        d = None if drift is None else drift[:3]
        A, b = data.rows(name)
        assert _close(A, J[:3]), name
        assert _close(b, _targets(J[:3], state.v, x - p, zero, zero, d, g), 1e-10), name
        rows = w.layout.task_slice(name)
        assert not w.velocity_ref[rows].any() and not w.feedforward[rows].any()


@pytest.mark.parametrize("seed", range(2))
def test_builders_work_at_both_levels_and_are_the_writers_rows(robot, seed):
    """The one-off builders from a drift-free state (velocity level) give the same
    ``J``, error and velocity targets as from a full state, with ``drift = None`` and an
    ``acceleration()`` that names the task."""
    full, light = _state(robot, seed), _state(robot, seed, drift=False)
    rng = np.random.default_rng(seed)
    ref = Reference(*rng.normal(size=(3, 3)))
    cref = Reference(*rng.normal(size=(3, 2)))
    rot = pin.exp3(rng.normal(size=3))
    M = pin.SE3(rot, ref.x)
    build = {"position": lambda s: frame_position(s, "sword_tip", ref),
             "point": lambda s: point_position(s, "left_hand", (0.5, 0, 0), ref),
             "orientation": lambda s: frame_orientation(s, "torso", rot),
             "pose": lambda s: frame_pose(s, "left_foot", ref, rot),
             "contact": lambda s: contact(s, "right_foot", M),
             "com": lambda s: com_position(s, cref),
             "posture": lambda s: posture(s, robot.q0)}
    for kind, f in build.items():
        a, b = f(full), f(light)
        assert np.array_equal(a.J, b.J) and np.array_equal(a.error, b.error), kind
        assert _close(a.velocity(2.0).b, b.velocity(2.0).b), kind
        assert a.drift is not None and np.all(np.isfinite(a.acceleration(4.0, 2.0).b))
        if kind != "posture":
            assert b.drift is None, kind
            with pytest.raises(TaskStackError, match=f"task {b.name!r}: it was built from a "
                                                     r"KinematicState\(drift=False\)"):
                b.acceleration(4.0, 2.0)
    # the point on the hand equals the sword-tip frame at the same place
    tip, pt = build["position"](full), build["point"](full)
    assert _close(tip.J, pt.J) and _close(tip.drift, pt.drift, 1e-10)


# ------------------------------------------------------------------ joint limits
def _ref_activation(robot, q, v, p, velocity):
    """The previous numpy activation rows (active rows and targets)."""
    nb = robot.n_base
    lo, hi, _ = robot.joint_limits()
    qa = q[robot.actuated_q_index()]
    va = v[nb:]
    width = np.minimum(p.margin, 0.25 * (hi - lo))
    y_lo, y_hi = lo + width - qa, qa - (hi - width)
    in_lo, in_hi = y_lo > 0, (y_hi > 0) & ~(y_lo > 0)
    s_lo, s_hi = np.minimum(y_lo / width, 1.0), np.minimum(y_hi / width, 1.0)
    if velocity:
        target = np.where(in_lo, s_lo * p.k * y_lo, -s_hi * p.k * y_hi)
    else:
        target = np.where(in_lo, s_lo * (p.kp * y_lo - p.kd * va),
                          -s_hi * (p.kp * y_hi + p.kd * va))
    rows = np.flatnonzero(in_lo | in_hi)
    return rows, target[rows]


def _ref_acceleration_bounds(robot, q, v, T, dt):
    """The previous numpy bounds on q̈ (robots.tasks.joint_limit_bounds before the writers)."""
    nb = robot.n_base
    lo, hi, vmax = robot.joint_limits()
    qa, va = q[robot.actuated_q_index()], v[nb:]
    with np.errstate(invalid="ignore", divide="ignore"):
        h_lo = 2.0 * (lo - qa - va * T) / T ** 2
        h_hi = 2.0 * (hi - qa - va * T) / T ** 2
        d_hi, d_lo = np.maximum(hi - qa, 1e-9), np.maximum(qa - lo, 1e-9)
        brake_hi = np.where((va > 0) & (h_hi < -va / T), -va ** 2 / (2.0 * d_hi), np.inf)
        brake_lo = np.where((va < 0) & (h_lo > -va / T), va ** 2 / (2.0 * d_lo), -np.inf)
        p_hi = np.minimum.reduce([h_hi, brake_hi, (hi - qa - va * dt) / dt ** 2])
        p_lo = np.maximum.reduce([h_lo, brake_lo, (lo - qa - va * dt) / dt ** 2])
        v_lo, v_hi = (-vmax - va) / dt, (vmax - va) / dt
    lower, upper = np.maximum(p_lo, v_lo), np.minimum(p_hi, v_hi)
    bad = lower > upper
    mid = np.where(va[bad] > 0, np.clip(p_hi[bad], v_lo[bad], v_hi[bad]),
                   np.clip(p_lo[bad], v_lo[bad], v_hi[bad]))
    lower[bad] = upper[bad] = np.where(np.isfinite(mid), mid, 0.0)
    return lower, upper


def _limit_states(robot, n, seed):
    """States spread over (and past) the joint ranges, at speeds up to twice the limit."""
    rng = np.random.default_rng(seed)
    lo, hi, vmax = robot.joint_limits()
    idx = robot.actuated_q_index()
    for _ in range(n):
        q = robot.q0.copy()
        q[idx] = rng.uniform(lo - 0.05, hi + 0.05)
        v = np.zeros(robot.nv)
        v[robot.n_base:] = rng.uniform(-2, 2, lo.size) * np.minimum(vmax, 10.0)
        yield q, v


@pytest.mark.parametrize("name", ["g1", "panda"])
def test_joint_limit_writers_match_the_previous_formulas(robot, name):
    r = robot if name == "g1" else panda()
    nb, k = r.n_base, r.nv - r.n_base
    p = JointLimitActivation()
    T, dt = 0.1, 0.002
    writers = {mode: TaskWriter(r, mode) for mode in ("velocity", "acceleration")}
    for mode, w in writers.items():
        w.add_joint_limits("rows", form="activation", activation=p)
        w.add_joint_limits("bounds", form="bounds", horizon=T if mode == "acceleration"
                           else None, dt=dt, level=1)
    _, hi, vmax = r.joint_limits()
    n_active = 0
    for q, v in _limit_states(r, 40, 3):
        state = KinematicState(r, q, v, drift=False)
        for mode, w in writers.items():
            active = w.joint_limits(state, "rows")
            w.joint_limits(state, "bounds")
            data = w.targets(state)
            rows, target = _ref_activation(r, q, v, p, mode == "velocity")
            A, b = data.rows("rows")
            assert active == rows.size
            assert np.array_equal(np.flatnonzero(A.any(axis=1)), rows)
            assert np.array_equal(A[rows], np.eye(r.nv)[nb + rows])
            assert not b[np.setdiff1d(np.arange(k), rows)].any()     # masked rows ask 0
            assert _close(b[rows], target, 1e-9)
            A, lower, upper = data.bounds("bounds")
            assert np.array_equal(A, np.eye(r.nv)[nb:])
            if mode == "acceleration":
                ref_lo, ref_up = _ref_acceleration_bounds(r, q, v, T, dt)
            else:
                qa = q[r.actuated_q_index()]
                lo_ = r.joint_limits()[0]
                ref_up = np.minimum((hi - qa) / dt, vmax)
                ref_lo = np.minimum(np.maximum((lo_ - qa) / dt, -vmax), ref_up)
            assert _close(lower, ref_lo, 1e-9) and _close(upper, ref_up, 1e-9), mode
            assert np.all(lower <= upper)
        n_active += active
    assert n_active > 10        # the states reach the margins: the check is not vacuous
    # the builders are these writers' rows
    state = KinematicState(r, q, v)
    assert np.array_equal(joint_limit_bounds(state, T, dt).lower,
                          _ref_acceleration_bounds(r, q, v, T, dt)[0])
    qa = q[r.actuated_q_index()]
    assert np.array_equal(joint_velocity_bounds(state, dt).upper,
                          np.minimum((hi - qa) / dt, vmax))


def test_masked_activation_rows_solve_like_the_active_rows(robot):
    """The fixed-size, masked activation level gives the same q̈ as the level of its
    active rows only (and, when no joint is near a limit, as no level at all)."""
    sc = FencingScenario("compatible", robot=robot)
    w = sc.acceleration_rows("activation")
    solver = formulations.prepare(w.layout, "extended_jacobian")
    for seed, spread in ((0, 0.0), (1, 1.5), (2, 1.5)):
        state = _state(robot, seed, spread=spread)
        data = sc.write_rows(w, state, 0.8)
        stack = sc.acceleration_stack(state, 0.8, "activation").stack
        x = solver.solve(data).x
        y = formulations.solve(stack, "extended_jacobian").x
        assert np.allclose(x, y, rtol=0, atol=1e-8 * (1 + np.abs(y).max())), seed
        has_level = "joint_limits" in [t.name for lvl in stack.levels for t in lvl.tasks]
        assert has_level == (seed > 0)


@pytest.mark.parametrize("variant", ["compatible", "incompatible"])
@pytest.mark.parametrize("t", [0.0, 0.7, 1.9, 3.0])
def test_fencing_rows_equal_the_scenario_stacks(robot, variant, t):
    scenario = FencingScenario(variant, robot=robot)
    writers = {("velocity", "none"): scenario.velocity_rows(10.0),
               ("velocity", "bounds"): scenario.velocity_rows(10.0, "bounds", dt=0.002),
               ("acceleration", "bounds"): scenario.acceleration_rows("bounds", dt=0.002)}
    for seed in range(2):
        for (mode, limits), w in writers.items():
            state = _state(robot, 10 + seed, drift=mode == "acceleration")
            data = scenario.write_rows(w, state, t)
            full = _state(robot, 10 + seed)
            stack = (scenario.velocity_stack(full, t, gain=10.0, limits=limits, dt=0.002)
                     if mode == "velocity" else
                     scenario.acceleration_stack(full, t, "bounds", dt=0.002)).stack
            assert [lvl.names for lvl in stack.levels] == list(data.layout.names)
            for level in stack.levels:
                for task in level:
                    if task.is_equality:
                        A, b = data.rows(task.name)
                        assert _close(A, task.A) and _close(b, task.b, 1e-10), task.name
                    else:
                        A, lo, up = data.bounds(task.name)
                        assert np.array_equal(A, task.A)
                        assert _close(lo, task.lower, 1e-10) and _close(up, task.upper, 1e-10)


# ------------------------------------------------------------------ declaring
def test_writer_builds_its_layout_from_the_declared_tasks(robot):
    w = TaskWriter(robot, "velocity")
    w.add_contact("support", "right_foot", gain=10.0)                 # level 0
    w.add_joint_limits("limits", form="bounds", dt=0.01)              # level 1
    w.add_com("com", gain=5.0, axes=(0, 1, 2), level=2)
    w.add_frame_position("tip", "sword_tip", gain=5.0, level=2, weight=4.0)
    w.add_posture("posture", gain=1.0)                                # level 3
    layout = w.layout
    assert layout.names == (("support",), ("limits",), ("com", "tip"), ("posture",))
    assert layout.kind_of("limits") == "inequality" and layout.kind_of("tip") == "equality"
    assert layout.m == 6 + 29 + 3 + 3 + 29 and layout.n == 35
    assert np.all(w.data.weights("tip") == 2.0) and np.all(w.data.weights("com") == 1.0)
    assert "tip" in w and "elbow" not in w
    with pytest.raises(TaskStackError, match="layout is fixed"):
        w.add_posture("again", gain=1.0)


def test_declaration_errors_are_named(robot):
    w = TaskWriter(robot, "acceleration")
    with pytest.raises(ValueError, match="task 'tip': at acceleration level gain is"):
        w.add_frame_position("tip", "sword_tip", gain=3.0)
    with pytest.raises(KeyError, match="no frame 'sword'"):
        w.add_frame_position("tip", "sword", gain=(1.0, 1.0))
    with pytest.raises(ValueError, match="com axes must be distinct among 0, 1, 2"):
        w.add_com("c", gain=(1.0, 1.0), axes=(3,))
    with pytest.raises(ValueError, match="need a horizon"):
        w.add_joint_limits("jl", form="bounds", dt=0.01)
    with pytest.raises(ValueError, match="need dt > 0"):
        w.add_joint_limits("jl", form="bounds", horizon=0.1)
    with pytest.raises(ValueError, match="form must be"):
        w.add_joint_limits("jl", form="soft")
    with pytest.raises(ValueError, match="mode must be one of"):
        TaskWriter(robot, "jerk")
    v = TaskWriter(robot, "velocity")
    with pytest.raises(ValueError, match="at velocity level gain is one number"):
        v.add_com("c", gain=(1.0, 2.0))
    v.add_com("c", gain=1.0, level=0)
    v.add_posture("p", gain=1.0, level=2)
    with pytest.raises(TaskStackError, match=r"levels \[1\] have no task"):
        _ = v.layout
    with pytest.raises(TaskStackError, match="duplicate task name"):
        v.add_com("c", gain=1.0)


def test_writer_errors_name_the_task(robot):
    w = TaskWriter(robot, "acceleration")
    w.add_frame_position("tip", "sword_tip", gain=(1.0, 1.0))
    w.add_com("com", gain=(1.0, 1.0))
    w.add_frame_pose("pose", "left_foot", gain=(1.0, 1.0))
    full, light = _state(robot, 0), _state(robot, 0, drift=False)
    with pytest.raises(ValueError, match="task 'tip': an acceleration-level writer needs"):
        w.frame_position(light, "tip", np.zeros(3))
    with pytest.raises(ValueError, match="task 'tip': x must have 3 entries"):
        w.frame_position(full, "tip", np.zeros(2))
    with pytest.raises(ValueError, match="task 'com': xd must have 2 entries"):
        w.com(full, "com", np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="task 'pose': rotation must be 3 × 3"):
        w.frame_pose(full, "pose", np.zeros(3), np.eye(2))
    with pytest.raises(TaskStackError,
                       match="task 'pose' was declared as frame_pose, not frame_position"):
        w.frame_position(full, "pose", np.zeros(3))
    with pytest.raises(TaskStackError, match="no task 'foot' declared"):
        w.frame_pose(full, "foot", np.zeros(3), np.eye(3))
    other = spatial_chain(3)
    with pytest.raises(ValueError, match="the state is of robot 'chain3'"):
        w.com(KinematicState(other, other.q0, np.zeros(3)), "com", np.zeros(2))


@pytest.mark.parametrize("mode, gain, message", [
    ("velocity", -1.0, r"gain must be ≥ 0, got -1.0"),
    ("velocity", np.nan, r"gain must be finite, got nan"),
    ("velocity", np.inf, r"gain must be finite, got inf"),
    ("acceleration", (10.0, -2.0), r"gain must be ≥ 0, got \(10.0, -2.0\)"),
    ("acceleration", (-10.0, 2.0), r"gain must be ≥ 0"),
    ("acceleration", (np.nan, 2.0), r"gain must be finite"),
])
def test_a_negative_or_non_finite_gain_is_refused_at_declaration(robot, mode, gain, message):
    w = TaskWriter(robot, mode)
    for declare in (lambda: w.add_frame_position("tip", "sword_tip", gain=gain),
                    lambda: w.add_com("tip", gain=gain),
                    lambda: w.add_posture("tip", gain=gain)):
        with pytest.raises(TaskStackError, match="task 'tip': " + message) as err:
            declare()
        assert err.value.task == "tip"
    assert w.tasks() == ()
    ok = 1.0 if mode == "velocity" else (1.0, 1.0)
    w.add_frame_position("tip", "sword_tip", gain=ok)
    with pytest.raises(TaskStackError, match="task 'tip': " + message):
        w.set_gains("tip", gain)
    assert w.kp[:3].tolist() == [1.0] * 3                 # the gains it had
    w.set_gains("tip", 0.0 if mode == "velocity" else (0.0, 0.0))   # 0: feed-forward only


def test_a_non_finite_reference_is_refused_at_the_writer_naming_task_and_argument(robot):
    """Every reference of every writer (targets, rates, rotations, q_ref): a NaN or an
    infinity raises at the call, naming the task, its level and the argument; the rows
    written before stay as they were."""
    w = TaskWriter(robot, "acceleration")
    w.add_frame_position("tip", "sword_tip", gain=(1.0, 1.0), level=0)
    w.add_frame_orientation("turn", "left_hand", gain=(1.0, 1.0), level=0)
    w.add_frame_pose("pose", "left_foot", gain=(1.0, 1.0), level=1)
    w.add_contact("foot", "right_foot", gain=(1.0, 1.0), level=1)
    w.add_com("com", gain=(1.0, 1.0), level=2)
    w.add_posture("posture", gain=(1.0, 1.0), level=3)
    state = _state(robot, 3)
    z, R = np.zeros(3), np.eye(3)

    def bad(shape, index, value=np.nan):
        a = np.zeros(shape) if shape != (3, 3) else np.eye(3)
        a[index] = value
        return a

    w.frame_position(state, "tip", z)
    before = w.data.A.copy(), w.error.copy()
    cases = [
        (lambda: w.frame_position(state, "tip", bad(3, 1)), "tip", 0, r"x\[1\] .*\(nan\)"),
        (lambda: w.frame_position(state, "tip", z, bad(3, 2, np.inf)), "tip", 0,
         r"xd\[2\] is not finite \(inf\)"),
        (lambda: w.frame_position(state, "tip", z, None, bad(3, 0, -np.inf)), "tip", 0,
         r"xdd\[0\] is not finite \(-inf\)"),
        (lambda: w.frame_orientation(state, "turn", bad((3, 3), (1, 2))), "turn", 0,
         r"rotation\[1, 2\] is not finite \(nan\)"),
        (lambda: w.frame_orientation(state, "turn", R, bad(3, 0)), "turn", 0,
         r"angular_velocity\[0\] is not finite"),
        (lambda: w.frame_orientation(state, "turn", R, None, bad(3, 2)), "turn", 0,
         r"angular_acceleration\[2\] is not finite"),
        (lambda: w.frame_pose(state, "pose", bad(3, 0), R), "pose", 1, r"x\[0\] is not"),
        (lambda: w.frame_pose(state, "pose", z, bad((3, 3), (0, 0), np.inf)), "pose", 1,
         r"rotation\[0, 0\] is not finite \(inf\)"),
        (lambda: w.contact(state, "foot", translation=bad(3, 1), rotation=R), "foot", 1,
         r"translation\[1\] is not finite"),
        (lambda: w.contact(state, "foot", pin.SE3(R, bad(3, 2))), "foot", 1,
         r"translation\[2\] is not finite"),
        (lambda: w.com(state, "com", bad(2, 1)), "com", 2, r"x\[1\] is not finite"),
        (lambda: w.com(state, "com", np.zeros(2), bad(2, 0)), "com", 2, r"xd\[0\] is not"),
        (lambda: w.posture(state, "posture", bad(robot.nq, 9)), "posture", 3,
         r"q_ref\[9\] is not finite \(nan\)"),
        (lambda: w.posture(state, "posture", list(bad(robot.nq, 8, np.inf))), "posture", 3,
         r"q_ref\[8\] is not finite \(inf\)"),
    ]
    for call, task, level, message in cases:
        with pytest.raises(TaskStackError, match=rf"level {level}, task '{task}': {message}") \
                as err:
            call()
        assert (err.value.task, err.value.level) == (task, level)
    assert np.array_equal(w.data.A, before[0]) and np.array_equal(w.error, before[1])


def test_builders_name_their_task_in_reference_and_gain_errors(robot):
    """The builders of robots.tasks refuse the same references, naming their own task
    (not their writer's inner one), and their terms refuse negative or non-finite gains."""
    state = _state(robot, 4)
    ref = Reference(np.array([0.3, np.nan, 0.5]), np.zeros(3), np.zeros(3))
    with pytest.raises(TaskStackError, match=r"task 'hand': x\[1\] is not finite") as err:
        frame_position(state, "sword_tip", ref, name="hand")
    assert err.value.task == "hand"
    with pytest.raises(TaskStackError, match=r"task 'sword_tip_pose': x\[1\] is not finite"):
        frame_pose(state, "sword_tip", ref, np.eye(3))
    term = frame_position(state, "sword_tip", Reference(np.zeros(3), np.zeros(3),
                                                        np.zeros(3)), name="hand")
    for call, message in ((lambda: term.velocity(-1.0), r"gain k must be .*got -1.0"),
                          (lambda: term.velocity(np.inf), r"gain k must be .*got inf"),
                          (lambda: term.acceleration(1.0, -2.0), r"gain kd .*got -2.0"),
                          (lambda: term.acceleration(np.nan, 2.0), r"gain kp .*got nan"),
                          (lambda: term.velocity("1"), r"gain k .*got '1'"),
                          (lambda: term.velocity(np.array([1.0, -1.0, 1.0])),
                           r"gain k .*got array")):
        with pytest.raises(TaskStackError, match=r"task 'hand': " + message):
            call()
    assert np.all(np.isfinite(term.acceleration(0.0, 0.0).b))
    per_row = term.velocity(np.array([1.0, 2.0, 3.0])).b          # one gain per row
    np.testing.assert_array_equal(per_row, term.velocity_ref
                                  + np.array([1.0, 2.0, 3.0]) * term.error)


def _declared(robot, keep=()):
    w = TaskWriter(robot, "velocity")
    w.add_frame_position("tip", "sword_tip", gain=1.0, level=0, keep="tip" in keep)
    w.add_com("com", gain=1.0, level=1, keep="com" in keep)
    w.add_posture("posture", gain=1.0, level=2, keep="posture" in keep)
    return w


def test_a_task_not_written_since_the_last_targets_is_refused_naming_it(robot):
    state = _state(robot, 5, drift=False)
    w = _declared(robot)
    w.frame_position(state, "tip", np.zeros(3))
    with pytest.raises(TaskStackError, match=r"level 1, task 'com': not written yet "
                                             r"\(unwritten: com, posture\).*keep=True") as err:
        w.targets(state)
    assert (err.value.task, err.value.level) == ("com", 1)
    w.com(state, "com", np.zeros(2))
    w.posture(state, "posture", robot.q0)
    first = w.targets(state).b.copy()
    w.frame_position(state, "tip", np.zeros(3))
    w.posture(state, "posture", robot.q0)
    with pytest.raises(TaskStackError, match=r"task 'com': not written since the last "
                                             r"targets\(\) \(unwritten: com\)"):
        w.velocity_targets()
    w.com(state, "com", np.zeros(2))
    assert np.array_equal(w.targets(state).b, first)        # same state, same targets
    with pytest.raises(TaskStackError, match=r"unwritten: tip, com, posture"):
        w.targets(state)                  # nothing written since the last targets()


def test_a_task_declared_with_keep_keeps_its_last_rows(robot):
    state = _state(robot, 6, drift=False)
    w = _declared(robot, keep=("com",))
    w.frame_position(state, "tip", np.zeros(3))
    w.posture(state, "posture", robot.q0)
    with pytest.raises(TaskStackError, match=r"task 'com': not written yet"):
        w.targets(state)                  # a kept task is written once first
    w.com(state, "com", np.array([0.1, -0.2]))
    sl = w.layout.task_slice("com")
    first = w.targets(state).b[sl].copy()
    for _ in range(3):                    # com never written again: its rows stay
        w.frame_position(state, "tip", np.zeros(3))
        w.posture(state, "posture", robot.q0)
        assert np.array_equal(w.targets(state).b[sl], first)
    with pytest.raises(TaskStackError, match="keep must be True or False, got 'yes'"):
        TaskWriter(robot, "velocity").add_posture("p", gain=1.0, keep="yes")


def test_writers_follow_a_reused_data_across_states(robot):
    """The writers read views of the state's ``pin.Data`` taken once: refilled by
    later states on the same ``Data``, they still equal pinocchio's formulas."""
    data = robot.model.createData()
    w = TaskWriter(robot, "velocity")
    w.add_frame_position("tip", "sword_tip", gain=0.0)
    target = np.array([0.3, 0.2, 0.9])
    for seed in range(3):
        rng = np.random.default_rng(seed)
        q = robot.q0.copy()
        q[7:] += rng.uniform(-0.3, 0.3, robot.nq - 7)
        state = KinematicState(robot, q, np.zeros(robot.nv), data, drift=False)
        w.frame_position(state, "tip", target)
        A, b = w.targets(state).rows("tip")
        J, p, _, _ = _ref_frame(KinematicState(robot, q, np.zeros(robot.nv)), "sword_tip")
        assert _close(A, J[:3]) and _close(b, np.zeros(3))
        assert _close(w.error, target - p)


def test_panda_writer_covers_all_nine_joints():
    r = panda()
    w = TaskWriter(r, "velocity")
    w.add_frame_pose("hand", "tcp", gain=1.0)
    w.add_joint_limits("limits", form="bounds", dt=0.01)
    w.add_posture("posture", gain=1.0)
    state = KinematicState(r, r.q0, np.zeros(9), drift=False)
    w.frame_pose(state, "hand", np.zeros(3), np.eye(3))
    w.joint_limits(state, "limits")
    w.posture(state, "posture", r.q0)
    data = w.targets(state)
    assert np.array_equal(data.rows("posture")[0], np.eye(9))
    A, lo, up = data.bounds("limits")
    assert np.array_equal(A, np.eye(9)) and np.all(np.isfinite(lo)) and np.all(lo < up)
    assert np.abs(data.rows("hand")[0][:, :7]).max() > 0.1      # the arm joints move the hand


def test_posture_of_joints_without_a_single_coordinate_uses_the_lie_difference():
    """A spherical joint (``n_q = 4``, ``n_v = 3``): the posture error is
    ``q_ref ⊖ q`` (pinocchio's ``difference``)."""
    from prioik.robots import RobotModel
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.appendBodyToJoint(j1, pin.Inertia.Random(), pin.SE3.Identity())
    j2 = model.addJoint(j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.3, 0, 0])),
                        "elbow")
    model.appendBodyToJoint(j2, pin.Inertia.Random(), pin.SE3.Identity())
    robot = RobotModel("ball", model, pin.neutral(model))
    assert not robot.floating_base
    q = pin.integrate(model, robot.q0, np.array([0.3, -0.2, 0.5, 0.4]))
    state = KinematicState(robot, q, np.zeros(4))
    w = TaskWriter(robot, "velocity")
    w.add_posture("posture", gain=2.0)
    w.posture(state, "posture", robot.q0)
    A, b = w.velocity_targets().rows("posture")
    assert np.array_equal(A, np.eye(4))
    assert _close(b, 2.0 * pin.difference(model, q, robot.q0))
    assert not np.allclose(w.error, robot.q0[[0, 1, 2, 4]] - q[[0, 1, 2, 4]])


@settings(max_examples=300, deadline=None)
@given(axis=arrays(np.float64, 3, elements=st.floats(-1, 1)),
       angle=st.one_of(st.floats(0.0, 1e-3), st.floats(0.0, np.pi - 1e-7),
                       st.floats(np.pi - 1e-2, np.pi - 1e-7)))
def test_log3_is_pinocchios_rotation_log(axis, angle):
    """The rotation vector θu back to 1e-12 for θ up to π − 1e-7 (pinocchio's own
    log3 is off by up to ~2e-12 near π, hence the looser comparison with it)."""
    assume(np.linalg.norm(axis) > 1e-3)
    w = angle * axis / np.linalg.norm(axis)
    R = pin.exp3(w)
    out = np.zeros(3)
    _k.log3(R, out, 0)
    assert np.allclose(out, w, rtol=0, atol=1e-12)
    assert np.allclose(out, pin.log3(R), rtol=0, atol=1e-10)


@pytest.mark.parametrize("axis", [(1.0, 0.0, 0.0), (0.06, 0.99, 0.23), (-1.0, 2.0, -3.0)])
def test_log3_at_half_a_turn_is_either_of_the_two_rotation_vectors(axis):
    """At θ = π, ``u`` and ``−u`` give the same rotation: the log is one of them."""
    u = np.array(axis) / np.linalg.norm(axis)
    R = pin.exp3(np.pi * u)
    out = np.zeros(3)
    _k.log3(R, out, 0)
    assert min(np.abs(out - np.pi * u).max(), np.abs(out + np.pi * u).max()) <= 1e-12
    assert np.allclose(pin.exp3(out), R, atol=1e-12)


def test_fencing_closed_loop_with_masked_activation_rows_follows_the_stack_path(robot):
    """0.3 s of the compatible fencing run from a knee inside its limit margin: the
    writer's fixed-size masked activation level under one prepared solver follows the
    one-off path whose activation level comes and goes (same trajectory to 1e-6)."""
    from prioik.robots import StepTasks, simulate
    sc = FencingScenario("compatible", robot=robot)
    q0 = robot.q0.copy()
    q0[7 + 3] = -0.05                        # left knee near its -0.087 limit
    w = sc.acceleration_rows("activation")
    solver = formulations.prepare(w.layout, "extended_jacobian")
    active = []

    def build_rows(state, t):
        data = sc.write_rows(w, state, t)
        active.append(int(data.rows("joint_limits")[0].any(axis=1).sum()))
        return StepTasks(data)

    run = dict(duration=0.3, dt=0.002, q0=q0, algorithmic_error=False)
    a = simulate(robot, build_rows, lambda d, **kw: solver.solve(d), **run)
    b = simulate(robot, lambda s, t: sc.acceleration_stack(s, t, "activation"),
                 lambda s, **kw: formulations.solve(s, "extended_jacobian"), **run)
    assert not a.failed and not b.failed
    assert max(active) >= 1                  # the masked level had active rows
    assert np.abs(a.q - b.q).max() < 1e-6 and np.abs(a.v - b.v).max() < 1e-5


def test_builders_from_several_threads_give_each_its_own_rows(robot):
    """The builders' writers are per thread: two threads building at once get the
    same terms as one thread alone."""
    import threading
    states = [_state(robot, seed) for seed in range(6)]
    ref = Reference(np.array([0.3, 0.2, 0.9]), np.zeros(3), np.zeros(3))
    expected = [frame_position(s, "sword_tip", ref).acceleration(25.0, 10.0).b
                for s in states]
    wrong = []

    def run(k):
        for j in range(400):
            i = (k + j) % len(states)
            b = frame_position(states[i], "sword_tip", ref).acceleration(25.0, 10.0).b
            if not np.array_equal(b, expected[i]):
                wrong.append(i)

    import sys
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)          # switch threads as often as possible
    try:
        threads = [threading.Thread(target=run, args=(k,)) for k in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    assert not wrong


# ------------------------------------------------------------------------- regions
@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
def test_region_writers_are_the_builders_rows_and_move_with_new_bounds(robot, mode):
    """Region tasks inside a writer with other tasks: rows and bounds equal the one-off
    builders'; only their rows and bounds are written (``b`` stays 0: an inequality);
    bounds and normals given at a step replace the declared ones from then on."""
    C = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    w = TaskWriter(robot, mode)
    gain = (4.0, 2.0) if mode == "acceleration" else 4.0
    w.add_com("com", gain=gain, level=0)
    w.add_frame_region("hand", "sword_tip", C, lower=[0.2, -np.inf], upper=[np.inf, 0.9],
                       dt=0.01, horizon=0.05, offset=[0.0, 0.1, 0.0], level=0)
    w.add_com_region("balance", C[1], lower=-0.1, upper=0.1, dt=0.01, level=1)
    w.add_posture("posture", gain=gain, level=1)
    state = _state(robot, 3, drift=mode == "acceleration")
    for step in range(2):
        lower = None if step == 0 else [0.3, -np.inf]
        w.frame_region(state, "hand", lower=lower)
        w.com_region(state, "balance")
        w.com(state, "com", np.zeros(2))
        w.posture(state, "posture", robot.q0)
        data = w.targets(state)
        hand = frame_region(state, "sword_tip", C, [0.2 if step == 0 else 0.3, -np.inf],
                            [np.inf, 0.9], dt=0.01, horizon=0.05, offset=[0.0, 0.1, 0.0],
                            mode=mode)
        balance = com_region(state, C[1], -0.1, 0.1, dt=0.01, mode=mode)
        for name, task in (("hand", hand), ("balance", balance)):
            A, lo, up = data.bounds(name)
            assert _close(A, task.A) and _close(lo, task.lower) and _close(up, task.upper)
            assert np.all(data.b[data.layout.task_slice(name)] == 0.0)
    w.frame_region(state, "hand")                    # the step-1 bound stays
    assert _close(data.bounds("hand")[1], hand.lower)
    assert data.layout.kind_of("hand") == data.layout.kind_of("balance") == "inequality"


def test_region_errors_name_the_task(robot):
    w = TaskWriter(robot, "acceleration")
    C = np.eye(3)[:2]
    cases = [
        (lambda: w.add_com_region("r", np.zeros((1, 3)), upper=1.0, dt=0.01),
         "task 'r': normal 0 is zero"),
        (lambda: w.add_com_region("r", np.ones((2, 2)), upper=1.0, dt=0.01),
         "task 'r': normals must be k × 3"),
        (lambda: w.add_com_region("r", [[np.nan, 0, 1]], upper=1.0, dt=0.01),
         "task 'r': normals must be finite"),
        (lambda: w.add_com_region("r", C, lower=[1.0, 0.0], upper=0.5, dt=0.01),
         "task 'r': row 0 has lower 1 > upper 0.5"),
        (lambda: w.add_com_region("r", C, lower=[0.0, np.nan], dt=0.01),
         "task 'r': lower bound 1 is NaN"),
        (lambda: w.add_com_region("r", C, lower=[0.0, -np.inf], dt=0.01),
         "task 'r': row 1 has no finite bound"),
        (lambda: w.add_com_region("r", C, lower=[0.0, 1.0, 2.0], dt=0.01),
         "task 'r': lower must be a number or 2 numbers"),
        (lambda: w.add_com_region("r", C, upper=1.0, dt=0.0), "task 'r': a region needs dt > 0"),
        (lambda: w.add_com_region("r", C, upper=1.0, dt=0.01, horizon=-1.0),
         "task 'r': horizon must be > 0"),
        (lambda: w.add_frame_region("r", "sword_tip", C, upper=1.0, dt=0.01, offset=[1, 2]),
         "task 'r': offset must be 3 finite numbers"),
        (lambda: w.add_frame_region("r", "sword_tip", C, upper=1.0, dt=0.01, offset="x"),
         "task 'r': offset must be 3 finite numbers"),
        (lambda: w.add_com_region("r", "abc", upper=1.0, dt=0.01),
         "task 'r': normals must be numbers"),
        (lambda: w.add_com_region("r", C, upper=1.0, dt="x"), "task 'r': a region needs dt"),
        (lambda: w.add_com_region("r", C, upper=1.0, dt=True), "task 'r': a region needs dt"),
    ]
    for call, message in cases:
        with pytest.raises(TaskStackError, match=message):
            call()
    with pytest.raises(KeyError, match="no frame 'sword'"):
        w.add_frame_region("r", "sword", C, upper=1.0, dt=0.01)
    w.add_com_region("r", C, upper=1.0, dt=0.01)
    w.add_frame_region("f", "sword_tip", C, upper=1.0, dt=0.01)
    with pytest.raises(TaskStackError, match="task 'r': the region was declared with 2 rows"):
        w.com_region(_state(robot, 0), "r", normals=np.eye(3))
    with pytest.raises(ValueError, match="task 'f': an acceleration-level writer needs"):
        w.frame_region(_state(robot, 0, drift=False), "f")
    with pytest.raises(TaskStackError, match="task 'f' was declared as frame_region, not "
                       "com_region"):
        w.com_region(_state(robot, 0), "f")


# ------------------------------------------------- damping and capped target rates
@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
def test_damping_rows_are_the_identity_on_every_coordinate_with_zero_target(robot, mode):
    w = TaskWriter(robot, mode)
    gain = 5.0 if mode == "velocity" else (25.0, 10.0)
    w.add_frame_position("tip", "sword_tip", gain=gain, level=0)
    w.add_damping("damping", weight=0.04, level=0)
    state = _state(robot, 1)
    w.frame_position(state, "tip", np.array([0.3, 0.2, 0.9]))
    A, b = w.targets(state).rows("damping")
    assert np.array_equal(A, np.eye(robot.nv))          # the floating base's columns too
    assert np.array_equal(b, np.zeros(robot.nv))
    assert np.all(w.data.weights("damping") == 0.2)
    assert w.layout.names == (("tip", "damping"),)


def test_a_damped_level_is_the_damped_least_squares_step(robot):
    """One level, a frame task and the damping task of weight λ²: the exact solvers
    give ``Jᵀ (J Jᵀ + λ² I)⁻¹ b`` (relative 1e-10)."""
    lam2 = 0.01
    w = TaskWriter(robot, "velocity")
    w.add_frame_position("tip", "sword_tip", gain=5.0, level=0)
    w.add_damping("damping", weight=lam2, level=0)
    state = _state(robot, 2, drift=False)
    w.frame_position(state, "tip", np.array([1.5, 0.2, 0.9]))
    data = w.targets(state)
    J, b = data.rows("tip")
    expected = J.T @ np.linalg.solve(J @ J.T + lam2 * np.eye(3), b)
    for name in ("hierarchical_active_set", "extended_jacobian", "reference"):
        x = formulations.solve(data.as_stack(), name).x
        assert np.linalg.norm(x - expected) <= 1e-10 * np.linalg.norm(expected), name


def test_max_rate_caps_the_velocity_target_and_leaves_a_smaller_one(robot):
    w = TaskWriter(robot, "velocity")
    w.add_frame_position("tip", "sword_tip", gain=10.0, level=0, max_rate=0.5)
    w.add_com("com", gain=10.0, level=0, max_rate=0.05)
    w.add_frame_orientation("turn", "left_foot", gain=10.0, level=1, max_rate=100.0)
    w.add_frame_position("free", "right_hand", gain=10.0, level=1)
    state = _state(robot, 3, drift=False)
    far = np.array([1.5, 0.2, 0.9])
    w.frame_position(state, "tip", far)
    w.com(state, "com", state.com[:2] + 0.004)             # K e = 0.0566 > 0.05
    w.frame_orientation(state, "turn", np.eye(3))
    w.frame_position(state, "free", far)
    data = w.targets(state)
    sl = w.layout.task_slice
    for name, cap in (("tip", 0.5), ("com", 0.05)):
        uncapped = 10.0 * w.error[sl(name)]
        b = data.rows(name)[1]
        assert np.linalg.norm(uncapped) > cap
        assert abs(np.linalg.norm(b) - cap) <= 1e-12 * cap
        assert _close(b / np.linalg.norm(b), uncapped / np.linalg.norm(uncapped))
    assert _close(data.rows("turn")[1], 10.0 * w.error[sl("turn")])     # under its cap
    assert _close(data.rows("free")[1], 10.0 * w.error[sl("free")])     # no cap


def test_damping_and_max_rate_errors_are_named(robot):
    w = TaskWriter(robot, "velocity")
    for bad in (0.0, -1.0, np.inf, "1", True):
        with pytest.raises(TaskStackError, match="damping weight must be finite and > 0"):
            w.add_damping("d", weight=bad)
        with pytest.raises(ValueError, match="task 'tip': max_rate must be finite and > 0"):
            w.add_frame_position("tip", "sword_tip", gain=1.0, max_rate=bad)
    assert w.tasks() == ()                          # nothing half-declared
    w.add_damping("d", weight=1e-2)
    with pytest.raises(ValueError, match="task 'd': a damping task has no gain"):
        w.set_gains("d", 1.0)
    a = TaskWriter(robot, "acceleration")
    with pytest.raises(ValueError, match="task 'tip': max_rate caps a velocity-level"):
        a.add_frame_position("tip", "sword_tip", gain=(1.0, 1.0), max_rate=1.0)


def test_a_writer_declares_hard_levels_and_a_violated_one_fails_the_solve(robot):
    """Two targets for one hand on a hard level 0 cannot both hold: the solve is
    "failed" naming level 0 and its tasks; the same rows with level 0 not hard give the
    least-squares compromise as the formulation's own status."""
    import prioik
    state = _state(robot, 8, drift=False)
    answers = {}
    for hard in ((0,), ()):
        w = TaskWriter(robot, "velocity", hard=hard)
        w.add_frame_position("reach", "left_hand", gain=1.0, level=0)
        w.add_frame_position("away", "left_hand", gain=1.0, level=0)
        w.add_posture("posture", gain=1.0, level=1)
        assert w.layout.hard == hard
        w.frame_position(state, "reach", np.array([0.3, 0.2, 1.0]))
        w.frame_position(state, "away", np.array([0.3, 0.2, 0.0]))
        w.posture(state, "posture", robot.q0)
        solver = prioik.prepare(w.layout, "hierarchical_active_set")
        answers[hard] = solver.solve(w.targets(state))
    sol, soft = answers[(0,)], answers[()]
    assert soft.status == "optimal" and sol.status == "failed"
    assert sol.diagnostics.fault.level == 0 and sol.diagnostics.fault.tasks == ("reach", "away")
    np.testing.assert_array_equal(sol.x, soft.x)
    bad = TaskWriter(robot, "velocity", hard=(1,))
    bad.add_posture("posture", gain=1.0, level=0)
    with pytest.raises(TaskStackError, match=r"hard levels must be distinct level indices "
                                             r"0 … 0, got \(1,\)"):
        _ = bad.layout
