"""prioik.robots.ControlStep against the writer loop it compiles: KinematicState + the
TaskWriter's writers + PreparedSolver.solve + pin.integrate, step for step."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import unaligned

import prioik
from prioik.formulations import ConcurrentUseError, FormulationError, Status
from prioik.formulations.base import CoreInputError
from prioik.hierarchy import TaskStackError
from prioik.robots import (
    TASK_KINDS,
    ControlStep,
    KinematicState,
    PostureTask,
    RobotTask,
    StateError,
    TaskWriter,
    load,
    register_task_kind,
)

DT = 0.002
REL = 1e-12          # q and q̇ per step, relative


@pytest.fixture(scope="module")
def panda():
    return load("panda")


@pytest.fixture(scope="module")
def g1():
    return load("g1")


@pytest.fixture(scope="module")
def talos():
    return load("talos")


@pytest.fixture(scope="module")
def go2():
    return load("go2")


def _placements(robot, q, frames):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    com = pin.centerOfMass(robot.model, data, q)
    return {f: data.oMf[robot.frame_id(f)].copy() for f in frames}, np.array(com)


def _run(robot, declare, references, steps, q0=None, follow=False, hard=(), **options):
    """Both loops from q0 (default robot.q0) for ``steps`` steps; ``references(i)``: task
    name → the writer's arguments (a task absent takes none). Returns per step
    (q_next, q̇, status) of the ControlStep and of the writer loop, and the step. With
    ``follow`` the writer loop steps from the ControlStep's q each step (a trajectory
    through near-singular configurations amplifies the last bits of the free flyer's
    integration, which pinocchio rounds in its own order)."""
    q0 = robot.q0 if q0 is None else q0
    rows = declare(TaskWriter(robot, "velocity", hard=hard))
    loop_rows = declare(TaskWriter(robot, "velocity", hard=hard))
    step = ControlStep(rows, "hierarchical_active_set", dt=DT, **options)
    solver = prioik.prepare(loop_rows.layout, "hierarchical_active_set", **options)
    data, zero = robot.model.createData(), np.zeros(robot.nv)
    q, q_loop = q0.copy(), q0.copy()
    ours, theirs = [], []
    for i in range(steps):
        if follow:
            q_loop = q.copy()
        refs = references(i)
        for name, args in refs.items():
            step.reference(name, *args)
        given = q.copy()
        q_next = step(q).copy()
        assert np.array_equal(q, given)                # the caller's q is not written
        q = q_next
        ours.append((q, step.velocity.copy(), step.status))
        state = KinematicState(robot, q_loop, zero, data, drift=False)
        for name in loop_rows.tasks():
            loop_rows.write(state, name, *refs.get(name, ()))
        sol = solver.solve(loop_rows.targets(state))
        if sol.status == Status.FAILED:
            v, q_next = np.zeros(robot.nv), q_loop.copy()
        else:
            v, q_next = sol.x, pin.integrate(robot.model, q_loop, sol.x * DT)
        theirs.append((q_next, v, sol.status))
        _assert_same_diagnostics(step.solution(), sol, i)
        q_loop = q_next
    return ours, theirs, step


def _assert_same_diagnostics(mine, ref, i):
    """The step's Solution and the writer loop's: the same status and diagnostics."""
    a, b = mine.diagnostics, ref.diagnostics
    assert mine.status == ref.status, f"step {i}"
    assert a.reason == b.reason, f"step {i}"
    assert a.capped_levels == b.capped_levels and a.ambiguous_levels == b.ambiguous_levels
    assert (a.fault is None) == (b.fault is None)
    if a.fault is not None:
        assert (a.fault.code, a.fault.level) == (b.fault.code, b.fault.level)
    assert list(a.infeasible_levels) == list(b.infeasible_levels), f"step {i}"
    assert np.array_equal(a.ranks, b.ranks) and np.array_equal(a.iterations, b.iterations)
    assert a.detail.equality_first == b.detail.equality_first, f"step {i}"


def _assert_same(ours, theirs):
    for i, ((q, v, st), (q2, v2, st2)) in enumerate(zip(ours, theirs, strict=True)):
        assert st == st2, f"step {i}: {st} vs {st2}"
        assert np.abs(q - q2).max() <= REL * max(1.0, np.abs(q2).max()), f"step {i}: q"
        assert np.abs(v - v2).max() <= REL * max(1.0, np.abs(v2).max()), f"step {i}: q̇"


def _panda_rows(rows):
    rows.add_joint_limits("limits", form="bounds", dt=DT, level=0)
    rows.add_frame_position("hand", rows.robot.frames["hand"], gain=10.0, level=1)
    rows.add_posture("posture", gain=1.0, level=2)
    return rows


def test_panda_with_limits_equals_the_writer_loop(panda):
    # the hand target moves along a circle that leaves the reach (x up to 1.3 m)
    def references(i):
        a = i / 40.0
        return {"hand": (np.array([0.5 + 0.8 * np.sin(a), 0.3 * np.cos(a), 0.45]),),
                "posture": (panda.q0,)}
    ours, theirs, step = _run(panda, _panda_rows, references, 400)
    _assert_same(ours, theirs)
    assert step.solution().status == ours[-1][2]


@pytest.mark.parametrize("hard", [(), (0, 1)], ids=["soft", "hard-limits-and-feet"])
def test_g1_free_flyer_contacts_com_hand_posture_limits(g1, hard):
    feet, com0 = _placements(g1, g1.q0, ("left_foot", "right_foot"))
    f = g1.frames

    def declare(rows):
        rows.add_joint_limits("limits", form="bounds", dt=DT, level=0)
        rows.add_contact("left_foot", f["left_foot"], gain=10.0, level=1)
        rows.add_contact("right_foot", f["right_foot"], gain=10.0, level=1)
        rows.add_com("com", gain=5.0, level=2)
        rows.add_frame_position("hand", f["right_hand"], gain=10.0, level=3)
        rows.add_posture("posture", gain=1.0, level=4)
        return rows

    hand0 = _placements(g1, g1.q0, ("right_hand",))[0]["right_hand"].translation
    rng = np.random.default_rng(7)
    path = hand0 + np.cumsum(rng.normal(0.0, 0.01, (300, 3)), axis=0)

    def references(i):
        return {"left_foot": (feet["left_foot"],), "right_foot": (feet["right_foot"],),
                "com": (com0[:2] + 0.02 * np.sin(i / 30.0),), "hand": (path[i],),
                "posture": (g1.q0,)}
    ours, theirs, _ = _run(g1, declare, references, 300, hard=hard)
    _assert_same(ours, theirs)


def test_talos_pose_orientation_capped_damped(talos):
    feet, _ = _placements(talos, talos.q0, ("left_foot", "right_foot"))
    hands, _ = _placements(talos, talos.q0, ("left_hand", "right_hand"))
    f = talos.frames

    def declare(rows):
        rows.add_joint_limits("limits", form="bounds", dt=DT, level=0)
        rows.add_contact("left_foot", f["left_foot"], gain=10.0, level=1)
        rows.add_frame_pose("right_foot", f["right_foot"], gain=10.0, level=1)
        rows.add_frame_position("left_hand", f["left_hand"], gain=10.0, level=2,
                                max_rate=0.3)
        rows.add_frame_orientation("right_hand", f["right_hand"], gain=5.0, level=2)
        rows.add_damping("damping", weight=1e-4, level=2)
        rows.add_posture("posture", gain=1.0, level=3)
        return rows

    turn = pin.exp3(np.array([0.0, 0.0, 0.8]))

    def references(i):
        rf = feet["right_foot"]
        return {"left_foot": (feet["left_foot"],),
                "right_foot": (rf.translation, rf.rotation),
                "left_hand": (hands["left_hand"].translation + [0.6, 0.1 * np.sin(i / 20), 0.2],),
                "right_hand": (turn @ hands["right_hand"].rotation,), "posture": (talos.q0,)}
    ours, theirs, _ = _run(talos, declare, references, 200)
    _assert_same(ours, theirs)


def test_go2_point_region_activation_limits(go2):
    f = go2.frames
    feet, com0 = _placements(go2, go2.q0, tuple(f[k] for k in f if k.endswith("foot")))

    def declare(rows):
        rows.add_joint_limits("limits", form="activation", level=0)
        for name in ("front_right_foot", "rear_left_foot", "rear_right_foot"):
            rows.add_frame_position(name, f[name], gain=10.0, level=0)
        rows.add_frame_region("floor", f["front_left_foot"], [0.0, 0.0, 1.0], lower=0.0,
                              dt=DT, level=0)
        rows.add_com_region("com_box", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                            lower=com0[:2] - 0.05, upper=com0[:2] + 0.05, dt=DT, level=0)
        rows.add_point("paw", f["front_left_foot"], [0.0, 0.0, 0.02], gain=10.0, level=1)
        rows.add_posture("posture", gain=1.0, level=2)
        return rows

    paw0 = feet[f["front_left_foot"]].translation + [0.0, 0.0, 0.02]

    def references(i):
        refs = {name: (feet[f[name]].translation,)
                for name in ("front_right_foot", "rear_left_foot", "rear_right_foot")}
        refs["paw"] = (paw0 + [0.1, 0.0, 0.15 * np.sin(i / 15.0) - 0.05],)
        refs["posture"] = (go2.q0,)
        return refs
    ours, theirs, _ = _run(go2, declare, references, 200, follow=True)
    _assert_same(ours, theirs)


def test_a_capped_step_is_the_prepared_solvers_answer(panda):
    # max_iter=1 caps a level: the step is finished by the solver's own code
    def references(i):
        return {"hand": (np.array([0.9, 0.4, 0.2]),), "posture": (panda.q0,)}
    ours, theirs, step = _run(panda, _panda_rows, references, 30, max_iter=1)
    _assert_same(ours, theirs)
    assert {s for _, _, s in ours} == {Status.APPROXIMATE}
    # (_run compared each step's Solution with the writer loop's)
    mine = step.solution()
    assert mine.diagnostics.capped_levels and mine.diagnostics.fault.code == "iteration_cap"


def test_failed_step_keeps_q(panda):
    rows = _panda_rows(TaskWriter(panda, "velocity", hard=(1,)))
    step = ControlStep(rows, dt=DT)
    step.reference("hand", np.array([3.0, 0.0, 0.5]))      # out of reach: level 1 hard
    step.reference("posture", panda.q0)
    q = panda.q0.copy()
    out = step(q)
    assert step.status == Status.FAILED
    assert step.solution().diagnostics.fault.code == "hard_level"
    assert np.array_equal(out, q) and not step.velocity.any()


@pytest.mark.parametrize("name", ["panda", "g1"])
def test_integration_is_pinocchios(name, request):
    robot = request.getfixturevalue(name)
    rows = TaskWriter(robot, "velocity")
    rows.add_posture("posture", gain=1.0, level=0)
    rng = np.random.default_rng(3)
    for dt in (0.002, 0.5):
        step = ControlStep(rows if dt == 0.002 else _copy_rows(robot), dt=dt)
        for scale in (1e-9, 1.0, 5.0):
            for _ in range(20):
                q = robot.q0 + rng.normal(0.0, 0.3, robot.nq)
                if robot.n_base:
                    quat = rng.normal(size=4)
                    q[3:7] = quat / np.linalg.norm(quat)
                v = rng.normal(0.0, scale, robot.nv)
                expect = pin.integrate(robot.model, q, v * dt)
                got = step.integrate(q, v)
                assert np.abs(got - expect).max() <= REL * max(1.0, np.abs(expect).max())


def _copy_rows(robot):
    rows = TaskWriter(robot, "velocity")
    rows.add_posture("posture", gain=1.0, level=0)
    return rows


def test_the_clean_path_is_compiled(panda, monkeypatch):
    rows = _panda_rows(TaskWriter(panda, "velocity"))
    step = ControlStep(rows, dt=DT)
    step.reference("hand", np.array([0.45, 0.2, 0.45]))
    step.reference("posture", panda.q0)

    def refuse(*_a, **_k):
        raise AssertionError("the Python path ran")
    from prioik._core import rows as core_rows
    for name in ("position_rows", "position_target_rows", "posture_error", "bounds_at",
                 "velocity_targets"):
        monkeypatch.setattr(core_rows, name, refuse)
    monkeypatch.setattr(step._impl, "answer", refuse)
    monkeypatch.setattr(step._impl, "solve_checked", refuse)
    monkeypatch.setattr(type(step.solver), "solve", refuse)
    monkeypatch.setattr(pin, "integrate", refuse)
    q = panda.q0.copy()
    for _ in range(50):
        q = step(q)
        assert step.status == Status.OPTIMAL
    assert np.abs(q - panda.q0).max() > 1e-3          # it moved


def test_bad_q(g1, panda):
    rows = TaskWriter(g1, "velocity")
    rows.add_posture("posture", gain=1.0, level=0)
    step = ControlStep(rows, dt=DT)
    step.reference("posture", g1.q0)
    with pytest.raises(StateError, match="q"):
        step(g1.q0[:-1])
    bad = g1.q0.copy()
    bad[10] = np.nan
    with pytest.raises(StateError, match="q"):
        step(bad)
    bad = g1.q0.copy()
    bad[3:7] = [0.0, 0.0, 0.0, 2.0]
    with pytest.raises(StateError, match="q"):
        step(bad)
    with pytest.raises(StateError, match="q"):
        step("not a configuration")
    strided = np.repeat(g1.q0, 2)[::2]                 # a view with strides
    assert np.array_equal(step(strided), step.integrate(g1.q0, step.velocity))
    assert np.array_equal(step(list(g1.q0)), step.integrate(g1.q0, step.velocity))
    assert np.array_equal(step(unaligned(g1.q0)), step.integrate(g1.q0, step.velocity))


def test_bad_references_and_declarations(panda):
    rows = _panda_rows(TaskWriter(panda, "velocity"))
    step = ControlStep(rows, dt=DT)
    with pytest.raises(TaskStackError, match="hand"):
        step(panda.q0)                                  # no reference yet
    with pytest.raises(TaskStackError, match="hand"):
        step.reference("hand", np.zeros(4))
    with pytest.raises(TaskStackError, match="hand"):
        step.reference("hand", np.array([0.1, np.nan, 0.2]))
    with pytest.raises(TaskStackError, match="posture"):
        step.reference("posture", panda.q0[:3])
    with pytest.raises(TaskStackError, match="limits"):
        step.reference("limits", 1.0)
    with pytest.raises(TaskStackError, match="nope"):
        step.reference("nope", 1.0)
    with pytest.raises(TaskStackError, match="hand"):
        step.reference("hand")
    with pytest.raises(TaskStackError, match="acceleration"):
        ControlStep(TaskWriter(panda, "acceleration"), dt=DT)
    with pytest.raises(FormulationError, match="extended_jacobian"):
        ControlStep(_panda_rows(TaskWriter(panda, "velocity")), "extended_jacobian", dt=DT)
    with pytest.raises(TaskStackError, match="dt"):
        ControlStep(_panda_rows(TaskWriter(panda, "velocity")), dt=float("nan"))


def test_a_kind_without_compiled_op_is_refused(panda):
    class UncompiledPosture(PostureTask):
        """A kind without a compiled op (the base's)."""

        kind = "test_uncompiled_posture"
        compiled_op = RobotTask.compiled_op

    register_task_kind(UncompiledPosture)
    try:
        rows = TaskWriter(panda, "velocity")
        rows.add(UncompiledPosture("mine", gain=1.0, level=0))
        with pytest.raises(TaskStackError, match="test_uncompiled_posture.*mine|mine.*test_unc"):
            ControlStep(rows, dt=DT)
    finally:
        del TASK_KINDS[UncompiledPosture.kind]     # (the registry is the process's)


def test_one_thread_at_a_time(panda):
    rows = _panda_rows(TaskWriter(panda, "velocity"))
    step = ControlStep(rows, dt=DT)
    step.reference("hand", np.array([0.45, 0.2, 0.45]))
    step.reference("posture", panda.q0)
    assert step.solver._acquire(False)
    try:
        with pytest.raises(ConcurrentUseError):
            step(panda.q0)
    finally:
        step.solver._release()
    step(panda.q0)


def test_core_binding_refuses_bad_arrays(panda):
    from prioik import _core
    rows = _panda_rows(TaskWriter(panda, "velocity"))
    step = ControlStep(rows, dt=DT)
    core = step._core
    for q in (None, [0.0] * panda.nq, np.zeros(panda.nq + 1), np.zeros(panda.nq, np.float32),
              np.zeros((panda.nq, 1))):
        with pytest.raises(CoreInputError, match="q"):
            core.step(q)
    with pytest.raises(CoreInputError, match="v"):
        core.integrate(panda.q0, np.zeros(panda.nv + 1), np.zeros(panda.nq))
    with pytest.raises(CoreInputError, match="out"):
        core.integrate(panda.q0, np.zeros(panda.nv), np.zeros(panda.nq)[::-1][:3])
    d = rows.data
    with pytest.raises(CoreInputError, match="solver"):
        _core.ControlStep(None, d.A, d.b, d.lower, d.upper, d.sqrt_weight, rows._Q,
                          step.data.J, panda.nq, DT, np.zeros(0, np.int64),
                          np.zeros((0, 5), np.int64), True)
    with pytest.raises(CoreInputError, match="A"):
        _core.ControlStep(step._impl._cpp, d.A[:, :2], d.b, d.lower, d.upper, d.sqrt_weight,
                          rows._Q, step.data.J, panda.nq, DT, np.zeros(0, np.int64),
                          np.zeros((0, 5), np.int64), True)
    with pytest.raises(CoreInputError, match="joints"):
        _core.ControlStep(step._impl._cpp, d.A, d.b, d.lower, d.upper, d.sqrt_weight,
                          rows._Q, step.data.J, panda.nq, DT, np.zeros(0, np.int64),
                          np.array([[5, 5, 7, 6, 1]], np.int64), True)
    with pytest.raises(CoreInputError, match="spec"):
        core.add_frame(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3),
                       np.array([0, 0, 1, 99], np.int64), np.zeros((5, 3)), True)
    with pytest.raises(CoreInputError, match="spec"):
        core.add_frame(np.zeros(3), np.eye(3), np.zeros(3), np.eye(3),
                       np.array([0, 5, 1, 0], np.int64), np.zeros((5, 3)), False)
    with pytest.raises(CoreInputError, match="lim"):
        core.add_limits(True, np.arange(3, dtype=np.int64), np.zeros((3, 2)), np.zeros(6))
    with pytest.raises(CoreInputError, match="rows"):
        core.add_posture(d.A.shape[0] - 1, np.arange(panda.nq, dtype=np.int64))
    buffer = np.zeros(3)
    for bad in (np.zeros(3)[::-1].copy(), buffer.copy()):
        bad.setflags(write=False)
        with pytest.raises(CoreInputError, match="buffer"):
            _core.put_reference(bad, 0, np.zeros(3), 3, -1)
    for value in (np.zeros(4), np.zeros((3, 1)), [0.0, 0.0, 0.0], np.zeros(3, np.float32)):
        with pytest.raises(CoreInputError, match="reference"):
            _core.put_reference(buffer, 0, value, 3, -1)
    with pytest.raises(CoreInputError, match="buffer"):
        _core.put_reference(buffer, 1, np.zeros(3), 3, -1)
    assert _core.put_reference(buffer, 0, np.array([1.0, np.inf, 2.0]), 3, -1) == 1
    assert not buffer.any()                      # nothing written


def test_held_hard_levels_stay_on_the_compiled_path(panda, monkeypatch):
    # the limits hard (level 0, always held): no step runs the Python hard check
    rows = _panda_rows(TaskWriter(panda, "velocity", hard=(0,)))
    step = ControlStep(rows, dt=DT)
    step.reference("hand", np.array([0.45, 0.2, 0.45]))
    step.reference("posture", panda.q0)

    def refuse(*_a, **_k):
        raise AssertionError("the Python hard check ran")
    monkeypatch.setattr(step.solver, "_check_hard", refuse)
    q = panda.q0
    for _ in range(50):
        q = step(q)
        assert step.status == Status.OPTIMAL
    assert np.abs(q - panda.q0).max() > 1e-3


def _wheel_arm():
    """A fixed-base arm whose first joint is continuous (n_q = 2, n_v = 1)."""
    from prioik.robots import RobotModel
    model = pin.Model()
    inertia = pin.Inertia(1.0, np.zeros(3), np.eye(3) * 0.01)
    parent = 0
    for i, joint in enumerate((pin.JointModelRUBZ(), pin.JointModelRY(), pin.JointModelRY())):
        parent = model.addJoint(parent, joint, pin.SE3(np.eye(3), np.array([0.3, 0, 0]) * (i > 0)),
                                f"joint{i}")
        model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
    model.addFrame(pin.Frame("tip", parent, 0, pin.SE3(np.eye(3), np.array([0.3, 0, 0])),
                             pin.FrameType.OP_FRAME))
    q0 = pin.neutral(model)
    q0[2:] = [0.4, -0.6]
    return RobotModel("wheel_arm", model, q0, {"tip": "tip"})


def test_a_continuous_joint_is_integrated_by_pinocchio():
    robot = _wheel_arm()

    def declare(rows):
        rows.add_frame_position("tip", "tip", gain=10.0, level=0)
        rows.add_damping("damping", weight=1e-3, level=1)
        return rows

    def references(i):
        return {"tip": (np.array([0.2 * np.cos(i / 20), 0.4 + 0.1 * np.sin(i / 20), 0.1]),)}
    ours, theirs, step = _run(robot, declare, references, 100)
    _assert_same(ours, theirs)
    assert not step._integrable
    # a posture over its continuous joint has no compiled op: refused, naming it
    rows = TaskWriter(robot, "velocity")
    rows.add_posture("posture", gain=1.0, level=0)
    with pytest.raises(TaskStackError, match="posture"):
        ControlStep(rows, dt=DT)
