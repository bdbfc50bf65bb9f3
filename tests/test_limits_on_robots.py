"""Inverse kinematics with joint limits on real robots through the public path
(:class:`prioik.robots.TaskWriter` → :func:`prioik.prepare` → ``hierarchical_active_set``),
on every example-robot-data model prioik names and on URDFs loaded by path.

The stack a user writes for a limb reach: joint position and velocity limits as bounds
at level 0, support contacts at level 1 (floating-base robots), a far target for one limb
below them and the posture last. Closed loop, velocity and acceleration level, ``dt = 10
ms``: every answer ``optimal``; the warm-started solver gives the cold one (relative
``1e-9``); every 10th answer passes :func:`prioik.hierarchy.check_lexicographic`; ``q``
never leaves its limits (beyond rounding, ``1e-10``); the contacts' rows are met exactly (the
limits leave room
for them; relative ``1e-10``); and the limits
are met with equality at some steps (the test is not vacuous: the reach drives joints
to them). ``sample_humanoid`` (pinocchio's sample model) is left out: no reach drives its
joints to its limits.

Regions (:func:`prioik.robots.polygon_region`, ``add_com_region``): a humanoid keeps its
centre of mass over its feet while a hand reaches forward and down, the stack a balance
controller writes: contacts, joint limits and the CoM over the support polygon (shrunk by
2 cm) at level 0, the reach at level 1, the posture last.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

import prioik
from prioik.hierarchy import check_lexicographic
from prioik.robots import (
    KinematicState,
    TaskWriter,
    example_robot_data_dir,
    from_urdf,
    load,
    polygon_region,
)

DT = 0.01
STEPS = 60
#: relative distance of the warm answer from the cold one
WARM_TOL = 1e-9
#: a limit row counts as met with equality within this (relative to 1 + |bound|)
AT_BOUND = 1e-9
#: how far q may pass a limit (rad or m): the bound rows' primal tolerance (relative
#: 1e-10) times dt, and the rounding of q + q̇ dt (a1: 5.6e-16 at a held limit)
Q_TOL = 1e-10
#: a contact's rows met to this, relative to ``‖A_c‖ ‖x‖ + ‖b_c‖``
CONTACT_TOL = 1e-10


def _xarm7():
    return from_urdf(example_robot_data_dir() / "xarm_description/urdf/xarm7.urdf",
                     frames={"tool": "link_eef"})


def _a1():
    d = example_robot_data_dir() / "a1_description"
    return from_urdf(d / "urdf/a1.urdf", srdf=d / "srdf/a1.srdf",
                     frames={"front_left_foot": "FL_foot", "front_right_foot": "FR_foot",
                             "rear_left_foot": "RL_foot", "rear_right_foot": "RR_foot"})


_QUADRUPED = (["front_right_foot", "rear_left_foot", "rear_right_foot"], "front_left_foot")
_HUMANOID = (["left_foot", "right_foot"], "right_hand")
#: robot → (loader, support contacts, the limb that reaches)
ROBOTS = {
    "panda": (lambda: load("panda"), [], "tcp"),
    "ur5": (lambda: load("ur5"), [], "tool"),
    "talos": (lambda: load("talos"), *_HUMANOID),
    "g1": (lambda: load("g1"), *_HUMANOID),
    "go2": (lambda: load("go2"), *_QUADRUPED),
    "solo12": (lambda: load("solo12"), *_QUADRUPED),
    "xarm7 (URDF path)": (_xarm7, [], "tool"),
    "a1 (URDF path)": (_a1, *_QUADRUPED),
}


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_a_limb_reach_with_joint_limits_is_exact_on_every_robot(name, mode):
    """A limb reaching beyond its workspace with joint limits as bounds at level 0
    (contacts at level 1 on legged robots): every warm answer `optimal` and within
    WARM_TOL of the cold one, certified every tenth step, limits reached. The xArm7 at
    acceleration level reaches (step 12) a warm step at the posture level whose held
    limits' free directions are near dependent (joints 0 and 2 aligned): the unit-row
    step's Schur complement took it with a rounding of ~1e-5 on q̈ (8.7e-6 from the cold
    answer, said `optimal`, rejected by the certificate) until it took only well
    conditioned ones (`_unit_rows_step`)."""
    loader, contacts, limb = ROBOTS[name]
    robot = loader()
    accel = mode == "acceleration"
    gain = (100.0, 20.0) if accel else 10.0
    w = TaskWriter(robot, mode)
    w.add_joint_limits("limits", form="bounds", dt=DT, level=0,
                       **({"horizon": 0.1} if accel else {}))
    for c in contacts:
        w.add_contact(c, c, gain=gain, level=1)
    w.add_frame_position("reach", limb, gain=gain)
    w.add_posture("posture", gain=(10.0, 6.0) if accel else 1.0)
    warm = prioik.prepare(w.layout, "hierarchical_active_set")
    cold = prioik.prepare(w.layout, "hierarchical_active_set", warm_start=False)

    q, v = robot.q0.copy(), np.zeros(robot.nv)
    start = KinematicState(robot, q, v)
    places = {c: start.placement(c).copy() for c in contacts}
    target = start.placement(limb).translation + np.array([0.4, -0.3, 0.5])
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    bounded = np.isfinite(lo) & np.isfinite(hi)
    bounded[:7 if robot.n_base else 0] = False       # the free flyer's entries
    data = robot.data()
    at_bound = 0
    for step in range(STEPS):
        state = KinematicState(robot, q, v, data, drift=accel)
        for c in contacts:
            w.contact(state, c, places[c])
        w.frame_position(state, "reach", target)
        w.joint_limits(state, "limits")
        w.posture(state, "posture", robot.q0)
        stack = w.targets(state)
        answer = warm.solve(stack)
        assert answer.status == "optimal", (step, answer.diagnostics)
        reference = cold.solve(stack)
        assert reference.status == "optimal", (step, reference.diagnostics)
        gap = np.linalg.norm(answer.x - reference.x)
        assert gap <= WARM_TOL * max(1.0, np.linalg.norm(reference.x)), (step, gap)
        if step % 10 == 9:
            check = check_lexicographic(stack.as_stack(), answer.x)
            assert check.ok, (step, check)
        A, lower, upper = stack.bounds("limits")
        ax = A @ answer.x
        at_bound += int(np.any((np.abs(ax - lower) <= AT_BOUND * (1 + np.abs(lower)))
                               | (np.abs(ax - upper) <= AT_BOUND * (1 + np.abs(upper)))))
        v = v + answer.x * DT if accel else answer.x
        q = pin.integrate(robot.model, q, v * DT)
        beyond = np.maximum(lo[bounded] - q[bounded], q[bounded] - hi[bounded]).max()
        assert beyond <= Q_TOL, (step, beyond)
        for c in contacts:       # met exactly: the limits leave room for them
            Ac, bc = stack.rows(c)
            miss = np.linalg.norm(Ac @ answer.x - bc)
            assert miss <= CONTACT_TOL * (np.linalg.norm(Ac) * np.linalg.norm(answer.x)
                                          + np.linalg.norm(bc)), (step, c, miss)
    assert at_bound >= 5, at_bound         # the limits shaped the answers


#: how far the CoM may leave its polygon (m): the rows bound the linearized step, the
#: robot moves along the curved one (measured: velocity 1.8e-4, acceleration 5.3e-5)
COM_TOL = {"velocity": 1e-3, "acceleration": 2e-4}


def _supports(start: KinematicState, feet, margin: float):
    """The feet's placements at ``start`` and the rows ``C, upper`` of their soles'
    polygon (corners 5 cm behind and 10 cm ahead of each foot frame, 3 cm to each side),
    shrunk by ``margin``."""
    places = {f: start.placement(f).copy() for f in feet}
    soles = [places[f].act(np.array([dx, dy, 0.0])) for f in feet
             for dx in (-0.05, 0.1) for dy in (-0.03, 0.03)]
    C, upper = polygon_region(soles, margin=margin)
    return places, C, upper


def _balanced_reach(robot, mode: str, region: bool, steps: int):
    """Closed loop of the balance stack (see the module docstring); returns how far the
    CoM went past its polygon (m, the worst step), at how many steps a polygon row was
    met with equality, and the answers' statuses."""
    accel = mode == "acceleration"
    dt = 0.005 if accel else DT
    gain = (100.0, 20.0) if accel else 10.0
    horizon = {"horizon": 0.1} if accel else {}
    w = TaskWriter(robot, mode)
    feet = ("left_foot", "right_foot")
    start = KinematicState(robot, robot.q0, np.zeros(robot.nv))
    places, C, upper = _supports(start, feet, 0.02)
    for f in feet:
        w.add_contact(f, f, gain=gain, level=0)
    w.add_joint_limits("limits", form="bounds", dt=dt, level=0, **horizon)
    if region:
        w.add_com_region("balance", C, upper=upper, dt=dt, level=0, **horizon)
    w.add_frame_position("reach", "left_hand", gain=(50.0, 14.0) if accel else 5.0, level=1)
    w.add_posture("posture", gain=(10.0, 6.0) if accel else 1.0, level=2)
    solver = prioik.prepare(w.layout, "hierarchical_active_set")
    target = start.placement("left_hand").translation + np.array([0.45, 0.1, -0.35])
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    data = robot.data()
    beyond, at_bound, statuses = -np.inf, 0, set()
    for step in range(steps):
        state = KinematicState(robot, q, v, data, drift=accel)
        for f in feet:
            w.contact(state, f, places[f])
        w.joint_limits(state, "limits")
        if region:
            w.com_region(state, "balance")
        w.frame_position(state, "reach", target)
        w.posture(state, "posture", robot.q0)
        stack = w.targets(state)
        answer = solver.solve(stack)
        statuses.add(answer.status)
        if region:
            A, _, up = stack.bounds("balance")
            at_bound += int(np.any(np.abs(A @ answer.x - up) <= AT_BOUND * (1 + np.abs(up))))
            if step % 20 == 19:
                check = check_lexicographic(stack.as_stack(), answer.x)
                assert check.ok, (step, check)
        v = v + answer.x * dt if accel else answer.x
        q = pin.integrate(robot.model, q, v * dt)
        com = KinematicState(robot, q, v, data, drift=False).com
        beyond = max(beyond, float(np.max(C @ com - upper)))
    return beyond, at_bound, statuses


@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("name", ["g1", "talos"])
def test_a_com_region_keeps_a_reaching_humanoid_over_its_feet(name, mode):
    """With the region the CoM stays over the polygon (to :data:`COM_TOL`), held at its
    edge at most steps, every answer ``optimal`` and every 20th certified; without it the
    same reach takes the CoM more than 0.2 m past the edge."""
    robot = load(name)
    steps = 150 if mode == "acceleration" else 60
    beyond, at_bound, statuses = _balanced_reach(robot, mode, True, steps)
    assert statuses == {"optimal"}
    assert beyond <= COM_TOL[mode], beyond
    assert at_bound >= steps // 2, at_bound
    free, _, statuses = _balanced_reach(robot, mode, False, steps)
    assert statuses == {"optimal"} and free > 0.2, free


#: robot → (its support contacts, the limb held behind a wall and pulled through it)
_WALLED = {"g1": (("left_foot", "right_foot"), "left_hand"),
           "talos": (("left_foot", "right_foot"), "left_hand"),
           "go2": (("front_right_foot", "rear_left_foot", "rear_right_foot"),
                   "front_left_foot")}


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("mode", ["velocity", "acceleration"])
@pytest.mark.parametrize("name", list(_WALLED))
def test_regions_at_two_levels_every_optimal_answer_is_certified(name, mode, seed):
    """Contacts, joint limits and (seeded) the CoM polygon at level 0 or 1, a wall for a
    limb (a frame region on a random normal, a random point on the limb) at level 1, a
    target behind the wall at level 2, the posture last: every answer that says
    ``optimal``, warm-started or cold, passes :func:`check_lexicographic`, and the wall
    holds the limb at some steps. (Along such runs the exact answers blow up where the
    reach meets a singularity: 61 steps stay clear of it on these seeds.) TALOS at
    acceleration level, seed 1, step 60: the warm answer leaves a joint's ``q̈`` 1.9e-8
    inside its limit, which the certificate reads moved onto it (``snapped_rows``)."""
    rng = np.random.default_rng(seed)
    robot = load(name)
    support, limb = _WALLED[name]
    accel = mode == "acceleration"
    dt = 0.005 if accel else DT
    gain = (100.0, 20.0) if accel else 10.0
    horizon = {"horizon": 0.1} if accel else {}
    w = TaskWriter(robot, mode)
    start = KinematicState(robot, robot.q0, np.zeros(robot.nv))
    balance_level = int(rng.integers(0, 2))
    places, C, upper = _supports(start, support, float(rng.uniform(0.0, 0.03)))
    for f in support:
        w.add_contact(f, f, gain=gain, level=0)
    w.add_joint_limits("limits", form="bounds", dt=dt, level=0, **horizon)
    w.add_com_region("balance", C, upper=upper, dt=dt, level=balance_level, **horizon)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    p0 = start.placement(limb).translation
    w.add_frame_region("wall", limb, normal, lower=normal @ p0 - 0.05, dt=dt, level=1,
                       offset=rng.uniform(-0.05, 0.05, 3), **horizon)
    w.add_frame_position("reach", limb, gain=(50.0, 14.0) if accel else 5.0, level=2)
    w.add_posture("posture", gain=(10.0, 6.0) if accel else 1.0, level=3)
    warm = prioik.prepare(w.layout, "hierarchical_active_set")
    cold = prioik.prepare(w.layout, "hierarchical_active_set", warm_start=False)
    target = p0 - 0.3 * normal + 0.1 * rng.normal(size=3)
    q, v = robot.q0.copy(), np.zeros(robot.nv)
    data = robot.data()
    held = 0
    for step in range(61):
        state = KinematicState(robot, q, v, data, drift=accel)
        for f in support:
            w.contact(state, f, places[f])
        w.joint_limits(state, "limits")
        w.com_region(state, "balance")
        w.frame_region(state, "wall")
        w.frame_position(state, "reach", target)
        w.posture(state, "posture", robot.q0)
        stack = w.targets(state)
        answer = warm.solve(stack)
        for sol in (answer, cold.solve(stack)):
            if sol.status == "optimal":
                check = check_lexicographic(stack, sol.x)
                assert check.ok, (step, sol.diagnostics, str(check))
        A, lower, _ = stack.bounds("wall")
        held += int(abs(A[0] @ answer.x - lower[0]) <= AT_BOUND * (1 + abs(lower[0])))
        v = v + answer.x * dt if accel else answer.x
        q = pin.integrate(robot.model, q, v * dt)
    assert held >= 10, held
