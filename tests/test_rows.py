"""robots.rows: the in-place builders give the same rows and targets as the
TaskTerm builders of robots.tasks (velocity and acceleration level), and the fencing
velocity rows equal the scenario's velocity stack."""

import numpy as np
import pinocchio as pin
import pytest

from robots import KinematicState, Reference, TaskRows, com_position, frame_pose, \
    frame_position, g1, posture
from robots.fencing import FencingScenario

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
        assert [lvl.names for lvl in stack.levels] == [n for n in buf.names]
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
    from hierarchy import TaskStackError
    with pytest.raises(TaskStackError, match="no task 'com'"):
        rows.com(state, "com", np.zeros(2))
