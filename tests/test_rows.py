"""robots.rows: the in-place builders give the same rows and targets as the
TaskTerm builders of robots.tasks (velocity and acceleration level), and the fencing
velocity rows equal the scenario's velocity stack."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from prioik.robots import KinematicState, Reference, TaskRows, com_position, frame_pose, \
    frame_position, g1, posture
from prioik.robots import _rows_kernel as _k
from prioik.robots.fencing import FencingScenario

#: the two paths do the same arithmetic in another order: rows agree to rounding
TOL = 1e-12


@pytest.fixture(scope="module")
def robot():
    return g1().with_point_frame("sword_tip", "left_hand", (0.5, 0.0, 0.0))


def _state(robot, seed, drift=True):
    rng = np.random.default_rng(seed)
    q = robot.q0.copy()
    q[7:] += rng.uniform(-0.2, 0.2, robot.nq - 7)
    return KinematicState(robot, q, rng.normal(size=robot.nv), drift=drift)


def _close(a, b):
    return np.allclose(a, b, rtol=TOL, atol=TOL)


@pytest.mark.parametrize("seed", range(3))
def test_every_writer_matches_its_task_builder(robot, seed):
    state = _state(robot, seed)
    rng = np.random.default_rng(50 + seed)
    ref = Reference(rng.normal(size=3), rng.normal(size=3), rng.normal(size=3))
    rot = pin.exp3(rng.normal(size=3))
    com_ref = Reference(rng.normal(size=2), rng.normal(size=2), rng.normal(size=2))
    terms = {"pose": frame_pose(state, "left_foot", ref, rot, name="pose"),
             "tip": frame_position(state, "sword_tip", ref, name="tip"),
             "com": com_position(state, com_ref, name="com"),
             "posture": posture(state, robot.q0, name="posture")}
    gains = {"pose": (25.0, 10.0), "tip": (16.0, 8.0), "com": (9.0, 6.0), "posture": (4.0, 4.0)}
    rows = TaskRows(robot, [[("pose", 6)], [("tip", 3), ("com", 2)],
                            [("posture", robot.nv - 6)]], gains)
    rows.frame_pose(state, "pose", "left_foot", ref.x, rot, ref.xd, ref.xdd)
    rows.frame_position(state, "tip", "sword_tip", ref.x, ref.xd, ref.xdd)
    rows.com(state, "com", com_ref.x, com_ref.xd, com_ref.xdd)
    rows.posture(state, "posture", robot.q0)
    buf = rows.acceleration_targets(state.v)
    for name, term in terms.items():
        A, b = buf.rows(name)
        assert _close(A, term.J), name
        assert _close(b, term.acceleration(*gains[name]).b), name
    rows.velocity_targets()
    for name, term in terms.items():
        assert _close(buf.rows(name)[1], term.velocity(gains[name][0]).b), name


@pytest.mark.parametrize("variant", ["compatible", "incompatible"])
@pytest.mark.parametrize("t", [0.0, 0.7, 1.9, 3.0])
def test_fencing_velocity_rows_equal_the_velocity_stack(robot, variant, t):
    scenario = FencingScenario(variant, robot=robot)
    rows = scenario.velocity_rows(10.0)
    for seed in range(2):
        state = _state(robot, 10 + seed, drift=False)
        buf = scenario.write_velocity_rows(rows, state, t)
        stack = scenario.velocity_stack(_state(robot, 10 + seed), t, gain=10.0).stack
        assert [lvl.names for lvl in stack.levels] == [n for n in buf.layout.names]
        for level in stack.levels:
            for task in level:
                A, b = buf.rows(task.name)
                assert _close(A, task.A) and _close(b, task.b), task.name


def test_velocity_state_has_no_drift_and_says_so(robot):
    state = _state(robot, 0, drift=False)
    assert state.acom_drift is None
    with pytest.raises(ValueError, match="drift=False"):
        state.frame_drift("left_foot")
    rows = TaskRows(robot, [[("tip", 3)]])
    rows.frame_position(state, "tip", "sword_tip", np.zeros(3))
    assert np.all(rows.drift == 0.0)


def test_wrong_row_count_and_unknown_task_are_named(robot):
    state = _state(robot, 0)
    rows = TaskRows(robot, [[("tip", 2)]])
    with pytest.raises(ValueError, match="'tip' has 2 rows in the layout, the builder writes 3"):
        rows.frame_position(state, "tip", "sword_tip", np.zeros(3))
    from prioik.hierarchy import TaskStackError
    with pytest.raises(TaskStackError, match="no task 'com'"):
        rows.com(state, "com", np.zeros(2))


def test_writers_follow_a_reused_data_across_states(robot):
    """The writers read views of the state's ``pin.Data`` taken once: refilled by
    later states on the same ``Data``, they still equal the builders."""
    data = robot.model.createData()
    rows = TaskRows(robot, [[("tip", 3), ("com", 2)], [("pose", 6)]])
    target = np.array([0.3, 0.2, 0.9])
    rot = pin.exp3(np.array([0.1, -0.2, 0.3]))
    for seed in range(3):
        rng = np.random.default_rng(seed)
        q = robot.q0.copy()
        q[7:] += rng.uniform(-0.3, 0.3, robot.nq - 7)
        state = KinematicState(robot, q, np.zeros(robot.nv), data, drift=False)
        rows.frame_position(state, "tip", "sword_tip", target)
        rows.com(state, "com", target[:2])
        rows.frame_pose(state, "pose", "left_foot", target, rot)
        buf = rows.velocity_targets()
        fresh = KinematicState(robot, q, np.zeros(robot.nv))
        ref = Reference(target, np.zeros(3), np.zeros(3))
        for name, term in {"tip": frame_position(fresh, "sword_tip", ref, name="tip"),
                           "com": com_position(fresh, Reference(target[:2], np.zeros(2),
                                                                np.zeros(2)), name="com"),
                           "pose": frame_pose(fresh, "left_foot", ref, rot, name="pose")
                           }.items():
            A, b = buf.rows(name)
            assert _close(A, term.J) and _close(b, term.velocity(0.0).b), name
            assert _close(rows.error[rows.data.layout.task_slice(name)], term.error), name


def test_acceleration_targets_refuse_rows_written_without_drift(robot):
    rows = TaskRows(robot, [[("tip", 3)], [("com", 2)]])
    slow, fast = _state(robot, 0, drift=True), _state(robot, 0, drift=False)
    rows.frame_position(slow, "tip", "sword_tip", np.zeros(3))
    rows.com(fast, "com", np.zeros(2))
    with pytest.raises(ValueError, match=r"\['com'\].*drift=False"):
        rows.acceleration_targets(slow.v)
    rows.com(slow, "com", np.zeros(2))
    assert np.all(np.isfinite(rows.acceleration_targets(slow.v).b))


def test_targets_of_the_wrong_size_name_the_task(robot):
    state = _state(robot, 0)
    rows = TaskRows(robot, [[("tip", 3), ("com", 2), ("pose", 6)]])
    with pytest.raises(ValueError, match="task 'tip': x must have 3 entries"):
        rows.frame_position(state, "tip", "sword_tip", np.zeros(2))
    with pytest.raises(ValueError, match="task 'com': xd must have 2 entries"):
        rows.com(state, "com", np.zeros(2), np.zeros(3))
    with pytest.raises(ValueError, match="task 'pose': rotation must be 3 × 3"):
        rows.frame_pose(state, "pose", "left_foot", np.zeros(3), np.eye(2))
    with pytest.raises(ValueError, match="com axes must be among 0, 1, 2"):
        TaskRows(robot, [[("c", 1)]]).com(state, "c", np.zeros(1), axes=(3,))


def test_posture_of_joints_without_a_single_coordinate_uses_the_lie_difference():
    """A spherical joint (``n_q = 4``, ``n_v = 3``): the posture error is
    ``q_ref ⊖ q`` (pinocchio's ``difference``), as the builder."""
    from prioik.robots import RobotModel, posture as posture_term
    model = pin.Model()
    j1 = model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    model.appendBodyToJoint(j1, pin.Inertia.Random(), pin.SE3.Identity())
    j2 = model.addJoint(j1, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.3, 0, 0])),
                        "elbow")
    model.appendBodyToJoint(j2, pin.Inertia.Random(), pin.SE3.Identity())
    robot = RobotModel("ball", model, pin.neutral(model), floating_base=False)
    q = pin.integrate(model, robot.q0, np.array([0.3, -0.2, 0.5, 0.4]))
    state = KinematicState(robot, q, np.zeros(4))
    rows = TaskRows(robot, [[("posture", 4)]], {"posture": 2.0})
    rows.posture(state, "posture", robot.q0)
    term = posture_term(state, robot.q0, name="posture")
    A, b = rows.velocity_targets().rows("posture")
    assert _close(A, term.J) and _close(b, term.velocity(2.0).b)
    assert not np.allclose(rows.error, robot.q0[[0, 1, 2, 4]] - q[[0, 1, 2, 4]])


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
