"""robots.tasks and robots.references: finite-difference checks of every Jacobian and
J̇q̇ term, the task equations (eq. 2-4 and the velocity form), both joint-limit forms and
the region (inequality) tasks.

Derivatives are checked by central differences along ``q(s) = q ⊕ s v`` (constant
velocity in pinocchio's convention, ``q̈ = 0``) with ``h = 1e-6``: ``ẋ = J v`` against
``(x(h) − x(−h)) / 2h`` and ``J̇ v`` against ``(J(h) v − J(−h) v) / 2h``, to
``1e-6 · (1 + |value|)`` (the truncation error is ``O(h²)``, the round-off ``O(ε/h)``).
"""

import numpy as np
import pinocchio as pin
import pytest

from prioik.hierarchy import TaskStackError
from prioik.robots import (
    JointLimitActivation,
    KinematicState,
    Reference,
    StateError,
    Waypoints,
    com_position,
    com_region,
    contact,
    frame_orientation,
    frame_pose,
    frame_position,
    frame_region,
    g1,
    go2,
    joint_limit_bounds,
    joint_limit_rows,
    joint_limit_violation,
    joint_velocity_bounds,
    minimum_jerk,
    panda,
    point_position,
    polygon_region,
    posture,
    sample_humanoid,
    spatial_chain,
)

H = 1e-6
TOL = 1e-6


@pytest.fixture(scope="module")
def robots_under_test():
    sword = g1().with_point_frame("sword_tip", "left_hand", (0.5, 0.0, 0.0))
    return {"g1": (sword, ["sword_tip", "left_foot", "right_foot", "torso"]),
            "sample_humanoid": (sample_humanoid(), ["left_hand", "right_foot"]),
            "chain7": (spatial_chain(7), ["tip"]),
            "panda": (panda(), ["tcp", "panda_link4"]),
            "go2": (go2(), ["front_left_foot", "rear_right_foot"])}


def _random_state(robot, seed):
    rng = np.random.default_rng(seed)
    q = robot.q0.copy()
    nb = robot.n_base
    if nb:
        q[7:] += rng.uniform(-0.2, 0.2, robot.nq - 7)
    else:
        q += rng.uniform(-0.2, 0.2, robot.nq)
    v = rng.normal(size=robot.nv)
    return q, v


def _states(robot, q, v):
    plus = KinematicState(robot, pin.integrate(robot.model, q, v * H), v)
    minus = KinematicState(robot, pin.integrate(robot.model, q, -v * H), v)
    return KinematicState(robot, q, v), plus, minus


def _close(a, b):
    return np.abs(np.asarray(a) - np.asarray(b)).max() <= TOL * (1 + np.abs(b).max())


@pytest.mark.parametrize("name", ["g1", "sample_humanoid", "chain7"])
@pytest.mark.parametrize("seed", range(3))
def test_frame_jacobians_and_drift_match_finite_differences(robots_under_test, name, seed):
    robot, frames = robots_under_test[name]
    q, v = _random_state(robot, seed)
    s0, sp, sm = _states(robot, q, v)
    for f in frames:
        J = s0.frame_jacobian(f)
        # linear rows: velocity of the frame origin in world coordinates
        dp = (sp.placement(f).translation - sm.placement(f).translation) / (2 * H)
        assert _close(J[:3] @ v, dp), f
        # angular rows: world angular velocity, from log(R(h) R(−h)ᵀ) / 2h
        dR = pin.log3(sp.placement(f).rotation @ sm.placement(f).rotation.T) / (2 * H)
        assert _close(J[3:] @ v, dR), f
        # drift J̇ q̇ = d/dt (J q̇) at q̈ = 0
        dJv = (sp.frame_jacobian(f) @ v - sm.frame_jacobian(f) @ v) / (2 * H)
        assert _close(s0.frame_drift(f), dJv), f
        assert np.abs(s0.frame_drift(f)).max() > 1e-3  # the check is not vacuous


@pytest.mark.parametrize("name", ["g1", "sample_humanoid", "chain7", "panda", "go2"])
@pytest.mark.parametrize("seed", range(2))
def test_every_writer_jacobian_and_drift_match_finite_differences(robots_under_test, name,
                                                                   seed):
    """The builders' (i.e. the compiled writers') rows: frame position, a point on a
    frame, orientation, pose, CoM — ``J v`` against the rate of the task value and
    ``J̇ v`` against the rate of ``J v``; the drift-free state gives the same ``J``."""
    robot, frames = robots_under_test[name]
    q, v = _random_state(robot, 20 + seed)
    s0, sp, sm = _states(robot, q, v)
    light = KinematicState(robot, q, v, drift=False)
    ref = Reference(np.zeros(3), np.zeros(3), np.zeros(3))
    off = np.array([0.05, -0.1, 0.2])

    def point(s, f):
        M = s.placement(f)
        return M.translation + M.rotation @ off

    for f in frames:
        for build, value in (
                (lambda s, f=f: frame_position(s, f, ref),
                 lambda s, f=f: s.placement(f).translation),
                (lambda s, f=f: point_position(s, f, off, ref), lambda s, f=f: point(s, f))):
            t0, tp, tm = build(s0), build(sp), build(sm)
            assert _close(t0.J @ v, (value(sp) - value(sm)) / (2 * H)), f
            assert _close(t0.drift, (tp.J @ v - tm.J @ v) / (2 * H)), f
            assert np.array_equal(build(light).J, t0.J) and build(light).drift is None
        R = s0.placement(f).rotation
        for build in (lambda s, f=f, R=R: frame_orientation(s, f, R),
                      lambda s, f=f, R=R: frame_pose(s, f, ref, R)):
            t0, tp, tm = build(s0), build(sp), build(sm)
            dR = pin.log3(sp.placement(f).rotation @ sm.placement(f).rotation.T) / (2 * H)
            assert _close((t0.J @ v)[-3:], dR), f
            assert _close(t0.drift, (tp.J @ v - tm.J @ v) / (2 * H)), f
            assert np.abs(t0.drift).max() > 1e-3                  # not vacuous
    cref = Reference(np.zeros(3), np.zeros(3), np.zeros(3))
    c0, cp, cm = (com_position(s, cref, axes=(0, 1, 2)) for s in (s0, sp, sm))
    assert _close(c0.J @ v, (sp.com - sm.com) / (2 * H))
    assert _close(c0.drift, (cp.J @ v - cm.J @ v) / (2 * H))
    assert np.array_equal(com_position(light, cref, axes=(0, 1, 2)).J, c0.J)


@pytest.mark.parametrize("name", ["g1", "sample_humanoid", "chain7"])
def test_com_jacobian_and_drift_match_finite_differences(robots_under_test, name):
    robot, _ = robots_under_test[name]
    q, v = _random_state(robot, 11)
    s0, sp, sm = _states(robot, q, v)
    assert _close(s0.Jcom @ v, (sp.com - sm.com) / (2 * H))
    assert _close(s0.vcom, s0.Jcom @ v)
    assert _close(s0.acom_drift, (sp.Jcom @ v - sm.Jcom @ v) / (2 * H))


def test_task_terms_give_the_acceleration_and_velocity_equations(robots_under_test):
    robot, _ = robots_under_test["g1"]
    q, v = _random_state(robot, 5)
    s = KinematicState(robot, q, v)
    ref = Reference(np.array([0.4, 0.2, 0.8]), np.array([0.1, 0.0, -0.2]),
                    np.array([1.0, 2.0, 3.0]))
    term = frame_position(s, "sword_tip", ref)
    p = s.placement("sword_tip").translation
    J = s.frame_jacobian("sword_tip")[:3]
    kp, kd = 25.0, 10.0
    task = term.acceleration(kp, kd)
    h = ref.xdd + kd * (ref.xd - J @ v) + kp * (ref.x - p) - s.frame_drift("sword_tip")[:3]
    assert np.allclose(task.A, J, rtol=0, atol=1e-15)
    assert np.allclose(task.b, h, rtol=1e-13, atol=1e-13)
    vel = term.velocity(3.0)
    assert np.allclose(vel.b, ref.xd + 3.0 * (ref.x - p), rtol=1e-13, atol=1e-13)
    # with q̈ solving J q̈ = h the task-space acceleration is the commanded one
    a = np.linalg.lstsq(J, task.b, rcond=None)[0]
    xdd = J @ a + s.frame_drift("sword_tip")[:3]
    assert np.allclose(xdd, ref.xdd + kd * term.rate_error + kp * term.error, atol=1e-9)


def test_orientation_pose_and_contact_errors(robots_under_test):
    robot, _ = robots_under_test["g1"]
    q, v = _random_state(robot, 6)
    s = KinematicState(robot, q, v)
    M = s.placement("left_foot")
    o = frame_orientation(s, "left_foot", M.rotation)
    assert np.abs(o.error).max() < 1e-12
    rot = pin.exp3(np.array([0.0, 0.0, 0.1])) @ M.rotation
    o2 = frame_orientation(s, "left_foot", rot)
    assert o2.error == pytest.approx([0, 0, 0.1], abs=1e-12)
    c = contact(s, "left_foot", M)
    assert c.J.shape == (6, 35) and np.abs(c.error).max() < 1e-12
    assert np.allclose(c.rate_error, -s.frame_velocity("left_foot"), atol=1e-14)
    ref = Reference(M.translation + [0.1, 0, 0], np.zeros(3), np.zeros(3))
    pose = frame_pose(s, "left_foot", ref, M.rotation)
    assert pose.error == pytest.approx([0.1, 0, 0, 0, 0, 0], abs=1e-12)


def test_com_task_selects_horizontal_axes(robots_under_test):
    robot, _ = robots_under_test["g1"]
    q, v = _random_state(robot, 7)
    s = KinematicState(robot, q, v)
    term = com_position(s, Reference(np.zeros(2), np.zeros(2), np.zeros(2)))
    assert term.J.shape == (2, 35)
    assert np.allclose(term.error, -s.com[:2]) and np.allclose(term.drift, s.acom_drift[:2])


def test_posture_rows_are_the_actuated_joints(robots_under_test):
    robot, _ = robots_under_test["g1"]
    q, v = _random_state(robot, 8)
    s = KinematicState(robot, q, v)
    term = posture(s, robot.q0)
    assert term.J.shape == (29, 35) and np.all(term.J[:, :6] == 0)
    assert np.allclose(term.error, robot.q0[7:] - q[7:], atol=1e-12)
    assert np.allclose(term.rate_error, -v[6:])


def test_state_copies_its_inputs(robots_under_test):
    robot, _ = robots_under_test["chain7"]
    q, v = _random_state(robot, 1)
    q_in, v_in = q.copy(), v.copy()
    s = KinematicState(robot, q, v)
    q[:] = 0
    assert np.array_equal(s.q, q_in) and np.array_equal(v, v_in)
    with pytest.raises(ValueError, match="entries"):
        KinematicState(robot, q[:3], v)


# ----------------------------------------------------------------- joint limits
def test_activation_rows_only_near_limits_and_push_away():
    robot = spatial_chain(4)
    q = np.zeros(4)
    v = np.zeros(4)
    assert joint_limit_rows(KinematicState(robot, q, v)) is None
    q = np.array([-2.45, 0.0, 2.47, 0.0])      # limits ±2.5, margin 0.1
    v = np.array([-1.0, 0.0, 1.0, 0.0])
    task = joint_limit_rows(KinematicState(robot, q, v))
    assert task.m == 2 and np.array_equal(np.flatnonzero(task.A.any(0)), [0, 2])
    assert task.b[0] > 0 and task.b[1] < 0
    p = JointLimitActivation()
    y, s = 0.05, 0.5                            # joint 0: depth 0.05 of 0.1
    assert task.b[0] == pytest.approx(s * (p.kp * y + p.kd * 1.0))


@pytest.mark.parametrize("v0", [0.5, 1.0, 3.0, 5.0])
def test_activation_target_stops_a_joint_inside_its_margin(v0):
    """1-D check of the blend: a joint entering the margin at v0 stops before the limit."""
    robot = spatial_chain(1)
    q, v, dt = np.array([2.39]), np.array([v0]), 1e-4
    qmax = q[0]
    for _ in range(20000):
        task = joint_limit_rows(KinematicState(robot, q, v))
        a = 0.0 if task is None else task.b[0]
        v = v + a * dt
        q = q + v * dt
        qmax = max(qmax, q[0])
    assert qmax < 2.5 and v[0] <= 0


@pytest.mark.parametrize("seed", range(3))
def test_velocity_bounds_keep_a_joint_inside_at_its_speed(seed):
    """At velocity level a joint commanded hard towards its limits, clipped to the bounds
    on q̇ every step, stays within its position limits and its speed."""
    robot = spatial_chain(1)
    rng = np.random.default_rng(seed)
    q, dt = np.array([2.0]), 0.002
    for k in range(2000):
        demand = rng.normal(0, 5.0) + (20.0 if (k // 400) % 2 == 0 else -20.0)
        task = joint_velocity_bounds(KinematicState(robot, q, np.zeros(1), drift=False), dt)
        qd = np.clip(demand, task.lower, task.upper)
        assert abs(qd[0]) <= 10.0 + 1e-12
        q = q + qd * dt
        assert joint_limit_violation(robot, q) < 1e-12


def test_bounds_respect_speed_and_are_consistent():
    robot = spatial_chain(5)
    rng = np.random.default_rng(3)
    _, _, vmax = robot.joint_limits()
    T, dt = 0.1, 0.002
    for _ in range(50):
        q = rng.uniform(-2.4, 2.4, 5)
        v = rng.uniform(-3, 3, 5)
        task = joint_limit_bounds(KinematicState(robot, q, v), T, dt)
        assert task.m == 5 and not task.is_equality
        assert np.all(task.lower <= task.upper)
        for a in (task.lower, task.upper):
            assert np.all(np.abs(v + a * dt) <= vmax + 1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_bounds_keep_a_joint_pushed_at_its_limit_inside(seed):
    """A joint driven hard towards its limits by random demands, clipped to the bounds
    every step, never passes a limit (beyond 1e-9 rad) and never exceeds its speed."""
    robot = spatial_chain(1)
    rng = np.random.default_rng(seed)
    q, v, dt = np.array([2.0]), np.array([0.0]), 0.002
    worst = 0.0
    for k in range(3000):
        demand = rng.normal(0, 200.0) + (300.0 if (k // 500) % 2 == 0 else -300.0)
        task = joint_limit_bounds(KinematicState(robot, q, v), 0.1, dt)
        a = np.clip(demand, task.lower, task.upper)
        v = v + a * dt
        q = q + v * dt
        worst = max(worst, joint_limit_violation(robot, q))
        assert abs(v[0]) <= 10.0 + 1e-9
    assert worst < 1e-9


def test_joint_limit_violation():
    robot = spatial_chain(3)
    assert joint_limit_violation(robot, np.array([0.0, 2.5, -2.5])) == 0.0
    assert joint_limit_violation(robot, np.array([0.0, 2.6, -2.7])) == pytest.approx(0.2)


@pytest.mark.parametrize("q, message", [
    (np.array([0.0, np.nan, 0.0]), r"q holds non-finite values at entries \[1\]"),  # was 0.0
    (np.zeros(4), r"q must have 3 entries for robot 'chain3', got shape \(4,\)"),  # IndexError
    (np.zeros((3, 1)), r"got shape \(3, 1\)"),
    (["a", 0, 0], "q cannot be read as numbers"),
])
def test_joint_limit_violation_refuses_a_bad_q(q, message):
    with pytest.raises(StateError, match=message):
        joint_limit_violation(spatial_chain(3), q)


# ------------------------------------------------------------------ robot states
def _g1_state():
    robot = g1()
    return robot, robot.q0.copy(), np.zeros(robot.nv)


@pytest.mark.parametrize("change, message", [
    (lambda q, v: q.__setitem__(slice(3, 7), 0.0),
     r"q\[3:7\] \(joint 'root_joint', quaternion\) has norm 0"),      # was accepted
    (lambda q, v: q.__setitem__(slice(3, 7), [0, 0, 0, 2.0]), "has norm 2"),
    (lambda q, v: q.__setitem__(10, np.nan), r"q holds non-finite values at entries \[10\]"),
    (lambda q, v: q.__setitem__(0, np.inf), r"q holds non-finite values at entries \[0\]"),
    (lambda q, v: v.__setitem__(4, np.nan), r"v holds non-finite values at entries \[4\]"),
])
def test_kinematic_state_refuses_a_bad_state(change, message):
    robot, q, v = _g1_state()
    change(q, v)
    with pytest.raises(StateError, match=message):
        KinematicState(robot, q, v)


@pytest.mark.parametrize("change, message", [
    (lambda q, v: q.__setitem__(2, np.nan), r"q holds non-finite values at entries \[2\]"),
    (lambda q, v: v.__setitem__(8, -np.inf), r"v holds non-finite values at entries \[8\]"),
])
def test_kinematic_state_of_a_fixed_base_arm_refuses_a_bad_state(change, message):
    """The Panda (no unit-norm part: the compiled check alone decides) names the entry."""
    from prioik.robots import panda
    robot = panda()
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    change(q, v)
    with pytest.raises(StateError, match=message):
        KinematicState(robot, q, v, drift=False)


def test_kinematic_state_copies_its_state_and_reads_any_sequence():
    robot, q, v = _g1_state()
    state = KinematicState(robot, q, v, drift=False)
    q[10] += 1.0
    v[3] = 5.0
    assert state.q[10] == robot.q0[10] and state.v[3] == 0.0
    listed = KinematicState(robot, robot.q0.tolist(), [0] * robot.nv, drift=False)
    assert np.array_equal(listed.q, robot.q0) and listed.v.dtype == np.float64
    assert np.array_equal(listed.data.oMf[3].homogeneous,
                          KinematicState(robot, robot.q0, v * 0, drift=False).data.oMf[3]
                          .homogeneous)


@pytest.mark.parametrize("q, v", [(np.zeros(35), np.zeros(35)), (None, np.zeros(34))])
def test_kinematic_state_refuses_wrong_sizes(q, v):
    robot, q0, _ = _g1_state()
    with pytest.raises(StateError, match="must have 3[56] entries for robot 'g1'"):
        KinematicState(robot, q0 if q is None else q, v)


def test_a_q_outside_the_limits_is_accepted_and_reported_by_the_limit_tasks():
    robot = spatial_chain(3)
    lo, hi, _ = robot.joint_limits()
    q = np.array([0.0, hi[1] + 1e6, lo[2] - 0.5])
    state = KinematicState(robot, q, np.zeros(3))
    assert state.limit_violation == pytest.approx(1e6)
    assert joint_limit_violation(robot, q) == pytest.approx(1e6)
    rows = joint_limit_rows(state)                  # both joints get a push-back row
    assert rows.A[:, 1:].tolist() == [[1.0, 0.0], [0.0, 1.0]]
    assert rows.b[0] < 0 < rows.b[1]
    bounds = joint_limit_bounds(state, 0.1, 0.002)  # q̈ must move them back inside
    assert bounds.upper[1] < 0 and bounds.lower[2] > 0


# ------------------------------------------------------------------- references
def test_minimum_jerk_endpoints_and_derivatives():
    x0, x1 = np.array([0.0, 1.0]), np.array([2.0, -1.0])
    start = minimum_jerk(x0, x1, 1.0, 2.0, 0.5)
    end = minimum_jerk(x0, x1, 1.0, 2.0, 3.5)
    assert np.array_equal(start.x, x0) and np.array_equal(end.x, x1)
    for r in (start, end, minimum_jerk(x0, x1, 1.0, 2.0, 1.0)):
        assert np.abs(r.xd).max() == 0 and np.abs(r.xdd).max() < 1e-12
    mid = minimum_jerk(x0, x1, 1.0, 2.0, 2.0)
    assert mid.x == pytest.approx(0.5 * (x0 + x1))
    h = 1e-5
    for t in (1.3, 2.0, 2.7):
        r = minimum_jerk(x0, x1, 1.0, 2.0, t)
        rp, rm = minimum_jerk(x0, x1, 1.0, 2.0, t + h), minimum_jerk(x0, x1, 1.0, 2.0, t - h)
        assert r.xd == pytest.approx((rp.x - rm.x) / (2 * h), abs=1e-8)
        assert r.xdd == pytest.approx((rp.xd - rm.xd) / (2 * h), abs=1e-7)
    with pytest.raises(ValueError, match="duration"):
        minimum_jerk(x0, x1, 0.0, 0.0, 0.0)


def test_waypoints_pass_through_points_and_hold():
    w = Waypoints((0.0, 1.0, 2.0), (0.0, 0.5, 0.0))
    assert w(-1.0).x == 0.0 and w(1.0).x == pytest.approx(0.5) and w(5.0).x == 0.0
    assert 0 < w(0.5).x < 0.5 and w(0.5).xd > 0 and w(1.5).xd < 0
    with pytest.raises(ValueError, match="increase"):
        Waypoints((0.0, 0.0), (1.0, 2.0))


def test_waypoints_scalar_is_the_reference_as_floats():
    w = Waypoints((0.0, 1.0, 2.0), (0.1, 0.5, -0.2))
    for t in (-1.0, 0.0, 0.3, 1.0, 1.7, 2.0, 5.0):
        r, f = w(t), w.scalar(t)
        assert all(type(v) is float for v in f)
        assert f == pytest.approx((float(r.x), float(r.xd), float(r.xdd)), abs=1e-15)
    assert w.scalar(1.7)[1] < 0 and w.scalar(5.0) == pytest.approx((-0.2, 0.0, 0.0), abs=1e-15)
    with pytest.raises(ValueError, match="scalar points"):
        Waypoints((0.0, 1.0), ((0.0, 1.0), (1.0, 2.0))).scalar(0.5)


# ------------------------------------------------------------------------- regions
@pytest.mark.parametrize("name", ["g1", "panda", "go2"])
@pytest.mark.parametrize("seed", range(2))
def test_region_rows_and_bounds_match_finite_differences(robots_under_test, name, seed):
    """``frame_region`` (a point off the frame) and ``com_region``: the rows are ``C J``
    (``C J v`` against the rate of ``C p``); the bounds, with every quantity from
    pinocchio's placements and finite differences: at velocity level ``(bound − C p)/T``;
    at acceleration level, far from the bounds (the horizon rule binds, no braking),
    ``2 (bound − C p − C ṗ T)/T² − C J̇ v``."""
    robot, frames = robots_under_test[name]
    q, v = _random_state(robot, 40 + seed)
    s0, sp, sm = _states(robot, q, v)
    light = KinematicState(robot, q, v, drift=False)
    rng = np.random.default_rng(seed)
    C = rng.normal(size=(3, 3))
    off = np.array([0.05, -0.1, 0.2])
    T, dt = 0.1, 0.01
    subjects = [(lambda s, **kw: frame_region(s, frames[0], C, *kw["b"], dt=dt, horizon=T,
                                              offset=off, mode=kw["mode"]),
                 lambda s: s.placement(frames[0]).translation
                 + s.placement(frames[0]).rotation @ off),
                (lambda s, **kw: com_region(s, C, *kw["b"], dt=dt, horizon=T,
                                            mode=kw["mode"]),
                 lambda s: s.com)]
    for build, point in subjects:
        y = C @ point(s0)
        yd = C @ (point(sp) - point(sm)) / (2 * H)
        lo, hi = y - 1.0, y + np.array([1.0, np.inf, 2.0])
        vel = build(light, b=(lo, hi), mode="velocity")
        assert _close(vel.A @ v, yd)
        assert _close(vel.lower, (lo - y) / T)
        assert _close(vel.upper[[0, 2]], ((hi - y) / T)[[0, 2]]) and vel.upper[1] == np.inf
        acc = build(s0, b=(lo, hi), mode="acceleration")
        assert np.array_equal(acc.A, vel.A)
        accp, accm = (build(s, b=(lo, hi), mode="acceleration") for s in (sp, sm))
        cdrift = (accp.A @ v - accm.A @ v) / (2 * H)
        assert np.abs(cdrift).max() > 1e-3                       # not vacuous
        assert _close(acc.lower, 2 * (lo - y - yd * T) / T ** 2 - cdrift)
        assert _close(acc.upper[[0, 2]], (2 * (hi - y - yd * T) / T ** 2 - cdrift)[[0, 2]])
        assert acc.upper[1] == np.inf


def test_velocity_region_bounds_hold_the_step_that_meets_them():
    """A q̇ on a velocity-level region's bound moves ``C p`` to the bound in ``T`` up to
    the step's curvature (``O(T²)``: here below 1e-6 m for ``‖q̇‖ T`` ~ 1e-3)."""
    robot = g1()
    s = KinematicState(robot, robot.q0, np.zeros(robot.nv), drift=False)
    p = s.placement("left_hand").translation
    n = np.array([0.6, 0.0, 0.8])
    T = 0.01
    task = frame_region(s, "left_hand", n, upper=n @ p + 1e-3, dt=T)
    qd = task.A[0] * (task.upper[0] / (task.A[0] @ task.A[0]))
    after = KinematicState(robot, pin.integrate(robot.model, robot.q0, qd * T), qd,
                           drift=False)
    assert abs(n @ after.placement("left_hand").translation - (n @ p + 1e-3)) < 1e-6
    assert task.lower[0] == -np.inf


def test_polygon_region_is_the_hull_shrunk_by_the_margin():
    """Unit outward normals, one per hull edge (interior and collinear points dropped),
    counter-clockwise; the margin moves every edge inwards."""
    square = [[1, 1], [-1, 1], [-1, -1], [1, -1], [0, 0], [1, 0], [0.2, -0.5]]
    C, upper = polygon_region(square, margin=0.25)
    assert C.shape == (4, 3) and np.all(C[:, 2] == 0)
    assert np.allclose(np.linalg.norm(C, axis=1), 1)
    assert sorted(map(tuple, np.round(C[:, :2], 12) + 0.0)) == [(-1, 0), (0, -1), (0, 1),
                                                                  (1, 0)]
    assert np.allclose(upper, 0.75)
    inside = np.array([0.7, -0.74, 3.0])
    assert np.all(C @ inside <= upper)
    assert np.any(C @ np.array([0.8, 0.0, 0.0]) > upper)
    tri, tu = polygon_region([[0, 0, 5], [2, 0, 5], [0, 2, 5], [1, 1, 5]])
    rows = sorted(zip(map(tuple, np.round(tri[:, :2], 12) + 0.0), np.round(tu, 12) + 0.0,
                      strict=True))
    r = np.round(2 ** -0.5, 12)
    assert rows == [((-1, 0), 0), ((0, -1), 0), ((r, r), np.round(2 ** 0.5, 12))]


@pytest.mark.parametrize("points, margin, message", [
    ([[0, 0], [1, 1], [2, 2]], 0.0, "no area"),
    ([[0, 0], [1, 0]], 0.0, "no area"),
    ([[0, 0], [1, 0], [0, np.nan]], 0.0, "finite"),
    ([[0, 0, 0, 0]], 0.0, "k × 2 or k × 3"),
    ([[0, 0], [1, 0], [0, 1]], -0.1, "margin"),
    ([[0, 0], [1, 0], [0, 1]], 0.5, "leaves"),
    ("abc", 0.0, "numbers"),
])
def test_polygon_region_refuses_what_has_no_region(points, margin, message):
    with pytest.raises(TaskStackError, match=message):
        polygon_region(points, margin=margin)


def test_region_builders_name_their_task_in_errors_and_answers():
    """The builders' tasks carry the given name (default ``<frame>_region``,
    ``com_region``), their errors too."""
    robot = g1()
    s = KinematicState(robot, robot.q0, np.zeros(robot.nv), drift=False)
    assert frame_region(s, "left_hand", [0, 0, 1], upper=1.0, dt=0.01).name == \
        "left_hand_region"
    assert com_region(s, [1, 0, 0], upper=1.0, dt=0.01, name="over_feet").name == "over_feet"
    with pytest.raises(TaskStackError, match="task 'wall': normals must be numbers"):
        frame_region(s, "left_hand", "abc", upper=1.0, dt=0.01, name="wall")
