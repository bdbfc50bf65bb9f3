"""robots.kinds and the task-kind registry: every registered kind's rows against finite
differences, and a toy kind registered here that the writer, a one-off stack and the
PlaCo and pink baselines take with no other edit.

Derivatives by central differences along ``q(s) = q ⊕ s v`` (``q̈ = 0``), ``h = 1e-6``:
``J v`` against the rate of the kind's task value and, for the equality kinds, the
drift ``J̇ v`` against the rate of ``J v``, to ``1e-6 · (1 + |value|)`` (truncation
``O(h²)``, round-off ``O(ε/h)``). A kind's value is its error's opposite (``e = x* − x``,
the target held at the first state) unless the sample gives it.
"""

import numpy as np
import pinocchio as pin
import pytest

import prioik
from prioik.hierarchy import TaskStack, TaskStackError
from prioik.robots import (
    TASK_KINDS,
    ComRegionTask,
    ComTask,
    ContactTask,
    DampingTask,
    FrameOrientationTask,
    FramePoseTask,
    FramePositionTask,
    FrameRegionTask,
    JointLimitsTask,
    KinematicState,
    PointTask,
    PostureTask,
    RobotTask,
    TaskWriter,
    g1,
    posture,
    register_task_kind,
    task_kind,
)
from prioik.robots.arm import TOOL, ArmScenario
from prioik.robots.scenario import BaselineTask

H = 1e-6
TOL = 1e-6
OFFSET = np.array([0.05, -0.1, 0.2])
NORMALS = np.array([[1.0, 0.0, 0.0], [0.3, -0.4, 0.5]])


@pytest.fixture(scope="module")
def robot():
    return g1().with_point_frame("sword_tip", "left_hand", (0.5, 0.0, 0.0))


def _states(robot, seed):
    rng = np.random.default_rng(seed)
    q = robot.q0.copy()
    q[7:] += rng.uniform(-0.2, 0.2, robot.nq - 7)
    v = rng.normal(size=robot.nv)
    return v, [KinematicState(robot, pin.integrate(robot.model, q, s * v), v)
               for s in (0.0, H, -H)]


def _point(state, frame, offset=OFFSET):
    M = state.placement(frame)
    return M.translation + M.rotation @ offset


def _displacement(s0):
    """The value ``q ⊖ q_0`` (``n_v``): its rate along ``q ⊕ s v`` is ``v``."""
    return lambda s, e: pin.difference(s0.robot.model, s0.q, s.q)


#: kind → (the task, its references at the first state, its value or None: ``−e``)
SAMPLES = {
    "frame_position": lambda s0: (FramePositionTask("t", "sword_tip", gain=(1.0, 1.0)),
                                  (np.zeros(3),), None),
    "point": lambda s0: (PointTask("t", "left_hand", OFFSET, gain=(1.0, 1.0)),
                         (np.zeros(3),), lambda s, e: _point(s, "left_hand")),
    "frame_orientation": lambda s0: (FrameOrientationTask("t", "torso", gain=(1.0, 1.0)),
                                     (s0.placement("torso").rotation.copy(),), None),
    "frame_pose": lambda s0: (FramePoseTask("t", "left_foot", gain=(1.0, 1.0)),
                              (np.zeros(3), s0.placement("left_foot").rotation.copy()),
                              None),
    "contact": lambda s0: (ContactTask("t", "right_foot", gain=(1.0, 1.0)),
                           (pin.SE3(s0.placement("right_foot")),), None),
    "com": lambda s0: (ComTask("t", gain=(1.0, 1.0), axes=(0, 1, 2)), (np.zeros(3),), None),
    "posture": lambda s0: (PostureTask("t", gain=(1.0, 1.0)), (s0.robot.q0,), None),
    "damping": lambda s0: (DampingTask("t", weight=0.01), (), _displacement(s0)),
    "joint_limits": lambda s0: (
        JointLimitsTask("t", form="bounds", dt=0.01, horizon=0.05), (),
        lambda s, e: _displacement(s0)(s, e)[s0.robot.n_base:]),
    "frame_region": lambda s0: (
        FrameRegionTask("t", "left_hand", NORMALS, upper=[2.0, 2.0], dt=0.01,
                        offset=OFFSET), (),
        lambda s, e: NORMALS @ _point(s, "left_hand")),
    "com_region": lambda s0: (ComRegionTask("t", NORMALS, upper=[2.0, 2.0], dt=0.01), (),
                              lambda s, e: NORMALS @ s.com),
}


def test_every_registered_kind_has_a_sample():
    assert sorted(SAMPLES) == sorted(TASK_KINDS)


@pytest.mark.parametrize("kind", sorted(TASK_KINDS))
@pytest.mark.parametrize("seed", range(2))
def test_every_kind_jacobian_and_drift_match_finite_differences(robot, kind, seed):
    v, states = _states(robot, 30 + seed)
    task, refs, value = SAMPLES[kind](states[0])
    assert type(task) is task_kind(kind)
    w = TaskWriter(robot, "acceleration")
    w.add(task)
    sl = w.layout.task_slice("t")
    out = []
    for s in states:
        task.write(s, *refs)
        out.append((w.data.A[sl].copy(), w.error[sl].copy(), w.drift[sl].copy()))
    (J0, _, d0), (Jp, _, _), (Jm, _, _) = out
    vals = [(-e if value is None else value(s, e))
            for s, (_, e, _) in zip(states, out, strict=True)]
    rate = (vals[1] - vals[2]) / (2 * H)
    assert np.abs(J0 @ v - rate).max() <= TOL * (1 + np.abs(rate).max()), kind
    assert np.abs(rate).max() > 1e-3, kind                     # not vacuous
    if not task.inequality:
        drift = (Jp @ v - Jm @ v) / (2 * H)
        assert np.abs(d0 - drift).max() <= TOL * (1 + np.abs(drift).max()), kind


def test_every_kind_gives_its_one_off_term_as_its_writer_rows(robot):
    """:meth:`RobotTask.term` is the rows a writer of the kind writes (named by the
    task); inequality kinds give their bounds task."""
    v, states = _states(robot, 5)
    s0 = states[0]
    for kind in sorted(TASK_KINDS):
        task, refs, _ = SAMPLES[kind](s0)
        w = TaskWriter(robot, "acceleration")
        w.add(task)
        task.write(s0, *refs)
        sl = w.layout.task_slice("t")
        fresh, _, _ = SAMPLES[kind](s0)
        fresh.name = "named"
        term = fresh.term(s0, *refs)
        assert term.name == "named", kind
        if task.inequality:
            A, lower, upper = w.data.bounds("t")
            assert np.array_equal(term.A, A) and np.array_equal(term.lower, lower), kind
            assert np.array_equal(term.upper, upper), kind
        else:
            assert np.array_equal(term.J, w.data.A[sl]), kind
            assert np.array_equal(term.error, w.error[sl]), kind


def test_registry_refuses_what_is_not_a_task_kind():
    with pytest.raises(TaskStackError, match="a task kind is a RobotTask subclass"):
        register_task_kind(int)

    class Clash(RobotTask):
        kind = "posture"
    with pytest.raises(TaskStackError, match="task kind 'posture' is already PostureTask"):
        register_task_kind(Clash)

    class Unnamed(RobotTask):
        pass
    with pytest.raises(TaskStackError, match="kind must be an identifier"):
        register_task_kind(Unnamed)
    with pytest.raises(TaskStackError, match="no task kind 'nosuch'.*frame_position"):
        task_kind("nosuch")
    assert TASK_KINDS["posture"] is PostureTask


def test_a_task_is_in_one_writer_and_named_writers_check_its_kind(robot):
    w = TaskWriter(robot, "velocity")
    task = w.add(PostureTask(gain=1.0))
    with pytest.raises(TaskStackError, match="already in a TaskWriter"):
        TaskWriter(robot, "velocity").add(task)
    with pytest.raises(TaskStackError, match="declared as posture, not com"):
        w.com(_states(robot, 0)[1][0], "posture", np.zeros(2))
    with pytest.raises(TaskStackError, match="FrameHeightTask is not a registered task kind"):
        w.add(FrameHeightTask("height", "sword_tip", gain=1.0))
    with pytest.raises(TaskStackError, match="a damping task takes no gain"):
        TaskWriter(robot, "velocity").add(_with_gain(DampingTask(weight=1.0)))
    with pytest.raises(TaskStackError, match="is in no TaskWriter"):
        PostureTask(gain=1.0).write(_states(robot, 0)[1][0], robot.q0)


def _with_gain(task):
    task.gain = 1.0
    return task


# ------------------------------------------------------------------ the toy kind
class FrameHeightTask(RobotTask):
    """A toy kind: the height (world z) of a frame's origin, one row, written in plain
    Python; PlaCo's position task masked to z, pink's frame task holding the frame's
    first x, y."""

    kind = "frame_height"

    def __init__(self, name, frame, *, gain=None, level=None, weight=1.0, keep=False):
        super().__init__(name, gain=gain, level=level, weight=weight, keep=keep)
        self.frame = frame

    def key(self):
        return (self.frame,)

    def declare(self, writer):
        writer.robot.frame_id(self.frame)
        return 1

    def write(self, state, z):
        w = self.ready_writer()
        i = self.start
        w.data.A[i] = state.frame_jacobian(self.frame)[2]
        w.error[i] = z - state.placement(self.frame).translation[2]
        w.velocity_ref[i] = w.feedforward[i] = 0.0
        w.drift[i] = state.frame_drift(self.frame)[2] if w.mode == "acceleration" else 0.0
        self.mark_written()

    @classmethod
    def baseline_task(cls, library, spec, target, context):
        if library == "placo":
            task = context["solver"].add_position_task(spec.frame, np.array([0, 0, target]))
            task.configure(spec.name, context["priority"], spec.weight)
            task.mask.set_axises("z")
            return task
        if library == "pink":
            from pink.tasks import FrameTask
            robot = context["robot"]
            start = KinematicState(robot, robot.q0, np.zeros(robot.nv), drift=False)
            task = FrameTask(spec.frame, position_cost=context["cost"], orientation_cost=0.0)
            task.xy = start.placement(spec.frame).translation[:2].copy()
            return task
        return super().baseline_task(library, spec, target, context)

    @classmethod
    def baseline_target(cls, library, task, target, context):
        if library == "placo":
            task.target_world = np.array([0.0, 0.0, target])
        elif library == "pink":
            task.set_target(pin.SE3(np.eye(3), np.array([*task.xy, target])))


@pytest.fixture
def toy_kind():
    register_task_kind(FrameHeightTask)
    yield FrameHeightTask
    del TASK_KINDS["frame_height"]


def test_a_registered_toy_kind_is_written_by_the_writer(robot, toy_kind):
    v, states = _states(robot, 1)
    s0 = states[0]
    w = TaskWriter(robot, "velocity")
    w.add(toy_kind("height", "sword_tip", gain=2.0, level=0))
    w.add_posture("posture", gain=1.0, level=1)
    w.write(s0, "height", 1.0)
    w.posture(s0, "posture", robot.q0)
    data = w.targets(s0)
    A, b = data.rows("height")
    assert np.array_equal(A[0], s0.frame_jacobian("sword_tip")[2])
    assert b[0] == pytest.approx(2.0 * (1.0 - s0.placement("sword_tip").translation[2]),
                                 abs=1e-12)
    sol = prioik.prepare(w.layout, "extended_jacobian").solve(data)
    assert A[0] @ sol.x == pytest.approx(b[0], abs=1e-9)


def test_a_registered_toy_kind_gives_a_one_off_stack(robot, toy_kind):
    v, states = _states(robot, 2)
    s0 = states[0]
    assert task_kind("frame_height") is toy_kind
    term = toy_kind("height", "sword_tip").term(s0, 1.0)
    assert term.name == "height" and term.J.shape == (1, robot.nv)
    stack = TaskStack([term.velocity(3.0), posture(s0, robot.q0).velocity(1.0)])
    sol = prioik.solve(stack, "extended_jacobian")
    assert term.J @ sol.x == pytest.approx(3.0 * term.error, abs=1e-9)
    assert np.array_equal(term.J[0], s0.frame_jacobian("sword_tip")[2])


class _HeightScenario(ArmScenario):
    """The arm: only the tool's height (5 cm up; the toy kind) and the posture."""

    def baseline_tasks(self):
        return [BaselineTask("tool_height", "frame_height", TOOL, 0),
                BaselineTask("posture", "posture", None, 1, weight=1e-4)]

    def baseline_target(self, name, t):
        if name == "tool_height":
            return self.start_height + 0.05
        return super().baseline_target(name, t)


@pytest.mark.parametrize("library", ["placo", "pink"])
def test_a_registered_toy_kind_runs_in_the_baselines(toy_kind, library):
    pytest.importorskip(library)
    scenario = _HeightScenario("reach")
    robot = scenario.robot
    start = KinematicState(robot, robot.q0, np.zeros(robot.nv), drift=False)
    scenario.start_height = start.placement(TOOL).translation[2]
    if library == "placo":
        from prioik.benchmarks.placo_baseline import run_placo as run
    else:
        from prioik.benchmarks.pink_baseline import run_pink as run
    res = run(scenario, duration=0.1, dt=0.01)
    assert not res.failed, res.message
    end = KinematicState(robot, res.q[-1], np.zeros(robot.nv), drift=False)
    rise = end.placement(TOOL).translation[2] - scenario.start_height
    assert 0.03 < rise < 0.06          # the toy's target, 5 cm up, (nearly) reached
